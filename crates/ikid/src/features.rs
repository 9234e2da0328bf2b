//! Frames in, network inputs out: the feature sets a model can be trained on.
//!
//! Training (through `ikid._native`) and inference both call [`FeatureSet::compute`], so the
//! two can never disagree. A *frame* is one time step of raw input (a marker frame of
//! [`MARKER_FRAME_LEN`] values, or a joint state); its *features* are what the network sees
//! for that time step. Arithmetic is f64 inside, f32 at the edges.

use crate::body::{self, COORDINATES, MARKER_FRAME_LEN, MARKERS, N_COORDINATES, Segment};
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Rotation3, Vector3};
use std::sync::OnceLock;

/// A named way of turning one frame into network inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum FeatureSet {
    /// The thesis' raw markers: 6 markers × xyz in the lab frame (18 per frame).
    Markers,
    /// The thesis' segment bases: per segment (forearm, hand) the technical frame's origin
    /// and its three unit vectors in the lab frame (24 per frame).
    Basis,
    /// The hand's technical frame expressed in the forearm's: rotation (9, row-major) and
    /// origin (3). Unchanged by any rigid motion of the whole arm, so a model trained on it
    /// does not depend on the shoulder pose (12 per frame).
    Relative,
    /// [`Relative`](Self::Relative) plus the lab's up direction in the forearm's technical
    /// frame (3): what gravity does to the wrist, for networks that give torques (15 per frame).
    RelativeGravity,
    /// The wrist angles of this frame alone (3): the hand's technical frame in the
    /// forearm's, turned into the anatomical frames by the body model's marker placement
    /// (a constant rotation per segment, the same for every subject size) and decomposed as
    /// the joint chain does. Exact on clean markers; a window of them lets a network filter.
    Angles,
    /// [`Angles`](Self::Angles) plus the lab's up direction in the forearm's technical frame
    /// (3): a joint state's worth of information for torque networks (6 per frame).
    AnglesGravity,
    /// Joint state for inverse dynamics: q, q̇, q̈ in coordinate order (9 per frame).
    JointState,
    /// A [`Tracker`](crate::Tracker)'s estimate and how noisy its markers are: frames hold q,
    /// q̇, q̈ in coordinate order and log10 of the mean hand-marker noise it learned (in
    /// metres); the features drop q (7 per frame), so a refiner learns from how the wrist
    /// moves, not where it is (a window of q̇ carries the relative angles).
    TrackerState,
}

/// What one raw input frame of a feature set holds: the one answer to "does this model read
/// markers?" for every caller (file readers, CLI, training, benches).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FrameKind {
    /// A marker frame: six markers × xyz, metres ([`MARKER_FRAME_LEN`] values).
    Markers,
    /// A joint state: q, q̇, q̈ in coordinate order.
    JointState,
    /// A [`Tracker`](crate::Tracker)'s state and its marker noise (a refiner's input).
    TrackerState,
}

impl FrameKind {
    /// The kind's name (`"markers"`, `"joint_state"`, `"tracker_state"`).
    pub fn name(self) -> &'static str {
        match self {
            FrameKind::Markers => "markers",
            FrameKind::JointState => "joint_state",
            FrameKind::TrackerState => "tracker_state",
        }
    }
}

/// Every feature set, in the order they are listed to users.
pub const FEATURE_SETS: [FeatureSet; 8] = [
    FeatureSet::Markers,
    FeatureSet::Basis,
    FeatureSet::Relative,
    FeatureSet::RelativeGravity,
    FeatureSet::Angles,
    FeatureSet::AnglesGravity,
    FeatureSet::JointState,
    FeatureSet::TrackerState,
];

