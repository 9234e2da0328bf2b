"""Files of any length in bounded memory (issue #31, item 4): a TRC read in blocks is the file
read whole, a run fed in blocks gives the rows a run over the whole arrays gives, `ikid ik`
writes them a block at a time, and its memory does not grow with the trial's length.

Expected rows come from the whole-file path (read_trc, run_model over the arrays), which
these tests compare the block path against, never from the block path itself.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import ikid
from ikid import pipeline
from ikid.cli import process
from ikid.io import open_trc, read_storage, read_trc, trc, write_trc

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


def _ik_peak(tmp_path, seconds: float) -> tuple[int, int]:
    """`ikid ik`'s work on a 1 kHz TRC of ``seconds`` in this process: (tracemalloc peak bytes,
    frames)."""
    time, markers = _markers(seconds)
    path = tmp_path / f"t{seconds:g}.trc"
    write_trc(path, time, markers, 1000.0)
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


def test_ik_memory_does_not_grow_with_the_trials_length(tmp_path, monkeypatch):
    # Blocks of 500 frames: 2 s and 8 s are ~5 and ~17 blocks. Read whole, 4x the frames was
    # ~4x the memory (the frames, the rows and the text); in blocks it is one block's.
    monkeypatch.setattr(trc, "BLOCK_FRAMES", 500)
    short, n_short = _ik_peak(tmp_path, 2.0)
    long, n_long = _ik_peak(tmp_path, 8.0)
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
