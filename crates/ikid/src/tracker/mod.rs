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
//!    own noise variance plus what the forearm's pose error adds to it (the forearm's markers'
//!    noise, learned from their fit residual, through the lever of each hand marker: the filter
//!    predicts the hand through the forearm's fitted pose; taken as exact, 1 mm on the forearm's
//!    markers passed straight to the angles) (the hand's markers rotate about the wrist centre,
//!    the forearm frame's origin). The measurement is linearised at the hand's own solution when its three
//!    markers are there, or two and the wrist centre (else at the prediction), and again at the
//!    corrected state while that
//!    moves (an iterated EKF: a fast move at a low frame rate, or one near gimbal lock, is not
//!    overshot); markers further from the prediction than its covariance allows
//!    ([`MANOEUVRE_NIS`]) scale that covariance up by as much (a manoeuvre: an impact the
//!    white-jerk model did not expect). e_f is kept within ±90° (past it, the other Euler
//!    triple of the same rotation);
//! 4. the torques follow from the state by Newton–Euler ([`reference::inverse_dynamics_moving`](crate::reference::inverse_dynamics_moving),
//!    gravity's direction from the fitted forearm, which carries the hand with its own motion
//!    once that stands out of its noise: `motion`); one beyond what a wrist can take
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
//! of the markers' residual to the hand's rigid fit instead: at a real lab's 70–100 Hz a fast
//! hand's own third differences are its motion, not noise (0.2 mm plates read as 1.7 mm). That
//! residual has no component normal to the markers' plane (the fit absorbs it), so it gives one
//! variance for the hand, in every direction, from its sum of squares over the three degrees of
//! freedom the fit leaves: read per lab coordinate, a hand resting with its plane facing one lab
//! axis had that axis learned at a fraction of its noise and the filter passed the noise through
//! (issue #28). Measured relative to their own centroid, the markers carry exactly the
//! information a diagonal, isotropic noise model gives them; a per-coordinate one would need
//! the centroid's shared noise modelled too.
//!
//! Optionally a learned *refiner* ([`Tracker::set_refiner`]) corrects the estimate: a network
//! over a window of the tracker's own states ([`FeatureSet::TrackerState`](crate::features::FeatureSet::TrackerState): q̇, q̈ and the
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
//!
//! Where each part lives: this file holds the [`Tracker`], its frame ([`Tracker::push`], one
//! method per step) and [`Tracker::run`]; `settings` its [`TrackerSettings`], `output` its
//! [`TrackerOutput`] and the torques; `checks` the markers' rigid shapes, jumps and status bits;
//! `placement` the calibration's templates and each marker's recent place; `forearm` the
//! forearm's pose from three or two markers; `motion` the forearm's own motion, for the torques; `centre` the wrist centre; `ekf` the filter's
//! prediction, gate, correction and restarts; `variance` the noise it learns; `refiner` the
//! learned refiner; `timing` time-stamped frames ([`Tracker::push_at`]: lost frames restart it).

mod centre;
mod checks;
mod ekf;
mod forearm;
mod motion;
mod output;
mod placement;
mod refiner;
mod settings;
mod timing;
mod variance;

pub use centre::{CENTRE_MEMORY_S, CENTRE_MIN_S, CENTRE_MIN_STD_M, CENTRE_WEIGHT, POSTURE_RIDGE};
pub use checks::{
    FIT_TOLERANCE_M, JUMP_TOLERANCE_M, MAX_RELOCATION_M, MAX_SEGMENT_SPEED, RIGID_TOLERANCE_M, RIGID_TOLERANCE_REL,
    missing_markers,
};
pub use ekf::{GATE_CHI2, GATE_FLOOR_M, MANOEUVRE_NIS, MAX_ITERATIONS, RELINEARISE_RAD};
pub use motion::{ANCHOR_EVERY_S, CENTRE_JERK_LEVER_M, MOTION_SIGNIFICANCE};
pub use output::{MIN_REPORTED_NOISE, SD_SCALE_TAU, TRACKER_VALUES, TrackerOutput, TrackerSd};
pub use placement::{LIVE_PLACEMENT_S, TEMPLATE_S};
pub use refiner::{
    REFINED_SD_SCALE_Q, REFINED_SD_SCALE_TAU, REFINER_GATE_NOISE, REFINER_TRUST, refiner_gate, refiner_outputs,
};
pub use settings::{DEFAULT_JERK_NOISE, TrackerSettings};

