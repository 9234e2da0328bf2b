"""Scoring models on recordings, with the classical reference on the same frames.

Only ``ikid`` and NumPy: shipped model files are evaluated exactly as users run them
(``Model.predict`` in the Rust core), never through torch.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

import ikid
from ikid.training import data as D

#: The thesis' test numbers (MSE, rad² for angles; its chain torque MSE as printed, N·m² by its units).
THESIS = {"ik_clean": 4.15e-5, "ik_1pct": 7e-4, "ik_5pct": 3.7e-3, "chain_torque_mse": 0.1727}
#: Noise levels of the thesis (uniform, ± fraction of each marker coordinate's range).
NOISE_LEVELS = {"clean": 0.0, "1%": 0.01, "5%": 0.05}
EVAL_SEED = 7_000_000  # evaluation noise seeds, never used in training


def truth(model: ikid.Model, rec: D.Recording) -> np.ndarray:
    return D.target(rec, model.task)[model.window - 1 :]


def predict(model: ikid.Model, rec: D.Recording) -> np.ndarray:
    """Predictions for every frame with a full window (row ``i`` is frame ``i + window - 1``)."""
    return model.predict(rec.frames(model.feature_set)).astype(np.float64)


def errors(model: ikid.Model, recs: Sequence[D.Recording], split: str) -> tuple[np.ndarray, np.ndarray]:
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
        errs.append(pred[a:b] - true[a:b])
        trues.append(true[a:b])
    return np.concatenate(errs), np.concatenate(trues)


def noisy(recs: Sequence[D.Recording], level: float, kind: str = "uniform", seed: int = EVAL_SEED) -> list[D.Recording]:
    return [D.add_noise(r, kind, level, seed + i) for i, r in enumerate(recs)]


def summary(err: np.ndarray, true: np.ndarray, unit: str) -> dict[str, Any]:
    """MSE over all outputs, RMSE per output, and RMSE as % of each output's true range."""
    rng = true.max(0) - true.min(0)
    rmse = np.sqrt((err**2).mean(0))
    out: dict[str, Any] = {"mse": float((err**2).mean()), "rmse": rmse.tolist(), "unit": unit, "frames": len(err)}
    if unit == "rad":
        out["rmse_deg"] = np.degrees(rmse).tolist()
    out["nrmse_pct_of_range"] = (100 * rmse / np.where(rng > 0, rng, 1)).tolist()
    return out


def card_metrics(model: ikid.Model, recs: Sequence[D.Recording]) -> dict[str, Any]:
    """Test-split metrics stored in the model card (thesis split; noise seeds not used in training)."""
    unit = model.output_units[0]
    if model.feature_set == "joint_state":
        return {"test": summary(*errors(model, recs, "test"), unit)}
    return {f"test_{name}": summary(*errors(model, noisy(recs, level), "test"), unit) for name, level in NOISE_LEVELS.items()}
