//! The forearm's own motion, for the torques: a hand carried by a forearm that swings (a
//! reach, a wheelchair push) needs torque to follow it — racing's wrist accelerates at
//! 31 m/s², three times gravity's pull on the hand — which a forearm taken to be at rest
//! leaves out with every status 0.
//!
//! Two constant-acceleration Kalman filters, driven by white jerk as the joint filter is, take
//! the forearm's pose whenever its three markers measured it: one its frame's origin (the body
//! model's wrist centre; calibrated, its markers' centroid, whose acceleration is carried to the
//! learned wrist centre as a rigid body's), one its orientation (multiplicatively: the state's
//! angle is the turn since the last frame's estimate, folded into it after each correction).
//! Each filter's three lab axes share one covariance, the pose's noise being about the same in
//! every direction. Measured on `tracker/motion.rs`'s swinging forearm (22 m/s² at the wrist,
//! 0.1 mm of noise): torques 0.066–0.069 N·m RMS off where carrying adds 0.373.
//!
//! A forearm at rest must not get its noise's second derivative as torque: on 0.3 mm of marker
//! noise the centre's acceleration is ±0.9 m/s², 0.025 N·m on the hand, as much as the torques'
//! whole error on a resting arm. So each rate counts only once it stands out of its own
//! uncertainty ([`MOTION_SIGNIFICANCE`]), shrunk toward zero by what it could be of noise
//! (`v (1 − k² σ² / |v|²)`, continuous where it starts to count).

use nalgebra::{Isometry3, Matrix3, UnitQuaternion, Vector3};

use super::checks::JUMP_TOLERANCE_M;
use super::output::MIN_REPORTED_NOISE;
use super::{Step, Tracker};
use crate::reference::ForearmMotion;

/// The wrist centre's jerk density over the joint angles' ([`TrackerSettings::jerk_noise`](super::TrackerSettings)),
/// m²/rad²: the square of a lever of 0.3 m (a reach moves the wrist 0.3 m for every radian the
/// wrist's own angles turn in one of the same duration; the forearm's own turn takes the joint
/// angles' density).
pub const CENTRE_JERK_LEVER_M: f64 = 0.3;

/// How many of its own posterior standard deviations a rate of the forearm's motion must stand
/// out by before it counts (see `tracker/motion.rs`): its angular velocity, and its
/// accelerations. The posterior counts the filter's uncertainty about the motion as well as the
/// markers' noise: on a forearm at rest the estimates' noise is 0.71 (velocity) and 0.41
/// (accelerations) of it at the filter's steady state, so these keep a resting forearm's three
/// axes at rest on all but 5e-4 and 3e-5 of its frames (χ² with 3 degrees of freedom past 17.9
/// and 23.8).
pub const MOTION_SIGNIFICANCE: [f64; 2] = [3.0, 2.0];

/// The standard deviation of a resting forearm's estimated accelerations over their posterior
/// one, at the filters' steady state (the closed loop's response to the markers' white noise
/// alone: 0.41 over the range of noise and jerk the tracker meets): what a counted
/// acceleration adds to the torques' σ is its posterior variance times this squared.
pub const ACCEL_NOISE_SHARE: f64 = 0.41;

/// How far a measured pose's origin may miss the prediction before it is a new start and not
/// motion (see [`ForearmMotionFilter::step`]): both the slack the tracker gives a forearm's
/// jump ([`JUMP_TOLERANCE_M`], 5 cm: a forearm's prediction over a frame is off by millimetres,
/// racing's at 70 Hz too) and this many standard deviations of the predicted miss.
const JUMP_SIGMAS: f64 = 30.0;

/// How often a calibrated tracker takes the learned wrist centre's place in the forearm for the
/// forearm's motion when nothing else solved it, s (solving costs about a push).
pub const ANCHOR_EVERY_S: f64 = 0.1;

/// A constant-acceleration filter over three lab axes that share one covariance.
#[derive(Debug, Clone, Copy)]
struct Axes {
    /// Rows: value, rate, acceleration; columns: lab axes.
    x: Matrix3<f64>,
    /// Covariance of (value, rate, acceleration) on each axis.
    p: Matrix3<f64>,
}

