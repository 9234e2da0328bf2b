//! Per-frame standard deviations of a network's outputs: a variance that is an affine function
//! of per-frame quantities a stream already has, its few coefficients fitted on held-out
//! simulated trials and carried in the model's card ([`SdCard`], the card's `uncertainty`), so
//! that a different model carries its own.
//!
//! For output `c` of a frame the network corrected:
//!
//! σ_c² = constant_c + Σ_k angle_noise_ck · N_k^p + correction_c · D_c^p
//!
//! - `N_k`: the noise variance of angle `k` of the per-frame solution (the first
//!   [`N_COORDINATES`] features of a frame: the per-frame angles of `angles`/`angles_gravity`,
//!   q of `joint_state`), measured from the data alone as a running mean of its squared third
//!   difference over 20 (white noise of variance v has third differences of variance 20 v; a
//!   smooth motion's are tiny at the rates models run at).
//! - `D_c`: a running mean of the squared correction (output minus the newest frame's
//!   same-named feature; only for a model that corrects it, card `output_offset`): how far the
//!   network moves the per-frame solution.
//! - `p`: the card's `power` (1: affine in the variances). Fitted below 1 where a network
//!   filters large noise relatively better than small (measured on the wrist-ik family: one
//!   affine map over-covered 5 % noise and under-covered 1 %).
//!
//! A frame whose output is the per-frame solution itself ([`status::PER_FRAME`]: the window
//! filling, or a correction withheld) has σ_c² = constant_c + N_c: that solution's own noise.
//! Both running means weigh the last [`SdCard::memory_frames`] frames (an exponential mean,
//! corrected for its start) and restart with the window. Until [`MIN_NOISE_FRAMES`] third
//! differences are seen after a (re)start no σ is given (`None`: not determined).
//!
//! [`status::PER_FRAME`]: crate::status::PER_FRAME

use crate::body::N_COORDINATES;
use crate::error::{Error, Result};
use crate::features::{FEATURE_SETS, FeatureSet};
use serde::{Deserialize, Serialize};

/// The card's `uncertainty.method` this build computes.
pub const SD_METHOD: &str = "affine-variance-v1";

/// Third differences seen since the window (re)started before a σ is given: fewer are too
/// few to tell the markers' noise (the first outputs after a restart carry none).
pub const MIN_NOISE_FRAMES: usize = 8;

/// The card's `uncertainty`: how the model's per-frame standard deviations are computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SdCard {
    /// Always [`SD_METHOD`].
    pub method: String,
    /// Frames the running means remember (weight 1 / memory per frame), ≥ 1.
    pub memory_frames: f64,
    /// The power `p` of the running means (0 < p ≤ 2; 1: affine).
    pub power: f64,
    /// Per output: variance of every frame, output unit².
    pub constant: Vec<f64>,
    /// Per output, per angle ([`N_COORDINATES`]): variance per rad² of that angle's per-frame noise.
    pub angle_noise: Vec<Vec<f64>>,
    /// Per output: variance per unit² of the running mean of the squared correction; all 0 for
    /// a model without an output offset.
    pub correction: Vec<f64>,
    /// What fitted the coefficients (study, seeds, noise levels) and the coverage measured on
    /// other trials; free-form.
    #[serde(default)]
    pub provenance: serde_json::Map<String, serde_json::Value>,
}

impl SdCard {
    /// Parses the card's `uncertainty` section alone (JSON); [`validate`](Self::validate)
    /// checks it against a model.
    pub fn from_json(json: &str) -> Result<Self> {
        serde_json::from_str(json).map_err(|e| Error::ModelCard(format!("field \"uncertainty\": {e}")))
    }

