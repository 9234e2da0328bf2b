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
    # 3.5° on gimbal_ok frames measured (docs/realdata.md): the 3° bound is not met, none asserted.
    ik = results["racing"]["ik"]
    assert ik is not None and ik.finite and ik.coverage >= 0.98, results["racing"]["ik_how"]


def test_the_100hz_ik_network_corrects_all_but_5_percent_of_pyomecas_rows(results):
    # Issue #28: the per-frame fallback (the window's posture beyond the network's training: the
    # ulnar deviation to 46°, docs/realdata.md) on at most 5 % of ik's rows, the window's filling
    # aside; 313 of 580 before wrist-ik-100hz trained on sessions past the anatomical ranges.
    beyond, rows = results["pyomeca"]["ik_per_frame"]
    assert rows >= 500 and beyond <= 0.05 * rows, (beyond, rows, results["pyomeca"]["ik_how"])


def test_the_1khz_ik_network_corrects_most_of_racings_rows(results):
    # Racing (the 1 kHz member on its 70 Hz frames): 72 of 700 rows fall back, its windows faster
    # than all but 0.1 % of the member's training windows; 194 before wrist-ik trained on fast
    # sessions. Issue #28 asks for 5 %: not met, and not loosened to meet it (windows that fast
    # read 2-3° off through the network against 0.5° per frame, docs/realdata.md).
    beyond, rows = results["racing"]["ik_per_frame"]
    assert rows >= 650 and beyond <= 0.15 * rows, (beyond, rows, results["racing"]["ik_how"])


def test_uncalibrated_ik_is_refused_with_what_to_do_instead(results):
    # Read with the body model's placement these markers give angles 68-128° off; the
    # placement check refuses them instead of writing those numbers.
    for name, r in results.items():
        assert r["ik_raw"] is None, (name, r["ik_raw"].rms_valid)
        assert "calibrate the subject" in r["ik_raw_how"] and "--calibration" in r["ik_raw_how"], name


def test_the_racing_static_trial_with_a_glove_marker_missing_is_refused_naming_the_frames_it_has(tool):
    # GloveR1 is missing in 99.6 % of the static trial: the 2-3 frames with all six are too few
    # for a calibration (one frame's noise would be its error), and the refusal counts them.
    rec = next(r for r in tool.RECORDINGS if r.name == "racing")
    mapping = MarkerMap.from_dict({"markers": rec.markers}, "racing")
    frames = read_markers(DATA / "kinematics_racing_static.c3d").frames(mapping)
    complete = int(np.isfinite(frames).all(axis=1).sum())
    assert 0 < complete < 5
    from ikid.calibration import calibrate_neutral

    too_few = rf"{complete} of the {len(frames)} neutral frames have all six"
    with pytest.raises(ikid.InputError, match=too_few):
        calibrate_neutral(frames)
    none = np.flatnonzero(~np.isfinite(frames).all(axis=1))[:10]
    with pytest.raises(ikid.InputError, match="no usable neutral frame: none of the 10 has all six markers"):
        calibrate_neutral(frames[none])


@pytest.mark.parametrize("name", ["pyomeca", "racing"])
def test_neutral_is_refused_where_the_forearm_markers_do_not_sit_as_the_model_puts_them(tool, name, tmp_path):
    # The neutral method keeps the body model's placement of RSP, USP and FAP: on pyomeca's skin
    # markers and racing's plates it read 56° (ik) and 45° (track) off and exited 0. Refused,
    # through the CLI, saying what to record instead.
    rec = next(r for r in tool.RECORDINGS if r.name == name)
    ref = tool.read_reference(DATA, rec.reference)
    mapping = tmp_path / "map.toml"
    mapping.write_text(tool.map_toml(rec))
    frames = ",".join(str(i) for i in ref["meta"]["neutral_frames"])
    out = tmp_path / "cal.json"
    cmd = ["calibrate", "--static", str(DATA / rec.trial), "--frames", frames, "--map", str(mapping)]
    done = tool.run(cmd + ["--method", "neutral", "-o", str(out)], [])
    message = done.stdout + done.stderr
    assert done.returncode == 2, message
    assert "the neutral method keeps the body model's placement of the forearm's markers" in message, message
    assert "--method landmarks" in message and "--method functional" in message, message
    assert not out.exists()


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


