"""Files of any length in bounded memory (issue #31, item 4): a TRC read in blocks is the file
read whole, a run fed in blocks gives the rows a run over the whole arrays gives, `ikid ik`
writes them a block at a time, and its memory does not grow with the trial's length; the same
for `ikid id`: its .mot read in blocks is the table written, its angles filtered and
differenced in blocks are SciPy's over each whole stretch, its torques those of the whole file.

Expected rows come from the whole-file path (read_trc, run_model over the arrays) or from SciPy
and the arrays written, which these tests compare the block path against, never from the block
path itself.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from scipy.signal import butter, filtfilt, sosfiltfilt

import ikid
from ikid import pipeline
from ikid.cli import main as cli
from ikid.cli import process
from ikid.io import (
    csv,
    mot_blocks,
    open_csv_markers,
    open_storage,
    open_trc,
    read_sto,
    read_storage,
    read_trc,
    storage,
    trc,
    write_csv_markers,
    write_mot,
    write_trc,
)
from ikid.io.resample import resample_stretches
from ikid.kinematics import joint_state_blocks, min_stretch_rows

#: Held-out trajectory (studies/rates.py's test seeds start at 9500).
SEED = 9506


def _markers(seconds: float, every: int = 1) -> tuple[np.ndarray, np.ndarray]:
    t = ikid.simulate("random", seed=SEED, duration=seconds, output_every=every)
    return np.asarray(t.time), np.asarray(t.markers, np.float64).reshape(len(t.time), -1)


def _with_gaps(markers: np.ndarray) -> np.ndarray:
    markers = markers.copy()
    markers[100:130, 12:15] = np.nan  # MC5 missing 30 frames
    markers[400, 0:3] = np.nan  # RSP, one frame
    return markers


def test_a_trc_read_in_blocks_is_the_trc_read_whole(tmp_path):
    time, markers = _markers(1.0)
    write_trc(tmp_path / "t.trc", time, _with_gaps(markers), 1000.0)
    whole = read_trc(tmp_path / "t.trc")
    for block_frames in (7, 1000, 5000):
        blocks = list(open_trc(tmp_path / "t.trc", block_frames=block_frames).blocks())
        assert max(len(b) for b in blocks) <= block_frames
        np.testing.assert_array_equal(np.concatenate([b.time for b in blocks]), whole.time)
        np.testing.assert_array_equal(np.concatenate([b.positions for b in blocks]), whole.positions)
    assert np.isnan(whole.positions[100:130, 4]).all() and np.isfinite(whole.positions[:100]).all()


def test_a_bad_row_late_in_a_file_is_named_when_its_block_is_read(tmp_path):
    time, markers = _markers(1.0)
    write_trc(tmp_path / "t.trc", time, markers, 1000.0)
    lines = (tmp_path / "t.trc").read_text().splitlines()
    cells = lines[900].split("\t")
    cells[5] = "x1"
    lines[900] = "\t".join(cells)
    (tmp_path / "t.trc").write_text("\n".join(lines) + "\n")
    with pytest.raises(ikid.InputError, match=r"t\.trc:901: 'x1' is not a number"):
        read_trc(tmp_path / "t.trc")
    blocks = open_trc(tmp_path / "t.trc", block_frames=100).blocks()
    with pytest.raises(ikid.InputError, match=r"t\.trc:901: 'x1' is not a number"):
        for _ in blocks:
            pass
    # A byte that is not UTF-8: named with its line too.
    raw = (tmp_path / "t.trc").read_bytes().split(b"\n")
    raw[900] = raw[900].replace(b"x1", b"1\xff")
    (tmp_path / "t.trc").write_bytes(b"\n".join(raw))
    with pytest.raises(ikid.InputError, match=r"t\.trc:901: not a text file"):
        list(open_trc(tmp_path / "t.trc", block_frames=100).blocks())


def _rows(run: pipeline.Run) -> tuple[np.ndarray, ...]:
    return run.time, run.values, run.status


@pytest.mark.parametrize(("rate", "seconds"), [(1000.0, 1.5), (70.0, 3.0)])
def test_a_run_in_blocks_gives_the_rows_of_a_run_over_the_whole_arrays(rate, seconds):
    # 1 kHz: the member at the rate, frame by frame; 70 Hz: the 1 kHz member over its grid,
    # whose held frames cross every block boundary.
    time, markers = _markers(seconds, every=1)
    if rate != 1000.0:
        fine_time = time
        time = np.arange(0.0, fine_time[-1], 1.0 / rate)
        markers = np.column_stack([np.interp(time, fine_time, c) for c in markers.T])
    markers = _with_gaps(markers) if rate == 1000.0 else markers
    whole = pipeline.run_model("wrist-ik", markers, time, rate_hz=rate)
    assert whole.n_outputs > 0.9 * len(time)
    for size in (1, 5, 97):
        blocks = ((time[k : k + size], markers[k : k + size]) for k in range(0, len(time), size))
        got = pipeline.run_blocks("wrist-ik", blocks, rate_hz=rate)
        for a, b in zip(_rows(got), _rows(whole), strict=True):
            np.testing.assert_array_equal(a, b)
        assert got.summary() == whole.summary()


def _ik_peak(tmp_path, seconds: float, suffix: str = ".trc") -> tuple[int, int]:
    """`ikid ik`'s work on a 1 kHz TRC (or marker CSV) of ``seconds`` in this process:
    (tracemalloc peak bytes, frames)."""
    time, markers = _markers(seconds)
    path = tmp_path / f"t{seconds:g}{suffix}"
    if suffix == ".trc":
        write_trc(path, time, markers, 1000.0)
    else:
        write_csv_markers(path, time, markers, units="mm")
    out = tmp_path / f"t{seconds:g}.mot"
    opt = {
        "map": None,
        "ik_model": "wrist-ik",
        "torque_model": None,
        "resample": False,
        "missing_markers": None,
        "progress": False,
        "calibration": None,
        "allow_unchecked": False,
        "outputs": (out, tmp_path / "unused.sto"),
    }
    ikid.load("wrist-ik")  # loaded once before measuring (its tensors are not the file's)
    tracemalloc.start()
    try:
        row = process._process_one((str(path), opt))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert row["ok"], row
    assert len(read_storage(out).time) == len(time)  # complete: a row for every frame
    return peak, len(time)


@pytest.mark.parametrize("suffix", [".trc", ".csv"])
def test_ik_memory_does_not_grow_with_the_trials_length(tmp_path, monkeypatch, suffix):
    # Blocks of 500 frames: 2 s and 8 s are ~5 and ~17 blocks. Read whole, 4x the frames was
    # ~4x the memory (the frames, the rows and the text); in blocks it is one block's.
    monkeypatch.setattr(trc, "BLOCK_FRAMES", 500)
    monkeypatch.setattr(csv, "BLOCK_FRAMES", 500)
    short, n_short = _ik_peak(tmp_path, 2.0, suffix)
    long, n_long = _ik_peak(tmp_path, 8.0, suffix)
    assert n_long > 3 * n_short
    assert long < 1.25 * short, (short, long)


def test_a_70hz_recording_runs_one_stream_over_the_model_grid(monkeypatch):
    # 10 s at 70 Hz on the 1 kHz member: one push per grid point (10,000), not one stream per
    # phase of the frames on the grid (100 streams of the whole trial, ~920,000 pushes).
    fine_time, fine = _markers(10.0)
    time = np.arange(0.0, 10.0, 1.0 / 70.0)
    markers = np.column_stack([np.interp(time, fine_time, c) for c in fine.T])
    pushes = 0
    push = pipeline._push

    def counted(*args):
        nonlocal pushes
        pushes += 1
        return push(*args)

    monkeypatch.setattr(pipeline, "_push", counted)
    run = pipeline.run_model("wrist-ik", markers, time)
    assert run.model_name == "wrist-ik" and run.at_recording_frames
    assert pushes <= 1000 * (time[-1] - time[0]) + 2, pushes
    assert "its family has no model at 70 Hz, only at 100, 250, 1000 Hz" in run.summary()


def test_grid_points_the_stream_refused_are_said_not_called_time_gaps(monkeypatch):
    # A 71 Hz recording with no time gap, MC2 and MC5 missing in every 5th frame: points of the
    # 1 kHz grid around those frames miss them and the stream refuses some; the window restarts after
    # them. The summary counts them by reason instead of reporting time gaps the file does not
    # have (real racing: 3 grid points, "MC2, MCB jumped", read as "1 window restarts after
    # time gaps").
    trial = ikid.simulate("random", seed=9507, duration=10.0)
    time, markers = trial.time[::14], trial.markers[::14].copy()
    assert np.ptp(np.diff(time)) < 1e-9  # evenly spaced: no time gap
    clean = pipeline.run_model("wrist-ik", markers, time)
    assert clean.gap_restarts == 0 and not clean.grid_refused
    markers[::5, 9:15] = np.nan  # MC2 and MC5: not fillable, from the motion before or after
    refusals = []
    push = pipeline._push

    def counted(stream, t, frame, window):
        got = push(stream, t, frame, window)
        on_frame = np.abs(time - t).min() < 1e-9
        if got[0] == "none" and got[1] != "window filling" and not on_frame:
            refusals.append(got[1])
        return got

    monkeypatch.setattr(pipeline, "_push", counted)
    run = pipeline.run_model("wrist-ik", markers, time)
    assert run.gap_restarts > 0 and refusals
    assert sum(run.grid_refused.values()) >= len(refusals)  # every refused point between frames
    assert set(run.grid_refused) == set(refusals) | set(run.refused)
    summary = run.summary()
    assert f"{sum(run.grid_refused.values())} points of the model's grid refused" in summary
    assert "after time gaps or refused grid points" in summary


def _angles(time: np.ndarray) -> np.ndarray:
    """Wrist-like angles (rad): slow sines within the range of motion, plus a little noise."""
    w = 2 * np.pi * np.array([0.7, 1.1, 0.4])
    noise = np.random.default_rng(SEED).normal(scale=2e-4, size=(len(time), 3))
    return np.array([0.4, 0.3, 0.15]) * np.sin(w * time[:, None] + np.array([0.0, 1.0, 2.0])) + noise


def test_a_mot_read_in_blocks_is_the_table_written(tmp_path):
    time = np.arange(1000) / 1000.0
    q = _angles(time)
    status = (np.arange(1000) % 7 == 0).astype(np.uint16)
    write_mot(tmp_path / "t.mot", time, q, status)
    for block_rows in (7, 1000, 5000):
        file = open_storage(tmp_path / "t.mot", block_rows=block_rows)
        blocks = list(file.blocks())
        assert max(len(b.time) for b in blocks) <= block_rows
        np.testing.assert_allclose(np.concatenate([b.time for b in blocks]), time, atol=1e-6)
        values = np.concatenate([b.values for b in blocks])
        np.testing.assert_allclose(values[:, :3], np.degrees(q), rtol=1e-9)  # written as %.10g
        np.testing.assert_array_equal(values[:, 3], status)
        got = list(mot_blocks(tmp_path / "t.mot", block_rows=block_rows))
        np.testing.assert_allclose(np.concatenate([a for _, a in got]), q, rtol=1e-9)
    # Windows' and classic Mac's line ends read as the whole-file reader always took them.
    text = (tmp_path / "t.mot").read_text()
    for name, end in (("crlf.mot", "\r\n"), ("cr.mot", "\r")):
        (tmp_path / name).write_bytes(text.replace("\n", end).encode())
        other = read_storage(tmp_path / name)
        np.testing.assert_array_equal(other.values, read_storage(tmp_path / "t.mot").values)
    # A bad row late in the file: the blocks before it are read, its own names its line.
    lines = (tmp_path / "t.mot").read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("0.900000"))
    lines[at] = lines[at].replace("\t", "\tx", 1)
    (tmp_path / "t.mot").write_text("\n".join(lines) + "\n")
    blocks = open_storage(tmp_path / "t.mot", block_rows=100).blocks()
    assert len(next(blocks).time) == 100
    with pytest.raises(ikid.InputError, match=rf"t\.mot:{at + 1}: not all numbers"):
        for _ in blocks:
            pass
    # A file cut short of its header's nRows is named when its blocks end.
    (tmp_path / "cut.mot").write_text("\n".join(lines[: at - 10]) + "\n")
    with pytest.raises(ikid.InputError, match=r"nRows=1000, the file has \d+ rows \(truncated\?\)"):
        list(open_storage(tmp_path / "cut.mot", block_rows=64).blocks())


def _scipy_states(time: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The oracle: SciPy's zero-lag 6 Hz Butterworth over the whole stretch, then differences."""
    b, a = butter(4, 6.0 / 500.0)
    angles = filtfilt(b, a, q, axis=0)
    rates = np.gradient(angles, time, axis=0)
    return np.concatenate([angles, rates, np.gradient(rates, time, axis=0)], axis=1)


