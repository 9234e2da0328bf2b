"""The ``.bioMod`` a biorbd user would write for an exam subject: no knowledge of the exam model.

The exact-body peer (``biomod.py``) is given the model's own axes, segment geometry, inertia and
nominal marker placement: an oracle no lab has. A biorbd user builds the wrist from what the
session records, the way ikid's calibration does (issue #28: "peers run as their own users
would"):

* the forearm's frame from the static trial's four probed landmarks, ISB style (y from the
  mid-styloids to the mid-epicondyles, x = y × (ulnar → radial styloid), z = x × y; origin at the
  mid-styloids, taken as the wrist's centre), free in the lab (six degrees of freedom, as ikid
  tracks it: a lab's forearm moves, and that the exam's stands still is not something the peer
  is told);
* the hand turning about that centre by the ISB joint coordinate system's three rotations,
  ``rotations yzx`` (R = Ry(q0) Rz(q1) Rx(q2)): with ikid's convention ``R = Rot(−y, s_p)
  Rot(z, e_f) Rot(x, ad_ab)`` that is ``s_p = −q0, e_f = q1, ad_ab = q2``, the truth's own
  decomposition — only the model's geometry (oblique pronation axis, carpal rows, offsets) is
  unknown to it. (Forearm rotation about ISB's own forearm axis instead, the line through the
  ulnar styloid, was tried: on the exam's first model and pose its angle error was 8× this
  one's; the peer is given the better of the two);
* the markers where the static trial puts them (its mean over the trial, the static posture taken
  as neutral, as ikid's calibration takes it);
* the hand's inertia from de Leva's (1996, J. Biomech. 29(9), 1223–1230, Table 4, men)
  proportions — hand length (wrist joint centre to the 3rd metacarpal head) 86.2 mm for a 268.9 mm
  forearm (elbow to wrist joint centres), centre of mass at 79.0 % of it from the wrist, radii of
  gyration 62.8 % (flexion axis), 51.3 % (deviation axis), 40.1 % (long axis) — scaled by the
  forearm the landmarks measure, with the hand mass a lab weighs or looks up (the same figure ikid
  gets as ``--mass-scale``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from studies.exam.models import GRAVITY, isb_forearm

DE_LEVA_HAND_OVER_FOREARM = 86.2 / 268.9
DE_LEVA_HAND_COM = 0.790
DE_LEVA_HAND_GYRATION = {"x": 0.513, "y": 0.401, "z": 0.628}  # deviation, long, flexion axes


def _v(v) -> str:
    return " ".join(f"{float(x):.12g}" for x in v)


def write_lab_biomod(
    static: np.ndarray,
    marker_labels: list[str],
    hand_labels: set[str],
    landmark_labels: dict[str, str],
    hand_mass: float,
    path: str | Path,
) -> Path:
    """Writes the lab's bioMod from the static trial ``static`` ``(n, 3·(markers + landmarks))``:
    ``marker_labels`` then the landmarks' columns in ``landmark_labels``' order (ikid name ->
    label), metres, NaN where missing; ``hand_labels``: the markers on the hand."""
    mean = np.nanmean(static, axis=0).reshape(-1, 3)
    if not np.isfinite(mean).all():
        raise ValueError("the static trial has a marker or landmark missing in every frame")
    pts = dict(zip(marker_labels + list(landmark_labels.values()), mean, strict=True))
    lms = {name: pts[label] for name, label in landmark_labels.items()}
    f, centre, forearm = isb_forearm(lms)
    hand_len = DE_LEVA_HAND_OVER_FOREARM * forearm
    com = np.array([0.0, -DE_LEVA_HAND_COM * hand_len, 0.0])  # distal: −y
    inertia = np.diag([hand_mass * (DE_LEVA_HAND_GYRATION[a] * hand_len) ** 2 for a in "xyz"])
    lines = ["version 4", "", "// an exam subject as a biorbd user builds it (studies/exam/lab_biomod.py)"]
    lines += [f"gravity {_v(GRAVITY)}", "", "segment forearm", "    rtinmatrix 1", "    rt"]
    lines += [f"        {_v(list(f[i]) + [centre[i]])}" for i in range(3)] + ["        0 0 0 1"]
    lines += ["    translations xyz", "    rotations xyz", "endsegment", ""]
    lines += ["segment hand", "    parent forearm", "    rotations yzx"]
    lines += ["    rangesQ", "        -3.14159 3.14159", "        -1.5 1.5", "        -3.14159 3.14159"]
    lines += [f"    mass {hand_mass:.12g}", f"    com {_v(com)}", "    inertia"]
    lines += [f"        {_v(row)}" for row in inertia] + ["endsegment", ""]
    for label in marker_labels:
        local = f.T @ (pts[label] - centre)  # the static posture is neutral: hand frame = forearm frame
        lines += [
            f"marker {label}",
            f"    parent {'hand' if label in hand_labels else 'forearm'}",
            f"    position {_v(local)}",
            "    technical 1",
            "endmarker",
            "",
        ]
    path = Path(path)
    path.write_text("\n".join(lines))
    return path


def to_ikid(q: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lab model's wrist coordinates (its last three, after the forearm's six: q0, q1, q2
    about y, z, x) and their generalized forces in ikid's convention: s_p = −q0 (its torque
    −τ0), e_f = q1, ad_ab = q2."""
    sign = np.array([-1.0, 1.0, 1.0])
    return q[..., -3:] * sign, tau[..., -3:] * sign