# --- the tracker's promises (issue #19 item 3), probed through `ikid track` ---------------------
# Measured (docs/realdata.md, make realdata): 200 ms gaps every 2 s cost pyomeca RSP 4.17x, USP
# 3.53x, FAP 1.76x, MC2 2.68x, MC5 2.04x, MCB 2.85x and racing RSP 1.08x, USP 1.09x, FAP 1.44x,
# MC2 2.66x, MC5 10.9x, MCB 27.4x the gap-free error: only the markers within the 2x bound are
# asserted. Garbage: a frame shifted by 1 km for 5 or 20 frames is taken as real after 3 frames
# (written unflagged), one marker 10 cm off for 5-20 frames on pyomeca is 4.9-7.5x off 100 ms
# after; not asserted. The left arm, calibrated by the mirror method, is within range +-45 deg on
# 100 % of frames by ik and track, its e_f correlating with the right arm's at 0.97 (both).


@pytest.fixture(scope="module")
def probed(tool, results, tmp_path_factory):
    work = tmp_path_factory.mktemp("probes")
    log: list[str] = []
    for r in results.values():
        (work / f"{r['rec'].name}.toml").write_text(tool.map_toml(r["rec"]))
    out = {name: tool.probes(r, DATA, work, log) for name, r in results.items()}
    right = {**results["racing"], "probes": out["racing"]}
    out["left"] = tool.left_arm(DATA, work, right, log)
    return out


@pytest.mark.parametrize(
    ("trial", "marker"), [("racing", "RSP"), ("racing", "USP"), ("racing", "FAP"), ("pyomeca", "FAP")]
)
def test_a_200_ms_gap_of_a_forearm_marker_costs_at_most_twice_the_gap_free_error(probed, trial, marker):
    gap = probed[trial]["gaps"][marker]
    assert gap["cost"] <= 2.0, gap
    assert gap["no_output"] == 0, gap


def test_tracked_angles_never_jump_a_turn_between_frames(probed):
    for trial in ("pyomeca", "racing"):
        for run, (step, _) in probed[trial]["jumps"].items():
            assert step <= 180.0, (trial, run, step)
    left = probed["left"]
    assert left["run"] is not None and left["jumps"][0] <= 180.0, left["jumps"]


@pytest.mark.parametrize("kind", ["random frames", "two labels swapped"])
def test_garbage_frames_are_flagged_or_absent(probed, kind):
    for trial in ("pyomeca", "racing"):
        for burst in probed[trial]["garbage"][kind]:
            assert burst["unflagged"] == 0, (trial, kind, burst)


def test_tracking_recovers_within_100_ms_of_garbage(probed):
    kinds = {
        "racing": list(probed["racing"]["garbage"]),
        "pyomeca": ["random frames", "shifted by 1 km", "two labels swapped"],
    }
    for trial, names in kinds.items():
        for kind in names:
            for burst in probed[trial]["garbage"][kind]:
                assert burst["cost"] <= 2.0 and burst["recovery_ms"] <= 100.0, (trial, kind, burst)


def test_uncalibrated_track_is_refused_saying_to_calibrate(probed):
    for trial in ("pyomeca", "racing"):
        u = probed[trial]["uncalibrated"]
        assert u.returncode != 0 and "calibrate" in u.message and "--calibration" in u.message, u.message


def test_the_racing_left_arm_is_calibrated_from_the_right_arm_mirrored_and_moves_with_it(probed):
    # Plates and a lateral epicondyle only: `--method mirror --from <the right arm's calibration>`.
    # The plates are equilateral, so the left epicondyle says how their markers pair: the map in
    # label order is refused saying which labels to swap, the map it asks for is taken.
    left = probed["left"]
    (first, _, refusal), (second, _, accepted) = left["attempts"]
    assert first == "RSP=ForearmL1, USP=ForearmL2, FAP=ForearmL3", left["attempts"]
    assert "give RSP the label now given to FAP, give FAP the label now given to RSP" in refusal, refusal
    assert second == "RSP=ForearmL3, USP=ForearmL2, FAP=ForearmL1" and left["calibrated"], accepted
    assert "lateral_epicondyle" in accepted and "mirrored from the right arm" in accepted, accepted
    # Issue #29: in range on >= 99 % of frames and e_f following the right arm's (r >= 0.8), both paths.
    for path in ("ik", "track"):
        assert left["in_range_by"][path] >= 0.99, (path, left["in_range_by"])
        assert left["ef_by"][path] >= 0.8, (path, left["ef_by"])
    assert not left["diverged"]


