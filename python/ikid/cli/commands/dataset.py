"""`ikid dataset`: the thesis-sized and the richer simulated datasets."""

from __future__ import annotations

import argparse
import json
import math
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from ikid.cli.options import COUNT, POSITIVE, POSITIVE_INT
from ikid.io._atomic import write_text_atomic
from ikid.sim import simulate


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("dataset", help="write the thesis-sized and the richer simulated datasets")
    p.add_argument("-o", "--output", required=True)
    p.add_argument(
        "--random-trials", type=COUNT, default=18, help="random multi-DoF trials (3 poses x 3 sizes x ...)"
    )
    p.add_argument("--duration", type=POSITIVE, default=60.0, help="seconds per random trial")
    p.add_argument("--jobs", type=POSITIVE_INT, default=None, help="threads (default: all cores)")
    p.set_defaults(func=run)


#: The thesis' shoulder flexion angles, degrees.
THESIS_SHOULDERS_DEG = (0.0, 45.0, -20.0)


def run(args: argparse.Namespace) -> int:
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
