"""Lab files in and out: TRC, C3D, MOT/STO, marker maps, resampling, and the `ikid ik` /
`ikid run` commands on them — round trips on files the tests write, and every kind of bad
file answered by a clear error with nothing partial written."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

import ikid
from ikid import _native, io
from ikid.cli import main as cli
from ikid.pipeline import run_model

LAB_LABELS = ("R_RSTY", "R_USTY", "R_FA", "R_MCP2", "R_MCP5", "R_MCB3")
LAB_MAP = (
    "[markers]\n"
    + "\n".join(f'{m} = "{lab}"' for m, lab in zip(ikid.marker_names(), LAB_LABELS, strict=True))
    + "\n"
)


@pytest.fixture(scope="module")
def trial():
    """A fresh simulated trial (seed unused in training), 1 % noise, with a lab's extra marker."""
    return ikid.simulate("random", seed=7001, duration=3.0, shoulder_flexion=0.3).with_noise(
        "uniform", 11, fraction=0.01
    )


def lab_data(trial, labels=LAB_LABELS, extra=True) -> io.MarkerData:
    """The trial as a lab's file would hold it: its own labels, plus a marker ikid does not use."""
    pos = trial.markers.reshape(-1, 6, 3)
    names = tuple(labels)
    if extra:
        pos = np.concatenate([pos, pos[:, :1] + 0.1], axis=1)
        names += ("C7",)
    return io.MarkerData(names, trial.time, pos, trial.rate_hz)


# --- round trips ------------------------------------------------------------------------------


@pytest.mark.parametrize("units", ["mm", "m", "cm"])
def test_trc_round_trip_keeps_positions_and_gaps(trial, tmp_path, units):
    markers = trial.markers.copy()
    markers[100:130, 3:6] = np.nan  # USP unseen for 30 frames
    path = io.write_trc(tmp_path / "t.trc", trial.time, markers, trial.rate_hz, units=units)
    data = io.read_trc(path)
    assert (
        data.labels == tuple(ikid.marker_names())
        and data.rate_hz == trial.rate_hz
        and data.file_units == units
    )
    got = data.frames()
    assert np.array_equal(np.isnan(got), np.isnan(markers))
    assert np.nanmax(np.abs(got - markers)) < 1e-6 * {"mm": 1, "cm": 10, "m": 1000}[units]
    np.testing.assert_allclose(data.time, trial.time, atol=1e-6)


@pytest.mark.parametrize(("command", "start"), [("ik", 300), ("ik", 0), ("track", 0)])
def test_a_gap_before_the_filler_knows_the_wrist_is_filled_from_the_motion_after_it(
    trial, tmp_path, capsys, command, start
):
    # MC2 unseen from the first frame or at 0.3 s, before the gap filler has located the wrist
    # from the motion: live, those frames have no output (ik refused them; track starts on the
    # first complete frame). A file is whole: they are filled from the motion after them,
    # flagged, and as close to the simulator's truth as the frames after them.
    gap = trial.markers.copy()
    gap[start : start + 20, 9:12] = np.nan
    path = io.write_trc(tmp_path / "early.trc", trial.time, gap, trial.rate_hz)
    out_file = tmp_path / ("early.mot" if command == "ik" else "early")
    assert cli([command, str(path), "-o", str(out_file)]) == 0
    out = capsys.readouterr().out
    n = len(trial.time)
    if command == "ik":
        assert f"{n}/{n} frames with output, 20 with a filled marker" in out, out
    else:
        assert f"{n}/{n} frames tracked from frame 0" in out and "20 filled" in out, out
    table = io.read_storage(tmp_path / "early.mot")
    status = table.column("ikid_status").astype(int)
    filled = (status & ikid.FRAME_STATUS["filled"]) != 0
    assert np.array_equal(np.flatnonzero(filled), np.arange(start, start + 20))
    q = np.radians(table.select(ikid.coordinate_names()))
    err = np.degrees(np.abs(q - trial.q)).max(axis=1)
    gap_err, after = err[start : start + 20].max(), err[start + 20 : start + 60].max()
    assert gap_err < max(3.0 * after, 0.5), (gap_err, after)


def test_leading_gaps_are_filled_from_the_motion_after_them_and_nothing_else_is_touched():
    # Oracle: the frames themselves and the simulator's markers. A recording without gaps has
    # nothing filled; in the first LEADING_FILL_S the gaps are filled from the motion after
    # them, where the marker was; past them nothing is; the frames always come back as they
    # were, in order, and the fills do not depend on how the recording is cut into blocks.
    from ikid.pipeline import LEADING_FILL_S, fill_leading_gaps

    trial = ikid.simulate("random", seed=7002, duration=LEADING_FILL_S + 2.0)
    rate, markers = trial.rate_hz, trial.markers.astype(np.float64)

    def blocks(frames, size):
        return [(trial.time[k : k + size], frames[k : k + size]) for k in range(0, len(frames), size)]

    assert all(filled is None for _, _, filled in fill_leading_gaps(blocks(markers, 4000), rate))

    gappy = markers.copy()
    gappy[300:320, 9:12] = np.nan  # before the filler knows the wrist
    gappy[1700:1720, 12:15] = np.nan
    late = int(LEADING_FILL_S * rate) + 500
    gappy[late : late + 20, 12:15] = np.nan  # past the start: untouched
    results = []
    for size in (4000, 777):
        got = list(fill_leading_gaps(blocks(gappy, size), rate))
        assert np.array_equal(np.concatenate([t for t, _, _ in got]), trial.time)
        assert np.array_equal(np.concatenate([f for _, f, _ in got]), gappy, equal_nan=True)
        results.append(np.concatenate([f if g is None else g for _, f, g in got]))
    filled = results[0]
    np.testing.assert_array_equal(results[1], filled)
    changed = np.flatnonzero((np.isnan(gappy) != np.isnan(filled)).any(axis=1))
    assert np.array_equal(changed, np.r_[300:320, 1700:1720])
    untouched = np.ones(len(filled), bool)
    untouched[changed] = False
    assert np.array_equal(filled[untouched], gappy[untouched], equal_nan=True)
    # Filled where the marker is: the rigid hand carries it (1 mm on clean markers).
    assert np.abs(filled[changed][:, 9:15] - markers[changed][:, 9:15]).max() < 1e-3


