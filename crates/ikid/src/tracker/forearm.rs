//! The forearm's pose: fitted to its three markers, or through a marker gap from the two
//! others, its roll about the line through them filtered ([`Roll`]) from how it was seen to
//! turn while whole ([`ForearmTurn`]) and the wrist centre seen from the hand.

use nalgebra::{Isometry3, Matrix2, Matrix3, SMatrix, Translation3, UnitQuaternion, Vector3};

use super::MIN_REPORTED_NOISE;
use super::centre::{CENTRE_WEIGHT, WristCentre};
use super::checks::FOREARM_MARKERS;
use super::ekf::wrap_angle;
use super::placement::fit_points;
use super::variance::{FIT_RESIDUAL_DOF, NOISE_CLIP, PRIOR_FRAMES, THIRD_DIFFERENCE_GAIN};
use super::{HAND_START, N_HAND, Step, Tracker};
use crate::body::{self, MARKER_FRAME_LEN, Segment};
use crate::reference;
use crate::status;

/// How the forearm turns between frames, learned from its whole (three-marker) poses: the
/// second difference of its orientation (rad per frame, per frame) is its angular acceleration
/// and its markers' noise; its mean square is how far its roll about the line through two of
/// its markers may stray per frame while the third is missing (see [`Roll`]). A forearm fixed in
/// the lab teaches ~0 (its roll is then held through a gap); a real one moving, what it does.
#[derive(Debug, Clone, Copy)]
pub(super) struct ForearmTurn {
    /// The last two whole poses' frame indices and orientations, newest first.
    last: [(usize, UnitQuaternion<f64>); 2],
    /// The newest turn per frame between them (rotation vector, rad, lab frame).
    spin: Vector3<f64>,
    /// Covariance of the second difference (rad², lab frame), and how many were seen.
    variance: Matrix3<f64>,
    samples: f64,
}

/// The forearm's roll about the line through its two present markers during a marker gap: a
/// constant-rate Kalman filter whose acceleration noise is [`ForearmTurn::variance`] and whose
/// measurement is the roll the wrist centre seen from the hand gives, as uncertain as the
/// learned hand-marker noise makes that centre. Noisy hand markers on a forearm that does not
/// turn leave its roll where it was; clean ones on a moving forearm are followed.
#[derive(Debug, Clone, Copy)]
pub(super) struct Roll {
    /// Whether a gap is under way (the state below is live).
    active: bool,
    /// Roll rate about the line, rad per frame ...
    rate: f64,
    /// ... and the covariance of (roll, rate).
    p: Matrix2<f64>,
}

/// The roll filter's acceleration noise over the forearm's learned second-difference variance
/// about the line ([`ForearmTurn::about`]): a forearm's acceleration lasts longer than a frame,
/// so a white-acceleration model given the per-frame variance alone lets the roll drift too
/// little over a gap. On the real recordings (docs/realdata.md, 200 ms gaps of FAP): 1× cost
/// pyomeca 1.43× the gap-free error, 10× 1.35× (the centre followed frame by frame: 1.32×); a
/// forearm fixed in the lab teaches ~0 either way.
const ROLL_NOISE_GAIN: f64 = 10.0;

/// Smallest variance of [`ForearmTurn::variance`] about any axis, rad² (a forearm fixed in the lab still lets its roll
/// move by a hundredth of a millidegree per frame).
const MIN_TURN_VARIANCE: f64 = 1e-14;

impl ForearmTurn {
    pub(super) fn new() -> Self {
        ForearmTurn {
            last: [(usize::MAX, UnitQuaternion::identity()); 2],
            spin: Vector3::zeros(),
            variance: Matrix3::from_diagonal_element(MIN_TURN_VARIANCE),
            samples: 0.0,
        }
    }

    /// The second difference's variance about the axis `axis` (rad², at least
    /// [`MIN_TURN_VARIANCE`]): how the forearm turns about it.
    pub(super) fn about(&self, axis: &Vector3<f64>) -> f64 {
        (axis.transpose() * self.variance * axis)[0].max(MIN_TURN_VARIANCE)
    }
}

