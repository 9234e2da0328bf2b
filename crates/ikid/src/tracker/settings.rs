//! How the tracker models motion and noise: [`TrackerSettings`], checked before a tracker is made.

use nalgebra::Rotation3;

use crate::body;
use crate::error::{Error, Result};

/// How the tracker models motion and noise, and the lab it is measured in.
///
/// Made by [`TrackerSettings::new`] from the markers' frame rate: the rate has no default,
/// since a recording tracked at another rate has every velocity, acceleration and torque wrong
/// by the ratio (a 100 Hz recording tracked as 1 kHz: torques 5× too large) and nothing in the
/// markers can say so.
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
    /// The lab's up direction (against gravity) in the markers' coordinates: `[0, 1, 0]`, the
    /// body model's lab, by default; `[0, 0, 1]` for a Z-up lab (Vicon, Qualisys). Only the
    /// torques depend on it (gravity's moment), and they are wrong by it silently: a Z-up
    /// recording tracked as Y-up gave torques 0.2-0.3 N·m off with every status 0. Any
    /// non-zero length; it is normalised.
    pub up: [f64; 3],
}

impl TrackerSettings {
    /// Settings for markers at `rate_hz`: [`DEFAULT_JERK_NOISE`]; a 10 s noise memory; 1 mm
    /// noise assumed at first (a guess too small makes the filter trust its first noisy frames
    /// and can throw it off); the hand measured by its position unless calibrated; +Y up.
    pub fn new(rate_hz: f64) -> Self {
        TrackerSettings {
            rate_hz,
            jerk_noise: DEFAULT_JERK_NOISE,
            noise_memory_s: 10.0,
            initial_marker_noise: 1e-3,
            relative_hand: false,
            up: [0.0, 1.0, 0.0],
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
        if self.rate_hz.is_nan() {
            // The C API's default settings leave the rate NaN: it has to be given.
            return Err(Error::BadArgument {
                what: "rate_hz",
                detail: "is not set (NaN): give the rate the frames come at, in Hz (tracked at another rate, every \
                         velocity, acceleration and torque is wrong and nothing in the markers can say so)"
                    .into(),
            });
        }
        // Lower ends too: 1e-300 Hz passed "positive" (review 5), a rate no recording has and
        // a step no filter survives; each floor is far below any real value.
        for (what, v, min, max, unit) in [
            ("rate_hz", self.rate_hz, 1.0, 100_000.0, "Hz"),
            ("jerk_noise", self.jerk_noise, 1e-6, 1e12, "rad²/s⁵"),
            ("noise_memory_s", self.noise_memory_s, 1e-3, 86_400.0, "s"),
            ("initial_marker_noise", self.initial_marker_noise, 1e-9, 1.0, "m"),
        ] {
            if !(v >= min && v <= max) {
                // 1e308 as 1e308, not as its 309 digits.
                let shown = if v.is_finite() && v != 0.0 && !(1e-3..1e6).contains(&v.abs()) {
                    format!("{v:e}")
                } else {
                    format!("{v}")
                };
                return Err(Error::BadArgument {
                    what,
                    detail: format!("is {shown}, expected a number from {min:e} to {max:e} {unit}"),
                });
            }
        }
        self.lab_turn().map(|_| ())
    }
}

impl TrackerSettings {
    /// The turn from the markers' lab into the body model's ([`body::lab_turn`]).
    pub(super) fn lab_turn(&self) -> Result<Option<Rotation3<f64>>> {
        body::lab_turn(self.up)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_out_of_any_recordings_range_are_refused_by_name_and_the_defaults_pass() {
        assert!(TrackerSettings::new(1000.0).check().is_ok());
        assert!(TrackerSettings::new(1.0).check().is_ok(), "1 Hz: the floor itself");
        for (settings, what) in [
            (TrackerSettings::new(1e-300), "rate_hz"),
            (TrackerSettings::new(0.5), "rate_hz"),
            (TrackerSettings { jerk_noise: 1e-300, ..TrackerSettings::new(100.0) }, "jerk_noise"),
            (TrackerSettings { initial_marker_noise: 1e-300, ..TrackerSettings::new(100.0) }, "initial_marker_noise"),
            (TrackerSettings { noise_memory_s: 1e-300, ..TrackerSettings::new(100.0) }, "noise_memory_s"),
        ] {
            let err = settings.check().unwrap_err().to_string();
            assert!(err.contains(what) && err.contains("expected a number from"), "{what}: {err}");
        }
    }

    #[test]
    fn an_up_axis_is_named_as_a_marker_map_names_it() {
        for (name, up) in
            [("+z", [0.0, 0.0, 1.0]), ("Z", [0.0, 0.0, 1.0]), (" -y ", [0.0, -1.0, 0.0]), ("+X", [1.0, 0.0, 0.0])]
        {
            assert_eq!(body::up_axis(name).unwrap(), up, "{name}");
        }
        for bad in ["", "w", "+", "zz", "++z", "1"] {
            let e = body::up_axis(bad).unwrap_err().to_string();
            assert!(e.contains("+x, -x, +y, -y, +z, -z"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_lab_axis_is_turned_onto_up_exactly_by_a_proper_rotation() {
        // Oracle: the axis lands on +Y, the turn is a signed permutation (every entry exactly
        // -1, 0 or 1: coordinates moved, never perturbed) with determinant +1 (no mirror).
        for name in ["+x", "-x", "-y", "+z", "-z"] {
            let up = body::up_axis(name).unwrap();
            let m = body::lab_turn(up).unwrap().expect("a turn").into_inner();
            assert_eq!(m * nalgebra::Vector3::from(up), nalgebra::Vector3::y(), "{name}");
            assert!(m.iter().all(|x| [-1.0, 0.0, 1.0].contains(x)), "{name}: {m}");
            assert_eq!(m.determinant(), 1.0, "{name}");
        }
        assert!(body::lab_turn([0.0, 1.0, 0.0]).unwrap().is_none());
        // A tilted lab keeps its exact shortest turn.
        let tilted = body::lab_turn([0.1, 1.0, 0.2]).unwrap().unwrap();
        let up = nalgebra::Vector3::new(0.1, 1.0, 0.2).normalize();
        assert!((tilted * up - nalgebra::Vector3::y()).norm() < 1e-15);
    }
}
