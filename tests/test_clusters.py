"""Segments with more than three markers (docs/markersets.md, "Clusters"): three named in
``[markers]``, the rest in ``[cluster]``, the cluster's rigid shape fitted to every marker seen.
The oracle is the body model's own markers: each extra marker is a fixed point of its segment
(an affine combination of the segment's three plus an offset along their plane's normal), so
where it is, and where a missing marker is, follows from the simulated pose alone."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import tomllib

import ikid
from ikid import io
from ikid.cli import main as cli
from ikid.io import MarkerMap, read_mot
from ikid.io.mapping import MarkerMapWarning
from ikid.io.markers import FileFormatError, MarkerData

SIX = {"RSP": "RSP", "USP": "USP", "FAP": "FAP", "MC2": "MC2", "MC5": "MC5", "MCB": "MCB"}
CLUSTERED = {"markers": SIX, "cluster": {"forearm": ["FA4"], "hand": ["H4", "H5"]}}


def fixed_point(three: np.ndarray, a: float, b: float, c: float) -> np.ndarray:
    """``(n, 3)``: the point ``a``, ``b`` of the way along a segment's first-to-second and
    first-to-third marker, ``c`` metres off their plane: rigid with the three."""
    p0, p1, p2 = three[:, 0:3], three[:, 3:6], three[:, 6:9]
    normal = np.cross(p1 - p0, p2 - p0)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return p0 + a * (p1 - p0) + b * (p2 - p0) + c * normal


def arm(n: int, rate: float = 1000.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The body model's wrist moving on every coordinate: truth angles ``(n, 3)``, its six
    markers ``(n, 18)`` and three further markers ``(n, 9)`` (one on the forearm, two on the
    hand), metres."""
    t = np.arange(n) / rate
    q = np.stack([0.4 * np.sin(1.3 * t), 0.6 * np.sin(2.1 * t + 0.5), 0.25 * np.cos(1.7 * t)], axis=1)
    six = ikid.forward_markers(q)
    extra = np.concatenate(
        [
            fixed_point(six[:, 0:9], 0.3, 0.4, 0.02),
            fixed_point(six[:, 9:18], 0.5, 0.2, -0.015),
            fixed_point(six[:, 9:18], -0.2, 0.6, 0.01),
        ],
        axis=1,
    )
    return q, six, extra


def data(six: np.ndarray, extra: np.ndarray, source: str = "trial.trc", rate: float = 1000.0) -> MarkerData:
    labels = (*SIX.values(), "FA4", "H4", "H5")
    positions = np.concatenate([six, extra], axis=1).reshape(len(six), 9, 3)
    return MarkerData(labels, np.arange(len(six)) / rate, positions, rate, source)


def test_a_cluster_map_is_read_checked_and_written():
    mapping = MarkerMap.from_dict(CLUSTERED)
    assert mapping.clusters == {"forearm": ("FA4",), "hand": ("H4", "H5")}
    assert MarkerMap.from_dict(tomllib.loads(mapping.to_toml())).clusters == mapping.clusters
    refused = {
        "its keys are the segments": {"elbow": ["X"]},
        "must be a list of one or more labels": {"forearm": "FA4"},
        "label 'MC2' is given to both MC2 and the forearm's cluster": {"forearm": ["MC2"]},
        "label 'X' is given to both the forearm's cluster and the hand's cluster": {
            "forearm": ["X"],
            "hand": ["X"],
        },
    }
    for message, cluster in refused.items():
        with pytest.raises(FileFormatError, match=message):
            MarkerMap.from_dict({"markers": SIX, "cluster": cluster})
    # A cluster marker may be a landmark of its own segment, not of the other one.
    both = MarkerMap.from_dict({**CLUSTERED, "landmarks": {"radial_styloid": "FA4"}})
    assert both.landmarks["radial_styloid"] == "FA4"
    with pytest.raises(FileFormatError, match=r"label 'H4' is given to marker in the hand's \[cluster\]"):
        MarkerMap.from_dict({**CLUSTERED, "landmarks": {"radial_styloid": "H4"}})
    # The ulnar styloid on a forearm cluster turns with neither bone, as on one of its three.
    with pytest.raises(FileFormatError, match="landmark ulnar_styloid: a marker on the ulna"):
        MarkerMap.from_dict({**CLUSTERED, "landmarks": {"ulnar_styloid": "FA4"}})
    # A one-marker hand's segments are built anew each frame from anatomical points.
    pig = {"RSP": "A", "USP": "B", "FAP": "C", "HND": "D"}
    with pytest.raises(FileFormatError, match="with a one-marker hand"):
        MarkerMap.from_dict({"markers": pig, "cluster": {"forearm": ["E"]}})


