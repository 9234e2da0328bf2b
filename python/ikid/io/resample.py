"""Resampling marker trajectories to the frame rate a model was trained at.

Method (documented, because timing matters to a windowed network): piecewise cubic Hermite
interpolation with finite-difference slopes (``numpy.gradient``, second order on uneven
spacing) — C¹-continuous, local (each output depends on the four nearest input samples),
exact for motion that is quadratic in time, no overshoot beyond what those samples imply.
A missing input sample (NaN) makes the outputs within two input intervals of it missing too (the slopes
beside it use it); it never bleeds further. The output grid starts at the first input time and steps by
``1 / rate_hz`` up to the last input time.
"""

from __future__ import annotations

import numpy as np

from ikid import _native


def resample(time, values, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """``(new_time, new_values)``: ``values`` ``(n, k)`` sampled at ``time`` ``(n,)``, on a
    uniform ``rate_hz`` grid."""
    time = np.asarray(time, np.float64)
    values = np.asarray(values, np.float64)
    if time.ndim != 1 or values.ndim != 2 or len(values) != len(time):
        raise _native.InputError(
            f"resample: expected time (n,) and values (n, k), got {time.shape} and {values.shape}"
        )
    if len(time) < 3:
        raise _native.InputError(f"resample: needs at least 3 samples, got {len(time)}")
    if not np.all(np.isfinite(time)) or np.any(np.diff(time) <= 0):
        raise _native.InputError("resample: time must be finite and strictly increasing")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise _native.InputError(f"resample: rate {rate_hz} Hz is not a positive number")
    count = int(np.floor((time[-1] - time[0]) * rate_hz + 1e-9)) + 1
    new_time = time[0] + np.arange(count) / rate_hz
    with np.errstate(invalid="ignore"):
        slopes = np.gradient(values, time, axis=0)
    i = np.clip(np.searchsorted(time, new_time, side="right") - 1, 0, len(time) - 2)
    h = (time[i + 1] - time[i])[:, None]
    s = ((new_time - time[i]) / h[:, 0])[:, None]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    new_values = h00 * values[i] + h10 * h * slopes[i] + h01 * values[i + 1] + h11 * h * slopes[i + 1]
    # A grid point that coincides with an input sample takes it exactly.
    exact = np.isclose(s[:, 0], 0.0, atol=1e-12)
    new_values[exact] = values[i[exact]]
    return new_time, new_values
