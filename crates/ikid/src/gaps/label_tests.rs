//! The gap filler's labels, refusals and fills in the cases `make mutants` found untested:
//! a label handed to a missing marker's place, a swap that ends while a marker is missing,
//! a swap while the whole arm accelerates, jumps that `fill_gaps` keeps missing, and a hand
//! that starts to move in the frame its marker drops. Expected values are the body model's
//! true marker positions and labels set by hand.

use super::*;
use crate::body::BodyModel;

/// Wrist motion about every axis at a shoulder pose, `dt` seconds a frame, `wrist` times as
/// fast as [`gaps::tests`](super::tests)' trial, the whole arm shifted by `shift(t)` (metres, lab).
fn frames(body: &BodyModel, n: usize, dt: f64, wrist: f64, shift: impl Fn(f64) -> Vector3<f64>) -> Vec<[f32; 18]> {
    let pose = body.forearm_pose(0.2);
    (0..n)
        .map(|i| {
            let t = i as f64 * dt;
            let w = wrist * t;
            let q = [0.8 * (1.3 * w).sin(), 0.6 * (0.7 * w + 1.0).sin(), 0.3 * (2.1 * w + 0.5).sin()];
            let mut p = pose;
            p.translation.vector += shift(t);
            body.marker_frame(&q, &p).map(|v| v as f32)
        })
        .collect()
}

/// A filler at `rate_hz` that has filled (learned from) `frames[..n]`, all complete.
fn learned(frames: &[[f32; 18]], n: usize, rate_hz: f64) -> GapFiller {
    let mut filler = GapFiller::at_rate(rate_hz);
    for (i, f) in frames[..n].iter().enumerate() {
        assert_eq!(filler.fill(&mut f.clone(), i).unwrap(), 0, "frame {i}");
    }
    filler
}

fn max_error(a: &[f32; 18], b: &[f32; 18]) -> f32 {
    (0..18).map(|k| (a[k] - b[k]).abs()).fold(0.0, f32::max)
}

#[test]
fn a_label_given_no_marker_takes_the_first_marker_no_label_was_given() {
    // By hand: markers 0, 1, 3, 4, 5 are taken, so label 2 gets marker 2; with labels 0 and 4
    // given none, markers 2 and 4 are free and go to them in order.
    assert_eq!(as_permutation([1, 0, NO_MARKER, 3, 4, 5]), [1, 0, 2, 3, 4, 5]);
    assert_eq!(as_permutation([NO_MARKER, 0, 1, 3, NO_MARKER, 5]), [2, 0, 1, 3, 4, 5]);
    assert_eq!(as_permutation([5, 4, 3, 2, 1, 0]), [5, 4, 3, 2, 1, 0]);
}

#[test]
fn a_marker_under_a_missing_markers_label_is_put_back_and_its_own_filled() {
    // MC5's position comes labelled MC2, and MC5 is missing (the labeller gave MC5 the wrong
    // name while MC2 was hidden): MC5 is put back under its own label, MC2 filled, both near
    // the truth, the frame flagged swapped and filled, and MC5's label names the marker that
    // came as MC2.
    let body = BodyModel::default();
    let truth = frames(&body, 400, 0.01, 1.0, |_| Vector3::zeros());
    let mut filler = learned(&truth, 300, 100.0);
    let mut f = truth[300];
    f[9..12].copy_from_slice(&truth[300][12..15]);
    f[12..15].fill(f32::NAN);
    assert_eq!(filler.fill(&mut f, 300).unwrap(), 1 << 3);
    assert_eq!(filler.status(), status::SWAPPED | status::FILLED);
    assert_eq!(filler.labels(), [0, 1, 2, NO_MARKER, 3, 5]);
    assert!(max_error(&f, &truth[300]) < 5e-4, "{} mm", 1e3 * max_error(&f, &truth[300]));
}

