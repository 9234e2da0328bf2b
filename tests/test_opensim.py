"""The OpenSim model ikid writes (``ikid.interop.opensim``) is ikid's body model: OpenSim's own
forward kinematics of the file reproduces ``ikid.forward_markers``, its coordinates, masses and
markers are the body model's, a marker set of one's own round-trips, and OpenSim's IK on an
ikid trial gives back ikid's angles. Needs the ``opensim`` package (``ikid[eval]``)."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

import ikid
from ikid import io
from ikid.interop import opensim as ios

# Whole file: OpenSim's forward kinematics must equal ikid's to this (metres).
FK_TOL = 1e-6


@pytest.fixture(scope="module")
def osim():
    osim = pytest.importorskip(
        "opensim", reason="the opensim package is not installed (pip install 'ikid[eval]')"
    )
    # OpenSim opens ./opensim.log (in the directory of the first model it loads) unless told not to.
    osim.Logger.removeFileSink()
    return osim


def random_angles(n: int, seed: int) -> np.ndarray:
    lo, hi = np.array([c["range"] for c in ikid.body_model()["coordinates"]]).T
    return np.random.default_rng(seed).uniform(lo, hi, (n, 3))


# --- forward kinematics ---------------------------------------------------------------------------


@pytest.mark.parametrize("length_scale, mass_scale", [(0.85, 0.7), (1.2, 1.5)])
@pytest.mark.parametrize("shoulder_deg", [0.0, 45.0, -20.0])
def test_opensim_forward_kinematics_equals_ikid(osim, tmp_path, length_scale, mass_scale, shoulder_deg):
    # A lab's placement differing from the model's: every marker moved, up to 15 mm.
    shift = np.random.default_rng(int(shoulder_deg) + 100 + int(100 * length_scale)).uniform(
        -0.015, 0.015, (6, 3)
    )
    shoulder = math.radians(shoulder_deg)
    path = ios.write_osim(
        tmp_path / "s.osim",
        length_scale=length_scale,
        mass_scale=mass_scale,
        shoulder_flexion=shoulder,
        marker_shift=shift,
    )
    q = random_angles(40, seed=int(100 * length_scale) + int(shoulder_deg) + 20)
    theirs = ios.marker_positions(path, q)
    ours = ikid.forward_markers(q, shoulder, length_scale, mass_scale, shift)
    err = np.abs(theirs - ours).max()
    assert err <= FK_TOL, f"OpenSim's markers differ from ikid's by up to {err:.3g} m"


def test_rotation_order_matters_so_the_check_can_fail(osim, tmp_path):
    """The FK check discriminates: the same axes composed the other way round (extrinsically,
    i.e. intrinsic in reverse order) put the hand markers centimetres away."""
    text = ios.osim_text(shoulder_flexion=0.3)
    first, third = (text.index(f'<TransformAxis name="rotation{i}">') for i in (1, 3))
    end = lambda at: text.index("</TransformAxis>", at) + len("</TransformAxis>")  # noqa: E731
    r1, r3 = text[first : end(first)], text[third : end(third)]
    swapped = (
        text.replace(r1, "@R1@")
        .replace(r3, r1.replace("rotation1", "rotation3"))
        .replace("@R1@", r3.replace("rotation3", "rotation1"))
    )
    (tmp_path / "reversed.osim").write_text(swapped)
    q = random_angles(20, seed=5)
    # Coordinates keep their names; reorder the values to the file's coordinate order.
    theirs = ios.marker_positions(tmp_path / "reversed.osim", q[:, ::-1])
    assert np.abs(theirs - ikid.forward_markers(q, 0.3)).max() > 0.005


# --- what the file holds ----------------------------------------------------------------------------


def test_model_loads_cleanly_and_holds_the_body_model(osim, tmp_path):
    path = ios.write_osim(tmp_path / "m.osim", length_scale=1.1, mass_scale=1.3, shoulder_flexion=0.5)
    assert path == tmp_path / "m.osim"
    assert [p.name for p in tmp_path.iterdir()] == ["m.osim"]  # atomic: no temporary left behind
    log = tmp_path / "opensim.log"
    osim.Logger.addFileSink(str(log))
    try:
        model = osim.Model(str(path))
        model.initSystem()
    finally:
        osim.Logger.removeFileSink()
    bad = [
        ln
        for ln in log.read_text().splitlines()
        if "[warning]" in ln or "[error]" in ln or "[critical]" in ln
    ]
    assert not bad, "\n".join(bad)

    body = ikid.body_model(1.1, 1.3, 0.5)
    assert model.getNumBodies() == 2 and model.getNumJoints() == 2
    assert list(model.getGravity().to_numpy()) == body["gravity"]
    for seg in ("forearm", "hand"):
        b, p = model.getBodySet().get(seg), body["segments"][seg]
        assert b.getMass() == pytest.approx(p["mass"], rel=1e-15)
        assert b.getMassCenter().to_numpy() == pytest.approx(p["com"], abs=1e-15)
        inertia = b.getInertia()
        assert inertia.getMoments().to_numpy() == pytest.approx(p["inertia"], rel=1e-15)
        assert inertia.getProducts().to_numpy() == pytest.approx([0, 0, 0], abs=0)

    coords = model.getCoordinateSet()
    assert [coords.get(j).getName() for j in range(coords.getSize())] == ikid.coordinate_names()
    for j, c in enumerate(body["coordinates"]):
        co = coords.get(j)
        assert (co.getRangeMin(), co.getRangeMax()) == pytest.approx(c["range"], abs=1e-15), c["name"]
        assert co.getMotionType() == osim.Coordinate.Rotational, c["name"]
        assert co.getJoint().getName() == ios.WRIST_JOINT
        # Read back as written: a misspelt property would be dropped silently by OpenSim.
        assert not co.get_clamped() and not co.get_locked() and co.getDefaultValue() == 0.0

    markers = model.getMarkerSet()
    assert [markers.get(k).getName() for k in range(markers.getSize())] == ikid.marker_names()
    for k, m in enumerate(body["markers"]):
        mk = markers.get(k)
        assert mk.getParentFrameName() == f"/bodyset/{m['segment']}" and mk.get_fixed(), m["name"]
        assert mk.get_location().to_numpy() == pytest.approx(m["offset"], abs=1e-15), m["name"]


def test_custom_marker_set_round_trips(osim, tmp_path):
    """Other labels and placements: OpenSim places them where ikid would place its own markers
    moved by the same amounts."""
    body = ikid.body_model(length_scale=0.9)
    shift = np.random.default_rng(3).uniform(-0.02, 0.02, (6, 3))
    labels = ["R_RSTY", "R_USTY", "R_FARM", "R_MCP2", "R_MCP5", "R_HAND"]
    custom = [
        (lab, m["segment"], list(np.add(m["offset"], d)))
        for lab, m, d in zip(labels, body["markers"], shift, strict=True)
    ]
    path = ios.write_osim(tmp_path / "c.osim", length_scale=0.9, shoulder_flexion=-0.35, markers=custom)
    model = osim.Model(str(path))
    markers = model.getMarkerSet()
    got = [
        (
            markers.get(k).getName(),
            markers.get(k).getParentFrameName(),
            list(markers.get(k).get_location().to_numpy()),
        )
        for k in range(markers.getSize())
    ]
    assert [(n, s) for n, s, _ in got] == [(n, f"/bodyset/{s}") for n, s, _ in custom]
    assert np.abs(np.array([o for *_, o in got]) - np.array([o for *_, o in custom])).max() == 0.0
    q = random_angles(20, seed=8)
    err = np.abs(ios.marker_positions(path, q) - ikid.forward_markers(q, -0.35, 0.9, 1.0, shift)).max()
    assert err <= FK_TOL


@pytest.mark.parametrize(
    "length_scale, mass_scale, shoulder_deg", [(1.0, 1.0, 0.0), (1.2, 1.7, 45.0), (0.85, 0.6, -20.0)]
)
def test_opensim_inverse_dynamics_equals_ikid(osim, tmp_path, length_scale, mass_scale, shoulder_deg):
    """Masses, centres of mass, inertias, gravity and the joint's axes, all at once: OpenSim's
    inverse dynamics of the file equals ikid's Newton-Euler. Bound: ikid's two virtual links
    (inertia 1e-10 kg·m², left out of the file) at these accelerations, < 1e-7 N·m."""
    rng = np.random.default_rng(int(shoulder_deg) + 50)
    q, qd, qdd = (
        random_angles(30, seed=int(shoulder_deg) + 60),
        rng.uniform(-4, 4, (30, 3)),
        rng.uniform(-40, 40, (30, 3)),
    )
    shoulder = math.radians(shoulder_deg)
    path = ios.write_osim(
        tmp_path / "s.osim", length_scale=length_scale, mass_scale=mass_scale, shoulder_flexion=shoulder
    )
    theirs = ios.inverse_dynamics(path, q, qd, qdd)
    ours = ikid.reference_id(q, qd, qdd, shoulder, length_scale, mass_scale)
    assert np.abs(ours).max() > 0.05  # torques of a real size, not a vacuous comparison
    err = np.abs(theirs - ours).max()
    assert err < 1e-7, f"OpenSim's torques differ from ikid's by up to {err:.3g} N·m"


# --- OpenSim IK on an ikid trial ---------------------------------------------------------------------

# The TRC holds mm to 6 decimals (1 nm); with accuracy 1e-10 OpenSim's least squares on exact
# markers gets within ~4e-8 rad. Its default accuracy (1e-5) stops early when frames are 1 ms
# apart (up to 6e-3 rad here: see docs/opensim.md), so the test sets it.
IK_ACCURACY = 1e-10
IK_TOL = 1e-6  # rad


def test_opensim_ik_returns_ikid_angles(osim, tmp_path):
    rate, n = 1000.0, 300
    t = np.arange(n) / rate
    # A smooth motion of all three coordinates across most of their ranges.
    q = np.column_stack(
        [
            1.2 * np.sin(2 * np.pi * t),
            0.9 * np.sin(2 * np.pi * 0.7 * t + 0.3),
            0.3 * np.sin(2 * np.pi * 1.3 * t + 1),
        ]
    )
    shoulder, length_scale = math.radians(45), 1.1
    io.write_trc(tmp_path / "trial.trc", t, ikid.forward_markers(q, shoulder, length_scale), rate_hz=rate)
    model = ios.write_osim(tmp_path / "s.osim", length_scale=length_scale, shoulder_flexion=shoulder)
    res = ios.inverse_kinematics(model, tmp_path / "trial.trc", tmp_path / "ik.mot", accuracy=IK_ACCURACY)
    assert res.coordinates == ikid.coordinate_names()
    assert np.allclose(res.time, t, atol=1e-9)
    err = np.abs(res.q - q).max(axis=0)
    assert np.all(err <= IK_TOL), f"OpenSim IK misses ikid's angles by {err} rad"
    # The .mot it wrote is one ikid reads back as the same angles.
    assert np.allclose(io.read_mot(tmp_path / "ik.mot")[1], res.q, atol=0)


def test_ik_names_markers_missing_from_the_file(osim, tmp_path):
    t = np.arange(10) / 100.0
    frames = ikid.forward_markers(np.zeros((10, 3)))
    io.write_trc(
        tmp_path / "t.trc", t, frames, rate_hz=100.0, labels=["RSP", "USP", "FAP", "MC2", "MC5", "XX"]
    )
    model = ios.write_osim(tmp_path / "s.osim")
    with pytest.raises(ValueError, match="MCB"):
        ios.inverse_kinematics(model, tmp_path / "t.trc", tmp_path / "o.mot")


# --- a dataset from another generator (examples/opensim_dataset.py) ----------------------------------


def test_opensim_dataset_example_writes_consistent_trials(osim, tmp_path):
    """The example's files are what they claim: the lab-labelled markers, mapped back to ikid's
    names, are ikid's markers moved by the lab placement; the torques are ikid's Newton-Euler."""
    path = Path(__file__).resolve().parents[1] / "examples" / "opensim_dataset.py"
    spec = importlib.util.spec_from_file_location("opensim_dataset", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    out = tmp_path / "ds"
    assert (
        example.main(
            ["--out", str(out), "--trials", "2", "--duration", "0.3", "--rate", "500", "--seed", "4"]
        )
        == 0
    )
    manifest = json.loads((out / "dataset.json").read_text())
    mapping = io.MarkerMap.load(out / "map.toml")
    for trial in manifest["trials"]:
        data = io.read_markers(out / f"{trial['name']}.trc")
        assert data.rate_hz == 500 and len(data.time) == 150 and "R_LEPI" in data.labels
        frames = data.frames(mapping)
        t, q = io.read_mot(out / f"{trial['name']}.mot")
        assert np.allclose(t, data.time)
        lo, hi = np.array([c["range"] for c in ikid.body_model()["coordinates"]]).T
        assert np.all((q >= lo) & (q <= hi))
        body = ikid.body_model(length_scale=trial["length_scale"])
        placement = np.array([o for *_, o in example.lab_markers(trial["length_scale"])[:6]])
        shift = placement - np.array([m["offset"] for m in body["markers"]])
        assert np.all(
            (np.linalg.norm(shift, axis=1) >= 0.005 - 1e-12)
            & (np.linalg.norm(shift, axis=1) <= 0.020 + 1e-12)
        )
        ours = ikid.forward_markers(
            q, trial["shoulder_flexion"], trial["length_scale"], trial["mass_scale"], shift
        )
        assert (
            np.abs(frames - ours).max() < 1e-8
        )  # the .trc holds mm to 6 decimals, the .mot degrees to 10 digits
        # The motion is the manifest's sinusoids; ikid's torques on their analytic derivatives.
        sines = trial["sines"]
        w = [2 * np.pi * np.array(s_["freq_hz"]) for s_ in sines]
        arg = [np.outer(t, w_) + s_["phase"] for w_, s_ in zip(w, sines, strict=True)]
        q_exact = np.column_stack(
            [s_["offset"] + np.sin(a) @ s_["amplitude"] for a, s_ in zip(arg, sines, strict=True)]
        )
        qd = np.column_stack(
            [np.cos(a) @ (np.array(s_["amplitude"]) * w_) for a, w_, s_ in zip(arg, w, sines, strict=True)]
        )
        qdd = np.column_stack(
            [
                -np.sin(a) @ (np.array(s_["amplitude"]) * w_**2)
                for a, w_, s_ in zip(arg, w, sines, strict=True)
            ]
        )
        assert np.abs(q_exact - q).max() < 1e-9
        _, tau = io.read_sto(out / f"{trial['name']}.sto")
        ref = ikid.reference_id(
            q_exact, qd, qdd, trial["shoulder_flexion"], trial["length_scale"], trial["mass_scale"]
        )
        assert np.abs(ref).max() > 0.01
        assert np.abs(tau - ref).max() < 1e-7  # ikid's virtual links; the .sto holds 10 digits


# --- bad arguments (no OpenSim needed) -----------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"markers": [("A", "forearm", [0, 0, 0])], "marker_shift": np.zeros((6, 3))}, "not both"),
        ({"markers": [("A", "elbow", [0, 0, 0])]}, "segment 'elbow'"),
        ({"markers": [("A", "hand", [0, 0, 0]), ("A", "hand", [0, 0, 1])]}, "'A' appears more than once"),
        ({"markers": [("A/B", "hand", [0, 0, 0])]}, "slashes"),
        ({"markers": [("A", "hand", [0, 0])]}, "3 finite numbers"),
        ({"markers": [("A", "hand", [0, np.nan, 0])]}, "3 finite numbers"),
        ({"markers": []}, "empty"),
        ({"name": "my model"}, "whitespace"),
    ],
)
def test_bad_arguments_are_named(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        ios.write_osim(tmp_path / "x.osim", **kwargs)
    assert not list(tmp_path.iterdir())


def test_bad_subject_is_refused_by_the_body_model(tmp_path):
    with pytest.raises(ValueError, match="length_scale"):
        ios.write_osim(tmp_path / "x.osim", length_scale=-1.0)
