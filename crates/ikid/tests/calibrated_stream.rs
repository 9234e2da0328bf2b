//! A stream's calibration and last output, as a user of the Rust API sees them: the
//! calibration moves every frame before the network reads it (the same as calibrating the
//! frames first, each segment fitted to the marker shapes of the first frames), and
//! `output()` is what the last push returned.

use ikid::testing::{random_frames, random_model};
use ikid::{Calibration, FeatureSet, MarkerShapes};
use nalgebra::{Matrix3, Rotation3, Vector3};

/// A placement 12° and 20° away from the body model's, about skew axes.
fn a_subjects_calibration() -> Calibration {
    let model = Calibration::body_model();
    let turn = |axis: [f64; 3], deg: f64| {
        Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::from(axis)), deg.to_radians())
    };
    let forearm: Matrix3<f64> = (turn([1.0, 2.0, 0.5], 12.0) * model.forearm).into_inner();
    let hand: Matrix3<f64> = (turn([-0.3, 1.0, 2.0], 20.0) * model.hand).into_inner();
    Calibration::from_matrices(forearm, hand).unwrap()
}

#[test]
fn a_calibrated_stream_equals_an_uncalibrated_one_on_calibrated_frames() {
    let model = random_model(FeatureSet::Angles, 5, &[24], 3, 9);
    let cal = a_subjects_calibration();
    let frames = random_frames(FeatureSet::Angles, 60, 4);
    let mut calibrated = model.stream();
    calibrated.set_calibration(Some(cal)).unwrap();
    assert_eq!(calibrated.calibration(), Some(&cal));
    let (mut plain, mut raw) = (model.stream(), model.stream());
    let mut differs = 0;
    let mut shapes = MarkerShapes::new(model.card().frame_rate_hz);
    for (i, frame) in frames.chunks_exact(18).enumerate() {
        let mut moved = frame.to_vec();
        cal.apply_fitted(&mut moved, i, &mut shapes, true).unwrap();
        let got = calibrated.push(frame).unwrap().map(<[f32]>::to_vec);
        let want = plain.push(&moved).unwrap().map(<[f32]>::to_vec);
        assert_eq!(got, want, "frame {i}");
        let uncalibrated = raw.push(frame).unwrap().map(<[f32]>::to_vec);
        if let (Some(g), Some(u)) = (&got, &uncalibrated) {
            differs += usize::from(g.iter().zip(u).any(|(a, b)| (a - b).abs() > 1e-3));
        }
    }
    assert_eq!(differs, 56, "every output must change with a 12-20° placement difference");
    // None goes back to the markers as they come.
    calibrated.set_calibration(None).unwrap();
    assert!(calibrated.calibration().is_none());
}