    /// Checks the coefficients against the model's outputs, feature set and offset.
    pub fn validate(&self, n_outputs: usize, feature_set: &str, has_offset: bool) -> Result<()> {
        let bad = |m: String| Err(Error::ModelCard(format!("field \"uncertainty\": {m}")));
        if self.method != SD_METHOD {
            return bad(format!("method is {:?}, expected {SD_METHOD:?}", self.method));
        }
        if !FeatureSet::from_name(feature_set).is_ok_and(FeatureSet::leads_with_angles) {
            let with_angles: Vec<_> =
                FEATURE_SETS.into_iter().filter(|f| f.leads_with_angles()).map(FeatureSet::name).collect();
            return bad(format!(
                "needs per-frame angles among the features; feature set {feature_set:?} has none (one of {with_angles:?} has)"
            ));
        }
        if !(self.power > 0.0 && self.power <= 2.0) {
            return bad(format!("power is {}, expected 0 < power <= 2", self.power));
        }
        if !(self.memory_frames.is_finite() && self.memory_frames >= 1.0) {
            return bad(format!("memory_frames is {}, expected a number >= 1", self.memory_frames));
        }
        for (what, n) in [("constant", self.constant.len()), ("correction", self.correction.len())] {
            if n != n_outputs {
                return bad(format!("{what} has {n} values, expected {n_outputs} (one per output)"));
            }
        }
        if self.angle_noise.len() != n_outputs || self.angle_noise.iter().any(|r| r.len() != N_COORDINATES) {
            return bad(format!(
                "angle_noise must be {n_outputs} rows of {N_COORDINATES} values (per output, per angle)"
            ));
        }
        let all = self.constant.iter().chain(self.angle_noise.iter().flatten()).chain(&self.correction);
        if let Some(v) = all.into_iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return bad(format!("a coefficient is {v}, expected finite and >= 0 (variances add)"));
        }
        if !has_offset && self.correction.iter().any(|&v| v != 0.0) {
            return bad(
                "correction coefficients given, but the model has no output offset to measure a correction by".into()
            );
        }
        if has_offset && n_outputs > N_COORDINATES {
            return bad(format!("a correcting model's {n_outputs} outputs exceed the {N_COORDINATES} angles"));
        }
        Ok(())
    }
}

/// A stream's running means and the σ of its last output; allocated once with the stream.
#[derive(Debug, Clone)]
pub struct SdState {
    /// The coefficients; `None`: the running means alone (for a study fitting them).
    card: Option<SdCard>,
    memory_frames: f64,
    /// The last three frames' angles, oldest first, and how many frames since the restart.
    history: [[f64; N_COORDINATES]; 3],
    frames: usize,
    noise: RunningMean<N_COORDINATES>,
    correction: Vec<f64>,
    correction_weight: f64,
    sd: Vec<f64>,
    valid: bool,
}

/// An exponential mean corrected for its start (the sum of weights divides).
#[derive(Debug, Clone, Copy)]
struct RunningMean<const N: usize> {
    sum: [f64; N],
    weight: f64,
    samples: usize,
}

impl<const N: usize> RunningMean<N> {
    fn new() -> Self {
        RunningMean { sum: [0.0; N], weight: 0.0, samples: 0 }
    }

    fn add(&mut self, x: &[f64; N], keep: f64) {
        for (s, v) in self.sum.iter_mut().zip(x) {
            *s = keep * *s + v;
        }
        self.weight = keep * self.weight + 1.0;
        self.samples += 1;
    }

    fn mean(&self, k: usize) -> f64 {
        self.sum[k] / self.weight
    }
}

impl SdState {
    /// State for a stream over a model of `n_outputs` outputs whose card carries `card`
    /// (validated with the card); without one the running means are kept (remembering
    /// `memory_frames`), no σ is given.
    pub fn new(card: Option<SdCard>, n_outputs: usize, memory_frames: f64) -> Self {
        let n = n_outputs;
        SdState {
            memory_frames: card.as_ref().map_or(memory_frames, |c| c.memory_frames),
            card,
            history: [[0.0; N_COORDINATES]; 3],
            frames: 0,
            noise: RunningMean::new(),
            correction: vec![0.0; n],
            correction_weight: 0.0,
            sd: vec![f64::NAN; n],
            valid: false,
        }
    }

    fn keep(&self) -> f64 {
        1.0 - 1.0 / self.memory_frames
    }

