//! What the tracker gives per frame ([`TrackerOutput`]), and the step that makes it: torques
//! from the state, and the frame's status.

use nalgebra::{Isometry3, SMatrix, SVector, Vector3};

use super::refiner::{REFINED_SD_SCALE_Q, REFINED_SD_SCALE_TAU};
use super::{N_HAND, N_STATE, StateMatrix, StateVector, Step, Tracker};
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
    /// forearm's pose `forearm`, the forearm's own motion as far as it is seen), and [`status::IMPLAUSIBLE`] for an angle or a torque no wrist
    /// reaches, or a hand that reads turned over on the forearm ([`status::TURNED_OVER`]).
    pub(super) fn output(
        &mut self,
        step: &mut Step,
        forearm: &Isometry3<f64>,
        state: JointState,
        refined: bool,
        noise: f64,
    ) -> Result<TrackerOutput> {
        if (0..N_COORDINATES).any(|c| status::angle_implausible(c, state.q[c])) {
            step.flags |= status::IMPLAUSIBLE;
        }
        step.flags |= self.turned_over.update(&state.q);
        let motion = self.forearm_motion(step, forearm);
        let tau =
            reference::inverse_dynamics_moving(&self.body, &forearm.rotation.to_rotation_matrix(), &motion, &state)?;
        if tau.iter().any(|&t| status::torque_implausible(t, self.torque_limit)) {
            step.flags |= status::IMPLAUSIBLE;
        }
        Ok(TrackerOutput { state, tau, missing: step.missing, refined, status: step.flags, noise })
    }
}

/// Frames the forearm's noise is followed through the filter for, as a power of two (2²⁰: far
/// longer than any gain's memory).
const DOUBLINGS: usize = 20;

/// What the torques' standard deviation from the markers' noise alone is multiplied by. Their
/// noise through the filter's gain leaves out the motion the filter lags behind; the filter's
/// covariance would count that lag as white jerk of [`TrackerSettings::jerk_noise`](super::TrackerSettings)
/// (a density chosen for the smallest errors, not to describe the motion), which made the
/// torques' σ 2.2× their errors. Tuned by `studies/sigma_coverage.py` on seeds TUNE (never the
/// SCORE seeds it is measured on): the share of frames within ±σ is then 68.3 % there.
pub const SD_SCALE_TAU: f64 = 1.10;

/// Standard deviations of a frame's estimate, from the filter's covariance and the markers' noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerSd {
    /// Of each angle, rad, coordinate order: the filter's covariance with the forearm's noise
    /// added ([`Tracker::output_sd`]).
    pub q: [f64; N_COORDINATES],
    /// Of each torque, N·m: the markers' noise through the filter carried through the inverse
    /// dynamics linearised at the estimate (J E Jᵀ, J by central differences), times
    /// [`SD_SCALE_TAU`].
    pub tau: [f64; N_COORDINATES],
}

