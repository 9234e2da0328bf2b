"""`make demo`: the whole path on a small scale, in well under a minute.

1. Make wrist-angle trajectories (smooth random multi-DoF reaches, minimum-jerk) and turn
   them into marker frames with the body model's forward kinematics (``ikid.forward_markers``);
   the rapier simulator will replace this with dynamics and torques.
2. Train a small MLP on 5-frame windows of the shoulder-pose-invariant ``relative`` features
   (computed by the Rust core, as at inference), export it with the project's exporter.
3. Stream a fresh trial (another seed, a shoulder pose and subject size not trained on)
   through the exported model frame by frame; print the angle errors and per-frame latency.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

import ikid
from training.export import Affine, ModelSpec, export

WINDOW = 5
RATE_HZ = 1000.0


def min_jerk_trajectory(rng: np.random.Generator, seconds: float) -> np.ndarray:
    """Angles ``(n, 3)`` moving between random targets within each coordinate's range."""
    ranges = np.array([c[2] for c in ikid.COORDINATES])
    n = int(seconds * RATE_HZ)
    q = np.zeros((n, 3))
    start, t = np.zeros(3), 0
    while t < n:
        duration = int(rng.uniform(0.25, 0.8) * RATE_HZ)
        target = rng.uniform(ranges[:, 0], ranges[:, 1]) * (rng.random(3) < 0.8)
        s = np.linspace(0, 1, duration)[:, None]
        profile = 10 * s**3 - 15 * s**4 + 6 * s**5
        seg = start + (target - start) * profile
        q[t : t + duration] = seg[: n - t]
        start, t = target, t + duration
    return q


def windows(features: np.ndarray) -> np.ndarray:
    idx = np.arange(len(features) - WINDOW + 1)[:, None] + np.arange(WINDOW)
    return features[idx].reshape(len(idx), -1)


def make_dataset(rng: np.random.Generator, seconds: float, shoulders_deg: list[float]):
    xs, ys = [], []
    for shoulder in shoulders_deg:
        q = min_jerk_trajectory(rng, seconds)
        markers = ikid.forward_markers(q, np.radians(shoulder), length_scale=rng.uniform(0.9, 1.1))
        xs.append(windows(ikid.compute_features(markers, "relative")))
        ys.append(q[WINDOW - 1 :])
    return np.concatenate(xs).astype(np.float32), np.concatenate(ys).astype(np.float32)


def train(x: np.ndarray, y: np.ndarray, seconds: float, seed: int) -> tuple[nn.Module, Affine, Affine]:
    torch.manual_seed(seed)
    inp = Affine.minmax(x.min(0), x.max(0))
    out_fwd = Affine.minmax(y.min(0), y.max(0))
    xs = torch.as_tensor(x * inp.scale + inp.shift)
    ys = torch.as_tensor(y * out_fwd.scale + out_fwd.shift)
    net = nn.Sequential(nn.Linear(x.shape[1], 128), nn.ReLU(), nn.Linear(128, 128), nn.ReLU(), nn.Linear(128, 3))
    opt = torch.optim.Adam(net.parameters(), lr=2e-3)
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=6, gamma=0.5)
    start, epoch = time.perf_counter(), 0
    while time.perf_counter() - start < seconds:
        perm = torch.randperm(len(xs))
        for i in range(0, len(xs), 256):
            b = perm[i : i + 256]
            loss = nn.functional.mse_loss(net(xs[b]), ys[b])
            opt.zero_grad()
            loss.backward()
            opt.step()
        sched.step()
        epoch += 1
        print(f"  epoch {epoch:2d}  train loss {loss.item():.2e} (scaled)  {time.perf_counter() - start:4.1f} s", flush=True)
    return net.eval(), inp, out_fwd.inverse()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("out/demo"), help="where the model files go")
    parser.add_argument("--train-seconds", type=float, default=20.0, help="wall-clock training budget")
    args = parser.parse_args()
    torch.set_num_threads(2)
    rng = np.random.default_rng(0)

    print("1. trajectories -> markers (3 shoulder poses x 40 s at 1 kHz)")
    x, y = make_dataset(rng, 40.0, [0.0, 45.0, -20.0])
    print(f"   {len(x)} windows of {x.shape[1]} features")
    print(f"2. training a {x.shape[1]}-128-128-3 MLP for {args.train_seconds:.0f} s")
    net, inp, out = train(x, y, args.train_seconds, seed=0)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "demo-ik.safetensors"
    spec = ModelSpec(
        name="demo-ik", task="ik", feature_set="relative", window=WINDOW, frame_rate_hz=RATE_HZ,
        scaling={"input": "minmax(-1,1)", "output": "minmax(-1,1)"},
        provenance={"generator": "training.demo min-jerk + forward kinematics", "seed": 0},
    )
    model = export(net, path, spec, inp, out)
    print(f"   exported {path} ({path.stat().st_size / 1024:.0f} KiB): {model!r}")

    print("3. streaming a fresh trial: seed 1, shoulder 30 deg, subject 1.15x size")
    q = min_jerk_trajectory(np.random.default_rng(1), 10.0)
    markers = ikid.forward_markers(q, np.radians(30.0), length_scale=1.15).astype(np.float32)
    stream = model.stream()
    preds, times = [], []
    for frame in markers:
        t0 = time.perf_counter_ns()
        o = stream.push(frame)
        times.append(time.perf_counter_ns() - t0)
        if o is not None:
            preds.append(o)
    err = np.degrees(np.stack(preds) - q[WINDOW - 1 :])
    rmse = np.sqrt((err**2).mean(0))
    mse = (np.radians(err) ** 2).mean()
    lat = np.array(times[WINDOW:]) / 1000
    for name, r in zip(model.output_names, rmse):
        print(f"   {name:12s} RMSE {r:5.2f} deg")
    print(f"   all angles    MSE {mse:.2e} rad^2 over {len(preds)} frames")
    print(f"   Stream.push from Python: p50 {np.median(lat):.1f} us, p99 {np.percentile(lat, 99):.1f} us per frame")


if __name__ == "__main__":
    main()
