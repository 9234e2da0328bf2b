"""What every command follows: where -o puts outputs (never over an input), how a model option is
loaded and checked against the command's task, how errors name their file."""

from __future__ import annotations

import os
import stat
import sys
import warnings
from pathlib import Path

import numpy as np

import ikid
from ikid import _native
from ikid.cli.options import UNCHECKED_FLAG


def _is_folder(output: str) -> bool:
    """``-o`` names a folder when it ends with a path separator or is an existing directory:
    outputs then go inside it, named after their input."""
    return output.endswith(("/", os.sep)) or Path(output).is_dir()


def _stem(output: str, name: str, suffixes: tuple[str, ...] = (".mot", ".sto"), create: bool = True) -> Path:
    """The output stem for ``-o OUTPUT``: ``OUTPUT/name`` when it names a folder, else
    ``OUTPUT`` without one of ``suffixes``; the folder is created if need be (unless not
    ``create``: a command names its outputs before it has checked anything)."""
    out = Path(output)
    if _is_folder(output):
        stem = out / name
    else:
        stem = out.with_suffix("") if out.suffix.lower() in suffixes else out
    if create:
        stem.parent.mkdir(parents=True, exist_ok=True)
    return stem


def _named(stem: Path, ext: str) -> Path:
    """``stem`` + ``ext``, even if the stem holds a dot (``trial.v2``)."""
    return stem.with_name(stem.name + ext)


def _file_id(file) -> tuple[int, int] | None:
    """(device, inode) of a path (links resolved) or of an open descriptor that is a regular
    file; None for what does not exist or is not a file (a terminal, a pipe)."""
    try:
        st = os.fstat(file) if isinstance(file, int) else os.stat(file)
    except (OSError, ValueError):
        return None
    return (st.st_dev, st.st_ino) if stat.S_ISREG(st.st_mode) else None


def _stdout_fd() -> int | None:
    """Standard output's descriptor, or None when it has none (replaced by a test harness)."""
    try:
        return sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return None


def _refuse_over_inputs(outputs: list, inputs: list, given: str | None = None, option: str = "-o") -> None:
    """The one check every writing command makes before it reads or writes anything: no
    output may be one of its inputs (the same file after resolving links, hard or symbolic,
    by device and inode), or ikid would replace what it read with what it computed (``ikid id
    t.mot -o t.mot``). Raises :class:`ikid.ArgumentError` (exit 2) naming both; nothing is
    written. ``outputs`` and ``inputs`` are paths (``None`` skipped) or descriptors (standard
    output); ``option`` and its value ``given`` are what the outputs were named by."""
    seen: dict[tuple[int, int], str | os.PathLike[str] | int] = {}
    for inp in inputs:
        if inp is not None and (key := _file_id(inp)) is not None:
            seen.setdefault(key, inp)
    for out in outputs:
        if out is None or (key := _file_id(out)) is None or key not in seen:
            continue
        inp = seen[key]
        if isinstance(inp, int):
            what = "standard output is the input, standard input (the same file)"
            fix = "print to another file (or none)"
        elif isinstance(out, int):
            what = f"standard output is the input {inp}"
            fix = "print to another file (or none)"
        else:
            same = "" if str(out) == str(inp) else " (the same file)"
            named = f"{option} {given}" if given is not None else option
            what = (
                f"{named} is the input {inp}{same}"
                if given is not None and str(out) == str(given)
                else f"{named}: the output {out} is the input {inp}{same}"
            )
            fix = f"give {option} another file"
        raise ikid.ArgumentError(f"{what}; ikid never writes over an input: {fix}")


def _model_file(name: str | None) -> str | None:
    """A model option's value when it names a file (not a shipped model's name)."""
    return None if name is None or ikid.is_model_name(name) else name


#: What a model of each task gives, the frames it reads and the unit of its outputs.
TASKS = {
    "ik": ("markers -> angles", "markers", "rad"),
    "chain": ("markers -> torques", "markers", "N*m"),
    "id": ("joint states -> torques", "joint_state", "N*m"),
    "refine": ("the Kalman tracker's refiner", "tracker_state", None),
}