impl Axes {
    /// Started at `value`, at rest as far as it knows: its rate and acceleration as uncertain
    /// as a limb's ever are (10 m/s or rad/s, 1000 m/s² or rad/s²), so they count only once seen.
    fn start(value: Vector3<f64>, variance: f64) -> Self {
        let mut x = Matrix3::zeros();
        x.set_row(0, &value.transpose());
        Axes { x, p: Matrix3::from_diagonal(&Vector3::new(variance, 1e2, 1e6)) }
    }

    /// One frame on: `f` is the constant-acceleration transition over `dt` (value += dt rate +
    /// dt²/2 acceleration, rate += dt acceleration), written out (a general 3×3 product here
    /// cost the tracker's push a few percent).
    fn predict(&mut self, dt: f64, q: &Matrix3<f64>) {
        let half = 0.5 * dt * dt;
        for axis in 0..3 {
            let (v, r, a) = (self.x[(0, axis)], self.x[(1, axis)], self.x[(2, axis)]);
            self.x[(0, axis)] = v + dt * r + half * a;
            self.x[(1, axis)] = r + dt * a;
        }
        // F P Fᵀ with F's rows (1, dt, dt²/2), (0, 1, dt), (0, 0, 1).
        let p = &self.p;
        let fp = Matrix3::from_fn(|i, j| match i {
            0 => p[(0, j)] + dt * p[(1, j)] + half * p[(2, j)],
            1 => p[(1, j)] + dt * p[(2, j)],
            _ => p[(2, j)],
        });
        self.p = Matrix3::from_fn(|i, j| match j {
            0 => fp[(i, 0)] + dt * fp[(i, 1)] + half * fp[(i, 2)],
            1 => fp[(i, 1)] + dt * fp[(i, 2)],
            _ => fp[(i, 2)],
        }) + q;
    }

    /// Corrects by a measured value `innovation` away from the predicted one, each axis's
    /// noise variance `r`.
    fn correct(&mut self, innovation: &Vector3<f64>, r: f64) {
        let s = self.p[(0, 0)] + r;
        let gain: Vector3<f64> = self.p.column(0) / s;
        self.x += gain * innovation.transpose();
        self.p -= gain * self.p.row(0);
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// Row `row` (1: the rate, 2: the acceleration), lab axes.
    fn row(&self, row: usize) -> Vector3<f64> {
        self.x.row(row).transpose()
    }
}

/// The rotation vector of a turn `q` between two frames, to first order: twice its
/// quaternion's vector part (on the short way round). A frame's turn is small (10 rad/s is 0.01
/// rad a frame at 1 kHz, 0.14 at 70 Hz: 1e-4 of it off), and the logarithm's trigonometry cost
/// the tracker's push 4 % of its time.
fn small_turn(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    q.imag() * (2.0 * q.w.signum())
}

/// The turn whose [`small_turn`] is `phi`, to the same order: the quaternion (1, φ/2), normed.
fn turned_by(phi: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(nalgebra::Quaternion::new(1.0, 0.5 * phi.x, 0.5 * phi.y, 0.5 * phi.z))
}

/// `v` as it counts: shrunk by what its variance per axis `variance` says it could be of noise,
/// zero within `k` standard deviations of it.
fn significant(v: Vector3<f64>, variance: f64, k: f64) -> [f64; 3] {
    let noise = k * k * variance.max(0.0);
    let norm2 = v.norm_squared();
    let keep = if norm2 > noise { 1.0 - noise / norm2 } else { 0.0 };
    (v * keep).into()
}

/// The forearm's motion as the torques take it (see the [module docs](self)).
#[derive(Debug, Clone, Copy)]
pub(super) struct ForearmMotionFilter {
    centre: Option<Axes>,
    turn: Option<Axes>,
    orientation: UnitQuaternion<f64>,
    /// The time between frames, s, and the process noise of the centre's and the turn's.
    dt: f64,
    centre_noise: Matrix3<f64>,
    turn_noise: Matrix3<f64>,
    /// [`pose_variances`] at unit marker noise (they scale with it) for the forearm's marker
    /// offsets they were computed at: the offsets change only when a template is taken.
    unit_variances: ([[f64; 3]; 3], Option<(f64, f64)>),
}

impl ForearmMotionFilter {
    /// A filter for frames `dt` seconds apart whose joint-jerk density is `jerk_noise`
    /// (rad²/s⁵, [`TrackerSettings::jerk_noise`](super::TrackerSettings)), not started.
    pub(super) fn new(dt: f64, jerk_noise: f64) -> Self {
        let (d2, d3) = (dt * dt, dt * dt * dt);
        let unit_noise = Matrix3::new(
            d2 * d3 / 20.0,
            d2 * d2 / 8.0,
            d3 / 6.0,
            d2 * d2 / 8.0,
            d3 / 3.0,
            d2 / 2.0,
            d3 / 6.0,
            d2 / 2.0,
            dt,
        );
        ForearmMotionFilter {
            centre: None,
            turn: None,
            orientation: UnitQuaternion::identity(),
            dt,
            centre_noise: unit_noise * (jerk_noise * CENTRE_JERK_LEVER_M * CENTRE_JERK_LEVER_M),
            turn_noise: unit_noise * jerk_noise,
            unit_variances: ([[f64::NAN; 3]; 3], None),
        }
    }

