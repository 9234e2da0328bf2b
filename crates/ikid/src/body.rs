//! The wrist body model: coordinates, axes, signs, markers and segment parameters.
//!
//! This is the single place these conventions live; the simulator, the reference solvers,
//! the features, the file writers and the docs read them from here.
//!
//! # Frames
//! * **Lab** (as OpenSim): X anterior, Y up, Z to the subject's right.
//! * **Forearm** (origin at the wrist joint centre): x volar (the way the palm faces at zero
//!   angles), y proximal along the forearm's long axis, z radial (thumb side); right-handed.
//!   With the shoulder at 0° flexion, elbow extended and the forearm mid-prone (thumb forward),
//!   forearm x = lab −Z, y = lab +Y, z = lab +X.
//! * **Hand** (origin at the wrist joint centre): equal to the forearm frame at zero angles.
//!
//! # Wrist coordinates, in order (s_p, e_f, ad_ab)
//! The hand's orientation in the forearm frame is `R = Rot(a1, q1) · Rot(a2, q2) · Rot(a3, q3)`
//! (intrinsic rotations about axes carried along the chain), with the axes below.

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};

/// One wrist degree of freedom.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coordinate {
    /// Name used in files and model cards (OpenSim-style).
    pub name: &'static str,
    /// What a positive angle means.
    pub positive: &'static str,
    /// Rotation axis, in the frame of the previous link of the chain, at zero angles.
    pub axis: [f64; 3],
    /// Anatomical range of motion `(min, max)` in radians (see [`COORDINATES`]).
    pub range: (f64, f64),
}

const DEG: f64 = std::f64::consts::PI / 180.0;

/// The three wrist coordinates in the canonical order `(s_p, e_f, ad_ab)`.
///
/// Ranges are typical active ranges of motion from the neutral (mid-prone, straight wrist)
/// position (AAOS / Norkin & White): pronation and supination 80° each, flexion 80°,
/// extension 70°, ulnar deviation (adduction) 30°, radial deviation (abduction) 20°.
pub const COORDINATES: [Coordinate; 3] = [
    Coordinate { name: "ra_wr_s_p", positive: "supination", axis: [0.0, -1.0, 0.0], range: (-80.0 * DEG, 80.0 * DEG) },
    Coordinate { name: "ra_wr_e_f", positive: "flexion", axis: [0.0, 0.0, 1.0], range: (-70.0 * DEG, 80.0 * DEG) },
    Coordinate {
        name: "ra_wr_ad_ab",
        positive: "adduction (ulnar deviation)",
        axis: [1.0, 0.0, 0.0],
        range: (-20.0 * DEG, 30.0 * DEG),
    },
];

/// Gravitational acceleration in the lab frame (Y up), m/s².
pub const GRAVITY: [f64; 3] = [0.0, -9.81, 0.0];

/// The up direction of a lab named by its axis: `"+z"`, `"z"`, `"-Y"`, ... (the names a
/// marker map's `up` takes); an error naming the six otherwise.
pub fn up_axis(name: &str) -> crate::Result<[f64; 3]> {
    let text = name.trim().to_ascii_lowercase();
    let (sign, axis) = match text.as_bytes() {
        [b'+', a] | [a] => (1.0, *a),
        [b'-', a] => (-1.0, *a),
        _ => (0.0, b'?'),
    };
    let Some(i) = [b'x', b'y', b'z'].iter().position(|&c| c == axis).filter(|_| sign != 0.0) else {
        return Err(crate::Error::BadArgument {
            what: "up",
            detail: format!("is {name:?}, expected the lab axis pointing up, one of +x, -x, +y, -y, +z, -z"),
        });
    };
    let mut up = [0.0; 3];
    up[i] = sign;
    Ok(up)
}

/// The rotation that turns a lab whose up direction (against gravity) is `up` into the body
/// model's (+Y up, [`GRAVITY`]), or `None` when it already is: the shortest turn taking `up`
/// onto +Y (which way the lab faces about the vertical changes no angle and no torque). An
/// `up` that is not a finite, non-zero vector is an error.
pub fn lab_turn(up: [f64; 3]) -> crate::Result<Option<Rotation3<f64>>> {
    let given = up;
    let up = Vector3::from(up);
    let norm = up.norm();
    if !(norm.is_finite() && norm > 1e-9) {
        return Err(crate::Error::BadArgument {
            what: "up",
            detail: format!(
                "is {:?}, expected the lab's up direction as a finite non-zero vector (e.g. [0, 0, 1] for a \
                 Z-up lab)",
                given
            ),
        });
    }
    let up = up / norm;
    let y = Vector3::y();
    if (up - y).norm() < 1e-12 {
        return Ok(None);
    }
    // Antiparallel (Y down): half a turn about x; otherwise the shortest arc.
    let turn = Rotation3::rotation_between(&up, &y)
        .unwrap_or_else(|| Rotation3::from_axis_angle(&Unit::new_unchecked(Vector3::x()), std::f64::consts::PI));
    // A lab axis's turn is a signed permutation: rounding cos(90°)'s 6e-17 away makes it exact,
    // so a lab's coordinates are moved, never perturbed.
    let snap = |x: f64| if (x - x.round()).abs() < 1e-12 { x.round() } else { x };
    Ok(Some(Rotation3::from_matrix_unchecked(turn.into_inner().map(snap))))
}

/// Number of wrist coordinates.
pub const N_COORDINATES: usize = 3;

/// The two rigid segments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Segment {
    /// Fixed in the lab at the shoulder pose.
    Forearm,
    /// Attached to the forearm by the 3-DoF wrist.
    Hand,
}

impl Segment {
    /// Lower-case name used in feature names and files.
    pub fn name(self) -> &'static str {
        match self {
            Segment::Forearm => "forearm",
            Segment::Hand => "hand",
        }
    }
}

