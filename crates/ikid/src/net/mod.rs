//! Multilayer perceptrons: the plain nalgebra form (`mlp`, the oracle), its packed forms (both
//! weight layouts, `packed`), the kernels over them, one sample at a time (`kernel`) or [`BATCH`]
//! at once (`batch`), and the [`Network`] a model runs (`network`: forward pass, output offset,
//! finiteness check). Within `net`, dependencies run one way: `mlp` ← `packed` ← `kernel` ←
//! `batch` ← `network`.

mod batch;
mod kernel;
mod mlp;
mod network;
mod packed;

pub use batch::{BATCH, BatchScratch};
pub use mlp::{Activation, Affine, Dense, Mlp};
pub use network::{Network, NewestFeatures};
pub use packed::{PackedMlp, Scratch};
