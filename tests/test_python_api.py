"""The Python API as a user reads it without the source: ``help()`` shows each argument's real
default (no ``Ellipsis``), every ``ikid.<name>`` a docstring mentions exists, and
``Tracker.push`` gives the status bits with the estimate (the same as ``run`` and C)."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import pydoc
import re
from collections.abc import Iterator

import numpy as np
import pytest

import ikid
from conftest import marker_frames

# A name after `ikid.` in prose: dotted identifiers (ikid.Model.predict, ikid.cli.main).
REFERENCE = re.compile(r"(?<![\w.])ikid\.([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)")


def documented() -> Iterator[tuple[str, object]]:
    """(qualified name, object) of every module, class, function, method and property of the
    installed package, the extension's included."""
    modules = [ikid, ikid._native]
    for info in pkgutil.walk_packages(ikid.__path__, "ikid."):
        if info.name.endswith("__main__"):
            continue
        modules.append(importlib.import_module(info.name))
    seen: set[int] = set()
    for module in modules:
        yield module.__name__, module
        for name, obj in vars(module).items():
            owner = getattr(obj, "__module__", None) or ""
            if id(obj) in seen or not (owner == "ikid" or owner.startswith("ikid.")):
                continue
            seen.add(id(obj))
            yield f"{module.__name__}.{name}", obj
            if inspect.isclass(obj):
                for attr, member in vars(obj).items():
                    yield f"{module.__name__}.{name}.{attr}", member


def resolves(dotted: str) -> bool:
    """True if ikid.<dotted> names something: an attribute chain from the package, or a
    submodule (imported on the way)."""
    obj: object = ikid
    parts = dotted.split(".")
    for i, part in enumerate(parts):
        if hasattr(obj, part):
            obj = getattr(obj, part)
            continue
        try:
            obj = importlib.import_module("ikid." + ".".join(parts[: i + 1]))
        except ImportError:
            return False
    return True


def test_every_ikid_name_in_a_docstring_exists():
    docs = [(where, inspect.getdoc(obj) or "") for where, obj in documented()]
    assert len(docs) > 100, "the walk found the package's objects"
    missing = sorted(
        {(where, ref) for where, doc in docs for ref in REFERENCE.findall(doc) if not resolves(ref)}
    )
    assert not missing, "docstrings name what does not exist:\n" + "\n".join(
        f"{w}: ikid.{r}" for w, r in missing
    )


def test_the_reference_reader_finds_names_and_misses():
    # The oracle for the test above: a known name resolves, a made-up one does not, and a
    # name inside another identifier (ikid_training.x) is not read as ikid.x.
    assert REFERENCE.findall("see ``ikid.FRAME_STATUS`` and ikid.Model.predict.") == [
        "FRAME_STATUS",
        "Model.predict",
    ]
    assert REFERENCE.findall("python -m ikid_training.export") == []
    assert resolves("FRAME_STATUS") and resolves("Model.predict") and resolves("cli")
    assert not resolves("STATUS") and not resolves("Model.nonexistent")


def test_help_shows_real_defaults():
    """No signature in the package shows `Ellipsis` (pyo3's rendering of a default it cannot
    print); the Tracker's jerk_noise default is the core's constant."""
    bad = []
    for where, obj in documented():
        if not callable(obj):
            continue
        try:
            sig = inspect.signature(obj)
        except (TypeError, ValueError):
            continue
        bad += [f"{where}{sig}" for p in sig.parameters.values() if p.default is Ellipsis]
    assert not bad, bad
    sig = inspect.signature(ikid.Tracker)
    assert sig.parameters["jerk_noise"].default == ikid.DEFAULT_JERK_NOISE
    # No default rate: tracked at another rate than the frames', every velocity and torque is wrong.
    assert sig.parameters["rate_hz"].default is None
    with pytest.raises(ikid.ArgumentError, match="rate_hz.*required.*the rate the frames come at"):
        ikid.Tracker()
    assert sig.parameters["noise_memory_s"].default == ikid.Tracker(rate_hz=1000.0).settings["noise_memory_s"]
    assert (
        sig.parameters["initial_marker_noise"].default
        == ikid.Tracker(rate_hz=1000.0).settings["initial_marker_noise"]
    )
    text = pydoc.render_doc(ikid.Tracker, renderer=pydoc.plaintext)
    assert "Ellipsis" not in text and f"jerk_noise={ikid.DEFAULT_JERK_NOISE!r}" in text
    # Every constructor argument is explained in the class's docstring.
    for name in sig.parameters:
        assert f"``{name}``" in (ikid.Tracker.__doc__ or ""), name