    /// Forgets every frame (the window restarted).
    pub fn restart(&mut self) {
        self.frames = 0;
        self.noise = RunningMean::new();
        self.correction.iter_mut().for_each(|v| *v = 0.0);
        self.correction_weight = 0.0;
        self.valid = false;
    }

    /// An accepted frame whose features start with `angles` (the per-frame solution): its
    /// third difference joins the noise's running mean. No σ until [`set_output`](Self::set_output).
    pub fn accept(&mut self, features: &[f32]) {
        let a: [f64; N_COORDINATES] = std::array::from_fn(|k| f64::from(features[k]));
        if self.frames >= 3 {
            let h = &self.history;
            let third: [f64; N_COORDINATES] = std::array::from_fn(|k| {
                let d = a[k] - 3.0 * h[2][k] + 3.0 * h[1][k] - h[0][k];
                d * d / 20.0
            });
            let keep = self.keep();
            self.noise.add(&third, keep);
        }
        self.history = [self.history[1], self.history[2], a];
        self.frames += 1;
        self.valid = false;
    }

    /// The σ of the output `output` just given for the accepted frame (features `features`):
    /// `per_frame` if it is the per-frame solution, else a network's (corrected, with an offset
    /// when `offset`). Allocation-free.
    pub fn set_output(&mut self, output: &[f32], features: &[f32], per_frame: bool, offset: bool) {
        let keep = self.keep();
        if offset && !per_frame {
            for (c, m) in self.correction.iter_mut().enumerate() {
                let d = f64::from(output[c]) - f64::from(features[c]);
                *m = keep * *m + d * d;
            }
            self.correction_weight = keep * self.correction_weight + 1.0;
        }
        self.valid = self.noise.samples >= MIN_NOISE_FRAMES && self.card.is_some();
        let Some(card) = self.card.as_ref().filter(|_| self.valid) else { return };
        for c in 0..self.sd.len() {
            let variance = if per_frame && offset {
                card.constant[c] + self.noise.mean(c)
            } else {
                let p = card.power;
                let noise: f64 =
                    (0..N_COORDINATES).map(|k| card.angle_noise[c][k] * self.noise.mean(k).max(0.0).powf(p)).sum();
                let correction = if self.correction_weight > 0.0 {
                    card.correction[c] * (self.correction[c] / self.correction_weight).max(0.0).powf(p)
                } else {
                    0.0
                };
                card.constant[c] + noise + correction
            };
            self.sd[c] = variance.max(0.0).sqrt();
        }
        self.valid = self.sd.iter().all(|v| v.is_finite());
    }

    /// The σ of the last output (output units), or `None`: no output yet, or too few frames
    /// since the window (re)started to tell the noise ([`MIN_NOISE_FRAMES`]).
    pub fn sd(&self) -> Option<&[f64]> {
        self.valid.then_some(&self.sd[..])
    }

