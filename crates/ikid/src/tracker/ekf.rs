//! The filter itself: the constant-acceleration motion model, the gate on the hand markers,
//! the iterated correction by them (with the manoeuvre test), holding and restarting, and the
//! angles kept on one branch.

use nalgebra::{Isometry3, Matrix3, Vector3};

use super::centre::WristCentre;
use super::checks::{hand_markers_present, reject_hand_markers};
use super::{HandPrediction, N_HAND, StateMatrix, StateVector, Step, Tracker, TrackerSettings};
use crate::body::{self, COORDINATES, N_COORDINATES, Segment};
use crate::error::{Error, Result};
use crate::reference;
use crate::status;

/// Hand marker innovations beyond this squared Mahalanobis distance (3 dof: p ≈ 1e-6) ...
pub const GATE_CHI2: f64 = 30.0;
/// ... and longer than this, m, are rejected as implausible for one frame.
pub const GATE_FLOOR_M: f64 = 0.02;
/// Squared Mahalanobis distance of the hand markers from the prediction, per coordinate, beyond
/// which the prediction's covariance is scaled up to match it (a manoeuvre).
pub const MANOEUVRE_NIS: f64 = 3.0;
/// The correction is linearised again at the corrected state while it moves an angle by more
/// than this, rad ...
pub const RELINEARISE_RAD: f64 = 1e-3;
/// ... at most this many times in all.
pub const MAX_ITERATIONS: usize = 5;

/// The constant-acceleration motion model at `settings`' rate: per coordinate, x = (q, q̇, q̈),
/// x' = F x, with white jerk of spectral density [`TrackerSettings::jerk_noise`] over one step.
/// Returns the transition and the process noise.
pub(super) fn motion_model(settings: &TrackerSettings) -> (StateMatrix, StateMatrix) {
    let dt = 1.0 / settings.rate_hz;
    let s = settings.jerk_noise;
    // Per coordinate: x = (q, q̇, q̈), x' = F x, white jerk of density s over one step.
    let f = Matrix3::new(1.0, dt, dt * dt / 2.0, 0.0, 1.0, dt, 0.0, 0.0, 1.0);
    let (d2, d3, d4, d5) = (dt * dt, dt.powi(3), dt.powi(4), dt.powi(5));
    let q = s * Matrix3::new(d5 / 20.0, d4 / 8.0, d3 / 6.0, d4 / 8.0, d3 / 3.0, d2 / 2.0, d3 / 6.0, d2 / 2.0, dt);
    let mut transition = StateMatrix::zeros();
    let mut process_noise = StateMatrix::zeros();
    for c in 0..N_COORDINATES {
        for i in 0..3 {
            for j in 0..3 {
                transition[(3 * i + c, 3 * j + c)] = f[(i, j)];
                process_noise[(3 * i + c, 3 * j + c)] = q[(i, j)];
            }
        }
    }
    (transition, process_noise)
}

impl Tracker {
    /// Standard deviations of the filter's current estimate of q and of q̈ (rad, rad/s²);
    /// zeros before it starts.
    pub fn state_std(&self) -> ([f64; N_COORDINATES], [f64; N_COORDINATES]) {
        match &self.state {
            None => ([0.0; N_COORDINATES], [0.0; N_COORDINATES]),
            Some((_, p)) => (
                std::array::from_fn(|c| p[(c, c)].max(0.0).sqrt()),
                std::array::from_fn(|c| p[(6 + c, 6 + c)].max(0.0).sqrt()),
            ),
        }
    }

    /// The state predicted to this frame, or (before the filter started) this frame's own
    /// solution when both segments are whole (and placed): `None` without one.
    pub(super) fn predict_or_start(&self, step: &Step, forearm: &Isometry3<f64>) -> Option<(StateVector, StateMatrix)> {
        match self.state {
            Some((x, p)) => {
                Some((self.transition * x, self.transition * p * self.transition.transpose() + self.process_noise))
            }
            None => {
                let placed = self.calibration.is_none() || self.templated == [true; 2];
                let start = if step.forearm_measured && step.hand_complete && placed {
                    self.frame_solution(forearm, &step.frame, step.index)
                } else {
                    None
                };
                let x = start?;
                Some((x, self.initial_covariance()))
            }
        }
    }

    /// Step 3: gates the hand markers on the prediction, and restarts from the hand's own pose
    /// when the wrist is lost.
    pub(super) fn gate_or_restart(
        &mut self,
        step: &mut Step,
        forearm: &Isometry3<f64>,
        x: &mut StateVector,
        p: &mut StateMatrix,
    ) {
        let (index, lost) = (step.index, step.lost);
        let present = hand_markers_present(&step.hand);
        let ungated = step.hand;
        let gated = self.gate(forearm, &step.hand, x, p);
        reject_hand_markers(&mut step.hand, gated);
        if gated != 0 {
            step.flags |= status::REJECTED_MARKER;
        }
        let used = hand_markers_present(&step.hand);
        self.gated_streak = if present != 0 && used == 0 { self.gated_streak + 1 } else { 0 };
        // Every hand marker present agreeing with the hand's shape (three fitting it, or two and
        // the wrist centre), yet gated: the markers agree with one another, not with the filter
        // — the filter is what is wrong (a fast move it could not follow, a gap it coasted
        // through), so restart now rather than after `lost`, from the hand's own pose.
        let own = if step.forearm_seen && (gated != 0 || self.gated_streak >= lost) {
            let centre = if present.count_ones() == 2 { self.centre_memo(&mut step.memo) } else { None };
            self.hand_pose(forearm, &ungated, x, centre, index)
        } else {
            None
        };
        let fits = gated != 0
            && match own {
                Some(_) if present == 0b111 => self.hand_fits(&ungated, index),
                Some((_, miss)) => self.centre_memo(&mut step.memo).is_some_and(|c| miss <= c.tolerance()),
                None => false,
            };
        if (self.gated_streak >= lost || fits)
            && let Some((pose, _)) = own
        {
            (*x, *p) = (self.solution(forearm, &pose), self.initial_covariance());
            self.state_age = 0;
            step.hand = ungated;
            self.gated_streak = 0;
            self.restarts += 1;
            self.settling = lost;
            if let Some(r) = self.refiner.as_mut() {
                r.reset();
            }
        }
    }

