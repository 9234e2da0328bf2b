//! Model handles: load (path or bytes), describe, predict whole recordings, free.

use crate::boundary::{Failure, free_handle, guard, ikid_status, non_null, non_null_mut, slice, slice_mut};
use ikid_core::Model;
use std::ffi::{CStr, CString, c_char};

/// A loaded, validated model (opaque). Thread-safe: share it between threads freely.
pub struct ikid_model {
    pub(crate) model: Model,
    name: CString,
    task: CString,
    feature_set: CString,
    output_names: Vec<CString>,
    frame_names: Vec<CString>,
}

/// Sizes of a model's inputs and outputs.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct ikid_model_info {
    /// Floats per input frame (18 for marker models: 6 markers × x, y, z in metres).
    pub frame_len: usize,
    /// Frames per window; predictions start with the `window`-th frame.
    pub window: usize,
    /// Floats per prediction.
    pub n_outputs: usize,
    /// Frame rate the model was trained at, Hz.
    pub frame_rate_hz: f64,
}

impl ikid_model {
    fn new(model: Model) -> Box<Self> {
        // Names are validated strings from the model card: no interior NULs.
        let c = |s: &str| CString::new(s.replace('\0', " ")).unwrap_or_default();
        let card = model.card();
        Box::new(ikid_model {
            name: c(&card.name),
            task: c(&card.task),
            feature_set: c(model.feature_set().name()),
            output_names: card.outputs.iter().map(|o| c(&o.name)).collect(),
            frame_names: model.feature_set().frame_names().iter().map(|n| c(n)).collect(),
            model,
        })
    }
}

/// Loads and validates a `.safetensors` model file; on success `*out` receives a handle to
/// release with `ikid_model_free`.
///
/// # Safety
/// `path` must be a NUL-terminated string; `out` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_load(path: *const c_char, out: *mut *mut ikid_model) -> ikid_status {
    guard(|| {
        // SAFETY: the caller passes a NUL-terminated string (checked non-NULL).
        let path = unsafe { CStr::from_ptr(non_null(path, "path")?) };
        let out = unsafe { non_null_mut(out, "out") }?;
        let path = path.to_str().map_err(|_| Failure::new(ikid_status::InvalidArgument, "path is not valid UTF-8"))?;
        *out = Box::into_raw(ikid_model::new(Model::load(path)?));
        Ok(())
    })
}

/// Validates a model held in memory (the `len` bytes of a `.safetensors` file at `data`).
///
/// # Safety
/// `data` must point to `len` readable bytes; `out` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_load_bytes(data: *const u8, len: usize, out: *mut *mut ikid_model) -> ikid_status {
    guard(|| {
        let bytes = unsafe { slice(data, len, "data") }?;
        let out = unsafe { non_null_mut(out, "out") }?;
        *out = Box::into_raw(ikid_model::new(Model::from_bytes(bytes)?));
        Ok(())
    })
}

/// Releases a model handle (NULL is ignored). Streams created from it stay valid.
///
/// # Safety
/// `model` must be NULL or a handle from `ikid_model_load*` not yet freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_free(model: *mut ikid_model) {
    // SAFETY: NULL or a live handle (caller's contract).
    unsafe { free_handle(model) }
}

/// Writes the model's sizes into `*out`.
///
/// # Safety
/// `model` must be a live handle; `out` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_get_info(model: *const ikid_model, out: *mut ikid_model_info) -> ikid_status {
    guard(|| {
        let m = &unsafe { non_null(model, "model") }?.model;
        let out = unsafe { non_null_mut(out, "out") }?;
        *out = ikid_model_info {
            frame_len: m.frame_len(),
            window: m.window(),
            n_outputs: m.n_outputs(),
            frame_rate_hz: m.card().frame_rate_hz,
        };
        Ok(())
    })
}

/// The model's name (e.g. `"wrist-ik"`), or NULL for a NULL model. Valid while the model
/// handle lives.
///
/// # Safety
/// `model` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_name(model: *const ikid_model) -> *const c_char {
    // SAFETY: NULL or live (caller's contract).
    unsafe { model.as_ref() }.map_or(std::ptr::null(), |m| m.name.as_ptr())
}

/// The model's task: `"ik"` (markers → angles), `"id"` (joint state → torques), `"chain"`
/// (markers → torques) or `"refine"` (a tracker's refiner); NULL for a NULL model.
///
/// # Safety
/// `model` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_task(model: *const ikid_model) -> *const c_char {
    // SAFETY: NULL or live (caller's contract).
    unsafe { model.as_ref() }.map_or(std::ptr::null(), |m| m.task.as_ptr())
}

/// The model's feature set (e.g. `"angles"`: what it computes from each frame); NULL for a
/// NULL model.
///
/// # Safety
/// `model` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_feature_set(model: *const ikid_model) -> *const c_char {
    // SAFETY: NULL or live (caller's contract).
    unsafe { model.as_ref() }.map_or(std::ptr::null(), |m| m.feature_set.as_ptr())
}

