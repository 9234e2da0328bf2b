"""Train one model from a TOML config: simulate (or load) data, train an MLP with noise
augmentation and early stopping, export ``.safetensors`` (+ ONNX) with a full model card.

    python -m ikid_training.train training/ikid_training/configs/wrist-ik.toml --out out/models

Config tables: ``[model]`` (name, task, feature_set, window, hidden), ``[data]`` (what to
simulate, or ``folder`` of saved trials), ``[train]`` (seed, batch, lr, budget, early stopping,
augmentation). See ``ikid_training/configs/`` for the shipped models' configs. Every run writes
its config, a per-epoch log (JSON lines) and its result under ``<out>/runs/<name>/``.
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

import ikid
from ikid.evaluate import NOISE_LEVELS, errors, noisy, summary
from ikid_training import data as D
from ikid_training.export import (
    Affine,
    ModelSpec,
    WindowModel,
    envelope_of,
    export,
    export_onnx,
    window_change,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

TRAIN_DEFAULTS: dict[str, Any] = {
    "seed": 0,
    "batch": 512,
    "lr": 1e-3,
    "max_minutes": 5.0,
    "max_epochs": 1000,
    "samples_per_epoch": 200_000,
    "patience": 25,  # epochs without a relative improvement of min_delta
    "min_delta": 1e-3,
    "lr_patience": 8,  # epochs without improvement before the learning rate halves
    "noise_kind": "uniform",
    "noise_levels": [0.0],  # each recording gets a level drawn from these, fresh every epoch
    # Occlusion: bursts (per second of recording) in which one marker is missing, filled by the
    # core's gap filler exactly as a "fill" stream does; needs [model] missing_markers = "fill".
    "occlusion_bursts_per_s": 0.0,
    "occlusion_s": [0.02, 0.5],
    "threads": 2,
    # Output scaling from the targets' [q, 1 - q] quantiles instead of their extremes (0: extremes),
    # and windows whose scaled target lies beyond OUTLIER_SCALED left out of training and
    # validation. For corrections whose extremes are noise wrapped past ±180° or amplified near
    # the Y-Z-X singularity (e_f near ±90°): fitted to them, the scaling spends the network's
    # precision on targets no window can predict.
    "output_quantile": 0.0,
    # Inputs relative to the window's newest frame: every older frame's features minus the
    # newest's (the newest kept whole), each scaled to [-1, 1] on the training windows, then
    # folded into the first layer, so the exported model is an ordinary one (a linear map of
    # its window). The posture no longer fills the scaled range, the shape of the window does:
    # noise and speed get the resolution.
    "relative_inputs": False,
    # Share of the recordings that reach the model as a recording at a lower rate does through
    # ikid.pipeline: frames kept at one of resampled_from_hz, the noise added there, the rest
    # made by the pipeline's cubic Hermite (D.resampled). The noise is then smooth between the
    # kept frames, which white noise at the model's rate never teaches. 0: none (the default).
    "resampled_share": 0.0,
    "resampled_from_hz": [100.0, 250.0],
}

#: With ``output_quantile``: scaled targets beyond this (the quantile range maps to [-1, 1]) are
#: outliers, left out.
OUTLIER_SCALED = 4.0


#: The simulator's step rate; ``[data] rate_hz`` (simulated data) keeps every k-th of its frames.
SIM_RATE_HZ = 1000.0


def load_config(path: str | Path) -> dict[str, Any]:
    with open(path, "rb") as f:
        cfg = tomllib.load(f)
    for table in ("model", "data"):
        if table not in cfg:
            raise ValueError(f"{path}: missing [{table}] table")
    cfg["train"] = {**TRAIN_DEFAULTS, **cfg.get("train", {})}
    unknown = set(cfg["train"]) - set(TRAIN_DEFAULTS)
    if unknown:
        raise ValueError(f"{path}: unknown [train] keys {sorted(unknown)} (known: {sorted(TRAIN_DEFAULTS)})")
    task = cfg["model"].get("task")
    if task not in D.TASKS:
        raise ValueError(f"{path}: [model] task {task!r} is not one of {list(D.TASKS)}")
    policy = cfg["model"].setdefault("missing_markers", "refuse")
    if policy not in ("refuse", "fill"):
        raise ValueError(f"{path}: [model] missing_markers {policy!r} is not 'refuse' or 'fill'")
    if cfg["model"].get("output_offset") not in (None, "newest_features"):
        raise ValueError(
            f"{path}: [model] output_offset {cfg['model']['output_offset']!r} is not "
            "'newest_features' (or absent)"
        )
    if cfg["train"]["occlusion_bursts_per_s"] > 0 and policy != "fill":
        raise ValueError(
            f"{path}: [train] occlusion_bursts_per_s needs [model] missing_markers = 'fill' "
            "(occluded frames are filled)"
        )
    return cfg


def build_recordings(data_cfg: dict[str, Any]) -> list[D.Recording]:
    """The training recordings named by a ``[data]`` table: ``lab`` (a folder of a lab's marker
    files with same-stem .mot/.sto; ``map``, ``rate_hz`` optional), ``folder`` (saved simulated
    trials), or what to simulate (``rate_hz``, optional: sampled at that rate, a divisor of 1 kHz)."""
    if "lab" in data_cfg:
        return D.load_lab_recordings(data_cfg["lab"], data_cfg.get("map"), data_cfg.get("rate_hz"))
    if "folder" in data_cfg:
        return D.load_recordings(data_cfg["folder"])
    common = {k: data_cfg[k] for k in ("shoulders_deg", "length_scales")}
    specs = D.recording_set(
        "random",
        seeds=data_cfg.get("seeds", [1000]),
        duration=data_cfg.get("duration", 60.0),
        octants=data_cfg.get("octants"),
        mass_follows_length=data_cfg.get("mass_follows_length", True),
        **common,
    )
    if data_cfg.get("include_thesis", False):
        specs += D.recording_set(
            "thesis", seeds=[0], mass_follows_length=data_cfg.get("mass_follows_length", True), **common
        )
    if "rate_hz" in data_cfg:
        # Recorded at rate_hz: the simulator steps at 1 kHz and keeps every k-th frame (the same
        # motion as at 1 kHz, sampled as a lab at that rate would).
        every = SIM_RATE_HZ / float(data_cfg["rate_hz"])
        if every < 1 or abs(every - round(every)) > 1e-9:
            raise ValueError(
                f"[data] rate_hz {data_cfg['rate_hz']} must divide {SIM_RATE_HZ:g} Hz (the simulator's rate)"
            )
        specs = [{**s, "output_every": int(round(every))} for s in specs]
    recs = D.simulate_all(specs)
    if "sessions" in data_cfg:
        # Sessions past the random protocol's ranges and speeds (ikid_training.data.session_q).
        rate = float(data_cfg.get("rate_hz", SIM_RATE_HZ))
        recs += [D.simulate_session(s, rate) for s in D.session_specs(data_cfg["sessions"], **common)]
    return recs


def check_targets(recs: list[D.Recording], task: str) -> None:
    """Every recording has finite targets for ``task`` (a lab trial without its .sto has no torques)."""
    missing = [r.name for r in recs if not np.isfinite(D.target(r, task)).all()]
    if missing:
        what = "torques (a same-stem .sto)" if D.TASKS[task] == "tau" else "angles"
        raise ikid.InputError(
            f"task {task!r} learns {what}, missing in {len(missing)} recording(s): {', '.join(missing[:5])}"
        )


def data_hash(recs: list[D.Recording]) -> str:
    h = hashlib.sha256()
    for r in recs:
        for a in r.arrays():
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def mlp(n_in: int, hidden: list[int], n_out: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    for width in hidden:
        layers += [nn.Linear(n_in, width), nn.ReLU()]
        n_in = width
    return nn.Sequential(*layers, nn.Linear(n_in, n_out))


@dataclass
class Trained:
    net: nn.Sequential
    input_scaling: Affine
    output_scaling: Affine  # network units -> SI
    log: list[dict[str, Any]]
    seconds: float
    best_val: float
    #: The training data's ranges, for the card (frames outside it are flagged).
    envelope: dict[str, Any] | None = None


def _noisy(recs: list[D.Recording], tcfg: dict[str, Any], rng: np.random.Generator) -> list[D.Recording]:
    """Fresh noise (a level drawn per recording), some recordings (``resampled_share``) as they
    come from a lower rate, and, if configured, occlusion bursts."""
    levels = tcfg["noise_levels"]
    out = [
        D.add_noise(r, tcfg["noise_kind"], float(rng.choice(levels)), int(rng.integers(2**62))) for r in recs
    ]
    if tcfg["resampled_share"] > 0:  # drawn only with a share: configs without one are as before
        for i, r in enumerate(recs):
            if rng.uniform() < tcfg["resampled_share"]:
                rate = float(rng.choice(tcfg["resampled_from_hz"]))
                level = float(rng.choice(levels))
                out[i] = D.resampled(r, rate, tcfg["noise_kind"], level, int(rng.integers(2**62)))
    if tcfg["occlusion_bursts_per_s"] > 0:
        lo, hi = tcfg["occlusion_s"]
        out = [
            D.add_occlusion(r, tcfg["occlusion_bursts_per_s"], lo, hi, int(rng.integers(2**62))) for r in out
        ]
    return out


def newest_features(x: np.ndarray, feature_len: int, n: int) -> np.ndarray:
    """The newest frame's first ``n`` features of flattened windows ``x`` (what the card's
    ``output_offset = "newest_features"`` adds to the outputs)."""
    start = x.shape[1] - feature_len
    return x[:, start : start + n]


def relative_to_newest(x: np.ndarray, feature_len: int) -> np.ndarray:
    """Flattened windows ``x`` with every older frame's features minus the newest frame's (the
    newest frame's kept as they are): the ``relative_inputs`` representation."""
    w = np.asarray(x).reshape(len(x), -1, feature_len)
    out = w - w[:, -1:, :]
    out[:, -1, :] = w[:, -1, :]
    return out.reshape(len(x), -1).astype(x.dtype, copy=False)


def relative_map(n_in: int, feature_len: int) -> np.ndarray:
    """The matrix ``T`` with ``relative_to_newest(x) = x @ T.T`` (float64)."""
    t = np.eye(n_in)
    newest = n_in - feature_len
    for i in range(newest):
        t[i, newest + i % feature_len] -= 1.0
    return t


def fold_relative_inputs(net: nn.Sequential, inp: Affine, feature_len: int) -> tuple[nn.Sequential, Affine]:
    """``net`` on scaled relative inputs as an equivalent network on the raw window: the first
    layer ``W (s ⊙ T x + c) + b`` becomes ``(W diag(s) T) x + (W c + b)`` and the input scaling
    the identity (float64 for the product, float32 stored, as every layer)."""
    first = net[0]
    assert isinstance(first, nn.Linear)
    w = first.weight.detach().double().numpy()
    b = first.bias.detach().double().numpy()
    s, c = inp.scale.astype(np.float64), inp.shift.astype(np.float64)
    t = relative_map(w.shape[1], feature_len)
    folded = copy.deepcopy(net)
    layer = folded[0]
    assert isinstance(layer, nn.Linear)
    with torch.no_grad():
        layer.weight.copy_(torch.as_tensor((w * s[None, :]) @ t, dtype=torch.float32))
        layer.bias.copy_(torch.as_tensor(w @ c + b, dtype=torch.float32))
    return folded, Affine.identity(w.shape[1])


def training_window_change(cfg: dict[str, Any]) -> np.ndarray:
    """The ``window_change`` :func:`train` writes into the card of ``cfg``'s model, from its
    training data rebuilt (same recordings, seeds and noise): for models trained before cards
    carried it (``python -m ikid_training.export --restamp FILE --change``)."""
    m, t = cfg["model"], cfg["train"]
    task, fs, window = m["task"], m["feature_set"], int(m.get("window", 5))
    train_parts = [r.part("train") for r in build_recordings(cfg["data"])]
    clean, _ = D.stack_windows(train_parts, task, fs, window, stride=7)
    seen = [clean]
    if m.get("output_offset"):
        noisy, _ = D.stack_windows(
            _noisy(train_parts, t, np.random.default_rng(t["seed"] + 2)), task, fs, window, stride=7
        )
        seen.append(noisy)
    return window_change(seen, D.feature_len(fs))


def train(
    cfg: dict[str, Any], recs: list[D.Recording], log_path: Path | None = None, progress: bool = True
) -> Trained:
    """Trains the ``[model]`` of ``cfg`` on the train parts of ``recs``; early stopping on the val parts."""
    m, t = cfg["model"], cfg["train"]
    task, fs, window = m["task"], m["feature_set"], int(m.get("window", 5))
    torch.manual_seed(t["seed"])
    torch.set_num_threads(t["threads"])
    rng = np.random.default_rng(t["seed"])
    train_parts = [r.part("train") for r in recs]
    val_parts = [r.part("val") for r in recs]

    offset = m.get("output_offset")  # "newest_features": learn a correction to the newest frame's features

    def targets(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return y - newest_features(x, D.feature_len(fs), y.shape[1]) if offset else y

    # Scaling (min-max to [-1, 1], stored in the model file): inputs from the clean training
    # windows; outputs from the targets, noisy ones for a correction (on clean windows it is ~0).
    x0, y0 = D.stack_windows(train_parts, task, fs, window, stride=7)
    fl = D.feature_len(fs)
    relative = bool(t["relative_inputs"])

    def inputs(x: np.ndarray) -> np.ndarray:
        return relative_to_newest(x, fl) if relative else x

    x0_in = inputs(x0)
    inp = Affine.minmax(x0_in.min(0), x0_in.max(0))
    del x0_in
    clean = (x0, y0)
    if offset:
        x0, y0 = D.stack_windows(
            _noisy(train_parts, t, np.random.default_rng(t["seed"] + 2)), task, fs, window, stride=7
        )
    # Ranges from the clean windows; how fast a window changes from the noisy ones too.
    envelope = envelope_of(clean[0], D.feature_len(fs), clean[1], seen=(x0,) if offset else ())
    del clean
    r0 = targets(x0, y0)
    oq = float(t["output_quantile"])
    out_fwd = (
        Affine.minmax(np.quantile(r0, oq, axis=0), np.quantile(r0, 1 - oq, axis=0))
        if oq > 0
        else Affine.minmax(r0.min(0), r0.max(0))
    )

    def inliers(ys: np.ndarray) -> np.ndarray:
        return (np.abs(ys) <= OUTLIER_SCALED).all(axis=1) if oq > 0 else np.ones(len(ys), bool)

    del x0, y0, r0
    # A fixed validation set with the same noise mixture (seeded), so early stopping compares like with like.
    xv, yv = D.stack_windows(
        _noisy(val_parts, t, np.random.default_rng(t["seed"] + 1)), task, fs, window, stride=5
    )
    yv = targets(xv, yv) * out_fwd.scale + out_fwd.shift
    keep = inliers(yv)
    xv_t = torch.as_tensor((inputs(xv) * inp.scale + inp.shift)[keep])
    yv_t = torch.as_tensor(yv[keep])

    net = mlp(xv.shape[1], list(m["hidden"]), yv.shape[1])
    opt = torch.optim.Adam(net.parameters(), lr=t["lr"])
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=t["lr_patience"])
    n_frames = sum(len(r) for r in train_parts)
    stride = max(1, n_frames // t["samples_per_epoch"])

    best, best_state, since_best, log = math.inf, copy.deepcopy(net.state_dict()), 0, []
    start = time.perf_counter()
    budget = 60.0 * t["max_minutes"]
    bar = tqdm(
        total=int(budget),
        unit="s",
        desc=f"{m['name']}",
        disable=not progress,
        bar_format="{l_bar}{bar}| {n:.0f}/{total} s {postfix}",
    )
    for epoch in range(t["max_epochs"]):
        # Fresh noise and a fresh subsample of windows every epoch.
        x, y = D.stack_windows(
            _noisy(train_parts, t, rng), task, fs, window, stride=stride, offset=int(rng.integers(stride))
        )
        y = targets(x, y) * out_fwd.scale + out_fwd.shift
        keep = inliers(y)
        xs = torch.as_tensor((inputs(x) * inp.scale + inp.shift)[keep])
        ys = torch.as_tensor(y[keep])
        net.train()
        perm = torch.randperm(len(xs))
        total = 0.0
        for i in range(0, len(xs), t["batch"]):
            b = perm[i : i + t["batch"]]
            loss = nn.functional.mse_loss(net(xs[b]), ys[b])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += loss.item() * len(b)
        net.eval()
        with torch.no_grad():
            val = nn.functional.mse_loss(net(xv_t), yv_t).item()
        sched.step(val)
        elapsed = time.perf_counter() - start
        entry = {
            "epoch": epoch,
            "train_loss": total / len(xs),
            "val_loss": val,
            "lr": opt.param_groups[0]["lr"],
            "seconds": elapsed,
        }
        log.append(entry)
        if log_path:
            with open(log_path, "a") as f:
                f.write(json.dumps(entry) + "\n")
        if val < best * (1 - t["min_delta"]):
            best, best_state, since_best = val, copy.deepcopy(net.state_dict()), 0
        else:
            since_best += 1
        bar.set_postfix_str(f"epoch {epoch} val {val:.2e} best {best:.2e} lr {entry['lr']:.1e}")
        bar.update(min(int(elapsed) - bar.n, int(budget) - bar.n))
        if since_best >= t["patience"] or elapsed > budget:
            break
    bar.close()
    net.load_state_dict(best_state)
    if relative:
        net, inp = fold_relative_inputs(net, inp, fl)
    return Trained(net.eval(), inp, out_fwd.inverse(), log, time.perf_counter() - start, best, envelope)


def spec_for(
    cfg: dict[str, Any], recs: list[D.Recording], trained: Trained, metrics: dict[str, Any] | None = None
) -> ModelSpec:
    m = cfg["model"]
    return ModelSpec(
        name=m["name"],
        task=m["task"],
        feature_set=m["feature_set"],
        window=int(m.get("window", 5)),
        frame_rate_hz=float(recs[0].meta.get("rate_hz", 1000.0)),
        missing_markers=m["missing_markers"],
        output_offset=m.get("output_offset"),
        output_names=ikid.coordinate_names(),
        envelope=trained.envelope,
        scaling={
            "input": (
                "relative to the newest frame, minmax(-1,1) on clean training windows, "
                "folded into the first layer"
                if cfg["train"]["relative_inputs"]
                else "minmax(-1,1) on clean training windows"
            ),
            "output": (
                f"quantiles {cfg['train']['output_quantile']:g}-{1 - cfg['train']['output_quantile']:g} "
                "of training targets to (-1,1)"
                if cfg["train"]["output_quantile"] > 0
                else "minmax(-1,1) on training targets"
            ),
        },
        provenance={
            "simulator": None if "lab" in cfg["data"] else ikid.SIMULATOR,
            "data": cfg["data"],
            "recordings": len(recs),
            "frames": int(sum(len(r) for r in recs)),
            "data_sha256_16": data_hash(recs),
            "split": "per recording: first 80 % train, next 10 % validation, last 10 % test",
            "train": cfg["train"],
            "hidden": list(m["hidden"]),
            "epochs": len(trained.log),
            "train_seconds": round(trained.seconds, 1),
            "best_val_loss_scaled": trained.best_val,
            "torch": torch.__version__,
            "ikid": ikid.__version__,
        },
        metrics=metrics or {},
    )


def card_metrics(model: ikid.Model, recs: Sequence[D.Recording]) -> dict[str, Any]:
    """Test-split metrics stored in the model card (thesis split; noise seeds not used in training)."""
    unit = model.output_units[0]
    if model.frame_kind == "joint_state":
        return {"test": summary(*errors(model, recs, "test"), unit)}
    return {
        f"test_{name}": summary(*errors(model, noisy(recs, level), "test"), unit)
        for name, level in NOISE_LEVELS.items()
    }


def run(cfg: dict[str, Any], out: Path, progress: bool = True, onnx: bool = True) -> tuple[ikid.Model, Path]:
    """Train and export one config; returns the loaded model and its path."""
    name = cfg["model"]["name"]
    run_dir = out / "runs" / name
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.json").write_text(json.dumps(cfg, indent=2))
    log_path = run_dir / "log.jsonl"
    log_path.unlink(missing_ok=True)
    t0 = time.perf_counter()
    recs = build_recordings(cfg["data"])
    check_targets(recs, cfg["model"]["task"])
    print(
        f"{name}: {len(recs)} recordings, {sum(len(r) for r in recs)} frames "
        f"({time.perf_counter() - t0:.1f} s to build)",
        flush=True,
    )
    trained = train(cfg, recs, log_path, progress)
    path = out / f"{name}.safetensors"
    model = export(
        trained.net, path, spec_for(cfg, recs, trained), trained.input_scaling, trained.output_scaling
    )
    metrics = card_metrics(model, recs)
    model = export(
        trained.net,
        path,
        spec_for(cfg, recs, trained, metrics),
        trained.input_scaling,
        trained.output_scaling,
    )
    if onnx:
        offset = D.feature_len(cfg["model"]["feature_set"]) if cfg["model"].get("output_offset") else 0
        export_onnx(
            WindowModel(trained.net, trained.input_scaling, trained.output_scaling, offset),
            out / f"{name}.onnx",
        )
    result = {"model": str(path), "epochs": len(trained.log), "seconds": trained.seconds, "metrics": metrics}
    (run_dir / "result.json").write_text(json.dumps(result, indent=2))
    print(
        f"{name}: {len(trained.log)} epochs in {trained.seconds:.0f} s -> {path}; "
        f"test metrics {json.dumps(metrics)}",
        flush=True,
    )
    return model, path


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("config", type=Path, nargs="+", help="TOML config(s), trained one after the other")
    parser.add_argument("--out", type=Path, default=Path("out/models"))
    parser.add_argument("--minutes", type=float, help="override [train] max_minutes")
    parser.add_argument("--no-onnx", action="store_true")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args()
    for path in args.config:
        cfg = load_config(path)
        if args.minutes is not None:
            cfg["train"]["max_minutes"] = args.minutes
        run(cfg, args.out, progress=not args.quiet, onnx=not args.no_onnx)


if __name__ == "__main__":
    main()