def _model_for(
    name: str,
    use: str,
    tasks: tuple[str, ...],
    rate_hz: float | None = None,
    allow_unchecked: bool = False,
) -> ikid.Model:
    """``ikid.load(name, rate_hz=rate_hz, allow_unchecked=allow_unchecked)`` for ``use`` (e.g.
    ``"ikid ik --model"``; with a rate, the family's member at it), refused with an
    :class:`ikid.ArgumentError` naming the model, its task and what ``use`` needs unless its
    card's task is one of ``tasks`` and its frames and output units are that task's."""
    model = ikid.load(name, rate_hz=rate_hz, allow_unchecked=allow_unchecked)
    need = " or ".join(f"{t!r} ({TASKS[t][0]})" for t in tasks)
    if model.task not in tasks:
        gives = TASKS.get(model.task, ("an unknown task",))[0]
        raise ikid.ArgumentError(
            f"{use} {name}: model {model.name!r} has task {model.task!r} ({gives}); "
            f"{use} needs a model of task {need}"
        )
    _, frames, unit = TASKS[model.task]
    if model.frame_kind != frames:
        raise ikid.ArgumentError(
            f"{use} {name}: model {model.name!r} (task {model.task!r}) reads {model.frame_kind} frames; "
            f"a {model.task!r} model reads {frames} frames"
        )
    if unit is not None and (model.n_outputs != 3 or set(model.output_units) != {unit}):
        raise ikid.ArgumentError(
            f"{use} {name}: model {model.name!r} gives {model.n_outputs} outputs in "
            f"{', '.join(sorted(set(model.output_units)))}; {use} writes the 3 wrist coordinates in {unit}"
        )
    return model


def _check_uncertainty(name: str, model: ikid.Model, use: str) -> None:
    """Refuses ``--sd`` for a model (or a member of its family) whose card does not say how
    to compute its outputs' standard deviations (no ``uncertainty``)."""
    from ikid.pipeline import family_members

    for m in family_members(name) or [model]:
        if m.card.get("uncertainty") is None:
            raise ikid.ArgumentError(
                f"{use} {name}: model {m.name!r} has no uncertainty in its card, so it gives no standard "
                "deviations; fit them with python -m studies.net_sigma, or leave out --sd"
            )


def _inputs(paths: list[str]) -> list[Path]:
    """Marker files named, or found (by suffix) in named folders. An entry of a folder named
    like a marker file but not one (a folder ``x.trc/``, a pipe) is kept: it fails as that
    file, named in the summary, instead of vanishing from the count."""
    from ikid.io import MARKER_READERS

    found: list[Path] = []
    unsearched: list[str] = []  # subfolders holding marker files: named, never silently passed by
    for p in map(Path, paths):
        if p.is_dir():
            found += sorted(f for f in p.iterdir() if f.suffix.lower() in MARKER_READERS)
            unsearched += sorted(
                str(d)
                for d in p.iterdir()
                if d.is_dir() and any(f.suffix.lower() in MARKER_READERS for f in d.iterdir())
            )
        elif os.path.lexists(p):
            found.append(p)
        else:
            raise ikid.NotFoundError(f"{p}: no such file or folder")
    shown = ", ".join(unsearched[:3]) + (" ..." if len(unsearched) > 3 else "")
    inside = f"; subfolders are not searched ({shown} hold marker files: name them too)" if unsearched else ""
    if not found:
        raise ikid.ArgumentError(
            f"no marker files ({', '.join(MARKER_READERS)}) in {', '.join(paths)}{inside}"
        )
    if inside:
        warnings.warn(f"{len(found)} marker files in {', '.join(paths)}{inside}", UserWarning, stacklevel=2)
    return found


