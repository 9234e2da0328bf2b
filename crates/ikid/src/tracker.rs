//! Causal tracking of the wrist's angles, velocities, accelerations and torques, frame by
//! frame: an extended Kalman filter over the body model that learns each marker
//! coordinate's noise as it goes.
//!
//! Per frame:
//! 1. the forearm's pose is fitted to its three markers (Kabsch); with one missing or rejected,
//!    to the two others, its roll about the line through them filtered (`Roll`): predicted from
//!    how the forearm was seen to turn while whole, corrected by the wrist centre seen from the
//!    hand as far as the learned hand-marker noise lets that centre tell (noisy hand markers
//!    made it jitter by degrees a frame, the filter restart and the torques reach kN·m). The
//!    centre is learned from the subject's whole frames (a functional joint centre,
//!    `JointCentre`, as a function of the hand's posture — no wrist is a ball joint: a fixed
//!    centre leaves 2–4 mm on real wrists — and where it sat over the last frames); it also
//!    closes the turn that two hand markers leave open (the hand measured by its orientation: a
//!    third measurement, weighed by its fit). A segment fitted to two of its markers takes them
//!    where they sat on it lately (skin markers slide: taken where they sat when its shape was
//!    learned, they turned a real forearm 8° off);
//! 2. the state — `(q, q̇, q̈)` of the three wrist coordinates — is predicted with a
//!    constant-acceleration model whose jerk is white noise of spectral density
//!    [`TrackerSettings::jerk_noise`];
//! 3. each hand marker coordinate that is present corrects it, weighted by that coordinate's
//!    own noise variance (the hand's markers rotate about the wrist centre, the forearm
//!    frame's origin). The measurement is linearised at the hand's own solution when its three
//!    markers are there, or two and the wrist centre (else at the prediction), and again at the
//!    corrected state while that
//!    moves (an iterated EKF: a fast move at a low frame rate, or one near gimbal lock, is not
//!    overshot); markers further from the prediction than its covariance allows
//!    ([`MANOEUVRE_NIS`]) scale that covariance up by as much (a manoeuvre: an impact the
//!    white-jerk model did not expect). e_f is kept within ±90° (past it, the other Euler
//!    triple of the same rotation);
//! 4. the torques follow from the state by Newton–Euler ([`reference::inverse_dynamics_at`],
//!    gravity's direction from the fitted forearm); one beyond what a wrist can take
//!    ([`status::torque_limit`]) marks the frame [`status::IMPLAUSIBLE`].
//!
//! Why it beats a fixed-noise filter (biorbd's `KalmanReconsMarkers`, measured in
//! `docs/ekf.md`): marker noise differs between coordinates and between recordings (the thesis'
//! noise is ±p of each coordinate's range), and no single setting suits clean and noisy
//! markers. The tracker estimates each coordinate's variance from its third differences
//! (white noise of variance σ² gives third differences of variance 20σ²; a smooth marker's
//! are ~1e-7 m at 1 kHz), so clean markers are followed exactly and noisy ones are weighed
//! by how noisy they are. A missing marker simply corrects nothing. Measuring the hand by its
//! orientation ([`TrackerSettings::relative_hand`], on with a calibration), the differences are
//! of each marker's residual to the hand's rigid fit instead: at a real lab's 70–100 Hz a fast
//! hand's own third differences are its motion, not noise (0.2 mm plates read as 1.7 mm).
//!
//! Optionally a learned *refiner* ([`Tracker::set_refiner`]) corrects the estimate: a network
//! over a window of the tracker's own states ([`FeatureSet::TrackerState`]: q̇, q̈ and the
//! measured noise level; not q, so it learns how wrists move, not where) that gives
//! corrections to q and q̈, gated by that noise ([`refiner_gate`]) so clean markers are left
//! as the filter has them, and capped at [`REFINER_TRUST`] standard deviations of the
//! filter's own estimate (a larger one means the network is outside what it learned). It
//! learns what a white-jerk model cannot know — how wrists actually move — and so the lag
//! and the noise the filter leaves (`make models-track`; measured in `docs/ekf.md`). It is
//! applied after the filter and never fed back into it.
//!
//! Never diverging silently: every marker is checked before it is used — a segment whose
//! markers break the rigid shape learned for it, a forearm that jumped faster than a forearm
//! moves, a hand marker too far from the prediction for the filter's own uncertainty — and a
//! rejected marker corrects nothing and teaches no noise. A marker off its segment's shape stays
//! rejected for as long as the shape had held before (a new shape is taken only once as many
//! consecutive frames agree on it), and is taken back as soon as it is in place again. When every
//! usable hand marker has been rejected for [`LOST_S`] — or at once when the hand's present
//! markers agree with one another (three fitting its shape within [`FIT_TOLERANCE_M`], or two and
//! the wrist centre) and are gated all the same — the tracker decides it, not the markers, is
//! wrong and restarts from the frame's own solution. Without any correction the angles go on at
//! their last velocity for [`LOST_S`] (an acceleration is not extrapolated), then hold. Angles
//! stay within one turn. Each output's [`status`] bits say what happened (tests: "a frame
//! shifted by a kilometre", "garbage frames", "a lost hand", "a marker off its place").
//!
//! Allocation-free: the state is fixed-size, so a push costs a few microseconds and no heap.

use nalgebra::{Isometry3, Matrix2, Matrix3, Rotation3, SMatrix, SVector, Translation3, UnitQuaternion, Vector3};

use crate::body::{self, BodyModel, COORDINATES, MARKER_FRAME_LEN, MARKERS, N_COORDINATES, Segment};
use crate::calibration::{Calibration, Side};
use crate::error::{Error, Result};
use crate::features::{FeatureSet, technical_frame};
use crate::model::Model;
use crate::reference::{self, JointState};
use crate::status;
use crate::stream::Stream;

/// State size: angle, velocity and acceleration of each coordinate.
const N_STATE: usize = 3 * N_COORDINATES;
/// Marker coordinates on the hand (the measurement).
const N_HAND: usize = 9;
/// First value of the hand's markers in a frame.
const HAND_START: usize = 3 * 3;
/// Variance of white noise's third difference over the noise's own variance: 1 + 9 + 9 + 1.
const THIRD_DIFFERENCE_GAIN: f64 = 20.0;
/// Noise variance over the mean square of a coordinate's distance from the rigid fit of three
/// markers: the fit takes 6 of the 9 coordinates' degrees of freedom.
const FIT_RESIDUAL_GAIN: f64 = 3.0;
/// Weight of the initial noise guess, in frames: the estimate is the guess for the first few
/// frames and the data's soon after.
const PRIOR_FRAMES: f64 = 10.0;
/// Smallest noise [`TrackerOutput::noise`] reports, m (before any third difference is seen).
pub const MIN_REPORTED_NOISE: f64 = 1e-9;
/// Largest noise sample taken, in current noise variances (a 5σ clip): one glitch cannot
/// inflate the noise estimate (a frame 1 km off made it 18 m), while a real rise in noise is
/// still learned, at most ×25 per memory length.
const NOISE_CLIP: f64 = 25.0;

/// How far a distance between two markers of one segment may stray from what the tracker
/// learned it to be, m, plus [`RIGID_TOLERANCE_REL`] of it: more and a marker is not where
/// that segment could put it (a glitch, a swapped label, another object's marker).
pub const RIGID_TOLERANCE_M: f64 = 0.015;
/// Relative part of the rigid tolerance ([`RIGID_TOLERANCE_M`]): skin markers stretch.
pub const RIGID_TOLERANCE_REL: f64 = 0.15;
/// Fastest a forearm moves, m/s, plus [`JUMP_TOLERANCE_M`]: a faster jump is a glitch.
pub const MAX_SEGMENT_SPEED: f64 = 20.0;
/// Slack on the forearm's jump check, m.
pub const JUMP_TOLERANCE_M: f64 = 0.05;
/// Largest jump of the forearm taken as real once it persists (the subject relabelled, a
/// camera re-calibrated, the first frames the odd ones), m: the size of a capture volume. A
/// farther jump (a frame 1 km off, coordinates in the wrong units) stays rejected however long
/// it lasts.
pub const MAX_RELOCATION_M: f64 = 20.0;
/// Hand marker innovations beyond this squared Mahalanobis distance (3 dof: p ≈ 1e-6) ...
pub const GATE_CHI2: f64 = 30.0;
/// ... and longer than this, m, are rejected as implausible for one frame.
pub const GATE_FLOOR_M: f64 = 0.02;
/// How long every usable marker of a segment may be rejected, s (at least 3 frames), before
/// the tracker decides it, not the markers, is wrong: it then re-learns the forearm's position
/// (its shape only once a new one has held as long as the old one had), or restarts the hand
/// from the frame's own solution ([`status::RESTARTED`]); and how long a state carried forward
/// without correction goes on at its last velocity before it holds.
pub const LOST_S: f64 = 0.03;
/// Squared Mahalanobis distance of the hand markers from the prediction, per coordinate, beyond
/// which the prediction's covariance is scaled up to match it (a manoeuvre).
pub const MANOEUVRE_NIS: f64 = 3.0;
/// How far a hand marker may sit from the rigid fit of the hand's shape to its three markers,
/// m, for the three to count as agreeing with one another.
pub const FIT_TOLERANCE_M: f64 = 0.005;
/// The correction is linearised again at the corrected state while it moves an angle by more
/// than this, rad ...
pub const RELINEARISE_RAD: f64 = 1e-3;
/// ... at most this many times in all.
pub const MAX_ITERATIONS: usize = 5;

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

/// The refiner's corrections are scaled by `σ / (σ + REFINER_GATE_NOISE)`, σ the mean learned
/// hand-marker noise (m): ~1 on noisy markers, → 0 on clean ones, which the filter already
/// follows exactly (a network's own error floor would only add to it there).
pub const REFINER_GATE_NOISE: f64 = 1e-4;

/// Largest refiner correction, in standard deviations of the filter's own estimate.
pub const REFINER_TRUST: f64 = 3.0;

/// The gate on the refiner's corrections at mean marker noise `noise` (m).
pub fn refiner_gate(noise: f64) -> f64 {
    noise / (noise + REFINER_GATE_NOISE)
}
/// The refiner's outputs, in order: corrections to q, then to q̈, per coordinate.
pub fn refiner_outputs() -> Vec<String> {
    ["dq", "dqdd"].iter().flat_map(|k| COORDINATES.iter().map(move |c| format!("{k}.{}", c.name))).collect()
}

type StateVector = SVector<f64, N_STATE>;
/// Each hand marker's predicted position and its motion per radian of each coordinate; the
/// fourth: the point asked for (the wrist centre), zeros without one.
type HandPrediction = ([Vector3<f64>; 4], [[Vector3<f64>; N_COORDINATES]; 4]);
type StateMatrix = SMatrix<f64, N_STATE, N_STATE>;

/// How the tracker models motion and noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerSettings {
    /// Frame rate of the markers, Hz.
    pub rate_hz: f64,
    /// Spectral density of the joint jerk the motion model allows, rad²/s⁵: larger follows
    /// faster moves with less lag and passes more noise.
    pub jerk_noise: f64,
    /// How far back the noise estimate looks, seconds (exponential forgetting).
    pub noise_memory_s: f64,
    /// Standard deviation of marker noise assumed before any has been measured, m.
    pub initial_marker_noise: f64,
    /// Measure the hand's orientation only — its markers relative to their own centroid — not
    /// its position relative to the forearm's frame. The body model knows the wrist centre of a
    /// simulated subject exactly; of a real subject it does not, and a centre a centimetre off
    /// is read as degrees of wrist angle. On with a calibration ([`Tracker::set_calibration`]);
    /// needs two hand markers per frame to correct.
    pub relative_hand: bool,
}

