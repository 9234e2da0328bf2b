//! Classical solvers in f64: the oracles the simulator is checked against and the
//! baselines the networks must beat.
//!
//! * [`ik`]: fit each segment's frame to its markers (Kabsch/SVD on the body model's marker
//!   offsets), then decompose the hand's orientation in the forearm frame in the joint order.
//! * [`id`]: recursive Newton–Euler inverse dynamics of the wrist chain.

pub mod id;
pub mod ik;

pub use id::{
    ForearmMotion, JointState, inverse_dynamics, inverse_dynamics_at, inverse_dynamics_moving, inverse_dynamics_rows,
};
pub use ik::{fit_points, fit_segment, inverse_kinematics, inverse_kinematics_frame};
