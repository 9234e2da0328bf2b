//! Robustness: random, truncated and corrupted inputs to the model loader, the stream and the
//! gap filler always give a value or an error — never a panic, a hang or a non-finite output —
//! and the same input always gives bit-identical output, across runs, threads and APIs.
//!
//! Case counts are proptest's (`PROPTEST_CASES` overrides; the note of issue 7 quotes them).

use ikid::model::CARD_KEY;
use ikid::testing::{exercise, random_frames, random_model};
use ikid::{Error, FeatureSet, GapFiller, MissingMarkers, Model};
use proptest::prelude::*;
use std::sync::OnceLock;

fn valid_file() -> &'static [u8] {
    static BYTES: OnceLock<Vec<u8>> = OnceLock::new();
    BYTES.get_or_init(|| random_model(FeatureSet::Angles, 4, &[8], 3, 1).to_bytes())
}

fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -1.0f32..1.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => any::<f32>(),
        1 => Just(0.0f32),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_are_refused_as_no_model_file(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        // Random bytes are not a safetensors container (its header is a length and JSON):
        // the loader says so, without a panic. Files that do parse are the next property's.
        match Model::from_bytes(&bytes) {
            Err(Error::Container(detail)) => prop_assert!(!detail.is_empty()),
            Err(other) => prop_assert!(false, "random bytes refused as {other:?}, not as a bad container"),
            Ok(_) => prop_assert!(false, "{} random bytes loaded as a model", bytes.len()),
        }
    }

    #[test]
    fn loader_survives_corrupted_valid_files(flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
                                             cut in any::<prop::sample::Index>(), truncate in any::<bool>()) {
        let mut bytes = valid_file().to_vec();
        for (at, value) in flips {
            let i = at.index(bytes.len());
            bytes[i] = value;
        }
        if truncate {
            bytes.truncate(cut.index(bytes.len()));
        }
        if let Ok(model) = Model::from_bytes(&bytes) {
            exercise(&model);
        }
    }

    #[test]
    fn loader_survives_random_model_cards(window in 0usize..10_000, task in "[a-z]{0,6}", set in "[a-z_]{0,16}",
                                          rate in any::<f64>(), policy in "(fill|refuse|[a-z]{0,5})", n_out in 0usize..5) {
        // Structurally plausible cards with random values: the loader's schema checks, not JSON's.
        let mut card: serde_json::Value = serde_json::from_str(&random_model(FeatureSet::Angles, 4, &[8], 3, 1).card().to_json()).unwrap();
        card["window"] = window.into();
        card["task"] = task.into();
        card["missing_markers"] = policy.into();
        card["frame_rate_hz"] = serde_json::Number::from_f64(rate).map_or(serde_json::Value::Null, Into::into);
        if n_out != 3 {
            card["outputs"] = serde_json::json!(vec![serde_json::json!({"name": "x", "unit": "rad"}); n_out]);
        }
        if set.len() % 2 == 1 {
            card["feature_set"] = set.into();
        }
        let st = safetensors::SafeTensors::deserialize(valid_file()).unwrap();
        let tensors: Vec<(String, safetensors::tensor::TensorView<'_>)> = st.tensors();
        let meta = std::collections::HashMap::from([(CARD_KEY.to_string(), card.to_string())]);
        let bytes = safetensors::serialize(tensors, Some(meta)).unwrap();
        if let Ok(model) = Model::from_bytes(&bytes) {
            exercise(&model);
        }
    }

    #[test]
    fn stream_survives_any_frames(values in proptest::collection::vec(any_f32(), 0..400), fill in any::<bool>(), cut in 0usize..40) {
        let model = random_model(FeatureSet::Angles, 3, &[8], 3, 2);
        let mut stream = model.stream();
        if fill {
            stream.set_missing_markers(MissingMarkers::Fill).unwrap();
        }
        // Whole frames and a ragged tail: each push either predicts finite values or errs.
        let (whole, tail) = values.split_at(values.len() - values.len() % 18);
        for frame in whole.chunks_exact(18).chain([tail, &values[..cut.min(values.len())]]) {
            if let Ok(Some(o)) = stream.push(frame) {
                prop_assert!(o.iter().all(|v| v.is_finite()));
            }
        }
        let mut out = vec![0f32; stream.rows_for(whole.len() / 18) * 3];
        if stream.push_many(whole, &mut out).is_ok() {
            prop_assert!(out.iter().all(|v| v.is_finite()));
        }
    }

    #[test]
    fn gap_filler_fills_finitely_or_refuses(noise in proptest::collection::vec(any_f32(), 18 * 64),
                                           gone in proptest::collection::vec(0usize..7, 64)) {
        // Real motion, then frames with random corruption and random missing markers.
        let mut filler = GapFiller::new();
        let clean = random_frames(FeatureSet::Angles, 200, 4);
        for (i, frame) in clean.chunks_exact(18).enumerate().take(136) {
            filler.fill(&mut frame.to_vec(), i).unwrap();
        }
        for (k, frame) in clean[136 * 18..].chunks_exact(18).enumerate() {
            let mut f = frame.to_vec();
            for (v, n) in f.iter_mut().zip(&noise[18 * k..18 * k + 18]) {
                *v += 0.001 * n;
            }
            if gone[k] < 6 {
                f[3 * gone[k]..3 * gone[k] + 3].fill(f32::NAN);
            }
            let before = f.clone();
            match filler.fill(&mut f, k) {
                Ok(_) => prop_assert!(f.iter().all(|v| v.is_finite())),
                Err(_) => prop_assert!(f.iter().zip(&before).all(|(a, b)| a.to_bits() == b.to_bits()), "a refused frame is unchanged"),
            }
        }
    }
}

#[test]
fn every_prefix_of_a_valid_file_is_refused() {
    let bytes = valid_file();
    for n in 0..bytes.len() {
        assert!(Model::from_bytes(&bytes[..n]).is_err(), "prefix of {n} bytes loaded");
    }
}

#[test]
fn threads_sharing_a_model_get_bit_identical_results() {
    // One model, 8 threads each with its own stream (and a batch call), same frames: every
    // thread's outputs equal the single-threaded run's bit for bit.
    let model = random_model(FeatureSet::Markers, 5, &[300, 300], 3, 9);
    let frames = random_frames(FeatureSet::Markers, 2000, 10);
    let reference: Vec<u32> = {
        let mut s = model.stream();
        frames
            .chunks_exact(18)
            .filter_map(|f| s.push(f).unwrap().map(<[f32]>::to_vec))
            .flatten()
            .map(f32::to_bits)
            .collect()
    };
    let results: Vec<(Vec<u32>, Vec<u32>)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..8)
            .map(|_| {
                scope.spawn(|| {
                    let mut s = model.stream();
                    let streamed = frames
                        .chunks_exact(18)
                        .filter_map(|f| s.push(f).unwrap().map(<[f32]>::to_vec))
                        .flatten()
                        .map(f32::to_bits)
                        .collect();
                    let mut batch = vec![0f32; model.n_predictions(2000) * 3];
                    model.predict(&frames, &mut batch).unwrap();
                    (streamed, batch.into_iter().map(f32::to_bits).collect())
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (streamed, batch) in results {
        assert_eq!(streamed, reference);
        assert_eq!(batch, reference, "batch = stream, bit for bit");
    }
}