    /// [`pose_variances`] for markers at `offsets` with noise variance `sigma2`, from the
    /// unit ones kept for those offsets.
    fn pose_variances(&mut self, offsets: &[[f64; 3]; 3], sigma2: f64) -> Option<(f64, f64)> {
        if self.unit_variances.0 != *offsets {
            self.unit_variances = (*offsets, pose_variances(offsets, 1.0));
        }
        self.unit_variances.1.map(|(centre, turn)| (centre * sigma2, turn * sigma2))
    }

    /// Forgets the motion: the next pose starts it again (at rest).
    pub(super) fn reset(&mut self) {
        self.centre = None;
        self.turn = None;
    }

    /// One frame: predicted, and corrected by the forearm's pose `pose` when it was measured
    /// this frame (its centre's noise variance `centre_variance`, m², and its turn's
    /// `turn_variance`, rad², per axis).
    pub(super) fn step(&mut self, pose: Option<&Isometry3<f64>>, centre_variance: f64, turn_variance: f64) {
        if let Some(c) = self.centre.as_mut() {
            c.predict(self.dt, &self.centre_noise);
        }
        if let Some(t) = self.turn.as_mut() {
            t.predict(self.dt, &self.turn_noise);
        }
        let Some(pose) = pose else { return };
        let at = pose.translation.vector;
        // A pose no motion reaches from the prediction (the lab shifted, the markers relabelled,
        // the forearm's position re-learned after a jump) is a new start, not an acceleration:
        // a whole lab shifted 20 cm read as 13 N·m of carried torque, status 0.
        if let Some(c) = self.centre.as_ref() {
            let miss = (at - c.x.row(0).transpose()).norm();
            if miss > JUMP_TOLERANCE_M && miss > JUMP_SIGMAS * (c.p[(0, 0)] + centre_variance).sqrt() {
                self.reset();
            }
        }
        match self.centre.as_mut() {
            Some(c) => c.correct(&(at - c.x.row(0).transpose()), centre_variance),
            None => self.centre = Some(Axes::start(at, centre_variance)),
        }
        match self.turn.as_mut() {
            Some(t) => {
                // The measured turn since the last estimate, against the predicted one; then the
                // corrected turn is folded into the orientation.
                let measured = small_turn(&(pose.rotation * self.orientation.inverse()));
                t.correct(&(measured - t.x.row(0).transpose()), turn_variance);
                self.orientation = turned_by(&t.x.row(0).transpose()) * self.orientation;
                t.x.set_row(0, &Vector3::zeros().transpose());
            }
            None => {
                self.orientation = pose.rotation;
                self.turn = Some(Axes::start(Vector3::zeros(), turn_variance));
            }
        }
    }