/// The forearm's markers' white noise, learned as the hand's is (`Tracker::learn_noise`): from
/// the third differences of their residual to the forearm's rigid fit, over the degrees of
/// freedom the fit leaves, one variance (m²) per coordinate. The filter takes the forearm's
/// fitted pose as exact, yet predicts every hand marker through it: that pose's error is the
/// hand measurement's noise too ([`Tracker::forearm_measurement_variance`]). Not the turn's
/// second differences ([`ForearmTurn`]): at a lab's 70–100 Hz those are the forearm's motion.
#[derive(Debug, Clone, Copy)]
pub(super) struct ForearmNoise {
    /// The last three residuals, newest first, and the frame index of the newest.
    history: [[f64; FOREARM_COORDINATES]; 3],
    len: usize,
    last: usize,
    variance: f64,
    samples: f64,
}

const FOREARM_COORDINATES: usize = 9;

impl ForearmNoise {
    pub(super) fn new() -> Self {
        ForearmNoise { history: [[0.0; FOREARM_COORDINATES]; 3], len: 0, last: usize::MAX, variance: 0.0, samples: 0.0 }
    }

    /// The noise variance per marker coordinate, m² (0 before any sample).
    pub(super) fn variance(&self) -> f64 {
        self.variance
    }

    /// [`variance`](Self::variance) once a sample taught it, `None` before.
    pub(super) fn learned(&self) -> Option<f64> {
        (self.samples > 0.0).then_some(self.variance)
    }

    /// Takes the forearm markers' residual to their rigid fit at frame `index`; frames must
    /// follow each other for a third difference (a gap starts over). `memory` is the noise's
    /// memory in frames.
    fn learn(&mut self, residual: [f64; FOREARM_COORDINATES], index: usize, memory: f64) {
        if self.last == usize::MAX || self.last + 1 != index {
            self.len = 0;
        }
        if self.len == 3 {
            let [a, b, c] = self.history;
            let sum: f64 =
                (0..FOREARM_COORDINATES).map(|i| (residual[i] - 3.0 * a[i] + 3.0 * b[i] - c[i]).powi(2)).sum();
            let sample = sum / (THIRD_DIFFERENCE_GAIN * FIT_RESIDUAL_DOF);
            // Clipped as a hand marker's sample is: one glitch teaches little. Against at least
            // the smallest noise reported, so noise that starts after a clean stretch (residuals
            // of 0 or ~1e-16 m) is still learned, within about two memory lengths.
            let clip = NOISE_CLIP * self.variance.max(MIN_REPORTED_NOISE * MIN_REPORTED_NOISE);
            let sample = if self.samples > 0.0 { sample.min(clip) } else { sample };
            let w = (1.0 / (self.samples + 1.0)).max(1.0 / memory);
            self.variance += w * (sample - self.variance);
            self.samples += 1.0;
        }
        self.history = [residual, self.history[0], self.history[1]];
        self.len = (self.len + 1).min(3);
        self.last = index;
    }
}

impl Roll {
    pub(super) fn idle() -> Self {
        Roll { active: false, rate: 0.0, p: Matrix2::zeros() }
    }
}

impl Tracker {
    /// Step 1, the forearm: measured if its markers are present, rigid as learned and not
    /// jumped (a calibration's template taken or averaged from it); which of its markers may be
    /// used otherwise.
    pub(super) fn measure_forearm(&mut self, step: &mut Step) {
        let (frame, index, lost) = (&step.frame[..], step.index, step.lost);
        // Its markers that may be used: present, and (two or three of them) rigid as learned.
        step.forearm_usable = !step.missing & FOREARM_MARKERS;
        if step.missing & FOREARM_MARKERS == 0 {
            let (rejected, relearned) = self.check_rigid(Segment::Forearm, frame, lost);
            if relearned {
                step.flags |= status::RESTARTED;
                self.templated[Segment::Forearm as usize] = false;
                self.motion.reset(); // a new shape, a new pose: no step of it is motion
            }
            if rejected == 0 && self.templating(Segment::Forearm) {
                self.take_template(Segment::Forearm, frame);
            }
            step.forearm_usable &= !rejected;
            if rejected == 0
                && let Ok(pose) = reference::fit_segment(&self.body, frame, Segment::Forearm, index)
            {
                if self.forearm_plausible(&pose, index, lost) {
                    self.forearm = Some(pose);
                    self.forearm_frame = index;
                    step.forearm_measured = true;
                    self.follow_placement(Segment::Forearm, &pose, frame);
                    self.learn_turn(&pose, index);
                    let residual = self.forearm_residual(frame, &pose);
                    let memory = self.settings.noise_memory_s * self.settings.rate_hz;
                    self.forearm_noise.learn(residual, index, memory);
                } else {
                    step.forearm_usable = 0; // the whole forearm jumped: nothing of it is used
                }
            }
            if !step.forearm_measured {
                step.flags |= status::REJECTED_MARKER;
            }
        } else if step.forearm_usable.count_ones() == 2 {
            let (rejected, _) = self.check_rigid(Segment::Forearm, frame, lost);
            if rejected != 0 {
                step.forearm_usable = 0;
                step.flags |= status::REJECTED_MARKER;
            }
        }
    }