/// One marker: its label and the segment it sits on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Marker {
    /// Label used in TRC/C3D files and feature names.
    pub name: &'static str,
    /// Segment carrying it.
    pub segment: Segment,
    /// Where it sits.
    pub description: &'static str,
    /// Default position in the segment's frame, metres, for the default subject.
    pub offset: [f64; 3],
}

/// The six markers in canonical order: three on the forearm, then three on the hand.
///
/// A marker frame is these six positions `x, y, z` in this order (18 values). Within a
/// segment the order matters: the technical frame is built from markers 0, 1, 2 of it.
pub const MARKERS: [Marker; 6] = [
    Marker {
        name: "RSP",
        segment: Segment::Forearm,
        description: "radial styloid process",
        offset: [0.000, 0.010, 0.030],
    },
    Marker {
        name: "USP",
        segment: Segment::Forearm,
        description: "ulnar styloid process",
        offset: [-0.010, 0.010, -0.025],
    },
    Marker {
        name: "FAP",
        segment: Segment::Forearm,
        description: "dorsal forearm, two thirds of the way to the elbow",
        offset: [-0.025, 0.180, 0.000],
    },
    Marker {
        name: "MC2",
        segment: Segment::Hand,
        description: "head of the 2nd metacarpal (dorsal)",
        offset: [-0.010, -0.080, 0.025],
    },
    Marker {
        name: "MC5",
        segment: Segment::Hand,
        description: "head of the 5th metacarpal (dorsal)",
        offset: [-0.010, -0.075, -0.025],
    },
    Marker {
        name: "MCB",
        segment: Segment::Hand,
        description: "base of the 3rd metacarpal (dorsal)",
        offset: [-0.020, -0.030, 0.000],
    },
];

/// A hand seen through one marker instead of [`MARKERS`]' three (Plug-in Gait's `FIN`, a
/// wheelchair glove's single marker): it gives the hand's direction from the wrist, not its
/// roll about that direction. See [`hand_from_one_marker`].
pub const HAND_POINT: Marker = Marker {
    name: "HND",
    segment: Segment::Hand,
    description: "one marker on the back of the hand, distally (Plug-in Gait's FIN): the hand's direction, \
                  not its roll",
    offset: [-0.010, -0.080, 0.000],
};
/// The markers of a one-marker hand's frame: the forearm's three ([`MARKERS`] 0-2), then
/// [`HAND_POINT`] (12 values).
pub const ONE_HAND_MARKER_FRAME_LEN: usize = 12;
/// The coordinate a one-marker hand does not determine: its roll about its own long axis,
/// which in the Y-Z'-X'' order is the first rotation (`ra_wr_s_p`).
pub const ONE_HAND_MARKER_UNDETERMINED: usize = 0;
/// Closest the hand's one marker may be to the mid-styloids, m: nearer, its direction from
/// the wrist is the markers' noise.
pub const MIN_HAND_POINT_DISTANCE_M: f64 = 0.03;
/// Smallest angle between the styloid line (RSP-USP) and the hand's direction, degrees: below
/// it the two do not span a plane and the virtual hand has no defined orientation.
pub const MIN_HAND_POINT_ANGLE_DEG: f64 = 20.0;

/// The six-marker frames (`(n, 18)`, [`MARKERS`] order) of frames with three forearm markers
/// on its landmarks and one hand marker (`(n, 12)`: RSP and USP on the radial and ulnar
/// styloids — a wrist bar —, FAP on the lateral epicondyle, [`HAND_POINT`]; metres, NaN =
/// missing), as Plug-in Gait marks an arm. All six are virtual, at the body model's offsets in
/// each segment's anatomical frame of that instant:
/// - the forearm's (ISB, as [`crate::calibration`]'s landmark method builds it): origin the
///   mid-styloids, `y` to FAP (proximal), `x = y × (USP → RSP)` (volar), `z = x × y` (radial).
///   Built anew each frame, not as a rigid cluster: FAP sits on the humerus and the styloids
///   turn about the forearm's axis with pronation, so the three are no rigid body;
/// - the hand's: `y` from the hand marker to the mid-styloids, `z` the forearm's `z` made
///   perpendicular to `y`, `x = y × z`. It has no roll of its own: a hand flexed by `e` and
///   deviated by `a` reads `Rot(z, e)·Rot(x, a)` in the forearm, exactly, and the first angle of
///   the Y-Z'-X'' order ([`ONE_HAND_MARKER_UNDETERMINED`], `ra_wr_s_p`) is not observed: it must
///   not be reported.
///
/// For a left arm (`left`) each `x` is negated, so that the arm mirrored into a right one (lab
/// `z` negated, as calibration does) has its markers where a right arm's would be. A segment's
/// virtual markers are NaN in a frame where one of its points is missing or degenerate: FAP
/// within [`MIN_HAND_POINT_DISTANCE_M`] of the mid-styloids, the hand marker as close, or
/// either direction within [`MIN_HAND_POINT_ANGLE_DEG`] of the styloid line (the hand's
/// markers need the forearm's).
pub fn hand_from_one_marker(frames: &[f64], left: bool) -> crate::Result<Vec<f64>> {
    if !frames.len().is_multiple_of(ONE_HAND_MARKER_FRAME_LEN) {
        return Err(crate::Error::BadArgument {
            what: "frames",
            detail: format!(
                "{} values is not whole frames of {ONE_HAND_MARKER_FRAME_LEN} (RSP, USP, FAP and the hand marker)",
                frames.len()
            ),
        });
    }
    let mirror = if left { -1.0 } else { 1.0 };
    let place = |out: &mut Vec<f64>, origin: Vector3<f64>, axes: Option<[Vector3<f64>; 3]>, markers: &[Marker]| {
        for m in markers {
            match axes {
                Some([x, y, z]) => {
                    let p = origin + x * (mirror * m.offset[0]) + y * m.offset[1] + z * m.offset[2];
                    out.extend_from_slice(&[p.x, p.y, p.z]);
                }
                None => out.extend_from_slice(&[f64::NAN; 3]),
            }
        }
    };
    let mut out = Vec::with_capacity(frames.len() / ONE_HAND_MARKER_FRAME_LEN * MARKER_FRAME_LEN);
    for f in frames.chunks_exact(ONE_HAND_MARKER_FRAME_LEN) {
        let (wrist, forearm, hand, _) = one_marker_frames(f);
        place(&mut out, wrist, forearm, &MARKERS[..first_marker(Segment::Hand)]);
        place(&mut out, wrist, hand, &MARKERS[first_marker(Segment::Hand)..]);
    }
    Ok(out)
}

