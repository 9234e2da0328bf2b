"""Property tests (hypothesis) of the Python surface: random, truncated and corrupted model
files, frames of any shape, dtype and value, missing and jumping markers — always a result or
an ``ikid`` error (``InputError``/``ModelFileError``, both ``IkidError``), never a crash, a
hang, another exception type or a non-finite output. Case counts are hypothesis' (the note of
issue 7 quotes them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import make_model
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import ikid

CASES = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
MODEL = make_model("angles", window=3, hidden=(8,))
VALID = MODEL.to_bytes()
TRIAL = ikid.simulate(seed=31, duration=3.0).markers.astype(np.float32)

floats = st.one_of(
    st.floats(-1.0, 1.0, width=32),
    st.sampled_from([np.nan, np.inf, -np.inf, 0.0, 1e30, -1e30]),
    st.floats(width=32),
)


def finite_or_ikid_error(call):
    try:
        out = call()
    except ikid.IkidError:
        return None
    if out is not None:
        assert np.all(np.isfinite(out))
    return out


@CASES
@given(st.binary(max_size=4096))
def test_loader_on_random_bytes(data):
    finite_or_ikid_error(lambda: ikid.Model.from_bytes(data).predict(TRIAL[:10]))


@CASES
@given(st.lists(st.tuples(st.integers(0, len(VALID) - 1), st.integers(0, 255)), min_size=1, max_size=8),
       st.integers(0, len(VALID)))
def test_loader_on_corrupted_files(flips, cut):
    data = bytearray(VALID)
    for at, value in flips:
        data[at] = value
    finite_or_ikid_error(lambda: ikid.Model.from_bytes(bytes(data[:cut])).predict(TRIAL[:10]))


@CASES
@given(hnp.arrays(st.sampled_from([np.float32, np.float64]), hnp.array_shapes(min_dims=1, max_dims=3, max_side=30), elements=floats),
       st.sampled_from(["refuse", "fill"]))
def test_stream_and_predict_on_any_array(frames, policy):
    stream = MODEL.stream(missing_markers=policy)
    if frames.ndim == 1:
        finite_or_ikid_error(lambda: stream.push(frames))
    elif frames.ndim == 2:
        finite_or_ikid_error(lambda: stream.push_many(frames))
        finite_or_ikid_error(lambda: MODEL.predict(frames))
        finite_or_ikid_error(lambda: ikid.fill_gaps(frames, unfillable="keep")[0][np.isfinite(frames).all(axis=1)] if frames.shape[1] == 18 else None)
    else:
        with pytest.raises(ikid.InputError):
            stream.push_many(frames)


@CASES
@given(st.lists(st.tuples(st.integers(1000, len(TRIAL) - 1), st.integers(0, 5), st.sampled_from(["nan", "jump", "swap"])), max_size=20))
def test_fill_stream_on_a_real_trial_with_random_damage(damage):
    # Missing markers, jumps and label swaps anywhere after the first second: each frame
    # gives a finite output (filled and flagged) or an ikid error, and a refused frame never
    # changes what the next frames give compared with a stream that never saw it.
    frames = TRIAL.copy()
    for f, m, kind in damage:
        if kind == "nan":
            frames[f, 3 * m : 3 * m + 3] = np.nan
        elif kind == "jump":
            frames[f, 3 * m + 1] += 0.03
        else:
            other = 3 * ((m + 1) % 3 + 3 * (m // 3))
            frames[f, [3 * m, 3 * m + 1, 3 * m + 2, other, other + 1, other + 2]] = frames[f, [other, other + 1, other + 2, 3 * m, 3 * m + 1, 3 * m + 2]]
    stream = MODEL.stream(missing_markers="fill")
    for frame in frames:
        finite_or_ikid_error(lambda: stream.push(frame))


# --- file readers (TRC, MOT/STO, marker maps; C3D is in test_io.py: each case is a process) ---

READER_CASES = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
_SIM = ikid.simulate(seed=32, duration=0.05)
_MARKERS = _SIM.markers.copy()
_MARKERS[10:20, 3:6] = np.nan


def _valid_files(tmp: Path) -> dict[str, bytes]:
    from ikid import io

    return {
        ".trc": io.write_trc(tmp / "v.trc", _SIM.time, _MARKERS, _SIM.rate_hz).read_bytes(),
        ".csv": io.write_csv_markers(tmp / "v.csv", _SIM.time, _MARKERS, units="mm").read_bytes(),
        ".mot": io.write_mot(tmp / "v.mot", _SIM.time, _SIM.q).read_bytes(),
        ".sto": io.write_sto(tmp / "v.sto", _SIM.time, _SIM.tau).read_bytes(),
        ".toml": ("[markers]\n" + "\n".join(f'{m} = "L{m}"' for m in ikid.marker_names()) + "\n").encode(),
    }


def _read(path: Path):
    from ikid import io

    if path.suffix in (".trc", ".csv"):
        data = io.read_markers(path)
        assert data.positions.shape == (len(data.time), len(data.labels), 3) and np.all(np.diff(data.time) > 0)
        return data.frames() if data.labels == tuple(ikid.marker_names()) else None
    if path.suffix == ".toml":
        return io.MarkerMap.load(path)
    table = io.read_storage(path)
    assert np.all(np.isfinite(table.values)) and np.all(np.diff(table.time) > 0)
    return io.read_mot(path) if path.suffix == ".mot" else io.read_sto(path)


@pytest.fixture(scope="module")
def valid_files(tmp_path_factory):
    return _valid_files(tmp_path_factory.mktemp("valid"))


@READER_CASES
@given(st.sampled_from([".trc", ".csv", ".mot", ".sto", ".toml"]), st.lists(st.tuples(st.floats(0, 1), st.integers(0, 255)), max_size=8),
       st.floats(0, 1), st.binary(max_size=64))
def test_file_readers_on_corrupted_truncated_and_random_files(valid_files, tmp_path, kind, flips, keep, junk):
    data = bytearray(valid_files[kind])
    for at, value in flips:
        data[int(at * (len(data) - 1))] = value
    data = bytes(data[: int(keep * len(data))]) + (junk if keep < 0.5 else b"")
    path = tmp_path / f"case{kind}"
    path.write_bytes(data)
    try:
        _read(path)
    except ikid.IkidError as e:
        assert str(e)  # names the file and what is wrong
