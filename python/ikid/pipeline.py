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
   on the one real recording at such a rate (racing, 70 Hz, calibrated; tools/realdata.py's
   scoring): the 1 kHz member 1.71° geodesic RMS with an output on every valid frame, the next
   faster (100 Hz, 100 ms window) 5.70° on 99.9 %; on simulated trials at 71.4 Hz (seeds
   9830-9832, 10 s) the 100 Hz member is better with noise (1.0e-4 vs 1.8e-4 rad² at 1 %), worse
   on clean markers (6.9e-6 vs 1.4e-6) — real markers, fast and clean, decide.
   One stream runs over the model's grid once (:class:`_ModelGrid`: 10 s at 70 Hz is 10,000
   pushes of the 1 kHz member, about 0.3 s; the earlier one stream per phase of the frames on
   the grid made 100 streams of the whole trial, 4–30 s), and a frame's output is the outputs
   of the grid points on either side of it interpolated linearly (within 1 ms at 1 kHz).
   Nothing is written between frames, and a missing frame stays missing: a grid point takes a
   recording frame's markers exactly where it falls on one, the cubic Hermite between two frames
   uses those two (never a missing one's neighbours), and no grid point is made inside a time gap.
   The summary says so, and why: the family has no model at the recording's rate.
   ``--resample`` (``resample_to_model``) keeps the older behaviour: the whole recording resampled,
   outputs on the model's grid.

A model given as a file (or an explicit per-rate name, or a loaded :class:`ikid.Model`) is
that model: at another rate than its card's it is refused unless ``resample_to_model``.

**A gap at the start of a recording** (:func:`fill_leading_gaps`). Live, a marker missing before
the gap filler has learned the wrist from the motion cannot be filled. A file is whole: a frame
of its first :data:`LEADING_FILL_S` that the stream refuses for such a gap is pushed again with
the gap filled from the motion after it (the same filler, run backwards in time), flagged
``filled``.
"""

from __future__ import annotations

import os
import re
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from ikid import _native
from ikid.io.resample import GAP_STEPS, resample_stretches

#: Relative difference between a file's frame rate and the model's that still counts as equal.
RATE_TOLERANCE = 1e-3


def same_rate(a_hz: float, b_hz: float) -> bool:
    """True if two frame rates are equal to :data:`RATE_TOLERANCE` (relative to ``b_hz``)."""
    return abs(a_hz - b_hz) <= RATE_TOLERANCE * b_hz


@dataclass
class Counts:
    """What a run's output rows carried, counted (all a summary needs; kept when the rows
    themselves went to a file block by block)."""

    rows: int = 0
    #: Rows with each ``ikid.FRAME_STATUS`` bit, by name.
    bits: Counter = field(default_factory=Counter)
    #: Rows given while the window filled (early outputs), and those of them flagged
    #: ``per_frame`` and nothing else.
    filling: int = 0
    filling_only_per_frame: int = 0
    #: Rows with any bit set.
    flagged: int = 0

    def add(self, status: np.ndarray, filling: np.ndarray) -> None:
        status = np.asarray(status, np.uint16)
        self.rows += len(status)
        for name, bit in _native.FRAME_STATUS.items():
            n = int(np.count_nonzero(status & bit))
            if n:
                self.bits[name] += n
        self.filling += int(np.count_nonzero(filling))
        self.filling_only_per_frame += int(
            np.count_nonzero(filling & (status == _native.FRAME_STATUS["per_frame"]))
        )
        self.flagged += int(np.count_nonzero(status))


@dataclass
class Run:
    """Outputs for the frames that have one, in input order (with ``on_rows``, see
    :func:`run_blocks`, the rows went to it and these arrays are empty; :attr:`counts` holds
    what the summary needs either way)."""

    time: np.ndarray
    #: Index of each output's frame in the (possibly resampled) input.
    frame: np.ndarray
    values: np.ndarray
    #: True where the stream filled a marker missing in that frame (status bit ``filled``; a
    #: marker rejected and replaced is ``rejected_marker``, labels put right ``swapped``).
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
    status: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint16))
    #: The model that ran (its card's name) and its card's rate.
    model_name: str = ""
    model_rate_hz: float = 0.0
    #: True if the recording was resampled to the model's rate and the outputs taken at the
    #: recording's own frame times (``rate_hz`` is then the recording's).
    at_recording_frames: bool = False
    #: True for each output row given while the stream's window was filling (an early output:
    #: the per-frame solution).
    filling: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    #: The rows' status bits counted (see :class:`Counts`).
    counts: Counts = field(default_factory=Counts)
    #: The rates of the model's family (:func:`family_members`), when it ran as one.
    family_rates_hz: tuple[float, ...] = ()
    #: Each output row's standard deviations ``(n, n_outputs)`` (``Stream.output_sd``), NaN
    #: where the stream gave none (a model whose card has no ``uncertainty``, or the first
    #: frames after the window restarted).
    sd: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    #: Points of the model's grid the stream refused, by reason (a recording resampled to the
    #: model's rate, ``at_recording_frames``): a frame between two of them keeps the output of
    #: the grid point on its other side if it has one (a frame on a refused point is counted in
    #: :attr:`refused`), and the window restarts after them, as after a time gap.
    grid_refused: Counter = field(default_factory=Counter)

    @property
    def n_outputs(self) -> int:
        """Output rows (written, or in :attr:`values`)."""
        return self.counts.rows

    def flagged(self, bit: str) -> int:
        """Output rows carrying status bit ``bit`` (an ``ikid.FRAME_STATUS`` name)."""
        _native.FRAME_STATUS[bit]  # a name that is not a bit is an error, not 0
        return int(self.counts.bits.get(bit, 0))

    @property
    def clean(self) -> bool:
        """True if every frame has an output and none is flagged: what ``--strict`` asks. The
        window's filling is not a flaw: its frames may lack an output, or carry the per-frame
        solution (``per_frame`` and nothing else)."""
        lost = sum(n for reason, n in self.refused.items() if reason != "window filling")
        return lost == 0 and self.counts.flagged - self.counts.filling_only_per_frame == 0

    def summary(self) -> str:
        parts = [f"{self.n_outputs}/{self.n_frames} frames with output"]
        if self.flagged("filled"):
            parts.append(f"{self.flagged('filled')} with a filled marker")
        if self.flagged("rejected_marker"):
            parts.append(
                f"{self.flagged('rejected_marker')} with a marker that jumped, replaced by a fill (flagged)"
            )
        if self.flagged("swapped"):
            parts.append(
                f"{self.flagged('swapped')} with swapped labels, used under their right labels (flagged)"
            )
        if self.flagged("outside_training"):
            parts.append(f"{self.flagged('outside_training')} outside the model's training range (flagged)")
        if self.flagged("per_frame"):
            early = self.counts.filling
            beyond = self.flagged("per_frame") - early
            parts.append(
                f"{self.flagged('per_frame')} per-frame solutions (flagged: {early} while the window filled, "
                f"{beyond} where the window's posture or speed was beyond training)"
            )
        for reason, n in self.refused.most_common():
            example = self.examples.get(reason)
            explained = any(w in reason for w in _SELF_EXPLAINED) or not example
            parts.append(f"{n} {reason}" if explained else f"{n} {reason} (first: {example})")
        if self.grid_refused:
            reasons = "; ".join(f"{n} {reason}" for reason, n in self.grid_refused.most_common())
            n = self.grid_refused.total()
            parts.append(f"{n} points of the model's grid refused ({reasons})")
        if self.gap_restarts:
            # A refused frame is never pushed: the next one comes after a gap in time.
            after = (
                "time gaps or refused grid points"
                if self.grid_refused
                else "time gaps or the frames refused above"
                if any(reason != "window filling" for reason in self.refused)
                else "time gaps"
            )
            parts.append(f"{self.gap_restarts} window restarts after {after}")
        if self.resampled_from_hz:
            parts.append(f"resampled {self.resampled_from_hz:g} -> {self.rate_hz:g} Hz")
        if self.model_name:
            parts.append(self.model_note())
        return ", ".join(parts)

    def model_note(self) -> str:
        """Which model ran, at which rate, on which frames (for the summary line)."""
        head = f"model {self.model_name} ({self.model_rate_hz:g} Hz)"
        if self.at_recording_frames:
            why = (
                f" (its family has no model at {self.rate_hz:g} Hz, only at "
                + ", ".join(f"{r:g}" for r in self.family_rates_hz)
                + " Hz)"
                if self.family_rates_hz
                else ""
            )
            return (
                f"{head}, the {self.rate_hz:g} Hz recording resampled to it, "
                f"outputs at the recording's frames{why}"
            )
        if self.resampled_from_hz:
            return f"{head}, outputs at its rate"
        return f"{head} at the recording's rate"


def refusal_reason(error: _native.InputError) -> str:
    """A short, countable reason for a refused frame, from the core's classification (its
    stable code; never the message, whose numbers differ from frame to frame)."""
    markers = ", ".join(error.markers)
    if error.code == "missing_markers":
        # The core's fixed reason (no numbers in it) for a gap before the filler knows the wrist.
        early = "locate the joint centre" in (error.reason or "")
        why = (
            ": the gap filler had not yet located the wrist's centre from the motion around it; "
            "the Tracker (`ikid track`, `ikid stream --tracker`) carries through such gaps once it has "
            "started"
            if early
            else ""
        )
        return f"missing {markers} (not fillable{why})"
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
        "resampled (it would add latency): record at one of those rates, run the Tracker, which runs at "
        "any rate (ikid stream --tracker, ikid.Tracker), run the recording offline (ikid ik resamples), "
        "or train a model at yours (ikid train, from ikid-training)"
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


#: How much of a recording's start :func:`fill_leading_gaps` fills from the motion after it, s
#: (held from its first gap: at most 10 s at 1 kHz, 1.4 MB): the gap filler needs enough wrist
#: motion to locate the wrist (about ±10° about every axis), which a session's first seconds
#: may not have.
LEADING_FILL_S = 10.0
#: Motion after a leading gap's last frame held for the filler to learn the wrist from, s.
LEARN_AFTER_S = 5.0
#: The longest start :func:`fill_leading_gaps` holds, s (8.6 MB at 1 kHz).
MAX_HOLD_S = 60.0


def fill_leading_gaps(
    blocks: Iterable[tuple[np.ndarray, np.ndarray]], rate_hz: float | None
) -> Iterable[tuple[np.ndarray, np.ndarray, np.ndarray | None]]:
    """``(time, frames, filled)`` for each ``(time, frames)`` block of a recording of marker
    frames (18 values), in order (a block may come in parts). ``filled`` is ``frames`` with the
    missing markers of the recording's start filled from the motion after them —
    :func:`ikid.fill_gaps` run backwards in time —, or ``None`` where a part has nothing filled.
    The start runs from the first gap of the first :data:`LEADING_FILL_S` to
    :data:`LEADING_FILL_S`, or to :data:`LEARN_AFTER_S` after its last gap if that is later
    (never past :data:`MAX_HOLD_S`): the filler needs wrist motion after a gap to fill it. A gap
    it cannot fill (two markers of a segment) stays missing. Where to use them is the caller's:
    :func:`run_blocks` pushes a filled frame only where its stream refuses the frame as it is
    (live, a gap before the filler has learned the wrist from the motion has no output);
    ``ikid track`` only before its tracker starts. Those frames are held in memory (cut by
    content and time, so the result does not depend on how the recording is blocked); a
    recording whose first seconds are whole passes through."""
    it = iter(blocks)
    held: list[tuple[np.ndarray, np.ndarray]] = []
    rest: tuple[np.ndarray, np.ndarray] | None = None
    t0: float | None = None
    last_gap = -np.inf
    for time, frames in it:
        time, frames = np.asarray(time, np.float64), np.asarray(frames, np.float64)
        if len(time) == 0:
            continue
        t0 = float(time[0]) if t0 is None else t0
        start = 0
        if not held:
            first = int(np.searchsorted(time - t0, LEADING_FILL_S, side="left"))
            gaps = np.flatnonzero(np.isnan(frames[:first]).any(axis=1))
            start = int(gaps[0]) if len(gaps) else first
            if start:
                yield time[:start], frames[:start], None
            if not len(gaps):
                if first < len(time):
                    rest = (time[first:], frames[first:])
                    break
                continue
        gap = np.isnan(frames).any(axis=1)
        end = start
        while end < len(time):
            limit = min(max(t0 + LEADING_FILL_S, last_gap + LEARN_AFTER_S), t0 + MAX_HOLD_S)
            if time[end] >= limit:
                break
            if gap[end]:
                last_gap = float(time[end])
            end += 1
        held.append((time[start:end], frames[start:end]))
        if end < len(time):
            rest = (time[end:], frames[end:])
            break
    if held:
        frames = np.concatenate([f for _, f in held])
        filled: np.ndarray | None = None
        if frames.shape[1] == 18 and rate_hz:
            backward = _native.fill_gaps(frames[::-1].copy(), unfillable="keep", rate_hz=float(rate_hz))[0][
                ::-1
            ]
            take = _missing(frames) & ~_missing(backward)
            if take.any():
                filled = frames.copy()
                cells = np.repeat(take, 3, axis=1)
                filled[cells] = backward[cells].astype(np.float64)
        k = 0
        for time, block in held:
            part = None if filled is None else filled[k : k + len(block)]
            yield time, block, None if part is None or np.array_equal(part, block, equal_nan=True) else part
            k += len(block)
    if rest is not None and len(rest[0]):
        yield rest[0], rest[1], None
    for time, frames in it:
        yield time, frames, None


def _missing(frames: np.ndarray) -> np.ndarray:
    """Per frame and marker of ``(n, 18)`` frames: is it missing."""
    return np.isnan(frames).reshape(len(frames), 6, 3).any(axis=2)


#: Frames per block when :func:`run_model` runs over arrays (the same code as a file read in
#: blocks, :func:`run_blocks`).
BLOCK_FRAMES = 65536

#: Called with each block of output rows, in order: ``(frame, time, values, status, sd)``
#: (frame indices, seconds, ``(k, n_outputs)``, ``ikid.FRAME_STATUS`` bits, standard
#: deviations ``(k, n_outputs)``, NaN where the stream gave none: see :attr:`Run.sd`).
RowSink = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], None]


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
    file without a checksum is loaded (with a warning; see :func:`ikid.load`).

    The arrays go through :func:`run_blocks` a block at a time, as a file of any length does."""
    frames = np.asarray(frames, np.float64)
    time = np.asarray(time, np.float64)
    if frames.ndim != 2 or time.shape != (len(frames),):
        n_cols = model.frame_len if isinstance(model, _native.Model) else "frame_len"
        raise _native.InputError(
            f"{source}: expected frames (n, {n_cols}) and time (n,), got {frames.shape} and {time.shape}"
        )
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise _native.InputError(
            f"{source}: time: row {bad[0]} is {time[bad[0]]} ({bad.size} rows not finite): every frame needs "
            "its time in seconds"
        )
    if rate_hz is None and len(time) > 1:
        rate_hz = 1.0 / float(np.median(np.diff(time)))
    blocks = (
        (time[k : k + BLOCK_FRAMES], frames[k : k + BLOCK_FRAMES]) for k in range(0, len(time), BLOCK_FRAMES)
    )
    return run_blocks(
        model,
        blocks,
        rate_hz=rate_hz,
        n_frames=len(time),
        resample_to_model=resample_to_model,
        missing_markers=missing_markers,
        calibration=calibration,
        source=source,
        progress=progress,
        early_outputs=early_outputs,
        allow_unchecked=allow_unchecked,
    )


