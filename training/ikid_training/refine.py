"""`python -m ikid_training.refine`: train the Tracker's refiner, shipped as ``wrist-track``
(1 kHz) and, with ``--rate 100`` / ``--rate 250``, ``wrist-track-100hz`` / ``wrist-track-250hz``:
the same data sampled at that rate (the simulator's 1 kHz frames kept every k-th), the tracker
run at it, a window of the same duration (~0.1 s). Only ``wrist-track`` is shipped: measured on
the held-out trials of docs/rates.md (last 10 %), a 100 Hz refiner trained this way (8 min, 6
epochs, validation loss 0.75) cut the angle MSE by 7 % at 1 and 5 % noise and the torque MSE by
14 % at 5 %, but raised the torque MSE by 35 % on clean markers and 7 % at 1 %, and changed
nothing on the real pyomeca recording (0.590 -> 0.598 deg); a 250 Hz one did not learn
(validation loss 1.09, worse than predicting the mean; torques 1.1-2.1x worse). At those rates
``ikid track`` runs the bare filter (0.7x the EKF's angle MSE there); a lab that wants a refiner
at its rate trains one (``--rate``) and passes it with ``--refiner FILE``.

``ikid.Tracker`` is an extended Kalman filter with a white-jerk motion model: it cannot know
how wrists actually move, so it lags on fast moves and passes noise on slow ones. The refiner
is a small network over a window of the tracker's own states (feature set ``tracker_state``:
q̇, q̈ and log10 of the mean hand-marker noise it learned; not q, so it learns how wrists
move rather than where these ones were) that predicts the tracker's
error in q and q̈; the core scales its output by the gate σ / (σ + ``ikid.REFINER_GATE_NOISE``)
(σ the learned noise), so clean markers are left as the filter has them. The core applies it after the filter
(``Tracker(refiner=...)``; crates/ikid/src/tracker/).

Data: simulated random multi-DoF trajectories, one per recording (seeds from 2100, none used by
any test set; one trajectory seen in many poses teaches the network that trajectory, not how
wrists move), in every joint-sign octant but +-+ (which ``make compare-ekf`` tests as unseen),
cycling through three shoulder poses and five subject sizes (0.9-1.1); uniform marker noise at
levels spanning 0.2-7 % (the thesis' definition) with fresh noise per realisation, half of them
with one marker occluded in bursts; the tracker runs over each exactly as at inference. The
last 10 % of every recording is validation (early stopping). Seeded and reproducible up to
torch's CPU kernels.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

import ikid
from ikid_training import data as D
from ikid_training.export import Affine, ModelSpec, export
from ikid_training.train import mlp

NAME = "wrist-track"
# One trajectory per recording: trained on 9 trajectories seen at 9 (pose, size) pairs each, the
# refiner learned those 9 motions and put their accelerations into others (compare-ekf torque
# MSE 0.71-0.76x the EKF's; with 81 distinct trajectories of the same total length, 0.30-0.34x).
FIRST_SEED = 2100
RECORDINGS = 162  # of 15 s; 81 gave 0.34x the EKF's torque MSE at 5 %, 162 0.29x (compare-ekf, last 10 %)
SHOULDERS_DEG = [0.0, 45.0, -20.0]
SIZES = [
    0.9,
    0.95,
    1.0,
    1.05,
    1.1,
]  # length scales, cycled (mass scale = length scale³); compare-ekf tests 0.85 and 1.15
# Every joint-sign octant but +-+ (s_p > 0, e_f < 0, ad_ab > 0), which compare-ekf tests as unseen.
OCTANTS = ["+++", "++-", "+--", "-++", "-+-", "--+", "---"]
DURATION_S = 15.0
NOISE_LEVELS = [0.002, 0.005, 0.01, 0.02, 0.035, 0.05, 0.07]
OCCLUSION = {"bursts_per_s": 1.0, "min_s": 0.02, "max_s": 0.5, "warmup_s": 3.0}
WINDOW = 96  # frames: ~0.1 s of motion at 1 kHz (32 gave twice the validation loss)
HIDDEN = [
    80,
    80,
]  # 215 KB of first-layer weights stay in L2: the refined step stays a few µs (256 wide: 17 µs)
STRIDE = 4  # every fourth newest frame: neighbouring windows are nearly the same sample
SETTLE = (
    300  # frames after the tracker starts before its states are used (its start-up is not what it refines)
)


SIM_HZ = 1000.0


def name_for(rate_hz: float) -> str:
    """The shipped refiner's name at ``rate_hz``: ``wrist-track`` at 1 kHz, else
    ``wrist-track-<rate>hz`` (the model family ``ikid track --refiner auto`` picks from)."""
    return NAME if rate_hz == SIM_HZ else f"{NAME}-{rate_hz:g}hz"


def at_rate(frames_at_1khz: int, rate_hz: float, least: int = 1) -> int:
    """A count of 1 kHz frames as the same duration at ``rate_hz``."""
    return max(least, int(round(frames_at_1khz * rate_hz / SIM_HZ)))


def recording_specs(count: int, duration: float, rate_hz: float = SIM_HZ) -> list[dict[str, Any]]:
    """``count`` random multi-DoF recordings, each its own trajectory (seed), cycling through the
    shoulder poses and subject sizes, sampled at ``rate_hz``."""
    every = int(round(SIM_HZ / rate_hz))
    if abs(SIM_HZ / every - rate_hz) > 1e-9 * rate_hz:
        raise ValueError(f"--rate {rate_hz:g}: the simulator's 1000 Hz frames kept every k-th give 1000/k Hz")
    specs = []
    for k in range(count):
        seed, sh, x = FIRST_SEED + k, SHOULDERS_DEG[k % len(SHOULDERS_DEG)], SIZES[k % len(SIZES)]
        specs.append(
            {
                "name": f"refine_seed{seed}_s{sh:+.0f}_x{x:.2f}",
                "protocol": "random",
                "seed": seed,
                "duration": duration,
                "shoulder_deg": sh,
                "length_scale": x,
                "mass_scale": x**3,
                "octants": OCTANTS,
                **({"output_every": every} if every > 1 else {}),
            }
        )
    return specs


def tracker_run(
    rec: D.Recording, level: float, seed: int, occluded: bool, rate_hz: float = SIM_HZ
) -> tuple[np.ndarray, np.ndarray, int]:
    """The bare tracker over ``rec`` with noise ``level`` (and occlusion bursts): its
    ``tracker_state`` features ``(n, 7)``, the refiner's targets ``(n, 6)`` and the first frame."""
    noisy = D.add_noise(rec, "uniform", level, seed)
    if occluded:
        noisy = D.add_occlusion(
            noisy,
            OCCLUSION["bursts_per_s"],
            OCCLUSION["min_s"],
            OCCLUSION["max_s"],
            seed=seed + 1,
            warmup_s=OCCLUSION["warmup_s"],
        )
    out = ikid.Tracker(
        length_scale=rec.meta["length_scale"], mass_scale=rec.meta["mass_scale"], rate_hz=rate_hz
    ).run(noisy.markers)
    k = out["start"] + at_rate(SETTLE, rate_hz)
    per_unit = (out["noise"][k:] / (out["noise"][k:] + ikid.REFINER_GATE_NOISE))[:, None]
    # The core's tracker_state features of each frame (q̇, q̈, log10 noise), computed by the core.
    frames = ikid.compute_features(
        np.column_stack([out["q"][k:], out["qd"][k:], out["qdd"][k:], np.log10(out["noise"][k:])]),
        "tracker_state",
    )
    targets = np.column_stack(
        [(rec.q[k:] - out["q"][k:]) / per_unit, (rec.qdd[k:] - out["qdd"][k:]) / per_unit]
    ).astype(np.float32)
    return frames, targets, k