# --- marker sets (docs/markersets.md) -----------------------------------------------------------


def test_plug_in_gait_one_hand_marker_follows_vicons_wrist_angles_within_2_degrees(tool, tmp_path):
    # Both arms of the Plug-in Gait walking trial as ikid's one-hand-marker set, calibrated from the
    # static trial; e_f and ad_ab against Vicon's own wrist angles converted as the data's README
    # says (an independent model), each trial's mean removed. Measured: ik 0.30/0.53 (R), 0.42/0.98
    # (L); track 0.30/0.54, 0.41/0.97. s_p is not written: one hand marker does not show the roll.
    pig = tool.pig(DATA, tmp_path, [])
    for side, arm in pig["arms"].items():
        assert arm["calibrated"], arm["calibrate_out"]
        for path in ("ik", "track"):
            s = arm[path]
            assert s is not None, arm[f"{path}_out"]
            assert s["rows"] == s["frames"] == 323, (side, path, s["rows"])
            assert s["not_determined"] == ["ra_wr_s_p"] and "ra_wr_s_p" not in s["columns"], s
            assert "ra_wr_s_p not written: the hand is one marker" in arm[f"{path}_out"], arm[f"{path}_out"]
            assert min(s["r"]) >= 0.9, (side, path, s["r"])
        # Live from a fake QTM (its AxisUpwards the C3D's +Z): what `track` gives on the file,
        # every line but the filter's first (flagged restarted) ok. Measured 0.30/0.54, 0.42/0.98.
        live = arm["stream"]
        assert live is not None, arm["stream_out"]
        assert live["rows"] >= live["frames"] - 5 and "ra_wr_s_p" not in live["columns"], live
        assert "lab up +z (QTM's AxisUpwards)" in arm["stream_out"], arm["stream_out"]
        assert max(abs(a - b) for a, b in zip(live["rms"], arm["track"]["rms"], strict=True)) < 0.1, live
    assert pig["ik"] <= 2.0 and pig["track"] <= 2.0, (pig["ik"], pig["track"])


def test_a_styloid_marker_that_is_also_the_styloid_landmark_calibrates_pyomeca_within_2_5_degrees(
    tool, tmp_path
):
    # STYLr as RSP and as radial_styloid (one label for both): 1.55° (calibration check), ik 1.69°,
    # track 1.57°. Both styloid markers in the cluster (STYLr/STYLu as RSP/USP) read 12.8° off the
    # radius-fixed reference (ik 12.7°, track 4.1°): the ulna stays while the radius turns about it,
    # so the three turn with neither bone; that map is refused, saying what to map instead.
    styloids = tool.pyomeca_styloids(DATA, tmp_path, [])
    radial = styloids["radial styloid as RSP"]
    assert radial["calibrated"], radial["calibrate_out"]
    assert radial["markers"]["RSP"] == "Daphnee:STYLr"
    assert radial["geometry"].rms_valid <= 2.5, radial["geometry"].rms_valid
    assert radial["ik"].rms_valid <= 2.5 and radial["track"].rms_valid <= 2.5, (
        radial["ik"].rms_valid,
        radial["track"].rms_valid,
    )
    both = styloids["both styloids as RSP/USP"]
    assert not both["calibrated"] and both["ik"] is None and both["track"] is None, both["calibrate_out"]
    assert "'Daphnee:STYLu' is forearm marker USP and landmark ulnar_styloid" in both["calibrate_out"]
    assert "the ulnar styloid in [landmarks] only" in both["calibrate_out"], both["calibrate_out"]


def test_a_calibration_from_one_frame_is_refused_saying_how_many_and_what_to_record(tool, tmp_path):
    rec = next(r for r in tool.RECORDINGS if r.name == "pyomeca")
    mapping = tmp_path / "map.toml"
    mapping.write_text(tool.map_toml(rec))
    out = tmp_path / "cal.json"
    cmd = [
        "calibrate",
        "--static",
        str(DATA / rec.trial),
        "--frames",
        "3",
        "--map",
        str(mapping),
        "-o",
        str(out),
    ]
    done = tool.run(cmd, [])
    message = done.stdout + done.stderr
    assert done.returncode == 2, message
    assert "1 neutral frame, with all six markers (at least 5 are needed" in message, message
    assert "record a static trial" in message, message
    assert not out.exists()