    /// Step 1b, a forearm with one marker missing or rejected: its pose from the two others and
    /// the wrist centre (see `forearm_from_two`), if that is a pose it could have reached; held
    /// otherwise.
    pub(super) fn forearm_through_gap(&mut self, step: &mut Step) {
        let mut forearm_estimated = false;
        if !step.forearm_measured
            && step.forearm_usable.count_ones() == 2
            && self.templated[Segment::Forearm as usize] | self.calibration.is_none()
            && let Some((pose, roll)) = self.forearm_from_two(
                &step.frame,
                step.forearm_usable,
                &step.hand,
                self.centre_memo(&mut step.memo),
                step.index,
            )
            && self.forearm_plausible(&pose, step.index, step.lost)
        {
            self.forearm = Some(pose);
            self.roll = roll;
            self.forearm_frame = step.index;
            forearm_estimated = true;
        }
        if !step.forearm_measured && !forearm_estimated && self.forearm.is_some() {
            step.flags |= status::HELD;
        }
        step.forearm_seen = step.forearm_measured || forearm_estimated;
    }

    /// The forearm's pose from two of its markers (`usable`: frame-marker bits 0–2): the last
    /// pose turned as little as fits them, then rolled about the line through them by its
    /// [`Roll`] filter, which the wrist centre seen from the hand corrects when the hand's three
    /// markers are there (`hand`). Returns the pose and the roll filter's new state; `None`
    /// without a last pose or a centre to use.
    fn forearm_from_two(
        &self,
        frame: &[f64],
        usable: u8,
        hand: &[f64; N_HAND],
        centre: Option<WristCentre>,
        index: usize,
    ) -> Option<(Isometry3<f64>, Roll)> {
        let [a, b] = {
            let mut two = (0..3).filter(|k| usable & (1 << k) != 0);
            [two.next()?, two.next()?]
        };
        let offset = |k: usize| self.live[k];
        let point = |k: usize| Vector3::new(frame[3 * k], frame[3 * k + 1], frame[3 * k + 2]);
        // The fit to the two markers and the wrist centre seen from the hand, with that centre.
        let mut seen = None;
        if hand.iter().all(|v| !v.is_nan())
            && let Some(centre) = centre
        {
            let mut whole = [0.0; MARKER_FRAME_LEN];
            whole[HAND_START..].copy_from_slice(hand);
            if let Ok(hand_pose) = reference::fit_segment(&self.body, &whole, Segment::Hand, index) {
                let world = (hand_pose * nalgebra::Point3::from(centre.ch)).coords;
                // The forearm's point at the wrist depends a little on the posture: taken at the
                // last estimate's, then at the fit's own.
                let mut relative = self
                    .state
                    .as_ref()
                    .map_or(Matrix3::identity(), |(x, _)| body::wrist_rotation(&[x[0], x[1], x[2]]).into_inner());
                for _ in 0..2 {
                    let fitted = fit_points(
                        &[offset(a), offset(b), centre.forearm_point(&relative)],
                        &[point(a), point(b), world],
                        [1.0, 1.0, CENTRE_WEIGHT],
                    )?;
                    relative = (fitted.rotation.inverse() * hand_pose.rotation).to_rotation_matrix().into_inner();
                    seen = Some((fitted, world, centre));
                }
            }
        }
        let Some(last) = self.forearm else {
            return seen.map(|(pose, _, _)| (pose, Roll::idle()));
        };
        let (was, now) = (last.rotation * (offset(b) - offset(a)), point(b) - point(a));
        let turn = UnitQuaternion::rotation_between(&was, &now).unwrap_or_else(UnitQuaternion::identity);
        let held = turn * last.rotation;
        let line = nalgebra::Unit::try_new(now, 1e-9)?;
        // The roll filter: predicted at its rate, its roll noise what the forearm was seen to do.
        let mut roll = self.roll;
        if !roll.active {
            // A gap begins: rolling as the forearm last turned about this line.
            let v = self.turn.about(&line);
            roll = Roll { active: true, rate: self.turn.spin.dot(&line), p: Matrix2::new(v, 0.0, 0.0, v) };
        }
        let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
        let q = ROLL_NOISE_GAIN * self.turn.about(&line) * Matrix2::new(0.25, 0.5, 0.5, 1.0);
        let (mut angle, mut p) = (roll.rate, f * roll.p * f.transpose() + q);
        let mut rate = roll.rate;
        if let Some((fitted, world, centre)) = seen {
            // The centre's roll: the turn from the held pose to the fitted one about the line ...
            let measured = (fitted.rotation * held.inverse()).scaled_axis().dot(&line);
            // ... as uncertain as the centre seen from the hand, over its distance from the line.
            let arm = world - point(a);
            let r2 = (arm - line.into_inner() * arm.dot(&line)).norm_squared();
            let variance = (self.centre_noise_variance(&centre) / r2.max(1e-6)).max(1e-12);
            let s = p[(0, 0)] + variance;
            let gain = p.column(0) / s;
            let innovation = wrap_angle(measured - angle);
            angle += gain[0] * innovation;
            rate += gain[1] * innovation;
            p -= gain * p.row(0);
            p = (p + p.transpose()) * 0.5;
        }
        let rotation = UnitQuaternion::from_axis_angle(&line, angle) * held;
        let translation = (point(a) + point(b)) / 2.0 - rotation * ((offset(a) + offset(b)) / 2.0);
        Some((Isometry3::from_parts(Translation3::from(translation), rotation), Roll { active: true, rate, p }))
    }