impl FeatureSet {
    /// Name used in model cards and by the Python API.
    pub fn name(self) -> &'static str {
        match self {
            FeatureSet::Markers => "markers",
            FeatureSet::Basis => "basis",
            FeatureSet::Relative => "relative",
            FeatureSet::RelativeGravity => "relative_gravity",
            FeatureSet::Angles => "angles",
            FeatureSet::AnglesGravity => "angles_gravity",
            FeatureSet::JointState => "joint_state",
            FeatureSet::TrackerState => "tracker_state",
        }
    }

    /// Looks a feature set up by [`name`](Self::name).
    pub fn from_name(name: &str) -> Result<Self> {
        FEATURE_SETS.into_iter().find(|f| f.name() == name).ok_or_else(|| Error::UnknownFeatureSet {
            name: name.to_owned(),
            known: FEATURE_SETS.map(|f| f.name()).join(", "),
        })
    }

    /// Whether the first [`N_COORDINATES`] features of a frame are the wrist's angles (rad,
    /// coordinate order): the per-frame angles of [`Angles`](Self::Angles) and
    /// [`AnglesGravity`](Self::AnglesGravity), a [`JointState`](Self::JointState)'s q. What
    /// the σ's noise term and the turned-over check read.
    pub fn leads_with_angles(self) -> bool {
        matches!(self, FeatureSet::Angles | FeatureSet::AnglesGravity | FeatureSet::JointState)
    }

    /// What one raw input frame holds.
    pub fn frame_kind(self) -> FrameKind {
        match self {
            FeatureSet::Markers
            | FeatureSet::Basis
            | FeatureSet::Relative
            | FeatureSet::RelativeGravity
            | FeatureSet::Angles
            | FeatureSet::AnglesGravity => FrameKind::Markers,
            FeatureSet::JointState => FrameKind::JointState,
            FeatureSet::TrackerState => FrameKind::TrackerState,
        }
    }

    /// Values in one raw input frame.
    pub fn frame_len(self) -> usize {
        match self.frame_kind() {
            FrameKind::Markers => MARKER_FRAME_LEN,
            FrameKind::JointState => 3 * N_COORDINATES,
            FrameKind::TrackerState => 3 * N_COORDINATES + 1,
        }
    }

    /// Values in one frame's features.
    pub fn feature_len(self) -> usize {
        match self {
            FeatureSet::Markers => MARKER_FRAME_LEN,
            FeatureSet::Basis => 24,
            FeatureSet::Relative => 12,
            FeatureSet::RelativeGravity => 15,
            FeatureSet::Angles => N_COORDINATES,
            FeatureSet::AnglesGravity => N_COORDINATES + 3,
            FeatureSet::JointState => 3 * N_COORDINATES,
            FeatureSet::TrackerState => 2 * N_COORDINATES + 1,
        }
    }

    /// Names of the values of one raw input frame, e.g. `"MC2.y"` or `"qd.ra_wr_e_f"`.
    pub fn frame_names(self) -> Vec<String> {
        match self {
            FeatureSet::JointState => joint_state_names(),
            FeatureSet::TrackerState => joint_state_names().into_iter().chain(["noise.log10_m".to_owned()]).collect(),
            _ => MARKERS.iter().flat_map(|m| xyz(m.name)).collect(),
        }
    }

    /// Names of one frame's features, in order.
    pub fn feature_names(self) -> Vec<String> {
        match self {
            FeatureSet::Markers | FeatureSet::JointState => self.frame_names(),
            FeatureSet::TrackerState => self.frame_names().split_off(N_COORDINATES),
            FeatureSet::Basis => [Segment::Forearm, Segment::Hand]
                .iter()
                .flat_map(|s| ["origin", "e1", "e2", "e3"].map(move |v| format!("{}.{v}", s.name())))
                .flat_map(|prefix| xyz(&prefix))
                .collect(),
            FeatureSet::Relative => {
                (0..3).flat_map(|r| (0..3).map(move |c| format!("rel.r{r}{c}"))).chain(xyz("rel.t")).collect()
            }
            FeatureSet::RelativeGravity => FeatureSet::Relative.feature_names().into_iter().chain(xyz("up")).collect(),
            FeatureSet::Angles => COORDINATES.iter().map(|c| format!("angle.{}", c.name)).collect(),
            FeatureSet::AnglesGravity => FeatureSet::Angles.feature_names().into_iter().chain(xyz("up")).collect(),
        }
    }

    /// Refuses a frame of the wrong length or holding a non-finite value (a missing marker
    /// is NaN), naming it; what [`compute`](Self::compute) checks first.
    pub fn check_frame(self, frame: &[f32], frame_index: usize) -> Result<()> {
        if frame.len() != self.frame_len() {
            return Err(Error::FrameLength {
                feature_set: self.name(),
                found: frame.len(),
                expected: self.frame_len(),
            });
        }
        if let Some(i) = frame.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFiniteInput {
                frame: frame_index,
                field: self.frame_names()[i].clone(),
                value: frame[i],
            });
        }
        Ok(())
    }

    /// Computes one frame's features into `out` (length [`feature_len`](Self::feature_len)).
    ///
    /// Refuses frames of the wrong length, non-finite values (a missing marker is NaN) and
    /// degenerate marker triangles. `frame_index` only labels errors. Does not allocate on
    /// success.
    pub fn compute(self, frame: &[f32], out: &mut [f32], frame_index: usize) -> Result<()> {
        self.check_frame(frame, frame_index)?;
        if out.len() != self.feature_len() {
            return Err(Error::BadArgument {
                what: "feature buffer",
                detail: format!("has {} values, expected {}", out.len(), self.feature_len()),
            });
        }
        match self {
            FeatureSet::Markers | FeatureSet::JointState => out.copy_from_slice(frame),
            FeatureSet::TrackerState => out.copy_from_slice(&frame[N_COORDINATES..]),
            FeatureSet::Basis => {
                for (k, segment) in [Segment::Forearm, Segment::Hand].into_iter().enumerate() {
                    let (origin, axes) = technical_frame(frame, segment, frame_index)?;
                    let dst = &mut out[12 * k..12 * k + 12];
                    write3(&mut dst[0..3], &origin);
                    for c in 0..3 {
                        write3(&mut dst[3 + 3 * c..6 + 3 * c], &axes.column(c).into_owned());
                    }
                }
            }
            FeatureSet::Relative | FeatureSet::RelativeGravity => {
                let (o_f, b_f) = technical_frame(frame, Segment::Forearm, frame_index)?;
                let (o_h, b_h) = technical_frame(frame, Segment::Hand, frame_index)?;
                let rel = b_f.transpose() * b_h;
                let t = b_f.transpose() * (o_h - o_f);
                for r in 0..3 {
                    for c in 0..3 {
                        out[3 * r + c] = rel[(r, c)] as f32;
                    }
                }
                write3(&mut out[9..12], &t);
                if self == FeatureSet::RelativeGravity {
                    write3(&mut out[12..15], &(b_f.transpose() * up()));
                }
            }
            FeatureSet::Angles | FeatureSet::AnglesGravity => {
                let (_, b_f) = technical_frame(frame, Segment::Forearm, frame_index)?;
                let (_, b_h) = technical_frame(frame, Segment::Hand, frame_index)?;
                let (t_f, t_h) = technical_in_anatomical();
                let wrist = Rotation3::from_matrix_unchecked(t_f * b_f.transpose() * b_h * t_h.transpose());
                for (o, a) in out.iter_mut().zip(body::wrist_angles(&wrist)) {
                    *o = a as f32;
                }
                if self == FeatureSet::AnglesGravity {
                    write3(&mut out[3..6], &(b_f.transpose() * up()));
                }
            }
        }
        Ok(())
    }

    /// Computes the features of many frames: `frames` holds whole frames back to back, `out`
    /// receives whole feature rows. Errors name the frame at fault.
    pub fn compute_rows(self, frames: &[f32], out: &mut [f32]) -> Result<()> {
        let (fl, nf) = (self.frame_len(), self.feature_len());
        if !frames.len().is_multiple_of(fl) {
            return Err(Error::BadArgument {
                what: "frames",
                detail: format!("{} values is not a whole number of {fl}-value frames", frames.len()),
            });
        }
        let n = frames.len() / fl;
        if out.len() != n * nf {
            return Err(Error::BadArgument {
                what: "feature output",
                detail: format!("has {} values, expected {n} rows × {nf} = {}", out.len(), n * nf),
            });
        }
        for (i, (frame, row)) in frames.chunks_exact(fl).zip(out.chunks_exact_mut(nf)).enumerate() {
            self.compute(frame, row, i)?;
        }
        Ok(())
    }
}

