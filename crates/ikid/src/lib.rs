//! ikid: real-time inverse kinematics and dynamics of the human wrist from motion-capture
//! markers.
//!
//! A small MLP over a short window of marker frames predicts the wrist's three angles (or
//! torques). This crate is the pure core: the [`body`] model and its conventions, the
//! [`features`] a network sees, the allocation-free [`net`] kernels, [`model`] files and the
//! frame-by-frame [`stream`]; the classical [`reference`](mod@reference) solvers (IK by segment
//! fitting, ID by Newton–Euler) the networks are measured against; and the [`tracker`], a
//! Kalman filter over the body model giving angles, velocities, accelerations and torques per
//! frame, optionally refined by a network.
//!
//! ```no_run
//! let model = ikid::Model::load("wrist-ik.safetensors")?;
//! let mut stream = model.stream();
//! # let frames: Vec<[f32; 18]> = vec![];
//! for frame in &frames {
//!     if let Some(angles) = stream.push(frame)? {
//!         println!("s_p {:.3} e_f {:.3} ad_ab {:.3} rad", angles[0], angles[1], angles[2]);
//!     }
//! }
//! # Ok::<(), ikid::Error>(())
//! ```

#![deny(missing_docs)]

pub mod body;
pub mod calibration;
pub mod error;
pub mod features;
pub mod gaps;
pub mod model;
pub mod net;
pub mod noise;
pub mod reference;
pub mod rng;
pub mod status;
pub mod stream;
pub mod testing;
pub mod tracker;

pub use calibration::Calibration;
pub use error::{Error, ErrorKind, Result};
pub use features::{FeatureSet, FrameKind};
pub use gaps::{GapFiller, MissingMarkers};
pub use model::{Model, ModelCard, OutputSpec};
pub use stream::Stream;
pub use tracker::{Tracker, TrackerOutput, TrackerSettings};

/// This crate's version.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
