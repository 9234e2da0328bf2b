//! The wrist's centre of rotation: the body model's (both segments' origin), or, calibrated,
//! learned from the subject's own frames ([`JointCentre`], a functional joint centre that
//! moves with the posture); and the hand's pose from two of its markers and that centre.

use nalgebra::{Isometry3, Matrix3, SMatrix, SVector, Vector3};

use super::checks::{FIT_TOLERANCE_M, hand_markers_present};
use super::ekf::nearest_triple;
use super::placement::fit_points;
use super::{HAND_START, N_HAND, StateVector, Step, Tracker};
use crate::body::{self, MARKER_FRAME_LEN, Segment};
use crate::reference;

/// How long the wrist's centre of rotation is remembered, s (exponential forgetting): the
/// functional joint centre (`JointCentre`) is learned from the frames with both segments whole.
pub const CENTRE_MEMORY_S: f64 = 30.0;
/// Frames with both segments whole needed before the learned centre is used, s (at least 10 frames).
pub const CENTRE_MIN_S: f64 = 0.5;
/// Smallest standard deviation the learned centre is given, m (its residual floor).
pub const CENTRE_MIN_STD_M: f64 = 1e-3;
/// Weight of the wrist centre beside each of a segment's two markers when the segment's pose is
/// fitted to them and it (a marker gap): the markers fix what they can, the centre the turn
/// about the line through them.
pub const CENTRE_WEIGHT: f64 = 0.01;

impl Tracker {
    /// The wrist's centre of rotation `(c_f, c_h, variance)`: in the forearm's and the hand's
    /// frames, and its uncertainty per coordinate (m²). Uncalibrated, the body model's (both
    /// segments' origin); calibrated, the one learned ([`JointCentre`]), once it has seen
    /// [`CENTRE_MIN_S`] of frames.
    fn wrist_centre(&self) -> Option<WristCentre> {
        if self.calibration.is_none() {
            return Some(WristCentre::origins());
        }
        if self.templated != [true; 2] {
            return None;
        }
        let min_frames = ((CENTRE_MIN_S * self.settings.rate_hz).ceil() as usize).max(10);
        self.centre.solve(min_frames)
    }

    /// The wrist centre, solved at most once a frame (`memo`: `None` until solved).
    pub(super) fn centre_memo(&self, memo: &mut Option<Option<WristCentre>>) -> Option<WristCentre> {
        *memo.get_or_insert_with(|| self.wrist_centre())
    }

    /// The variance per coordinate of the wrist centre as the rigid fit of the hand's three
    /// markers puts it (m²): the learned hand-marker noise, carried by the fit (its position
    /// is their mean; its turn, over their spread, moves the centre by its distance from them),
    /// plus the learned centre's own.
    pub(super) fn centre_noise_variance(&self, centre: &WristCentre) -> f64 {
        let noise = self.noise_variance.iter().sum::<f64>() / N_HAND as f64;
        let mean = (self.live[3] + self.live[4] + self.live[5]) / 3.0;
        let spread: f64 = (3..6).map(|k| (self.live[k] - mean).norm_squared()).sum();
        let lever = (centre.ch - mean).norm_squared();
        noise * (1.0 / 3.0 + lever / spread.max(1e-6)) + centre.variance
    }

