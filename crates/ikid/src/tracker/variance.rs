//! Each hand marker coordinate's noise, learned from the data as it comes: from third
//! differences of its coordinates, or (the hand measured by its orientation) of its residual to
//! the hand's rigid fit, one variance for the hand.

use nalgebra::Vector3;

use super::{HAND_START, MIN_REPORTED_NOISE, N_HAND, Tracker};
use crate::body::{MARKER_FRAME_LEN, Segment};
use crate::reference;

/// Variance of white noise's third difference over the noise's own variance: 1 + 9 + 9 + 1.
pub(super) const THIRD_DIFFERENCE_GAIN: f64 = 20.0;
/// Degrees of freedom of the residual of three markers' nine coordinates to their rigid fit:
/// the fit takes six (a translation and a turn), so white noise of variance σ² in every
/// direction leaves a residual whose sum of squares is 3σ² on average.
pub(super) const FIT_RESIDUAL_DOF: f64 = 3.0;
/// Weight of the initial noise guess, in frames: the estimate is the guess for the first few
/// frames and the data's soon after.
pub(super) const PRIOR_FRAMES: f64 = 10.0;
/// Largest noise sample taken, in current noise variances (a 5σ clip): one glitch cannot
/// inflate the noise estimate (a frame 1 km off made it 18 m), while a real rise in noise is
/// still learned, at most ×25 per memory length.
pub(super) const NOISE_CLIP: f64 = 25.0;
/// How far a coordinate's own third differences may raise the calibrated hand's noise above the
/// fit residual's (variance ratio). The residual misses noise normal to the markers' plane, so a
/// hand resting with that plane facing one lab axis had that axis learned at 0.4–0.6× its noise
/// and the filter passed each frame's noise to the torques (2.6 N·m on the exam's 5 % trials at
/// one pose, issue #28); a coordinate's own third differences see it, but at a lab's rate a fast
/// hand's are its motion (uncapped, racing's 70 Hz track went 0.6° -> 5.3° off): capped, its
/// SD rises at most 1.6× above the residual's.
pub const RAW_NOISE_CAP: f64 = 2.5;
/// Memory of the hand template's misfit estimate, s: skin slides with the posture, so the misfit
/// changes as fast as the posture does, and a second holds enough frames at any lab's rate.
pub const MISFIT_MEMORY_S: f64 = 1.0;

impl Tracker {
    /// Each hand marker coordinate's current noise estimate (standard deviation, m), in frame
    /// order (`MC2.x` first).
    pub fn marker_noise(&self) -> [f64; N_HAND] {
        self.noise_variance.map(f64::sqrt)
    }

    /// The mean of the hand markers' noise (standard deviation) from the data alone (floored:
    /// none yet in the first frames), so that clean markers read as clean at once rather than as
    /// the fading initial guess: [`TrackerOutput::noise`](super::TrackerOutput::noise).
    pub(super) fn reported_noise(&self) -> f64 {
        (self.data_variance.iter().map(|v| v.sqrt()).sum::<f64>() / N_HAND as f64).max(MIN_REPORTED_NOISE)
    }

