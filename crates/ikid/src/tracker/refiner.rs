//! The optional learned refiner: a network over a window of the filter's own states that
//! corrects q and q̈ after the filter, gated by the learned noise and held to the filter's
//! own uncertainty; never fed back.

use super::{N_STATE, StateMatrix, StateVector, Tracker};
use crate::body::{COORDINATES, N_COORDINATES};
use crate::error::{Error, Result};
use crate::features::FeatureSet;
use crate::model::Model;
use crate::reference::JointState;

/// The refiner's corrections are scaled by `σ / (σ + REFINER_GATE_NOISE)`, σ the mean learned
/// hand-marker noise (m): ~1 on noisy markers, → 0 on clean ones, which the filter already
/// follows exactly (a network's own error floor would only add to it there).
pub const REFINER_GATE_NOISE: f64 = 1e-4;

/// Largest refiner correction, in standard deviations of the filter's own estimate.
pub const REFINER_TRUST: f64 = 3.0;

/// A refined estimate's standard deviations, as a share of the filter's own
/// ([`Tracker::output_sd`]): the shipped `wrist-track`'s errors over the filter's σ, tuned by
/// `studies/sigma_coverage.py` on its TUNE seeds (the share that puts 68.3 % of the refined
/// frames within ±σ, pooled over its noisy conditions; scored on others). One share, not one
/// opened with the refiner's gate: its errors over the filter's σ were alike at 1 % and 5 %
/// noise (0.60 and 0.65), where the gate is half and fully open (scaled by the gate, 5 % was
/// under-covered, 0.60).
pub const REFINED_SD_SCALE_Q: f64 = 0.63;
/// The same for the torques.
pub const REFINED_SD_SCALE_TAU: f64 = 0.35;

/// The gate on the refiner's corrections at mean marker noise `noise` (m).
pub fn refiner_gate(noise: f64) -> f64 {
    noise / (noise + REFINER_GATE_NOISE)
}
/// The refiner's outputs, in order: corrections to q, then to q̈, per coordinate.
pub fn refiner_outputs() -> Vec<String> {
    ["dq", "dqdd"].iter().flat_map(|k| COORDINATES.iter().map(move |c| format!("{k}.{}", c.name))).collect()
}

impl Tracker {
    /// Use `model` to refine every estimate (see the [module docs](super)), or none. The model
    /// must read [`FeatureSet::TrackerState`] frames at the tracker's rate and give
    /// [`refiner_outputs`]. Starts fresh: its window fills from the next frame.
    pub fn set_refiner(&mut self, model: Option<Model>) -> Result<()> {
        let Some(model) = model else {
            self.refiner = None;
            return Ok(());
        };
        let name = model.card().name.clone();
        let bad = |detail: String| {
            Err(Error::BadArgument {
                what: "refiner",
                detail: format!("model {name:?} cannot refine a tracker: {detail}"),
            })
        };
        if model.feature_set() != FeatureSet::TrackerState {
            return bad(format!(
                "it reads {} frames, not {}",
                model.feature_set().name(),
                FeatureSet::TrackerState.name()
            ));
        }
        let names: Vec<String> = model.card().outputs.iter().map(|o| o.name.clone()).collect();
        if names != refiner_outputs() {
            return bad(format!("its outputs are [{}], expected [{}]", names.join(", "), refiner_outputs().join(", ")));
        }
        let rate = model.card().frame_rate_hz;
        if (rate - self.settings.rate_hz).abs() > 1e-6 * self.settings.rate_hz {
            return bad(format!("it was trained at {rate} Hz, the tracker runs at {} Hz", self.settings.rate_hz));
        }
        self.refiner = Some(model.stream());
        Ok(())
    }

    /// The refinement model in use, if any.
    pub fn refiner(&self) -> Option<&Model> {
        self.refiner.as_ref().map(|s| s.model())
    }

