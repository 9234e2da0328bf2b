//! The movements method: a static trial and single-coordinate movements, the clinical
//! functional-axis protocol ([`Calibration::from_trials`]).

use super::*;

impl Calibration {
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
            mirror: None,
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
        report.placement_deg = Calibration { forearm, hand, side: Side::Right, shapes: None }.placement_deg();
        if let Some(worst) = report.placement_deg.iter().copied().find(|&a| a > MAX_PLACEMENT_DEG) {
            return Err(bad(format!(
                "the markers sit {worst:.0}° from the body model's placement (at most {MAX_PLACEMENT_DEG}°): are they labelled right?"
            )));
        }
        Ok((Calibration { forearm, hand, side: Side::Right, shapes: None }, report))
    }
}

/// Orthogonal Procrustes: the rotation `T` maximising `Σ aᵀ T t` over pairs `(a, t)` (model
/// axis, measured axis in technical coordinates).
pub(super) fn procrustes(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Rotation3<f64> {
    let n = pairs.iter().fold(Matrix3::zeros(), |acc, (a, t)| acc + t * a.transpose());
    let svd = n.svd(true, true);
    let (u, v_t) = (svd.u.expect("requested"), svd.v_t.expect("requested"));
    let d = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, (v_t.transpose() * u.transpose()).determinant().signum()));
    Rotation3::from_matrix(&(v_t.transpose() * d * u.transpose()))
}