    /// Update each coordinate's noise variance from its newest third difference (skipped where
    /// a marker was missing in any of the four frames). With [`TrackerSettings::relative_hand`],
    /// from the third differences of the hand markers' residual to the rigid fit of the hand's
    /// shape (skipped unless all three hand markers were there): at a low frame rate a fast
    /// hand's third differences are its motion, not noise, and a skin marker's slow slide is not
    /// noise the filter can average either; the fit's residual removes the first, the difference
    /// the second. That residual cannot see noise normal to the markers' plane (a translation
    /// and two tilts of the fit absorb it), so it is not read per lab coordinate — a hand resting
    /// with its plane facing one lab axis would have that axis learned at a fraction of its noise
    /// (issue #28) — but as one variance for the hand, in every direction: the residual's sum of
    /// squares over the [`FIT_RESIDUAL_DOF`] degrees of freedom the fit leaves it.
    pub(super) fn learn_noise(&mut self, hand: &[f64; N_HAND], index: usize) {
        let relative = self.relative_hand();
        let now = if relative { self.fit_residual(hand, index).unwrap_or([f64::NAN; N_HAND]) } else { *hand };
        if relative && now.iter().all(|r| r.is_finite()) {
            let sample = now.iter().map(|r| r * r).sum::<f64>() / N_HAND as f64;
            let w = (1.0 / (self.fit_residual_samples + 1.0)).max(1.0 / (MISFIT_MEMORY_S * self.settings.rate_hz));
            self.fit_residual_ms += w * (sample - self.fit_residual_ms);
            self.fit_residual_samples += 1.0;
        }
        if self.history_len == 3 {
            let d3: [f64; N_HAND] = std::array::from_fn(|i| {
                let [a, b, c] = [self.history[0][i], self.history[1][i], self.history[2][i]];
                now[i] - 3.0 * a + 3.0 * b - c
            });
            if relative {
                if d3.iter().all(|d| d.is_finite()) {
                    let sample = d3.iter().map(|d| d * d).sum::<f64>() / (THIRD_DIFFERENCE_GAIN * FIT_RESIDUAL_DOF);
                    let own: [f64; N_HAND] = std::array::from_fn(|i| {
                        let [a, b, c] = [self.raw_history[0][i], self.raw_history[1][i], self.raw_history[2][i]];
                        (hand[i] - 3.0 * a + 3.0 * b - c).powi(2) / THIRD_DIFFERENCE_GAIN
                    });
                    // Each coordinate's share from the two running means, not frame by frame (a
                    // maximum of two noisy samples would overstate both).
                    if own.iter().all(|v| v.is_finite()) {
                        let forget = 1.0 / (self.settings.noise_memory_s * self.settings.rate_hz);
                        let w = (1.0 / (self.own_noise_samples + 1.0)).max(forget);
                        for (mean, v) in self.own_noise.iter_mut().zip(own) {
                            *mean += w * (v - *mean);
                        }
                        self.fit_noise += w * (sample - self.fit_noise);
                        self.own_noise_samples += 1.0;
                    }
                    for i in 0..N_HAND {
                        let share = if self.fit_noise > 0.0 { self.own_noise[i] / self.fit_noise } else { 1.0 };
                        self.add_noise_sample(i, sample * share.clamp(1.0, RAW_NOISE_CAP));
                    }
                }
            } else {
                for (i, d3) in d3.into_iter().enumerate() {
                    if d3.is_finite() {
                        self.add_noise_sample(i, d3 * d3 / THIRD_DIFFERENCE_GAIN);
                    }
                }
            }
        }
        self.history = [now, self.history[0], self.history[1]];
        self.raw_history = [*hand, self.raw_history[0], self.raw_history[1]];
        self.history_len = (self.history_len + 1).min(3);
    }

    /// The variance per hand marker coordinate by which the hand's template misses the markers
    /// beyond their white noise `noise_variance` (0 for a template that fits): skin markers whose
    /// shape changes with the posture. The fit's residual keeps [`FIT_RESIDUAL_DOF`] of the nine
    /// coordinates' degrees of freedom, so a coordinate's misfit is its mean square times
    /// 9 / [`FIT_RESIDUAL_DOF`].
    pub(super) fn template_misfit_variance(&self, noise_variance: f64) -> f64 {
        if self.fit_residual_samples < 1.0 {
            return 0.0;
        }
        (self.fit_residual_ms * N_HAND as f64 / FIT_RESIDUAL_DOF - noise_variance).max(0.0)
    }

    fn add_noise_sample(&mut self, i: usize, sample: f64) {
        let forget = 1.0 / (self.settings.noise_memory_s * self.settings.rate_hz);
        let sample = sample.min(NOISE_CLIP * self.noise_variance[i].max(self.data_variance[i]));
        let w = (1.0 / (self.noise_samples[i] + PRIOR_FRAMES)).max(forget);
        self.noise_variance[i] += w * (sample - self.noise_variance[i]);
        let w = (1.0 / (self.noise_samples[i] + 1.0)).max(forget);
        self.data_variance[i] += w * (sample - self.data_variance[i]);
        self.noise_samples[i] += 1.0;
    }

