"""biorbd model files (``.bioMod``) of ikid's body model, for biorbd's Kalman filter, IK and ID.

:func:`write_biomod` writes the subject and shoulder pose that :func:`ikid.body_model`
describes — the same numbers the simulator and the reference solvers use — so biorbd's
forward kinematics at ikid's angles gives ikid's markers and its inverse dynamics gives
ikid's Newton–Euler torques (``tests/test_biorbd.py`` checks both). Standard library only:
biorbd itself is needed to *read* the file, never to write it.

Layout of the file (lab frame = biorbd's root, gravity from the body model):

* ``forearm``: fixed to the lab at the shoulder pose (no degrees of freedom), with its mass,
  centre of mass, inertia and the forearm markers.
* ``wrist_<coordinate>`` (one per wrist coordinate but the last): the tiny links between the
  wrist's joints (``virtual_link``), one rotation each.
* ``hand``: the last wrist rotation, the hand's inertial parameters and markers.

biorbd rotates a segment about its own x, y or z axis only. Where an ikid axis is not one of
those (``s_p`` turns about −y), the segment's frame is turned by a constant rotation ``C``
that carries a local axis onto the ikid axis (``C Rot(e, q) Cᵀ = Rot(C e, q)``); the next
segment's fixed transform undoes it (``RT = C_prevᵀ C``), and a segment's mass properties
and markers are expressed in its turned frame. The hand's frame is ikid's hand frame
whenever its axis is a positive basis axis (true for ikid's ``ad_ab`` = +x).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from decimal import Decimal
from pathlib import Path
from typing import Any

Matrix = list[list[float]]

_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def write_biomod(
    path: str | os.PathLike[str],
    *,
    length_scale: float = 1.0,
    mass_scale: float = 1.0,
    shoulder_flexion: float = 0.0,
    marker_shift: Sequence[Sequence[float]] | None = None,
) -> Path:
    """Writes the ``.bioMod`` of a subject (``length_scale``, ``mass_scale``, optional
    ``marker_shift`` per marker in its segment's frame, m) with the forearm at
    ``shoulder_flexion`` (rad) to ``path``, atomically, and returns the path.

    Degrees of freedom: the three wrist coordinates in ikid's order (s_p, e_f, ad_ab), with
    their ranges; markers: ikid's six, in ikid's order, all technical.
    """
    import ikid  # the body model is the single source of truth
    from ikid.io._atomic import write_text_atomic

    body = ikid.body_model(
        length_scale=length_scale,
        mass_scale=mass_scale,
        shoulder_flexion=shoulder_flexion,
        marker_shift=marker_shift,
    )
    return write_text_atomic(path, biomod_text(body))


def biomod_text(body: dict[str, Any]) -> str:
    """The ``.bioMod`` text of a body model as returned by :func:`ikid.body_model`."""
    coords = body["coordinates"]
    segments = body["segments"]
    pose = body["forearm_pose"]
    lines = [
        "version 4",
        "",
        "// Written by ikid.interop.biorbd from ikid.body_model("
        f"length_scale={body['length_scale']!r}, mass_scale={body['mass_scale']!r}, "
        f"shoulder_flexion={body['shoulder_flexion']!r}).",
        "// Lab frame: X anterior, Y up, Z right. Wrist coordinates in ikid's order; all values SI.",
        "gravity " + _vec(body["gravity"]),
        "",
    ]
    # Forearm: fixed in the lab, frame = ikid's forearm frame (origin at the wrist centre).
    lines += _segment(
        "forearm", None, pose["rotation"], pose["translation"], None, None, segments["forearm"], _identity()
    )

    parent, turn_prev = "forearm", _identity()
    for i, coord in enumerate(coords):
        last = i == len(coords) - 1
        name = "hand" if last else f"wrist_{_short(coord['name'])}"
        letter, turn = _local_axis(coord["axis"])
        # Fixed transform from the parent's (turned) frame to this segment's, at q = 0.
        rt = _matmul(_transpose(turn_prev), turn)
        params = segments["hand"] if last else body["virtual_link"]
        lines += _segment(name, parent, rt, [0.0, 0.0, 0.0], letter, coord["range"], params, turn)
        parent, turn_prev = name, turn

    # The hand's markers are expressed in the hand segment's (possibly turned) frame.
    turns = {"forearm": _identity(), "hand": turn_prev}
    for m in body["markers"]:
        local = _matvec(_transpose(turns[m["segment"]]), m["offset"])
        lines += [
            f"marker {m['name']}",
            f"    parent {m['segment']}",
            f"    position {_vec(local)}",
            "    technical 1",
            "endmarker",
            "",
        ]
    return "\n".join(lines)


# --- helpers -----------------------------------------------------------------------------------


def _segment(
    name: str,
    parent: str | None,
    rotation: Matrix,
    translation: Sequence[float],
    letter: str | None,
    q_range: Sequence[float] | None,
    params: dict[str, Any],
    turn: Matrix,
) -> list[str]:
    """One ``segment`` block; ``params`` (ikid's segment frame) re-expressed in the frame
    turned by ``turn``: com' = Cᵀ c, inertia' = Cᵀ diag(I) C."""
    com = _matvec(_transpose(turn), params["com"])
    diag = [[params["inertia"][r] if r == c else 0.0 for c in range(3)] for r in range(3)]
    inertia = _matmul(_matmul(_transpose(turn), diag), turn)
    out = [f"segment {name}"]
    if parent is not None:
        out.append(f"    parent {parent}")
    out += ["    rtinmatrix 1", "    rt"]
    for r in range(3):
        out.append(f"        {_vec(list(rotation[r]) + [translation[r]])}")
    out.append("        0 0 0 1")
    if letter is not None:
        out.append(f"    rotations {letter}")
        assert q_range is not None
        out.append(f"    rangesQ {_num(q_range[0])} {_num(q_range[1])}")
    out.append(f"    mass {_num(params['mass'])}")
    out.append(f"    com {_vec(com)}")
    out.append("    inertia")
    for r in range(3):
        out.append(f"        {_vec(inertia[r])}")
    out += ["endsegment", ""]
    return out


def _local_axis(axis: Sequence[float]) -> tuple[str, Matrix]:
    """The biorbd rotation letter and the constant turn ``C`` with ``C e_letter = axis``
    (``C`` = identity when ``axis`` is a positive basis axis)."""
    a = [float(v) for v in axis]
    norm = math.sqrt(sum(v * v for v in a))
    if not norm > 0:
        raise ValueError(f"coordinate axis {axis!r} has zero length")
    a = [v / norm for v in a]
    for letter, e in _AXES.items():
        if all(abs(x - y) < 1e-15 for x, y in zip(a, e, strict=True)):
            return letter, _identity()
    # Otherwise turn local x onto the axis: columns (a, b, a × b) form a proper rotation.
    helper = (0.0, 0.0, 1.0) if abs(a[2]) < 0.9 else (1.0, 0.0, 0.0)
    b = _cross(helper, a)
    nb = math.sqrt(sum(v * v for v in b))
    b = [v / nb for v in b]
    c = _cross(a, b)
    return "x", [[a[r], b[r], c[r]] for r in range(3)]


def _short(name: str) -> str:
    # "ra_wr_s_p" -> "s_p": the segment names stay readable in biorbd's listings.
    return name.split("_wr_", 1)[-1]


def _num(x: float) -> str:
    # Positional notation with every digit of the shortest round-trip repr: biorbd's reader
    # parses a plain number with stod, but evaluates "1.2e-17" as an expression (pow and a
    # 20-decimal fixed to_string), which loses digits.
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"non-finite value {x!r} in the body model")
    if x == 0.0:
        return "0"
    return format(Decimal(repr(x)), "f")


def _vec(v: Sequence[float]) -> str:
    return " ".join(_num(x) for x in v)


def _identity() -> Matrix:
    return [[1.0 if r == c else 0.0 for c in range(3)] for r in range(3)]


def _transpose(m: Matrix) -> Matrix:
    return [[m[c][r] for c in range(3)] for r in range(3)]


def _matmul(a: Matrix, b: Matrix) -> Matrix:
    return [[sum(a[r][k] * b[k][c] for k in range(3)) for c in range(3)] for r in range(3)]


def _matvec(m: Matrix, v: Sequence[float]) -> list[float]:
    return [sum(m[r][k] * v[k] for k in range(3)) for r in range(3)]


def _cross(a: Sequence[float], b: Sequence[float]) -> list[float]:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
