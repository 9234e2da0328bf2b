"""Every shipped model's card carries its evaluation figures (issue #31: `wrist-track`'s had
none), measured as training measures them: the last 10 % of held-out simulated recordings at
the thesis' noise levels. The slow tier checks that `wrist-track`'s figures are what its
evaluation gives today (``python -m ikid_training.refine --metrics-only`` rewrites them)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import ikid


@pytest.mark.parametrize("name", ikid.available_models())
def test_every_shipped_card_carries_its_test_figures(name):
    metrics = ikid.load(name).card.get("metrics") or {}
    tests = {k: v for k, v in metrics.items() if k.startswith("test")}
    assert tests, f"{name}: no test figures in its card: {sorted(metrics)}"
    for label, m in tests.items():
        assert m["frames"] > 1000 and np.isfinite(m["mse"]) and m["mse"] > 0, (name, label, m)
        assert len(m["rmse"]) == 3 and m["unit"] in ("rad", "N*m"), (name, label, m)


def test_wrist_tracks_figures_are_the_tracker_refined_by_it_in_angles_and_torques():
    metrics = ikid.load("wrist-track").card["metrics"]
    for label in ("test_clean", "test_1%", "test_5%"):
        m = metrics[label]
        assert m["unit"] == "rad" and m["torque"]["unit"] == "N*m", m
        # The refiner earns its place: better than the bare filter on noisy markers.
        if label != "test_clean":
            assert m["mse"] < m["bare_filter_mse"]["angles"], (label, m)
            assert m["torque"]["mse"] < m["bare_filter_mse"]["torque"], (label, m)
    assert metrics["test_1%"]["mse"] < metrics["test_5%"]["mse"]
    assert "Tracker" in metrics["evaluated_on"]["estimator"]


@pytest.mark.skipif(importlib.util.find_spec("ikid_training") is None, reason="needs ikid-training")
def test_wrist_tracks_card_figures_are_what_its_evaluation_gives():
    from ikid_training import data as D
    from ikid_training.refine import card_metrics, evaluation_specs

    refiner = ikid.load("wrist-track")
    fresh = card_metrics(refiner, D.simulate_all(evaluation_specs()))
    card = refiner.card["metrics"]
    hint = "the Tracker or wrist-track changed: python -m ikid_training.refine --metrics-only rewrites them"
    for label in ("test_clean", "test_1%", "test_5%"):
        np.testing.assert_allclose(fresh[label]["mse"], card[label]["mse"], rtol=1e-6, err_msg=hint)
        np.testing.assert_allclose(
            fresh[label]["torque"]["mse"], card[label]["torque"]["mse"], rtol=1e-6, err_msg=hint
        )