/// One frame of [`hand_from_one_marker`]'s input: the mid-styloids, the forearm's and the
/// hand's anatomical axes (right-arm construction; None where not determined), the hand marker.
type OneMarkerFrames = (Vector3<f64>, Option<[Vector3<f64>; 3]>, Option<[Vector3<f64>; 3]>, Vector3<f64>);

fn one_marker_frames(f: &[f64]) -> OneMarkerFrames {
    // `towards` made perpendicular to the unit `y`, unit; None when within the smallest angle.
    let across = |towards: Vector3<f64>, y: Vector3<f64>| {
        let angle = towards.angle(&y).to_degrees();
        (angle.min(180.0 - angle) >= MIN_HAND_POINT_ANGLE_DEG).then(|| (towards - y * towards.dot(&y)).normalize())
    };
    let point = |m: usize| Vector3::new(f[3 * m], f[3 * m + 1], f[3 * m + 2]);
    let seen = |m: usize| f[3 * m..3 * m + 3].iter().all(|v| v.is_finite());
    let (rsp, usp, fap, hnd) = (point(0), point(1), point(2), point(3));
    let wrist = (rsp + usp) / 2.0;
    let forearm = (seen(0) && seen(1) && seen(2) && (fap - wrist).norm() >= MIN_HAND_POINT_DISTANCE_M)
        .then(|| (fap - wrist).normalize())
        .and_then(|y| across(rsp - usp, y).map(|z| [y.cross(&z), y, z]));
    let hand =
        forearm.filter(|_| seen(3) && (wrist - hnd).norm() >= MIN_HAND_POINT_DISTANCE_M).and_then(|[_, _, z_f]| {
            let y = (wrist - hnd).normalize();
            across(z_f, y).map(|z| [y.cross(&z), y, z])
        });
    (wrist, forearm, hand, hnd)
}

/// The hand's two landmarks (second and fifth metacarpal heads, [`crate::calibration::HAND_LANDMARKS`]
/// order, `(n, 6)`) a one-marker hand stands for: the hand marker ± 25 mm along the virtual
/// hand's `z` ([`hand_from_one_marker`]), from frames as that takes them. With the styloids and
/// FAP as the forearm's landmarks, a calibration then finds both segments at the body model's
/// placement: the virtual markers are their anatomical frames, and the angles read the hand's
/// direction in the forearm rather than the static posture as zero. NaN where the hand's
/// frame is not determined.
pub fn one_marker_hand_landmarks(frames: &[f64]) -> crate::Result<Vec<f64>> {
    if !frames.len().is_multiple_of(ONE_HAND_MARKER_FRAME_LEN) {
        return Err(crate::Error::BadArgument {
            what: "frames",
            detail: format!(
                "{} values is not whole frames of {ONE_HAND_MARKER_FRAME_LEN} (RSP, USP, FAP and the hand marker)",
                frames.len()
            ),
        });
    }
    let mut out = Vec::with_capacity(frames.len() / 2);
    for f in frames.chunks_exact(ONE_HAND_MARKER_FRAME_LEN) {
        let (_, _, hand, hnd) = one_marker_frames(f);
        for sign in [1.0, -1.0] {
            let p = hand.map_or(Vector3::repeat(f64::NAN), |[_, _, z]| hnd + z * (sign * 0.025));
            out.extend_from_slice(&[p.x, p.y, p.z]);
        }
    }
    Ok(out)
}

/// Number of markers in a frame.
pub const N_MARKERS: usize = MARKERS.len();
/// Values in one marker frame (`x, y, z` per marker).
pub const MARKER_FRAME_LEN: usize = 3 * N_MARKERS;
/// Index of a segment's first marker in [`MARKERS`] (each segment has three, contiguous).
pub fn first_marker(segment: Segment) -> usize {
    match segment {
        Segment::Forearm => 0,
        Segment::Hand => 3,
    }
}

/// The index in [`COORDINATES`] of the coordinate called `name` (e.g. `"ra_wr_e_f"`); an
/// unknown name is refused, naming the known ones.
pub fn coordinate_index(name: &str) -> crate::Result<usize> {
    COORDINATES.iter().position(|c| c.name == name).ok_or_else(|| crate::Error::BadArgument {
        what: "coordinate",
        detail: format!("unknown coordinate {name:?} (known: {})", COORDINATES.map(|c| c.name).join(", ")),
    })
}

/// The missing markers of a marker frame ([`MARKERS`] order, f32 or f64): bit `i` is set when
/// marker `i` has a non-finite coordinate (NaN: not seen). The one missing-marker mask: the gap
/// filler, the tracker and the bindings' flags all mean this.
#[inline]
pub fn missing_markers<T: Copy + Into<f64>>(frame: &[T]) -> u8 {
    frame
        .chunks_exact(3)
        .take(N_MARKERS)
        .enumerate()
        .filter(|(_, xyz)| xyz.iter().any(|&v| !v.into().is_finite()))
        .fold(0, |mask, (i, _)| mask | (1 << i))
}