def build(recs: list[D.Recording], seed: int, window: int, rate_hz: float = SIM_HZ) -> dict[str, Any]:
    """Every (recording, level, occlusion) run, frames back to back, with the newest-frame
    indices of the training and validation windows (validation: the last 10 % of each)."""
    frames, targets, levels, train_idx, val_idx = [], [], [], [], []
    offset = 0
    for i, rec in enumerate(recs):
        for j, level in enumerate(NOISE_LEVELS):
            for occluded in (False, True):
                f, t, _ = tracker_run(
                    rec, level, seed + 1000 * i + 10 * j + int(occluded) * 5, occluded, rate_hz
                )
                n = len(f)
                cut = int(0.9 * n)
                stride = at_rate(STRIDE, rate_hz)
                train_idx.append(offset + np.arange(window - 1, cut, stride))
                val_idx.append(offset + np.arange(cut + window - 1, n, stride))
                frames.append(f)
                targets.append(t)
                levels.append(np.full(n, j, np.int64))
                offset += n
    return {
        "frames": np.concatenate(frames),
        "targets": np.concatenate(targets),
        "levels": np.concatenate(levels),
        "train": np.concatenate(train_idx),
        "val": np.concatenate(val_idx),
    }


#: Held-out trials the card's figures are measured on: seeds no refiner trained on (training
#: takes FIRST_SEED on, RECORDINGS of them), the trained octants, shoulders and sizes.
EVAL_FIRST_SEED = 2700
EVAL_RECORDINGS = 9