    /// The hand's pose from its markers in `hand` (NaN where missing): fitted to its three, or
    /// to two and the wrist centre (fixed in `forearm`) for the turn about the line through
    /// them; with how far the hand then puts the centre from the forearm's (0 with three).
    pub(super) fn hand_pose(
        &self,
        forearm: &Isometry3<f64>,
        hand: &[f64; N_HAND],
        near: &StateVector,
        centre: Option<WristCentre>,
        index: usize,
    ) -> Option<(Isometry3<f64>, f64)> {
        let present = hand_markers_present(hand);
        if present == 0b111 {
            let mut whole = [0.0; MARKER_FRAME_LEN];
            whole[HAND_START..].copy_from_slice(hand);
            return reference::fit_segment(&self.body, &whole, Segment::Hand, index).ok().map(|pose| (pose, 0.0));
        }
        if present.count_ones() != 2 {
            return None;
        }
        let centre = centre?;
        let [a, b] = {
            let mut two = (0..3).filter(|m| present & (1 << m) != 0);
            [two.next()?, two.next()?]
        };
        let offset = |m: usize| self.live[3 + m];
        let point = |m: usize| Vector3::new(hand[3 * m], hand[3 * m + 1], hand[3 * m + 2]);
        // The forearm's point at the wrist at the posture `near`, then at the fit's own.
        let mut relative = body::wrist_rotation(&[near[0], near[1], near[2]]).into_inner();
        let mut fit = None;
        for _ in 0..2 {
            let world = (forearm * nalgebra::Point3::from(centre.forearm_point(&relative))).coords;
            let pose = fit_points(
                &[offset(a), offset(b), centre.ch],
                &[point(a), point(b), world],
                [1.0, 1.0, CENTRE_WEIGHT],
            )?;
            let miss = ((pose * nalgebra::Point3::from(centre.ch)).coords - world).norm();
            relative = (forearm.rotation.inverse() * pose.rotation).to_rotation_matrix().into_inner();
            fit = Some((pose, miss));
        }
        fit
    }

    /// The hand's own pose, from its three markers or two and the wrist centre (`None` unless
    /// the forearm was seen): with three, each marker's recent place follows it, and with both
    /// segments whole (calibrated) it is a frame for the wrist centre. Returns the centre the
    /// correction uses (with two markers measured relative to each other) and the Euler triple
    /// of the hand's pose nearest the state `x`, where the correction is linearised first.
    pub(super) fn learn_from_hand(
        &mut self,
        step: &mut Step,
        forearm: &Isometry3<f64>,
        x: &StateVector,
    ) -> (Option<WristCentre>, Option<Vector3<f64>>) {
        let used = hand_markers_present(&step.hand);
        // Two hand markers measured relative to each other leave the hand's turn about the line
        // through them open: the wrist centre, fixed in the forearm, closes it.
        let centre = if used.count_ones() == 2 { self.centre_memo(&mut step.memo) } else { None };
        // The hand's own pose, from its three markers or two and the centre.
        let pose = if step.forearm_seen { self.hand_pose(forearm, &step.hand, x, centre, step.index) } else { None };
        if let Some((whole, _)) = pose
            && used == 0b111
        {
            let mut markers = [0.0; MARKER_FRAME_LEN];
            markers[HAND_START..].copy_from_slice(&step.hand);
            self.follow_placement(Segment::Hand, &whole, &markers);
            if step.forearm_measured && self.calibration.is_some() && self.templated == [true; 2] {
                // Both segments whole and agreeing with the filter: a frame for the wrist centre.
                let forget = 1.0 / (CENTRE_MEMORY_S * self.settings.rate_hz);
                self.centre.add(forearm, &whole, forget);
            }
        }
        // Linearise first at the hand's own solution (the Euler triple nearest the prediction):
        // near gimbal lock the prediction can be far off in angles while near in rotation, and
        // the iterations then start in the right place.
        let start = pose.map(|(pose, _)| nearest_triple(&self.solution(forearm, &pose), x));
        let centre = if self.relative_hand() { centre } else { None };
        (centre, start)
    }
}