@pytest.mark.parametrize("size", [1, 97, 2000, 65536])
def test_angles_filtered_in_blocks_are_scipys_over_each_whole_stretch(size):
    # 12 s at 1 kHz with two gaps (rows left out): a 10-row stretch, too short to filter, and
    # stretches longer than the filter's context (2.6 s), so they are given in pieces.
    time = np.arange(12000) / 1000.0
    keep = np.r_[0:5000, 5100:5110, 5200:12000]
    time, q = time[keep], _angles(time)[keep]
    blocks = [(time[k : k + size], q[k : k + size]) for k in range(0, len(time), size)]
    out = list(joint_state_blocks(blocks, 1000.0, 6.0))
    np.testing.assert_array_equal(np.concatenate([t for t, _ in out]), time)
    got = np.concatenate([s for _, s in out])
    assert np.isnan(got[5000:5010]).all() and 10 < min_stretch_rows(6.0)
    for part in (slice(0, 5000), slice(5010, None)):
        want = _scipy_states(time[part], q[part])
        # Within the rounding of the filter (a piece's edge effect, unchecked, is ~1e-3 of it),
        # amplified a thousandfold by each difference at 1 kHz.
        scale = np.abs(want).max(axis=0)
        off = np.abs(got[part] - want).max(axis=0) / scale
        assert np.all(off < 1e-8), off
    # Unfiltered: plain central differences on the sampling grid, the same in any blocks.
    raw = np.concatenate([s for _, s in joint_state_blocks(blocks, 1000.0, None)])
    np.testing.assert_allclose(raw[5010:, 3:6], np.gradient(q[5010:], 1e-3, axis=0), rtol=1e-12)


