"""`ikid demo` (`make demo`): the main job end to end on the shipped models.

Simulates a fresh trial (a seed and a shoulder pose no shipped model trained on) on the
rapier wrist model, adds marker noise, streams it frame by frame through the shipped IK
(markers → angles) and chain (markers → torques) models, and through ``ikid.Tracker`` refined
by the shipped ``wrist-track`` (angles, velocities, accelerations and torques in one step:
the README's path for angles and torques), and prints each one's errors against the
simulator's ground truth on the same frames, the classical reference, and the per-frame
latency. Writes a plot if matplotlib is installed.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

import ikid
from ikid.cli.options import SEED, SHOULDER_DEG, _number


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "demo",
        help="stream a fresh simulated trial through the shipped models",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--seed", type=SEED, default=424242, help="trial seed (the shipped models trained on seeds 1000-9004)"
    )
    parser.add_argument("--seconds", type=_number(gt=0, le=36000, unit=" s"), default=20.0)
    parser.add_argument(
        "--shoulder-deg", type=SHOULDER_DEG, default=30.0, help="shoulder flexion (training: 0, 45, -20)"
    )
    parser.add_argument(
        "--noise",
        type=_number(ge=0, le=1),
        default=0.01,
        help="uniform marker noise, fraction of each coordinate's range",
    )
    parser.add_argument("--plot", type=Path, default=Path("out/demo/demo.png"))
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    ik, chain = ikid.load("wrist-ik"), ikid.load("wrist-chain")
    print(
        f"1. simulating {args.seconds:.0f} s of random wrist movement (seed {args.seed}, shoulder "
        f"{args.shoulder_deg:.0f}°) with {100 * args.noise:g} % marker noise"
    )
    t0 = time.perf_counter()
    trial = ikid.simulate(
        "random", seed=args.seed, duration=args.seconds, shoulder_flexion=math.radians(args.shoulder_deg)
    )
    trial = trial.with_noise("uniform", seed=args.seed, fraction=args.noise) if args.noise > 0 else trial
    print(f"   {len(trial.time)} frames at {trial.rate_hz:.0f} Hz in {time.perf_counter() - t0:.1f} s")

    print(
        f"2. streaming frame by frame through {ik.name} ({ik.feature_set} × {ik.window}) and {chain.name} "
        f"({chain.feature_set} × {chain.window})"
    )
    frames = np.ascontiguousarray(trial.markers, np.float32)
    s_ik, s_chain = ik.stream(), chain.stream()
    angles = np.full((len(frames), 3), np.nan)
    torques = np.full((len(frames), 3), np.nan)
    step_ns = np.zeros(len(frames))
    for i, frame in enumerate(frames):
        t = time.perf_counter_ns()
        a = s_ik.push(frame)
        tau = s_chain.push(frame)
        step_ns[i] = time.perf_counter_ns() - t
        if a is not None:
            angles[i] = a
        if tau is not None:
            torques[i] = tau
    ok = slice(max(ik.window, chain.window), None)  # both windows full

    refiner = ikid.load("wrist-track")
    print(
        f"3. the same frames through ikid.Tracker (Kalman filter over the body model) refined by "
        f"{refiner.name} ({refiner.window} states): angles, velocities, accelerations, torques"
    )
    tracker = ikid.Tracker(refiner=refiner, rate_hz=trial.rate_hz)
    tracked_q = np.full((len(frames), 3), np.nan)
    tracked_tau = np.full((len(frames), 3), np.nan)
    track_ns = np.zeros(len(frames))
    for i, frame in enumerate(frames):
        t = time.perf_counter_ns()
        est = tracker.push(frame)
        track_ns[i] = time.perf_counter_ns() - t
        if est is not None:
            tracked_q[i], tracked_tau[i] = est.q, est.tau

    print("4. errors against the simulator's ground truth (same frames)")
    ref = ikid.reference_ik(trial.markers)
    names = ikid.coordinate_names()
    ang_err = np.degrees(angles[ok] - trial.q[ok])
    ref_err = np.degrees(ref[ok] - trial.q[ok])
    tau_err = torques[ok] - trial.tau[ok]
    span = trial.tau[ok].max(0) - trial.tau[ok].min(0)
    print(f"   {'':12s} {'angle RMSE':>11s} {'reference IK':>13s} {'torque RMSE':>12s} {'% of range':>11s}")
    for k, name in enumerate(names):
        print(
            f"   {name:12s} {rms(ang_err[:, k]):9.3f} °  {rms(ref_err[:, k]):9.3f} °  "
            f"{rms(tau_err[:, k]):8.4f} N·m  {100 * rms(tau_err[:, k]) / span[k]:8.2f} %"
        )
    print(
        f"   angle MSE {np.mean(np.radians(ang_err) ** 2):.2e} rad² (reference IK per frame "
        f"{np.mean(np.radians(ref_err) ** 2):.2e}); torque MSE {np.mean(tau_err**2):.2e} N·m² "
        "(thesis chain: 0.1727)"
    )
    trk_err = np.degrees(tracked_q[ok] - trial.q[ok])
    trk_tau = tracked_tau[ok] - trial.tau[ok]
    print(f"   Tracker + {refiner.name}: {'angle RMSE':>11s} {'torque RMSE':>12s} {'% of range':>11s}")
    for k, name in enumerate(names):
        print(
            f"   {name:12s} {rms(trk_err[:, k]):9.3f} °  {rms(trk_tau[:, k]):8.4f} N·m  "
            f"{100 * rms(trk_tau[:, k]) / span[k]:8.2f} %"
        )
    print(
        f"   Tracker + {refiner.name}: angle MSE {np.mean(np.radians(trk_err) ** 2):.2e} rad², torque MSE "
        f"{np.mean(trk_tau**2):.2e} N·m²"
    )
    lat = step_ns[ok] / 1e3
    print(
        f"5. one frame → angles + torques from Python: p50 {np.median(lat):.1f} µs, p99 "
        f"{np.percentile(lat, 99):.1f} µs (budget 2000 µs)"
    )
    lat = track_ns[ok] / 1e3
    print(
        f"   one frame → Tracker + {refiner.name} (angles, velocities, accelerations, torques): p50 "
        f"{np.median(lat):.1f} µs, p99 {np.percentile(lat, 99):.1f} µs"
    )
    plot(args.plot, trial, angles, torques, ok, tracked_q, tracked_tau)
    return 0


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def plot(
    path: Path,
    trial: ikid.Trial,
    angles: np.ndarray,
    torques: np.ndarray,
    ok: slice,
    tracked_q: np.ndarray,
    tracked_tau: np.ndarray,
) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("   (no matplotlib: plot skipped; pip install matplotlib)")
        return
    t = trial.time
    fig, axes = plt.subplots(3, 2, figsize=(11, 6), sharex=True)
    for k, name in enumerate(ikid.coordinate_names()):
        axes[k, 0].plot(t, np.degrees(trial.q[:, k]), "k", lw=1, label="true")
        axes[k, 0].plot(t[ok], np.degrees(angles[ok, k]), "r", lw=0.7, label="wrist-ik")
        axes[k, 0].plot(t[ok], np.degrees(tracked_q[ok, k]), "g", lw=0.7, label="Tracker + wrist-track")
        axes[k, 0].set_ylabel(f"{name} °")
        axes[k, 1].plot(t, trial.tau[:, k], "k", lw=1, label="true")
        axes[k, 1].plot(t[ok], torques[ok, k], "b", lw=0.7, label="wrist-chain")
        axes[k, 1].plot(t[ok], tracked_tau[ok, k], "g", lw=0.7, label="Tracker + wrist-track")
        axes[k, 1].set_ylabel("N·m")
    axes[0, 0].legend(fontsize=8)
    axes[0, 1].legend(fontsize=8)
    axes[2, 0].set_xlabel("time, s")
    axes[2, 1].set_xlabel("time, s")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    print(f"6. plot: {path}")