def test_a_missing_marker_is_put_where_its_cluster_holds_it():
    _, six, extra = arm(600)
    holed = six.copy()
    holed[100:200, 0:3] = np.nan  # RSP, for 0.1 s
    holed[300:350, 9:15] = np.nan  # MC2 and MC5 together: the hand keeps MCB, H4, H5
    frames = data(holed, extra).frames(MarkerMap.from_dict(CLUSTERED))
    assert np.isfinite(frames).all()
    np.testing.assert_allclose(frames, six, atol=1e-6)
    # Without the cluster, the hand with two of its three markers gone has no frame there.
    plain = data(holed, extra).frames(MarkerMap.from_dict({"markers": SIX}))
    assert np.isnan(plain[300:350, 9:15]).all()


def test_a_frame_with_too_few_cluster_markers_keeps_its_three_as_they_are():
    _, six, extra = arm(300)
    holed, extra = six.copy(), extra.copy()
    holed[50:60, 9:12] = np.nan  # MC2 ...
    extra[50:60, 3:9] = np.nan  # ... and both of the hand's extra markers: two of five seen
    frames = data(holed, extra).frames(MarkerMap.from_dict(CLUSTERED))
    assert np.isnan(frames[50:60, 9:12]).all()
    np.testing.assert_allclose(frames[50:60, 12:18], six[50:60, 12:18], atol=1e-6)


def test_a_marker_that_leaves_its_place_is_left_out_and_named():
    _, six, extra = arm(500)
    knocked = extra.copy()
    knocked[200:300, 3:6] += [0.0, 0.04, 0.0]  # H4 read 40 mm off in a fifth of the frames
    with pytest.warns(MarkerMapWarning) as said:
        frames = data(six, knocked).frames(MarkerMap.from_dict(CLUSTERED))
    said = " ".join(str(w.message) for w in said)
    assert (
        "marker 'H4' of the hand's cluster is more than 15 mm" in said and " in 100 of the 500 frames" in said
    )
    assert "marker 'H4' of the hand's cluster does not keep its distances" in said, said
    np.testing.assert_allclose(frames, six, atol=1e-6)
    # A clean recording says nothing.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data(six, extra).frames(MarkerMap.from_dict(CLUSTERED))


def test_every_block_of_a_file_is_fitted_with_the_shape_of_its_first():
    _, six, extra = arm(400)
    mapping = MarkerMap.from_dict(CLUSTERED)
    first = data(six[:200], extra[:200], "long.trc").frames(mapping, whole=False)
    np.testing.assert_allclose(first, six[:200], atol=1e-6)
    # The next block never has RSP: its cluster is not learnt again, it is fitted as learnt.
    later = six[200:].copy()
    later[:, 0:3] = np.nan
    again = data(later, extra[200:], "long.trc").frames(mapping, whole=False)
    np.testing.assert_allclose(again, six[200:], atol=1e-6)
    # A file whose first block never shows the cluster whole reads the segment's three as they
    # are, and says so.
    with pytest.warns(
        MarkerMapWarning,
        match=r"other.trc: the forearm's cluster \(RSP 'RSP'.*'FA4'\) is not used: .*all seen in 0 of 200 .*"
        r"the forearm's three \[markers\] are read as they are",
    ):
        plain = data(later, extra[200:], "other.trc").frames(mapping, whole=False)
    assert np.isnan(plain[:, 0:3]).all()
    np.testing.assert_allclose(plain[:, 3:], six[200:, 3:], atol=1e-6)


def test_ik_through_a_four_marker_cluster_reads_noisy_markers_closer_to_the_truth(tmp_path):
    # 1 mm of Gaussian noise on every marker: fitting each segment to four or five markers
    # averages it, so the angles ik writes are nearer the simulated ones than from three.
    q, six, extra = arm(3000)
    rng = np.random.default_rng(0)
    noisy = np.concatenate([six, extra], axis=1) + rng.normal(0.0, 0.001, (3000, 27))
    trc = io.write_trc(
        tmp_path / "t.trc", np.arange(3000) / 1000.0, noisy, 1000.0, [*SIX.values(), "FA4", "H4", "H5"]
    )
    errors = {}
    for name, table in (("three", {"markers": SIX}), ("cluster", CLUSTERED)):
        path = tmp_path / f"{name}.toml"
        path.write_text(MarkerMap.from_dict(table).to_toml())
        assert cli(["ik", str(trc), "--map", str(path), "-o", str(tmp_path / f"{name}.mot")]) == 0
        t, angles = read_mot(tmp_path / f"{name}.mot")
        rows = np.rint(t * 1000.0).astype(int)
        errors[name] = float(np.sqrt(np.mean((angles - q[rows]) ** 2)))
    assert errors["cluster"] < 0.85 * errors["three"], errors