/// The wrist's centre of rotation learned from the subject's own frames (a functional joint
/// centre, as SCoRE): the point `c_f` fixed in the forearm and `c_h` fixed in the hand that stay
/// together, `R_f c_f + t_f = R_h c_h + t_h`, by least squares over the frames where both
/// segments' poses were measured whole (exponential forgetting over [`CENTRE_MEMORY_S`]), pulled
/// weakly towards the point midway between the two segments' origins of the first such frame
/// (what rotations about one axis leave undetermined). Fixed-size: no allocation.
#[derive(Debug, Clone, Copy)]
pub(super) struct JointCentre {
    normal: SMatrix<f64, 6, 6>,
    rhs: SVector<f64, 6>,
    /// Sum of |t_h − t_f|² (weighted), for the residual.
    bb: f64,
    weight: f64,
    frames: usize,
    prior: SVector<f64, 6>,
    /// The hand's origin in the forearm's frame regressed on the hand's rotation there
    /// ([`posture_features`]): Σ x xᵀ and Σ x pᵀ (weighted).
    xx: SMatrix<f64, POSTURE_FEATURES, POSTURE_FEATURES>,
    xp: SMatrix<f64, POSTURE_FEATURES, 3>,
    /// The last frames' hand rotation in the forearm and hand origin there, newest first.
    recent: [(Matrix3<f64>, Vector3<f64>); RECENT_FRAMES],
}

/// Frames the centre's recent miss is averaged over.
const RECENT_FRAMES: usize = 5;

/// Values [`posture_features`] gives.
const POSTURE_FEATURES: usize = 10;

/// What the wrist centre's posture dependence is regressed on: 1 and the entries of the hand's
/// rotation `r` in the forearm (row by row).
fn posture_features(r: &Matrix3<f64>) -> SVector<f64, POSTURE_FEATURES> {
    SVector::<f64, POSTURE_FEATURES>::from_fn(|i, _| if i == 0 { 1.0 } else { r[((i - 1) / 3, (i - 1) % 3)] })
}

/// Ridge of the posture-dependent centre towards the fixed one, per unit weight of frames.
pub const POSTURE_RIDGE: f64 = 1e-2;

/// The wrist's centre as learned: `c_f` fixed in the forearm and `c_h` fixed in the hand, the
/// variance of its residual per coordinate (m²), and how the forearm's point moves with the
/// posture (a real wrist is no ball joint: the fixed centre leaves 2–4 mm).
#[derive(Debug, Clone, Copy)]
pub(super) struct WristCentre {
    pub(super) cf: Vector3<f64>,
    pub(super) ch: Vector3<f64>,
    pub(super) variance: f64,
    pub(super) shift: SMatrix<f64, POSTURE_FEATURES, 3>,
}

impl WristCentre {
    /// The body model's own: both segments' origins.
    pub(super) fn origins() -> Self {
        WristCentre {
            cf: Vector3::zeros(),
            ch: Vector3::zeros(),
            variance: CENTRE_MIN_STD_M * CENTRE_MIN_STD_M,
            shift: SMatrix::zeros(),
        }
    }

    /// How far the hand may put the centre from the forearm's for its markers to count as
    /// agreeing with it, m: [`FIT_TOLERANCE_M`] plus three standard deviations of the centre.
    pub(super) fn tolerance(&self) -> f64 {
        FIT_TOLERANCE_M + 3.0 * self.variance.sqrt()
    }

    /// The forearm's point where the hand's `ch` sits with the hand at `relative` in the forearm.
    pub(super) fn forearm_point(&self, relative: &Matrix3<f64>) -> Vector3<f64> {
        self.cf + self.shift.transpose() * posture_features(relative)
    }
}

impl JointCentre {
    pub(super) fn new() -> Self {
        JointCentre {
            normal: SMatrix::zeros(),
            rhs: SVector::zeros(),
            bb: 0.0,
            weight: 0.0,
            frames: 0,
            prior: SVector::zeros(),
            xx: SMatrix::zeros(),
            xp: SMatrix::zeros(),
            recent: [(Matrix3::zeros(), Vector3::zeros()); RECENT_FRAMES],
        }
    }

