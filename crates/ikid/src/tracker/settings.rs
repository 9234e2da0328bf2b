//! How the tracker models motion and noise: [`TrackerSettings`], checked before a tracker is made.

use crate::error::{Error, Result};

/// How the tracker models motion and noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerSettings {
    /// Frame rate of the markers, Hz.
    pub rate_hz: f64,
    /// Spectral density of the joint jerk the motion model allows, rad²/s⁵: larger follows
    /// faster moves with less lag and passes more noise.
    pub jerk_noise: f64,
    /// How far back the noise estimate looks, seconds (exponential forgetting).
    pub noise_memory_s: f64,
    /// Standard deviation of marker noise assumed before any has been measured, m.
    pub initial_marker_noise: f64,
    /// Measure the hand's orientation only — its markers relative to their own centroid — not
    /// its position relative to the forearm's frame. The body model knows the wrist centre of a
    /// simulated subject exactly; of a real subject it does not, and a centre a centimetre off
    /// is read as degrees of wrist angle. On with a calibration ([`Tracker::set_calibration`](super::Tracker::set_calibration));
    /// needs two hand markers per frame to correct.
    pub relative_hand: bool,
}

impl Default for TrackerSettings {
    /// 1 kHz; [`DEFAULT_JERK_NOISE`]; a 10 s noise memory; 1 mm noise assumed at first (a
    /// guess too small makes the filter trust its first noisy frames and can throw it off).
    fn default() -> Self {
        TrackerSettings {
            rate_hz: 1000.0,
            jerk_noise: DEFAULT_JERK_NOISE,
            noise_memory_s: 10.0,
            initial_marker_noise: 1e-3,
            relative_hand: false,
        }
    }
}

/// [`TrackerSettings::jerk_noise`]'s default, rad²/s⁵: chosen by `make compare-ekf` on its
/// validation trials (never the test trials) as the grid point whose worst MSE ratio to the best
/// biorbd EKF setting over 0/1/5 % noise, angles and torques, is smallest (`docs/ekf.md`).
pub const DEFAULT_JERK_NOISE: f64 = 3e3;

impl TrackerSettings {
    /// Each setting must be positive and at most what any recording needs: a value beyond is a
    /// typo (or a unit slip) that would make the filter's arithmetic overflow, not a setting.
    pub(super) fn check(&self) -> Result<()> {
        for (what, v, max, unit) in [
            ("rate_hz", self.rate_hz, 100_000.0, "Hz"),
            ("jerk_noise", self.jerk_noise, 1e12, "rad²/s⁵"),
            ("noise_memory_s", self.noise_memory_s, 86_400.0, "s"),
            ("initial_marker_noise", self.initial_marker_noise, 1.0, "m"),
        ] {
            if !(v > 0.0 && v <= max) {
                return Err(Error::BadArgument {
                    what,
                    detail: format!("is {v}, expected a positive number up to {max:e} {unit}"),
                });
            }
        }
        Ok(())
    }
}
