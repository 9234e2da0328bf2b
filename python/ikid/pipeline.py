"""A model over a whole recording from a lab: markers in, one output row per frame that has
one, and an account of every frame that has none.

This is what the ``ikid ik`` / ``ikid run`` commands do, as a function. Frames go through
a :class:`ikid.Stream` with their timestamps, exactly as they would live: the model's
missing-marker policy applies, a gap in time restarts the window, and a frame the stream
refuses (a marker it cannot fill, a jumping marker) yields no row — it is counted, by
reason, in :attr:`Run.refused`, never written as a guess.

**Which model, at which rate** (:func:`pick_model`, the one place this is decided). A shipped
name without a rate suffix, such as ``wrist-ik``, names a *family*: that model and its shipped
siblings ``<name>-<rate>hz`` (``wrist-ik-100hz``, ``wrist-ik-250hz``). Each member's rate is its
card's ``frame_rate_hz`` (the suffix only finds the files). For a recording at rate *r*:

1. the member whose rate equals *r* (within :data:`RATE_TOLERANCE`) runs on the recording's own
   frames, exactly as a live stream at that rate would;
2. otherwise the fastest member (``wrist-ik``, 1 kHz: the shortest window in seconds) runs at
   its own rate on the recording *resampled to it*, and the outputs are the ones at the
   recording's own frame times (:func:`run_model`, ``at_recording_frames``). Measured both ways
   on the one real recording at such a rate (racing, 70 Hz, calibrated): the 1 kHz member 3.97°
   geodesic RMS with an output on 99.3 % of its valid frames, the next faster (100 Hz, 100 ms
   window) 6.11° and 95.8 %; on simulated trials at 70 Hz the 100 Hz member is better with noise
   (1.2e-4 vs 2.0e-4 rad² at 1 %), equal on clean markers — real markers, fast and clean, decide.
   Nothing is written between frames, and a missing frame stays missing: a grid point takes a
   recording frame's markers exactly where it falls on one, the cubic Hermite between two frames
   uses those two (never a missing one's neighbours), and no grid point is made inside a time gap.
   ``--resample`` (``resample_to_model``) keeps the older behaviour: the whole recording resampled,
   outputs on the model's grid.

A model given as a file (or an explicit per-rate name, or a loaded :class:`ikid.Model`) is
that model: at another rate than its card's it is refused unless ``resample_to_model``.
"""

from __future__ import annotations

import os
import re
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ikid import _native
from ikid.io.resample import resample

#: Relative difference between a file's frame rate and the model's that still counts as equal.
RATE_TOLERANCE = 1e-3


def same_rate(a_hz: float, b_hz: float) -> bool:
    """True if two frame rates are equal to :data:`RATE_TOLERANCE` (relative to ``b_hz``)."""
    return abs(a_hz - b_hz) <= RATE_TOLERANCE * b_hz