def test_the_mirror_method_refuses_what_it_cannot_know_saying_what_to_record(results, tool, tmp_path):
    # The racing left plate is equilateral: without a landmark of the left arm, which of its markers
    # matches which of the right plate's cannot be known (six pairings fit its shape).
    rec = next(r for r in tool.RECORDINGS if r.name == "racing")
    mapping = tmp_path / "left.toml"
    left = tool.Recording("l", rec.trial, rec.reference, tool.LEFT_MARKERS, {}, "", "left")
    mapping.write_text(tool.map_toml(left))
    right = str(results["racing"]["cal_path"])
    out = tmp_path / "left.json"
    held = tool.median_posture_frames(read_markers(DATA / rec.trial), tool.LEFT_MARKERS)
    frames = ",".join(str(i) for i in held)
    cmd = ["calibrate", "--static", str(DATA / rec.trial), "--frames", frames, "--map", str(mapping)]
    done = tool.run(cmd + ["--from", right, "-o", str(out)], [])
    message = done.stdout + done.stderr
    assert done.returncode == 2 and not out.exists(), message
    assert "paired 6 ways" in message and "record a landmark of this arm too" in message, message
    # The right arm's own calibration is no other arm's.
    right_map = tmp_path / "right.toml"
    right_map.write_text(tool.map_toml(rec))
    frames = ",".join(str(i) for i in results["racing"]["ref"]["meta"]["neutral_frames"])
    static = str(DATA / rec.calibration_file)
    cmd = ["calibrate", "--static", static, "--frames", frames, "--map", str(right_map)]
    done = tool.run(cmd + ["--method", "mirror", "--from", right, "-o", str(out)], [])
    assert done.returncode == 2 and "this one is of the right arm too" in done.stderr, done.stderr


@pytest.mark.parametrize(
    "hand",
    [
        ("LARM_elb", "WRIST2", "INDEX"),  # an elbow marker and a forearm marker in the "hand"
        ("LARM_elb", "LARMm", "LARMl"),  # a "hand" that is all forearm: it does not move with the wrist
        ("WRIST2", "MEDH", "LATH"),  # one forearm marker among the hand's
    ],
)
def test_a_map_naming_nonsense_is_flagged_before_any_angle_and_the_real_maps_are_not(tool, hand):
    # pyomeca's box task: each segment's markers keep their distances within 12 mm (skin), the
    # racing plates within 1 mm, Plug-in Gait's forearm within 5 mm; across a joint 18-120 mm.
    rec = next(r for r in tool.RECORDINGS if r.name == "pyomeca")
    data = read_markers(DATA / rec.trial)
    assert (
        MarkerMap.from_dict({"markers": rec.markers}).stretched_segments(
            data.frames(MarkerMap.from_dict({"markers": rec.markers}))
        )
        == []
    )
    labels = [f"Daphnee:{h}" if h != "WRIST2" else rec.markers["FAP"] for h in hand]
    forearm = {**rec.markers}
    if rec.markers["FAP"] in labels:  # the forearm marker now in the hand: the forearm takes another
        forearm["FAP"] = "Daphnee:LARMm" if "Daphnee:LARMm" not in labels else "Daphnee:LARMl"
    mapping = MarkerMap.from_dict(
        {"markers": {**forearm, "MC2": labels[0], "MC5": labels[1], "MCB": labels[2]}}
    )
    found = mapping.stretched_segments(data.frames(mapping))
    assert found and all("one of them seems to be on another segment" in f for f in found), found
    assert any("the hand's markers" in f for f in found), found


def test_a_forearm_and_a_hand_marker_swapped_in_the_map_are_refused_and_the_real_maps_are_not(tool):
    # pyomeca with FAP's and MC2's labels exchanged: calibrated, it tracked 580 rows with status 0,
    # 28-36° RMS from the right map's angles. Every one of the nine forearm-hand exchanges on each
    # recording: named as the exchange it is, or left to the stretch warning (pyomeca's RSP-MC5:
    # RSP sits near the wrist, so the hand barely stretches with it); never a wrong pair named.
    for rec, refused in (("pyomeca", 8), ("racing", 9)):
        rec = next(r for r in tool.RECORDINGS if r.name == rec)
        data = read_markers(DATA / rec.trial)
        mapping = MarkerMap.from_dict({"markers": rec.markers})
        assert mapping.swapped_across_segments(data.frames(mapping)) is None, rec.name
        found = 0
        for f in ("RSP", "USP", "FAP"):
            for h in ("MC2", "MC5", "MCB"):
                labels = {**rec.markers, f: rec.markers[h], h: rec.markers[f]}
                wrong = MarkerMap.from_dict({"markers": labels})
                said = wrong.swapped_across_segments(data.frames(wrong))
                if said is not None:
                    found += 1
                    assert f"marker {f} ({labels[f]!r}) and the hand's {h} ({labels[h]!r})" in said, said
                    assert f"give {f} = {rec.markers[f]!r} and {h} = {rec.markers[h]!r}" in said, said
        assert found == refused, rec.name


