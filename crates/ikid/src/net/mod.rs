//! Multilayer perceptrons: the plain nalgebra form (the oracle) and the packed fast form.

mod kernel;
mod mlp;

pub use kernel::{PackedMlp, Scratch};
pub use mlp::{Activation, Affine, Dense, Mlp};
