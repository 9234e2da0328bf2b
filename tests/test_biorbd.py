"""The .bioMod written from ikid's body model is the same body in biorbd: forward kinematics
at ikid's angles gives ikid's markers (≤ 1 µm), inverse dynamics gives ikid's Newton–Euler
torques (≤ 1e-6 N·m), for several subjects and the three shoulder poses."""

from __future__ import annotations

import math

import numpy as np
import pytest

import ikid
from ikid.interop.biorbd import biomod_text, write_biomod

biorbd = pytest.importorskip(
    "biorbd", reason="biorbd is an optional evaluation dependency (pip install 'ikid[eval]')"
)

SHOULDERS = [0.0, math.radians(45.0), math.radians(-20.0)]
# (length_scale, mass_scale): small and large subjects, one with a mass not following length.
SUBJECTS = [(0.85, 0.85**3), (1.0, 1.0), (1.2, 1.2**3), (1.15, 0.8)]
FK_TOL_M = 1e-6
ID_TOL_NM = 1e-6


def random_states(seed: int, n: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angles over the whole anatomical ranges, fast velocities and large accelerations."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array([c["range"] for c in ikid.body_model()["coordinates"]]).T
    return rng.uniform(lo, hi, (n, 3)), rng.uniform(-15.0, 15.0, (n, 3)), rng.uniform(-800.0, 800.0, (n, 3))


def load(tmp_path, **kw) -> biorbd.Model:
    path = write_biomod(tmp_path / "wrist.bioMod", **kw)
    return biorbd.Model(str(path))


def biorbd_markers(model, q: np.ndarray) -> np.ndarray:
    return np.array([np.concatenate([m.to_array() for m in model.markers(row)]) for row in q])


@pytest.mark.parametrize("length_scale,mass_scale", SUBJECTS)
@pytest.mark.parametrize("shoulder", SHOULDERS)
def test_forward_kinematics_and_inverse_dynamics_match_ikid(tmp_path, shoulder, length_scale, mass_scale):
    model = load(tmp_path, length_scale=length_scale, mass_scale=mass_scale, shoulder_flexion=shoulder)
    q, qd, qdd = random_states(seed=int(1000 * (shoulder + length_scale + mass_scale)))

    fk_err = np.abs(
        biorbd_markers(model, q)
        - ikid.forward_markers(q, shoulder_flexion=shoulder, length_scale=length_scale, mass_scale=mass_scale)
    ).max()
    assert fk_err <= FK_TOL_M, f"biorbd markers differ from ikid's by {fk_err:.3g} m"

    tau_biorbd = np.array(
        [model.InverseDynamics(a, b, c).to_array() for a, b, c in zip(q, qd, qdd, strict=True)]
    )
    tau_ikid = ikid.reference_id(
        q, qd, qdd, shoulder_flexion=shoulder, length_scale=length_scale, mass_scale=mass_scale
    )
    # The states are violent enough that a wrong inertia, centre of mass or axis shows up.
    assert np.abs(tau_ikid).max() > 0.5
    id_err = np.abs(tau_biorbd - tau_ikid).max()
    assert id_err <= ID_TOL_NM, f"biorbd torques differ from ikid's by {id_err:.3g} N·m"


def test_gravity_only_torques_match(tmp_path):
    # At rest only gravity loads the wrist: checks gravity's direction and the hand's mass/com alone.
    model = load(tmp_path, shoulder_flexion=SHOULDERS[1])
    q, _, _ = random_states(seed=5)
    zero = np.zeros_like(q)
    tau_biorbd = np.array([model.InverseDynamics(a, z, z).to_array() for a, z in zip(q, zero, strict=True)])
    tau_ikid = ikid.reference_id(q, zero, zero, shoulder_flexion=SHOULDERS[1])
    assert np.abs(tau_ikid).max() > 0.05
    assert np.abs(tau_biorbd - tau_ikid).max() <= ID_TOL_NM


def test_names_order_and_ranges(tmp_path):
    model = load(tmp_path)
    assert [n.to_string() for n in model.markerNames()] == ikid.marker_names()
    assert model.nbTechnicalMarkers() == len(ikid.marker_names())
    assert model.nbQ() == 3
    # One rotation per wrist segment, in ikid's coordinate order, with ikid's ranges.
    dofs = [n.to_string() for n in model.nameDof()]
    assert [d.split("_Rot")[0] for d in dofs] == ["wrist_s_p", "wrist_e_f", "hand"]
    lo, hi = biorbd.get_range_q(model)
    ranges = np.array([c["range"] for c in ikid.body_model()["coordinates"]])
    np.testing.assert_allclose(np.stack([lo, hi], 1), ranges, rtol=0, atol=1e-15)
    g = model.getGravity().to_array()
    np.testing.assert_array_equal(g, ikid.body_model()["gravity"])


def test_marker_shift_moves_the_markers(tmp_path):
    shift = np.zeros((6, 3))
    shift[4] = [0.004, -0.01, 0.006]  # MC5, in the hand's frame
    shift[1] = [0.0, 0.003, -0.002]  # USP, in the forearm's frame
    model = load(tmp_path, length_scale=1.1, shoulder_flexion=SHOULDERS[2], marker_shift=shift)
    q, _, _ = random_states(seed=9)
    expect = ikid.forward_markers(q, shoulder_flexion=SHOULDERS[2], length_scale=1.1, marker_shift=shift)
    assert np.abs(biorbd_markers(model, q) - expect).max() <= FK_TOL_M
    assert (
        np.abs(expect - ikid.forward_markers(q, shoulder_flexion=SHOULDERS[2], length_scale=1.1)).max() > 5e-3
    )


def test_numbers_are_written_positionally():
    # biorbd evaluates "1e-10" as an expression with a fixed-decimal round trip: every number
    # must be plain positional notation so that stod reads it exactly.
    text = biomod_text(ikid.body_model(length_scale=1.37, mass_scale=0.61, shoulder_flexion=0.3))
    body = [line for line in text.splitlines() if not line.lstrip().startswith("//")]
    assert not any(
        "e-" in tok or "e+" in tok
        for line in body
        for tok in line.split()
        if tok[0].isdigit() or tok[0] == "-"
    )


def test_write_is_atomic_and_reports_bad_arguments(tmp_path):
    path = write_biomod(tmp_path / "w.bioMod")
    assert path.read_text().startswith("version 4")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.bioMod"]  # no temporary left behind
    with pytest.raises(ValueError, match="length_scale"):
        write_biomod(tmp_path / "bad.bioMod", length_scale=-1.0)
    assert not (tmp_path / "bad.bioMod").exists()