    /// Without any hand marker to correct it, the state is carried forward at its last velocity
    /// (an acceleration nothing confirms is not extrapolated), and once that has lasted
    /// [`LOST_S`](super::LOST_S), held; and the frames after a restart or a long hold are
    /// flagged while q̇ and q̈ (so the torques) settle.
    pub(super) fn coast_or_settle(&mut self, step: &mut Step, x: &mut StateVector) {
        let lost = step.lost;
        if self.state.is_none() {
            // The filter's first frame: it starts from the frame's own solution, q̇ and q̈
            // unknown, as after a restart (a simulated trial started mid-movement: torques up to
            // 0.54 N·m off over the first 30 ms at 1 % noise, status 0 before).
            self.settling = self.settling.max(lost);
        }
        let coasted = self.coast_streak;
        self.coast_streak = if hand_markers_present(&step.hand) == 0 { self.coast_streak + 1 } else { 0 };
        if self.coast_streak == 0 && coasted >= lost {
            // Corrected again after holding: the velocities and accelerations start over.
            self.settling = self.settling.max(lost);
        }
        if self.settling > 0 {
            // A restart and the frames after it while q̇ and q̈ (so the torques) settle.
            step.flags |= status::RESTARTED;
            self.settling -= 1;
        }
        if self.coast_streak > 0 {
            step.flags |= status::HELD;
        }
        if self.coast_streak > 0
            && let Some((last, _)) = &self.state
        {
            // Carried forward without a correction: at the last velocity (an acceleration
            // nothing confirms is not extrapolated), and once that has lasted `lost`, held.
            let dt = if self.coast_streak < lost { 1.0 / self.settings.rate_hz } else { 0.0 };
            for c in 0..N_COORDINATES {
                x[c] = last[c] + dt * last[3 + c];
                x[3 + c] = if dt > 0.0 { last[3 + c] } else { 0.0 };
                x[6 + c] = 0.0;
            }
        }
        if step.missing != 0 {
            step.flags |= status::FILLED;
        }
    }

    /// Keeps the corrected state (and returns it): each angle within one turn and e_f within
    /// ±90°; a state that is not finite resets the tracker and is an error.
    pub(super) fn keep_state(
        &mut self,
        mut x: StateVector,
        mut p: StateMatrix,
        index: usize,
    ) -> Result<(StateVector, StateMatrix)> {
        // One turn is one posture: keep each angle in (−π, π] so that a restart or a long
        // gap can never leave the estimate a whole turn off; and e_f within ±90°.
        principal_branch(&mut x, &mut p);
        for c in 0..N_COORDINATES {
            x[c] = wrap_angle(x[c]);
        }
        if x.iter().any(|v| !v.is_finite()) {
            self.reset();
            let value = x.iter().find(|v| !v.is_finite()).copied().unwrap_or(f64::NAN) as f32;
            return Err(Error::NonFiniteOutput { frame: index, value });
        }
        self.state_age = if self.state.is_none() { 1 } else { self.state_age + 1 };
        self.state = Some((x, p));
        Ok((x, p))
    }

    /// Wide enough for any wrist motion: angles within ~0.1 rad of the first frame's fit,
    /// velocities to ~30 rad/s, accelerations to ~300 rad/s².
    pub(super) fn initial_covariance(&self) -> StateMatrix {
        let mut p = StateMatrix::zeros();
        for c in 0..N_COORDINATES {
            p[(c, c)] = 1e-2;
            p[(3 + c, 3 + c)] = 1e3;
            p[(6 + c, 6 + c)] = 1e5;
        }
        p
    }

    /// The state at this frame's own solution (the hand's fitted pose in the forearm's; at
    /// rest), or `None` if the hand's markers do not give one.
    fn frame_solution(&self, forearm: &Isometry3<f64>, frame: &[f64], index: usize) -> Option<StateVector> {
        let hand_pose = reference::fit_segment(&self.body, frame, Segment::Hand, index).ok()?;
        let q0 = body::wrist_angles(&(forearm.rotation.inverse() * hand_pose.rotation).to_rotation_matrix());
        let mut x = StateVector::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(&Vector3::from(q0));
        Some(x)
    }

    /// The state at the hand's pose `hand` in `forearm` (at rest).
    pub(super) fn solution(&self, forearm: &Isometry3<f64>, hand: &Isometry3<f64>) -> StateVector {
        let q0 = body::wrist_angles(&(forearm.rotation.inverse() * hand.rotation).to_rotation_matrix());
        let mut x = StateVector::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(&Vector3::from(q0));
        x
    }

