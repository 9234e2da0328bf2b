"""Real recordings (../shared/realdata, or $IKID_REALDATA) through the CLI, as `make realdata`
runs them: calibrated from the recording itself, scored against the independent reference.

Measured (tools/realdata.py, docs/realdata.md): pyomeca ik 2.18° geodesic RMS on valid frames;
racing ik 6.03° on gimbal_ok frames, short of the 3° issue #19 asks (its error is the network's
beyond its training range, e_f to -80°: the calibration itself reads the reference to 0.34°),
so racing's ik has no bound here; `ikid track` is scored but not bounded either.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

import ikid
from ikid.io import MarkerMap, read_markers

REPO = Path(__file__).resolve().parent.parent
DATA = Path(os.environ.get("IKID_REALDATA", REPO.parent / "shared" / "realdata"))

pytestmark = pytest.mark.skipif(
    not (DATA / "reference").is_dir(),
    reason=f"no real recordings at {DATA} (set IKID_REALDATA to the folder described in issue #19)",
)


def _tool():
    spec = importlib.util.spec_from_file_location("realdata_tool", REPO / "tools" / "realdata.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def tool():
    return _tool()


@pytest.fixture(scope="module")
def results(tool, tmp_path_factory):
    work = tmp_path_factory.mktemp("realdata")
    log: list[str] = []
    return {rec.name: tool.process(rec, DATA, work, log) for rec in tool.RECORDINGS}


def test_the_reference_and_ikid_conventions_agree(tool):
    tool.check_conventions()


def test_each_recording_is_calibrated_from_itself_by_landmarks(results):
    for name, r in results.items():
        assert r["calibrated"], (name, r["calibrate_out"])
        assert "Calibration(landmarks, right arm" in r["calibrate_out"], r["calibrate_out"]


def test_the_calibration_reads_the_reference_to_its_own_spread(results):
    # Per-frame geometry through the calibration file: what remains is the reference's own
    # Kabsch-vs-Gram-Schmidt spread (pyomeca 1.96°, racing 0.35°, its README).
    geometry = {name: r["geometry"] for name, r in results.items()}
    assert geometry["pyomeca"].rms_valid <= 2.05, geometry["pyomeca"].rms_valid
    assert geometry["racing"].rms_valid <= 0.45, geometry["racing"].rms_valid
    assert geometry["racing"].max_valid <= 2.0, geometry["racing"].max_valid


def test_pyomeca_ik_calibrated_from_the_recording_is_within_2_5_degrees(results):
    ik = results["pyomeca"]["ik"]
    assert ik is not None, results["pyomeca"]["ik_how"]
    assert ik.rms_valid <= 2.5, ik.rms_valid
    assert ik.coverage >= 0.98, ik.coverage  # outputs at the valid frames (window and gaps aside)


def test_racing_ik_calibrated_from_the_recording_gives_outputs(results):
    # 6.0° on gimbal_ok frames measured (docs/realdata.md): no 3° bound met, none asserted.
    ik = results["racing"]["ik"]
    assert ik is not None and ik.finite and ik.coverage >= 0.98, results["racing"]["ik_how"]


def test_uncalibrated_ik_is_refused_with_what_to_do_instead(results):
    # Read with the body model's placement these markers give angles 68-128° off; the
    # placement check refuses them instead of writing those numbers.
    for name, r in results.items():
        assert r["ik_raw"] is None, (name, r["ik_raw"].rms_valid)
        assert "calibrate the subject" in r["ik_raw_how"] and "--calibration" in r["ik_raw_how"], name


def test_the_racing_static_trial_with_a_glove_marker_missing_calibrates_from_frames_that_have_it(
    tmp_path, tool
):
    # GloveR1 is missing in 99.6 % of the static trial: the frames that have all six are used.
    rec = next(r for r in tool.RECORDINGS if r.name == "racing")
    mapping = MarkerMap.from_dict({"markers": rec.markers}, "racing")
    data = read_markers(DATA / "kinematics_racing_static.c3d")
    frames = data.frames(mapping)
    complete = np.isfinite(frames).all(axis=1)
    assert 0 < complete.sum() < 0.01 * len(frames)
    from ikid.calibration import calibrate_neutral

    cal = calibrate_neutral(frames)
    assert cal.method == "neutral" and cal.report["neutral_frames"] == int(complete.sum())
    # A frame range without the glove marker says what to record.
    none = np.flatnonzero(~complete)[:10]
    with pytest.raises(ikid.InputError, match="no usable neutral frame: none of the 10 has all six markers"):
        calibrate_neutral(frames[none])


def test_a_calibration_file_records_method_side_and_map_and_refuses_another_map(results, tmp_path):
    from ikid.calibration import calibration_info, check_calibration_map

    cal_path = tmp_path / "p.json"
    r = results["pyomeca"]
    mapping = MarkerMap.from_dict(
        {"markers": r["rec"].markers, "landmarks": r["rec"].landmarks}, "pyomeca.toml"
    )
    cal = ikid.load_calibration(r["cal_path"])
    ikid.save_calibration(cal, cal_path, marker_map=mapping)
    info = calibration_info(cal_path)
    assert info["method"] == "matrices" and info["side"] == "right"
    assert info["marker_map"]["markers"]["MC2"] == "Daphnee:INDEX"
    check_calibration_map(cal_path, mapping)
    other = MarkerMap.from_dict({"markers": {**r["rec"].markers, "MC2": "Daphnee:LASTC"}}, "other.toml")
    with pytest.raises(
        ikid.InputError, match=r"MC2 is 'Daphnee:LASTC' here, 'Daphnee:INDEX' in the calibration"
    ):
        check_calibration_map(cal_path, other)
    assert json.loads(Path(r["cal_path"]).read_text())["method"] == "landmarks"
