"""From a model's coordinates to ikid's convention, and OpenSim's kinematics and dynamics.

The mapping (written down in docs/exam.md): the forearm's anatomical frame F is the ISB frame
of the model's own landmarks (``models.forearm_frame``), fixed in the ulna; the hand's frame
is F carried by the hand from the model's neutral posture q0. The hand's orientation in the
forearm's frame, ``R(q) = Fᵀ R_hand(q) R_hand(q0)ᵀ F`` (R_hand: the hand body's rotation in
the ulna), is decomposed as ikid does (``crates/ikid/src/body.rs``): ``R = Rot(−y, s_p)
Rot(z, e_f) Rot(x, ad_ab)``, intrinsic; s_p + = supination, e_f + = flexion, ad_ab + = ulnar
deviation. Torques: ``τ_ikid = (∂q_model/∂q_ikid)ᵀ τ_model`` (virtual work), the Jacobian by
central differences of the mapping. Peers' outputs in the model's coordinates go through the
same functions.
"""

from __future__ import annotations

import numpy as np

from studies.exam.models import WristModel, body_poses, forearm_frame

# ikid's wrist axes (crates/ikid/src/body.rs COORDINATES): s_p about -y, e_f about z, ad_ab about x.
A1, A2, A3 = np.array((0.0, -1.0, 0.0)), np.array((0.0, 0.0, 1.0)), np.array((1.0, 0.0, 0.0))


def ikid_angles(r: np.ndarray) -> np.ndarray:
    """(s_p, e_f, ad_ab) of hand orientations ``r`` ``(n, 3, 3)`` in the forearm frame: the
    inverse of ``Rot(a1,q1) Rot(a2,q2) Rot(a3,q3)`` for |e_f| < 90°."""
    s = np.sign(np.cross(A1, A2) @ A3)
    ra3, ra2, ra1 = r @ A3, r @ A2, r @ A1
    q2 = np.arcsin(np.clip(s * (ra3 @ A1), -1.0, 1.0))
    q1 = np.arctan2(-s * (ra3 @ A2), ra3 @ A3)
    q3 = np.arctan2(-s * (ra2 @ A1), ra1 @ A1)
    return np.stack([q1, q2, q3], axis=-1)


class Mapping:
    """Model coordinates -> ikid's angles for one model (see the module docstring)."""

    def __init__(self, model: WristModel):
        self.model = model
        self.f, _ = forearm_frame(model)
        self.r0 = body_poses(model, np.array(model.neutral))[model.hand][0]

    def from_hand_rotations(self, r_hand_in_ulna: np.ndarray) -> np.ndarray:
        """ikid angles ``(n, 3)`` from the hand body's rotations in the ulna ``(n, 3, 3)``."""
        rel = self.f.T @ r_hand_in_ulna @ self.r0.T @ self.f
        return ikid_angles(rel)

    def angles(self, q: np.ndarray) -> np.ndarray:
        """ikid angles ``(n, 3)`` at model coordinates ``q`` ``(n, 3)`` (NumPy kinematics)."""
        q = np.atleast_2d(q)
        rs = np.stack([body_poses(self.model, row)[self.model.hand][0] for row in q])
        return self.from_hand_rotations(rs)

    def jacobian(self, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
        """∂(ikid angles)/∂(model coordinates) ``(n, 3, 3)``, central differences."""
        q = np.atleast_2d(q)
        cols = []
        for j in range(q.shape[1]):
            d = np.zeros(q.shape[1])
            d[j] = h
            cols.append((self.angles(q + d) - self.angles(q - d)) / (2 * h))
        return np.stack(cols, axis=-1)

    def torques(self, q: np.ndarray, tau_model: np.ndarray) -> np.ndarray:
        """Model generalized forces ``(n, 3)`` at ``q`` -> ikid's, by virtual work:
        τ_ikid = (∂q_model/∂q_ikid)ᵀ τ_model = J⁻ᵀ τ_model with J = ∂q_ikid/∂q_model."""
        jac = self.jacobian(q)
        return np.linalg.solve(np.swapaxes(jac, 1, 2), tau_model[..., None])[..., 0]


def opensim_hand_rotations(osim_path: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenSim's forward kinematics of the model file at coordinates ``q`` ``(n, 3)``: the hand's
    rotation in the ulna ``(n, 3, 3)`` and its pose in the lab (rotations, translations)."""
    import opensim as osim

    model = osim.Model(osim_path)
    state = model.initSystem()
    coords = model.getCoordinateSet()
    hand, ulna = model.getBodySet().get("hand"), model.getBodySet().get("ulna")
    model.realizePosition(state)
    ru = _rot(ulna.getTransformInGround(state).R())
    n = len(q)
    r_lab, t_lab = np.empty((n, 3, 3)), np.empty((n, 3))
    for i, row in enumerate(q):
        for j in range(3):
            coords.get(j).setValue(state, float(row[j]), False)
        model.realizePosition(state)
        x = hand.getTransformInGround(state)
        r_lab[i] = _rot(x.R())
        p = x.p()
        t_lab[i] = (p.get(0), p.get(1), p.get(2))
    return ru.T @ r_lab, (r_lab, t_lab)


def _rot(r) -> np.ndarray:
    return np.array([[r.get(i, j) for j in range(3)] for i in range(3)])
