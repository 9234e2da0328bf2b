//! Tracker handles: the causal Kalman tracker (angles, velocities, accelerations and torques
//! per marker frame), one thread at a time per tracker. Conversion only: every call forwards
//! to the core's `Tracker`.

use crate::boundary::{
    Failure, free_handle, guard, ikid_status, non_null, non_null_mut, slice, slice_mut, write_doubles,
};
use crate::calibration::calibration_with_shapes;
use crate::model::ikid_model;
use ikid_core::body::{BodyModel, MARKER_FRAME_LEN};
use ikid_core::tracker::{TRACKER_VALUES, TrackerOutput};
use ikid_core::{Tracker, TrackerSettings};

/// A causal tracker of one subject's wrist (opaque): an extended Kalman filter over the body
/// model that learns each marker coordinate's noise as it goes, optionally refined by a
/// network. Use from one thread at a time (give each thread its own).
pub struct ikid_tracker {
    tracker: Tracker,
}

/// The subject and how the tracker models motion and noise; start from
/// `ikid_tracker_settings_default()` and change what differs. A subject's marker placement is
/// given by `ikid_tracker_set_calibration`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ikid_tracker_settings {
    /// Subject's segment lengths (and marker offsets) relative to the default subject.
    pub length_scale: f64,
    /// Subject's segment masses relative to the default subject.
    pub mass_scale: f64,
    /// Frame rate of the markers, Hz: push frames at this rate. No default (NaN in
    /// `ikid_tracker_settings_default()`): `ikid_tracker_new` refuses settings without it, since
    /// tracked at another rate every velocity, acceleration and torque is wrong by the ratio.
    pub rate_hz: f64,
    /// Spectral density of the joint jerk the motion model allows, rad²/s⁵: larger follows
    /// faster moves with less lag and passes more noise.
    pub jerk_noise: f64,
    /// How far back the noise estimate looks, seconds (exponential forgetting).
    pub noise_memory_s: f64,
    /// Standard deviation of the marker noise assumed before any has been measured, m.
    pub initial_marker_noise: f64,
    /// Measure the hand by its orientation only (its markers relative to their centroid), not
    /// by its position relative to the forearm: for real subjects, whose wrist centre the body
    /// model does not know. Always on with a calibration (`ikid_tracker_set_calibration`).
    pub relative_hand: bool,
    /// The lab's up direction (against gravity) in the markers' coordinates, any non-zero
    /// length: {0, 1, 0} by default (the body model's lab), {0, 0, 1} for a Z-up lab (Vicon,
    /// Qualisys). Only the torques depend on it, and silently: set it.
    pub up: [f64; 3],
}

/// Per-frame flags of a tracker's estimate.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ikid_tracker_flags {
    /// Bit `i` set: marker `i` (frame order: RSP, USP, FAP, MC2, MC5, MCB) had a NaN
    /// coordinate in this frame and corrected nothing.
    pub missing: u32,
    /// True when this frame has an estimate; false before the filter started (it starts on
    /// the first frame with every marker), and then the 12 values are NaN.
    pub ready: bool,
    /// True when the refiner corrected this estimate (false without one and while its window
    /// fills).
    pub refined: bool,
    /// Mean noise (standard deviation) of the hand markers measured so far, m; NaN when not
    /// `ready`. What the refiner is told and gated by.
    pub noise: f64,
    /// `IKID_FRAME_*` bits: markers rejected as implausible, a segment's pose held, a restart
    /// after the tracker lost the hand, an angle no wrist reaches (write it as missing).
    pub status: u32,
}

impl ikid_tracker_flags {
    fn new(out: &TrackerOutput, ready: bool) -> Self {
        ikid_tracker_flags {
            missing: u32::from(out.missing),
            ready,
            refined: out.refined,
            noise: out.noise,
            status: u32::from(out.status),
        }
    }
}