def _message(error: BaseException) -> str:
    """The error's message as the command line says it: a file the system could not open named
    first, and a model file without a checksum names this command's opt-in
    (:data:`UNCHECKED_FLAG`), not the Python API's."""
    message = str(error)
    if isinstance(error, OSError) and error.filename is not None and error.strerror:
        # Python's "[Errno 2] No such file or directory: 'x.toml'" read as ikid's messages are:
        # the file first, then what is wrong with it.
        reason = error.strerror[:1].lower() + error.strerror[1:]
        also = f" (and {error.filename2})" if error.filename2 is not None else ""
        return f"{error.filename}{also}: {reason}"
    if getattr(error, "code", None) == "missing_checksum":
        message = message.replace(
            ikid.UNCHECKED_OPT_IN, f"or give {UNCHECKED_FLAG} to load it anyway (with a warning)"
        )
    return message


def _naming(path: str, error: BaseException) -> str:
    """The error's message, starting with the input file it concerns (a read or write error
    names its own file already)."""
    message = _message(error)
    if path in message or isinstance(error, OSError):
        return message
    return f"{path}: {message}"


def _subject_calibration(
    frames: np.ndarray,
    calibration: str | None,
    mapping,
    source: str,
    *,
    whole: bool = True,
    labelled: bool = True,
):
    """The calibration a run of ``frames`` (read with ``mapping``) uses: the file given,
    checked against the marker map it was measured with; or, without one, the body model's
    placement, after checking that it can read these markers at all (units, then placement:
    an uncalibrated real recording reads 50-170° off). Errors name ``source``. ``whole``: the
    frames are a whole trial (a live stream's first frames say nothing of whether the wrist
    moves, so they are not asked). ``labelled``: the frames were read by their labels, so a
    calibration measured with another labelling is refused (frames on stdin have none)."""
    from ikid.calibration import (
        check_calibration_map,
        check_marker_distances,
        uncalibrated,
    )
    from ikid.io import MarkerMap
    from ikid.io.mapping import MarkerMapWarning

    try:
        ikid.check_marker_units(frames)
        # A segment whose markers do not keep their distances names a marker of another one
        # (a "hand" with an elbow marker): said before any angle is written.
        checked = mapping or MarkerMap.identity()
        flat = checked.flat_segments(frames)
        swapped = checked.swapped_across_segments(frames)
        if flat or swapped:
            raise ikid.InputError("; ".join(flat + ([swapped] if swapped else [])))
        held = checked.hand_held_to_forearm(frames) if whole else None
        for problem in checked.stretched_segments(frames) + ([held] if held else []):
            warnings.warn(f"{source}: {problem}", MarkerMapWarning, stacklevel=2)
        if calibration:
            if labelled:
                check_calibration_map(calibration, mapping)
            check_marker_distances(calibration, frames, source, whole, mapping)
            return ikid.load_calibration(calibration)
        # Uncalibrated, the body model's placement; a left arm (the map's side) mirrored into
        # a right one first, as its calibration would.
        try:
            ikid.check_default_placement(frames, side=checked.side)
        except ikid.InputError as e:
            if not checked.one_hand_marker:
                raise
            # A one-marker hand's frames are built from its markers each frame, at the body
            # model's placement: a calibration changes nothing of what they read, a label does.
            reading = str(e.reason or e).split(": the markers do not sit")[0].split(": they do not sit")[0]
            raise ikid.InputError(
                f"{reading}: with one hand marker both segments' frames are built from the markers "
                f"themselves (a calibration does not change what they read), so a marker is not where "
                f"its label says: {checked.label_of(_native.HAND_POINT[0])!r} ({_native.HAND_POINT[0]}) "
                "on the back of the hand over the third metacarpal (Plug-in Gait's FIN), "
                f"{checked.label_of('RSP')!r} and {checked.label_of('USP')!r} (RSP, USP) the wrist bar's "
                f"thumb and little-finger sides, {checked.label_of('FAP')!r} (FAP) the lateral epicondyle"
            ) from None
    except ikid.IkidError as e:
        raise type(e)(_naming(source, e)) from None
    return uncalibrated(checked.side)