impl Default for TrackerSettings {
    /// 1 kHz; [`DEFAULT_JERK_NOISE`]; a 10 s noise memory; 1 mm noise assumed at first (a
    /// guess too small makes the filter trust its first noisy frames and can throw it off).
    fn default() -> Self {
        TrackerSettings {
            rate_hz: 1000.0,
            jerk_noise: DEFAULT_JERK_NOISE,
            noise_memory_s: 10.0,
            initial_marker_noise: 1e-3,
            relative_hand: false,
        }
    }
}

/// [`TrackerSettings::jerk_noise`]'s default, rad²/s⁵: chosen by `make compare-ekf` on its
/// validation trials (never the test trials) as the grid point whose worst MSE ratio to the best
/// biorbd EKF setting over 0/1/5 % noise, angles and torques, is smallest (`docs/ekf.md`).
pub const DEFAULT_JERK_NOISE: f64 = 3e3;

impl TrackerSettings {
    /// Each setting must be positive and at most what any recording needs: a value beyond is a
    /// typo (or a unit slip) that would make the filter's arithmetic overflow, not a setting.
    fn check(&self) -> Result<()> {
        for (what, v, max, unit) in [
            ("rate_hz", self.rate_hz, 100_000.0, "Hz"),
            ("jerk_noise", self.jerk_noise, 1e12, "rad²/s⁵"),
            ("noise_memory_s", self.noise_memory_s, 86_400.0, "s"),
            ("initial_marker_noise", self.initial_marker_noise, 1.0, "m"),
        ] {
            if !(v > 0.0 && v <= max) {
                return Err(Error::BadArgument {
                    what,
                    detail: format!("is {v}, expected a positive number up to {max:e} {unit}"),
                });
            }
        }
        Ok(())
    }
}

/// One frame's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerOutput {
    /// Angles, velocities and accelerations (rad, rad/s, rad/s²), coordinate order.
    pub state: JointState,
    /// Joint torques, N·m, coordinate order.
    pub tau: [f64; N_COORDINATES],
    /// Bit `i` set: marker `i` ([`MARKERS`] order) was missing in this frame.
    pub missing: u8,
    /// Whether a refiner corrected this estimate (false without one, and while its window fills).
    pub refined: bool,
    /// [`status`] bits: markers rejected, poses held, a restart, an implausible angle.
    pub status: u8,
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

/// The filter's memory between frames. See the [module docs](self).
#[derive(Debug, Clone)]
pub struct Tracker {
    body: BodyModel,
    settings: TrackerSettings,
    transition: StateMatrix,
    process_noise: StateMatrix,
    /// `None` until a frame with every marker started the filter.
    state: Option<(StateVector, StateMatrix)>,
    forearm: Option<Isometry3<f64>>,
    /// The last three frames' hand marker coordinates, newest first (NaN where missing).
    history: [[f64; N_HAND]; 3],
    history_len: usize,
    noise_variance: [f64; N_HAND],
    /// The same estimate from the data alone (no initial guess): what the refiner is told.
    data_variance: [f64; N_HAND],
    noise_samples: [f64; N_HAND],
    frames: usize,
    refiner: Option<Stream>,
    /// Per segment: its rigid shape, as learned.
    shapes: [RigidShape; 2],
    /// Frame index of the forearm's last measured pose, and frames in a row its jump check failed.
    forearm_frame: usize,
    forearm_jumps: usize,
    /// Frames in a row whose present hand markers were all gated, and without any correction.
    gated_streak: usize,
    coast_streak: usize,
    /// Frames still to flag [`status::RESTARTED`] after a restart or a long hold.
    settling: usize,
    restarts: usize,
    /// The subject's placement: each segment's markers in its anatomical frame are taken from
    /// the subject's own markers (their shape as learned, turned by the calibration) instead of
    /// the body model's, once per shape learned (`templated`).
    calibration: Option<Calibration>,
    templated: [bool; 2],
    /// The wrist's centre of rotation, learned from frames with both segments whole (with a
    /// calibration; the body model's own is its segments' common origin).
    centre: JointCentre,
    /// The body model's own marker offsets, restored by [`reset`](Tracker::reset).
    model_offsets: [[f64; 3]; body::N_MARKERS],
    /// Each marker where it sat in its segment lately (a running mean over [`LIVE_PLACEMENT_S`]
    /// of the frames that measured the segment whole): the segment's pose from its other two
    /// markers is the one its three would give.
    live: [Vector3<f64>; body::N_MARKERS],
    /// How the forearm turned while it was measured whole (see [`ForearmTurn`]) ...
    turn: ForearmTurn,
    /// ... and its roll about the line through two of its markers while one is missing.
    roll: Roll,
    /// [`status::torque_limit`] for this subject, N·m.
    torque_limit: f64,
}

/// How the forearm turns between frames, learned from its whole (three-marker) poses: the
/// second difference of its orientation (rad per frame, per frame) is its angular acceleration
/// and its markers' noise; its mean square is how far its roll about the line through two of
/// its markers may stray per frame while the third is missing (see [`Roll`]). A forearm fixed in
/// the lab teaches ~0 (its roll is then held through a gap); a real one moving, what it does.
#[derive(Debug, Clone, Copy)]
struct ForearmTurn {
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
struct Roll {
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
    fn new() -> Self {
        ForearmTurn {
            last: [(usize::MAX, UnitQuaternion::identity()); 2],
            spin: Vector3::zeros(),
            variance: Matrix3::from_diagonal_element(MIN_TURN_VARIANCE),
            samples: 0.0,
        }
    }
}

impl ForearmTurn {
    /// The second difference's variance about the axis `axis` (rad², at least
    /// [`MIN_TURN_VARIANCE`]): how the forearm turns about it.
    fn about(&self, axis: &Vector3<f64>) -> f64 {
        (axis.transpose() * self.variance * axis)[0].max(MIN_TURN_VARIANCE)
    }
}

impl Roll {
    fn idle() -> Self {
        Roll { active: false, rate: 0.0, p: Matrix2::zeros() }
    }
}

impl Tracker {
    /// A tracker for the subject `body` (segment parameters and marker placement).
    pub fn new(body: BodyModel, settings: TrackerSettings) -> Result<Self> {
        settings.check()?;
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
        let mut tracker = Tracker {
            body,
            settings,
            transition,
            process_noise,
            state: None,
            forearm: None,
            history: [[f64::NAN; N_HAND]; 3],
            history_len: 0,
            noise_variance: [0.0; N_HAND],
            data_variance: [0.0; N_HAND],
            noise_samples: [0.0; N_HAND],
            frames: 0,
            refiner: None,
            shapes: [RigidShape::new(); 2],
            forearm_frame: 0,
            forearm_jumps: 0,
            gated_streak: 0,
            coast_streak: 0,
            settling: 0,
            restarts: 0,
            calibration: None,
            templated: [false; 2],
            centre: JointCentre::new(),
            model_offsets: [[0.0; 3]; body::N_MARKERS],
            live: [Vector3::zeros(); body::N_MARKERS],
            turn: ForearmTurn::new(),
            roll: Roll::idle(),
            torque_limit: 0.0,
        };
        // The subject's mass scale: its hand's mass over the default subject's.
        tracker.torque_limit = status::torque_limit(tracker.body.hand.mass / BodyModel::default().hand.mass);
        tracker.model_offsets = tracker.body.marker_offsets;
        tracker.reset();
        Ok(tracker)
    }

    /// Forget everything seen: the next frame with every marker starts the filter again.
    pub fn reset(&mut self) {
        self.state = None;
        self.forearm = None;
        self.history_len = 0;
        self.noise_variance = [self.settings.initial_marker_noise.powi(2); N_HAND];
        self.data_variance = [0.0; N_HAND];
        self.noise_samples = [0.0; N_HAND];
        self.frames = 0;
        self.shapes = [RigidShape::new(); 2];
        self.forearm_frame = 0;
        self.forearm_jumps = 0;
        self.gated_streak = 0;
        self.coast_streak = 0;
        self.settling = 0;
        self.restarts = 0;
        self.templated = [false; 2];
        self.centre = JointCentre::new();
        self.body.marker_offsets = self.model_offsets;
        self.live = self.model_offsets.map(Vector3::from);
        self.turn = ForearmTurn::new();
        self.roll = Roll::idle();
        if let Some(r) = self.refiner.as_mut() {
            r.reset();
        }
    }

    /// Track a subject measured by `calibration` (see [`crate::calibration`]): each segment's
    /// markers are placed in its anatomical frame by the calibration (their shape taken from the
    /// subject's first complete frame), a left arm is mirrored into a right one, and the hand is
    /// measured by its orientation ([`TrackerSettings::relative_hand`]). `None`: the body model's
    /// placement. Starts fresh, as after [`reset`](Self::reset).
    pub fn set_calibration(&mut self, calibration: Option<Calibration>) {
        self.calibration = calibration;
        self.reset();
    }

    /// The calibration in use, if any.
    pub fn calibration(&self) -> Option<&Calibration> {
        self.calibration.as_ref()
    }

    fn relative_hand(&self) -> bool {
        self.settings.relative_hand || self.calibration.is_some()
    }

    /// Places `segment`'s markers in the body model as the calibration says: the markers of
    /// `frame` in the segment's technical frame, turned into its anatomical frame.
    fn take_template(&mut self, segment: Segment, frame: &[f64]) {
        let Some(calibration) = self.calibration else { return };
        let narrow: [f32; MARKER_FRAME_LEN] = std::array::from_fn(|i| frame[i] as f32);
        let Ok((origin, technical)) = technical_frame(&narrow, segment, 0) else { return };
        let t = match segment {
            Segment::Forearm => calibration.forearm,
            Segment::Hand => calibration.hand,
        };
        let first = body::first_marker(segment);
        for k in first..first + 3 {
            let p = Vector3::new(frame[3 * k], frame[3 * k + 1], frame[3 * k + 2]);
            let local = t * (technical.transpose() * (p - origin));
            self.body.marker_offsets[k] = [local.x, local.y, local.z];
            self.live[k] = local;
        }
        self.templated[segment as usize] = true;
        self.shapes[segment as usize].template = self.shapes[segment as usize].learned;
        // The centre was learned in the old placement's frames.
        self.centre = JointCentre::new();
    }

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

