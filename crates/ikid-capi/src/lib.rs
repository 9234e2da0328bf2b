//! libikid: the C ABI of ikid. Opaque handles, status codes, a thread-local error message;
//! no logic (every function forwards to the same function of the core crate).
//!
//! Conventions (as rustls-ffi): every symbol is prefixed `ikid_`; a handle is created by
//! `ikid_*_new`/`ikid_model_load*` into an out-pointer and released by the NULL-safe
//! `ikid_*_free`; every fallible function returns an [`ikid_status`] and writes its outputs
//! only on success; after a failure `ikid_last_error()` gives a message naming what was
//! wrong. No panic crosses the boundary: each body runs behind `catch_unwind` and a panic
//! becomes `IKID_STATUS_PANIC`.
//!
//! Threads: a model may be shared by any number of threads; a stream or a tracker is used by
//! one thread at a time (give each thread its own). Streams and trackers hold their own
//! reference to the model, so the model handle may be freed before them.

#![allow(non_camel_case_types)] // C names in the C header
#![allow(unsafe_code)] // the ABI is raw pointers; every dereference is checked first

mod boundary;
mod calibration;
mod model;
mod stream;
mod tracker;

pub use boundary::{ikid_last_error, ikid_status, ikid_status_message, ikid_version};
pub use model::{ikid_model, ikid_model_info};
pub use stream::{ikid_missing_markers, ikid_stream};
pub use tracker::{ikid_tracker, ikid_tracker_flags, ikid_tracker_settings};

/// Frame status bit (`ikid_tracker_flags.status`): a missing marker was filled, or the
/// estimate was made without it.
pub const IKID_FRAME_FILLED: u32 = 1;
/// Frame status bit: a present marker was rejected as implausible and not used.
pub const IKID_FRAME_REJECTED_MARKER: u32 = 2;
/// Frame status bit: the tracker lost the hand and restarted from this frame's own solution.
pub const IKID_FRAME_RESTARTED: u32 = 4;
/// Frame status bit: a segment was not measured in this frame; its pose was held.
pub const IKID_FRAME_HELD: u32 = 8;
/// Frame status bit: the inputs lie outside the model's training envelope.
pub const IKID_FRAME_OUTSIDE_TRAINING: u32 = 16;
/// Frame status bit: an output no wrist can give; write it as missing, not as a number.
pub const IKID_FRAME_IMPLAUSIBLE: u32 = 32;
/// Frame status bit: a correcting model's correction was withheld (its window's posture or
/// speed beyond training): the output is the frame's per-frame solution.
pub const IKID_FRAME_PER_FRAME: u32 = 64;
/// Frame status bit: a marker was found where another marker of the frame belongs (labels
/// swapped in the recording); the markers were used under their right labels.
pub const IKID_FRAME_SWAPPED: u32 = 128;
/// Frame status bit: a stream's first output after it took its source's new clock (the source
/// was restarted): frames were lost before it.
pub const IKID_FRAME_RESYNCED: u32 = 256;
/// Frame status bit: the hand reads turned over on the forearm (two labels of one segment
/// swapped throughout, hand or forearm: MC2/MC5, RSP/USP; or a cluster mapped or calibrated
/// the other way round); always with `IKID_FRAME_IMPLAUSIBLE`.
pub const IKID_FRAME_TURNED_OVER: u32 = 512;

// cbindgen writes literals only: the values above are the core's (ikid::status), checked here.
const _: () = {
    use ikid_core::status;
    assert!(IKID_FRAME_FILLED == status::FILLED as u32);
    assert!(IKID_FRAME_REJECTED_MARKER == status::REJECTED_MARKER as u32);
    assert!(IKID_FRAME_RESTARTED == status::RESTARTED as u32);
    assert!(IKID_FRAME_HELD == status::HELD as u32);
    assert!(IKID_FRAME_OUTSIDE_TRAINING == status::OUTSIDE_TRAINING as u32);
    assert!(IKID_FRAME_IMPLAUSIBLE == status::IMPLAUSIBLE as u32);
    assert!(IKID_FRAME_PER_FRAME == status::PER_FRAME as u32);
    assert!(IKID_FRAME_SWAPPED == status::SWAPPED as u32);
    assert!(IKID_FRAME_RESYNCED == status::RESYNCED as u32);
    assert!(IKID_FRAME_TURNED_OVER == status::TURNED_OVER as u32);
    assert!(status::ALL.len() == 10);
};