#[test]
fn a_swap_that_ends_as_a_marker_drops_is_not_flagged() {
    // MC2 and MC5 swap labels for ten frames; the frame in which the labels come right again
    // also loses FAP. The markers are then under their own labels as they came: only the fill
    // is flagged, each label names its own marker (FAP's none), and the frame is the truth.
    let body = BodyModel::default();
    let truth = frames(&body, 400, 0.01, 1.0, |_| Vector3::zeros());
    let mut filler = learned(&truth, 300, 100.0);
    for (i, t) in truth.iter().enumerate().take(310).skip(300) {
        let mut f = *t;
        for k in 0..3 {
            f.swap(9 + k, 12 + k);
        }
        assert_eq!(filler.fill(&mut f, i).unwrap(), 0, "frame {i}");
        assert_eq!(filler.status(), status::SWAPPED, "frame {i}");
    }
    let mut f = truth[310];
    f[6..9].fill(f32::NAN);
    assert_eq!(filler.fill(&mut f, 310).unwrap(), 1 << 2);
    assert_eq!(filler.status(), status::FILLED);
    assert_eq!(filler.labels(), [0, 1, NO_MARKER, 3, 4, 5]);
    assert!(max_error(&f, &truth[310]) < 5e-4, "{} mm", 1e3 * max_error(&f, &truth[310]));
    // And the swap is over: the next frame is taken as it comes.
    assert_eq!(filler.fill(&mut truth[311].clone(), 311).unwrap(), 0);
    assert_eq!(filler.status(), 0);
    assert_eq!(filler.labels(), IDENTITY_LABELS);
}

#[test]
fn a_swap_while_the_whole_arm_accelerates_is_put_right() {
    // At 25 Hz the whole arm sways ±20 cm at 1.5 Hz (a wheelchair racer's push) and the wrist
    // turns up to 4 rad/s: between frames a marker strays up to 28 mm from where its velocity
    // took it, so in the frames swapped here where MC2 and MC5 were heading in the lab cannot
    // tell them apart (by hand below: neither nearer its own lab prediction than SWAP_RATIO of
    // the other's); where they were heading in the forearm's frame, velocity there included
    // (up to 10 mm a frame), can. Each swapped frame must come back as the truth, bit for bit,
    // flagged swapped.
    let body = BodyModel::default();
    let omega = 2.0 * std::f64::consts::PI * 1.5;
    let truth = frames(&body, 800, 0.04, 3.0, |t| Vector3::new(0.2 * (omega * t).sin(), 0.0, 0.0));
    let mut filler = learned(&truth, 500, 25.0);
    let lab_tells = |i: usize| {
        let heading = |m: usize| 2.0 * marker(&truth[i - 1], m) - marker(&truth[i - 2], m);
        let fits = |from: usize, to: usize| {
            let here = marker(&truth[i], from);
            (here - heading(from)).norm() <= SWAP_RATIO * (here - heading(to)).norm()
        };
        fits(3, 4) && fits(4, 3)
    };
    let mut put_right = 0;
    for (i, t) in truth.iter().enumerate().skip(500) {
        let mut f = *t;
        let swap = i % 3 == 0 && !lab_tells(i);
        if swap {
            for k in 0..3 {
                f.swap(9 + k, 12 + k);
            }
        }
        assert_eq!(filler.fill(&mut f, i).unwrap(), 0, "frame {i}");
        assert_eq!(filler.status(), if swap { status::SWAPPED } else { 0 }, "frame {i}");
        assert_eq!(f.map(f32::to_bits), t.map(f32::to_bits), "frame {i}");
        put_right += usize::from(swap);
    }
    assert!(put_right >= 20, "{put_right} frames swapped where the lab's prediction cannot tell");
}

