//! The fast forward pass: weights packed for streaming, scaling folded in, no allocation.
//! This file owns both packed layouts (the blocks read here and the panels `batch.rs` reads).
//!
//! A batch-1 MLP is a chain of matrix-vector products, bound by how fast the weights stream
//! from cache. Each layer's outputs are cut into blocks of `B` (64, or 8 for tiny layers);
//! a block's weights are stored input by input (`[block][input][B]`), so the kernel reads
//! them sequentially and keeps a block's partial sums in eight AVX registers (one set of
//! eight vectors for `B = 64`; four interleaved input streams of one vector for `B = 8`),
//! enough independent FMA chains to hide their latency. Padded outputs have zero weights
//! and bias. Measured on the development machine (90→300→300→3, a timed
//! push loop): B = 16 ~8–10 µs, B = 32 ~7.5–8.5 µs, B = 64 ~6–8 µs per push.
//!
//! After a ReLU about half of a layer's inputs are exactly zero. Their weight rows
//! contribute nothing, so a layer fed by a ReLU first lists its nonzero inputs and streams
//! only those rows: the weight traffic (the bound) drops with the sparsity. Skipping a
//! `w · 0` term cannot change a finite sum, so results equal the dense product. The AVX2
//! path builds that list eight inputs per step from a compare mask (scalar, it was ~12% of a
//! batch `Model::predict`).
//!
//! The input affine map is folded into the first layer and the output map into the last:
//! `W (x∘s + t) + b = (W diag s) x + (W t + b)`. Folding is done in f64 and rounds once.

use super::mlp::{Activation, Mlp};

/// Outputs per block for layers wider than [`SMALL_BLOCK`].
pub(super) const BLOCK: usize = 64;
/// Outputs per block for layers with at most this many outputs.
pub(super) const SMALL_BLOCK: usize = 8;
/// Independent accumulator sets (interleaved over inputs) of the portable kernel.
const LANES: usize = 4;

/// One packed dense layer.
#[derive(Debug, Clone)]
pub(super) struct PackedLayer {
    pub(super) n_in: usize,
    pub(super) n_out: usize,
    pub(super) block: usize,
    /// `[n_blocks][n_in][block]`.
    pub(super) weights: Vec<f32>,
    /// `[n_blocks * block]`, zero-padded.
    pub(super) bias: Vec<f32>,
    pub(super) relu: bool,
    /// Input comes from a ReLU: list the nonzero inputs and skip the rest.
    pub(super) sparse_input: bool,
    /// The same weights for the batch kernel (`batch.rs`), `[n_panels][n_in][PANEL]`;
    /// empty for layers of at most [`SMALL_BLOCK`] outputs.
    pub(super) panels: Vec<f32>,
    /// `[n_panels * PANEL]`, zero-padded.
    pub(super) panel_bias: Vec<f32>,
}

impl PackedLayer {
    pub(super) fn padded_out(&self) -> usize {
        self.bias.len()
    }

    /// Outputs the batch kernel writes (padding included).
    pub(super) fn batch_padded_out(&self) -> usize {
        if self.panels.is_empty() { self.padded_out() } else { self.panel_bias.len() }
    }
}

/// An [`Mlp`] packed for the fast kernel. Immutable and `Sync`: many streams share one.
#[derive(Debug, Clone)]
pub struct PackedMlp {
    pub(super) layers: Vec<PackedLayer>,
    n_in: usize,
    n_out: usize,
    max_width: usize,
    pub(super) use_fma: bool,
}

/// Per-caller work space for [`PackedMlp::forward`]; create once, reuse for every call.
#[derive(Debug, Clone)]
pub struct Scratch {
    pub(super) a: Vec<f32>,
    pub(super) b: Vec<f32>,
    /// Indices of the nonzero inputs of the current layer.
    pub(super) active: Vec<u32>,
}

