//! Calibration to a subject's marker placement: where each segment's technical frame (built
//! from its three markers) sits in the segment's anatomical frame (the joint's axes).
//!
//! The networks were trained on the body model's placement. A lab's markers sit elsewhere —
//! 15 mm off on a hand 5 cm wide turns the hand's technical frame by ~15°, which a network
//! (or any angle computation) reads as a wrist rotation. A [`Calibration`] measured on the
//! subject undoes that: [`apply`](Calibration::apply) moves each segment's markers to where
//! the body model would put them on a segment in the same anatomical pose, so everything
//! downstream (gap filler aside, which runs before) sees placement-normalised input.
//!
//! Three ways to measure it ([`Method`]), from what a session has:
//! - **landmarks** ([`Calibration::from_neutral`] with landmarks): the epicondyles and the
//!   styloids (markers, or virtual points from a probing file), averaged in the forearm's
//!   technical frame over the frames where each is seen, give the forearm's anatomical frame as
//!   the ISB recommends (Wu et al. 2005): `y` from the mid-styloids to the mid-epicondyles
//!   (proximal), `x = y × (ulnar → radial styloid)` (volar), `z = x × y` (radial). These are
//!   the body model's forearm axes (x volar, y proximal, z radial; see [`crate::body`]), so
//!   the ISB frame is ikid's forearm frame as it is. The hand's anatomical frame is the
//!   forearm's at the neutral posture (the chosen frames): the neutral posture reads zero.
//! - **neutral** ([`Calibration::from_neutral`] without landmarks): the same for the hand; the
//!   forearm keeps the body model's placement (its markers are assumed where the model puts
//!   RSP, USP and FAP).
//! - **movements** ([`Calibration::from_trials`]): a static trial in the neutral pose and at
//!   least two movements of a single coordinate each, the clinical functional-axis protocol:
//!   - static: the hand's technical frame in the forearm's, `S = B_fᵀB_h`, at neutral;
//!   - each movement of coordinate `j`: the hand's rotation away from neutral, seen in the
//!     forearm's technical frame, turns about one fixed axis — coordinate `j`'s axis `a_j`
//!     expressed in technical coordinates, `t_j = T_fᵀ a_j` (principal axis of the rotation
//!     vectors, sign taken from the body model's placement);
//!   - `T_f` is the rotation that best maps the measured `t_j` onto the model's `a_j`
//!     (orthogonal Procrustes, SVD), and `T_h = T_f S` makes the neutral pose read zero.
//!
//! The movements method takes its axis signs from the body model's placement, so it refuses a
//! placement more than [`MAX_PLACEMENT_DEG`] from it; landmarks and neutral frames define the
//! frames themselves and take clusters mounted at any orientation.
//!
//! **Left arms** ([`Side::Left`]) are mirrored into right arms: every point's lab `z` is
//! negated (a reflection; ikid's lab has Z to the subject's right, so it is the sagittal
//! mirror and keeps gravity, −Y, as it is), both when the calibration is measured and in
//! [`apply`](Calibration::apply). The mirrored arm is a right arm, measured and read with the
//! right arm's conventions, so every angle keeps its anatomical sign on either side
//! (supination, flexion and ulnar deviation positive) and the networks, trained on right
//! arms, see a right arm. Which lab plane mirrors does not matter for the angles (two mirrors
//! differ by a rotation of the whole arm).
//!
//! Segment lengths need no calibration: angles do not depend on them.
//!
//! One file per method and what it needs: `neutral.rs` (neutral posture, and the landmarks
//! method built on it), `landmarks.rs` (segment frames from landmarks), `functional.rs`,
//! `movements.rs`, `placement.rs` (whether an uncalibrated recording fits the body model's
//! placement); here the types, the limits every method is held to, applying a calibration and
//! the helpers the methods share.

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, UnitQuaternion, Vector3};

use crate::body::{self, COORDINATES, MARKER_FRAME_LEN, N_COORDINATES, Segment};
use crate::error::{Error, Result};
use crate::features::{technical_frame, technical_in_anatomical};

mod functional;
mod landmarks;
mod mirror;
mod movements;
mod neutral;
mod placement;

use landmarks::{forearm_from_landmarks, hand_from_landmarks};
pub use mirror::{ForearmGeometry, MAX_MIRROR_CLUSTER_M, MAX_MIRROR_LANDMARK_DEG, MirrorReport};
pub use neutral::SUBJECT_SCALES;
use neutral::neutral_posture;
pub use placement::{
    MIRROR_FIT_SHARE, MIRROR_MIN_RESIDUAL_M, PLACEMENT_DISTANCE_SHARE, PLACEMENT_DISTANCE_SLACK_M,
    PLACEMENT_POSTURE_MARGIN_RAD, check_default_placement, hand_about_wrist_residual,
};

/// How long a segment's marker shape is averaged over, s, from the first frame with all its
/// markers measured: one noisy frame puts a shape millimetres off, and every angle after it by
/// as much as that turns the segment (the Tracker's templates and a stream's [`MarkerShapes`]).
pub const TEMPLATE_S: f64 = 0.5;

/// Frames a static trial needs.
pub const MIN_STATIC_FRAMES: usize = 10;
/// Neutral frames a calibration needs (with all six markers): one frame's noise is the
/// calibration's error, and its count is no evidence the posture was held.
pub const MIN_NEUTRAL_FRAMES: usize = 5;
/// Largest rotation of the hand (relative to the forearm) away from the static trial's mean
/// allowed within it, degrees, the markers' noise averaged out (see `HeldPosture`): more is
/// not a static trial.
pub const MAX_STATIC_SPREAD_DEG: f64 = 5.0;
/// How far the noise may leave a held posture's smoothed path, degrees: the window over
/// which [`HeldPosture`] averages frames grows until the noise left in it is this small.
const SMOOTHED_NOISE_DEG: f64 = 1.0;
/// Smallest range of a calibration movement, degrees: less does not show its axis.
pub const MIN_MOVEMENT_DEG: f64 = 10.0;
/// Share of a movement's rotation that must lie along one axis.
pub const MIN_AXIS_PURITY: f64 = 0.9;
/// Largest departure from perpendicular between two measured axes, degrees (the model's
/// coordinate axes are perpendicular; a larger skew means a movement mixed coordinates).
pub const MAX_AXIS_SKEW_DEG: f64 = 10.0;
/// Largest difference from the body model's placement, degrees, beyond which the markers are
/// more likely mislabelled than misplaced.
pub const MAX_PLACEMENT_DEG: f64 = 60.0;

/// Shortest distance from the mid-styloids to the mid-epicondyles, metres: less is not a
/// forearm (landmarks mislabelled, or all taken at one end).
pub const MIN_FOREARM_AXIS_M: f64 = 0.05;
/// Shortest distance between the radial and the ulnar styloid, metres.
pub const MIN_STYLOID_SPAN_M: f64 = 0.01;
/// Farthest the forearm's three markers (their centroid) may lie from the forearm their
/// landmarks span (the segment from the mid-styloids to the mid-epicondyles), metres. On the
/// real recordings a skin cluster lies 16 mm from it and a rigid plate 58 mm; the other arm's
/// plate under this arm's landmarks (a map naming one arm's markers and the other's
/// landmarks) 706 mm.
pub const MAX_CLUSTER_FROM_FOREARM_M: f64 = 0.15;
/// Largest RMS residual of a functional fit, degrees: more means the forearm turned
/// (pronation-supination) during the movement, which a two-axis fit cannot describe.
pub const MAX_FUNCTIONAL_RESIDUAL_DEG: f64 = 5.0;
/// Smallest share of an axis along the body model's placement of it for the fit to take its
/// sign from there (cos 60°: see [`MAX_PLACEMENT_DEG`]).
const MIN_SIGN_SHARE: f64 = 0.5;

/// Smallest angle between the styloid line and the forearm's long axis, degrees: below it the
/// four landmarks are too close to one line to say which way is volar.
pub const MIN_LANDMARK_ANGLE_DEG: f64 = 30.0;

/// Turns of the styloid line from the epicondyle line about the forearm's long axis (degrees,
/// positive the way a right forearm pronates) that no forearm
/// makes: a forearm turns it from about 0° (supinated) to about 180° (pronated), and the other
/// way is two landmarks under each other's labels (the styloids, or the epicondyles) or the
/// other arm's `side`, which read every flexion and deviation mirrored (measured: a real
/// recording's styloids swapped, 46° and 57° RMS with every status 0). Read in the landmark
/// frames: 52° and 137° on the two real recordings, 1° and 54° on the two OpenSim models of the
/// exam; a swap there reads -128°, -43°, -179° and -126°. Within 25° of either end a swap
/// cannot be told from a forearm near full supination or pronation: not refused.
pub const MIRRORED_TURN_DEG: (f64, f64) = (-155.0, -25.0);
/// Shortest span of the epicondyles across the long axis for [`MIRRORED_TURN_DEG`] to be read,
/// metres (one label for both when a lab has no medial one: nothing to read).
pub const MIN_EPICONDYLE_SPAN_M: f64 = 0.02;

/// Which arm. A left arm is mirrored into a right arm (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Side {
    /// The body model's own side.
    #[default]
    Right,
    /// Mirrored (lab `z` negated) into a right arm.
    Left,
}

impl Side {
    /// `"right"` or `"left"`, as files and the command line write it.
    pub fn name(self) -> &'static str {
        match self {
            Side::Right => "right",
            Side::Left => "left",
        }
    }

    /// The side named `name` (`"right"` or `"left"`).
    pub fn from_name(name: &str) -> Result<Self> {
        match name {
            "right" => Ok(Side::Right),
            "left" => Ok(Side::Left),
            _ => {
                Err(Error::BadArgument { what: "side", detail: format!("is {name:?}, expected \"right\" or \"left\"") })
            }
        }
    }

    /// Mirrors points (`x, y, z` triples back to back, lab frame) of this side's arm into a
    /// right arm's, in place: a left arm's `z` is negated, a right arm's left as it is.
    pub fn to_right(self, points: &mut [f32]) {
        if self == Side::Left {
            for z in points.iter_mut().skip(2).step_by(3) {
                *z = -*z;
            }
        }
    }
}

/// How a calibration was measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// The body model's own placement (nothing measured).
    BodyModel,
    /// Given as matrices (e.g. read back from a file).
    Matrices,
    /// Static trial plus single-coordinate movements ([`Calibration::from_trials`]).
    Movements,
    /// Epicondyles and styloids, hand at the neutral posture ([`Calibration::from_neutral`]).
    Landmarks,
    /// Neutral posture only; forearm at the body model's placement ([`Calibration::from_neutral`]).
    Neutral,
    /// Neutral posture plus the flexion and deviation axes fitted to any movement mixing them
    /// ([`Calibration::functional`]).
    Functional,
    /// The other arm's forearm frame, mirrored onto clusters mounted alike; the hand at this
    /// arm's neutral posture ([`Calibration::mirrored`]).
    Mirror,
}

impl Method {
    /// Lower-case name, as the calibration file records it.
    pub fn name(self) -> &'static str {
        match self {
            Method::BodyModel => "body_model",
            Method::Matrices => "matrices",
            Method::Movements => "movements",
            Method::Landmarks => "landmarks",
            Method::Neutral => "neutral",
            Method::Functional => "functional",
            Method::Mirror => "mirror",
        }
    }
}

/// One anatomical landmark of the forearm calibration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Landmark {
    /// Name used in marker maps and reports.
    pub name: &'static str,
    /// Where it is.
    pub description: &'static str,
}

/// The landmarks in the order of a landmark frame: `x, y, z` of each, 12 values (NaN = not
/// seen in that frame).
pub const LANDMARKS: [Landmark; 4] = [
    Landmark { name: "lateral_epicondyle", description: "lateral epicondyle of the humerus" },
    Landmark { name: "medial_epicondyle", description: "medial epicondyle of the humerus" },
    Landmark { name: "radial_styloid", description: "radial styloid process" },
    Landmark { name: "ulnar_styloid", description: "ulnar styloid process" },
];
/// Values in one landmark frame.
pub const LANDMARK_FRAME_LEN: usize = 3 * LANDMARKS.len();

/// The hand's landmarks, optional: with them the hand's anatomical frame is its own (ISB
/// style, as the forearm's) rather than the forearm's at the neutral posture.
pub const HAND_LANDMARKS: [Landmark; 2] = [
    Landmark { name: "second_metacarpal_head", description: "head of the second metacarpal (index knuckle)" },
    Landmark { name: "fifth_metacarpal_head", description: "head of the fifth metacarpal (little-finger knuckle)" },
];
/// Values in one hand landmark frame.
pub const HAND_LANDMARK_FRAME_LEN: usize = 3 * HAND_LANDMARKS.len();
/// Shortest distance from the mid-metacarpal heads to the mid-styloids, metres.
pub const MIN_HAND_AXIS_M: f64 = 0.03;

/// Landmarks seen beside the forearm's markers: `markers` are marker frames (only the
/// forearm's three are read), `landmarks` the landmark frames of the same instants
/// ([`LANDMARK_FRAME_LEN`] values each). NaN = not seen in that frame.
#[derive(Debug, Clone, Copy)]
pub struct LandmarkTrial<'a> {
    /// Marker frames, [`MARKER_FRAME_LEN`] values each.
    pub markers: &'a [f32],
    /// Landmark frames, [`LANDMARK_FRAME_LEN`] values each, one per marker frame.
    pub landmarks: &'a [f32],
    /// The hand's landmarks ([`HAND_LANDMARKS`]), [`HAND_LANDMARK_FRAME_LEN`] values per
    /// marker frame, when recorded.
    pub hand_landmarks: Option<&'a [f32]>,
}