    /// The running means behind the last σ: the angles' noise variances `N_k` and the mean
    /// squared corrections `D_c` (what a study fits the coefficients on); `None` as [`sd`](Self::sd)
    /// before [`MIN_NOISE_FRAMES`].
    pub fn terms(&self) -> Option<([f64; N_COORDINATES], [f64; N_COORDINATES])> {
        if self.noise.samples < MIN_NOISE_FRAMES {
            return None;
        }
        let noise = std::array::from_fn(|k| self.noise.mean(k));
        let correction = std::array::from_fn(|c| {
            if self.correction_weight > 0.0 && c < self.correction.len() {
                self.correction[c] / self.correction_weight
            } else {
                0.0
            }
        });
        Some((noise, correction))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn card(constant: f64, noise: f64, correction: f64) -> SdCard {
        SdCard {
            method: SD_METHOD.into(),
            memory_frames: 1e9, // a plain mean
            power: 1.0,
            constant: vec![constant; 3],
            angle_noise: (0..3).map(|c| (0..3).map(|k| if k == c { noise } else { 0.0 }).collect()).collect(),
            correction: vec![correction; 3],
            provenance: Default::default(),
        }
    }

    #[test]
    fn third_differences_measure_white_noise_and_ignore_a_smooth_motion() {
        // Oracle: white noise of variance v gives third differences of variance 20 v; a
        // quadratic motion has none.
        let mut state = SdState::new(Some(card(0.0, 1.0, 0.0)), 3, 1.0);
        let mut rng = crate::rng::SplitMix::new(5);
        let sigma = 0.01;
        for i in 0..20000 {
            let t = i as f64 * 1e-3;
            let f: [f32; 3] = std::array::from_fn(|k| (0.3 * t * t + k as f64 * t + sigma * rng.normal()) as f32);
            state.accept(&f);
            state.set_output(&f, &f, false, false);
        }
        let sd = state.sd().unwrap();
        for &s in sd {
            assert!((s / sigma - 1.0).abs() < 0.03, "{s} for σ {sigma}");
        }
    }

    #[test]
    fn no_sd_until_enough_frames_after_a_restart_and_per_frame_rows_use_the_noise_alone() {
        let mut state = SdState::new(Some(card(4.0, 100.0, 9.0)), 3, 1.0);
        for i in 0..(3 + MIN_NOISE_FRAMES) {
            assert!(state.sd().is_none(), "frame {i}");
            let f = [(i % 2) as f32, 0.0, 0.0];
            state.accept(&f);
            state.set_output(&[f[0] + 1.0, 0.0, 0.0], &f, false, true);
        }
        // Alternating 0/1: third differences ±4 → 16 / 20 = 0.8 rad² of noise; corrections all 1.
        let sd = state.sd().unwrap().to_vec();
        assert!((sd[0] - (4.0f64 + 100.0 * 0.8 + 9.0).sqrt()).abs() < 1e-9, "{sd:?}");
        assert!((sd[1] - (4.0f64 + 0.0 + 0.0).sqrt()).abs() < 1e-9, "{sd:?}");
        let mut squared = SdState::new(Some(SdCard { power: 0.5, ..card(4.0, 100.0, 9.0) }), 3, 1.0);
        for i in 0..(3 + MIN_NOISE_FRAMES) {
            let f = [(i % 2) as f32, 0.0, 0.0];
            squared.accept(&f);
            squared.set_output(&[f[0] + 1.0, 0.0, 0.0], &f, false, true);
        }
        let got = squared.sd().unwrap()[0];
        assert!((got - (4.0f64 + 100.0 * 0.8f64.sqrt() + 9.0).sqrt()).abs() < 1e-9, "{got}");
        let f = [0.0f32; 3];
        state.accept(&f);
        state.set_output(&f, &f, true, true);
        let per_frame = state.sd().unwrap();
        assert!(per_frame[0] > 2.0 && per_frame[0] < (4.0f64 + 0.8).sqrt() + 1e-9, "{per_frame:?}");
        state.restart();
        assert!(state.sd().is_none() && state.terms().is_none());
    }

    #[test]
    fn the_card_is_checked_field_by_field() {
        let ok = card(1e-6, 1.0, 0.5);
        ok.validate(3, "angles", true).unwrap();
        let refuse = |c: SdCard, set: &str, offset: bool, what: &str| {
            let e = c.validate(3, set, offset).unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
        };
        refuse(ok.clone(), "markers", true, "per-frame angles");
        refuse(ok.clone(), "angles_gravity", false, "no output offset");
        refuse(SdCard { method: "x".into(), ..ok.clone() }, "angles", true, "method");
        refuse(SdCard { constant: vec![1.0; 2], ..ok.clone() }, "angles", true, "constant has 2");
        refuse(SdCard { constant: vec![-1.0; 3], ..ok.clone() }, "angles", true, ">= 0");
        refuse(SdCard { memory_frames: 0.5, ..ok.clone() }, "angles", true, "memory_frames");
        refuse(SdCard { power: 0.0, ..ok.clone() }, "angles", true, "power");
        refuse(SdCard { angle_noise: vec![vec![0.0; 2]; 3], ..ok }, "angles", true, "angle_noise");
    }
}
