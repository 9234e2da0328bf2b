"""OpenSim model files (``.osim``, OpenSim 4.x) of ikid's body model, so a trial opens in
OpenSim with the same subject, coordinates and markers.

    ikid.interop.opensim.write_osim("s01.osim", length_scale=1.1, shoulder_flexion=0.79)

The model: ground → ``forearm`` welded at the shoulder pose's forearm frame → ``hand`` by a
``CustomJoint`` whose three rotations are ikid's coordinates, with the same names, ranges,
order and axes, so OpenSim's coordinate values are ikid's angles (radians). Everything is
read from :func:`ikid.body_model`; written with the standard library only. OpenSim itself (the
``opensim`` package, ``pip install 'ikid[eval]'``) is needed only to open the file and by the
helpers that run it: :func:`marker_positions` (its forward kinematics),
:func:`inverse_kinematics` (its ``InverseKinematicsTool``) and :func:`inverse_dynamics` (its
``InverseDynamicsSolver``).

Why no intermediate bodies: OpenSim's ``SpatialTransform`` composes ``rotation1..3`` as
rotations about axes carried along by the previous ones (``R = R1·R2·R3``), exactly ikid's
intrinsic sequence, so one mobilizer carries the whole wrist. ``tests/test_opensim.py``
checks it: OpenSim's forward kinematics equals ``ikid.forward_markers`` (≤ 1 µm required, 1e-16 m
measured) and OpenSim's inverse dynamics ``ikid.reference_id`` (< 1e-7 N·m: ikid's two virtual
links, 1e-6 kg, are left out of the file).
"""

from __future__ import annotations

import math
import os
import re
import time
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import ikid
from ikid.io._atomic import write_text_atomic

#: ``OpenSimDocument`` version: the 4.0 format (sockets, offset frames), which every 4.x opens.
DOCUMENT_VERSION = "40000"
#: Names of the two joints (the coordinates take their names from the body model).
WELD_JOINT = "forearm_in_lab"
WRIST_JOINT = "wrist"

# OpenSim resolves components by path: a name with a slash or whitespace cannot be found.
_BAD_NAME = re.compile(r"[\s/\\]")

MarkerSpec = tuple[str, str, Sequence[float]]


def write_osim(
    path: str | os.PathLike[str],
    *,
    length_scale: float = 1.0,
    mass_scale: float = 1.0,
    shoulder_flexion: float = 0.0,
    marker_shift: Any = None,
    markers: Sequence[MarkerSpec] | None = None,
    name: str = "ikid_wrist",
) -> Path:
    """Write the subject (scaled by ``length_scale``/``mass_scale``, forearm at
    ``shoulder_flexion`` rad) as an OpenSim model, atomically; returns ``path``.

    Markers: ikid's six (moved by ``marker_shift`` ``(6, 3)`` m in their segments' frames, as in
    :func:`ikid.forward_markers`), or ``markers``: a list of ``(name, segment, offset)`` with
    ``segment`` ``"forearm"`` or ``"hand"`` and ``offset`` in metres in that segment's frame
    (the frames of ``crates/ikid/src/body.rs``), for another marker set. Not both.
    """
    text = osim_text(
        length_scale=length_scale,
        mass_scale=mass_scale,
        shoulder_flexion=shoulder_flexion,
        marker_shift=marker_shift,
        markers=markers,
        name=name,
    )
    return write_text_atomic(path, text)