use nalgebra::{Isometry3, Rotation3, SMatrix, SVector, Vector3};

use crate::body::{self, BodyModel, MARKER_FRAME_LEN, MARKERS, N_COORDINATES};
use crate::calibration::{Calibration, Side};
use crate::error::{Error, Result};
use crate::status;
use crate::stream::Stream;
use centre::{JointCentre, WristCentre};
use checks::RigidShape;
use forearm::{ForearmNoise, ForearmTurn, Roll};
use motion::ForearmMotionFilter;

/// State size: angle, velocity and acceleration of each coordinate.
const N_STATE: usize = 3 * N_COORDINATES;
/// Marker coordinates on the hand (the measurement).
const N_HAND: usize = 9;
/// First value of the hand's markers in a frame.
const HAND_START: usize = 3 * 3;

/// How long every usable marker of a segment may be rejected, s (at least 3 frames), before
/// the tracker decides it, not the markers, is wrong: it then re-learns the forearm's position
/// (its shape only once a new one has held as long as the old one had), or restarts the hand
/// from the frame's own solution ([`status::RESTARTED`]); and how long a state carried forward
/// without correction goes on at its last velocity before it holds.
pub const LOST_S: f64 = 0.03;

type StateVector = SVector<f64, N_STATE>;
/// Each hand marker's predicted position and its motion per radian of each coordinate; the
/// fourth: the point asked for (the wrist centre), zeros without one.
type HandPrediction = ([Vector3<f64>; 4], [[Vector3<f64>; N_COORDINATES]; 4]);
type StateMatrix = SMatrix<f64, N_STATE, N_STATE>;

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
    /// The last three frames' hand marker coordinates as measured (the calibrated hand's
    /// `history` holds its fit residual instead), newest first.
    raw_history: [[f64; N_HAND]; 3],
    /// Running means of each coordinate's own third-difference noise sample and of the fit
    /// residual's (calibrated hand), and how many went in: their ratio corrects the residual's
    /// blindness normal to the markers' plane (see [`variance::RAW_NOISE_CAP`]).
    own_noise: [f64; N_HAND],
    fit_noise: f64,
    own_noise_samples: f64,
    noise_variance: [f64; N_HAND],
    /// The same estimate from the data alone (no initial guess): what the refiner is told.
    data_variance: [f64; N_HAND],
    noise_samples: [f64; N_HAND],
    /// Mean square of the hand markers' residual to the rigid fit of the hand's template, over
    /// about [`MISFIT_MEMORY_S`](variance::MISFIT_MEMORY_S) (calibrated hand only): white noise
    /// and the template's misfit (skin sliding with the posture) together.
    fit_residual_ms: f64,
    fit_residual_samples: f64,
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
    /// Frames the state has run since it last started from a frame's own solution (its
    /// velocities and accelerations unknown then: `output_sd` widens the torques' for a while).
    state_age: usize,
    restarts: usize,
    /// The subject's placement: each segment's markers in its anatomical frame are taken from
    /// the subject's own markers (their shape as learned, turned by the calibration) instead of
    /// the body model's, once per shape learned (`templated`).
    calibration: Option<Calibration>,
    templated: [bool; 2],
    /// Frames each segment's template was averaged over ([`TEMPLATE_S`]).
    template_frames: [usize; 2],
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
    /// The forearm markers' noise (see [`ForearmNoise`]) ...
    forearm_noise: ForearmNoise,
    /// ... and its roll about the line through two of its markers while one is missing.
    roll: Roll,
    /// The forearm's own motion, which the torques carry ([`motion`]), and the point of the
    /// forearm (its frame) whose acceleration they take: the wrist centre as last learned.
    motion: ForearmMotionFilter,
    motion_anchor: Vector3<f64>,
    /// [`status::torque_limit`] for this subject, N·m.
    torque_limit: f64,
    /// Whether the refiner corrected the last estimate ([`Tracker::output_sd`]).
    refined: bool,
    /// Whether the estimate reads the hand turned over on the forearm ([`status::TURNED_OVER`]).
    turned_over: status::TurnedOverWatch,
    /// The turn from the markers' lab into the body model's (+Y up), `None` when it is that
    /// lab ([`TrackerSettings::up`]).
    lab: Option<Rotation3<f64>>,
    /// Where the stamped frames fall in time ([`push_at`](Tracker::push_at)); an unstamped
    /// push moves it on by a period.
    clock: crate::stream::FrameGrid,
    /// Restarts after time gaps ([`push_at`](Tracker::push_at)) since the start, and lost
    /// frames bridged (fewer than [`LOST_S`] in a row).
    gap_restarts: usize,
    bridged: usize,
    /// How the stamps follow each other (a source slower than the rate).
    pace: crate::stream::SourcePace,
}

