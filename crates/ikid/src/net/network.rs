//! The network a model runs, as its callers see it: the packed MLP (scaling folded in), then
//! the card's output offset, then the check that every output is finite. A stream's push (one
//! window) and `Model::predict` ([`BATCH`] windows at a time) both run it, so they cannot
//! disagree on any of the three.

use super::batch::{BATCH, BatchScratch};
use super::mlp::Mlp;
use super::packed::{PackedMlp, Scratch};
use crate::error::{Error, Result};

/// What a model adds to its network's outputs: output `k` plus the newest frame's feature `k`
/// (the card's `output_offset = "newest_features"`: the network learns a correction).
#[derive(Debug, Clone, PartialEq)]
pub struct NewestFeatures {
    /// Features per frame: a window is whole frames of this many, oldest first.
    pub features: usize,
    /// Per feature, the range (`lo`, `hi`) the window's mean must lie in for the correction to
    /// be added; outside it the output is the newest frame's features alone. `None`: always
    /// corrected.
    pub trained: Option<(Vec<f32>, Vec<f32>)>,
    /// Per feature, the largest change of the mean from the window's older half to its newer
    /// half (`frames / 2` frames each) for the correction to be added: a window moving faster
    /// than the model learned to correct (the card's `window_change`: all but the fastest 0.1 %
    /// of its training windows) gets the newest frame's features alone. `None`: no limit.
    pub change: Option<Vec<f32>>,
}

/// A packed MLP with its output offset and the finiteness check: the one forward pass of a
/// model. Immutable and `Sync`; every caller brings its own [`Scratch`] or [`BatchScratch`].
#[derive(Debug, Clone)]
pub struct Network {
    packed: PackedMlp,
    offset: Option<NewestFeatures>,
}

impl Network {
    /// Packs `mlp` (see [`PackedMlp::new`]) with the output offset `offset`. Refused when
    /// folding the scaling into the weights overflows to a non-finite value.
    pub fn new(mlp: &Mlp, offset: Option<NewestFeatures>) -> Result<Self> {
        let packed = PackedMlp::new(mlp);
        if let Some((layer, value)) = packed.first_non_finite() {
            return Err(Error::NonFiniteWeight {
                name: format!("layers.{layer}.weight (scaling folded in)"),
                index: 0,
                value,
            });
        }
        Ok(Network { packed, offset })
    }

    /// The packed MLP alone (no offset, no check).
    pub fn packed(&self) -> &PackedMlp {
        &self.packed
    }

    /// The output offset, if the model has one.
    pub fn offset(&self) -> Option<&NewestFeatures> {
        self.offset.as_ref()
    }

    /// Work space for [`run`](Self::run).
    pub fn scratch(&self) -> Scratch {
        self.packed.scratch()
    }

    /// Work space for [`run_batch`](Self::run_batch).
    pub fn batch_scratch(&self) -> BatchScratch {
        self.packed.batch_scratch()
    }

    /// The outputs for one window (whole frames' features, oldest first) into `out`
    /// ([`PackedMlp::n_outputs`] values): forward pass, offset, check. A non-finite output is
    /// [`Error::NonFiniteOutput`] naming `frame` (the caller's number for the window's newest
    /// frame); `out` then holds it. Returns false if a correcting model's correction was
    /// withheld (the output is the newest frame's features: see [`NewestFeatures`]), true
    /// otherwise. Does not allocate.
    ///
    /// # Panics
    /// If a length does not match this network (callers check lengths first).
    #[inline]
    pub fn run(&self, window: &[f32], scratch: &mut Scratch, out: &mut [f32], frame: usize) -> Result<bool> {
        self.packed.forward(window, scratch, out);
        self.finish(window, out, frame)
    }

    /// [`run`](Self::run) for [`BATCH`] windows at once, window `s` for frame `first_frame + s`,
    /// into `out` ([`BATCH`] rows of [`PackedMlp::n_outputs`]); bit for bit what `run` gives for
    /// each. On error, the first window with a non-finite output is named. Does not allocate.
    ///
    /// # Panics
    /// If a length does not match this network.
    pub fn run_batch(
        &self,
        windows: [&[f32]; BATCH],
        scratch: &mut BatchScratch,
        out: &mut [f32],
        first_frame: usize,
    ) -> Result<()> {
        let no = self.packed.n_outputs();
        assert_eq!(out.len(), BATCH * no, "one row per window");
        let mut rows = out.chunks_exact_mut(no);
        let outs = std::array::from_fn(|_| rows.next().expect("BATCH rows"));
        self.packed.forward_batch(windows, scratch, outs);
        for (s, (window, row)) in windows.iter().zip(out.chunks_exact_mut(no)).enumerate() {
            self.finish(window, row, first_frame + s)?;
        }
        Ok(())
    }

    /// Adds the offset to the network's outputs `out` for `window` and checks them; false if
    /// the correction was withheld.
    #[inline]
    fn finish(&self, window: &[f32], out: &mut [f32], frame: usize) -> Result<bool> {
        let corrected = self.offset.as_ref().is_none_or(|offset| offset.apply(window, out));
        match out.iter().find(|v| !v.is_finite()) {
            Some(&value) => Err(Error::NonFiniteOutput { frame, value }),
            None => Ok(corrected),
        }
    }
}

