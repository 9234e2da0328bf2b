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

from collections.abc import Iterable, Iterator

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
    new_time = time[0] + np.arange(_grid_count(time[0], time[-1], rate_hz)) / rate_hz
    with np.errstate(invalid="ignore"):
        slopes = np.gradient(values, time, axis=0)
    return new_time, _hermite(time, values, slopes, new_time)


def _grid_count(first: float, last: float, rate_hz: float) -> int:
    """Grid points from ``first`` up to ``last`` (inclusive, to rounding) at ``rate_hz``."""
    return int(np.floor((last - first) * rate_hz + 1e-9)) + 1


def _hermite(time: np.ndarray, values: np.ndarray, slopes: np.ndarray, new_time: np.ndarray) -> np.ndarray:
    """The cubic Hermite through ``values`` with ``slopes`` at ``time``, at ``new_time``."""
    i = np.clip(np.searchsorted(time, new_time, side="right") - 1, 0, len(time) - 2)
    h = (time[i + 1] - time[i])[:, None]
    s = ((new_time - time[i]) / h[:, 0])[:, None]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    new_values = h00 * values[i] + h10 * h * slopes[i] + h01 * values[i + 1] + h11 * h * slopes[i + 1]
    # A grid point that coincides with an input sample takes it exactly.
    exact = np.isclose(s[:, 0], 0.0, atol=1e-12)
    new_values[exact] = values[i[exact]]
    return new_values


#: A step longer than this many frame steps is a time gap between stretches (here and in
#: :mod:`ikid.kinematics`, whose low-pass treats each stretch alone): the core's, at which a
#: stamped tracker or stream restarts.
GAP_STEPS: float = _native.GAP_PERIODS


def resample_stretches(
    blocks: Iterable[tuple[np.ndarray, np.ndarray]], from_hz: float, rate_hz: float
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """:func:`resample` over ``(time, values)`` blocks in order (a file read in blocks) sampled
    at ``from_hz``, each stretch between time gaps (a step over :data:`GAP_STEPS` input steps:
    rows a writer left out) alone, on its own grid from its first time: no value is made inside
    a gap. A stretch of under 3 rows cannot be resampled: its rows come back at their own times
    as NaN, for the caller to count. Memory is a block's, whatever the length; the values are
    :func:`resample`'s over each whole stretch."""
    gap = GAP_STEPS / from_hz
    # The current stretch: its first time, its rows not yet used up (with one row before the
    # next grid point's interval, for that row's slope), its next grid index and its row count.
    start = 0.0
    time, values = np.empty(0), None
    k = rows = 0
    last = -np.inf

    def give(final: bool) -> tuple[np.ndarray, np.ndarray] | None:
        """The grid points the rows so far decide: every one to the stretch's end if ``final``,
        else those before the next-to-last row (whose slope needs the row after it)."""
        nonlocal time, values, k
        assert values is not None
        if rows < 3:
            return (time, np.full(values.shape, np.nan)) if final and rows else None
        new_time = start + np.arange(k, _grid_count(start, time[-1], rate_hz)) / rate_hz
        if not final:
            new_time = new_time[new_time < time[-2]]
        if len(new_time) == 0:
            return None
        with np.errstate(invalid="ignore"):
            slopes = np.gradient(values, time, axis=0)
        out = _hermite(time, values, slopes, new_time)
        k += len(new_time)
        # Keep from the row before the next grid point's interval.
        nxt = start + k / rate_hz
        keep = max(0, int(np.searchsorted(time, nxt, side="right")) - 2)
        time, values = time[keep:], values[keep:]
        return new_time, out

    for block_time, block_values in blocks:
        block_time = np.asarray(block_time, np.float64)
        block_values = np.asarray(block_values, np.float64)
        if len(block_time) == 0:
            continue
        cuts = np.flatnonzero(np.diff(np.concatenate([[last], block_time])) > gap).tolist()
        last = float(block_time[-1])
        bounds = [0, *cuts, len(block_time)]
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if a == b:
                continue
            if a in cuts:  # a new stretch: the one before has ended
                if values is not None and (part := give(final=True)) is not None:
                    yield part
                start, time, values, k, rows = float(block_time[a]), np.empty(0), None, 0, 0
            time = np.concatenate([time, block_time[a:b]])
            values = block_values[a:b] if values is None else np.concatenate([values, block_values[a:b]])
            rows += b - a
            if (part := give(final=False)) is not None:
                yield part
    if values is not None and (part := give(final=True)) is not None:
        yield part
