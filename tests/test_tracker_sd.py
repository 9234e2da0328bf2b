"""The Tracker's standard deviations (``Tracker.output_sd``, ``run``'s ``q_sd``/``tau_sd``):
there once the filter runs, and calibrated — about 68 % of frames within ±1 σ — on a simulated
trial no setting was chosen on (the simulation's own angles and torques are the oracle)."""

from __future__ import annotations

import numpy as np
import pytest

import ikid
from ikid import _native
from studies import sigma_coverage as study

# Held out from the study's tuning and scoring seeds alike.
SEED = 9720


def test_the_study_tunes_and_scores_on_disjoint_seeds_and_this_test_on_neither():
    assert not set(study.TUNE) & set(study.SCORE)
    assert SEED not in study.TUNE + study.SCORE and SEED + 1 not in study.TUNE + study.SCORE


def test_sd_is_none_before_the_start_and_push_and_run_agree():
    trial = ikid.simulate(seed=SEED, duration=1.0).with_noise("gaussian", SEED + 1, sigma=1e-3)
    tracker = ikid.Tracker(rate_hz=1000.0)
    assert tracker.output_sd is None
    pushed = []
    for frame in trial.markers:
        out = tracker.push(frame)
        sd = tracker.output_sd
        if out is None:
            assert sd is None
            pushed.append(np.full((2, 3), np.nan))
            continue
        assert sd is not None and sd.shape == (2, 3) and np.all(np.isfinite(sd)) and np.all(sd > 0)
        pushed.append(sd)
    run = ikid.Tracker(rate_hz=1000.0).run(np.asarray(trial.markers), sd=True)
    assert "q_sd" not in ikid.Tracker(rate_hz=1000.0).run(
        np.asarray(trial.markers)
    )  # only when asked: it costs
    np.testing.assert_array_equal(run["q_sd"], np.array([p[0] for p in pushed]))
    np.testing.assert_array_equal(run["tau_sd"], np.array([p[1] for p in pushed]))
    assert np.all(np.isnan(run["q_sd"][: run["start"]]))


@pytest.mark.parametrize(
    "noise",
    [("gaussian", {"sigma": 1e-3}), ("uniform", {"fraction": 0.05})],
    ids=["gaussian-1mm-every-marker", "uniform-5pct-hand"],
)
def test_sd_covers_about_68_percent_of_the_true_errors(noise):
    # Gaussian noise on every marker: the forearm's pose noise, which the filter's covariance
    # does not count, is most of the angles' error (without it, 0.50 of frames were covered).
    trial = ikid.simulate(seed=SEED, duration=4.0, shoulder_flexion=0.2)
    noisy = trial.with_noise(noise[0], SEED + 1, **noise[1])
    out = ikid.Tracker(rate_hz=1000.0).run(np.asarray(noisy.markers), sd=True)
    keep = np.arange(len(trial.time)) >= max(out["start"], 500)
    q_cover = np.mean((np.abs(out["q"] - trial.q) <= out["q_sd"])[keep])
    tau_cover = np.mean((np.abs(out["tau"] - trial.tau) <= out["tau_sd"])[keep])
    # 3500 frames × 3 coordinates, correlated in time: a band about the 0.683 a calibrated σ
    # gives. Measured: Gaussian 0.718 / 0.709 (0.668 / 0.668 before the filter counted the
    # forearm's noise: it is now averaged, not only added), uniform 0.721 / 0.658; σ × 1.2 gave
    # 0.752 / 0.761 and 0.804 / 0.754, σ / 1.2 0.579 / 0.577 (Gaussian): out of it.
    assert 0.62 < q_cover < 0.745, q_cover
    assert 0.62 < tau_cover < 0.745, tau_cover


def test_the_shipped_torque_scale_is_the_one_the_study_tunes():
    assert study.tuned_torque_scale() == pytest.approx(_native.SD_SCALE_TAU, abs=0.01)


def test_the_shipped_refined_shares_are_the_ones_the_study_tunes():
    q, tau = study.tuned_refined_scales()
    assert q == pytest.approx(_native.REFINED_SD_SCALE_Q, abs=0.01)
    assert tau == pytest.approx(_native.REFINED_SD_SCALE_TAU, abs=0.01)


#: Trials for the refined σ's check: held out from the study's seeds, and pooled (a refined
#: estimate's coverage varies more from trial to trial than the filter's).
REFINED_SEEDS = [9722, 9724, 9726]


@pytest.mark.parametrize(
    "noise",
    [("gaussian", {"sigma": 1e-3}), ("uniform", {"fraction": 0.05})],
    ids=["gaussian-1mm-every-marker", "uniform-5pct-hand"],
)
def test_a_refined_estimates_sd_covers_about_68_percent_too(noise):
    # The shipped refiner (ikid track's default at 1 kHz) narrows the estimate's error; its σ is
    # the filter's narrowed by the shares tuned on other seeds. Judged on the refined frames.
    assert not set(REFINED_SEEDS + [s + 1 for s in REFINED_SEEDS]) & set(study.TUNE + study.SCORE + [SEED])
    q_hits, tau_hits = [], []
    for k, seed in enumerate(REFINED_SEEDS):
        trial = ikid.simulate(seed=seed, duration=4.0, shoulder_flexion=[0.2, -0.3, 0.5][k])
        noisy = trial.with_noise(noise[0], seed + 1, **noise[1])
        out = ikid.Tracker(rate_hz=1000.0, refiner=ikid.load("wrist-track")).run(
            np.asarray(noisy.markers), sd=True
        )
        keep = (np.arange(len(trial.time)) >= max(out["start"], 500)) & out["refined"]
        assert keep.mean() > 0.8
        q_hits.append((np.abs(out["q"] - trial.q) <= out["q_sd"])[keep])
        tau_hits.append((np.abs(out["tau"] - trial.tau) <= out["tau_sd"])[keep])
    q_cover, tau_cover = np.mean(np.concatenate(q_hits)), np.mean(np.concatenate(tau_hits))
    # Before the shares (the filter's σ on refined estimates): 0.86 / 0.92 covered with 1 mm on
    # every marker. The torques' share is one for every noise level, and the refiner helps the
    # torques more at 1 % than at 5 %: at 5 % they are covered less (0.58 on the study's seeds).
    assert 0.62 < q_cover < 0.745, q_cover
    assert 0.55 < tau_cover < 0.745, tau_cover
