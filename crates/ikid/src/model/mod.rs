//! Model files: one `.safetensors` holding the MLP's tensors and a JSON model card.
//!
//! Tensors (all F32, looked up by name, torch layout):
//! `layers.{k}.weight` `[out, in]`, `layers.{k}.bias` `[out]` for `k = 0..n_layers`,
//! `input.scale`, `input.shift` `[window × features]`, `output.scale`, `output.shift` `[outputs]`.
//! The network computes `y = out(L_n(…L_1(x ∘ input.scale + input.shift)))` with
//! `out(h) = h ∘ output.scale + output.shift`; `x` is the window of per-frame features,
//! oldest frame first. The card ([`ModelCard`]) is JSON under the metadata key
//! [`CARD_KEY`]. The loader checks everything and names what is wrong.
//!
//! One concern per file: `card` (the card's schema and checks), `file` (the byte format:
//! reading, bounded, and the one writer), `handle` (the loaded [`Model`] and its accessors)
//! and `predict` (whole recordings, on several threads). A stream over a model is
//! [`crate::stream`]'s.

mod card;
mod file;
mod handle;
mod predict;
pub mod uncertainty;

pub use card::{
    Bounds, CARD_KEY, Envelope, FORMAT, FORMAT_VERSION, MAX_WINDOW, ModelCard, NEWEST_FEATURES, OutputSpec, TASKS,
};
pub use file::{MAX_MODEL_FILE_BYTES, read_bounded, tensor_sha256, to_bytes};
pub use handle::Model;
pub use handle::{CHANGE_MARGIN, CORRECTION_MARGIN, ENVELOPE_MARGIN, IMPLAUSIBLE_MARGIN};
pub use uncertainty::{SdCard, SdState};