/// Technical frame of a segment from its three markers `m0, m1, m2`: origin at their
/// centroid, `e1` along `m0→m1`, `e3` normal to the marker plane, `e2 = e3 × e1`.
/// Returns the origin and the rotation whose columns are `e1, e2, e3` (lab frame).
pub fn technical_frame(frame: &[f32], segment: Segment, frame_index: usize) -> Result<(Vector3<f64>, Matrix3<f64>)> {
    let first = body::first_marker(segment);
    let m = |k: usize| {
        let i = 3 * (first + k);
        Vector3::new(frame[i] as f64, frame[i + 1] as f64, frame[i + 2] as f64)
    };
    let (m0, m1, m2) = (m(0), m(1), m(2));
    let origin = (m0 + m1 + m2) / 3.0;
    let degenerate = || Error::DegenerateSegment { frame: frame_index, segment: segment.name() };
    // Thresholds in metres (m²): markers closer than 0.1 mm or triangles this thin carry no
    // orientation worth fitting.
    let e1 = (m1 - m0).try_normalize(1e-4).ok_or_else(degenerate)?;
    let e3 = e1.cross(&(m2 - m0)).try_normalize(1e-8).ok_or_else(degenerate)?;
    let e2 = e3.cross(&e1);
    Ok((origin, Matrix3::from_columns(&[e1, e2, e3])))
}