/// The names of the markers in a mask (bit `i` = [`MARKERS`]`[i]`), in [`MARKERS`] order.
pub fn marker_names(mask: u8) -> impl Iterator<Item = &'static str> {
    MARKERS.iter().enumerate().filter(move |(i, _)| mask & (1 << i) != 0).map(|(_, m)| m.name)
}

/// Subjects' segment lengths relative to the default subject's that [`BodyModel::try_scaled`]
/// accepts: a small child's to a very tall adult's, with room (a factor outside is a typo).
pub const LENGTH_SCALE_RANGE: (f64, f64) = (0.3, 3.0);
/// Subjects' segment masses relative to the default subject's that [`BodyModel::try_scaled`]
/// accepts (mass grows with the cube of size).
pub const MASS_SCALE_RANGE: (f64, f64) = (0.02, 30.0);

/// How far apart a forearm's and hand's six markers can be, m: their largest distance is at
/// least 4 cm (two 3-marker clusters) and at most 0.8 m (an arm's forearm and hand together
/// are ~0.45 m). Outside it, the numbers are not in the units the file or caller says — the
/// commonest cause: millimetres read as centimetres or metres.
pub const MARKER_SPAN_M: (f64, f64) = (0.04, 0.8);

/// The largest distance between two markers present (finite) in `frame` (a marker frame), m;
/// `None` with fewer than two present.
pub fn marker_span(frame: &[f64]) -> Option<f64> {
    let point = |m: usize| Vector3::new(frame[3 * m], frame[3 * m + 1], frame[3 * m + 2]);
    let present = |m: usize| frame[3 * m..3 * m + 3].iter().all(|v| v.is_finite());
    let mut span: Option<f64> = None;
    for a in (0..N_MARKERS).filter(|&m| present(m)) {
        for b in (a + 1..N_MARKERS).filter(|&m| present(m)) {
            let d = (point(a) - point(b)).norm();
            span = Some(span.map_or(d, |s: f64| s.max(d)));
        }
    }
    span
}

/// Refuses a marker frame whose markers spread over a distance no forearm and hand span
/// ([`MARKER_SPAN_M`]), naming the likely cause.
pub fn check_marker_span(frame: &[f64], frame_index: usize) -> crate::Result<()> {
    match marker_span(frame) {
        Some(span) if !(MARKER_SPAN_M.0..=MARKER_SPAN_M.1).contains(&span) => {
            Err(crate::Error::ImplausibleMarkers { frame: frame_index, detail: span_problem(span) })
        }
        _ => Ok(()),
    }
}

/// Checks a whole recording's scale (frames back to back): its median marker span must be one
/// a forearm and hand can have ([`MARKER_SPAN_M`]). One glitched frame does not fail it; a
/// recording in the wrong units does, with a message naming the likely cause.
pub fn check_recording_span(frames: &[f64]) -> crate::Result<()> {
    let mut spans: Vec<f64> = frames.chunks_exact(MARKER_FRAME_LEN).filter_map(marker_span).collect();
    if spans.is_empty() {
        return Ok(());
    }
    let mid = spans.len() / 2;
    let (_, median, _) = spans.select_nth_unstable_by(mid, f64::total_cmp);
    let median = *median;
    if (MARKER_SPAN_M.0..=MARKER_SPAN_M.1).contains(&median) {
        return Ok(());
    }
    let first = frames
        .chunks_exact(MARKER_FRAME_LEN)
        .position(|f| marker_span(f).is_some_and(|s| !(MARKER_SPAN_M.0..=MARKER_SPAN_M.1).contains(&s)))
        .unwrap_or(0);
    // A marker at exactly the lab's origin in most frames is a missing one exported as zeros
    // (review 7: read as a marker, it was told "are the units mm, read as cm?").
    // (All of them there: no data at all, said by the span itself.)
    let n = frames.len() / MARKER_FRAME_LEN;
    let zeroed: Vec<usize> = (0..N_MARKERS)
        .filter(|&m| {
            let at_origin = frames.chunks_exact(MARKER_FRAME_LEN).filter(|f| f[3 * m..3 * m + 3] == [0.0; 3]).count();
            2 * at_origin > n
        })
        .collect();
    if let Some(&m) = zeroed.first().filter(|_| zeroed.len() + 2 <= N_MARKERS) {
        return Err(crate::Error::ImplausibleMarkers {
            frame: first,
            detail: format!(
                "marker {} sits at exactly (0, 0, 0) in most frames: a missing marker exported as zeros? ikid \
                 reads a missing marker as an empty cell or NaN; export gaps as such (or relabel the marker)",
                MARKERS[m].name
            ),
        });
    }
    Err(crate::Error::ImplausibleMarkers {
        frame: first,
        detail: format!("{} (the median over the recording)", span_problem(median)),
    })
}

fn span_problem(span: f64) -> String {
    let (lo, hi) = MARKER_SPAN_M;
    let hint = if span > hi {
        let ratio = span / 0.3;
        if ratio > 300.0 {
            "are the units mm, read as metres?"
        } else if ratio > 3.0 {
            "are the units mm (or cm), read as cm (or metres)?"
        } else {
            "is a marker of another object (or a ghost) labelled as one of the arm's?"
        }
    } else {
        "are the units metres, read as mm?"
    };
    format!(
        "the markers spread over {span:.3} m, a forearm and hand over {:.0}–{:.0} cm: {hint}",
        lo * 100.0,
        hi * 100.0
    )
}