def test_id_in_blocks_writes_the_torques_of_the_whole_file(tmp_path, monkeypatch):
    monkeypatch.setattr(storage, "BLOCK_ROWS", 500)
    time = np.arange(6000) / 1000.0
    q = _angles(time)
    keep = np.r_[0:2500, 2600:6000]  # a gap: two stretches, each filtered alone
    write_mot(tmp_path / "t.mot", time[keep], q[keep])
    qw = read_storage(tmp_path / "t.mot").values[:, :3]  # the angles as written (degrees, 10 digits)
    qw = np.radians(qw)
    parts = [slice(0, 2500), slice(2500, None)]
    state = np.concatenate([_scipy_states(time[keep][p], qw[p]) for p in parts])
    # The exact reference: Newton-Euler on SciPy's joint states, row for row.
    assert cli(["id", str(tmp_path / "t.mot"), "-o", str(tmp_path / "ref.sto"), "--reference"]) == 0
    t, tau = read_sto(tmp_path / "ref.sto")
    np.testing.assert_allclose(t, time[keep], atol=1e-6)
    want = ikid.reference_id(state[:, :3], state[:, 3:6], state[:, 6:])
    np.testing.assert_allclose(tau, want, rtol=1e-6, atol=1e-6 * np.abs(want).max())
    # The network over its window, restarted at the gap.
    model = ikid.load("wrist-id")
    assert cli(["id", str(tmp_path / "t.mot"), "-o", str(tmp_path / "net.sto")]) == 0
    t, tau = read_sto(tmp_path / "net.sto")
    want = np.concatenate([model.predict(state[p]) for p in parts])
    assert len(t) == len(keep) - 2 * (model.window - 1)
    np.testing.assert_allclose(tau, want, rtol=1e-5, atol=1e-7)