impl PackedMlp {
    /// Packs `mlp`, folding its input and output scaling into the first and last layers.
    pub fn new(mlp: &Mlp) -> Self {
        let n_layers = mlp.layers.len();
        let layers: Vec<PackedLayer> = mlp
            .layers
            .iter()
            .enumerate()
            .map(|(k, l)| {
                let (n_out, n_in) = l.weight.shape();
                // Effective weight w'[o][i] and bias b'[o] in f64, with folding.
                let mut w = vec![0f64; n_out * n_in];
                let mut b: Vec<f64> = l.bias.iter().map(|&v| v as f64).collect();
                for o in 0..n_out {
                    for i in 0..n_in {
                        let mut wi = l.weight[(o, i)] as f64;
                        if k == 0 {
                            b[o] += wi * mlp.input.shift[i] as f64;
                            wi *= mlp.input.scale[i] as f64;
                        }
                        w[o * n_in + i] = wi;
                    }
                }
                if k == n_layers - 1 {
                    for o in 0..n_out {
                        let (s, t) = (mlp.output.scale[o] as f64, mlp.output.shift[o] as f64);
                        b[o] = b[o] * s + t;
                        for i in 0..n_in {
                            w[o * n_in + i] *= s;
                        }
                    }
                }
                let block = if n_out <= SMALL_BLOCK { SMALL_BLOCK } else { BLOCK };
                let n_blocks = n_out.div_ceil(block);
                let mut weights = vec![0f32; n_blocks * n_in * block];
                let mut bias = vec![0f32; n_blocks * block];
                for o in 0..n_out {
                    let (blk, lane) = (o / block, o % block);
                    bias[o] = b[o] as f32;
                    for i in 0..n_in {
                        weights[(blk * n_in + i) * block + lane] = w[o * n_in + i] as f32;
                    }
                }
                let sparse_input = k > 0 && mlp.layers[k - 1].activation == Activation::Relu;
                let mut layer = PackedLayer {
                    n_in,
                    n_out,
                    block,
                    weights,
                    bias,
                    relu: l.activation == Activation::Relu,
                    sparse_input,
                    panels: vec![],
                    panel_bias: vec![],
                };
                if block == BLOCK {
                    (layer.panels, layer.panel_bias) = pack_panels(&layer);
                }
                layer
            })
            .collect();
        // Scratch holds any layer's input (for the active list) or padded output.
        let max_width = layers.iter().map(|l| l.padded_out().max(l.batch_padded_out()).max(l.n_in)).max().unwrap_or(0);
        PackedMlp { n_in: mlp.n_inputs(), n_out: mlp.n_outputs(), layers, max_width, use_fma: fma_available() }
    }

    /// Network input width.
    pub fn n_inputs(&self) -> usize {
        self.n_in
    }

    /// Network output width.
    pub fn n_outputs(&self) -> usize {
        self.n_out
    }

    /// The first layer whose packed (scaling-folded) weights or biases hold a non-finite
    /// value, with that value.
    pub fn first_non_finite(&self) -> Option<(usize, f32)> {
        self.layers
            .iter()
            .enumerate()
            .find_map(|(k, l)| l.weights.iter().chain(&l.bias).find(|v| !v.is_finite()).map(|&v| (k, v)))
    }

    /// Work space sized for this network.
    pub fn scratch(&self) -> Scratch {
        Scratch { a: vec![0.0; self.max_width], b: vec![0.0; self.max_width], active: vec![0; self.max_width] }
    }

    /// Bytes of packed weights and biases streamed per forward pass.
    pub fn weight_bytes(&self) -> usize {
        self.layers.iter().map(|l| 4 * (l.weights.len() + l.bias.len())).sum()
    }

