"""`ikid ik` and `ikid run`: marker files -> .mot (+ .sto), one file in this process or many in
worker processes (:mod:`ikid.cli.batch`), with --resume."""

from __future__ import annotations

import argparse
import os
import sys
import time
import traceback
from pathlib import Path

import numpy as np

import ikid
from ikid.cli import batch
from ikid.cli.common import (
    _cause,
    _check_uncertainty,
    _file_id,
    _inputs,
    _is_folder,
    _model_file,
    _model_for,
    _named,
    _naming,
    _refuse_over_inputs,
    _stem,
    _subject_calibration,
)
from ikid.cli.options import POSITIVE_INT
from ikid.io._atomic import atomic_outputs, remove_temporaries


def _process_one(job: tuple[str, dict]) -> dict:
    """One marker file -> .mot (and .sto): read, map, check the rate, run, write. In a worker.
    The file is read and its outputs written a block at a time (:func:`ikid.io.open_markers`,
    :func:`ikid.pipeline.run_blocks`), so memory does not grow with its length. The outputs of
    one file replace the old ones together, or none does."""
    from contextlib import ExitStack

    from ikid.calibration import map_with_calibration
    from ikid.forearm_motion import ForearmMotion
    from ikid.io import MarkerMap, mot_writer, open_markers, sto_writer
    from ikid.io.markers import check_markers_seen, seen_markers
    from ikid.pipeline import run_blocks

    path, opt = job
    t0 = time.perf_counter()
    row: dict = {"file": path}
    try:
        data = open_markers(path)
        mapping = map_with_calibration(MarkerMap.load(opt["map"]), opt["calibration"]) if opt["map"] else None
        first = next(data.blocks(), None)
        if first is None:
            raise ikid.InputError(f"{path}: no frames")
        calibration = _subject_calibration(
            first.frames(mapping, whole=False), opt["calibration"], mapping, path
        )
        # Gravity's direction: torque models depend on it (frames come turned into ikid's +Y up).
        up, up_from = first.lab_up(mapping.up if mapping else None)
        runs = {}

        def frames_of_file(motion: ForearmMotion | None = None):
            """The file's (time, frames) blocks; after the last, every marker must have been seen.
            ``motion`` (if given) is fed each block."""
            seen = np.zeros(6, bool)
            for block in data.blocks():
                frames = block.frames(mapping, whole=False)
                seen |= seen_markers(frames)
                if motion is not None:
                    motion.add(block.time, frames)
                yield block.time, frames
            check_markers_seen(seen, mapping or MarkerMap.identity(), path)

        # The torque networks take the forearm at rest: how much it moves is measured and said.
        forearm_motion = ForearmMotion()

        # Coordinates the markers do not determine (a one-marker hand's s_p): not written.
        undetermined = mapping.undetermined if mapping else {}
        writers = {"angles": (mot_writer, 0), "torques": (sto_writer, 1)}
        with_sd = bool(opt.get("sd"))
        #: Rows not written for want of a standard deviation (--sd), per kind.
        no_sd = {"angles": 0, "torques": 0}
        with atomic_outputs() as written, ExitStack() as files:
            for kind, name in (("angles", opt["ik_model"]), ("torques", opt.get("torque_model"))):
                if not name:
                    continue
                make, k = writers[kind]
                write = files.enter_context(
                    make(opt["outputs"][k], undetermined=undetermined, with_sd=with_sd)
                )

                def to_file(_frames, t, values, status, sd, write=write, kind=kind) -> None:
                    if not with_sd:
                        write(t, values, status)
                        return
                    # A row whose σ is not known (the first frames after the window restarted)
                    # is counted, not written with a made-up one.
                    known = np.all(np.isfinite(sd), axis=1)
                    no_sd[kind] += int(np.count_nonzero(~known))
                    write(t[known], values[known], status[known], sd[known])

                # A shipped family name (the default wrist-ik) runs its model for the file's rate
                # (ikid.pipeline.pick_model); a file or a per-rate name is that model.
                runs[kind] = run_blocks(
                    name,
                    frames_of_file(forearm_motion if kind == "torques" else None),
                    rate_hz=data.rate_hz,
                    n_frames=data.n_frames,
                    resample_to_model=opt["resample"],
                    missing_markers=opt["missing_markers"],
                    calibration=calibration,
                    source=path,
                    progress=opt["progress"],
                    allow_unchecked=opt["allow_unchecked"],
                    on_rows=to_file,
                )
                if runs[kind].n_outputs == 0:
                    # A window that never filled (time gaps closer than it, review 7: every 40th
                    # frame dropped) said only "window filling": say what does read such a file.
                    unfilled = set(runs[kind].refused) == {"window filling"}
                    advice = (
                        "; the model's window never filled between the file's time gaps (rows missing "
                        "from its time column, closer together than the window): `ikid ik` gives the "
                        "angles (per frame where its window cannot fill); a recording without dropped "
                        "frames gives both"
                        if unfilled
                        else ""
                    )
                    raise ikid.InputError(f"{path}: no frame gave {kind}: {runs[kind].summary()}{advice}")
        first_run = next(iter(runs.values()))
        carried = forearm_motion.note() if "torques" in runs else None
        row.update(
            clean=all(r.clean for r in runs.values()),
            ok=True,
            frames=data.n_frames,
            rate_hz=data.rate_hz,
            summary="; ".join(
                [first_run.summary()]
                + [f"{kind}: {r.summary()}" for kind, r in list(runs.items())[1:]]
                + ([f"torques with lab up {up} ({up_from})"] if "torques" in runs else [])
                + ([carried] if carried else [])
                + [f"{name} not written: {why}" for name, why in undetermined.items()]
                + [
                    f"{n} {kind} rows without a standard deviation (the first frames after the window "
                    "(re)started), not written"
                    for kind, n in no_sd.items()
                    if n
                ]
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


def process_files(args: argparse.Namespace) -> int:
    """`ik` and `run`: marker files -> .mot (+ .sto), one file or many in parallel (see
    :mod:`ikid.cli.batch`: results printed as each file ends; a worker that dies fails its file
    only; SIGINT/SIGTERM stop every worker and list the files done and not done)."""
    inputs = _inputs(args.inputs)
    many = len(inputs) > 1 or any(Path(p).is_dir() for p in args.inputs)
    torque_model = getattr(args, "torque_model", None)
    # The models' cards against what the command writes, once, before any file is read.
    unchecked = args.allow_unchecked_model
    ik_model = _model_for(args.model, f"ikid {args.command} --model", ("ik",), allow_unchecked=unchecked)
    if args.sd:
        _check_uncertainty(args.model, ik_model, f"ikid {args.command} --sd --model")
    if torque_model:
        chain = _model_for(
            torque_model, f"ikid {args.command} --torque-model", ("chain",), allow_unchecked=unchecked
        )
        if args.sd:
            _check_uncertainty(torque_model, chain, f"ikid {args.command} --sd --torque-model")
    stems = [p.stem for p in inputs]
    clash = sorted({s for s in stems if stems.count(s) > 1})
    if many and clash:
        named = "; ".join(", ".join(str(p) for p in inputs if p.stem == c) for c in clash[:3])
        raise ikid.ArgumentError(
            f"several inputs are named {', '.join(clash)} ({named}); their outputs would overwrite each "
            "other: give one of each, or move the others elsewhere"
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
            "sd": args.sd,
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
        outcome = batch.Outcome()
    else:
        outcome = batch.run_jobs(_process_one, jobs, args.jobs or os.cpu_count() or 1, report, died)
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
        help="resample markers to the model's rate (cubic Hermite; output rows at the model's rate; a gap at "
        "the file's start is not filled from the motion after it on this path)",
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
    p.add_argument(
        "--sd",
        action="store_true",
        help="follow each angle (torque) by its standard deviation, <name>_sd, listed in the header's "
        "ikid_sd line: the model card's uncertainty (studies/net_sigma.py fits it and measures how well it "
        "covers). Rows whose σ is not yet known (the first frames after the window restarts) are not "
        "written; the summary counts them",
    )