    /// The forearm markers of `frame` minus where its fitted `pose` puts them, m.
    fn forearm_residual(&self, frame: &[f64], pose: &Isometry3<f64>) -> [f64; FOREARM_COORDINATES] {
        std::array::from_fn(|i| {
            let fitted = pose * nalgebra::Point3::from(Vector3::from(self.body.marker_offsets[i / 3]));
            frame[i] - fitted[i % 3]
        })
    }

    /// What the forearm's pose error adds to the hand markers' measurement noise: its
    /// covariance between the hand's coordinates, m² (`predicted`: the hand's markers where the
    /// filter expects them); `None` for a forearm measured clean. Isotropic marker noise σ²
    /// ([`ForearmNoise`]) gives a rigid fit's turn the covariance σ² (Σ sₘᵀ sₘ)⁻¹ (sₘ =
    /// [markerₘ − centroid]ₓ, the forearm's frame) and its centroid σ²/3 per axis; a hand marker
    /// moves by the turn times its lever from the centroid, and by the centroid's error, every
    /// marker alike (measuring the hand by its orientation, from the hand's own centroid: the
    /// forearm centroid's error then moves none of it).
    pub(super) fn forearm_measurement_covariance(
        &self,
        forearm: &Isometry3<f64>,
        predicted: &[Vector3<f64>; 4],
    ) -> Option<SMatrix<f64, N_HAND, N_HAND>> {
        let sigma2 = self.forearm_noise.variance();
        if sigma2 <= 0.0 {
            return None;
        }
        let offsets: [Vector3<f64>; 3] = std::array::from_fn(|m| Vector3::from(self.body.marker_offsets[m]));
        let local = (offsets[0] + offsets[1] + offsets[2]) / 3.0;
        let spread = offsets.iter().fold(Matrix3::zeros(), |acc, o| {
            let s = (o - local).cross_matrix();
            acc + s.transpose() * s
        });
        let rotation = forearm.rotation.to_rotation_matrix();
        let turn = rotation * (spread.try_inverse()? * sigma2) * rotation.transpose();
        let relative = self.relative_hand();
        let about = if relative {
            (predicted[0] + predicted[1] + predicted[2]) / 3.0
        } else {
            (forearm * nalgebra::Point3::from(local)).coords
        };
        let mut lever = SMatrix::<f64, N_HAND, 3>::zeros();
        for (m, marker) in predicted[..3].iter().enumerate() {
            let moved = -(marker - about).cross_matrix(); // δ × lever = −[lever]ₓ δ
            lever.fixed_view_mut::<3, 3>(3 * m, 0).copy_from(&moved);
        }
        let mut covariance = lever * turn * lever.transpose();
        if !relative {
            for i in 0..N_HAND {
                for j in (i % 3..N_HAND).step_by(3) {
                    covariance[(i, j)] += sigma2 / 3.0;
                }
            }
        }
        covariance.iter().all(|v| v.is_finite()).then_some(covariance)
    }