#[test]
fn fill_gaps_keeps_markers_that_jumped_and_could_not_be_filled_missing() {
    // MC2 and MCB both jump 2 cm in one frame (the hand then has one marker it can trust: no
    // fill): kept, that frame has exactly those two missing, the rest as measured; without
    // keep_unfillable the run stops there naming them.
    let body = BodyModel::default();
    let truth: Vec<[f32; 18]> = frames(&body, 400, 0.01, 1.0, |_| Vector3::zeros());
    for jumped in [[3, 5], [0, 2]] {
        let mut recording: Vec<f32> = truth.iter().flatten().copied().collect();
        let at = 350 * 18;
        for (m, axis) in jumped.into_iter().zip([0, 1]) {
            recording[at + 3 * m + axis] += 0.02;
        }
        let (filled, masks) = fill_gaps(&recording, true, 100.0).unwrap();
        assert!(masks.iter().all(|&m| m == 0));
        for m in 0..N_MARKERS {
            let cell = &filled[at + 3 * m..at + 3 * m + 3];
            if jumped.contains(&m) {
                assert!(cell.iter().all(|v| v.is_nan()), "{jumped:?}: marker {m} {cell:?}");
            } else {
                assert_eq!(cell, &recording[at + 3 * m..at + 3 * m + 3], "{jumped:?}: marker {m}");
            }
        }
        // The frames after it are untouched.
        assert_eq!(filled[at + 18..], recording[at + 18..]);
        let err = fill_gaps(&recording, false, 100.0).unwrap_err();
        assert!(matches!(err, Error::OutlierMarker { frame: 350, .. }), "{err}");
    }
}

#[test]
fn a_hand_that_starts_moving_as_its_marker_drops_is_not_held_where_it_was() {
    // A calibrated filler (it fills from the first frame) sees the hand held still for a
    // second, then the wrist flexes 6° in one 10-ms frame in which MC5 is missing. Its
    // last position, which a still hand would keep, is no guide now: the visible markers
    // say the hand moved, and the fill must follow them (the truth within 0.1 mm, where
    // holding MC5 near its old place would cost millimetres).
    let body = BodyModel::default();
    let pose = body.forearm_pose(0.2);
    let still = body.marker_frame(&[0.0; 3], &pose).map(|v| v as f32);
    let moved = body.marker_frame(&[0.1, 0.0, 0.0], &pose).map(|v| v as f32);
    let mut filler = GapFiller::at_rate(100.0);
    filler.set_calibration(Some(&Calibration::body_model()));
    for i in 0..100 {
        assert_eq!(filler.fill(&mut still.clone(), i).unwrap(), 0);
    }
    let mut f = moved;
    f[12..15].fill(f32::NAN);
    assert_eq!(filler.fill(&mut f, 100).unwrap(), 1 << 4);
    let err = max_error(&f, &moved);
    assert!(err < 1e-4, "MC5 {} mm from the truth", 1e3 * err);
}

#[test]
fn a_jump_the_arms_motion_would_hide_is_caught_by_the_marker_distances() {
    // The swaying arm of the racer above, markers with ±0.5 mm noise: they move ~5 cm a frame,
    // so a 2-cm jump of MC5 is well within what its motion allows; its distances to MC2 and
    // MCB, each constant to the noise (σ ≈ 0.4 mm, the floor of 5 mm is the limit), change by
    // more than the floor (by hand below). The jump must be dropped, filled near the truth
    // and flagged.
    let body = BodyModel::default();
    let omega = 2.0 * std::f64::consts::PI * 1.5;
    let truth = frames(&body, 600, 0.04, 1.0, |t| Vector3::new(0.2 * (omega * t).sin(), 0.0, 0.0));
    let mut rng = crate::rng::SplitMix::new(11);
    let noisy: Vec<[f32; 18]> = truth.iter().map(|f| f.map(|v| v + rng.uniform(-5e-4, 5e-4) as f32)).collect();
    let mut filler = learned(&noisy, 500, 25.0);
    let t = truth[500];
    let mut f = noisy[500];
    let hand = (marker(&t, 3) + marker(&t, 4) + marker(&t, 5)) / 3.0;
    let out = (marker(&t, 4) - hand).normalize() * 0.02;
    for a in 0..3 {
        f[12 + a] += out[a] as f32;
    }
    for other in [3, 5] {
        let change = (marker(&f, 4) - marker(&f, other)).norm() - (marker(&t, 4) - marker(&t, other)).norm();
        assert!(change > OUTLIER_FLOOR + 2e-3, "MC5 to marker {other}: {change} m");
    }
    assert_eq!(filler.fill(&mut f, 500).unwrap(), 1 << 4);
    assert_eq!(filler.status(), status::REJECTED_MARKER);
    let err = (marker(&f, 4) - marker(&t, 4)).norm();
    assert!(err < 3e-3, "MC5 filled {} mm from the truth", 1e3 * err);
}