/// Each segment's technical frame in its anatomical frame: `v_anatomical = T · v_technical`
/// (for a left arm, of the arm mirrored into a right one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// `T_f`, forearm.
    pub forearm: Rotation3<f64>,
    /// `T_h`, hand.
    pub hand: Rotation3<f64>,
    /// The arm: [`apply`](Self::apply) mirrors a left arm's frames into a right arm's.
    pub side: Side,
    /// Each segment's marker shape at the calibration's own neutral frames ([`marker_shapes`]),
    /// forearm then hand: what a stream fits its segments to ([`MarkerShapes`]) and the Tracker
    /// takes as its template, in place of a trial's first [`TEMPLATE_S`]. `None`: learned from
    /// the trial. The calibration's rotations were measured on the technical frames of these
    /// very frames; skin markers slide with the posture, so a shape learned where a trial
    /// starts (another posture) turns every angle of the trial by as much: a pyomeca task cut
    /// from frame 150 read 2.6° off instead of 0.9°.
    pub shapes: Option<SegmentShapes>,
}

/// Each segment's three markers in its technical frame (origin: their centroid), forearm then
/// hand; a left arm's as mirrored into a right arm's.
pub type SegmentShapes = [[Vector3<f64>; 3]; 2];

/// Number of values of [`SegmentShapes`] as rows: each segment's three markers, `x y z`,
/// forearm first (a calibration file's `"marker_shapes_m"`, flattened).
pub const SEGMENT_SHAPES_LEN: usize = 18;

/// [`SegmentShapes`] from their [`SEGMENT_SHAPES_LEN`] values (metres, forearm's three markers
/// then the hand's, `x y z` each, as a calibration file's `"marker_shapes_m"` rows), refused
/// unless that many and all finite: what every binding reads a file's shapes with.
pub fn shapes_from_rows(values: &[f64]) -> Result<SegmentShapes> {
    if values.len() != SEGMENT_SHAPES_LEN || !values.iter().all(|v| v.is_finite()) {
        return Err(bad(format!(
            "marker_shapes: expected {SEGMENT_SHAPES_LEN} finite values (6 rows x y z: the forearm's three \
             markers, then the hand's), got {} ({} not finite)",
            values.len(),
            values.iter().filter(|v| !v.is_finite()).count()
        )));
    }
    Ok(std::array::from_fn(|s| {
        std::array::from_fn(|k| Vector3::from_row_slice(&values[9 * s + 3 * k..9 * s + 3 * k + 3]))
    }))
}

/// The marker shapes of `frames` (whole marker frames back to back, of the `side` arm): each
/// segment's markers in its technical frame, averaged over the frames with all six measured.
/// Refused when no frame has them all, or a segment's markers are degenerate.
pub fn marker_shapes(frames: &[f32], side: Side) -> Result<SegmentShapes> {
    if !frames.len().is_multiple_of(MARKER_FRAME_LEN) {
        return Err(bad(format!("{} values are not whole marker frames of {MARKER_FRAME_LEN}", frames.len())));
    }
    let mut sum = [[Vector3::zeros(); 3]; 2];
    let mut n = 0usize;
    for (i, f) in frames.chunks_exact(MARKER_FRAME_LEN).enumerate() {
        if !f.iter().all(|v| v.is_finite()) {
            continue;
        }
        let mut frame = [0f32; MARKER_FRAME_LEN];
        frame.copy_from_slice(f);
        side.to_right(&mut frame);
        for segment in [Segment::Forearm, Segment::Hand] {
            let (origin, b) = technical_frame(&frame, segment, i)?;
            let first = body::first_marker(segment);
            for (k, point) in sum[segment as usize].iter_mut().enumerate() {
                let j = 3 * (first + k);
                let p = Vector3::new(f64::from(frame[j]), f64::from(frame[j + 1]), f64::from(frame[j + 2]));
                *point += b.transpose() * (p - origin);
            }
        }
        n += 1;
    }
    if n == 0 {
        return Err(bad("no frame has all six markers to take their shapes from".into()));
    }
    Ok(sum.map(|segment| segment.map(|p| p / n as f64)))
}

/// What the calibration learned besides the rotations, for the user to judge it by.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationReport {
    /// How it was measured.
    pub method: Method,
    /// The arm.
    pub side: Side,
    /// Per coordinate given: range of the movement (degrees) and share along its axis.
    pub movements: Vec<(usize, f64, f64)>,
    /// Angle between the measured and the body model's placement, forearm and hand, degrees.
    pub placement_deg: [f64; 2],
    /// Angle between measured axes that should be perpendicular and 90°, largest, degrees.
    pub axis_skew_deg: f64,
    /// Neutral (or static) frames used: those with all six markers.
    pub neutral_frames: usize,
    /// Largest rotation of the hand (in the forearm) from their mean, degrees, the markers'
    /// noise averaged out (see `HeldPosture`).
    pub neutral_spread_deg: f64,
    /// The markers' noise as it turns one frame's hand in the forearm, degrees RMS (from the
    /// differences between consecutive neutral frames).
    pub neutral_noise_deg: f64,
    /// Standard error of the neutral posture the calibration took (the mean over the neutral
    /// frames), degrees: how far the noise alone may have put it from the posture held.
    pub neutral_uncertainty_deg: f64,
    /// What the landmarks measured, for [`Method::Landmarks`].
    pub landmarks: Option<LandmarkReport>,
    /// What the functional fit measured, for [`Method::Functional`].
    pub functional: Option<FunctionalReport>,
    /// How the clusters and landmarks of the two arms matched, for [`Method::Mirror`].
    pub mirror: Option<MirrorReport>,
}

/// The functional fit ([`Calibration::functional`]) as it came out.
#[derive(Debug, Clone, PartialEq)]
pub struct FunctionalReport {
    /// Movement frames used (those with all six markers).
    pub frames: usize,
    /// The forearm's rotation the movement held, read with the fitted axes (supination
    /// positive), degrees.
    pub supination_held_deg: f64,
    /// Range of flexion-extension over them, read with the fitted axes, degrees.
    pub flexion_range_deg: f64,
    /// Range of radial-ulnar deviation over them, degrees.
    pub deviation_range_deg: f64,
    /// RMS of the fit's residual, the markers' noise taken out, degrees: how far the hand turned
    /// about the forearm's long axis (pronation-supination) during the movement, which the fit
    /// assumes held.
    pub residual_deg: f64,
    /// The markers' noise in that residual, degrees RMS (from consecutive frames' differences).
    pub noise_deg: f64,
}

/// The forearm's landmarks as the calibration saw them.
#[derive(Debug, Clone, PartialEq)]
pub struct LandmarkReport {
    /// Frames each landmark was averaged over ([`LANDMARKS`] order).
    pub frames: [usize; 4],
    /// Mid-styloids to mid-epicondyles, mm.
    pub long_axis_mm: f64,
    /// Radial to ulnar styloid, mm.
    pub styloid_span_mm: f64,
    /// Lateral to medial epicondyle, mm.
    pub epicondyle_span_mm: f64,
    /// Angle between the styloid line and the long axis, degrees (90 for ideal landmarks).
    pub styloid_axis_deg: f64,
    /// The subject's size estimated from it: the long axis (mid-styloids to mid-epicondyles,
    /// the forearm's length) over the default subject's forearm length — what
    /// [`BodyModel::scaled`](crate::body::BodyModel::scaled) takes as `length_factor` (its
    /// cube is the matching `mass_factor` for a subject of the default's build).
    pub length_scale: f64,
    /// The hand's own landmarks, when given: the hand's frame came from them.
    pub hand: Option<HandLandmarkReport>,
    /// The forearm's cluster and landmarks in its technical frame: what
    /// [`Calibration::mirrored`] takes to the other arm.
    pub geometry: ForearmGeometry,
}

/// The hand's landmarks as the calibration saw them.
#[derive(Debug, Clone, PartialEq)]
pub struct HandLandmarkReport {
    /// Frames with the hand's markers, both metacarpal heads and both styloids.
    pub frames: usize,
    /// Mid-metacarpal heads to the mid-styloids (the wrist), mm.
    pub long_axis_mm: f64,
    /// Second to fifth metacarpal head, mm.
    pub metacarpal_span_mm: f64,
    /// The hand's frame from its landmarks against the forearm's at the neutral frames,
    /// degrees: the neutral posture as the anatomical frames read it.
    pub neutral_offset_deg: f64,
}

/// Each segment's marker shape as a trial's first frames show it (its three markers in the
/// segment's technical frame, averaged over [`TEMPLATE_S`] of
/// frames with all of them measured), for [`Calibration::apply_fitted`]: the segment's
/// orientation is then the rotation that carries that shape onto the frame's markers by least
/// squares (Kabsch), not the technical frame built from two of them and the third's side.
/// On rigid markers the two agree exactly. Skin markers slide with the posture, and the frame
/// built from two of them turns with whichever slid: on issue #28's exam (skin markers on the
/// Gonzalez wrist) the per-frame angles' MSE was 0.015 rad² from the technical frames and
/// 0.0062 from the least-squares fit — what the Tracker, which fits its markers the same way,
/// gives. Fixed-size: no allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkerShapes {
    /// Forearm's and hand's markers in their technical frames (origin: their centroid).
    points: [[Vector3<f64>; 3]; 2],
    /// Frames each shape was averaged over.
    frames: [usize; 2],
    /// Frames to average.
    needed: usize,
}

impl MarkerShapes {
    /// Shapes to learn from the first [`TEMPLATE_S`] of frames at
    /// `rate_hz` (at least one frame).
    pub fn new(rate_hz: f64) -> Self {
        let needed = (TEMPLATE_S * rate_hz).ceil();
        MarkerShapes {
            points: [[Vector3::zeros(); 3]; 2],
            frames: [0; 2],
            needed: if needed.is_finite() && needed >= 1.0 { needed as usize } else { 1 },
        }
    }

    /// [`new`](Self::new), or the calibration's own shapes when it has them (then nothing is
    /// learned from the trial).
    pub fn for_calibration(calibration: Option<&Calibration>, rate_hz: f64) -> Self {
        let mut shapes = Self::new(rate_hz);
        if let Some(points) = calibration.and_then(|c| c.shapes) {
            shapes.points = points;
            shapes.frames = [shapes.needed; 2];
        }
        shapes
    }

    /// Frames each segment's shape (forearm, hand) was averaged over so far.
    pub fn frames(&self) -> [usize; 2] {
        self.frames
    }

    /// The orientation of `segment` in `frame` (whose technical frame is `origin`, `b`): fitted
    /// to the learned shape once there is one, after learning from this frame if `learn` and
    /// the shape is still being averaged.
    fn orientation(
        &mut self,
        frame: &[f32],
        segment: Segment,
        origin: &Vector3<f64>,
        b: &Matrix3<f64>,
        learn: bool,
    ) -> Matrix3<f64> {
        let s = segment as usize;
        let first = body::first_marker(segment);
        let measured: [Vector3<f64>; 3] = std::array::from_fn(|k| {
            let i = 3 * (first + k);
            Vector3::new(f64::from(frame[i]), f64::from(frame[i + 1]), f64::from(frame[i + 2]))
        });
        if learn && self.frames[s] < self.needed {
            self.frames[s] += 1;
            let weight = 1.0 / self.frames[s] as f64;
            for (point, m) in self.points[s].iter_mut().zip(&measured) {
                *point += weight * (b.transpose() * (m - origin) - *point);
            }
        }
        if self.frames[s] == 0 {
            return *b;
        }
        crate::reference::fit_points(&self.points[s], &measured, [1.0; 3])
            .map_or(*b, |pose| pose.rotation.to_rotation_matrix().into_inner())
    }
}

impl Default for Calibration {
    fn default() -> Self {
        Self::body_model()
    }
}

impl Calibration {
    /// The body model's own placement (what an uncalibrated stream assumes).
    pub fn body_model() -> Self {
        let (t_f, t_h) = technical_in_anatomical();
        Calibration {
            forearm: Rotation3::from_matrix_unchecked(*t_f),
            hand: Rotation3::from_matrix_unchecked(*t_h),
            side: Side::Right,
            shapes: None,
        }
    }

    /// This calibration with each segment's marker shape ([`shapes`](Self::shapes)).
    pub fn with_shapes(self, shapes: Option<SegmentShapes>) -> Self {
        Calibration { shapes, ..self }
    }

    /// How far each segment's measured placement lies from the body model's, forearm and hand,
    /// degrees (what the report's `placement_deg` and the Python repr show).
    pub fn placement_deg(&self) -> [f64; 2] {
        let default = Self::body_model();
        [angle_deg(&(self.forearm * default.forearm.inverse())), angle_deg(&(self.hand * default.hand.inverse()))]
    }

    /// A right arm's calibration from its two rotation matrices (e.g. read back from a file);
    /// refuses matrices that are not rotations to 1e-6.
    pub fn from_matrices(forearm: Matrix3<f64>, hand: Matrix3<f64>) -> Result<Self> {
        Self::from_matrices_for(forearm, hand, Side::Right)
    }

    /// [`from_matrices`](Self::from_matrices) for either arm.
    pub fn from_matrices_for(forearm: Matrix3<f64>, hand: Matrix3<f64>, side: Side) -> Result<Self> {
        for (name, m) in [("forearm", &forearm), ("hand", &hand)] {
            let off = (m.transpose() * m - Matrix3::identity()).abs().max();
            if !m.iter().all(|v| v.is_finite()) || off > 1e-6 || m.determinant() < 0.0 {
                return Err(bad(format!(
                    "the {name} matrix is not a rotation (|MᵀM − I| = {off:.2e}, det {:.3})",
                    m.determinant()
                )));
            }
        }
        Ok(Calibration {
            forearm: Rotation3::from_matrix(&forearm),
            hand: Rotation3::from_matrix(&hand),
            side,
            shapes: None,
        })
    }

