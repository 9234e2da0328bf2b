//! The fast forward pass: weights packed for streaming, scaling folded in, no allocation.
//!
//! A batch-1 MLP is a chain of matrix-vector products, bound by how fast the weights stream
//! from cache. Each layer's outputs are cut into blocks of `B` (16, or 8 for tiny layers);
//! a block's weights are stored input by input (`[block][input][B]`), so the kernel reads
//! them strictly sequentially and keeps `4 × B` partial sums in registers (four interleaved
//! input streams hide the FMA latency). Padded outputs have zero weights and bias.
//!
//! The input affine map is folded into the first layer and the output map into the last:
//! `W (x∘s + t) + b = (W diag s) x + (W t + b)`. Folding is done in f64 and rounds once.

use super::mlp::{Activation, Mlp};

/// Outputs per block for layers wider than [`SMALL_BLOCK`].
const BLOCK: usize = 16;
/// Outputs per block for layers with at most this many outputs.
const SMALL_BLOCK: usize = 8;
/// Independent accumulator sets (interleaved over inputs).
const LANES: usize = 4;

/// One packed dense layer.
#[derive(Debug, Clone)]
struct PackedLayer {
    n_in: usize,
    n_out: usize,
    block: usize,
    /// `[n_blocks][n_in][block]`.
    weights: Vec<f32>,
    /// `[n_blocks * block]`, zero-padded.
    bias: Vec<f32>,
    relu: bool,
}

impl PackedLayer {
    fn padded_out(&self) -> usize {
        self.bias.len()
    }
}

/// An [`Mlp`] packed for the fast kernel. Immutable and `Sync`: many streams share one.
#[derive(Debug, Clone)]
pub struct PackedMlp {
    layers: Vec<PackedLayer>,
    n_in: usize,
    n_out: usize,
    max_width: usize,
    use_fma: bool,
}

/// Per-caller work space for [`PackedMlp::forward`]; create once, reuse for every call.
#[derive(Debug, Clone)]
pub struct Scratch {
    a: Vec<f32>,
    b: Vec<f32>,
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
                PackedLayer { n_in, n_out, block, weights, bias, relu: l.activation == Activation::Relu }
            })
            .collect();
        let max_width = layers.iter().map(PackedLayer::padded_out).max().unwrap_or(0);
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

    /// Work space sized for this network.
    pub fn scratch(&self) -> Scratch {
        Scratch { a: vec![0.0; self.max_width], b: vec![0.0; self.max_width] }
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
        forward_impl::<false>(self, x, scratch, out);
    }
}

fn fma_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The same code compiled with AVX2 + FMA enabled (the generic body is `inline(always)`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn forward_avx2_fma(net: &PackedMlp, x: &[f32], scratch: &mut Scratch, out: &mut [f32]) {
    forward_impl::<true>(net, x, scratch, out);
}

#[inline(always)]
fn forward_impl<const FMA: bool>(net: &PackedMlp, x: &[f32], scratch: &mut Scratch, out: &mut [f32]) {
    let Scratch { a, b } = scratch;
    let (mut src, mut dst): (&mut Vec<f32>, &mut Vec<f32>) = (a, b);
    let last = net.layers.len() - 1;
    for (k, layer) in net.layers.iter().enumerate() {
        let input: &[f32] = if k == 0 { x } else { &src[..layer.n_in] };
        let y = &mut dst[..layer.padded_out()];
        match layer.block {
            BLOCK => layer_forward::<BLOCK, FMA>(layer, input, y),
            _ => layer_forward::<SMALL_BLOCK, FMA>(layer, input, y),
        }
        if k == last {
            out.copy_from_slice(&y[..layer.n_out]);
        }
        std::mem::swap(&mut src, &mut dst);
    }
}

#[inline(always)]
fn layer_forward<const B: usize, const FMA: bool>(layer: &PackedLayer, x: &[f32], y: &mut [f32]) {
    let n_in = x.len();
    let split = n_in - n_in % LANES;
    let blocks = layer.weights.chunks_exact(B * n_in).zip(layer.bias.chunks_exact(B)).zip(y.chunks_exact_mut(B));
    for ((w, bias), yb) in blocks {
        let mut acc = [[0f32; B]; LANES];
        acc[0].copy_from_slice(bias);
        for (xs, ws) in x[..split].chunks_exact(LANES).zip(w[..split * B].chunks_exact(LANES * B)) {
            for (u, acc_u) in acc.iter_mut().enumerate() {
                let xj = xs[u];
                let wj = &ws[u * B..(u + 1) * B];
                for l in 0..B {
                    acc_u[l] = madd::<FMA>(wj[l], xj, acc_u[l]);
                }
            }
        }
        for (j, &xj) in x.iter().enumerate().skip(split) {
            let wj = &w[j * B..(j + 1) * B];
            for l in 0..B {
                acc[0][l] = madd::<FMA>(wj[l], xj, acc[0][l]);
            }
        }
        for l in 0..B {
            let v = (acc[0][l] + acc[1][l]) + (acc[2][l] + acc[3][l]);
            yb[l] = if layer.relu { v.max(0.0) } else { v };
        }
    }
}

#[inline(always)]
fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::{Affine, Dense};
    use nalgebra::{DMatrix, DVector};
    use crate::testing::SplitMix;

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

    fn check_against_oracle(widths: &[usize], use_fma: bool) {
        let mlp = random_mlp(widths, 7);
        let mut packed = PackedMlp::new(&mlp);
        packed.use_fma = use_fma && fma_available();
        let mut scratch = packed.scratch();
        let mut out = vec![0f32; packed.n_outputs()];
        let mut rng = SplitMix::new(11);
        for _ in 0..20 {
            let x: Vec<f32> = (0..widths[0]).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
            packed.forward(&x, &mut scratch, &mut out);
            let want = mlp.forward_reference(&x);
            let scale = want.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
            for (g, w) in out.iter().zip(&want) {
                assert!((g - w).abs() <= 1e-5 * scale, "{widths:?} fma={use_fma}: {g} vs {w}");
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
