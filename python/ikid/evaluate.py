"""Scoring models on recordings, with the classical reference on the same frames
(``ikid report --data``; training's model cards and ``make report`` score with it too).

Only ``ikid`` and NumPy: model files are evaluated exactly as users run them
(``Model.predict`` in the Rust core), never through torch.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

import ikid
from ikid import recordings as D

#: Noise levels of the thesis (uniform, ± fraction of each marker coordinate's range).
NOISE_LEVELS = {"clean": 0.0, "1%": 0.01, "5%": 0.05}
EVAL_SEED = 7_000_000  # evaluation noise seeds, never used in training


class Predictor(Protocol):
    """What scoring needs of a model: an ``ikid.Model``, or :class:`ClassicalIk`."""

    @property
    def task(self) -> str: ...
    @property
    def feature_set(self) -> str: ...
    @property
    def window(self) -> int: ...
    def predict(self, frames: np.ndarray) -> np.ndarray: ...


def truth(model: Predictor, rec: D.Recording) -> np.ndarray:
    return D.target(rec, model.task)[model.window - 1 :]


def predict(model: Predictor, rec: D.Recording) -> np.ndarray:
    """Predictions for every frame with a full window (row ``i`` is frame ``i + window - 1``);
    NaN where a stream refuses the frame (at 100 Hz the gap filler takes a rare fast reach for a
    jump, which ``predict`` refuses for the whole recording)."""
    frames = rec.frames(model.feature_set)
    try:
        return model.predict(frames).astype(np.float64)
    except ikid.InputError:
        stream = model.stream()  # type: ignore[attr-defined]
        out = np.full((len(frames), model.n_outputs), np.nan)  # type: ignore[attr-defined]
        for i, frame in enumerate(frames):
            try:
                y = stream.push(frame)
            except ikid.InputError:
                continue
            if y is not None:
                out[i] = y
        return out[model.window - 1 :]


def errors(model: Predictor, recs: Sequence[D.Recording], split: str) -> tuple[np.ndarray, np.ndarray]:
    """Stacked (prediction − truth, truth) over the ``split`` part of each recording.

    The part is cut *after* predicting the whole recording, so the first test frames use the
    frames before them, as a live stream would.
    """
    errs, trues = [], []
    for r in recs:
        pred, true = predict(model, r), truth(model, r)
        lo, hi = D.SPLIT_FRACTIONS[split] if split != "all" else (0.0, 1.0)
        n = len(r)
        a, b = max(int(round(lo * n)) - (model.window - 1), 0), int(round(hi * n)) - (model.window - 1)
        ok = np.isfinite(pred[a:b]).all(axis=1)
        errs.append((pred[a:b] - true[a:b])[ok])
        trues.append(true[a:b][ok])
    return np.concatenate(errs), np.concatenate(trues)


def noisy(
    recs: Sequence[D.Recording], level: float, kind: str = "uniform", seed: int = EVAL_SEED
) -> list[D.Recording]:
    return [D.add_noise(r, kind, level, seed + i) for i, r in enumerate(recs)]


def summary(err: np.ndarray, true: np.ndarray, unit: str) -> dict[str, Any]:
    """MSE over all outputs, RMSE per output, and RMSE as % of each output's true range."""
    rng = true.max(0) - true.min(0)
    rmse = np.sqrt((err**2).mean(0))
    out: dict[str, Any] = {
        "mse": float((err**2).mean()),
        "rmse": rmse.tolist(),
        "unit": unit,
        "frames": len(err),
    }
    if unit == "rad":
        out["rmse_deg"] = np.degrees(rmse).tolist()
    out["nrmse_pct_of_range"] = (100 * rmse / np.where(rng > 0, rng, 1)).tolist()
    return out


def evaluate_recordings(
    model: ikid.Model, recs: Sequence[D.Recording], noise_levels: dict[str, float] | None = None
) -> dict[str, Any]:
    """The report of ``model`` on ``recs`` (e.g. a lab's trials): per added noise level (marker
    models only), the last 10 % of each recording (``test``) and all frames (``all``); for angle
    models also the core's per-frame least squares (``ikid.reference_ik``, the body model's
    marker placement) on the same frames."""
    levels = {"clean": 0.0} if model.frame_kind == "joint_state" else (noise_levels or NOISE_LEVELS)
    unit = model.output_units[0]
    out: dict[str, Any] = {
        "model": model.name,
        "recordings": len(recs),
        "frames": int(sum(len(r) for r in recs)),
        "rate_hz": model.frame_rate_hz,
        "levels": {},
    }
    for name, level in levels.items():
        data = noisy(recs, level) if level else list(recs)
        row: dict[str, Any] = {split: summary(*errors(model, data, split), unit) for split in ("test", "all")}
        if model.task == "ik":
            # The classical per-frame solution on the very frames the model scored (same skip).
            ref = ClassicalIk(model.window)
            row["classical"] = {split: summary(*errors(ref, data, split), unit) for split in ("test", "all")}
        out["levels"][name] = row
    return out


class ClassicalIk:
    """``ikid.reference_ik`` dressed as a model for :func:`errors` (rows aligned to ``window``)."""

    task = "ik"
    feature_set = "markers"

    def __init__(self, window: int):
        self.window = window

    def predict(self, frames: np.ndarray) -> np.ndarray:
        return ikid.reference_ik(frames)[self.window - 1 :]


def markdown(result: dict[str, Any]) -> str:
    """:func:`evaluate_recordings` as a Markdown table."""
    deg = "rmse_deg" in next(iter(result["levels"].values()))["all"]
    per = "RMSE per DoF (°)" if deg else "RMSE per DoF"
    lines = [
        f"Model `{result['model']}` on {result['recordings']} recordings ({result['frames']} frames, "
        f"{result['rate_hz']:g} Hz).",
        "Noise: uniform ±p of each marker coordinate's range, added here (seeded). MSE in "
        "rad² (angles) or N·m² (torques).",
        "",
        f"| noise | frames | MSE last 10 % | MSE all | {per}, all | classical MSE last "
        "10 % | classical MSE all |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, row in result["levels"].items():
        rmse = row["all"]["rmse_deg" if deg else "rmse"]
        cls = row.get("classical")
        c = (f"{cls['test']['mse']:.3g} | {cls['all']['mse']:.3g}") if cls else "– | –"
        lines.append(
            f"| {name} | {row['all']['frames']} | {row['test']['mse']:.3g} | {row['all']['mse']:.3g} | "
            f"{' / '.join(f'{v:.3g}' for v in rmse)} | {c} |"
        )
    return "\n".join(lines) + "\n"
