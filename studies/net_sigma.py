"""Per-frame standard deviations of the networks' outputs (issue #30 item 4): the card's
``uncertainty`` coefficients, fitted here on simulated trials, and how well the σ they give
covers the truth on other trials.

The core computes σ (``crates/ikid/src/model/uncertainty.rs``): per output a variance that is
an affine function of the per-frame angles' noise measured from the data alone (a running mean
of their squared third differences) and, for a model that corrects the per-frame solution (the
wrist-ik family), of the running mean of its squared correction. Its few coefficients live in
the model file's card, so each model carries its own.

- **Fit** (seeds FIT, uniform noise at every level of FIT_LEVELS, clean included): per output,
  the variance model by non-negative least squares on the squared errors, reweighted by the
  fitted variance (a Gaussian likelihood's weights), then one factor per output that puts
  68.27 % of the fit's frames within ±σ (errors are not Gaussian: the factor makes "±1 σ" mean
  what a lab reads it as).
- **Coverage** (seeds SCORE, never fitted on; the production path ``ikid.pipeline.run_model``,
  the simulator's own angles and torques the truth): the share of output rows with a σ whose
  true value lies within ±σ, per condition: clean, uniform ±1 % and ±5 % of each coordinate's
  range (ikid's noise: the simulated forearm is fixed, only the hand's markers are noisy; as in
  docs/ekf.md), and Gaussian 1 mm on every marker (a noise the fit never saw).

Seeds: 98xx, used by no training config (1000–3004, 2100–2199, 2700s), not the exam's (above
10⁶, guarded by tests/test_exam.py) and not studies/sigma_coverage.py's (9700–9720).

    python -m studies.net_sigma            # fit, then coverage of the fitted σ on SCORE
    python -m studies.net_sigma --write    # ... and write the coefficients into python/ikid/models/
    python -m studies.net_sigma --score    # coverage of the shipped cards' σ on SCORE only
"""

from __future__ import annotations

import argparse
import functools
import json
from pathlib import Path

import numpy as np

import ikid
from ikid import _native
from ikid.kinematics import joint_states
from ikid.pipeline import run_model

#: Model name -> (its rate, Hz; the truth it is scored on: "q" angles or "tau" torques).
MODELS = {
    "wrist-ik": (1000.0, "q"),
    "wrist-ik-250hz": (250.0, "q"),
    "wrist-ik-100hz": (100.0, "q"),
    "wrist-chain": (1000.0, "tau"),
    "wrist-id": (1000.0, "tau"),
}
#: What a joint-state model (``ikid id``) reads: the angles ``ikid ik`` writes with its default
#: model from the trial's markers, low-passed and differenced as ``ikid id`` does by default
#: (``ikid.kinematics.joint_states``). Its σ is for the chain users run, not for exact angles.
UPSTREAM = "wrist-ik"
FIT = [9800, 9801, 9802, 9803, 9804, 9805]
SCORE = [9810, 9811, 9812, 9813, 9814, 9815]
#: Uniform noise levels (fraction of each coordinate's range; 0: clean) the fit pools.
FIT_LEVELS = [0.0, 0.005, 0.01, 0.02, 0.035, 0.05]
DURATION_S = 8.0
SHOULDERS = [0.0, 0.4, -0.3]
#: Subject sizes the trials cycle through: the IK models were trained on 0.9–1.1, the chain
#: (torques: they scale with size, which it is not told) on 1.0 only.
LENGTH_SCALES = {"q": [1.0, 0.95, 1.05], "tau": [1.0]}
ONE_SIGMA = 0.6827
MEMORY_WINDOWS = 1.0  # the running means remember one window of the model ...
#: ... and at least this many frames: a 5-frame window (wrist-id) would judge the angles' noise
#: from its last few third differences alone.
MIN_MEMORY_FRAMES = 50.0
#: Powers of the running means tried (1: affine in the variances; wrist-id's errors on noisy
#: angles hardly grow with the noise, so it takes 0.3-0.4).
POWERS = [0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]
#: Constants tried, as multiples of the median squared error of the fit's frames (and 0).
CONSTANTS = list(np.geomspace(1e-3, 3.0, 36))
#: name -> (noise kind, its parameters); None: clean.
CONDITIONS: dict[str, tuple[str, dict[str, float]] | None] = {
    "clean": None,
    "uniform 1 %": ("uniform", {"fraction": 0.01}),
    "uniform 5 %": ("uniform", {"fraction": 0.05}),
    "gaussian 1 mm": ("gaussian", {"sigma": 1e-3}),
}
MODELS_DIR = Path(__file__).resolve().parents[1] / "python" / "ikid" / "models"


def trial(seed: int, k: int, rate_hz: float, truth: str, noise: tuple[str, dict] | None) -> ikid.Trial:
    """Seed ``seed``'s trial (the ``k``-th of its list: shoulder and size cycle) at ``rate_hz``."""
    sizes = LENGTH_SCALES[truth]
    t = ikid.simulate(
        seed=seed,
        duration=DURATION_S,
        shoulder_flexion=SHOULDERS[k % len(SHOULDERS)],
        length_scale=sizes[k % len(sizes)],
        output_every=round(1000.0 / rate_hz),
    )
    return t if noise is None else t.with_noise(noise[0], seed + 1, **noise[1])


