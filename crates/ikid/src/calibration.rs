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

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, UnitQuaternion, Vector3};

use crate::body::{self, COORDINATES, MARKER_FRAME_LEN, N_COORDINATES, Segment};
use crate::error::{Error, Result};
use crate::features::{technical_frame, technical_in_anatomical};

/// Frames a static trial needs.
pub const MIN_STATIC_FRAMES: usize = 10;
/// Neutral frames a calibration needs (with all six markers): one frame's noise is the
/// calibration's error, and its count is no evidence the posture was held.
pub const MIN_NEUTRAL_FRAMES: usize = 5;
/// Largest rotation of the hand (relative to the forearm) away from the static trial's mean
/// allowed within it, degrees, the markers' noise averaged out (see [`HeldPosture`]): more is
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
/// Largest RMS residual of a functional fit, degrees: more means the forearm turned
/// (pronation-supination) during the movement, which a two-axis fit cannot describe.
pub const MAX_FUNCTIONAL_RESIDUAL_DEG: f64 = 5.0;
/// Smallest share of an axis along the body model's placement of it for the fit to take its
/// sign from there (cos 60°: see [`MAX_PLACEMENT_DEG`]).
const MIN_SIGN_SHARE: f64 = 0.5;

/// Smallest angle between the styloid line and the forearm's long axis, degrees: below it the
/// four landmarks are too close to one line to say which way is volar.
pub const MIN_LANDMARK_ANGLE_DEG: f64 = 30.0;

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
    /// noise averaged out (see [`HeldPosture`]).
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
        }
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
        Ok(Calibration { forearm: Rotation3::from_matrix(&forearm), hand: Rotation3::from_matrix(&hand), side })
    }

    /// Measures the calibration from a static neutral trial and single-coordinate movements
    /// `(coordinate index, frames)`; frames are whole marker frames back to back, complete
    /// (fill gaps first). At least two different coordinates are needed.
    pub fn from_trials(static_frames: &[f32], movements: &[(usize, &[f32])]) -> Result<(Self, CalibrationReport)> {
        let statics = relative_rotations(static_frames, "static trial")?;
        if statics.len() < MIN_STATIC_FRAMES {
            return Err(bad(format!(
                "the static trial has {} frames, at least {MIN_STATIC_FRAMES} are needed",
                statics.len()
            )));
        }
        let held = HeldPosture::of(&statics);
        if held.spread_deg > MAX_STATIC_SPREAD_DEG {
            return Err(bad(format!(
                "the hand moves {:.1}° within the static trial, its markers' noise ({:.1}° a frame) averaged out \
                 (at most {MAX_STATIC_SPREAD_DEG}°): it must hold the neutral pose",
                held.spread_deg, held.noise_deg
            )));
        }
        let neutral = held.mean;
        let mut coords: Vec<usize> = movements.iter().map(|m| m.0).collect();
        coords.sort_unstable();
        coords.dedup();
        if coords.len() != movements.len() || coords.len() < 2 || coords.iter().any(|&j| j >= N_COORDINATES) {
            return Err(bad(format!(
                "needs movements of at least two different coordinates (of {}), each once",
                COORDINATES.map(|c| c.name).join(", ")
            )));
        }
        let default = Self::body_model();
        let mut report = CalibrationReport {
            method: Method::Movements,
            side: Side::Right,
            movements: Vec::new(),
            placement_deg: [0.0; 2],
            axis_skew_deg: 0.0,
            neutral_frames: statics.len(),
            neutral_spread_deg: held.spread_deg,
            neutral_noise_deg: held.noise_deg,
            neutral_uncertainty_deg: held.uncertainty_deg,
            landmarks: None,
            functional: None,
        };
        let mut measured = Vec::new();
        for &(j, frames) in movements {
            let name = COORDINATES[j].name;
            let rotations = relative_rotations(frames, name)?;
            // Rotation vectors via quaternions: Rotation3::scaled_axis is NaN when round-off puts
            // the trace a hair above 3 (a frame at neutral).
            let vectors: Vec<Vector3<f64>> = rotations
                .iter()
                .map(|r| UnitQuaternion::from_rotation_matrix(&(r * neutral.inverse())).scaled_axis())
                .collect();
            let scatter = vectors.iter().fold(Matrix3::zeros(), |acc, v| acc + v * v.transpose());
            let eigen = SymmetricEigen::new(scatter);
            let k = eigen.eigenvalues.imax();
            let mut axis: Vector3<f64> = eigen.eigenvectors.column(k).into_owned();
            let purity = eigen.eigenvalues[k] / eigen.eigenvalues.sum().max(f64::MIN_POSITIVE);
            let range =
                vectors.iter().map(|v| v.dot(&axis)).fold((f64::MAX, f64::MIN), |(lo, hi), x| (lo.min(x), hi.max(x)));
            let range_deg = (range.1 - range.0).to_degrees();
            if range_deg < MIN_MOVEMENT_DEG {
                return Err(bad(format!(
                    "the {name} movement spans {range_deg:.1}°; at least {MIN_MOVEMENT_DEG}° shows its axis"
                )));
            }
            if purity < MIN_AXIS_PURITY {
                return Err(bad(format!(
                    "the {name} movement is {:.0} % about one axis (at least {:.0} %): move that coordinate alone",
                    100.0 * purity,
                    100.0 * MIN_AXIS_PURITY
                )));
            }
            // The sign of an axis is not in the data; the body model's placement gives it.
            let model_axis = Vector3::from(COORDINATES[j].axis);
            if axis.dot(&(default.forearm.inverse() * model_axis)) < 0.0 {
                axis = -axis;
            }
            report.movements.push((j, range_deg, purity));
            measured.push((model_axis, axis));
        }
        for (a, (_, t1)) in measured.iter().enumerate() {
            for (_, t2) in &measured[a + 1..] {
                report.axis_skew_deg =
                    report.axis_skew_deg.max((t1.dot(t2).clamp(-1.0, 1.0).acos().to_degrees() - 90.0).abs());
            }
        }
        if report.axis_skew_deg > MAX_AXIS_SKEW_DEG {
            return Err(bad(format!(
                "the movements' axes are {:.0}° from perpendicular (at most {MAX_AXIS_SKEW_DEG}°): move each coordinate alone",
                report.axis_skew_deg
            )));
        }
        let forearm = procrustes(&measured);
        let hand = forearm * neutral;
        report.placement_deg = Calibration { forearm, hand, side: Side::Right }.placement_deg();
        if let Some(worst) = report.placement_deg.iter().copied().find(|&a| a > MAX_PLACEMENT_DEG) {
            return Err(bad(format!(
                "the markers sit {worst:.0}° from the body model's placement (at most {MAX_PLACEMENT_DEG}°): are they labelled right?"
            )));
        }
        Ok((Calibration { forearm, hand, side: Side::Right }, report))
    }

    /// Measures the calibration from frames of the neutral posture (a static trial, or chosen
    /// frames of any trial; all wrist angles read zero there) and, when given, the forearm's
    /// landmarks ([`Method::Landmarks`]); without them the forearm keeps the body model's
    /// placement ([`Method::Neutral`]). With the hand's landmarks too (the second and fifth
    /// metacarpal heads), the hand's frame is its own: `y` from the mid-heads to the
    /// mid-styloids, `x = y × (fifth → second head)`, `z = x × y`, as the forearm's; the
    /// neutral posture then reads what the anatomical frames say, not zero. Frames may miss markers (NaN): the hand's neutral
    /// posture is averaged over the frames with all six markers, each landmark over the
    /// frames where it and the forearm's three markers are seen. Clusters may sit at any
    /// orientation. `side` is the arm the frames show (a left one is mirrored, see the module
    /// documentation).
    pub fn from_neutral(
        neutral: &[f32],
        landmarks: Option<LandmarkTrial<'_>>,
        side: Side,
    ) -> Result<(Self, CalibrationReport)> {
        let frames = neutral;
        let held = neutral_posture(frames, side)?;
        let neutral = held.mean;
        let default = Self::body_model();
        let (method, forearm, mut landmark_report) = match landmarks {
            None => {
                check_forearm_placement(frames)?;
                (Method::Neutral, default.forearm, None)
            }
            Some(trial) => {
                let (forearm, report) = forearm_from_landmarks(trial, side)?;
                (Method::Landmarks, forearm, Some(report))
            }
        };
        let mut hand = forearm * neutral;
        if let (Some(trial), Some(report)) = (landmarks, landmark_report.as_mut())
            && trial.hand_landmarks.is_some()
        {
            let (own, mut hand_report) = hand_from_landmarks(trial, side)?;
            hand_report.neutral_offset_deg = angle_deg(&(own * hand.inverse()));
            hand = own;
            report.hand = Some(hand_report);
        }
        let report = CalibrationReport {
            method,
            side,
            movements: Vec::new(),
            placement_deg: Calibration { forearm, hand, side }.placement_deg(),
            axis_skew_deg: 0.0,
            neutral_frames: held.frames,
            neutral_spread_deg: held.spread_deg,
            neutral_noise_deg: held.noise_deg,
            neutral_uncertainty_deg: held.uncertainty_deg,
            landmarks: landmark_report,
            functional: None,
        };
        Ok((Calibration { forearm, hand, side }, report))
    }

    /// Measures the calibration from frames of the neutral posture (as [`from_neutral`](
    /// Self::from_neutral)) and a movement of the wrist mixing flexion-extension and radial-
    /// ulnar deviation in any proportion (circles, a task), the forearm's rotation
    /// (pronation-supination) held: a least-squares functional method ([`Method::Functional`]).
    ///
    /// With `s_p` held, `R = Rot(z, e)·Rot(x, a)` up to a constant: the flexion axis `z` is
    /// fixed in the forearm, the deviation axis `x` in the hand, and they stay perpendicular,
    /// `zᵀRx = 0`, whatever `e` and `a` are. In technical coordinates every movement frame
    /// `M_k = B_fᵀB_h` gives `uᵀ M_k v = 0` for `u = T_fᵀz`, `v = T_hᵀx`; the unit `u`, `v`
    /// minimising `Σ (uᵀM_kv)²` are found by alternating least squares (each step a smallest
    /// eigenvector). The neutral posture `N` gives `T_fᵀx = N v`; `u` lies in the forearm's
    /// x-z plane (turned about its long axis by whatever pronation the movement held), so
    /// `T_fᵀy ∝ u × N v`; `T_h = T_f N`. The residual (`asin(uᵀM_kv)`, RMS) is the change of
    /// pronation-supination during the movement, which the fit cannot describe.
    ///
    /// Movement data carry no sign for an axis: both are taken from the body model's placement
    /// of the forearm's markers, which they must be within [`MAX_PLACEMENT_DEG`] of (the hand's
    /// cluster may sit any way round; a forearm cluster turned half a turn reads mirrored
    /// angles: calibrate such a cluster from landmarks). Frames missing a marker
    /// are skipped. Refused, with what to record, when the movement spans less than
    /// [`MIN_MOVEMENT_DEG`] of flexion or of deviation, or the residual exceeds
    /// [`MAX_FUNCTIONAL_RESIDUAL_DEG`].
    pub fn functional(neutral: &[f32], movement: &[f32], side: Side) -> Result<(Self, CalibrationReport)> {
        let held = neutral_posture(neutral, side)?;
        let posture = held.mean;
        let mut frames = whole_frames(movement, MARKER_FRAME_LEN, "movement frames")?.to_vec();
        side.to_right(&mut frames);
        let mut moves = Vec::new();
        for (i, f) in frames.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            if f.iter().all(|v| v.is_finite()) {
                let (_, b_f) = technical_frame(f, Segment::Forearm, i)?;
                let (_, b_h) = technical_frame(f, Segment::Hand, i)?;
                moves.push(b_f.transpose() * b_h);
            }
        }
        let what_to_record = "record the wrist moving through flexion-extension and radial-ulnar deviation \
                              together (circles, or a task that bends the wrist both ways) with the forearm's \
                              rotation held, or calibrate from landmarks";
        if moves.len() < MIN_STATIC_FRAMES {
            return Err(bad(format!(
                "the movement has {} frames with all six markers (at least {MIN_STATIC_FRAMES}); {what_to_record}",
                moves.len()
            )));
        }
        let (u, v, residual, noise) = fit_universal_axes(&moves);
        let default = Self::body_model();
        // Signs from the body model's placement of the forearm: its z, and its x, which the
        // hand's deviation axis is at neutral (so the hand's cluster may sit any way round).
        let (model_z, model_x) = (Vector3::from(COORDINATES[1].axis), Vector3::from(COORDINATES[2].axis));
        let forearm_hint = default.forearm.inverse();
        let mut axes = [(u, forearm_hint * model_z, "flexion"), (posture * v, forearm_hint * model_x, "deviation")];
        let shares = axes.map(|(axis, hint, _)| axis.dot(&hint));
        for ((axis, _, _), share) in axes.iter_mut().zip(shares) {
            if share < 0.0 {
                *axis = -*axis;
            }
        }
        let (u, x) = (axes[0].0, axes[1].0.normalize());
        // The forearm's axes in its technical frame: x is the deviation axis at neutral; the
        // flexion axis u lies in its x-z plane (turned about y by the pronation the movement
        // held), so y = u × x.
        let y = u.cross(&x);
        if y.norm() < 0.5 {
            return Err(bad(format!(
                "the fitted flexion and deviation axes are {:.0}° apart at the neutral posture: are the neutral \
                 frames the neutral posture? Else {what_to_record}",
                u.angle(&x).to_degrees()
            )));
        }
        let y = y.normalize();
        let forearm = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, x.cross(&y)]).transpose());
        let hand = forearm * posture;
        let calibration = Calibration { forearm, hand, side };
        let mut angles: [Vec<f64>; N_COORDINATES] = std::array::from_fn(|_| Vec::with_capacity(moves.len()));
        for m in &moves {
            let q = body::wrist_angles(&(forearm * Rotation3::from_matrix_unchecked(*m) * hand.inverse()));
            for c in 0..N_COORDINATES {
                angles[c].push(q[c]);
            }
        }
        for a in &mut angles {
            a.sort_unstable_by(f64::total_cmp);
        }
        let (lo, hi): ([f64; N_COORDINATES], [f64; N_COORDINATES]) =
            (std::array::from_fn(|c| angles[c][0]), std::array::from_fn(|c| angles[c][moves.len() - 1]));
        let range_deg = |c: usize| (hi[c] - lo[c]).to_degrees();
        let report = FunctionalReport {
            frames: moves.len(),
            supination_held_deg: (0.5 * (hi[0] + lo[0])).to_degrees(),
            flexion_range_deg: range_deg(1),
            deviation_range_deg: range_deg(2),
            residual_deg: residual.to_degrees(),
            noise_deg: noise.to_degrees(),
        };
        if report.flexion_range_deg.min(report.deviation_range_deg) < MIN_MOVEMENT_DEG {
            // A movement about one axis fits a second axis anywhere in a plane: the two ranges
            // read with the fitted axes say "one axis only", not which one.
            return Err(bad(format!(
                "the movement spans {:.1}° of flexion and {:.1}° of deviation read with the fitted axes (at \
                 least {MIN_MOVEMENT_DEG}° of each show both axes); {what_to_record}",
                report.flexion_range_deg, report.deviation_range_deg
            )));
        }
        if report.residual_deg > MAX_FUNCTIONAL_RESIDUAL_DEG {
            return Err(bad(format!(
                "the hand turned about the forearm's long axis by {:.1}° RMS during the movement (at most \
                 {MAX_FUNCTIONAL_RESIDUAL_DEG}°): the fit needs pronation-supination held; {what_to_record}",
                report.residual_deg
            )));
        }
        // Any two of the three coordinates moving alone fit a universal joint (pronation with
        // flexion does): read with the wrong pair of axes, the movement bends the wrist where
        // wrists do not go.
        for c in [1, 2] {
            let (range, n) = (COORDINATES[c].range, moves.len());
            let (p2, p98) = (angles[c][n / 50], angles[c][n - 1 - n / 50]);
            if p2 < range.0 - PLACEMENT_POSTURE_MARGIN_RAD || p98 > range.1 + PLACEMENT_POSTURE_MARGIN_RAD {
                return Err(bad(format!(
                    "read with the fitted axes, the movement takes {} from {:.0}° to {:.0}° (2nd to 98th \
                     percentile), beyond what wrists do ({:.0}° to {:.0}°): it turned about another pair of axes \
                     (pronation with flexion fits a two-axis joint too); {what_to_record}",
                    COORDINATES[c].name,
                    p2.to_degrees(),
                    p98.to_degrees(),
                    range.0.to_degrees(),
                    range.1.to_degrees()
                )));
            }
        }
        for ((_, _, name), share) in axes.iter().zip(shares) {
            if share.abs() < MIN_SIGN_SHARE {
                return Err(bad(format!(
                    "the fitted {name} axis is {:.0}° from the body model's placement of it in the forearm's \
                     markers (at most {MAX_PLACEMENT_DEG}° tells its sign): are the forearm's markers labelled \
                     right? A forearm cluster mounted any way round needs landmarks (epicondyles, styloids)",
                    share.abs().clamp(-1.0, 1.0).acos().to_degrees()
                )));
            }
        }
        let report = CalibrationReport {
            method: Method::Functional,
            side,
            movements: Vec::new(),
            placement_deg: Calibration { forearm, hand, side }.placement_deg(),
            axis_skew_deg: 0.0,
            neutral_frames: held.frames,
            neutral_spread_deg: held.spread_deg,
            neutral_noise_deg: held.noise_deg,
            neutral_uncertainty_deg: held.uncertainty_deg,
            landmarks: None,
            functional: Some(report),
        };
        Ok((calibration, report))
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
    pub fn apply(&self, frame: &mut [f32], frame_index: usize) -> Result<()> {
        if frame.len() != MARKER_FRAME_LEN {
            return Err(bad(format!("a frame has {} values, a marker frame {MARKER_FRAME_LEN}", frame.len())));
        }
        if self.side == Side::Left {
            // Checked before mirroring so that a refused frame is left as it came.
            technical_frame(frame, Segment::Forearm, frame_index)?;
            technical_frame(frame, Segment::Hand, frame_index)?;
            self.side.to_right(frame);
        }
        let (t0_f, t0_h) = technical_in_anatomical();
        let local = default_local_markers();
        for (segment, t, t0) in [(Segment::Forearm, &self.forearm, t0_f), (Segment::Hand, &self.hand, t0_h)] {
            let (origin, b) = technical_frame(frame, segment, frame_index)?;
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

/// How far a distance between two markers of one segment may differ from the body model's
/// before the model's placement cannot describe the subject: this share of it, plus
/// [`PLACEMENT_DISTANCE_SLACK_M`].
pub const PLACEMENT_DISTANCE_SHARE: f64 = 0.25;
/// Absolute slack of the placement distance check, m.
pub const PLACEMENT_DISTANCE_SLACK_M: f64 = 0.01;
/// How far beyond a coordinate's range the median posture of an uncalibrated recording may
/// lie, rad (15°: ranges are typical active ones, and a few degrees of misplacement are what
/// the networks were trained to absorb).
pub const PLACEMENT_POSTURE_MARGIN_RAD: f64 = 0.2618;

/// Whether a recording's markers (frames back to back, metres) can be read with the body
/// model's own placement (`body`'s markers: what an uncalibrated stream or tracker assumes).
/// Refused, with what to do instead, when the median distance between two markers of a
/// segment differs from the model's by more than [`PLACEMENT_DISTANCE_SHARE`] (+ slack), or
/// when the median posture read that way lies beyond a coordinate's range (a cluster turned
/// on its segment keeps its distances but reads as a wrist bent past what wrists do). Frames
/// missing a marker are skipped; a recording without a complete frame passes (nothing to
/// judge). Uncalibrated real recordings read 46–171° off without this check.
pub fn check_default_placement(frames: &[f64], body: &body::BodyModel) -> Result<()> {
    let complete: Vec<&[f64]> =
        frames.chunks_exact(MARKER_FRAME_LEN).filter(|f| f.iter().all(|v| v.is_finite())).collect();
    if complete.is_empty() {
        return Ok(());
    }
    let median = |mut v: Vec<f64>| {
        let mid = v.len() / 2;
        *v.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    let advice =
        "calibrate the subject (ikid calibrate: landmarks or neutral frames of this session) and pass --calibration";
    for segment in [Segment::Forearm, Segment::Hand] {
        let first = body::first_marker(segment);
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            let (i, j) = (first + a, first + b);
            let model = (Vector3::from(body.marker_offsets[i]) - Vector3::from(body.marker_offsets[j])).norm();
            let seen = median(
                complete
                    .iter()
                    .map(|f| {
                        (Vector3::new(f[3 * i], f[3 * i + 1], f[3 * i + 2])
                            - Vector3::new(f[3 * j], f[3 * j + 1], f[3 * j + 2]))
                        .norm()
                    })
                    .collect(),
            );
            if (seen - model).abs() > PLACEMENT_DISTANCE_SHARE * model + PLACEMENT_DISTANCE_SLACK_M {
                return Err(bad(format!(
                    "markers {} and {} are {:.0} mm apart, where the body model puts them {:.0} mm apart: they do not sit where an uncalibrated run assumes; {advice}",
                    body::MARKERS[i].name,
                    body::MARKERS[j].name,
                    seen * 1e3,
                    model * 1e3
                )));
            }
        }
    }
    let mut angles = [Vec::new(), Vec::new(), Vec::new()];
    for f in &complete {
        let narrow: [f32; MARKER_FRAME_LEN] = std::array::from_fn(|i| f[i] as f32);
        let mut q = [0f32; N_COORDINATES];
        if crate::features::FeatureSet::Angles.compute(&narrow, &mut q, 0).is_ok() {
            for (c, v) in q.iter().enumerate() {
                angles[c].push(f64::from(*v));
            }
        }
    }
    if angles[0].is_empty() {
        return Ok(());
    }
    let posture: [f64; N_COORDINATES] = std::array::from_fn(|c| median(angles[c].clone()));
    if let Some(c) = (0..N_COORDINATES).find(|&c| {
        let (lo, hi) = COORDINATES[c].range;
        !(lo - PLACEMENT_POSTURE_MARGIN_RAD..=hi + PLACEMENT_POSTURE_MARGIN_RAD).contains(&posture[c])
    }) {
        return Err(bad(format!(
            "read with the body model's marker placement, the recording's median posture has {} = {:.0}° (its range is {:.0}° to {:.0}°): the markers do not sit where an uncalibrated run assumes; {advice}",
            COORDINATES[c].name,
            posture[c].to_degrees(),
            COORDINATES[c].range.0.to_degrees(),
            COORDINATES[c].range.1.to_degrees()
        )));
    }
    Ok(())
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

/// The forearm's ISB anatomical frame from its landmarks (mirrored into a right arm's for a
/// left one): `T_f`, and what the landmarks measured.
fn forearm_from_landmarks(trial: LandmarkTrial<'_>, side: Side) -> Result<(Rotation3<f64>, LandmarkReport)> {
    let mut markers = whole_frames(trial.markers, MARKER_FRAME_LEN, "landmark trial markers")?.to_vec();
    let mut landmarks = whole_frames(trial.landmarks, LANDMARK_FRAME_LEN, "landmarks")?.to_vec();
    let n = markers.len() / MARKER_FRAME_LEN;
    if landmarks.len() / LANDMARK_FRAME_LEN != n {
        return Err(bad(format!(
            "{} landmark frames for {n} marker frames: give one landmark frame per marker frame",
            landmarks.len() / LANDMARK_FRAME_LEN
        )));
    }
    side.to_right(&mut markers);
    side.to_right(&mut landmarks);
    let mut sums = [Vector3::zeros(); 4];
    let mut counts = [0usize; 4];
    let mut seen_anywhere = [0usize; 4];
    for (i, (f, l)) in
        markers.chunks_exact(MARKER_FRAME_LEN).zip(landmarks.chunks_exact(LANDMARK_FRAME_LEN)).enumerate()
    {
        let seen: [bool; 4] = std::array::from_fn(|k| l[3 * k..3 * k + 3].iter().all(|v| v.is_finite()));
        for k in 0..4 {
            seen_anywhere[k] += seen[k] as usize;
        }
        if !f[..9].iter().all(|v| v.is_finite()) || !seen.iter().any(|&s| s) {
            continue;
        }
        let (origin, b) = technical_frame(f, Segment::Forearm, i)?;
        for k in (0..4).filter(|&k| seen[k]) {
            let p = Vector3::new(l[3 * k] as f64, l[3 * k + 1] as f64, l[3 * k + 2] as f64);
            sums[k] += b.transpose() * (p - origin);
            counts[k] += 1;
        }
    }
    if let Some(k) = (0..4).find(|&k| counts[k] == 0) {
        let how = if seen_anywhere[k] == 0 {
            "is missing in every one".to_string()
        } else {
            format!("is seen in {} but never with the forearm's three markers", seen_anywhere[k])
        };
        return Err(bad(format!(
            "landmark {} ({}) {how} of the {n} calibration frames: record it (a marker on it in the static \
             trial, or a point probed relative to the forearm cluster) in frames where the forearm's \
             markers are seen, or calibrate from the neutral posture alone",
            LANDMARKS[k].name, LANDMARKS[k].description
        )));
    }
    let [le, me, rs, us]: [Vector3<f64>; 4] = std::array::from_fn(|k| sums[k] / counts[k] as f64);
    let long = (le + me) / 2.0 - (rs + us) / 2.0;
    let across = rs - us;
    let what_to_record = "record the epicondyles at the elbow and the styloids either side of the wrist, each \
                          labelled as the marker map says";
    if long.norm() < MIN_FOREARM_AXIS_M {
        return Err(bad(format!(
            "the mid-styloids are {:.0} mm from the mid-epicondyles (at least {:.0}): the landmarks do not \
             span the forearm; {what_to_record}",
            1e3 * long.norm(),
            1e3 * MIN_FOREARM_AXIS_M
        )));
    }
    if across.norm() < MIN_STYLOID_SPAN_M {
        return Err(bad(format!(
            "the radial and ulnar styloids are {:.1} mm apart (at least {:.0}); {what_to_record}",
            1e3 * across.norm(),
            1e3 * MIN_STYLOID_SPAN_M
        )));
    }
    let styloid_axis_deg = long.angle(&across).to_degrees();
    if styloid_axis_deg.min(180.0 - styloid_axis_deg) < MIN_LANDMARK_ANGLE_DEG {
        return Err(bad(format!(
            "the landmarks are nearly collinear: the styloid line is {styloid_axis_deg:.0}° from the forearm's \
             long axis (at least {MIN_LANDMARK_ANGLE_DEG}° from it); {what_to_record}"
        )));
    }
    let y = long.normalize();
    let x = y.cross(&across).normalize();
    let z = x.cross(&y);
    // Columns: the anatomical axes in technical coordinates, A; T_f = Aᵀ.
    let axes = Matrix3::from_columns(&[x, y, z]);
    let report = LandmarkReport {
        frames: counts,
        long_axis_mm: 1e3 * long.norm(),
        styloid_span_mm: 1e3 * across.norm(),
        epicondyle_span_mm: 1e3 * (le - me).norm(),
        styloid_axis_deg,
        length_scale: long.norm() / body::BodyModel::default().forearm.length,
        hand: None,
    };
    Ok((Rotation3::from_matrix_unchecked(axes.transpose()), report))
}

/// The hand's rotation in the forearm (`B_fᵀB_h`, technical frames) at the neutral posture:
/// held over the frames with all six markers (a left arm's mirrored first; [`HeldPosture`]).
/// Refused when fewer than [`MIN_NEUTRAL_FRAMES`] are complete or the hand moves more than
/// [`MAX_STATIC_SPREAD_DEG`].
fn neutral_posture(neutral: &[f32], side: Side) -> Result<HeldPosture> {
    let mut frames = whole_frames(neutral, MARKER_FRAME_LEN, "neutral frames")?.to_vec();
    side.to_right(&mut frames);
    let n = frames.len() / MARKER_FRAME_LEN;
    let mut relative = Vec::new();
    let mut unseen = [0usize; 6];
    for (i, f) in frames.chunks_exact(MARKER_FRAME_LEN).enumerate() {
        let mut complete = true;
        for (m, count) in unseen.iter_mut().enumerate() {
            if !f[3 * m..3 * m + 3].iter().all(|v| v.is_finite()) {
                *count += 1;
                complete = false;
            }
        }
        if complete {
            let (_, b_f) = technical_frame(f, Segment::Forearm, i)?;
            let (_, b_h) = technical_frame(f, Segment::Hand, i)?;
            relative.push(Rotation3::from_matrix_unchecked(b_f.transpose() * b_h));
        }
    }
    if relative.is_empty() {
        let missing: Vec<String> = unseen
            .iter()
            .enumerate()
            .filter(|&(_, &c)| c > 0)
            .map(|(m, c)| format!("{} in {c}", body::MARKERS[m].name))
            .collect();
        return Err(bad(format!(
            "no usable neutral frame: none of the {n} has all six markers (missing: {}); choose frames of \
             the neutral posture where every marker is seen, or record a static trial with all six",
            if missing.is_empty() { "none, but there are no frames".to_string() } else { missing.join(", ") }
        )));
    }
    if relative.len() < MIN_NEUTRAL_FRAMES {
        return Err(bad(format!(
            "{} of the {n} neutral frames have all six markers (at least {MIN_NEUTRAL_FRAMES} are needed: one \
             frame's noise would be the calibration's error); choose more frames of the neutral posture where \
             every marker is seen, or record a static trial of a second or more",
            relative.len()
        )));
    }
    let held = HeldPosture::of(&relative);
    if held.spread_deg > MAX_STATIC_SPREAD_DEG {
        return Err(bad(format!(
            "the hand moves {:.1}° within the neutral frames, its markers' noise ({:.1}° a frame) averaged out \
             (at most {MAX_STATIC_SPREAD_DEG}°): choose frames where the wrist holds one posture",
            held.spread_deg, held.noise_deg
        )));
    }
    Ok(held)
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

/// Refuses neutral frames whose forearm markers do not sit where the body model puts RSP, USP
/// and FAP — the neutral method keeps that placement for the forearm, so it cannot know any
/// other: the median distance between two of the forearm's markers must be the model's, for a
/// subject of any size the scale of the triangle fits within [`SUBJECT_SCALES`], each within
/// [`PLACEMENT_DISTANCE_SHARE`] (+ [`PLACEMENT_DISTANCE_SLACK_M`]), as the uncalibrated path
/// checks. A cluster (a plate's 4 cm sides against the model's 17 cm) is refused with what to
/// record instead.
fn check_forearm_placement(frames: &[f32]) -> Result<()> {
    let body = body::BodyModel::default();
    let complete: Vec<&[f32]> =
        frames.chunks_exact(MARKER_FRAME_LEN).filter(|f| f[..9].iter().all(|v| v.is_finite())).collect();
    if complete.is_empty() {
        return Ok(()); // neutral_posture has refused these frames already
    }
    let pairs = [(0, 1), (0, 2), (1, 2)];
    let point = |f: &[f32], m: usize| Vector3::new(f[3 * m] as f64, f[3 * m + 1] as f64, f[3 * m + 2] as f64);
    let seen: [f64; 3] = pairs.map(|(i, j)| {
        let mut d: Vec<f64> = complete.iter().map(|f| (point(f, i) - point(f, j)).norm()).collect();
        let mid = d.len() / 2;
        *d.select_nth_unstable_by(mid, f64::total_cmp).1
    });
    let model: [f64; 3] =
        pairs.map(|(i, j)| (Vector3::from(body.marker_offsets[i]) - Vector3::from(body.marker_offsets[j])).norm());
    let fitted = seen.iter().zip(&model).map(|(s, m)| s * m).sum::<f64>() / model.iter().map(|m| m * m).sum::<f64>();
    let scale = fitted.clamp(SUBJECT_SCALES.0, SUBJECT_SCALES.1);
    for (k, (i, j)) in pairs.into_iter().enumerate() {
        let expected = scale * model[k];
        if (seen[k] - expected).abs() > PLACEMENT_DISTANCE_SHARE * expected + PLACEMENT_DISTANCE_SLACK_M {
            return Err(bad(format!(
                "the neutral method keeps the body model's placement of the forearm's markers, and these do not \
                 sit there: {} and {} are {:.0} mm apart where the model puts them {:.0} mm apart (for a subject \
                 {scale:.2}× its size), so the forearm's axes cannot be known from them. Record the epicondyles \
                 and styloids (markers in a static trial, or points probed relative to the forearm's markers) \
                 and calibrate with --method landmarks, or record the wrist moving through flexion and \
                 deviation together with the forearm still (--method functional)",
                body::MARKERS[i].name,
                body::MARKERS[j].name,
                1e3 * seen[k],
                1e3 * expected
            )));
        }
    }
    Ok(())
}

/// Sizes of subjects the neutral method's placement check allows, as the body model's length
/// factor: from a small adult's forearm to a tall one's.
pub const SUBJECT_SCALES: (f64, f64) = (0.75, 1.35);

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

/// Orthogonal Procrustes: the rotation `T` maximising `Σ aᵀ T t` over pairs `(a, t)` (model
/// axis, measured axis in technical coordinates).
fn procrustes(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Rotation3<f64> {
    let n = pairs.iter().fold(Matrix3::zeros(), |acc, (a, t)| acc + t * a.transpose());
    let svd = n.svd(true, true);
    let (u, v_t) = (svd.u.expect("requested"), svd.v_t.expect("requested"));
    let d = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, (v_t.transpose() * u.transpose()).determinant().signum()));
    Rotation3::from_matrix(&(v_t.transpose() * d * u.transpose()))
}

/// The unit `u`, `v` minimising `Σ (uᵀ M_k v)²` (a universal joint: `u` fixed in the first
/// segment, `v` in the second, perpendicular in every frame), by alternating least squares
/// from several starts; with the RMS of `asin(uᵀM_kv)` that is not the markers' noise (the
/// turn the fit cannot describe), and the noise's, radians.
fn fit_universal_axes(moves: &[Matrix3<f64>]) -> (Vector3<f64>, Vector3<f64>, f64, f64) {
    let smallest = |scatter: Matrix3<f64>| -> Vector3<f64> {
        let eigen = SymmetricEigen::new(scatter);
        eigen.eigenvectors.column(eigen.eigenvalues.imin()).into_owned()
    };
    let cost = |u: &Vector3<f64>, v: &Vector3<f64>| moves.iter().map(|m| u.dot(&(m * v)).powi(2)).sum::<f64>();
    let mut best: Option<(Vector3<f64>, Vector3<f64>, f64)> = None;
    for start in [Vector3::x(), Vector3::y(), Vector3::z()] {
        let mut v = start;
        let mut u = smallest(moves.iter().fold(Matrix3::zeros(), |acc, m| acc + (m * v) * (m * v).transpose()));
        let mut last = f64::MAX;
        for _ in 0..20000 {
            v = smallest(moves.iter().fold(Matrix3::zeros(), |acc, m| {
                let w = m.transpose() * u;
                acc + w * w.transpose()
            }));
            u = smallest(moves.iter().fold(Matrix3::zeros(), |acc, m| acc + (m * v) * (m * v).transpose()));
            let c = cost(&u, &v);
            if last - c <= 1e-15 * moves.len() as f64 {
                break;
            }
            last = c;
        }
        let c = cost(&u, &v);
        if best.as_ref().is_none_or(|b| c < b.2) {
            best = Some((u, v, c));
        }
    }
    let (u, v, _) = best.expect("three starts");
    let residuals: Vec<f64> = moves.iter().map(|m| u.dot(&(m * v)).clamp(-1.0, 1.0).asin()).collect();
    let n = residuals.len() as f64;
    let mean_square = residuals.iter().map(|r| r * r).sum::<f64>() / n;
    // The markers' noise differs between consecutive frames, a turn of the forearm hardly:
    // half the mean square of the differences is the noise's share of the residual.
    let noise = consecutive_noise_variance(residuals.windows(2).map(|w| (w[1] - w[0]).powi(2)), 1);
    (u, v, (mean_square - noise).max(0.0).sqrt(), noise.sqrt())
}

/// The hand's anatomical frame from its landmarks and the styloids (mirrored into a right
/// arm's for a left one): `T_h`, and what the landmarks measured (its neutral offset left 0).
fn hand_from_landmarks(trial: LandmarkTrial<'_>, side: Side) -> Result<(Rotation3<f64>, HandLandmarkReport)> {
    let hand_points = trial.hand_landmarks.expect("called with hand landmarks");
    let n = trial.markers.len() / MARKER_FRAME_LEN;
    let mut hand_points = whole_frames(hand_points, HAND_LANDMARK_FRAME_LEN, "hand landmarks")?.to_vec();
    if hand_points.len() / HAND_LANDMARK_FRAME_LEN != n {
        return Err(bad(format!(
            "{} hand landmark frames for {n} marker frames: give one per marker frame",
            hand_points.len() / HAND_LANDMARK_FRAME_LEN
        )));
    }
    let mut markers = trial.markers.to_vec();
    let mut landmarks = trial.landmarks.to_vec();
    side.to_right(&mut markers);
    side.to_right(&mut landmarks);
    side.to_right(&mut hand_points);
    let point = |v: &[f32], k: usize| Vector3::new(v[3 * k] as f64, v[3 * k + 1] as f64, v[3 * k + 2] as f64);
    let seen = |v: &[f32], k: usize| v[3 * k..3 * k + 3].iter().all(|x| x.is_finite());
    let (mut wrist, mut second, mut fifth, mut count) = (Vector3::zeros(), Vector3::zeros(), Vector3::zeros(), 0usize);
    for (i, ((f, l), h)) in markers
        .chunks_exact(MARKER_FRAME_LEN)
        .zip(landmarks.chunks_exact(LANDMARK_FRAME_LEN))
        .zip(hand_points.chunks_exact(HAND_LANDMARK_FRAME_LEN))
        .enumerate()
    {
        if !(f[9..].iter().all(|v| v.is_finite()) && seen(l, 2) && seen(l, 3) && seen(h, 0) && seen(h, 1)) {
            continue;
        }
        let (origin, b) = technical_frame(f, Segment::Hand, i)?;
        let local = |p: Vector3<f64>| b.transpose() * (p - origin);
        wrist += local((point(l, 2) + point(l, 3)) / 2.0);
        second += local(point(h, 0));
        fifth += local(point(h, 1));
        count += 1;
    }
    let what_to_record = "record the second and fifth metacarpal heads (knuckles) with the styloids and the \
                          hand's three markers in the same frames, or leave the hand landmarks out (the hand then \
                          equals the forearm at the neutral posture)";
    if count == 0 {
        return Err(bad(format!(
            "no frame of the {n} has the hand's three markers, both metacarpal heads and both styloids; \
             {what_to_record}"
        )));
    }
    let (wrist, second, fifth) = (wrist / count as f64, second / count as f64, fifth / count as f64);
    let long = wrist - (second + fifth) / 2.0;
    let across = second - fifth;
    if long.norm() < MIN_HAND_AXIS_M || across.norm() < MIN_STYLOID_SPAN_M {
        return Err(bad(format!(
            "the metacarpal heads are {:.0} mm from the mid-styloids and {:.1} mm apart (at least {:.0} and \
             {:.0}): they do not span the hand; {what_to_record}",
            1e3 * long.norm(),
            1e3 * across.norm(),
            1e3 * MIN_HAND_AXIS_M,
            1e3 * MIN_STYLOID_SPAN_M
        )));
    }
    let angle = long.angle(&across).to_degrees();
    if angle.min(180.0 - angle) < MIN_LANDMARK_ANGLE_DEG {
        return Err(bad(format!(
            "the hand's landmarks are nearly collinear: the metacarpal heads' line is {angle:.0}° from the \
             hand's long axis (at least {MIN_LANDMARK_ANGLE_DEG}° from it); {what_to_record}"
        )));
    }
    let y = long.normalize();
    let x = y.cross(&across).normalize();
    let z = x.cross(&y);
    let report = HandLandmarkReport {
        frames: count,
        long_axis_mm: 1e3 * long.norm(),
        metacarpal_span_mm: 1e3 * across.norm(),
        neutral_offset_deg: 0.0,
    };
    Ok((Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]).transpose()), report))
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
        assert!(report.placement_deg[1] > MAX_PLACEMENT_DEG, "{report:?}");
        let q = [0.5, -0.6, 0.25];
        let (frame, _) = neutral_session(1, &SHIFT, 120.0, q);
        let out = angles_after(&cal, &frame);
        for k in 0..3 {
            assert!((out[k] as f64 - q[k]).abs() < 1e-4, "{out:?} vs {q:?}");
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
        assert!(err.contains("4 of the 4 neutral frames have all six markers (at least 5 are needed"), "{err}");
        let one = &clean[..MARKER_FRAME_LEN];
        let err = Calibration::from_neutral(one, None, Side::Right).unwrap_err().to_string();
        assert!(err.contains("1 of the 1 neutral frames"), "{err}");
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
}
