//! What the tracker gives per frame ([`TrackerOutput`]), and the step that makes it: torques
//! from the state, and the frame's status.

use nalgebra::Isometry3;

use super::{Step, Tracker};
use crate::body::N_COORDINATES;
use crate::error::Result;
use crate::reference::{self, JointState};
use crate::status;

/// Smallest noise [`TrackerOutput::noise`] reports, m (before any third difference is seen).
pub const MIN_REPORTED_NOISE: f64 = 1e-9;

/// One frame's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerOutput {
    /// Angles, velocities and accelerations (rad, rad/s, rad/s²), coordinate order.
    pub state: JointState,
    /// Joint torques, N·m, coordinate order.
    pub tau: [f64; N_COORDINATES],
    /// Bit `i` set: marker `i` ([`MARKERS`](crate::body::MARKERS) order) was missing in this frame.
    pub missing: u8,
    /// Whether a refiner corrected this estimate (false without one, and while its window fills).
    pub refined: bool,
    /// [`status`] bits: markers rejected, poses held, a restart, an implausible angle.
    pub status: u16,
    /// Mean of the hand markers' noise (standard deviation) measured so far from the data
    /// alone, m (at least [`MIN_REPORTED_NOISE`]); what the refiner is told and gated by.
    pub noise: f64,
}

/// Values per frame in [`TrackerOutput::values`]: q, q̇, q̈ and τ, three each.
pub const TRACKER_VALUES: usize = 4 * N_COORDINATES;

impl TrackerOutput {
    /// What [`Tracker::run`] reports for a frame without an estimate (before the filter
    /// started): NaN angles, velocities, accelerations, torques and noise, not refined, and the
    /// frame's own `missing` markers.
    pub fn waiting(missing: u8) -> Self {
        let nan = [f64::NAN; N_COORDINATES];
        TrackerOutput {
            state: JointState { q: nan, qd: nan, qdd: nan },
            tau: nan,
            missing,
            refined: false,
            status: 0,
            noise: f64::NAN,
        }
    }

    /// q, q̇, q̈ and τ back to back ([`TRACKER_VALUES`] values; rad, rad/s, rad/s², N·m).
    pub fn values(&self) -> [f64; TRACKER_VALUES] {
        let rows = [self.state.q, self.state.qd, self.state.qdd, self.tau];
        std::array::from_fn(|i| rows[i / N_COORDINATES][i % N_COORDINATES])
    }
}

impl Tracker {
    /// The frame's output: the torques of `state` by Newton–Euler (gravity's direction from the
    /// forearm's pose `forearm`), and [`status::IMPLAUSIBLE`] for an angle or a torque no wrist
    /// reaches.
    pub(super) fn output(
        &self,
        step: &mut Step,
        forearm: &Isometry3<f64>,
        state: JointState,
        refined: bool,
        noise: f64,
    ) -> Result<TrackerOutput> {
        if (0..N_COORDINATES).any(|c| status::angle_implausible(c, state.q[c])) {
            step.flags |= status::IMPLAUSIBLE;
        }
        let tau = reference::inverse_dynamics_at(&self.body, &forearm.rotation.to_rotation_matrix(), &state)?;
        if tau.iter().any(|&t| status::torque_implausible(t, self.torque_limit)) {
            step.flags |= status::IMPLAUSIBLE;
        }
        Ok(TrackerOutput { state, tau, missing: step.missing, refined, status: step.flags, noise })
    }
}

/// Standard deviations of a frame's estimate, from the filter's covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerSd {
    /// Of each angle, rad, coordinate order: the square root of the covariance's diagonal.
    pub q: [f64; N_COORDINATES],
    /// Of each torque, N·m: the covariance of the state carried through the inverse dynamics
    /// linearised at the estimate (J P Jᵀ, J by central differences).
    pub tau: [f64; N_COORDINATES],
}

impl Tracker {
    /// The standard deviations of the filter's last estimate ([`TrackerSd`]), or `None`
    /// before it started (or after a reset). They describe the filter's own state: a refined
    /// output (a refiner moved it) is not what they measure.
    pub fn output_sd(&self) -> Option<TrackerSd> {
        let (x, p) = self.state.as_ref()?;
        let forearm = self.forearm?.rotation.to_rotation_matrix();
        let state_of = |x: &super::StateVector| JointState {
            q: [x[0], x[1], x[2]],
            qd: [x[3], x[4], x[5]],
            qdd: [x[6], x[7], x[8]],
        };
        let mut jacobian = nalgebra::SMatrix::<f64, N_COORDINATES, { 3 * N_COORDINATES }>::zeros();
        for k in 0..3 * N_COORDINATES {
            // A step a small share of the state's own spread (angles, velocities, accelerations
            // differ by orders of magnitude).
            let h = (p[(k, k)].sqrt() * 1e-3).max(1e-7);
            let (mut up, mut down) = (*x, *x);
            up[k] += h;
            down[k] -= h;
            let tau_up = reference::inverse_dynamics_at(&self.body, &forearm, &state_of(&up)).ok()?;
            let tau_down = reference::inverse_dynamics_at(&self.body, &forearm, &state_of(&down)).ok()?;
            for c in 0..N_COORDINATES {
                jacobian[(c, k)] = (tau_up[c] - tau_down[c]) / (2.0 * h);
            }
        }
        let tau_cov = jacobian * p * jacobian.transpose();
        Some(TrackerSd {
            q: std::array::from_fn(|c| p[(c, c)].max(0.0).sqrt()),
            tau: std::array::from_fn(|c| tau_cov[(c, c)].max(0.0).sqrt()),
        })
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {

    use super::*;

    use crate::reference::JointState;

    #[test]
    fn values_are_q_qd_qdd_tau_in_order() {
        let out = TrackerOutput {
            state: JointState { q: [1.0, 2.0, 3.0], qd: [4.0, 5.0, 6.0], qdd: [7.0, 8.0, 9.0] },
            tau: [10.0, 11.0, 12.0],
            missing: 0,
            refined: false,
            status: 0,
            noise: 1e-3,
        };
        assert_eq!(TRACKER_VALUES, 12);
        assert_eq!(out.values(), std::array::from_fn(|i| (i + 1) as f64));
        let w = TrackerOutput::waiting(0b10_0001);
        assert!(w.values().iter().all(|v| v.is_nan()) && w.noise.is_nan());
        assert_eq!((w.missing, w.refined), (0b10_0001, false));
    }
}