    /// [`apply`](Self::apply) to every frame of `frames` (whole marker frames back to back),
    /// each checked complete first; refused at the first frame that is not (named by its
    /// index), the frames before it moved, it and those after as they were.
    pub fn apply_rows(&self, frames: &mut [f32]) -> Result<()> {
        let frames = whole_frames_mut(frames)?;
        frames.chunks_exact_mut(MARKER_FRAME_LEN).enumerate().try_for_each(|(i, f)| {
            crate::features::FeatureSet::Markers.check_frame(f, i)?;
            self.apply(f, i)
        })
    }

    /// Moves each segment's markers, in place, to where the body model puts them on a
    /// segment in the same anatomical pose (origin: the segment's marker centroid; a left
    /// arm's first mirrored into a right arm's). Refuses frames whose segments have no
    /// orientation (the frame is then left as it was); does not allocate.
    ///
    /// Each segment's orientation is its technical frame, built from two of its markers and
    /// the third's side: exact on rigid markers. A stream, which sees many frames of one
    /// subject, fits it by least squares instead ([`apply_fitted`](Self::apply_fitted)).
    pub fn apply(&self, frame: &mut [f32], frame_index: usize) -> Result<()> {
        self.apply_with(frame, frame_index, None)
    }

    /// [`apply`](Self::apply) with each segment's orientation fitted by least squares to its
    /// three markers' shape in `shapes` (learned here from the first frames given with
    /// `learn`; see [`MarkerShapes`]). Does not allocate.
    pub fn apply_fitted(
        &self,
        frame: &mut [f32],
        frame_index: usize,
        shapes: &mut MarkerShapes,
        learn: bool,
    ) -> Result<()> {
        self.apply_with(frame, frame_index, Some((shapes, learn)))
    }

    fn apply_with(
        &self,
        frame: &mut [f32],
        frame_index: usize,
        mut shapes: Option<(&mut MarkerShapes, bool)>,
    ) -> Result<()> {
        if frame.len() != MARKER_FRAME_LEN {
            return Err(bad(format!("a frame has {} values, a marker frame {MARKER_FRAME_LEN}", frame.len())));
        }
        // Both segments checked before anything changes, so that a refused frame is left as it
        // came and teaches the shapes nothing.
        technical_frame(frame, Segment::Forearm, frame_index)?;
        technical_frame(frame, Segment::Hand, frame_index)?;
        if self.side == Side::Left {
            self.side.to_right(frame);
        }
        let (t0_f, t0_h) = technical_in_anatomical();
        let local = default_local_markers();
        for (segment, t, t0) in [(Segment::Forearm, &self.forearm, t0_f), (Segment::Hand, &self.hand, t0_h)] {
            let (origin, mut b) = technical_frame(frame, segment, frame_index)?;
            if let Some((shapes, learn)) = shapes.as_mut() {
                b = shapes.orientation(frame, segment, &origin, &b, *learn);
            }
            let virtual_frame = b * t.matrix().transpose() * t0;
            let first = body::first_marker(segment);
            for m in first..first + 3 {
                let p = origin + virtual_frame * local[m];
                for (dst, v) in frame[3 * m..3 * m + 3].iter_mut().zip(p.iter()) {
                    *dst = *v as f32;
                }
            }
        }
        Ok(())
    }
}

/// Rotation angle in degrees, robust to round-off (nalgebra's `angle` is NaN for a trace a
/// hair above 3).
pub fn angle_deg(r: &Rotation3<f64>) -> f64 {
    ((r.matrix().trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
}

fn bad(detail: String) -> Error {
    Error::BadArgument { what: "calibration", detail }
}

fn whole_frames_mut(values: &mut [f32]) -> Result<&mut [f32]> {
    if !values.len().is_multiple_of(MARKER_FRAME_LEN) {
        return Err(bad(format!(
            "frames: {} values is not a whole number of {MARKER_FRAME_LEN}-value marker frames",
            values.len()
        )));
    }
    Ok(values)
}

fn whole_frames<'a>(values: &'a [f32], len: usize, what: &str) -> Result<&'a [f32]> {
    if values.is_empty() || !values.len().is_multiple_of(len) {
        return Err(bad(format!("{what}: {} values is not a whole number (≥ 1) of {len}-value frames", values.len())));
    }
    Ok(values)
}

/// A posture held over consecutive frames, told apart from the markers' noise: the mean of
/// the hand's rotations in the forearm, how far the posture itself moved, the noise and how
/// uncertain the mean is. A frame's rotation is the posture plus noise; noise differs from
/// frame to frame while a held posture does not, so half the mean square of consecutive
/// differences measures the noise (`noise_deg`), and the frames' moving average over a window
/// long enough to bring that noise below [`SMOOTHED_NOISE_DEG`] measures the posture's
/// movement (`spread_deg`, its largest distance from the mean; the raw frames' on clean
/// markers). Taken as the largest distance of single frames, 5 % marker noise read as 13–15°
/// of movement in a trial that held still.
#[derive(Debug, Clone, Copy)]
struct HeldPosture {
    mean: Rotation3<f64>,
    frames: usize,
    spread_deg: f64,
    noise_deg: f64,
    uncertainty_deg: f64,
}

impl HeldPosture {
    /// Of `rotations` in time order (at least one).
    fn of(rotations: &[Rotation3<f64>]) -> Self {
        let mean = mean_rotation(rotations);
        let n = rotations.len();
        let offsets: Vec<Vector3<f64>> = rotations
            .iter()
            .map(|r| UnitQuaternion::from_rotation_matrix(&(mean.inverse() * r)).scaled_axis())
            .collect();
        let noise_var = consecutive_noise_variance(offsets.windows(2).map(|w| (w[1] - w[0]).norm_squared()), 3);
        // Frames averaged: enough to bring the noise left below SMOOTHED_NOISE_DEG, at most a
        // third of them (so that a movement within the trial still shows).
        let target = SMOOTHED_NOISE_DEG.to_radians().powi(2);
        let window = ((noise_var / target).ceil() as usize).clamp(1, (n / 3).max(1));
        let mut sum: Vector3<f64> = offsets[..window].iter().sum();
        let mut spread = (sum / window as f64).norm();
        for i in window..n {
            sum += offsets[i] - offsets[i - window];
            spread = spread.max((sum / window as f64).norm());
        }
        HeldPosture {
            mean,
            frames: n,
            spread_deg: spread.to_degrees(),
            noise_deg: noise_var.sqrt().to_degrees(),
            uncertainty_deg: (noise_var / n as f64).sqrt().to_degrees(),
        }
    }
}

/// The noise variance (summed over `dims` dimensions) of values whose consecutive
/// differences have the squared lengths `squares`: half their median, over the median of χ²
/// with `dims` degrees of freedom per degree of freedom (Gaussian noise). The median, so that
/// a frame where the posture really moved, or a glitch, reads as neither noise nor no noise.
/// 0 without differences.
fn consecutive_noise_variance(squares: impl Iterator<Item = f64>, dims: usize) -> f64 {
    let mut squares: Vec<f64> = squares.collect();
    if squares.is_empty() {
        return 0.0;
    }
    let mid = squares.len() / 2;
    let median = *squares.select_nth_unstable_by(mid, f64::total_cmp).1;
    // Median of χ²(k) / k for k = 1, 2, 3.
    let chi2_median_per_dof = match dims {
        1 => 0.4549,
        2 => std::f64::consts::LN_2,
        _ => 0.7887,
    };
    median / 2.0 / chi2_median_per_dof
}

/// `B_fᵀ B_h` of every frame.
fn relative_rotations(frames: &[f32], what: &str) -> Result<Vec<Rotation3<f64>>> {
    if !frames.len().is_multiple_of(MARKER_FRAME_LEN) {
        return Err(bad(format!("{what}: {} values is not a whole number of marker frames", frames.len())));
    }
    frames
        .chunks_exact(MARKER_FRAME_LEN)
        .enumerate()
        .map(|(i, f)| {
            if let Some(k) = f.iter().position(|v| !v.is_finite()) {
                return Err(bad(format!(
                    "{what}: frame {i}: marker {} is missing; fill gaps first",
                    body::MARKERS[k / 3].name
                )));
            }
            let (_, b_f) = technical_frame(f, Segment::Forearm, i)?;
            let (_, b_h) = technical_frame(f, Segment::Hand, i)?;
            Ok(Rotation3::from_matrix_unchecked(b_f.transpose() * b_h))
        })
        .collect()
}

/// Chordal mean: the rotation nearest the average matrix.
fn mean_rotation(rotations: &[Rotation3<f64>]) -> Rotation3<f64> {
    let sum = rotations.iter().fold(Matrix3::zeros(), |acc, r| acc + r.matrix());
    Rotation3::from_matrix(&(sum / rotations.len() as f64))
}

/// Each marker in its segment's technical frame, for the default body.
fn default_local_markers() -> &'static [Vector3<f64>; 6] {
    static LOCAL: std::sync::OnceLock<[Vector3<f64>; 6]> = std::sync::OnceLock::new();
    LOCAL.get_or_init(|| {
        let body = body::BodyModel::default();
        let frame = body.marker_frame(&[0.0; N_COORDINATES], &body.forearm_pose(0.0)).map(|v| v as f32);
        std::array::from_fn(|m| {
            let segment = body::MARKERS[m].segment;
            let (origin, b) = technical_frame(&frame, segment, 0).expect("the body model's markers span each segment");
            let i = 3 * m;
            b.transpose() * (Vector3::new(frame[i] as f64, frame[i + 1] as f64, frame[i + 2] as f64) - origin)
        })
    })
}