@dataclass
class Run:
    """Outputs for the frames that have one, in input order."""

    time: np.ndarray
    #: Index of each output's frame in the (possibly resampled) input.
    frame: np.ndarray
    values: np.ndarray
    #: True where the stream filled a missing marker of that frame.
    filled: np.ndarray
    n_frames: int
    #: Frames without an output, by reason (the window filling up is ``"window filling"``).
    refused: Counter = field(default_factory=Counter)
    rate_hz: float = 0.0
    resampled_from_hz: float | None = None
    #: Times a gap in the timestamps restarted the window.
    gap_restarts: int = 0
    #: The first frame's message for each reason in :attr:`refused` (e.g. why the markers are
    #: implausible), shown in the summary.
    examples: dict[str, str] = field(default_factory=dict)
    #: Each output row's ``ikid.FRAME_STATUS`` bits (filled, outside the training range).
    status: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint8))
    #: The model that ran (its card's name) and its card's rate.
    model_name: str = ""
    model_rate_hz: float = 0.0
    #: True if the recording was resampled to the model's rate and the outputs taken at the
    #: recording's own frame times (``rate_hz`` is then the recording's).
    at_recording_frames: bool = False
    #: True for each output row given while the stream's window was filling (an early output:
    #: the per-frame solution).
    filling: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def flagged(self, bit: str) -> int:
        """Output rows carrying status bit ``bit`` (an ``ikid.FRAME_STATUS`` name)."""
        return int(np.count_nonzero(self.status & _native.FRAME_STATUS[bit]))

    @property
    def clean(self) -> bool:
        """True if every frame has an output and none is flagged: what ``--strict`` asks. The
        window's filling is not a flaw: its frames may lack an output, or carry the per-frame
        solution (``per_frame`` and nothing else)."""
        lost = sum(n for reason, n in self.refused.items() if reason != "window filling")
        flagged = self.status.copy()
        if len(self.filling):
            flagged[self.filling & (flagged == _native.FRAME_STATUS["per_frame"])] = 0
        return lost == 0 and not flagged.any()

    def summary(self) -> str:
        parts = [f"{len(self.time)}/{self.n_frames} frames with output"]
        if self.filled.any():
            parts.append(f"{int(self.filled.sum())} with a filled marker")
        if self.flagged("outside_training"):
            parts.append(f"{self.flagged('outside_training')} outside the model's training range (flagged)")
        if self.flagged("per_frame"):
            early = int(np.count_nonzero(self.filling)) if len(self.filling) else 0
            beyond = self.flagged("per_frame") - early
            parts.append(
                f"{self.flagged('per_frame')} per-frame solutions (flagged: {early} while the window filled, "
                f"{beyond} where the window's posture or speed was beyond training)"
            )
        for reason, n in self.refused.most_common():
            example = self.examples.get(reason)
            explained = any(w in reason for w in _SELF_EXPLAINED) or not example
            parts.append(f"{n} {reason}" if explained else f"{n} {reason} (first: {example})")
        if self.gap_restarts:
            parts.append(f"{self.gap_restarts} window restarts after time gaps")
        if self.resampled_from_hz:
            parts.append(f"resampled {self.resampled_from_hz:g} -> {self.rate_hz:g} Hz")
        if self.model_name:
            parts.append(self.model_note())
        return ", ".join(parts)

    def model_note(self) -> str:
        """Which model ran, at which rate, on which frames (for the summary line)."""
        head = f"model {self.model_name} ({self.model_rate_hz:g} Hz)"
        if self.at_recording_frames:
            return (
                f"{head}, the {self.rate_hz:g} Hz recording resampled to it, "
                f"outputs at the recording's frames"
            )
        if self.resampled_from_hz:
            return f"{head}, outputs at its rate"
        return f"{head} at the recording's rate"


def refusal_reason(error: _native.InputError) -> str:
    """A short, countable reason for a refused frame, from the core's classification (its
    stable code; never the message, whose numbers differ from frame to frame)."""
    markers = ", ".join(error.markers)
    if error.code == "missing_markers":
        return f"missing {markers} (not fillable)"
    if error.code == "outlier_marker":
        return f"{markers} jumped"
    if error.code == "non_finite_input":
        return "missing marker (model refuses gaps)"
    if error.code:
        return error.code.replace("_", " ")
    return (error.reason or str(error)).split(";")[0]


#: Reasons that say all there is to say; any other is shown with its first frame's message.
_SELF_EXPLAINED = ("window filling", "missing ", "jumped", "missing marker")


def check_rate(model: _native.Model, rate_hz: float, source: str, allow_resample: bool) -> bool:
    """True if ``rate_hz`` must be resampled to the model's rate; an error if it differs and
    resampling was not asked for."""
    if same_rate(rate_hz, model.frame_rate_hz):
        return False
    if not allow_resample:
        raise _native.InputError(
            f"{source} is sampled at {rate_hz:g} Hz but model {model.name!r} was trained at "
            f"{model.frame_rate_hz:g} Hz; resample it (--resample, or ikid.io.resample: cubic Hermite to "
            f"{model.frame_rate_hz:g} Hz) — a windowed model run at another rate would be silently mis-timed"
        )
    return True


#: A shipped per-rate model's name: its family's name and its rate (``wrist-ik-100hz``).
_PER_RATE = re.compile(r"^(?P<family>.+)-(?P<rate>\d+(?:\.\d+)?)hz$")

#: A recording frame runs on the model grid point within 1/(2·PHASE_STEPS) of a model period
#: of it (0.05 ms at 100 Hz): frames are grouped by their phase on the model's grid in steps of
#: 1/PHASE_STEPS period, one stream per group (70 Hz on a 100 Hz model: 7 groups).
PHASE_STEPS = 100


