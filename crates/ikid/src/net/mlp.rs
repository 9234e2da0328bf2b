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

#[cfg(test)]
mod tests {
    use super::*;

    /// 2 → 2 (ReLU) → 1 with input and output scaling, small enough to compute by hand.
    fn hand_network() -> Mlp {
        Mlp::new(
            Affine { scale: DVector::from_vec(vec![2.0, 0.5]), shift: DVector::from_vec(vec![-1.0, 1.0]) },
            vec![
                Dense {
                    weight: DMatrix::from_row_slice(2, 2, &[1.0, -2.0, 0.5, 3.0]),
                    bias: DVector::from_vec(vec![0.25, -1.0]),
                    activation: Activation::Relu,
                },
                Dense {
                    weight: DMatrix::from_row_slice(1, 2, &[2.0, -1.0]),
                    bias: DVector::from_vec(vec![0.5]),
                    activation: Activation::Identity,
                },
            ],
            Affine { scale: DVector::from_vec(vec![10.0]), shift: DVector::from_vec(vec![3.0]) },
        )
        .unwrap()
    }

    #[test]
    fn the_oracle_computes_what_the_formula_says() {
        let net = hand_network();
        // x = (1, 2): scaled (1, 2); hidden (1 − 4 + 0.25, 0.5 + 6 − 1) = (−2.75, 5.5) → ReLU
        // (0, 5.5); output 0 − 5.5 + 0.5 = −5; scaled −50 + 3 = −47.
        assert_eq!(net.forward_reference(&[1.0, 2.0]), vec![-47.0]);
        // x = (3, −4): scaled (5, −1); hidden (5 + 2 + 0.25, 2.5 − 3 − 1) = (7.25, −1.5) → (7.25, 0);
        // output 14.5 + 0.5 = 15; scaled 153.
        assert_eq!(net.forward_reference(&[3.0, -4.0]), vec![153.0]);
        assert_eq!(net.widths(), vec![2, 2, 1]);
        assert_eq!(net.multiply_adds(), 6);
        assert_eq!((net.n_inputs(), net.n_outputs()), (2, 1));
    }

    #[test]
    fn affine_and_activation_by_hand() {
        let a =
            Affine { scale: DVector::from_vec(vec![2.0, -1.0, 0.0]), shift: DVector::from_vec(vec![1.0, 1.0, 4.0]) };
        assert_eq!(a.apply(&DVector::from_vec(vec![3.0, 5.0, 9.0])).as_slice(), &[7.0, -4.0, 4.0]);
        assert_eq!((a.len(), a.is_empty()), (3, false));
        let id = Affine::identity(2);
        assert_eq!(id.apply(&DVector::from_vec(vec![-1.5, 2.5])).as_slice(), &[-1.5, 2.5]);
        assert!(Affine::identity(0).is_empty());
        let mut v = [-1.0, 0.0, 2.0];
        Activation::Relu.apply(&mut v);
        assert_eq!(v, [0.0, 0.0, 2.0]);
        let mut v = [-1.0, 2.0];
        Activation::Identity.apply(&mut v);
        assert_eq!(v, [-1.0, 2.0]);
        assert_eq!((Activation::Relu.name(), Activation::Identity.name()), ("relu", "identity"));
    }

    #[test]
    fn a_network_that_does_not_chain_is_refused_with_the_reason() {
        let net = hand_network();
        let err = |input: Affine, layers: Vec<Dense>, output: Affine| {
            Mlp::new(input, layers, output).unwrap_err().to_string()
        };
        assert!(err(net.input.clone(), vec![], net.output.clone()).contains("has no layers"));
        let e = err(Affine::identity(3), net.layers.clone(), net.output.clone());
        assert!(e.contains("layer 0 takes 2 inputs but receives 3"), "{e}");
        let mut short_bias = net.layers.clone();
        short_bias[1].bias = DVector::from_vec(vec![0.5, 0.5]);
        let e = err(net.input.clone(), short_bias, net.output.clone());
        assert!(e.contains("layer 1 has 1 outputs but 2 biases"), "{e}");
        let e = err(net.input.clone(), net.layers.clone(), Affine::identity(2));
        assert!(e.contains("output scaling has 2 elements, network gives 1"), "{e}");
        for poison in 0..4 {
            let (mut input, mut layers, mut output) = (net.input.clone(), net.layers.clone(), net.output.clone());
            match poison {
                0 => input.shift[1] = f32::NAN,
                1 => output.scale[0] = f32::INFINITY,
                2 => layers[0].weight[(1, 0)] = f32::NAN,
                _ => layers[1].bias[0] = f32::NEG_INFINITY,
            }
            let e = err(input, layers, output);
            assert!(e.contains("non-finite"), "{poison}: {e}");
        }
    }
}