def osim_text(
    *,
    length_scale: float = 1.0,
    mass_scale: float = 1.0,
    shoulder_flexion: float = 0.0,
    marker_shift: Any = None,
    markers: Sequence[MarkerSpec] | None = None,
    name: str = "ikid_wrist",
) -> str:
    """The ``.osim`` XML text :func:`write_osim` writes."""
    if markers is not None and marker_shift is not None:
        raise ValueError(
            "give either marker_shift (moves ikid's six markers) or markers (a marker "
            "set of your own), not both"
        )
    _check_name("model name", name)
    body = ikid.body_model(length_scale, mass_scale, shoulder_flexion, marker_shift)
    segments = body["segments"]
    marker_list = (
        _marker_list(markers, segments)
        if markers is not None
        else [(m["name"], m["segment"], m["offset"]) for m in body["markers"]]
    )

    doc = ET.Element("OpenSimDocument", Version=DOCUMENT_VERSION)
    model = _sub(doc, "Model", name=name)
    _sub(
        model,
        "credits",
        text="Written by ikid " + ikid.__version__ + " from ikid.body_model" + _subject_note(body),
    )
    _sub(model, "length_units", text="meters")
    _sub(model, "force_units", text="N")
    _sub(model, "Ground", name="ground")
    _sub(model, "gravity", text=_vec(body["gravity"]))

    bodies = _sub(_sub(model, "BodySet", name="bodyset"), "objects")
    for seg in ("forearm", "hand"):
        p = segments[seg]
        b = _sub(bodies, "Body", name=seg)
        _sub(b, "mass", text=_num(p["mass"]))
        _sub(b, "mass_center", text=_vec(p["com"]))
        # Principal moments along the segment axes: the products of inertia are zero.
        _sub(b, "inertia", text=_vec([*p["inertia"], 0.0, 0.0, 0.0]))

    joints = _sub(_sub(model, "JointSet", name="jointset"), "objects")
    pose = body["forearm_pose"]
    weld = _sub(joints, "WeldJoint", name=WELD_JOINT)
    _sub(weld, "socket_parent_frame", text="ground_offset")
    _sub(weld, "socket_child_frame", text="forearm_offset")
    frames = _sub(weld, "frames")
    _offset_frame(frames, "ground_offset", "/ground", pose["translation"], _xyz_body_fixed(pose["rotation"]))
    _offset_frame(frames, "forearm_offset", "/bodyset/forearm", [0.0] * 3, [0.0] * 3)

    wrist = _sub(joints, "CustomJoint", name=WRIST_JOINT)
    _sub(wrist, "socket_parent_frame", text="forearm_offset")
    _sub(wrist, "socket_child_frame", text="hand_offset")
    coords = _sub(wrist, "coordinates")
    for c in body["coordinates"]:
        co = _sub(coords, "Coordinate", name=c["name"])
        _sub(co, "default_value", text="0")
        _sub(co, "range", text=_vec(c["range"]))
        # Unclamped: OpenSim's IK is then the same unconstrained least squares as
        # ikid.reference_ik (noise may push a fit past the anatomical range).
        _sub(co, "clamped", text="false")
        _sub(co, "locked", text="false")
    frames = _sub(wrist, "frames")
    # Both joint frames at the wrist centre, aligned with the segments: the hand frame equals
    # the forearm frame at zero angles.
    _offset_frame(frames, "forearm_offset", "/bodyset/forearm", [0.0] * 3, [0.0] * 3)
    _offset_frame(frames, "hand_offset", "/bodyset/hand", [0.0] * 3, [0.0] * 3)
    st = _sub(wrist, "SpatialTransform")
    for i, c in enumerate(body["coordinates"]):
        ax = _sub(st, "TransformAxis", name=f"rotation{i + 1}")
        _sub(ax, "coordinates", text=c["name"])
        _sub(ax, "axis", text=_vec(c["axis"]))
        _sub(_sub(ax, "LinearFunction", name="function"), "coefficients", text="1 0")
    for i, axis in enumerate(([1, 0, 0], [0, 1, 0], [0, 0, 1])):
        ax = _sub(st, "TransformAxis", name=f"translation{i + 1}")
        _sub(ax, "coordinates")
        _sub(ax, "axis", text=_vec(axis))
        _sub(_sub(ax, "Constant", name="function"), "value", text="0")

    objects = _sub(_sub(model, "MarkerSet", name="markerset"), "objects")
    for label, seg, offset in marker_list:
        mk = _sub(objects, "Marker", name=label)
        _sub(mk, "socket_parent_frame", text=f"/bodyset/{seg}")
        _sub(mk, "location", text=_vec(offset))
        _sub(mk, "fixed", text="true")

    ET.indent(doc, space="\t")
    return '<?xml version="1.0" encoding="UTF-8" ?>\n' + ET.tostring(doc, encoding="unicode") + "\n"


@dataclass
class IKResult:
    """Angles from OpenSim's ``InverseKinematicsTool`` and what the run cost."""

    time: np.ndarray
    #: ``(n, len(coordinates))`` radians, columns in ``coordinates`` order.
    q: np.ndarray
    coordinates: list[str]
    #: Wall time of ``InverseKinematicsTool.run()``: reading the marker file, building the
    #: system, solving every frame, writing the ``.mot``. Loading the model is not included.
    seconds: float