def test_a_leading_gap_that_lasts_most_of_the_first_seconds_is_filled_from_the_seconds_after():
    # MC2 unseen for the first 9 s: the start held runs on LEARN_AFTER_S past the gap's end, so
    # the filler has motion to learn the wrist from (the first LEADING_FILL_S alone left 1 s).
    from ikid.pipeline import LEADING_FILL_S, LEARN_AFTER_S, fill_leading_gaps

    trial = ikid.simulate("random", seed=7004, duration=16.0)
    rate, markers = trial.rate_hz, trial.markers.astype(np.float64)
    gap_end = int((LEADING_FILL_S - 1.0) * rate)
    gappy = markers.copy()
    gappy[:gap_end, 9:12] = np.nan
    got = list(fill_leading_gaps([(trial.time, gappy)], rate))
    filled = np.concatenate([f if g is None else g for _, f, g in got])
    assert not np.isnan(filled[:gap_end]).any()
    assert np.abs(filled[:gap_end, 9:12] - markers[:gap_end, 9:12]).max() < 2e-3
    held = sum(len(t) for t, _, g in got if g is not None)
    assert held <= gap_end + LEARN_AFTER_S * rate  # nothing held past the motion it needed


@pytest.mark.parametrize("rate", [200.0, 100.0])
def test_a_leading_gap_is_filled_at_a_rate_with_or_without_a_model_of_its_own(rate, tmp_path, capsys):
    # 200 Hz runs the 1 kHz model on its grid between the recording's frames, 100 Hz a model of
    # its own: both fill a leading gap the same way, and only where the stream refused it.
    trial = ikid.simulate("random", seed=7003, duration=4.0, output_every=int(1000 / rate))
    gap = trial.markers.copy()
    gap[int(0.2 * rate) : int(0.5 * rate), 12:15] = np.nan  # MC5 unseen from 0.2 to 0.5 s
    path = io.write_trc(tmp_path / "early.trc", trial.time, gap, trial.rate_hz)
    assert cli(["ik", str(path), "-o", str(tmp_path / "early.mot")]) == 0
    out = capsys.readouterr().out
    n, k = len(trial.time), int(0.3 * rate)
    assert f"{n}/{n} frames with output, {k} with a filled marker" in out, out
    table = io.read_storage(tmp_path / "early.mot")
    filled = (table.column("ikid_status").astype(int) & ikid.FRAME_STATUS["filled"]) != 0
    assert np.array_equal(np.flatnonzero(filled), np.arange(int(0.2 * rate), int(0.5 * rate)))


def test_trc_times_printed_to_a_few_decimals_agree_with_the_header_rate(tmp_path):
    # 120 Hz with times to the ms (steps of 8 and 9 ms): the mean regular step is the header's.
    trial = ikid.simulate("random", seed=52, duration=1.0, output_every=1)
    frames, time = trial.markers[::8][:100], np.round(np.arange(100) / 120.0, 3)
    path = io.write_trc(tmp_path / "t.trc", time, frames, 120.0)
    assert io.read_trc(path).rate_hz == 120.0


def test_a_trc_gap_written_as_zeros_is_a_gap_and_filled_like_an_empty_one(trial, tmp_path, capsys):
    # Some exporters write an unseen marker as 0, 0, 0: read as a position, its 20 frames were
    # dropped with a hint about units. Read as a gap, they are filled, as empty cells are.
    gap = trial.markers.copy()
    gap[2500:2520, 9:12] = np.nan
    zeros = io.write_trc(tmp_path / "zeros.trc", trial.time, np.nan_to_num(gap, nan=0.0), trial.rate_hz)
    io.write_trc(tmp_path / "empty.trc", trial.time, gap, trial.rate_hz)
    assert np.array_equal(np.isnan(io.read_trc(zeros).frames()), np.isnan(gap))
    for name in ("zeros", "empty"):
        assert cli(["ik", str(tmp_path / f"{name}.trc"), "-o", str(tmp_path / f"{name}.mot")]) == 0
    assert "20 with a filled marker" in capsys.readouterr().out
    a, b = io.read_mot(tmp_path / "zeros.mot"), io.read_mot(tmp_path / "empty.mot")
    np.testing.assert_array_equal(a[1], b[1])
    # A marker at the origin in every frame (a file in that marker's own frame) stays a marker.
    still = trial.markers - np.tile(trial.markers[:, 0:3], 6)  # every marker relative to RSP
    assert np.isfinite(io.read_trc(io.write_trc(tmp_path / "o.trc", trial.time, still)).frames()).all()