/// The default subject and settings: both scales 1, the core's default jerk noise (chosen
/// against biorbd's EKF, see docs/ekf.md), a 10 s noise memory, 1 mm initial noise, +Y up;
/// `rate_hz` NaN, to be set to the markers' frame rate (`ikid_tracker_new` refuses it unset).
#[unsafe(no_mangle)]
pub extern "C" fn ikid_tracker_settings_default() -> ikid_tracker_settings {
    let s = TrackerSettings::new(f64::NAN);
    ikid_tracker_settings {
        length_scale: 1.0,
        mass_scale: 1.0,
        rate_hz: s.rate_hz,
        jerk_noise: s.jerk_noise,
        noise_memory_s: s.noise_memory_s,
        initial_marker_noise: s.initial_marker_noise,
        relative_hand: s.relative_hand,
        up: s.up,
    }
}

/// Creates a tracker for the subject and settings in `*settings`, refined by `refiner` (a
/// `refine` model such as the shipped `wrist-track`, trained at `rate_hz`) or unrefined if
/// `refiner` is NULL; on success `*out` receives a handle to release with
/// `ikid_tracker_free`. A setting that is not a positive finite number, or a model that
/// cannot refine a tracker, is refused (`IKID_STATUS_INVALID_ARGUMENT`, the message names
/// it). The tracker holds its own reference to the refiner: the model handle may be freed
/// first. Allocates once, here; pushes and runs never allocate. No calibration: see
/// `ikid_tracker_settings`.
///
/// # Safety
/// `settings` must point to a readable `ikid_tracker_settings`; `refiner` must be NULL or a
/// live model handle; `out` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_new(
    settings: *const ikid_tracker_settings,
    refiner: *const ikid_model,
    out: *mut *mut ikid_tracker,
) -> ikid_status {
    guard(|| {
        let s = unsafe { non_null(settings, "settings") }?;
        let out = unsafe { non_null_mut(out, "out") }?;
        // SAFETY: NULL or a live handle (caller's contract).
        let refiner = unsafe { refiner.as_ref() }.map(|m| m.model.clone());
        let body = BodyModel::try_scaled(s.length_scale, s.mass_scale)?;
        let settings = TrackerSettings {
            rate_hz: s.rate_hz,
            jerk_noise: s.jerk_noise,
            noise_memory_s: s.noise_memory_s,
            initial_marker_noise: s.initial_marker_noise,
            relative_hand: s.relative_hand,
            up: s.up,
        };
        let mut tracker = Tracker::new(body, settings)?;
        tracker.set_refiner(refiner)?;
        *out = Box::into_raw(Box::new(ikid_tracker { tracker }));
        Ok(())
    })
}

/// Pushes one marker frame: `frame_len` (18) doubles, the six markers' x, y, z in metres in
/// the lab frame, NaN for a missing marker (it corrects nothing; an infinite value is an
/// error). On success `*flags` is written and `out` (room for `out_len` doubles, at least 12)
/// receives q, q̇, q̈ and τ (3 each; rad, rad/s, rad/s², N·m, coordinates s_p, e_f, ad_ab) for
/// this frame, or 12 NaN while `flags->ready` is false. Frames must come at the settings'
/// `rate_hz`. On failure nothing is written; a NULL pointer, an `out` shorter than 12, a
/// frame of the wrong length or with an infinite value, or, before the filter has started,
/// markers no arm could hold (wrong units; `IKID_STATUS_INPUT`) leaves the tracker as it was.
///
/// # Safety
/// `tracker` must be a live handle used by no other thread meanwhile; `frame` must point to
/// `frame_len` readable doubles, `out` to `out_len` writable doubles, `flags` to writable
/// storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_push(
    tracker: *mut ikid_tracker,
    frame: *const f64,
    frame_len: usize,
    out: *mut f64,
    out_len: usize,
    flags: *mut ikid_tracker_flags,
) -> ikid_status {
    // SAFETY: the caller's contract, as `push_one` needs it.
    unsafe { push_one(tracker, frame, frame_len, out, out_len, flags, |t, frame| t.push(frame)) }
}

