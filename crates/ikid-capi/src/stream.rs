//! Stream handles: frame-by-frame inference, one thread at a time per stream.

use crate::boundary::{
    Failure, doubles_out, free_handle, guard, ikid_status, non_null, non_null_mut, slice, slice_mut,
};
use crate::calibration::calibration_with_shapes;
use crate::model::{ikid_model, recording_args};
use ikid_core::Stream;

/// A causal frame-by-frame stream over a model (opaque). Use from one thread at a time.
pub struct ikid_stream {
    stream: Stream,
    /// Rows the last `ikid_stream_push_many` wrote before a frame it refused (0 if none).
    rows_before_refusal: usize,
}

/// Creates a stream over `model`; on success `*out` receives a handle to release with
/// `ikid_stream_free`. Allocates once, here; pushes never allocate.
///
/// # Safety
/// `model` must be a live handle; `out` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_new(model: *const ikid_model, out: *mut *mut ikid_stream) -> ikid_status {
    guard(|| {
        let m = unsafe { non_null(model, "model") }?;
        let out = unsafe { non_null_mut(out, "out") }?;
        *out = Box::into_raw(Box::new(ikid_stream { stream: m.model.stream(), rows_before_refusal: 0 }));
        Ok(())
    })
}

/// Pushes one frame of `frame_len` floats. `*ready` is set to false while the window is
/// filling; once it is full it is set to true and `out` (room for `out_len` floats, at least
/// `n_outputs`) receives the prediction for this frame. On failure nothing is written and
/// the frame is not taken into the window.
///
/// # Safety
/// `stream` must be a live handle used by no other thread meanwhile; `frame` must point to
/// `frame_len` readable floats, `out` to `out_len` writable floats, `ready` to a bool.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_push(
    stream: *mut ikid_stream,
    frame: *const f32,
    frame_len: usize,
    out: *mut f32,
    out_len: usize,
    ready: *mut bool,
) -> ikid_status {
    guard(|| unsafe { push_one(stream, None, frame, frame_len, out, out_len, ready) })
}

/// `ikid_stream_push` for a frame stamped with its acquisition time `time_s` (seconds, any
/// origin): after a gap of more than 1.5 frame periods of the model's rate (from the last
/// stamp and from the frame grid the stamps before it keep: jitter of up to ±0.35 periods is
/// not a gap), up to 1 s, the window restarts (outputs resume once it has refilled). A stamp that jumps (more than 1 s
/// ahead, or not after the last accepted frame's: a glitch of the source's clock, 1e300) is
/// refused alone (`IKID_STATUS_INVALID_ARGUMENT`) and the frames after it go on as if it had
/// not come; three jumped stamps in a row, each one period after the one before, are taken as
/// the source's new clock (the third is accepted and the window restarts). A source slower
/// than the model's rate (three stamps in a row each more than 1.5 periods after the one
/// before: every frame would restart the window, which would never fill) is refused from the
/// third on, the message naming its rate, until a stamp comes one period after the one before.
/// So is a source at another rate whose steps each pass for a jittered frame's (80 Hz at a
/// 100 Hz model: 1.25 periods), once 128 consecutive frames' mean step is more than 10 % off one
/// period. A frame refused for its markers keeps its stamp in order: frames after a long gap
/// of such frames are a gap, not a jump.
///
/// # Safety
/// As `ikid_stream_push`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_push_at(
    stream: *mut ikid_stream,
    time_s: f64,
    frame: *const f32,
    frame_len: usize,
    out: *mut f32,
    out_len: usize,
    ready: *mut bool,
) -> ikid_status {
    guard(|| unsafe { push_one(stream, Some(time_s), frame, frame_len, out, out_len, ready) })
}

/// # Safety
/// As `ikid_stream_push`.
unsafe fn push_one(
    stream: *mut ikid_stream,
    time_s: Option<f64>,
    frame: *const f32,
    frame_len: usize,
    out: *mut f32,
    out_len: usize,
    ready: *mut bool,
) -> Result<(), Failure> {
    let s = &mut unsafe { non_null_mut(stream, "stream") }?.stream;
    let frame = unsafe { slice(frame, frame_len, "frame") }?;
    let ready = unsafe { non_null_mut(ready, "ready") }?;
    let n_out = s.model().n_outputs();
    if out_len < n_out {
        return Err(Failure::new(
            ikid_status::InvalidArgument,
            format!("out has room for {out_len} floats, the model gives {n_out}"),
        ));
    }
    let out = unsafe { slice_mut(out, n_out, "out") }?;
    let pushed = match time_s {
        None => s.push(frame)?,
        Some(t) => s.push_at(t, frame)?,
    };
    match pushed {
        Some(prediction) => {
            out.copy_from_slice(prediction);
            *ready = true;
        }
        None => *ready = false,
    }
    Ok(())
}

/// What a stream does with a missing (NaN) marker (`ikid_stream_set_missing_markers`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ikid_missing_markers {
    /// Refuse the frame: an error, no output.
    Refuse = 0,
    /// Fill it from the other markers and flag it (`ikid_stream_filled_markers`,
    /// `IKID_FRAME_FILLED`).
    Fill = 1,
}

