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
//! It is measured from a static trial in the neutral pose (all wrist angles zero) and at
//! least two movements of a single coordinate each (e.g. flexion–extension only, then
//! pronation–supination only), the clinical functional-axis protocol:
//! - static: the hand's technical frame in the forearm's, `S = B_fᵀB_h`, at neutral;
//! - each movement of coordinate `j`: the hand's rotation away from neutral, seen in the
//!   forearm's technical frame, turns about one fixed axis — coordinate `j`'s axis `a_j`
//!   expressed in technical coordinates, `t_j = T_fᵀ a_j` (principal axis of the rotation
//!   vectors, sign taken from the body model's placement);
//! - `T_f` is the rotation that best maps the measured `t_j` onto the model's `a_j`
//!   (orthogonal Procrustes, SVD), and `T_h = T_f S` makes the neutral pose read zero.
//!
//! Segment lengths need no calibration: angles do not depend on them.

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, UnitQuaternion, Vector3};

use crate::body::{self, COORDINATES, MARKER_FRAME_LEN, N_COORDINATES, Segment};
use crate::error::{Error, Result};
use crate::features::{technical_frame, technical_in_anatomical};

/// Frames a static trial needs.
pub const MIN_STATIC_FRAMES: usize = 10;
/// Largest rotation of the hand (relative to the forearm) away from the static trial's mean
/// allowed within it, degrees: more is not a static trial.
pub const MAX_STATIC_SPREAD_DEG: f64 = 5.0;
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

/// Each segment's technical frame in its anatomical frame: `v_anatomical = T · v_technical`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// `T_f`, forearm.
    pub forearm: Rotation3<f64>,
    /// `T_h`, hand.
    pub hand: Rotation3<f64>,
}

/// What the calibration learned besides the rotations, for the user to judge it by.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationReport {
    /// Per coordinate given: range of the movement (degrees) and share along its axis.
    pub movements: Vec<(usize, f64, f64)>,
    /// Angle between the measured and the body model's placement, forearm and hand, degrees.
    pub placement_deg: [f64; 2],
    /// Angle between measured axes that should be perpendicular and 90°, largest, degrees.
    pub axis_skew_deg: f64,
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
        Calibration { forearm: Rotation3::from_matrix_unchecked(*t_f), hand: Rotation3::from_matrix_unchecked(*t_h) }
    }

    /// A calibration from its two rotation matrices (e.g. read back from a file); refuses
    /// matrices that are not rotations to 1e-6.
    pub fn from_matrices(forearm: Matrix3<f64>, hand: Matrix3<f64>) -> Result<Self> {
        for (name, m) in [("forearm", &forearm), ("hand", &hand)] {
            let off = (m.transpose() * m - Matrix3::identity()).abs().max();
            if !m.iter().all(|v| v.is_finite()) || off > 1e-6 || m.determinant() < 0.0 {
                return Err(bad(format!(
                    "the {name} matrix is not a rotation (|MᵀM − I| = {off:.2e}, det {:.3})",
                    m.determinant()
                )));
            }
        }
        Ok(Calibration { forearm: Rotation3::from_matrix(&forearm), hand: Rotation3::from_matrix(&hand) })
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
        let neutral = mean_rotation(&statics);
        let spread = statics.iter().map(|s| angle_deg(&(s * neutral.inverse()))).fold(0.0, f64::max);
        if spread > MAX_STATIC_SPREAD_DEG {
            return Err(bad(format!(
                "the hand moves {spread:.1}° within the static trial (at most {MAX_STATIC_SPREAD_DEG}°): it must hold the neutral pose"
            )));
        }
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
        let mut report = CalibrationReport { movements: Vec::new(), placement_deg: [0.0; 2], axis_skew_deg: 0.0 };
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
        // Orthogonal Procrustes: the rotation T_f maximising Σ a_jᵀ T_f t_j.
        let n = measured.iter().fold(Matrix3::zeros(), |acc, (a, t)| acc + t * a.transpose());
        let svd = n.svd(true, true);
        let (u, v_t) = (svd.u.expect("requested"), svd.v_t.expect("requested"));
        let d =
            Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, (v_t.transpose() * u.transpose()).determinant().signum()));
        let forearm = Rotation3::from_matrix(&(v_t.transpose() * d * u.transpose()));
        let hand = forearm * neutral;
        report.placement_deg =
            [angle_deg(&(forearm * default.forearm.inverse())), angle_deg(&(hand * default.hand.inverse()))];
        if let Some(worst) = report.placement_deg.iter().copied().find(|&a| a > MAX_PLACEMENT_DEG) {
            return Err(bad(format!(
                "the markers sit {worst:.0}° from the body model's placement (at most {MAX_PLACEMENT_DEG}°): are they labelled right?"
            )));
        }
        Ok((Calibration { forearm, hand }, report))
    }

    /// Moves each segment's markers, in place, to where the body model puts them on a
    /// segment in the same anatomical pose (origin: the segment's marker centroid). Refuses
    /// frames whose segments have no orientation; does not allocate.
    pub fn apply(&self, frame: &mut [f32], frame_index: usize) -> Result<()> {
        if frame.len() != MARKER_FRAME_LEN {
            return Err(bad(format!("a frame has {} values, a marker frame {MARKER_FRAME_LEN}", frame.len())));
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

/// Rotation angle in degrees, robust to round-off (nalgebra's `angle` is NaN for a trace a
/// hair above 3).
pub fn angle_deg(r: &Rotation3<f64>) -> f64 {
    ((r.matrix().trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
}

fn bad(detail: String) -> Error {
    Error::BadArgument { what: "calibration", detail }
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
}