/// Each segment's technical frame expressed in its anatomical frame, from the default body
/// at neutral (`B = A·T`). Marker placement scales with the subject, so `T` does not.
pub(crate) fn technical_in_anatomical() -> &'static (Matrix3<f64>, Matrix3<f64>) {
    static FRAMES: OnceLock<(Matrix3<f64>, Matrix3<f64>)> = OnceLock::new();
    FRAMES.get_or_init(|| {
        let body = body::BodyModel::default();
        let pose = body.forearm_pose(0.0);
        // An array, not a Vec: the first push of a stream runs this and must not allocate.
        let frame = body.marker_frame(&[0.0; N_COORDINATES], &pose).map(|v| v as f32);
        let anatomical = pose.rotation.to_rotation_matrix().into_inner();
        let technical =
            |segment| technical_frame(&frame, segment, 0).expect("the body model's markers span each segment").1;
        (anatomical.transpose() * technical(Segment::Forearm), anatomical.transpose() * technical(Segment::Hand))
    })
}

/// The lab's up direction (against gravity).
fn up() -> Vector3<f64> {
    -Vector3::from(body::GRAVITY).normalize()
}

fn write3(dst: &mut [f32], v: &Vector3<f64>) {
    for (d, s) in dst.iter_mut().zip(v.iter()) {
        *d = *s as f32;
    }
}

fn xyz(prefix: &str) -> [String; 3] {
    ["x", "y", "z"].map(|a| format!("{prefix}.{a}"))
}