def marker_positions(model_path: str | os.PathLike[str], q: Any) -> np.ndarray:
    """OpenSim's forward kinematics: every marker of the model in the lab at each row of
    coordinate values ``q`` ``(n, n_coordinates)`` (radians, the model's coordinate order);
    ``(n, 3 * n_markers)`` metres, markers in the model's order."""
    osim = require_opensim()
    model = osim.Model(str(model_path))
    state = model.initSystem()
    coords, markers = model.getCoordinateSet(), model.getMarkerSet()
    q = np.atleast_2d(np.asarray(q, np.float64))
    if q.ndim != 2 or q.shape[1] != coords.getSize():
        raise ValueError(f"q: expected (n, {coords.getSize()}) coordinate values, got shape {q.shape}")
    out = np.empty((len(q), 3 * markers.getSize()))
    for i, row in enumerate(q):
        for j, v in enumerate(row):
            coords.get(j).setValue(state, float(v), False)  # no constraints to enforce: a tree
        model.realizePosition(state)
        for k in range(markers.getSize()):
            p = markers.get(k).getLocationInGround(state)
            out[i, 3 * k : 3 * k + 3] = (p.get(0), p.get(1), p.get(2))
    return out


def inverse_dynamics(model_path: str | os.PathLike[str], q: Any, qd: Any, qdd: Any) -> np.ndarray:
    """OpenSim's inverse dynamics: the generalized forces ``(n, n_coordinates)`` (N·m for the
    wrist's rotations) that give accelerations ``qdd`` at ``q``, ``qd`` (radians, rad/s, rad/s²,
    the model's coordinate order), with gravity and no other forces."""
    osim = require_opensim()
    model = osim.Model(str(model_path))
    state = model.initSystem()
    coords = model.getCoordinateSet()
    nc = coords.getSize()
    arrays = [np.atleast_2d(np.asarray(a, np.float64)) for a in (q, qd, qdd)]
    for what, a in zip(("q", "qd", "qdd"), arrays, strict=True):
        if a.shape != (len(arrays[0]), nc):
            raise ValueError(f"{what}: expected ({len(arrays[0])}, {nc}) values, got shape {a.shape}")
    if model.getNumSpeeds() != nc:
        raise ValueError(
            f"{model_path}: {model.getNumSpeeds()} mobilities for {nc} coordinates "
            "(constraints?); not supported"
        )
    # Coordinates' values and speeds by name; accelerations in mobility order (the state's u).
    u_index = [_speed_index(model, state, coords.get(j)) for j in range(nc)]
    solver = osim.InverseDynamicsSolver(model)
    udot = osim.Vector(nc, 0.0)
    out = np.empty((len(arrays[0]), nc))
    for i, (qi, qdi, qddi) in enumerate(zip(*arrays, strict=True)):
        for j in range(nc):
            coords.get(j).setValue(state, float(qi[j]), False)
            coords.get(j).setSpeedValue(state, float(qdi[j]))
            udot.set(u_index[j], float(qddi[j]))
        model.realizeVelocity(state)
        tau = solver.solve(state, udot)
        out[i] = [tau.get(u_index[j]) for j in range(nc)]
    return out


def inverse_kinematics(
    model_path: str | os.PathLike[str],
    marker_file: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    accuracy: float | None = None,
) -> IKResult:
    """Run OpenSim's ``InverseKinematicsTool`` on a ``.trc`` over its whole time range, every
    model marker weighted 1 (the tool's default weight, made explicit), writing ``output``
    (``.mot``). ``accuracy`` is the solver's convergence tolerance (OpenSim's default 1e-5 if
    None). Markers the file lacks are an error naming them."""
    osim = require_opensim()
    from ikid.io import read_storage, read_trc

    data = read_trc(marker_file)
    model = osim.Model(str(model_path))
    names = [model.getMarkerSet().get(k).getName() for k in range(model.getMarkerSet().getSize())]
    absent = [n for n in names if n not in data.labels]
    if absent:
        raise ValueError(
            f"{marker_file}: no column for model marker(s) {', '.join(absent)}; the file "
            f"has {', '.join(data.labels)}"
        )
    tool = osim.InverseKinematicsTool()
    tool.setModel(model)
    tool.setMarkerDataFileName(str(marker_file))
    tool.setStartTime(float(data.time[0]))
    tool.setEndTime(float(data.time[-1]))
    tool.setOutputMotionFileName(str(output))
    tool.set_report_errors(False)
    tasks = tool.getIKTaskSet()
    for n in names:
        task = osim.IKMarkerTask()
        task.setName(n)
        task.setWeight(1.0)
        task.setApply(True)
        tasks.cloneAndAppend(task)
    if accuracy is not None:
        tool.set_accuracy(float(accuracy))
    start = time.perf_counter()
    if not tool.run():
        raise RuntimeError(f"OpenSim's InverseKinematicsTool failed on {marker_file} (see OpenSim's log)")
    seconds = time.perf_counter() - start
    table = read_storage(output)
    coords = [model.getCoordinateSet().get(j).getName() for j in range(model.getCoordinateSet().getSize())]
    q = table.select(coords)
    return IKResult(table.time, np.radians(q) if table.in_degrees else q, coords, seconds)