    /// The motion the torques take ([`ForearmMotion`], the lab frame of the poses), the linear
    /// acceleration of the point `lever` (lab axes) from the poses' origin, the rigid forearm's
    /// `a + α × r + ω × (ω × r)`: each as far as it stands out of its uncertainty; at rest
    /// before a pose was seen.
    pub(super) fn motion(&self, lever: &Vector3<f64>) -> ForearmMotion {
        let (Some(c), Some(t)) = (self.centre.as_ref(), self.turn.as_ref()) else {
            return ForearmMotion::default();
        };
        let (omega, alpha) = (t.row(1), t.row(2));
        let accel = c.row(2) + alpha.cross(lever) + omega.cross(&omega.cross(lever));
        let accel_variance = c.p[(2, 2)] + lever.norm_squared() * t.p[(2, 2)];
        let [k_rate, k_accel] = MOTION_SIGNIFICANCE;
        ForearmMotion {
            omega: significant(omega, t.p[(1, 1)], k_rate),
            alpha: significant(alpha, t.p[(2, 2)], k_accel),
            accel: significant(accel, accel_variance, k_accel),
        }
    }

    /// The noise variance per axis of what [`motion`](Self::motion) counts of the wrist centre's
    /// acceleration (m²/s⁴) and of the forearm's angular acceleration (rad²/s⁴): zero for one not
    /// counted. (Its angular velocity's noise moves the torques by second-order terms only.)
    pub(super) fn counted_noise(&self, lever: &Vector3<f64>) -> (f64, f64) {
        let (Some(c), Some(t)) = (self.centre.as_ref(), self.turn.as_ref()) else {
            return (0.0, 0.0);
        };
        let m = self.motion(lever);
        let share = ACCEL_NOISE_SHARE * ACCEL_NOISE_SHARE;
        let counted = |v: [f64; 3], variance: f64| if v == [0.0; 3] { 0.0 } else { share * variance };
        (counted(m.accel, c.p[(2, 2)] + lever.norm_squared() * t.p[(2, 2)]), counted(m.alpha, t.p[(2, 2)]))
    }

    /// The wrist centre's acceleration as estimated, before the significance test (m/s²).
    #[cfg(test)]
    fn raw_accel(&self) -> Vector3<f64> {
        self.centre.map_or(Vector3::zeros(), |c| c.x.row(2).transpose())
    }
}

impl Tracker {
    /// Step 1c: the forearm's motion follows its pose when its three markers measured it this
    /// frame, and goes on as predicted otherwise. A pose from two markers is not the three's (its
    /// roll filtered, its markers where they sat lately): each gap's ends stepped it, and the
    /// steps read as accelerations (the exam's dropouts of a forearm marker: torques 0.036 →
    /// 0.235 N·m RMS off). The pose's noise is its markers' as learned
    /// ([`ForearmNoise`](super::forearm::ForearmNoise)), the tracker's initial guess until a
    /// sample taught it (the first frames then count as noisy, not exact).
    pub(super) fn follow_forearm_motion(&mut self, step: &Step) {
        let pose = if step.forearm_measured { self.forearm.as_ref() } else { None };
        let sigma2 = self
            .forearm_noise
            .learned()
            .unwrap_or(self.settings.initial_marker_noise.powi(2))
            .max(MIN_REPORTED_NOISE * MIN_REPORTED_NOISE);
        let offsets = [self.body.marker_offsets[0], self.body.marker_offsets[1], self.body.marker_offsets[2]];
        // Three markers on a line give no turn: their pose is no measurement of it either.
        let (centre, turn) = self.motion.pose_variances(&offsets, sigma2).unwrap_or((sigma2, f64::INFINITY));
        let pose = if turn.is_finite() { pose } else { None };
        self.motion.step(pose, centre, turn);
    }

    /// The forearm's motion the torques take, at the wrist centre (see
    /// [`ForearmMotionFilter::motion`]): the body model's, its forearm frame's origin; calibrated,
    /// the learned centre's point in the forearm (the forearm's frame is then its markers'
    /// centroid, centimetres away), taken as it is solved, or every [`ANCHOR_EVERY_S`]; the
    /// centroid's own until it is learned.
    pub(super) fn forearm_motion(&mut self, step: &mut Step, forearm: &Isometry3<f64>) -> ForearmMotion {
        if self.calibration.is_some() {
            let every = ((ANCHOR_EVERY_S * self.settings.rate_hz).ceil() as usize).max(1);
            if (step.memo.is_some() || step.index.is_multiple_of(every))
                && let Some(centre) = self.centre_memo(&mut step.memo)
            {
                self.motion_anchor = centre.cf;
            }
        }
        self.motion.motion(&(forearm.rotation * self.motion_anchor))
    }

