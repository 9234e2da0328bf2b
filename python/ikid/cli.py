"""The ``ikid`` command line.

Examples::

    ikid ik trial.c3d -o trial.mot --map lab.toml          # markers -> wrist angles (OpenSim .mot)
    ikid run trial.trc -o out/trial                          # -> out/trial.mot + out/trial.sto (torques)
    ikid ik sessions/ -o results/ --map lab.toml --resample  # a folder, in parallel, with a summary
    ikid map-template trial.c3d > lab.toml                   # start a marker map from a file's labels
    ikid calibrate --static st.c3d --movement ra_wr_e_f=fe.c3d --movement ra_wr_s_p=ps.c3d -o s01.json
    ikid ik trial.c3d -o trial.mot --calibration s01.json    # the subject's own marker placement
    ikid simulate --protocol thesis --shoulder-deg 45 -o data/thesis_s45
    ikid simulate --protocol random --seed 3 --duration 60 --noise uniform:0.01 -o data/r3
    ikid dataset -o data            # thesis-sized set + the richer random set, in parallel
    ikid demo                       # a fresh trial through the shipped models, errors + latency
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

import ikid
from ikid.sim import Trial, simulate

#: The thesis' shoulder flexion angles, degrees.
THESIS_SHOULDERS_DEG = (0.0, 45.0, -20.0)


def _noise(spec: str) -> tuple[str, dict]:
    """``uniform:0.01``, ``gaussian:0.002`` (m), ``drift:0.005`` (m), ``occlusion:0.5`` (bursts/s)."""
    kind, _, value = spec.partition(":")
    try:
        v = float(value)
    except ValueError:
        raise SystemExit(f"--noise {spec!r}: expected KIND:NUMBER, e.g. uniform:0.01") from None
    params = {"uniform": {"fraction": v}, "gaussian": {"sigma": v}, "drift": {"amplitude": v, "rate_hz": 0.0},
              "occlusion": {"bursts_per_second": v, "min_s": 0.05, "max_s": 0.3, "rate_hz": 0.0}}
    if kind not in params:
        raise SystemExit(f"--noise {spec!r}: unknown kind {kind!r} (uniform, gaussian, drift, occlusion)")
    return kind, params[kind]


def _with_noise(trial: Trial, specs: list[str], seed: int) -> Trial:
    for k, spec in enumerate(specs):
        kind, params = _noise(spec)
        if "rate_hz" in params:
            params["rate_hz"] = trial.rate_hz
        trial = trial.with_noise(kind, seed * 1000 + k + 1, **params)
    return trial


def cmd_simulate(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    trial = simulate(args.protocol, seed=args.seed, duration=args.duration, shoulder_flexion=math.radians(args.shoulder_deg),
                     length_scale=args.length_scale, mass_scale=args.mass_scale, dt=1.0 / args.rate)
    trial = _with_noise(trial, args.noise, args.seed)
    paths = trial.save(args.output)
    elapsed = time.perf_counter() - t0
    print(f"{len(trial.time)} frames ({trial.time[-1]:.1f} s) in {elapsed:.2f} s -> " + ", ".join(map(str, paths)))
    return 0


def cmd_dataset(args: argparse.Namespace) -> int:
    """The thesis-sized set (3 shoulder poses x 42 movements) and the richer random set."""
    jobs = [(f"thesis_s{int(s):+d}", dict(protocol="thesis", shoulder_flexion=math.radians(s))) for s in THESIS_SHOULDERS_DEG]
    for k in range(args.random_trials):
        shoulder = THESIS_SHOULDERS_DEG[k % 3]
        scale = (0.85, 1.0, 1.15)[(k // 3) % 3]
        jobs.append((f"random_{k:03d}_s{int(shoulder):+d}_x{scale:.2f}",
                     dict(protocol="random", seed=1000 + k, duration=args.duration, shoulder_flexion=math.radians(shoulder),
                          length_scale=scale, mass_scale=scale**3)))
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
    summary = {"trials": len(results), "frames": frames, "seconds_simulated": frames / 1000.0, "wall_s": round(elapsed, 2),
               "simulation_x_real_time_per_core": round(frames / 1000.0 / sim_s, 1),
               "with_file_writing_x_real_time": round(frames / 1000.0 / elapsed, 1)}
    (out / "dataset.json").write_text(json.dumps({"summary": summary, "trials": [r[0] for r in results]}, indent=1))
    print(json.dumps(summary))
    return 0


def _inputs(paths: list[str]) -> list[Path]:
    """Marker files named, or found (by suffix) in named folders."""
    from ikid.io import MARKER_READERS

    found: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found += sorted(f for f in p.iterdir() if f.suffix.lower() in MARKER_READERS and f.is_file())
        elif p.exists():
            found.append(p)
        else:
            raise SystemExit(f"ikid: error: {p}: no such file or folder")
    if not found:
        raise SystemExit(f"ikid: error: no marker files ({', '.join(MARKER_READERS)}) in {', '.join(paths)}")
    return found


def _process_one(job: tuple[str, dict]) -> dict:
    """One marker file -> .mot (and .sto): read, map, check the rate, run, write. In a worker."""
    from ikid.io import MarkerMap, read_markers, write_mot, write_sto
    from ikid.pipeline import run_model

    path, opt = job
    t0 = time.perf_counter()
    row: dict = {"file": path}
    try:
        data = read_markers(path)
        mapping = MarkerMap.load(opt["map"]) if opt["map"] else None
        frames = data.frames(mapping)
        calibration = ikid.load_calibration(opt["calibration"]) if opt["calibration"] else None
        runs = {}
        for kind, name in (("angles", opt["ik_model"]), ("torques", opt.get("torque_model"))):
            if name:
                runs[kind] = run_model(ikid.load(name), frames, data.time, rate_hz=data.rate_hz, resample_to_model=opt["resample"],
                                       missing_markers=opt["missing_markers"], calibration=calibration, source=path,
                                       progress=opt["progress"])
        written = []
        for kind, r in runs.items():
            if len(r.time) == 0:
                raise ikid.InputError(f"{path}: no frame gave {kind}: {r.summary()}")
        if "angles" in runs:
            written.append(str(write_mot(opt["outputs"][0], runs["angles"].time, runs["angles"].values)))
        if "torques" in runs:
            written.append(str(write_sto(opt["outputs"][1], runs["torques"].time, runs["torques"].values)))
        first = next(iter(runs.values()))
        row.update(ok=True, frames=len(data), rate_hz=data.rate_hz, summary=first.summary(), written=written)
    except (ikid.IkidError, OSError) as e:
        row.update(ok=False, error=str(e))
    row["seconds"] = round(time.perf_counter() - t0, 3)
    return row


def cmd_process(args: argparse.Namespace) -> int:
    """`ik` and `run`: marker files -> .mot (+ .sto), one file or many in parallel."""
    from concurrent.futures import ProcessPoolExecutor

    inputs = _inputs(args.inputs)
    out = Path(args.output)
    many = len(inputs) > 1 or any(Path(p).is_dir() for p in args.inputs)
    torque_model = getattr(args, "torque_model", None)
    stems = [p.stem for p in inputs]
    clash = sorted({s for s in stems if stems.count(s) > 1})
    if many and clash:
        raise SystemExit(f"ikid: error: several inputs are named {', '.join(clash)}; their outputs would overwrite each other")
    jobs = []
    for path in inputs:
        if many:
            out.mkdir(parents=True, exist_ok=True)
            stem = out / path.stem
        else:
            stem = out.with_suffix("") if out.suffix.lower() in (".mot", ".sto") else out
            stem.parent.mkdir(parents=True, exist_ok=True)
        mot = out if (not many and out.suffix.lower() == ".mot") else stem.with_name(stem.name + ".mot")
        opt = {"map": args.map, "ik_model": args.model, "torque_model": torque_model, "resample": args.resample,
               "missing_markers": args.missing_markers, "progress": not many, "calibration": args.calibration,
               "outputs": (mot, stem.with_name(stem.name + ".sto"))}
        jobs.append((str(path), opt))
    if len(jobs) == 1:
        rows = [_process_one(jobs[0])]
    else:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            rows = list(pool.map(_process_one, jobs))
    for row in rows:
        if row["ok"]:
            print(f"{row['file']}: {row['summary']} ({row['seconds']:.2f} s) -> {', '.join(row['written'])}")
        else:
            print(f"ikid: error: {row['error']}", file=sys.stderr)
    if many:
        ok = sum(r["ok"] for r in rows)
        print(f"{ok}/{len(rows)} files processed, {len(rows) - ok} failed")
    return 0 if all(r["ok"] for r in rows) else 2


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Static + single-coordinate movement files -> a calibration JSON."""
    from ikid.io import MarkerMap, read_markers

    mapping = MarkerMap.load(args.map) if args.map else None
    movements = {}
    for spec in args.movement:
        coord, sep, path = spec.partition("=")
        if not sep or coord not in ikid.coordinate_names():
            raise SystemExit(f"ikid: error: --movement {spec!r}: expected COORDINATE=FILE, COORDINATE one of {', '.join(ikid.coordinate_names())}")
        movements[coord] = read_markers(path).frames(mapping)
    cal = ikid.calibrate(read_markers(args.static).frames(mapping), movements)
    ikid.save_calibration(cal, args.output, static=args.static, movements=dict(s.partition("=")[::2] for s in args.movement))
    r = cal.report or {}
    moves = ", ".join(f"{k} {v['range_deg']:.0f}° ({100 * v['single_axis_share']:.1f} % one axis)" for k, v in r.get("movements", {}).items())
    print(f"{cal!r}; movements: {moves}; axis skew {r.get('axis_skew_deg', 0):.2f}° -> {args.output}")
    return 0


