//! [`BATCH`] samples at once: each weight row read from L1 feeds six windows, and each
//! 16-output panel of weights read from L2 serves four such groups.
//!
//! A single frame is bound by streaming the weights (see `kernel.rs`); a whole recording
//! need not be. Layers wider than [`SMALL_BLOCK`](super::packed::SMALL_BLOCK) keep a second
//! copy of their weights (packed with the first, in `packed.rs`) as panels of [`PANEL`]
//! outputs, `[panel][input][PANEL]`, read back to back. For every input a panel's two weight
//! vectors are multiplied into six samples' accumulators (12 of the 16 AVX registers), so the
//! loop is bound by FMA throughput, not by loads; only `ceil(n_out / PANEL)` panels are computed. Narrower layers (the output layer)
//! run the single-sample kernel per sample: it sums over each sample's own list of nonzero
//! inputs in four interleaved lanes, an order a batch cannot share.
//!
//! Measured on the development machine (2-core AMD EPYC, Zen 3; `Model::predict` on 4096
//! windows, features included, one thread, interleaved runs): 90→300→300→3 went from 3.75 µs
//! per sample (16-output slices of the 64-wide blocks, scalar active lists) to ~2.7 µs; the
//! inner loop runs at ~6 G FMA/s, about 3/4 of the core's peak. Tried and dropped: four
//! samples × three vectors (16 live registers: LLVM spills, twice as slow); panels aligned to
//! 64 bytes (no measurable change).
//!
//! Every output is summed in the same order as the single-sample kernel (bias, then the
//! inputs in ascending order); that kernel merely skips inputs that are exactly zero, which
//! leaves a finite sum unchanged. So `Model::predict` gives bit for bit what a `Stream` gives.

use super::kernel::forward_portable;
use super::packed::{PANEL, PackedLayer, PackedMlp, Scratch};

/// Samples per batched forward pass: four register-blocked groups of six, so a weight panel
/// read from L2 for the first group is reused from L1 by the others.
pub const BATCH: usize = 24;

/// Work space for [`PackedMlp::forward_batch`]: one [`Scratch`] per sample.
#[derive(Debug, Clone)]
pub struct BatchScratch {
    samples: [Scratch; BATCH],
}

impl PackedMlp {
    /// Work space for [`forward_batch`](Self::forward_batch).
    pub fn batch_scratch(&self) -> BatchScratch {
        BatchScratch { samples: std::array::from_fn(|_| self.scratch()) }
    }

