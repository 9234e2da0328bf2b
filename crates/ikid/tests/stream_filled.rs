//! `Stream::filled`: how many frames the window holds, what the bindings report before the
//! first output (the window minus one frames give none; the window's frame gives one).

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