/// Inertial and geometric parameters of one segment, in its own frame (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentParams {
    /// Length along the long axis, m.
    pub length: f64,
    /// Mass, kg.
    pub mass: f64,
    /// Centre of mass in the segment frame, m.
    pub com: [f64; 3],
    /// Principal moments of inertia about the centre of mass, along the segment axes
    /// `(x, y, z)`, kg·m².
    pub inertia: [f64; 3],
}

/// The two links between the wrist's joints in the simulator and the reference dynamics:
/// tiny but not zero (a rigid-body engine gives a massless dynamic body infinite mass).
/// Their effect on the torques is below 1e-7 N·m.
pub const VIRTUAL_LINK: SegmentParams = SegmentParams { length: 0.0, mass: 1e-6, com: [0.0; 3], inertia: [1e-10; 3] };

/// A subject: segment parameters and marker placement.
///
/// [`BodyModel::default`] is an adult male from de Leva (1996), "Adjustments to
/// Zatsiorsky-Seluyanov's segment inertia parameters", J. Biomech. 29(9), Table 4
/// (body mass 73 kg): forearm 1.62 % of body mass, length 0.2689 m, centre of mass 45.74 %
/// from the elbow, radii of gyration 27.6 / 26.5 / 12.1 % (sagittal / transverse /
/// longitudinal); hand 0.61 %, 0.0862 m (wrist centre to 3rd metacarpal head), centre of
/// mass 79.0 % from the wrist, radii of gyration 62.8 / 51.3 / 40.1 %; upper arm 0.2817 m.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyModel {
    /// Upper arm length (shoulder to elbow), m: places the forearm in the lab.
    pub upper_arm_length: f64,
    /// Forearm parameters (frame at the wrist joint centre, y proximal).
    pub forearm: SegmentParams,
    /// Hand parameters (frame at the wrist joint centre, −y distal).
    pub hand: SegmentParams,
    /// Marker positions in their segment's frame, in [`MARKERS`] order, m.
    pub marker_offsets: [[f64; 3]; N_MARKERS],
    /// Shoulder centre in the lab, m.
    pub shoulder: [f64; 3],
}

/// Body mass of the default subject, kg.
pub const DEFAULT_BODY_MASS: f64 = 73.0;

impl Default for BodyModel {
    fn default() -> Self {
        let m = DEFAULT_BODY_MASS;
        let forearm_len = 0.2689;
        let forearm_mass = 0.0162 * m;
        // Forearm centre of mass lies 45.74 % of the length from the elbow, i.e. proximal of
        // the wrist by (1 - 0.4574) L.
        let forearm_com_from_wrist = (1.0 - 0.4574) * forearm_len;
        let hand_len = 0.0862;
        let hand_mass = 0.0061 * m;
        let gyr = |mass: f64, len: f64, sag: f64, trans: f64, long: f64| {
            // Segment x is volar (antero-posterior: rotation about it is frontal-plane, i.e.
            // the "transverse" radius in de Leva's naming), z is radial (sagittal-plane
            // rotation), y is the long axis.
            [mass * (trans * len).powi(2), mass * (long * len).powi(2), mass * (sag * len).powi(2)]
        };
        BodyModel {
            upper_arm_length: 0.2817,
            forearm: SegmentParams {
                length: forearm_len,
                mass: forearm_mass,
                com: [0.0, forearm_com_from_wrist, 0.0],
                inertia: gyr(forearm_mass, forearm_len, 0.276, 0.265, 0.121),
            },
            hand: SegmentParams {
                length: hand_len,
                mass: hand_mass,
                com: [0.0, -0.790 * hand_len, 0.0],
                inertia: gyr(hand_mass, hand_len, 0.628, 0.513, 0.401),
            },
            marker_offsets: MARKERS.map(|mk| mk.offset),
            shoulder: [0.0, 1.40, 0.20],
        }
    }
}

impl BodyModel {
    /// [`scaled`](Self::scaled) with the factors checked (positive and finite).
    pub fn try_scaled(length_factor: f64, mass_factor: f64) -> crate::Result<Self> {
        for (what, v, (lo, hi)) in
            [("length_scale", length_factor, LENGTH_SCALE_RANGE), ("mass_scale", mass_factor, MASS_SCALE_RANGE)]
        {
            if !(lo..=hi).contains(&v) {
                return Err(crate::Error::BadArgument {
                    what,
                    detail: format!("is {v}, expected a factor from {lo} to {hi} (of the default subject's)"),
                });
            }
        }
        Ok(Self::scaled(length_factor, mass_factor))
    }

    /// A subject scaled from the default: lengths and marker offsets by `length_factor`,
    /// masses by `mass_factor`, inertias by `mass_factor · length_factor²`.
    pub fn scaled(length_factor: f64, mass_factor: f64) -> Self {
        let base = Self::default();
        let scale_seg = |s: SegmentParams| SegmentParams {
            length: s.length * length_factor,
            mass: s.mass * mass_factor,
            com: s.com.map(|c| c * length_factor),
            inertia: s.inertia.map(|i| i * mass_factor * length_factor * length_factor),
        };
        BodyModel {
            upper_arm_length: base.upper_arm_length * length_factor,
            forearm: scale_seg(base.forearm),
            hand: scale_seg(base.hand),
            marker_offsets: base.marker_offsets.map(|o| o.map(|c| c * length_factor)),
            shoulder: base.shoulder,
        }
    }