    /// Forward pass of [`BATCH`] input vectors; each output equals what
    /// [`forward`](Self::forward) gives for that input. Does not allocate.
    ///
    /// # Panics
    /// If an input or output length does not match this network.
    pub fn forward_batch(&self, xs: [&[f32]; BATCH], scratch: &mut BatchScratch, outs: [&mut [f32]; BATCH]) {
        for (x, out) in xs.iter().zip(&outs) {
            assert_eq!(x.len(), self.n_inputs(), "network input length");
            assert_eq!(out.len(), self.n_outputs(), "network output length");
        }
        #[cfg(target_arch = "x86_64")]
        if self.use_fma {
            // SAFETY: `use_fma` is true only if the CPU reported AVX2 and FMA at run time.
            #[allow(unsafe_code)]
            unsafe {
                forward_batch_avx2_fma(self, xs, scratch, outs)
            };
            return;
        }
        for ((x, out), sc) in xs.into_iter().zip(outs).zip(&mut scratch.samples) {
            forward_portable(self, x, sc, out);
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn forward_batch_avx2_fma(
    net: &PackedMlp,
    xs: [&[f32]; BATCH],
    scratch: &mut BatchScratch,
    mut outs: [&mut [f32]; BATCH],
) {
    use super::kernel::avx2;
    let last = net.layers.len() - 1;
    for (k, layer) in net.layers.iter().enumerate() {
        // Layer k reads buffer `b` and writes `a` when k is even, the other way when odd.
        let mut srcs: [&[f32]; BATCH] = [&[]; BATCH];
        let mut dsts: [&mut [f32]; BATCH] = Default::default();
        let mut actives: [&mut [u32]; BATCH] = Default::default();
        for (s, sc) in scratch.samples.iter_mut().enumerate() {
            let Scratch { a, b, active } = sc;
            let (src, dst) = if k % 2 == 0 { (&b[..], &mut a[..]) } else { (&a[..], &mut b[..]) };
            srcs[s] = if k == 0 { xs[s] } else { &src[..layer.n_in] };
            dsts[s] = &mut dst[..layer.batch_padded_out()];
            actives[s] = &mut active[..];
        }
        if !layer.panels.is_empty() {
            avx2_batch::layer_batch(layer, srcs, &mut dsts);
        } else {
            for s in 0..BATCH {
                let n = avx2::active_inputs(layer, srcs[s], actives[s]);
                avx2::small_layer(layer, srcs[s], &actives[s][..n], dsts[s]);
            }
        }
        if k == last {
            for (out, dst) in outs.iter_mut().zip(&dsts) {
                out.copy_from_slice(&dst[..layer.n_out]);
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod avx2_batch {
    use super::{BATCH, PANEL, PackedLayer};
    use std::arch::x86_64::*;

    /// Samples per register block.
    const S: usize = 6;
    /// Vectors of outputs per register block (S × V = 12 accumulators).
    const V: usize = PANEL / 8;
    const GROUPS: usize = BATCH / S;

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn layer_batch(layer: &PackedLayer, xs: [&[f32]; BATCH], ys: &mut [&mut [f32]; BATCH]) {
        let n_in = layer.n_in;
        let zero = _mm256_setzero_ps();
        // Raw pointers in the hot loop: the bounds are established once, here.
        assert!(xs.iter().all(|x| x.len() >= n_in) && ys.iter().all(|y| y.len() >= layer.panel_bias.len()));
        for (p, (w, bias)) in
            layer.panels.chunks_exact(n_in * PANEL).zip(layer.panel_bias.chunks_exact(PANEL)).enumerate()
        {
            let wp = w.as_ptr();
            // This panel's weights (n_in rows × PANEL floats) stay in L1 across the groups.
            for g in 0..GROUPS {
                // SAFETY: `bias` holds PANEL = 8 V floats.
                let b: [__m256; V] = std::array::from_fn(|v| unsafe { _mm256_loadu_ps(bias.as_ptr().add(8 * v)) });
                let mut acc = [b; S];
                let xp: [*const f32; S] = std::array::from_fn(|s| xs[g * S + s].as_ptr());
                for j in 0..n_in {
                    // SAFETY: j < n_in, so row j's PANEL floats at j·PANEL lie inside `w`
                    // (length n_in·PANEL) and xs[s][j] inside each input (length ≥ n_in).
                    unsafe {
                        let r = wp.add(j * PANEL);
                        let wv: [__m256; V] = std::array::from_fn(|v| _mm256_loadu_ps(r.add(8 * v)));
                        for s in 0..S {
                            let x = _mm256_broadcast_ss(&*xp[s].add(j));
                            for v in 0..V {
                                acc[s][v] = _mm256_fmadd_ps(wv[v], x, acc[s][v]);
                            }
                        }
                    }
                }
                let o = p * PANEL;
                for (y, acc_s) in ys[g * S..(g + 1) * S].iter_mut().zip(&acc) {
                    let dst = &mut y[o..o + PANEL];
                    for (v, &a) in acc_s.iter().enumerate() {
                        let val = if layer.relu { _mm256_max_ps(a, zero) } else { a };
                        // SAFETY: `dst` holds PANEL = 8 V floats.
                        unsafe { _mm256_storeu_ps(dst.as_mut_ptr().add(8 * v), val) };
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::BATCH;
    use crate::FeatureSet;
    use crate::testing::{random_frames, random_model};

    #[test]
    fn forward_batch_equals_forward_bit_for_bit() {
        for (set, hidden) in [
            (FeatureSet::Markers, &[300, 300][..]),
            (FeatureSet::JointState, &[330, 60, 165]),
            (FeatureSet::Relative, &[70, 9]),
        ] {
            let model = random_model(set, 5, hidden, 3, 4);
            let net = model.net().packed();
            let nf = set.feature_len();
            let frames = random_frames(set, BATCH + 4, 5);
            let mut features = vec![0f32; (BATCH + 4) * nf];
            set.compute_rows(&frames, &mut features).unwrap();
            let xs: [&[f32]; BATCH] = std::array::from_fn(|s| &features[s * nf..(s + 5) * nf]);
            let mut single = [[0f32; 3]; BATCH];
            let mut sc = net.scratch();
            for (x, out) in xs.iter().zip(&mut single) {
                net.forward(x, &mut sc, out);
            }
            let mut batched = [[0f32; 3]; BATCH];
            let mut rows = batched.iter_mut();
            net.forward_batch(xs, &mut net.batch_scratch(), std::array::from_fn(|_| &mut rows.next().unwrap()[..]));
            assert_eq!(single.map(|o| o.map(f32::to_bits)), batched.map(|o| o.map(f32::to_bits)), "{hidden:?}");
        }
    }
}