    pub(super) fn add(&mut self, forearm: &Isometry3<f64>, hand: &Isometry3<f64>, forget: f64) {
        let (rf, rh) =
            (forearm.rotation.to_rotation_matrix().into_inner(), hand.rotation.to_rotation_matrix().into_inner());
        let (tf, th) = (forearm.translation.vector, hand.translation.vector);
        if self.frames == 0 {
            let mid = (tf + th) / 2.0;
            let (cf, ch) = (rf.transpose() * (mid - tf), rh.transpose() * (mid - th));
            self.prior = SVector::<f64, 6>::from_iterator(cf.iter().chain(ch.iter()).copied());
        }
        let mut a = SMatrix::<f64, 3, 6>::zeros();
        a.fixed_view_mut::<3, 3>(0, 0).copy_from(&rf);
        a.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-rh));
        let b = th - tf;
        let keep = 1.0 - forget;
        self.normal = self.normal * keep + a.transpose() * a;
        self.rhs = self.rhs * keep + a.transpose() * b;
        self.bb = self.bb * keep + b.norm_squared();
        self.weight = self.weight * keep + 1.0;
        let x = posture_features(&(rf.transpose() * rh));
        let p = rf.transpose() * b;
        self.recent.rotate_right(1);
        self.recent[0] = (rf.transpose() * rh, p);
        self.xx = self.xx * keep + x * x.transpose();
        self.xp = self.xp * keep + x * p.transpose();
        self.frames += 1;
    }

    /// `(c_f, c_h, variance)`: the centre in the forearm's and the hand's frames, and the mean
    /// square of its residual per coordinate (m², at least [`CENTRE_MIN_STD_M`]²); `None` before
    /// `min_frames` frames.
    pub(super) fn solve(&self, min_frames: usize) -> Option<WristCentre> {
        if self.frames < min_frames {
            return None;
        }
        let lambda = 1e-4 * self.weight;
        let m = self.normal + SMatrix::<f64, 6, 6>::identity() * lambda;
        let c = m.cholesky()?.solve(&(self.rhs + self.prior * lambda));
        let (cf, ch) = (c.fixed_rows::<3>(0).into_owned(), c.fixed_rows::<3>(3).into_owned());
        // The fixed centre as a regression on the posture (p = c_f − R c_h), and the regression
        // itself pulled towards it.
        let mut fixed = SMatrix::<f64, POSTURE_FEATURES, 3>::zeros();
        for i in 0..3 {
            fixed[(0, i)] = cf[i];
            for j in 0..3 {
                fixed[(1 + 3 * i + j, i)] = -ch[j];
            }
        }
        let ridge = POSTURE_RIDGE * self.weight;
        let w = (self.xx + SMatrix::<f64, POSTURE_FEATURES, POSTURE_FEATURES>::identity() * ridge)
            .cholesky()?
            .solve(&(self.xp + fixed * ridge));
        let residual = (self.bb - 2.0 * (w.transpose() * self.xp).trace() + (w.transpose() * self.xx * w).trace())
            / (3.0 * self.weight);
        if !residual.is_finite() || w.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let variance = residual.max(CENTRE_MIN_STD_M * CENTRE_MIN_STD_M);
        let mut centre = WristCentre { cf, ch, variance, shift: w - fixed };
        // Where it sat over the last frames (skin slides; a wrist is no hinge): their mean miss.
        let recent = &self.recent[..self.frames.min(RECENT_FRAMES)];
        let miss = recent.iter().map(|(r, p)| p + r * ch - centre.forearm_point(r)).sum::<Vector3<f64>>();
        centre.cf += miss / recent.len() as f64;
        Some(centre)
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {
    use super::super::testkit::*;
    use super::super::*;
    use super::*;
    use crate::body::BodyModel;

    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn a_lost_hand_with_a_marker_missing_restarts_from_the_two_others_and_the_centre() {
        // MC5 gone for 2 s; in the middle the hand jumps by 60° of flexion for good (a
        // relabelling, a tracker thrown off): MC2 and MCB are gated, and agree with the wrist
        // centre, so the tracker restarts from them at once (it held until MC5 came back: three
        // markers were needed).
        let body = BodyModel::default();
        let rate = 100.0;
        let mut q = trajectory(600, rate);
        for qi in &mut q[300..] {
            qi[1] += 60f64.to_radians();
        }
        let mut f = frames(&body, &q, 0.2);
        for i in 200..400 {
            f[i * MARKER_FRAME_LEN + 12..i * MARKER_FRAME_LEN + 15].fill(f64::NAN);
        }
        let (est, status, tracker) = track_calibrated(&f, rate);
        assert_eq!(tracker.restarts(), 1);
        let restart = first_restart(&status, &tracker).unwrap();
        // At once: not after LOST_S (3 frames here) of gated frames, as without the centre.
        assert_eq!(restart, 300);
        let off = worst_turn_deg(&q[restart + 5..400], &est[restart + 5..400]);
        assert!(off < 0.5, "{off}° after the restart, MC5 still missing");
    }

    #[test]
    fn the_centres_variance_is_what_the_hands_rigid_fit_puts_on_it() {
        // Monte Carlo oracle: the hand's three markers (where they sit lately) with noise of σ
        // per coordinate, the rigid fit of those places to them (Kabsch), and how far that fit
        // moves the centre, per coordinate, plus the learned centre's own variance. The formula
        // takes the turn's effect as isotropic (the fit's turn is stiffer about the markers'
        // normal): 18% under the Monte Carlo here (NumPy: 0.82), within 25%.
        let mut tracker = Tracker::new(BodyModel::default(), TrackerSettings::new(1000.0)).unwrap();
        let sigma = 1e-3;
        tracker.noise_variance = [sigma * sigma; N_HAND];
        let places =
            [Vector3::new(0.01, -0.06, 0.03), Vector3::new(0.0, -0.07, -0.02), Vector3::new(-0.03, -0.05, 0.0)];
        tracker.live[3..6].copy_from_slice(&places);
        // Away from the markers (the turn's share), and at their mean (the mean's alone: σ²/3).
        let mean = (places[0] + places[1] + places[2]) / 3.0;
        for (ch, variance) in [(Vector3::new(0.0, 0.01, 0.0), 1e-6), (mean, 0.0)] {
            let centre = WristCentre { ch, variance, ..WristCentre::origins() };
            let mut rng = crate::rng::SplitMix::new(3);
            let n = 4000;
            let mut sum = 0.0;
            for _ in 0..n {
                let measured = places.map(|p| p + Vector3::from_fn(|_, _| sigma * rng.normal()));
                let fit = fit_points(&places, &measured, [1.0; 3]).unwrap();
                let moved = fit * nalgebra::Point3::from(centre.ch);
                sum += (moved.coords - centre.ch).norm_squared() / 3.0;
            }
            let monte_carlo = sum / n as f64 + centre.variance;
            let ratio = tracker.centre_noise_variance(&centre) / monte_carlo;
            assert!((ratio - 1.0).abs() < 0.25, "centre {ch:?}: formula / Monte Carlo = {ratio}");
        }
    }

    #[test]
    fn a_wrist_centre_that_moves_with_the_posture_is_learned() {
        // No wrist is a ball joint: here the hand's centre shifts 6 mm per radian of flexion
        // and 4 mm per radian of deviation in the forearm. A fixed centre (the functional one)
        // left the hand up to 9° off through 200 ms gaps of a hand marker at 70 Hz (MC2's); the
        // centre learned as a function of the posture keeps it within 2.5° (MC5's, 1.1° MC2's).
        let rate = 70.0;
        let body = BodyModel::default();
        let q = fast_trajectory(700, rate);
        let pose = body.forearm_pose(0.2);
        let clean: Vec<f64> = q
            .iter()
            .flat_map(|qi| {
                let shift = Vector3::new(0.006 * qi[1], 0.004 * qi[2], -0.004 * qi[1]);
                let hand = pose
                    * Isometry3::from_parts(
                        Translation3::from(shift),
                        UnitQuaternion::from_rotation_matrix(&body::wrist_rotation(qi)),
                    );
                let mut frame = body.marker_frame(qi, &pose);
                for k in 3..6 {
                    let p = hand * nalgebra::Point3::from(body.marker_offsets[k]);
                    frame[3 * k..3 * k + 3].copy_from_slice(p.coords.as_slice());
                }
                frame
            })
            .collect();
        let (good, _, _) = track_calibrated(&clean, rate);
        let truth_off = worst_turn_deg(&q[140..], &good[140..]);
        assert!(truth_off < 1.0, "gap-free: {truth_off}°");
        for marker in 3..6 {
            let mut f = clean.clone();
            for i in (280..700).filter(|i| i % 140 < 14) {
                f[i * MARKER_FRAME_LEN + 3 * marker..i * MARKER_FRAME_LEN + 3 * marker + 3].fill(f64::NAN);
            }
            let (est, _, _) = track_calibrated(&f, rate);
            let off = worst_turn_deg(&q[280..], &est[280..]);
            assert!(off < 2.5, "marker {marker}: {off}° off through its gaps");
        }
    }

    #[test]
    fn the_centre_learns_from_no_frame_whose_forearm_came_through_a_gap() {
        // Calibrated at 100 Hz, RSP missing for 50 frames once the centre is learned: the
        // forearm goes through the gap from its two other markers and the centre (not held),
        // so those frames, whose forearm pose the centre itself made, teach it nothing: it has
        // learned from exactly 50 frames fewer than through the same frames without the gap.
        let body = BodyModel::default();
        let rate = 100.0;
        let q = trajectory(400, rate);
        let clean = frames(&body, &q, 0.2);
        let mut gapped = clean.clone();
        for i in 200..250 {
            gapped[i * MARKER_FRAME_LEN..i * MARKER_FRAME_LEN + 3].fill(f64::NAN);
        }
        let (_, _, whole) = track_calibrated(&clean, rate);
        let (_, status, tracker) = track_calibrated(&gapped, rate);
        assert!(status[200..250].iter().all(|s| s & status::HELD == 0), "the forearm was held");
        assert!(whole.centre.frames > 300, "{} frames learned from", whole.centre.frames);
        assert_eq!(whole.centre.frames - tracker.centre.frames, 50);
    }

    #[test]
    fn a_learned_centre_is_solved_from_its_min_frames_th_frame_on() {
        // A hand turning about a centre 1 cm distal of the forearm's origin; each frame added
        // counts once, and `solve(n)` answers from the n-th on.
        let mut centre = JointCentre::new();
        let forearm = Isometry3::translation(0.1, 1.0, 0.2);
        for k in 0..12 {
            let q = [0.3 * (k as f64).sin(), 0.5 * (0.7 * k as f64).cos(), 0.2 * (1.3 * k as f64).sin()];
            let turn = UnitQuaternion::from_rotation_matrix(&body::wrist_rotation(&q));
            let at = Vector3::new(0.0, -0.01, 0.0);
            let hand = forearm * Isometry3::from_parts(Translation3::from(at - turn * at), turn);
            centre.add(&forearm, &hand, 0.0);
            let n = k + 1;
            assert!(centre.solve(n).is_some() && centre.solve(n + 1).is_none(), "after {n} frames");
        }
        let solved = centre.solve(12).unwrap();
        // (Its small ridge towards the first frame's midpoint leaves ~20 µm.)
        assert!((solved.cf - Vector3::new(0.0, -0.01, 0.0)).norm() < 1e-4, "{solved:?}");
    }

    #[test]
    fn a_centre_that_moved_is_followed_as_the_old_frames_are_forgotten() {
        // 2000 frames about a centre 1 cm distal, then 2000 about one 2 cm distal (a marker
        // plate that slipped), forgetting 1/200 per frame: the second centre is what is solved.
        let mut centre = JointCentre::new();
        let forearm = Isometry3::translation(0.1, 1.0, 0.2);
        for k in 0..4000 {
            let t = k as f64 * 0.01;
            let q = [0.3 * t.sin(), 0.5 * (0.7 * t).cos(), 0.2 * (1.3 * t).sin()];
            let turn = UnitQuaternion::from_rotation_matrix(&body::wrist_rotation(&q));
            let at = Vector3::new(0.0, if k < 2000 { -0.01 } else { -0.02 }, 0.0);
            let hand = forearm * Isometry3::from_parts(Translation3::from(at - turn * at), turn);
            centre.add(&forearm, &hand, 1.0 / 200.0);
        }
        let solved = centre.solve(12).unwrap();
        assert!((solved.cf - Vector3::new(0.0, -0.02, 0.0)).norm() < 1e-4, "{solved:?}");
    }

    #[test]
    fn the_calibrated_wrist_centre_waits_for_its_half_second_of_frames() {
        // At 100 Hz the centre is solved once it has learned from CENTRE_MIN_S of frames (50;
        // at least 10 at any rate): not from the 45th frame, from the 50th.
        let rate = 100.0;
        let q = trajectory(60, rate);
        let f = frames(&BodyModel::default(), &q, 0.2);
        let solved_after = |n: usize| track_calibrated(&f[..n * MARKER_FRAME_LEN], rate).2.wrist_centre().is_some();
        assert!(!solved_after(45));
        assert!(solved_after(50));
    }

    #[test]
    fn two_hand_markers_that_miss_the_centre_do_not_restart_the_tracker() {
        // Uncalibrated (the centre is the body model's, 1 mm uncertain): MC5 missing from frame
        // 200 on, and MC2 3 cm off for two frames (a ghost, shorter than LOST_S). MC2 and MCB
        // then put the centre ~3 cm from the forearm's, beyond its tolerance (5 mm + 3 × 1 mm):
        // gated, no restart onto the ghost.
        let body = BodyModel::default();
        let rate = 100.0;
        let q = trajectory(400, rate);
        let mut f = frames(&body, &q, 0.2);
        for i in 200..400 {
            f[i * MARKER_FRAME_LEN + 12..i * MARKER_FRAME_LEN + 15].fill(f64::NAN);
        }
        for i in 300..302 {
            f[i * MARKER_FRAME_LEN + 9] += 0.03;
        }
        let (est, status, tracker) = track(&f, rate);
        assert_eq!(tracker.restarts(), 0, "restarted at {:?}", status.iter().position(|s| s & status::RESTARTED != 0));
        let off = worst_turn_deg(&q[200..], &est[200..]);
        assert!(off < 1.0, "{off}° off through the ghost");
    }

    #[test]
    fn a_learned_centres_variance_is_its_residual_per_coordinate() {
        // The hand turning about a fixed centre, its position 3 mm (σ, per coordinate) off each
        // frame: the centre's residual variance is that noise's, 9 mm² (less the regression's
        // 10 features of 2000 frames), well above its 1 mm² floor.
        let sigma = 0.003;
        let mut rng = crate::rng::SplitMix::new(9);
        let mut centre = JointCentre::new();
        let forearm = Isometry3::translation(0.1, 1.0, 0.2);
        let at = Vector3::new(0.0, -0.01, 0.0);
        for k in 0..2000 {
            let t = k as f64 * 0.01;
            let q = [0.6 * (1.3 * t).sin(), 0.5 * (0.9 * t).cos(), 0.2 * (1.7 * t).sin()];
            let turn = UnitQuaternion::from_rotation_matrix(&body::wrist_rotation(&q));
            let noise = Vector3::from_fn(|_, _| sigma * rng.normal());
            let hand = forearm * Isometry3::from_parts(Translation3::from(at - turn * at + noise), turn);
            centre.add(&forearm, &hand, 0.0);
        }
        let solved = centre.solve(2000).unwrap();
        let ratio = solved.variance / (sigma * sigma);
        assert!((ratio - 1.0).abs() < 0.1, "variance {} mm², expected 9", solved.variance * 1e6);
    }
}
