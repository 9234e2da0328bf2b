//! Random models and frames for tests, benchmarks and examples (seeded, reproducible).

use crate::body::{BodyModel, COORDINATES};
use crate::features::FeatureSet;
use crate::model::{Model, ModelCard, OutputSpec};
use crate::net::{Activation, Affine, Dense, Mlp};
use nalgebra::{DMatrix, DVector};

pub use crate::rng::SplitMix;

/// An IK-style model with random weights: `window` frames of `set`, ReLU hidden layers of
/// the given widths, `n_outputs` outputs, random input and output scaling. Weights are scaled
/// (He-style) so activations stay O(1), as in a trained network.
pub fn random_model(set: FeatureSet, window: usize, hidden: &[usize], n_outputs: usize, seed: u64) -> Model {
    let mut rng = SplitMix::new(seed);
    let widths: Vec<usize> =
        std::iter::once(window * set.feature_len()).chain(hidden.iter().copied()).chain([n_outputs]).collect();
    let layers: Vec<Dense> = widths
        .windows(2)
        .enumerate()
        .map(|(k, w)| {
            let bound = (6.0 / w[0] as f64).sqrt();
            Dense {
                weight: DMatrix::from_fn(w[1], w[0], |_, _| rng.uniform(-bound, bound) as f32),
                bias: DVector::from_fn(w[1], |_, _| rng.uniform(-0.1, 0.1) as f32),
                activation: if k + 2 == widths.len() { Activation::Identity } else { Activation::Relu },
            }
        })
        .collect();
    let activations: Vec<Activation> = layers.iter().map(|l| l.activation).collect();
    // Scaling as a trained model has it (min–max in, its inverse out), never the identity, so
    // every test of a model also tests how the packed kernel folds the scaling in.
    let mut affine = |n: usize, scale: (f64, f64), shift: f64| Affine {
        scale: DVector::from_fn(n, |_, _| rng.uniform(scale.0, scale.1) as f32),
        shift: DVector::from_fn(n, |_, _| rng.uniform(-shift, shift) as f32),
    };
    let input = affine(widths[0], (0.5, 2.0), 0.5);
    let output = affine(n_outputs, (0.5, 3.0), 0.2);
    let mlp = Mlp::new(input, layers, output).expect("shapes chain");
    let outputs = (0..n_outputs)
        .map(|i| OutputSpec {
            name: COORDINATES.get(i).map_or(format!("out{i}"), |c| c.name.to_string()),
            unit: "rad".into(),
        })
        .collect();
    let card = ModelCard::new("random", "ik", set, window, 1000.0, outputs, &activations);
    Model::from_parts(card, mlp).expect("random model is valid")
}

/// A [`Tracker`](crate::Tracker) refiner with random weights (outputs
/// [`refiner_outputs`](crate::tracker::refiner_outputs), small so corrections stay modest).
pub fn random_refiner(window: usize, hidden: &[usize], seed: u64) -> Model {
    let base = random_model(FeatureSet::TrackerState, window, hidden, 6, seed);
    let mut card = base.card().clone();
    card.task = "refine".into();
    card.outputs =
        crate::tracker::refiner_outputs().into_iter().map(|name| OutputSpec { name, unit: "rad/mm".into() }).collect();
    Model::from_parts(card, base.mlp().clone()).expect("random refiner is valid")
}

/// `n` plausible frames for `set`, back to back: markers of the default subject at random
/// wrist angles and shoulder poses, or random joint states.
pub fn random_frames(set: FeatureSet, n: usize, seed: u64) -> Vec<f32> {
    let mut rng = SplitMix::new(seed);
    let body = BodyModel::default();
    let mut out = Vec::with_capacity(n * set.frame_len());
    for _ in 0..n {
        if matches!(set, FeatureSet::JointState | FeatureSet::TrackerState) {
            out.extend((0..set.frame_len()).map(|_| rng.uniform(-1.0, 1.0) as f32));
        } else {
            let q = COORDINATES.map(|c| rng.uniform(c.range.0, c.range.1));
            let pose = body.forearm_pose(rng.uniform(-0.35, 0.8));
            out.extend(body.marker_frame(&q, &pose).iter().map(|&v| v as f32));
        }
    }
    out
}

/// Runs a model that loaded (from any bytes) the way a user would, batch and stream, and
/// panics if it ever gives a non-finite output instead of an error: the property the
/// loader's proptest and fuzz target check.
pub fn exercise(model: &Model) {
    let frames = random_frames(model.feature_set(), 12, 3);
    let mut out = vec![0f32; model.n_predictions(12) * model.n_outputs()];
    if model.predict(&frames, &mut out).is_ok() {
        assert!(out.iter().all(|v| v.is_finite()), "predict gave a non-finite output");
    }
    let mut stream = model.stream();
    for frame in frames.chunks_exact(model.frame_len()) {
        if let Ok(Some(o)) = stream.push(frame) {
            assert!(o.iter().all(|v| v.is_finite()), "push gave a non-finite output");
        }
    }
}