@pytest.mark.parametrize("units", ["mm", "m"])
def test_csv_round_trip_keeps_positions_and_gaps(trial, tmp_path, units):
    markers = trial.markers.copy()
    markers[100:130, 3:6] = np.nan
    path = io.write_csv_markers(tmp_path / "t.csv", trial.time, markers, units=units)
    data = io.read_markers(path)
    assert data.labels == tuple(ikid.marker_names()) and data.file_units == units
    assert data.rate_hz == pytest.approx(trial.rate_hz, rel=1e-6)
    got = data.frames()
    assert np.array_equal(np.isnan(got), np.isnan(markers))
    assert np.nanmax(np.abs(got - markers)) < 1e-9
    # Columns in another order, '_x' names and no units line (metres) read the same.
    cols = [f"{m}_{a}" for m in reversed(ikid.marker_names()) for a in "XYZ"]
    rev = trial.markers.reshape(-1, 6, 3)[:, ::-1].reshape(len(trial.time), -1)
    io.write_csv(tmp_path / "r.csv", trial.time, rev, cols)
    np.testing.assert_allclose(io.read_markers(tmp_path / "r.csv").frames(), trial.markers, atol=1e-9)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("t,RSP.x\n0,1\n", "first column must be 'time'"),
        ("time,RSP.x,RSP.y\n0,1,2\n0.001,1,2\n", "RSP lack an x, y or z"),
        ("time,RSP.x,RSP.y,RSP.z,RSP.w\n", "'RSP.w' is not"),
        ("time,A.x,A.y,A.z\n0,1,2,3\n0.001,1,two,3\n", ":3: 'two' is not a number"),
        ("time,A.x,A.y,A.z\n0,1,2,3\n0.001,1,2\n", ":3: 3 values, the header names 4"),
        ("time,A.x,A.y,A.z\n0,1,2,3\n0.001,1,2,3\n0.005,1,2,3\n", "not evenly spaced"),
        ("# units=inches\ntime,A.x,A.y,A.z\n0,1,2,3\n0.001,1,2,3\n", "inches"),
    ],
)
def test_bad_csv_files_say_what_is_wrong(tmp_path, text, message):
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(io.FileFormatError, match=re.escape(message)):
        io.read_markers(tmp_path / "bad.csv")


def test_a_csv_in_mm_says_whether_its_unit_was_declared_or_assumed(trial, tmp_path):
    # The same millimetres, with its '# units=m' line (a wrong declaration) and without one (the
    # default assumed): each error says which, and the second how to declare the unit.
    io.write_csv_markers(tmp_path / "said.csv", trial.time, np.asarray(trial.markers) * 1000)
    text = (tmp_path / "said.csv").read_text()
    bare = "".join(line for line in text.splitlines(True) if not line.startswith("#"))
    (tmp_path / "bare.csv").write_text(bare)
    with pytest.raises(ikid.InputError, match=r"are the units mm.*\(the file says its units are 'm'\)"):
        io.read_markers(tmp_path / "said.csv").frames()
    with pytest.raises(ikid.InputError, match=r"no '# units=' line: metres assumed; declare .* '# units=mm'"):
        io.read_markers(tmp_path / "bare.csv").frames()


def test_csv_writer_refuses_non_finite_values_and_writes_nothing(tmp_path):
    with pytest.raises(io.FileFormatError, match="not written"):
        io.write_csv(
            tmp_path / "q.csv", [0.0, 0.001], [[0.1, np.nan, 0.0], [0.1, 0.2, 0.3]], ikid.coordinate_names()
        )
    assert list(tmp_path.iterdir()) == []


def test_c3d_round_trip_keeps_labels_positions_and_gaps(trial, tmp_path):
    data = lab_data(trial)
    pos = data.positions.copy()
    pos[200:260, 4] = np.nan
    data = io.MarkerData(data.labels, data.time, pos, data.rate_hz)
    back = io.read_c3d(io.write_c3d(tmp_path / "t.c3d", data))
    assert back.labels == data.labels and back.rate_hz == data.rate_hz and back.file_units == "mm"
    assert np.array_equal(np.isnan(back.positions), np.isnan(pos))
    assert np.nanmax(np.abs(back.positions - pos)) < 1e-7  # float32 millimetres
    np.testing.assert_allclose(back.time, trial.time, atol=1e-9)


def test_c3d_writes_a_time_gap_as_frames_without_markers_and_refuses_times_off_its_grid(trial, tmp_path):
    # Rows 300-899 left out (0.6 s at 1 kHz): a C3D's times are implied by its frames, so
    # closed up every later row would move 0.6 s earlier. Oracle: the rows kept, at their own
    # times, and the frames between them without markers.
    data = lab_data(trial)
    keep = np.ones(len(data.time), bool)
    keep[300:900] = False
    gapped = io.MarkerData(data.labels, data.time[keep], data.positions[keep], data.rate_hz)
    back = io.read_c3d(io.write_c3d(tmp_path / "gap.c3d", gapped))
    assert len(back.time) == len(data.time)
    np.testing.assert_allclose(back.time[keep], data.time[keep], atol=1e-9)
    assert np.isnan(back.positions[~keep]).all()
    assert np.nanmax(np.abs(back.positions[keep] - data.positions[keep])) < 1e-7
    # A row between two frames of the rate: refused, naming it, and nothing written.
    time = data.time.copy()
    time[10:] += 0.5 / data.rate_hz
    with pytest.raises(ikid.InputError, match=r"row 10's time .* is not a frame of 1000 Hz"):
        io.write_c3d(tmp_path / "off.c3d", io.MarkerData(data.labels, time, data.positions, data.rate_hz))
    assert not (tmp_path / "off.c3d").exists()


def test_mot_and_sto_round_trip(trial, tmp_path):
    t, q = io.read_mot(io.write_mot(tmp_path / "q.mot", trial.time, trial.q))
    np.testing.assert_allclose(q, trial.q, atol=1e-9)
    np.testing.assert_allclose(t, trial.time, atol=1e-6)
    t, tau = io.read_sto(io.write_sto(tmp_path / "tau.sto", trial.time, trial.tau))
    np.testing.assert_allclose(tau, trial.tau, rtol=1e-9, atol=1e-12)
    table = io.read_storage(tmp_path / "q.mot")
    assert table.in_degrees and table.columns == tuple(ikid.coordinate_names())