fn joint_state_names() -> Vec<String> {
    ["q", "qd", "qdd"]
        .iter()
        .flat_map(|kind| body::COORDINATES.iter().map(move |c| format!("{kind}.{}", c.name)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyModel;

    fn frame_for(q: [f64; 3], shoulder: f64) -> Vec<f32> {
        let body = BodyModel::default();
        body.marker_frame(&q, &body.forearm_pose(shoulder)).iter().map(|&v| v as f32).collect()
    }

    #[test]
    fn a_short_frame_is_named_by_what_the_caller_gives() {
        // Error::FrameLength names the frame kind (error.rs cannot see this module): a marker
        // frame for every set that reads markers, whatever features it computes.
        for set in FEATURE_SETS {
            let message = set.check_frame(&[0.0; 2], 0).unwrap_err().to_string();
            let want = match set.frame_kind() {
                FrameKind::Markers => "a marker frame",
                FrameKind::JointState => "a joint state",
                FrameKind::TrackerState => "a tracker state",
            };
            assert!(
                message.starts_with(&format!("frame has 2 values, expected {}: {want}", set.frame_len())),
                "{set:?}: {message}"
            );
        }
    }

    #[test]
    fn every_set_names_every_value() {
        let kinds = FEATURE_SETS.map(|f| f.frame_kind().name());
        assert_eq!(
            kinds,
            ["markers", "markers", "markers", "markers", "markers", "markers", "joint_state", "tracker_state"]
        );
        for set in FEATURE_SETS {
            assert_eq!(set.frame_names().len(), set.frame_len(), "{set:?}");
            assert_eq!(set.feature_names().len(), set.feature_len(), "{set:?}");
            assert_eq!(FeatureSet::from_name(set.name()).unwrap(), set);
        }
        assert!(matches!(FeatureSet::from_name("nope"), Err(Error::UnknownFeatureSet { .. })));
    }

    #[test]
    fn basis_of_known_triangle() {
        // Forearm markers on the lab axes; hand markers a shifted, rotated copy.
        let mut frame = vec![0.0f32; 18];
        frame[0..9].copy_from_slice(&[0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0, 0.0]);
        // Hand: m0=(1,1,1), m1 along +y, m2 along -x: e1=+y, e3=+y×-x=+z, e2=z×y=-x.
        frame[9..18].copy_from_slice(&[1.0, 1.0, 1.0, 1.0, 2.0, 1.0, 0.0, 1.0, 1.0]);
        let mut out = vec![0.0f32; 24];
        FeatureSet::Basis.compute(&frame, &mut out, 0).unwrap();
        let expect_forearm = [2.0 / 3.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let expect_hand = [2.0 / 3.0, 4.0 / 3.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        for (got, want) in out.iter().zip(expect_forearm.iter().chain(&expect_hand)) {
            assert!((got - want).abs() < 1e-6, "{out:?}");
        }
    }

    #[test]
    fn relative_is_independent_of_shoulder_pose() {
        let q = [0.4, -0.3, 0.2];
        let mut a = vec![0.0f32; 12];
        let mut b = vec![0.0f32; 12];
        FeatureSet::Relative.compute(&frame_for(q, 0.0), &mut a, 0).unwrap();
        FeatureSet::Relative.compute(&frame_for(q, 45f64.to_radians()), &mut b, 0).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 2e-5, "{a:?} vs {b:?}");
        }
        // ...but does change with the wrist angles.
        FeatureSet::Relative.compute(&frame_for([0.0, 0.0, 0.0], 0.0), &mut b, 0).unwrap();
        assert!(a.iter().zip(&b).any(|(x, y)| (x - y).abs() > 0.05));
    }

    #[test]
    fn relative_gravity_adds_the_up_direction_in_the_forearm_frame() {
        let q = [0.4, -0.3, 0.2];
        let features = |shoulder: f64| {
            let mut out = vec![0.0f32; 15];
            FeatureSet::RelativeGravity.compute(&frame_for(q, shoulder), &mut out, 0).unwrap();
            out
        };
        let (a, b) = (features(0.0), features(45f64.to_radians()));
        let mut rel = vec![0.0f32; 12];
        FeatureSet::Relative.compute(&frame_for(q, 0.0), &mut rel, 0).unwrap();
        assert_eq!(&a[..12], &rel[..]);
        let mut ag = [0.0f32; 6];
        FeatureSet::AnglesGravity.compute(&frame_for(q, 0.0), &mut ag, 0).unwrap();
        assert_eq!(&ag[3..], &a[12..]);
        let (up_a, up_b) = (Vector3::new(a[12], a[13], a[14]), Vector3::new(b[12], b[13], b[14]));
        assert!((up_a.norm() - 1.0).abs() < 1e-6 && (up_b.norm() - 1.0).abs() < 1e-6);
        // Shoulder flexion turns the forearm by 45° relative to gravity.
        let angle = up_a.cast::<f64>().angle(&up_b.cast::<f64>());
        assert!((angle - 45f64.to_radians()).abs() < 1e-5, "{angle}");
    }

    #[test]
    fn the_gravity_features_point_up_in_the_forearms_technical_frame() {
        // By hand: the forearm's technical frame from its markers (e1 along RSP→USP, e3
        // normal to the triangle, e2 = e3 × e1), and the lab's up, +y (gravity is −y), in it.
        for (q, shoulder) in [([0.4, -0.3, 0.2], 0.0), ([-0.9, 0.6, -0.2], 0.7), ([1.1, 0.1, 0.3], -0.3)] {
            let frame = frame_for(q, shoulder);
            let m = |k: usize| Vector3::new(frame[3 * k] as f64, frame[3 * k + 1] as f64, frame[3 * k + 2] as f64);
            let e1 = (m(1) - m(0)).normalize();
            let e3 = e1.cross(&(m(2) - m(0))).normalize();
            let e2 = e3.cross(&e1);
            let want = [e1.y, e2.y, e3.y];
            let mut rg = [0.0f32; 15];
            FeatureSet::RelativeGravity.compute(&frame, &mut rg, 0).unwrap();
            let mut ag = [0.0f32; 6];
            FeatureSet::AnglesGravity.compute(&frame, &mut ag, 0).unwrap();
            for k in 0..3 {
                assert!((rg[12 + k] as f64 - want[k]).abs() < 1e-6, "{rg:?} vs {want:?}");
                assert!((ag[3 + k] as f64 - want[k]).abs() < 1e-6, "{ag:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn angles_are_exact_on_clean_markers_for_any_size_and_pose() {
        for (q, shoulder, scale) in
            [([0.5, 0.2, -0.1], 0.3, 1.0), ([-1.2, 1.1, 0.4], -0.35, 0.85), ([1.3, -1.0, -0.3], 0.8, 1.2)]
        {
            let body = BodyModel::scaled(scale, 1.0);
            let frame: Vec<f32> =
                body.marker_frame(&q, &body.forearm_pose(shoulder)).iter().map(|&v| v as f32).collect();
            let mut out = [0.0f32; 3];
            FeatureSet::Angles.compute(&frame, &mut out, 0).unwrap();
            for k in 0..3 {
                // f32 marker coordinates limit it to ~1e-5 rad.
                assert!((out[k] as f64 - q[k]).abs() < 5e-5, "{out:?} vs {q:?} (scale {scale})");
            }
        }
    }

    #[test]
    fn relative_rotation_tracks_wrist_rotation() {
        // R_rel(q) = B_fᵀ B_h(q) and B_h(q) = R_forearm · R_wrist(q) · B_h(0) in the forearm
        // frame, so R_rel(q) · R_rel(0)ᵀ = T · R_wrist(q) · Tᵀ with T the forearm's technical
        // frame in its anatomical one: the same rotation angle as R_wrist(q).
        let q = [0.5, 0.2, -0.1];
        let rel = |q: [f64; 3]| {
            let mut out = vec![0.0f32; 12];
            FeatureSet::Relative.compute(&frame_for(q, 0.3), &mut out, 0).unwrap();
            Matrix3::from_row_iterator(out[..9].iter().map(|&v| v as f64))
        };
        let delta = rel(q) * rel([0.0; 3]).transpose();
        let angle = ((delta.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
        let want = body::wrist_rotation(&q).angle();
        assert!((angle - want).abs() < 1e-4, "{angle} vs {want}");
    }

    #[test]
    fn missing_marker_is_named() {
        let mut frame = frame_for([0.0; 3], 0.0);
        frame[10] = f32::NAN; // MC2.y
        let mut out = vec![0.0f32; 18];
        let err = FeatureSet::Markers.compute(&frame, &mut out, 7).unwrap_err();
        assert!(err.to_string().contains("MC2.y") && err.to_string().contains("frame 7"), "{err}");
    }

    #[test]
    fn a_missing_value_names_its_marker_and_nothing_else_does() {
        // `Error::markers` reads the marker from the value's name (`NAME.x|y|z`): every frame
        // value of every feature set, refused, names its marker, and only marker values do.
        for set in FEATURE_SETS {
            for (i, name) in set.frame_names().iter().enumerate() {
                let mut frame = match set.frame_kind() {
                    FrameKind::Markers => frame_for([0.1, -0.2, 0.05], 0.3),
                    _ => vec![0.1f32; set.frame_len()],
                };
                frame[i] = f32::NAN;
                let err = set.check_frame(&frame, 0).unwrap_err();
                let want: Vec<&str> = match set.frame_kind() {
                    FrameKind::Markers => vec![body::MARKERS[i / 3].name],
                    _ => vec![],
                };
                assert_eq!(err.markers(), want, "{} value {name}", set.name());
            }
        }
    }

    #[test]
    fn collinear_markers_are_refused() {
        let mut frame = frame_for([0.0; 3], 0.0);
        frame[9..18].copy_from_slice(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0]);
        let mut out = vec![0.0f32; 24];
        let err = FeatureSet::Basis.compute(&frame, &mut out, 0).unwrap_err();
        assert!(matches!(err, Error::DegenerateSegment { segment: "hand", .. }), "{err}");
    }

    #[test]
    fn wrong_frame_length_is_refused() {
        let mut out = vec![0.0f32; 18];
        let err = FeatureSet::Markers.compute(&[0.0; 17], &mut out, 0).unwrap_err();
        assert!(err.to_string().contains("17") && err.to_string().contains("18"), "{err}");
    }
}
