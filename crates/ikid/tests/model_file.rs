//! Model files: round trip, and every kind of bad file refused with an error naming the fault.

use ikid::model::{CARD_KEY, to_bytes};
use ikid::testing::{random_frames, random_model};
use ikid::{Error, FeatureSet, Model};
use safetensors::{Dtype, tensor::TensorView};
use std::collections::HashMap;

/// A tensor as (name, shape, f32 values).
type Tensor = (String, Vec<usize>, Vec<f32>);

fn model() -> Model {
    random_model(FeatureSet::Markers, 5, &[16, 12], 3, 5)
}

/// The model's tensors as (name, shape, f32 values) and its card as a JSON value, without its
/// checksum (as a file written before checksums: the structural checks below are reached).
fn parts(m: &Model) -> (Vec<Tensor>, serde_json::Value) {
    let bytes = m.to_bytes();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut tensors: Vec<_> = st
        .tensors()
        .into_iter()
        .map(|(n, t)| {
            let v = t.data().chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
            (n, t.shape().to_vec(), v)
        })
        .collect();
    tensors.sort_by(|a, b| a.0.cmp(&b.0));
    let mut card: serde_json::Value = serde_json::from_str(&m.card().to_json()).unwrap();
    card.as_object_mut().unwrap().remove("tensor_sha256");
    (tensors, card)
}

/// A SHA-256 written independently of the crate's (Python's hashlib computed the same bytes'
/// digest: the layout is documented on `tensor_sha256`), for a one-tensor file.
#[test]
fn the_checksum_is_sha256_of_the_documented_layout() {
    // name "a", 0, "F32", 0, dims [2] as u64 LE, byte length 8 as u64 LE, then 1.0f32, -2.0f32.
    let data: Vec<u8> = [1.0f32, -2.0].iter().flat_map(|x| x.to_le_bytes()).collect();
    let sum = ikid::model::tensor_sha256([("a", Dtype::F32, &[2usize][..], &data[..])]);
    // python3 -c "import hashlib,struct; print(hashlib.sha256(b'a\0F32\0'+struct.pack('<QQ',2,8)+struct.pack('<ff',1,-2)).hexdigest())"
    assert_eq!(sum, "51867837c40fa265b1e2c3a5e881cb02e9bb224acca5d6b39423c4cec52c3f0e");
}

