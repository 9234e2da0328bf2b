//! The wrist simulator: the forearm fixed in the lab at a shoulder pose, the hand driven
//! through the three wrist joints by a computed-torque controller, stepped by rapier.
//!
//! * [`protocol`]: the prescribed motions (analytic q, q̇, q̈).
//! * [`world`]: the rapier model built from `ikid::body` (the only place rapier types appear).
//! * [`trial`]: runs a protocol and records ground truth: the angles, velocities and
//!   accelerations rapier produced and the torques that produced them, plus the markers.

#![deny(missing_docs)]

pub mod protocol;
pub mod trial;
pub mod world;

pub use trial::{SimConfig, Trial, simulate};

/// Names this simulator and the physics engine behind it, for data provenance.
pub const SIMULATOR: &str = concat!("ikid-sim ", env!("CARGO_PKG_VERSION"), " on rapier3d-f64 0.35.2");

/// What can go wrong setting up a simulation; messages name the parameter.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A parameter is out of its valid range.
    #[error("{name} is {value}: {expected}")]
    Parameter {
        /// Parameter name.
        name: &'static str,
        /// Value given.
        value: String,
        /// What is accepted.
        expected: String,
    },
    /// A protocol name [`Protocol::from_name`](protocol::Protocol::from_name) does not know.
    #[error("unknown protocol {name:?} (known: {known})")]
    UnknownProtocol {
        /// Name given.
        name: String,
        /// The known names, quoted and comma-separated.
        known: String,
    },
    /// Joint-sign octants that do not parse, or given to a protocol that has none.
    #[error("octants: {0}")]
    Octants(String),
    /// An error from the core (e.g. a non-finite joint state).
    #[error(transparent)]
    Core(#[from] ikid::Error),
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

pub(crate) fn check(name: &'static str, value: f64, ok: bool, expected: &str) -> Result<()> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(Error::Parameter { name, value: value.to_string(), expected: expected.into() })
    }
}