/// What one frame's steps share ([`Tracker::push`]), on the stack: the frame as checked, its
/// status so far, and what each step found.
struct Step {
    /// The frame's index since the start (or the last reset).
    index: usize,
    /// [`LOST_S`] in frames.
    lost: usize,
    /// Bit `i`: marker `i` missing ([`missing_markers`]).
    missing: u8,
    /// [`status`] bits so far.
    flags: u16,
    /// The frame as used: all NaN when no arm could hold its markers, mirrored for a left arm.
    frame: [f64; MARKER_FRAME_LEN],
    /// Whether the forearm's pose was fitted to its three markers ...
    forearm_measured: bool,
    /// ... its markers that may be used (present, and rigid as learned; frame-marker bits 0–2) ...
    forearm_usable: u8,
    /// ... and whether it was measured or estimated from two of them.
    forearm_seen: bool,
    /// The hand's markers: NaN where missing or rejected.
    hand: [f64; N_HAND],
    /// Whether the hand's three markers passed the shape check.
    hand_complete: bool,
    /// The wrist centre, solved at most once a frame (`None` until solved).
    memo: Option<Option<WristCentre>>,
}

impl Tracker {
    /// A tracker for the subject `body` (segment parameters and marker placement).
    pub fn new(body: BodyModel, settings: TrackerSettings) -> Result<Self> {
        settings.check()?;
        let lab = settings.lab_turn()?;
        let (transition, process_noise) = ekf::motion_model(&settings);
        let mut tracker = Tracker {
            body,
            settings,
            transition,
            process_noise,
            state: None,
            forearm: None,
            history: [[f64::NAN; N_HAND]; 3],
            history_len: 0,
            raw_history: [[f64::NAN; N_HAND]; 3],
            own_noise: [0.0; N_HAND],
            fit_noise: 0.0,
            own_noise_samples: 0.0,
            noise_variance: [0.0; N_HAND],
            data_variance: [0.0; N_HAND],
            noise_samples: [0.0; N_HAND],
            fit_residual_ms: 0.0,
            fit_residual_samples: 0.0,
            frames: 0,
            refiner: None,
            shapes: [RigidShape::new(); 2],
            forearm_frame: 0,
            forearm_jumps: 0,
            gated_streak: 0,
            coast_streak: 0,
            settling: 0,
            state_age: 0,
            restarts: 0,
            calibration: None,
            templated: [false; 2],
            template_frames: [0; 2],
            centre: JointCentre::new(),
            model_offsets: [[0.0; 3]; body::N_MARKERS],
            live: [Vector3::zeros(); body::N_MARKERS],
            turn: ForearmTurn::new(),
            forearm_noise: ForearmNoise::new(),
            roll: Roll::idle(),
            motion: ForearmMotionFilter::new(1.0 / settings.rate_hz, settings.jerk_noise),
            motion_anchor: Vector3::zeros(),
            torque_limit: 0.0,
            refined: false,
            turned_over: status::TurnedOverWatch::new(),
            lab,
            clock: crate::stream::FrameGrid::default(),
            gap_restarts: 0,
            bridged: 0,
            pace: crate::stream::SourcePace::default(),
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
        self.fit_residual_ms = 0.0;
        self.fit_residual_samples = 0.0;
        self.own_noise = [0.0; N_HAND];
        self.fit_noise = 0.0;
        self.own_noise_samples = 0.0;
        self.frames = 0;
        self.shapes = [RigidShape::new(); 2];
        self.forearm_frame = 0;
        self.forearm_jumps = 0;
        self.gated_streak = 0;
        self.coast_streak = 0;
        self.settling = 0;
        self.state_age = 0;
        self.restarts = 0;
        self.templated = [false; 2];
        self.template_frames = [0; 2];
        self.centre = JointCentre::new();
        self.body.marker_offsets = self.model_offsets;
        self.live = self.model_offsets.map(Vector3::from);
        self.turn = ForearmTurn::new();
        self.forearm_noise = ForearmNoise::new();
        self.roll = Roll::idle();
        self.motion.reset();
        self.motion_anchor = Vector3::zeros();
        self.refined = false;
        self.turned_over = status::TurnedOverWatch::new();
        self.clock = crate::stream::FrameGrid::default();
        self.gap_restarts = 0;
        self.bridged = 0;
        self.pace = crate::stream::SourcePace::default();
        if let Some(r) = self.refiner.as_mut() {
            r.reset();
        }
    }

    /// Track a subject measured by `calibration` (see [`crate::calibration`]): each segment's
    /// markers are placed in its anatomical frame by the calibration (their shape averaged over
    /// the subject's first [`TEMPLATE_S`] of complete frames), a left arm is mirrored into a
    /// right one, and the hand is measured by its orientation
    /// ([`TrackerSettings::relative_hand`]). `None`: the body model's placement. Starts fresh,
    /// as after [`reset`](Self::reset).
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

    /// The subject tracked.
    pub fn body(&self) -> &BodyModel {
        &self.body
    }

    /// The settings in use.
    pub fn settings(&self) -> &TrackerSettings {
        &self.settings
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
    /// the old one had. An infinite value is an error (NaN means missing), and so, before the
    /// filter has started, are markers no arm could hold (wrong units: there is no motion yet
    /// for them to stray from); nothing else a frame holds stops the tracker.
    ///
    /// The frame's values are `f32` (as [`Stream::push`](crate::Stream::push) takes them) or
    /// `f64`; `f32` values are widened exactly.
    pub fn push<V: Copy + Into<f64>>(&mut self, frame: &[V]) -> Result<Option<TrackerOutput>> {
        let out = self.push_frame(frame)?;
        // An unstamped frame comes one period after the one before.
        self.clock.advance(1.0 / self.settings.rate_hz);
        self.pace.advance(1.0 / self.settings.rate_hz);
        Ok(out)
    }

    /// [`push`](Self::push)'s steps, leaving the clock of [`push_at`](Self::push_at) alone.
    fn push_frame<V: Copy + Into<f64>>(&mut self, frame: &[V]) -> Result<Option<TrackerOutput>> {
        if frame.len() != MARKER_FRAME_LEN {
            return Err(Error::FrameLength { feature_set: "markers", found: frame.len(), expected: MARKER_FRAME_LEN });
        }
        let frame: [f64; MARKER_FRAME_LEN] = std::array::from_fn(|i| frame[i].into());
        let mut step = self.begin(&frame)?;
        // 1. The forearm, 2. the hand's markers, 1b. the forearm through a gap of one marker.
        self.measure_forearm(&mut step);
        self.check_hand(&mut step);
        self.forearm_through_gap(&mut step);
        self.follow_forearm_motion(&step);
        // The state predicted, or started from this frame's own solution.
        let Some(forearm) = self.forearm else {
            self.learn_noise(&step.hand, step.index);
            return Ok(None);
        };
        let Some((mut x, mut p)) = self.predict_or_start(&step, &forearm) else {
            self.learn_noise(&step.hand, step.index);
            return Ok(None);
        };
        // 3. Gate the hand markers on the prediction; restart when the wrist is lost; coast
        // without any.
        self.gate_or_restart(&mut step, &forearm, &mut x, &mut p);
        self.coast_or_settle(&mut step, &mut x);
        // Learn the noise, the markers' places and the wrist centre; correct by the markers.
        self.learn_noise(&step.hand, step.index);
        let (centre, start) = self.learn_from_hand(&mut step, &forearm, &x);
        self.correct(&forearm, &step.hand, centre, start, &mut x, &mut p);
        let (x, p) = self.keep_state(x, p, step.index)?;
        // 4. Refine and output.
        let noise = self.reported_noise();
        let (state, refined) = self.refine(&x, &p, noise, step.index)?;
        self.output(&mut step, &forearm, state, refined, noise).map(Some)
    }

    /// Checks a frame and starts its [`Step`]: a frame of the wrong length or with an infinite
    /// value is an error; markers no arm could hold (wrong units, a ghost far away) are all
    /// rejected; a left arm is mirrored into a right one.
    fn begin(&mut self, frame: &[f64; MARKER_FRAME_LEN]) -> Result<Step> {
        let index = self.frames;
        if let Some(i) = frame.iter().position(|v| v.is_infinite()) {
            return Err(Error::NonFiniteInput {
                frame: index,
                field: format!("{}.{}", MARKERS[i / 3].name, ["x", "y", "z"][i % 3]),
                value: frame[i] as f32,
            });
        }
        // Before the filter runs there is no motion for a ghost to stray from: markers no arm
        // could hold are refused, saying why (mm read as metres returned no estimate, ever,
        // and no error), where a running filter rejects and flags them (below).
        if self.state.is_none() {
            body::check_marker_span(frame, index)?;
        }
        self.frames += 1;
        let mut step = Step {
            index,
            lost: self.lost_frames(),
            missing: missing_markers(frame),
            flags: 0,
            frame: [f64::NAN; MARKER_FRAME_LEN],
            forearm_measured: false,
            forearm_usable: 0,
            forearm_seen: false,
            hand: [f64::NAN; N_HAND],
            hand_complete: false,
            memo: None,
        };
        // Markers no arm could hold (wrong units, a ghost far away) are all rejected.
        if body::check_marker_span(frame, index).is_ok() {
            step.frame.copy_from_slice(frame);
        } else {
            step.flags |= status::REJECTED_MARKER;
        }
        // Into the body model's lab (gravity along -Y), before a left arm's mirror (which
        // keeps the vertical).
        if let Some(turn) = self.lab {
            for m in step.frame.chunks_exact_mut(3) {
                let v = turn * Vector3::new(m[0], m[1], m[2]);
                m.copy_from_slice(v.as_slice());
            }
        }
        if self.calibration.as_ref().is_some_and(|c| c.side == Side::Left) {
            for z in step.frame.iter_mut().skip(2).step_by(3) {
                *z = -*z;
            }
        }
        Ok(step)
    }

    /// How many times the tracker lost the hand and restarted from a frame's own solution.
    pub fn restarts(&self) -> usize {
        self.restarts
    }

    /// [`LOST_S`] in frames at the tracker's rate, at least 3.
    fn lost_frames(&self) -> usize {
        ((LOST_S * self.settings.rate_hz).ceil() as usize).max(3)
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
        self.run_observed(frames, None, |_, i, out, estimated| each(i, out, estimated))
    }

    /// [`run`](Self::run) with each frame stamped by its time in `times` (one per frame,
    /// seconds), pushed by [`push_at`](Self::push_at): lost frames restart the filter. A
    /// `times` of another length than the frames is refused before anything is pushed.
    pub fn run_at(
        &mut self,
        times: &[f64],
        frames: &[f64],
        mut each: impl FnMut(usize, &TrackerOutput, bool),
    ) -> Result<Option<usize>> {
        self.run_observed(frames, Some(times), |_, i, out, estimated| each(i, out, estimated))
    }

    /// [`run`](Self::run), with the tracker itself handed to `each` after every frame (what
    /// its state says of that frame: [`output_sd`](Self::output_sd)).
    pub(super) fn run_observed(
        &mut self,
        frames: &[f64],
        times: Option<&[f64]>,
        mut each: impl FnMut(&Self, usize, &TrackerOutput, bool),
    ) -> Result<Option<usize>> {
        if !frames.len().is_multiple_of(MARKER_FRAME_LEN) {
            return Err(Error::BadArgument {
                what: "frames",
                detail: format!("{} values is not a whole number of {MARKER_FRAME_LEN}-value frames", frames.len()),
            });
        }
        if let Some(times) = times
            && times.len() != frames.len() / MARKER_FRAME_LEN
        {
            return Err(Error::BadArgument {
                what: "times",
                detail: format!("has {} values for {} frames", times.len(), frames.len() / MARKER_FRAME_LEN),
            });
        }
        let mut start = None;
        for (i, frame) in frames.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let pushed = match times {
                // A refused stamp is named by its row, as a refused frame is.
                Some(times) => self.push_at(times[i], frame).map_err(|e| match e {
                    Error::BadArgument { what: "time", detail } => {
                        Error::BadArgument { what: "times", detail: format!("row {i}: {detail}") }
                    }
                    other => other,
                }),
                None => self.push(frame),
            };
            match pushed.map_err(|e| e.renumbered(i))? {
                Some(out) => {
                    start.get_or_insert(i);
                    each(self, i, &out, true);
                }
                None => each(self, i, &TrackerOutput::waiting(missing_markers(frame)), false),
            }
        }
        Ok(start)
    }
}

#[cfg(test)]
mod testkit;

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {
    use super::testkit::*;
    use super::*;
    use crate::body::BodyModel;

    use crate::noise::uniform_range;

    /// Bit patterns of an output (NaN compares equal to the same NaN).
    fn bits(out: &TrackerOutput) -> (Vec<u64>, u8, bool, u64) {
        (out.values().iter().map(|v| v.to_bits()).collect(), out.missing, out.refined, out.noise.to_bits())
    }

    #[test]
    fn f32_frames_are_the_f64_frames_they_widen_to() {
        // The frame type of Stream::push (f32) is taken as is: the same estimates, bit for bit,
        // as the same values given as f64; a short frame is refused either way.
        let body = BodyModel::default();
        let q = trajectory(300, 1000.0);
        let narrow: Vec<f32> = frames(&body, &q, 0.2).iter().map(|&v| v as f32).collect();
        let wide: Vec<f64> = narrow.iter().map(|&v| f64::from(v)).collect();
        let mut a = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        let mut b = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
        for (x, y) in narrow.chunks_exact(MARKER_FRAME_LEN).zip(wide.chunks_exact(MARKER_FRAME_LEN)) {
            let (x, y) = (a.push(x).unwrap().unwrap(), b.push(y).unwrap().unwrap());
            assert_eq!((bits(&x), x.status), (bits(&y), y.status));
        }
        let err = a.push(&narrow[..17]).unwrap_err();
        assert!(matches!(err, Error::FrameLength { found: 17, expected: 18, .. }), "{err}");
        assert!(err.to_string().contains("a marker frame"), "{err}");
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
                    Tracker::new(body.clone(), TrackerSettings { jerk_noise: 800.0, ..TrackerSettings::new(1000.0) })
                        .unwrap();
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
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
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
        let mut twin = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
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
    fn starts_on_the_first_complete_frame_and_rejects_bad_input() {
        let body = BodyModel::default();
        let q = trajectory(10, 1000.0);
        let mut f = frames(&body, &q, 0.0);
        f[9] = f64::NAN; // MC2.x on frame 0
        let mut tracker = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
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
            Tracker::new(BodyModel::default(), TrackerSettings { jerk_noise: -1.0, ..TrackerSettings::new(1000.0) })
                .unwrap_err();
        assert!(err.to_string().contains("jerk_noise"), "{err}");
        // Absurdly large settings are typos, refused by name, not an overflow later.
        for (settings, name) in [
            (TrackerSettings::new(1e308), "rate_hz"),
            (TrackerSettings { jerk_noise: 1e13, ..TrackerSettings::new(1000.0) }, "jerk_noise"),
            (TrackerSettings { noise_memory_s: 1e9, ..TrackerSettings::new(1000.0) }, "noise_memory_s"),
            (TrackerSettings { initial_marker_noise: 2.0, ..TrackerSettings::new(1000.0) }, "initial_marker_noise"),
        ] {
            let err = Tracker::new(BodyModel::default(), settings).unwrap_err().to_string();
            assert!(err.contains(name) && err.contains("expected a number from"), "{err}");
        }
        assert!(
            Tracker::new(BodyModel::default(), TrackerSettings { jerk_noise: 1e12, ..TrackerSettings::new(1000.0) })
                .is_ok()
        );
        tracker.reset();
        assert!(tracker.push(&f[..MARKER_FRAME_LEN]).unwrap().is_none());
    }
}