    /// Forward pass of one input vector into `out` (length [`n_outputs`](Self::n_outputs)).
    /// Does not allocate.
    ///
    /// # Panics
    /// If `x`, `out` or `scratch` do not match this network (callers check lengths first).
    pub fn forward(&self, x: &[f32], scratch: &mut Scratch, out: &mut [f32]) {
        assert_eq!(x.len(), self.n_in, "network input length");
        assert_eq!(out.len(), self.n_out, "network output length");
        assert!(scratch.a.len() >= self.max_width, "scratch built for another network");
        #[cfg(target_arch = "x86_64")]
        if self.use_fma {
            // SAFETY: `use_fma` is true only if the CPU reported AVX2 and FMA at run time.
            #[allow(unsafe_code)]
            unsafe {
                forward_avx2_fma(self, x, scratch, out)
            };
            return;
        }
        forward_portable(self, x, scratch, out);
    }
}

/// Outputs per panel of the batch kernel's (`batch.rs`)'s weight copy (two AVX vectors).
pub(super) const PANEL: usize = 16;

/// A wide layer's weights as panels of [`PANEL`] outputs, `[panel][input][PANEL]`, so the
/// batch kernel reads one panel's rows back to back; and its bias per panel. Zero-padded.
pub(super) fn pack_panels(layer: &PackedLayer) -> (Vec<f32>, Vec<f32>) {
    let (n_in, n_out) = (layer.n_in, layer.n_out);
    let n_panels = n_out.div_ceil(PANEL);
    let mut panels = vec![0f32; n_panels * n_in * PANEL];
    let mut bias = vec![0f32; n_panels * PANEL];
    bias[..n_out].copy_from_slice(&layer.bias[..n_out]);
    for o in 0..n_out {
        let (p, lane) = (o / PANEL, o % PANEL);
        for j in 0..n_in {
            panels[(p * n_in + j) * PANEL + lane] = layer.weights[((o / BLOCK) * n_in + j) * BLOCK + o % BLOCK];
        }
    }
    (panels, bias)
}

pub(super) fn fma_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The x86-64 path: explicit AVX2 + FMA (the autovectoriser does not vectorise across the
/// accumulator arrays of the portable code).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn forward_avx2_fma(net: &PackedMlp, x: &[f32], scratch: &mut Scratch, out: &mut [f32]) {
    forward_with(net, x, scratch, out, |layer, input, active, y| {
        let n = avx2::active_inputs(layer, input, active);
        let active = &active[..n];
        match layer.block {
            BLOCK => avx2::layer::<BLOCK, { BLOCK / 8 }, { 64 / BLOCK }>(layer, input, active, y),
            _ => avx2::small_layer(layer, input, active, y),
        }
    });
}

/// The portable path (any CPU; also the test of the packing independent of the SIMD code).
pub(super) fn forward_portable(net: &PackedMlp, x: &[f32], scratch: &mut Scratch, out: &mut [f32]) {
    forward_with(net, x, scratch, out, |layer, input, active, y| {
        let n = active_inputs(layer, input, active);
        let active = &active[..n];
        match layer.block {
            BLOCK => portable_layer::<BLOCK>(layer, input, active, y),
            _ => portable_layer::<SMALL_BLOCK>(layer, input, active, y),
        }
    });
}

/// Runs the layers, ping-ponging between the two scratch buffers. `layer_fn` computes one
/// layer, listing the inputs it reads in the `active` buffer first.
#[inline(always)]
fn forward_with(
    net: &PackedMlp,
    x: &[f32],
    scratch: &mut Scratch,
    out: &mut [f32],
    mut layer_fn: impl FnMut(&PackedLayer, &[f32], &mut [u32], &mut [f32]),
) {
    let Scratch { a, b, active } = scratch;
    let (mut src, mut dst): (&mut Vec<f32>, &mut Vec<f32>) = (a, b);
    let last = net.layers.len() - 1;
    for (k, layer) in net.layers.iter().enumerate() {
        let input: &[f32] = if k == 0 { x } else { &src[..layer.n_in] };
        let y = &mut dst[..layer.padded_out()];
        layer_fn(layer, input, active, y);
        if k == last {
            out.copy_from_slice(&y[..layer.n_out]);
        }
        std::mem::swap(&mut src, &mut dst);
    }
}

