//! A held posture's moving average ([`HeldPosture::of`]) spans at most a third of the frames,
//! so that however noisy the markers, a movement within the trial still shows.

use super::*;

#[test]
fn a_short_noisy_trial_that_moves_in_its_last_third_is_refused() {
    // 15 frames, markers with ±2 mm noise (single frames turn by degrees, so the noise alone
    // would ask for a longer average than a third of them): the hand held for ten frames,
    // then bent 10° for the last five. Averaged over five frames, the last five sit 10° from
    // the held ten, ~6.7° from the mean of all: more than MAX_STATIC_SPREAD_DEG, refused.
    let body = body::BodyModel::default();
    let pose = body.forearm_pose(0.3);
    let mut rng = crate::rng::SplitMix::new(5);
    let bend = 10f64.to_radians();
    let frames: Vec<f32> = (0..15)
        .flat_map(|i| {
            let q = [0.0, if i < 10 { 0.0 } else { bend }, 0.0];
            body.marker_frame(&q, &pose)
        })
        .map(|v| (v + rng.uniform(-0.002, 0.002)) as f32)
        .collect();
    let err = Calibration::from_neutral(&frames, None, Side::Right).unwrap_err().to_string();
    assert!(err.contains("the hand moves") && err.contains("averaged out (at most 5°)"), "{err}");
    // The same frames held throughout are accepted.
    let mut rng = crate::rng::SplitMix::new(5);
    let held: Vec<f32> = (0..15)
        .flat_map(|_| body.marker_frame(&[0.0; 3], &pose))
        .map(|v| (v + rng.uniform(-0.002, 0.002)) as f32)
        .collect();
    let (_, report) = Calibration::from_neutral(&held, None, Side::Right).unwrap();
    // (The noise alone asks for more than a third of the frames: (noise / 1°)² > 15 / 3.)
    assert!(report.neutral_noise_deg.powi(2) > 5.0 * SMOOTHED_NOISE_DEG.powi(2), "{report:?}");
}