def test_a_live_source_reads_each_segment_from_its_three_and_says_so():
    from ikid.live.sources import marker_columns

    positions = {
        lab: (3 * i, 3 * i + 1, 3 * i + 2) for i, lab in enumerate(["FA4", *SIX.values(), "H4", "H5"])
    }
    with pytest.warns(
        MarkerMapWarning, match=r"\[cluster\] markers \(FA4, H4, H5\) are not used on a live source"
    ):
        columns = marker_columns(positions, MarkerMap.from_dict(CLUSTERED), "lsl")
    assert list(columns) == list(range(3, 21))


# --- one hand marker with a forearm cluster ---------------------------------------------------

#: Four markers of a forearm plate, in the forearm's anatomical frame (x volar, y proximal,
#: z radial; origin mid-styloids), metres: on its back, a third of the way up, turned askew.
PLATE = np.array([[-0.03, 0.07, 0.01], [-0.035, 0.11, -0.02], [-0.03, 0.12, 0.025], [-0.04, 0.095, 0.0]])


def plate_arm(n: int, rate: float, seed: int, moving: bool = True):
    """``one_marker_arm``'s arm (wrist bar, elbow, one hand marker; truth flexion and
    deviation) with a four-marker plate on the forearm: ``(n, 12)`` plate, ``(n, 12)`` the
    anatomical markers, truth e, a."""
    from test_markersets import one_marker_arm

    anatomical, e, a = one_marker_arm(n, rate, seed, moving)
    wra, wrb, elb = anatomical[:, 0:3], anatomical[:, 3:6], anatomical[:, 6:9]
    wrist = (wra + wrb) / 2
    y = elb - wrist
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, wra - wrb)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    z = np.cross(x, y)
    plate = np.concatenate([wrist + p[0] * x + p[1] * y + p[2] * z for p in PLATE], axis=1)
    return plate, anatomical, e, a


def write_plate_arm(path, plate, anatomical, rate, landmarks: bool):
    """A TRC of the plate, the hand marker and (``landmarks``) the wrist bar and the elbow."""
    labels = ["FA1", "FA2", "FA3", "FA4", "RFIN"] + (["RWRA", "RWRB", "RELB"] if landmarks else [])
    columns = [plate, anatomical[:, 9:12]] + ([anatomical[:, 0:9]] if landmarks else [])
    return io.write_trc(path, np.arange(len(plate)) / rate, np.concatenate(columns, axis=1), rate, labels)


PLATE_MAP = {
    "markers": {"RSP": "FA1", "USP": "FA2", "FAP": "FA3", "HND": "RFIN"},
    "cluster": {"forearm": ["FA4"]},
    "landmarks": {
        "lateral_epicondyle": "RELB",
        "medial_epicondyle": "RELB",
        "radial_styloid": "RWRA",
        "ulnar_styloid": "RWRB",
    },
}


@pytest.mark.parametrize("command", ["ik", "track"])
def test_one_hand_marker_with_a_forearm_cluster_measures_the_hand_in_its_anatomical_frame(
    command, tmp_path, capsys
):
    # The static trial has the styloids and the elbow; the task has the plate and the hand
    # marker only: the plate carries the anatomical points the static trial measured.
    rate = 100.0
    plate, anatomical, _, _ = plate_arm(100, rate, 1, moving=False)
    write_plate_arm(tmp_path / "static.trc", plate, anatomical, rate, landmarks=True)
    plate, anatomical, e, a = plate_arm(600, rate, 2)
    write_plate_arm(tmp_path / "trial.trc", plate, anatomical, rate, landmarks=False)
    (tmp_path / "map.toml").write_text(MarkerMap.from_dict(PLATE_MAP).to_toml())
    cal = tmp_path / "cal.json"
    common = ["--map", str(tmp_path / "map.toml")]
    assert cli(["calibrate", "--static", str(tmp_path / "static.trc"), "-o", str(cal), *common]) == 0
    said = capsys.readouterr().out
    assert "forearm 0.0°, hand 0.0° from the body model's placement" in said, said
    assert "forearm cluster's anatomical points from the landmarks in 100 frames" in said, said
    out = tmp_path / "out.mot"
    target = str(out) if command == "ik" else str(tmp_path / "out")
    assert cli([command, str(tmp_path / "trial.trc"), "-o", target, "--calibration", str(cal), *common]) == 0
    assert "ra_wr_s_p not written: the hand is one marker" in capsys.readouterr().out
    t, q = read_mot(out)
    rows = np.rint(t * rate).astype(int)
    settled = rows >= 50
    err = np.degrees(q[settled, 1:] - np.stack([e, a], axis=1)[rows[settled]])
    rms = np.sqrt(np.mean(err**2, axis=0))
    assert (rms < 1.5).all(), rms
    assert np.isnan(q[:, 0]).all()