def run_blocks(
    model: _native.Model | str | os.PathLike[str],
    blocks: Iterable[tuple[np.ndarray, np.ndarray]],
    *,
    rate_hz: float | None,
    n_frames: int | None = None,
    resample_to_model: bool = False,
    missing_markers: str | None = None,
    calibration: _native.Calibration | None = None,
    source: str = "frames",
    progress: bool = False,
    early_outputs: bool | None = None,
    allow_unchecked: bool = False,
    on_rows: RowSink | None = None,
) -> Run:
    """:func:`run_model` over a recording given as blocks of ``(time, frames)`` in order (a file
    read in blocks, :func:`ikid.io.open_markers`), at ``rate_hz`` (the file's; ``None`` for a
    single frame). With ``on_rows`` each block's output rows go to it as they are made and the
    :class:`Run` keeps only their counts: memory independent of the recording's length, with
    ``resample_to_model`` too (:func:`ikid.io.resample_stretches`)."""
    model_arg = model
    model, how = pick_model(
        model, rate_hz, resample_to_model=resample_to_model, source=source, allow_unchecked=allow_unchecked
    )
    if rate_hz is None:
        rate_hz = model.frame_rate_hz
    if early_outputs is None:
        early_outputs = model.card.get("output_offset") is not None
    stream = model.stream(
        missing_markers=missing_markers, calibration=calibration, early_outputs=early_outputs
    )
    tally = _Tally(model.n_outputs, on_rows)
    # A file is whole: a frame refused for a gap at its start is pushed again with the gap
    # filled from the motion after it (fill_leading_gaps), and flagged filled. Not on the
    # --resample path (its frames are the model's grid's).
    fills = (missing_markers or model.missing_markers) == "fill" and model.frame_kind == "markers"
    with_fills = (
        fill_leading_gaps(blocks, rate_hz)
        if fills and rate_hz and how != "resample"
        else ((t, f, None) for t, f in blocks)
    )
    bar = _progress(n_frames, source) if progress else None
    resampled_from = None
    file_gaps = 0
    try:
        if how == "resample":
            # A block at a time, each stretch between time gaps alone: no frame is made in a gap.
            blocks = resample_stretches(blocks, rate_hz, model.frame_rate_hz)
            with_fills = ((t, f, None) for t, f in blocks)
            resampled_from, rate_hz = rate_hz, model.frame_rate_hz
        if how == "at_frames":
            grid = _ModelGrid(model, stream, rate_hz, tally)
            for time, frames, filled in with_fills:
                grid.feed(np.asarray(time, np.float64), np.asarray(frames, np.float64), filled)
                if bar is not None:
                    bar.update(len(time))
            grid.finish()
            file_gaps = grid.file_gaps
        else:
            last_t = None
            for time, frames, filled in with_fills:
                time = np.asarray(time, np.float64)
                frames = np.asarray(frames, np.float64)
                for i, (t, frame) in enumerate(zip(time, frames, strict=True)):
                    # A file's stamps are its own, never a live clock's glitch: a step longer
                    # than a live stream takes as frames lost (two takes joined, a pause in a
                    # recording) is a gap, and the window starts again after it.
                    if last_t is not None and t - last_t > _native.MAX_TIME_GAP_S:
                        stream.reset()
                        file_gaps += 1
                    last_t = t
                    got = _push(stream, t, frame, model)
                    if filled is not None:
                        got = _retry_filled(stream, t, got, filled[i], model)
                    tally.add(t, got)
                tally.flush()
                if bar is not None:
                    bar.update(len(time))
    finally:
        if bar is not None:
            bar.close()
    family = (
        family_members(model_arg) if how == "at_frames" and not isinstance(model_arg, _native.Model) else []
    )
    return tally.run(
        model,
        rate_hz,
        resampled_from,
        stream.gap_restarts + file_gaps,
        at_frames=how == "at_frames",
        family_rates=tuple(m.frame_rate_hz for m in family),
    )