    /// Each hand marker coordinate of `hand` minus the rigid fit of the hand's shape (as placed
    /// in the body model) to the three, m; `None` unless all three are present and the shape
    /// is the subject's (after a calibration's template is taken).
    pub(super) fn fit_residual(&self, hand: &[f64; N_HAND], index: usize) -> Option<[f64; N_HAND]> {
        if hand.iter().any(|v| v.is_nan()) || (self.calibration.is_some() && !self.templated[Segment::Hand as usize]) {
            return None;
        }
        let mut frame = [0.0; MARKER_FRAME_LEN];
        frame[HAND_START..].copy_from_slice(hand);
        let pose = reference::fit_segment(&self.body, &frame, Segment::Hand, index).ok()?;
        let fitted: [Vector3<f64>; 3] = std::array::from_fn(|m| {
            pose.transform_vector(&Vector3::from(self.body.marker_offsets[3 + m])) + pose.translation.vector
        });
        Some(std::array::from_fn(|i| hand[i] - fitted[i / 3][i % 3]))
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {
    use super::super::testkit::*;
    use super::super::*;
    use super::*;
    use crate::body::BodyModel;

    use crate::noise::uniform_range;
    use crate::reference::{self};

    #[test]
    fn the_templates_misfit_is_its_residuals_mean_square_per_coordinate_beyond_the_noise() {
        // Documented: the residual's mean square × 9 / FIT_RESIDUAL_DOF, less the white noise,
        // never below 0; nothing before a first residual; from the first one on.
        let mut tracker = Tracker::new(BodyModel::default(), TrackerSettings::new(1000.0)).unwrap();
        assert_eq!(tracker.template_misfit_variance(0.0), 0.0);
        for samples in [1.0, 50.0] {
            (tracker.fit_residual_ms, tracker.fit_residual_samples) = (1e-4, samples);
            let want = 1e-4 * 9.0 / FIT_RESIDUAL_DOF - 1e-6;
            assert!((tracker.template_misfit_variance(1e-6) - want).abs() < 1e-15, "{samples} samples");
            assert_eq!(tracker.template_misfit_variance(1.0), 0.0);
        }
    }

    #[test]
    fn one_glitch_teaches_a_coordinates_noise_little() {
        // 1e-6 m² learned over 2000 samples, then one sample 1 km² (a frame a kilometre off):
        // capped at 25× the variance, it raises it by 24·w at most (w, the sample's weight, here
        // 1/2010), not to metres.
        let mut tracker = Tracker::new(BodyModel::default(), TrackerSettings::new(1000.0)).unwrap();
        for _ in 0..2000 {
            tracker.add_noise_sample(0, 1e-6);
        }
        let before = tracker.noise_variance[0];
        tracker.add_noise_sample(0, 1e6);
        let memory = tracker.settings.noise_memory_s * tracker.settings.rate_hz;
        let w = (1.0 / (2000.0 + PRIOR_FRAMES)).max(1.0 / memory);
        let after = tracker.noise_variance[0];
        assert!(after <= before * (1.0 + 24.0 * w) * (1.0 + 1e-9), "{before:.3e} -> {after:.3e} m²");
        assert!(after > before, "still taken, capped");
    }

    #[test]
    fn a_hand_held_exactly_still_learns_no_noise() {
        // Identical frames (a lab's static trial replayed, or markers snapped to a grid): the
        // fit's residuals and every third difference are exactly 0: the noise is the prior's
        // (1e-6 m², weighing PRIOR_FRAMES samples) averaged with zeros, 4.5e-9 m² after 2000
        // frames, whatever the shares of two zero means are taken to be (0/0 grew it to 3e49 m²).
        let body = BodyModel::default();
        let frame = body.marker_frame(&[0.3, -0.2, 0.1], &body.forearm_pose(0.2));
        let f: Vec<f64> = (0..2000).flat_map(|_| frame).collect();
        let (_, _, tracker) = track_calibrated(&f, 1000.0);
        let worst = tracker.noise_variance.iter().fold(0.0, |a: f64, &b| a.max(b));
        assert!(worst < 1e-8, "{worst:.3e} m² learned from a still hand");
    }

    #[test]
    fn noise_is_learned_per_coordinate_and_filtered() {
        let body = BodyModel::default();
        let q = trajectory(6000, 1000.0);
        let clean = frames(&body, &q, 0.0);
        let mut noisy = clean.clone();
        uniform_range(&mut noisy, 0.05, 11).unwrap();
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        let (mut se_tracker, mut se_frame) = (0.0, 0.0);
        for (i, frame) in noisy.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let out = tracker.push(frame).unwrap().unwrap();
            if i >= 1000 {
                let per_frame = reference::inverse_kinematics_frame(&body, frame, i).unwrap();
                for c in 0..3 {
                    se_tracker += (out.state.q[c] - q[i][c]).powi(2);
                    se_frame += (per_frame[c] - q[i][c]).powi(2);
                }
            }
        }
        // Uniform ±5 % of each coordinate's range: σ = 0.05 · range / √3, different per coordinate.
        let noise = tracker.marker_noise();
        for i in 0..N_HAND {
            let col: Vec<f64> = clean.chunks_exact(MARKER_FRAME_LEN).map(|f| f[HAND_START + i]).collect();
            let range = col.iter().cloned().fold(f64::MIN, f64::max) - col.iter().cloned().fold(f64::MAX, f64::min);
            let expected = 0.05 * range / 3f64.sqrt();
            assert!((noise[i] / expected - 1.0).abs() < 0.1, "coordinate {i}: {} vs {expected}", noise[i]);
        }
        assert!(se_tracker * 10.0 < se_frame, "filtered {se_tracker} vs per frame {se_frame}");
    }

    /// Hand marker coordinates of `frames` (back to back) and their noise as the tracker is
    /// documented to learn it, computed here from the third differences alone: per coordinate
    /// a running mean of d³²/20 over the frames where four consecutive values are present
    /// (weight 1/(n+1), or the forgetting rate once that is larger), and the same with the
    /// initial guess counting as `PRIOR_FRAMES − 1` samples.
    fn third_difference_noise(frames: &[f64], settings: &TrackerSettings) -> (Vec<[f64; N_HAND]>, Vec<[f64; N_HAND]>) {
        let hand: Vec<[f64; N_HAND]> =
            frames.chunks_exact(MARKER_FRAME_LEN).map(|f| std::array::from_fn(|i| f[HAND_START + i])).collect();
        let forget = 1.0 / (settings.noise_memory_s * settings.rate_hz);
        let mut data = [0.0; N_HAND];
        let mut guessed = [settings.initial_marker_noise.powi(2); N_HAND];
        let mut n = [0.0; N_HAND];
        let (mut data_out, mut guessed_out) = (Vec::new(), Vec::new());
        for t in 0..hand.len() {
            if t >= 3 {
                for i in 0..N_HAND {
                    let d3 = hand[t][i] - 3.0 * hand[t - 1][i] + 3.0 * hand[t - 2][i] - hand[t - 3][i];
                    if d3.is_nan() {
                        continue;
                    }
                    let sample = d3 * d3 / 20.0;
                    let w = f64::max(1.0 / (n[i] + 1.0), forget);
                    data[i] = (1.0 - w) * data[i] + w * sample;
                    let w = f64::max(1.0 / (n[i] + PRIOR_FRAMES), forget);
                    guessed[i] = (1.0 - w) * guessed[i] + w * sample;
                    n[i] += 1.0;
                }
            }
            data_out.push(data.map(f64::sqrt));
            guessed_out.push(guessed.map(f64::sqrt));
        }
        (data_out, guessed_out)
    }

    #[test]
    fn the_reported_noise_is_the_third_difference_estimate_of_the_data() {
        let body = BodyModel::default();
        let q = trajectory(3000, 1000.0);
        let mut f = frames(&body, &q, 0.2);
        uniform_range(&mut f, 0.02, 17).unwrap();
        // MC5 missing for a while: those coordinates skip the samples that touch the gap.
        for i in 700..720 {
            f[i * MARKER_FRAME_LEN + 12..i * MARKER_FRAME_LEN + 15].fill(f64::NAN);
        }
        for settings in [
            TrackerSettings::new(1000.0),
            TrackerSettings { noise_memory_s: 0.05, initial_marker_noise: 3e-3, ..TrackerSettings::new(1000.0) },
        ] {
            let (data, guessed) = third_difference_noise(&f, &settings);
            let mut tracker = Tracker::new(body.clone(), settings).unwrap();
            for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
                let out = tracker.push(frame).unwrap().unwrap();
                let mean = (data[i].iter().sum::<f64>() / N_HAND as f64).max(MIN_REPORTED_NOISE);
                assert!((out.noise / mean - 1.0).abs() < 1e-9, "frame {i}: {} vs {mean} ({settings:?})", out.noise);
                let learned = tracker.marker_noise();
                for k in 0..N_HAND {
                    assert!(
                        (learned[k] / guessed[i][k] - 1.0).abs() < 1e-9,
                        "frame {i} coordinate {k}: {} vs {}",
                        learned[k],
                        guessed[i][k]
                    );
                }
            }
        }
    }