def _cause(file: str, error: str) -> str:
    """An error message without the file name it starts with (the summary names the file)."""
    if error.startswith(file + ":"):
        rest = error[len(file) + 1 :].lstrip()
        head, sep, tail = rest.partition(": ")
        return f"line {head}: {tail}" if sep and head.isdigit() else rest
    return error


#: How to get the training pipeline, a distribution of its own (``training/`` of a checkout).
TRAINING_HINT = "pip install ./training (from an ikid source checkout; it brings torch)"


def _training_package(what: str):
    """The ``ikid_training`` package (imported only here, on demand), or an error telling how
    to install it (exit 2)."""
    try:
        import ikid_training
    except ImportError as e:
        raise ikid.InputError(
            f"{what} needs ikid-training, the training pipeline, a distribution of its own beside "
            f"ikid (not installed: {e}); install it with {TRAINING_HINT}"
        ) from None
    return ikid_training


def subject_size(
    calibration: str | None,
    length_scale: float | None = None,
    mass_scale: float | None = None,
    markers: np.ndarray | None = None,
    source: str = "",
) -> tuple[float, float, str]:
    """The subject's (length, mass) scales for a tracker, and where they came from: those given;
    else the calibration's size estimate (its landmarks: the forearm's length over the default
    subject's; a mirror calibration carries the other arm's); else, uncalibrated, the size the
    ``markers``' distances say (:func:`~ikid.io.marker_checks.marker_length_scale`) when it is
    more than :data:`~ikid.io.marker_checks.TRACKER_SIZE_TOLERANCE` from the default subject's;
    else the default subject. The mass is the length's cube unless given. One rule for
    ``ikid track`` and ``ikid stream --tracker``: the same calibration gives the same torques.

    Uncalibrated, the tracker measures the hand by where its markers sit from the body model's
    wrist centre, so a ``length_scale`` given against what the markers say is refused (an
    error naming ``source``): read at the wrong size, the torques were 20-60× their size."""
    from ikid.calibration import calibration_info
    from ikid.io.marker_checks import TRACKER_SIZE_TOLERANCE, marker_length_scale

    estimate, estimated_from = None, "the calibration's landmarks"
    if calibration:
        info = calibration_info(calibration)
        landmarks = (info.get("report") or {}).get("landmarks") or {}
        estimate = landmarks.get("length_scale")
        if estimate is None and (mirrored := (info.get("provenance") or {}).get("mirror_length_scale")):
            estimate, estimated_from = mirrored, "the other arm's landmarks (mirror calibration)"
    said = marker_length_scale(markers) if markers is not None and not calibration else None
    if (
        said is not None
        and length_scale is not None
        and abs(length_scale / said - 1.0) > TRACKER_SIZE_TOLERANCE
    ):
        raise ikid.InputError(
            f"{source}: --length-scale {length_scale:g}, but the markers' distances say the subject is "
            f"×{said:.3g} the body model's: an uncalibrated tracker measures the hand by where its markers "
            f"sit from the model's wrist centre, so read at ×{length_scale:g} its angles and torques are "
            f"wrong; give --length-scale {said:.3g}, or calibrate the subject (ikid calibrate) and pass "
            "--calibration"
        )
    if said is not None and estimate is None and abs(said - 1.0) > TRACKER_SIZE_TOLERANCE:
        estimate, estimated_from = said, "the markers' distances, uncalibrated"
    if length_scale is not None:
        length, where = length_scale, "given"
    elif estimate is not None:
        lo, hi = ikid._native.LENGTH_SCALE_RANGE
        length = min(max(float(estimate), lo), hi)
        where = f"estimated from {estimated_from}"
    else:
        length, where = 1.0, "the default subject"
    if mass_scale is not None:
        mass = mass_scale
        if length_scale is not None:
            where = "given"
        elif estimate is None:
            where = "the default subject's length, mass given"
        else:
            where = f"length {where}, mass given"
    else:
        mass = length**3
        if length_scale is not None:
            where = "length given, mass its cube"
    return length, mass, where