class _Tally:
    """Outcomes per frame, in frame order, into a :class:`Run`: rows kept, or handed to a sink
    a block at a time (:meth:`flush`)."""

    def __init__(self, n_outputs: int, on_rows: RowSink | None) -> None:
        self.n_outputs = n_outputs
        self.on_rows = on_rows
        self.n = 0
        self.kept: list[tuple[np.ndarray, ...]] = []
        self._block()
        self.counts = Counts()
        self.refused: Counter = Counter()
        self.examples: dict[str, str] = {}
        #: Grid points refused by the stream (:class:`_ModelGrid`), by reason.
        self.grid_refused: Counter = Counter()

    def _block(self) -> None:
        self.rows: list = []
        self.index: list[int] = []
        self.time: list[float] = []
        self.status: list[int] = []
        self.filling: list[bool] = []
        self.sd: list = []

    def add(self, t: float, outcome: tuple) -> None:
        """The next frame's outcome (``_push``'s)."""
        i = self.n
        self.n += 1
        if outcome[0] == "out":
            _, values, _filled, status, filling, sd = outcome
            self.rows.append(values)
            self.sd.append(sd)
            self.index.append(i)
            self.time.append(t)
            self.status.append(status)
            self.filling.append(filling)
        else:
            _, reason, example = outcome
            self.refused[reason] += 1
            if example is not None:
                self.examples.setdefault(reason, f"frame {i}: {example}")

    def flush(self) -> None:
        """The rows added since the last flush: counted, and kept or handed to the sink."""
        values = np.array(self.rows, np.float64).reshape(-1, self.n_outputs)
        status = np.array(self.status, np.uint16)
        filling = np.array(self.filling, bool)
        index = np.array(self.index, np.int64)
        time = np.array(self.time, np.float64)
        sd = np.array(self.sd, np.float64).reshape(-1, self.n_outputs)
        self.counts.add(status, filling)
        if self.on_rows is not None:
            if len(index):
                self.on_rows(index, time, values, status, sd)
        else:
            self.kept.append((index, time, values, status, filling, sd))
        self._block()

    def run(self, model, rate_hz, resampled_from, gap_restarts, at_frames=False, family_rates=()) -> Run:
        self.flush()
        cols = list(zip(*self.kept, strict=True)) if self.kept else [[] for _ in range(6)]

        def joined(parts, dtype, shape=(0,)):
            return np.concatenate(parts).astype(dtype) if len(parts) else np.zeros(shape, dtype)

        idx = joined(cols[0], np.int64)
        status = joined(cols[3], np.uint16)
        return Run(
            joined(cols[1], np.float64),
            idx,
            joined(cols[2], np.float64, (0, model.n_outputs)).reshape(-1, model.n_outputs),
            (status & _native.FRAME_STATUS["filled"]) != 0,
            self.n,
            self.refused,
            rate_hz,
            resampled_from,
            gap_restarts,
            self.examples,
            status,
            model.name,
            model.frame_rate_hz,
            at_frames,
            joined(cols[4], bool),
            self.counts,
            family_rates,
            joined(cols[5], np.float64, (0, model.n_outputs)).reshape(-1, model.n_outputs),
            self.grid_refused,
        )


