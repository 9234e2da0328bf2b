"""A wrist dataset made by a different generator than ikid's: OpenSim's kinematics and dynamics
of an exported model with a lab's own marker set, driven by a trajectory generator of its own.

    python examples/opensim_dataset.py --out data/opensim --trials 6 --duration 20 --seed 0
    ikid train --data data/opensim --map data/opensim/map.toml ...

What differs from ikid's simulator, on purpose:

* **markers**: other labels (``R_RSTY R_USTY R_FARM R_MCP2 R_MCP5 R_HAND``), written in another
  order, each placed 5-20 mm from ikid's default (a fixed, seeded "lab placement", the same in
  every trial), plus an elbow marker (``R_LEPI``) that ikid does not use;
* **motion**: each coordinate is a sum of random sinusoids (0.1-1.5 Hz), scaled to sweep 95 % of
  its range about the range's middle: not ikid's min-jerk protocol, not rapier;
* **positions and torques**: OpenSim's forward kinematics of the ``.osim`` and its
  ``InverseDynamicsSolver`` (analytic velocities and accelerations of the sinusoids).

Per trial (``osim_000`` ...): ``.trc`` (mm), ``.mot`` (degrees), ``.sto`` (N·m, unless
``--no-torques``) and the ``.osim`` it came from (opens with the ``.trc`` in OpenSim);
``map.toml`` (ikid marker = the lab label, for ``--map``) and ``dataset.json`` (how each trial
was made). Subjects: length 0.9-1.1× the default (mass ∝ length³), shoulder 0°, 45°, −20° in turn.
Needs the ``opensim`` package (``pip install 'ikid[eval]'``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

import ikid
from ikid import io
from ikid.interop import opensim as ios

#: The lab's label for each ikid marker, and the order the lab's files list them in.
LAB_LABELS = {
    "RSP": "R_RSTY",
    "USP": "R_USTY",
    "FAP": "R_FARM",
    "MC2": "R_MCP2",
    "MC5": "R_MCP5",
    "MCB": "R_HAND",
}
FILE_ORDER = ["R_MCP2", "R_MCP5", "R_HAND", "R_LEPI", "R_RSTY", "R_USTY", "R_FARM"]
#: Seed of the lab's marker placement (fixed: one lab, one placement, whatever --seed).
PLACEMENT_SEED = 20_261_123
SHOULDERS_DEG = [0.0, 45.0, -20.0]
SINES = 4  # per coordinate
FREQ_HZ = (0.1, 1.5)
SWEEP = 0.95  # fraction of each coordinate's range the motion spans


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--out", required=True, type=Path, help="folder to write the trials into (created)")
    ap.add_argument("--trials", type=int, default=6, help="number of trials (default 6)")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per trial (default 20)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the motions and subjects (default 0)")
    ap.add_argument(
        "--rate", type=float, default=1000.0, help="frame rate, Hz (default 1000, the shipped models' rate)"
    )
    ap.add_argument(
        "--no-torques", action="store_true", help="skip the .sto torques (OpenSim inverse dynamics)"
    )
    args = ap.parse_args(argv)
    for what, v in (("--trials", args.trials), ("--duration", args.duration), ("--rate", args.rate)):
        if not (v > 0 and math.isfinite(v)):
            ap.error(f"{what} must be positive, got {v}")
    n = int(round(args.duration * args.rate))
    if n < 2:
        ap.error(f"--duration {args.duration} s at --rate {args.rate} Hz is fewer than 2 frames")

    osim = ios.require_opensim()
    osim.Logger.removeFileSink()  # no opensim.log in the working directory
    osim.Logger.setLevelString("warn")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "map.toml").write_text(io.MarkerMap(dict(LAB_LABELS), "opensim_dataset").to_toml())
    rng = np.random.default_rng(args.seed)
    t = np.arange(n) / args.rate
    manifest: dict = {
        "generator": (
            "examples/opensim_dataset.py: sums of random sinusoids, "
            "OpenSim forward kinematics and inverse dynamics"
        ),
        "opensim": osim.GetVersionAndDate(),
        "seed": args.seed,
        "rate_hz": args.rate,
        "placement_seed": PLACEMENT_SEED,
        "markers": FILE_ORDER,
        "trials": [],
    }
    for k in range(args.trials):
        name = f"osim_{k:03d}"
        start = time.perf_counter()
        length_scale = float(rng.uniform(0.9, 1.1))
        shoulder_deg = SHOULDERS_DEG[k % len(SHOULDERS_DEG)]
        subject = {
            "length_scale": length_scale,
            "mass_scale": length_scale**3,
            "shoulder_flexion": math.radians(shoulder_deg),
        }
        placement = lab_markers(length_scale)
        model = ios.write_osim(args.out / f"{name}.osim", markers=placement, name=name, **subject)
        q, qd, qdd, sines = motion(t, rng)
        markers = ios.marker_positions(model, q)  # (n, 3 * 7), the model's marker order
        model_order = [lab for lab, _, _ in placement]
        cols = np.concatenate(
            [np.arange(3 * model_order.index(lab), 3 * model_order.index(lab) + 3) for lab in FILE_ORDER]
        )
        io.write_trc(args.out / f"{name}.trc", t, markers[:, cols], rate_hz=args.rate, labels=FILE_ORDER)
        io.write_mot(args.out / f"{name}.mot", t, q)
        if not args.no_torques:
            io.write_sto(args.out / f"{name}.sto", t, ios.inverse_dynamics(model, q, qd, qdd))
        manifest["trials"].append(
            {"name": name, **subject, "shoulder_deg": shoulder_deg, "frames": n, "sines": sines}
        )
        print(
            f"{name}: {n} frames, length x{length_scale:.3f}, shoulder {shoulder_deg:+.0f} deg "
            f"({time.perf_counter() - start:.1f} s)"
        )
    (args.out / "dataset.json").write_text(json.dumps(manifest, indent=1))
    print(f"wrote {args.trials} trials to {args.out} (markers mapped by {args.out / 'map.toml'})")
    return 0


def lab_markers(length_scale: float) -> list[tuple[str, str, list[float]]]:
    """The lab's marker set on a subject: ikid's six (scaled with the subject) each moved 5-20 mm
    in a seeded direction, relabelled, plus the lateral epicondyle at the elbow."""
    body = ikid.body_model(length_scale=length_scale)
    rng = np.random.default_rng(PLACEMENT_SEED)
    out = []
    for m in body["markers"]:
        direction = rng.normal(size=3)
        shift = rng.uniform(0.005, 0.020) * direction / np.linalg.norm(direction)
        out.append((LAB_LABELS[m["name"]], m["segment"], list(np.add(m["offset"], shift))))
    # Forearm frame: y proximal, z radial; the elbow is one forearm length up the long axis.
    out.append(("R_LEPI", "forearm", [0.0, body["segments"]["forearm"]["length"], 0.035]))
    return out


def motion(t: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    """Angles, velocities and accelerations (analytic) of random sinusoid sums, one per
    coordinate, sweeping ``SWEEP`` of its range about the range's middle."""
    coords = ikid.body_model()["coordinates"]
    q, qd, qdd = (np.empty((len(t), len(coords))) for _ in range(3))
    params = []
    for j, c in enumerate(coords):
        lo, hi = c["range"]
        f = rng.uniform(*FREQ_HZ, SINES)
        a = rng.uniform(0.2, 1.0, SINES)
        phase = rng.uniform(0, 2 * np.pi, SINES)
        w = 2 * np.pi * f
        arg = np.outer(t, w) + phase
        s = np.sin(arg) @ a
        peak = np.abs(s - s.mean()).max()
        # Scale so the motion spans SWEEP of the range: q = mid + k (s - mean(s)).
        k = SWEEP * (hi - lo) / 2 / peak
        q[:, j] = (lo + hi) / 2 + k * (s - s.mean())
        qd[:, j] = k * (np.cos(arg) @ (a * w))
        qdd[:, j] = -k * (np.sin(arg) @ (a * w**2))
        params.append(
            {
                "coordinate": c["name"],
                "freq_hz": f.tolist(),
                "amplitude": (k * a).tolist(),
                "phase": phase.tolist(),
                "offset": (lo + hi) / 2 - k * s.mean(),
            }
        )
    return q, qd, qdd, params


if __name__ == "__main__":
    sys.exit(main())
