//! What the tracker's tests share: trajectories, their markers, and trackers run over them.

use super::{Tracker, TrackerSettings};
use crate::body::{self, BodyModel};
use crate::calibration::Calibration;

pub(super) fn trajectory(n: usize, rate: f64) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let t = i as f64 / rate;
            [0.6 * (1.3 * t).sin(), -0.5 * (0.9 * t + 0.4).sin(), 0.2 * (1.7 * t).cos()]
        })
        .collect()
}

pub(super) fn frames(body: &BodyModel, q: &[[f64; 3]], shoulder: f64) -> Vec<f64> {
    body.marker_frames(&q.concat(), shoulder).unwrap()
}

/// Runs `f` through a fresh tracker; per frame, the angles (NaN before the start) and status.
pub(super) fn track(f: &[f64], rate: f64) -> (Vec<[f64; 3]>, Vec<u16>, Tracker) {
    let settings = TrackerSettings::new(rate);
    let mut tracker = Tracker::new(BodyModel::default(), settings).unwrap();
    let (mut q, mut st) = (vec![], vec![]);
    tracker
        .run(f, |_, o, _| {
            q.push(o.state.q);
            st.push(o.status);
        })
        .unwrap();
    (q, st, tracker)
}

pub(super) fn worst_deg(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter().zip(b).flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs().to_degrees())).fold(0.0, f64::max)
}

/// Runs `f` through a fresh tracker at `rate` calibrated to the body model's own placement
/// (so: the hand measured by its orientation, the wrist centre learned); per frame, the
/// angles (NaN before the start) and status.
pub(super) fn track_calibrated(f: &[f64], rate: f64) -> (Vec<[f64; 3]>, Vec<u16>, Tracker) {
    let settings = TrackerSettings::new(rate);
    let mut tracker = Tracker::new(BodyModel::default(), settings).unwrap();
    tracker.set_calibration(Some(Calibration::body_model()));
    let (mut q, mut st) = (vec![], vec![]);
    tracker
        .run(f, |_, o, _| {
            q.push(o.state.q);
            st.push(o.status);
        })
        .unwrap();
    (q, st, tracker)
}

/// Largest geodesic angle between the hand-in-forearm rotations of `a` and `b`, degrees.
pub(super) fn worst_turn_deg(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| body::wrist_rotation(x).angle_to(&body::wrist_rotation(y)).to_degrees())
        .fold(0.0, f64::max)
}

/// A fast wrist (flexion swinging ±60° at 1.5 Hz, deviation and pronation with it), as
/// wheelchair racing's at a lab's 70 Hz.
pub(super) fn fast_trajectory(n: usize, rate: f64) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let w = std::f64::consts::TAU * 1.5 * i as f64 / rate;
            [0.5 * (w + 0.3).sin(), -0.2 + 1.0 * w.sin(), 0.25 * (2.0 * w).cos()]
        })
        .collect()
}

/// Standard normal samples from `seed`: Box–Muller on a 64-bit LCG, independent of the crate's
/// noise module (the noise the tests add is then no function the code under test shares).
pub(super) fn lcg_gaussian(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        let mut u = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (-2.0 * u().ln()).sqrt() * (std::f64::consts::TAU * u()).cos()
    }
}

/// The first frame flagged [`RESTARTED`](crate::status::RESTARTED) after the filter's own start
/// (whose first [`LOST_S`](super::LOST_S) of frames are flagged too, q̇ and q̈ settling).
pub(super) fn first_restart(status: &[u16], tracker: &Tracker) -> Option<usize> {
    let start = tracker.lost_frames();
    status.iter().skip(start).position(|s| s & crate::status::RESTARTED != 0).map(|i| i + start)
}
