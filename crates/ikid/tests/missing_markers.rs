//! The missing-marker policy end to end: the model card's field, the stream, batch prediction.

use ikid::testing::{random_frames, random_model};
use ikid::{Error, FeatureSet, MissingMarkers, Model};

fn with_policy(model: &Model, policy: &str) -> ikid::Result<Model> {
    let mut card = model.card().clone();
    card.missing_markers = policy.into();
    Model::from_parts(card, model.mlp().clone())
}

/// 400 frames; from frame 100 on, every fourth frame loses one marker (in turn).
fn occluded_frames() -> (Vec<f32>, Vec<usize>) {
    let mut frames = random_frames(FeatureSet::Angles, 400, 11);
    let mut hit = vec![];
    for (i, frame) in frames.chunks_exact_mut(18).enumerate().skip(100).step_by(4) {
        frame[3 * (i % 6)..3 * (i % 6) + 3].fill(f32::NAN);
        hit.push(i);
    }
    (frames, hit)
}

#[test]
fn the_card_says_the_policy_and_the_loader_checks_it() {
    let base = random_model(FeatureSet::Angles, 5, &[16], 3, 1);
    assert_eq!(base.missing_markers(), MissingMarkers::Refuse, "absent field = refuse");
    let fill = with_policy(&base, "fill").unwrap();
    let reloaded = Model::from_bytes(&fill.to_bytes()).unwrap();
    assert_eq!(reloaded.missing_markers(), MissingMarkers::Fill);
    assert_eq!(reloaded.stream().missing_markers(), MissingMarkers::Fill);

    let err = with_policy(&base, "guess").unwrap_err().to_string();
    assert!(err.contains("missing_markers") && err.contains("guess") && err.contains("fill"), "{err}");
    let id = random_model(FeatureSet::JointState, 5, &[16], 3, 1);
    let err = with_policy(&id, "fill").unwrap_err().to_string();
    assert!(err.contains("missing_markers") && err.contains("joint_state"), "{err}");
    let err = id.stream().set_missing_markers(MissingMarkers::Fill).unwrap_err().to_string();
    assert!(err.contains("joint_state"), "{err}");
}

#[test]
fn a_fill_stream_fills_flags_and_equals_batch_prediction() {
    let model = with_policy(&random_model(FeatureSet::Angles, 5, &[32, 32], 3, 2), "fill").unwrap();
    let (frames, hit) = occluded_frames();
    let mut stream = model.stream();
    let mut streamed = vec![];
    for (i, frame) in frames.chunks_exact(18).enumerate() {
        if let Some(out) = stream.push(frame).unwrap_or_else(|e| panic!("frame {i}: {e}")) {
            streamed.extend_from_slice(out);
        }
        let expect_mask = if hit.contains(&i) { 1u8 << (i % 6) } else { 0 };
        assert_eq!(stream.filled_markers(), expect_mask, "frame {i}");
    }
    let mut batch = vec![0f32; model.n_predictions(400) * 3];
    model.predict(&frames, &mut batch).unwrap();
    assert_eq!(streamed, batch, "stream and batch must agree bit for bit");
    // push_many fills too, and agrees.
    let mut many = vec![0f32; batch.len()];
    let rows = model.stream().push_many(&frames, &mut many).unwrap();
    assert_eq!((rows, &many), (396, &batch));
}

#[test]
fn refuse_policy_refuses_and_unfillable_frames_leave_the_stream_as_it_was() {
    let fill = with_policy(&random_model(FeatureSet::Angles, 5, &[32], 3, 3), "fill").unwrap();
    let (frames, _) = occluded_frames();
    let first_gap = &frames[100 * 18..101 * 18];

    let mut refusing = fill.stream();
    refusing.set_missing_markers(MissingMarkers::Refuse).unwrap();
    for frame in frames[..100 * 18].chunks_exact(18) {
        refusing.push(frame).unwrap();
    }
    assert!(matches!(refusing.push(first_gap), Err(Error::NonFiniteInput { .. })));

    let mut stream = fill.stream();
    for frame in frames[..100 * 18].chunks_exact(18) {
        stream.push(frame).unwrap();
    }
    let mut two_gone = frames[100 * 18..101 * 18].to_vec();
    two_gone[..6].fill(f32::NAN); // RSP and USP
    let err = stream.push(&two_gone).unwrap_err().to_string();
    assert!(err.contains("RSP, USP") && err.contains("only one"), "{err}");
    // The refused frame changed nothing: the next frames give what a stream that never saw it gives.
    let mut clean = fill.stream();
    for frame in frames[..100 * 18].chunks_exact(18) {
        clean.push(frame).unwrap();
    }
    for frame in frames[100 * 18..120 * 18].chunks_exact(18) {
        assert_eq!(stream.push(frame).unwrap().map(<[f32]>::to_vec), clean.push(frame).unwrap().map(<[f32]>::to_vec));
    }
}

#[test]
fn a_gap_in_time_restarts_the_window_and_backwards_time_is_refused() {
    let model = random_model(FeatureSet::Angles, 5, &[16], 3, 4); // 1000 Hz
    let frames = random_frames(FeatureSet::Angles, 20, 12);
    let mut stream = model.stream();
    let mut outputs = vec![];
    for (i, frame) in frames.chunks_exact(18).enumerate() {
        // Frames 0-9 at 1 ms, then 3 frames dropped (frame 10 arrives at 13 ms).
        let t = if i < 10 { i as f64 * 1e-3 } else { (i + 3) as f64 * 1e-3 };
        outputs.push(stream.push_at(t, frame).unwrap().is_some());
    }
    let expect: Vec<bool> = (0..20).map(|i| (4..10).contains(&i) || i >= 14).collect();
    assert_eq!(outputs, expect, "no output until the window refills after the gap");
    assert_eq!(stream.gap_restarts(), 1);
    let err = stream.push_at(0.019, &frames[..18]).unwrap_err().to_string();
    assert!(err.contains("time") && err.contains("does not follow"), "{err}");
    assert!(stream.push_at(f64::NAN, &frames[..18]).is_err());
}