impl Tracker {
    /// The standard deviations of the last estimate ([`TrackerSd`]), or `None` before it
    /// started (or after a reset). A refined estimate's are the filter's times
    /// [`REFINED_SD_SCALE_Q`] (and `_TAU`): measured for the shipped
    /// refiner (it never feeds the filter back, so its error is the filter's, reduced).
    pub fn output_sd(&self) -> Option<TrackerSd> {
        let (x, p) = self.state.as_ref()?;
        let pose = self.forearm?;
        let forearm = pose.rotation.to_rotation_matrix();
        let (motion, (accel_noise, alpha_noise)) = self.forearm_motion_now();
        // Angles: the filter's covariance, which counts the hand's noise alone, plus what the
        // forearm's adds. Torques: the markers' noise (the hand's and the forearm's) through
        // the filter's gain, without the white-jerk allowance (see `SD_SCALE_TAU`).
        // (Without them — a singular matrix — the filter's own covariance, wider for torques.)
        let (forearm_noise, all_noise) = self.noise_covariances(&pose, x, p).unwrap_or((StateMatrix::zeros(), *p));
        let p_q = p + forearm_noise;
        let state_of = |x: &super::StateVector| JointState {
            q: [x[0], x[1], x[2]],
            qd: [x[3], x[4], x[5]],
            qdd: [x[6], x[7], x[8]],
        };
        let mut jacobian = nalgebra::SMatrix::<f64, N_COORDINATES, { 3 * N_COORDINATES }>::zeros();
        for k in 0..3 * N_COORDINATES {
            // A step a small share of the state's own spread (angles, velocities, accelerations
            // differ by orders of magnitude).
            let h = (p_q[(k, k)].sqrt() * 1e-3).max(1e-7);
            let (mut up, mut down) = (*x, *x);
            up[k] += h;
            down[k] -= h;
            let tau_up = reference::inverse_dynamics_moving(&self.body, &forearm, &motion, &state_of(&up)).ok()?;
            let tau_down = reference::inverse_dynamics_moving(&self.body, &forearm, &motion, &state_of(&down)).ok()?;
            for c in 0..N_COORDINATES {
                jacobian[(c, k)] = (tau_up[c] - tau_down[c]) / (2.0 * h);
            }
        }
        let mut tau_cov = jacobian * all_noise * jacobian.transpose();
        // The forearm's counted accelerations carry their own noise into the torques, linearly:
        // each axis's column is the torques' change per unit of it.
        let state = state_of(x);
        let base = reference::inverse_dynamics_moving(&self.body, &forearm, &motion, &state).ok()?;
        for (variance, alpha) in [(accel_noise, false), (alpha_noise, true)] {
            if variance <= 0.0 {
                continue;
            }
            for k in 0..3 {
                let mut nudged = motion;
                if alpha {
                    nudged.alpha[k] += 1.0
                } else {
                    nudged.accel[k] += 1.0
                }
                let tau = reference::inverse_dynamics_moving(&self.body, &forearm, &nudged, &state).ok()?;
                let column = nalgebra::Vector3::from_fn(|c, _| tau[c] - base[c]);
                tau_cov += column * column.transpose() * variance;
            }
        }
        // Just (re)started from a frame's own solution, at rest, the velocities and
        // accelerations are the filter's guesses, not yet the markers' noise through its gain:
        // until they settle the torques' σ is also at least the filter's own covariance (the
        // first rows after a restart read 0.0004-0.004 N·m while 0.003-0.1 off).
        let settling = self.state_age <= self.lost_frames();
        let tau_state = if settling { jacobian * p * jacobian.transpose() } else { nalgebra::Matrix3::zeros() };
        let (share_q, share_tau) = if self.refined { (REFINED_SD_SCALE_Q, REFINED_SD_SCALE_TAU) } else { (1.0, 1.0) };
        Some(TrackerSd {
            q: std::array::from_fn(|c| share_q * p_q[(c, c)].max(0.0).sqrt()),
            tau: std::array::from_fn(|c| {
                let noise = SD_SCALE_TAU * tau_cov[(c, c)].max(0.0).sqrt();
                share_tau * noise.max(tau_state[(c, c)].max(0.0).sqrt())
            }),
        })
    }

    /// What the markers' noise adds to the estimate `x` (posterior covariance `p`): (the
    /// forearm's beyond what the filter counts, the forearm's and the hand's). The filter
    /// predicts every hand marker through the forearm's fitted pose, so that pose's error is
    /// noise of the hand's measurement, white from frame to frame and correlated between the
    /// hand's coordinates ([`Tracker::forearm_measurement_covariance`]); the filter counts part
    /// of it, as if each coordinate's were its own ([`Tracker::forearm_variance_counted`]). White measurement noise of
    /// covariance C passes through the filter's own gain K = P Hᵀ R⁻¹ (the posterior's identity;
    /// R the variances the filter used) and at a steady state adds E = A E Aᵀ + K C Kᵀ,
    /// A = (I − K H) F: for the first, C is the forearm's covariance less what the filter
    /// counted (P holds that); for the second, the hand's noise and the forearm's whole. `None` where a matrix is
    /// singular or the sum not finite.
    fn noise_covariances(
        &self,
        pose: &Isometry3<f64>,
        x: &StateVector,
        p: &StateMatrix,
    ) -> Option<(StateMatrix, StateMatrix)> {
        let (predicted, jac) = self.hand_prediction(pose, &Vector3::new(x[0], x[1], x[2]), &[0.0; N_HAND], None)?;
        let forearm = self.forearm_measurement_covariance(pose, &predicted).unwrap_or_else(SMatrix::zeros);
        let mut h = SMatrix::<f64, N_HAND, N_STATE>::zeros();
        for m in 0..3 {
            for k in 0..3 {
                for c in 0..N_COORDINATES {
                    h[(3 * m + k, c)] = jac[m][c][k];
                }
            }
        }
        let hand = SVector::<f64, N_HAND>::from_fn(|i, _| self.noise_variance[i].max(MIN_REPORTED_NOISE.powi(2)));
        let counted = SVector::<f64, N_HAND>::from(self.forearm_variance_counted(&forearm));
        let used = hand + counted;
        let gain = p * h.transpose() * SMatrix::<f64, N_HAND, N_HAND>::from_diagonal(&used.map(|v| 1.0 / v));
        let closed = (StateMatrix::identity() - gain * h) * self.transition;
        let uncounted = forearm - SMatrix::<f64, N_HAND, N_HAND>::from_diagonal(&counted);
        let e_forearm = steady_sum(&closed, gain * uncounted * gain.transpose());
        let e_all = steady_sum(
            &closed,
            gain * (forearm + SMatrix::<f64, N_HAND, N_HAND>::from_diagonal(&hand)) * gain.transpose(),
        );
        (e_forearm.iter().chain(e_all.iter()).all(|v| v.is_finite())).then_some((e_forearm, e_all))
    }