def family_members(name: str | os.PathLike[str]) -> list[_native.Model]:
    """The shipped models of family ``name``, slowest first: ``name`` itself and every shipped
    ``<name>-<rate>hz``, each at its card's ``frame_rate_hz``. Empty if ``name`` is not a family
    (a path, a per-rate name such as ``wrist-ik-100hz``, or not shipped)."""
    import ikid

    if not ikid.is_model_name(name) or _PER_RATE.match(str(name)):
        return []
    names = [
        n
        for n in ikid.available_models()
        if n == name or ((m := _PER_RATE.match(n)) is not None and m["family"] == name)
    ]
    return sorted((ikid.load(n) for n in names), key=lambda m: m.frame_rate_hz)


def model_at_rate(
    model: str | os.PathLike[str],
    rate_hz: float,
    source: str = "the stream",
    *,
    allow_unchecked: bool = False,
) -> _native.Model:
    """The model of ``model`` (a family name, a shipped name or a file) trained at ``rate_hz``,
    for frames that cannot be resampled (a live stream); an :class:`ikid.InputError` listing
    the rates there are otherwise. ``allow_unchecked``: as :func:`ikid.load`."""
    import ikid

    if not (isinstance(rate_hz, (int, float)) and np.isfinite(rate_hz) and rate_hz > 0):
        raise _native.ArgumentError(f"rate_hz: {rate_hz!r}: expected a rate in Hz greater than 0")
    members = family_members(model) or [ikid.load(model, allow_unchecked=allow_unchecked)]
    for m in members:
        if same_rate(rate_hz, m.frame_rate_hz):
            return m
    rates = ", ".join(f"{m.frame_rate_hz:g} Hz ({m.name})" for m in members)
    raise _native.InputError(
        f"{source} runs at {rate_hz:g} Hz; {str(model)!r} has models at {rates}. A live stream is not "
        "resampled (it would add latency): record at one of those rates, run the recording offline "
        "(ikid ik resamples), or train a model at yours (ikid train, from ikid-training)"
    )


def pick_model(
    model: _native.Model | str | os.PathLike[str],
    rate_hz: float | None,
    *,
    resample_to_model: bool = False,
    source: str = "frames",
    allow_unchecked: bool = False,
) -> tuple[_native.Model, str]:
    """The model to run on a recording at ``rate_hz`` and how: ``(model, how)``, ``how`` one of
    ``"native"`` (the recording's own frames), ``"at_frames"`` (resampled to the model's rate,
    outputs at the recording's frame times) or ``"resample"`` (resampled, outputs on the model's
    grid: ``resample_to_model``). The rule is the module's docstring; a model that cannot run at
    ``rate_hz`` is an :class:`ikid.InputError` saying what to do. ``allow_unchecked``: a model
    file without a checksum is loaded (see :func:`ikid.load`)."""
    if isinstance(model, _native.Model):
        return model, (
            "resample" if rate_hz and check_rate(model, rate_hz, source, resample_to_model) else "native"
        )
    members = family_members(model)
    if not members:
        import ikid

        loaded = ikid.load(model, allow_unchecked=allow_unchecked)
        return pick_model(loaded, rate_hz, resample_to_model=resample_to_model, source=source)
    if rate_hz is None:  # one frame: no rate to go by, the family's own model
        return next(m for m in members if m.name == str(model) or m is members[-1]), "native"
    for m in members:
        if same_rate(rate_hz, m.frame_rate_hz):
            return m, "native"
    # No member at this rate: the fastest (the module docstring says why, measured).
    chosen = max(members, key=lambda m: m.frame_rate_hz)
    return chosen, ("resample" if resample_to_model else "at_frames")


