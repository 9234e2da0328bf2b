"""`make demo`: the whole path on a small scale, in well under a minute.

1. Simulate random multi-DoF wrist movements on the rapier model (``ikid.simulate``) at the
   thesis' three shoulder poses and a few subject sizes: markers with exact angles.
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


def windows(features: np.ndarray) -> np.ndarray:
    idx = np.arange(len(features) - WINDOW + 1)[:, None] + np.arange(WINDOW)
    return features[idx].reshape(len(idx), -1)


def make_dataset(seconds: float, shoulders_deg: list[float]):
    xs, ys = [], []
    for k, shoulder in enumerate(shoulders_deg):
        trial = ikid.simulate("random", seed=100 + k, duration=seconds, shoulder_flexion=np.radians(shoulder),
                              length_scale=(0.9, 1.0, 1.1)[k % 3])
        xs.append(windows(ikid.compute_features(trial.markers, "relative")))
        ys.append(trial.q[WINDOW - 1 :])
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
    print("1. simulating 3 shoulder poses x 40 s at 1 kHz (rapier)")
    x, y = make_dataset(40.0, [0.0, 45.0, -20.0])
    print(f"   {len(x)} windows of {x.shape[1]} features")
    print(f"2. training a {x.shape[1]}-128-128-3 MLP for {args.train_seconds:.0f} s")
    net, inp, out = train(x, y, args.train_seconds, seed=0)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "demo-ik.safetensors"
    spec = ModelSpec(
        name="demo-ik", task="ik", feature_set="relative", window=WINDOW, frame_rate_hz=RATE_HZ,
        scaling={"input": "minmax(-1,1)", "output": "minmax(-1,1)"},
        provenance={"simulator": ikid.SIMULATOR, "protocol": "random", "seeds": [100, 101, 102]},
    )
    model = export(net, path, spec, inp, out)
    print(f"   exported {path} ({path.stat().st_size / 1024:.0f} KiB): {model!r}")

    print("3. streaming a fresh simulated trial: seed 999, shoulder 30 deg, subject 1.15x size")
    trial = ikid.simulate("random", seed=999, duration=10.0, shoulder_flexion=np.radians(30.0), length_scale=1.15)
    q = trial.q
    markers = trial.markers.astype(np.float32)
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
    ref = ikid.reference_ik(trial.markers, length_scale=1.15)
    print(f"   classical reference IK (segment fit) on the same clean frames: MSE {np.mean((ref - q) ** 2):.1e} rad^2")


if __name__ == "__main__":
    main()