    /// What the filter adds to each hand coordinate's variance from the forearm's
    /// `covariance` ([`forearm_measurement_covariance`](Self::forearm_measurement_covariance)):
    /// the correction takes one coordinate at a time, so its diagonal; measuring the hand by its
    /// orientation, its mean, the same on each coordinate, as the hand's own noise is one
    /// variance there: weights that differ between coordinates turn skin markers' misfit into a
    /// bias of the angles (per coordinate, the exam's Gonzalez skin trials with 1 mm on every
    /// marker went 1.00–2.06× → 1.08–2.42× the EKF's error; with the mean, 1.00–2.06×).
    pub(super) fn forearm_variance_counted(&self, covariance: &SMatrix<f64, N_HAND, N_HAND>) -> [f64; N_HAND] {
        if self.relative_hand() {
            [covariance.trace() / N_HAND as f64; N_HAND]
        } else {
            std::array::from_fn(|i| covariance[(i, i)])
        }
    }

    /// Learns how the forearm turns ([`ForearmTurn`]) from its whole pose `pose` at frame `index`;
    /// its roll filter is idle again.
    fn learn_turn(&mut self, pose: &Isometry3<f64>, index: usize) {
        self.roll = Roll::idle();
        let t = &mut self.turn;
        let [(i1, r1), (i2, r2)] = t.last;
        if i1 != usize::MAX && i1 + 1 == index {
            let spin = (pose.rotation * r1.inverse()).scaled_axis();
            if i2 != usize::MAX && i2 + 2 == index {
                let previous = (r1 * r2.inverse()).scaled_axis();
                let d = spin - previous;
                // Clipped as a marker's noise sample is (`NOISE_CLIP`): one glitch teaches little.
                let clip = NOISE_CLIP * t.variance.trace();
                let d = if d.norm_squared() > clip { d * (clip / d.norm_squared()).sqrt() } else { d };
                let forget = 1.0 / (self.settings.noise_memory_s * self.settings.rate_hz);
                let w = (1.0 / (t.samples + PRIOR_FRAMES)).max(forget);
                t.variance += w * (d * d.transpose() - t.variance);
                t.samples += 1.0;
            }
            t.spin = spin;
        } else {
            t.spin = Vector3::zeros();
        }
        t.last = [(index, pose.rotation), (i1, r1)];
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {
    use super::super::testkit::*;

    use super::*;
    use crate::body::BodyModel;

    #[test]
    fn through_faps_gaps_the_roll_filter_smooths_the_centres_noise() {
        // Calibrated at 100 Hz, 0.5 mm of noise on every marker, FAP gone 300 ms of every
        // second: the forearm's roll about RSP–USP comes from the wrist centre seen from the
        // noisy hand, filtered. Measured: the angles' frame-to-frame change 2.0° RMS off the
        // truth's through the gaps; the centre's roll followed frame by frame (its filter's
        // covariance not carried over the frame), 5.1°.
        let body = BodyModel::default();
        let rate = 100.0;
        let q = trajectory(1000, rate);
        let mut f = frames(&body, &q, 0.2);
        let mut gauss = super::super::testkit::lcg_gaussian(5);
        f.iter_mut().for_each(|v| *v += 5e-4 * gauss());
        let gap: Vec<usize> = (300..900).filter(|i| i % 100 < 30).collect();
        for &i in &gap {
            f[i * MARKER_FRAME_LEN + 6..i * MARKER_FRAME_LEN + 9].fill(f64::NAN);
        }
        let (est, _, _) = track_calibrated(&f, rate);
        let steps = gap.iter().filter(|&&i| i % 100 > 0);
        let square: f64 = steps
            .clone()
            .map(|&i| (0..3).map(|c| ((est[i][c] - est[i - 1][c]) - (q[i][c] - q[i - 1][c])).powi(2)).sum::<f64>())
            .sum();
        let jitter = (square / steps.count() as f64).sqrt().to_degrees();
        assert!(jitter < 3.0, "{jitter}° RMS");
    }

    #[test]
    fn through_faps_gaps_the_roll_filter_follows_a_forearm_turning_about_the_styloids() {
        // The forearm turns about the RSP–USP line (the roll two markers leave open) by ±0.2 rad
        // at 1 Hz while FAP is gone 300 ms of every second: the roll comes from the wrist
        // centre seen from the hand, predicted at its rate between frames. Measured: 1.85° at
        // worst; with the roll's covariance not grown by its process noise, 9.7°.
        let body = BodyModel::default();
        let rate = 100.0;
        let q = trajectory(1000, rate);
        let base = body.forearm_pose(0.2);
        let (rsp, usp) = (Vector3::from(crate::body::MARKERS[0].offset), Vector3::from(crate::body::MARKERS[1].offset));
        let axis = nalgebra::Unit::new_normalize(usp - rsp);
        let mut f = Vec::with_capacity(1000 * MARKER_FRAME_LEN);
        for (i, qi) in q.iter().enumerate() {
            let turn = 0.2 * (std::f64::consts::TAU * i as f64 / rate).sin();
            let about = Isometry3::translation(rsp.x, rsp.y, rsp.z)
                * Isometry3::rotation(axis.into_inner() * turn)
                * Isometry3::translation(-rsp.x, -rsp.y, -rsp.z);
            f.extend_from_slice(&body.marker_frame(qi, &(base * about)));
        }
        for i in (300..900).filter(|i| i % 100 < 30) {
            f[i * MARKER_FRAME_LEN + 6..i * MARKER_FRAME_LEN + 9].fill(f64::NAN);
        }
        let (est, _, _) = track_calibrated(&f, rate);
        let worst = worst_turn_deg(&q[300..900], &est[300..900]);
        assert!(worst < 3.0, "{worst}° off through the gaps");
    }

    #[test]
    fn the_tracker_runs_at_100_hz_through_a_gap_of_a_forearm_marker() {
        let body = BodyModel::default();
        let q = trajectory(1000, 100.0);
        let mut f = frames(&body, &q, 0.0);
        for frame in 300..320 {
            f[frame * MARKER_FRAME_LEN] = f64::NAN; // RSP gone for 200 ms
        }
        let (est, status, tracker) = track(&f, 100.0);
        // The forearm's pose comes from its two other markers and the wrist centre: filled, not held.
        assert!(status[300..320].iter().all(|s| s & status::HELD == 0 && s & status::FILLED != 0));
        assert!(worst_deg(&q[300..], &est[300..]) < 0.5, "{}", worst_deg(&q[300..], &est[300..]));
        assert!(est.iter().flatten().all(|v| v.is_finite()));
        assert_eq!(tracker.restarts(), 0);
    }

    /// Mean squared angle error (rad², per coordinate) of `est` against `truth` from frame `from`.
    fn mse(est: &[[f64; 3]], truth: &[[f64; 3]], from: usize) -> f64 {
        let n = (est.len() - from) as f64 * 3.0;
        est[from..]
            .iter()
            .zip(&truth[from..])
            .flat_map(|(e, t)| (0..3).map(move |c| (e[c] - t[c]).powi(2)))
            .sum::<f64>()
            / n
    }

    /// The markers of `q` with Gaussian noise of `forearm_sd` and `hand_sd` (m) on each
    /// forearm and hand marker coordinate.
    fn noisy(q: &[[f64; 3]], forearm_sd: f64, hand_sd: f64, seed: u64) -> Vec<f64> {
        let mut f = frames(&BodyModel::default(), q, 0.3);
        let mut rng = crate::rng::SplitMix::new(seed);
        for (i, v) in f.iter_mut().enumerate() {
            *v += rng.normal() * if i % MARKER_FRAME_LEN < HAND_START { forearm_sd } else { hand_sd };
        }
        f
    }

    /// [`mse`] of each frame's own solution (the segments' rigid fits, `reference`) of `f`.
    fn per_frame_mse(f: &[f64], truth: &[[f64; 3]], from: usize) -> f64 {
        let mut per_frame = vec![[0.0; 3]; truth.len()];
        reference::inverse_kinematics(&BodyModel::default(), f, per_frame.as_flattened_mut()).unwrap();
        mse(&per_frame, truth, from)
    }

    #[test]
    fn a_noisy_forearm_is_averaged_as_a_noisy_hand_is_not_passed_to_the_angles() {
        // Every camera marker is noisy, the forearm's too. Here only the forearm's (1 mm): its
        // fitted pose jitters, and every hand marker predicted through it with it. The oracle is
        // each frame's own solution (the segments' rigid fits, `reference`): a filter that took
        // the forearm's pose as exact passed that jitter to the angles, and more (1.4× the
        // per-frame error, measured: its manoeuvre test took the jitter for motion); one that
        // counts it as the hand measurement's noise averages it as it does the hand's own.
        let rate = 1000.0;
        let q = trajectory(4000, rate);
        let f = noisy(&q, 1e-3, 0.0, 11);
        let (est, _, tracker) = track(&f, rate);
        let (filtered, raw) = (mse(&est, &q, 1000), per_frame_mse(&f, &q, 1000));
        assert!(filtered < 0.25 * raw, "tracker {filtered:.2e} rad² against per-frame {raw:.2e}");
        // What it counted: the forearm markers' noise, learned to within 5 % of its SD.
        let learned = tracker.forearm_noise.variance().sqrt();
        assert!((learned / 1e-3 - 1.0).abs() < 0.05, "learned {:.3} mm", 1e3 * learned);
        // The same noise on the hand alone costs no more: the forearm's is no longer the worse.
        let (hand_est, _, _) = track(&noisy(&q, 0.0, 1e-3, 11), rate);
        assert!(
            filtered < 2.0 * mse(&hand_est, &q, 1000),
            "forearm {filtered:.2e} hand {:.2e}",
            mse(&hand_est, &q, 1000)
        );
    }

    #[test]
    fn measuring_the_hand_by_its_orientation_the_noisy_forearm_is_averaged_too_and_evenly() {
        // Calibrated (the hand by its orientation, about its own centroid): the forearm's turn
        // alone moves the hand's markers, and the filter counts it as one variance for every
        // coordinate, as it does the hand's own noise.
        let rate = 1000.0;
        let q = trajectory(4000, rate);
        let f = noisy(&q, 1e-3, 0.0, 12);
        let (est, _, tracker) = track_calibrated(&f, rate);
        let (filtered, raw) = (mse(&est, &q, 1000), per_frame_mse(&f, &q, 1000));
        assert!(filtered < 0.3 * raw, "tracker {filtered:.2e} rad² against per-frame {raw:.2e}");
        let pose = tracker.forearm.unwrap();
        let predicted: [Vector3<f64>; 4] =
            std::array::from_fn(|m| Vector3::from(tracker.body.marker_offsets[3 + m.min(2)]));
        let covariance = tracker.forearm_measurement_covariance(&pose, &predicted).unwrap();
        let counted = tracker.forearm_variance_counted(&covariance);
        let mean = (0..N_HAND).map(|i| covariance[(i, i)]).sum::<f64>() / N_HAND as f64;
        assert!(counted.iter().all(|&c| (c - mean).abs() < 1e-12 * mean), "{counted:?} against {mean}");
    }

    #[test]
    fn noise_that_starts_after_a_clean_stretch_is_learned() {
        // The forearm's markers clean for 5 s, then noisy (1 mm) for 40 s, at 100 Hz with a 10-s
        // memory: the noise is learned by the end (within 10 % of its SD). Each sample is capped
        // at 25× the variance learned so far; capped against that variance alone, it never rose
        // from the clean stretch's (measured: 0.000 mm learned here).
        let rate = 100.0;
        let q = trajectory(4500, rate);
        let mut f = noisy(&q, 0.0, 0.0, 13);
        let mut gauss = super::super::testkit::lcg_gaussian(13);
        for (i, v) in f.iter_mut().enumerate().skip(500 * MARKER_FRAME_LEN) {
            if i % MARKER_FRAME_LEN < HAND_START {
                *v += 1e-3 * gauss();
            }
        }
        let (_, _, tracker) = track(&f, rate);
        let learned = tracker.forearm_noise.variance().sqrt();
        assert!((learned / 1e-3 - 1.0).abs() < 0.1, "learned {:.3} mm", 1e3 * learned);
    }

    #[test]
    fn one_glitch_of_the_forearms_turn_teaches_its_turn_little() {
        // The forearm's markers turned 10° for one frame (a glitch, not motion): each of the two
        // turn samples it makes is clipped to 25× the variance learned so far, so the learned
        // turn variance rises ~1 + 2·25·w (w = 1/memory), not by the glitch's size.
        let rate = 100.0;
        let q = trajectory(600, rate);
        let clean = noisy(&q, 2e-4, 2e-4, 14);
        let mut glitched = clean.clone();
        let at = 500 * MARKER_FRAME_LEN;
        let centroid = (0..3)
            .fold(Vector3::zeros(), |c, m| c + Vector3::from_column_slice(&clean[at + 3 * m..at + 3 * m + 3]))
            / 3.0;
        let turn = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), 10f64.to_radians());
        for m in 0..3 {
            let p = centroid + turn * (Vector3::from_column_slice(&clean[at + 3 * m..at + 3 * m + 3]) - centroid);
            glitched[at + 3 * m..at + 3 * m + 3].copy_from_slice(p.as_slice());
        }
        let upto = 503 * MARKER_FRAME_LEN;
        let (_, _, a) = track(&clean[..upto], rate);
        let (_, _, b) = track(&glitched[..upto], rate);
        let (before, after) = (a.turn.variance.trace(), b.turn.variance.trace());
        assert!(after < 1.5 * before, "turn variance {before:.3e} -> {after:.3e} rad²");
        // ... and teaches it what the cap allows: three samples of 25× (measured +15 %).
        assert!(after > 1.1 * before, "turn variance {before:.3e} -> {after:.3e} rad²");
        // And without the glitch, the noise's own: a fixed forearm's markers 0.2 mm noisy, a few
        // centimetres apart, turn it ~(0.2/50)² rad² per frame, second-differenced ×6 (measured
        // 1.9e-4). A sample over the clip grown instead of cut would feed on itself (27.9); no
        // sample taken would leave the floor (3e-14).
        assert!(1e-5 < before && before < 1e-3, "turn variance {before:.3e} rad²");
        // An average over the frames (≥ the noise memory's): six frames earlier it was the same.
        let (_, _, earlier) = track(&clean[..497 * MARKER_FRAME_LEN], rate);
        let ratio = earlier.turn.variance.trace() / before;
        assert!((ratio - 1.0).abs() < 0.05, "turn variance 6 frames apart: ratio {ratio:.3}");
    }