def run_model(
    model: _native.Model | str | os.PathLike[str],
    frames,
    time,
    *,
    rate_hz: float | None = None,
    resample_to_model: bool = False,
    missing_markers: str | None = None,
    calibration: _native.Calibration | None = None,
    source: str = "frames",
    progress: bool = False,
    early_outputs: bool | None = None,
    allow_unchecked: bool = False,
) -> Run:
    """Run ``model`` over ``frames`` ``(n, frame_len)`` at ``time`` ``(n,)`` seconds; with a
    ``calibration`` (see :func:`ikid.calibrate`), for this subject's marker placement.

    ``model`` is a loaded model, a file, or a shipped name; a family name (``"wrist-ik"``) runs
    the family's model for the recording's rate (:func:`pick_model`; :attr:`Run.model_name` says
    which). ``rate_hz`` defaults to the median of the time steps. ``early_outputs`` (default:
    whenever the model corrects its newest frame's features, as the IK models do): while a
    window fills (the first frames, and after a time gap) each frame gets its per-frame
    solution, flagged ``per_frame``, so every frame has an output. ``allow_unchecked``: a model
    file without a checksum is loaded (with a warning; see :func:`ikid.load`)."""
    frames = np.asarray(frames, np.float64)
    time = np.asarray(time, np.float64)
    if frames.ndim != 2 or time.shape != (len(frames),):
        n_cols = model.frame_len if isinstance(model, _native.Model) else "frame_len"
        raise _native.InputError(
            f"{source}: expected frames (n, {n_cols}) and time (n,), got {frames.shape} and {time.shape}"
        )
    if rate_hz is None and len(time) > 1:
        rate_hz = 1.0 / float(np.median(np.diff(time)))
    model, how = pick_model(
        model, rate_hz, resample_to_model=resample_to_model, source=source, allow_unchecked=allow_unchecked
    )
    if rate_hz is None:
        rate_hz = model.frame_rate_hz
    if early_outputs is None:
        early_outputs = model.card.get("output_offset") is not None
    kw: dict[str, Any] = {
        "missing_markers": missing_markers,
        "calibration": calibration,
        "early_outputs": early_outputs,
    }
    bar = _progress(len(frames), source) if progress else None
    try:
        if how == "at_frames":
            return _run_at_recording_frames(model, frames, time, rate_hz, kw, bar)
        resampled_from = None
        if how == "resample":
            time, frames = resample(time, frames, model.frame_rate_hz)
            resampled_from, rate_hz = rate_hz, model.frame_rate_hz
        tally = _Tally(len(frames))
        stream = model.stream(**kw)
        for i, (t, frame) in enumerate(zip(time, frames, strict=True)):
            if bar is not None and i % 1000 == 999:
                bar.update(1000)
            tally.add(i, _push(stream, t, frame, model.window))
        return tally.run(model, time, rate_hz, resampled_from, stream.gap_restarts)
    finally:
        if bar is not None:
            bar.close()