    /// [`forearm_motion`](Self::forearm_motion) as last taken, and the noise variances of what
    /// it counts ([`ForearmMotionFilter::counted_noise`]), for the standard deviations.
    pub(super) fn forearm_motion_now(&self) -> (ForearmMotion, (f64, f64)) {
        let Some(forearm) = self.forearm.as_ref() else { return (ForearmMotion::default(), (0.0, 0.0)) };
        let lever = forearm.rotation * self.motion_anchor;
        (self.motion.motion(&lever), self.motion.counted_noise(&lever))
    }
}

/// Per axis, the noise variance of a rigid fit's origin (m²) and of its turn (rad²), for
/// markers of isotropic noise variance `sigma2` (m²) at `offsets` in the segment's frame (whose
/// origin is the wrist centre): the fit's turn has covariance σ² (Σ sₘᵀ sₘ)⁻¹ (sₘ = [markerₘ −
/// centroid]ₓ), its centroid σ²/3 per axis, and the origin moves with the centroid and by the
/// turn times its lever from it. Means over the axes; `None` for markers on a line.
pub(super) fn pose_variances(offsets: &[[f64; 3]; 3], sigma2: f64) -> Option<(f64, f64)> {
    let offsets = offsets.map(Vector3::from);
    let centroid = (offsets[0] + offsets[1] + offsets[2]) / 3.0;
    let spread = offsets.iter().fold(Matrix3::zeros(), |acc, o| {
        let s = (o - centroid).cross_matrix();
        acc + s.transpose() * s
    });
    let turn = spread.try_inverse()? * sigma2;
    let lever = (-centroid).cross_matrix();
    let origin = Matrix3::from_diagonal_element(sigma2 / 3.0) + lever * turn * lever.transpose();
    Some((origin.trace() / 3.0, turn.trace() / 3.0))
}

#[cfg(test)]
mod tests {
    use super::super::testkit::lcg_gaussian;
    use super::super::{Tracker, TrackerSettings};
    use super::*;
    use crate::body::{self, BodyModel};
    use crate::reference::{self, JointState};
    use nalgebra::Translation3;

    const RATE: f64 = 1000.0;
    const JERK: f64 = super::super::DEFAULT_JERK_NOISE;

    /// A pose seen with white noise of `sd` (m) on the centre and `sd / 0.04` (rad) on the turn.
    fn noisy(pose: &Isometry3<f64>, sd: f64, rng: &mut crate::rng::SplitMix) -> Isometry3<f64> {
        let n = |rng: &mut crate::rng::SplitMix| Vector3::from_fn(|_, _| rng.normal() * sd);
        let turn = UnitQuaternion::from_scaled_axis(n(rng) / 0.04);
        Isometry3::from_parts(Translation3::from(pose.translation.vector + n(rng)), turn * pose.rotation)
    }

    #[test]
    fn the_written_out_prediction_is_the_transitions_product() {
        let dt = 0.014;
        let f = Matrix3::new(1.0, dt, 0.5 * dt * dt, 0.0, 1.0, dt, 0.0, 0.0, 1.0);
        let a = Matrix3::new(2.0, 0.3, -0.1, 0.3, 5.0, 0.7, -0.1, 0.7, 9.0);
        let q = Matrix3::new(1e-3, 2e-3, 3e-3, 2e-3, 5e-3, 6e-3, 3e-3, 6e-3, 9e-3);
        let x = Matrix3::new(0.1, -0.2, 0.3, 1.5, 2.5, -3.5, 40.0, -50.0, 60.0);
        let mut axes = Axes { x, p: a };
        axes.predict(dt, &q);
        assert!((axes.x - f * x).abs().max() < 1e-12, "{}", axes.x - f * x);
        assert!((axes.p - (f * a * f.transpose() + q)).abs().max() < 1e-12);
    }

