"""The ``ikid`` command line.

Examples::

    ikid ik trial.c3d -o trial.mot --map lab.toml          # markers -> wrist angles (OpenSim .mot)
    ikid run trial.trc -o out/trial                          # -> out/trial.mot + out/trial.sto (torques)
    ikid ik sessions/ -o results/ --map lab.toml --resample  # a folder, in parallel, with a summary
    ikid map-template trial.c3d > lab.toml                   # start a marker map from a file's labels
    ikid calibrate --static st.c3d --movement ra_wr_e_f=fe.c3d --movement ra_wr_s_p=ps.c3d -o s01.json
    ikid ik trial.c3d -o trial.mot --calibration s01.json    # the subject's own marker placement
    ikid id trial.mot -o trial.sto                           # angles -> torques (wrist-id; or --reference)
    ikid stream --model wrist-ik < frames.csv                # one frame per line in, one result per line out
    ikid stream --udp 9870 --count 10000                     # frames as UDP datagrams on 127.0.0.1
    ikid train --data lab/ --map lab.toml --task ik -o models/lab-ik.safetensors
    ikid report --model models/lab-ik.safetensors --data lab_test/ --map lab.toml
    ikid bench --model wrist-ik                              # push latency and batch throughput here
    ikid simulate --protocol thesis --shoulder-deg 45 -o data/thesis_s45
    ikid simulate --protocol random --seed 3 --duration 60 --noise uniform:0.01 -o data/r3
    ikid dataset -o data            # thesis-sized set + the richer random set, in parallel
    ikid demo                       # a fresh trial through the shipped models, errors + latency
"""

from __future__ import annotations

import argparse
import json
import math
import os
import stat
import sys
import time
import traceback
import warnings
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

import ikid
from ikid import _batch, _native
from ikid.io._atomic import atomic_outputs, remove_temporaries, write_text_atomic
from ikid.sim import Trial, simulate

#: The thesis' shoulder flexion angles, degrees.
THESIS_SHOULDERS_DEG = (0.0, 45.0, -20.0)

#: Exit status of `ikid stream` when it ran to the end but frames were lost or refused.
EXIT_FRAMES_LOST = 3


# --- numeric options: checked by argparse, the message names the option ------------------------


def _number(
    cast: type = float,
    *,
    gt: float | None = None,
    ge: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    name: str = "",
    unit: str = "",
):
    """An argparse ``type`` for a number: finite, within the bounds given; a bad value is
    refused by argparse as ``argument --OPTION: VALUE: ...`` (exit 2), never a traceback later.
    ``name`` is what the value is called in the API, for the message."""
    what = f"{name} " if name else ""
    bounds = [
        (gt, lambda v, b: v > b, "greater than"),
        (ge, lambda v, b: v >= b, "at least"),
        (le, lambda v, b: v <= b, "at most"),
        (lt, lambda v, b: v < b, "less than"),
    ]

    def parse(text: str):
        try:
            value = cast(text)
        except ValueError:
            kind = "an integer" if cast is int else "a number"
            raise argparse.ArgumentTypeError(f"{text!r}: {what}must be {kind}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r}: {what}must be a finite number")
        for bound, ok, words in bounds:
            if bound is not None and not ok(value, bound):
                raise argparse.ArgumentTypeError(f"{text}: {what}must be {words} {bound:g}{unit}")
        return value

    parse.__name__ = "integer" if cast is int else "number"
    return parse


POSITIVE = _number(gt=0)
POSITIVE_INT = _number(int, ge=1)
COUNT = _number(int, ge=0)
FINITE = _number()
SUBJECT_LENGTH = _number(
    ge=_native.LENGTH_SCALE_RANGE[0],
    le=_native.LENGTH_SCALE_RANGE[1],
    name="length_scale (the subject's segment lengths / the default's)",
)
SUBJECT_MASS = _number(
    ge=_native.MASS_SCALE_RANGE[0],
    le=_native.MASS_SCALE_RANGE[1],
    name="mass_scale (the subject's segment masses / the default's)",
)
SHOULDER_DEG = _number(ge=-180, le=180, unit=" degrees")
SEED = _number(int, ge=0, lt=2**32)
SIM_RATE = _number(gt=0, le=100_000, unit=" Hz")
PORT = _number(int, ge=0, le=65535)


def _widths(text: str) -> str:
    """``--hidden``: layer widths like ``128,128``, each a positive integer."""
    try:
        widths = [int(w) for w in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected widths like 128,128") from None
    if not widths or min(widths) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: every width must be a positive integer")
    return text


#: Noise kinds of ``--noise KIND:VALUE``, and the parameters each VALUE fills.
NOISE_KINDS = ("uniform", "gaussian", "drift", "occlusion")


#: Largest value of each noise kind: all of a marker's range (uniform, a fraction), 10 cm
#: (gaussian, drift), 100 occlusion bursts per second (one every 10 ms).
NOISE_MAX = {"uniform": 1.0, "gaussian": 0.1, "drift": 0.1, "occlusion": 100.0}


def _noise_spec(spec: str) -> str:
    """``--noise``: checked here (argparse type), parsed by :func:`_noise`."""
    kind, _, value = spec.partition(":")
    if kind not in NOISE_KINDS:
        raise argparse.ArgumentTypeError(f"{spec!r}: unknown kind {kind!r} ({', '.join(NOISE_KINDS)})")
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{spec!r}: expected KIND:NUMBER, e.g. uniform:0.01") from None
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"{spec!r}: the value must be a finite number >= 0")
    if v > NOISE_MAX[kind]:
        raise argparse.ArgumentTypeError(f"{spec!r}: {kind} noise is at most {NOISE_MAX[kind]:g}")
    return spec


def _noise(spec: str) -> tuple[str, dict]:
    """``uniform:0.01``, ``gaussian:0.002`` (m), ``drift:0.005`` (m), ``occlusion:0.5`` (bursts/s)."""
    kind, _, value = _noise_spec(spec).partition(":")
    v = float(value)
    params = {
        "uniform": {"fraction": v},
        "gaussian": {"sigma": v},
        "drift": {"amplitude": v, "rate_hz": 0.0},
        "occlusion": {"bursts_per_second": v, "min_s": 0.05, "max_s": 0.3, "rate_hz": 0.0},
    }
    return kind, params[kind]


def _with_noise(trial: Trial, specs: list[str], seed: int) -> Trial:
    for k, spec in enumerate(specs):
        kind, params = _noise(spec)
        if "rate_hz" in params:
            params["rate_hz"] = trial.rate_hz
        trial = trial.with_noise(kind, seed * 1000 + k + 1, **params)
    return trial


# --- outputs and models: the rules every command follows -----------------------------------------


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


