//! `Stream::filled`: how many frames the window holds, what the bindings report before the
//! first output (the window minus one frames give none; the window's frame gives one); and
//! `Stream::sd_terms`, the running means the window's frames give the σ.

use ikid::FeatureSet;
use ikid::testing::{random_frames, random_model};

#[test]
fn filled_counts_the_frames_held_up_to_the_window() {
    let model = random_model(FeatureSet::Markers, 5, &[16, 12], 3, 5);
    let frames = random_frames(FeatureSet::Markers, 8, 1);
    let mut s = model.stream();
    assert_eq!(s.filled(), 0);
    for (k, f) in frames.chunks_exact(18).enumerate() {
        let out = s.push(f).unwrap().is_some();
        // By hand: k + 1 frames pushed, a 5-frame window.
        assert_eq!(s.filled(), (k + 1).min(5), "after {} frames", k + 1);
        assert_eq!(out, k + 1 >= 5, "after {} frames", k + 1);
    }
    s.reset();
    assert_eq!(s.filled(), 0);
}

#[test]
fn sd_terms_are_the_per_frame_angles_noise_once_eight_third_differences_are_in() {
    // The wrist alternating between q0 + δ and q0 − δ: every third difference of an angle is
    // ±8 δ_k, so its noise term (the mean of their squares over 20) is 64 δ_k² / 20 from the
    // first on; no correction term without an output offset. None before the 8th (frame 11).
    let body = ikid::body::BodyModel::default();
    let pose = body.forearm_pose(0.2);
    let (q0, delta) = ([0.2, -0.3, 0.1], [0.01, 0.02, 0.015]);
    let model = random_model(FeatureSet::Angles, 5, &[16], 3, 3);
    let mut s = model.stream();
    for i in 0..30 {
        let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
        let q: [f64; 3] = std::array::from_fn(|k| q0[k] + sign * delta[k]);
        let frame: Vec<f32> = body.marker_frame(&q, &pose).iter().map(|&v| v as f32).collect();
        s.push(&frame).unwrap();
        assert_eq!(s.sd_terms().is_some(), i + 1 >= 11, "after {} frames", i + 1);
    }
    let (noise, correction) = s.sd_terms().unwrap();
    for k in 0..3 {
        let expected = 64.0 * delta[k] * delta[k] / 20.0;
        assert!((noise[k] / expected - 1.0).abs() < 1e-3, "angle {k}: {} vs {expected}", noise[k]);
    }
    assert_eq!(correction, [0.0; 3]);
}