/// `ikid_tracker_push` for a frame stamped with its acquisition time (seconds, any origin),
/// for a source that can lose frames: a stamp more than 1.5 periods of `rate_hz` after the
/// last one and after the frame grid the stamps before it keep (frames lost: jitter of up to
/// ±0.35 periods is not a gap), or not after the last one (the source's clock restarted), restarts the
/// filter instead of bridging the gap as one step (0.1 s lost gave torques 3.8 N·m off) —
/// but for fewer lost frames than 30 ms of them, which it carries itself through as frames
/// with every marker missing; what was learned of the subject is kept, and the first frames
/// after a restart are flagged `IKID_FRAME_RESTARTED` while the velocities settle.
/// `ikid_tracker_gap_restarts` counts the restarts. A stamp less than half a period after the last one, equal to it (a frame sent twice),
/// or not finite, is refused
/// (`IKID_STATUS_INVALID_ARGUMENT`) and changes nothing. A source slower than `rate_hz` (three
/// stamps in a row each more than 1.5 periods after the one before) is refused from the third
/// on, the message naming its rate, until a stamp comes one period after the one before; so is
/// one whose consecutive frames' mean step, over 128 of them, is more than 10 % off one period.
///
/// # Safety
/// As `ikid_tracker_push`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_push_at(
    tracker: *mut ikid_tracker,
    time_s: f64,
    frame: *const f64,
    frame_len: usize,
    out: *mut f64,
    out_len: usize,
    flags: *mut ikid_tracker_flags,
) -> ikid_status {
    // SAFETY: the caller's contract, as `push_one` needs it.
    unsafe { push_one(tracker, frame, frame_len, out, out_len, flags, |t, frame| t.push_at(time_s, frame)) }
}

/// One frame through `push` (stamped or not): the checks of the pointers and lengths, the
/// estimate (or the waiting frame's NaN) into `out` and its flags into `*flags`.
///
/// # Safety
/// As `ikid_tracker_push`.
unsafe fn push_one(
    tracker: *mut ikid_tracker,
    frame: *const f64,
    frame_len: usize,
    out: *mut f64,
    out_len: usize,
    flags: *mut ikid_tracker_flags,
    push: impl FnOnce(&mut Tracker, &[f64]) -> ikid_core::Result<Option<TrackerOutput>>,
) -> ikid_status {
    guard(|| {
        let t = &mut unsafe { non_null_mut(tracker, "tracker") }?.tracker;
        let frame = unsafe { slice(frame, frame_len, "frame") }?;
        let flags = unsafe { non_null_mut(flags, "flags") }?;
        let out = unsafe { slice_mut(out, room(out_len, 1)?, "out") }?;
        let (estimate, ready) = match push(t, frame)? {
            Some(o) => (o, true),
            None => (TrackerOutput::waiting(ikid_core::tracker::missing_markers(frame)), false),
        };
        out.copy_from_slice(&estimate.values());
        *flags = ikid_tracker_flags::new(&estimate, ready);
        Ok(())
    })
}

/// Writes into `*restarts` how many times `ikid_tracker_push_at` restarted the filter after a
/// time gap since the tracker was made or reset.
///
/// # Safety
/// `tracker` must be a live handle; `restarts` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_gap_restarts(tracker: *const ikid_tracker, restarts: *mut usize) -> ikid_status {
    guard(|| {
        let t = &unsafe { non_null(tracker, "tracker") }?.tracker;
        *unsafe { non_null_mut(restarts, "restarts") }? = t.gap_restarts();
        Ok(())
    })
}

