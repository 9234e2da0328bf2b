//! Latency of `Stream::push` and per-sample cost of `Model::predict` for the thesis' three
//! network shapes, with random weights (cost does not depend on the values), and of
//! `Tracker::push`. Every model carries a training envelope, so each push pays for the
//! plausibility check (status bits) as a shipped model's does.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use ikid::body::{BodyModel, MARKER_FRAME_LEN};
use ikid::model::{Bounds, Envelope};
use ikid::testing::{random_frames, random_model};
use ikid::{FeatureSet, Model, Tracker, TrackerSettings};
use std::hint::black_box;

/// A random model whose card carries a (wide) envelope, like a trained one.
fn enveloped(set: FeatureSet, hidden: &[usize]) -> Model {
    let m = random_model(set, 5, hidden, 3, 1);
    let mut card = m.card().clone();
    let wide = |n: usize| Bounds { min: vec![-1e3; n], max: vec![1e3; n] };
    card.envelope = Some(Envelope { inputs: wide(set.feature_len()), outputs: wide(3), window_change: None });
    Model::from_parts(card, m.mlp().clone()).expect("a valid card")
}

/// (label, feature set, hidden widths): input width is window (5) × the set's features.
const NETS: [(&str, FeatureSet, &[usize]); 3] = [
    ("ik_markers_90-300-300-3", FeatureSet::Markers, &[300, 300]),
    ("ik_basis_120-240-240-3", FeatureSet::Basis, &[240, 240]),
    ("id_45-330-60-165-3", FeatureSet::JointState, &[330, 60, 165]),
];

fn push(c: &mut Criterion) {
    let mut group = c.benchmark_group("push");
    for (label, set, hidden) in NETS {
        let model = enveloped(set, hidden);
        let frames = random_frames(set, 64, 2);
        let mut stream = model.stream();
        let fl = set.frame_len();
        for f in frames.chunks_exact(fl).take(model.window()) {
            stream.push(f).unwrap();
        }
        let mut i = 0;
        group.bench_function(label, |b| {
            b.iter(|| {
                i = (i + 1) % 64;
                let out = stream.push(black_box(&frames[i * fl..(i + 1) * fl])).unwrap();
                black_box(out.map(|o| o[0]))
            })
        });
    }
    group.finish();
}

fn predict(c: &mut Criterion) {
    let mut group = c.benchmark_group("predict");
    const N: usize = 1000;
    for (label, set, hidden) in NETS {
        let model = random_model(set, 5, hidden, 3, 1);
        let frames = random_frames(set, N, 2);
        let mut out = vec![0f32; model.n_predictions(N) * model.n_outputs()];
        group.throughput(Throughput::Elements(model.n_predictions(N) as u64));
        for threads in [1, 2] {
            group.bench_with_input(BenchmarkId::new(format!("{label}/threads{threads}"), N), &frames, |b, frames| {
                b.iter(|| model.predict_with_threads(black_box(frames), &mut out, threads).unwrap())
            });
        }
    }
    group.finish();
}

/// One tracker push on a smooth 1 kHz movement: bare, and calibrated (relative hand).
fn tracker(c: &mut Criterion) {
    let mut group = c.benchmark_group("tracker");
    let body = BodyModel::default();
    let n = 2000;
    let q: Vec<f64> = (0..n)
        .flat_map(|i| {
            let t = i as f64 / 1000.0;
            [0.6 * (1.3 * t).sin(), -0.5 * (0.9 * t).sin(), 0.2 * (1.7 * t).cos()]
        })
        .collect();
    let frames = body.marker_frames(&q, 0.3).expect("a valid trajectory");
    for (label, relative_hand) in [("push", false), ("push_relative_hand", true)] {
        let settings = TrackerSettings { relative_hand, ..TrackerSettings::new(1000.0) };
        let mut tracker = Tracker::new(body.clone(), settings).expect("valid settings");
        let mut i = 0;
        group.bench_function(label, |b| {
            b.iter(|| {
                if i == 0 {
                    tracker.reset();
                }
                let out = tracker.push(black_box(&frames[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN]));
                i = (i + 1) % n;
                black_box(out.map(|o| o.map(|o| o.state.q[0])))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, push, predict, tracker);
criterion_main!(benches);