/// Deprecated (use `ikid_model_name`, `ikid_model_task`, `ikid_model_feature_set`): the
/// model's name, task or feature set by `field` (0, 1, 2); NULL for another `field`.
///
/// # Safety
/// `model` must be NULL or a live handle.
#[deprecated(note = "use ikid_model_name, ikid_model_task or ikid_model_feature_set")]
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_describe(model: *const ikid_model, field: u32) -> *const c_char {
    match field {
        0 => unsafe { ikid_model_name(model) },
        1 => unsafe { ikid_model_task(model) },
        2 => unsafe { ikid_model_feature_set(model) },
        _ => std::ptr::null(),
    }
}

/// Name of output `index` (e.g. `"ra_wr_s_p"`), or NULL if out of range. Valid while the
/// model handle lives. Outputs are in SI units (radians, N·m).
///
/// # Safety
/// `model` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_output_name(model: *const ikid_model, index: usize) -> *const c_char {
    // SAFETY: NULL or live (caller's contract).
    unsafe { model.as_ref() }.and_then(|m| m.output_names.get(index)).map_or(std::ptr::null(), |s| s.as_ptr())
}

/// Name of value `index` of an input frame (e.g. `"MC2.y"`), or NULL if out of range.
/// Valid while the model handle lives.
///
/// # Safety
/// `model` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_frame_name(model: *const ikid_model, index: usize) -> *const c_char {
    // SAFETY: NULL or live (caller's contract).
    unsafe { model.as_ref() }.and_then(|m| m.frame_names.get(index)).map_or(std::ptr::null(), |s| s.as_ptr())
}

/// Number of predictions for a recording of `n_frames` frames: `n_frames - window + 1`, or
/// 0 (also for a NULL model).
///
/// # Safety
/// `model` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_predict_rows(model: *const ikid_model, n_frames: usize) -> usize {
    // SAFETY: NULL or live (caller's contract).
    unsafe { model.as_ref() }.map_or(0, |m| m.model.n_predictions(n_frames))
}

/// Deprecated name of `ikid_model_predict_rows` (kept for one release).
///
/// # Safety
/// As `ikid_model_predict_rows`.
#[deprecated(note = "renamed ikid_model_predict_rows")]
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_predict_rows(model: *const ikid_model, n_frames: usize) -> usize {
    unsafe { ikid_model_predict_rows(model, n_frames) }
}

/// Predicts a whole recording: `frames` holds `n_frames × frame_len` floats (row-major);
/// `out` (room for `out_len` floats) receives `ikid_model_predict_rows(n_frames)` rows of
/// `n_outputs`, row `i` for frame `i + window - 1`; `*rows` receives the row count. Uses all
/// cores. Nothing is written on failure.
///
/// # Safety
/// `frames` must point to `n_frames × frame_len` readable floats, `out` to `out_len`
/// writable floats, `rows` to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_model_predict(
    model: *const ikid_model,
    frames: *const f32,
    n_frames: usize,
    frame_len: usize,
    out: *mut f32,
    out_len: usize,
    rows: *mut usize,
) -> ikid_status {
    guard(|| {
        let m = &unsafe { non_null(model, "model") }?.model;
        let rows = unsafe { non_null_mut(rows, "rows") }?;
        let (frames, out) =
            unsafe { recording_args(m, frames, n_frames, frame_len, out, out_len, m.n_predictions(n_frames)) }?;
        *rows = m.predict(frames, out)?;
        Ok(())
    })
}

/// Deprecated name of `ikid_model_predict` (kept for one release).
///
/// # Safety
/// As `ikid_model_predict`.
#[deprecated(note = "renamed ikid_model_predict")]
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_predict(
    model: *const ikid_model,
    frames: *const f32,
    n_frames: usize,
    frame_len: usize,
    out: *mut f32,
    out_len: usize,
    rows: *mut usize,
) -> ikid_status {
    unsafe { ikid_model_predict(model, frames, n_frames, frame_len, out, out_len, rows) }
}

/// Checks and converts the arguments shared by `ikid_model_predict` and `ikid_stream_push_many`:
/// `n_frames` frames of `frame_len` floats at `frames`, and room at `out` (`out_len` floats)
/// for `rows` predictions of `m`.
///
/// # Safety
/// As the callers': `frames` readable for `n_frames × frame_len` floats, `out` writable for
/// `out_len` floats.
pub(crate) unsafe fn recording_args<'a>(
    m: &Model,
    frames: *const f32,
    n_frames: usize,
    frame_len: usize,
    out: *mut f32,
    out_len: usize,
    rows: usize,
) -> Result<(&'a [f32], &'a mut [f32]), Failure> {
    if frame_len != m.frame_len() {
        return Err(Failure::new(
            ikid_status::Input,
            format!(
                "frame_len is {frame_len}, the model's feature set {:?} takes {}",
                m.feature_set().name(),
                m.frame_len()
            ),
        ));
    }
    let overflow = || Failure::new(ikid_status::InvalidArgument, "n_frames × frame_len overflows");
    let frames = unsafe { slice(frames, n_frames.checked_mul(frame_len).ok_or_else(overflow)?, "frames") }?;
    let need = rows.checked_mul(m.n_outputs()).ok_or_else(overflow)?;
    if out_len < need {
        return Err(Failure::new(
            ikid_status::InvalidArgument,
            format!("out has room for {out_len} floats, {need} needed"),
        ));
    }
    Ok((frames, unsafe { slice_mut(out, need, "out") }?))
}