def cmd_simulate(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    trial = simulate(
        args.protocol,
        seed=args.seed,
        duration=args.duration,
        shoulder_flexion=math.radians(args.shoulder_deg),
        length_scale=args.length_scale,
        mass_scale=args.mass_scale,
        dt=1.0 / args.rate,
    )
    trial = _with_noise(trial, args.noise, args.seed)
    # The four files replace any old ones together (Trial.save), or none does.
    paths = trial.save(_stem(args.output, f"{args.protocol}_{args.seed}", (".npz", ".trc", ".mot", ".sto")))
    elapsed = time.perf_counter() - t0
    print(
        f"{len(trial.time)} frames ({trial.time[-1]:.1f} s) in {elapsed:.2f} s -> "
        + ", ".join(map(str, paths))
    )
    return 0


def cmd_dataset(args: argparse.Namespace) -> int:
    """The thesis-sized set (3 shoulder poses x 42 movements) and the richer random set."""
    jobs = [
        (f"thesis_s{int(s):+d}", dict(protocol="thesis", shoulder_flexion=math.radians(s)))
        for s in THESIS_SHOULDERS_DEG
    ]
    for k in range(args.random_trials):
        shoulder = THESIS_SHOULDERS_DEG[k % 3]
        scale = (0.85, 1.0, 1.15)[(k // 3) % 3]
        jobs.append(
            (
                f"random_{k:03d}_s{int(shoulder):+d}_x{scale:.2f}",
                dict(
                    protocol="random",
                    seed=1000 + k,
                    duration=args.duration,
                    shoulder_flexion=math.radians(shoulder),
                    length_scale=scale,
                    mass_scale=scale**3,
                ),
            )
        )
    out = Path(args.output)
    t0 = time.perf_counter()

    def run(job: tuple[str, dict]) -> tuple[str, int, float]:
        name, kw = job
        t = time.perf_counter()
        trial = simulate(**kw)
        sim_s = time.perf_counter() - t
        trial.save(out / name)
        return name, len(trial.time), sim_s

    # simulate() releases the GIL: threads run trials on all cores.
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        results = list(pool.map(run, jobs))
    elapsed = time.perf_counter() - t0
    frames = sum(r[1] for r in results)
    sim_s = sum(r[2] for r in results)
    summary = {
        "trials": len(results),
        "frames": frames,
        "seconds_simulated": frames / 1000.0,
        "wall_s": round(elapsed, 2),
        "simulation_x_real_time_per_core": round(frames / 1000.0 / sim_s, 1),
        "with_file_writing_x_real_time": round(frames / 1000.0 / elapsed, 1),
    }
    write_text_atomic(
        out / "dataset.json", json.dumps({"summary": summary, "trials": [r[0] for r in results]}, indent=1)
    )
    print(json.dumps(summary))
    return 0


def _inputs(paths: list[str]) -> list[Path]:
    """Marker files named, or found (by suffix) in named folders. An entry of a folder named
    like a marker file but not one (a folder ``x.trc/``, a pipe) is kept: it fails as that
    file, named in the summary, instead of vanishing from the count."""
    from ikid.io import MARKER_READERS

    found: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found += sorted(f for f in p.iterdir() if f.suffix.lower() in MARKER_READERS)
        elif os.path.lexists(p):
            found.append(p)
        else:
            raise ikid.NotFoundError(f"{p}: no such file or folder")
    if not found:
        raise ikid.ArgumentError(f"no marker files ({', '.join(MARKER_READERS)}) in {', '.join(paths)}")
    return found


#: How the command line opts in to a model file without a checksum (see :func:`ikid.load`).
UNCHECKED_FLAG = "--allow-unchecked-model"


def _message(error: BaseException) -> str:
    """The error's message as the command line says it: a model file without a checksum names
    this command's opt-in (:data:`UNCHECKED_FLAG`), not the Python API's."""
    message = str(error)
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


def _subject_calibration(frames: np.ndarray, calibration: str | None, mapping, source: str):
    """The calibration a run of ``frames`` (read with ``mapping``) uses: the file given,
    checked against the marker map it was measured with; or, without one, the body model's
    placement, after checking that it can read these markers at all (units, then placement:
    an uncalibrated real recording reads 50-170° off). Errors name ``source``."""
    from ikid.calibration import check_calibration_map

    try:
        ikid.check_marker_units(frames)
        if calibration:
            check_calibration_map(calibration, mapping)
            return ikid.load_calibration(calibration)
        ikid.check_default_placement(frames)
    except ikid.IkidError as e:
        raise type(e)(_naming(source, e)) from None
    return None


def _process_one(job: tuple[str, dict]) -> dict:
    """One marker file -> .mot (and .sto): read, map, check the rate, run, write. In a worker.
    The outputs of one file replace the old ones together, or none does."""
    from ikid.io import MarkerMap, read_markers, write_mot, write_sto
    from ikid.pipeline import run_model

    path, opt = job
    t0 = time.perf_counter()
    row: dict = {"file": path}
    try:
        data = read_markers(path)
        mapping = MarkerMap.load(opt["map"]) if opt["map"] else None
        frames = data.frames(mapping)
        calibration = _subject_calibration(frames, opt["calibration"], mapping, path)
        runs = {}
        for kind, name in (("angles", opt["ik_model"]), ("torques", opt.get("torque_model"))):
            if name:
                # A shipped family name (the default wrist-ik) runs its model for the file's rate
                # (ikid.pipeline.pick_model); a file or a per-rate name is that model.
                runs[kind] = run_model(
                    name,
                    frames,
                    data.time,
                    rate_hz=data.rate_hz,
                    resample_to_model=opt["resample"],
                    missing_markers=opt["missing_markers"],
                    calibration=calibration,
                    source=path,
                    progress=opt["progress"],
                    allow_unchecked=opt["allow_unchecked"],
                )
        for kind, r in runs.items():
            if len(r.time) == 0:
                raise ikid.InputError(f"{path}: no frame gave {kind}: {r.summary()}")
        with atomic_outputs() as written:
            if "angles" in runs:
                r = runs["angles"]
                write_mot(opt["outputs"][0], r.time, r.values, status=r.status)
            if "torques" in runs:
                r = runs["torques"]
                write_sto(opt["outputs"][1], r.time, r.values, status=r.status)
        first = next(iter(runs.values()))
        row.update(
            clean=all(r.clean for r in runs.values()),
            ok=True,
            frames=len(data),
            rate_hz=data.rate_hz,
            summary="; ".join(
                [first.summary()] + [f"{kind}: {r.model_note()}" for kind, r in list(runs.items())[1:]]
            ),
            written=list(map(str, written)),
        )
    except (ikid.IkidError, OSError) as e:
        row.update(ok=False, error=_naming(path, e))
    except Exception as e:  # a bug: named with its traceback, and the batch goes on
        row.update(
            ok=False, error=f"{path}: unexpected {type(e).__name__} (a bug in ikid: please report it): {e}"
        )
        row["traceback"] = traceback.format_exc()
    row["seconds"] = round(time.perf_counter() - t0, 3)
    return row


def _cause(file: str, error: str) -> str:
    """An error message without the file name it starts with (the summary names the file)."""
    if error.startswith(file + ":"):
        rest = error[len(file) + 1 :].lstrip()
        head, sep, tail = rest.partition(": ")
        return f"line {head}: {tail}" if sep and head.isdigit() else rest
    return error


def cmd_process(args: argparse.Namespace) -> int:
    """`ik` and `run`: marker files -> .mot (+ .sto), one file or many in parallel (see
    :mod:`ikid._batch`: results printed as each file ends; a worker that dies fails its file
    only; SIGINT/SIGTERM stop every worker and list the files done and not done)."""
    inputs = _inputs(args.inputs)
    many = len(inputs) > 1 or any(Path(p).is_dir() for p in args.inputs)
    torque_model = getattr(args, "torque_model", None)
    # The models' cards against what the command writes, once, before any file is read.
    unchecked = args.allow_unchecked_model
    _model_for(args.model, f"ikid {args.command} --model", ("ik",), allow_unchecked=unchecked)
    if torque_model:
        _model_for(torque_model, f"ikid {args.command} --torque-model", ("chain",), allow_unchecked=unchecked)
    stems = [p.stem for p in inputs]
    clash = sorted({s for s in stems if stems.count(s) > 1})
    if many and clash:
        raise ikid.ArgumentError(
            f"several inputs are named {', '.join(clash)}; their outputs would overwrite each other"
        )
    # Several inputs, or -o naming a folder: outputs inside it, named after their inputs.
    out = Path(args.output)
    into_folder = many or _is_folder(args.output)
    if into_folder:
        out.mkdir(parents=True, exist_ok=True)
    jobs = []
    for path in inputs:
        stem = out / path.stem if into_folder else _stem(args.output, path.stem)
        mot = out if (not into_folder and out.suffix.lower() == ".mot") else _named(stem, ".mot")
        opt = {
            "map": args.map,
            "ik_model": args.model,
            "torque_model": torque_model,
            "resample": args.resample,
            "missing_markers": args.missing_markers,
            "progress": not many,
            "calibration": args.calibration,
            "allow_unchecked": unchecked,
            "outputs": (mot, _named(stem, ".sto")),
        }
        jobs.append((str(path), opt))
    _refuse_over_inputs(
        [o for _, opt in jobs for o in _job_outputs(opt)],
        [*inputs, args.map, args.calibration, _model_file(args.model), _model_file(torque_model)],
        given=args.output,
    )
    skipped = []
    if args.resume:
        skipped = [f for f, opt in jobs if _whole(_job_outputs(opt), [f, args.map, args.calibration])]
        for f in skipped:
            print(f"{f}: skipped (--resume: its outputs are whole and newer than its inputs)", flush=True)
        jobs = [(f, opt) for f, opt in jobs if f not in skipped]
    rows: dict[int, dict] = {}

    def report(index: int, row: dict) -> None:
        """A file's result, printed as soon as it is known."""
        rows[index] = row
        if row["ok"]:
            line = f"{row['file']}: {row['summary']} ({row['seconds']:.2f} s) -> {', '.join(row['written'])}"
            print(line, flush=True)
        else:
            print(row.get("traceback", "") + f"ikid: error: {row['error']}", file=sys.stderr, flush=True)

    def died(index: int, how: str) -> None:
        file = jobs[index][0]
        error = f"{file}: the process working on it died ({how}); nothing was written for it"
        report(index, {"file": file, "ok": False, "error": error})

    started = time.time()
    before = {path: _file_id(path) for _, opt in jobs for path in _job_outputs(opt)}
    if len(jobs) == 1:
        report(0, _process_one(jobs[0]))  # in this process; SIGINT/SIGTERM end it in main()
        outcome = _batch.Outcome()
    else:
        outcome = _batch.run_jobs(_process_one, jobs, args.jobs or os.cpu_count() or 1, report, died)
    # A worker killed outright may leave a temporary file beside an output: none stays.
    for index, (_, opt) in enumerate(jobs):
        if not rows.get(index, {}).get("ok"):
            for path in _job_outputs(opt):
                remove_temporaries(path, started)
    if outcome.stopped_by:
        # A file whose worker was stopped between writing its outputs and reporting them: its
        # outputs are new files (renamed into place whole), so it is done all the same.
        for index in list(outcome.not_done):
            outputs = _job_outputs(jobs[index][1])
            if all(_file_id(p) is not None and _file_id(p) != before[p] for p in outputs):
                file = jobs[index][0]
                rows[index] = {"file": file, "ok": True, "clean": True, "written": list(map(str, outputs))}
                outcome.not_done.remove(index)
    ended = [rows[k] for k in sorted(rows)]
    failed = [r for r in ended if not r["ok"]]
    if outcome.stopped_by:
        _stopped_summary(args, outcome, [f for f, _ in jobs], ended, skipped)
        return outcome.exit_status
    if many:
        # The summary: every file that gave no output, with its cause.
        print(
            f"{len(ended) - len(failed)}/{len(ended)} files processed, {len(failed)} failed"
            + (f", {len(skipped)} skipped (--resume)" if skipped else "")
            + (":" if failed else "")
        )
        for r in failed:
            print(f"  {r['file']}: {_cause(r['file'], r['error'])}")
    if failed:
        return 2
    unclean = [r["file"] for r in ended if not r["clean"]]
    if args.strict and unclean:
        print(
            f"ikid: --strict: {len(unclean)} file(s) with refused, implausible or flagged frames: "
            + ", ".join(unclean),
            file=sys.stderr,
        )
        return 3
    return 0


def _job_outputs(opt: dict) -> list[Path]:
    """The files one `ik`/`run` job writes: the .mot, and the .sto when it computes torques."""
    return list(opt["outputs"][: 2 if opt["torque_model"] else 1])


def _whole(outputs: list[Path], inputs: list) -> bool:
    """``--resume``: True if every output exists, reads as a complete table (rows and header
    agree) and is newer than every input given (the marker file, map and calibration), so a
    run that was stopped, or ended, wrote it from these inputs."""
    from ikid.io import read_storage

    newest = max((os.stat(p).st_mtime for p in inputs if p is not None and os.path.exists(p)), default=0.0)
    for path in outputs:
        try:
            if not path.is_file() or path.stat().st_mtime < newest or len(read_storage(path).time) == 0:
                return False
        except (ikid.IkidError, OSError, ValueError):
            return False
    return True


def _stopped_summary(
    args: argparse.Namespace, outcome, files: list[str], ended: list[dict], skipped: list
) -> None:
    """What a batch stopped by a signal did: the files done (written, or failed), those not
    done, and the command that resumes it."""
    import shlex

    written = [r["file"] for r in ended if r["ok"]]
    failed = [r["file"] for r in ended if not r["ok"]]
    not_done = [files[k] for k in outcome.not_done]
    argv = list(getattr(args, "argv", None) or [])
    resume = "ikid " + shlex.join(argv if "--resume" in argv else [*argv, "--resume"])
    lines = [
        f"ikid: stopped by {outcome.stopped_by}: {len(written) + len(failed)} of {len(files)} files done, "
        f"{len(not_done)} not done (nothing written for them: their old outputs, if any, are as they were)",
        f"  done: {', '.join(written) or 'none'}",
    ]
    if failed:
        lines.append(f"  failed (named above): {', '.join(failed)}")
    if skipped:
        lines.append(f"  skipped (--resume, done before): {len(skipped)}")
    lines += [f"  not done: {', '.join(not_done)}", f"  to resume: {resume}"]
    print("\n".join(lines), file=sys.stderr, flush=True)


def cmd_track(args: argparse.Namespace) -> int:
    """Markers -> angles (.mot) and torques (.sto) with ``ikid.Tracker``: the causal Kalman
    tracker over the body model, for one subject (no network), at the recording's own rate.
    Every row carries its status bits; a row no wrist can give is not written but counted."""
    from ikid.io import MarkerMap, read_markers, write_mot, write_sto

    stem = _stem(args.output, Path(args.input).stem, create=False)
    refiner_file = None if args.refiner in ("auto", "", "none") else _model_file(args.refiner)
    _refuse_over_inputs(
        [_named(stem, ".mot"), _named(stem, ".sto")],
        [args.input, args.map, args.calibration, refiner_file],
        given=args.output,
    )
    data = read_markers(args.input)
    refiner = None
    if args.refiner == "auto":
        from ikid.pipeline import family_members, same_rate

        # The shipped refiner family's member at the recording's rate, if there is one.
        refiner = next(
            (m for m in family_members("wrist-track") if same_rate(data.rate_hz, m.frame_rate_hz)), None
        )
    elif args.refiner not in ("", "none"):
        refiner = _model_for(
            args.refiner, "ikid track --refiner", ("refine",), allow_unchecked=args.allow_unchecked_model
        )
    mapping = MarkerMap.load(args.map) if args.map else None
    frames = data.frames(mapping)
    calibration = _subject_calibration(frames, args.calibration, mapping, args.input)
    length_scale, mass_scale, size_from = _subject_size(args)
    try:
        tracker = ikid.Tracker(
            length_scale=length_scale,
            mass_scale=mass_scale,
            rate_hz=data.rate_hz,
            jerk_noise=args.jerk_noise,
            refiner=refiner,
            calibration=calibration,
        )
        out = tracker.run(frames)
    except ikid.IkidError as e:
        raise type(e)(_naming(args.input, e)) from None
    k = out["start"]
    status = out["status"]
    bits = ikid.FRAME_STATUS
    keep = np.arange(len(frames)) >= k
    implausible = keep & (status & bits["implausible"] != 0)
    keep &= ~implausible  # nothing no wrist can do is written as a number
    stem.parent.mkdir(parents=True, exist_ok=True)
    with atomic_outputs():  # the pair replaces the old pair, or neither is replaced
        mot = write_mot(_named(stem, ".mot"), data.time[keep], out["q"][keep], status=status[keep])
        sto = write_sto(_named(stem, ".sto"), data.time[keep], out["tau"][keep], status=status[keep])
    counts = {name: int(np.count_nonzero(status[keep] & bit)) for name, bit in bits.items()}
    noise_mm = ", ".join(f"{v * 1e3:.2f}" for v in tracker.marker_noise)
    how = f"refined by {refiner.name}" if refiner else "not refined"
    placed = "uncalibrated"
    if calibration is not None:
        from ikid.calibration import calibration_info

        placed = f"calibrated ({calibration_info(args.calibration)['method']}, {calibration.side} arm)"
    notes = [f"{n} {name.replace('_', ' ')}" for name, n in counts.items() if n]
    if implausible.any():
        notes.append(f"{int(implausible.sum())} implausible (not written)")
    if tracker.restarts:
        notes.append(f"{tracker.restarts} restarts after losing the hand")
    print(
        f"{args.input}: {int(keep.sum())}/{len(frames)} frames tracked from frame {k} "
        f"at {data.rate_hz:g} Hz, subject ×{length_scale:.3g} length, ×{mass_scale:.3g} mass ({size_from}), "
        f"{placed}, {how}; flagged: {', '.join(notes) or 'none'}; hand marker noise learned (mm): {noise_mm} "
        f"-> {mot}, {sto}"
    )
    if args.strict and (k > 0 or status[k:].any()):
        print(f"ikid: --strict: {args.input} has frames without an estimate or flagged", file=sys.stderr)
        return 3
    return 0


def _subject_size(args: argparse.Namespace) -> tuple[float, float, str]:
    """The subject's (length, mass) scales for the tracker, and where they came from: the
    options; else the calibration's size estimate (its landmarks: the forearm's length over
    the default subject's), mass its cube; else the default subject."""
    from ikid.calibration import calibration_info

    estimate = None
    if args.calibration:
        landmarks = (calibration_info(args.calibration).get("report") or {}).get("landmarks") or {}
        estimate = landmarks.get("length_scale")
    if args.length_scale is not None:
        length, source = args.length_scale, "given"
    elif estimate is not None:
        length = min(max(float(estimate), _native.LENGTH_SCALE_RANGE[0]), _native.LENGTH_SCALE_RANGE[1])
        source = "estimated from the calibration's landmarks"
    else:
        length, source = 1.0, "the default subject"
    mass = args.mass_scale if args.mass_scale is not None else length**3
    return length, mass, source


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Landmarks and/or neutral frames, or static + single-coordinate movement files -> a
    calibration JSON recording the method, the side and the marker map."""
    from ikid.calibration import calibrate_functional, calibrate_neutral
    from ikid.io import MarkerMap, read_markers

    def _frame_selection(spec: str, n: int, source: str) -> np.ndarray:
        """Frame numbers (0-based) from "0-9", "41,76,220" or "0-4,10-14"; each within the file."""
        chosen: list[int] = []
        for part in spec.split(","):
            lo, sep, hi = part.strip().partition("-")
            try:
                first, last = int(lo), int(hi) if sep else int(lo)
            except ValueError:
                raise SystemExit(
                    f"ikid: error: --frames {spec!r}: expected frame numbers such as 0-9 or 41,76,220"
                ) from None
            if not 0 <= first <= last < n:
                raise SystemExit(
                    f"ikid: error: --frames {spec!r}: {part.strip()} is outside frames 0-{n - 1} of {source}"
                )
            chosen += range(first, last + 1)
        return np.array(sorted(set(chosen)), np.int64)

    movement_files = [spec.partition("=")[2] or None for spec in args.movement]
    _refuse_over_inputs(
        [args.output],
        [args.static, args.landmarks, args.motion, args.map, *movement_files],
        given=args.output,
    )
    mapping = MarkerMap.load(args.map) if args.map else MarkerMap.identity()
    side = args.side or mapping.side
    static = read_markers(args.static)
    chosen = _frame_selection(args.frames, len(static), args.static) if args.frames else None
    neutral = static.frames(mapping)
    try:
        ikid.check_marker_units(neutral)
    except ikid.IkidError as e:
        raise type(e)(_naming(args.static, e)) from None
    if chosen is not None:
        neutral = neutral[chosen]
    method = args.method
    if method == "auto":
        method = (
            "movements"
            if args.movement
            else "functional"
            if args.motion
            else ("landmarks" if mapping.landmarks else "neutral")
        )
    if method != "movements" and args.movement:
        raise SystemExit(f"ikid: error: --movement is for --method movements, not {method}")
    if (method == "functional") != bool(args.motion):
        raise SystemExit(
            "ikid: error: --method functional needs --motion FILE (a movement mixing flexion and deviation)"
            if method == "functional"
            else f"ikid: error: --motion is for --method functional, not {method}"
        )
    if args.motion_frames and not args.motion:
        raise SystemExit("ikid: error: --motion-frames selects frames of --motion; give --motion FILE")
    provenance: dict = {"static": args.static, "frames": args.frames}
    if method == "movements":
        if side != "right":
            raise SystemExit(
                "ikid: error: the movements method measures right arms only; calibrate a left arm from "
                "landmarks or neutral frames"
            )
        movements = {}
        for spec in args.movement:
            coord, sep, path = spec.partition("=")
            if not sep or coord not in ikid.coordinate_names():
                raise SystemExit(
                    f"ikid: error: --movement {spec!r}: expected COORDINATE=FILE, COORDINATE one of "
                    f"{', '.join(ikid.coordinate_names())}"
                )
            movements[coord] = read_markers(path).frames(mapping)
        cal = ikid.calibrate(neutral, movements)
        provenance["movements"] = dict(s.partition("=")[::2] for s in args.movement)
    elif method == "landmarks":
        source = read_markers(args.landmarks) if args.landmarks else static
        where = chosen if (chosen is not None and not args.landmarks) else slice(None)
        points = np.concatenate(
            [source.marker(lab) for lab in mapping.landmark_labels_in_order(source)], axis=1
        )[where]
        beside = neutral if source is static else source.frames(mapping)[where]
        hand_labels = mapping.hand_landmark_labels_in_order(source)
        hand_points = (
            None
            if hand_labels is None
            else np.concatenate([source.marker(lab) for lab in hand_labels], axis=1)[where]
        )
        cal = calibrate_neutral(
            neutral, points, landmark_frames=beside, side=side, hand_landmarks=hand_points
        )
        provenance["landmarks"] = args.landmarks or args.static
    elif method == "functional":
        motion = read_markers(args.motion)
        moving = motion.frames(mapping)
        if args.motion_frames:
            moving = moving[_frame_selection(args.motion_frames, len(moving), args.motion)]
        cal = calibrate_functional(neutral, moving, side=side)
        provenance["motion"] = args.motion
        provenance["motion_frames"] = args.motion_frames
    else:
        cal = calibrate_neutral(neutral, side=side)
    ikid.save_calibration(cal, args.output, marker_map=mapping, **provenance)
    r = cal.report or {}
    spread = r.get("neutral_spread_deg", 0.0)
    used = r.get("neutral_frames", len(neutral))
    noise, uncertainty = r.get("neutral_noise_deg", 0.0), r.get("neutral_uncertainty_deg", 0.0)
    details = [
        f"{used} of {len(neutral)} neutral frames used (spread {spread:.1f}°, marker noise "
        f"{noise:.1f}° a frame, neutral posture ± {uncertainty:.2f}°)"
    ]
    if r.get("movements"):
        details.append(
            "movements: "
            + ", ".join(
                f"{k} {v['range_deg']:.0f}° ({100 * v['single_axis_share']:.1f} % one axis)"
                for k, v in r["movements"].items()
            )
            + f"; axis skew {r.get('axis_skew_deg', 0):.2f}°"
        )
    if r.get("functional"):
        fn = r["functional"]
        details.append(
            f"functional fit over {fn['frames']} frames: flexion {fn['flexion_range_deg']:.0f}°, deviation "
            f"{fn['deviation_range_deg']:.0f}°, pronation held at {-fn['supination_held_deg']:.0f}° "
            f"(residual {fn['residual_deg']:.1f}° RMS beside {fn['noise_deg']:.1f}° of marker noise)"
        )
    if r.get("landmarks"):
        lm = r["landmarks"]
        if lm.get("hand"):
            details.append(
                f"hand frame from its landmarks ({lm['hand']['frames']} frames; the neutral frames read "
                f"{lm['hand']['neutral_offset_deg']:.1f}° from zero)"
            )
        details.append(
            f"landmarks: forearm axis {lm['long_axis_mm']:.0f} mm, styloids "
            f"{lm['styloid_span_mm']:.0f} mm apart at {lm['styloid_axis_deg']:.0f}° to it, seen in "
            + "/".join(str(n) for n in lm["frames"].values())
            + " frames"
        )
    print(f"{cal!r}; {'; '.join(details)} -> {args.output}")
    return 0


def cmd_map_template(args: argparse.Namespace) -> int:
    from ikid.io import MarkerMap, read_markers

    text = MarkerMap.identity().to_toml()
    if args.input:
        _refuse_over_inputs([_stdout_fd()], [args.input])
        labels = read_markers(args.input).labels
        text = f"# labels in {args.input}: {', '.join(labels)}\n" + text
    print(text, end="")
    return 0


# --- id: angles -> torques ---------------------------------------------------------------------


def cmd_id(args: argparse.Namespace) -> int:
    """Angles (.mot) -> torques (.sto): the wrist-id network over (q, q̇, q̈), or the exact
    Newton-Euler reference for a subject (``--reference``). Velocities and accelerations are
    central differences of the angles (a file is offline: no lag)."""
    from ikid.io import read_mot, resample, write_sto
    from ikid.pipeline import check_rate, run_model

    output = (
        _named(_stem(args.output, Path(args.input).stem, create=False), ".sto")
        if _is_folder(args.output)
        else Path(args.output)
    )
    _refuse_over_inputs(
        [output], [args.input, None if args.reference else _model_file(args.model)], given=args.output
    )
    time_s, q = read_mot(args.input)
    if len(time_s) < 3:
        raise ikid.InputError(
            f"{args.input}: {len(time_s)} rows; at least 3 are needed for velocities and accelerations"
        )
    rate = 1.0 / float(np.median(np.diff(time_s)))
    if args.reference:
        qd = np.gradient(q, time_s, axis=0)
        tau = ikid.reference_id(
            q,
            qd,
            np.gradient(qd, time_s, axis=0),
            shoulder_flexion=math.radians(args.shoulder_deg),
            length_scale=args.length_scale,
            mass_scale=args.mass_scale,
        )
        out_time, summary = (
            time_s,
            f"{len(time_s)} frames, exact Newton-Euler (subject ×{args.length_scale:g} length, "
            f"×{args.mass_scale:g} mass)",
        )
    else:
        model = _model_for(args.model, "ikid id --model", ("id",), allow_unchecked=args.allow_unchecked_model)
        if check_rate(model, rate, args.input, args.resample):
            time_s, q = resample(time_s, q, model.frame_rate_hz)
        qd = np.gradient(q, time_s, axis=0)
        run = run_model(
            model,
            np.concatenate([q, qd, np.gradient(qd, time_s, axis=0)], axis=1),
            time_s,
            rate_hz=model.frame_rate_hz,
            source=args.input,
        )
        if len(run.time) == 0:
            raise ikid.InputError(f"{args.input}: no frame gave torques: {run.summary()}")
        out_time, tau, summary, status = run.time, run.values, run.summary(), run.status
    output.parent.mkdir(parents=True, exist_ok=True)
    path = write_sto(
        output,
        out_time,
        tau,
        status=None if args.reference else status,
    )
    print(f"{args.input}: {summary} -> {path}")
    if args.strict and not args.reference and not run.clean:
        print(f"ikid: --strict: {args.input} has refused, implausible or flagged frames", file=sys.stderr)
        return 3
    return 0


# --- stream: live frames in, one line out per frame ----------------------------------------------


def _parse_frame(
    line: str, frame_len: int, with_time: bool, with_number: bool = False
) -> tuple[int | None, float | None, np.ndarray]:
    """One text frame: the source's frame number first with ``--frame-number``, then the time
    with ``--time``, then ``frame_len`` numbers (comma, semicolon, tab or space separated). An
    empty field or ``nan`` is a missing value."""
    line = line.strip()
    fields = [f.strip() for f in line.split(",")] if "," in line else line.replace(";", " ").split()
    lead = int(with_number) + int(with_time)
    want = frame_len + lead
    if len(fields) != want:
        first = ("frame number + " if with_number else "") + ("time + " if with_time else "")
        raise ikid.InputError(f"expected {want} values ({first}{frame_len} frame values), got {len(fields)}")
    number = None
    if with_number:
        try:
            number = int(fields[0])
        except ValueError:
            raise ikid.InputError(f"frame number {fields[0]!r} is not an integer") from None
        fields = fields[1:]
    try:
        values = np.array([float(f) if f else np.nan for f in fields], np.float64)
    except ValueError as e:
        raise ikid.InputError(f"not a number: {e}") from None
    if with_time and not math.isfinite(values[0]):
        raise ikid.InputError(f"time {fields[0]!r} is not a finite number")
    return (number, float(values[0]), values[1:]) if with_time else (number, None, values)


#: Receive buffer `ikid stream --udp` asks for, bytes: a burst of 40,000 frames (~200 bytes a
#: datagram) — a second of a 42 kHz burst, or 40 s at 1 kHz of a reader that stalled.
UDP_RECEIVE_BUFFER = 8 << 20


def _receive_buffer(sock, want: int = UDP_RECEIVE_BUFFER) -> int:
    """Ask for a ``want``-byte receive buffer; the size granted (the system caps it: Linux's
    ``net.core.rmem_max``). Linux reports twice what it grants (its bookkeeping): halved here."""
    import socket

    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, want)
    except OSError:
        pass  # the default stays; reported below
    granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    return granted // 2 if sys.platform.startswith("linux") else granted


def _udp_lines(port: int, count: int | None, idle_s: float):
    """Datagrams on 127.0.0.1:``port`` as text lines, until ``count`` frames, an ``END``
    datagram, or ``idle_s`` seconds without one."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        granted = _receive_buffer(sock)
        sock.bind(("127.0.0.1", port))
        sock.settimeout(idle_s)
        print(f"ikid stream: listening on udp 127.0.0.1:{sock.getsockname()[1]}", file=sys.stderr, flush=True)
        note = (
            ""
            if granted >= UDP_RECEIVE_BUFFER
            else f", asked for {UDP_RECEIVE_BUFFER} (the system's limit; on Linux raise net.core.rmem_max): "
            "a larger burst overflows it and its frames are lost"
        )
        print(f"ikid stream: receive buffer {granted} bytes{note}", file=sys.stderr, flush=True)
        received = 0
        while count is None or received < count:
            try:
                data = sock.recv(65536)
            except TimeoutError:
                print(f"ikid stream: no frame for {idle_s:g} s, stopping", file=sys.stderr)
                return
            for line in data.decode("utf-8", "replace").splitlines():
                if line.strip() == "END":
                    return
                if line.strip():
                    received += 1
                    yield line


class _Losses:
    """Frames lost between those received: from the source's frame numbers (a jump of k is
    k - 1 lost), else from its times (a gap of k periods is k - 1 lost). A frame whose number
    is not after the last one's is refused (late or repeated)."""

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.lost = 0
        self.last_number: int | None = None
        self.last_time: float | None = None

    def number(self, n: int) -> None:
        if self.last_number is not None:
            if n <= self.last_number:
                raise ikid.InputError(f"frame number {n} after {self.last_number} (late or repeated)")
            self.lost += n - self.last_number - 1
        self.last_number = n

    def time(self, t: float) -> None:
        if self.last_time is not None and t > self.last_time:
            self.lost += max(0, round((t - self.last_time) * self.rate_hz) - 1)
        self.last_time = t


def cmd_stream(args: argparse.Namespace) -> int:
    """Frames (text lines) from stdin or UDP -> one CSV line per frame on stdout:
    ``frame,status,<outputs>``; status ``ok``, ``filled:<markers>``, ``filling`` (window not
    full yet) or ``refused:<reason>`` (outputs empty). Nothing is skipped silently: the summary
    on stderr counts frames received, refused (by reason) and lost; exit status 0 if every
    frame was processed, 3 if frames were lost or refused, 2 on an error."""
    from ikid.pipeline import refusal_reason

    stdin = None
    if args.udp is None:
        try:
            stdin = sys.stdin.fileno()
        except (AttributeError, OSError, ValueError):
            pass
    _refuse_over_inputs(
        [_stdout_fd()],
        [stdin, args.calibration, _model_file(args.model), _model_file(args.torque_model)],
    )
    unchecked = args.allow_unchecked_model
    models = [_model_for(args.model, "ikid stream --model", ("ik", "chain"), args.rate, unchecked)]
    if args.torque_model:
        models.append(
            _model_for(args.torque_model, "ikid stream --torque-model", ("chain",), args.rate, unchecked)
        )
    rate = models[0].frame_rate_hz
    for m in models:
        if m.frame_len != models[0].frame_len:
            raise ikid.InputError(f"models {models[0].name!r} and {m.name!r} read different frames")
    calibration = ikid.load_calibration(args.calibration) if args.calibration else None
    streams = [m.stream(missing_markers=args.missing_markers, calibration=calibration) for m in models]
    names = [n for m in models for n in m.output_names]
    out = sys.stdout
    out.write("frame,status," + ",".join(names) + "\n")
    lines = (
        _udp_lines(args.udp, args.count, args.idle)
        if args.udp is not None
        else (line for k, line in enumerate(sys.stdin) if args.count is None or k < args.count)
    )
    counts: Counter = Counter()
    refused: Counter = Counter()
    losses = _Losses(rate)
    frame = 0
    for line in lines:
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        status, values, label = "ok", "", frame
        try:
            try:
                number, t, x = _parse_frame(line, models[0].frame_len, args.time, args.frame_number)
            except ikid.InputError as e:
                raise _Refused(str(e), "unreadable line") from None
            if number is not None:
                label = number
                try:
                    losses.number(number)
                except ikid.InputError as e:
                    raise _Refused(str(e), "late or repeated frame number") from None
            elif t is not None:
                losses.time(t)
            try:
                results = [s.push(x, time=t) for s in streams]
            except ikid.InputError as e:
                # The line's frame column is the one to read: the reason alone goes in the status.
                raise _Refused(e.reason or str(e), refusal_reason(e)) from e
            ready = [r for r in results if r is not None]
            if len(ready) < len(results):
                status = "filling"
            else:
                values = ",".join(f"{v:.7g}" for r in ready for v in r)
                filled = streams[0].filled_markers
                if filled:
                    status = "filled:" + "+".join(filled)
        except _Refused as e:
            status = "refused:" + e.detail.replace(",", ";").replace("\n", " ")
            refused[e.key] += 1
            if args.strict:
                print(f"ikid: error: frame {label}: {e.detail}", file=sys.stderr)
                return 2
        out.write(f"{label},{status},{values}\n")
        if args.flush:
            out.flush()
        counts[status.split(":")[0]] += 1
        frame += 1
    out.flush()
    parts = [f"{counts[k]} {k}" for k in ("ok", "filled", "filling", "refused") if counts[k]]
    if args.frame_number or args.time:
        parts.append(f"{losses.lost} lost (by {'frame number' if args.frame_number else 'time'})")
    else:
        parts.append("lost not counted (no frame numbers or times: --frame-number, --time)")
    print(f"ikid stream: {frame} frames received at {rate:g} Hz: " + ", ".join(parts), file=sys.stderr)
    if refused:
        print(
            "ikid stream: refused: " + "; ".join(f"{n} {reason}" for reason, n in refused.most_common()),
            file=sys.stderr,
        )
    return EXIT_FRAMES_LOST if refused or losses.lost else 0


class _Refused(Exception):
    """A frame `ikid stream` gives no output for: ``detail`` for its line, ``key`` to count it by."""

    def __init__(self, detail: str, key: str) -> None:
        super().__init__(detail)
        self.detail, self.key = detail, key


# --- train / report / bench --------------------------------------------------------------------

#: The shipped config each task starts from (architecture, window, augmentation, budget).
BASE_CONFIG = {"ik": "wrist-ik", "chain": "wrist-chain", "id": "wrist-id"}


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


def _config_path(name: str) -> Path:
    """A shipped config's name (``ikid_training/configs``) or a TOML path, by the rule of
    :func:`ikid.load`: a name with no path separator and no ``.toml`` suffix is a shipped
    config, even if a file or folder of that name is in the working directory."""
    shipped_dir = Path(_training_package("ikid train").CONFIG_DIR)
    if ikid.is_model_name(name) and not name.endswith(".toml"):
        shipped = shipped_dir / f"{name}.toml"
        if not shipped.is_file():
            known = sorted(q.stem for q in shipped_dir.glob("*.toml"))
            raise ikid.InputError(
                f"no shipped config {name!r} (shipped: {', '.join(known)}); a config file is given by a "
                "path (with a folder or the .toml suffix)"
            )
        return shipped
    p = Path(name)
    if not p.is_file():
        raise ikid.InputError(f"{p}: no such config file")
    return p


def _training():
    _training_package("ikid train")
    try:
        from ikid_training import train
    except ImportError as e:  # installed without its dependencies (torch)
        raise ikid.InputError(
            f"ikid train needs torch, a dependency of ikid-training ({e}); install it with {TRAINING_HINT}"
        ) from None
    return train


def cmd_train(args: argparse.Namespace) -> int:
    train = _training()
    if args.data is None and args.config is None:
        raise ikid.InputError("give --data DIR (a lab's trials) or --config NAME|FILE (a training config)")
    try:
        cfg = train.load_config(_config_path(args.config or BASE_CONFIG[args.task or "ik"]))
    except ValueError as e:  # a config problem, named by load_config
        raise ikid.InputError(str(e)) from None
    if args.task is not None and cfg["model"]["task"] != args.task:
        raise ikid.InputError(
            f"--task {args.task} but config {args.config!r} trains task {cfg['model']['task']!r}; "
            "drop one of them"
        )
    out = Path(args.output)
    if out.suffix == ".safetensors":
        cfg["model"]["name"], out_dir = out.stem, out.parent
    else:
        out_dir = out
    if args.data is not None:
        task = cfg["model"]["task"]
        cfg["data"] = {"lab": str(Path(args.data).resolve())}
        if args.map:
            cfg["data"]["map"] = str(Path(args.map).resolve())
        if args.rate is not None:
            cfg["data"]["rate_hz"] = args.rate
        if out.suffix != ".safetensors" and args.config is None:
            cfg["model"]["name"] = f"lab-{task}"
    if args.minutes is not None:
        cfg["train"]["max_minutes"] = args.minutes
    if args.window is not None:
        cfg["model"]["window"] = args.window
    if args.hidden is not None:
        try:
            cfg["model"]["hidden"] = [int(w) for w in args.hidden.split(",")]
        except ValueError:
            raise ikid.InputError(f"--hidden {args.hidden!r}: expected widths like 128,128") from None
    name = cfg["model"]["name"]
    lab = Path(args.data) if args.data is not None else None
    _refuse_over_inputs(
        [out_dir / f"{name}.safetensors", out_dir / f"{name}.onnx"],
        [
            _config_path(args.config) if args.config else None,
            args.map,
            *(sorted(lab.iterdir()) if lab is not None and lab.is_dir() else []),
        ],
        given=args.output,
    )
    train.run(cfg, out_dir, progress=sys.stderr.isatty(), onnx=not args.no_onnx)
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    if args.data is None:
        _training_package("ikid report without --data (the shipped models' full report)")
        try:
            from ikid_training import report
        except ImportError as e:  # installed without its dependencies (matplotlib)
            raise ikid.InputError(
                f"the full report needs matplotlib, a dependency of ikid-training ({e}); install it "
                f"with {TRAINING_HINT}"
            ) from None
        report.main(["--out", args.output or "docs"])
        return 0
    from ikid import recordings as D
    from ikid.evaluate import evaluate_recordings, markdown

    model = _model_for(
        args.model, "ikid report --model", ("ik", "chain", "id"), allow_unchecked=args.allow_unchecked_model
    )
    out = None
    if args.output:
        out = (
            _named(_stem(args.output, model.name, (".md",), create=False), ".md")
            if _is_folder(args.output)
            else Path(args.output)
        )
        data_files = sorted(Path(args.data).iterdir()) if Path(args.data).is_dir() else []
        _refuse_over_inputs(
            [out, out.with_suffix(".json")],
            [_model_file(args.model), args.map, *data_files],
            given=args.output,
        )
    recs = D.load_lab_recordings(args.data, args.map, model.frame_rate_hz if args.resample else None)
    rates = {r.meta["rate_hz"] for r in recs}
    from ikid.pipeline import check_rate

    for rate in rates:
        check_rate(model, rate, str(args.data), allow_resample=False)
    levels = {"clean": 0.0} if args.clean_only else None
    result = evaluate_recordings(model, recs, levels)
    text = f"# ikid report: `{model.name}` on {args.data}\n\n" + markdown(result)
    print(text, end="")
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        with atomic_outputs():  # the report and its numbers replace the old pair together
            write_text_atomic(out, text)
            write_text_atomic(out.with_suffix(".json"), json.dumps(result, indent=1))
        print(f"-> {out}, {out.with_suffix('.json')}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    """Per-push latency (p50/p99/max) of ``Stream.push`` from Python and ``predict``
    throughput (1 and 2 threads) of a model on a fresh simulated trial, on this machine."""
    model = ikid.load(args.model, allow_unchecked=args.allow_unchecked_model)
    if args.frames <= model.window:
        raise ikid.ArgumentError(
            f"--frames {args.frames}: model {model.name!r} gives its first output at frame {model.window}; "
            f"give more than {model.window} frames"
        )
    if model.frame_kind != "markers":
        t = simulate("random", seed=424242, duration=args.frames / 1000.0 + 0.1)
        frames = np.concatenate([t.q, t.qd, t.qdd], axis=1)[: args.frames]
        if model.frame_kind == "tracker_state":  # plus the tracker's log10 marker noise (1 mm)
            frames = np.concatenate([frames, np.full((len(frames), 1), -3.0)], axis=1)
    else:
        frames = simulate("random", seed=424242, duration=args.frames / 1000.0 + 0.1).markers[: args.frames]
    frames = np.ascontiguousarray(frames, np.float32)
    stream = model.stream()
    push = stream.push
    ns = np.empty(len(frames), np.int64)
    clock = time.perf_counter_ns
    for i, f in enumerate(frames):
        t0 = clock()
        push(f)
        ns[i] = clock() - t0
    us = ns[model.window :] / 1e3
    lines = [
        f"{model.name}: {model.feature_set} x {model.window}, layers "
        f"{'-'.join(map(str, model.layer_widths))}, {len(frames)} frames",
        f"  Stream.push (Python): p50 {np.median(us):.2f} µs, p99 {np.percentile(us, 99):.2f} µs, "
        f"max {us.max():.1f} µs (budget 2000 µs: {2000 / np.percentile(us, 99):.0f}× headroom at p99)",
    ]
    for threads in (1, 2):
        # The lambda runs before the loop moves on.
        best = min(_timed(lambda: model.predict(frames, threads=threads)) for _ in range(3))  # noqa: B023
        lines.append(
            f"  predict, {threads} thread{'s' if threads > 1 else ''}: {best / len(frames) * 1e6:.3f} µs per "
            f"frame ({_significant(len(frames) / best / 1e6)} M frames/s)"
        )
    print("\n".join(lines))
    return 0


def _significant(x: float, digits: int = 3) -> str:
    """``x`` to ``digits`` significant digits, in plain notation (0.0648, 12.3, 1230): a rate
    of 0.06 M frames/s printed as "0.06" would be 8 % off the time per frame beside it."""
    if x == 0 or not math.isfinite(x):
        return f"{x:g}"
    rounded = float(f"{x:.{digits - 1}e}")  # first, so 9.9996 gives 10.0, not 10.00
    decimals = max(0, digits - 1 - math.floor(math.log10(abs(rounded))))
    return f"{rounded:.{decimals}f}"


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as the command line prints it: one line, no source location."""
    print(f"ikid: warning: {message}", file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="ikid", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"ikid {ikid.__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("simulate", help="simulate one trial and write .npz/.trc/.mot/.sto")
    p.add_argument("--protocol", choices=["thesis", "random"], default="random")
    p.add_argument("--seed", type=SEED, default=0, help="0 <= SEED < 2^32")
    p.add_argument("--duration", type=POSITIVE, default=10.0, help="seconds (random protocol)")
    p.add_argument("--shoulder-deg", type=SHOULDER_DEG, default=0.0, help="shoulder flexion, degrees")
    p.add_argument("--length-scale", type=SUBJECT_LENGTH, default=1.0)
    p.add_argument("--mass-scale", type=SUBJECT_MASS, default=1.0)
    p.add_argument(
        "--rate", type=SIM_RATE, default=1000.0, help="physics and output rate, Hz (up to 100 kHz)"
    )
    p.add_argument(
        "--noise",
        type=_noise_spec,
        action="append",
        default=[],
        metavar="KIND:VALUE",
        help="uniform:0.01 | gaussian:0.002 | drift:0.005 | occlusion:0.5 (repeatable)",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="output stem (writes STEM.npz, .trc, .mot, .sto, replacing old ones together), or a folder "
        "(ending with / or existing: FOLDER/PROTOCOL_SEED.*)",
    )
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("dataset", help="write the thesis-sized and the richer simulated datasets")
    p.add_argument("-o", "--output", required=True)
    p.add_argument(
        "--random-trials", type=COUNT, default=18, help="random multi-DoF trials (3 poses x 3 sizes x ...)"
    )
    p.add_argument("--duration", type=POSITIVE, default=60.0, help="seconds per random trial")
    p.add_argument("--jobs", type=POSITIVE_INT, default=None, help="threads (default: all cores)")
    p.set_defaults(func=cmd_dataset)

    def unchecked_option(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            UNCHECKED_FLAG,
            action="store_true",
            help="load a model file written before model files carried a checksum of their weights "
            "(refused otherwise: a corrupted copy cannot be told from a good one; a warning is printed). "
            "python -m ikid_training.export --restamp FILE adds the checksum for good",
        )

    def processing_options(p: argparse.ArgumentParser, model_help: str) -> None:
        p.add_argument("inputs", nargs="+", metavar="IN", help="marker files (.c3d, .trc) or folders of them")
        p.add_argument(
            "-o",
            "--output",
            required=True,
            help="output file (one input), or a folder (several inputs, or ending with / or existing): "
            "FOLDER/<input name>.mot",
        )
        p.add_argument("--model", default="wrist-ik", help=model_help)
        p.add_argument(
            "--map", metavar="TOML", help="marker map: which label is which ikid marker (see map-template)"
        )
        p.add_argument(
            "--resample",
            action="store_true",
            help="resample markers to the model's rate (cubic Hermite; output rows at the model's rate)",
        )
        p.add_argument(
            "--missing-markers", choices=["fill", "refuse"], default=None, help="override the model's policy"
        )
        p.add_argument(
            "--calibration", metavar="JSON", help="the subject's marker placement (see `ikid calibrate`)"
        )
        p.add_argument("--jobs", type=POSITIVE_INT, default=None, help="parallel files (default: all cores)")
        p.add_argument(
            "--resume",
            action="store_true",
            help="skip the files whose outputs are whole and newer than their inputs (marker file, map, "
            "calibration): a stopped batch goes on where it stopped",
        )
        p.add_argument(
            "--strict",
            action="store_true",
            help="exit 3 if any frame was refused, or any output flagged (the ikid_status column)",
        )

    p = sub.add_parser(
        "ik",
        help="markers (.c3d/.trc) -> wrist angles (.mot, degrees)",
        description="Markers -> wrist angles.\n\n  ikid ik trial.c3d -o trial.mot --map lab.toml\n"
        "  ikid ik sessions/ -o results/ --resample",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    processing_options(
        p,
        "angle model, shipped name or file (default wrist-ik: the shipped wrist-ik model whose card rate is "
        "the file's, e.g. wrist-ik-100hz; another rate runs on the next faster one, resampled, outputs "
        "at the file's frames)",
    )
    unchecked_option(p)
    p.set_defaults(func=cmd_process)

    p = sub.add_parser(
        "run",
        help="markers -> wrist angles (.mot) and torques (.sto)",
        description="Markers -> angles and torques.\n\n"
        "  ikid run trial.c3d -o out/trial   # out/trial.mot, out/trial.sto",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    processing_options(
        p, "angle model (default wrist-ik: the shipped wrist-ik model for the file's rate, as in `ikid ik`)"
    )
    p.add_argument(
        "--torque-model", default="wrist-chain", help="markers -> torques model (default wrist-chain)"
    )
    unchecked_option(p)
    p.set_defaults(func=cmd_process)

    p = sub.add_parser(
        "track",
        help="markers -> angles (.mot) and torques (.sto) with the Kalman tracker + its refiner",
        description="Markers -> wrist angles and torques, causally, with ikid.Tracker: an extended Kalman "
        "filter over the body model that learns each marker coordinate's noise, refined by the shipped "
        "wrist-track network.\n\n"
        "  ikid track trial.c3d -o out/trial --length-scale 1.1 --mass-scale 1.3"
        "   # out/trial.mot, out/trial.sto",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="marker file (.c3d, .trc, .csv)")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="output stem: writes STEM.mot and STEM.sto (together); a folder (ending with / or existing): "
        "FOLDER/<input name>.mot, .sto",
    )
    p.add_argument("--map", help="marker map (TOML) from the file's labels to ikid's")
    p.add_argument(
        "--length-scale",
        type=SUBJECT_LENGTH,
        default=None,
        help="subject's segment lengths / the default subject's (default: the calibration's estimate "
        "from its landmarks, else 1)",
    )
    p.add_argument(
        "--mass-scale",
        type=SUBJECT_MASS,
        default=None,
        help="subject's segment masses / the default subject's (default: the cube of the length scale)",
    )
    p.add_argument(
        "--refiner",
        default="auto",
        help="refinement model, shipped name or file; 'none' for the bare filter; 'auto' (default): "
        "the shipped wrist-track family's member at the recording's rate (wrist-track: 1000 Hz), else none "
        "(the summary says which; a refiner at another rate: python -m ikid_training.refine --rate)",
    )
    p.add_argument(
        "--jerk-noise",
        type=_number(gt=0, le=1e12, unit=" rad²/s⁵"),
        default=ikid.DEFAULT_JERK_NOISE,
        help=f"motion model's jerk density, rad²/s⁵ (default {ikid.DEFAULT_JERK_NOISE:g}, "
        "tuned in docs/ekf.md)",
    )
    p.add_argument(
        "--calibration",
        metavar="JSON",
        help="the subject's marker placement (see `ikid calibrate`); without it the body model's placement "
        "is checked against the markers first, and a recording it cannot read is refused",
    )
    p.add_argument(
        "--strict",
        action="store_true",
        help="exit 3 if any frame has no estimate or is flagged (the ikid_status column)",
    )
    unchecked_option(p)
    p.set_defaults(func=cmd_track)

    p = sub.add_parser(
        "calibrate",
        help="measure a subject's marker placement (landmarks, neutral frames, or movements)",
        description="A subject's marker placement -> calibration JSON (method, side and marker map recorded; "
        "ikid.calibration.check_calibration_map refuses a trial read with another map).\n\n"
        "  # landmarks (the map's [landmarks]: epicondyles, styloids) + neutral frames of any trial:\n"
        "  ikid calibrate --static s01_task.c3d --frames 0-9 --map lab.toml -o s01.json\n"
        "  # neutral posture only (no landmarks in the map, or --method neutral):\n"
        "  ikid calibrate --static s01_static.c3d --method neutral --map lab.toml -o s01.json\n"
        "  # neutral frames + any movement bending the wrist both ways (functional axes):\n"
        "  ikid calibrate --static s01_task.c3d --frames 0-9 --motion s01_circles.c3d \\\n"
        "      --map lab.toml -o s01.json\n"
        "  # static trial + movements of one coordinate each:\n"
        "  ikid calibrate --static s01_static.c3d --movement ra_wr_e_f=s01_flex.c3d \\\n"
        "      --movement ra_wr_s_p=s01_pron.c3d --map lab.toml -o s01.json\n"
        "  ikid ik s01_task.c3d -o s01_task.mot --map lab.toml --calibration s01.json\n\n"
        "landmarks: the forearm's ISB frame (y from the mid-styloids to the mid-epicondyles, "
        "x = y x (ulnar -> radial styloid), z = x x y), each landmark averaged in the forearm cluster's "
        "frame over the frames it is seen in; the hand's frame equals the forearm's at the neutral "
        "posture, which reads zero, or, when the map names second_metacarpal_head and fifth_metacarpal_head, "
        "is the hand's own (y from the mid-heads to the mid-styloids, as the forearm's). "
        "With landmarks, clusters may sit at any orientation. "
        "neutral: the same, the forearm at the body model's placement: refused (saying what to record) when "
        "the forearm's markers are not spread as the model's RSP, USP and FAP (clusters, plates). "
        "functional: the flexion axis (fixed in the forearm) and the deviation axis (fixed in the hand) "
        "fitted by least squares to a movement mixing both, pronation held; the neutral frames read zero; "
        "the axes' signs come from the forearm markers' placement (within 60 degrees of the body model's), "
        "the hand's cluster may sit any way round. "
        'A left arm (side = "left" in the map, or --side left) is mirrored into a right arm: its angles keep '
        "their anatomical signs.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--static",
        required=True,
        help="marker file of the neutral posture: a static trial, or any trial with --frames",
    )
    p.add_argument(
        "--frames",
        metavar="LIST",
        help="frames of --static in the neutral posture, 0-based: 0-9, 41,76,220 (default: all); the "
        "landmarks are averaged over them too",
    )
    p.add_argument(
        "--method",
        choices=["auto", "landmarks", "neutral", "functional", "movements"],
        default="auto",
        help="auto (default): movements if --movement is given, functional if --motion is, landmarks if "
        "the map names them, else neutral",
    )
    p.add_argument(
        "--motion",
        metavar="FILE",
        help="functional method: a marker file where the wrist bends through flexion-extension and "
        "deviation together (circles, or a task), the forearm's rotation held",
    )
    p.add_argument("--motion-frames", metavar="LIST", help="frames of --motion to fit (default: all)")
    p.add_argument(
        "--landmarks",
        metavar="FILE",
        help="marker file holding the landmarks with the forearm's markers (default: --static), all its "
        "frames used",
    )
    p.add_argument(
        "--movement",
        action="append",
        default=[],
        metavar="COORD=FILE",
        help="a movement of that coordinate alone (movements method: at least two coordinates)",
    )
    p.add_argument("--side", choices=["right", "left"], help="the arm (default: the map's side, else right)")
    p.add_argument("--map", metavar="TOML", help="marker map, optionally with [landmarks] (see map-template)")
    p.add_argument("-o", "--output", required=True, help="calibration JSON to write")
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("map-template", help="print a marker map (TOML) to fill in, listing a file's labels")
    p.add_argument("input", nargs="?", help="a .c3d/.trc whose labels to list")
    p.set_defaults(func=cmd_map_template)

    p = sub.add_parser(
        "id",
        help="angles (.mot) -> wrist torques (.sto)",
        description="Angles -> torques (velocities, accelerations: central differences).\n\n"
        "  ikid id trial.mot -o trial.sto                 # the wrist-id network\n"
        "  ikid id trial.mot -o trial.sto --reference --length-scale 1.1 --mass-scale 1.33",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", metavar="IN", help="angles, OpenSim .mot")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help=".sto to write, or a folder (ending with / or existing): FOLDER/<input name>.sto",
    )
    p.add_argument("--model", default="wrist-id", help="joint-state model (default wrist-id)")
    p.add_argument(
        "--reference",
        action="store_true",
        help="exact Newton-Euler for the subject below instead of the network",
    )
    p.add_argument("--length-scale", type=SUBJECT_LENGTH, default=1.0, help="subject size (--reference)")
    p.add_argument("--mass-scale", type=SUBJECT_MASS, default=1.0, help="subject mass factor (--reference)")
    p.add_argument(
        "--shoulder-deg", type=SHOULDER_DEG, default=0.0, help="shoulder flexion, degrees (--reference)"
    )
    p.add_argument("--resample", action="store_true", help="resample the angles to the model's rate")
    p.add_argument(
        "--strict",
        action="store_true",
        help="exit 3 if any frame was refused or any torque flagged (the ikid_status column)",
    )
    unchecked_option(p)
    p.set_defaults(func=cmd_id)

    p = sub.add_parser(
        "stream",
        help="live frames (stdin or UDP on 127.0.0.1) -> one CSV line per frame",
        description="Frames in, one result line out per frame (CSV: frame,status,outputs).\n\n"
        "  ikid stream < frames.csv                          # 18 numbers per line (m)\n"
        "  ikid stream --time --torque-model wrist-chain < frames.csv   # time first\n"
        "  ikid stream --udp 9870 --count 100000 --idle 5     # datagrams, 'END' stops\n"
        "  ikid stream --udp 9870 --frame-number --time       # 'N,t,x1,...,z6': lost frames counted\n\n"
        "At the end, a summary on stderr: frames received, ok, filled, filling, refused (by\n"
        "reason) and lost (counted from the source's frame numbers, --frame-number, or its\n"
        "times, --time). UDP asks for an 8 MiB receive buffer for bursts and says if it got less.\n\n"
        "Exit status: 0 every frame was processed; 3 frames were lost or refused; 2 an error\n"
        "(or, with --strict, the first refused frame).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", default="wrist-ik", help="model (default wrist-ik)")
    p.add_argument(
        "--torque-model", default=None, help="a second model on the same frames (e.g. wrist-chain)"
    )
    p.add_argument(
        "--udp",
        type=PORT,
        default=None,
        metavar="PORT",
        help="read datagrams on 127.0.0.1:PORT (0: any free port)",
    )
    p.add_argument("--count", type=POSITIVE_INT, default=None, help="stop after this many frames")
    p.add_argument(
        "--idle", type=POSITIVE, default=10.0, help="UDP: stop after this many seconds without a frame"
    )
    p.add_argument(
        "--time",
        action="store_true",
        help="each line starts with the frame's time (s): gaps restart the window and count lost frames",
    )
    p.add_argument(
        "--frame-number",
        action="store_true",
        help="each line starts with the source's frame number (before the time with --time): a jump "
        "counts the frames lost between; a number not after the last is refused",
    )
    p.add_argument(
        "--rate",
        type=POSITIVE,
        default=None,
        help="the source's frame rate (Hz): the model family's member at that rate (wrist-ik at 100 -> "
        "wrist-ik-100hz); refused if it has none (a live stream is not resampled)",
    )
    p.add_argument(
        "--missing-markers", choices=["fill", "refuse"], default=None, help="override the model's policy"
    )
    p.add_argument(
        "--calibration", metavar="JSON", help="the subject's marker placement (see `ikid calibrate`)"
    )
    p.add_argument("--strict", action="store_true", help="stop at the first refused frame (exit 2)")
    p.add_argument("--flush", action="store_true", help="flush stdout after every line (for pipes read live)")
    unchecked_option(p)
    p.set_defaults(func=cmd_stream)

    p = sub.add_parser(
        "train",
        help="train a model on a lab's trials (or a config); needs ikid-training",
        description="Train a model: a lab's trials (marker files + same-stem .mot angles [+ .sto torques])\n"
        "through the same pipeline as the shipped models (80/10/10 split per trial, noise and\n"
        "occlusion augmentation, early stopping), exported as .safetensors + .onnx.\n"
        "Needs the training pipeline (torch), a distribution of its own: pip install ./training\n"
        "(from an ikid source checkout).\n\n"
        "  ikid train --data lab/ --map lab.toml --task ik -o models/lab-ik.safetensors\n"
        "  ikid train --data lab/ --task chain --minutes 10 -o models/lab-chain.safetensors\n"
        "  ikid train --config wrist-ik -o out/models    # a shipped config (simulated data)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--data", default=None, metavar="DIR", help="a lab's trials: .c3d/.trc with same-stem .mot (and .sto)"
    )
    p.add_argument("--map", metavar="TOML", help="marker map for the trials (see map-template)")
    p.add_argument(
        "--task",
        choices=sorted(BASE_CONFIG),
        default=None,
        help="ik: angles (default); chain: markers -> torques; id: joint states -> torques",
    )
    p.add_argument("--config", default=None, help="config name or TOML (default: the shipped one for --task)")
    p.add_argument("--rate", type=POSITIVE, default=None, help="resample every trial to this rate (Hz) first")
    p.add_argument("--minutes", type=POSITIVE, default=None, help="training time budget")
    p.add_argument(
        "--window", type=POSITIVE_INT, default=None, help="frames per window (default: the config's)"
    )
    p.add_argument(
        "--hidden", type=_widths, default=None, help="hidden widths, e.g. 128,128 (default: the config's)"
    )
    p.add_argument("--no-onnx", action="store_true", help="skip the ONNX copy")
    p.add_argument("-o", "--output", required=True, help="model file (.safetensors) or output folder")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser(
        "report",
        help="score a model on a lab's trials (or the full report of the shipped models)",
        description="Score a model on trials with known angles (or torques): MSE and RMSE per DoF on the\n"
        "last 10 % of each trial and on all frames, clean and with 1 % / 5 % added noise,\n"
        "beside the classical per-frame solution on the same frames.\n\n"
        "  ikid report --model models/lab-ik.safetensors --data lab_test/ --map lab.toml -o lab.md\n"
        "  ikid report -o docs        # the shipped models' report (needs ikid-training,\n"
        "                             # pip install ./training from a source checkout)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", default="wrist-ik")
    p.add_argument(
        "--data", default=None, metavar="DIR", help="trials: .c3d/.trc with same-stem .mot (and .sto)"
    )
    p.add_argument("--map", metavar="TOML")
    p.add_argument("--resample", action="store_true", help="resample the trials to the model's rate")
    p.add_argument("--clean-only", action="store_true", help="no added noise levels")
    p.add_argument(
        "-o",
        "--output",
        default=None,
        help="Markdown file (+ .json beside it), or a folder (FOLDER/<model name>.md); for the full "
        "report a folder",
    )
    unchecked_option(p)
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("bench", help="latency and throughput of a model on this machine")
    p.add_argument("--model", default="wrist-ik")
    p.add_argument(
        "--frames",
        type=_number(int, ge=1, le=36_000_000),
        default=20000,
        help="frames to push (more than the window; at most 10 hours at 1 kHz)",
    )
    unchecked_option(p)
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser(
        "demo", help="stream a fresh simulated trial through the shipped models", add_help=False
    )
    p.set_defaults(func=None)

    if argv is None:
        argv = sys.argv[1:]
    # SIGINT (Ctrl-C) and SIGTERM (kill) end every command the same way: Stopped raised where
    # the command is, files under way removed on the way out (atomic writes), a line saying so,
    # exit 128 + the signal's number; a batch lists what it did first (ikid._batch).
    with _batch.stop_on_signals(), warnings.catch_warnings():
        warnings.showwarning = _show_warning
        try:
            if argv[:1] == ["demo"]:  # its own options (see `ikid demo --help`)
                from ikid.demo import main as demo

                demo(argv[1:])
                return 0
            args = parser.parse_args(argv)
            args.argv = list(argv)
            return args.func(args)
        except (ikid.IkidError, OSError) as e:
            # What a user can act on (a bad file, option or model; a failed write) is a message naming
            # it; anything else is a bug and keeps its traceback.
            print(f"ikid: error: {_message(e)}", file=sys.stderr)
            return 2
        except _batch.Stopped as stop:
            print(
                f"ikid: stopped by {stop.name}; the outputs under way were not written (any old ones are "
                "as they were)",
                file=sys.stderr,
            )
            return stop.exit_status


if __name__ == "__main__":
    sys.exit(main())