    /// Hand markers (bits 0–2) whose innovation at the prediction is implausible: beyond
    /// [`GATE_CHI2`] of its predicted covariance and longer than [`GATE_FLOOR_M`].
    fn gate(&self, forearm: &Isometry3<f64>, hand: &[f64; N_HAND], x: &StateVector, p: &StateMatrix) -> u8 {
        let Some((predicted, jac)) = self.hand_prediction(forearm, &x.fixed_rows::<3>(0).into_owned(), hand, None)
        else {
            return 0;
        };
        let p_q = p.fixed_view::<3, 3>(0, 0).into_owned();
        let mut gated = 0u8;
        for m in 0..3 {
            let z = Vector3::new(hand[3 * m], hand[3 * m + 1], hand[3 * m + 2]);
            if z.iter().any(|v| v.is_nan()) {
                continue;
            }
            let nu = z - predicted[m];
            if nu.norm() <= GATE_FLOOR_M {
                continue;
            }
            let j = Matrix3::from_columns(&jac[m]);
            let r = Matrix3::from_diagonal(&Vector3::from_fn(|k, _| self.noise_variance[3 * m + k]));
            let s = j * p_q * j.transpose() + r;
            let d2 = s.try_inverse().map_or(f64::INFINITY, |inv| (nu.transpose() * inv * nu)[0]);
            // A NaN distance (a singular covariance) gates too.
            if d2.is_nan() || d2 > GATE_CHI2 {
                gated |= 1 << m;
            }
        }
        gated
    }

    /// The hand markers' predicted positions at the state `x`, and each one's Jacobian columns
    /// (its motion per radian of each coordinate). With [`TrackerSettings::relative_hand`],
    /// relative to the centroid of the markers present in `hand` (the measured centroid is
    /// taken as it is: only the hand's orientation is predicted); `None` there with fewer than
    /// two present, which carry no orientation.
    pub(super) fn hand_prediction(
        &self,
        forearm: &Isometry3<f64>,
        q: &Vector3<f64>,
        hand: &[f64; N_HAND],
        extra: Option<Vector3<f64>>,
    ) -> Option<HandPrediction> {
        // World axes of the three joints at the prediction: a point p of the hand moves by
        // w_i × (p − centre) per radian of coordinate i. The chain's product is the hand's
        // orientation in the lab (the forearm's times `body::wrist_rotation`).
        let mut rotation = forearm.rotation.to_rotation_matrix();
        let mut axes = [Vector3::zeros(); N_COORDINATES];
        for (i, axis) in axes.iter_mut().enumerate() {
            let local = Vector3::from(COORDINATES[i].axis);
            *axis = rotation * local;
            rotation *= nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(local), q[i]);
        }
        // A marker missing: the others where they sat lately (skin markers slide on the segment).
        let partial = hand_markers_present(hand) != 0b111;
        let offset = |m: usize| if partial { self.live[3 + m] } else { Vector3::from(self.body.marker_offsets[3 + m]) };
        let (centre, reference) = if self.relative_hand() {
            let present = hand_markers_present(hand);
            let n = present.count_ones();
            if n < 2 {
                return None;
            }
            let (mut measured, mut local) = (Vector3::zeros(), Vector3::zeros());
            for m in (0..3).filter(|m| present & (1 << m) != 0) {
                measured += Vector3::new(hand[3 * m], hand[3 * m + 1], hand[3 * m + 2]);
                local += offset(m);
            }
            let n = f64::from(n);
            (measured / n, local / n)
        } else {
            (forearm.translation.vector, Vector3::zeros())
        };
        let arms: [Vector3<f64>; 4] = std::array::from_fn(|m| match m {
            3 => extra.map_or(Vector3::zeros(), |e| rotation * (e - reference)),
            _ => rotation * (offset(m) - reference),
        });
        Some((arms.map(|a| centre + a), arms.map(|a| axes.map(|w| w.cross(&a)))))
    }

    /// The Kalman correction by the present hand marker coordinates, one scalar at a time (the
    /// noise is independent between coordinates), linearised at the prediction and then, while
    /// the correction moves an angle by more than [`RELINEARISE_RAD`], again at the corrected
    /// state (an iterated EKF, at most [`MAX_ITERATIONS`] times): a large correction — a fast
    /// move at a low frame rate, or near gimbal lock — is not overshot.
    pub(super) fn correct(
        &self,
        forearm: &Isometry3<f64>,
        hand: &[f64; N_HAND],
        centre: Option<WristCentre>,
        start: Option<Vector3<f64>>,
        x: &mut StateVector,
        p: &mut StateMatrix,
    ) {
        let (prior, mut prior_p) = (*x, *p);
        let mut at = start.unwrap_or(Vector3::new(x[0], x[1], x[2]));
        let mut inflated = false;
        let mut iteration = 0;
        // The manoeuvre test allows for the template's misfit (skin markers sliding with
        // the posture): a misfit the prediction cannot remove is no manoeuvre, and treating
        // it as one passed each frame's noise through to the angles and their derivatives
        // (issue #28: skin markers with 1 % noise gave torques of 11 N·m).
        let mean_noise = self.noise_variance.iter().sum::<f64>() / N_HAND as f64;
        let misfit = self.template_misfit_variance(mean_noise);
        // With the hand's three markers, the misfit is part of each marker's error in the fit
        // too: weighed by each lab coordinate's white noise alone, noise that differs between
        // the lab's axes turned the skin's misfit into a bias of the angles (issue #28's exam,
        // skin markers with 1 % noise: 0.0062 → 0.0072 rad² on the Gonzalez wrist, where the
        // per-frame fit stays at 0.0063). The misfit evens out the coordinates' weights only:
        // scaled back to the white noise's mean, the markers weigh as much against the
        // prediction as before (a misfit that slides slowly with the posture is no white noise
        // to smooth away: counted as one, the filter lagged real movement, pyomeca 0.68° →
        // 1.02°). With two markers and the wrist centre the centre's weight against the
        // markers is kept as learned.
        let evened = if centre.is_none() && misfit > 0.0 { mean_noise / (mean_noise + misfit) } else { 1.0 };
        let in_gain = if centre.is_none() { misfit } else { 0.0 };
        // The forearm's pose error moves every predicted hand marker: noise of the measurement
        // the filter must average like the hand's own (a lab's markers are all noisy: 1 mm on
        // the forearm's too passed the forearm's jitter straight to the angles, 12x the error
        // of the same noise on the hand alone). Taken at the first linearisation, as the hand's
        // own noise is counted ([`Tracker::forearm_variance_counted`]).
        let mut from_forearm: Option<[f64; N_HAND]> = None;
        while iteration < MAX_ITERATIONS {
            let Some((predicted, jac)) = self.hand_prediction(forearm, &at, hand, centre.map(|c| c.ch)) else {
                return;
            };
            let from_forearm = *from_forearm.get_or_insert_with(|| {
                self.forearm_measurement_covariance(forearm, &predicted)
                    .map_or([0.0; N_HAND], |c| self.forearm_variance_counted(&c))
            });
            // The forearm's point where the hand's centre sits, at this posture.
            let world = centre.map(|c| {
                let relative = body::wrist_rotation(&[at[0], at[1], at[2]]).into_inner();
                (forearm * nalgebra::Point3::from(c.forearm_point(&relative))).coords
            });
            let (mut xi, mut pi) = (prior, prior_p);
            let (mut nis, mut used) = (0.0, 0.0);
            for m in 0..4 {
                for k in 0..3 {
                    // The fourth: the wrist centre (the forearm's point, where the hand's would be).
                    // `tested`: the variance the manoeuvre test allows (white noise and misfit).
                    let (z, variance, tested) = match (m, world, centre) {
                        (3, Some(world), Some(c)) => (world[k], c.variance, c.variance),
                        (3, _, _) => break,
                        _ => {
                            let white = self.noise_variance[3 * m + k];
                            let f = from_forearm[3 * m + k];
                            (hand[3 * m + k], (white + in_gain) * evened + f, white + misfit + f)
                        }
                    };
                    if z.is_nan() {
                        continue;
                    }
                    // h_row · (x − at) accounts for the corrections already made, and for the
                    // linearisation point's distance from the prediction.
                    let h = [jac[m][0][k], jac[m][1][k], jac[m][2][k]];
                    let moved: f64 = (0..3).map(|i| h[i] * (xi[i] - at[i])).sum();
                    let innovation = z - predicted[m][k] - moved;
                    // ph = P hᵀ (h touches only the angles).
                    let ph: StateVector = pi.column(0) * h[0] + pi.column(1) * h[1] + pi.column(2) * h[2];
                    let s = h[0] * ph[0] + h[1] * ph[1] + h[2] * ph[2] + variance;
                    nis += innovation * innovation / (s - variance + tested);
                    used += 1.0;
                    let gain = ph / s;
                    xi += gain * innovation;
                    pi -= gain * ph.transpose();
                }
            }
            if iteration == 0 && !inflated && nis > MANOEUVRE_NIS * used {
                // The markers are further from the prediction than its covariance allows: the
                // hand moved as the motion model did not expect (an impact, a fast turn at a low
                // frame rate). Trust the prediction less, by as much as it missed.
                prior_p *= nis / used;
                inflated = true;
                continue;
            }
            // Keep P symmetric against rounding.
            *p = (pi + pi.transpose()) * 0.5;
            *x = xi;
            let step = (0..3).map(|i| (xi[i] - at[i]).abs()).fold(0.0, f64::max);
            if step.is_nan() || step <= RELINEARISE_RAD {
                return;
            }
            at = Vector3::new(xi[0], xi[1], xi[2]);
            iteration += 1;
        }
    }
}