#: Why a frame whose hand reads turned over on the forearm (status bit ``turned_over``) has
#: no output: the tracker's summary says the same.
TURNED_OVER_REASON = (
    "the hand reads turned over on the forearm, further from neutral than a wrist turns (two markers of "
    "a segment under each other's labels throughout, e.g. MC2/MC5 or RSP/USP, or a calibration made "
    "with another labelling, or from landmarks measured with the markers placed otherwise, in another "
    "session): not written; check the labels of the hand's and the forearm's markers, and that the "
    "calibration's static trial is this session's"
)
#: The same for a model fed angles (a joint state): the angles themselves turn it over.
TURNED_OVER_ANGLES_REASON = (
    "the input angles turn the hand further from neutral on the forearm than a wrist turns (over "
    "130 degrees): not written; check the angles' convention (units, the zero posture, the order "
    + ", ".join(c[0] for c in _native.COORDINATES)
    + ")"
)


def _push(stream: _native.Stream, t: float, frame: np.ndarray, model: _native.Model) -> tuple:
    """One frame through ``stream``: ``("out", values, filled, status, filling, sd)``
    (``filling``: an early output, the window not yet full; ``sd``: the outputs' standard
    deviations, NaN without) or ``("none", reason, example message or None)``."""
    try:
        out = stream.push(frame, time=float(t))
    except _native.InputError as e:
        return ("none", refusal_reason(e), e.reason or str(e))
    if out is None:
        return ("none", "window filling", None)
    if stream.status & _native.FRAME_STATUS["implausible"]:
        # Nothing no wrist can give is written as a number: the frame is counted instead.
        reason = "implausible outputs (far outside the model's training range), not written"
        if stream.status & _native.FRAME_STATUS["turned_over"]:
            reason = TURNED_OVER_REASON if model.frame_kind == "markers" else TURNED_OVER_ANGLES_REASON
        return ("none", reason, np.array2string(np.asarray(out), precision=3))
    status = stream.status
    filled = bool(status & _native.FRAME_STATUS["filled"])
    sd = stream.output_sd
    sd = np.full(len(out), np.nan) if sd is None else sd
    return ("out", out, filled, status, stream.filled < model.window, sd)


