"""biorbd's model (``.bioMod``) of an exam model, for biorbd's EKF and inverse dynamics.

The same description as the OpenSim model (``models.WristModel``): the ulna fixed in the lab,
then one segment per rotation. biorbd turns a segment about its own x, y or z only, so each
segment's frame is the model's body frame turned by a constant ``C`` whose z is the link's
axis (``C Rot(e_z, q) Cᵀ = Rot(C e_z, q)``); the next segment's fixed transform undoes it
(``RT = C_prevᵀ [C | centre]``) and mass properties and markers are expressed in the turned
frame (``tests/test_exam.py`` checks biorbd's marker positions against OpenSim's).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from studies.exam.models import GRAVITY, WristModel, ulna_in_lab


def _turn(axis) -> np.ndarray:
    a = np.asarray(axis, float)
    b = np.cross(a, (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0))
    b /= np.linalg.norm(b)
    return np.column_stack([b, np.cross(a, b), a])


def _v(v) -> str:
    return " ".join(f"{float(x):.12g}" for x in v)


def write_biomod(
    model: WristModel, shoulder_flexion: float, markers: dict[str, tuple[str, np.ndarray]], path: str | Path
) -> Path:
    """Writes the bioMod of ``model`` at the shoulder pose with ``markers`` (name -> (body,
    point in the body's frame), in the order given) to ``path``."""
    r, t = ulna_in_lab(model, shoulder_flexion)
    turns = {"ulna": np.eye(3)}
    lines = ["version 4", "", f"// exam model {model.name}: {model.source}", f"gravity {_v(GRAVITY)}", ""]

    def segment(name, parent, rt, tr, dof, q_range, inertial, turn):
        out = [f"segment {name}"]
        if parent:
            out.append(f"    parent {parent}")
        out += ["    rtinmatrix 1", "    rt"]
        out += [f"        {_v(list(rt[i]) + [tr[i]])}" for i in range(3)] + ["        0 0 0 1"]
        if dof:
            out += ["    rotations z", f"    rangesQ {q_range[0]:.12g} {q_range[1]:.12g}"]
        out += [
            f"    mass {inertial.mass:.12g}",
            f"    com {_v(turn.T @ np.array(inertial.com))}",
            "    inertia",
        ]
        out += [f"        {_v(row)}" for row in turn.T @ inertial.inertia @ turn]
        return out + ["endsegment", ""]

    lines += segment("ulna", None, r, t, False, None, model.ulna, np.eye(3))
    for lk in model.links:
        c_prev, c = turns[lk.parent], _turn(lk.axis)
        turns[lk.body] = c
        lines += segment(
            lk.body, lk.parent, c_prev.T @ c, c_prev.T @ np.array(lk.centre), True, lk.range, lk.inertial, c
        )
    for name, (body, p) in markers.items():
        local = turns[body].T @ np.asarray(p, float)
        lines += [
            f"marker {name}",
            f"    parent {body}",
            f"    position {_v(local)}",
            "    technical 1",
            "endmarker",
            "",
        ]
    path = Path(path)
    path.write_text("\n".join(lines))
    return path