    /// Pose of the forearm frame in the lab for a shoulder flexion angle (radians, positive
    /// raises the arm forward), with the elbow extended and the forearm mid-prone.
    pub fn forearm_pose(&self, shoulder_flexion: f64) -> Isometry3<f64> {
        // Forearm axes in the lab at zero flexion: x = -Z, y = +Y, z = +X.
        let neutral = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
            0.0, 0.0, 1.0, //
            0.0, 1.0, 0.0, //
            -1.0, 0.0, 0.0,
        ));
        let flexion = Rotation3::from_axis_angle(&Vector3::z_axis(), shoulder_flexion);
        let arm_length = self.upper_arm_length + self.forearm.length;
        let wrist = Vector3::from(self.shoulder) + flexion * Vector3::new(0.0, -arm_length, 0.0);
        Isometry3::from_parts(Translation3::from(wrist), UnitQuaternion::from_rotation_matrix(&(flexion * neutral)))
    }

    /// Marker positions in the lab for wrist angles `q` and a forearm pose, as one frame of
    /// [`MARKER_FRAME_LEN`] values in [`MARKERS`] order.
    pub fn marker_frame(&self, q: &[f64; 3], forearm_pose: &Isometry3<f64>) -> [f64; MARKER_FRAME_LEN] {
        let hand_pose = forearm_pose
            * Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_rotation_matrix(&wrist_rotation(q)));
        let mut frame = [0.0; MARKER_FRAME_LEN];
        for (i, marker) in MARKERS.iter().enumerate() {
            let pose = match marker.segment {
                Segment::Forearm => forearm_pose,
                Segment::Hand => &hand_pose,
            };
            let p = pose * Point3::from(self.marker_offsets[i]);
            frame[3 * i..3 * i + 3].copy_from_slice(p.coords.as_slice());
        }
        frame
    }
}

impl BodyModel {
    /// A subject: the default one scaled by `length_scale` and `mass_scale` (checked, see
    /// [`try_scaled`](Self::try_scaled)), each marker then moved by `marker_shift` when given
    /// (see [`shift_markers`](Self::shift_markers)). What every binding builds a subject with.
    pub fn subject(length_scale: f64, mass_scale: f64, marker_shift: Option<&[f64]>) -> crate::Result<Self> {
        let mut body = Self::try_scaled(length_scale, mass_scale)?;
        if let Some(shift) = marker_shift {
            body.shift_markers(shift)?;
        }
        Ok(body)
    }

    /// Moves each marker by `shift`: [`N_MARKERS`] rows of `x, y, z` (metres, in the marker's
    /// segment's frame, [`MARKERS`] order) added to its offset, for a lab whose placement differs
    /// from the model's. Refused, changing nothing, unless it is 18 finite values.
    pub fn shift_markers(&mut self, shift: &[f64]) -> crate::Result<()> {
        use crate::Error;
        if shift.len() != MARKER_FRAME_LEN {
            return Err(Error::BadArgument {
                what: "marker_shift",
                detail: format!("expected {N_MARKERS} finite rows of 3 (metres), got {} values", shift.len()),
            });
        }
        if let Some(i) = shift.iter().position(|v| !v.is_finite()) {
            return Err(Error::BadArgument {
                what: "marker_shift",
                detail: format!(
                    "{}.{} is {}, expected a finite shift in metres",
                    MARKERS[i / 3].name,
                    ["x", "y", "z"][i % 3],
                    shift[i]
                ),
            });
        }
        for (offset, s) in self.marker_offsets.iter_mut().zip(shift.chunks_exact(3)) {
            for (o, d) in offset.iter_mut().zip(s) {
                *o += d;
            }
        }
        Ok(())
    }

    /// Marker frames for a whole trajectory: `q` holds `n` angle triples back to back
    /// (radians), the result `n` frames of [`MARKER_FRAME_LEN`] values (metres, lab frame).
    pub fn marker_frames(&self, q: &[f64], shoulder_flexion: f64) -> crate::Result<Vec<f64>> {
        use crate::Error;
        if !q.len().is_multiple_of(N_COORDINATES) {
            return Err(Error::BadArgument {
                what: "q",
                detail: format!("{} values is not a whole number of angle triples", q.len()),
            });
        }
        if let Some(i) = q.iter().position(|v| !v.is_finite()) {
            let name = COORDINATES[i % N_COORDINATES].name;
            return Err(Error::BadArgument {
                what: "q",
                detail: format!("row {}: {name} is {}", i / N_COORDINATES, q[i]),
            });
        }
        // Every posture has angles within ±π: beyond is a unit mistake (degrees), not a wrist.
        if let Some(i) = q.iter().position(|v| v.abs() > std::f64::consts::PI + 1e-9) {
            let name = COORDINATES[i % N_COORDINATES].name;
            return Err(Error::BadArgument {
                what: "q",
                detail: format!(
                    "row {}: {name} is {} rad ({:.0}°), beyond ±π: the angles are radians (degrees given?)",
                    i / N_COORDINATES,
                    q[i],
                    q[i].to_degrees()
                ),
            });
        }
        if !shoulder_flexion.is_finite() {
            return Err(Error::BadArgument { what: "shoulder_flexion", detail: format!("is {shoulder_flexion}") });
        }
        let pose = self.forearm_pose(shoulder_flexion);
        Ok(q.chunks_exact(N_COORDINATES).flat_map(|c| self.marker_frame(&[c[0], c[1], c[2]], &pose)).collect())
    }
}

/// Unit rotation axis of coordinate `i`.
fn axis(i: usize) -> Unit<Vector3<f64>> {
    Unit::new_unchecked(Vector3::from(COORDINATES[i].axis))
}

/// Orientation of the hand in the forearm frame for wrist angles `q` (radians).
pub fn wrist_rotation(q: &[f64; 3]) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&axis(0), q[0])
        * Rotation3::from_axis_angle(&axis(1), q[1])
        * Rotation3::from_axis_angle(&axis(2), q[2])
}

