//! The MLP as loaded from a model file, in plain nalgebra: the test oracle for the kernel.
//!
//! `y = out.apply(L_n(... L_1(inp.apply(x))))` where each dense layer computes
//! `act(W x + b)` with `W` stored `[out, in]` as torch does.

use crate::error::{Error, Result};
use nalgebra::{DMatrix, DVector};

/// Activation after a dense layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Activation {
    /// `max(0, x)`.
    Relu,
    /// No activation (the output layer).
    Identity,
}

impl Activation {
    /// Name used in model cards.
    pub fn name(self) -> &'static str {
        match self {
            Activation::Relu => "relu",
            Activation::Identity => "identity",
        }
    }

    /// Applies the activation in place.
    pub fn apply(self, v: &mut [f32]) {
        if self == Activation::Relu {
            for x in v {
                *x = x.max(0.0);
            }
        }
    }
}

/// Element-wise affine map `x * scale + shift` (input/output scaling, e.g. min–max).
#[derive(Debug, Clone, PartialEq)]
pub struct Affine {
    /// Multiplier per element.
    pub scale: DVector<f32>,
    /// Offset per element, added after scaling.
    pub shift: DVector<f32>,
}

impl Affine {
    /// The identity map on `n` elements.
    pub fn identity(n: usize) -> Self {
        Affine { scale: DVector::from_element(n, 1.0), shift: DVector::zeros(n) }
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.scale.len()
    }

    /// True for a map on zero elements.
    pub fn is_empty(&self) -> bool {
        self.scale.is_empty()
    }

    /// `x * scale + shift`.
    pub fn apply(&self, x: &DVector<f32>) -> DVector<f32> {
        x.component_mul(&self.scale) + &self.shift
    }
}

/// One dense layer: `act(W x + b)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    /// Weights, `[out, in]`.
    pub weight: DMatrix<f32>,
    /// Bias, `[out]`.
    pub bias: DVector<f32>,
    /// Activation applied after the affine map.
    pub activation: Activation,
}

/// A validated MLP with input and output scaling.
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp {
    /// Applied to the raw network input (the flattened window of features).
    pub input: Affine,
    /// Dense layers, first to last.
    pub layers: Vec<Dense>,
    /// Applied to the last layer's output to give the prediction in SI units.
    pub output: Affine,
}

impl Mlp {
    /// Checks that the shapes chain and every value is finite.
    pub fn new(input: Affine, layers: Vec<Dense>, output: Affine) -> Result<Self> {
        let bad = |detail: String| Err(Error::BadArgument { what: "network", detail });
        if layers.is_empty() {
            return bad("has no layers".into());
        }
        let mut width = input.len();
        for (i, l) in layers.iter().enumerate() {
            if l.weight.ncols() != width {
                return bad(format!("layer {i} takes {} inputs but receives {width}", l.weight.ncols()));
            }
            if l.bias.len() != l.weight.nrows() {
                return bad(format!("layer {i} has {} outputs but {} biases", l.weight.nrows(), l.bias.len()));
            }
            width = l.weight.nrows();
        }
        if output.len() != width {
            return bad(format!("output scaling has {} elements, network gives {width}", output.len()));
        }
        let all = input.scale.iter().chain(input.shift.iter()).chain(output.scale.iter()).chain(output.shift.iter());
        let weights = layers.iter().flat_map(|l| l.weight.iter().chain(l.bias.iter()));
        if let Some(v) = all.chain(weights).find(|v| !v.is_finite()) {
            return bad(format!("holds a non-finite value {v}"));
        }
        Ok(Mlp { input, layers, output })
    }

    /// Network input width (window × features per frame).
    pub fn n_inputs(&self) -> usize {
        self.input.len()
    }

    /// Network output width.
    pub fn n_outputs(&self) -> usize {
        self.output.len()
    }

    /// Layer widths from input to output, e.g. `[90, 300, 300, 3]`.
    pub fn widths(&self) -> Vec<usize> {
        std::iter::once(self.n_inputs()).chain(self.layers.iter().map(|l| l.weight.nrows())).collect()
    }

    /// Multiply-adds per forward pass.
    pub fn multiply_adds(&self) -> usize {
        self.layers.iter().map(|l| l.weight.len()).sum()
    }

    /// Forward pass in plain nalgebra, allocating: the reference the fast kernel is tested
    /// against.
    pub fn forward_reference(&self, x: &[f32]) -> Vec<f32> {
        let mut h = self.input.apply(&DVector::from_column_slice(x));
        for l in &self.layers {
            h = &l.weight * h + &l.bias;
            l.activation.apply(h.as_mut_slice());
        }
        self.output.apply(&h).as_slice().to_vec()
    }
}