#[cfg(test)]
mod held_tests;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::FeatureSet;

    /// Frames of the default body whose markers are shifted by `shift` (metres, segment
    /// frame) and scaled by `scale`, at angles `q`.
    fn frames(q: &[[f64; 3]], shift: &[[f64; 3]; 6], scale: f64, shoulder: f64) -> Vec<f32> {
        let mut body = body::BodyModel::scaled(scale, scale);
        for (o, s) in body.marker_offsets.iter_mut().zip(shift) {
            for k in 0..3 {
                o[k] += s[k];
            }
        }
        let pose = body.forearm_pose(shoulder);
        q.iter().flat_map(|q| body.marker_frame(q, &pose).map(|v| v as f32)).collect()
    }

    fn single(j: usize, n: usize, amplitude: f64) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let mut q = [0.0; 3];
                q[j] = amplitude * (i as f64 / n as f64 * std::f64::consts::TAU).sin();
                q
            })
            .collect()
    }

    const SHIFT: [[f64; 3]; 6] = [
        [0.0, 0.01, 0.015],
        [-0.012, 0.0, 0.01],
        [0.015, -0.01, 0.0],
        [0.0, 0.015, -0.01],
        [0.01, 0.0, 0.015],
        [-0.015, 0.01, 0.0],
    ];

    /// The hand's lab rotation from `before` to `after` as a calibration applied with `shapes`
    /// (or without, `None`) reads it: the applied frames' hand technical frames, `B₂ B₁ᵀ`.
    fn hand_turn(before: &[f32], after: &[f32], shapes: Option<&mut MarkerShapes>) -> Matrix3<f64> {
        let cal = Calibration::body_model();
        let (mut one, mut two) = (before.to_vec(), after.to_vec());
        match shapes {
            Some(shapes) => {
                cal.apply_fitted(&mut one, 0, shapes, true).unwrap();
                cal.apply_fitted(&mut two, 1, shapes, true).unwrap();
            }
            None => {
                cal.apply(&mut one, 0).unwrap();
                cal.apply(&mut two, 1).unwrap();
            }
        }
        let (_, b1) = technical_frame(&one, Segment::Hand, 0).unwrap();
        let (_, b2) = technical_frame(&two, Segment::Hand, 1).unwrap();
        b2 * b1.transpose()
    }

    #[test]
    fn a_stream_fits_a_sliding_marker_by_least_squares_over_the_segments_three() {
        // The hand turned 0.3 rad about its markers' plane normal, then one marker slid 6 mm
        // in that plane (skin). The least-squares turn of three points in a plane has a closed
        // form (2-D Procrustes about their centroids): θ = atan2(Σ n·(tₖ × mₖ), Σ tₖ·mₖ).
        let before = frames(&[[0.0; 3]], &[[0.0; 3]; 6], 1.0, 0.3);
        let hand = |f: &[f32], k: usize| Vector3::from_fn(|i, _| f64::from(f[3 * (3 + k) + i]));
        let pts: [Vector3<f64>; 3] = std::array::from_fn(|k| hand(&before, k));
        let centroid = (pts[0] + pts[1] + pts[2]) / 3.0;
        let n = (pts[1] - pts[0]).cross(&(pts[2] - pts[0])).normalize();
        let turn = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(n), 0.3);
        let slide = n.cross(&(pts[1] - pts[0])).normalize() * 0.006;
        let mut after = before.clone();
        for k in 0..3 {
            let p = centroid + turn * (pts[k] - centroid) + if k == 1 { slide } else { Vector3::zeros() };
            for i in 0..3 {
                after[3 * (3 + k) + i] = p[i] as f32;
            }
        }
        let moved: [Vector3<f64>; 3] = std::array::from_fn(|k| hand(&after, k));
        let moved_centroid = (moved[0] + moved[1] + moved[2]) / 3.0;
        let (mut cross, mut dot) = (0.0, 0.0);
        for k in 0..3 {
            let (t, m) = (pts[k] - centroid, moved[k] - moved_centroid);
            cross += n.dot(&t.cross(&m));
            dot += t.dot(&m);
        }
        let least_squares = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(n), cross.atan2(dot));
        // One frame to learn the shape from (0.5 s at 2 Hz).
        let mut shapes = MarkerShapes::new(2.0);
        let fitted = Rotation3::from_matrix_unchecked(hand_turn(&before, &after, Some(&mut shapes)));
        assert_eq!(shapes.frames(), [1, 1], "the second frame is past the shape's first 0.5 s");
        let off = angle_deg(&(fitted * least_squares.inverse()));
        assert!(off < 1e-3, "fitted turn {off}° from the least-squares one");
        // The technical frame turns with the two markers it is built from: further off.
        let two_markers = Rotation3::from_matrix_unchecked(hand_turn(&before, &after, None));
        let gs_off = angle_deg(&(two_markers * least_squares.inverse()));
        assert!(gs_off > 1.0, "the slide should turn the technical frame: {gs_off}°");
        // Rigid markers: the fit and the technical frame agree.
        let rigid = frames(&[[0.4, -0.5, 0.2]], &[[0.0; 3]; 6], 1.0, 0.3);
        let mut shapes = MarkerShapes::new(2.0);
        let fitted = hand_turn(&before, &rigid, Some(&mut shapes));
        let built = hand_turn(&before, &rigid, None);
        assert!((fitted - built).abs().max() < 1e-6, "{fitted} vs {built}");
    }

    #[test]
    fn shapes_from_rows_reads_a_files_rows_forearm_first_and_refuses_any_other_count_or_a_nan() {
        // The oracle: value v = 10 s + 3 k + c + 1 at segment s, marker k, coordinate c, laid
        // out row by row as "marker_shapes_m" is (forearm's three markers, then the hand's).
        let rows: Vec<f64> = (0..SEGMENT_SHAPES_LEN).map(|i| (10 * (i / 9) + i % 9 + 1) as f64).collect();
        let shapes = shapes_from_rows(&rows).unwrap();
        for (s, segment) in shapes.iter().enumerate() {
            for (k, marker) in segment.iter().enumerate() {
                for (c, v) in marker.iter().enumerate() {
                    assert_eq!(*v, (10 * s + 3 * k + c + 1) as f64, "segment {s} marker {k} axis {c}");
                }
            }
        }
        assert!(shapes_from_rows(&rows[..17]).is_err());
        assert!(shapes_from_rows(&[rows.clone(), vec![1.0]].concat()).is_err());
        for bad in [f64::NAN, f64::INFINITY] {
            let mut r = rows.clone();
            r[7] = bad;
            let err = shapes_from_rows(&r).unwrap_err().to_string();
            assert!(err.contains("marker_shapes") && err.contains("1 not finite"), "{err}");
        }
    }

    #[test]
    fn marker_shapes_are_the_calibration_frames_shapes_and_a_preset_one_is_fitted_from_the_first_frame() {
        // The oracle: the hand turned 0.3 rad with one marker slid 6 mm (as above), its turn by
        // least squares. The shapes are those of `before` (the calibration's frames: a frame
        // with a marker missing is left out of the mean, a left arm's taken mirrored), so a
        // stream given them fits `after` at once, with no frame of the trial learned.
        let before = frames(&[[0.4, -0.5, 0.2]], &[[0.0; 3]; 6], 1.0, 0.3);
        let mut gappy = before.clone();
        gappy.extend(before.iter().enumerate().map(|(i, v)| if i == 4 { f32::NAN } else { v * 1.3 }));
        let shapes = marker_shapes(&gappy, Side::Right).unwrap();
        let mut learned = MarkerShapes::new(2.0);
        let mut probe = before.clone();
        Calibration::body_model().apply_fitted(&mut probe, 0, &mut learned, true).unwrap();
        for (s, segment) in shapes.iter().enumerate() {
            for (k, p) in segment.iter().enumerate() {
                assert!(
                    (p - learned.points[s][k]).norm() < 1e-9,
                    "segment {s} marker {k}: {p} vs {}",
                    learned.points[s][k]
                );
            }
        }
        let mut left = before.clone();
        Side::Left.to_right(&mut left);
        let mirrored = marker_shapes(&left, Side::Left).unwrap();
        assert!(mirrored.iter().flatten().zip(shapes.iter().flatten()).all(|(a, b)| (a - b).norm() < 1e-9));
        let all_gaps = vec![f32::NAN; MARKER_FRAME_LEN];
        assert!(marker_shapes(&all_gaps, Side::Right).is_err());
        // Over several frames, the mean of each frame's shapes: a hand marker 6 mm off in one
        // of two frames is 3 mm off in the shapes.
        let mut off = before.clone();
        off[13] += 0.006;
        let (one, other) = (marker_shapes(&before, Side::Right).unwrap(), marker_shapes(&off, Side::Right).unwrap());
        let both = marker_shapes(&[before.clone(), off].concat(), Side::Right).unwrap();
        for s in 0..2 {
            for k in 0..3 {
                let mean = (one[s][k] + other[s][k]) / 2.0;
                assert!((both[s][k] - mean).norm() < 1e-9, "segment {s} marker {k}: {} vs {mean}", both[s][k]);
            }
        }
        assert!((one[1][1] - other[1][1]).norm() > 1e-3, "the hand's shape differs between the frames");
        // Preset from the calibration: nothing left to learn, and the first frame is fitted.
        let cal = Calibration::body_model().with_shapes(Some(shapes));
        let preset = MarkerShapes::for_calibration(Some(&cal), 2.0);
        assert_eq!(preset.frames(), [1, 1]);
        assert_eq!(MarkerShapes::for_calibration(Some(&Calibration::body_model()), 2.0).frames(), [0, 0]);
        let mut slid = before.clone();
        let hand = |f: &[f32], k: usize| Vector3::new(f[9 + 3 * k] as f64, f[10 + 3 * k] as f64, f[11 + 3 * k] as f64);
        slid[12..15].copy_from_slice(&{
            let p = hand(&before, 1) + Vector3::new(0.0, 0.0, 0.006);
            [p.x as f32, p.y as f32, p.z as f32]
        });
        let mut from_preset = preset;
        let mut a = slid.clone();
        cal.apply_fitted(&mut a, 0, &mut from_preset, true).unwrap();
        let mut from_before = MarkerShapes::new(2.0);
        let mut b = before.clone();
        cal.apply_fitted(&mut b, 0, &mut from_before, true).unwrap();
        let mut c = slid.clone();
        cal.apply_fitted(&mut c, 1, &mut from_before, true).unwrap();
        assert!(a.iter().zip(&c).all(|(x, y)| (x - y).abs() < 1e-6), "preset shapes fit as shapes learned from before");
    }

    #[test]
    fn calibrated_angles_are_exact_under_misplaced_markers_and_another_size() {
        let statics = frames(&[[0.0; 3]; 20], &SHIFT, 1.2, 0.4);
        let moves: Vec<(usize, Vec<f32>)> =
            (0..2).map(|j| (j, frames(&single(j, 200, 0.6), &SHIFT, 1.2, 0.4))).collect();
        let refs: Vec<(usize, &[f32])> = moves.iter().map(|(j, f)| (*j, f.as_slice())).collect();
        let (cal, report) = Calibration::from_trials(&statics, &refs).unwrap();
        assert!(report.placement_deg[1] > 5.0, "the shift should matter: {report:?}");
        assert!(report.axis_skew_deg < 1e-3, "{report:?}");
        let q = [0.5, -0.7, 0.3];
        let mut frame = frames(&[q], &SHIFT, 1.2, 0.4);
        let mut raw = [0.0f32; 3];
        FeatureSet::Angles.compute(&frame, &mut raw, 0).unwrap();
        assert!((raw[1] as f64 - q[1]).abs() > 0.02, "uncalibrated should be off: {raw:?}");
        cal.apply(&mut frame, 0).unwrap();
        let mut out = [0.0f32; 3];
        FeatureSet::Angles.compute(&frame, &mut out, 0).unwrap();
        for k in 0..3 {
            assert!((out[k] as f64 - q[k]).abs() < 1e-5, "{out:?} vs {q:?}");
        }
    }

    /// A seeded random marker placement: every marker moved up to `reach` metres per axis.
    fn random_shift(seed: u64, reach: f64) -> [[f64; 3]; 6] {
        let mut rng = crate::rng::SplitMix::new(seed);
        std::array::from_fn(|_| std::array::from_fn(|_| rng.uniform(-reach, reach)))
    }

    #[test]
    fn calibration_recovers_angles_for_many_placements_and_any_pair_of_movements() {
        // Two movements leave the third axis to the Procrustes fit's reflection guard: each
        // placement and pair must still give a proper rotation that reads the angles exactly.
        let q = [-0.4, 0.5, 0.25];
        for seed in 0..12u64 {
            let shift = random_shift(seed, 0.015);
            let pair = [(0, 1), (0, 2), (1, 2)][seed as usize % 3];
            let statics = frames(&[[0.0; 3]; 12], &shift, 0.9, 0.2);
            let moves: Vec<(usize, Vec<f32>)> =
                [pair.0, pair.1].iter().map(|&j| (j, frames(&single(j, 120, 0.5), &shift, 0.9, 0.2))).collect();
            let refs: Vec<(usize, &[f32])> = moves.iter().map(|(j, f)| (*j, f.as_slice())).collect();
            let (cal, _) = Calibration::from_trials(&statics, &refs).unwrap();
            for r in [cal.forearm, cal.hand] {
                assert!((r.matrix().determinant() - 1.0).abs() < 1e-9, "seed {seed}: not a rotation");
            }
            let mut frame = frames(&[q], &shift, 0.9, 0.2);
            cal.apply(&mut frame, 0).unwrap();
            let mut out = [0.0f32; 3];
            FeatureSet::Angles.compute(&frame, &mut out, 0).unwrap();
            for k in 0..3 {
                assert!((out[k] as f64 - q[k]).abs() < 1e-4, "seed {seed} pair {pair:?}: {out:?} vs {q:?}");
            }
        }
    }

    #[test]
    fn markers_far_from_the_models_placement_are_refused_as_mislabelled() {
        // The hand's markers turned 90° about the hand's long axis (as if MC2/MC5/MCB were
        // labelled round the wrong way): beyond the 60° a placement may differ.
        let body = body::BodyModel::default();
        let turn = Rotation3::from_axis_angle(&Vector3::x_axis(), 90f64.to_radians());
        let mut shift = [[0.0; 3]; 6];
        for (s, offset) in shift.iter_mut().zip(&body.marker_offsets).skip(3) {
            let o = Vector3::from(*offset);
            let moved = turn * o - o;
            *s = [moved.x, moved.y, moved.z];
        }
        let statics = frames(&[[0.0; 3]; 20], &shift, 1.0, 0.0);
        let moves: Vec<(usize, Vec<f32>)> =
            (0..2).map(|j| (j, frames(&single(j, 200, 0.6), &shift, 1.0, 0.0))).collect();
        let refs: Vec<(usize, &[f32])> = moves.iter().map(|(j, f)| (*j, f.as_slice())).collect();
        let err = Calibration::from_trials(&statics, &refs).unwrap_err().to_string();
        assert!(err.contains("from the body model's placement (at most 60°): are they labelled right?"), "{err}");
        // 15 mm misplacements are well inside it.
        let statics = frames(&[[0.0; 3]; 20], &SHIFT, 1.0, 0.0);
        let moves: Vec<(usize, Vec<f32>)> =
            (0..2).map(|j| (j, frames(&single(j, 200, 0.6), &SHIFT, 1.0, 0.0))).collect();
        let refs: Vec<(usize, &[f32])> = moves.iter().map(|(j, f)| (*j, f.as_slice())).collect();
        let (_, report) = Calibration::from_trials(&statics, &refs).unwrap();
        assert!(report.placement_deg.iter().all(|&a| a < MAX_PLACEMENT_DEG), "{report:?}");
    }

    #[test]
    fn a_movement_is_measured_by_its_range_and_its_share_about_one_axis() {
        let statics = frames(&[[0.0; 3]; 20], &SHIFT, 1.0, 0.0);
        let flex = frames(&single(1, 400, 0.6), &SHIFT, 1.0, 0.0);
        let pron = frames(&single(0, 400, 0.5), &SHIFT, 1.0, 0.0);
        let (_, report) = Calibration::from_trials(&statics, &[(1, &flex), (0, &pron)]).unwrap();
        // By hand: a sine of amplitude a spans 2a; a single coordinate is all about its axis.
        for (&(j, range, purity), amplitude) in report.movements.iter().zip([0.6f64, 0.5]) {
            assert!((range - 2.0 * amplitude.to_degrees()).abs() < 0.5, "coordinate {j}: {range}°");
            assert!(purity > 0.999 && purity <= 1.0, "coordinate {j}: {purity}");
        }
        // A circle (s_p as a sine, e_f as a cosine) turns about two axes equally: about 50 %.
        let circle: Vec<[f64; 3]> = (0..400)
            .map(|i| {
                let t = i as f64 / 400.0 * std::f64::consts::TAU;
                [0.4 * t.sin(), 0.4 * t.cos(), 0.0]
            })
            .collect();
        let circle = frames(&circle, &SHIFT, 1.0, 0.0);
        let err = Calibration::from_trials(&statics, &[(1, &flex), (0, &circle)]).unwrap_err().to_string();
        assert!(err.contains("ra_wr_s_p movement is 5") && err.contains("% about one axis (at least 90 %)"), "{err}");
    }

    #[test]
    fn a_static_trial_needs_its_documented_number_of_frames() {
        let flex = frames(&single(1, 100, 0.6), &SHIFT, 1.0, 0.0);
        let pron = frames(&single(0, 100, 0.6), &SHIFT, 1.0, 0.0);
        let moves: [(usize, &[f32]); 2] = [(1, &flex), (0, &pron)];
        for n in [1, MIN_STATIC_FRAMES - 1] {
            let statics = frames(&vec![[0.0; 3]; n], &SHIFT, 1.0, 0.0);
            let err = Calibration::from_trials(&statics, &moves).unwrap_err().to_string();
            assert!(err.contains(&format!("has {n} frames, at least 10")), "{err}");
        }
        let statics = frames(&[[0.0; 3]; MIN_STATIC_FRAMES], &SHIFT, 1.0, 0.0);
        assert!(Calibration::from_trials(&statics, &moves).is_ok());
    }

    #[test]
    fn from_matrices_round_trips_a_calibration_and_refuses_what_is_not_a_rotation() {
        let statics = frames(&[[0.0; 3]; 20], &SHIFT, 1.0, 0.0);
        let moves: Vec<(usize, Vec<f32>)> =
            (0..2).map(|j| (j, frames(&single(j, 200, 0.6), &SHIFT, 1.0, 0.0))).collect();
        let refs: Vec<(usize, &[f32])> = moves.iter().map(|(j, f)| (*j, f.as_slice())).collect();
        let (cal, _) = Calibration::from_trials(&statics, &refs).unwrap();
        let back = Calibration::from_matrices(*cal.forearm.matrix(), *cal.hand.matrix()).unwrap();
        assert!((back.forearm.matrix() - cal.forearm.matrix()).abs().max() < 1e-12);
        assert!((back.hand.matrix() - cal.hand.matrix()).abs().max() < 1e-12);
        assert_ne!(back, Calibration::body_model(), "the measured placement differs from the model's");
        let reflection = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        let stretched = Matrix3::from_diagonal(&Vector3::new(1.0, 1.01, 1.0));
        let mut nan = Matrix3::identity();
        nan[(1, 2)] = f64::NAN;
        for (m, which) in [(reflection, "forearm"), (stretched, "forearm"), (nan, "forearm")] {
            let err = Calibration::from_matrices(m, Matrix3::identity()).unwrap_err().to_string();
            assert!(err.contains(&format!("the {which} matrix is not a rotation")), "{err}");
        }
        let err = Calibration::from_matrices(Matrix3::identity(), reflection).unwrap_err().to_string();
        assert!(err.contains("the hand matrix is not a rotation"), "{err}");
    }

    #[test]
    fn body_model_calibration_changes_no_angle() {
        let mut frame = frames(&[[0.3, 0.2, -0.1]], &[[0.0; 3]; 6], 1.0, 0.0);
        let before = frame.clone();
        Calibration::body_model().apply(&mut frame, 0).unwrap();
        for (a, b) in frame.iter().zip(&before) {
            assert!((a - b).abs() < 1e-6);
        }
    }

    /// Landmarks of the default forearm (scaled), in its anatomical frame: symmetric about
    /// the long axis, so that the ISB frame they give is the body model's forearm frame.
    fn landmark_offsets(scale: f64) -> [[f64; 3]; 4] {
        [[0.0, 0.26, 0.035], [0.0, 0.26, -0.035], [0.0, 0.005, 0.03], [0.0, 0.005, -0.03]]
            .map(|p: [f64; 3]| p.map(|c| c * scale))
    }

    /// Neutral marker frames of a subject whose markers are shifted by `shift` and whose
    /// hand cluster is turned by `turn` about the hand's long axis, with its landmark frames.
    fn neutral_session(n: usize, shift: &[[f64; 3]; 6], turn_deg: f64, q: [f64; 3]) -> (Vec<f32>, Vec<f32>) {
        let mut body = body::BodyModel::scaled(1.1, 1.1);
        let turn = Rotation3::from_axis_angle(&Vector3::y_axis(), turn_deg.to_radians());
        for (m, (o, s)) in body.marker_offsets.iter_mut().zip(shift).enumerate() {
            let moved = Vector3::from(*o) + Vector3::from(*s);
            let moved = if m >= 3 { turn * moved } else { moved };
            *o = [moved.x, moved.y, moved.z];
        }
        let pose = body.forearm_pose(0.5);
        let markers: Vec<f32> = (0..n).flat_map(|_| body.marker_frame(&q, &pose).map(|v| v as f32)).collect();
        let landmarks: Vec<f32> = (0..n)
            .flat_map(|_| {
                landmark_offsets(1.1).into_iter().flat_map(|p| {
                    let p = pose * nalgebra::Point3::from(p);
                    [p.x as f32, p.y as f32, p.z as f32]
                })
            })
            .collect();
        (markers, landmarks)
    }

    fn angles_after(cal: &Calibration, frame: &[f32]) -> [f32; 3] {
        let mut frame = frame.to_vec();
        cal.apply(&mut frame, 0).unwrap();
        let mut out = [0.0f32; 3];
        FeatureSet::Angles.compute(&frame, &mut out, 0).unwrap();
        out
    }

    fn mirrored(frames: &[f32]) -> Vec<f32> {
        let mut m = frames.to_vec();
        Side::Left.to_right(&mut m);
        m
    }

    #[test]
    fn landmarks_estimate_the_subjects_size_from_the_forearms_length() {
        // Epicondyles at the elbow and styloids at the wrist of a subject 1.1× the default:
        // the long axis is the subject's forearm, so the estimate is the subject's scale.
        let scale = 1.1;
        let body = body::BodyModel::scaled(scale, scale.powi(3));
        let length = body.forearm.length;
        let pose = body.forearm_pose(0.5);
        let (markers, _) = neutral_session(10, &[[0.0; 3]; 6], 0.0, [0.0; 3]);
        let points = [[0.0, length, 0.035], [0.0, length, -0.035], [0.0, 0.0, 0.03], [0.0, 0.0, -0.03]];
        let landmarks: Vec<f32> = (0..10)
            .flat_map(|_| {
                points.into_iter().flat_map(|p| {
                    let p = pose * nalgebra::Point3::from(p);
                    [p.x as f32, p.y as f32, p.z as f32]
                })
            })
            .collect();
        let trial = LandmarkTrial { markers: &markers, landmarks: &landmarks, hand_landmarks: None };
        let (_, report) = Calibration::from_neutral(&markers, Some(trial), Side::Right).unwrap();
        let lm = report.landmarks.unwrap();
        assert!((lm.length_scale - scale).abs() < 1e-5, "{lm:?}");
        assert!((lm.long_axis_mm - 1e3 * length).abs() < 1e-2, "{lm:?}");
    }

    #[test]
    fn landmarks_calibrate_misplaced_clusters_at_any_orientation_through_gaps() {
        // The hand cluster turned 120° about the hand's long axis: far beyond the 60° the
        // movements method allows, and no matter here.
        let (mut markers, mut landmarks) = neutral_session(12, &SHIFT, 120.0, [0.0; 3]);
        markers[3 * 18 + 10] = f32::NAN; // MC2 missing in frame 3
        markers[5 * 18 + 1] = f32::NAN; // USP missing in frame 5
        for i in 0..6 {
            landmarks[i * 12 + 6] = f32::NAN; // the radial styloid seen in half the frames only
        }
        let trial = LandmarkTrial { markers: &markers, landmarks: &landmarks, hand_landmarks: None };
        let (cal, report) = Calibration::from_neutral(&markers, Some(trial), Side::Right).unwrap();
        assert_eq!(report.method, Method::Landmarks);
        assert_eq!(report.neutral_frames, 10, "two frames miss a marker");
        let lm = report.landmarks.as_ref().unwrap();
        assert_eq!(lm.frames, [11, 11, 6, 11], "frame 5 has no forearm frame; frames 0-5 no radial styloid");
        assert!((lm.styloid_span_mm - 66.0).abs() < 1e-3 && (lm.styloid_axis_deg - 90.0).abs() < 1e-3, "{lm:?}");
        // The epicondyles at z = ±35 mm (×1.1).
        assert!((lm.epicondyle_span_mm - 77.0).abs() < 1e-3, "{lm:?}");
        assert!(report.placement_deg[1] > MAX_PLACEMENT_DEG, "{report:?}");
        let q = [0.5, -0.6, 0.25];
        let (frame, _) = neutral_session(1, &SHIFT, 120.0, q);
        let out = angles_after(&cal, &frame);
        for k in 0..3 {
            assert!((out[k] as f64 - q[k]).abs() < 1e-4, "{out:?} vs {q:?}");
        }
    }

    #[test]
    fn styloids_turned_the_other_way_than_a_forearm_turns_them_are_refused() {
        // The styloids turned about the forearm's long axis (the body model's y) from the
        // epicondyle line: a forearm turns them 0° (supinated) to 180° (pronated) one way. The
        // oracle is the turn given: 60° and 170° accepted; -60° and -120° (two labels swapped:
        // a 60° pronation read with the styloids' labels exchanged) refused, naming the turn;
        // -179° and 10° (within 25° of an end: a swap there cannot be told) accepted.
        let (markers, _) = neutral_session(6, &[[0.0; 3]; 6], 0.0, [0.0; 3]);
        let body = body::BodyModel::scaled(1.1, 1.1);
        let pose = body.forearm_pose(0.5);
        let at = |turn_deg: f64| -> Vec<f32> {
            let turn = Rotation3::from_axis_angle(&Vector3::y_axis(), turn_deg.to_radians());
            let points = landmark_offsets(1.1);
            let centre = (Vector3::from(points[2]) + Vector3::from(points[3])) / 2.0;
            (0..6)
                .flat_map(|_| {
                    points.into_iter().enumerate().flat_map(|(k, p)| {
                        let p = Vector3::from(p);
                        let p = if k >= 2 { centre + turn * (p - centre) } else { p };
                        let p = pose * nalgebra::Point3::from(p);
                        [p.x as f32, p.y as f32, p.z as f32]
                    })
                })
                .collect()
        };
        for (turn, refused) in
            [(60.0, false), (170.0, false), (-60.0, true), (-120.0, true), (-179.0, false), (10.0, false)]
        {
            let landmarks = at(turn);
            let trial = LandmarkTrial { markers: &markers, landmarks: &landmarks, hand_landmarks: None };
            match Calibration::from_neutral(&markers, Some(trial), Side::Right) {
                Ok(_) => assert!(!refused, "{turn}° accepted"),
                Err(e) => {
                    let e = e.to_string();
                    assert!(refused, "{turn}° refused: {e}");
                    assert!(
                        e.contains(&format!("turned {turn:.0}°")) && e.contains("under each other's labels"),
                        "{e}"
                    );
                }
            }
        }
        // One label for both epicondyles (no medial one): nothing to read, nothing refused.
        let mut one = at(-120.0);
        for f in one.chunks_exact_mut(12) {
            let (lateral, rest) = f.split_at_mut(3);
            rest[..3].copy_from_slice(lateral);
        }
        let trial = LandmarkTrial { markers: &markers, landmarks: &one, hand_landmarks: None };
        assert!(Calibration::from_neutral(&markers, Some(trial), Side::Right).is_ok());
    }

    #[test]
    fn landmarks_of_another_arm_are_refused_naming_how_far_the_markers_are_from_them() {
        // The landmarks as recorded, then moved 0.7 m across the body (the other arm's, as a
        // map naming one arm's plate and the other's landmarks gives; racing: 706 mm).
        let (markers, landmarks) = neutral_session(10, &SHIFT, 40.0, [0.0; 3]);
        let trial = LandmarkTrial { markers: &markers, landmarks: &landmarks, hand_landmarks: None };
        assert!(Calibration::from_neutral(&markers, Some(trial), Side::Right).is_ok());
        // Along the forearm too: 0.4 m along its long axis puts the markers beyond an end of the
        // forearm the landmarks span, though on its line.
        let at = |k: usize| Vector3::from_fn(|r, _| f64::from(landmarks[3 * k + r]));
        let long = ((at(0) + at(1)) / 2.0 - (at(2) + at(3)) / 2.0).normalize();
        let z = Vector3::z();
        for (shift, across_m, refused) in [(z, 0.1, false), (z, 0.7, true), (long, 0.4, true)] {
            let moved: Vec<f32> =
                landmarks.iter().enumerate().map(|(i, &v)| v + (across_m * shift[i % 3]) as f32).collect();
            let trial = LandmarkTrial { markers: &markers, landmarks: &moved, hand_landmarks: None };
            let got = Calibration::from_neutral(&markers, Some(trial), Side::Right);
            if refused {
                let err = got.unwrap_err().to_string();
                assert!(err.contains("landmarks are not on the arm those markers are on"), "{err}");
                let mm: f64 = err.split("markers are ").nth(1).unwrap().split(" mm").next().unwrap().parse().unwrap();
                let expected = if shift == z { 650.0..=750.0 } else { 250.0..=450.0 };
                assert!(expected.contains(&mm), "{err}");
            } else {
                assert!(got.is_ok(), "{across_m} m: {:?}", got.err());
            }
        }
    }

    #[test]
    fn a_left_arm_is_its_mirror_image_and_reads_the_same_anatomical_angles() {
        // A left arm in the same anatomical pose as a right one is the right one's mirror image.
        let (markers, landmarks) = neutral_session(10, &SHIFT, 40.0, [0.0; 3]);
        let (markers, landmarks) = (mirrored(&markers), mirrored(&landmarks));
        let trial = LandmarkTrial { markers: &markers, landmarks: &landmarks, hand_landmarks: None };
        let (cal, report) = Calibration::from_neutral(&markers, Some(trial), Side::Left).unwrap();
        assert_eq!((cal.side, report.side), (Side::Left, Side::Left));
        let q = [-0.4, 0.5, -0.2];
        let (frame, _) = neutral_session(1, &SHIFT, 40.0, q);
        let out = angles_after(&cal, &mirrored(&frame));
        for k in 0..3 {
            assert!((out[k] as f64 - q[k]).abs() < 1e-4, "left: {out:?} vs {q:?}");
        }
        // Read as a right arm, the mirror image's supination and adduction change sign.
        let as_right = Calibration { side: Side::Right, ..cal };
        let out = angles_after(&as_right, &frame);
        assert!((out[0] as f64 + q[0]).abs() > 0.1, "{out:?}");
        let back = Calibration::from_matrices_for(*cal.forearm.matrix(), *cal.hand.matrix(), Side::Left).unwrap();
        assert_eq!(back.side, Side::Left);
        assert_eq!(Side::from_name("left").unwrap(), Side::Left);
        assert!(Side::from_name("both").unwrap_err().to_string().contains("expected \"right\" or \"left\""));
    }

    #[test]
    fn neutral_frames_alone_calibrate_the_hand_to_the_forearm() {
        // Forearm markers where the body model puts them, the hand's anywhere.
        let mut shift = SHIFT;
        shift[..3].copy_from_slice(&[[0.0; 3]; 3]);
        let (markers, _) = neutral_session(10, &shift, -75.0, [0.0; 3]);
        let (cal, report) = Calibration::from_neutral(&markers, None, Side::Right).unwrap();
        assert_eq!(report.method, Method::Neutral);
        assert!(report.placement_deg[0] < 1e-9 && report.landmarks.is_none(), "{report:?}");
        let q = [0.3, 0.4, -0.15];
        let (frame, _) = neutral_session(1, &shift, -75.0, q);
        let out = angles_after(&cal, &frame);
        for k in 0..3 {
            assert!((out[k] as f64 - q[k]).abs() < 1e-4, "{out:?} vs {q:?}");
        }
    }

    #[test]
    fn bad_landmarks_and_neutral_frames_say_what_to_record() {
        let (markers, landmarks) = neutral_session(10, &SHIFT, 0.0, [0.0; 3]);
        let run = |m: &[f32], l: &[f32]| {
            let trial = LandmarkTrial { markers: m, landmarks: l, hand_landmarks: None };
            Calibration::from_neutral(m, Some(trial), Side::Right).unwrap_err().to_string()
        };
        let mut gone = landmarks.clone();
        gone.iter_mut().skip(9).step_by(12).for_each(|v| *v = f32::NAN);
        let err = run(&markers, &gone);
        assert!(
            err.contains("landmark ulnar_styloid (ulnar styloid process) is missing in every one of the 10"),
            "{err}"
        );
        assert!(err.contains("record it"), "{err}");
        // Seen, but only in three frames missing RSP: how often it was seen, and why unused.
        let (mut partial, mut seldom) = (markers.clone(), gone.clone());
        for i in 0..3 {
            partial[18 * i] = f32::NAN;
            seldom[12 * i + 9..12 * i + 12].copy_from_slice(&landmarks[12 * i + 9..12 * i + 12]);
        }
        let trial = LandmarkTrial { markers: &partial, landmarks: &seldom, hand_landmarks: None };
        let err = Calibration::from_neutral(&markers, Some(trial), Side::Right).unwrap_err().to_string();
        assert!(
            err.contains(
                "landmark ulnar_styloid (ulnar styloid process) is seen in 3 but never with the forearm's three \
                 markers of the 10"
            ),
            "{err}"
        );
        // The styloids on the long axis: collinear.
        let mut collinear = landmarks.clone();
        for f in collinear.chunks_exact_mut(12) {
            let (le, me) = (Vector3::new(f[0], f[1], f[2]), Vector3::new(f[3], f[4], f[5]));
            let mid = (le + me) / 2.0;
            let (rs, us) = (Vector3::new(f[6], f[7], f[8]), Vector3::new(f[9], f[10], f[11]));
            let axis = mid - (rs + us) / 2.0;
            let (a, b) = ((rs + us) / 2.0 + 0.1 * axis, (rs + us) / 2.0 - 0.1 * axis);
            f[6..9].copy_from_slice(a.as_slice());
            f[9..12].copy_from_slice(b.as_slice());
        }
        let err = run(&markers, &collinear);
        assert!(err.contains("the landmarks are nearly collinear: the styloid line is 0° from"), "{err}");
        let mut one_point = landmarks.clone();
        for f in one_point.chunks_exact_mut(12) {
            let rs: [f32; 3] = f[6..9].try_into().unwrap();
            f[9..12].copy_from_slice(&rs);
        }
        assert!(run(&markers, &one_point).contains("styloids are 0.0 mm apart (at least 10)"));
        let err = run(&markers, &landmarks[..12 * 9]);
        assert!(err.contains("9 landmark frames for 10 marker frames"), "{err}");
        // A glove marker missing in every neutral frame (as in a static trial gone wrong).
        let mut no_hand = markers.clone();
        no_hand.iter_mut().skip(9).step_by(18).for_each(|v| *v = f32::NAN);
        let err = Calibration::from_neutral(&no_hand, None, Side::Right).unwrap_err().to_string();
        assert!(
            err.contains("no usable neutral frame: none of the 10 has all six markers (missing: MC2 in 10)"),
            "{err}"
        );
        let mut moving = markers.clone();
        let (far, _) = neutral_session(1, &SHIFT, 0.0, [0.0, 0.3, 0.0]);
        moving[..18].copy_from_slice(&far);
        let err = Calibration::from_neutral(&moving, None, Side::Right).unwrap_err().to_string();
        assert!(err.contains("within the neutral frames, its markers' noise (0.0° a frame)"), "{err}");
        assert!(err.contains("(at most 5°): choose frames where the wrist holds one posture"), "{err}");
        assert!(Calibration::from_neutral(&[], None, Side::Right).unwrap_err().to_string().contains("whole number"));
    }

    /// `frames` with uniform noise of ±`amplitude` metres on every coordinate.
    fn noisy(frames: &[f32], amplitude: f64, seed: u64) -> Vec<f32> {
        let mut rng = crate::rng::SplitMix::new(seed);
        frames.iter().map(|v| v + rng.uniform(-amplitude, amplitude) as f32).collect()
    }

    /// Angle, degrees, between each frame's hand-in-forearm rotation in `a` and in `b`.
    fn relative_turns_deg(a: &[f32], b: &[f32]) -> Vec<f64> {
        let rel = |f: &[f32]| {
            let (_, b_f) = technical_frame(f, Segment::Forearm, 0).unwrap();
            let (_, b_h) = technical_frame(f, Segment::Hand, 0).unwrap();
            Rotation3::from_matrix_unchecked(b_f.transpose() * b_h)
        };
        a.chunks_exact(MARKER_FRAME_LEN)
            .zip(b.chunks_exact(MARKER_FRAME_LEN))
            .map(|(x, y)| angle_deg(&(rel(x) * rel(y).inverse())))
            .collect()
    }

    #[test]
    fn a_noisy_static_trial_is_averaged_and_says_how_uncertain_it_is() {
        let q = [0.1, 0.2, -0.05];
        let clean = frames(&[q; 1000], &SHIFT, 1.0, 0.3);
        let (clean_cal, _) = Calibration::from_neutral(&clean, None, Side::Right).unwrap();
        let held = noisy(&clean, 0.002, 7);
        // The oracle: each noisy frame's hand against the same frame's without noise.
        let turns = relative_turns_deg(&held, &clean);
        let rms = (turns.iter().map(|t| t * t).sum::<f64>() / turns.len() as f64).sqrt();
        let largest = turns.iter().copied().fold(0.0, f64::max);
        assert!(largest > 2.0 * MAX_STATIC_SPREAD_DEG, "single frames turn by up to {largest:.1}°");
        let (cal, report) = Calibration::from_neutral(&held, None, Side::Right).unwrap();
        assert_eq!(report.neutral_frames, 1000);
        assert!(report.neutral_spread_deg < 0.5 * MAX_STATIC_SPREAD_DEG, "{report:?}");
        assert!((report.neutral_noise_deg / rms - 1.0).abs() < 0.25, "noise {rms:.2}°: {report:?}");
        let error = angle_deg(&(cal.hand * clean_cal.hand.inverse()));
        assert!((report.neutral_uncertainty_deg - rms / 1000f64.sqrt()).abs() < 0.3 * rms / 1000f64.sqrt());
        assert!(error < 3.0 * report.neutral_uncertainty_deg, "{error:.3}° off: {report:?}");
        // The same noise on a hand that bends 8° and back within the trial: movement, refused.
        let bending: Vec<[f64; 3]> =
            (0..1000).map(|i| [q[0], q[1] + 0.14 * (i as f64 / 1000.0 * std::f64::consts::PI).sin(), q[2]]).collect();
        let bent = noisy(&frames(&bending, &SHIFT, 1.0, 0.3), 0.002, 7);
        let err = Calibration::from_neutral(&bent, None, Side::Right).unwrap_err().to_string();
        assert!(err.contains("the hand moves") && err.contains("averaged out (at most 5°)"), "{err}");
        // And a static trial of the movements method alike.
        let moves: Vec<(usize, Vec<f32>)> =
            (0..2).map(|j| (j, frames(&single(j, 200, 0.6), &SHIFT, 1.0, 0.3))).collect();
        let refs: Vec<(usize, &[f32])> = moves.iter().map(|(j, f)| (*j, f.as_slice())).collect();
        let still = noisy(&frames(&[[0.0; 3]; 1000], &SHIFT, 1.0, 0.3), 0.002, 8);
        let (_, report) = Calibration::from_trials(&still, &refs).unwrap();
        assert!(report.neutral_spread_deg < 0.5 * MAX_STATIC_SPREAD_DEG && report.neutral_uncertainty_deg > 0.0);
        let err = Calibration::from_trials(&bent, &refs).unwrap_err().to_string();
        assert!(err.contains("within the static trial"), "{err}");
    }

    #[test]
    fn too_few_neutral_frames_are_refused_with_their_count() {
        let clean = frames(&[[0.0; 3]; MIN_NEUTRAL_FRAMES], &SHIFT, 1.0, 0.0);
        assert!(Calibration::from_neutral(&clean, None, Side::Right).is_ok());
        let err = Calibration::from_neutral(&clean[MARKER_FRAME_LEN..], None, Side::Right).unwrap_err().to_string();
        // Every frame complete: counted as such, with no empty "missing" list.
        assert!(err.contains("4 neutral frames, each with all six markers (at least 5 are needed"), "{err}");
        assert!(!err.contains("missing"), "{err}");
        // A marker lost in most frames of a static trial (racing's GloveR1): named, with its count.
        let mut lost = frames(&[[0.0; 3]; 8], &SHIFT, 1.0, 0.0);
        for i in 0..6 {
            lost[i * MARKER_FRAME_LEN + 9] = f32::NAN; // MC2's x
        }
        let err = Calibration::from_neutral(&lost, None, Side::Right).unwrap_err().to_string();
        assert!(err.contains("2 of the 8 neutral frames") && err.contains("missing: MC2 in 6)"), "{err}");
        let one = &clean[..MARKER_FRAME_LEN];
        let err = Calibration::from_neutral(one, None, Side::Right).unwrap_err().to_string();
        assert!(err.contains("1 neutral frame, with all six markers"), "{err}");
    }

    #[test]
    fn the_neutral_method_refuses_a_forearm_placement_it_cannot_know() {
        // A forearm plate: the three markers 3 cm from their centroid, where the body model
        // spreads RSP, USP and FAP over 17 cm.
        let mut body = body::BodyModel::default();
        let centroid: Vector3<f64> = (0..3).map(|m| Vector3::from(body.marker_offsets[m])).sum::<Vector3<f64>>() / 3.0;
        for m in 0..3 {
            let o = Vector3::from(body.marker_offsets[m]);
            body.marker_offsets[m] = (centroid + (o - centroid).normalize() * 0.03).into();
        }
        let pose = body.forearm_pose(0.2);
        let plate: Vec<f32> = (0..20).flat_map(|_| body.marker_frame(&[0.0; 3], &pose).map(|v| v as f32)).collect();
        let err = Calibration::from_neutral(&plate, None, Side::Right).unwrap_err().to_string();
        assert!(err.contains("the neutral method keeps the body model's placement of the forearm's markers"), "{err}");
        assert!(err.contains("--method landmarks") && err.contains("--method functional"), "{err}");
        // With landmarks the same plate is calibrated (its frame comes from them).
        let landmarks: Vec<f32> = (0..20)
            .flat_map(|_| {
                let offsets = landmark_offsets(1.0);
                offsets
                    .iter()
                    .flat_map(|o| {
                        let p = pose * nalgebra::Point3::from(Vector3::from(*o));
                        [p.x as f32, p.y as f32, p.z as f32]
                    })
                    .collect::<Vec<f32>>()
            })
            .collect();
        let trial = LandmarkTrial { markers: &plate, landmarks: &landmarks, hand_landmarks: None };
        assert!(Calibration::from_neutral(&plate, Some(trial), Side::Right).is_ok());
        // The model's placement on subjects from small to tall, and markers a little off, pass.
        for scale in [0.8, 1.0, 1.3] {
            let ok = frames(&[[0.0; 3]; 10], &SHIFT, scale, 0.0);
            assert!(Calibration::from_neutral(&ok, None, Side::Right).is_ok(), "scale {scale}");
        }
        // The placement is judged by each distance's median over the frames: a few frames off
        // (2 of 11 with the plate's) do not decide it, most frames off do.
        let ok = frames(&[[0.0; 3]; 9], &SHIFT, 1.0, 0.0);
        let mostly = [ok.clone(), plate[..2 * MARKER_FRAME_LEN].to_vec()].concat();
        assert!(neutral::check_forearm_placement(&mostly).is_ok());
        let mostly_off = [ok[..2 * MARKER_FRAME_LEN].to_vec(), plate[..9 * MARKER_FRAME_LEN].to_vec()].concat();
        assert!(neutral::check_forearm_placement(&mostly_off).is_err());
    }

    #[test]
    fn a_noisy_functional_movement_is_fitted_with_the_noise_taken_out_of_its_residual() {
        let shift = random_shift(5, 0.01);
        let neutral = noisy(&frames(&[[0.0; 3]; 300], &shift, 1.0, 0.3), 0.003, 11);
        let movement = noisy(&frames(&circles(3000, 0.3, 0.0), &shift, 1.0, 0.3), 0.003, 12);
        let (cal, report) = Calibration::functional(&neutral, &movement, Side::Right).unwrap();
        let f = report.functional.as_ref().unwrap();
        assert!(f.noise_deg > 2.0 && f.residual_deg < 0.3 * MAX_FUNCTIONAL_RESIDUAL_DEG, "{f:?}");
        let q = [-0.4, 0.5, 0.25];
        let out = angles_after(&cal, &frames(&[q], &shift, 1.0, 0.3));
        for k in 0..3 {
            assert!((out[k] as f64 - q[k]).abs() < 0.03, "{out:?} vs {q:?}");
        }
        // A forearm that turns while the wrist circles is still refused through the noise.
        let turning = noisy(&frames(&circles(3000, 0.3, 0.3), &shift, 1.0, 0.3), 0.003, 12);
        let err = Calibration::functional(&neutral, &turning, Side::Right).unwrap_err().to_string();
        assert!(err.contains("the hand turned about the forearm's long axis"), "{err}");
    }

    #[test]
    fn sides_and_methods_are_named_as_files_and_the_command_line_write_them() {
        // Calibration files and maps record these names; a reader takes them back by name.
        assert_eq!((Side::Right.name(), Side::Left.name()), ("right", "left"));
        for side in [Side::Right, Side::Left] {
            assert_eq!(Side::from_name(side.name()).unwrap(), side);
        }
        let err = Side::from_name("up").unwrap_err().to_string();
        assert!(err.contains(r#"is "up", expected "right" or "left""#), "{err}");
        let names = [
            (Method::BodyModel, "body_model"),
            (Method::Matrices, "matrices"),
            (Method::Movements, "movements"),
            (Method::Landmarks, "landmarks"),
            (Method::Neutral, "neutral"),
            (Method::Functional, "functional"),
            (Method::Mirror, "mirror"),
        ];
        for (method, name) in names {
            assert_eq!(method.name(), name);
        }
    }

    #[test]
    fn a_refused_left_frame_is_left_as_it_came() {
        let cal = Calibration { side: Side::Left, ..Calibration::body_model() };
        let mut frame = vec![0.0f32; MARKER_FRAME_LEN];
        frame[2] = 1.0;
        assert!(cal.apply(&mut frame, 4).is_err());
        assert_eq!(frame[2], 1.0);
    }

    #[test]
    fn bad_calibration_trials_are_named() {
        let statics = frames(&[[0.0; 3]; 20], &SHIFT, 1.0, 0.0);
        let flex = frames(&single(1, 100, 0.6), &SHIFT, 1.0, 0.0);
        let err = |r: Result<(Calibration, CalibrationReport)>| r.unwrap_err().to_string();
        assert!(err(Calibration::from_trials(&statics, &[(1, &flex)])).contains("at least two different coordinates"));
        assert!(err(Calibration::from_trials(&flex, &[(1, &flex), (0, &flex)])).contains("must hold the neutral pose"));
        let tiny = frames(&single(0, 100, 0.05), &SHIFT, 1.0, 0.0);
        assert!(
            err(Calibration::from_trials(&statics, &[(1, &flex), (0, &tiny)])).contains("ra_wr_s_p movement spans")
        );
        let mixed: Vec<[f64; 3]> =
            single(0, 100, 0.6).iter().zip(single(1, 100, 0.6)).map(|(a, b)| [a[0], b[1], 0.0]).collect();
        let mixed = frames(&mixed, &SHIFT, 1.0, 0.0);
        assert!(
            err(Calibration::from_trials(&statics, &[(1, &flex), (0, &mixed)])).contains("move each coordinate alone")
        );
        let mut gap = statics.clone();
        gap[4] = f32::NAN;
        assert!(
            err(Calibration::from_trials(&gap, &[(1, &flex), (0, &flex)]))
                .contains("static trial: frame 0: marker USP is missing")
        );
    }

    /// A wrist circling through flexion and deviation (irregularly: a task, not a protocol),
    /// the forearm's rotation held at `s_p`.
    fn circles(n: usize, s_p: f64, s_p_wobble: f64) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64 * std::f64::consts::TAU;
                [s_p + s_p_wobble * (3.0 * t).sin(), 0.6 * (2.0 * t).sin() + 0.2 * t.cos(), 0.25 * (3.0 * t).cos()]
            })
            .collect()
    }

    #[test]
    fn functional_axes_from_mixed_movement_read_angles_exactly_for_any_held_pronation() {
        for (seed, s_p) in [(1u64, 0.0), (2, 0.5), (3, -0.4)] {
            let shift = random_shift(seed, 0.015);
            let neutral = frames(&[[0.0; 3]; 12], &shift, 1.1, 0.3);
            let mut movement = frames(&circles(300, s_p, 0.0), &shift, 1.1, 0.3);
            movement[7 * MARKER_FRAME_LEN + 4] = f32::NAN; // a frame missing a marker is skipped
            let (cal, report) = Calibration::functional(&neutral, &movement, Side::Right).unwrap();
            let f = report.functional.as_ref().unwrap();
            assert_eq!((report.method, f.frames), (Method::Functional, 299));
            assert!(f.residual_deg < 0.01 && (f.supination_held_deg - s_p.to_degrees()).abs() < 0.01, "{f:?}");
            assert!(f.flexion_range_deg > 60.0 && f.deviation_range_deg > 25.0, "{f:?}");
            let q = [-0.4, 0.5, 0.25];
            let out = angles_after(&cal, &frames(&[q], &shift, 1.1, 0.3));
            for k in 0..3 {
                assert!((out[k] as f64 - q[k]).abs() < 1e-4, "seed {seed}: {out:?} vs {q:?}");
            }
            // A short movement (under 50 frames: its percentiles are its extremes) is fitted too.
            let short = frames(&circles(30, s_p, 0.0), &shift, 1.1, 0.3);
            let (_, report) = Calibration::functional(&neutral, &short, Side::Right).unwrap();
            assert_eq!(report.functional.as_ref().unwrap().frames, 30);
        }
    }

    #[test]
    fn functional_fit_of_a_left_arm_reads_its_anatomical_angles() {
        let neutral = mirrored(&frames(&[[0.0; 3]; 12], &SHIFT, 1.0, 0.3));
        let movement = mirrored(&frames(&circles(200, 0.2, 0.0), &SHIFT, 1.0, 0.3));
        let (cal, _) = Calibration::functional(&neutral, &movement, Side::Left).unwrap();
        let q = [0.3, -0.5, 0.2];
        let out = angles_after(&cal, &mirrored(&frames(&[q], &SHIFT, 1.0, 0.3)));
        for k in 0..3 {
            assert!((out[k] as f64 - q[k]).abs() < 1e-4, "{out:?} vs {q:?}");
        }
    }

    #[test]
    fn too_little_movement_for_a_functional_fit_says_what_to_record() {
        let neutral = frames(&[[0.0; 3]; 12], &SHIFT, 1.0, 0.3);
        let err = |movement: &[f32]| Calibration::functional(&neutral, movement, Side::Right).unwrap_err().to_string();
        // Flexion alone shows one axis only: the deviation axis could be any in a plane.
        let flexion = err(&frames(&single(1, 200, 0.6), &SHIFT, 1.0, 0.3));
        for one_axis in [flexion, err(&frames(&single(2, 200, 0.4), &SHIFT, 1.0, 0.3))] {
            assert!(
                one_axis.contains("at least 10° of each") && one_axis.contains("radial-ulnar deviation together"),
                "{one_axis}"
            );
        }
        // The forearm turning during the movement is what a two-axis fit cannot describe.
        let turning = err(&frames(&circles(300, 0.0, 0.4), &SHIFT, 1.0, 0.3));
        assert!(turning.contains("turned about the forearm's long axis") && turning.contains("RMS"), "{turning}");
        // Pronation with flexion fits a two-axis joint as well; it must not pass as one.
        let propulsion: Vec<[f64; 3]> = (0..300)
            .map(|i| {
                let t = i as f64 / 300.0 * std::f64::consts::TAU;
                [0.8 * (2.0 * t).sin(), 0.6 * t.cos(), 0.0]
            })
            .collect();
        let wrong_pair = err(&frames(&propulsion, &SHIFT, 1.0, 0.3));
        assert!(wrong_pair.contains("calibration:"), "{wrong_pair}");
        let few = err(&frames(&circles(5, 0.0, 0.0), &SHIFT, 1.0, 0.3));
        assert!(few.contains("5 frames with all six markers"), "{few}");
        // The hand's cluster may sit any way round; a forearm cluster turned a quarter turn
        // leaves the axes without a sign.
        let (neutral_turned, _) = neutral_session(12, &SHIFT, 120.0, [0.0; 3]);
        let mut moving = Vec::new();
        for q in circles(200, 0.1, 0.0) {
            moving.extend(neutral_session(1, &SHIFT, 120.0, q).0);
        }
        let (cal, _) = Calibration::functional(&neutral_turned, &moving, Side::Right).unwrap();
        let q = [0.2, 0.4, -0.1];
        let out = angles_after(&cal, &neutral_session(1, &SHIFT, 120.0, q).0);
        for k in 0..3 {
            assert!((out[k] as f64 - q[k]).abs() < 1e-4, "hand cluster turned: {out:?} vs {q:?}");
        }
        let quarter = Rotation3::from_axis_angle(&Vector3::y_axis(), 1.5);
        let turn_forearm = |f: Vec<f32>| -> Vec<f32> {
            f.chunks_exact(MARKER_FRAME_LEN)
                .flat_map(|f| {
                    let c = Vector3::new(f[3] as f64, f[4] as f64, f[5] as f64);
                    let mut g = f.to_vec();
                    for m in [0, 2] {
                        let p =
                            c + quarter * (Vector3::new(f[3 * m] as f64, f[3 * m + 1] as f64, f[3 * m + 2] as f64) - c);
                        g[3 * m..3 * m + 3].copy_from_slice(&[p.x as f32, p.y as f32, p.z as f32]);
                    }
                    g
                })
                .collect()
        };
        let sign = Calibration::functional(&turn_forearm(neutral), &turn_forearm(moving), Side::Right)
            .unwrap_err()
            .to_string();
        assert!(sign.contains("needs landmarks"), "{sign}");
    }

    #[test]
    fn hand_landmarks_give_the_hands_own_frame_whatever_posture_the_session_held() {
        // The session holds the wrist bent (not neutral): with the metacarpal heads the hand's
        // frame is its own, so every posture reads its true angles; without them the held
        // posture would read zero.
        let held = [0.2, -0.3, 0.1];
        let body = {
            let mut b = body::BodyModel::scaled(1.1, 1.1);
            let turn = Rotation3::from_axis_angle(&Vector3::y_axis(), 2.0);
            for (m, (o, s)) in b.marker_offsets.iter_mut().zip(&SHIFT).enumerate() {
                let moved = Vector3::from(*o) + Vector3::from(*s);
                let moved = if m >= 3 { turn * moved } else { moved };
                *o = [moved.x, moved.y, moved.z];
            }
            b
        };
        let pose = body.forearm_pose(0.5);
        let at = |q: [f64; 3]| body.marker_frame(&q, &pose).map(|v| v as f32).to_vec();
        let lab = |iso: &nalgebra::Isometry3<f64>, p: [f64; 3]| {
            let p = iso * nalgebra::Point3::from(p.map(|c| c * 1.1));
            [p.x as f32, p.y as f32, p.z as f32]
        };
        let hand_pose = pose * nalgebra::Isometry3::rotation(body::wrist_rotation(&held).scaled_axis());
        let forearm_points: Vec<f32> = [[0.0, 0.26, 0.035], [0.0, 0.26, -0.035], [0.0, 0.0, 0.03], [0.0, 0.0, -0.03]]
            .iter()
            .flat_map(|p| lab(&pose, *p))
            .collect();
        let hand_points: Vec<f32> =
            [[0.0, -0.07, 0.025], [0.0, -0.065, -0.025]].iter().flat_map(|p| lab(&hand_pose, *p)).collect();
        let n = 8;
        let markers: Vec<f32> = (0..n).flat_map(|_| at(held)).collect();
        let landmarks: Vec<f32> = (0..n).flat_map(|_| forearm_points.clone()).collect();
        let mut hands: Vec<f32> = (0..n).flat_map(|_| hand_points.clone()).collect();
        hands[3] = f32::NAN; // a frame without a metacarpal head is skipped
        let trial = LandmarkTrial { markers: &markers, landmarks: &landmarks, hand_landmarks: Some(&hands) };
        let (cal, report) = Calibration::from_neutral(&markers, Some(trial), Side::Right).unwrap();
        let hand = report.landmarks.as_ref().unwrap().hand.as_ref().unwrap();
        assert_eq!(hand.frames, n - 1);
        // The metacarpal heads sit at (0, −70, 25) and (0, −65, −25) mm (×1.1) of the hand, the
        // mid-styloids at the wrist's centre, which the hand turns about: so 1.1 × 67.5 mm from
        // their midpoint and 1.1 × |(0, −5, 50)| mm apart, whatever the held posture.
        assert!((hand.long_axis_mm - 1.1 * 67.5).abs() < 1e-2, "{hand:?}");
        assert!((hand.metacarpal_span_mm - 1.1 * 5f64.hypot(50.0)).abs() < 1e-2, "{hand:?}");
        assert!((hand.neutral_offset_deg - angle_deg(&body::wrist_rotation(&held))).abs() < 1e-3, "{hand:?}");
        for q in [held, [0.0; 3], [-0.5, 0.6, -0.2]] {
            let out = angles_after(&cal, &at(q));
            for k in 0..3 {
                assert!((out[k] as f64 - q[k]).abs() < 1e-4, "{out:?} vs {q:?}");
            }
        }
        // Collinear hand landmarks, or none seen with the hand's markers, say what to record.
        let on_axis: Vec<f32> = (0..n).flat_map(|_| lab(&hand_pose, [0.0, -0.07, 0.0]).repeat(2)).collect();
        let trial = LandmarkTrial { markers: &markers, landmarks: &landmarks, hand_landmarks: Some(&on_axis) };
        let e = Calibration::from_neutral(&markers, Some(trial), Side::Right).unwrap_err().to_string();
        assert!(e.contains("do not span the hand") && e.contains("metacarpal heads (knuckles)"), "{e}");
        // Apart (41 mm) but their line 14° from the hand's long axis: nearly collinear.
        let along: Vec<f32> = (0..n)
            .flat_map(|_| [lab(&hand_pose, [0.0, -0.05, 0.005]), lab(&hand_pose, [0.0, -0.09, -0.005])].concat())
            .collect();
        let trial = LandmarkTrial { markers: &markers, landmarks: &landmarks, hand_landmarks: Some(&along) };
        let e = Calibration::from_neutral(&markers, Some(trial), Side::Right).unwrap_err().to_string();
        assert!(e.contains("the hand's landmarks are nearly collinear: the metacarpal heads' line is 14°"), "{e}");
        let unseen = vec![f32::NAN; n * HAND_LANDMARK_FRAME_LEN];
        let trial = LandmarkTrial { markers: &markers, landmarks: &landmarks, hand_landmarks: Some(&unseen) };
        let e = Calibration::from_neutral(&markers, Some(trial), Side::Right).unwrap_err().to_string();
        assert!(e.contains("no frame of the 8 has the hand's three markers, both metacarpal heads"), "{e}");
    }

    #[test]
    fn apply_rows_moves_every_frame_and_names_the_first_incomplete_one() {
        let (cal, _) = Calibration::functional(
            &frames(&[[0.0; 3]; 12], &SHIFT, 1.0, 0.3),
            &frames(&circles(200, 0.0, 0.0), &SHIFT, 1.0, 0.3),
            Side::Right,
        )
        .unwrap();
        let q = [[0.3, -0.2, 0.1], [-0.1, 0.4, -0.05]];
        let mut rows = frames(&q, &SHIFT, 1.0, 0.3);
        cal.apply_rows(&mut rows).unwrap();
        for (k, f) in rows.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let mut out = [0f32; 3];
            FeatureSet::Angles.compute(f, &mut out, 0).unwrap();
            for c in 0..3 {
                assert!((out[c] as f64 - q[k][c]).abs() < 1e-4, "row {k}: {out:?}");
            }
        }
        let mut gap = frames(&q, &SHIFT, 1.0, 0.3);
        gap[MARKER_FRAME_LEN + 4] = f32::NAN;
        let e = cal.apply_rows(&mut gap).unwrap_err().to_string();
        assert!(e.contains("frame 1") && e.contains("USP"), "{e}");
        assert!(cal.apply_rows(&mut [0.0; 5]).unwrap_err().to_string().contains("not a whole number"));
    }

    /// Frames (f64, as the placement check takes them) of the default body at angles `q`,
    /// each segment's markers spread by `spread[segment]` about its first marker (a uniform
    /// scaling: every distance within the segment grows by that factor, its frame's
    /// orientation does not change).
    fn spread_frames(n: usize, spread: [f64; 2], q: [f64; 3]) -> Vec<f64> {
        let mut body = body::BodyModel::default();
        let o = body.marker_offsets;
        for m in 0..6 {
            let (first, s) = if m < 3 { (0, spread[0]) } else { (3, spread[1]) };
            body.marker_offsets[m] = std::array::from_fn(|k| o[first][k] + s * (o[m][k] - o[first][k]));
        }
        let pose = body.forearm_pose(0.3);
        (0..n).flat_map(|_| body.marker_frame(&q, &pose)).collect()
    }

    #[test]
    fn the_default_placement_check_takes_the_models_own_markers_and_its_slack() {
        let body = body::BodyModel::default();
        // The body model's own markers, at a posture inside every range: nothing to refuse.
        check_default_placement(&spread_frames(5, [1.0, 1.0], [0.4, -0.3, 0.2]), &body, Side::Right).unwrap();
        // Every distance 25% longer: at PLACEMENT_DISTANCE_SHARE exactly, 1 cm inside the
        // limit (share × model + slack); a limit of share × model − slack would refuse it.
        let d =
            |i: usize, j: usize| (Vector3::from(body.marker_offsets[i]) - Vector3::from(body.marker_offsets[j])).norm();
        assert!((PLACEMENT_DISTANCE_SHARE - 0.25).abs() < 1e-12 && PLACEMENT_DISTANCE_SLACK_M == 0.01);
        assert!([(0, 1), (0, 2), (1, 2), (3, 4), (3, 5), (4, 5)].iter().all(|&(i, j)| d(i, j) > 0.02));
        check_default_placement(&spread_frames(5, [1.25, 1.25], [0.0; 3]), &body, Side::Right).unwrap();
        // A recording with no complete frame has nothing to judge.
        check_default_placement(&[f64::NAN; MARKER_FRAME_LEN * 3], &body, Side::Right).unwrap();
    }

    #[test]
    fn markers_farther_apart_than_the_model_puts_them_name_the_pair() {
        let body = body::BodyModel::default();
        // Forearm markers 50% farther apart: RSP–USP, the first pair checked, is refused.
        let e = check_default_placement(&spread_frames(5, [1.5, 1.0], [0.0; 3]), &body, Side::Right)
            .unwrap_err()
            .to_string();
        assert!(e.contains("markers RSP and USP are") && e.contains("ikid calibrate"), "{e}");
        // Hand markers 50% farther apart (the forearm's as the model has them): MC2–MC5.
        let e = check_default_placement(&spread_frames(5, [1.0, 1.5], [0.0; 3]), &body, Side::Right)
            .unwrap_err()
            .to_string();
        assert!(e.contains("markers MC2 and MC5 are"), "{e}");
        // The same with the median over frames: three of five frames as the model has them
        // pass, three of five spread do not.
        let mut mixed = spread_frames(3, [1.0, 1.0], [0.0; 3]);
        mixed.extend(spread_frames(2, [1.0, 1.5], [0.0; 3]));
        check_default_placement(&mixed, &body, Side::Right).unwrap();
        let mut mixed = spread_frames(2, [1.0, 1.0], [0.0; 3]);
        mixed.extend(spread_frames(3, [1.0, 1.5], [0.0; 3]));
        assert!(check_default_placement(&mixed, &body, Side::Right).is_err());
    }

    #[test]
    fn a_median_posture_past_a_range_and_its_margin_is_refused() {
        let body = body::BodyModel::default();
        // Ulnar/radial deviation ranges over −20°..30°, with the 15° margin −35°..45°.
        let (lo, hi) = COORDINATES[2].range;
        assert!((lo.to_degrees() + 20.0).abs() < 1e-9 && (hi.to_degrees() - 30.0).abs() < 1e-9);
        assert!((PLACEMENT_POSTURE_MARGIN_RAD.to_degrees() - 15.0).abs() < 0.01);
        for (deg, ok) in [(-30.0, true), (-40.0, false), (40.0, true), (50.0, false)] {
            let q = [0.0, 0.0, f64::to_radians(deg)];
            let got = check_default_placement(&spread_frames(5, [1.0, 1.0], q), &body, Side::Right);
            match got {
                Ok(()) => assert!(ok, "{deg}° passed"),
                Err(e) => {
                    let e = e.to_string();
                    assert!(!ok, "{deg}° refused: {e}");
                    assert!(e.contains(&format!("ra_wr_ad_ab = {deg:.0}°")) && e.contains("-20° to 30°"), "{e}");
                }
            }
        }
    }

    /// Frames of a `length`-scaled subject's right arm at postures spread over every range
    /// (shoulder at 0.3 rad), and the same frames mirrored (lab `z` negated: the left arm in
    /// the same anatomical postures, as a left-arm recording has it).
    fn right_and_left_arm(length: f64) -> (Vec<f64>, Vec<f64>) {
        let body = body::BodyModel::scaled(length, 1.0);
        let pose = body.forearm_pose(0.3);
        let mut right = Vec::new();
        for k in 0..40 {
            let t = k as f64 / 40.0;
            let q: [f64; 3] = std::array::from_fn(|c| {
                let (lo, hi) = COORDINATES[c].range;
                lo + (hi - lo) * (0.5 + 0.45 * (std::f64::consts::TAU * t * (c + 1) as f64).sin())
            });
            right.extend(body.marker_frame(&q, &pose));
        }
        let left = right.iter().enumerate().map(|(i, v)| if i % 3 == 2 { -v } else { *v }).collect();
        (right, left)
    }

    #[test]
    fn the_other_arms_markers_are_refused_naming_the_side_to_give() {
        let body = body::BodyModel::default();
        for length in [0.85, 1.0, 1.15] {
            let (right, left) = right_and_left_arm(length);
            // Each arm read as itself: passes (any size; the check scales to the markers).
            check_default_placement(&right, &body, Side::Right).unwrap();
            check_default_placement(&left, &body, Side::Left).unwrap();
            // Each read as the other: every distance is the same, the handedness is not.
            for (frames, given, other) in [(&left, Side::Right, "left"), (&right, Side::Left, "right")] {
                let e = check_default_placement(frames, &body, given).unwrap_err().to_string();
                assert!(
                    e.contains(&format!("read as a {} arm, the markers are its mirror image", given.name()))
                        && e.contains(&format!("side = \"{other}\"")),
                    "{length}: {e}"
                );
            }
        }
    }

    #[test]
    fn the_hand_fits_about_the_wrist_centre_at_any_posture_and_not_mirrored() {
        let body = body::BodyModel::default();
        for length in [0.85, 1.15] {
            let (right, left) = right_and_left_arm(length);
            for (r, l) in right.chunks_exact(MARKER_FRAME_LEN).zip(left.chunks_exact(MARKER_FRAME_LEN)) {
                // Exact for the arm as it is; the mirror image's tetrahedron (the wrist centre
                // ~26 mm out of the hand markers' plane) fits no rotation of the model's.
                assert!(hand_about_wrist_residual(r, &body) < 1e-6);
                let mirrored = hand_about_wrist_residual(l, &body);
                assert!(mirrored > 1.5 * MIRROR_MIN_RESIDUAL_M, "{mirrored}");
            }
        }
    }

    #[test]
    fn a_functional_movement_is_held_to_the_ranges_between_its_2nd_and_98th_percentiles() {
        // 294 frames circling well inside the ranges, and `k` frames at either end of radial-
        // ulnar deviation past range + margin (−35° to 45°): −40° and +50°. With k = 3 (1% of
        // 300, below the 2% cut: the 2nd percentile is the 7th frame from either end) they are
        // outliers the check ignores; with k = 7 they are the 2nd and 98th percentiles.
        let neutral = frames(&[[0.0; 3]; 12], &SHIFT, 1.0, 0.3);
        let movement = |k: usize| {
            let mut q = circles(300 - 2 * k, 0.0, 0.0);
            for _ in 0..k {
                q.push([0.0, 0.0, f64::to_radians(-40.0)]);
                q.push([0.0, 0.0, f64::to_radians(50.0)]);
            }
            frames(&q, &SHIFT, 1.0, 0.3)
        };
        let (cal, report) = Calibration::functional(&neutral, &movement(3), Side::Right).unwrap();
        assert_eq!(report.functional.as_ref().unwrap().frames, 300);
        let q = [0.1, 0.3, -0.2];
        let out = angles_after(&cal, &frames(&[q], &SHIFT, 1.0, 0.3));
        for c in 0..3 {
            assert!((out[c] as f64 - q[c]).abs() < 1e-4, "{out:?} vs {q:?}");
        }
        let e = Calibration::functional(&neutral, &movement(7), Side::Right).unwrap_err().to_string();
        assert!(e.contains("takes ra_wr_ad_ab from -40° to 50° (2nd to 98th percentile)"), "{e}");
    }

    #[test]
    fn the_universal_joint_fit_takes_the_best_of_its_starts() {
        // Exact universal joints (flexion about z fixed in the forearm, deviation about x fixed
        // in the hand) seen through technical frames turned anyhow: M_k = Aᵀ Rz(e_k) Rx(a_k) B.
        // Their axes are u = Aᵀz, v = Bᵀx, with no residual. Alternating least squares from one
        // start can settle on a worse fixed point (for about one in ten such joints from the
        // x start, in a NumPy replica); the best of the three starts must be exact for all.
        let mut rng = crate::rng::SplitMix::new(17);
        for case in 0..30 {
            let mut turn = || Rotation3::from_scaled_axis(Vector3::from_fn(|_, _| rng.uniform(-3.0, 3.0)));
            let (a, b) = (turn(), turn());
            let (flexion, deviation) = (rng.uniform(0.2, 1.3), rng.uniform(0.1, 1.3));
            let moves: Vec<Matrix3<f64>> = (0..40)
                .map(|i| {
                    let t = i as f64 / 40.0 * std::f64::consts::TAU;
                    let e = flexion * (2.0 * t).sin() + 0.2 * t.cos();
                    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), e)
                        * Rotation3::from_axis_angle(&Vector3::x_axis(), deviation * (3.0 * t).cos());
                    (a.inverse() * r * b).into_inner()
                })
                .collect();
            let (u, v, residual, _) = functional::fit_universal_axes(&moves);
            let (true_u, true_v) = (a.inverse() * Vector3::z(), b.inverse() * Vector3::x());
            assert!(residual < 1e-6, "case {case}: residual {residual} rad");
            assert!(u.dot(&true_u).abs() > 1.0 - 1e-9 && v.dot(&true_v).abs() > 1.0 - 1e-9, "case {case}: {u} {v}");
        }
    }
}
