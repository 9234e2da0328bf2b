//! Multilayer perceptrons: the plain nalgebra form (the oracle) and the packed fast form,
//! one sample at a time (`kernel`, which also packs both weight layouts) or [`BATCH`] at once
//! (`batch`).

mod batch;
mod kernel;
mod mlp;

pub use batch::{BATCH, BatchScratch};
pub use kernel::{PackedMlp, Scratch};
pub use mlp::{Activation, Affine, Dense, Mlp};