def test_pyomeca_with_four_marker_segments_holds_the_reference_within_2_5_degrees(tool, tmp_path):
    # [cluster]: the forearm's three radius markers with STYLr, the hand's three with LASTC (its
    # gaps and MEDH's overlap in 10 frames: those keep their three as seen and are gap-filled).
    # Skin markers: the fourth ones slide otherwise than the three and only stand in for a missing
    # one. Measured: ik 0.86/0.88/0.87°, track 0.70/0.69/0.69° (forearm/hand/both; the three
    # alone 0.88/0.70), every row written.
    clusters = tool.pyomeca_clusters(DATA, tmp_path, [])
    assert set(clusters) == set(tool.PYOMECA_CLUSTERS)
    for name, c in clusters.items():
        assert c["calibrated"], (name, c["calibrate_out"])
        assert c["ik"].rms_valid <= 2.5 and c["track"].rms_valid <= 2.5, (
            name,
            c["ik"].rms_valid,
            c["track"].rms_valid,
        )
        assert c["ik_per_frame"][1] == 580, (name, c["ik_per_frame"])


def test_a_forearm_plate_with_one_glove_marker_off_the_hands_axis_is_refused_at_calibration(tool, tmp_path):
    # ForearmR1-3 as the forearm's cluster, GloveR2 alone on the hand, calibrated from the probed
    # landmarks at the reference's own neutral frames. A one-marker hand's angles are the marker's
    # direction from the wrist; this glove's marker is far off the hand's axis, so it read e_f 49°
    # and ad_ab 40° on average through propulsion with status 0 (review 4). The calibration is now
    # refused, naming the marker and how far from zero it reads there. The oracle for that angle:
    # the marker's direction from the mid-styloids against the distal axis of the ISB forearm
    # frame the four landmarks give, at those frames (computed here, not by ikid).
    r = tool.racing_one_hand(DATA, tmp_path, [])
    assert not r["calibrated"], r["calibrate_out"]
    said = r["calibrate_out"]
    assert "the hand's one marker 'GloveR2' (HND) reads the hand" in said, said
    reported = float(said.split("reads the hand ")[1].split("°")[0])
    full = read_markers(DATA / "kinematics_racing_full.c3d")
    neutral = tool.read_reference(DATA, "racing_propulsion_R")["meta"]["neutral_frames"]
    lm = {k: full.marker(v)[neutral] for k, v in tool.RECORDINGS[1].landmarks.items()}
    wrist = (lm["radial_styloid"] + lm["ulnar_styloid"]) / 2
    y = (lm["lateral_epicondyle"] + lm["medial_epicondyle"]) / 2 - wrist
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, lm["radial_styloid"] - lm["ulnar_styloid"])
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    forearm = np.stack([x, y, np.cross(x, y)], axis=2)
    # The hand's frame one marker gives (no roll): y from the marker to the wrist, z the
    # forearm's made perpendicular to it; how far it is turned from the forearm's.
    hy = wrist - full.marker("GloveR2")[neutral]
    hy /= np.linalg.norm(hy, axis=1, keepdims=True)
    hz = forearm[:, :, 2] - hy * np.sum(forearm[:, :, 2] * hy, axis=1, keepdims=True)
    hz /= np.linalg.norm(hz, axis=1, keepdims=True)
    hand = np.stack([np.cross(hy, hz), hy, hz], axis=2)
    trace = np.einsum("nij,nij->n", forearm, hand)
    off = np.degrees(np.arccos(np.clip((trace - 1) / 2, -1, 1)))
    assert abs(reported - np.median(off)) < 2.0, (reported, off)
    assert reported > 30.0
