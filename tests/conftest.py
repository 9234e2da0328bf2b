"""Shared fixtures: small models built with NumPy only (no torch), and marker frames."""

from __future__ import annotations

import itertools
import json
import locale
import sys
from pathlib import Path

import numpy as np
import pytest

import ikid
from ikid import _native

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # for `training`

# The slow tier (`make test` only; `make check` runs the rest): the C programs under valgrind,
# training end to end and the shipped models' accuracy, the torch/OpenSim/biorbd peers, and
# the C3D corruption sweep (a process per case).
SLOW_MODULES = {
    "test_capi.py",
    "test_capi_tracker.py",
    "test_training.py",
    "test_parity.py",
    "test_opensim.py",
    "test_biorbd.py",
    "test_batch.py",  # 200 trials through `ikid run`, twice (~12 s)
}
SLOW_TESTS = {
    "test_train_and_report_on_a_lab_folder_through_the_cli",
    "test_corrupted_c3d_files_are_read_or_refused_never_a_crash",
    "test_wrist_tracks_card_figures_are_what_its_evaluation_gives",  # ~50 s: 9 trials, 3 noise levels
}


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.name in SLOW_MODULES or getattr(item, "originalname", item.name) in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)


def make_card(
    feature_set: str = "markers", window: int = 5, activations=("relu", "relu", "identity"), **extra
):
    card = {
        "format": "ikid-model",
        "format_version": 1,
        "name": "test",
        "task": "ik",
        "feature_set": feature_set,
        "feature_names": ikid.feature_set_info(feature_set)["feature_names"],
        "window": window,
        "predicted_frame": "newest",
        "frame_rate_hz": 1000.0,
        "outputs": [{"name": n, "unit": "rad"} for n in ikid.coordinate_names()],
        "activations": list(activations),
    }
    card.update(extra)
    return card


def make_model(feature_set: str = "markers", window: int = 5, hidden=(32, 32), seed: int = 0) -> ikid.Model:
    rng = np.random.default_rng(seed)
    n_in = window * ikid.feature_set_info(feature_set)["feature_len"]
    widths = [n_in, *hidden, 3]
    weights = [
        rng.uniform(-1, 1, (o, i)).astype(np.float32) / np.sqrt(i) for i, o in itertools.pairwise(widths)
    ]
    biases = [rng.uniform(-0.1, 0.1, o).astype(np.float32) for o in widths[1:]]
    acts = ["relu"] * len(hidden) + ["identity"]
    card = make_card(feature_set, window, acts)
    return _native.build_model(
        json.dumps(card),
        weights,
        biases,
        rng.uniform(0.5, 2, n_in).astype(np.float32),
        rng.uniform(-1, 1, n_in).astype(np.float32),
        np.full(3, 0.5, np.float32),
        np.full(3, 0.1, np.float32),
    )


def marker_frames(n: int, seed: int = 0) -> np.ndarray:
    """Plausible marker frames: the body model's markers moved by a smooth random wrist motion
    (rigid segments, as real markers are; the stream checks that)."""
    rng = np.random.default_rng(seed)
    q = 0.4 * np.sin(np.linspace(0, 3, n)[:, None] * rng.uniform(1, 3, 3) + rng.uniform(0, 6, 3))
    return ikid.forward_markers(q, 0.3).astype(np.float32)


@pytest.fixture(autouse=True)
def _locale_kept():
    """Puts the process's locale back after each test: biorbd sets LC_ALL to "C" when it loads a
    model, and every later ``open()`` without an encoding then read ASCII (about 20 tests of
    other files failed reading UTF-8 after tests/test_exam.py)."""
    before = locale.setlocale(locale.LC_ALL)
    yield
    if locale.setlocale(locale.LC_ALL) != before:
        locale.setlocale(locale.LC_ALL, before)


@pytest.fixture
def model() -> ikid.Model:
    return make_model()


@pytest.fixture
def frames() -> np.ndarray:
    return marker_frames(40)
