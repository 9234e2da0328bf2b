//! Per-push latency distribution (p50/p99/max) of `Stream::push`, for the thesis' three
//! network shapes with random weights or for a given model file.
//!
//! ```text
//! cargo run --release -p ikid --example latency -- [--pushes N] [--save-dir DIR] [--model FILE]
//! cargo run --release -p ikid --example latency -- --tracker [--refiner FILE] [--pushes N]
//! ```
//! `--tracker` times `Tracker::push` (angles, velocities, accelerations and torques) on a
//! smooth wrist motion with 1 % marker noise instead, with `--refiner` refined by that model.
//! `--save-dir` also writes the random models there, so another process (the Python
//! overhead benchmark in `benches/report.py`) can time exactly the same networks.
//! Prints one JSON object per model.

use ikid::testing::{random_frames, random_model};
use ikid::{FeatureSet, Model};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |flag: &str| args.iter().position(|a| a == flag).and_then(|i| args.get(i + 1)).cloned();
    let pushes: usize = value("--pushes").map(|v| v.parse()).transpose()?.unwrap_or(200_000);
    if args.iter().any(|a| a == "--tracker") {
        let refiner = value("--refiner").map(Model::load).transpose()?;
        return tracker_latency(pushes, refiner);
    }
    let models: Vec<(String, Model)> = match value("--model") {
        Some(path) => vec![(path.clone(), Model::load(&path)?)],
        None => [
            ("ik_markers_90-300-300-3", FeatureSet::Markers, &[300, 300][..]),
            ("ik_basis_120-240-240-3", FeatureSet::Basis, &[240, 240]),
            ("id_45-330-60-165-3", FeatureSet::JointState, &[330, 60, 165]),
        ]
        .into_iter()
        .map(|(label, set, hidden)| (label.to_string(), random_model(set, 5, hidden, 3, 1)))
        .collect(),
    };
    if let Some(dir) = value("--save-dir") {
        std::fs::create_dir_all(&dir)?;
        for (label, model) in &models {
            model.save(format!("{dir}/{label}.safetensors"))?;
        }
    }
    for (label, model) in &models {
        let frames = random_frames(model.feature_set(), 1024, 2);
        let fl = model.frame_len();
        let mut stream = model.stream();
        let mut ns = Vec::with_capacity(pushes);
        let mut sink = 0f32;
        for i in 0..pushes + 10_000 {
            let frame = &frames[(i % 1024) * fl..(i % 1024 + 1) * fl];
            let t = Instant::now();
            let out = stream.push(frame)?;
            let dt = t.elapsed().as_nanos() as u64;
            sink += out.map_or(0.0, |o| o[0]);
            if i >= 10_000 {
                ns.push(dt); // after warm-up
            }
        }
        ns.sort_unstable();
        let q = |p: f64| ns[((ns.len() - 1) as f64 * p) as usize] as f64 / 1000.0;
        println!(
            "{{\"model\": \"{label}\", \"pushes\": {pushes}, \"p50_us\": {:.3}, \"p90_us\": {:.3}, \"p99_us\": {:.3}, \"p999_us\": {:.3}, \"max_us\": {:.3}, \"multiply_adds\": {}, \"checksum\": {sink}}}",
            q(0.5),
            q(0.9),
            q(0.99),
            q(0.999),
            q(1.0),
            model.mlp().multiply_adds()
        );
    }
    Ok(())
}

fn tracker_latency(pushes: usize, refiner: Option<Model>) -> Result<(), Box<dyn std::error::Error>> {
    use ikid::body::{BodyModel, MARKER_FRAME_LEN};
    let body = BodyModel::default();
    let n = pushes + 10_000;
    let q: Vec<f64> = (0..n)
        .flat_map(|i| {
            let t = i as f64 / 1000.0;
            [0.8 * (2.1 * t).sin(), -0.6 * (1.3 * t + 0.5).sin(), 0.25 * (3.1 * t).cos()]
        })
        .collect();
    let mut frames = body.marker_frames(&q, 0.3)?;
    ikid::noise::uniform_range(&mut frames, 0.01, 7)?;
    let mut tracker = ikid::Tracker::new(body, ikid::TrackerSettings::new(1000.0))?;
    let label = if refiner.is_some() { "tracker+refiner" } else { "tracker" };
    tracker.set_refiner(refiner)?;
    let mut ns = Vec::with_capacity(pushes);
    let mut sink = 0.0;
    for (i, frame) in frames.chunks_exact(MARKER_FRAME_LEN).enumerate() {
        let t = Instant::now();
        let out = tracker.push(frame)?;
        let dt = t.elapsed().as_nanos() as u64;
        sink += out.map_or(0.0, |o| o.tau[0]);
        if i >= 10_000 {
            ns.push(dt);
        }
    }
    ns.sort_unstable();
    let q = |p: f64| ns[((ns.len() - 1) as f64 * p) as usize] as f64 / 1000.0;
    println!(
        "{{\"model\": \"{label}\", \"pushes\": {pushes}, \"p50_us\": {:.3}, \"p90_us\": {:.3}, \"p99_us\": {:.3}, \"p999_us\": {:.3}, \"max_us\": {:.3}, \"checksum\": {sink}}}",
        q(0.5),
        q(0.9),
        q(0.99),
        q(0.999),
        q(1.0)
    );
    Ok(())
}