def _id_peak(tmp_path, seconds: float) -> int:
    """`ikid id`'s tracemalloc peak on a 1 kHz .mot of ``seconds``, the output checked whole."""
    time = np.arange(int(seconds * 1000)) / 1000.0
    path = write_mot(tmp_path / f"a{seconds:g}.mot", time, _angles(time))
    out = tmp_path / f"a{seconds:g}.sto"
    ikid.load("wrist-id")  # loaded once before measuring (its tensors are not the file's)
    tracemalloc.start()
    try:
        assert cli(["id", str(path), "-o", str(out)]) == 0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(read_sto(out)[0]) == len(time) - ikid.load("wrist-id").window + 1
    return peak


def test_id_memory_does_not_grow_with_the_trials_length(tmp_path, monkeypatch):
    # Blocks of 500 rows and the filter's 2.6-s context: 10 s and 40 s are ~20 and ~80 blocks.
    # Read whole, 4x the rows was ~4x the memory; in blocks it is a block's and the context's.
    monkeypatch.setattr(storage, "BLOCK_ROWS", 500)
    short = _id_peak(tmp_path, 10.0)
    long = _id_peak(tmp_path, 40.0)
    assert long < 1.25 * short, (short, long)


def test_resampled_in_blocks_each_stretch_alone_nothing_inside_a_gap():
    # 100 Hz angles, quadratic in time, with gaps: stretches 0-1.49 s, 2.01-2.47 s, 2.50-2.51 s
    # (two rows: too short to resample) and 2.54-3.99 s. Cubic Hermite with second-order slopes
    # is exact for a quadratic away from a stretch's end intervals.
    rows = np.arange(400)
    keep = ((rows < 150) | (rows > 200)) & ~np.isin(rows, [248, 249, 252, 253])
    time = rows[keep] / 100.0
    coef = np.array([[0.1, -0.3, 0.2], [0.4, 0.1, -0.2], [-0.05, 0.02, 0.03]])
    q = coef[0] + time[:, None] * coef[1] + time[:, None] ** 2 * coef[2]
    stretches = ((0.0, 1.49), (2.01, 2.47), (2.54, 3.99))
    for size in (1, 3, 64, 1000):
        blocks = [(time[k : k + size], q[k : k + size]) for k in range(0, len(time), size)]
        out = list(resample_stretches(blocks, 100.0, 1000.0))
        t = np.concatenate([a for a, _ in out])
        v = np.concatenate([b for _, b in out])
        assert np.all(np.diff(t) > 0)
        short = np.isnan(v).any(axis=1)
        np.testing.assert_allclose(t[short], [2.5, 2.51])  # the 2-row stretch, at its own times
        inside = np.zeros(len(t), bool)
        for lo, hi in stretches:  # each stretch on its own 1 kHz grid, and nothing between them
            mine = (t >= lo - 1e-9) & (t <= hi + 1e-9)
            np.testing.assert_allclose(t[mine], lo + np.arange(mine.sum()) / 1000.0, atol=1e-9)
            assert mine.sum() == round((hi - lo) * 1000) + 1
            inside |= mine
        assert np.all(inside | short)
        inner = np.zeros(len(t), bool)
        for lo, hi in stretches:
            inner |= (t > lo + 0.01 + 1e-9) & (t < hi - 0.01 - 1e-9)
        want = coef[0] + t[inner, None] * coef[1] + t[inner, None] ** 2 * coef[2]
        np.testing.assert_allclose(v[inner], want, atol=1e-12)