class _Tally:
    """Outcomes per frame, in frame order, into a :class:`Run`."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.rows: list = []
        self.index: list[int] = []
        self.filled: list[bool] = []
        self.status: list[int] = []
        self.filling: list[bool] = []
        self.refused: Counter = Counter()
        self.examples: dict[str, str] = {}

    def add(self, i: int, outcome: tuple) -> None:
        if outcome[0] == "out":
            _, values, filled, status, filling = outcome
            self.rows.append(values)
            self.index.append(i)
            self.filled.append(filled)
            self.status.append(status)
            self.filling.append(filling)
        else:
            _, reason, example = outcome
            self.refused[reason] += 1
            if example is not None:
                self.examples.setdefault(reason, f"frame {i}: {example}")

    def run(self, model, time, rate_hz, resampled_from, gap_restarts, at_frames: bool = False) -> Run:
        values = np.array(self.rows, np.float64).reshape(-1, model.n_outputs)
        idx = np.array(self.index, np.int64)
        return Run(
            time[idx],
            idx,
            values,
            np.array(self.filled, bool),
            self.n,
            self.refused,
            rate_hz,
            resampled_from,
            gap_restarts,
            self.examples,
            np.array(self.status, np.uint8),
            model.name,
            model.frame_rate_hz,
            at_frames,
            np.array(self.filling, bool),
        )


def _push(stream: _native.Stream, t: float, frame: np.ndarray, window: int) -> tuple:
    """One frame through ``stream``: ``("out", values, filled, status, filling)`` (``filling``:
    an early output, the window not yet full) or ``("none", reason, example message or None)``."""
    try:
        out = stream.push(frame, time=float(t))
    except _native.InputError as e:
        return ("none", refusal_reason(e), e.reason or str(e))
    if out is None:
        return ("none", "window filling", None)
    if stream.status & _native.FRAME_STATUS["implausible"]:
        # Nothing no wrist can give is written as a number: the frame is counted instead.
        reason = "implausible outputs (far outside the model's training range), not written"
        return ("none", reason, np.array2string(np.asarray(out), precision=3))
    return ("out", out, bool(stream.filled_markers), stream.status, stream.filled < window)


def _run_at_recording_frames(
    model: _native.Model, frames: np.ndarray, time: np.ndarray, rate_hz: float, kw: dict, bar
) -> Run:
    """``model`` at its own rate over a recording at ``rate_hz``, an output at each recording
    frame's time: the frames are grouped by their phase on the model's grid (see
    :data:`PHASE_STEPS`); each group gets its own stream over a grid of that phase, on which every
    frame of the group is a grid point carrying the frame's own markers, the points between
    frames interpolated (cubic Hermite from the two frames around them only), none made inside a
    time gap (> 1.5 recording periods: the stream restarts after it, as live)."""
    if len(time) < 2:
        raise _native.InputError(f"resampling needs at least 2 frames, got {len(time)}")
    if not np.all(np.isfinite(time)) or np.any(np.diff(time) <= 0):
        raise _native.InputError("time must be finite and strictly increasing to resample")
    period = 1.0 / model.frame_rate_hz
    pos = (time - time[0]) / period
    phase = np.round((pos - np.floor(pos)) * PHASE_STEPS).astype(np.int64) % PHASE_STEPS
    gap = 1.5 / rate_hz
    slopes = _local_slopes(time, frames, gap)
    outcomes: list[tuple | None] = [None] * len(time)
    restarts = 0
    for b in np.unique(phase):
        phi = b / PHASE_STEPS
        members = np.flatnonzero(phase == b)
        at = np.round(pos[members] - phi).astype(np.int64)
        grid_t = time[0] + (phi + np.arange(at.max() + 1)) * period
        values, valid = _hermite(time, frames, slopes, grid_t, gap)
        values[at], grid_t[at], valid[at] = frames[members], time[members], True
        frame_at = dict(zip(at.tolist(), members.tolist(), strict=True))
        stream = model.stream(**kw)
        for k in np.flatnonzero(valid):
            outcome = _push(stream, grid_t[k], values[k], model.window)
            i = frame_at.get(int(k))
            if i is not None:
                outcomes[i] = outcome
                if bar is not None:
                    bar.update(1)
        restarts = max(restarts, stream.gap_restarts)
    tally = _Tally(len(time))
    for i, got in enumerate(outcomes):
        tally.add(i, got or ("none", "not run", None))
    return tally.run(model, time, rate_hz, None, restarts, at_frames=True)


def _local_slopes(time: np.ndarray, values: np.ndarray, gap: float) -> np.ndarray:
    """Each sample's slope (as :func:`ikid.io.resample`'s: second-order central differences) from
    its neighbours that are present and not across a time gap (> ``gap`` s): one-sided beside a
    missing sample or a gap, 0 with neither. A missing sample never makes its neighbours' slopes
    missing, so it only touches the intervals on either side of it."""
    h = np.diff(time)[:, None]
    d = np.diff(values, axis=0) / h
    ok = np.isfinite(d) & (h <= gap)
    nan_row = np.full((1, values.shape[1]), np.nan)
    back = np.vstack([nan_row, np.where(ok, d, np.nan)])
    fwd = np.vstack([np.where(ok, d, np.nan), nan_row])
    h1 = np.vstack([nan_row[:, :1], h])
    h2 = np.vstack([h, nan_row[:, :1]])
    with np.errstate(invalid="ignore"):
        central = (h2 * back + h1 * fwd) / (h1 + h2)  # = numpy.gradient's second-order formula
    slopes = np.where(np.isfinite(central), central, np.where(np.isfinite(back), back, fwd))
    return np.where(np.isfinite(slopes), slopes, 0.0)


def _hermite(
    time: np.ndarray, values: np.ndarray, slopes: np.ndarray, new_time: np.ndarray, gap: float
) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite values at ``new_time`` and whether each point is usable (inside the
    recording, not inside a time gap). A point between a missing sample and its neighbour is
    missing (NaN) in that column."""
    i = np.clip(np.searchsorted(time, new_time, side="right") - 1, 0, len(time) - 2)
    h = (time[i + 1] - time[i])[:, None]
    s = (new_time[:, None] - time[i][:, None]) / h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    out = h00 * values[i] + h10 * h * slopes[i] + h01 * values[i + 1] + h11 * h * slopes[i + 1]
    valid = (h[:, 0] <= gap) & (new_time >= time[0]) & (new_time <= time[-1])
    return out, valid


def _progress(total: int, label: str):
    """A tqdm bar on stderr when it is a terminal (tqdm decides), else nothing."""
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency of the wheel
        return None
    return tqdm(total=total, desc=label, unit="frame", unit_scale=True, leave=False, disable=None)
