"""The classical reference solvers from Python: exact on clean markers, consistent dynamics."""

import numpy as np
import pytest

import ikid


def random_angles(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(lo, hi, n) for _, _, (lo, hi) in ikid.COORDINATES], axis=1)


@pytest.mark.parametrize(("shoulder_deg", "scale"), [(0.0, 1.0), (45.0, 1.2), (-20.0, 0.8)])
def test_reference_ik_recovers_clean_angles(shoulder_deg, scale):
    q = random_angles(500)
    markers = ikid.forward_markers(q, np.radians(shoulder_deg), length_scale=scale)
    got = ikid.reference_ik(markers, length_scale=scale)
    assert np.sqrt(np.mean((got - q) ** 2)) < 1e-9


def test_reference_ik_names_a_missing_marker():
    markers = ikid.forward_markers(random_angles(5))
    markers[3, 12] = np.nan
    with pytest.raises(ikid.InputError, match=r"frame 3: value MC5\.x"):
        ikid.reference_ik(markers)


def test_reference_id_gravity_and_inertia():
    zeros = np.zeros((1, 3))
    assert np.allclose(ikid.reference_id(zeros, zeros, zeros), 0.0, atol=1e-12)
    # Flexion acceleration from rest, wrist straight, arm horizontal-forward (90° flexion):
    # torque grows linearly with the acceleration.
    qdd = np.array([[0.0, 100.0, 0.0], [0.0, 200.0, 0.0]])
    tau = ikid.reference_id(np.zeros((2, 3)), np.zeros((2, 3)), qdd, shoulder_flexion=np.pi / 2)
    static = ikid.reference_id(
        np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3)), shoulder_flexion=np.pi / 2
    )
    assert np.isclose(tau[1, 1] - static[0, 1], 2 * (tau[0, 1] - static[0, 1]))
    assert tau[0, 1] - static[0, 1] > 0.1  # about 0.34 N·m for the default hand


def test_reference_id_errors_name_the_row():
    q = np.zeros((3, 3))
    qd = q.copy()
    qd[2, 1] = np.inf
    with pytest.raises(ikid.InputError, match=r"row 2: qd\.ra_wr_e_f is inf"):
        ikid.reference_id(q, qd, q)
    with pytest.raises(ikid.InputError, match="whole rows"):
        ikid.reference_id(q, q[:2], q)


def test_reference_id_refuses_non_finite_shoulder_and_overflow():
    z = np.zeros((1, 3))
    with pytest.raises(ikid.InputError, match="shoulder_flexion: is NaN"):
        ikid.reference_id(z, z, z, shoulder_flexion=float("nan"))
    with pytest.raises(ikid.InputError, match="non-finite"):
        ikid.reference_id(z, np.full((1, 3), 1e200), z)
    with pytest.raises(ikid.InputError, match="dtype"):
        ikid.reference_ik(np.zeros((2, 18), complex))