def test_sd_columns_follow_their_coordinates_declared_in_the_header_and_skip_undetermined(tmp_path):
    from ikid.io.storage import mot_writer, read_storage, sd_columns, sto_writer

    n = 5
    time = np.arange(n) / 100.0
    q = np.linspace(0.1, 0.5, 3 * n).reshape(n, 3)
    sd = np.full((n, 3), 0.01) * np.arange(1, 4)
    names = ikid.coordinate_names()
    with mot_writer(tmp_path / "q.mot", undetermined={names[0]: "one hand marker"}, with_sd=True) as write:
        write(time, q, np.zeros(n, np.uint16), sd)
    table = read_storage(tmp_path / "q.mot")
    # s_p not determined: neither it nor its σ is written.
    assert table.columns == (names[1], f"{names[1]}_sd", names[2], f"{names[2]}_sd", "ikid_status")
    assert sd_columns(table) == [f"{names[1]}_sd", f"{names[2]}_sd"]
    np.testing.assert_allclose(table.select([f"{names[1]}_sd", f"{names[2]}_sd"]), np.degrees(sd[:, 1:]))
    np.testing.assert_allclose(io.read_mot(tmp_path / "q.mot")[1][:, 1:], q[:, 1:], atol=1e-9)
    # A σ that is not finite is refused by name, never written; σ missing or unasked is refused.
    bad = sd.copy()
    bad[2, 1] = np.nan
    refusals = [(bad, f"value {names[1]}_moment_sd at row 2 is nan"), (None, "declares standard deviations")]
    for given, message in refusals:
        with pytest.raises(ikid.InputError, match=message):
            with sto_writer(tmp_path / "tau.sto", with_sd=True) as write:
                write(time, q, np.zeros(n, np.uint16), given)
        assert not (tmp_path / "tau.sto").exists()
    with pytest.raises(ikid.InputError, match="without their columns"):
        with sto_writer(tmp_path / "tau.sto") as write:
            write(time, q, np.zeros(n, np.uint16), sd)


def test_a_block_with_every_row_refused_writes_nothing_and_the_next_block_its_rows(tmp_path):
    # `ikid track` reads in blocks and writes each one's plausible rows: a block where every row
    # was refused gave a reshape traceback (issue #28's exam, a skin-marker trial).
    from ikid.io.storage import mot_writer, read_storage

    names = ikid.coordinate_names()
    q, sd = np.full((2, 3), 0.2), np.full((2, 3), 0.01)
    with mot_writer(tmp_path / "q.mot", with_sd=True) as write:
        write(np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.uint16), np.zeros((0, 3)))
        write(np.array([0.01, 0.02]), q, np.zeros(2, np.uint16), sd)
    table = read_storage(tmp_path / "q.mot")
    assert table.columns[:2] == (names[0], f"{names[0]}_sd")
    np.testing.assert_allclose(table.select([names[0], f"{names[0]}_sd"]), np.degrees([[0.2, 0.01]] * 2))


def test_storage_reads_radians_files_and_names_missing_columns(tmp_path):
    path = io.write_storage(
        tmp_path / "r.mot",
        [0.0, 0.01],
        np.zeros((2, 3)),
        ["ra_wr_s_p", "ra_wr_e_f", "elbow_flex"],
        in_degrees=False,
    )
    with pytest.raises(
        ikid.InputError, match=r"no column\(s\) ra_wr_ad_ab; it has ra_wr_s_p, ra_wr_e_f, elbow_flex"
    ):
        io.read_mot(path)


# --- marker maps ------------------------------------------------------------------------------


def test_marker_map_selects_a_labs_labels_in_ikid_order(trial, tmp_path):
    (tmp_path / "lab.toml").write_text(LAB_MAP)
    frames = lab_data(trial).frames(io.MarkerMap.load(tmp_path / "lab.toml"))
    assert np.array_equal(frames, trial.markers)


def test_frames_take_a_marker_maps_path_and_refuse_anything_else(trial, tmp_path):
    (tmp_path / "lab.toml").write_text(LAB_MAP)
    by_path = lab_data(trial).frames(tmp_path / "lab.toml")
    np.testing.assert_array_equal(by_path, lab_data(trial).frames(io.MarkerMap.load(tmp_path / "lab.toml")))
    np.testing.assert_array_equal(by_path, lab_data(trial).frames(str(tmp_path / "lab.toml")))
    with pytest.raises(ikid.ArgumentError, match="expected a MarkerMap or the path of a marker map, got"):
        lab_data(trial).frames({"RSP": "R_RSTY"})


def test_missing_label_lists_the_labels_the_file_has(trial, tmp_path):
    (tmp_path / "lab.toml").write_text(LAB_MAP.replace("R_MCP5", "R_MCP5_typo"))
    with pytest.raises(
        ikid.InputError,
        match=r"label\(s\) R_MCP5_typo \(MC5\) not found; the file has R_RSTY, .*R_MCP5, R_MCB3, C7",
    ):
        lab_data(trial).frames(io.MarkerMap.load(tmp_path / "lab.toml"))
    with pytest.raises(ikid.InputError, match="give a marker map"):
        lab_data(trial).frames()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[markers]\nRSP = 'a'\n", r"does not name USP, FAP, MC2, MC5, MCB"),
        (LAB_MAP + "ELB = 'x'\n", r"unknown ikid marker\(s\) ELB"),
        (LAB_MAP.replace("R_USTY", "R_RSTY"), r"label 'R_RSTY' is given to both RSP and USP"),
        ("markers = 3", r"expected a \[markers\] table"),
        ("[markers\n", r"not valid TOML"),
        # A mistyped key is refused, never left at its default (a right arm, no landmarks).
        ('sid = "left"\n' + LAB_MAP, r"unknown key\(s\) 'sid' \(did you mean 'side'\?\)"),
        (LAB_MAP + "[landmark]\nradial_styloid = 'R_RSTY'\n", r"'landmark' \(did you mean 'landmarks'\?\)"),
        ('units = "mm"\n' + LAB_MAP, r"unknown key\(s\) 'units'; a marker map has markers, side, up"),
    ],
)
def test_bad_marker_maps_say_what_is_wrong(tmp_path, text, message):
    (tmp_path / "m.toml").write_text(text)
    with pytest.raises(io.FileFormatError, match=message):
        io.MarkerMap.load(tmp_path / "m.toml")