#[test]
fn a_fills_fitted_markers_carry_no_velocity_into_the_next_frame() {
    // USP slips 4 mm on the skin (within what its distances and motion allow, so it is kept),
    // then FAP drops for one frame: the fill puts the forearm's markers where the placement
    // learned before the slip has them, USP millimetres from where it is measured. That
    // difference is the fit, not motion: the next complete frame, USP where it has been since
    // the slip, must be taken as it is, not refused as a jump from where a velocity read off
    // the fit would send it.
    let body = BodyModel::default();
    let mut truth = frames(&body, 420, 0.01, 1.0, |_| Vector3::zeros());
    for f in &mut truth[390..] {
        f[4] += 0.004;
    }
    let mut filler = learned(&truth, 400, 100.0);
    let mut f = truth[400];
    f[6..9].fill(f32::NAN);
    assert_eq!(filler.fill(&mut f, 400).unwrap(), 1 << 2);
    let off = (marker(&f, 1) - marker(&truth[400], 1)).norm();
    // (2-3 mm before the fill weighed the joint centre by how well one point fits the
    // wrist: the slip is that misfit, so the fit now leans on the measured markers, ~1 mm.)
    assert!(off > 5e-4, "USP fitted {} mm from where it is measured", 1e3 * off);
    for (i, t) in truth.iter().enumerate().skip(401) {
        assert_eq!(filler.fill(&mut t.clone(), i).unwrap(), 0, "frame {i}");
        assert_eq!(filler.status(), 0, "frame {i}");
    }
}

#[test]
fn a_swap_right_after_refused_frames_is_put_right_from_the_velocity_before_them() {
    // The racer's swaying arm, the wrist at up to 2.6 rad/s: three frames with MC2 and MCB missing
    // (unfillable, refused), then MC2 and MC5 swap labels for good. Four frames on from the
    // last accepted one, where the markers were heading in the lab is centimetres off (by hand
    // below: it cannot tell MC2 from MC5); where the hand's markers were heading in the
    // forearm's frame, moved on over the refused frames, can. The swap must be found in its
    // first frame and followed: every frame the truth, flagged swapped.
    let body = BodyModel::default();
    let omega = 2.0 * std::f64::consts::PI * 1.5;
    let truth = frames(&body, 600, 0.04, 2.0, |t| Vector3::new(0.2 * (omega * t).sin(), 0.0, 0.0));
    // The arm at its turn (most acceleration) when the swap comes.
    let start = 502;
    let mut filler = learned(&truth, start, 25.0);
    for (i, t) in truth.iter().enumerate().take(start + 3).skip(start) {
        let mut f = *t;
        f[9..12].fill(f32::NAN);
        f[15..18].fill(f32::NAN);
        assert!(filler.fill(&mut f, i).is_err(), "frame {i}");
    }
    let heading = |m: usize| 5.0 * marker(&truth[start - 1], m) - 4.0 * marker(&truth[start - 2], m);
    let near = |from: usize, to: usize| {
        let here = marker(&truth[start + 3], from);
        (here - heading(from)).norm() <= SWAP_RATIO * (here - heading(to)).norm()
    };
    assert!(!(near(3, 4) && near(4, 3)), "the lab's prediction alone would find this swap");
    for (i, t) in truth.iter().enumerate().skip(start + 3) {
        let mut f = *t;
        for k in 0..3 {
            f.swap(9 + k, 12 + k);
        }
        assert_eq!(filler.fill(&mut f, i).unwrap(), 0, "frame {i}");
        assert_eq!(filler.status(), status::SWAPPED, "frame {i}");
        assert_eq!(f.map(f32::to_bits), t.map(f32::to_bits), "frame {i}");
    }
}