def test_one_hand_marker_with_a_forearm_cluster_is_refused_without_its_landmarks(tmp_path, capsys):
    rate = 100.0
    plate, anatomical, _, _ = plate_arm(200, rate, 3)
    trial = write_plate_arm(tmp_path / "trial.trc", plate, anatomical, rate, landmarks=True)
    (tmp_path / "map.toml").write_text(MarkerMap.from_dict(PLATE_MAP).to_toml())
    common = ["--map", str(tmp_path / "map.toml")]
    # No calibration: what to record and run is said, nothing is written.
    assert cli(["ik", str(trial), "-o", str(tmp_path / "o.mot"), *common]) == 2
    err = capsys.readouterr().err
    assert "are a cluster and the hand one marker" in err and "ikid calibrate --static" in err, err
    assert not (tmp_path / "o.mot").exists()
    # A calibration without them (written before ikid measured them, or edited).
    cal = tmp_path / "cal.json"
    static, lm, _, _ = plate_arm(100, rate, 4, moving=False)
    write_plate_arm(tmp_path / "static.trc", static, lm, rate, landmarks=True)
    assert cli(["calibrate", "--static", str(tmp_path / "static.trc"), "-o", str(cal), *common]) == 0
    doc = json.loads(cal.read_text())
    del doc["forearm_landmarks"]
    cal.write_text(json.dumps(doc))
    capsys.readouterr()
    assert cli(["ik", str(trial), "-o", str(tmp_path / "o.mot"), "--calibration", str(cal), *common]) == 2
    assert "has no forearm landmarks in the frame of the forearm's markers" in capsys.readouterr().err
    # A calibration measured with the plate's markers named otherwise.
    good = tmp_path / "good.json"
    assert cli(["calibrate", "--static", str(tmp_path / "static.trc"), "-o", str(good), *common]) == 0
    swapped = {**PLATE_MAP, "markers": {**PLATE_MAP["markers"], "RSP": "FA2", "USP": "FA1"}}
    (tmp_path / "swapped.toml").write_text(MarkerMap.from_dict(swapped).to_toml())
    capsys.readouterr()
    cmd = ["ik", str(trial), "-o", str(tmp_path / "o.mot"), "--calibration", str(good)]
    assert cli([*cmd, "--map", str(tmp_path / "swapped.toml")]) == 2
    assert "calibrate again with this map" in capsys.readouterr().err
    # A map naming the cluster without every landmark is refused when it is read.
    lacking = {**PLATE_MAP, "landmarks": {"radial_styloid": "RWRA", "ulnar_styloid": "RWRB"}}
    with pytest.raises(FileFormatError, match="does not name lateral_epicondyle, medial_epicondyle"):
        MarkerMap.from_dict(lacking)
    with pytest.raises(FileFormatError, match="the hand is that one marker"):
        MarkerMap.from_dict({**PLATE_MAP, "cluster": {"hand": ["X"]}})
    # A static trial with the landmarks in too few frames.
    data = io.read_markers(tmp_path / "static.trc")
    positions = data.positions.copy()
    positions[3:, data.labels.index("RWRA")] = np.nan
    io.write_trc(
        tmp_path / "few.trc", data.time, positions.reshape(len(positions), -1), rate, list(data.labels)
    )
    cmd = ["calibrate", "--static", str(tmp_path / "few.trc"), "-o", str(tmp_path / "few.json"), *common]
    assert cli(cmd) == 2
    assert "seen together in 3 of the frames given" in capsys.readouterr().err


def test_a_plate_named_as_a_wrist_bar_and_elbow_is_refused(tmp_path):
    # The plate's markers as RSP, USP, FAP of a one-marker hand, no landmarks: read as the
    # styloids and the elbow they would give a made-up forearm frame.
    plate, anatomical, _, _ = plate_arm(50, 100.0, 5)
    data = io.read_markers(write_plate_arm(tmp_path / "t.trc", plate, anatomical, 100.0, landmarks=True))
    as_bar = MarkerMap.from_dict({"markers": {"RSP": "FA1", "USP": "FA2", "FAP": "FA3", "HND": "RFIN"}})
    with pytest.raises(
        ikid.InputError, match=r"RSP 'FA1' and USP 'FA2' are 50 mm apart.*FAP 'FA3' 43 mm from"
    ):
        data.frames(as_bar)
    # The wrist bar and the elbow themselves are read.
    bar = MarkerMap.from_dict({"markers": {"RSP": "RWRA", "USP": "RWRB", "FAP": "RELB", "HND": "RFIN"}})
    assert np.isfinite(data.frames(bar)).all()