def cmd_map_template(args: argparse.Namespace) -> int:
    from ikid.io import MarkerMap, read_markers

    text = MarkerMap.identity().to_toml()
    if args.input:
        labels = read_markers(args.input).labels
        text = f"# labels in {args.input}: {', '.join(labels)}\n" + text
    print(text, end="")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ikid", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"ikid {ikid.__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("simulate", help="simulate one trial and write .npz/.trc/.mot/.sto")
    p.add_argument("--protocol", choices=["thesis", "random"], default="random")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=10.0, help="seconds (random protocol)")
    p.add_argument("--shoulder-deg", type=float, default=0.0, help="shoulder flexion, degrees")
    p.add_argument("--length-scale", type=float, default=1.0)
    p.add_argument("--mass-scale", type=float, default=1.0)
    p.add_argument("--rate", type=float, default=1000.0, help="physics and output rate, Hz")
    p.add_argument("--noise", action="append", default=[], metavar="KIND:VALUE",
                   help="uniform:0.01 | gaussian:0.002 | drift:0.005 | occlusion:0.5 (repeatable)")
    p.add_argument("-o", "--output", required=True, help="output stem (writes STEM.npz, .trc, .mot, .sto)")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("dataset", help="write the thesis-sized and the richer simulated datasets")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--random-trials", type=int, default=18, help="random multi-DoF trials (3 poses x 3 sizes x ...)")
    p.add_argument("--duration", type=float, default=60.0, help="seconds per random trial")
    p.add_argument("--jobs", type=int, default=None, help="threads (default: all cores)")
    p.set_defaults(func=cmd_dataset)

    def processing_options(p: argparse.ArgumentParser, model_help: str) -> None:
        p.add_argument("inputs", nargs="+", metavar="IN", help="marker files (.c3d, .trc) or folders of them")
        p.add_argument("-o", "--output", required=True, help="output file (one input) or folder (several)")
        p.add_argument("--model", default="wrist-ik", help=model_help)
        p.add_argument("--map", metavar="TOML", help="marker map: which label is which ikid marker (see map-template)")
        p.add_argument("--resample", action="store_true",
                       help="resample markers to the model's rate (cubic Hermite; output rows at the model's rate)")
        p.add_argument("--missing-markers", choices=["fill", "refuse"], default=None, help="override the model's policy")
        p.add_argument("--calibration", metavar="JSON", help="the subject's marker placement (see `ikid calibrate`)")
        p.add_argument("--jobs", type=int, default=None, help="parallel files (default: all cores)")

    p = sub.add_parser("ik", help="markers (.c3d/.trc) -> wrist angles (.mot, degrees)",
                       description="Markers -> wrist angles.\n\n  ikid ik trial.c3d -o trial.mot --map lab.toml\n"
                                   "  ikid ik sessions/ -o results/ --resample", formatter_class=argparse.RawDescriptionHelpFormatter)
    processing_options(p, "angle model, shipped name or file (default wrist-ik)")
    p.set_defaults(func=cmd_process)

    p = sub.add_parser("run", help="markers -> wrist angles (.mot) and torques (.sto)",
                       description="Markers -> angles and torques.\n\n  ikid run trial.c3d -o out/trial   # out/trial.mot, out/trial.sto",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    processing_options(p, "angle model (default wrist-ik)")
    p.add_argument("--torque-model", default="wrist-chain", help="markers -> torques model (default wrist-chain)")
    p.set_defaults(func=cmd_process)

    p = sub.add_parser("calibrate", help="measure a subject's marker placement (static + single-coordinate movements)",
                       description="Static neutral trial + movements of one coordinate each -> calibration JSON.\n\n"
                                   "  ikid calibrate --static s01_static.c3d --movement ra_wr_e_f=s01_flex.c3d \\\n"
                                   "      --movement ra_wr_s_p=s01_pron.c3d --map lab.toml -o s01.json\n"
                                   "  ikid ik s01_task.c3d -o s01_task.mot --map lab.toml --calibration s01.json",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--static", required=True, help="marker file of the neutral pose held still")
    p.add_argument("--movement", action="append", default=[], metavar="COORD=FILE", required=True,
                   help="a movement of that coordinate alone (at least two coordinates)")
    p.add_argument("--map", metavar="TOML", help="marker map (see map-template)")
    p.add_argument("-o", "--output", required=True, help="calibration JSON to write")
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("map-template", help="print a marker map (TOML) to fill in, listing a file's labels")
    p.add_argument("input", nargs="?", help="a .c3d/.trc whose labels to list")
    p.set_defaults(func=cmd_map_template)

    p = sub.add_parser("demo", help="stream a fresh simulated trial through the shipped models", add_help=False)
    p.set_defaults(func=None)

    if argv is None:
        argv = sys.argv[1:]
    if argv[:1] == ["demo"]:  # its own options (see `ikid demo --help`)
        from ikid.demo import main as demo

        demo(argv[1:])
        return 0
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ikid.IkidError as e:
        print(f"ikid: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