    /// [`run`](Self::run) (or [`run_at`](Self::run_at) with `times`), handing `each` every
    /// frame's standard deviations too when `sd` ([`output_sd`](Self::output_sd) after that
    /// frame; `None` without an estimate or without `sd`: it costs several times the filter's
    /// own step).
    pub fn run_with_sd(
        &mut self,
        frames: &[f64],
        times: Option<&[f64]>,
        sd: bool,
        mut each: impl FnMut(usize, &TrackerOutput, Option<TrackerSd>, bool),
    ) -> Result<Option<usize>> {
        self.run_observed(frames, times, |tracker, i, out, estimated| {
            each(i, out, if estimated && sd { tracker.output_sd() } else { None }, estimated)
        })
    }
}

/// E = Σₙ Aⁿ Q Aⁿᵀ (n ≥ 0), the steady state of E = A E Aᵀ + Q for a stable A, summed by
/// doubling: after k steps, 2ᵏ terms ([`DOUBLINGS`]).
fn steady_sum(a: &StateMatrix, q: StateMatrix) -> StateMatrix {
    let (mut power, mut sum) = (*a, q);
    for _ in 0..DOUBLINGS {
        sum += power * sum * power.transpose();
        power = power * power;
    }
    sum
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {

    use super::*;

    use crate::reference::JointState;

    /// Share of frames (every fourth after the first second) whose angle error is within ±1 σ, with Gaussian
    /// noise of `sigma` m on the markers `markers` (frame order) only; the hand measured by its
    /// orientation alone when `relative` ([`TrackerSettings::relative_hand`](crate::tracker::TrackerSettings)).
    fn angle_coverage(markers: std::ops::Range<usize>, sigma: f64, relative: bool) -> f64 {
        use super::super::testkit::{frames, trajectory};
        use crate::body::{BodyModel, MARKER_FRAME_LEN};
        let body = BodyModel::default();
        let q = trajectory(3000, 1000.0);
        let mut f = frames(&body, &q, 0.3);
        let mut gauss = super::super::testkit::lcg_gaussian(11);
        for frame in f.chunks_exact_mut(MARKER_FRAME_LEN) {
            for v in &mut frame[markers.clone()] {
                *v += sigma * gauss();
            }
        }
        let settings =
            crate::tracker::TrackerSettings { relative_hand: relative, ..crate::tracker::TrackerSettings::new(1000.0) };
        let mut tracker = Tracker::new(body, settings).unwrap();
        let (mut covered, mut counted) = (0.0, 0.0);
        for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let out = tracker.push(frame).unwrap().unwrap();
            // Every fourth frame after the first second (σ costs more than a push).
            if i >= 1000 && i % 4 == 0 {
                let sd = tracker.output_sd().unwrap();
                for c in 0..N_COORDINATES {
                    covered += f64::from(u8::from((out.state.q[c] - q[i][c]).abs() <= sd.q[c]));
                    counted += 1.0;
                }
            }
        }
        covered / counted
    }

    #[test]
    fn the_angles_sd_counts_the_forearms_noise_as_well_as_the_hands() {
        // The filter's covariance alone covered 0.04-0.08 of frames with noise on the forearm's
        // markers only (its σ knew only the hand's); a calibrated σ covers 0.683.
        // Measured: 0.675, 0.735, 0.674; the hand measured by its orientation alone (the turn
        // about the hand markers' centroid), 0.673, 0.741, 0.703.
        for relative in [false, true] {
            for (what, markers) in [("the forearm's markers", 0..9), ("the hand's", 9..18), ("every marker", 0..18)] {
                let share = angle_coverage(markers, 1e-3, relative);
                assert!(
                    (0.6..0.78).contains(&share),
                    "relative {relative}, noise on {what}: {share} of frames within ±1 σ"
                );
            }
        }
    }

    #[test]
    fn the_sd_does_not_depend_on_where_the_labs_origin_is() {
        // The same noisy markers (MC2's noise 1 mm, the others' 0.2 mm: the hand's markers weigh
        // unequally) 1 m further along each lab axis: the same σ, the hand measured by its
        // orientation alone or not. (A turn of the forearm moves the hand markers about their
        // centroid, or the forearm's, never about a point fixed in the lab.)
        use super::super::testkit::{frames, trajectory};
        use crate::body::{BodyModel, MARKER_FRAME_LEN};
        let q = trajectory(1000, 1000.0);
        let mut f = frames(&BodyModel::default(), &q, 0.3);
        let mut gauss = super::super::testkit::lcg_gaussian(3);
        for frame in f.chunks_exact_mut(MARKER_FRAME_LEN) {
            for (i, v) in frame.iter_mut().enumerate() {
                *v += if (9..12).contains(&i) { 1e-3 } else { 2e-4 } * gauss();
            }
        }
        let moved: Vec<f64> = f.iter().enumerate().map(|(i, v)| v + 1.0 + (i % 3) as f64).collect();
        for relative in [false, true] {
            let sd = |frames: &[f64]| {
                let settings = crate::tracker::TrackerSettings {
                    relative_hand: relative,
                    ..crate::tracker::TrackerSettings::new(1000.0)
                };
                let mut tracker = Tracker::new(BodyModel::default(), settings).unwrap();
                tracker.run(frames, |_, _, _| {}).unwrap();
                tracker.output_sd().unwrap()
            };
            let (here, there) = (sd(&f), sd(&moved));
            for c in 0..N_COORDINATES {
                for (a, b) in [(here.q[c], there.q[c]), (here.tau[c], there.tau[c])] {
                    assert!((a / b - 1.0).abs() < 1e-6, "relative {relative}, coordinate {c}: {here:?} vs {there:?}");
                }
            }
        }
    }

    #[test]
    fn the_torques_sd_is_the_markers_noise_through_the_inverse_dynamics() {
        // J E Jᵀ times SD_SCALE_TAU, E the markers' noise through the filter: here J by one-sided
        // differences at steps of their own (output_sd takes central ones at a share of P).
        use super::super::testkit::{frames, trajectory};
        let q = trajectory(500, 1000.0);
        let f = frames(&crate::body::BodyModel::default(), &q, 0.3);
        let mut tracker =
            Tracker::new(crate::body::BodyModel::default(), crate::tracker::TrackerSettings::new(1000.0)).unwrap();
        tracker.run(&f, |_, _, _| {}).unwrap();
        let sd = tracker.output_sd().unwrap();
        let ((x, p), pose) = (tracker.state.unwrap(), tracker.forearm.unwrap());
        let (_, e) = tracker.noise_covariances(&pose, &x, &p).unwrap();
        let forearm = pose.rotation.to_rotation_matrix();
        let tau = |x: &StateVector| {
            let state = JointState { q: [x[0], x[1], x[2]], qd: [x[3], x[4], x[5]], qdd: [x[6], x[7], x[8]] };
            crate::reference::inverse_dynamics_at(&tracker.body, &forearm, &state).unwrap()
        };
        let at = tau(&x);
        let mut j = nalgebra::SMatrix::<f64, N_COORDINATES, N_STATE>::zeros();
        for k in 0..N_STATE {
            let h = 1e-6 * x[k].abs().max(1.0);
            let mut moved = x;
            moved[k] += h;
            let up = tau(&moved);
            for c in 0..N_COORDINATES {
                j[(c, k)] = (up[c] - at[c]) / h;
            }
        }
        let cov = j * e * j.transpose();
        for c in 0..N_COORDINATES {
            let expected = SD_SCALE_TAU * cov[(c, c)].sqrt();
            assert!(
                expected > 0.0 && (sd.tau[c] / expected - 1.0).abs() < 1e-3,
                "torque {c}: {} vs {expected}",
                sd.tau[c]
            );
        }
    }

    #[test]
    fn the_torques_sd_is_widest_on_the_first_frames_after_a_start_or_a_restart() {
        // On its first frames (velocities and accelerations guessed at rest) the filter's
        // torques are off by what the markers' noise through its gain cannot tell: that σ alone
        // read 0.006 N·m on the first frame after a gap where the steady one before read 0.027.
        // Oracle: the trajectory's true torques (its angles and their central differences
        // through the reference inverse dynamics); 1 mm noise on every marker, 0.1 s of frames
        // lost mid-movement. The first frame after the start and after the gap: σ wider than
        // the steady σ before the gap, and covering its error; every frame while settling
        // within 4 σ (measured: 3.4, at the start, where the trajectory is already moving).
        use super::super::testkit::{frames, trajectory};
        use crate::body::{BodyModel, MARKER_FRAME_LEN};
        let (rate, shoulder) = (1000.0, 0.3);
        let body = BodyModel::default();
        let q = trajectory(1400, rate);
        let mut f = frames(&body, &q, shoulder);
        let mut gauss = super::super::testkit::lcg_gaussian(21);
        for v in f.iter_mut() {
            *v += 1e-3 * gauss();
        }
        let truth = |i: usize| {
            let h = 1.0 / rate;
            let state = JointState {
                q: q[i],
                qd: std::array::from_fn(|c| (q[i + 1][c] - q[i - 1][c]) / (2.0 * h)),
                qdd: std::array::from_fn(|c| (q[i + 1][c] - 2.0 * q[i][c] + q[i - 1][c]) / (h * h)),
            };
            crate::reference::inverse_dynamics(&body, shoulder, &state).unwrap()
        };
        let mut tracker = Tracker::new(body.clone(), crate::tracker::TrackerSettings::new(rate)).unwrap();
        let settling = tracker.lost_frames();
        let (mut firsts, mut steady, mut worst) = (vec![], 0.0, 0.0_f64);
        for i in (1..1000).chain(1100..1399) {
            let frame = &f[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN];
            let out = tracker.push_at(i as f64 / rate, frame).unwrap().unwrap();
            let sd = tracker.output_sd().unwrap();
            let t = truth(i);
            if i == 999 {
                steady = sd.tau.iter().copied().fold(0.0, f64::max);
            }
            if i == 1 || i == 1100 {
                firsts.push((i, sd.tau, std::array::from_fn::<f64, 3, _>(|c| (out.tau[c] - t[c]).abs())));
            }
            if i <= settling || (1100..1100 + settling).contains(&i) {
                for c in 0..N_COORDINATES {
                    worst = worst.max((out.tau[c] - t[c]).abs() / sd.tau[c]);
                }
            }
        }
        for (i, sd, error) in firsts {
            for c in 0..N_COORDINATES {
                assert!(
                    sd[c] > 3.0 * steady && sd[c] >= error[c],
                    "frame {i}, torque {c}: σ {sd:?}, steady {steady}, error {error:?}"
                );
            }
        }
        assert!(worst < 4.0, "an error of {worst} σ while settling");
    }

    #[test]
    fn a_torque_beyond_the_subjects_limit_flags_its_frame_implausible() {
        // The same clean frames: under the subject's limit nothing is implausible; with a limit
        // below every torque (1 µN·m), every frame with an estimate is, whatever else it carries.
        use super::super::testkit::{frames, trajectory};
        use crate::body::{BodyModel, MARKER_FRAME_LEN};
        let f = frames(&BodyModel::default(), &trajectory(500, 1000.0), 0.3);
        for (limit, flagged) in [(None, false), (Some(1e-6), true)] {
            let mut tracker = Tracker::new(BodyModel::default(), crate::tracker::TrackerSettings::new(1000.0)).unwrap();
            if let Some(limit) = limit {
                tracker.torque_limit = limit;
            }
            for frame in f.chunks_exact(MARKER_FRAME_LEN) {
                let out = tracker.push(frame).unwrap().unwrap();
                assert_eq!(out.status & status::IMPLAUSIBLE != 0, flagged, "limit {limit:?}: {out:?}");
            }
        }
    }

    #[test]
    fn the_steady_sum_is_the_series_summed_term_by_term() {
        // A stable A (spectral radius below 1) and a positive Q: the doubling's 2^20 terms
        // against the series summed one term at a time until its terms vanish.
        let mut next = super::super::testkit::lcg_gaussian(5);
        let a = StateMatrix::from_fn(|_, _| 0.08 * next()) + StateMatrix::identity() * 0.5;
        let m = StateMatrix::from_fn(|_, _| next());
        let q = m * m.transpose();
        let (mut term, mut want) = (q, StateMatrix::zeros());
        for _ in 0..2000 {
            want += term;
            term = a * term * a.transpose();
        }
        assert!(term.norm() < 1e-12 * want.norm(), "the series has not converged");
        let got = steady_sum(&a, q);
        assert!((got - want).norm() < 1e-9 * want.norm(), "{got} vs {want}");
    }

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
