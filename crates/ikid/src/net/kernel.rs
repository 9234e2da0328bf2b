//! The single-sample forward pass over the blocks `packed.rs` lays out: no allocation, one
//! window at a time (a stream's push).
//!
//! After a ReLU about half of a layer's inputs are exactly zero. Their weight rows
//! contribute nothing, so a layer fed by a ReLU first lists its nonzero inputs and streams
//! only those rows: the weight traffic (the bound) drops with the sparsity. Skipping a
//! `w · 0` term cannot change a finite sum, so results equal the dense product. The AVX2
//! path builds that list eight inputs per step from a compare mask (scalar, it was ~12% of a
//! batch `Model::predict`).

use super::packed::{BLOCK, PackedLayer, PackedMlp, SMALL_BLOCK, Scratch};

/// Independent accumulator sets (interleaved over inputs) of the portable kernel.
const LANES: usize = 4;

impl PackedMlp {
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
    use crate::net::packed::fma_available;
    use crate::net::{Activation, Affine, Dense, Mlp};
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