/// Writes into `*frames` how many lost frames `ikid_tracker_push_at` carried the filter through
/// (a loss shorter than 30 ms is bridged as frames with every marker missing, instead of
/// restarting) since the tracker was made or reset.
///
/// # Safety
/// `tracker` must be a live handle; `frames` must point to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_bridged_frames(tracker: *const ikid_tracker, frames: *mut usize) -> ikid_status {
    guard(|| {
        let t = &unsafe { non_null(tracker, "tracker") }?.tracker;
        *unsafe { non_null_mut(frames, "frames") }? = t.bridged_frames();
        Ok(())
    })
}

/// Pushes a block of frames in order, exactly as `ikid_tracker_push` one at a time: `frames`
/// holds `n_values` doubles, a whole number of 18-value frames back to back. For frame `i`,
/// `out` (room for `out_len` doubles, at least 12 per frame) receives its 12 values at
/// `out + 12 i` and `flags` (room for `flags_len`, at least one per frame) its flags at
/// `flags + i`; `*start` receives the index of the first frame with an estimate (0 when the
/// filter was already running, the frame count if no frame of the block started it).
/// Continues from the tracker's state. A block that is not a whole number of frames, or
/// buffers too small, are refused (`IKID_STATUS_INVALID_ARGUMENT`) before anything is pushed.
/// On a refused frame `ikid_last_error()` names its index in the block, `*start` is not
/// written, the rows before it hold their results (those from it on are unspecified) and the
/// frames before it stay pushed.
///
/// # Safety
/// As `ikid_tracker_push`, with `frames` holding `n_values` readable doubles, `flags` room
/// for `flags_len` flags and `start` pointing to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_run(
    tracker: *mut ikid_tracker,
    frames: *const f64,
    n_values: usize,
    out: *mut f64,
    out_len: usize,
    flags: *mut ikid_tracker_flags,
    flags_len: usize,
    start: *mut usize,
) -> ikid_status {
    guard(|| {
        let t = &mut unsafe { non_null_mut(tracker, "tracker") }?.tracker;
        let start = unsafe { non_null_mut(start, "start") }?;
        let frames = unsafe { slice(frames, n_values, "frames") }?;
        // (A partial frame at the end is the core's to refuse, before it pushes anything.)
        let n = n_values / MARKER_FRAME_LEN;
        let out = unsafe { slice_mut(out, room(out_len, n)?, "out") }?;
        if flags_len < n {
            return Err(Failure::new(
                ikid_status::InvalidArgument,
                format!("flags has room for {flags_len} frames, the block holds {n}"),
            ));
        }
        let flags = unsafe { slice_mut(flags, n, "flags") }?;
        let first = t.run(frames, |i, o, ready| {
            out[i * TRACKER_VALUES..(i + 1) * TRACKER_VALUES].copy_from_slice(&o.values());
            flags[i] = ikid_tracker_flags::new(o, ready);
        })?;
        *start = first.unwrap_or(n);
        Ok(())
    })
}

/// The 12 values per frame `out_len` must hold for `n_frames` frames, or the failure saying
/// it does not.
fn room(out_len: usize, n_frames: usize) -> Result<usize, Failure> {
    let need = n_frames
        .checked_mul(TRACKER_VALUES)
        .ok_or_else(|| Failure::new(ikid_status::InvalidArgument, "the block is too large"))?;
    if out_len < need {
        return Err(Failure::new(
            ikid_status::InvalidArgument,
            format!("out has room for {out_len} doubles, {need} needed (12 per frame)"),
        ));
    }
    Ok(need)
}

/// Forgets everything seen (state, forearm pose, noise estimates, the refiner's window): the
/// next frame with every marker starts the filter again. Keeps the settings and refiner.
///
/// # Safety
/// `tracker` must be a live handle used by no other thread meanwhile.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_reset(tracker: *mut ikid_tracker) -> ikid_status {
    guard(|| {
        unsafe { non_null_mut(tracker, "tracker") }?.tracker.reset();
        Ok(())
    })
}

