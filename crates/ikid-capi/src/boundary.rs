//! The panic boundary, status codes, the thread-local last error, and pointer checks.

use ikid_core::{Error, ErrorKind};
use std::cell::RefCell;
use std::ffi::{CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};

/// Result of every fallible libikid call.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ikid_status {
    /// Success.
    Ok = 0,
    /// A required pointer argument was NULL.
    NullParameter = 1,
    /// An argument has the wrong length or value (buffer too small, misaligned, bad UTF-8...).
    InvalidArgument = 2,
    /// A file could not be read.
    Io = 3,
    /// A model file is corrupt, truncated, or does not fit its model card.
    ModelFile = 4,
    /// A frame is unusable: wrong length, a missing (NaN) marker, degenerate markers, or a
    /// non-finite prediction (input far outside the training range).
    Input = 5,
    /// An internal error (a bug): please report it with the message.
    Panic = 6,
}

/// A failed call: its status and message.
pub(crate) struct Failure {
    pub status: ikid_status,
    pub message: String,
}

impl Failure {
    pub fn new(status: ikid_status, message: impl Into<String>) -> Self {
        Failure { status, message: message.into() }
    }
}

impl From<Error> for Failure {
    /// The status is the core's [`ErrorKind`], mapped here once and exhaustively (a new kind
    /// does not compile until it has a status); the message is the core's.
    fn from(e: Error) -> Self {
        let status = match e.kind() {
            ErrorKind::Input => ikid_status::Input,
            ErrorKind::Argument => ikid_status::InvalidArgument,
            ErrorKind::ModelFile => ikid_status::ModelFile,
            ErrorKind::Io => ikid_status::Io,
        };
        Failure::new(status, e.to_string())
    }
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(message: &str) {
    // Interior NULs cannot be represented in a C string: replace them.
    let c = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

/// Runs an ABI body: maps its failure or panic to a status and records the message.
pub(crate) fn guard(body: impl FnOnce() -> Result<(), Failure>) -> ikid_status {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => ikid_status::Ok,
        Ok(Err(f)) => {
            set_last_error(&f.message);
            f.status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            set_last_error(&format!("internal error in libikid (please report): {what}"));
            ikid_status::Panic
        }
    }
}

/// Frees a handle made by `Box::into_raw` (NULL is ignored), behind the panic boundary.
///
/// # Safety
/// `handle` must be NULL or a pointer from `Box::into_raw` not yet freed.
pub(crate) unsafe fn free_handle<T>(handle: *mut T) {
    if !handle.is_null() {
        let _ = guard(|| {
            // SAFETY: a handle from Box::into_raw, freed once (caller's contract).
            drop(unsafe { Box::from_raw(handle) });
            Ok(())
        });
    }
}

/// `ptr` as a reference, or a NullParameter failure naming `what`.
///
/// # Safety
/// A non-NULL `ptr` must point to a valid `T` for `'a`.
pub(crate) unsafe fn non_null<'a, T>(ptr: *const T, what: &str) -> Result<&'a T, Failure> {
    // SAFETY: the caller guarantees validity when non-NULL.
    unsafe { ptr.as_ref() }.ok_or_else(|| Failure::new(ikid_status::NullParameter, format!("{what} is NULL")))
}

/// `ptr` as a mutable reference, or a NullParameter failure naming `what`.
///
/// # Safety
/// A non-NULL `ptr` must point to a valid `T`, not aliased, for `'a`.
pub(crate) unsafe fn non_null_mut<'a, T>(ptr: *mut T, what: &str) -> Result<&'a mut T, Failure> {
    // SAFETY: the caller guarantees validity when non-NULL.
    unsafe { ptr.as_mut() }.ok_or_else(|| Failure::new(ikid_status::NullParameter, format!("{what} is NULL")))
}

/// `len` values at `ptr` as a slice; NULL and misaligned pointers are refused (unless
/// `len` is 0), as is a byte size beyond `isize::MAX`.
///
/// # Safety
/// A non-NULL, aligned `ptr` must point to `len` readable values for `'a`.
pub(crate) unsafe fn slice<'a, T>(ptr: *const T, len: usize, what: &str) -> Result<&'a [T], Failure> {
    if len == 0 {
        return Ok(&[]); // nothing to read: any pointer, even NULL, will do
    }
    if ptr.is_null() {
        return Err(Failure::new(ikid_status::NullParameter, format!("{what} is NULL")));
    }
    if !ptr.is_aligned() {
        return Err(Failure::new(ikid_status::InvalidArgument, format!("{what} is not aligned for its type")));
    }
    check_size::<T>(len, what)?;
    // SAFETY: non-NULL, aligned, size in range; the caller guarantees `len` readable values.
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// `len` values at `ptr` as a mutable slice; NULL and misaligned pointers are refused.
///
/// # Safety
/// A non-NULL, aligned `ptr` must point to `len` writable values, not aliased, for `'a`.
pub(crate) unsafe fn slice_mut<'a, T>(ptr: *mut T, len: usize, what: &str) -> Result<&'a mut [T], Failure> {
    if len == 0 {
        return Ok(&mut []); // nothing to write: any pointer, even NULL, will do
    }
    if ptr.is_null() {
        return Err(Failure::new(ikid_status::NullParameter, format!("{what} is NULL")));
    }
    if !ptr.is_aligned() {
        return Err(Failure::new(ikid_status::InvalidArgument, format!("{what} is not aligned for its type")));
    }
    check_size::<T>(len, what)?;
    // SAFETY: non-NULL, aligned, size in range; the caller guarantees `len` writable values.
    Ok(unsafe { std::slice::from_raw_parts_mut(ptr, len) })
}

/// Copies `values` to `out`, a caller's buffer of `out_len` doubles; too small a buffer is
/// refused, naming both sizes.
///
/// # Safety
/// As [`slice_mut`]: a non-NULL `out` must point to `out_len` writable doubles.
pub(crate) unsafe fn write_doubles(out: *mut f64, out_len: usize, values: &[f64]) -> Result<(), Failure> {
    unsafe { doubles_out(out, out_len, values.len()) }?.copy_from_slice(values);
    Ok(())
}

/// The first `n` doubles of `out`, a caller's buffer of `out_len` doubles; too small a buffer
/// is refused, naming both sizes.
///
/// # Safety
/// As [`slice_mut`]: a non-NULL `out` must point to `out_len` writable doubles.
pub(crate) unsafe fn doubles_out<'a>(out: *mut f64, out_len: usize, n: usize) -> Result<&'a mut [f64], Failure> {
    if out_len < n {
        return Err(Failure::new(
            ikid_status::InvalidArgument,
            format!("out has room for {out_len} doubles, {n} needed"),
        ));
    }
    unsafe { slice_mut(out, n, "out") }
}

fn check_size<T>(len: usize, what: &str) -> Result<(), Failure> {
    match len.checked_mul(std::mem::size_of::<T>()) {
        Some(bytes) if bytes <= isize::MAX as usize => Ok(()),
        _ => Err(Failure::new(ikid_status::InvalidArgument, format!("{what}: length {len} is too large"))),
    }
}

/// The library version, e.g. `"0.1.0"` (static string).
#[unsafe(no_mangle)]
pub extern "C" fn ikid_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

/// A short description of an `ikid_status` value (static string; any int is accepted).
#[unsafe(no_mangle)]
pub extern "C" fn ikid_status_message(status: std::ffi::c_int) -> *const c_char {
    // Taken as an int: a C caller may pass any value, and an invalid enum is UB in Rust.
    let s: &'static str = match status {
        0 => "ok\0",
        1 => "a required pointer argument was NULL\0",
        2 => "an argument has the wrong length or value\0",
        3 => "a file could not be read\0",
        4 => "the model file is invalid\0",
        5 => "the frame is unusable\0",
        6 => "internal error\0",
        _ => "unknown status\0",
    };
    s.as_ptr().cast()
}

/// The message of the last failed call on this thread ("" if none). The pointer stays valid
/// until the next failing libikid call on this thread.
#[unsafe(no_mangle)]
pub extern "C" fn ikid_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn last_error() -> String {
        // SAFETY: ikid_last_error returns a valid NUL-terminated string.
        unsafe { std::ffi::CStr::from_ptr(ikid_last_error()) }.to_string_lossy().into_owned()
    }

    #[test]
    fn a_panic_becomes_a_status_and_a_message() {
        let status = guard(|| panic!("boom at frame 3"));
        assert_eq!(status, ikid_status::Panic);
        assert!(last_error().contains("boom at frame 3"), "{}", last_error());
    }

    #[test]
    fn core_errors_map_to_their_status() {
        let status = guard(|| Err(ikid_core::Error::ModelCard("field \"window\" is 0".into()).into()));
        assert_eq!(status, ikid_status::ModelFile);
        assert!(last_error().contains("window"));
        assert_eq!(guard(|| Ok(())), ikid_status::Ok);
    }
}