def test_tracker_push_gives_the_status_with_the_estimate():
    frames = marker_frames(400, seed=5).astype(np.float64)
    frames[200:230, 3] += 0.05  # a hand marker that jumped: rejected (a status bit)
    frames[300:310, 12:15] = np.nan  # MC5 missing
    batch = ikid.Tracker(rate_hz=1000.0).run(frames)
    tracker = ikid.Tracker(rate_hz=1000.0)
    pushed = [tracker.push(f) for f in frames]
    start = batch["start"]
    assert all(p is None for p in pushed[:start]) and all(p is not None for p in pushed[start:])
    estimates = [p for p in pushed[start:] if p is not None]
    for key in ("q", "qd", "qdd", "tau"):
        np.testing.assert_array_equal(np.stack([getattr(e, key) for e in estimates]), batch[key][start:])
    np.testing.assert_array_equal([e.status for e in estimates], batch["status"][start:])
    np.testing.assert_array_equal([e.missing for e in estimates], batch["missing"][start:])
    np.testing.assert_array_equal([e.noise for e in estimates], batch["noise"][start:])
    np.testing.assert_array_equal([e.refined for e in estimates], batch["refined"][start:])
    assert any(e.status != 0 for e in estimates), "the jumped marker was flagged"
    assert all(e.missing == 1 << 4 for e in estimates[300 - start : 310 - start])
    # As before, the estimate is the (4, 3) array of the four rows: numpy, indexing, unpacking.
    e = estimates[-1]
    rows = np.array([e.q, e.qd, e.qdd, e.tau])
    np.testing.assert_array_equal(np.asarray(e), rows)
    np.testing.assert_array_equal(e.values, rows)
    np.testing.assert_array_equal(e[0], e.q)
    np.testing.assert_array_equal(e[3, 2], e.tau[2])
    q, qd, qdd, tau = e
    np.testing.assert_array_equal(np.stack([q, qd, qdd, tau]), rows)
    assert len(e) == 4 and np.asarray(e, dtype=np.float32).dtype == np.float32
    assert "TrackerEstimate(" in repr(e) and f"status={e.status}" in repr(e)


def test_arguments_of_the_wrong_kind_name_the_argument_and_names_and_paths_are_taken(tmp_path):
    # As the CLI takes them: a refiner by its name, a calibration by its file; the oracle is the
    # same run with the loaded objects. Anything else is an ArgumentError naming the argument
    # and what it got (pyo3's TypeError named neither).
    frames = marker_frames(300, seed=5).astype(np.float64)
    calibration = ikid.Calibration.from_neutral(np.repeat(frames[:1], 50, axis=0))  # held still
    path = tmp_path / "subject.json"
    ikid.save_calibration(calibration, path)
    by_name = ikid.Tracker(rate_hz=1000.0, refiner="wrist-track", calibration=path).run(frames)
    loaded = ikid.Tracker(
        rate_hz=1000.0, refiner=ikid.load("wrist-track"), calibration=ikid.load_calibration(path)
    ).run(frames)
    np.testing.assert_array_equal(by_name["tau"], loaded["tau"])
    a = ikid.load("wrist-ik").stream(calibration=str(path))
    b = ikid.load("wrist-ik").stream(calibration=calibration)
    for f in frames[:80].astype(np.float32):
        x, y = a.push(f), b.push(f)
        assert (x is None and y is None) or np.array_equal(x, y)
    model, time = "expected an ikid.Model or a model's name", "time: expected the frame's time"
    for call, message in [
        (lambda: ikid.Tracker(rate_hz="100"), "rate_hz: expected the frames' rate in Hz, got '100'"),
        (lambda: ikid.Tracker(rate_hz=1000.0, refiner=3), f"refiner: {model}"),
        (lambda: ikid.Tracker(rate_hz=1000.0, calibration=3.0), "calibration: expected an ikid.Calibration"),
        (lambda: ikid.load("wrist-ik").stream(calibration=[1]), "calibration: expected an ikid.Calibration"),
        (lambda: ikid.Tracker(rate_hz=1000.0).push(frames[0], time="a"), time),
        (lambda: ikid.load("wrist-ik").stream().push(frames[0], time=b"0"), time),
    ]:
        with pytest.raises(ikid.ArgumentError, match=re.escape(message)):
            call()


def test_a_short_frame_names_a_marker_frame_for_a_model_that_reads_markers():
    """The error names what the caller must give (a marker frame of 18 values), not the
    model's internal feature set."""
    for name in ikid.available_models():
        model = ikid.load(name)
        if ikid.feature_set_info(model.feature_set)["frame_kind"] != "markers":
            continue
        with pytest.raises(ikid.InputError) as e:
            model.stream().push(np.zeros(17, np.float32))
        assert "marker frame" in str(e.value) and "18" in str(e.value) and "17" in str(e.value), str(e.value)
        assert f"{model.feature_set!r}" not in str(e.value) or model.feature_set == "markers", str(e.value)
    with pytest.raises(ikid.InputError, match="marker frame"):
        ikid.Tracker(rate_hz=1000.0).push(np.zeros(17))


def test_forward_markers_refuses_angles_beyond_a_half_turn_as_degrees_given():
    # Every posture has angles within ±π; [[10, 20, -5]] (degrees) were taken as radians and gave
    # markers of a hand turned round and round, silently.
    with pytest.raises(
        ikid.ArgumentError, match=r"row 0: ra_wr_s_p is 10 rad \(573°\), beyond ±π.*degrees given"
    ):
        ikid.forward_markers(np.array([[10.0, 20.0, -5.0]]))
    at_limit = np.array([[np.pi, 0.0, -np.pi]])
    assert np.isfinite(ikid.forward_markers(at_limit)).all()