/// Moves a state whose e_f is beyond ±90° (past gimbal lock) to the other Euler triple of the
/// same rotation, `(s_p + π, ±π − e_f, ad_ab + π)`, the one [`body::wrist_angles`] gives and
/// the one a restart starts from: e_f's velocity and acceleration change sign, the others'
/// do not (and so the covariance's e_f rows and columns).
fn principal_branch(x: &mut StateVector, p: &mut StateMatrix) {
    use std::f64::consts::{FRAC_PI_2, PI};
    let b = wrap_angle(x[1]);
    if b.abs() <= FRAC_PI_2 {
        return;
    }
    x[0] += PI;
    x[1] = PI.copysign(b) - b;
    x[2] += PI;
    for i in [4, 7] {
        x[i] = -x[i];
    }
    for i in [1, 4, 7] {
        let mut row = p.row_mut(i);
        row *= -1.0;
        let mut col = p.column_mut(i);
        col *= -1.0;
    }
}

/// Of the two Euler triples of the rotation whose angles are `solution`'s first three, moved by
/// whole turns, the one nearest the angles of `x`.
pub(super) fn nearest_triple(solution: &StateVector, x: &StateVector) -> Vector3<f64> {
    use std::f64::consts::PI;
    let near = |q: [f64; 3]| Vector3::from_fn(|i, _| x[i] + wrap_angle(q[i] - x[i]));
    let a = near([solution[0], solution[1], solution[2]]);
    let b = near([solution[0] + PI, PI - solution[1], solution[2] + PI]);
    let distance = |q: &Vector3<f64>| (0..3).map(|i| (q[i] - x[i]).powi(2)).sum::<f64>();
    if distance(&b) < distance(&a) { b } else { a }
}