/// Sets what the stream does with a missing (NaN) marker: `IKID_MISSING_MARKERS_REFUSE` or
/// `IKID_MISSING_MARKERS_FILL` (an `ikid_missing_markers`; any other value is refused with
/// `IKID_STATUS_INVALID_ARGUMENT`). Streams start with the model card's policy.
///
/// # Safety
/// `stream` must be a live handle used by no other thread meanwhile.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_set_missing_markers(stream: *mut ikid_stream, policy: u32) -> ikid_status {
    guard(|| {
        let s = &mut unsafe { non_null_mut(stream, "stream") }?.stream;
        // A u32, not the enum: a C caller may pass any integer, which must not become UB here.
        let policy = match policy {
            p if p == ikid_missing_markers::Refuse as u32 => ikid_core::MissingMarkers::Refuse,
            p if p == ikid_missing_markers::Fill as u32 => ikid_core::MissingMarkers::Fill,
            other => {
                return Err(Failure::new(
                    ikid_status::InvalidArgument,
                    format!(
                        "policy is {other}, expected IKID_MISSING_MARKERS_REFUSE (0) or IKID_MISSING_MARKERS_FILL (1)"
                    ),
                ));
            }
        };
        s.set_missing_markers(policy)?;
        Ok(())
    })
}

/// Calibrates the stream to a subject's marker placement, for a right arm: as
/// `ikid_stream_set_calibration_side(stream, forearm, hand, "right")`.
///
/// # Safety
/// As `ikid_stream_set_calibration_side`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_set_calibration(
    stream: *mut ikid_stream,
    forearm: *const f64,
    hand: *const f64,
) -> ikid_status {
    unsafe { ikid_stream_set_calibration_side(stream, forearm, hand, std::ptr::null()) }
}

/// Calibrates the stream to a subject's marker placement: `forearm` and `hand` each point to
/// the 9 values (row-major) of one 3×3 rotation matrix, as the `"forearm"` and `"hand"`
/// arrays of a calibration file written by `ikid calibrate`, and `side` its `"side"`:
/// `"right"` (or NULL) or `"left"` (a left arm is mirrored into a right one; a left-arm
/// calibration used as a right one gives s_p and ad_ab with the wrong sign); both matrices
/// NULL removes the calibration. Refused (nothing
/// changed) if a matrix is not a rotation or the model does not read marker frames.
///
/// # Safety
/// `stream` must be a live handle used by no other thread meanwhile; `forearm` and `hand`
/// must each be NULL or point to 9 readable doubles; `side` NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_set_calibration_side(
    stream: *mut ikid_stream,
    forearm: *const f64,
    hand: *const f64,
    side: *const std::ffi::c_char,
) -> ikid_status {
    unsafe { ikid_stream_set_calibration_shapes(stream, forearm, hand, side, std::ptr::null()) }
}

/// As `ikid_stream_set_calibration_side`, with the calibration file's marker shapes too:
/// `shapes` NULL (none, as `ikid_stream_set_calibration_side`) or 18 doubles, the
/// `"marker_shapes_m"` rows of a calibration file written by `ikid calibrate` one after the
/// other (each segment's three markers in its technical frame, the forearm's first, metres).
/// With them each segment is fitted to the shape its rotations were measured with, from the
/// first frame, as `ikid ik` and Python do with that file (bit for bit); without them, to the
/// trial's first frames (skin markers slid there turn every angle: a trial cut 1.5 s into a
/// real recording read 2.6° instead of 0.9°). Refused (nothing changed) as
/// `ikid_stream_set_calibration_side`, or if `shapes` are given without the matrices or are
/// not finite.
///
/// # Safety
/// As `ikid_stream_set_calibration_side`; `shapes` NULL or 18 readable doubles.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_set_calibration_shapes(
    stream: *mut ikid_stream,
    forearm: *const f64,
    hand: *const f64,
    side: *const std::ffi::c_char,
    shapes: *const f64,
) -> ikid_status {
    guard(|| {
        let s = &mut unsafe { non_null_mut(stream, "stream") }?.stream;
        let calibration = unsafe { calibration_with_shapes(forearm, hand, side, shapes) }?;
        s.set_calibration(calibration)?;
        Ok(())
    })
}

/// The lab's up direction (against gravity) in the coordinates of the marker frames pushed
/// from now on: `up` points to 3 doubles, `{0, 1, 0}` (the body model's lab) until set,
/// `{0, 0, 1}` for a Z-up lab (Vicon, Qualisys), any non-zero length. Each frame is turned
/// into the body model's lab first. Only a model that reads gravity's direction (the
/// `wrist-chain` torques) depends on it, and silently. A vector that is not finite and
/// non-zero is refused (`IKID_STATUS_INVALID_ARGUMENT`), nothing changed.
///
/// # Safety
/// `stream` must be a live handle used by no other thread meanwhile; `up` must point to 3
/// readable doubles.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_set_lab_up(stream: *mut ikid_stream, up: *const f64) -> ikid_status {
    guard(|| {
        let s = &mut unsafe { non_null_mut(stream, "stream") }?.stream;
        let up = unsafe { slice(up, 3, "up") }?;
        s.set_lab_up([up[0], up[1], up[2]])?;
        Ok(())
    })
}