def evaluation_specs(duration: float = DURATION_S, rate_hz: float = SIM_HZ) -> list[dict[str, Any]]:
    """The held-out recordings of :func:`card_metrics`: :func:`recording_specs`' poses and
    sizes, seeds from :data:`EVAL_FIRST_SEED`."""
    specs = recording_specs(EVAL_RECORDINGS, duration, rate_hz)
    for k, spec in enumerate(specs):
        seed = EVAL_FIRST_SEED + k
        spec["seed"] = seed
        spec["name"] = spec["name"].replace(f"seed{FIRST_SEED + k}", f"seed{seed}")
    assert EVAL_FIRST_SEED >= FIRST_SEED + RECORDINGS, "evaluation seeds overlap the training seeds"
    return specs


def card_metrics(refiner: ikid.Model, recs: list[D.Recording]) -> dict[str, Any]:
    """The card's evaluation figures, measured as training measures the other shipped models
    (``ikid.evaluate``: the thesis' noise levels with the evaluation seeds, the test split —
    the last 10 % — of each held-out recording, after running the whole recording causally):
    for each level ``test_<level>``, the angle errors of ``ikid.Tracker`` refined by
    ``refiner`` (its product: MSE, RMSE per coordinate in rad and degrees, % of range) and,
    under ``"torque"``, its torques' (N·m); ``"bare_filter_mse"`` is the same without the
    refiner, for scale."""
    from ikid.evaluate import EVAL_SEED, NOISE_LEVELS, summary

    rate = float(refiner.frame_rate_hz)
    lo, hi = D.SPLIT_FRACTIONS["test"]
    out: dict[str, Any] = {}
    for label, level in NOISE_LEVELS.items():
        runs: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = {
            "refined": [],
            "bare": [],
        }
        for i, rec in enumerate(recs):
            noisy = D.add_noise(rec, "uniform", level, EVAL_SEED + i) if level > 0 else rec
            a, b = int(round(lo * len(rec))), int(round(hi * len(rec)))
            for kind, model in (("refined", refiner), ("bare", None)):
                est = ikid.Tracker(
                    length_scale=rec.meta["length_scale"],
                    mass_scale=rec.meta["mass_scale"],
                    rate_hz=rate,
                    refiner=model,
                ).run(noisy.markers)
                k = max(a, int(est["start"]))
                runs[kind].append((est["q"][k:b], rec.q[k:b], est["tau"][k:b], rec.tau[k:b]))

        def stacked(kind: str, j: int, runs: dict = runs) -> np.ndarray:
            return np.concatenate([r[j] for r in runs[kind]])

        angles = summary(stacked("refined", 0) - stacked("refined", 1), stacked("refined", 1), "rad")
        angles["torque"] = summary(
            stacked("refined", 2) - stacked("refined", 3), stacked("refined", 3), "N*m"
        )
        angles["bare_filter_mse"] = {
            "angles": float(((stacked("bare", 0) - stacked("bare", 1)) ** 2).mean()),
            "torque": float(((stacked("bare", 2) - stacked("bare", 3)) ** 2).mean()),
        }
        out[f"test_{label}"] = angles
    out["evaluated_on"] = {
        "trials": [r.name for r in recs],
        "split": "test (last 10 % of each)",
        "noise": "uniform, seeds from ikid.evaluate.EVAL_SEED",
        "estimator": "ikid.Tracker(refiner=this model), the recording's own subject size",
    }
    return out