# --- resampling -------------------------------------------------------------------------------


def test_resample_is_exact_for_quadratic_motion_and_keeps_gaps_local():
    t = np.sort(np.random.default_rng(0).uniform(0, 1, 80))
    x = np.column_stack([3 * t**2 - t + 0.5, -t])
    new_t, new_x = io.resample(t, x, 1000.0)
    assert new_t[0] == t[0] and new_t[-1] <= t[-1] and np.allclose(np.diff(new_t), 1e-3)
    inner = (new_t > t[1]) & (new_t < t[-2])  # np.gradient is one-sided (first order) at the ends
    np.testing.assert_allclose(
        new_x[inner], np.column_stack([3 * new_t**2 - new_t + 0.5, -new_t])[inner], atol=1e-9
    )
    x[40] = np.nan
    _, gappy = io.resample(t, x, 1000.0)
    missing = np.isnan(gappy[:, 0])
    assert missing.any() and np.all((new_t[missing] > t[37]) & (new_t[missing] < t[43]))


def test_a_100_hz_file_is_refused_unless_resampled_then_runs_at_the_models_rate(trial, tmp_path):
    slow = slice(None, None, 10)
    path = io.write_trc(tmp_path / "slow.trc", trial.time[slow], trial.markers[slow], 100.0)
    data = io.read_trc(path)
    model = ikid.load("wrist-ik")
    with pytest.raises(
        ikid.InputError,
        match=r"sampled at 100 Hz but model 'wrist-ik' was trained at 1000 Hz; resample it \(--resample",
    ):
        run_model(model, data.frames(), data.time, rate_hz=data.rate_hz)
    run = run_model(model, data.frames(), data.time, rate_hz=data.rate_hz, resample_to_model=True)
    assert run.resampled_from_hz == 100.0 and run.rate_hz == 1000.0
    truth = trial.q[np.round(run.time * 1000).astype(int)]
    assert np.mean((run.values - truth) ** 2) < 3e-4  # the 1 %-noise bound of the 1000 Hz model


# --- the commands -----------------------------------------------------------------------------


def test_ik_command_on_c3d_and_trc_equals_the_python_api(trial, tmp_path):
    """Simulated trial -> C3D and TRC (a lab's labels) -> `ikid ik` -> MOT = Model.predict."""
    (tmp_path / "lab.toml").write_text(LAB_MAP)
    data = lab_data(trial)
    io.write_c3d(tmp_path / "trial.c3d", data)
    io.write_trc(
        tmp_path / "trial.trc",
        data.time,
        data.positions.reshape(len(data), -1),
        data.rate_hz,
        labels=data.labels,
    )
    io.write_csv_markers(
        tmp_path / "trial.csv",
        data.time,
        data.positions.reshape(len(data), -1),
        labels=list(data.labels),
        units="mm",
    )
    model = ikid.load("wrist-ik")
    w = model.window
    want = model.predict(trial.markers)  # rows for frames window-1 ... n-1
    for src in ("trial.c3d", "trial.trc", "trial.csv"):
        out = tmp_path / f"{src}.mot"
        assert cli(["ik", str(tmp_path / src), "-o", str(out), "--map", str(tmp_path / "lab.toml")]) == 0
        t, q = io.read_mot(out)
        # A row for every frame: while the first window fills, the frame's per-frame solution
        # (its markers' own angles; the IK model corrects those), then the network's.
        assert len(q) == len(trial.markers)
        np.testing.assert_allclose(t, trial.time, atol=1e-6)
        # Same frames as read back from the file: equal to the printed precision.
        frames = io.read_markers(tmp_path / src).frames(io.MarkerMap.load(tmp_path / "lab.toml"))
        np.testing.assert_allclose(q[w - 1 :], model.predict(frames), atol=1e-8)
        np.testing.assert_allclose(q[: w - 1], _native.compute_features(frames[: w - 1], "angles"), atol=1e-7)
        q = q[w - 1 :]
        # And the original frames: within the file's rounding (float32 or 1e-6 mm).
        np.testing.assert_allclose(q, want, atol=2e-5)


def test_run_command_writes_angles_and_torques_for_a_folder(trial, tmp_path, capsys):
    (tmp_path / "in").mkdir()
    (tmp_path / "lab.toml").write_text(LAB_MAP)
    for k in range(2):
        io.write_c3d(tmp_path / "in" / f"trial{k}.c3d", lab_data(trial))
    assert (
        cli(
            [
                "run",
                str(tmp_path / "in"),
                "-o",
                str(tmp_path / "out"),
                "--map",
                str(tmp_path / "lab.toml"),
                "--jobs",
                "2",
            ]
        )
        == 0
    )
    assert "2/2 files processed, 0 failed" in capsys.readouterr().out
    for k in range(2):
        _, q = io.read_mot(tmp_path / "out" / f"trial{k}.mot")
        t, tau = io.read_sto(tmp_path / "out" / f"trial{k}.sto")
        np.testing.assert_allclose(
            tau,
            ikid.load("wrist-chain").predict(
                io.read_c3d(tmp_path / "in" / f"trial{k}.c3d").frames(
                    io.MarkerMap.load(tmp_path / "lab.toml")
                )
            ),
            atol=1e-8,
        )
        # Per torque, the MSE is a fraction of the truth's variance (its MSE about its mean): a
        # constant prediction scores >= 1 there, zero 2.0-2.9; wrist-chain 0.02-0.19 on this trial.
        truth = trial.tau[np.round(t * 1000).astype(int)]
        assert np.all(np.mean((tau - truth) ** 2, axis=0) <= 0.5 * truth.var(axis=0))


