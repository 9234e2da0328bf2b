"""Angles -> the joint states a ``joint_state`` model reads (``ikid id``): q, q̇, q̈.

A file is offline, so the rates are central differences (no lag), taken after a zero-lag
low-pass of the angles: a 4th-order Butterworth run forwards and backwards (SciPy's
``filtfilt``), at 6 Hz by default — the cut-off OpenSim's users give its inverse dynamics tool.
Differencing twice at 1 kHz multiplies an angle's frame-to-frame noise by ~10⁶: on ``ikid ik``'s
angles from markers with 1 % noise, unfiltered, 78 % of the frames gave implausible torques and
the rest were off by 0.4-0.8 N·m (torques of ±0.3 N·m); low-passed at 6 Hz every frame had one,
within 0.04-0.07 N·m, as from clean markers (simulated seeds 9810-9812, wrist-ik then wrist-id).

Each stretch between time gaps (a step over 1.5 median steps: rows ``ikid ik`` left out) is
filtered and differenced alone: nothing is smeared across a gap. A stretch too short to do so
gives NaN rows, for the caller to count and leave out.
"""

from __future__ import annotations

import numpy as np

from ikid import _native

#: The default cut-off of the angles' low-pass, Hz (OpenSim's inverse dynamics practice).
DEFAULT_LOWPASS_HZ = 6.0
#: The Butterworth filter's order (as OpenSim's IIR low-pass of coordinates).
LOWPASS_ORDER = 4
#: A step longer than this many median steps is a gap between stretches.
GAP_STEPS = 1.5


def min_stretch_rows(lowpass_hz: float | None) -> int:
    """The fewest rows a stretch needs: three for a second difference; more to filter it
    (``filtfilt`` pads each end by three times the filter's length)."""
    return 3 * (LOWPASS_ORDER + 1) + 1 if lowpass_hz else 3


def stretches(time: np.ndarray) -> list[slice]:
    """The runs of rows between time gaps (steps over :data:`GAP_STEPS` median steps)."""
    if len(time) < 2:
        return [slice(0, len(time))]
    step = np.diff(time)
    cuts = np.flatnonzero(step > GAP_STEPS * float(np.median(step))) + 1
    bounds = [0, *cuts.tolist(), len(time)]
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def joint_states(q, time, lowpass_hz: float | None = DEFAULT_LOWPASS_HZ) -> np.ndarray:
    """Angles ``q`` ``(n, 3)`` (rad) at ``time`` ``(n,)`` s -> joint states ``(n, 9)``: the
    angles low-passed at ``lowpass_hz`` (``None`` or 0: as they are), their first and second
    time derivatives. Rows of a stretch shorter than :func:`min_stretch_rows` are NaN."""
    q = np.asarray(q, np.float64)
    time = np.asarray(time, np.float64)
    if q.ndim != 2 or q.shape[1] != 3 or time.shape != (len(q),):
        raise _native.InputError(f"angles: expected (n, 3) and time (n,), got {q.shape} and {time.shape}")
    out = np.full((len(q), 9), np.nan)
    if len(q) < 2:
        return out
    rate = 1.0 / float(np.median(np.diff(time)))
    if lowpass_hz:
        if not (0.0 < lowpass_hz < rate / 2.0):
            raise _native.InputError(
                f"low-pass at {lowpass_hz:g} Hz: must lie below half the angles' rate ({rate / 2.0:g} Hz)"
            )
        from scipy.signal import butter, filtfilt

        b, a = butter(LOWPASS_ORDER, lowpass_hz / (rate / 2.0))
    for part in stretches(time):
        if part.stop - part.start < min_stretch_rows(lowpass_hz):
            continue
        angles = filtfilt(b, a, q[part], axis=0) if lowpass_hz else q[part]
        rates = np.gradient(angles, time[part], axis=0)
        out[part] = np.concatenate([angles, rates, np.gradient(rates, time[part], axis=0)], axis=1)
    return out