    #[test]
    fn a_forearm_at_rest_under_noise_is_at_rest() {
        let mut rng = crate::rng::SplitMix::new(7);
        let sd: f64 = 0.3e-3;
        let rest =
            Isometry3::from_parts(Translation3::new(0.1, 1.0, 0.2), UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0));
        let mut filter = ForearmMotionFilter::new(1.0 / RATE, JERK);
        let mut moved = 0;
        for _ in 0..20_000 {
            filter.step(Some(&noisy(&rest, sd, &mut rng)), sd * sd, (sd / 0.04).powi(2));
            if filter.motion(&Vector3::zeros()) != ForearmMotion::default() {
                moved += 1;
            }
        }
        // The raw estimate does move with the noise: the test is the significance, not a
        // filter too slow to see anything.
        assert!(filter.raw_accel().norm() > 0.0);
        // MOTION_SIGNIFICANCE lets through about 1e-3 of the frames (three rates, each 5e-4 or
        // less once settled): at most a quarter of a percent.
        assert!(moved < 50, "{moved} of 20000 frames of a resting forearm counted as moving");
    }

    #[test]
    fn a_swinging_forearms_motion_is_followed() {
        // The wrist centre on a circle of 0.28 m about an elbow, the forearm turning with it:
        // θ(t) = 1.2 sin(2π 1.5 t) rad (peak 11 rad/s, 107 rad/s², 30 m/s² at the centre).
        let mut rng = crate::rng::SplitMix::new(3);
        let sd: f64 = 0.1e-3;
        let (radius, amp, w) = (0.28, 1.2, 2.0 * std::f64::consts::PI * 1.5);
        let axis = Vector3::z_axis();
        let pose = |t: f64| {
            let theta = amp * (w * t).sin();
            let r = UnitQuaternion::from_axis_angle(&axis, theta);
            Isometry3::from_parts(Translation3::from(r * Vector3::new(0.0, -radius, 0.0)), r)
        };
        let truth = |t: f64| {
            let (th, thd, thdd) = (amp * (w * t).sin(), amp * w * (w * t).cos(), -amp * w * w * (w * t).sin());
            let r = UnitQuaternion::from_axis_angle(&axis, th);
            let arm = r * Vector3::new(0.0, -radius, 0.0);
            let (omega, alpha) = (axis.into_inner() * thd, axis.into_inner() * thdd);
            (omega, alpha, alpha.cross(&arm) + omega.cross(&omega.cross(&arm)))
        };
        let mut filter = ForearmMotionFilter::new(1.0 / RATE, JERK);
        let (mut err, mut size, mut n) = ([0.0; 3], [0.0; 3], 0.0);
        for i in 0..4000 {
            let t = i as f64 / RATE;
            filter.step(Some(&noisy(&pose(t), sd, &mut rng)), sd * sd, (sd / 0.04).powi(2));
            if t < 1.0 {
                continue; // settled
            }
            let m = filter.motion(&Vector3::zeros());
            let (omega, alpha, accel) = truth(t);
            for (k, (got, want)) in [(m.omega, omega), (m.alpha, alpha), (m.accel, accel)].into_iter().enumerate() {
                err[k] += (Vector3::from(got) - want).norm_squared();
                size[k] += want.norm_squared();
            }
            n += 1.0;
        }
        let relative: [f64; 3] = std::array::from_fn(|k| (err[k] / size[k]).sqrt());
        // RMS error within a fifth of the motion's RMS for ω, a quarter for the centre's
        // acceleration (its centripetal part turns at twice the swing's frequency) and 0.3 for
        // α: on 0.1 mm of noise over markers 4 cm apart the turn's second derivative is as
        // noisy as that. A forearm taken at rest is off by all of each, 1.0.
        assert!(
            relative[0] < 0.2 && relative[1] < 0.3 && relative[2] < 0.25,
            "relative RMS errors {relative:?} (n {n})"
        );
    }