#[test]
fn frames_from_a_faster_source_are_refused_not_mistimed() {
    let model = random_model(FeatureSet::Angles, 5, &[16], 3, 4); // 1000 Hz
    let frames = random_frames(FeatureSet::Angles, 4, 12);
    let mut stream = model.stream();
    stream.push_at(0.0, &frames[..18]).unwrap();
    // A 2.5 kHz source: the next frame 0.4 ms later.
    let err = stream.push_at(0.0004, &frames[18..36]).unwrap_err().to_string();
    assert!(
        err.contains("1000 Hz") && err.contains("resample") && err.contains("0.400 ms after the previous"),
        "{err}"
    );
    // Jitter within half a period is accepted.
    assert!(stream.push_at(0.0009, &frames[18..36]).is_ok());
    assert!(stream.push_at(0.0021, &frames[36..54]).is_ok());
    assert_eq!(stream.gap_restarts(), 0, "1.2 periods is jitter, not a gap");
}

#[test]
fn a_gap_in_time_restarts_the_window_once() {
    let model = random_model(FeatureSet::Angles, 5, &[16], 3, 4); // 1000 Hz, window 5
    let frames = random_frames(FeatureSet::Angles, 20, 13);
    let mut stream = model.stream();
    let mut outputs = vec![];
    for (i, frame) in frames.chunks_exact(18).enumerate() {
        // Frames 8.. come after a 6 ms gap (5 frames dropped).
        let t = if i < 8 { i as f64 * 1e-3 } else { (i + 5) as f64 * 1e-3 };
        outputs.push(stream.push_at(t, frame).unwrap().is_some());
    }
    assert_eq!(stream.gap_restarts(), 1);
    // Outputs from frame 4; none while the window refills after the gap (frames 8-11).
    let expect: Vec<bool> = (0..20).map(|i| (4..8).contains(&i) || i >= 12).collect();
    assert_eq!(outputs, expect);
}

#[test]
fn stream_errors_name_the_frame_by_its_number_in_the_stream() {
    let model = random_model(FeatureSet::Angles, 5, &[16], 3, 3);
    let mut frames = random_frames(FeatureSet::Angles, 40, 6);
    frames[30 * 18 + 13] = f32::NAN; // MC5.y of frame 30
    let mut stream = model.stream();
    for (i, frame) in frames.chunks_exact(18).enumerate() {
        match stream.push(frame) {
            Err(e) => {
                assert_eq!(i, 30, "{e}");
                assert_eq!((e.frame(), e.code(), e.markers()), (Some(30), "non_finite_input", vec!["MC5"]));
                assert!(e.to_string().starts_with("frame 30: value MC5.y"), "{e}");
            }
            Ok(_) => assert_ne!(i, 30),
        }
    }
    assert_eq!(stream.frames_pushed(), 40);
    // Frames refused for their time stamp count too.
    let mut timed = model.stream();
    timed.push_at(0.0, &frames[..18]).unwrap();
    assert!(timed.push_at(0.0, &frames[18..36]).is_err());
    let err = timed.push_at(0.001, &frames[30 * 18..31 * 18]).unwrap_err();
    assert_eq!(err.frame(), Some(2), "{err}");
}

#[test]
fn push_many_refusing_a_frame_part_way_keeps_the_rows_of_the_frames_before_it() {
    // Frame 150 loses two markers (unfillable): the 146 rows of frames 4-149 were computed and
    // stay in `out`, equal to what frame-by-frame pushes give (the oracle).
    let fill = with_policy(&random_model(FeatureSet::Angles, 5, &[32], 3, 3), "fill").unwrap();
    let (mut frames, _) = occluded_frames();
    frames[150 * 18..150 * 18 + 6].fill(f32::NAN); // RSP and USP
    let mut one_by_one = fill.stream();
    let mut want = vec![];
    for frame in frames[..150 * 18].chunks_exact(18) {
        if let Some(o) = one_by_one.push(frame).unwrap() {
            want.extend_from_slice(o);
        }
    }
    let mut stream = fill.stream();
    let mut out = vec![f32::NAN; stream.rows_for(400) * 3];
    let err = stream.push_many(&frames, &mut out).unwrap_err();
    assert!(err.to_string().contains("frame 150") && err.to_string().contains("RSP, USP"), "{err}");
    assert_eq!(stream.rows_before_refusal(), 146);
    assert_eq!(&out[..146 * 3], &want[..]);
    // A block refused whole (a missing value under the refuse policy) wrote none.
    let mut refusing = fill.stream();
    refusing.set_missing_markers(MissingMarkers::Refuse).unwrap();
    assert!(refusing.push_many(&frames, &mut out).is_err());
    assert_eq!(refusing.rows_before_refusal(), 0);
    // And a block pushed whole says 0 too.
    assert_eq!(stream.push_many(&frames[151 * 18..160 * 18], &mut out).unwrap(), 9);
    assert_eq!(stream.rows_before_refusal(), 0);
}
