"""A model over a whole recording from a lab: markers in, one output row per frame that has
one, and an account of every frame that has none.

This is what the ``ikid ik`` / ``ikid run`` commands do, as a function. Frames go through
a :class:`ikid.Stream` with their timestamps, exactly as they would live: the model's
missing-marker policy applies, a gap in time restarts the window, and a frame the stream
refuses (a marker it cannot fill, a jumping marker) yields no row — it is counted, by
reason, in :attr:`Run.refused`, never written as a guess.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

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

    def flagged(self, bit: str) -> int:
        """Output rows carrying status bit ``bit`` (an ``ikid.FRAME_STATUS`` name)."""
        return int(np.count_nonzero(self.status & _native.FRAME_STATUS[bit]))

    @property
    def clean(self) -> bool:
        """True if every frame has an output and none is flagged: what ``--strict`` asks."""
        lost = sum(n for reason, n in self.refused.items() if reason != "window filling")
        return lost == 0 and not self.status.any()

    def summary(self) -> str:
        parts = [f"{len(self.time)}/{self.n_frames} frames with output"]
        if self.filled.any():
            parts.append(f"{int(self.filled.sum())} with a filled marker")
        if self.flagged("outside_training"):
            parts.append(f"{self.flagged('outside_training')} outside the model's training range (flagged)")
        for reason, n in self.refused.most_common():
            example = self.examples.get(reason)
            explained = any(w in reason for w in _SELF_EXPLAINED) or not example
            parts.append(f"{n} {reason}" if explained else f"{n} {reason} (first: {example})")
        if self.gap_restarts:
            parts.append(f"{self.gap_restarts} window restarts after time gaps")
        if self.resampled_from_hz:
            parts.append(f"resampled {self.resampled_from_hz:g} -> {self.rate_hz:g} Hz")
        return ", ".join(parts)


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


def run_model(
    model: _native.Model,
    frames,
    time,
    *,
    rate_hz: float | None = None,
    resample_to_model: bool = False,
    missing_markers: str | None = None,
    calibration: _native.Calibration | None = None,
    source: str = "frames",
    progress: bool = False,
) -> Run:
    """Run ``model`` over ``frames`` ``(n, frame_len)`` at ``time`` ``(n,)`` seconds; with a
    ``calibration`` (see :func:`ikid.calibrate`), for this subject's marker placement."""
    frames = np.asarray(frames, np.float64)
    time = np.asarray(time, np.float64)
    if frames.ndim != 2 or time.shape != (len(frames),):
        raise _native.InputError(
            f"{source}: expected frames (n, {model.frame_len}) and time (n,), "
            f"got {frames.shape} and {time.shape}"
        )
    if rate_hz is None:
        rate_hz = 1.0 / float(np.median(np.diff(time))) if len(time) > 1 else model.frame_rate_hz
    resampled_from = None
    if check_rate(model, rate_hz, source, resample_to_model):
        time, frames = resample(time, frames, model.frame_rate_hz)
        resampled_from, rate_hz = rate_hz, model.frame_rate_hz
    stream = model.stream(missing_markers=missing_markers, calibration=calibration)
    rows, index, filled, status = [], [], [], []
    implausible = _native.FRAME_STATUS["implausible"]
    refused: Counter = Counter()
    examples: dict[str, str] = {}
    bar = _progress(len(frames), source) if progress else None
    for i, (t, frame) in enumerate(zip(time, frames, strict=True)):
        if bar is not None and i % 1000 == 999:
            bar.update(1000)
        try:
            out = stream.push(frame, time=float(t))
        except _native.InputError as e:
            reason = refusal_reason(e)
            refused[reason] += 1
            examples.setdefault(reason, f"frame {i}: {e.reason or e}")
            continue
        if out is None:
            refused["window filling"] += 1
            continue
        if stream.status & implausible:
            # Nothing no wrist can give is written as a number: the frame is counted instead.
            reason = "implausible outputs (far outside the model's training range), not written"
            refused[reason] += 1
            examples.setdefault(reason, f"frame {i}: {np.array2string(np.asarray(out), precision=3)}")
            continue
        rows.append(out)
        index.append(i)
        filled.append(bool(stream.filled_markers))
        status.append(stream.status)
    if bar is not None:
        bar.close()
    values = np.array(rows, np.float64).reshape(-1, model.n_outputs)
    idx = np.array(index, np.int64)
    return Run(
        time[idx],
        idx,
        values,
        np.array(filled, bool),
        len(frames),
        refused,
        rate_hz,
        resampled_from,
        stream.gap_restarts,
        examples,
        np.array(status, np.uint8),
    )


def _progress(total: int, label: str):
    """A tqdm bar on stderr when it is a terminal (tqdm decides), else nothing."""
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency of the wheel
        return None
    return tqdm(total=total, desc=label, unit="frame", unit_scale=True, leave=False, disable=None)