    #[test]
    fn a_short_noise_memory_forgets_old_noise_and_a_long_one_does_not() {
        // 2 s of 5 % noise, then 2 s of clean markers: a 0.1 s memory reads the clean markers
        // as clean by the end, a 100 s memory still remembers the noise.
        let body = BodyModel::default();
        let q = trajectory(4000, 1000.0);
        let clean = frames(&body, &q, 0.0);
        let mut f = clean.clone();
        uniform_range(&mut f[..2000 * MARKER_FRAME_LEN], 0.05, 3).unwrap();
        let last_noise = |memory: f64| {
            let mut tracker =
                Tracker::new(body.clone(), TrackerSettings { noise_memory_s: memory, ..TrackerSettings::new(1000.0) })
                    .unwrap();
            let mut noisy_end = 0.0;
            let mut out = None;
            for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
                out = tracker.push(frame).unwrap();
                if i == 1999 {
                    noisy_end = out.unwrap().noise;
                }
            }
            (noisy_end, out.unwrap().noise)
        };
        let (noisy_short, end_short) = last_noise(0.1);
        let (noisy_long, end_long) = last_noise(100.0);
        assert!(noisy_short > 1e-4 && noisy_long > 1e-4, "{noisy_short} {noisy_long}");
        // After 20 memories of clean frames: down by e^-20 in variance.
        assert!(end_short < 1e-3 * noisy_short, "short memory: {end_short} after {noisy_short}");
        // With n samples the running mean halves its variance at most: σ falls by ≤ √2.
        assert!(end_long > noisy_long / 1.5, "long memory: {end_long} after {noisy_long}");
    }

    #[test]
    fn a_resting_calibrated_hand_learns_the_noise_its_fit_cannot_see() {
        // At rest, lab noise much larger along one axis than the others: the rigid fit's residual
        // cannot see the part normal to the markers' plane; each coordinate's own third
        // differences can (issue #28).
        let body = BodyModel::default();
        let q = vec![[0.2, -0.1, 0.05]; 6000];
        let mut f = frames(&body, &q, 0.0);
        let sigma = [0.0002, 0.0002, 0.001];
        let mut gauss = super::super::testkit::lcg_gaussian(7);
        for (i, v) in f.iter_mut().enumerate() {
            *v += sigma[i % 3] * gauss();
        }
        let mut tracker = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
        tracker.set_calibration(Some(crate::calibration::Calibration::body_model()));
        tracker.run(&f, |_, _, _| {}).unwrap();
        // The residual alone learns every coordinate alike (0.27 mm here); z's own third
        // differences raise it to the cap (0.42 mm, of a true 1 mm), x and y stay.
        let noise = tracker.marker_noise();
        for m in 0..3 {
            let (x, z) = (noise[3 * m], noise[3 * m + 2]);
            assert!(z > 1.4 * x && z < sigma[2], "hand marker {m}: z noise {z} against x {x}, true {sigma:?}");
        }
    }
}