def test_map_template_lists_the_files_labels(trial, tmp_path, capsys):
    io.write_c3d(tmp_path / "t.c3d", lab_data(trial))
    assert cli(["map-template", str(tmp_path / "t.c3d")]) == 0
    text = capsys.readouterr().out
    assert "R_RSTY, R_USTY, R_FA, R_MCP2, R_MCP5, R_MCB3, C7" in text
    (tmp_path / "m.toml").write_text(text)
    assert io.MarkerMap.load(tmp_path / "m.toml") == io.MarkerMap(
        io.MarkerMap.identity().labels, str(tmp_path / "m.toml")
    )


# --- bad files: a clear error each, nothing written -------------------------------------------


def _bad_trc_in_metres_labelled_mm(trial, tmp_path):
    path = io.write_trc(
        tmp_path / "bad.trc", trial.time, trial.markers / 1000.0, trial.rate_hz
    )  # values in m, says mm
    return path, r"markers spread over 0\.000 m.*are the units metres, read as mm\?.*units are 'mm'"


def _bad_unknown_unit(trial, tmp_path):
    path = io.write_trc(tmp_path / "bad.trc", trial.time, trial.markers, trial.rate_hz)
    path.write_text(path.read_text().replace("\tmm\t", "\tinches\t", 1))
    return path, r"unknown length unit 'inches' \(known: mm, cm, m\)"


def _bad_all_nan_marker(trial, tmp_path):
    m = trial.markers.copy()
    m[:, 9:12] = np.nan
    return io.write_trc(
        tmp_path / "bad.trc", trial.time, m, trial.rate_hz
    ), r"marker MC2 \(label 'MC2'\) is missing in every frame"