/// Wrist angles `(s_p, e_f, ad_ab)` of a hand orientation in the forearm frame: the inverse
/// of [`wrist_rotation`] for `|e_f| < 90°` (the middle angle is the one that can gimbal-lock).
///
/// Works for any mutually orthogonal axis triple: with `a3 = s (a1 × a2)`, `s = ±1`,
/// `q2 = asin(s a1ᵀRa3)`, `q1 = atan2(−s a2ᵀRa3, a3ᵀRa3)`, `q3 = atan2(−s a1ᵀRa2, a1ᵀRa1)`.
pub fn wrist_angles(r: &Rotation3<f64>) -> [f64; 3] {
    let (a1, a2, a3) = (axis(0).into_inner(), axis(1).into_inner(), axis(2).into_inner());
    let s = a1.cross(&a2).dot(&a3).signum();
    let m = r.matrix();
    let ra3 = m * a3;
    let ra2 = m * a2;
    let ra1 = m * a1;
    let q2 = (s * a1.dot(&ra3)).clamp(-1.0, 1.0).asin();
    let q1 = (-s * a2.dot(&ra3)).atan2(a3.dot(&ra3));
    let q3 = (-s * a1.dot(&ra2)).atan2(a1.dot(&ra1));
    [q1, q2, q3]
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_one_marker_hand_reads_flexion_and_deviation_exactly_and_no_roll() {
        // Oracle: an arm whose forearm's anatomical frame is `arm` (lab) with the origin at
        // `at`, its hand posed by Rot(z, e)·Rot(x, a) in it: the forearm's markers sit at
        // arm·offset, the hand's at arm·pose·offset; the function sees the styloids, a point on
        // the long axis and one hand marker straight distal, nothing of the rest.
        let arm = Rotation3::from_euler_angles(0.3, -0.5, 1.1);
        let at = Vector3::new(0.2, 1.0, -0.4);
        for &(e, a) in &[(0.4, 0.2), (-0.6, -0.3), (0.1, 0.35), (0.0, 0.0)] {
            let lab = |p: Vector3<f64>| at + arm * p;
            // Styloids off the perpendicular (a real wrist bar), their midpoint the origin.
            let (rsp, usp) = (lab(Vector3::new(0.0, 0.004, 0.03)), lab(Vector3::new(0.0, -0.004, -0.03)));
            let fap = lab(Vector3::new(0.0, 0.25, 0.0));
            let pose =
                Rotation3::from_axis_angle(&Vector3::z_axis(), e) * Rotation3::from_axis_angle(&Vector3::x_axis(), a);
            let hnd = lab(pose * Vector3::new(0.0, -0.08, 0.0));
            let frame: Vec<f64> = [rsp, usp, fap, hnd].iter().flat_map(|p| [p.x, p.y, p.z]).collect();
            let six = hand_from_one_marker(&frame, false).unwrap();
            for (k, m) in MARKERS.iter().enumerate() {
                let local = Vector3::from(m.offset);
                let want = if k < 3 { lab(local) } else { lab(pose * local) };
                for c in 0..3 {
                    assert!((six[3 * k + c] - want[c]).abs() < 1e-12, "{e} {a} marker {k}");
                }
            }
            // The hand's landmarks it stands for give, by the calibration's rule for a hand's own
            // frame (y from the mid-heads to the mid-styloids, x = y × (fifth → second head)), the
            // hand's axes.
            let lm = one_marker_hand_landmarks(&frame).unwrap();
            let (second, fifth) = (Vector3::new(lm[0], lm[1], lm[2]), Vector3::new(lm[3], lm[4], lm[5]));
            let y = ((rsp + usp) / 2.0 - (second + fifth) / 2.0).normalize();
            let x = y.cross(&(second - fifth)).normalize();
            assert!((y - arm * pose * Vector3::y()).norm() < 1e-12);
            assert!((x - arm * pose * Vector3::x()).norm() < 1e-12);
            // A left arm: mirrored (z negated) and built with `left`, then mirrored back, the same.
            let mirrored: Vec<f64> = frame.iter().enumerate().map(|(i, v)| if i % 3 == 2 { -v } else { *v }).collect();
            let left = hand_from_one_marker(&mirrored, true).unwrap();
            for (i, (l, r)) in left.iter().zip(&six).enumerate() {
                assert!((if i % 3 == 2 { -l } else { *l } - r).abs() < 1e-12);
            }
        }
        // No direction: the hand marker on the wrist, missing, or along the styloid line: the
        // hand's markers NaN, the forearm's kept; FAP missing: neither.
        let base = [0.0, 0.0, 0.03, 0.0, 0.0, -0.03, 0.0, 0.2, 0.0];
        for hnd in [[0.0, -0.01, 0.0], [f64::NAN, 0.0, 0.0], [0.0, 0.0, 0.09]] {
            let frame: Vec<f64> = base.iter().chain(&hnd).copied().collect();
            let six = hand_from_one_marker(&frame, false).unwrap();
            assert!(six[9..].iter().all(|v| v.is_nan()) && six[..9].iter().all(|v| v.is_finite()));
        }
        let mut no_fap: Vec<f64> = base.iter().chain(&[0.0, -0.08, 0.0]).copied().collect();
        no_fap[6] = f64::NAN;
        assert!(hand_from_one_marker(&no_fap, false).unwrap().iter().all(|v| v.is_nan()));
        assert!(hand_from_one_marker(&[0.0; 13], false).is_err());
        assert!(one_marker_hand_landmarks(&[0.0; 13]).is_err());
    }

    use super::*;
    use proptest::prelude::*;

    fn in_range(i: usize) -> std::ops::Range<f64> {
        let (lo, hi) = COORDINATES[i].range;
        lo..hi
    }

    proptest! {
        #[test]
        fn wrist_angles_inverts_wrist_rotation(q0 in in_range(0), q1 in in_range(1), q2 in in_range(2)) {
            let q = [q0, q1, q2];
            let back = wrist_angles(&wrist_rotation(&q));
            for i in 0..3 {
                prop_assert!((back[i] - q[i]).abs() < 1e-12, "{q:?} -> {back:?}");
            }
        }
    }

    #[test]
    fn positive_angles_move_the_hand_as_named() {
        // The hand's distal direction is forearm -y; its palm normal is +x.
        let distal = Vector3::new(0.0, -1.0, 0.0);
        let palm = Vector3::new(1.0, 0.0, 0.0);
        // Flexion moves the distal hand volar (+x).
        assert!((wrist_rotation(&[0.0, 0.3, 0.0]) * distal).x > 0.2);
        // Adduction (ulnar deviation) moves it ulnar (-z).
        assert!((wrist_rotation(&[0.0, 0.0, 0.3]) * distal).z < -0.2);
        // Supination turns the palm normal radially (+z) from mid-prone.
        assert!((wrist_rotation(&[0.3, 0.0, 0.0]) * palm).z > 0.2);
    }

    #[test]
    fn forearm_pose_matches_documented_axes() {
        let body = BodyModel::default();
        let pose = body.forearm_pose(0.0);
        let r = pose.rotation.to_rotation_matrix();
        assert!((r * Vector3::x() - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        assert!((r * Vector3::y() - Vector3::y()).norm() < 1e-12);
        // Forward flexion of 90° points the arm forward (+X).
        let raised = body.forearm_pose(std::f64::consts::FRAC_PI_2);
        assert!(raised.translation.vector.x > 0.5);
    }

    #[test]
    fn subject_moves_each_marker_by_its_shift() {
        let mut shift = [0.0; MARKER_FRAME_LEN];
        shift[3 * 4..3 * 4 + 3].copy_from_slice(&[0.004, -0.01, 0.006]);
        let body = BodyModel::subject(1.1, 1.2, Some(&shift)).unwrap();
        let plain = BodyModel::scaled(1.1, 1.2);
        for m in 0..N_MARKERS {
            for k in 0..3 {
                let moved = body.marker_offsets[m][k] - plain.marker_offsets[m][k];
                assert!((moved - shift[3 * m + k]).abs() < 1e-15, "marker {m} axis {k}");
            }
        }
        assert_eq!(BodyModel::subject(1.1, 1.2, None).unwrap(), plain);
        let short = BodyModel::subject(1.0, 1.0, Some(&shift[..15])).unwrap_err();
        assert!(short.to_string().starts_with("marker_shift: expected 6 finite rows"), "{short}");
        shift[7] = f64::NAN;
        let nan = BodyModel::subject(1.0, 1.0, Some(&shift)).unwrap_err();
        assert_eq!(nan.to_string(), "marker_shift: FAP.y is NaN, expected a finite shift in metres");
        assert!(BodyModel::subject(0.0, 1.0, None).is_err());
    }

    #[test]
    fn coordinates_are_found_by_name() {
        assert_eq!(coordinate_index("ra_wr_e_f").unwrap(), 1);
        let e = coordinate_index("elbow").unwrap_err();
        assert_eq!(e.kind(), crate::ErrorKind::Argument);
        assert!(e.to_string().contains("unknown coordinate \"elbow\" (known: ra_wr_s_p, ra_wr_e_f"), "{e}");
    }

    #[test]
    fn missing_marker_mask_and_names() {
        let mut frame = [0.1f32; MARKER_FRAME_LEN];
        assert_eq!(missing_markers(&frame), 0);
        frame[4] = f32::NAN; // USP.y
        frame[15] = f32::INFINITY; // MCB.x
        assert_eq!(missing_markers(&frame), 0b10_0010);
        let wide: [f64; MARKER_FRAME_LEN] = frame.map(f64::from);
        assert_eq!(missing_markers(&wide), 0b10_0010);
        assert_eq!(marker_names(0b10_0010).collect::<Vec<_>>(), ["USP", "MCB"]);
        assert_eq!(marker_names(0).count(), 0);
    }

    #[test]
    fn scaled_subject_scales_lengths_and_masses() {
        let base = BodyModel::default();
        let big = BodyModel::scaled(1.2, 1.1);
        assert!((big.hand.length - 1.2 * base.hand.length).abs() < 1e-15);
        assert!((big.hand.mass - 1.1 * base.hand.mass).abs() < 1e-15);
        assert!((big.marker_offsets[3][1] - 1.2 * base.marker_offsets[3][1]).abs() < 1e-15);
    }

    #[test]
    fn marker_frames_take_angles_within_a_half_turn_and_name_the_first_beyond_it() {
        let body = super::BodyModel::default();
        let pi = std::f64::consts::PI;
        // Every posture has angles within ±π: the bounds themselves are postures.
        assert!(body.marker_frames(&[pi, 0.0, -pi, 0.0, pi / 2.0, 0.0], 0.0).is_ok());
        // Degrees given as radians: refused, naming the row, the coordinate and both units.
        for (q, row, name, shown) in [
            (vec![0.0, 0.0, 0.0, 0.1, 0.2, 10.0], 1, "ra_wr_ad_ab", "10 rad (573°)"),
            (vec![-4.0, 20.0, 0.0], 0, "ra_wr_s_p", "-4 rad (-229°)"),
            (vec![0.0, 0.0, 0.0, 0.0, pi + 1e-6, 0.0], 1, "ra_wr_e_f", "rad (180°)"),
        ] {
            let err = body.marker_frames(&q, 0.0).unwrap_err().to_string();
            assert!(err.contains(&format!("row {row}: {name} is")) && err.contains(shown), "{err}");
            assert!(err.contains("degrees given?"), "{err}");
        }
        // A non-finite value is named the same way (its coordinate, its row).
        let err = body.marker_frames(&[0.0, 0.0, 0.0, 0.0, 0.0, f64::NAN], 0.0).unwrap_err().to_string();
        assert!(err.contains("row 1: ra_wr_ad_ab is NaN"), "{err}");
    }
}
