//! Reference inverse kinematics: per frame, least-squares segment poses, then joint angles.
//!
//! Exact on clean markers (the fit is exact when the markers are the body model's offsets
//! moved rigidly). On noisy markers it fits each segment to its own markers, forearm included;
//! OpenSim's IK on the exported model (forearm welded at its known pose) fits only the hand's
//! rotation about the known wrist centre, a different and less noisy least-squares problem
//! (measured side by side in docs/opensim.md).

use crate::body::{self, BodyModel, MARKER_FRAME_LEN, MARKERS, N_COORDINATES, Segment};
use crate::error::{Error, Result};
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Least-squares rigid pose (segment frame in the lab) mapping the segment's marker offsets
/// onto its measured markers (Kabsch). `frame` holds one marker frame (metres, lab).
pub fn fit_segment(body: &BodyModel, frame: &[f64], segment: Segment, frame_index: usize) -> Result<Isometry3<f64>> {
    let first = body::first_marker(segment);
    let mut template = [Vector3::zeros(); 3];
    let mut measured = [Vector3::zeros(); 3];
    for k in 0..3 {
        let i = first + k;
        template[k] = Vector3::from(body.marker_offsets[i]);
        measured[k] = Vector3::new(frame[3 * i], frame[3 * i + 1], frame[3 * i + 2]);
        if let Some(axis) = (0..3).find(|&a| !measured[k][a].is_finite()) {
            return Err(Error::NonFiniteInput {
                frame: frame_index,
                field: format!("{}.{}", MARKERS[i].name, ["x", "y", "z"][axis]),
                value: measured[k][axis] as f32,
            });
        }
    }
    let tc = (template[0] + template[1] + template[2]) / 3.0;
    let mc = (measured[0] + measured[1] + measured[2]) / 3.0;
    let h: Matrix3<f64> = (0..3).map(|k| (template[k] - tc) * (measured[k] - mc).transpose()).sum();
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u.expect("requested"), svd.v_t.expect("requested"));
    // A rank-deficient cross-covariance means collinear markers: no unique rotation.
    if svd.singular_values.iter().filter(|&&s| s > 1e-12).count() < 2 {
        return Err(Error::DegenerateSegment { frame: frame_index, segment: segment.name() });
    }
    let d = (v_t.transpose() * u.transpose()).determinant().signum();
    let r = v_t.transpose() * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let translation = mc - rotation * tc;
    Ok(Isometry3::from_parts(Translation3::from(translation), rotation))
}

/// Wrist angles `(s_p, e_f, ad_ab)` of one marker frame.
pub fn inverse_kinematics_frame(body: &BodyModel, frame: &[f64], frame_index: usize) -> Result<[f64; N_COORDINATES]> {
    if frame.len() != MARKER_FRAME_LEN {
        return Err(Error::FrameLength { feature_set: "markers", found: frame.len(), expected: MARKER_FRAME_LEN });
    }
    let forearm = fit_segment(body, frame, Segment::Forearm, frame_index)?;
    let hand = fit_segment(body, frame, Segment::Hand, frame_index)?;
    let relative = forearm.rotation.inverse() * hand.rotation;
    Ok(body::wrist_angles(&relative.to_rotation_matrix()))
}

/// Wrist angles of every frame: `frames` holds whole marker frames back to back, `out`
/// receives `N_COORDINATES` angles per frame. Errors name the frame.
pub fn inverse_kinematics(body: &BodyModel, frames: &[f64], out: &mut [f64]) -> Result<()> {
    if !frames.len().is_multiple_of(MARKER_FRAME_LEN) || out.len() != frames.len() / MARKER_FRAME_LEN * N_COORDINATES {
        return Err(Error::BadArgument {
            what: "inverse_kinematics",
            detail: format!("{} marker values and {} outputs do not make whole frames", frames.len(), out.len()),
        });
    }
    for (i, (frame, q)) in frames.chunks_exact(MARKER_FRAME_LEN).zip(out.chunks_exact_mut(N_COORDINATES)).enumerate() {
        q.copy_from_slice(&inverse_kinematics_frame(body, frame, i)?);
    }
    Ok(())
}

/// Marker positions of a segment at a pose (used by tests and the simulator).
pub fn segment_markers(body: &BodyModel, pose: &Isometry3<f64>, segment: Segment) -> [Point3<f64>; 3] {
    let first = body::first_marker(segment);
    std::array::from_fn(|k| pose * Point3::from(body.marker_offsets[first + k]))
}

/// The rigid motion taking the `template` points onto the `measured` ones by weighted least
/// squares (Kabsch); `None` if they are collinear.
pub fn fit_points(
    template: &[Vector3<f64>; 3],
    measured: &[Vector3<f64>; 3],
    weights: [f64; 3],
) -> Option<Isometry3<f64>> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::COORDINATES;
    use proptest::prelude::*;

    fn range(i: usize) -> std::ops::Range<f64> {
        COORDINATES[i].range.0..COORDINATES[i].range.1
    }

    proptest! {
        #[test]
        fn recovers_angles_from_clean_markers(q0 in range(0), q1 in range(1), q2 in range(2),
                                              shoulder in -0.6f64..1.2, scale in 0.8f64..1.2) {
            let body = BodyModel::scaled(scale, 1.0);
            let q = [q0, q1, q2];
            let frame = body.marker_frame(&q, &body.forearm_pose(shoulder));
            let got = inverse_kinematics_frame(&body, &frame, 0).unwrap();
            for i in 0..3 {
                prop_assert!((got[i] - q[i]).abs() < 1e-9, "{q:?} -> {got:?}");
            }
        }
    }

    #[test]
    fn missing_marker_and_collinear_markers_are_named() {
        let body = BodyModel::default();
        let mut frame = body.marker_frame(&[0.1, 0.2, 0.0], &body.forearm_pose(0.0)).to_vec();
        frame[16] = f64::NAN; // MCB.y
        let err = inverse_kinematics_frame(&body, &frame, 4).unwrap_err();
        assert!(err.to_string().contains("frame 4") && err.to_string().contains("MCB.y"), "{err}");
        let mut frame = body.marker_frame(&[0.0; 3], &body.forearm_pose(0.0)).to_vec();
        frame[0..9].copy_from_slice(&[0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.2, 0.0, 0.0]);
        let err = inverse_kinematics_frame(&body, &frame, 0).unwrap_err();
        assert!(matches!(err, Error::DegenerateSegment { segment: "forearm", .. }), "{err}");
    }

    #[test]
    fn noisy_markers_give_the_least_squares_pose() {
        // With symmetric noise the fitted pose stays close: a sanity bound, 1 mm noise.
        let body = BodyModel::default();
        let q = [0.3, -0.4, 0.1];
        let mut frame = body.marker_frame(&q, &body.forearm_pose(0.2)).to_vec();
        let noise = [
            0.001, -0.001, 0.0005, -0.0005, 0.001, 0.0, -0.001, 0.0, 0.001, 0.0005, -0.001, 0.0, 0.001, 0.0005,
            -0.0005, -0.001, 0.0, 0.001,
        ];
        for (v, n) in frame.iter_mut().zip(noise) {
            *v += n;
        }
        let got = inverse_kinematics_frame(&body, &frame, 0).unwrap();
        for i in 0..3 {
            assert!((got[i] - q[i]).abs() < 0.05, "{got:?} vs {q:?}");
        }
    }
}
