//! The packed forms of an [`Mlp`], both of them, and the one place they are laid out: the
//! single-sample kernel (`kernel.rs`) reads the blocks, the batch kernel (`batch.rs`) the panels.
//!
//! **Blocks** (every layer). A batch-1 MLP is a chain of matrix-vector products, bound by how
//! fast the weights stream from cache. Each layer's outputs are cut into blocks of `B` (64, or
//! 8 for tiny layers); a block's weights are stored input by input (`[block][input][B]`), so the
//! kernel reads them sequentially and keeps a block's partial sums in eight AVX registers (one
//! set of eight vectors for `B = 64`; four interleaved input streams of one vector for `B = 8`),
//! enough independent FMA chains to hide their latency. Padded outputs have zero weights and
//! bias. Measured on the development machine (90→300→300→3, a timed push loop): B = 16
//! ~8–10 µs, B = 32 ~7.5–8.5 µs, B = 64 ~6–8 µs per push.
//!
//! **Panels** (layers wider than [`SMALL_BLOCK`]). A second copy of the same weights as panels
//! of [`PANEL`] outputs, `[panel][input][PANEL]`, read back to back by the batch kernel.
//!
//! The input affine map is folded into the first layer and the output map into the last:
//! `W (x∘s + t) + b = (W diag s) x + (W t + b)`. Folding is done in f64 and rounds once; both
//! copies hold the same rounded values.

use super::mlp::{Activation, Mlp};

/// Outputs per block for layers wider than [`SMALL_BLOCK`].
pub(super) const BLOCK: usize = 64;
/// Outputs per block for layers with at most this many outputs.
pub(super) const SMALL_BLOCK: usize = 8;

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
    pub(super) n_in: usize,
    pub(super) n_out: usize,
    /// Widest layer input or padded output: the scratch buffers' length.
    pub(super) max_width: usize,
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