def _retry_filled(stream: _native.Stream, t: float, got: tuple, filled: np.ndarray, model) -> tuple:
    """``got``; or, where the stream refused its frame for a missing marker that
    :func:`fill_leading_gaps` filled (``filled``: the frame with it), the outcome of the filled
    frame, flagged ``filled`` (a refused push leaves the stream as it was)."""
    if got[0] != "none" or not got[1].startswith("missing ") or np.isnan(filled).any():
        return got
    again = _push(stream, t, filled, model)
    if again[0] != "out":
        return got
    _, values, _, status, filling, sd = again
    return ("out", values, True, status | _native.FRAME_STATUS["filled"], filling, sd)


def _combine(a: tuple | None, b: tuple | None, w: float) -> tuple:
    """A recording frame's outcome from those of the model's grid points before (``a``) and
    after (``b``) it, ``w`` of the way to ``b``: the outputs (and their standard deviations: NaN
    if either has none) interpolated linearly and the flags of both when both have one, else
    the one that has."""
    if a is not None and a[0] == "out" and b is not None and b[0] == "out":
        values = (1.0 - w) * np.asarray(a[1], np.float64) + w * np.asarray(b[1], np.float64)
        sd = (1.0 - w) * a[5] + w * b[5]
        return ("out", values, a[2] or b[2], a[3] | b[3], a[4] or b[4], sd)
    for got in (a, b):
        if got is not None and got[0] == "out":
            return got
    return a or b or ("none", "not run", None)