/// `a` (rad) moved by whole turns into (−π, π].
pub(super) fn wrap_angle(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if a > -PI && a <= PI { a } else { a - TAU * ((a - PI) / TAU).ceil() }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {
    use super::super::testkit::*;
    use super::super::*;
    use super::*;
    use crate::body::BodyModel;

    use crate::reference::{self, JointState};

    use std::f64::consts::{PI, TAU};

    #[test]
    fn of_a_rotations_two_euler_triples_the_one_near_the_state_is_taken() {
        // Each rotation has two triples (s_p, e_f, ad_ab) and (s_p + π, π − e_f, ad_ab + π): the
        // oracle is the body's own rotation of each (`body::wrist_rotation`), the same matrix.
        // The neutral posture too: the distance is a difference of angles, never a ratio.
        for x in [[0.1, 0.2, 0.3], [-1.2, 0.7, -0.4], [2.9, -1.3, 1.0], [0.0, 0.0, 0.0]] {
            let other = [x[0] + PI, PI - x[1], x[2] + PI];
            let (r, r_other) = (body::wrist_rotation(&x), body::wrist_rotation(&other));
            assert!((r.matrix() - r_other.matrix()).norm() < 1e-12, "the premise: one rotation");
            let state = |q: [f64; 3]| StateVector::from_fn(|i, _| if i < 3 { q[i] } else { 0.0 });
            // Given the other triple, the state's own comes back, and given the state's, itself.
            for solution in [other, x] {
                let got = nearest_triple(&state(solution), &state(x));
                assert!((got - Vector3::from(x)).norm() < 1e-12, "{solution:?} -> {got:?} near {x:?}");
            }
        }
    }

    #[test]
    fn without_a_correction_the_angles_go_on_at_their_last_velocity_then_hold() {
        // Ten frames a kilometre off (all rejected): the first LOST_S of them carry the angles
        // forward at the last velocity, no acceleration extrapolated (at 70 Hz a racing wrist's
        // acceleration extrapolated over three frames ran 145° off), then hold them.
        let rate = 70.0;
        let body = BodyModel::default();
        let q = fast_trajectory(300, rate);
        let clean = frames(&body, &q, 0.2);
        let (good, _, _) = track(&clean, rate);
        let mut f = clean.clone();
        for v in &mut f[150 * MARKER_FRAME_LEN..160 * MARKER_FRAME_LEN] {
            *v += 1000.0;
        }
        let settings = TrackerSettings::new(rate);
        let mut tracker = Tracker::new(body, settings).unwrap();
        let out: Vec<TrackerOutput> =
            f.chunks_exact(MARKER_FRAME_LEN).map(|frame| tracker.push(frame).unwrap().unwrap()).collect();
        // LOST_S at 70 Hz: ceil(0.03 s × 70 Hz = 2.1) = 3 frames.
        let lost = 3;
        assert_eq!(tracker.lost_frames(), lost);
        let last = out[149].state;
        for (k, o) in out[150..160].iter().enumerate() {
            assert!(o.status & status::HELD != 0);
            assert_eq!(o.state.qdd, [0.0; 3], "frame {}", 150 + k);
            let moving = k + 1 < lost;
            for c in 0..3 {
                let expected = if moving { last.qd[c] } else { 0.0 };
                assert_eq!(o.state.qd[c], expected, "frame {} coordinate {c}", 150 + k);
                let steps = (k + 1).min(lost - 1) as f64;
                assert!((o.state.q[c] - (last.q[c] + steps * last.qd[c] / rate)).abs() < 1e-12, "frame {}", 150 + k);
            }
        }
        // Back on the clean run's estimate within 100 ms.
        let after = worst_deg(&good[167..], &out[167..].iter().map(|o| o.state.q).collect::<Vec<_>>());
        assert!(after < 0.1, "{after}° off the clean run");
        // The hand's markers alone gone (the forearm seen): held and flagged all the same, and
        // only those frames.
        let mut f = clean.clone();
        for frame in 150..160 {
            f[frame * MARKER_FRAME_LEN + HAND_START..(frame + 1) * MARKER_FRAME_LEN].fill(f64::NAN);
        }
        let (_, status, _) = track(&f, rate);
        assert!(status[150..160].iter().all(|s| s & status::HELD != 0), "{:?}", &status[150..160]);
        assert!(status[140..150].iter().chain(&status[170..]).all(|s| s & status::HELD == 0));
    }

    #[test]
    fn the_motion_model_is_white_jerk_integrated_over_one_step() {
        // Per coordinate, a jerk impulse τ before the step's end leaves g(τ) = (τ²/2, τ, 1) in
        // (q, q̇, q̈): Q = s ∫₀^dt g gᵀ dτ, here by the midpoint rule over 10⁴ slices; and the
        // transition is exp(A dt) for A the chain q̈ → q̇ → q.
        let (rate, s) = (50.0, 3.0);
        let settings = TrackerSettings { jerk_noise: s, ..TrackerSettings::new(rate) };
        let (transition, process_noise) = motion_model(&settings);
        let (dt, n) = (1.0 / rate, 10_000);
        let mut expected = nalgebra::Matrix3::zeros();
        for k in 0..n {
            let t = (k as f64 + 0.5) * dt / n as f64;
            let g = nalgebra::Vector3::new(t * t / 2.0, t, 1.0);
            expected += g * g.transpose() * (s * dt / n as f64);
        }
        let a = nalgebra::Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0) * dt;
        let exp = nalgebra::Matrix3::identity() + a + a * a / 2.0; // A³ = 0
        for c in 0..N_COORDINATES {
            for i in 0..3 {
                for j in 0..3 {
                    let (got, want) = (process_noise[(3 * i + c, 3 * j + c)], expected[(i, j)]);
                    assert!((got - want).abs() <= 1e-6 * want.abs(), "Q[{i}][{j}] = {got:e}, expected {want:e}");
                    assert_eq!(transition[(3 * i + c, 3 * j + c)], exp[(i, j)], "F[{i}][{j}]");
                }
            }
        }
    }

    #[test]
    fn lost_s_is_counted_in_frames_at_the_trackers_rate_and_at_least_three() {
        // LOST_S = 30 ms: 1.5 frames at 50 Hz (held to 3), 4.5 at 150 Hz (5), 30 at 1 kHz.
        for (rate, frames) in [(50.0, 3), (150.0, 5), (1000.0, 30)] {
            let settings = TrackerSettings::new(rate);
            let tracker = Tracker::new(BodyModel::default(), settings).unwrap();
            assert_eq!(tracker.lost_frames(), frames, "{rate} Hz");
        }
    }

    #[test]
    fn a_lost_hand_is_restarted_from_its_own_solution_and_flagged() {
        // The hand jumps by 60° of flexion for good (a relabelling, or a tracker thrown off): the
        // gate rejects it at first, then the tracker restarts on the new posture.
        let body = BodyModel::default();
        let mut q = trajectory(1000, 1000.0);
        for qi in &mut q[400..] {
            qi[1] += 60f64.to_radians();
        }
        let f = frames(&body, &q, 0.0);
        let (est, status, tracker) = track(&f, 1000.0);
        assert_eq!(tracker.restarts(), 1);
        let restart = first_restart(&status, &tracker).unwrap();
        // At once: the three markers fit the hand's shape, so the filter is what is wrong (not
        // after LOST_S of gated frames, 30 here).
        assert_eq!(restart, 400);
        assert!(worst_deg(&q[restart + 50..], &est[restart + 50..]) < 0.05);
    }

    #[test]
    fn the_filters_first_frames_are_flagged_restarted_while_its_velocities_settle() {
        // Started on a moving wrist, the filter knows its angles and not yet q̇ and q̈ (so not the
        // torques): its first LOST_S, 30 frames at 1 kHz, are flagged as after a restart; none after.
        let body = BodyModel::default();
        let q = trajectory(300, 1000.0);
        let (_, status, tracker) = track(&frames(&body, &q, 0.0), 1000.0);
        assert!(status[..30].iter().all(|s| s & status::RESTARTED != 0), "{:?}", &status[..31]);
        assert!(status[30..].iter().all(|s| s & status::RESTARTED == 0), "{:?}", &status[28..40]);
        assert_eq!(tracker.restarts(), 0, "a start is not a restart of a lost wrist");
    }

    #[test]
    fn a_lost_hand_whose_markers_miss_its_shape_restarts_after_lost_s() {
        // The same jump, and MCB 2 cm off from it on: the three markers no longer fit the hand's
        // shape (5 mm), so nothing says at once that the filter is wrong; it restarts once every
        // hand marker has been gated for LOST_S (30 frames at 1 kHz): on frame 429.
        let body = BodyModel::default();
        let mut q = trajectory(1000, 1000.0);
        for qi in &mut q[400..] {
            qi[1] += 60f64.to_radians();
        }
        let mut f = frames(&body, &q, 0.0);
        for i in 400..1000 {
            f[i * MARKER_FRAME_LEN + 15] += 0.02;
        }
        let (_, status, tracker) = track(&f, 1000.0);
        assert_eq!(tracker.restarts(), 1);
        assert_eq!(first_restart(&status, &tracker), Some(429));
    }

    #[test]
    fn each_hand_marker_coordinate_is_gated_against_its_own_learned_noise() {
        // The learned noise: σ 1 mm for every hand marker coordinate but MC5's x, 5 cm. With a
        // certain state (P = 0) a marker's distance is Σ (ν_k / σ_k)² over its coordinates.
        let body = BodyModel::default();
        let forearm = body.forearm_pose(0.2);
        let q = [0.3, -0.2, 0.1];
        let frame = body.marker_frame(&q, &forearm);
        let at_rest: [f64; N_HAND] = std::array::from_fn(|i| frame[HAND_START + i]);
        let mut tracker = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
        tracker.noise_variance = [1e-6; N_HAND];
        tracker.noise_variance[3] = 0.05 * 0.05;
        let mut x = StateVector::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(&Vector3::from(q));
        let p = StateMatrix::zeros();
        assert_eq!(tracker.gate(&forearm, &at_rest, &x, &p), 0);
        // Every marker 3 cm off along one axis (beyond the 2 cm floor): along x, MC5's distance
        // is (0.03 / 0.05)² = 0.36 and the others' (0.03 / 0.001)² = 900, against GATE_CHI2 = 30;
        // along y, every one's is 900.
        for (axis, expected) in [(0, 0b101), (1, 0b111)] {
            let mut hand = at_rest;
            for m in 0..3 {
                hand[3 * m + axis] += 0.03;
            }
            assert_eq!(tracker.gate(&forearm, &hand, &x, &p), expected, "3 cm along axis {axis}");
        }
    }

    #[test]
    fn with_two_markers_and_the_centre_a_template_misfit_leaves_the_markers_weight_as_learned() {
        // MC5 missing: MC2, MCB and the wrist centre correct the state. A skin template's misfit
        // only widens what the manoeuvre test allows (no manoeuvre here either way): the state
        // and covariance after the correction are those of a template that fits, to the bit.
        let body = BodyModel::default();
        let forearm = body.forearm_pose(0.2);
        let q = [0.3, -0.2, 0.1];
        let frame = body.marker_frame(&q, &forearm);
        let mut hand: [f64; N_HAND] = std::array::from_fn(|i| frame[HAND_START + i] + 1e-3 * (i as f64).sin());
        hand[3..6].fill(f64::NAN);
        let settings = TrackerSettings { relative_hand: true, ..TrackerSettings::new(1000.0) };
        let mut tracker = Tracker::new(body, settings).unwrap();
        tracker.noise_variance = [1e-6; N_HAND];
        let mut x0 = StateVector::zeros();
        x0.fixed_rows_mut::<3>(0).copy_from(&Vector3::new(q[0] + 0.01, q[1] - 0.02, q[2] + 0.01));
        let p0 = tracker.initial_covariance();
        let corrected = |tracker: &Tracker| {
            let (mut x, mut p) = (x0, p0);
            tracker.correct(&forearm, &hand, Some(WristCentre::origins()), None, &mut x, &mut p);
            (x, p)
        };
        let fits = corrected(&tracker);
        assert_ne!(fits.0, x0, "no correction");
        (tracker.fit_residual_ms, tracker.fit_residual_samples) = (1e-4, 100.0);
        assert!(tracker.template_misfit_variance(1e-6) > 1e-5);
        assert_eq!(corrected(&tracker), fits);
    }

    #[test]
    fn a_large_correction_is_relinearised_until_it_lands_on_the_markers() {
        // A prior 0.2-0.4 rad off and exact hand markers far more certain than it: one
        // linearisation at the prior lands where its tangent says, off by the curvature; the
        // iterated correction goes on from there until a step is under RELINEARISE_RAD.
        let body = BodyModel::default();
        let forearm = body.forearm_pose(0.2);
        let q = [0.3, -0.2, 0.1];
        let frame = body.marker_frame(&q, &forearm);
        let hand: [f64; N_HAND] = std::array::from_fn(|i| frame[HAND_START + i]);
        let mut tracker = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
        tracker.noise_variance = [1e-12; N_HAND];
        let mut x = StateVector::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(&Vector3::new(q[0] - 0.3, q[1] + 0.4, q[2] - 0.2));
        let mut p = tracker.initial_covariance() * 100.0;
        tracker.correct(&forearm, &hand, None, None, &mut x, &mut p);
        let off = (0..3).map(|c| (x[c] - q[c]).abs()).fold(0.0, f64::max);
        assert!(off < 2e-3, "{off} rad from the markers' angles after the correction");
    }

    #[test]
    fn the_initial_covariance_is_as_wide_as_documented_and_uncorrelated() {
        // Standard deviations 0.1 rad, ~30 rad/s and ~300 rad/s² for every coordinate, nothing
        // correlated (a velocity or acceleration known a priori would slow the start).
        let tracker = Tracker::new(BodyModel::default(), TrackerSettings::new(1000.0)).unwrap();
        let p = tracker.initial_covariance();
        for i in 0..N_STATE {
            for j in 0..N_STATE {
                let want = if i != j { 0.0 } else { [0.1f64, 1e3f64.sqrt(), 1e5f64.sqrt()][i / 3].powi(2) };
                assert!((p[(i, j)] - want).abs() <= 1e-9 * want, "P[{i}][{j}] = {}", p[(i, j)]);
            }
        }
    }

    #[test]
    fn past_gimbal_lock_the_state_moves_to_the_other_triple_of_the_same_rotation() {
        // e_f beyond ±90° (either side, and a whole turn off): the rotation stays, e_f comes
        // within ±90°, e_f's velocity and acceleration change sign and the covariance's e_f
        // rows and columns with them (P' = D P D, D = diag(±1)); within ±90° nothing moves.
        let p: StateMatrix = StateMatrix::from_fn(|i, j| 1.0 + (i * N_STATE + j) as f64 + (i + j) as f64);
        let p = p + p.transpose();
        let flip = StateMatrix::from_diagonal(&StateVector::from_fn(|i, _| if i % 3 == 1 { -1.0 } else { 1.0 }));
        for e_f in [2.0, -2.5, 2.0 + TAU, 0.5] {
            let mut x = StateVector::from_fn(|i, _| 0.1 * (i + 1) as f64);
            x[1] = e_f;
            let (before, p_before) = (x, p);
            let mut p = p;
            principal_branch(&mut x, &mut p);
            let turn = body::wrist_rotation(&[before[0], before[1], before[2]])
                .angle_to(&body::wrist_rotation(&[x[0], x[1], x[2]]));
            assert!(turn < 1e-12, "e_f {e_f}: the rotation turned by {turn} rad");
            if wrap_angle(e_f).abs() <= PI / 2.0 {
                assert_eq!((x, p), (before, p_before), "e_f {e_f}");
                continue;
            }
            assert!(x[1].abs() <= PI / 2.0, "e_f {e_f} → {}", x[1]);
            for i in 3..N_STATE {
                let sign = if i % 3 == 1 { -1.0 } else { 1.0 };
                assert_eq!(x[i], sign * before[i], "e_f {e_f}: state {i}");
            }
            assert_eq!(p, flip * p_before * flip, "e_f {e_f}");
        }
    }

    #[test]
    fn angles_stay_within_one_turn() {
        for (a, wrapped) in [(3.5, 3.5 - TAU), (-3.5, TAU - 3.5), (PI, PI), (-PI, PI), (7.0 * PI, PI), (0.3, 0.3)] {
            assert!((wrap_angle(a) - wrapped).abs() < 1e-12, "{a}");
        }
        // A pronation past ±180° (absurd, but what a lost filter reports) comes back as the
        // same posture, never a whole turn off.
        assert!(status::angle_implausible(0, wrap_angle(4.0)));
    }

    #[test]
    fn clean_markers_are_followed_closely_with_derivatives() {
        let body = BodyModel::default();
        let q = trajectory(3000, 1000.0);
        let f = frames(&body, &q, 0.3);
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        let mut last = None;
        for frame in f.chunks_exact(MARKER_FRAME_LEN) {
            last = tracker.push(frame).unwrap();
        }
        let out = last.unwrap();
        let t: f64 = 2.999;
        let truth_qd = [0.6 * 1.3 * (1.3 * t).cos(), -0.5 * 0.9 * (0.9 * t + 0.4).cos(), -0.2 * 1.7 * (1.7 * t).sin()];
        for c in 0..3 {
            assert!((out.state.q[c] - q[2999][c]).abs() < 1e-5, "q {c}: {} vs {}", out.state.q[c], q[2999][c]);
            assert!((out.state.qd[c] - truth_qd[c]).abs() < 1e-2, "qd {c}: {} vs {}", out.state.qd[c], truth_qd[c]);
        }
        assert_eq!(out.missing, 0);
        // Torques equal Newton–Euler at the true state, up to the state's error.
        let truth = JointState { q: q[2999], qd: truth_qd, qdd: out.state.qdd };
        let tau = reference::inverse_dynamics(&body, 0.3, &truth).unwrap();
        for c in 0..3 {
            assert!((out.tau[c] - tau[c]).abs() < 1e-4, "tau {c}: {} vs {}", out.tau[c], tau[c]);
        }
    }

    #[test]
    fn missing_markers_correct_nothing_and_are_reported() {
        let body = BodyModel::default();
        let q = trajectory(2000, 1000.0);
        let mut f = frames(&body, &q, 0.0);
        // MC5 (marker 4) missing from frame 1000 to 1199, the forearm's FAP (marker 2) at 1500.
        for i in 1000..1200 {
            f[i * MARKER_FRAME_LEN + 12..i * MARKER_FRAME_LEN + 15].fill(f64::NAN);
        }
        f[1500 * MARKER_FRAME_LEN + 6] = f64::NAN;
        let mut tracker = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
        for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let out = tracker.push(frame).unwrap().unwrap();
            let expect = if (1000..1200).contains(&i) {
                1 << 4
            } else if i == 1500 {
                1 << 2
            } else {
                0
            };
            assert_eq!(out.missing, expect, "frame {i}");
            for c in 0..3 {
                // Two hand markers and the wrist centre still fix the hand: no loss on clean data.
                let error = (out.state.q[c] - q[i][c]).abs();
                assert!(i < 200 || error < 1e-5, "frame {i} coordinate {c}: {error}");
            }
        }
    }

    #[test]
    fn the_filter_starts_open_to_any_velocity_and_acceleration() {
        // Started mid-movement (every coordinate turning at 1–2 rad/s): the documented initial
        // uncertainty (velocities to ~30 rad/s, accelerations to ~300 rad/s²) lets the filter
        // find the velocity within 20 ms on clean markers; the accelerations' uncertainty is
        // untouched by the first frame (markers see angles only): √1e5 rad/s².
        let body = BodyModel::default();
        let v = [1.5, -1.0, 2.0];
        let q: Vec<[f64; 3]> = (0..40).map(|i| std::array::from_fn(|c| 0.1 + v[c] * i as f64 * 1e-3)).collect();
        let f = frames(&body, &q, 0.2);
        let mut tracker = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
        tracker.push(&f[..MARKER_FRAME_LEN]).unwrap().unwrap();
        assert_eq!(tracker.state_std().1, [1e5f64.sqrt(); 3]);
        let mut last = None;
        for frame in f.chunks_exact(MARKER_FRAME_LEN).skip(1).take(20) {
            last = tracker.push(frame).unwrap();
        }
        let qd = last.unwrap().state.qd;
        for c in 0..3 {
            assert!((qd[c] - v[c]).abs() < 0.05, "coordinate {c}: {} vs {}", qd[c], v[c]);
        }
    }

    #[test]
    fn a_skin_template_misfit_is_no_manoeuvre_and_noise_stays_out_of_the_accelerations() {
        // Skin hand markers sliding up to 8 mm with the posture (smoothly: the template taken at
        // the start misses them later), with 1 % white noise on top. Treated as a manoeuvre, the
        // misfit let each frame's noise through to the angles: accelerations of thousands of
        // rad/s² (torques of 11 N·m on the exam's skin trials, issue #28).
        let rate = 1000.0;
        let q = trajectory(8000, rate);
        let mut f = Vec::with_capacity(q.len() * body::MARKER_FRAME_LEN);
        for qi in &q {
            let mut shift = [0.0; body::MARKER_FRAME_LEN];
            for m in 3..6 {
                let k = m as f64;
                shift[3 * m] = 0.008 * (2.0 * qi[0] + k).sin();
                shift[3 * m + 1] = 0.006 * (1.5 * qi[1] - k).cos();
                shift[3 * m + 2] = 0.008 * (3.0 * qi[2] + 0.5 * k).sin();
            }
            let mut body = BodyModel::default();
            body.shift_markers(&shift).unwrap();
            f.extend(body.marker_frames(qi, 0.0).unwrap());
        }
        crate::noise::uniform_range(&mut f, 0.01, 5).unwrap();
        let settings = TrackerSettings::new(rate);
        let mut tracker = Tracker::new(BodyModel::default(), settings).unwrap();
        tracker.set_calibration(Some(crate::calibration::Calibration::body_model()));
        let (mut se, mut n) = (0.0, 0.0);
        tracker
            .run(&f, |i, o, _| {
                if i >= 2000 {
                    let t = i as f64 / rate;
                    let truth = [
                        -0.6 * 1.69 * (1.3 * t).sin(),
                        0.5 * 0.81 * (0.9 * t + 0.4).sin(),
                        -0.2 * 2.89 * (1.7 * t).cos(),
                    ];
                    for c in 0..3 {
                        se += (o.state.qdd[c] - truth[c]).powi(2);
                        n += 1.0;
                    }
                }
            })
            .unwrap();
        // 5 rad/s² here; 15,000 with the misfit taken for a manoeuvre.
        let rms = (se / n).sqrt();
        assert!(rms < 50.0, "angular acceleration error {rms:.1} rad/s² RMS");
    }
}
