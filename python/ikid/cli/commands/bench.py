"""`ikid bench`: a model's push latency and batch throughput on this machine."""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import ikid
from ikid.cli.options import _number, unchecked_option
from ikid.sim import simulate


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="latency and throughput of a model on this machine")
    p.add_argument("--model", default="wrist-ik")
    p.add_argument(
        "--frames",
        type=_number(int, ge=1, le=36_000_000),
        default=20000,
        help="frames to push (more than the window; at most 10 hours at 1 kHz)",
    )
    unchecked_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
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