#[test]
fn a_calibrations_centre_holds_until_the_wrist_has_moved_enough_to_locate_its_own() {
    // The default subject told its own calibration (the seed is the true centre: the wrist,
    // the body model's segments' common origin), markers with ±1 mm noise, the wrist turning
    // by ±1° for two seconds at 100 Hz: far too little motion to locate the centre against
    // that noise (it takes ±10° about every axis, SEED_FRAMES frames of it to outweigh the
    // seed). The centre the filler reports must stay near the wrist (the noise moves it
    // millimetres), where the motion alone would put it centimetres off.
    let body = BodyModel::default();
    let pose = body.forearm_pose(0.2);
    let wrist = pose.translation.vector;
    let mut rng = crate::rng::SplitMix::new(9);
    let mut filler = GapFiller::at_rate(100.0);
    filler.set_calibration(Some(&Calibration::body_model()));
    let still = body.marker_frame(&[0.0; 3], &pose).map(|v| v as f32);
    for i in 0..200 {
        let t = i as f64 * 0.01;
        let a = 1f64.to_radians();
        let q = [a * (7.0 * t).sin(), a * (5.0 * t + 1.0).sin(), a * (3.0 * t + 0.5).sin()];
        let mut f = body.marker_frame(&q, &pose).map(|v| (v + rng.uniform(-1e-3, 1e-3)) as f32);
        assert_eq!(filler.fill(&mut f, i).unwrap(), 0);
    }
    let (c_f, c_h) = filler.joint_centre().expect("seeded");
    for (segment, c) in [(Segment::Forearm, c_f), (Segment::Hand, c_h)] {
        let (o, r) = technical_frame(&still, segment, 0).unwrap();
        let miss = (r * c + o - wrist).norm();
        assert!(miss < 5e-3, "{segment:?}: the centre {} mm off the wrist", 1e3 * miss);
    }
}

#[test]
fn the_centre_learned_from_enough_motion_takes_over_from_a_calibrations() {
    // A subject 15 % larger told the default calibration: the seed sits about a centimetre
    // off. Four seconds of the trial's motion (±46°, ±34° and ±17° about the three axes, far
    // more than SEED_FRAMES frames of ±10°) locate the centre on their own; it must then be
    // the subject's wrist, within a millimetre.
    let body = BodyModel::scaled(1.15, 1.0);
    let truth = frames(&body, 400, 0.01, 1.0, |_| Vector3::zeros());
    let wrist = body.forearm_pose(0.2).translation.vector;
    let mut filler = GapFiller::at_rate(100.0);
    filler.set_calibration(Some(&Calibration::body_model()));
    let (seed_f, _) = calibration_joint_centre(&Calibration::body_model());
    let (o, r) = technical_frame(&truth[0], Segment::Forearm, 0).unwrap();
    let seed_miss = (r * seed_f + o - wrist).norm();
    assert!(seed_miss > 5e-3, "the seed is {} mm off the wrist", 1e3 * seed_miss);
    for (i, t) in truth.iter().enumerate() {
        assert_eq!(filler.fill(&mut t.clone(), i).unwrap(), 0);
    }
    let (c_f, c_h) = filler.joint_centre().expect("seeded");
    for (segment, c) in [(Segment::Forearm, c_f), (Segment::Hand, c_h)] {
        let (o, r) = technical_frame(&truth[399], segment, 0).unwrap();
        let miss = (r * c + o - wrist).norm();
        assert!(miss < 1e-3, "{segment:?}: the centre {} mm off the wrist", 1e3 * miss);
    }
}
