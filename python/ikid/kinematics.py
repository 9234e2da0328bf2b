"""Angles -> the joint states a ``joint_state`` model reads (``ikid id``): q, q̇, q̈.

A file is offline, so the rates are central differences (no lag), taken after a zero-lag
low-pass of the angles: a 4th-order Butterworth run forwards and backwards (SciPy's
``sosfiltfilt``, padded as ``filtfilt`` pads), at 6 Hz by default — the cut-off OpenSim's users
give its inverse dynamics tool.
Differencing twice at 1 kHz multiplies an angle's frame-to-frame noise by ~10⁶: on ``ikid ik``'s
angles from markers with 1 % noise, unfiltered, 78 % of the frames gave implausible torques and
the rest were off by 0.4-0.8 N·m (torques of ±0.3 N·m); low-passed at 6 Hz every frame had one,
within 0.04-0.07 N·m, as from clean markers (simulated seeds 9810-9812, wrist-ik then wrist-id).

Each stretch between time gaps (a step over 1.5 median steps: rows ``ikid ik`` left out) is
filtered and differenced alone: nothing is smeared across a gap. A stretch too short to do so
gives NaN rows, for the caller to count and leave out.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from ikid import _native
from ikid.io.resample import GAP_STEPS

#: The default cut-off of the angles' low-pass, Hz (OpenSim's inverse dynamics practice).
DEFAULT_LOWPASS_HZ = 6.0
#: The Butterworth filter's order (as OpenSim's IIR low-pass of coordinates).
LOWPASS_ORDER = 4
#: Rows ``filtfilt`` pads each end with (SciPy's default for this order's transfer function,
#: kept for the second-order sections so the ends are filtered as they always were).
PAD_ROWS = 3 * (LOWPASS_ORDER + 1)


def min_stretch_rows(lowpass_hz: float | None) -> int:
    """The fewest rows a stretch needs: three for a second difference; more to filter it
    (each end is padded with :data:`PAD_ROWS` rows reflected from it)."""
    return PAD_ROWS + 1 if lowpass_hz else 3


def joint_states(q, time, lowpass_hz: float | None = DEFAULT_LOWPASS_HZ) -> np.ndarray:
    """Angles ``q`` ``(n, 3)`` (rad) at ``time`` ``(n,)`` s -> joint states ``(n, 9)``: the
    angles low-passed at ``lowpass_hz`` (``None`` or 0: as they are), their first and second
    time derivatives. Rows of a stretch shorter than :func:`min_stretch_rows` are NaN."""
    q = np.asarray(q, np.float64)
    time = np.asarray(time, np.float64)
    _check_block(q, time)
    if len(q) < 2:
        return np.full((len(q), 9), np.nan)
    parts = [s for _, s in joint_state_blocks([(time, q)], sample_rate(time), lowpass_hz)]
    return np.concatenate(parts) if parts else np.full((len(q), 9), np.nan)


def sample_rate(time) -> float:
    """The rate of rows stamped ``time`` (s): one over their mean step, steps away from the
    median one (gaps, over :data:`GAP_STEPS` of it) left out. Rounded stamps give the rate they
    were sampled at: a 120 Hz file's times rounded to the millisecond step 8 and 9 ms, and their
    median step read as 125 Hz (review 7)."""
    steps = np.diff(np.asarray(time, np.float64))
    median = float(np.median(steps))
    near = steps[(steps > 0.5 * median) & (steps <= GAP_STEPS * median)]
    return 1.0 / float(near.mean()) if len(near) else 1.0 / median


def _check_block(q: np.ndarray, time: np.ndarray) -> None:
    if q.ndim != 2 or q.shape[1] != 3 or time.shape != (len(q),):
        raise _native.InputError(f"angles: expected (n, 3) and time (n,), got {q.shape} and {time.shape}")


def overlap_rows(rate_hz: float, lowpass_hz: float | None) -> int:
    """Rows of context on each side of a block that make it low-pass and difference as the
    whole stretch would: two for the second difference, and the rows over which the filter's
    slowest pole decays to 1e-16 (the design's own poles, not roots of its polynomial, which
    lose their digits near a cut-off of 0 or half the rate)."""
    if not lowpass_hz:
        return 2
    _, poles, _ = _butter(rate_hz, lowpass_hz, "zpk")
    slowest = float(np.max(np.abs(poles)))
    return 2 + int(np.ceil(np.log(1e-16) / np.log(slowest)))


def _butter(rate_hz: float, lowpass_hz: float, output: str = "sos"):
    """The low-pass Butterworth as second-order sections (well conditioned at any cut-off, where
    a transfer function's coefficients are not near 0 or half the rate), or ``"zpk"``."""
    if not (0.0 < lowpass_hz < rate_hz / 2.0):
        raise _native.InputError(
            f"low-pass at {lowpass_hz:g} Hz: must lie below half the angles' rate ({rate_hz / 2.0:g} Hz)"
        )
    from scipy.signal import butter

    return butter(LOWPASS_ORDER, lowpass_hz / (rate_hz / 2.0), output=output)


#: How close to a time gap, in periods of the low-pass cut-off, a row's states are still
#: settling: the filter and the differences there have the stretch on one side only. Measured
#: (smooth angles, a 3-row gap every 0.5 s, exact Newton-Euler torques against the true ones,
#: 6 Hz): e_f's torque error next to a gap 0.056 / 0.064 / 0.076 N·m at 70 / 100 / 1000 Hz
#: against 0.001-0.007 inside a stretch, back within 1.5x of it 0.1-0.2 s away. Unfiltered, the
#: differences' own two rows.
EDGE_CUTOFF_PERIODS = 1.5


def gap_edge_s(rate_hz: float, lowpass_hz: float | None) -> float:
    """How long after and before a time gap a row's joint states count as settling
    (:data:`EDGE_CUTOFF_PERIODS`; two rows unfiltered)."""
    return EDGE_CUTOFF_PERIODS / lowpass_hz if lowpass_hz else 2.0 / rate_hz


def joint_state_blocks(
    blocks: Iterable[tuple[np.ndarray, np.ndarray]], rate_hz: float, lowpass_hz: float | None
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """:func:`joint_states` over angles given as ``(time, q)`` blocks in order (a file read in
    blocks), at ``rate_hz`` (a step over :data:`GAP_STEPS` of ``1 / rate_hz`` is a gap): the
    ``(time, states)`` blocks, every input row once, in order. A long stretch is filtered a
    piece at a time with :func:`overlap_rows` of context each side, as it would be whole
    (within rounding): memory is a block's and two overlaps', whatever the length."""
    for time, states, _, _ in joint_state_blocks_near_edges(blocks, rate_hz, lowpass_hz):
        yield time, states


def joint_state_blocks_near_edges(
    blocks: Iterable[tuple[np.ndarray, np.ndarray]], rate_hz: float, lowpass_hz: float | None
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """:func:`joint_state_blocks`, each block with which of its rows lie within
    :func:`gap_edge_s` of a time gap (before or after it), and which within it of the file's
    own first or last row: there the states are still settling (the filter and the differences
    have the stretch on one side only; a file's ends are as far off as a gap's, so a torque
    there is as unsure)."""
    # A quarter period less, so a row at the edge itself is not in or out by its time's rounding.
    edge = gap_edge_s(rate_hz, lowpass_hz) - 0.25 / rate_hz
    # The current stretch's first time, and whether a gap (not the file's start) came before it.
    first_time, after_gap = None, False

    for time, states, end, last in _state_blocks(blocks, rate_hz, lowpass_hz):
        if first_time is None and len(time):
            first_time = float(time[0])
        start_near = time - first_time < edge if first_time is not None else np.zeros(len(time), bool)
        end_near = end - time < edge if end is not None else np.zeros(len(time), bool)
        near_gap = (start_near if after_gap else False) | (end_near if not last else False)
        near_file_end = (start_near if not after_gap else False) | (end_near if last else False)
        yield time, states, np.asarray(near_gap, bool), np.asarray(near_file_end, bool)
        if end is not None:  # the stretch ended at a gap: the next one starts after it
            first_time, after_gap = None, True


def _state_blocks(
    blocks: Iterable[tuple[np.ndarray, np.ndarray]], rate_hz: float, lowpass_hz: float | None
) -> Iterator[tuple[np.ndarray, np.ndarray, float | None, bool]]:
    """:func:`joint_state_blocks`' blocks, each with the last time of its stretch when the
    block ends a stretch (``None`` otherwise), and whether that end is the file's (the last
    block) rather than a time gap's."""
    if lowpass_hz:
        from scipy.signal import sosfiltfilt

        sos = _butter(rate_hz, lowpass_hz)
    context = overlap_rows(rate_hz, lowpass_hz)
    gap = GAP_STEPS / rate_hz
    least = min_stretch_rows(lowpass_hz)

    def states(time: np.ndarray, q: np.ndarray) -> np.ndarray:
        """A whole stretch (or a piece with its context) -> its states. Differenced on the
        sampling grid, as the low-pass takes the rows: within a stretch each step is one period
        (gaps end it), and a time column's jitter is its clock's or its export's rounding, not
        the sampling's (review 7: ±0.1 ms on a 1 kHz .mot, differenced as stamped, put the
        torques 0.17 N·m off where they are 0.125 N·m RMS, every row status 0)."""
        angles = sosfiltfilt(sos, q, axis=0, padlen=PAD_ROWS) if lowpass_hz else q
        rates = np.gradient(angles, 1.0 / rate_hz, axis=0)
        return np.concatenate([angles, rates, np.gradient(rates, 1.0 / rate_hz, axis=0)], axis=1)

    # The current stretch's rows not yet given (after ``done`` rows of context already given),
    # and how many rows of it were given before (a stretch given in pieces is long).
    time, q = np.empty(0), np.empty((0, 3))
    done = given = 0
    last = -np.inf
    for block_time, block_q in blocks:
        block_time = np.asarray(block_time, np.float64)
        block_q = np.asarray(block_q, np.float64)
        _check_block(block_q, block_time)
        if len(block_time) == 0:
            continue
        cuts = np.flatnonzero(np.diff(np.concatenate([[last], block_time])) > gap)
        last = float(block_time[-1])
        time, q = np.concatenate([time, block_time]), np.concatenate([q, block_q])
        # Stretches that ended in this block: each given whole (with its first rows' context).
        start = len(time) - len(block_time)
        for cut in cuts:
            end = start + int(cut)
            if end > 0 and end > done:
                yield (
                    time[done:end],
                    _stretch(states, time[:end], q[:end], done, given, least),
                    float(time[end - 1]),
                    False,
                )
            time, q = time[end:], q[end:]
            start -= end
            done = given = 0
        # A stretch going on: give all but the context its last rows need.
        if len(time) - done > 2 * context:
            upto = len(time) - context
            yield time[done:upto], states(time, q)[done:upto], None, False
            given += upto - done
            time, q = time[upto - context :], q[upto - context :]
            done = context
    if len(time) > done:
        # Its context rows (:func:`overlap_rows`, many periods of the cut-off) were held back
        # to here, so every row within gap_edge_s of the file's end is in this block.
        yield time[done:], _stretch(states, time, q, done, given, least), float(time[-1]), True


def _stretch(states, time: np.ndarray, q: np.ndarray, done: int, given: int, least: int) -> np.ndarray:
    """The last rows (from ``done``) of a stretch that has ended; NaN if the whole stretch (its
    ``given`` rows before these, and these) is too short to filter and difference."""
    if given + len(time) - done < least:
        return np.full((len(time) - done, 9), np.nan)
    return states(time, q)[done:]