/// Writes the current noise estimate (standard deviation, m) of each hand marker coordinate
/// into `out` (room for `out_len` doubles, at least 9), in frame order: MC2.x, MC2.y, MC2.z,
/// MC5.x, ..., MCB.z. The initial guess until frames have been seen.
///
/// # Safety
/// `tracker` must be a live handle; `out` must point to `out_len` writable doubles.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_marker_noise(
    tracker: *const ikid_tracker,
    out: *mut f64,
    out_len: usize,
) -> ikid_status {
    guard(|| {
        let t = &unsafe { non_null(tracker, "tracker") }?.tracker;
        unsafe { write_doubles(out, out_len, &t.marker_noise()) }
    })
}

/// Writes the standard deviations of the last estimate to `out` (at least 6 doubles): each
/// angle's (rad), then each torque's (N·m), coordinate order (`ikid::Tracker::output_sd`: the
/// filter's covariance with the forearm's noise added; the torques' from the markers' noise
/// through the filter; docs/live.md measures their coverage). NaN before the filter started
/// (as the values are). They describe the filter's own estimate, not a refiner's correction.
///
/// # Safety
/// `tracker` must be a live handle; `out` must point to `out_len` writable doubles.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_output_sd(
    tracker: *const ikid_tracker,
    out: *mut f64,
    out_len: usize,
) -> ikid_status {
    guard(|| {
        let t = &unsafe { non_null(tracker, "tracker") }?.tracker;
        const N: usize = 2 * ikid_core::body::N_COORDINATES;
        let values: [f64; N] = match t.output_sd() {
            Some(sd) => std::array::from_fn(|i| if i < N / 2 { sd.q[i] } else { sd.tau[i - N / 2] }),
            None => [f64::NAN; N],
        };
        unsafe { write_doubles(out, out_len, &values) }
    })
}

/// Releases a tracker handle (NULL is ignored).
///
/// # Safety
/// `tracker` must be NULL or a handle from `ikid_tracker_new` not yet freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_free(tracker: *mut ikid_tracker) {
    // SAFETY: NULL or a live handle (caller's contract).
    unsafe { free_handle(tracker) }
}

/// Tracks a subject measured by a calibration (as `ikid_stream_set_calibration_side`: two
/// row-major rotation matrices and the side, `"right"`/NULL or `"left"`; both matrices NULL
/// removes it): each segment's markers are placed by it and the hand is measured by its
/// orientation. Starts the tracker afresh, as `ikid_tracker_reset`.
///
/// # Safety
/// `tracker` a live handle used by no other thread meanwhile; `forearm` and `hand` NULL or 9
/// readable doubles each; `side` NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_set_calibration(
    tracker: *mut ikid_tracker,
    forearm: *const f64,
    hand: *const f64,
    side: *const std::ffi::c_char,
) -> ikid_status {
    unsafe { ikid_tracker_set_calibration_shapes(tracker, forearm, hand, side, std::ptr::null()) }
}

/// As `ikid_tracker_set_calibration`, with the calibration file's marker shapes too (as
/// `ikid_stream_set_calibration_shapes`: `shapes` NULL or the 18 doubles of its
/// `"marker_shapes_m"` rows): each segment's markers are placed by the shape the calibration's
/// rotations were measured with, as `ikid track` and `ikid.Tracker` do with that file (bit for
/// bit), not by the trial's first frames. Starts the tracker afresh.
///
/// # Safety
/// As `ikid_tracker_set_calibration`; `shapes` NULL or 18 readable doubles.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ikid_tracker_set_calibration_shapes(
    tracker: *mut ikid_tracker,
    forearm: *const f64,
    hand: *const f64,
    side: *const std::ffi::c_char,
    shapes: *const f64,
) -> ikid_status {
    guard(|| {
        let t = &mut unsafe { non_null_mut(tracker, "tracker") }?.tracker;
        let calibration = unsafe { calibration_with_shapes(forearm, hand, side, shapes) }?;
        t.set_calibration(calibration);
        Ok(())
    })
}
