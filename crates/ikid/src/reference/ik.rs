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
    best_fit(&template, &measured, [1.0; 3], 1e-12)
        .ok_or(Error::DegenerateSegment { frame: frame_index, segment: segment.name() })
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
    best_fit(template, measured, weights, 1e-15)
}

/// The least-squares rigid motion (Kabsch: the rotation maximising `tr(R·H)`, `H` the
/// weighted cross-covariance) taking three `template` points onto three `measured` ones, in
/// closed form; `None` when `H`'s second singular value is at most `min_singular` (collinear
/// points: no unique rotation).
///
/// Three centred points lie in a plane, so `H` has rank two and the fit is a plane-to-plane
/// problem: the best rotation maps the template's plane onto the measured one and turns within
/// it by the 2-D Procrustes angle. Each plane faces the way its own points turn (its normal the
/// cross product of its edges): in those frames both triangles run counter-clockwise around a
/// (weighted) centroid inside them, so the 2-D cross-covariance has a positive determinant
/// (Cauchy–Binet: every pair's signed areas have one sign) and facing them the same way is the
/// optimum; a mirrored copy is the same triangle turned over. The same rotation as the SVD's to
/// rounding (tested), at a fraction of its cost: nalgebra's 3×3 SVD was 45 % of a tracker push,
/// which fits three or four segments a frame.
fn best_fit(
    template: &[Vector3<f64>; 3],
    measured: &[Vector3<f64>; 3],
    weights: [f64; 3],
    min_singular: f64,
) -> Option<Isometry3<f64>> {
    let total: f64 = weights.iter().sum();
    let tc = (0..3).map(|k| template[k] * weights[k]).sum::<Vector3<f64>>() / total;
    let mc = (0..3).map(|k| measured[k] * weights[k]).sum::<Vector3<f64>>() / total;
    let a: [Vector3<f64>; 3] = std::array::from_fn(|k| template[k] - tc);
    let b: [Vector3<f64>; 3] = std::array::from_fn(|k| measured[k] - mc);
    let fa = plane_frame(&a, &weights)?;
    let fb = plane_frame(&b, &weights)?;
    // Each point in its plane's coordinates; (c, s) the 2-D cross-covariance's rotation part,
    // (c_flip, s_flip) its reflection part: their lengths are σ₁ + σ₂ and σ₁ − σ₂.
    let (mut c, mut sn, mut c_flip, mut s_flip) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..3 {
        let (xa, ya) = (a[k].dot(&fa.column(0)), a[k].dot(&fa.column(1)));
        let (xb, yb) = (b[k].dot(&fb.column(0)), b[k].dot(&fb.column(1)));
        let w = weights[k];
        c += w * (xa * xb + ya * yb);
        sn += w * (xa * yb - ya * xb);
        c_flip += w * (xa * xb - ya * yb);
        s_flip += w * (xa * yb + ya * xb);
    }
    let norm = c.hypot(sn);
    if (norm - c_flip.hypot(s_flip)) / 2.0 <= min_singular {
        return None;
    }
    // The turn within the plane: (x, y) -> (x cos θ - y sin θ, x sin θ + y cos θ).
    let (cos, sin) = (c / norm, sn / norm);
    let turn = Matrix3::new(cos, -sin, 0.0, sin, cos, 0.0, 0.0, 0.0, 1.0);
    let r = fb * turn * fa.transpose();
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let translation = mc - rotation * tc;
    Some(Isometry3::from_parts(Translation3::from(translation), rotation))
}