def model_input(model: _native.Model, t: ikid.Trial) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What ``model``'s stream reads of trial ``t``: (its input rows, their times, the trial's
    frame of each row). The trial's markers, or for a joint-state model the joint states of the
    angles ``UPSTREAM`` gives from them (the frames it gave an output for)."""
    if model.feature_set != "joint_state":
        return t.markers, t.time, np.arange(len(t.time))
    rate, _ = MODELS[model.name]
    angles = run_model(UPSTREAM, t.markers, t.time, rate_hz=rate)
    states = joint_states(angles.values, angles.time)
    whole = np.all(np.isfinite(states), axis=1)  # as `ikid id`: short stretches are left out
    return states[whole], angles.time[whole], angles.frame[whole]


def collect(model: _native.Model, seeds: list[int], level: float) -> dict[str, np.ndarray]:
    """Per output row of the stream ``ikid ik`` runs (early outputs for a correcting model): the
    error against the truth, the σ terms (``Stream.sd_terms``) and whether it is the per-frame
    solution. Rows before the terms exist, and implausible rows (never written), are left out."""
    rate, truth = MODELS[model.name]
    offset = model.card.get("output_offset") is not None
    errors, noise, correction, per_frame = [], [], [], []
    for k, seed in enumerate(seeds):
        t = trial(seed, k, rate, truth, ("uniform", {"fraction": level}) if level > 0 else None)
        stream = model.stream(early_outputs=offset)
        rows, times, index = model_input(model, t)
        true = getattr(t, truth)[index]
        for i, (time, frame) in enumerate(zip(times, rows, strict=True)):
            try:
                out = stream.push(frame, time=float(time))
            except ikid.InputError:
                continue
            terms = stream.sd_terms
            if out is None or terms is None or stream.status & _native.FRAME_STATUS["implausible"]:
                continue  # an implausible row is not written (ikid.pipeline), so needs no σ
            errors.append(np.asarray(out, np.float64) - true[i])
            noise.append(terms[0])
            correction.append(terms[1])
            per_frame.append(bool(stream.status & _native.FRAME_STATUS["per_frame"]))
    return {
        "error": np.array(errors),
        "noise": np.array(noise),
        "correction": np.array(correction),
        "per_frame": np.array(per_frame),
    }


def memory_frames(model: _native.Model) -> float:
    """Frames the card's running means remember."""
    return max(float(model.window * MEMORY_WINDOWS), MIN_MEMORY_FRAMES)