    /// The variance per coordinate of the wrist centre as the rigid fit of the hand's three
    /// markers puts it (m²): the learned hand-marker noise, carried by the fit (its position
    /// is their mean; its turn, over their spread, moves the centre by its distance from them),
    /// plus the learned centre's own.
    fn centre_noise_variance(&self, centre: &WristCentre) -> f64 {
        let noise = self.noise_variance.iter().sum::<f64>() / N_HAND as f64;
        let mean = (self.live[3] + self.live[4] + self.live[5]) / 3.0;
        let spread: f64 = (3..6).map(|k| (self.live[k] - mean).norm_squared()).sum();
        let lever = (centre.ch - mean).norm_squared();
        noise * (1.0 / 3.0 + lever / spread.max(1e-6)) + centre.variance
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

    /// Use `model` to refine every estimate (see the [module docs](self)), or none. The model
    /// must read [`FeatureSet::TrackerState`] frames at the tracker's rate and give
    /// [`refiner_outputs`]. Starts fresh: its window fills from the next frame.
    pub fn set_refiner(&mut self, model: Option<Model>) -> Result<()> {
        let Some(model) = model else {
            self.refiner = None;
            return Ok(());
        };
        let name = model.card().name.clone();
        let bad = |detail: String| {
            Err(Error::BadArgument {
                what: "refiner",
                detail: format!("model {name:?} cannot refine a tracker: {detail}"),
            })
        };
        if model.feature_set() != FeatureSet::TrackerState {
            return bad(format!(
                "it reads {} frames, not {}",
                model.feature_set().name(),
                FeatureSet::TrackerState.name()
            ));
        }
        let names: Vec<String> = model.card().outputs.iter().map(|o| o.name.clone()).collect();
        if names != refiner_outputs() {
            return bad(format!("its outputs are [{}], expected [{}]", names.join(", "), refiner_outputs().join(", ")));
        }
        let rate = model.card().frame_rate_hz;
        if (rate - self.settings.rate_hz).abs() > 1e-6 * self.settings.rate_hz {
            return bad(format!("it was trained at {rate} Hz, the tracker runs at {} Hz", self.settings.rate_hz));
        }
        self.refiner = Some(model.stream());
        Ok(())
    }

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

    /// The refinement model in use, if any.
    pub fn refiner(&self) -> Option<&Model> {
        self.refiner.as_ref().map(|s| s.model())
    }

    /// The subject tracked.
    pub fn body(&self) -> &BodyModel {
        &self.body
    }

    /// The settings in use.
    pub fn settings(&self) -> &TrackerSettings {
        &self.settings
    }

    /// Each hand marker coordinate's current noise estimate (standard deviation, m), in frame
    /// order (`MC2.x` first).
    pub fn marker_noise(&self) -> [f64; N_HAND] {
        self.noise_variance.map(f64::sqrt)
    }

    /// Take one marker frame ([`MARKER_FRAME_LEN`] values, metres, lab frame; NaN = missing)
    /// and return the estimate for it, or `None` while the filter has not started (it starts on
    /// the first frame with every marker). Frames must come at [`TrackerSettings::rate_hz`].
    ///
    /// Markers are checked before they are used (see [`status`]): a segment whose markers break
    /// its learned rigid shape, a forearm that jumped faster than [`MAX_SEGMENT_SPEED`], a hand
    /// marker too far from the prediction ([`GATE_CHI2`], [`GATE_FLOOR_M`]) are rejected for
    /// that frame and learn no noise. When every usable hand marker has been rejected for
    /// [`LOST_S`], the tracker restarts from the frame's own solution; a forearm whose position
    /// is broken that long is re-learned, a segment's shape once a new one has held as long as
    /// the old one had. An infinite value is an error (NaN means missing); nothing else a frame
    /// holds stops the tracker.
    pub fn push(&mut self, frame: &[f64]) -> Result<Option<TrackerOutput>> {
        let index = self.frames;
        if frame.len() != MARKER_FRAME_LEN {
            return Err(Error::FrameLength { feature_set: "markers", found: frame.len(), expected: MARKER_FRAME_LEN });
        }
        if let Some(i) = frame.iter().position(|v| v.is_infinite()) {
            return Err(Error::NonFiniteInput {
                frame: index,
                field: format!("{}.{}", MARKERS[i / 3].name, ["x", "y", "z"][i % 3]),
                value: frame[i] as f32,
            });
        }
        self.frames += 1;
        let lost = self.lost_frames();
        let missing = missing_markers(frame);
        let mut flags = 0u8;
        // Markers no arm could hold (wrong units, a ghost far away) are all rejected.
        let mut checked = [f64::NAN; MARKER_FRAME_LEN];
        if body::check_marker_span(frame, index).is_ok() {
            checked.copy_from_slice(frame);
        } else {
            flags |= status::REJECTED_MARKER;
        }
        if self.calibration.is_some_and(|c| c.side == Side::Left) {
            for z in checked.iter_mut().skip(2).step_by(3) {
                *z = -*z;
            }
        }
        let frame = &checked[..];

        // 1. The forearm: measured if its markers are present, rigid as learned and not jumped.
        let mut forearm_measured = false;
        // Its markers that may be used: present, and (two or three of them) rigid as learned.
        let mut forearm_usable = !missing & FOREARM_MARKERS;
        if missing & FOREARM_MARKERS == 0 {
            let (rejected, relearned) = self.check_rigid(Segment::Forearm, frame, lost);
            if relearned {
                flags |= status::RESTARTED;
                self.templated[Segment::Forearm as usize] = false;
            }
            if rejected == 0 && !self.templated[Segment::Forearm as usize] {
                self.take_template(Segment::Forearm, frame);
            }
            forearm_usable &= !rejected;
            if rejected == 0
                && let Ok(pose) = reference::fit_segment(&self.body, frame, Segment::Forearm, index)
            {
                if self.forearm_plausible(&pose, index, lost) {
                    self.forearm = Some(pose);
                    self.forearm_frame = index;
                    forearm_measured = true;
                    self.follow_placement(Segment::Forearm, &pose, frame);
                    self.learn_turn(&pose, index);
                } else {
                    forearm_usable = 0; // the whole forearm jumped: nothing of it is used
                }
            }
            if !forearm_measured {
                flags |= status::REJECTED_MARKER;
            }
        } else if forearm_usable.count_ones() == 2 {
            let (rejected, _) = self.check_rigid(Segment::Forearm, frame, lost);
            if rejected != 0 {
                forearm_usable = 0;
                flags |= status::REJECTED_MARKER;
            }
        }

        // 2. The hand's markers: NaN where missing or breaking the hand's rigid shape.
        let mut hand: [f64; N_HAND] = std::array::from_fn(|i| frame[HAND_START + i]);
        let (rejected, relearned) = self.check_rigid(Segment::Hand, frame, lost);
        if relearned {
            flags |= status::RESTARTED;
            self.templated[Segment::Hand as usize] = false;
        }
        if rejected == 0 && missing >> 3 == 0 && !self.templated[Segment::Hand as usize] {
            self.take_template(Segment::Hand, frame);
        }
        reject_hand_markers(&mut hand, rejected >> 3);
        if rejected != 0 {
            flags |= status::REJECTED_MARKER;
        }
        let hand_complete = hand.iter().all(|v| !v.is_nan());

        // 1b. A forearm with one marker missing or rejected: its pose from the two others and
        // the wrist centre (see `forearm_from_two`), if that is a pose it could have reached.
        let mut forearm_estimated = false;
        // The wrist centre, solved once in a frame that needs it.
        let mut memo = None;
        if !forearm_measured
            && forearm_usable.count_ones() == 2
            && self.templated[Segment::Forearm as usize] | self.calibration.is_none()
            && let Some((pose, roll)) =
                self.forearm_from_two(frame, forearm_usable, &hand, self.centre_memo(&mut memo), index)
            && self.forearm_plausible(&pose, index, lost)
        {
            self.forearm = Some(pose);
            self.roll = roll;
            self.forearm_frame = index;
            forearm_estimated = true;
        }
        if !forearm_measured && !forearm_estimated && self.forearm.is_some() {
            flags |= status::HELD;
        }
        let forearm_seen = forearm_measured || forearm_estimated;

        let Some(forearm) = self.forearm else {
            self.learn_noise(&hand, index);
            return Ok(None);
        };
        let (mut x, mut p) = match self.state {
            Some((x, p)) => {
                (self.transition * x, self.transition * p * self.transition.transpose() + self.process_noise)
            }
            None => {
                let placed = self.calibration.is_none() || self.templated == [true; 2];
                let start = if forearm_measured && hand_complete && placed {
                    self.frame_solution(&forearm, frame, index)
                } else {
                    None
                };
                let Some(x) = start else {
                    self.learn_noise(&hand, index);
                    return Ok(None);
                };
                (x, self.initial_covariance())
            }
        };

        // 3. Gate the hand markers on the prediction; restart when the wrist is lost.
        let present = hand_markers_present(&hand);
        let ungated = hand;
        let gated = self.gate(&forearm, &hand, &x, &p);
        reject_hand_markers(&mut hand, gated);
        if gated != 0 {
            flags |= status::REJECTED_MARKER;
        }
        let used = hand_markers_present(&hand);
        self.gated_streak = if present != 0 && used == 0 { self.gated_streak + 1 } else { 0 };
        // Every hand marker present agreeing with the hand's shape (three fitting it, or two and
        // the wrist centre), yet gated: the markers agree with one another, not with the filter
        // — the filter is what is wrong (a fast move it could not follow, a gap it coasted
        // through), so restart now rather than after `lost`, from the hand's own pose.
        let own = if forearm_seen && (gated != 0 || self.gated_streak >= lost) {
            let centre = if present.count_ones() == 2 { self.centre_memo(&mut memo) } else { None };
            self.hand_pose(&forearm, &ungated, &x, centre, index)
        } else {
            None
        };
        let fits = gated != 0
            && match own {
                Some(_) if present == 0b111 => self.hand_fits(&ungated, index),
                Some((_, miss)) => self.centre_memo(&mut memo).is_some_and(|c| miss <= c.tolerance()),
                None => false,
            };
        if (self.gated_streak >= lost || fits)
            && let Some((pose, _)) = own
        {
            (x, p) = (self.solution(&forearm, &pose), self.initial_covariance());
            hand = ungated;
            self.gated_streak = 0;
            self.restarts += 1;
            self.settling = lost;
            if let Some(r) = self.refiner.as_mut() {
                r.reset();
            }
        }
        let coasted = self.coast_streak;
        self.coast_streak = if hand_markers_present(&hand) == 0 { self.coast_streak + 1 } else { 0 };
        if self.coast_streak == 0 && coasted >= lost {
            // Corrected again after holding: the velocities and accelerations start over.
            self.settling = self.settling.max(lost);
        }
        if self.settling > 0 {
            // A restart and the frames after it while q̇ and q̈ (so the torques) settle.
            flags |= status::RESTARTED;
            self.settling -= 1;
        }
        if self.coast_streak > 0 {
            flags |= status::HELD;
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
        if missing != 0 {
            flags |= status::FILLED;
        }
        self.learn_noise(&hand, index);
        let used = hand_markers_present(&hand);
        // Two hand markers measured relative to each other leave the hand's turn about the line
        // through them open: the wrist centre, fixed in the forearm, closes it.
        let centre = if used.count_ones() == 2 { self.centre_memo(&mut memo) } else { None };
        // The hand's own pose, from its three markers or two and the centre.
        let pose = if forearm_seen { self.hand_pose(&forearm, &hand, &x, centre, index) } else { None };
        if let Some((whole, _)) = pose
            && used == 0b111
        {
            let mut markers = [0.0; MARKER_FRAME_LEN];
            markers[HAND_START..].copy_from_slice(&hand);
            self.follow_placement(Segment::Hand, &whole, &markers);
            if forearm_measured && self.calibration.is_some() && self.templated == [true; 2] {
                // Both segments whole and agreeing with the filter: a frame for the wrist centre.
                let forget = 1.0 / (CENTRE_MEMORY_S * self.settings.rate_hz);
                self.centre.add(&forearm, &whole, forget);
            }
        }
        // Linearise first at the hand's own solution (the Euler triple nearest the prediction):
        // near gimbal lock the prediction can be far off in angles while near in rotation, and
        // the iterations then start in the right place.
        let start = pose.map(|(pose, _)| nearest_triple(&self.solution(&forearm, &pose), &x));
        let centre = if self.relative_hand() { centre } else { None };
        self.correct(&forearm, &hand, centre, start, &mut x, &mut p);
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
        self.state = Some((x, p));
        let mut state = JointState { q: [x[0], x[1], x[2]], qd: [x[3], x[4], x[5]], qdd: [x[6], x[7], x[8]] };
        // The data's own estimate (floored: none yet in the first frames), so that clean
        // markers read as clean at once rather than as the fading initial guess.
        let noise = (self.data_variance.iter().map(|v| v.sqrt()).sum::<f64>() / N_HAND as f64).max(MIN_REPORTED_NOISE);
        let mut refined = false;
        if let Some(refiner) = self.refiner.as_mut() {
            let mut frame = [0f32; N_STATE + 1];
            for (f, v) in frame.iter_mut().zip(x.iter()) {
                *f = *v as f32;
            }
            frame[N_STATE] = noise.log10() as f32;
            if let Some(out) = refiner.push(&frame).map_err(|e| e.renumbered(index))? {
                let per_unit = refiner_gate(noise);
                // A correction beyond REFINER_TRUST filter standard deviations is not one the
                // filter's own uncertainty allows: the network is outside what it learned.
                let trust = |value: f64, variance: f64| {
                    let limit = REFINER_TRUST * variance.max(0.0).sqrt();
                    value.clamp(-limit, limit)
                };
                for c in 0..N_COORDINATES {
                    state.q[c] += trust(f64::from(out[c]) * per_unit, p[(c, c)]);
                    state.qdd[c] += trust(f64::from(out[N_COORDINATES + c]) * per_unit, p[(6 + c, 6 + c)]);
                }
                refined = true;
            }
        }
        if (0..N_COORDINATES).any(|c| status::angle_implausible(c, state.q[c])) {
            flags |= status::IMPLAUSIBLE;
        }
        let tau = reference::inverse_dynamics_at(&self.body, &forearm.rotation.to_rotation_matrix(), &state)?;
        if tau.iter().any(|&t| status::torque_implausible(t, self.torque_limit)) {
            flags |= status::IMPLAUSIBLE;
        }
        Ok(Some(TrackerOutput { state, tau, missing, refined, status: flags, noise }))
    }

    /// How many times the tracker lost the hand and restarted from a frame's own solution.
    pub fn restarts(&self) -> usize {
        self.restarts
    }

    /// [`LOST_S`] in frames at the tracker's rate, at least 3.
    fn lost_frames(&self) -> usize {
        ((LOST_S * self.settings.rate_hz).ceil() as usize).max(3)
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

    /// Moves each of `segment`'s markers' recent placement ([`Tracker::live`]) towards where
    /// `frame` has it in the segment's pose `pose`.
    fn follow_placement(&mut self, segment: Segment, pose: &Isometry3<f64>, frame: &[f64]) {
        let w = (1.0 / (LIVE_PLACEMENT_S * self.settings.rate_hz)).min(1.0);
        let first = body::first_marker(segment);
        for k in first..first + 3 {
            let p = nalgebra::Point3::new(frame[3 * k], frame[3 * k + 1], frame[3 * k + 2]);
            let local = pose.inverse_transform_point(&p).coords;
            self.live[k] += w * (local - self.live[k]);
        }
    }

    /// The hand's pose from its markers in `hand` (NaN where missing): fitted to its three, or
    /// to two and the wrist centre (fixed in `forearm`) for the turn about the line through
    /// them; with how far the hand then puts the centre from the forearm's (0 with three).
    fn hand_pose(
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

    /// The wrist centre, solved at most once a frame (`memo`: `None` until solved).
    fn centre_memo(&self, memo: &mut Option<Option<WristCentre>>) -> Option<WristCentre> {
        *memo.get_or_insert_with(|| self.wrist_centre())
    }

    /// The state at the hand's pose `hand` in `forearm` (at rest).
    fn solution(&self, forearm: &Isometry3<f64>, hand: &Isometry3<f64>) -> StateVector {
        let q0 = body::wrist_angles(&(forearm.rotation.inverse() * hand.rotation).to_rotation_matrix());
        let mut x = StateVector::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(&Vector3::from(q0));
        x
    }

    /// Whether the three markers of `hand` sit where the hand's shape puts them, each within
    /// [`FIT_TOLERANCE_M`] of the rigid fit of the shape to them (none of them an outlier).
    fn hand_fits(&self, hand: &[f64; N_HAND], index: usize) -> bool {
        self.fit_residual(hand, index).is_some_and(|r| {
            r.chunks_exact(3).all(|m| m.iter().map(|v| v * v).sum::<f64>() <= FIT_TOLERANCE_M * FIT_TOLERANCE_M)
        })
    }

    /// Checks a segment's present markers against the distances between them learned so far
    /// (learning them on the first complete frame, then following them slowly). Returns the
    /// frame-marker bits of the markers rejected, and whether a new shape was learned (its
    /// template must be taken again; see [`RigidShape`]). One broken distance rejects the
    /// marker of its pair that moved against the third marker since the shape was last kept
    /// (both when that does not tell), two the marker they share, three all.
    fn check_rigid(&mut self, segment: Segment, frame: &[f64], lost: usize) -> (u8, bool) {
        let s = segment as usize;
        let first = body::first_marker(segment);
        let points: [Vector3<f64>; 3] = std::array::from_fn(|k| {
            Vector3::new(frame[3 * (first + k)], frame[3 * (first + k) + 1], frame[3 * (first + k) + 2])
        });
        let distances: [f64; 3] = SHAPE_PAIRS.map(|(a, b)| (points[a] - points[b]).norm());
        let complete = distances.iter().all(|&d| d > 0.0);
        let shape = &mut self.shapes[s];
        let Some(learned) = shape.learned else {
            if complete {
                *shape = RigidShape { learned: Some(distances), support: 1.0, last: points, ..RigidShape::new() };
            }
            return (0, false);
        };
        let broken: [bool; 3] = std::array::from_fn(|i| !d_agrees(distances[i], learned[i]));
        let n_broken = broken.iter().filter(|&&b| b).count();
        if n_broken == 0 {
            shape.candidate = None;
            shape.candidate_frames = 0;
            let forget = 1.0 / self.settings.rate_hz; // a one-second memory
            let w = (1.0 / (shape.support + 1.0)).max(forget);
            let mut kept = learned;
            for (l, d) in kept.iter_mut().zip(distances) {
                if !d.is_nan() {
                    *l += w * (d - *l);
                }
            }
            shape.learned = Some(kept);
            shape.support += 1.0;
            if complete {
                shape.last = points;
            }
            return (0, false);
        }
        if complete {
            // Another shape: taken once as many consecutive complete frames agree on it as
            // agreed with the one learned (at least `lost`), at once if it is the shape the
            // template was taken from (a marker coming back). A marker off its place for less
            // long than it was in place stays rejected however long it lasts.
            match shape.candidate {
                Some(c) if shapes_agree(&distances, &c) => shape.candidate_frames += 1,
                _ => {
                    shape.candidate = Some(distances);
                    shape.candidate_frames = 1;
                }
            }
            let back = shape.template.is_some_and(|t| shapes_agree(&distances, &t));
            let needed = if back { 1 } else { lost.max(shape.support as usize) };
            if shape.candidate_frames >= needed {
                let frames = shape.candidate_frames;
                *shape = RigidShape {
                    learned: Some(distances),
                    support: frames as f64,
                    template: shape.template,
                    last: points,
                    ..RigidShape::new()
                };
                return (0, !back);
            }
        }
        let mut bad = 0u8;
        for (i, &(a, b)) in SHAPE_PAIRS.iter().enumerate() {
            if broken[i] {
                bad |= 1 << a | 1 << b;
            }
        }
        match n_broken {
            1 => {
                let i = broken.iter().position(|&b| b).unwrap_or(0);
                let (a, b) = SHAPE_PAIRS[i];
                let c = 3 - a - b;
                // How far each moved against the third since the shape was last kept.
                let moved = |k: usize| ((points[k] - points[c]) - (shape.last[k] - shape.last[c])).norm();
                let (ma, mb) = (moved(a), moved(b));
                if ma > 2.0 * mb {
                    bad = 1 << a;
                } else if mb > 2.0 * ma {
                    bad = 1 << b;
                }
            }
            2 => {
                let shared =
                    (0..3).find(|&k| SHAPE_PAIRS.iter().zip(broken).all(|(&(a, b), br)| !br || a == k || b == k));
                if let Some(k) = shared {
                    bad = 1 << k;
                }
            }
            _ => {}
        }
        (bad << first, false)
    }

    /// Whether the forearm's newly fitted pose is one it could have reached since its last
    /// measured one (accepting it anyway once the jump has persisted `lost` frames).
    fn forearm_plausible(&mut self, pose: &Isometry3<f64>, index: usize, lost: usize) -> bool {
        let Some(last) = self.forearm else { return true };
        let elapsed = (index - self.forearm_frame) as f64 / self.settings.rate_hz;
        let jump = (pose.translation.vector - last.translation.vector).norm();
        if jump <= MAX_SEGMENT_SPEED * elapsed + JUMP_TOLERANCE_M {
            self.forearm_jumps = 0;
            return true;
        }
        self.forearm_jumps += 1;
        if self.forearm_jumps >= lost && jump <= MAX_RELOCATION_M {
            self.forearm_jumps = 0;
            return true;
        }
        false
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
    fn hand_prediction(
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

    /// Pushes every frame of `frames` ([`MARKER_FRAME_LEN`] values each, back to back) in
    /// order, exactly as [`push`](Self::push) one at a time, and hands each frame's result to
    /// `each(i, output, estimated)`: its estimate (`estimated` true), or, before the filter
    /// started, [`TrackerOutput::waiting`] with the frame's missing markers (`estimated` false).
    /// Returns the index of the first frame with an estimate: 0 when the filter was already
    /// running, `None` if no frame of the block started it. Continues from the tracker's state.
    ///
    /// A block that is not a whole number of frames is refused before anything is pushed. A
    /// refused frame (an infinite value, degenerate markers, ...) stops the run with its error,
    /// numbered by its index in `frames`; the frames before it stay pushed (and were handed to
    /// `each`). Does not allocate (beyond what `each` does).
    pub fn run(&mut self, frames: &[f64], mut each: impl FnMut(usize, &TrackerOutput, bool)) -> Result<Option<usize>> {
        if !frames.len().is_multiple_of(MARKER_FRAME_LEN) {
            return Err(Error::BadArgument {
                what: "frames",
                detail: format!("{} values is not a whole number of {MARKER_FRAME_LEN}-value frames", frames.len()),
            });
        }
        let mut start = None;
        for (i, frame) in frames.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            match self.push(frame).map_err(|e| e.renumbered(i))? {
                Some(out) => {
                    start.get_or_insert(i);
                    each(i, &out, true);
                }
                None => each(i, &TrackerOutput::waiting(missing_markers(frame)), false),
            }
        }
        Ok(start)
    }

    /// Wide enough for any wrist motion: angles within ~0.1 rad of the first frame's fit,
    /// velocities to ~30 rad/s, accelerations to ~300 rad/s².
    fn initial_covariance(&self) -> StateMatrix {
        let mut p = StateMatrix::zeros();
        for c in 0..N_COORDINATES {
            p[(c, c)] = 1e-2;
            p[(3 + c, 3 + c)] = 1e3;
            p[(6 + c, 6 + c)] = 1e5;
        }
        p
    }

    /// Update each coordinate's noise variance from its newest third difference (skipped where
    /// a marker was missing in any of the four frames). With [`TrackerSettings::relative_hand`],
    /// the third difference of its distance from the rigid fit of the hand's shape (skipped
    /// unless all three hand markers were there): at a low frame rate a fast hand's third
    /// differences are its motion, not noise, and a skin marker's slow slide is not noise the
    /// filter can average either; the fit's residual removes the first, the difference the second.
    fn learn_noise(&mut self, hand: &[f64; N_HAND], index: usize) {
        let now = if self.relative_hand() {
            self.fit_residual(hand, index).map_or([f64::NAN; N_HAND], |r| r.map(|v| v * FIT_RESIDUAL_GAIN.sqrt()))
        } else {
            *hand
        };
        if self.history_len == 3 {
            for (i, &now) in now.iter().enumerate() {
                let [a, b, c] = [self.history[0][i], self.history[1][i], self.history[2][i]];
                let d3 = now - 3.0 * a + 3.0 * b - c;
                if d3.is_finite() {
                    self.add_noise_sample(i, d3 * d3 / THIRD_DIFFERENCE_GAIN);
                }
            }
        }
        self.history = [now, self.history[0], self.history[1]];
        self.history_len = (self.history_len + 1).min(3);
    }

    fn add_noise_sample(&mut self, i: usize, sample: f64) {
        let forget = 1.0 / (self.settings.noise_memory_s * self.settings.rate_hz);
        let sample = sample.min(NOISE_CLIP * self.noise_variance[i].max(self.data_variance[i]));
        let w = (1.0 / (self.noise_samples[i] + PRIOR_FRAMES)).max(forget);
        self.noise_variance[i] += w * (sample - self.noise_variance[i]);
        let w = (1.0 / (self.noise_samples[i] + 1.0)).max(forget);
        self.data_variance[i] += w * (sample - self.data_variance[i]);
        self.noise_samples[i] += 1.0;
    }

    /// Each hand marker coordinate of `hand` minus the rigid fit of the hand's shape (as placed
    /// in the body model) to the three, m; `None` unless all three are present and the shape
    /// is the subject's (after a calibration's template is taken).
    fn fit_residual(&self, hand: &[f64; N_HAND], index: usize) -> Option<[f64; N_HAND]> {
        if hand.iter().any(|v| v.is_nan()) || (self.calibration.is_some() && !self.templated[Segment::Hand as usize]) {
            return None;
        }
        let mut frame = [0.0; MARKER_FRAME_LEN];
        frame[HAND_START..].copy_from_slice(hand);
        let pose = reference::fit_segment(&self.body, &frame, Segment::Hand, index).ok()?;
        let fitted: [Vector3<f64>; 3] = std::array::from_fn(|m| {
            pose.transform_vector(&Vector3::from(self.body.marker_offsets[3 + m])) + pose.translation.vector
        });
        Some(std::array::from_fn(|i| hand[i] - fitted[i / 3][i % 3]))
    }

    /// The Kalman correction by the present hand marker coordinates, one scalar at a time (the
    /// noise is independent between coordinates), linearised at the prediction and then, while
    /// the correction moves an angle by more than [`RELINEARISE_RAD`], again at the corrected
    /// state (an iterated EKF, at most [`MAX_ITERATIONS`] times): a large correction — a fast
    /// move at a low frame rate, or near gimbal lock — is not overshot.
    fn correct(
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
        while iteration < MAX_ITERATIONS {
            let Some((predicted, jac)) = self.hand_prediction(forearm, &at, hand, centre.map(|c| c.ch)) else {
                return;
            };
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
                    let (z, variance) = match (m, world, centre) {
                        (3, Some(world), Some(c)) => (world[k], c.variance),
                        (3, _, _) => break,
                        _ => (hand[3 * m + k], self.noise_variance[3 * m + k]),
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
                    nis += innovation * innovation / s;
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

/// How long a marker's recent placement on its segment looks back, s (see [`Tracker::push`]):
/// skin markers slide with the posture, and the pose from two of a segment's markers is the
/// three's only with the two where they sit now, not where they sat when the shape was taken.
pub const LIVE_PLACEMENT_S: f64 = 0.1;

/// Marker pairs of a segment whose distances make its shape (indices within the segment).
const SHAPE_PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];

/// Whether a distance `d` between two markers is the learned `l`, within the rigid tolerance
/// ([`RIGID_TOLERANCE_M`], [`RIGID_TOLERANCE_REL`]); a NaN distance (a marker missing) agrees.
fn d_agrees(d: f64, l: f64) -> bool {
    d.is_nan() || (d - l).abs() <= RIGID_TOLERANCE_M + RIGID_TOLERANCE_REL * l
}

/// Whether two shapes (the three distances of a segment) are one within the rigid tolerance.
fn shapes_agree(a: &[f64; 3], b: &[f64; 3]) -> bool {
    (0..3).all(|i| d_agrees(a[i], b[i]))
}

/// What the tracker knows of one segment's rigid shape (see `Tracker::check_rigid`).
#[derive(Debug, Clone, Copy)]
struct RigidShape {
    /// The distances between its markers (01, 02, 12) as learned, and how many frames agreed.
    learned: Option<[f64; 3]>,
    support: f64,
    /// Another shape, seen in consecutive complete frames that agree with one another, and how many.
    candidate: Option<[f64; 3]>,
    candidate_frames: usize,
    /// The shape the segment's template was taken from (with a calibration).
    template: Option<[f64; 3]>,
    /// The segment's markers in the last complete frame that kept the shape.
    last: [Vector3<f64>; 3],
}

impl RigidShape {
    fn new() -> Self {
        RigidShape {
            learned: None,
            support: 0.0,
            candidate: None,
            candidate_frames: 0,
            template: None,
            last: [Vector3::repeat(f64::NAN); 3],
        }
    }
}

/// The wrist's centre of rotation learned from the subject's own frames (a functional joint
/// centre, as SCoRE): the point `c_f` fixed in the forearm and `c_h` fixed in the hand that stay
/// together, `R_f c_f + t_f = R_h c_h + t_h`, by least squares over the frames where both
/// segments' poses were measured whole (exponential forgetting over [`CENTRE_MEMORY_S`]), pulled
/// weakly towards the point midway between the two segments' origins of the first such frame
/// (what rotations about one axis leave undetermined). Fixed-size: no allocation.
#[derive(Debug, Clone, Copy)]
struct JointCentre {
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
struct WristCentre {
    cf: Vector3<f64>,
    ch: Vector3<f64>,
    variance: f64,
    shift: SMatrix<f64, POSTURE_FEATURES, 3>,
}

impl WristCentre {
    /// The body model's own: both segments' origins.
    fn origins() -> Self {
        WristCentre {
            cf: Vector3::zeros(),
            ch: Vector3::zeros(),
            variance: CENTRE_MIN_STD_M * CENTRE_MIN_STD_M,
            shift: SMatrix::zeros(),
        }
    }

    /// How far the hand may put the centre from the forearm's for its markers to count as
    /// agreeing with it, m: [`FIT_TOLERANCE_M`] plus three standard deviations of the centre.
    fn tolerance(&self) -> f64 {
        FIT_TOLERANCE_M + 3.0 * self.variance.sqrt()
    }

    /// The forearm's point where the hand's `ch` sits with the hand at `relative` in the forearm.
    fn forearm_point(&self, relative: &Matrix3<f64>) -> Vector3<f64> {
        self.cf + self.shift.transpose() * posture_features(relative)
    }
}

impl JointCentre {
    fn new() -> Self {
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

    fn add(&mut self, forearm: &Isometry3<f64>, hand: &Isometry3<f64>, forget: f64) {
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
    fn solve(&self, min_frames: usize) -> Option<WristCentre> {
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

/// The rigid motion taking the `template` points onto the `measured` ones by weighted least
/// squares (Kabsch); `None` if they are collinear.
fn fit_points(template: &[Vector3<f64>; 3], measured: &[Vector3<f64>; 3], weights: [f64; 3]) -> Option<Isometry3<f64>> {
    let total: f64 = weights.iter().sum();
    let tc = (0..3).map(|k| template[k] * weights[k]).sum::<Vector3<f64>>() / total;
    let mc = (0..3).map(|k| measured[k] * weights[k]).sum::<Vector3<f64>>() / total;
    let h: Matrix3<f64> = (0..3).map(|k| (template[k] - tc) * (measured[k] - mc).transpose() * weights[k]).sum();
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    if svd.singular_values.iter().filter(|&&s| s > 1e-15).count() < 2 {
        return None;
    }
    let d = (v_t.transpose() * u.transpose()).determinant().signum();
    let r = v_t.transpose() * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let translation = mc - rotation * tc;
    Some(Isometry3::from_parts(Translation3::from(translation), rotation))
}

/// Frame-marker bits of the forearm's markers.
const FOREARM_MARKERS: u8 = 0b000_111;

/// Sets hand markers `bits` (0–2) of `hand` to NaN: not used.
fn reject_hand_markers(hand: &mut [f64; N_HAND], bits: u8) {
    for m in 0..3 {
        if bits & (1 << m) != 0 {
            hand[3 * m..3 * m + 3].fill(f64::NAN);
        }
    }
}

/// Bits 0–2: hand markers with all three coordinates present.
fn hand_markers_present(hand: &[f64; N_HAND]) -> u8 {
    (0..3).filter(|&m| hand[3 * m..3 * m + 3].iter().all(|v| !v.is_nan())).fold(0, |b, m| b | 1 << m)
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
fn nearest_triple(solution: &StateVector, x: &StateVector) -> Vector3<f64> {
    use std::f64::consts::PI;
    let near = |q: [f64; 3]| Vector3::from_fn(|i, _| x[i] + wrap_angle(q[i] - x[i]));
    let a = near([solution[0], solution[1], solution[2]]);
    let b = near([solution[0] + PI, PI - solution[1], solution[2] + PI]);
    let distance = |q: &Vector3<f64>| (0..3).map(|i| (q[i] - x[i]).powi(2)).sum::<f64>();
    if distance(&b) < distance(&a) { b } else { a }
}

/// `a` (rad) moved by whole turns into (−π, π].
fn wrap_angle(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if a > -PI && a <= PI { a } else { a - TAU * ((a - PI) / TAU).ceil() }
}

/// Bit `i` set: marker `i` of `frame` ([`MARKERS`] order) has a NaN coordinate.
pub fn missing_markers(frame: &[f64]) -> u8 {
    frame
        .chunks_exact(3)
        .enumerate()
        .filter(|(_, xyz)| xyz.iter().any(|v| v.is_nan()))
        .fold(0, |bits, (m, _)| bits | 1 << m)
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {
    use super::*;
    use crate::body::BodyModel;
    use crate::calibration::Calibration;
    use crate::noise::uniform_range;
    use std::f64::consts::{PI, TAU};

    fn trajectory(n: usize, rate: f64) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let t = i as f64 / rate;
                [0.6 * (1.3 * t).sin(), -0.5 * (0.9 * t + 0.4).sin(), 0.2 * (1.7 * t).cos()]
            })
            .collect()
    }

    fn frames(body: &BodyModel, q: &[[f64; 3]], shoulder: f64) -> Vec<f64> {
        body.marker_frames(&q.concat(), shoulder).unwrap()
    }

    /// Runs `f` through a fresh tracker; per frame, the angles (NaN before the start) and status.
    fn track(f: &[f64], rate: f64) -> (Vec<[f64; 3]>, Vec<u8>, Tracker) {
        let settings = TrackerSettings { rate_hz: rate, ..Default::default() };
        let mut tracker = Tracker::new(BodyModel::default(), settings).unwrap();
        let (mut q, mut st) = (vec![], vec![]);
        tracker
            .run(f, |_, o, _| {
                q.push(o.state.q);
                st.push(o.status);
            })
            .unwrap();
        (q, st, tracker)
    }

    fn worst_deg(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
        a.iter().zip(b).flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs().to_degrees())).fold(0.0, f64::max)
    }

    #[test]
    fn a_burst_a_kilometre_off_stays_rejected_and_a_real_relocation_is_taken() {
        let body = BodyModel::default();
        let q = trajectory(2000, 1000.0);
        let clean = frames(&body, &q, 0.2);
        let (good, _, _) = track(&clean, 1000.0);
        for (shift, taken) in [(1000.0, false), (1.0, true)] {
            // 100 frames (more than LOST_S): the 1 km ones stay rejected and flagged, then the
            // tracker goes on as if they never came; the 1 m ones are a relocation, taken.
            let mut f = clean.clone();
            for v in &mut f[1000 * MARKER_FRAME_LEN..1100 * MARKER_FRAME_LEN] {
                *v += shift;
            }
            let (est, status, _) = track(&f, 1000.0);
            let flagged = status[1000..1100].iter().filter(|s| *s & status::REJECTED_MARKER != 0).count();
            if taken {
                assert!(flagged < 100, "{shift} m: {flagged} of 100 rejected");
            } else {
                assert_eq!(flagged, 100, "{shift} m");
                let after = worst_deg(&good[1200..], &est[1200..]); // 100 ms after the burst
                assert!(after < 0.01, "{after}° off after the burst");
            }
        }
    }

    #[test]
    fn a_frame_shifted_by_a_kilometre_is_rejected_and_poisons_nothing() {
        // Issue #22 case 1: it used to teach the tracker 18 m of noise and leave it 871° off.
        let body = BodyModel::default();
        let q = trajectory(3000, 1000.0);
        let clean = frames(&body, &q, 0.2);
        let mut glitched = clean.clone();
        for v in &mut glitched[1000 * MARKER_FRAME_LEN..1001 * MARKER_FRAME_LEN] {
            *v += 1000.0;
        }
        let (good, _, clean_tracker) = track(&clean, 1000.0);
        let (bad, status, tracker) = track(&glitched, 1000.0);
        assert!(status[1000] & status::REJECTED_MARKER != 0 && status[1000] & status::HELD != 0, "{}", status[1000]);
        assert_eq!(status[999] & status::REJECTED_MARKER, 0);
        assert!(worst_deg(&good[1001..], &bad[1001..]) < 0.01, "{}", worst_deg(&good[1001..], &bad[1001..]));
        // The noise learned is the clean run's, not the glitch's.
        let (a, b) = (tracker.marker_noise(), clean_tracker.marker_noise());
        assert!(a.iter().zip(b).all(|(x, y)| *x < 2.0 * y + 1e-6), "{a:?} vs {b:?}");
        assert_eq!(tracker.restarts(), 0);
    }

    /// Runs `f` through a fresh tracker at `rate` calibrated to the body model's own placement
    /// (so: the hand measured by its orientation, the wrist centre learned); per frame, the
    /// angles (NaN before the start) and status.
    fn track_calibrated(f: &[f64], rate: f64) -> (Vec<[f64; 3]>, Vec<u8>, Tracker) {
        let settings = TrackerSettings { rate_hz: rate, ..Default::default() };
        let mut tracker = Tracker::new(BodyModel::default(), settings).unwrap();
        tracker.set_calibration(Some(Calibration::body_model()));
        let (mut q, mut st) = (vec![], vec![]);
        tracker
            .run(f, |_, o, _| {
                q.push(o.state.q);
                st.push(o.status);
            })
            .unwrap();
        (q, st, tracker)
    }

    /// Largest geodesic angle between the hand-in-forearm rotations of `a` and `b`, degrees.
    fn worst_turn_deg(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| body::wrist_rotation(x).angle_to(&body::wrist_rotation(y)).to_degrees())
            .fold(0.0, f64::max)
    }

    /// A fast wrist (flexion swinging ±60° at 1.5 Hz, deviation and pronation with it), as
    /// wheelchair racing's at a lab's 70 Hz.
    fn fast_trajectory(n: usize, rate: f64) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let w = std::f64::consts::TAU * 1.5 * i as f64 / rate;
                [0.5 * (w + 0.3).sin(), -0.2 + 1.0 * w.sin(), 0.25 * (2.0 * w).cos()]
            })
            .collect()
    }

    #[test]
    fn a_marker_off_its_place_for_longer_than_lost_stays_rejected_and_is_taken_back() {
        // MC5 and then USP 10 cm off for 200 ms (20 frames, LOST_S is 3): every frame flagged
        // rejected_marker, the estimate as without them throughout, nothing flagged once they
        // are back. (The shape used to be re-learned after LOST_S from the garbage, its
        // template taken from it: rows unflagged, a restart, and the wrong placement after.)
        let body = BodyModel::default();
        let rate = 100.0;
        let q = trajectory(600, rate);
        let clean = frames(&body, &q, 0.2);
        let (good, _, _) = track_calibrated(&clean, rate);
        for (marker, at) in [(4, 200), (1, 400)] {
            let mut f = clean.clone();
            for i in at..at + 20 {
                f[i * MARKER_FRAME_LEN + 3 * marker] += 0.06;
                f[i * MARKER_FRAME_LEN + 3 * marker + 1] -= 0.08;
            }
            let (est, status, tracker) = track_calibrated(&f, rate);
            assert!(status[at..at + 20].iter().all(|s| s & status::REJECTED_MARKER != 0), "marker {marker}");
            assert!(status.iter().all(|s| s & status::RESTARTED == 0), "marker {marker}: {:?}", &status[at..]);
            assert!(status[at + 20..].iter().all(|&s| s == 0), "marker {marker}: {:?}", &status[at + 20..]);
            let off = worst_turn_deg(&good[at..], &est[at..]);
            assert!(off < 0.5, "marker {marker}: {off}° from the clean run");
            assert_eq!(tracker.restarts(), 0);
        }
    }

    #[test]
    fn one_broken_distance_rejects_the_marker_that_moved() {
        // USP moved 3 cm away from RSP, keeping its distance to FAP: only RSP–USP breaks. The
        // marker that moved against FAP is USP, so RSP and FAP still fit the forearm (it was
        // held before: both markers of the broken pair were rejected).
        let body = BodyModel::default();
        let q = trajectory(800, 1000.0);
        let mut f = frames(&body, &q, 0.2);
        for i in 400..450 {
            let m = |k: usize| Vector3::new(f[i * 18 + 3 * k], f[i * 18 + 3 * k + 1], f[i * 18 + 3 * k + 2]);
            let (rsp, usp, fap) = (m(0), m(1), m(2));
            let arm = usp - fap;
            let away = -((rsp - usp) - arm * (rsp - usp).dot(&arm) / arm.norm_squared()).normalize();
            // Turned about FAP (its distance to it kept) away from RSP until RSP–USP breaks
            // by a centimetre more than the tolerance.
            let broken = |p: Vector3<f64>| {
                let (d, l) = ((p - rsp).norm(), (usp - rsp).norm());
                d - l > RIGID_TOLERANCE_M + RIGID_TOLERANCE_REL * l + 0.01
            };
            let moved = (1..90)
                .map(|deg| {
                    let a = f64::from(deg).to_radians();
                    fap + (arm * a.cos() + away * arm.norm() * a.sin())
                })
                .find(|&p| broken(p))
                .unwrap();
            assert!(((moved - fap).norm() - arm.norm()).abs() < 1e-9);
            f[i * 18 + 3..i * 18 + 6].copy_from_slice(moved.as_slice());
        }
        let (est, status, _) = track(&f, 1000.0);
        for s in &status[400..450] {
            assert!(s & status::REJECTED_MARKER != 0 && s & status::HELD == 0, "{}", status::describe(*s));
        }
        assert!(worst_deg(&q[400..], &est[400..]) < 0.05, "{}", worst_deg(&q[400..], &est[400..]));
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
        let settings = TrackerSettings { rate_hz: rate, ..Default::default() };
        let mut tracker = Tracker::new(body, settings).unwrap();
        let out: Vec<TrackerOutput> =
            f.chunks_exact(MARKER_FRAME_LEN).map(|frame| tracker.push(frame).unwrap().unwrap()).collect();
        let lost = tracker.lost_frames();
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
    }

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
        let restart = status.iter().position(|s| s & status::RESTARTED != 0).unwrap();
        assert!((300..303).contains(&restart), "{restart}");
        let off = worst_turn_deg(&q[restart + 5..400], &est[restart + 5..400]);
        assert!(off < 0.5, "{off}° after the restart, MC5 still missing");
    }

    #[test]
    fn a_segment_from_two_markers_takes_them_where_they_sit_now() {
        // Skin markers slide: USP drifts 5 mm on the forearm, and MC2 on the hand, over 4 s (the
        // gap-free run reads 8° off the bones by then: the markers define the segments). Gaps
        // of each other marker are bridged with those two where they sit lately, not where the
        // shape was taken: 0.3–2° off the gap-free run (1.4–5.3° before).
        let rate = 100.0;
        let body = BodyModel::default();
        let q = trajectory(500, rate);
        let pose = body.forearm_pose(0.2);
        let clean: Vec<f64> = q
            .iter()
            .enumerate()
            .flat_map(|(i, qi)| {
                let mut slid = body.clone();
                let s = 0.005 * i as f64 / 400.0;
                slid.marker_offsets[1][0] += s;
                slid.marker_offsets[3][2] -= s;
                slid.marker_frame(qi, &pose)
            })
            .collect();
        let (good, _, _) = track_calibrated(&clean, rate);
        for (marker, bound) in [(0, 1.2), (2, 2.5), (4, 1.0), (5, 0.6)] {
            let mut f = clean.clone();
            for i in 400..420 {
                f[i * MARKER_FRAME_LEN + 3 * marker..i * MARKER_FRAME_LEN + 3 * marker + 3].fill(f64::NAN);
            }
            let (est, _, _) = track_calibrated(&f, rate);
            let off = worst_turn_deg(&good[400..], &est[400..]);
            assert!(off < bound, "marker {marker}: {off}° off the gap-free run");
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
    fn garbage_frames_are_flagged_and_tracking_recovers_within_100_ms() {
        let body = BodyModel::default();
        let q = trajectory(2000, 1000.0);
        let clean = frames(&body, &q, 0.0);
        let mut rng = crate::rng::SplitMix::new(7);
        for scale in [1.0, 0.05] {
            let mut f = clean.clone();
            // 50 ms of random frames: metres apart, or hand-sized (5 cm) noise.
            for v in &mut f[500 * MARKER_FRAME_LEN..550 * MARKER_FRAME_LEN] {
                *v = scale * rng.normal();
            }
            let (est, status, _) = track(&f, 1000.0);
            assert!(status[500..550].iter().all(|s| s & (status::REJECTED_MARKER | status::HELD) != 0), "{scale}");
            let after = worst_deg(&q[650..], &est[650..]);
            assert!(after < 0.1, "scale {scale}: {after}° off 100 ms after the garbage");
            assert!(status[700..].iter().all(|&s| s == 0), "scale {scale}");
        }
    }

    #[test]
    fn one_hand_marker_off_its_segment_is_rejected_alone() {
        let body = BodyModel::default();
        let q = trajectory(1000, 1000.0);
        let mut f = frames(&body, &q, 0.0);
        let mc5_x = 3 * 4;
        for frame in 600..650 {
            f[frame * MARKER_FRAME_LEN + mc5_x] += 0.08; // MC5 8 cm off: a swapped or ghost marker
        }
        let (est, status, tracker) = track(&f, 1000.0);
        assert!(status[600..650].iter().all(|s| s & status::REJECTED_MARKER != 0));
        // MC2 and MCB alone keep the estimate on the wrist.
        assert!(worst_deg(&q[600..], &est[600..]) < 0.05, "{}", worst_deg(&q[600..], &est[600..]));
        assert_eq!(tracker.restarts(), 0);
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
        let restart = status.iter().position(|s| s & status::RESTARTED != 0).unwrap();
        assert!((400..400 + 3 * 30).contains(&restart), "{restart}");
        assert!(worst_deg(&q[restart + 50..], &est[restart + 50..]) < 0.05);
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

    #[test]
    fn clean_markers_are_followed_closely_with_derivatives() {
        let body = BodyModel::default();
        let q = trajectory(3000, 1000.0);
        let f = frames(&body, &q, 0.3);
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::default()).unwrap();
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
    fn noise_is_learned_per_coordinate_and_filtered() {
        let body = BodyModel::default();
        let q = trajectory(6000, 1000.0);
        let clean = frames(&body, &q, 0.0);
        let mut noisy = clean.clone();
        uniform_range(&mut noisy, 0.05, 11).unwrap();
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::default()).unwrap();
        let (mut se_tracker, mut se_frame) = (0.0, 0.0);
        for (i, frame) in noisy.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let out = tracker.push(frame).unwrap().unwrap();
            if i >= 1000 {
                let per_frame = reference::inverse_kinematics_frame(&body, frame, i).unwrap();
                for c in 0..3 {
                    se_tracker += (out.state.q[c] - q[i][c]).powi(2);
                    se_frame += (per_frame[c] - q[i][c]).powi(2);
                }
            }
        }
        // Uniform ±5 % of each coordinate's range: σ = 0.05 · range / √3, different per coordinate.
        let noise = tracker.marker_noise();
        for i in 0..N_HAND {
            let col: Vec<f64> = clean.chunks_exact(MARKER_FRAME_LEN).map(|f| f[HAND_START + i]).collect();
            let range = col.iter().cloned().fold(f64::MIN, f64::max) - col.iter().cloned().fold(f64::MAX, f64::min);
            let expected = 0.05 * range / 3f64.sqrt();
            assert!((noise[i] / expected - 1.0).abs() < 0.1, "coordinate {i}: {} vs {expected}", noise[i]);
        }
        assert!(se_tracker * 10.0 < se_frame, "filtered {se_tracker} vs per frame {se_frame}");
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
        let mut tracker = Tracker::new(body, TrackerSettings::default()).unwrap();
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
    fn a_refiner_corrects_by_its_outputs_gated_by_the_learned_noise() {
        use crate::testing::{random_model, random_refiner};
        let body = BodyModel::default();
        let q = trajectory(400, 1000.0);
        let mut f = frames(&body, &q, 0.1);
        uniform_range(&mut f, 0.02, 5).unwrap();
        let refiner = random_refiner(8, &[16], 3);
        let mut bare = Tracker::new(body.clone(), TrackerSettings::default()).unwrap();
        let mut refined = Tracker::new(body.clone(), TrackerSettings::default()).unwrap();
        refined.set_refiner(Some(refiner.clone())).unwrap();
        let mut stream = refiner.stream();
        for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let a = bare.push(frame).unwrap().unwrap();
            let b = refined.push(frame).unwrap().unwrap();
            // The refiner's input: the bare filter's state and log10 of its noise.
            let mut input = [0f32; 10];
            for k in 0..3 {
                input[k] = a.state.q[k] as f32;
                input[3 + k] = a.state.qd[k] as f32;
                input[6 + k] = a.state.qdd[k] as f32;
            }
            input[9] = a.noise.log10() as f32;
            let out = stream.push(&input).unwrap().map(|o| o.to_vec());
            assert_eq!(b.refined, out.is_some(), "frame {i}");
            assert_eq!(b.noise, a.noise);
            assert_eq!(b.state.qd, a.state.qd, "q̇ is the filter's");
            // The gate by hand: σ / (σ + 0.1 mm).
            let per_unit = a.noise / (a.noise + 1e-4);
            let (sd_q, sd_qdd) = bare.state_std();
            for k in 0..3 {
                let (dq, dqdd) = out.as_ref().map_or((0.0, 0.0), |o| (f64::from(o[k]), f64::from(o[3 + k])));
                let clamp = |v: f64, sd: f64| v.clamp(-REFINER_TRUST * sd, REFINER_TRUST * sd);
                assert_eq!(b.state.q[k], a.state.q[k] + clamp(dq * per_unit, sd_q[k]), "frame {i}");
                assert_eq!(b.state.qdd[k], a.state.qdd[k] + clamp(dqdd * per_unit, sd_qdd[k]), "frame {i}");
            }
            let tau = reference::inverse_dynamics(&body, 0.1, &b.state).unwrap();
            for k in 0..3 {
                assert!((b.tau[k] - tau[k]).abs() < 1e-12, "torques follow the refined state");
            }
        }
        // The wrong kind of model is refused with the reason.
        let err =
            refined.set_refiner(Some(random_model(FeatureSet::JointState, 5, &[8], 6, 1))).unwrap_err().to_string();
        assert!(err.contains("reads joint_state frames"), "{err}");
        let err =
            refined.set_refiner(Some(random_model(FeatureSet::TrackerState, 5, &[8], 3, 1))).unwrap_err().to_string();
        assert!(err.contains("its outputs are"), "{err}");
        let mut slow = Tracker::new(body, TrackerSettings { rate_hz: 500.0, ..Default::default() }).unwrap();
        let err = slow.set_refiner(Some(refiner)).unwrap_err().to_string();
        assert!(err.contains("1000 Hz") && err.contains("500 Hz"), "{err}");
        refined.set_refiner(None).unwrap();
        assert!(refined.refiner().is_none());
    }

    /// A random refiner whose outputs are multiplied by `gain` and shifted by `offset`.
    fn rescaled_refiner(seed: u64, gain: f32, offset: f32) -> Model {
        use crate::net::{Affine, Mlp};
        let base = crate::testing::random_refiner(4, &[8], seed);
        let mlp = base.mlp();
        let out =
            Affine { scale: mlp.output.scale.map(|s| s * gain), shift: mlp.output.shift.map(|s| s * gain + offset) };
        Model::from_parts(base.card().clone(), Mlp::new(mlp.input.clone(), mlp.layers.clone(), out).unwrap()).unwrap()
    }

    #[test]
    fn a_refiner_that_overreaches_is_held_to_three_standard_deviations() {
        // A refiner whose corrections are 10⁴ times too large: every correction it makes is cut
        // to ±3 standard deviations of the filter's own estimate (the bare filter's here).
        let refiner = rescaled_refiner(9, 1e4, 1e3);
        let body = BodyModel::default();
        let mut f = frames(&body, &trajectory(300, 1000.0), 0.1);
        uniform_range(&mut f, 0.02, 8).unwrap();
        let mut bare = Tracker::new(body.clone(), TrackerSettings::default()).unwrap();
        let mut refined = Tracker::new(body, TrackerSettings::default()).unwrap();
        refined.set_refiner(Some(refiner)).unwrap();
        let mut clamped = 0;
        for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let a = bare.push(frame).unwrap().unwrap();
            let b = refined.push(frame).unwrap().unwrap();
            // From frame 100 the learned noise (2 %) opens the gate: the corrections are huge.
            if i < 100 {
                continue;
            }
            assert!(b.refined);
            let (sd_q, sd_qdd) = bare.state_std();
            for k in 0..3 {
                let (dq, dqdd) = ((b.state.q[k] - a.state.q[k]).abs(), (b.state.qdd[k] - a.state.qdd[k]).abs());
                assert!((dq / (3.0 * sd_q[k]) - 1.0).abs() < 1e-9, "q {k}: {dq} vs 3 × {}", sd_q[k]);
                assert!((dqdd / (3.0 * sd_qdd[k]) - 1.0).abs() < 1e-9, "q̈ {k}: {dqdd} vs 3 × {}", sd_qdd[k]);
                clamped += 1;
            }
        }
        assert_eq!(clamped, 600);
    }

    #[test]
    fn a_quiet_refiner_is_applied_times_the_gate_without_clamping() {
        // Corrections of ~10 µrad, well inside 3 sd of the estimate: each applied exactly as
        // the network's output times σ / (σ + 0.1 mm).
        let refiner = rescaled_refiner(11, 1e-5, 0.0);
        let body = BodyModel::default();
        let mut f = frames(&body, &trajectory(300, 1000.0), 0.1);
        uniform_range(&mut f, 0.002, 3).unwrap();
        let mut bare = Tracker::new(body.clone(), TrackerSettings::default()).unwrap();
        let mut refined = Tracker::new(body, TrackerSettings::default()).unwrap();
        refined.set_refiner(Some(refiner.clone())).unwrap();
        let mut stream = refiner.stream();
        let mut checked = 0;
        for frame in f.chunks_exact(MARKER_FRAME_LEN) {
            let a = bare.push(frame).unwrap().unwrap();
            let b = refined.push(frame).unwrap().unwrap();
            let input: Vec<f32> = a
                .state
                .q
                .iter()
                .chain(&a.state.qd)
                .chain(&a.state.qdd)
                .map(|&v| v as f32)
                .chain([a.noise.log10() as f32])
                .collect();
            let Some(out) = stream.push(&input).unwrap() else { continue };
            let gate = a.noise / (a.noise + 1e-4);
            for k in 0..3 {
                assert_eq!(b.state.q[k], a.state.q[k] + f64::from(out[k]) * gate);
                assert_eq!(b.state.qdd[k], a.state.qdd[k] + f64::from(out[3 + k]) * gate);
            }
            checked += 1;
        }
        assert_eq!(checked, 297);
    }

    #[test]
    fn a_refiner_at_the_trackers_rate_to_a_millionth_is_accepted() {
        use crate::testing::random_refiner;
        let refiner = random_refiner(4, &[8], 2); // 1000 Hz
        for (rate, ok) in [(1000.0005, true), (999.9995, true), (1000.002, false), (999.998, false)] {
            let mut t =
                Tracker::new(BodyModel::default(), TrackerSettings { rate_hz: rate, ..Default::default() }).unwrap();
            assert_eq!(t.set_refiner(Some(refiner.clone())).is_ok(), ok, "{rate} Hz");
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
        let mut tracker = Tracker::new(body, TrackerSettings::default()).unwrap();
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
    fn the_refiner_gate_is_half_open_at_its_noise_and_closed_on_clean_markers() {
        // By hand: σ / (σ + 0.1 mm).
        assert_eq!(refiner_gate(0.0), 0.0);
        assert!((refiner_gate(1e-4) - 0.5).abs() < 1e-12);
        assert!((refiner_gate(1e-3) - 1e-3 / 1.1e-3).abs() < 1e-12);
        assert!((refiner_gate(1e-6) - 1e-6 / 1.01e-4).abs() < 1e-12);
        assert!(refiner_gate(1.0) > 0.9999 && refiner_gate(1.0) < 1.0);
    }

    /// Hand marker coordinates of `frames` (back to back) and their noise as the tracker is
    /// documented to learn it, computed here from the third differences alone: per coordinate
    /// a running mean of d³²/20 over the frames where four consecutive values are present
    /// (weight 1/(n+1), or the forgetting rate once that is larger), and the same with the
    /// initial guess counting as `PRIOR_FRAMES − 1` samples.
    fn third_difference_noise(frames: &[f64], settings: &TrackerSettings) -> (Vec<[f64; N_HAND]>, Vec<[f64; N_HAND]>) {
        let hand: Vec<[f64; N_HAND]> =
            frames.chunks_exact(MARKER_FRAME_LEN).map(|f| std::array::from_fn(|i| f[HAND_START + i])).collect();
        let forget = 1.0 / (settings.noise_memory_s * settings.rate_hz);
        let mut data = [0.0; N_HAND];
        let mut guessed = [settings.initial_marker_noise.powi(2); N_HAND];
        let mut n = [0.0; N_HAND];
        let (mut data_out, mut guessed_out) = (Vec::new(), Vec::new());
        for t in 0..hand.len() {
            if t >= 3 {
                for i in 0..N_HAND {
                    let d3 = hand[t][i] - 3.0 * hand[t - 1][i] + 3.0 * hand[t - 2][i] - hand[t - 3][i];
                    if d3.is_nan() {
                        continue;
                    }
                    let sample = d3 * d3 / 20.0;
                    let w = f64::max(1.0 / (n[i] + 1.0), forget);
                    data[i] = (1.0 - w) * data[i] + w * sample;
                    let w = f64::max(1.0 / (n[i] + PRIOR_FRAMES), forget);
                    guessed[i] = (1.0 - w) * guessed[i] + w * sample;
                    n[i] += 1.0;
                }
            }
            data_out.push(data.map(f64::sqrt));
            guessed_out.push(guessed.map(f64::sqrt));
        }
        (data_out, guessed_out)
    }

    #[test]
    fn the_reported_noise_is_the_third_difference_estimate_of_the_data() {
        let body = BodyModel::default();
        let q = trajectory(3000, 1000.0);
        let mut f = frames(&body, &q, 0.2);
        uniform_range(&mut f, 0.02, 17).unwrap();
        // MC5 missing for a while: those coordinates skip the samples that touch the gap.
        for i in 700..720 {
            f[i * MARKER_FRAME_LEN + 12..i * MARKER_FRAME_LEN + 15].fill(f64::NAN);
        }
        for settings in [
            TrackerSettings::default(),
            TrackerSettings { noise_memory_s: 0.05, initial_marker_noise: 3e-3, ..Default::default() },
        ] {
            let (data, guessed) = third_difference_noise(&f, &settings);
            let mut tracker = Tracker::new(body.clone(), settings).unwrap();
            for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
                let out = tracker.push(frame).unwrap().unwrap();
                let mean = (data[i].iter().sum::<f64>() / N_HAND as f64).max(MIN_REPORTED_NOISE);
                assert!((out.noise / mean - 1.0).abs() < 1e-9, "frame {i}: {} vs {mean} ({settings:?})", out.noise);
                let learned = tracker.marker_noise();
                for k in 0..N_HAND {
                    assert!(
                        (learned[k] / guessed[i][k] - 1.0).abs() < 1e-9,
                        "frame {i} coordinate {k}: {} vs {}",
                        learned[k],
                        guessed[i][k]
                    );
                }
            }
        }
    }

    #[test]
    fn a_short_noise_memory_forgets_old_noise_and_a_long_one_does_not() {
        // 2 s of 5 % noise, then 2 s of clean markers: a 0.1 s memory reads the clean markers
        // as clean by the end, a 100 s memory still remembers the noise.
        let body = BodyModel::default();
        let q = trajectory(4000, 1000.0);
        let clean = frames(&body, &q, 0.0);
        let mut f = clean.clone();
        uniform_range(&mut f[..2000 * MARKER_FRAME_LEN], 0.05, 3).unwrap();
        let last_noise = |memory: f64| {
            let mut tracker =
                Tracker::new(body.clone(), TrackerSettings { noise_memory_s: memory, ..Default::default() }).unwrap();
            let mut noisy_end = 0.0;
            let mut out = None;
            for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
                out = tracker.push(frame).unwrap();
                if i == 1999 {
                    noisy_end = out.unwrap().noise;
                }
            }
            (noisy_end, out.unwrap().noise)
        };
        let (noisy_short, end_short) = last_noise(0.1);
        let (noisy_long, end_long) = last_noise(100.0);
        assert!(noisy_short > 1e-4 && noisy_long > 1e-4, "{noisy_short} {noisy_long}");
        // After 20 memories of clean frames: down by e^-20 in variance.
        assert!(end_short < 1e-3 * noisy_short, "short memory: {end_short} after {noisy_short}");
        // With n samples the running mean halves its variance at most: σ falls by ≤ √2.
        assert!(end_long > noisy_long / 1.5, "long memory: {end_long} after {noisy_long}");
    }

    /// Bit patterns of an output (NaN compares equal to the same NaN).
    fn bits(out: &TrackerOutput) -> (Vec<u64>, u8, bool, u64) {
        (out.values().iter().map(|v| v.to_bits()).collect(), out.missing, out.refined, out.noise.to_bits())
    }

    #[test]
    fn run_equals_push_one_by_one_bit_for_bit() {
        use crate::testing::random_refiner;
        let body = BodyModel::scaled(1.1, 1.2);
        let q = trajectory(600, 1000.0);
        let mut f = frames(&body, &q, 0.2);
        uniform_range(&mut f, 0.02, 23).unwrap();
        // The first three frames miss a marker (the filter waits), MCB goes missing later on.
        for i in 0..3 {
            f[i * MARKER_FRAME_LEN + 3 * (i + 1)] = f64::NAN;
        }
        for i in 300..340 {
            f[i * MARKER_FRAME_LEN + 15..i * MARKER_FRAME_LEN + 18].fill(f64::NAN);
        }
        for refiner in [None, Some(random_refiner(8, &[16], 4))] {
            let new = || {
                let mut t =
                    Tracker::new(body.clone(), TrackerSettings { jerk_noise: 800.0, ..Default::default() }).unwrap();
                t.set_refiner(refiner.clone()).unwrap();
                t
            };
            let mut one = new();
            let pushed: Vec<_> = f
                .chunks_exact(MARKER_FRAME_LEN)
                .map(|frame| match one.push(frame).unwrap() {
                    Some(out) => (bits(&out), true),
                    None => (bits(&TrackerOutput::waiting(missing_markers(frame))), false),
                })
                .collect();
            assert!(pushed.iter().filter(|p| p.0.2).count() > 500 || refiner.is_none());
            // One block, then the same frames in blocks of 7 and 250 (continuing from the state).
            for block in [600, 7, 250] {
                let mut run = new();
                let mut got = Vec::new();
                let mut starts = Vec::new();
                for (b, chunk) in f.chunks(block * MARKER_FRAME_LEN).enumerate() {
                    let start = run
                        .run(chunk, |i, out, estimated| {
                            assert_eq!(got.len(), b * block + i, "frames in order");
                            got.push((bits(out), estimated));
                        })
                        .unwrap();
                    starts.push(start.map(|s| b * block + s));
                }
                assert_eq!(got, pushed, "block {block}");
                assert_eq!(starts.iter().flatten().next(), Some(&3), "block {block}");
                assert!(starts.iter().skip(1).all(|s| s.is_some()), "a running filter starts every block at 0");
                assert_eq!(run.marker_noise().map(f64::to_bits), one.marker_noise().map(f64::to_bits));
            }
        }
    }

    #[test]
    fn run_refuses_a_partial_frame_before_pushing_and_numbers_a_bad_frame_in_its_block() {
        let body = BodyModel::default();
        let q = trajectory(20, 1000.0);
        let mut f = frames(&body, &q, 0.0);
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::default()).unwrap();
        let mut calls = 0;
        let err = tracker.run(&f[..MARKER_FRAME_LEN * 2 + 5], |_, _, _| calls += 1).unwrap_err();
        assert!(matches!(err, Error::BadArgument { what: "frames", .. }), "{err}");
        assert_eq!(calls, 0);
        assert_eq!(tracker.run(&[], |_, _, _| calls += 1).unwrap(), None);
        // A block without a complete frame never starts the filter: NaN rows, the masks.
        let mut holes = f[..3 * MARKER_FRAME_LEN].to_vec();
        for (i, m) in [0, 2, 5].iter().enumerate() {
            holes[i * MARKER_FRAME_LEN + 3 * m + 1] = f64::NAN;
        }
        let mut seen = Vec::new();
        assert_eq!(tracker.run(&holes, |i, o, e| seen.push((i, o.missing, e, o.state.q[0].is_nan()))).unwrap(), None);
        assert_eq!(seen, [(0, 1, false, true), (1, 1 << 2, false, true), (2, 1 << 5, false, true)]);
        tracker.reset();
        // An infinite value in frame 4 of the block (frame 14 of the tracker): named frame 4,
        // the four frames before it pushed, as by push.
        f[14 * MARKER_FRAME_LEN + 7] = f64::INFINITY;
        let mut twin = Tracker::new(body, TrackerSettings::default()).unwrap();
        for frame in f[..14 * MARKER_FRAME_LEN].chunks_exact(MARKER_FRAME_LEN) {
            twin.push(frame).unwrap();
        }
        tracker.run(&f[..10 * MARKER_FRAME_LEN], |_, _, _| ()).unwrap();
        let mut seen = 0;
        let err = tracker.run(&f[10 * MARKER_FRAME_LEN..], |_, _, _| seen += 1).unwrap_err();
        assert_eq!((err.frame(), seen), (Some(4), 4), "{err}");
        assert!(err.to_string().contains("FAP.y"), "{err}");
        let next = &f[15 * MARKER_FRAME_LEN..16 * MARKER_FRAME_LEN];
        assert_eq!(tracker.push(next).unwrap().map(|o| bits(&o)), twin.push(next).unwrap().map(|o| bits(&o)));
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

    #[test]
    fn starts_on_the_first_complete_frame_and_rejects_bad_input() {
        let body = BodyModel::default();
        let q = trajectory(10, 1000.0);
        let mut f = frames(&body, &q, 0.0);
        f[9] = f64::NAN; // MC2.x on frame 0
        let mut tracker = Tracker::new(body, TrackerSettings::default()).unwrap();
        assert_eq!(tracker.push(&f[..MARKER_FRAME_LEN]).unwrap(), None);
        assert!(tracker.push(&f[MARKER_FRAME_LEN..2 * MARKER_FRAME_LEN]).unwrap().is_some());
        let err = tracker.push(&f[..5]).unwrap_err().to_string();
        assert!(err.contains("18"), "{err}");
        let mut bad = f[..MARKER_FRAME_LEN].to_vec();
        bad[13] = f64::INFINITY;
        let err = tracker.push(&bad).unwrap_err().to_string();
        // Two frames were taken before it (the first waited for MC2): this one is frame 2.
        assert!(err.contains("MC5.y") && err.starts_with("frame 2:"), "{err}");
        let err =
            Tracker::new(BodyModel::default(), TrackerSettings { jerk_noise: -1.0, ..Default::default() }).unwrap_err();
        assert!(err.to_string().contains("jerk_noise"), "{err}");
        // Absurdly large settings are typos, refused by name, not an overflow later.
        for (settings, name) in [
            (TrackerSettings { rate_hz: 1e308, ..Default::default() }, "rate_hz"),
            (TrackerSettings { jerk_noise: 1e13, ..Default::default() }, "jerk_noise"),
            (TrackerSettings { noise_memory_s: 1e9, ..Default::default() }, "noise_memory_s"),
            (TrackerSettings { initial_marker_noise: 2.0, ..Default::default() }, "initial_marker_noise"),
        ] {
            let err = Tracker::new(BodyModel::default(), settings).unwrap_err().to_string();
            assert!(err.contains(name) && err.contains("up to"), "{err}");
        }
        assert!(Tracker::new(BodyModel::default(), TrackerSettings { jerk_noise: 1e12, ..Default::default() }).is_ok());
        tracker.reset();
        assert!(tracker.push(&f[..MARKER_FRAME_LEN]).unwrap().is_none());
    }
}