    #[test]
    fn the_origins_noise_counts_its_lever_from_the_markers() {
        // Three markers on a circle of radius ρ = 5 cm in the xz-plane, their centroid 10 cm
        // up y from the origin. In closed form: the turn's covariance is σ² diag(1/1.5ρ²,
        // 1/3ρ², 1/1.5ρ²), a mean of σ² 5/(9ρ²); the origin moves with the centroid (σ²/3 per
        // axis) and by the turns about x and z times the 0.1 m lever: a mean of
        // σ²/3 + 0.01 · 2σ²/(4.5ρ²).
        let (rho, h, sigma2) = (0.05, 0.1, 1e-6);
        let c = 3f64.sqrt() / 2.0 * rho;
        let offsets = [[rho, h, 0.0], [-rho / 2.0, h, c], [-rho / 2.0, h, -c]];
        let (origin, turn) = pose_variances(&offsets, sigma2).unwrap();
        let rho2 = rho * rho;
        let (want_origin, want_turn) =
            (sigma2 / 3.0 + h * h * 2.0 * sigma2 / (4.5 * rho2), sigma2 * 5.0 / (9.0 * rho2));
        assert!(
            (origin - want_origin).abs() < 1e-9 * want_origin.max(1.0) + 1e-6 * want_origin,
            "{origin} vs {want_origin}"
        );
        assert!((turn - want_turn).abs() < 1e-6 * want_turn, "{turn} vs {want_turn}");
        assert!(pose_variances(&[[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.0, 0.0]], 1e-6).is_none());
    }

    /// Per frame of a forearm swinging about its elbow (θ = 0.8 sin(2π 1.2 t) about the lab's
    /// z, through the elbow 0.27 m up the forearm) while the wrist moves as
    /// `testkit::trajectory`: the marker frame, and the true torques carried and at rest.
    fn swinging(body: &BodyModel, n: usize, rate: f64) -> Vec<([f64; body::MARKER_FRAME_LEN], [f64; 3], [f64; 3])> {
        let rest = body.forearm_pose(0.0);
        let elbow = rest * nalgebra::Point3::new(0.0, body.forearm.length, 0.0);
        let (amp, w) = (0.8, std::f64::consts::TAU * 1.2);
        let axis = Vector3::z_axis();
        (0..n)
            .map(|i| {
                let t = i as f64 / rate;
                let (th, thd, thdd) = (amp * (w * t).sin(), amp * w * (w * t).cos(), -amp * w * w * (w * t).sin());
                let turn = UnitQuaternion::from_axis_angle(&axis, th);
                let centre = elbow.coords + turn * (rest.translation.vector - elbow.coords);
                let pose = Isometry3::from_parts(Translation3::from(centre), turn * rest.rotation);
                let arm = centre - elbow.coords;
                let (omega, alpha) = (axis.into_inner() * thd, axis.into_inner() * thdd);
                let carried = ForearmMotion {
                    omega: omega.into(),
                    alpha: alpha.into(),
                    accel: (alpha.cross(&arm) + omega.cross(&omega.cross(&arm))).into(),
                };
                // testkit::trajectory's angles and their derivatives.
                let state = JointState {
                    q: [0.6 * (1.3 * t).sin(), -0.5 * (0.9 * t + 0.4).sin(), 0.2 * (1.7 * t).cos()],
                    qd: [0.78 * (1.3 * t).cos(), -0.45 * (0.9 * t + 0.4).cos(), -0.34 * (1.7 * t).sin()],
                    qdd: [-1.014 * (1.3 * t).sin(), 0.405 * (0.9 * t + 0.4).sin(), -0.578 * (1.7 * t).cos()],
                };
                let r = pose.rotation.to_rotation_matrix();
                let moving = reference::inverse_dynamics_moving(body, &r, &carried, &state).unwrap();
                let at_rest = reference::inverse_dynamics_at(body, &r, &state).unwrap();
                (body.marker_frame(&state.q, &pose), moving, at_rest)
            })
            .collect()
    }