/// An orthonormal frame of three centred points' plane (columns: an in-plane axis, the
/// second in-plane axis, the normal `x × y`), or `None` if they lie on a line (or a point).
fn plane_frame(points: &[Vector3<f64>; 3], weights: &[f64; 3]) -> Option<Matrix3<f64>> {
    // The in-plane axis along the farthest (weighted) point from the centroid, the normal
    // from the two edge vectors: both well conditioned for any non-degenerate triangle.
    let far = (0..3)
        .filter(|&k| weights[k] > 0.0)
        .max_by(|&i, &j| points[i].norm_squared().total_cmp(&points[j].norm_squared()))?;
    let z = (points[1] - points[0]).cross(&(points[2] - points[0])).try_normalize(0.0)?;
    let x = (points[far] - z * points[far].dot(&z)).try_normalize(0.0)?;
    let y = z.cross(&x);
    Some(Matrix3::from_columns(&[x, y, z]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::COORDINATES;
    use proptest::prelude::*;

    /// Kabsch by the SVD (the textbook solution), the oracle for [`best_fit`]: the rotation
    /// and its cross-covariance's second singular value.
    fn kabsch_by_svd(
        template: &[Vector3<f64>; 3],
        measured: &[Vector3<f64>; 3],
        weights: [f64; 3],
    ) -> (Rotation3<f64>, f64) {
        let total: f64 = weights.iter().sum();
        let tc = (0..3).map(|k| template[k] * weights[k]).sum::<Vector3<f64>>() / total;
        let mc = (0..3).map(|k| measured[k] * weights[k]).sum::<Vector3<f64>>() / total;
        let h: Matrix3<f64> = (0..3).map(|k| (template[k] - tc) * (measured[k] - mc).transpose() * weights[k]).sum();
        let svd = h.svd(true, true);
        let (u, v_t) = (svd.u.unwrap(), svd.v_t.unwrap());
        let d = (v_t.transpose() * u.transpose()).determinant().signum();
        let r = v_t.transpose() * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
        let mut sv = svd.singular_values;
        sv.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
        (Rotation3::from_matrix_unchecked(r), sv[1])
    }

    proptest! {
        /// The closed-form fit is Kabsch's optimum: any triangles, any rotation (to 180°), any
        /// noise up to the triangle's own size, mirrored copies, weights.
        #[test]
        fn the_closed_form_fit_is_the_svds(
            t in prop::array::uniform9(-0.1f64..0.1),
            axis in prop::array::uniform3(-1.0f64..1.0),
            angle in 0.0f64..std::f64::consts::PI,
            noise in prop::array::uniform9(-1.0f64..1.0),
            scale in prop::sample::select(vec![0.0, 1e-3, 0.02, 0.1]),
            shift in prop::array::uniform3(-2.0f64..2.0),
            weights in prop::array::uniform3(0.2f64..3.0),
            mirrored in any::<bool>(),
        ) {
            let template: [Vector3<f64>; 3] = std::array::from_fn(|k| Vector3::new(t[3 * k], t[3 * k + 1], t[3 * k + 2]));
            let turn = Rotation3::new(Vector3::from(axis).try_normalize(1e-6).unwrap_or(Vector3::x()) * angle);
            // A mirrored copy (swapped labels) is the same triangle turned over.
            let mirror = Vector3::new(1.0, 1.0, if mirrored { -1.0 } else { 1.0 });
            let measured: [Vector3<f64>; 3] = std::array::from_fn(|k| {
                turn * template[k].component_mul(&mirror)
                    + Vector3::from(shift)
                    + scale * Vector3::new(noise[3 * k], noise[3 * k + 1], noise[3 * k + 2])
            });
            let (want, sigma2) = kabsch_by_svd(&template, &measured, weights);
            prop_assume!(sigma2 > 1e-9);
            let got = best_fit(&template, &measured, weights, 1e-15).unwrap();
            let err = (got.rotation.to_rotation_matrix().into_inner() - want.into_inner()).abs().max();
            // The SVD's own rounding turns its rotation by ~5e-15 / σ₂ (more below 1e-5) about
            // the triangle's long axis (a nearly collinear triangle pins that turn by σ₂ alone).
            prop_assert!(sigma2 < 1e-5 || err < 1e-13 / sigma2 + 1e-12, "rotation off by {err} (sigma2 {sigma2})");
            // And it is the optimum itself: R·H symmetric (stationary), tr(R·H)·I − R·H positive
            // semidefinite (a maximum, not a saddle), to rounding.
            let total: f64 = weights.iter().sum();
            let tc = (0..3).map(|k| template[k] * weights[k]).sum::<Vector3<f64>>() / total;
            let mc = (0..3).map(|k| measured[k] * weights[k]).sum::<Vector3<f64>>() / total;
            let h: Matrix3<f64> = (0..3).map(|k| (template[k] - tc) * (measured[k] - mc).transpose() * weights[k]).sum();
            let rh = got.rotation.to_rotation_matrix().into_inner() * h;
            let size = h.abs().max();
            prop_assert!((rh - rh.transpose()).abs().max() < 1e-13 * size);
            let curvature = Matrix3::identity() * rh.trace() - (rh + rh.transpose()) / 2.0;
            prop_assert!(curvature.symmetric_eigenvalues().min() > -1e-13 * size);
            prop_assert!((got * Point3::from(tc) - Point3::from(mc)).norm() < 1e-12);
        }
    }

    #[test]
    fn collinear_points_have_no_fit() {
        let line = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.01, 0.02, 0.0), Vector3::new(0.03, 0.06, 0.0)];
        let triangle = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.05, 0.0, 0.0), Vector3::new(0.0, 0.04, 0.0)];
        assert!(best_fit(&triangle, &line, [1.0; 3], 1e-15).is_none());
        assert!(best_fit(&line, &triangle, [1.0; 3], 1e-15).is_none());
        assert!(best_fit(&triangle, &triangle, [1.0; 3], 1e-15).is_some());
        // Off the line by a micrometre: a plane, with σ₂ ≈ 3e-8 m² (the SVD's): no fit under a
        // floor a half above it, one under a floor a third below.
        let nearly = [line[0], line[1], line[2] + Vector3::new(0.0, 0.0, 1e-6)];
        let (_, sigma2) = kabsch_by_svd(&triangle, &nearly, [1.0; 3]);
        assert!(best_fit(&triangle, &nearly, [1.0; 3], 1.5 * sigma2).is_none());
        assert!(best_fit(&triangle, &nearly, [1.0; 3], sigma2 / 1.5).is_some());
    }

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