    #[test]
    fn one_glitch_of_a_forearm_residual_teaches_its_noise_little() {
        // Residuals 1 mm noisy learned over 2000 frames, then one residual 5 cm off: its third
        // differences make four samples, each capped at 25× the variance, so the variance rises
        // by at most 4·25·w of itself (w = 1/memory = 1e-3): 10 %, not the glitch's 2500×.
        // The same for noise of 10 µm (rigid plates), far above the smallest reported noise.
        for sigma in [1e-3, 1e-5] {
            let mut noise = ForearmNoise::new();
            let mut gauss = super::super::testkit::lcg_gaussian(21);
            let memory = 1000.0;
            for index in 0..2000 {
                noise.learn(std::array::from_fn(|_| sigma * gauss()), index, memory);
            }
            let before = noise.variance();
            let mut glitch: [f64; FOREARM_COORDINATES] = std::array::from_fn(|_| sigma * gauss());
            glitch[4] += 0.05;
            noise.learn(glitch, 2000, memory);
            for index in 2001..2004 {
                noise.learn(std::array::from_fn(|_| sigma * gauss()), index, memory);
            }
            assert!(noise.variance() < 1.11 * before, "σ {sigma}: {:.3e} -> {:.3e} m²", before, noise.variance());
        }
    }

    #[test]
    fn the_first_samples_teach_the_noise_at_once() {
        // The first sample is taken whole (nothing learned yet to cap it against), the next
        // ones as a running mean: after 20 samples the noise is already near what 2000 give.
        // Capped from the start, it would creep up from the floor (1e-18 m²) instead.
        let learn = |n: usize| {
            let mut noise = ForearmNoise::new();
            let mut gauss = super::super::testkit::lcg_gaussian(31);
            for index in 0..n {
                noise.learn(std::array::from_fn(|_| 1e-3 * gauss()), index, 1000.0);
            }
            noise.variance()
        };
        let (early, settled) = (learn(23), learn(2000));
        assert!(
            early > 0.3 * settled && early < 3.0 * settled,
            "{early:.3e} after 20 samples, {settled:.3e} after 1997"
        );
    }

    #[test]
    fn a_residual_that_changes_smoothly_is_no_noise() {
        // A forearm marker's residual that is constant, drifts, or bends (skin over bone: a
        // quadratic in time) has third differences of 0: nothing is learned as noise.
        let mut noise = ForearmNoise::new();
        for index in 0..200 {
            let t = index as f64 * 1e-2;
            noise.learn(std::array::from_fn(|i| 1e-3 * (i as f64 + 1.0) * (1.0 + t + 0.5 * t * t)), index, 100.0);
        }
        assert!(noise.variance() < 1e-20, "{:.3e} m²", noise.variance());
    }

    #[test]
    fn a_clean_forearm_adds_no_noise_to_the_hands_measurement() {
        // Noise-free forearm markers: nothing learned, nothing added (the filter follows the hand
        // exactly, as before the forearm's noise was counted).
        let q = trajectory(2000, 1000.0);
        let (est, _, tracker) = track(&noisy(&q, 0.0, 0.0, 3), 1000.0);
        assert!(tracker.forearm_noise.variance() < 1e-20, "{}", tracker.forearm_noise.variance());
        assert!(worst_deg(&q[200..], &est[200..]) < 1e-3);
    }
}