@functools.cache
def fit_rows(name: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The FIT seeds' rows of shipped model ``name`` at every FIT level, pooled, and each
    row's level (index into FIT_LEVELS). The running means remember what the fitted card's will
    (:func:`memory_frames`; a card of zeros carries that to the stream)."""
    model = ikid.load(name)
    n = model.n_outputs
    zeros = {
        "method": "affine-variance-v1",
        "memory_frames": memory_frames(model),
        "power": 1.0,
        "constant": [0.0] * n,
        "angle_noise": [[0.0] * 3 for _ in range(n)],
        "correction": [0.0] * n,
    }
    model = model.with_uncertainty(json.dumps(zeros))
    rows = [collect(model, FIT, level) for level in FIT_LEVELS]
    level_of = np.concatenate([np.full(len(r["error"]), j) for j, r in enumerate(rows)])
    return {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}, level_of


def weighted_quantile(x: np.ndarray, weight: np.ndarray, q: float) -> float:
    """The smallest value of ``x`` at or below which lies a share ``q`` of the total weight."""
    order = np.argsort(x)
    cumulative = np.cumsum(weight[order])
    return float(x[order][np.searchsorted(cumulative, q * cumulative[-1])])


def fit(name: str, powers: list[float]) -> dict:
    """The card's ``uncertainty`` for shipped model ``name``, fitted on the FIT seeds' frames.

    Per output ``c``: σ² = a + k · T^p, T the running mean a σ is to scale with — the squared
    correction D_c for a correcting model, else the mean of the three angles' noise N (the
    terms are near collinear; one is kept). For each power ``p`` in POWERS and constant ``a``
    in CONSTANTS, ``k`` is the one that covers 68.27 % of the fit's frames, each noise level
    weighing the same (a weighted quantile: frame e is within ±σ iff (e² − a) / T^p ≤ k; a
    level's rows are those written, fewer where more are implausible); the (p, a) kept is the
    one whose worst noise level is nearest 68.27 %. Coverage is the target, so it is what is
    fitted."""
    model = ikid.load(name)
    offset = model.card.get("output_offset") is not None
    data, level_of = fit_rows(name)
    use = ~data["per_frame"]  # per-frame rows use that solution's own noise, unfitted
    levels = level_of[use]
    weight = 1.0 / np.bincount(levels)[levels]
    constant, angle_noise, correction, worst_level, chosen = [], [], [], [], []
    for c in range(model.n_outputs):
        term = data["correction"][use, c] if offset else data["noise"][use].mean(axis=1)
        e2 = data["error"][use, c] ** 2
        scale = float(np.median(e2))
        best: tuple[float, float, float, float] | None = None
        for p in powers:
            tp = np.maximum(term, 1e-300) ** p
            for a in [0.0, *(scale * f for f in CONSTANTS)]:
                ratio = (e2 - a) / tp
                k = weighted_quantile(ratio, weight, ONE_SIGMA)
                if k <= 0:
                    continue
                within = ratio <= k
                worst = max(abs(within[levels == j].mean() - ONE_SIGMA) for j in range(len(FIT_LEVELS)))
                if best is None or worst < best[0]:
                    best = (worst, p, a, k)
        assert best is not None, f"{name}: no σ model fits output {c}"
        worst_level.append(best[0])
        chosen.append(best[1])
        constant.append(best[2])
        k = best[3]
        angle_noise.append([0.0] * 3 if offset else [k / 3.0] * 3)
        correction.append(k if offset else 0.0)
    return {
        "method": "affine-variance-v1",
        "memory_frames": memory_frames(model),
        "powers": chosen,
        "constant": constant,
        "angle_noise": angle_noise,
        "correction": correction,
        "fit_worst_level": worst_level,
    }


def card_of(name: str) -> dict:
    """:func:`fit` with one power for the model (the card has one): each output refitted at the
    power that is best for the outputs together."""
    fits = {p: fit(name, [p]) for p in POWERS}
    p = min(fits, key=lambda q: max(fits[q]["fit_worst_level"]))
    f = fits[p]
    return {
        "method": f["method"],
        "memory_frames": f["memory_frames"],
        "power": float(p),
        "constant": f["constant"],
        "angle_noise": f["angle_noise"],
        "correction": f["correction"],
        "provenance": {
            "study": "studies/net_sigma.py",
            "fit_seeds": FIT,
            "fit_noise": {"kind": "uniform", "fractions": FIT_LEVELS},
            "fit_worst_level_deviation": f["fit_worst_level"],
            "duration_s": DURATION_S,
            "shoulders_rad": SHOULDERS,
            "length_scales": LENGTH_SCALES[MODELS[name][1]],
            "powers_tried": POWERS,
        },
    }


def coverage(model: _native.Model, seeds: list[int] = SCORE) -> dict[str, dict[str, float]]:
    """Per condition, on ``seeds`` through ``ikid.pipeline.run_model`` (what ``ikid ik`` runs):
    ``within`` (share of (row, output) with a σ whose truth lies within ±σ, per output and all),
    ``with_sd`` (share of output rows that have a σ) and ``rows``."""
    rate, truth = MODELS[model.name]
    result = {}
    for condition, noise in CONDITIONS.items():
        hits, has, n = [], 0, 0
        for k, seed in enumerate(seeds):
            t = trial(seed, k, rate, truth, noise)
            rows, times, index = model_input(model, t)
            run = run_model(model, rows, times, rate_hz=rate)
            error = np.abs(run.values - getattr(t, truth)[index][run.frame])
            known = np.all(np.isfinite(run.sd), axis=1)
            hits.append(error[known] <= run.sd[known])
            has += int(known.sum())
            n += len(known)
        within = np.concatenate(hits)
        result[condition] = {
            "within": float(within.mean()),
            **{f"within.{o}": float(within[:, c].mean()) for c, o in enumerate(model.output_names)},
            "with_sd": has / max(n, 1),
            "rows": float(n),
        }
    return result


def describe(name: str, cover: dict[str, dict[str, float]]) -> str:
    per = "; ".join(
        f"{cond} {v['within']:.3f} ("
        + "/".join(f"{v[k]:.2f}" for k in v if k.startswith("within."))
        + f", σ on {v['with_sd']:.3f} of {int(v['rows'])} rows)"
        for cond, v in cover.items()
    )
    return f"{name}: within ±1 σ on seeds {SCORE[0]}-{SCORE[-1]} (target {ONE_SIGMA}): {per}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--write", action="store_true", help="write the fitted coefficients into the shipped files"
    )
    p.add_argument("--score", action="store_true", help="only score the shipped cards")
    p.add_argument("--models", nargs="+", default=list(MODELS), choices=list(MODELS))
    args = p.parse_args()
    for name in args.models:
        model = ikid.load(name)
        if not args.score:
            card = card_of(name)
            model = model.with_uncertainty(json.dumps(card))
            cover = coverage(model)
            card["provenance"]["coverage"] = {"seeds": SCORE, **cover}
            model = ikid.load(name).with_uncertainty(json.dumps(card))
            print(f"{name}: fitted {json.dumps({k: card[k] for k in card if k != 'provenance'})}")
            if args.write:
                model.save(MODELS_DIR / f"{name}.safetensors")
                print(f"{name}: written to {MODELS_DIR / f'{name}.safetensors'}")
        elif model.card.get("uncertainty") is None:
            print(f"{name}: its card has no uncertainty")
            continue
        else:
            cover = coverage(model)
        print(describe(name, cover), flush=True)


if __name__ == "__main__":
    main()