#[test]
fn a_calibrated_stream_learns_its_marker_shapes_from_the_frames_as_measured() {
    // Markers that are not rigid (up to 0.5 mm off, each): a segment fitted to the shapes learned
    // from the frames differs from its technical frame, so the stream equals the calibrated
    // frames only if it learns the shapes from its own frames (none of which is filled). With
    // the gap filler on: it passes on which frames are as measured.
    let model = random_model(FeatureSet::Angles, 5, &[24], 3, 9);
    let cal = a_subjects_calibration();
    // A smooth movement, as the gap filler (which the shapes' learning follows) expects.
    let body = ikid::body::BodyModel::default();
    let mut frames: Vec<f32> = (0..60)
        .flat_map(|i| {
            let t = f64::from(i) / model.card().frame_rate_hz;
            let q = [0.6 * (3.0 * t).sin(), 0.5 * (2.0 * t).cos(), 0.2 * (4.0 * t).sin()];
            body.marker_frame(&q, &body.forearm_pose(0.2)).map(|v| v as f32)
        })
        .collect();
    let mut state = 0x9E37_79B9_7F4A_7C15_u64;
    for v in &mut frames {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        *v += 5e-4 * ((state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0);
    }
    let mut calibrated = model.stream();
    calibrated.set_missing_markers(ikid::MissingMarkers::Fill).unwrap();
    calibrated.set_calibration(Some(cal)).unwrap();
    let (mut learned, mut unlearned) = (model.stream(), model.stream());
    let (mut shapes, mut never) =
        (MarkerShapes::new(model.card().frame_rate_hz), MarkerShapes::new(model.card().frame_rate_hz));
    let mut differs = 0;
    for (i, frame) in frames.chunks_exact(18).enumerate() {
        let (mut fitted, mut built) = (frame.to_vec(), frame.to_vec());
        cal.apply_fitted(&mut fitted, i, &mut shapes, true).unwrap();
        cal.apply_fitted(&mut built, i, &mut never, false).unwrap();
        let got = calibrated.push(frame).unwrap().map(<[f32]>::to_vec);
        assert_eq!(got, learned.push(&fitted).unwrap().map(<[f32]>::to_vec), "frame {i}");
        let other = unlearned.push(&built).unwrap().map(<[f32]>::to_vec);
        if let (Some(g), Some(o)) = (&got, &other) {
            differs += usize::from(g.iter().zip(o).any(|(a, b)| (a - b).abs() > 1e-6));
        }
    }
    assert_eq!(never.frames(), [0, 0]);
    assert!(differs > 40, "the shapes' fit must matter here: {differs} of 56 outputs differ");
}

#[test]
fn a_joint_state_stream_refuses_a_calibration() {
    let mut stream = random_model(FeatureSet::JointState, 5, &[8], 3, 1).stream();
    let err = stream.set_calibration(Some(a_subjects_calibration())).unwrap_err().to_string();
    assert!(err.contains("calibration") && err.contains("joint_state"), "{err}");
    stream.set_calibration(None).unwrap();
}

#[test]
fn output_is_the_last_prediction_and_equals_batch_prediction() {
    let model = random_model(FeatureSet::Relative, 4, &[16, 16], 3, 5);
    let frames = random_frames(FeatureSet::Relative, 30, 8);
    let mut batch = vec![0f32; model.n_predictions(30) * 3];
    assert_eq!(model.predict(&frames, &mut batch).unwrap(), 27);
    let mut stream = model.stream();
    for (i, frame) in frames.chunks_exact(18).enumerate() {
        let pushed = stream.push(frame).unwrap().map(<[f32]>::to_vec);
        if i >= 3 {
            let pushed = pushed.expect("window full");
            assert_eq!(stream.output(), &pushed[..], "frame {i}");
            assert_eq!(stream.output(), &batch[(i - 3) * 3..(i - 2) * 3], "frame {i}");
        } else {
            assert!(pushed.is_none());
        }
    }
}

#[test]
fn a_calibrated_stream_fills_a_missing_marker_from_its_first_complete_frame() {
    // Uncalibrated, the filler must first see the wrist move about every axis to locate the
    // joint centre; a calibration says where it is, so the second frame can already be filled.
    let model = random_model(FeatureSet::Angles, 1, &[8], 3, 10);
    let body = ikid::body::BodyModel::default();
    let frame = |q: [f64; 3]| body.marker_frame(&q, &body.forearm_pose(0.2)).map(|v| v as f32);
    let first = frame([0.1, 0.2, -0.1]);
    let mut second = frame([0.12, 0.22, -0.1]);
    let truth = second;
    second[9..12].fill(f32::NAN); // MC2 missing
    for calibrated in [false, true] {
        let mut stream = model.stream();
        stream.set_missing_markers(ikid::MissingMarkers::Fill).unwrap();
        if calibrated {
            stream.set_calibration(Some(Calibration::body_model())).unwrap();
        }
        stream.push(&first).unwrap();
        let got = stream.push(&second);
        assert_eq!(got.is_ok(), calibrated, "calibrated {calibrated}: {:?}", got.err());
        if calibrated {
            assert_eq!(stream.filled_markers(), 0b000_1000);
            // Where the stream's filler put MC2: within a millimetre of the truth.
            let mut filler = ikid::GapFiller::at_rate(1000.0);
            filler.set_calibration(Some(&Calibration::body_model()));
            let mut a = first;
            filler.fill(&mut a, 0).unwrap();
            let mut b = second;
            filler.fill(&mut b, 1).unwrap();
            let off = (0..3).map(|k| (b[9 + k] - truth[9 + k]).powi(2)).sum::<f32>().sqrt();
            assert!(off < 1e-3, "MC2 filled {off} m from the truth");
        }
    }
}