def require_opensim() -> Any:
    """The ``opensim`` module, or an ImportError saying how to install it."""
    try:
        import opensim
    except ImportError as e:
        raise ImportError(
            f"running OpenSim needs the opensim package (pip install 'ikid[eval]'): {e}"
        ) from None
    return opensim


# --- helpers -------------------------------------------------------------------------------------


def _marker_list(
    markers: Sequence[MarkerSpec], segments: dict[str, Any]
) -> list[tuple[str, str, list[float]]]:
    """Checked ``(name, segment, offset)`` triples; errors name the marker and the field."""
    out: list[tuple[str, str, list[float]]] = []
    seen: set[str] = set()
    if len(markers) == 0:
        raise ValueError(
            "markers: the list is empty (give (name, segment, offset) triples, or None for ikid's six)"
        )
    for i, entry in enumerate(markers):
        try:
            label, seg, offset = entry
        except (TypeError, ValueError):
            raise ValueError(f"markers[{i}]: expected (name, segment, offset), got {entry!r}") from None
        if not isinstance(label, str) or not label:
            raise ValueError(f"markers[{i}]: name must be a non-empty string, got {label!r}")
        _check_name(f"markers[{i}] name", label)
        if label in seen:
            raise ValueError(f"markers[{i}]: name {label!r} appears more than once")
        seen.add(label)
        if seg not in segments:
            raise ValueError(f"marker {label!r}: segment {seg!r} is not one of {', '.join(segments)}")
        try:
            xyz = [float(v) for v in offset]
        except (TypeError, ValueError):
            raise ValueError(f"marker {label!r}: offset must be 3 numbers (m), got {offset!r}") from None
        if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
            raise ValueError(f"marker {label!r}: offset must be 3 finite numbers (m), got {offset!r}")
        out.append((label, seg, xyz))
    return out


def _speed_index(model: Any, state: Any, coordinate: Any) -> int:
    """Where a coordinate's speed sits in the state's u: set it alone and look."""
    u = state.updU()
    for k in range(u.size()):
        u.set(k, 0.0)
    coordinate.setSpeedValue(state, 1.0)
    hits = [k for k in range(state.getU().size()) if state.getU().get(k) == 1.0]
    if len(hits) != 1:
        raise ValueError(f"coordinate {coordinate.getName()}: cannot find its speed in the state")
    coordinate.setSpeedValue(state, 0.0)
    return hits[0]


def _check_name(what: str, name: str) -> None:
    if not name or _BAD_NAME.search(name):
        raise ValueError(f"{what} {name!r}: OpenSim names must be non-empty, without whitespace or slashes")


def _xyz_body_fixed(rows: Sequence[Sequence[float]]) -> list[float]:
    """Angles ``(a, b, c)`` with ``R = Rx(a)·Ry(b)·Rz(c)``: OpenSim's offset-frame ``orientation``
    (a frame-fixed x-y-z sequence).

    ``b`` comes from atan2, not asin: the shoulder-neutral forearm pose is exactly at
    ``b = 90°``, where asin would lose half the digits.
    """
    r = rows
    b = math.atan2(r[0][2], math.hypot(r[0][0], r[0][1]))
    if math.hypot(r[0][0], r[0][1]) < 1e-12:
        # Gimbal lock: only a ± c is defined; put it all in a.
        return [math.atan2(r[2][1], r[1][1]), b, 0.0]
    return [math.atan2(-r[1][2], r[2][2]), b, math.atan2(-r[0][1], r[0][0])]


def _offset_frame(
    parent: ET.Element, name: str, socket: str, translation: Sequence[float], orientation: Sequence[float]
) -> None:
    f = _sub(parent, "PhysicalOffsetFrame", name=name)
    _sub(f, "socket_parent", text=socket)
    _sub(f, "translation", text=_vec(translation))
    _sub(f, "orientation", text=_vec(orientation))


def _subject_note(body: dict[str, Any]) -> str:
    return (
        f" (length_scale {body['length_scale']:g}, mass_scale {body['mass_scale']:g},"
        f" shoulder_flexion {body['shoulder_flexion']:g} rad)"
    )


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrs: str) -> ET.Element:
    e = ET.SubElement(parent, tag, attrs)
    if text is not None:
        e.text = text
    return e


def _num(v: float) -> str:
    # repr is the shortest text that reads back as the same double: no rounding in the file.
    return repr(float(v))


def _vec(values: Sequence[float]) -> str:
    return " ".join(_num(v) for v in values)
