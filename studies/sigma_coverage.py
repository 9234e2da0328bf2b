"""How far to trust the Tracker's standard deviations (`Tracker.output_sd`, from its
covariance): the share of frames whose true angle (torque) lies within ±1 σ of the estimate,
on simulated trials with marker noise that no setting here was chosen on.

A calibrated σ covers 68.3 % of frames. The raw figure is reported as measured. A scale factor
for σ is then tuned on one set of trials (seeds TUNE) — the factor that makes 68.3 % of their
frames fall within ±factor·σ — and its coverage scored on another (seeds SCORE): never tuned
and scored on the same frames.

    python studies/sigma_coverage.py      # prints the figures; `make live` prints the raw one
"""

from __future__ import annotations

import numpy as np

import ikid

RATE_HZ = 1000.0
DURATION_S = 4.0
SETTLE_S = 0.5  # the filter's start-up (its initial covariance is wide on purpose)
TUNE = [9700, 9701, 9702]
SCORE = [9710, 9711, 9712, 9713, 9714, 9715]
SHOULDERS = [0.0, 0.4, -0.3]
NOISE_SIGMA_M = 1e-3  # Gaussian marker noise, 1 mm per coordinate
ONE_SIGMA = 0.6827


def errors_over_sd(seeds: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """|estimate − truth| / σ per frame and coordinate (after SETTLE_S), angles and torques."""
    angles, torques = [], []
    for k, seed in enumerate(seeds):
        trial = ikid.simulate(seed=seed, duration=DURATION_S, shoulder_flexion=SHOULDERS[k % len(SHOULDERS)])
        noisy = trial.with_noise("gaussian", seed + 1, sigma=NOISE_SIGMA_M)
        tracker = ikid.Tracker(rate_hz=RATE_HZ)
        q_true, tau_true = np.asarray(trial.q), np.asarray(trial.tau)
        for i, frame in enumerate(noisy.markers):
            out = tracker.push(frame)
            sd = tracker.output_sd
            if out is None or sd is None or i < SETTLE_S * RATE_HZ:
                continue
            angles.append(np.abs(out[0] - q_true[i]) / sd[0])
            torques.append(np.abs(out[3] - tau_true[i]) / sd[1])
    return np.array(angles), np.array(torques)


def coverage() -> dict[str, float]:
    """Raw coverage on the scored trials, the factor tuned on the others, and its coverage."""
    tune_q, tune_tau = errors_over_sd(TUNE)
    score_q, score_tau = errors_over_sd(SCORE)
    factor_q = float(np.quantile(tune_q, ONE_SIGMA))
    factor_tau = float(np.quantile(tune_tau, ONE_SIGMA))
    return {
        "raw_angles": float(np.mean(score_q <= 1.0)),
        "raw_torques": float(np.mean(score_tau <= 1.0)),
        "factor_angles": factor_q,
        "factor_torques": factor_tau,
        "tuned_angles": float(np.mean(score_q <= factor_q)),
        "tuned_torques": float(np.mean(score_tau <= factor_tau)),
        "frames": float(len(score_q)),
    }


def describe(c: dict[str, float]) -> str:
    held_out = f"{int(c['frames'])} held-out frames ({len(SCORE)} trials, {NOISE_SIGMA_M * 1e3:g} mm noise)"
    raw = f"raw σ covers angles {c['raw_angles']:.3f}, torques {c['raw_torques']:.3f}"
    factors = f"σ × {c['factor_angles']:.3g} (angles), × {c['factor_torques']:.3g} (torques)"
    tuned = f"tuned on seeds {TUNE[0]}-{TUNE[-1]}: {c['tuned_angles']:.3f}, {c['tuned_torques']:.3f}"
    return f"sigma coverage on {held_out}: {raw}; {factors} {tuned}"


if __name__ == "__main__":
    print(describe(coverage()))