/// Lists the inputs a layer must read into `active` (all, or the nonzero ones after a ReLU).
#[inline(always)]
pub(super) fn active_inputs(layer: &PackedLayer, input: &[f32], active: &mut [u32]) -> usize {
    if !layer.sparse_input {
        return all_inputs(input.len(), active);
    }
    // Branch-free compaction.
    let mut n = 0;
    for (j, &v) in input.iter().enumerate() {
        active[n] = j as u32;
        n += usize::from(v != 0.0);
    }
    n
}

/// Lists every input, `0..n`.
fn all_inputs(n: usize, active: &mut [u32]) -> usize {
    for (j, a) in active[..n].iter_mut().enumerate() {
        *a = j as u32;
    }
    n
}

/// Portable kernel: `LANES` interleaved accumulator sets of `B` outputs per block.
fn portable_layer<const B: usize>(layer: &PackedLayer, x: &[f32], active: &[u32], y: &mut [f32]) {
    let n_in = x.len();
    let split = active.len() - active.len() % LANES;
    let blocks = layer.weights.chunks_exact(B * n_in).zip(layer.bias.chunks_exact(B)).zip(y.chunks_exact_mut(B));
    for ((w, bias), yb) in blocks {
        let mut acc = [[0f32; B]; LANES];
        acc[0].copy_from_slice(bias);
        for js in active[..split].chunks_exact(LANES) {
            for (u, acc_u) in acc.iter_mut().enumerate() {
                let j = js[u] as usize;
                let (xj, wj) = (x[j], &w[j * B..(j + 1) * B]);
                for l in 0..B {
                    acc_u[l] += wj[l] * xj;
                }
            }
        }
        for &j in &active[split..] {
            let (xj, wj) = (x[j as usize], &w[j as usize * B..(j as usize + 1) * B]);
            for l in 0..B {
                acc[0][l] += wj[l] * xj;
            }
        }
        for l in 0..B {
            let v = (acc[0][l] + acc[1][l]) + (acc[2][l] + acc[3][l]);
            yb[l] = if layer.relu { v.max(0.0) } else { v };
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
pub(super) mod avx2 {
    use super::{PackedLayer, SMALL_BLOCK};
    use std::arch::x86_64::*;

    /// For each 8-bit mask, the positions of its set bits, lowest first (then zeros).
    const POSITIONS: [[u8; 8]; 256] = {
        let mut t = [[0u8; 8]; 256];
        let mut m = 0;
        while m < 256 {
            let (mut bit, mut n) = (0, 0);
            while bit < 8 {
                if m & (1 << bit) != 0 {
                    t[m][n] = bit as u8;
                    n += 1;
                }
                bit += 1;
            }
            m += 1;
        }
        t
    };

    /// [`super::active_inputs`], eight inputs per step: the nonzero lanes' indices are
    /// looked up from the compare mask and stored at once. Same list, a fraction of the time.
    #[target_feature(enable = "avx2,fma")]
    pub(in crate::net) fn active_inputs(layer: &PackedLayer, input: &[f32], active: &mut [u32]) -> usize {
        if !layer.sparse_input {
            return super::all_inputs(input.len(), active);
        }
        let zero = _mm256_setzero_ps();
        let mut n = 0;
        let chunks = input.chunks_exact(8);
        let tail = chunks.remainder();
        for (c, x) in chunks.enumerate() {
            // SAFETY: `x` holds 8 floats.
            let v = unsafe { _mm256_loadu_ps(x.as_ptr()) };
            // Unordered-or-not-equal: NaN counts as nonzero, as `v != 0.0` does.
            let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_NEQ_UQ>(v, zero)) as usize;
            let pos = _mm_cvtsi64_si128(i64::from_le_bytes(POSITIONS[mask]));
            let idx = _mm256_add_epi32(_mm256_cvtepu8_epi32(pos), _mm256_set1_epi32(8 * c as i32));
            // n ≤ 8c, so these 8 slots lie within the input's length (≤ active.len()).
            let dst = &mut active[n..n + 8];
            // SAFETY: `dst` holds 8 u32.
            unsafe { _mm256_storeu_si256(dst.as_mut_ptr().cast(), idx) };
            n += (mask as u32).count_ones() as usize;
        }
        let base = input.len() - tail.len();
        for (j, &v) in tail.iter().enumerate() {
            active[n] = (base + j) as u32;
            n += usize::from(v != 0.0);
        }
        n
    }

    /// A layer of [`SMALL_BLOCK`] outputs: four interleaved accumulator vectors.
    #[target_feature(enable = "avx2,fma")]
    pub(in crate::net) fn small_layer(small: &PackedLayer, x: &[f32], active: &[u32], y: &mut [f32]) {
        layer::<SMALL_BLOCK, { SMALL_BLOCK / 8 }, 4>(small, x, active, y)
    }

    /// How many active inputs ahead to prefetch weight rows.
    const PREFETCH_AHEAD: usize = 8;

    /// AVX2 kernel: `B` outputs per block as `V = B / 8` vectors, `LANES` interleaved
    /// accumulator sets (`LANES × V` registers) to hide the FMA latency.
    #[target_feature(enable = "avx2,fma")]
    pub(in crate::net) fn layer<const B: usize, const V: usize, const LANES: usize>(
        layer: &PackedLayer,
        x: &[f32],
        active: &[u32],
        y: &mut [f32],
    ) {
        assert!(B == 8 * V);
        let n_in = x.len();
        let split = active.len() - active.len() % LANES;
        let blocks = layer.weights.chunks_exact(B * n_in).zip(layer.bias.chunks_exact(B)).zip(y.chunks_exact_mut(B));
        // `row(w, j)` is the j-th input's B weights: bounds-checked slice, then SIMD loads.
        let row = |w: &[f32], j: usize| -> [__m256; V] {
            let r = &w[j * B..(j + 1) * B];
            // SAFETY: `r` holds B = 8 V floats, so each 8-float unaligned load is in bounds.
            std::array::from_fn(|v| unsafe { _mm256_loadu_ps(r.as_ptr().add(8 * v)) })
        };
        for ((w, bias), yb) in blocks {
            let zero = _mm256_setzero_ps();
            let mut acc = [[zero; V]; LANES];
            // SAFETY: `bias` holds B floats.
            acc[0] = std::array::from_fn(|v| unsafe { _mm256_loadu_ps(bias.as_ptr().add(8 * v)) });
            for (c, js) in active[..split].chunks_exact(LANES).enumerate() {
                // Rows of skipped inputs leave holes the hardware prefetcher does not
                // foresee: fetch the row PREFETCH_AHEAD active inputs ahead.
                if let Some(&ahead) = active.get(c * LANES + PREFETCH_AHEAD) {
                    let r = &w[ahead as usize * B..(ahead as usize + 1) * B];
                    for line in (0..B).step_by(16) {
                        _mm_prefetch::<_MM_HINT_T0>(r[line..].as_ptr().cast());
                    }
                }
                for u in 0..LANES {
                    let j = js[u] as usize;
                    let xj = _mm256_set1_ps(x[j]);
                    let wj = row(w, j);
                    for v in 0..V {
                        acc[u][v] = _mm256_fmadd_ps(wj[v], xj, acc[u][v]);
                    }
                }
            }
            for &j in &active[split..] {
                let xj = _mm256_set1_ps(x[j as usize]);
                let wj = row(w, j as usize);
                for v in 0..V {
                    acc[0][v] = _mm256_fmadd_ps(wj[v], xj, acc[0][v]);
                }
            }
            for v in 0..V {
                let mut s = acc[0][v];
                for a in &acc[1..] {
                    s = _mm256_add_ps(s, a[v]);
                }
                if layer.relu {
                    s = _mm256_max_ps(s, zero);
                }
                let dst = &mut yb[8 * v..8 * v + 8];
                // SAFETY: `dst` holds 8 floats.
                unsafe { _mm256_storeu_ps(dst.as_mut_ptr(), s) };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::{Affine, Dense};
    use crate::testing::SplitMix;
    use nalgebra::{DMatrix, DVector};

    fn random_mlp(widths: &[usize], seed: u64) -> Mlp {
        let mut rng = SplitMix::new(seed);
        let mut r = |n: usize, m: usize| DMatrix::from_fn(n, m, |_, _| rng.uniform(-0.3, 0.3) as f32);
        let layers = widths
            .windows(2)
            .enumerate()
            .map(|(k, w)| Dense {
                weight: r(w[1], w[0]),
                bias: r(w[1], 1).column(0).into_owned(),
                activation: if k + 2 == widths.len() { Activation::Identity } else { Activation::Relu },
            })
            .collect();
        let n_in = widths[0];
        let n_out = *widths.last().unwrap();
        let input = Affine { scale: r(n_in, 1).column(0).map(|v| 1.0 + v), shift: r(n_in, 1).column(0).into_owned() };
        let output = Affine { scale: DVector::from_element(n_out, 2.5), shift: DVector::from_element(n_out, -0.1) };
        Mlp::new(input, layers, output).unwrap()
    }

    /// Whether the AVX2+FMA kernel can be tested here. CI machines have it (the design's
    /// target CPU): there its absence fails the test rather than skipping the kernel unseen.
    fn fma_testable() -> bool {
        let available = fma_available();
        if !available {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI must test the AVX2+FMA kernel, but this CPU lacks AVX2 or FMA"
            );
            eprintln!("skipped: this CPU lacks AVX2+FMA, so only the portable kernel is tested");
        }
        available
    }

    fn check_against_oracle(widths: &[usize], use_fma: bool) {
        let mlp = random_mlp(widths, 7);
        let mut packed = PackedMlp::new(&mlp);
        packed.use_fma = use_fma && fma_testable();
        let mut scratch = packed.scratch();
        let mut out = vec![0f32; packed.n_outputs()];
        let mut rng = SplitMix::new(11);
        for _ in 0..20 {
            let x: Vec<f32> = (0..widths[0]).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
            packed.forward(&x, &mut scratch, &mut out);
            let want = mlp.forward_reference(&x);
            assert_eq!(want.len(), out.len(), "the oracle gives one value per output");
            let scale = want.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
            for (g, w) in out.iter().zip(&want) {
                assert!((g - w).abs() <= 1e-5 * scale, "{widths:?} fma={use_fma}: {g} vs {w}");
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn simd_active_list_equals_scalar() {
        if !fma_testable() {
            return;
        }
        let mut rng = SplitMix::new(3);
        for n_in in 0..42 {
            let layer = PackedLayer {
                n_in,
                n_out: 1,
                block: SMALL_BLOCK,
                weights: vec![],
                bias: vec![],
                relu: false,
                sparse_input: true,
                panels: vec![],
                panel_bias: vec![],
            };
            for _ in 0..20 {
                let x: Vec<f32> = (0..n_in)
                    .map(|_| match rng.uniform(0.0, 5.0) as u32 {
                        0 => 0.0,
                        1 => -0.0,
                        2 => f32::NAN,
                        _ => rng.uniform(-1.0, 1.0) as f32,
                    })
                    .collect();
                let (mut want, mut got) = (vec![0u32; n_in], vec![0u32; n_in]);
                let n = active_inputs(&layer, &x, &mut want);
                // SAFETY: the CPU has AVX2 and FMA (checked above).
                #[allow(unsafe_code)]
                let m = unsafe { avx2::active_inputs(&layer, &x, &mut got) };
                assert_eq!(&want[..n], &got[..m], "{x:?}");
            }
        }
    }

    #[test]
    fn packed_matches_oracle_on_thesis_shapes() {
        for widths in [&[90, 300, 300, 3][..], &[120, 240, 240, 3], &[45, 330, 60, 165, 3], &[7, 5, 2], &[3, 17, 9]] {
            check_against_oracle(widths, true);
            check_against_oracle(widths, false);
        }
    }
}