    #[test]
    fn a_hand_carried_by_a_swinging_forearm_gets_the_torques_of_its_motion() {
        // The wrist centre accelerates at up to 22 m/s²: carried, the hand needs up to 0.4 N·m
        // more than at rest. With 0.1 mm of noise on every marker, uncalibrated and
        // calibrated, the torques must follow the carried truth to within a fifth of what
        // carrying adds (a forearm taken at rest misses all of it), and their σ say so.
        let (rate, n) = (1000.0, 6000);
        let body = BodyModel::default();
        let trial = swinging(&body, n, rate);
        for calibrated in [true, false] {
            let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(rate)).unwrap();
            if calibrated {
                tracker.set_calibration(Some(crate::calibration::Calibration::body_model()));
            }
            let mut noise = lcg_gaussian(11);
            let (mut err, mut carried, mut rows, mut within, mut judged) = (0.0, 0.0, 0, 0, 0);
            for (i, (frame, moving, at_rest)) in trial.iter().enumerate() {
                let noisy: Vec<f64> = frame.iter().map(|v| v + 1e-4 * noise()).collect();
                let Some(out) = tracker.push(&noisy).unwrap() else { continue };
                if i < rate as usize {
                    continue; // the noise learned, the filters settled
                }
                err += (0..3).map(|c| (out.tau[c] - moving[c]).powi(2)).sum::<f64>();
                if i % 10 == 0 {
                    let sd = tracker.output_sd().unwrap().tau;
                    within += (0..3).filter(|&c| (out.tau[c] - moving[c]).abs() <= 2.0 * sd[c]).count();
                    judged += 3;
                }
                carried += (0..3).map(|c| (at_rest[c] - moving[c]).powi(2)).sum::<f64>();
                rows += 1;
            }
            let (err, carried) = ((err / rows as f64).sqrt(), (carried / rows as f64).sqrt());
            assert!(carried > 0.1, "the swing carries {carried} N·m RMS: too little to test");
            assert!(err < 0.2 * carried, "calibrated {calibrated}: {err} N·m RMS off where carrying adds {carried}");
            // The torques' σ counts the forearm's accelerations' noise: ±2σ holds 77-80 % of the
            // errors (48-55 % without it; the rest is the lag a white-jerk model leaves).
            let coverage = within as f64 / judged as f64;
            assert!(coverage > 0.7, "calibrated {calibrated}: ±2σ holds {coverage} of the torques' errors");
        }
    }

    #[test]
    fn a_forearm_marker_gap_is_no_forearm_motion() {
        // A resting forearm whose marker drops out for 0.3 s: the pose from its two others is
        // not the three's, and each end of the gap stepped it. Taken as motion, the exam's
        // dropouts put the torques 6.5× further off (0.036 → 0.235 N·m RMS); the forearm must
        // stay at rest through the gap and after it, as without one.
        let (rate, shoulder) = (1000.0, 0.3);
        let body = BodyModel::default();
        let q = super::super::testkit::trajectory(4000, rate);
        let pose = body.forearm_pose(shoulder);
        let mut at_rest = 0;
        for gap in [None, Some(0), Some(1), Some(2)] {
            let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(rate)).unwrap();
            tracker.set_calibration(Some(crate::calibration::Calibration::body_model()));
            let mut noise = lcg_gaussian(5);
            let mut moving = 0;
            for (i, q) in q.iter().enumerate() {
                let mut frame: Vec<f64> = body.marker_frame(q, &pose).iter().map(|v| v + 1e-4 * noise()).collect();
                if let Some(m) = gap
                    && (2000..2300).contains(&i)
                {
                    frame[3 * m..3 * m + 3].fill(f64::NAN);
                }
                tracker.push(&frame).unwrap();
                if i >= 1000 && tracker.forearm_motion_now().0 != ForearmMotion::default() {
                    moving += 1;
                }
            }
            if gap.is_none() {
                at_rest = moving; // what noise alone lets through (MOTION_SIGNIFICANCE)
            }
            assert!(
                moving <= at_rest + 5,
                "marker {gap:?} gone 0.3 s: the resting forearm moved on {moving} of 3000 frames ({at_rest} without the gap)"
            );
        }
    }

    #[test]
    fn a_lab_that_shifts_is_no_forearm_motion() {
        // Every marker 20 cm on from frame 2000 (the lab re-calibrated, a fault probe): the
        // forearm's step is a new start, not 13 N·m of carried torque with status 0.
        let (rate, shoulder) = (1000.0, 0.3);
        let body = BodyModel::default();
        let q = super::super::testkit::trajectory(3000, rate);
        let pose = body.forearm_pose(shoulder);
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(rate)).unwrap();
        let mut moving = 0;
        for (i, q) in q.iter().enumerate() {
            let shift = if i >= 2000 { 0.2 } else { 0.0 };
            let frame: Vec<f64> = body.marker_frame(q, &pose).iter().map(|v| v + shift).collect();
            tracker.push(&frame).unwrap();
            if i >= 1000 && tracker.forearm_motion_now().0 != ForearmMotion::default() {
                moving += 1;
            }
        }
        assert_eq!(moving, 0, "the shifted lab moved the resting forearm on {moving} frames");
    }
}