#[test]
fn a_flipped_bit_in_any_tensor_is_refused_by_the_checksum() {
    let m = model();
    assert!(m.has_checksum() && m.card().tensor_sha256.is_some());
    let bytes = m.to_bytes();
    let header = 8 + u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    // The sign bit of a few values spread over the data section (every tensor's bytes).
    for at in [header + 3, header + (bytes.len() - header) / 2 + 3, bytes.len() - 1] {
        let mut bad = bytes.clone();
        bad[at] ^= 0x80;
        let err = load_err(&bad);
        assert!(matches!(err, Error::ChecksumMismatch { .. }), "byte {at}: {err}");
        assert_eq!(err.kind(), ikid::ErrorKind::ModelFile);
        assert!(err.to_string().contains("corrupt"), "{err}");
    }
    // A file without a checksum (written before they existed) is refused, saying how to add
    // one; it loads only when the caller opts in, and then says it has none.
    let (t, card) = parts(&m);
    let unchecked = build(&t, &card);
    let err = load_err(&unchecked);
    assert!(matches!(err, Error::MissingChecksum), "{err}");
    assert_eq!((err.kind(), err.code()), (ikid::ErrorKind::ModelFile, "missing_checksum"));
    assert!(err.to_string().contains("--restamp"), "{err}");
    let old = Model::from_bytes_allowing_unchecked(&unchecked).unwrap();
    assert!(!old.has_checksum());
    assert_eq!(old.mlp(), m.mlp());
    let dir = std::env::temp_dir().join(format!("ikid-unchecked-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("old.safetensors");
    std::fs::write(&path, &unchecked).unwrap();
    let err = Model::load(&path).unwrap_err();
    assert!(err.to_string().contains(&path.display().to_string()) && err.code() == "missing_checksum", "{err}");
    assert!(!Model::load_allowing_unchecked(&path).unwrap().has_checksum());
    // The opt-in is for a missing checksum only: a wrong one is refused all the same.
    let mut bad = bytes.clone();
    bad[header + 3] ^= 0x80;
    assert!(matches!(Model::from_bytes_allowing_unchecked(&bad), Err(Error::ChecksumMismatch { .. })));
    std::fs::remove_dir_all(&dir).unwrap();
    // A checksum that is not 64 hex digits is a card error, named.
    let mut card = card;
    card["tensor_sha256"] = "xyz".into();
    assert!(load_err(&build(&t, &card)).to_string().contains("tensor_sha256"));
}

fn build(tensors: &[Tensor], card: &serde_json::Value) -> Vec<u8> {
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|(n, s, v)| (n.clone(), s.clone(), v.iter().flat_map(|x| x.to_le_bytes()).collect()))
        .collect();
    let views: Vec<_> =
        bytes.iter().map(|(n, s, b)| (n.as_str(), TensorView::new(Dtype::F32, s.clone(), b).unwrap())).collect();
    safetensors::serialize(views, Some(HashMap::from([(CARD_KEY.to_string(), card.to_string())]))).unwrap()
}

fn load_err(bytes: &[u8]) -> Error {
    Model::from_bytes(bytes).expect_err("the file must be refused")
}

#[test]
fn save_and_load_round_trip() {
    let m = model();
    let dir = std::env::temp_dir().join(format!("ikid-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("m.safetensors");
    m.save(&path).unwrap();
    let back = Model::load(&path).unwrap();
    assert_eq!(back.card(), m.card());
    assert_eq!(back.mlp(), m.mlp());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn missing_file_names_the_path() {
    let err = Model::load("/nonexistent/wrist.safetensors").unwrap_err();
    assert!(matches!(err, Error::Io { .. }) && err.to_string().contains("/nonexistent/wrist.safetensors"), "{err}");
}

#[test]
fn truncated_file_is_refused() {
    let bytes = model().to_bytes();
    for cut in [0, 7, 100, bytes.len() / 2, bytes.len() - 1] {
        let err = load_err(&bytes[..cut]);
        assert!(matches!(err, Error::Container(_)), "cut at {cut}: {err}");
    }
}

#[test]
fn missing_tensor_is_named() {
    let (mut t, card) = parts(&model());
    t.retain(|(n, _, _)| n != "layers.1.bias");
    let err = load_err(&build(&t, &card));
    assert!(matches!(&err, Error::MissingTensor { name } if name == "layers.1.bias"), "{err}");
}

#[test]
fn extra_tensor_is_named() {
    let (mut t, card) = parts(&model());
    t.push(("layers.9.weight".into(), vec![1], vec![0.0]));
    let err = load_err(&build(&t, &card));
    assert!(matches!(&err, Error::UnexpectedTensor { name } if name == "layers.9.weight"), "{err}");
}

#[test]
fn shape_mismatch_is_named() {
    let (mut t, card) = parts(&model());
    let w = t.iter_mut().find(|(n, _, _)| n == "layers.1.weight").unwrap();
    w.1 = vec![12, 15];
    w.2.truncate(12 * 15);
    let err = load_err(&build(&t, &card));
    assert!(matches!(&err, Error::ShapeMismatch { name, .. } if name == "layers.1.weight"), "{err}");
    assert!(err.to_string().contains("[12, 15]") && err.to_string().contains("16"), "{err}");
}

#[test]
fn output_count_must_match_card() {
    let (t, mut card) = parts(&model());
    card["outputs"].as_array_mut().unwrap().pop();
    let err = load_err(&build(&t, &card));
    assert!(matches!(&err, Error::ShapeMismatch { name, .. } if name == "layers.2.weight"), "{err}");
}

#[test]
fn non_finite_weight_is_named() {
    let (mut t, card) = parts(&model());
    t.iter_mut().find(|(n, _, _)| n == "layers.0.weight").unwrap().2[5] = f32::NAN;
    let err = load_err(&build(&t, &card));
    assert!(matches!(&err, Error::NonFiniteWeight { name, index: 5, .. } if name == "layers.0.weight"), "{err}");
    let (mut t, card) = parts(&model());
    t.iter_mut().find(|(n, _, _)| n == "input.scale").unwrap().2[0] = f32::INFINITY;
    assert!(matches!(load_err(&build(&t, &card)), Error::NonFiniteWeight { .. }));
}

#[test]
fn wrong_dtype_is_named() {
    let m = model();
    let bytes = m.to_bytes();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let f64_data: Vec<u8> = st
        .tensor("output.shift")
        .unwrap()
        .data()
        .chunks_exact(4)
        .flat_map(|b| (f32::from_le_bytes(b.try_into().unwrap()) as f64).to_le_bytes())
        .collect();
    let mut views: Vec<(String, TensorView<'_>)> =
        st.tensors().into_iter().filter(|(n, _)| n != "output.shift").collect();
    views.push(("output.shift".into(), TensorView::new(Dtype::F64, vec![3], &f64_data).unwrap()));
    let (_, card) = parts(&m); // without the checksum, which the new bytes would fail first
    let meta = HashMap::from([(CARD_KEY.to_string(), card.to_string())]);
    let err = load_err(&safetensors::serialize(views, Some(meta)).unwrap());
    assert!(matches!(&err, Error::WrongDtype { name, .. } if name == "output.shift"), "{err}");
    assert!(err.to_string().contains("F64"), "{err}");
}

#[test]
fn card_problems_are_named() {
    let (t, card) = parts(&model());
    let with = |key: &str, value: serde_json::Value| {
        let mut c = card.clone();
        c[key] = value;
        load_err(&build(&t, &c))
    };
    assert!(matches!(with("format_version", 2.into()), Error::UnsupportedVersion { found: 2, supported: 1 }));
    assert!(matches!(with("feature_set", "pixels".into()), Error::UnknownFeatureSet { .. }));
    for (key, value, needle) in [
        ("window", serde_json::json!(0), "window"),
        ("format", serde_json::json!("onnx"), "format"),
        ("task", serde_json::json!("dance"), "task"),
        ("frame_rate_hz", serde_json::json!(-5.0), "frame_rate_hz"),
        ("predicted_frame", serde_json::json!("middle"), "predicted_frame"),
        ("activations", serde_json::json!(["relu", "gelu", "identity"]), "activations"),
        ("feature_names", serde_json::json!(["RSP.x"]), "feature_names"),
    ] {
        let err = with(key, value);
        assert!(matches!(err, Error::ModelCard(_)) && err.to_string().contains(needle), "{key}: {err}");
    }
    let mut c = card.clone();
    c.as_object_mut().unwrap().remove("window");
    assert!(load_err(&build(&t, &c)).to_string().contains("window"));
    let no_card = safetensors::serialize(Vec::<(&str, TensorView<'_>)>::new(), None).unwrap();
    assert!(load_err(&no_card).to_string().contains("no \"ikid\" key"));
}

#[test]
fn stream_fills_then_predicts_and_matches_batch_bit_for_bit() {
    let m = random_model(FeatureSet::Basis, 5, &[32, 32], 3, 9);
    let frames = random_frames(FeatureSet::Basis, 50, 10);
    let mut batch = vec![0f32; m.n_predictions(50) * 3];
    assert_eq!(m.predict(&frames, &mut batch).unwrap(), 46);
    let mut stream = m.stream();
    let mut streamed = Vec::new();
    for (i, f) in frames.chunks_exact(18).enumerate() {
        match stream.push(f).unwrap() {
            None => assert!(i < 4, "frame {i} gave nothing"),
            Some(out) => streamed.extend_from_slice(out),
        }
    }
    assert_eq!(
        streamed.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        batch.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    // And both match the plain nalgebra oracle on the same window.
    let mut features = vec![0f32; 50 * 24];
    FeatureSet::Basis.compute_rows(&frames, &mut features).unwrap();
    let want = m.mlp().forward_reference(&features[10 * 24..15 * 24]);
    assert_eq!(want.len(), 3, "the oracle gives one value per output");
    for (g, w) in batch[10 * 3..11 * 3].iter().zip(&want) {
        assert!((g - w).abs() <= 1e-5 * w.abs().max(1e-3), "{g} vs {w}");
    }
}

#[test]
fn refused_frame_leaves_the_window_unchanged() {
    let m = model();
    let frames = random_frames(FeatureSet::Markers, 8, 1);
    let mut a = m.stream();
    let mut b = m.stream();
    for f in frames.chunks_exact(18).take(6) {
        a.push(f).unwrap();
        b.push(f).unwrap();
        let mut bad = f.to_vec();
        bad[4] = f32::NAN;
        let err = b.push(&bad).unwrap_err();
        assert!(err.to_string().contains("USP.y"), "{err}");
        assert!(matches!(b.push(&f[..17]), Err(Error::FrameLength { found: 17, expected: 18, .. })));
    }
    let last = &frames[7 * 18..];
    assert_eq!(a.push(last).unwrap().map(<[f32]>::to_vec), b.push(last).unwrap().map(<[f32]>::to_vec));
}

#[test]
fn reset_forgets_the_window() {
    let m = model();
    let frames = random_frames(FeatureSet::Markers, 10, 1);
    let mut s = m.stream();
    for f in frames.chunks_exact(18).take(5) {
        s.push(f).unwrap();
    }
    s.reset();
    assert_eq!(s.filled(), 0);
    assert!(s.push(&frames[..18]).unwrap().is_none());
}

#[test]
fn predict_checks_its_buffers() {
    let m = model();
    let frames = random_frames(FeatureSet::Markers, 10, 1);
    assert!(matches!(m.predict(&frames[..17], &mut []), Err(Error::BadArgument { what: "frames", .. })));
    assert!(matches!(m.predict(&frames, &mut [0.0; 5]), Err(Error::BadArgument { what: "output buffer", .. })));
    assert_eq!(m.predict(&frames[..3 * 18], &mut []).unwrap(), 0);
    let mut bad = frames.clone();
    bad[6 * 18 + 2] = f32::NAN;
    let err = m.predict(&bad, &mut [0.0; 18]).unwrap_err();
    assert!(err.to_string().contains("frame 6") && err.to_string().contains("RSP.z"), "{err}");
}

#[test]
fn to_bytes_refuses_nothing_valid() {
    let m = model();
    assert_eq!(to_bytes(m.card(), m.mlp()).unwrap(), m.to_bytes());
}

#[test]
fn threaded_predict_is_bit_identical_to_single_threaded() {
    let m = random_model(FeatureSet::Relative, 5, &[48, 48], 3, 2);
    let frames = random_frames(FeatureSet::Relative, 2000, 3);
    let rows = m.n_predictions(2000);
    let run = |threads: usize| {
        let mut out = vec![0f32; rows * 3];
        m.predict_with_threads(&frames, &mut out, threads).unwrap();
        out.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    };
    let one = run(1);
    for threads in [2, 3, 8] {
        assert_eq!(run(threads), one, "{threads} threads");
    }
}

#[test]
fn threaded_predict_reports_the_earliest_bad_frame() {
    let m = random_model(FeatureSet::Markers, 5, &[16], 3, 2);
    let mut frames = random_frames(FeatureSet::Markers, 3000, 3);
    // Bad frames in several feature blocks: whichever thread meets one first, the error
    // names the earliest, as a serial pass does.
    for frame in [2900, 1700, 1234] {
        frames[frame * 18 + 4] = f32::NAN;
    }
    let mut out = vec![0f32; m.n_predictions(3000) * 3];
    for threads in [1, 2, 8] {
        let err = m.predict_with_threads(&frames, &mut out, threads).unwrap_err();
        assert!(matches!(err, Error::NonFiniteInput { frame: 1234, .. }), "{threads} threads: {err}");
    }
}

#[test]
fn push_many_equals_pushing_one_by_one() {
    let m = model();
    let frames = random_frames(FeatureSet::Markers, 23, 4);
    let mut one = m.stream();
    let want: Vec<f32> =
        frames.chunks_exact(18).filter_map(|f| one.push(f).unwrap().map(<[f32]>::to_vec)).flatten().collect();
    let mut many = m.stream();
    let mut got = Vec::new();
    // In packets of 3 frames: the first packets fill the window.
    for packet in frames.chunks(3 * 18) {
        let mut out = vec![0f32; many.rows_for(packet.len() / 18) * 3];
        let rows = many.push_many(packet, &mut out).unwrap();
        assert_eq!(rows * 3, out.len());
        got.extend(out);
    }
    assert_eq!(got, want);
    // An output buffer with room to spare is fine; one row short is refused before anything is
    // pushed, naming what it needed.
    let (mut roomy, mut short) = (m.stream(), m.stream());
    let rows = roomy.rows_for(23);
    let mut out = vec![0f32; (rows + 1) * 3];
    assert_eq!(roomy.push_many(&frames, &mut out).unwrap(), rows);
    assert_eq!(&out[..rows * 3], &want[..]);
    let err = short.push_many(&frames, &mut vec![0f32; (rows - 1) * 3]).unwrap_err().to_string();
    assert!(err.contains("output buffer") && err.contains(&format!("{rows} rows")), "{err}");
    assert_eq!(short.rows_for(23), rows, "nothing was pushed");
    let mut bad = frames[..4 * 18].to_vec();
    bad[2 * 18 + 5] = f32::NAN;
    let err = m.stream().push_many(&bad, &mut [0.0; 12]).unwrap_err();
    assert!(err.to_string().starts_with("frame 2: value USP.z"), "{err}");
}

#[test]
fn non_finite_predictions_are_errors_never_outputs() {
    // One linear layer summing its 90 inputs: 90 × 1e37 overflows f32.
    use ikid::net::{Activation, Affine, Dense, Mlp};
    use ikid::{ModelCard, OutputSpec};
    let layer = Dense {
        weight: nalgebra::DMatrix::from_element(3, 90, 1.0),
        bias: nalgebra::DVector::zeros(3),
        activation: Activation::Identity,
    };
    let mlp = Mlp::new(Affine::identity(90), vec![layer], Affine::identity(3)).unwrap();
    let outputs = (0..3).map(|i| OutputSpec { name: format!("o{i}"), unit: "rad".into() }).collect();
    // Joint-state frames (9 values): marker frames this large would be refused before the
    // network as no arm's.
    let card = ModelCard::new("sum", "id", FeatureSet::JointState, 10, 1000.0, outputs, &[Activation::Identity]);
    let m = Model::from_parts(card, mlp).unwrap();
    let frames = vec![1.0e37f32; 12 * 9];
    let err = m.predict(&frames, &mut [0.0; 3 * 3]).unwrap_err();
    assert!(matches!(err, Error::NonFiniteOutput { frame: 9, .. }), "{err}");
    let mut s = m.stream();
    let mut last = None;
    for f in frames.chunks_exact(9) {
        last = Some(s.push(f).map(|o| o.is_some()));
    }
    assert!(matches!(last, Some(Err(Error::NonFiniteOutput { .. }))));
}

#[test]
fn scaling_that_overflows_once_folded_is_refused() {
    let (mut t, card) = parts(&model());
    t.iter_mut().find(|(n, _, _)| n == "input.scale").unwrap().2[0] = 1.0e30;
    t.iter_mut().find(|(n, _, _)| n == "layers.0.weight").unwrap().2.iter_mut().for_each(|w| *w = 1.0e10);
    let err = load_err(&build(&t, &card));
    assert!(matches!(&err, Error::NonFiniteWeight { name, .. } if name.contains("folded")), "{err}");
}

#[test]
fn output_offset_adds_the_newest_frames_angles_in_stream_and_batch() {
    let plain = random_model(FeatureSet::Angles, 6, &[16], 3, 21);
    let mut card = plain.card().clone();
    card.output_offset = Some(ikid::model::NEWEST_FEATURES.into());
    let offset = Model::from_parts(card, plain.mlp().clone()).unwrap();
    assert!(offset.adds_newest_features() && !plain.adds_newest_features());
    let n = 3000; // > one block of rows, so the batch path and the remainder path both run
    let frames = random_frames(FeatureSet::Angles, n, 22);
    let rows = offset.n_predictions(n);
    let (mut a, mut b) = (vec![0f32; rows * 3], vec![0f32; rows * 3]);
    plain.predict(&frames, &mut a).unwrap();
    offset.predict(&frames, &mut b).unwrap();
    let mut angles = vec![0f32; n * 3];
    FeatureSet::Angles.compute_rows(&frames, &mut angles).unwrap();
    for r in 0..rows {
        for k in 0..3 {
            let want = a[r * 3 + k] + angles[(r + 5) * 3 + k];
            assert_eq!(b[r * 3 + k].to_bits(), want.to_bits(), "row {r} output {k}");
        }
    }
    let mut stream = offset.stream();
    let streamed: Vec<f32> =
        frames.chunks_exact(18).filter_map(|f| stream.push(f).unwrap().map(<[f32]>::to_vec)).flatten().collect();
    assert_eq!(
        streamed.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        b.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    // It survives a save/load round trip.
    assert!(Model::from_bytes(&offset.to_bytes()).unwrap().adds_newest_features());
}

#[test]
fn output_offset_is_checked_against_the_features() {
    let (t, mut card) = parts(&model()); // markers: feature 0 is RSP.x, not an angle
    card["output_offset"] = "newest_features".into();
    let err = load_err(&build(&t, &card)).to_string();
    assert!(err.contains("output_offset") && err.contains("RSP.x") && err.contains("same quantity"), "{err}");
    card["output_offset"] = "oldest".into();
    assert!(load_err(&build(&t, &card)).to_string().contains("\"oldest\""));
}

#[test]
fn load_refuses_what_is_not_a_bounded_regular_file_without_reading_it() {
    let dir = std::env::temp_dir().join(format!("ikid-bounded-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A directory, /dev/zero (endless), a named pipe (would block) and a 4 GB sparse file.
    let fifo = dir.join("fifo");
    let _ = std::fs::remove_file(&fifo);
    let made_fifo = std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
    let sparse = dir.join("huge.safetensors");
    std::fs::File::create(&sparse).unwrap().set_len(4 << 30).unwrap();
    let mut cases = vec![
        (dir.clone(), "a directory"),
        ("/dev/zero".into(), "not a regular file"),
        (sparse.clone(), "4294967296 bytes"),
    ];
    if made_fifo {
        cases.push((fifo.clone(), "not a regular file"));
    }
    for (path, says) in cases {
        let started = std::time::Instant::now();
        let err = Model::load(&path).unwrap_err();
        assert!(matches!(err, Error::Io { .. }), "{err}");
        assert_eq!(err.kind(), ikid::ErrorKind::Io);
        let message = err.to_string();
        assert!(message.contains(&path.display().to_string()) && message.contains(says), "{message}");
        assert!(started.elapsed().as_secs_f64() < 1.0, "{} took {:?}", path.display(), started.elapsed());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
