//! Calibrations from C: the two rotation matrices and the side of a calibration file, checked
//! by the core and handed to streams and trackers.

use crate::boundary::{Failure, ikid_status, non_null, slice};
use ikid_core::Calibration;
use ikid_core::calibration::Side;
use nalgebra::Matrix3;

/// The calibration given by `forearm` and `hand` (9 row-major doubles each) and `side`
/// (`"right"`/`"left"`, NULL = right); `None` when both matrices are NULL.
///
/// # Safety
/// `forearm` and `hand` NULL or 9 readable doubles; `side` NULL or NUL-terminated.
pub(crate) unsafe fn calibration_from(
    forearm: *const f64,
    hand: *const f64,
    side: *const std::ffi::c_char,
) -> Result<Option<Calibration>, Failure> {
    let side = if side.is_null() {
        Side::Right
    } else {
        let ptr = unsafe { non_null(side, "side") }?;
        // SAFETY: non-null and NUL-terminated (caller's contract).
        let name = unsafe { std::ffi::CStr::from_ptr(ptr) }
            .to_str()
            .map_err(|_| Failure::new(ikid_status::InvalidArgument, "side is not UTF-8"))?;
        Side::from_name(name)?
    };
    match (forearm.is_null(), hand.is_null()) {
        (true, true) => Ok(None),
        (false, false) => {
            let f = unsafe { slice(forearm, 9, "forearm") }?;
            let h = unsafe { slice(hand, 9, "hand") }?;
            Ok(Some(Calibration::from_matrices_for(Matrix3::from_row_slice(f), Matrix3::from_row_slice(h), side)?))
        }
        _ => Err(Failure::new(
            ikid_status::InvalidArgument,
            "forearm and hand: give both matrices, or both NULL to remove the calibration",
        )),
    }
}

/// [`calibration_from`] with the calibration file's marker shapes: `shapes` NULL (none: each
/// trial's first frames give them) or 18 readable doubles (`"marker_shapes_m"`, row by row),
/// only with both matrices.
///
/// # Safety
/// As [`calibration_from`]; `shapes` NULL or 18 readable doubles.
pub(crate) unsafe fn calibration_with_shapes(
    forearm: *const f64,
    hand: *const f64,
    side: *const std::ffi::c_char,
    shapes: *const f64,
) -> Result<Option<Calibration>, Failure> {
    let calibration = unsafe { calibration_from(forearm, hand, side) }?;
    if shapes.is_null() {
        return Ok(calibration);
    }
    let Some(calibration) = calibration else {
        return Err(Failure::new(
            ikid_status::InvalidArgument,
            "shapes: marker shapes belong to a calibration: give its forearm and hand matrices too",
        ));
    };
    let values = unsafe { slice(shapes, ikid_core::calibration::SEGMENT_SHAPES_LEN, "shapes") }?;
    Ok(Some(calibration.with_shapes(Some(ikid_core::calibration::shapes_from_rows(values)?))))
}