impl NewestFeatures {
    /// Adds the newest frame's features of `window` to `out`.
    ///
    /// The network's correction was learned inside its training range only: when the window's
    /// mean features (its posture, noise averaged out) lie outside [`trained`](Self::trained),
    /// the output is the newest frame's features alone (the per-frame solution, exact on clean
    /// markers wherever they are). Measured on real recordings calibrated from themselves with
    /// the 1 kHz model (racing: e_f to −80°, beyond training): racing 6.0° → 4.0° geodesic RMS,
    /// pyomeca 2.2° → 2.0°; on simulated held-out trials at 1 and 5 % noise the MSE is unchanged
    /// to 3 digits (no margin: +17 % and +40 %; a per-frame rule: up to 2.6×, noisy frames stray
    /// past the clean training range).
    ///
    /// Nor was it learned at every speed: a window whose features change faster than the
    /// training windows' ([`change`](Self::change): newer half's mean against the older half's,
    /// so noise averages out; all but the fastest 0.1 % of them) gets the newest frame's
    /// features too. Real wheelchair racing turns the forearm 60° in 40 ms, three times faster
    /// than the random protocol: corrected anyway, those returns cost 10–20° transients
    /// (racing: 3.5° → 2.1° geodesic RMS, largest error 19° → 10°). A quantile, not the
    /// largest: the fastest few windows teach the network little, and one 40 ms burst of the
    /// training sessions set the largest past every racing window.
    ///
    /// Returns false when the correction was withheld.
    #[inline]
    fn apply(&self, window: &[f32], out: &mut [f32]) -> bool {
        let nf = self.features;
        let newest = &window[window.len() - nf..];
        let frames = (window.len() / nf) as f32;
        let half = window.len() / nf / 2;
        let untrained = (0..nf).any(|k| {
            let (mut sum, mut older, mut newer) = (0.0f32, 0.0f32, 0.0f32);
            for (i, &v) in window.iter().skip(k).step_by(nf).enumerate() {
                sum += v;
                if i < half {
                    older += v;
                }
                if i as f32 >= frames - half as f32 {
                    newer += v;
                }
            }
            let mean = sum / frames;
            let beyond_posture = self.trained.as_ref().is_some_and(|(tlo, thi)| !(mean >= tlo[k] && mean <= thi[k]));
            // Not within the limit (NaN is not): beyond, as a NaN mean is.
            let beyond_speed = self.change.as_ref().is_some_and(|c| {
                let change = (newer - older).abs() / half.max(1) as f32;
                !matches!(change.partial_cmp(&c[k]), Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal))
            });
            beyond_posture || beyond_speed
        });
        for (o, f) in out.iter_mut().zip(newest) {
            *o = if untrained { *f } else { *o + f };
        }
        !untrained
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FeatureSet;
    use crate::testing::{random_frames, random_model};

    fn network(offset: Option<NewestFeatures>) -> (Network, Vec<f32>, usize) {
        let model = random_model(FeatureSet::Angles, 5, &[40, 40], 3, 9);
        let nf = FeatureSet::Angles.feature_len();
        let frames = random_frames(FeatureSet::Angles, BATCH + 4, 2);
        let mut features = vec![0f32; (BATCH + 4) * nf];
        FeatureSet::Angles.compute_rows(&frames, &mut features).unwrap();
        (Network::new(model.mlp(), offset).unwrap(), features, nf)
    }

    #[test]
    fn the_offset_adds_the_newest_features_inside_the_trained_range() {
        let (bare, features, nf) = network(None);
        let window = &features[..5 * nf];
        let (mut plain, mut scratch) = ([0f32; 3], bare.scratch());
        bare.run(window, &mut scratch, &mut plain, 4).unwrap();
        let newest = &window[4 * nf..];
        let wide = (vec![-1e3; nf], vec![1e3; nf]);
        let narrow = (vec![1e3; nf], vec![2e3; nf]);
        for (trained, want) in [
            (None, [plain[0] + newest[0], plain[1] + newest[1], plain[2] + newest[2]]),
            (Some(wide), [plain[0] + newest[0], plain[1] + newest[1], plain[2] + newest[2]]),
            (Some(narrow), [newest[0], newest[1], newest[2]]),
        ] {
            let (with, _, _) = network(Some(NewestFeatures { features: nf, trained, change: None }));
            let mut out = [0f32; 3];
            with.run(window, &mut with.scratch(), &mut out, 4).unwrap();
            assert_eq!(out, want);
        }
    }

    #[test]
    fn run_batch_equals_run_and_names_the_first_bad_frame() {
        let nf = FeatureSet::Angles.feature_len();
        let (net, mut features, _) = network(Some(NewestFeatures { features: nf, trained: None, change: None }));
        let windows: [&[f32]; BATCH] = std::array::from_fn(|s| &features[s * nf..(s + 5) * nf]);
        let mut batched = vec![0f32; BATCH * 3];
        net.run_batch(windows, &mut net.batch_scratch(), &mut batched, 100).unwrap();
        let mut scratch = net.scratch();
        for (s, window) in windows.iter().enumerate() {
            let mut one = [0f32; 3];
            net.run(window, &mut scratch, &mut one, 100 + s).unwrap();
            assert_eq!(one.map(f32::to_bits), [0, 1, 2].map(|k| batched[3 * s + k].to_bits()), "window {s}");
        }
        // An infinite newest feature makes the offset output infinite: window 3's newest frame.
        features[7 * nf] = f32::INFINITY;
        let windows: [&[f32]; BATCH] = std::array::from_fn(|s| &features[s * nf..(s + 5) * nf]);
        let e = net.run_batch(windows, &mut net.batch_scratch(), &mut batched, 100).unwrap_err();
        assert!(matches!(e, Error::NonFiniteOutput { frame: 103, .. }), "{e}");
        let e = net.run(windows[3], &mut scratch, &mut [0f32; 3], 42).unwrap_err();
        assert!(matches!(e, Error::NonFiniteOutput { frame: 42, .. }), "{e}");
    }
}