def test_id_resample_writes_no_torque_inside_a_time_gap(tmp_path, capsys):
    time = np.arange(0.0, 4.0, 0.01)
    keep = (time < 1.5) | (time > 2.0)
    write_mot(tmp_path / "gap.mot", time[keep], _angles(time)[keep])
    assert cli(["id", str(tmp_path / "gap.mot"), "-o", str(tmp_path / "gap.sto"), "--resample"]) == 0
    assert "angles resampled 100 -> 1000 Hz" in capsys.readouterr().out
    t, tau = read_sto(tmp_path / "gap.sto")
    assert not np.any((t > 1.49 + 1e-9) & (t < 2.01 - 1e-9))  # was 499 rows made up in the gap
    assert np.isfinite(tau).all() and t[-1] > 3.98


def test_a_run_resampled_to_the_model_makes_no_frame_inside_a_time_gap():
    # 100 Hz markers with 0.4 s of rows left out, run on the 1 kHz member with --resample
    # (resample_to_model): each stretch resampled alone (before, the whole recording was, and
    # the gap was filled with interpolated frames, each given an output).
    time, markers = _markers(3.0, every=10)
    keep = (time < 1.0) | (time > 1.4)
    time, markers = time[keep], markers[keep]
    model = ikid.load("wrist-ik")  # the 1 kHz model itself, not its family (which has a 100 Hz member)
    whole = pipeline.run_model(model, markers, time, rate_hz=100.0, resample_to_model=True)
    assert whole.resampled_from_hz == 100.0 and whole.rate_hz == 1000.0
    assert not np.any((whole.time > time[time < 1.0][-1] + 1e-9) & (whole.time < time[time > 1.4][0] - 1e-9))
    assert whole.n_outputs > 0.9 * 1000 * (time[-1] - time[0] - 0.4)
    for size in (7, 128):
        blocks = ((time[k : k + size], markers[k : k + size]) for k in range(0, len(time), size))
        got = pipeline.run_blocks(model, blocks, rate_hz=100.0, resample_to_model=True)
        np.testing.assert_array_equal(got.time, whole.time)
        np.testing.assert_allclose(got.values, whole.values, atol=1e-9)


