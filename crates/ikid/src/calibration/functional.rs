//! The functional method: neutral frames and a movement mixing flexion and deviation, the
//! two axes by least squares ([`Calibration::functional`]).

use super::*;

impl Calibration {
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
        let calibration = Calibration { forearm, hand, side, shapes: None };
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
            placement_deg: Calibration { forearm, hand, side, shapes: None }.placement_deg(),
            axis_skew_deg: 0.0,
            neutral_frames: held.frames,
            neutral_spread_deg: held.spread_deg,
            neutral_noise_deg: held.noise_deg,
            neutral_uncertainty_deg: held.uncertainty_deg,
            landmarks: None,
            functional: Some(report),
            mirror: None,
        };
        Ok((calibration, report))
    }
}

/// The unit `u`, `v` minimising `Σ (uᵀ M_k v)²` (a universal joint: `u` fixed in the first
/// segment, `v` in the second, perpendicular in every frame), by alternating least squares
/// from several starts; with the RMS of `asin(uᵀM_kv)` that is not the markers' noise (the
/// turn the fit cannot describe), and the noise's, radians.
pub(super) fn fit_universal_axes(moves: &[Matrix3<f64>]) -> (Vector3<f64>, Vector3<f64>, f64, f64) {
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