class _ModelGrid:
    """A model at its own rate over a recording at ``rate_hz``, fed in blocks, an output at each
    recording frame's time. One stream runs over the model's grid (``t0 + k / model rate``,
    ``t0`` the first frame's time): each grid point carries the markers the cubic Hermite
    between the two recording frames around it gives (slopes from their present neighbours, as
    :func:`_local_slopes`; a point between two frames is missing in a marker's columns where
    either frame misses it), none is made inside a time gap (> 1.5 recording periods: the stream
    restarts after it, as live), and a frame's output is the outputs of the grid points before
    and after it interpolated linearly (within one model period; exactly the grid point's
    output where the frame falls on one). Three recording frames are held between blocks (the
    slopes at an interval's ends need the frames beyond them), so memory is bounded."""

    #: Grid positions this close to an integer count as on the grid point (float rounding).
    EPS = 1e-6

    def __init__(self, model: _native.Model, stream: _native.Stream, rate_hz: float, tally: _Tally) -> None:
        self.model, self.stream, self.tally = model, stream, tally
        # Swapped labels are found at the recording's frames, before the grid's interpolation
        # smears a swap into a motion (a "fill" stream over marker frames only).
        self.labels = (
            _native.LabelCheck(rate_hz)
            if stream.missing_markers == "fill" and model.frame_kind == "markers" and model.frame_len == 18
            else None
        )
        #: Global indices of frames whose labels were put right (their rows flagged swapped).
        self.swapped: set[int] = set()
        self.period = 1.0 / model.frame_rate_hz
        self.gap = GAP_STEPS / rate_hz
        self.t0: float | None = None
        self.time = np.empty(0)
        self.values = np.empty((0, model.frame_len))
        #: ``values`` with a file's leading gaps filled (:func:`fill_leading_gaps`), once any are.
        self.filled: np.ndarray | None = None
        #: Global index of ``self.time[0]``, and the first interval not yet run (global index
        #: of its first frame).
        self.base = 0
        self.next_interval = 0
        #: Outcomes of the grid points that recording frames wait for.
        self.outcomes: dict[int, tuple] = {}
        #: The first frame whose outcome is not yet given.
        self.next_frame = 0
        self.n_seen = 0
        #: Time of the end of the last interval run: grid points before it have run.
        self.ran_until = -np.inf
        #: The last grid point pushed, and the stream's restarts after a file's long gaps.
        self.last_pushed: float | None = None
        self.file_gaps = 0

    def feed(self, time: np.ndarray, values: np.ndarray, filled: np.ndarray | None = None) -> None:
        """The next recording frames; ``filled``: the same with leading gaps filled (a grid point
        refused for a missing marker is pushed again from them, flagged filled), or ``None``."""
        if len(time) == 0:
            return
        if not np.all(np.isfinite(time)) or np.any(np.diff(np.concatenate([self.time[-1:], time])) <= 0):
            raise _native.InputError("time must be finite and strictly increasing to resample")
        if self.t0 is None:
            self.t0 = float(time[0])
        if self.labels is not None:
            values = self._put_right(values)
        if filled is not None or self.filled is not None:
            if self.filled is None:
                self.filled = self.values.copy()
            add = values if filled is None else np.where(np.isnan(values) & ~np.isnan(filled), filled, values)
            self.filled = np.concatenate([self.filled, add])
        self.time = np.concatenate([self.time, time])
        self.values = np.concatenate([self.values, values])
        self.n_seen += len(time)
        # Intervals whose two ends have their neighbours on both sides in hand.
        self._run_intervals(last=self.base + len(self.time) - 3)

    def _put_right(self, values: np.ndarray) -> np.ndarray:
        """``values`` with each marker under the label the gap filler found it belongs to."""
        assert self.labels is not None
        labels = self.labels.labels(values)
        moved = np.flatnonzero((labels != np.arange(6)).any(axis=1))
        if len(moved) == 0:
            return values
        values = values.copy()
        for k in moved:
            row = values[k].reshape(6, 3).copy()
            values[k] = np.where(labels[k][:, None] >= 0, row[labels[k]], np.nan).reshape(-1)
            self.swapped.add(self.n_seen + int(k))
        return values

    def finish(self) -> None:
        if self.n_seen < 2:
            raise _native.InputError(f"resampling needs at least 2 frames, got {self.n_seen}")
        self._run_intervals(last=self.base + len(self.time) - 2, final=True)
        self._give_frames(upto=self.n_seen, final=True)

    def _run_intervals(self, last: int, final: bool = False) -> None:
        """Runs the grid points of the intervals ``next_interval .. last`` (global first
        frames), then drops the frames no later interval needs."""
        if last < self.next_interval:
            return
        time, values, filled = self.time, self.values, self.filled
        slopes = _local_slopes(time, values, self.gap)
        filled_slopes = None if filled is None else _local_slopes(time, filled, self.gap)
        assert self.t0 is not None
        for j in range(self.next_interval, last + 1):
            m = j - self.base
            t_a, t_b = time[m], time[m + 1]
            if t_b - t_a <= self.gap:
                k_first = int(np.ceil((t_a - self.t0) / self.period - self.EPS))
                k_end = int(np.ceil((t_b - self.t0) / self.period - self.EPS))  # exclusive
                if final and j == last and abs((t_b - self.t0) / self.period - (k_end)) < self.EPS:
                    k_end += 1  # the last frame on a grid point: that point too
                if k_end > k_first:
                    grid_t = self.t0 + np.arange(k_first, k_end) * self.period
                    pts, _ = _hermite(time[m : m + 2], values[m : m + 2], slopes[m : m + 2], grid_t, np.inf)
                    # A grid point on a frame carries the frame's own markers, exactly.
                    on_a = np.abs(grid_t - t_a) <= self.EPS * self.period
                    pts[on_a] = values[m]
                    on_b = np.abs(grid_t - t_b) <= self.EPS * self.period
                    pts[on_b] = values[m + 1]
                    pts_filled = None
                    if filled is not None and filled_slopes is not None:
                        pts_filled, _ = _hermite(
                            time[m : m + 2], filled[m : m + 2], filled_slopes[m : m + 2], grid_t, np.inf
                        )
                        pts_filled[on_a], pts_filled[on_b] = filled[m], filled[m + 1]
                    for i, (k, g, p) in enumerate(zip(range(k_first, k_end), grid_t, pts, strict=True)):
                        again = None if pts_filled is None else pts_filled[i]
                        self.outcomes[k] = self._push_point(g, p, again)
            else:
                # A gap after this frame: the grid point on it (if it falls on one) is its own
                # output, as the last frame of a file's is; the points after it are in the gap.
                pos = (t_a - self.t0) / self.period
                k = int(round(pos))
                if abs(pos - k) < self.EPS and k not in self.outcomes:
                    again = None if filled is None else filled[m]
                    self.outcomes[k] = self._push_point(float(self.t0 + k * self.period), values[m], again)
            self.next_interval = j + 1
            self.ran_until = float(t_b)
            self._give_frames(upto=j + 1)
        # Keep the frame before the next interval (its slope's neighbour) and every frame
        # still waiting for its outcome.
        drop = min(self.next_interval - 1, self.next_frame) - self.base
        if drop > 0:
            self.time, self.values = time[drop:], values[drop:]
            if filled is not None:
                self.filled = filled[drop:]
                if np.array_equal(self.filled, self.values, equal_nan=True):
                    self.filled = None  # the filled frames are behind: no second pass needed
            self.base += drop

    def _push_point(self, g: float, point: np.ndarray, filled: np.ndarray | None) -> tuple:
        """One grid point at time ``g`` through the stream (``filled``: the point from the
        filled frames, pushed again where the stream refused it for a missing marker)."""
        # A file's gap longer than a live stream's frames lost restarts the window (as
        # run_model's frames do), not a clock glitch to refuse.
        if self.last_pushed is not None and g - self.last_pushed > _native.MAX_TIME_GAP_S:
            self.stream.reset()
            self.file_gaps += 1
        self.last_pushed = float(g)
        got = _push(self.stream, g, point, self.model)
        if filled is not None:
            got = _retry_filled(self.stream, g, got, filled, self.model)
        if got[0] == "none" and got[1] != "window filling":
            self.tally.grid_refused[got[1]] += 1
        return got

    def _give_frames(self, upto: int, final: bool = False) -> None:
        """Gives the outcomes of frames ``next_frame .. upto - 1`` (global), whose grid points
        have all run; forgets the grid points no later frame needs."""
        assert self.t0 is not None
        while self.next_frame < upto:
            j = self.next_frame
            t = float(self.time[j - self.base])
            pos = (t - self.t0) / self.period
            k0 = int(np.floor(pos + self.EPS))
            w = max(pos - k0, 0.0)
            if w <= self.EPS:
                got = self.outcomes.get(k0)
            elif not final and self.t0 + (k0 + 1) * self.period >= self.ran_until:
                break  # its grid point after it is in an interval not run yet
            else:
                got = _combine(self.outcomes.get(k0), self.outcomes.get(k0 + 1), w)
            got = got or ("none", "not run", None)
            if j in self.swapped:
                self.swapped.discard(j)
                if got[0] == "out":
                    got = (*got[:3], got[3] | _native.FRAME_STATUS["swapped"], *got[4:])
            self.tally.add(t, got)
            self.next_frame += 1
            for k in [k for k in self.outcomes if k < k0]:
                del self.outcomes[k]
        self.tally.flush()


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


def _progress(total: int | None, label: str):
    """A tqdm bar on stderr when it is a terminal (tqdm decides), else nothing."""
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency of the wheel
        return None
    return tqdm(total=total, desc=label, unit="frame", unit_scale=True, leave=False, disable=None)


def _run_at_recording_frames(
    model: _native.Model, frames: np.ndarray, time: np.ndarray, rate_hz: float, kw: dict, bar=None
) -> Run:
    """``model`` at its own rate over a recording at ``rate_hz`` given whole, outputs at the
    recording's frames (:class:`_ModelGrid`; what :func:`run_model` does for a family with no
    member at the rate). ``kw``: the stream's options."""
    stream = model.stream(**kw)
    tally = _Tally(model.n_outputs, None)
    grid = _ModelGrid(model, stream, rate_hz, tally)
    grid.feed(np.asarray(time, np.float64), np.asarray(frames, np.float64))
    grid.finish()
    return tally.run(model, rate_hz, None, stream.gap_restarts + grid.file_gaps, at_frames=True)