def test_a_marker_csv_read_in_blocks_is_the_table_written(tmp_path):
    time, markers = _markers(1.0)
    markers = _with_gaps(markers)
    write_csv_markers(tmp_path / "t.csv", time, markers, units="mm")
    for block_frames in (2, 7, 1000, 5000):
        file = open_csv_markers(tmp_path / "t.csv", block_frames=block_frames)
        assert file.n_frames == len(time) and file.rate_hz == pytest.approx(1000.0, rel=1e-6)
        blocks = list(file.blocks())
        assert max(len(b) for b in blocks) <= block_frames
        np.testing.assert_allclose(np.concatenate([b.time for b in blocks]), time, atol=1e-6)
        got = np.concatenate([b.positions for b in blocks]).reshape(len(time), -1)
        np.testing.assert_allclose(got, markers, rtol=1e-9, atol=1e-12)  # NaN where missing, too
    # Late faults are named when their block is read: a bad cell, then a step off the rate.
    lines = (tmp_path / "t.csv").read_text().splitlines()
    bad = list(lines)
    bad[902] = bad[902].replace(",", ",x", 1)
    (tmp_path / "bad.csv").write_text("\n".join(bad) + "\n")
    blocks = open_csv_markers(tmp_path / "bad.csv", block_frames=100).blocks()
    assert len(next(blocks).time) == 100
    with pytest.raises(ikid.InputError, match=r"bad\.csv:903: 'x.*' is not a number"):
        for _ in blocks:
            pass
    del lines[700]  # one frame gone: a 2 ms step in a 1 ms recording
    (tmp_path / "step.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(ikid.InputError, match=r"step\.csv: frames are not evenly spaced"):
        list(open_csv_markers(tmp_path / "step.csv", block_frames=100).blocks())


@pytest.mark.parametrize("cut_off", [0.5, 490.0, 499.9])
def test_cut_offs_near_0_and_half_the_rate_filter_in_blocks_as_whole(cut_off):
    # Second-order sections (a transfer function's coefficients lose their digits there, and
    # the context computed from their roots came out negative: a traceback at 499.99 Hz).
    time = np.arange(150_000) / 1000.0
    q = _angles(time)
    sos = butter(4, cut_off / 500.0, output="sos")
    angles = sosfiltfilt(sos, q, axis=0, padlen=15)
    rates = np.gradient(angles, time, axis=0)
    want = np.concatenate([angles, rates, np.gradient(rates, time, axis=0)], axis=1)
    blocks = [(time[k : k + 65536], q[k : k + 65536]) for k in range(0, len(time), 65536)]
    got = np.concatenate([s for _, s in joint_state_blocks(blocks, 1000.0, cut_off)])
    off = np.abs(got - want).max(axis=0) / np.abs(want).max(axis=0)
    assert np.all(off < 1e-8), off


def test_id_refuses_what_it_cannot_read_whole_and_names_where(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(storage, "BLOCK_ROWS", 500)
    # A file that changes rate part-way: refused (it was read as 1,500 one-row stretches).
    time = np.concatenate([np.arange(2000) / 1000.0, 2.0 + np.arange(1, 1501) / 500.0])
    write_mot(tmp_path / "two-rates.mot", time, _angles(time))
    assert cli(["id", str(tmp_path / "two-rates.mot"), "-o", str(tmp_path / "x.sto"), "--reference"]) == 2
    assert "at 500 Hz, the first rows at 1000 Hz" in capsys.readouterr().err
    # A byte that is not UTF-8 late in the file: named with its line.
    time = np.arange(3000) / 1000.0
    path = write_mot(tmp_path / "bad-byte.mot", time, _angles(time))
    lines = path.read_bytes().split(b"\n")
    lines[2800] += b" \xff"
    path.write_bytes(b"\n".join(lines))
    assert cli(["id", str(path), "-o", str(tmp_path / "x.sto")]) == 2
    assert "bad-byte.mot:2801: not a text file" in capsys.readouterr().err
    # --resample means the network's rate: with --reference it is refused, not ignored.
    assert (
        cli(
            [
                "id",
                str(tmp_path / "two-rates.mot"),
                "-o",
                str(tmp_path / "x.sto"),
                "--reference",
                "--resample",
            ]
        )
        == 2
    )
    assert "leave out --resample" in capsys.readouterr().err
    assert not (tmp_path / "x.sto").exists()


@pytest.mark.parametrize("every", [10, 8])  # 100 Hz (its own member), 125 Hz (the 1 kHz grid)
def test_two_takes_joined_with_a_time_jump_restart_the_window_instead_of_refusing_a_clock(every):
    # Review 3: a file of two takes joined (its time jumping 4 s) had the frames after the jump
    # refused as "a glitch of the source's clock", as a live stream's would be. A file's stamps
    # are its own: the window restarts after the gap. The oracle: the second take run alone.
    takes = [ikid.simulate("random", seed=s, duration=2.0, output_every=every) for s in (61, 62)]
    second_time = takes[1].time + takes[0].time[-1] + 4.0
    frames = np.concatenate([takes[0].markers, takes[1].markers])
    time = np.concatenate([takes[0].time, second_time])
    joined = pipeline.run_model("wrist-ik", frames, time)
    alone = pipeline.run_model("wrist-ik", takes[1].markers, second_time)
    assert joined.refused.total() == 0 and joined.gap_restarts == 1, joined.summary()
    n0 = len(takes[0].time)
    later = joined.frame >= n0
    np.testing.assert_array_equal(joined.frame[later] - n0, alone.frame)
    np.testing.assert_allclose(joined.values[later], alone.values, atol=1e-6)


def test_a_time_that_is_not_a_number_is_named_by_its_row_not_read_as_a_rate():
    # Review 3: one NaN in the time array read as "rate_hz: NaN: expected a rate in Hz greater
    # than 0", an argument the user never gave.
    trial = ikid.simulate("random", seed=63, duration=0.5)
    time = trial.time.copy()
    time[100] = np.nan
    with pytest.raises(ikid.InputError, match=r"time: row 100 is nan \(1 rows not finite\)"):
        pipeline.run_model("wrist-ik", trial.markers, time)
