"""Property tests (hypothesis) of the Python surface: random, truncated and corrupted model
files, frames of any shape, dtype and value, missing and jumping markers — always a result or
an ``ikid`` error (``InputError``/``ModelFileError``, both ``IkidError``), never a crash, a
hang, another exception type or a non-finite output. Case counts are hypothesis' (the note of
issue 7 quotes them)."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import ikid
from conftest import make_model

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
@given(
    st.lists(st.tuples(st.integers(0, len(VALID) - 1), st.integers(0, 255)), min_size=1, max_size=8),
    st.integers(0, len(VALID)),
)
def test_loader_on_corrupted_files(flips, cut):
    data = bytearray(VALID)
    for at, value in flips:
        data[at] = value
    finite_or_ikid_error(lambda: ikid.Model.from_bytes(bytes(data[:cut])).predict(TRIAL[:10]))


@CASES
@given(
    hnp.arrays(
        st.sampled_from([np.float32, np.float64]),
        hnp.array_shapes(min_dims=1, max_dims=3, max_side=30),
        elements=floats,
    ),
    st.sampled_from(["refuse", "fill"]),
)
def test_stream_and_predict_on_any_array(frames, policy):
    stream = MODEL.stream(missing_markers=policy)
    if frames.ndim == 1:
        finite_or_ikid_error(lambda: stream.push(frames))
    elif frames.ndim == 2:
        finite_or_ikid_error(lambda: stream.push_many(frames))
        finite_or_ikid_error(lambda: MODEL.predict(frames))
        finite_or_ikid_error(
            lambda: (
                ikid.fill_gaps(frames, unfillable="keep")[0][np.isfinite(frames).all(axis=1)]
                if frames.shape[1] == 18
                else None
            )
        )
    else:
        with pytest.raises(ikid.InputError):
            stream.push_many(frames)


# --- a refused frame leaves the stream as it was ---------------------------------------------------
#
# Stream (stream.rs): "A frame that is refused (wrong length, NaN, degenerate markers) leaves the
# window exactly as it was", and the gap filler "refuses before changing anything". Checked by a
# stream that never saw the refused frames: every later frame gives the same bits, the same
# filled-marker flags and the same refusal (error and message).

PRE = 1700  # clean frames first: the gap filler can fill from frame 1589 of this trial on
SHORT = TRIAL[:2200]


def damage(frame: np.ndarray, kind: str, m: int = 4) -> np.ndarray:
    """`frame` with marker `m` (0-5) damaged: missing, jumped, swapped, ... or the frame cut."""
    f = frame.copy()
    if len(f) != 18:  # already cut or lengthened: wrong length stays the damage
        return f
    xyz = slice(3 * m, 3 * m + 3)
    other = 3 * ((m + 1) % 3 + 3 * (m // 3))  # another marker of the same segment
    if kind == "nan":
        f[xyz] = np.nan
    elif kind == "inf":
        f[3 * m] = np.inf
    elif kind == "nan2":  # one marker of each segment: more than the filler fills
        f[xyz] = np.nan
        f[3 * ((m + 3) % 6) : 3 * ((m + 3) % 6) + 3] = np.nan
    elif kind == "jump":
        f[3 * m + 1] += 0.03
    elif kind == "jump2":  # a jump in each segment
        f[3 * m + 1] += 0.03
        f[3 * ((m + 3) % 6) + 2] -= 0.03
    elif kind == "swap":
        f[[3 * m, 3 * m + 1, 3 * m + 2, other, other + 1, other + 2]] = f[
            [other, other + 1, other + 2, 3 * m, 3 * m + 1, 3 * m + 2]
        ]
    elif kind == "collapse":  # the segment's markers on one point
        first = 9 * (m // 3)
        f[first : first + 9] = np.tile(f[first : first + 3], 3)
    elif kind == "huge":
        f[:] = 1e30
    elif kind == "short":
        f = f[:17]
    elif kind == "long":
        f = np.append(f, f[0])
    else:
        raise ValueError(kind)
    return f


def outcome(stream, frame, time=None):
    """What a push gives: ("out", output bytes or None, filled-marker flags, gap restarts) or
    ("error", type, message). An output is finite."""
    try:
        out = stream.push(frame, time)
    except ikid.IkidError as e:
        # Errors number a frame among all the frames pushed, refused ones included: that number
        # differs by design between the two streams, the rest of the message may not.
        return ("error", type(e).__name__, re.sub(r"\bframe \d+", "frame #", str(e)))
    assert out is None or np.all(np.isfinite(out))
    return (
        "out",
        None if out is None else (out.dtype.str, out.tobytes()),
        tuple(stream.filled_markers),
        stream.gap_restarts,
        stream.reanchors,
    )


def refused(result) -> bool:
    # A non-finite prediction is an error too, but that frame stays in the window (documented).
    return result[0] == "error" and "prediction is not finite" not in result[2]


def refusals_change_nothing(frames, policy, times=None) -> list[int]:
    """Pushes `frames` (a list: some may have the wrong length) through one stream; for each
    frame k it refuses, a second stream given the frames before k that the first accepted then
    takes the frames after k up to the next refused one: each must give exactly what it gave
    the first stream (so the next refused frame is refused alike). Returns the refused frames."""
    times = [None] * len(frames) if times is None else times
    seen = MODEL.stream(missing_markers=policy)
    results = [outcome(seen, f, t) for f, t in zip(frames, times, strict=True)]
    gone = [i for i, r in enumerate(results) if refused(r)]
    reanchors = 0  # the stream's count after the last accepted frame
    reanchored_after = set()  # refused frames whose run ended in a re-anchor
    for i, r in enumerate(results):
        if refused(r):
            continue
        if r[4] > reanchors:
            # By design the one exception: REANCHOR_FRAMES (3) frames in a row refused only for
            # moving too far, agreeing with each other, are a new place (a stall without time
            # stamps): the third is taken. The refusals of that run do count; nothing else may.
            run = list(itertools.takewhile(lambda j: j in gone, range(i - 1, -1, -1)))
            assert len(run) >= 2, f"frame {i} re-anchored after {len(run)} refused frames"
            reanchored_after.update(run)
            reanchors = r[4]
    for k, end in itertools.pairwise([*gone, len(frames) - 1]):
        if k in reanchored_after:
            continue
        never = MODEL.stream(missing_markers=policy)
        # The frames the first stream accepted, and the runs of refusals that re-anchored it
        # (they count: the second stream is refused them alike, and re-anchors alike).
        prefix = [i for i in range(k) if i not in gone or i in reanchored_after]
        if times[0] is None and not reanchored_after.intersection(prefix):
            never.push_many(np.asarray([frames[i] for i in prefix]))  # = one by one (stream.rs)
        else:
            for i in prefix:
                if i in reanchored_after:
                    assert outcome(never, frames[i], times[i]) == results[i], f"{policy}: run frame {i}"
                else:
                    never.push(frames[i], times[i])
        for i in range(k + 1, end + 1):
            assert outcome(never, frames[i], times[i]) == results[i], (
                f"{policy}: frame {i} differs after refused frame {k} ({results[k][2]})"
            )
    return gone


@CASES
@given(
    st.lists(
        st.tuples(
            st.integers(PRE, len(SHORT) - 1),
            st.integers(0, 5),
            st.sampled_from(
                ["nan", "inf", "nan2", "jump", "jump2", "swap", "collapse", "huge", "short", "long"]
            ),
        ),
        max_size=12,
    ),
    st.sampled_from(["refuse", "fill"]),
)
def test_a_refused_frame_never_changes_what_the_next_frames_give(damages, policy):
    # Missing markers, jumps, label swaps, collapsed segments and frames of the wrong length
    # after the first second: each frame gives a finite output (filled and flagged) or an ikid
    # error, and a refused frame never changes what the next frames give compared with a
    # stream that never saw it.
    frames = list(SHORT)
    for f, m, kind in damages:
        frames[f] = damage(frames[f], kind, m)
    refusals_change_nothing(frames, policy)


# Per policy, garbage each stream must refuse (under "fill" one missing or jumped marker is
# filled, not refused), followed by frames whose outcome rests on what the gap filler learned:
# a missing marker and a jump (filled, or refused).
REFUSED = {
    "refuse": ["nan", "inf", "nan2", "jump", "jump2", "swap", "collapse", "huge", "short", "long"],
    "fill": ["nan2", "jump2", "huge", "short", "long"],
}


@pytest.mark.parametrize(("policy", "kind"), [(p, k) for p, kinds in REFUSED.items() for k in kinds])
def test_each_kind_of_refused_frame_leaves_the_stream_as_it_was(policy, kind):
    frames = list(SHORT)
    garbage = [PRE + 7, PRE + 8, PRE + 60, PRE + 300]  # twice in a row, then alone
    for k in garbage:
        frames[k] = damage(frames[k], kind, m=k % 6)
    frames[PRE + 9] = damage(frames[PRE + 9], "nan", 5)  # the frame after: MCB missing
    frames[PRE + 20] = damage(frames[PRE + 20], "nan", 2)  # FAP missing
    frames[PRE + 61] = damage(frames[PRE + 61], "jump", 4)  # MC5 jumps
    gone = refusals_change_nothing(frames, policy)
    assert set(garbage) <= set(gone), gone
    assert (PRE + 9 in gone) == (policy == "refuse")  # filled under "fill"


def test_a_refused_time_stamped_frame_leaves_the_stream_as_it_was():
    frames = list(SHORT)
    times = [i / 1000.0 for i in range(len(frames))]
    frames[PRE + 5] = damage(frames[PRE + 5], "nan", 1)
    times[PRE + 30] = times[PRE + 29]  # time that does not increase
    times[PRE + 50] = times[PRE + 49] + 0.0002  # 0.2 ms after the previous frame
    frames[PRE + 70] = damage(frames[PRE + 70], "short")
    times[PRE + 100 :] = [t + 0.01 for t in times[PRE + 100 :]]  # a 10 ms gap, then a refused frame
    frames[PRE + 100] = damage(frames[PRE + 100], "nan2", 0)
    assert refusals_change_nothing(frames, "refuse", times) == [PRE + k for k in (5, 30, 50, 70, 100)]


@pytest.mark.parametrize("policy", ["refuse", "fill"])
def test_a_refused_frame_stamped_ahead_of_the_clock_leaves_the_stream_as_it_was(policy):
    # A garbled packet between two frames: its time 10 ms ahead and its markers garbage; the
    # next frame is back on the 1 ms clock, one period after the last accepted frame.
    frames = list(SHORT)
    times = [i / 1000.0 for i in range(len(frames))]
    frames.insert(PRE + 5, damage(frames[PRE + 5], "short"))
    times.insert(PRE + 5, times[PRE + 5] + 0.01)
    assert refusals_change_nothing(frames, policy, times) == [PRE + 5]


# --- file readers (TRC, MOT/STO, marker maps; C3D is in test_io.py: each case is a process) ---

READER_CASES = settings(
    max_examples=300,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
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
        assert data.positions.shape == (len(data.time), len(data.labels), 3) and np.all(
            np.diff(data.time) > 0
        )
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
@given(
    st.sampled_from([".trc", ".csv", ".mot", ".sto", ".toml"]),
    st.lists(st.tuples(st.floats(0, 1), st.integers(0, 255)), max_size=8),
    st.floats(0, 1),
    st.binary(max_size=64),
)
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
