//! Latency of `Stream::push` and per-sample cost of `Model::predict` for the thesis' three
//! network shapes, with random weights (cost does not depend on the values).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use ikid::FeatureSet;
use ikid::testing::{random_frames, random_model};
use std::hint::black_box;

/// (label, feature set, hidden widths): input width is window (5) × the set's features.
const NETS: [(&str, FeatureSet, &[usize]); 3] = [
    ("ik_markers_90-300-300-3", FeatureSet::Markers, &[300, 300]),
    ("ik_basis_120-240-240-3", FeatureSet::Basis, &[240, 240]),
    ("id_45-330-60-165-3", FeatureSet::JointState, &[330, 60, 165]),
];

fn push(c: &mut Criterion) {
    let mut group = c.benchmark_group("push");
    for (label, set, hidden) in NETS {
        let model = random_model(set, 5, hidden, 3, 1);
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

criterion_group!(benches, push, predict);
criterion_main!(benches);