/// `*rows` receives the rows the last failed `ikid_stream_push_many` wrote into its `out` for
/// the frames before the one it refused (they stay pushed); 0 after a block refused whole
/// (nothing pushed) or pushed whole.
///
/// # Safety
/// `stream` must be a live handle; `rows` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_rows_before_refusal(stream: *const ikid_stream, rows: *mut usize) -> ikid_status {
    guard(|| {
        let handle = unsafe { non_null(stream, "stream") }?;
        *unsafe { non_null_mut(rows, "rows") }? = handle.rows_before_refusal;
        Ok(())
    })
}

/// `*mask` receives the markers filled in the last accepted frame (bit `i` = marker `i` in
/// frame order; 0 when the frame was complete): the flag on an output that rests on filled
/// positions.
///
/// # Safety
/// `stream` must be a live handle; `mask` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_filled_markers(stream: *const ikid_stream, mask: *mut u32) -> ikid_status {
    guard(|| {
        let s = &unsafe { non_null(stream, "stream") }?.stream;
        *unsafe { non_null_mut(mask, "mask") }? = u32::from(s.filled_markers());
        Ok(())
    })
}

/// `*status` receives the `IKID_FRAME_*` bits of the last output (valid after a push that
/// gave one): `IKID_FRAME_FILLED`, `IKID_FRAME_OUTSIDE_TRAINING` (the frame's features beyond
/// the model's training envelope), `IKID_FRAME_IMPLAUSIBLE` (an output far beyond it: treat it
/// as missing).
///
/// # Safety
/// `stream` must be a live handle; `status` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_status(stream: *const ikid_stream, status: *mut u32) -> ikid_status {
    guard(|| {
        let s = &unsafe { non_null(stream, "stream") }?.stream;
        *unsafe { non_null_mut(status, "status") }? = u32::from(s.status());
        Ok(())
    })
}

/// Writes the standard deviation of each output of the last push into `out` (room for
/// `out_len` doubles, at least `n_outputs`), output units (`ikid::Stream::output_sd`: the
/// model card's `uncertainty`, see `crates/ikid/src/model/uncertainty.rs`). NaN when there is
/// none: the card has no `uncertainty`, the last push gave no output, or too few frames came
/// since the window (re)started to tell the markers' noise.
///
/// # Safety
/// `stream` must be a live handle; `out` must point to `out_len` writable doubles.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_output_sd(
    stream: *const ikid_stream,
    out: *mut f64,
    out_len: usize,
) -> ikid_status {
    guard(|| {
        let s = &unsafe { non_null(stream, "stream") }?.stream;
        let dst = unsafe { doubles_out(out, out_len, s.model().n_outputs()) }?;
        match s.output_sd() {
            Some(sd) => dst.copy_from_slice(sd),
            None => dst.fill(f64::NAN),
        }
        Ok(())
    })
}

/// Pushes `n_frames` frames (`n_frames × frame_len` floats, e.g. a packet from the
/// acquisition system) and writes one row of `n_outputs` into `out` for each frame that
/// completes a window; `*rows` receives the row count. On failure `ikid_last_error()` names
/// the frame and `*rows` is not written; when a frame was refused part-way, the frames before
/// it stay pushed and their rows stay written at the start of `out` (the rest of it is
/// unspecified): `ikid_stream_rows_before_refusal` says how many.
///
/// # Safety
/// As `ikid_stream_push`, with `frames` holding `n_frames × frame_len` floats and `rows`
/// pointing to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_push_many(
    stream: *mut ikid_stream,
    frames: *const f32,
    n_frames: usize,
    frame_len: usize,
    out: *mut f32,
    out_len: usize,
    rows: *mut usize,
) -> ikid_status {
    guard(|| {
        let handle = unsafe { non_null_mut(stream, "stream") }?;
        handle.rows_before_refusal = 0;
        let s = &mut handle.stream;
        let rows = unsafe { non_null_mut(rows, "rows") }?;
        let n_rows = s.rows_for(n_frames);
        let (frames, out) = unsafe { recording_args(s.model(), frames, n_frames, frame_len, out, out_len, n_rows) }?;
        match s.push_many(frames, out) {
            Ok(n) => *rows = n,
            Err(e) => {
                handle.rows_before_refusal = s.rows_before_refusal();
                return Err(e.into());
            }
        }
        Ok(())
    })
}

/// Forgets every frame held (e.g. after a gap in the recording).
///
/// # Safety
/// `stream` must be a live handle used by no other thread meanwhile.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_reset(stream: *mut ikid_stream) -> ikid_status {
    guard(|| {
        unsafe { non_null_mut(stream, "stream") }?.stream.reset();
        Ok(())
    })
}

/// Releases a stream handle (NULL is ignored).
///
/// # Safety
/// `stream` must be NULL or a handle from `ikid_stream_new` not yet freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_stream_free(stream: *mut ikid_stream) {
    // SAFETY: NULL or a live handle (caller's contract).
    unsafe { free_handle(stream) }
}
