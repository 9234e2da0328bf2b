"""The exam (studies/exam, `make exam`): out of training's reach, and its truth and peers exact.

(a) Training cannot reach the exam: its seeds lie far beyond every seed a training config or
script can produce, and nothing under training/ or python/ikid imports the exam or names its
models. (b) The truth mapping, checked by an independent oracle: OpenSim's markers at known
coordinates, calibrated by ikid's landmark method and solved by ikid's per-frame reference IK,
give the mapped truth angles. (c) The bioMod writer: biorbd's marker positions equal OpenSim's.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

osim = pytest.importorskip("opensim", reason="the exam needs OpenSim (pip install 'ikid[eval]')")
osim.Logger.removeFileSink()  # no opensim.log in the working directory

import ikid  # noqa: E402
from ikid.interop.opensim import marker_positions  # noqa: E402
from studies.exam import exam  # noqa: E402
from studies.exam import markers as MK  # noqa: E402
from studies.exam.biomod import write_biomod  # noqa: E402
from studies.exam.lab_biomod import to_ikid, write_lab_biomod  # noqa: E402
from studies.exam.models import MODELS, build_osim, isb_forearm  # noqa: E402
from studies.exam.truth import Mapping  # noqa: E402

TRAINING = ROOT / "training"


def _config_seeds() -> list[int]:
    """Every integer under a key naming a seed in the training configs."""
    found: list[int] = []

    def walk(node):
        if isinstance(node, dict):
            for k, v in node.items():
                if "seed" in k.lower():
                    found.extend(v if isinstance(v, list) else [v])
                walk(v)

    for cfg in sorted((TRAINING / "ikid_training" / "configs").glob("*.toml")):
        walk(tomllib.loads(cfg.read_text()))
    return [int(s) for s in found]


def _script_seed_constants() -> list[int]:
    """Integer literals the training and tuning scripts assign to, or add to, a seed."""
    pattern = re.compile(
        r"(?i)(?:seed\w*\s*[=:]\s*|seed\w*\s*\+\s*|([0-9][0-9_]*)\s*\+\s*\w*seed)([0-9][0-9_]*)?"
    )
    found: list[int] = []
    for path in sorted(TRAINING.rglob("*.py")) + [ROOT / "python" / "ikid" / "sim.py"]:
        for m in pattern.finditer(path.read_text()):
            for g in m.groups():
                if g:
                    found.append(int(g.replace("_", "")))
    return found


def test_training_cannot_reach_the_exams_seeds_or_models():
    training = _config_seeds() + _script_seed_constants()
    assert training, "found no training seeds: the search patterns no longer match the scripts"
    exam_seeds = exam.all_seeds()
    # A training seed s reaches s + (combinations, offsets, per-recording strides): refine.py's
    # noise seeds go to 31_000 + 1000 x recordings. Far more than any of that is left free.
    reach = 10 * max(training) + 1_000_000
    assert min(exam_seeds) > reach, (min(exam_seeds), reach)
    assert not set(exam_seeds) & set(training)
    for folder in (TRAINING, ROOT / "python" / "ikid"):
        for path in folder.rglob("*.py"):
            text = path.read_text()
            assert "studies.exam" not in text and "studies/exam" not in text, path
            for name in MODELS:
                assert name not in text, f"{path} names the exam's model {name}"


@pytest.mark.parametrize("name", list(MODELS))
def test_truth_mapping_agrees_with_ikids_landmark_calibration_and_reference_ik(tmp_path, name):
    model = MODELS[name]()
    pts = MK.layout(model, "anatomical", 0)
    lms = MK.landmark_points(model)
    path = build_osim(model, 0.4, {**pts, **lms}, str(tmp_path / "m.osim"))
    rng = np.random.default_rng(5)
    lo, hi = model.ranges().T
    q0 = np.array(model.neutral)
    q = np.vstack(
        [np.repeat(q0[None], 5, 0), rng.uniform(q0 + 0.7 * (lo - q0), q0 + 0.7 * (hi - q0), (40, 3))]
    )
    xyz = marker_positions(path, q)  # OpenSim's kinematics: markers then landmarks
    frames, landmarks = xyz[:, :18], xyz[:, 18:]
    cal = ikid.calibration.calibrate_neutral(frames[:5], landmarks[:5])
    got = ikid.reference_ik(cal.apply(frames).astype(np.float64))
    want = Mapping(model).angles(q)
    # The calibrated frames pass through float32 (Calibration.apply): ~1e-6 rad of rounding.
    np.testing.assert_allclose(got, want, atol=5e-6)


@pytest.mark.parametrize("name", list(MODELS))
def test_biomod_puts_the_markers_where_opensim_does(tmp_path, name):
    biorbd = pytest.importorskip(
        "biorbd", reason="the exam's EKF peer needs biorbd (pip install 'ikid[eval]')"
    )
    model = MODELS[name]()
    pts = MK.layout(model, "cluster", 3)
    path = build_osim(model, -0.3, pts, str(tmp_path / "m.osim"))
    bio = biorbd.Model(str(write_biomod(model, -0.3, pts, tmp_path / "m.bioMod")))
    rng = np.random.default_rng(8)
    lo, hi = model.ranges().T
    q = rng.uniform(lo, hi, (10, 3))
    want = marker_positions(path, q)
    got = np.array([np.concatenate([m.to_array() for m in bio.markers(row)]) for row in q])
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_torque_mapping_is_virtual_work():
    """τ_ikid · δq_ikid = τ_model · δq_model for a small move: the map conserves power."""
    model = MODELS["gonzalez1997"]()
    mapping = Mapping(model)
    q = np.array([[0.3, -0.4, 0.2]])
    tau_model = np.array([[0.5, -1.2, 0.7]])
    tau = mapping.torques(q, tau_model)
    dq = np.array([[1e-5, -2e-5, 1.5e-5]])
    d_ikid = mapping.angles(q + dq) - mapping.angles(q)
    assert float(np.sum(tau * d_ikid)) == pytest.approx(float(np.sum(tau_model * dq)), rel=1e-4)


def _rot(axis, angle: float) -> np.ndarray:
    """Rodrigues: the rotation by ``angle`` about the unit ``axis`` (independent of every module)."""
    a = np.asarray(axis, float)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_lab_biomod_turns_the_hand_by_ikids_convention_and_weighs_it(tmp_path):
    """The lab-model peer: a static trial's markers, turned by ikid's ``Rot(−y, s_p) Rot(z, e_f)
    Rot(x, ad_ab)`` about the mid-styloids in the landmarks' ISB frame, are where biorbd puts them
    at the coordinates ``to_ikid`` maps back to those angles; at rest its inverse dynamics is the
    hand's weight's moment about each axis."""
    biorbd = pytest.importorskip(
        "biorbd", reason="the exam's EKF peer needs biorbd (pip install 'ikid[eval]')"
    )
    rng = np.random.default_rng(5)
    axis = rng.normal(size=3)
    turn = _rot(axis / np.linalg.norm(axis), 1.1)
    origin = np.array([0.2, 1.0, -0.3])
    local_lms = {  # a right forearm in its ISB frame: y proximal, z radial
        "lateral_epicondyle": [0.0, 0.26, 0.03],
        "medial_epicondyle": [0.0, 0.26, -0.03],
        "radial_styloid": [0.0, 0.0, 0.03],
        "ulnar_styloid": [0.0, 0.0, -0.03],
    }
    local_mk = np.array(
        [
            [0.01, 0.02, 0.03],
            [0.01, 0.02, -0.03],
            [-0.02, 0.15, 0.0],
            [0.01, -0.07, 0.03],
            [0.01, -0.07, -0.03],
            [-0.02, -0.03, 0.0],
        ]
    )
    labels = ["A", "B", "C", "D", "E", "F"]
    lab = lambda p: origin + turn @ np.asarray(p, float)  # noqa: E731
    frame = np.concatenate([lab(p) for p in local_mk] + [lab(local_lms[k]) for k in MK.LANDMARKS])
    static = np.tile(frame, (5, 1))
    mass = 0.45
    bio = biorbd.Model(
        str(write_lab_biomod(static, labels, {"D", "E", "F"}, MK.LANDMARKS, mass, tmp_path / "l.bioMod"))
    )
    f, centre, _ = isb_forearm({k: lab(v) for k, v in local_lms.items()})
    np.testing.assert_allclose(f, turn, atol=1e-12)
    for s_p, e_f, ad in rng.uniform(-0.8, 0.8, (5, 3)):
        r = _rot([0, -1, 0], s_p) @ _rot([0, 0, 1], e_f) @ _rot([1, 0, 0], ad)
        want = [lab(p) for p in local_mk[:3]] + [lab(r @ p) for p in local_mk[3:]]
        wrist, _ = to_ikid(np.array([s_p, e_f, ad]), np.zeros(3))  # the map is its own inverse
        q = np.concatenate([np.zeros(6), wrist])  # the forearm where the static trial had it
        got = [m.to_array() for m in bio.markers(q)]
        np.testing.assert_allclose(got, want, atol=1e-9)
    # At rest in neutral: τ_j = (r_com × m g) · axis_j (the hand's weight held by the joint).
    q0 = np.zeros(9)
    _, tau = to_ikid(q0, bio.InverseDynamics(q0, q0, q0).to_array())
    tau = tau * np.array([-1.0, 1.0, 1.0])  # back to the model's own coordinates
    g = np.array([0.0, -9.80665, 0.0])
    r_com = turn @ np.array([0.0, -0.79 * 86.2 / 268.9 * 0.26, 0.0])
    moment = np.cross(r_com, mass * g)  # about the mid-styloids, where all three axes cross
    want_tau = -np.array([moment @ turn[:, 1], moment @ turn[:, 2], moment @ turn[:, 0]])
    np.testing.assert_allclose(tau, want_tau, atol=1e-9)