def _bad_truncated_trc(trial, tmp_path):
    path = io.write_trc(tmp_path / "bad.trc", trial.time, trial.markers, trial.rate_hz)
    text = path.read_text()
    path.write_text(text[: len(text) // 2])
    return path, r"header says 3\d\d\d frames, the file has \d+ \(truncated\?\)|is not a number|columns"


def _bad_truncated_c3d(trial, tmp_path):
    path = io.write_c3d(tmp_path / "bad.c3d", lab_data(trial, tuple(ikid.marker_names()), extra=False))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path, r"header says 3\d\d\d frames, the file holds \d+ \(truncated\?\)"


def _bad_not_a_c3d(trial, tmp_path):
    path = tmp_path / "bad.c3d"
    path.write_bytes(b"\x00" * 100)
    return path, r"not a readable C3D file: 100 bytes, shorter than a C3D file's 512-byte header"


def _bad_c3d_cut_in_its_parameters(trial, tmp_path):
    # Cut before its data starts: ezc3d's own message advises its ignoreBadFormatting flag, which
    # no ikid option sets; the error says what happened to the file instead.
    path = io.write_c3d(tmp_path / "bad.c3d", lab_data(trial, tuple(ikid.marker_names()), extra=False))
    path.write_bytes(path.read_bytes()[:1000])
    return (
        path,
        r"not a readable C3D file: it stops \(1000 bytes\) before the parameters or data its header "
        r"(?!.*ignoreBadFormatting)",
    )


def _bad_rate_contradicts_times(trial, tmp_path):
    # Header 120 Hz, times 1 ms apart (the trial's 1 kHz): which one is right cannot be known.
    path = io.write_trc(tmp_path / "bad.trc", trial.time, trial.markers, 120.0)
    return path, r"header's DataRate is 120 Hz but its Time column steps 1 ms \(1000 Hz\).*correct the one"


def _bad_zeros(trial, tmp_path):
    # (A file at another rate is no longer bad: the IK family runs any rate, tests/test_rates.py.)
    return io.write_trc(
        tmp_path / "bad.trc", trial.time, 0.0 * trial.markers, trial.rate_hz
    ), r"markers spread over 0\.000 m"


@pytest.mark.parametrize(
    "make_bad",
    [
        _bad_trc_in_metres_labelled_mm,
        _bad_unknown_unit,
        _bad_all_nan_marker,
        _bad_truncated_trc,
        _bad_truncated_c3d,
        _bad_not_a_c3d,
        _bad_c3d_cut_in_its_parameters,
        _bad_rate_contradicts_times,
        _bad_zeros,
    ],
)
def test_bad_files_get_a_clear_error_and_no_output(trial, tmp_path, capsys, make_bad):
    path, message = make_bad(trial, tmp_path)
    out = tmp_path / "out.mot"
    assert cli(["ik", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"ikid: error: {path}") and __import__("re").search(message, err), err
    assert not out.exists() and not list(tmp_path.glob(".out.mot*"))  # nothing partial either


def test_corrupted_c3d_files_are_read_or_refused_never_a_crash(tmp_path):
    """ezc3d 1.7.2 segfaults on some corrupted parameter sections (found by flipping bytes);
    ikid parses in a child process, so every corrupted file is read whole or refused."""
    data = lab_data(ikid.simulate("random", seed=7002, duration=0.3))
    good = io.write_c3d(tmp_path / "good.c3d", data).read_bytes()
    refused = 0
    for k, pos in enumerate(range(512, 1100, 13)):
        bad = bytearray(good)
        bad[pos] ^= 0xFF
        path = tmp_path / f"flip{k}.c3d"
        path.write_bytes(bytes(bad))
        try:
            got = io.read_c3d(path)
        except io.FileFormatError as e:
            assert str(e).startswith(str(path))
            refused += 1
        else:
            assert got.positions.shape[1:] == (len(got.labels), 3)
    assert refused > 0


def test_a_parser_crash_is_reported_as_a_bad_file(tmp_path, monkeypatch):
    from ikid.io import c3d

    monkeypatch.setattr(c3d, "_CHILD", "import os, signal; os.kill(os.getpid(), signal.SIGSEGV)")
    (tmp_path / "x.c3d").write_bytes(b"\x02P" + b"\x00" * 510)
    with pytest.raises(
        io.FileFormatError, match=r"x.c3d: not a readable C3D file: the C3D parser crashed \(signal 11\)"
    ):
        io.read_c3d(tmp_path / "x.c3d")
    assert subprocess.run([sys.executable, "-c", "import ikid"]).returncode == 0


def test_text_outputs_are_utf8_and_get_normal_permissions_whatever_the_locale(tmp_path):
    """An ASCII locale (C without UTF-8 mode) must not break writing '°' or '²', and outputs
    are not left private (mkstemp's 0600)."""
    code = (
        "import sys; from ikid.io._atomic import write_text_atomic; "
        "write_text_atomic(sys.argv[1], 'RMSE (\\u00b0), MSE (rad\\u00b2)\\n')"
    )  # ASCII source: the locale is ASCII
    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    result = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "r.md")], capture_output=True, text=True, env=env
    )
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "r.md").read_bytes().decode("utf-8") == "RMSE (°), MSE (rad²)\n"
    old = os.umask(0o022)
    try:
        from ikid.io._atomic import write_text_atomic

        write_text_atomic(tmp_path / "m.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "m.txt").stat().st_mode & 0o777 == 0o644


# --- whole files or none ----------------------------------------------------------------------

#: Each writer, as a child process would call it on the same deterministic data: a statement
#: writing ``path`` (``t`` a 0.5 s trial, ``io``/``ikid``/``np`` imported).
WRITERS = {
    "c3d": "io.write_c3d(path, io.MarkerData(tuple(ikid.marker_names()), t.time, "
    "t.markers.reshape(-1, 6, 3), t.rate_hz))",
    "trc": "io.write_trc(path, t.time, t.markers, t.rate_hz)",
    "csv": "io.write_csv(path, t.time, t.q, ikid.coordinate_names())",
    "csv_markers": "io.write_csv_markers(path, t.time, t.markers)",
    "mot": "io.write_mot(path, t.time, t.q)",
    "sto": "io.write_sto(path, t.time, t.tau)",
    "json": "__import__('ikid.io._atomic').io._atomic.write_text_atomic(path, "
    "__import__('json').dumps({'q': t.q.tolist()}))",
    "npz": "t.save(path[: -len('.npz')])",
}
_SUFFIX = {"csv_markers": ".csv", "json": ".json"}

_WRITE_CHILD = """
import json, resource, signal, sys
import ikid, numpy as np
from ikid import io
path, limit, mode = sys.argv[1], int(sys.argv[2]), sys.argv[3]
t = ikid.simulate("random", seed=7100, duration=0.5)
if mode == "limit":
    # A full disk, reproducibly: the process may not grow a file past `limit` bytes. SIGXFSZ
    # ignored, so the write gets EFBIG (what a full disk's ENOSPC looks like to a writer).
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))
try:
    exec(sys.argv[4])
except Exception as e:
    print(json.dumps({"type": type(e).__name__, "write_error": isinstance(e, ikid.WriteError),
                      "os_error": isinstance(e, OSError), "message": str(e)}))
    sys.exit(1)
print(json.dumps({"type": None}))
"""


def _write_in_child(path, writer: str, limit: int = 0) -> tuple[int, dict]:
    run = subprocess.run(
        [sys.executable, "-c", _WRITE_CHILD, str(path), str(limit), "limit" if limit else "free", writer],
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = run.stdout.strip().splitlines()
    assert lines, run.stderr
    return run.returncode, __import__("json").loads(lines[-1])


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_a_write_cut_short_by_a_full_disk_is_a_named_error_and_the_old_file_stays(tmp_path, kind):
    """Issue #22 case 5: a file size limit at a third of the file (a full disk). ezc3d reports
    success on a short write, so the C3D writer reads its file back; the others check their
    writes. Every writer raises ikid.WriteError naming the file, and the good file written
    before is byte for byte as it was, with no temporary file left beside it."""
    path = tmp_path / f"trial{_SUFFIX.get(kind, '.' + kind)}"
    status, result = _write_in_child(path, WRITERS[kind])
    assert status == 0 and result["type"] is None, result
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    size = path.stat().st_size
    assert size > 3000, size  # big enough that a third of it is a short file, not an empty one

    status, result = _write_in_child(path, WRITERS[kind], limit=size // 3)
    assert status == 1, result
    assert result["write_error"] and result["os_error"], result
    assert result["message"].startswith(f"{path}: could not write it whole: "), result["message"]
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert after == before  # the old file(s) unchanged, nothing new (no temporary file) beside


def test_the_c3d_read_back_refuses_a_short_file_and_passes_a_whole_one(trial, tmp_path):
    """The check behind the C3D writer, on a file ezc3d wrote whole, then cut: every cut is
    caught, by the header's point and frame counts or by the size they need."""
    from ikid.io._atomic import Incomplete
    from ikid.io.c3d import check_c3d

    data = lab_data(trial, tuple(ikid.marker_names()), extra=False)
    good = io.write_c3d(tmp_path / "good.c3d", data).read_bytes()
    check_c3d(tmp_path / "good.c3d", len(data), 6)  # whole: passes
    # The size a float C3D of 6 points needs: its parameter blocks, then 16 bytes a point a frame.
    assert len(good) >= 512 * (good[16] + 256 * good[17] - 1) + len(data) * 6 * 16
    for cut in (0, 100, 512, 2048, len(good) // 3, len(good) - 600):
        (tmp_path / "cut.c3d").write_bytes(good[:cut])
        with pytest.raises(Incomplete, match="read back"):
            check_c3d(tmp_path / "cut.c3d", len(data), 6)
    with pytest.raises(Incomplete, match="read back 6 points in the header, 7 were written"):
        check_c3d(tmp_path / "good.c3d", len(data), 7)
    with pytest.raises(Incomplete, match=rf"read back {len(data)} frames in the header, 5 were written"):
        check_c3d(tmp_path / "good.c3d", 5, 6)


def test_bytes_reach_the_disk_before_the_rename_and_the_folder_after(tmp_path, monkeypatch):
    """write + flush + fsync of the temporary file, whole, while the old file is still in
    place; then the rename; then an fsync of the folder."""
    from ikid.io._atomic import write_text_atomic

    target = tmp_path / "q.mot"
    target.write_text("old\n")
    text = "new contents °\n" * 1000
    synced: list[tuple[str, bytes | None, str]] = []
    real_fsync = os.fsync

    def fsync(fd: int) -> None:
        real_fsync(fd)
        where = os.readlink(f"/proc/self/fd/{fd}")
        content = open(where, "rb").read() if os.path.isfile(where) else None
        synced.append((where, content, target.read_text()))

    monkeypatch.setattr(os, "fsync", fsync)
    write_text_atomic(target, text)
    files = [(w, c, t) for w, c, t in synced if c is not None]
    assert files and all(os.path.basename(w).startswith(".q.mot.") for w, _, _ in files), synced
    assert all(c == text.encode() for _, c, _ in files)  # whole when synced...
    assert all(t == "old\n" for _, _, t in files)  # ...and before the target was replaced
    assert synced[-1][0] == str(tmp_path) and synced[-1][2] == text  # the folder, after the rename
    assert target.read_text() == text and sorted(p.name for p in tmp_path.iterdir()) == ["q.mot"]


def test_a_failed_sync_is_a_named_error_and_nothing_is_replaced(tmp_path, monkeypatch):
    import errno

    target = io.write_mot(tmp_path / "q.mot", [0.0, 0.001], np.zeros((2, 3)))
    before = target.read_bytes()

    def failing_fsync(fd: int) -> None:
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(
        ikid.WriteError, match=rf"^{re.escape(str(target))}: could not write it whole: Input"
    ) as e:
        io.write_mot(target, [0.0, 0.001], np.ones((2, 3)))
    assert e.value.errno == errno.EIO and isinstance(e.value, OSError)
    assert target.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["q.mot"]


def test_outputs_that_go_together_are_replaced_together_or_not_at_all(tmp_path, monkeypatch):
    """atomic_outputs: a failure on the second file (its sync, or its rename) leaves the old
    pair exactly as it was — the first file, already written, is not renamed (or is put back)."""
    import errno

    from ikid.io._atomic import atomic_outputs

    mot, sto = tmp_path / "t.mot", tmp_path / "t.sto"
    io.write_mot(mot, [0.0, 0.001], np.zeros((2, 3)))
    io.write_sto(sto, [0.0, 0.001], np.zeros((2, 3)))
    old = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    real_fsync = os.fsync

    def fsync(fd: int) -> None:  # the disk fails on the .sto's temporary file
        if ".t.sto." in os.readlink(f"/proc/self/fd/{fd}"):
            raise OSError(errno.EIO, "Input/output error")
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    with pytest.raises(ikid.WriteError, match=rf"^{re.escape(str(sto))}: .*none of the outputs .*t\.mot"):
        with atomic_outputs():
            io.write_mot(mot, [0.0, 0.001], np.ones((2, 3)))
            io.write_sto(sto, [0.0, 0.001], np.ones((2, 3)))
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == old
    monkeypatch.setattr(os, "fsync", real_fsync)

    # The rename of the second fails (a folder sits where its file goes): the first is put back.
    sto.unlink()
    sto.mkdir()
    old = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    with pytest.raises(ikid.WriteError, match=rf"^{re.escape(str(sto))}: could not write it whole"):
        with atomic_outputs():
            io.write_mot(mot, [0.0, 0.001], np.ones((2, 3)))
            io.write_sto(sto, [0.0, 0.001], np.ones((2, 3)))
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.mot", "t.sto"]  # no temporary left
    # And when both succeed, both are replaced.
    sto.rmdir()
    with atomic_outputs() as written:
        io.write_mot(mot, [0.0, 0.001], np.ones((2, 3)))
        io.write_sto(sto, [0.0, 0.001], np.ones((2, 3)))
    assert written == [mot, sto]
    np.testing.assert_allclose(io.read_mot(mot)[1], np.ones((2, 3)), rtol=1e-9)
    np.testing.assert_array_equal(io.read_sto(sto)[1], np.ones((2, 3)))


def test_a_trial_is_saved_whole_or_its_old_files_stay(tmp_path, monkeypatch):
    """Trial.save (and `ikid simulate`): four files that belong together; the last failing
    leaves the old four, byte for byte."""
    import errno

    ikid.simulate("random", seed=7101, duration=0.1).save(tmp_path / "t")
    old = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert sorted(old) == ["t.mot", "t.npz", "t.sto", "t.trc"]
    real_fsync = os.fsync

    def fsync(fd: int) -> None:
        if ".t.sto." in os.readlink(f"/proc/self/fd/{fd}"):
            raise OSError(errno.ENOSPC, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    with pytest.raises(
        ikid.WriteError, match=r"t\.sto: could not write it whole: No space left on device \(the disk"
    ):
        ikid.simulate("random", seed=7102, duration=0.1).save(tmp_path / "t")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == old


def test_refused_frames_are_counted_by_the_cores_code_not_by_their_message(trial):
    """Messages carry numbers that differ from frame to frame (a spread of 2.616 m, 2.617 m...):
    the summary counts frames by the core's stable code, with the first frame's message once."""
    frames = trial.markers[:300] * 10.0  # a file in mm read as cm: every frame implausible
    run = run_model(ikid.load("wrist-ik"), frames, trial.time[:300])
    assert dict(run.refused) == {"implausible markers": 300}
    summary = run.summary()
    assert summary.startswith("0/300 frames with output, 300 implausible markers (first: frame 0: "), summary
    assert summary.count("implausible") == 1 and "units" in summary, summary