    /// The state `x` as output: corrected by the refiner, if there is one and its window is
    /// full, by its outputs gated by the learned noise `noise` and held to [`REFINER_TRUST`]
    /// standard deviations of the filter's own estimate (covariance `p`). Returns the state and
    /// whether it was refined.
    pub(super) fn refine(
        &mut self,
        x: &StateVector,
        p: &StateMatrix,
        noise: f64,
        index: usize,
    ) -> Result<(JointState, bool)> {
        let mut state = JointState { q: [x[0], x[1], x[2]], qd: [x[3], x[4], x[5]], qdd: [x[6], x[7], x[8]] };
        let mut refined = false;
        if let Some(refiner) = self.refiner.as_mut() {
            let mut frame = [0f32; N_STATE + 1];
            for (f, v) in frame.iter_mut().zip(x.iter()) {
                *f = *v as f32;
            }
            frame[N_STATE] = noise.log10() as f32;
            if let Some(out) = refiner.push(&frame).map_err(|e| e.renumbered(index))? {
                let per_unit = refiner_gate(noise);
                // A correction beyond REFINER_TRUST filter standard deviations is not one the
                // filter's own uncertainty allows: the network is outside what it learned.
                let trust = |value: f64, variance: f64| {
                    let limit = REFINER_TRUST * variance.max(0.0).sqrt();
                    value.clamp(-limit, limit)
                };
                for c in 0..N_COORDINATES {
                    state.q[c] += trust(f64::from(out[c]) * per_unit, p[(c, c)]);
                    state.qdd[c] += trust(f64::from(out[N_COORDINATES + c]) * per_unit, p[(6 + c, 6 + c)]);
                }
                refined = true;
            }
        }
        self.refined = refined;
        Ok((state, refined))
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {
    use super::super::testkit::*;
    use super::super::*;
    use super::*;
    use crate::body::BodyModel;

    use crate::features::FeatureSet;
    use crate::model::Model;
    use crate::noise::uniform_range;
    use crate::reference::{self};

    #[test]
    fn a_refiner_corrects_by_its_outputs_gated_by_the_learned_noise() {
        use crate::testing::{random_model, random_refiner};
        let body = BodyModel::default();
        let q = trajectory(400, 1000.0);
        let mut f = frames(&body, &q, 0.1);
        uniform_range(&mut f, 0.02, 5).unwrap();
        let refiner = random_refiner(8, &[16], 3);
        let mut bare = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        let mut refined = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        refined.set_refiner(Some(refiner.clone())).unwrap();
        let mut stream = refiner.stream();
        for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let a = bare.push(frame).unwrap().unwrap();
            let b = refined.push(frame).unwrap().unwrap();
            // The refiner's input: the bare filter's state and log10 of its noise.
            let mut input = [0f32; 10];
            for k in 0..3 {
                input[k] = a.state.q[k] as f32;
                input[3 + k] = a.state.qd[k] as f32;
                input[6 + k] = a.state.qdd[k] as f32;
            }
            input[9] = a.noise.log10() as f32;
            let out = stream.push(&input).unwrap().map(|o| o.to_vec());
            assert_eq!(b.refined, out.is_some(), "frame {i}");
            assert_eq!(b.noise, a.noise);
            assert_eq!(b.state.qd, a.state.qd, "q̇ is the filter's");
            // The gate by hand: σ / (σ + 0.1 mm).
            let per_unit = a.noise / (a.noise + 1e-4);
            let (sd_q, sd_qdd) = bare.state_std();
            for k in 0..3 {
                let (dq, dqdd) = out.as_ref().map_or((0.0, 0.0), |o| (f64::from(o[k]), f64::from(o[3 + k])));
                let clamp = |v: f64, sd: f64| v.clamp(-REFINER_TRUST * sd, REFINER_TRUST * sd);
                assert_eq!(b.state.q[k], a.state.q[k] + clamp(dq * per_unit, sd_q[k]), "frame {i}");
                assert_eq!(b.state.qdd[k], a.state.qdd[k] + clamp(dqdd * per_unit, sd_qdd[k]), "frame {i}");
            }
            let tau = reference::inverse_dynamics(&body, 0.1, &b.state).unwrap();
            for k in 0..3 {
                assert!((b.tau[k] - tau[k]).abs() < 1e-12, "torques follow the refined state");
            }
        }
        // The wrong kind of model is refused with the reason.
        let err =
            refined.set_refiner(Some(random_model(FeatureSet::JointState, 5, &[8], 6, 1))).unwrap_err().to_string();
        assert!(err.contains("reads joint_state frames"), "{err}");
        let err =
            refined.set_refiner(Some(random_model(FeatureSet::TrackerState, 5, &[8], 3, 1))).unwrap_err().to_string();
        assert!(err.contains("its outputs are"), "{err}");
        let mut slow = Tracker::new(body, TrackerSettings::new(500.0)).unwrap();
        let err = slow.set_refiner(Some(refiner)).unwrap_err().to_string();
        assert!(err.contains("1000 Hz") && err.contains("500 Hz"), "{err}");
        refined.set_refiner(None).unwrap();
        assert!(refined.refiner().is_none());
    }

    #[test]
    fn a_refined_estimates_sd_is_the_filters_narrowed_by_the_shares() {
        // The refiner never feeds the filter back, so the filter's σ is the bare tracker's; a
        // refined estimate's is that times the shares, an unrefined one's (the refiner's window
        // filling) the filter's.
        use crate::testing::random_refiner;
        let body = BodyModel::default();
        let q = trajectory(300, 1000.0);
        let mut f = frames(&body, &q, 0.1);
        uniform_range(&mut f, 0.02, 5).unwrap();
        let mut bare = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        let mut refined = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        refined.set_refiner(Some(random_refiner(8, &[16], 3))).unwrap();
        let mut seen = [false; 2];
        for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let b = refined.push(frame).unwrap().unwrap();
            bare.push(frame).unwrap().unwrap();
            let (sa, sb) = (bare.output_sd().unwrap(), refined.output_sd().unwrap());
            seen[usize::from(b.refined)] = true;
            let (share_q, share_tau) = if b.refined { (REFINED_SD_SCALE_Q, REFINED_SD_SCALE_TAU) } else { (1.0, 1.0) };
            for c in 0..3 {
                let (want_q, want_tau) = (sa.q[c] * share_q, sa.tau[c] * share_tau);
                assert!((sb.q[c] - want_q).abs() <= 1e-12 * want_q, "frame {i}: {} vs {want_q}", sb.q[c]);
                assert!((sb.tau[c] - want_tau).abs() <= 1e-9 * want_tau, "frame {i}: {} vs {want_tau}", sb.tau[c]);
            }
        }
        assert_eq!(seen, [true, true], "frames before and after the refiner's window filled");
    }

