//! The model loader (safetensors container + JSON model card + tensor checks) on arbitrary
//! bytes: it must return a model or an error, never panic, hang or read out of bounds; a
//! model it accepts must predict finite values or refuse.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(model) = ikid::Model::from_bytes(data) else { return };
    let frames = ikid::testing::random_frames(model.feature_set(), 8, 1);
    let mut out = vec![0f32; model.n_predictions(8) * model.n_outputs()];
    if model.predict(&frames, &mut out).is_ok() {
        assert!(out.iter().all(|v| v.is_finite()));
    }
    let mut stream = model.stream();
    for frame in frames.chunks_exact(model.frame_len()) {
        if let Ok(Some(o)) = stream.push(frame) {
            assert!(o.iter().all(|v| v.is_finite()));
        }
    }
});