def stamp_metrics(path: Path, duration: float = DURATION_S) -> dict[str, Any]:
    """Evaluate the refiner at ``path`` on the held-out trials and write the figures into its
    card (tensors unchanged, checksum renewed: ``export.restamp``); returns them."""
    from ikid_training.export import restamp

    refiner = ikid.load(path)
    recs = D.simulate_all(evaluation_specs(duration, float(refiner.frame_rate_hz)))
    metrics = {**refiner.card.get("metrics", {}), **card_metrics(refiner, recs)}
    restamp(path, None, metrics)
    return metrics


def gather(frames: torch.Tensor, newest: torch.Tensor, window: int) -> torch.Tensor:
    """Flattened windows ``(m, window × 7)``, oldest frame first (the core's layout)."""
    idx = newest[:, None] - torch.arange(window - 1, -1, -1)[None, :]
    return frames[idx].reshape(len(newest), -1)


def train(data: dict[str, Any], window: int, hidden: list[int], minutes: float, seed: int) -> dict[str, Any]:
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    frames = torch.from_numpy(data["frames"])
    targets = torch.from_numpy(data["targets"])
    train_idx, val_idx = torch.from_numpy(data["train"]), torch.from_numpy(data["val"])
    # Min-max scaling of each input over the training frames (the same per frame of the window).
    used = data["frames"][data["train"]]
    per_frame = Affine.minmax(used.min(0), used.max(0))
    inp = Affine(np.tile(per_frame.scale, window), np.tile(per_frame.shift, window))
    mean, std = data["targets"][data["train"]].mean(0), data["targets"][data["train"]].std(0) + 1e-12
    standardise = Affine(
        (1.0 / std).astype(np.float32), (-mean / std).astype(np.float32)
    )  # SI -> network units
    in_scale, in_shift = torch.from_numpy(inp.scale), torch.from_numpy(inp.shift)
    # Every noise level counts alike: each output's squared error is weighed by 1 / its spread at
    # that level (else the noisiest levels' large corrections drown the small ones of 1 %).
    lv = data["levels"]
    spread = np.stack(
        [data["targets"][data["train"][lv[data["train"]] == j]].std(0) for j in range(len(NOISE_LEVELS))]
    )
    weight = torch.from_numpy(
        ((std / spread) ** 2).astype(np.float32)
    )  # (levels, outputs), in standardised units
    level_of = torch.from_numpy(lv)
    y_scale, y_shift = torch.from_numpy(standardise.scale), torch.from_numpy(standardise.shift)
    net = mlp(window * frames.shape[1], hidden, targets.shape[1])
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    best, best_state, since, epochs, log = float("inf"), None, 0, 0, []
    t0 = time.perf_counter()
    xv = gather(frames, val_idx, window) * in_scale + in_shift
    yv = targets[val_idx] * y_scale + y_shift
    while time.perf_counter() - t0 < minutes * 60:
        net.train()
        perm = train_idx[torch.from_numpy(rng.permutation(len(train_idx)))]
        for b in range(0, len(perm), 1024):
            j = perm[b : b + 1024]
            err = net(gather(frames, j, window) * in_scale + in_shift) - (targets[j] * y_scale + y_shift)
            loss = (weight[level_of[j]] * err**2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        net.eval()
        with torch.no_grad():
            val = float((weight[level_of[val_idx]] * (net(xv) - yv) ** 2).mean())
        epochs += 1
        log.append({"epoch": epochs, "val": val, "seconds": round(time.perf_counter() - t0, 1)})
        print(
            f"epoch {epochs}: validation loss {val:.4f} (per noise level, scaled; 1 = predicting the mean)",
            flush=True,
        )
        if val < best - 1e-4:
            best, since = val, 0
            best_state = {k: v.clone() for k, v in net.state_dict().items()}
        else:
            since += 1
            if since == 2:  # plateau: halve the step, then stop after a further 4 epochs without gain
                for g in opt.param_groups:
                    g["lr"] *= 0.5
            if since >= 6:
                break
    assert best_state is not None
    net.load_state_dict(best_state)
    return {
        "net": net,
        "input": inp,
        "output": standardise.inverse(),
        "epochs": epochs,
        "best_val": best,
        "log": log,
        "seconds": time.perf_counter() - t0,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        # Run from a source checkout (make models-track): the shipped models live in the
        # runtime package's sources, not in site-packages.
        default=None,
        help="model file (default: python/ikid/models/<wrist-track[-<rate>hz]>.safetensors)",
    )
    parser.add_argument(
        "--rate",
        type=float,
        default=SIM_HZ,
        help="frame rate, Hz: 1000 (wrist-track), 250, 200, 125, 100, ...",
    )
    parser.add_argument(
        "--minutes", type=float, default=8.0, help="training time budget (early stopping may end sooner)"
    )
    parser.add_argument(
        "--window", type=int, default=None, help=f"frames (default: {WINDOW} at 1 kHz, ~0.1 s)"
    )
    parser.add_argument("--hidden", type=int, nargs="+", default=HIDDEN)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--recordings",
        type=int,
        default=RECORDINGS,
        help=f"simulated recordings, seeds {FIRST_SEED} on, one trajectory each",
    )
    parser.add_argument("--duration", type=float, default=DURATION_S, help="seconds per recording")
    parser.add_argument(
        "--metrics-only",
        action="store_true",
        help="do not train: evaluate the refiner at --output (default: the shipped one) on the held-out "
        "trials and write the figures into its card (its tensors unchanged)",
    )
    args = parser.parse_args(argv)
    name = name_for(args.rate)
    args.output = args.output or Path("python/ikid/models") / f"{name}.safetensors"
    if args.metrics_only:
        t0 = time.perf_counter()
        metrics = stamp_metrics(args.output, args.duration)
        print(json.dumps({k: v for k, v in metrics.items() if k.startswith("test_")}, indent=1))
        print(f"wrote the figures into {args.output}'s card ({time.perf_counter() - t0:.0f} s)")
        return
    args.window = args.window or at_rate(WINDOW, args.rate, least=4)
    torch.set_num_threads(2)
    t0 = time.perf_counter()
    specs = recording_specs(args.recordings, args.duration, args.rate)
    seeds = [s["seed"] for s in specs]
    recs = D.simulate_all(specs)
    data = build(recs, 31_000 + args.seed, args.window, args.rate)
    print(
        f"{len(recs)} recordings x {len(NOISE_LEVELS)} noise levels x 2 (occlusion): {len(data['train'])} "
        f"training and {len(data['val'])} validation windows ({time.perf_counter() - t0:.0f} s)",
        flush=True,
    )
    trained = train(data, args.window, args.hidden, args.minutes, args.seed)
    spec = ModelSpec(
        name=name,
        task="refine",
        feature_set="tracker_state",
        window=args.window,
        frame_rate_hz=args.rate,
        output_names=list(ikid.REFINER_OUTPUTS),
        output_units=["rad"] * 3 + ["rad/s^2"] * 3,
        scaling={
            "input": "minmax(-1,1) per tracker_state feature",
            "output": "standardised; the core gates it by the learned noise",
        },
        provenance={
            "trainer": "ikid_training.refine",
            "simulator": ikid.SIMULATOR,
            "seeds": seeds,
            "shoulders_deg": SHOULDERS_DEG,
            "length_scales": SIZES,
            "octants": OCTANTS,
            "duration_s": args.duration,
            "noise": {"kind": "uniform", "levels": NOISE_LEVELS},
            "occlusion": OCCLUSION,
            "tracker_jerk_noise": ikid.DEFAULT_JERK_NOISE,
            "hidden": args.hidden,
            "seed": args.seed,
            "epochs": trained["epochs"],
            "training_s": round(trained["seconds"], 1),
        },
        metrics={"validation_loss_scaled": trained["best_val"]},
    )
    args.output.parent.mkdir(parents=True, exist_ok=True)
    export(trained["net"], args.output, spec, trained["input"], trained["output"])
    stamp_metrics(args.output, args.duration)  # the card's evaluation figures, as the others carry
    (args.output.with_suffix(".log.json")).write_text(json.dumps(trained["log"], indent=1))
    print(
        f"wrote {args.output} ({trained['epochs']} epochs, best validation loss {trained['best_val']:.4f}, "
        f"{time.perf_counter() - t0:.0f} s in all)"
    )


if __name__ == "__main__":
    main()