    /// A random refiner whose outputs are multiplied by `gain` and shifted by `offset`.
    fn rescaled_refiner(seed: u64, gain: f32, offset: f32) -> Model {
        use crate::net::{Affine, Mlp};
        let base = crate::testing::random_refiner(4, &[8], seed);
        let mlp = base.mlp();
        let out =
            Affine { scale: mlp.output.scale.map(|s| s * gain), shift: mlp.output.shift.map(|s| s * gain + offset) };
        Model::from_parts(base.card().clone(), Mlp::new(mlp.input.clone(), mlp.layers.clone(), out).unwrap()).unwrap()
    }

    #[test]
    fn a_refiner_that_overreaches_is_held_to_three_standard_deviations() {
        // A refiner whose corrections are 10⁴ times too large: every correction it makes is cut
        // to ±3 standard deviations of the filter's own estimate (the bare filter's here).
        let refiner = rescaled_refiner(9, 1e4, 1e3);
        let body = BodyModel::default();
        let mut f = frames(&body, &trajectory(300, 1000.0), 0.1);
        uniform_range(&mut f, 0.02, 8).unwrap();
        let mut bare = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        let mut refined = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
        refined.set_refiner(Some(refiner)).unwrap();
        let mut clamped = 0;
        for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let a = bare.push(frame).unwrap().unwrap();
            let b = refined.push(frame).unwrap().unwrap();
            // From frame 100 the learned noise (2 %) opens the gate: the corrections are huge.
            if i < 100 {
                continue;
            }
            assert!(b.refined);
            let (sd_q, sd_qdd) = bare.state_std();
            for k in 0..3 {
                let (dq, dqdd) = ((b.state.q[k] - a.state.q[k]).abs(), (b.state.qdd[k] - a.state.qdd[k]).abs());
                assert!((dq / (3.0 * sd_q[k]) - 1.0).abs() < 1e-9, "q {k}: {dq} vs 3 × {}", sd_q[k]);
                assert!((dqdd / (3.0 * sd_qdd[k]) - 1.0).abs() < 1e-9, "q̈ {k}: {dqdd} vs 3 × {}", sd_qdd[k]);
                clamped += 1;
            }
        }
        assert_eq!(clamped, 600);
    }

    #[test]
    fn a_quiet_refiner_is_applied_times_the_gate_without_clamping() {
        // Corrections of ~10 µrad, well inside 3 sd of the estimate: each applied exactly as
        // the network's output times σ / (σ + 0.1 mm).
        let refiner = rescaled_refiner(11, 1e-5, 0.0);
        let body = BodyModel::default();
        let mut f = frames(&body, &trajectory(300, 1000.0), 0.1);
        uniform_range(&mut f, 0.002, 3).unwrap();
        let mut bare = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        let mut refined = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
        refined.set_refiner(Some(refiner.clone())).unwrap();
        let mut stream = refiner.stream();
        let mut checked = 0;
        for frame in f.chunks_exact(MARKER_FRAME_LEN) {
            let a = bare.push(frame).unwrap().unwrap();
            let b = refined.push(frame).unwrap().unwrap();
            let input: Vec<f32> = a
                .state
                .q
                .iter()
                .chain(&a.state.qd)
                .chain(&a.state.qdd)
                .map(|&v| v as f32)
                .chain([a.noise.log10() as f32])
                .collect();
            let Some(out) = stream.push(&input).unwrap() else { continue };
            let gate = a.noise / (a.noise + 1e-4);
            for k in 0..3 {
                assert_eq!(b.state.q[k], a.state.q[k] + f64::from(out[k]) * gate);
                assert_eq!(b.state.qdd[k], a.state.qdd[k] + f64::from(out[3 + k]) * gate);
            }
            checked += 1;
        }
        assert_eq!(checked, 297);
    }

    #[test]
    fn a_refiner_at_the_trackers_rate_to_a_millionth_is_accepted() {
        use crate::testing::random_refiner;
        let refiner = random_refiner(4, &[8], 2); // 1000 Hz
        for (rate, ok) in [(1000.0005, true), (999.9995, true), (1000.002, false), (999.998, false)] {
            let mut t = Tracker::new(BodyModel::default(), TrackerSettings::new(rate)).unwrap();
            assert_eq!(t.set_refiner(Some(refiner.clone())).is_ok(), ok, "{rate} Hz");
        }
    }

    #[test]
    fn the_refiner_gate_is_half_open_at_its_noise_and_closed_on_clean_markers() {
        // By hand: σ / (σ + 0.1 mm).
        assert_eq!(refiner_gate(0.0), 0.0);
        assert!((refiner_gate(1e-4) - 0.5).abs() < 1e-12);
        assert!((refiner_gate(1e-3) - 1e-3 / 1.1e-3).abs() < 1e-12);
        assert!((refiner_gate(1e-6) - 1e-6 / 1.01e-4).abs() < 1e-12);
        assert!(refiner_gate(1.0) > 0.9999 && refiner_gate(1.0) < 1.0);
    }
}
