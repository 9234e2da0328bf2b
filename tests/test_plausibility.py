"""Plausibility from the Python side: checksums refuse corrupt weights, the training envelope
flags frames outside it, the frame status bits are the C header's, wrong units are named."""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np
import pytest

import ikid
from ikid import _native
from ikid.sim import simulate

ROOT = Path(__file__).resolve().parents[1]


def _data_start(raw: bytes) -> int:
    return 8 + struct.unpack("<Q", raw[:8])[0]


@pytest.mark.parametrize("name", ["wrist-ik", "wrist-id", "wrist-chain", "wrist-track"])
def test_a_flipped_sign_bit_in_a_shipped_model_is_refused(tmp_path, name):
    # Issue #22 case 8: one flipped sign bit used to load and move the angles by 3.3°.
    src = Path(ikid.__file__).with_name("models") / f"{name}.safetensors"
    assert ikid.load(name).has_checksum
    raw = bytearray(src.read_bytes())
    start = _data_start(bytes(raw))
    rng = np.random.default_rng(0)
    for at in rng.integers(start, len(raw), size=5):
        bad = bytearray(raw)
        bad[(int(at) - start) // 4 * 4 + start + 3] ^= 0x80  # the sign bit of one f32
        path = tmp_path / f"bad{at}.safetensors"
        path.write_bytes(bytes(bad))
        with pytest.raises(ikid.ModelFileError) as e:
            ikid.load(path)
        assert e.value.code == "checksum_mismatch" and "corrupt" in str(e.value) and str(path) in str(e.value)


def test_frame_status_bits_are_the_c_headers():
    header = (ROOT / "include" / "ikid.h").read_text(encoding="utf-8")
    defined = {m[0].lower(): int(m[1]) for m in re.findall(r"#define IKID_FRAME_(\w+) (\d+)", header)}
    assert defined == dict(_native.FRAME_STATUS) and len(defined) == 10


def _markers(seed: int) -> np.ndarray:
    t = simulate(seed=seed, duration=2)
    return np.asarray(t.markers, np.float64).reshape(len(t.time), -1)


def _statuses(model, frames) -> np.ndarray:
    stream, bits = model.stream(), []
    for f in frames:
        if stream.push(f) is not None:
            bits.append(stream.status)
    return np.array(bits)


def test_simulated_trials_are_inside_the_shipped_envelopes_and_shrunk_wrists_are_not():
    frames = _markers(21)
    ik = ikid.load("wrist-ik")
    assert ik.card["envelope"]["inputs"]["min"][0] < 0 < ik.card["envelope"]["inputs"]["max"][0]
    assert not _statuses(ik, frames).any()
    # The same markers with the hand turned 120° about the forearm: angles no training trial had.
    q = np.radians([[0.0, 110.0, 60.0]] * 60)
    outside = _native.forward_markers(q)
    bits = _statuses(ik, outside)
    assert (bits & ikid.FRAME_STATUS["outside_training"]).all(), bits


def test_model_frame_status_agrees_with_the_stream():
    ik = ikid.load("wrist-ik")
    frames = _markers(22)[:200]
    feats = ikid.compute_features(frames, "angles")
    out = ik.predict(frames)
    w = ik.window
    assert np.array_equal(ik.frame_status(feats[w - 1 :], out), _statuses(ik, frames))


@pytest.mark.parametrize("scale, cause", [(10.0, "are the units mm"), (1e-3, "read as mm")])
def test_markers_in_the_wrong_units_are_named(scale, cause):
    frames = _markers(23) * scale
    with pytest.raises(ikid.InputError, match=cause):
        _native.check_marker_units(frames)
    _native.check_marker_units(frames / scale)  # the right units pass
    with pytest.raises(ikid.InputError, match=cause):
        ikid.Tracker(rate_hz=1000.0).run(frames)
    stream = ikid.load("wrist-ik").stream()
    with pytest.raises(ikid.InputError) as e:
        stream.push(frames[0])
    assert e.value.code == "implausible_markers"


def test_the_c_stream_reports_the_same_status_and_takes_a_left_arm_calibration():
    import ctypes as C

    from faults.capi import f32p, f64p, last_error, lib

    path = Path(ikid.__file__).with_name("models") / "wrist-ik.safetensors"
    model = C.c_void_p()
    assert lib().ikid_model_load(str(path).encode(), C.byref(model)) == 0, last_error()
    try:
        # A wrist turning from neutral to postures beyond the training range over 0.4 s.
        q = np.radians(np.linspace([0.0, 0.0, 0.0], [0.0, 110.0, 60.0], 400))
        mirror = np.tile([1.0, 1.0, -1.0], 6)
        frames = (_native.forward_markers(q) * mirror).astype(np.float32)  # a left arm
        neutral = _native.forward_markers(np.zeros((10, 3))) * mirror
        measured = ikid.Calibration.from_neutral(neutral, side="left")
        calibration = ikid.Calibration.from_matrices(measured.forearm, measured.hand, side="left")
        py = ikid.load("wrist-ik").stream(calibration=calibration)
        stream = C.c_void_p()
        assert lib().ikid_stream_new(model, C.byref(stream)) == 0
        forearm = np.ascontiguousarray(measured.forearm)
        hand = np.ascontiguousarray(measured.hand)
        status = lib().ikid_stream_set_calibration_side(
            stream, forearm.ctypes.data_as(f64p), hand.ctypes.data_as(f64p), b"left"
        )
        assert status == 0, last_error()
        seen = set()
        for f in frames:
            want = py.push(f)
            out = np.zeros(3, np.float32)
            ready = C.c_bool(False)
            frame = np.ascontiguousarray(f)
            pushed = lib().ikid_stream_push(
                stream, frame.ctypes.data_as(f32p), 18, out.ctypes.data_as(f32p), 3, C.byref(ready)
            )
            assert pushed == 0, last_error()
            assert ready.value == (want is not None)
            if want is not None:
                bits = C.c_uint32(99)
                assert lib().ikid_stream_status(stream, C.byref(bits)) == 0
                assert bits.value == py.status and out.tobytes() == want.tobytes()
                seen.add(bits.value & ikid.FRAME_STATUS["outside_training"])
        assert seen == {0, ikid.FRAME_STATUS["outside_training"]}  # both kinds of frame were there
        assert lib().ikid_stream_status(stream, None) != 0 and "status" in last_error()
        lib().ikid_stream_free(stream)
    finally:
        lib().ikid_model_free(model)


def test_a_wrist_moving_faster_than_its_training_reads_its_per_frame_angles():
    """The shipped IK models know how fast their training data moved (the card's
    ``window_change``: all but the fastest 0.1 % of the training windows): a sweep faster than
    that (pronation through 120° in 60 ms, as wheelchair racing does) gets each frame's own
    angles, flagged ``per_frame``, instead of a correction the network never learned; held-out
    trials at training speeds are corrected throughout."""
    from ikid.pipeline import run_model

    for name in ("wrist-ik", "wrist-ik-100hz", "wrist-ik-250hz"):
        assert len(ikid.load(name).card["envelope"]["window_change"]) == 3
    n = 400
    q = np.zeros((n, 3))
    q[:, 1] = 0.3
    ramp = np.clip((np.arange(n) - 200) / 60.0, 0.0, 1.0)
    q[:, 0] = np.radians(-60.0 + 120.0 * (3 * ramp**2 - 2 * ramp**3))  # smooth, 60 ms
    markers = ikid.forward_markers(q, 0.0)
    run = run_model("wrist-ik", markers, np.arange(n) / 1000.0)
    model = ikid.load("wrist-ik")
    window, half = model.window, model.window // 2
    per_frame = run.status & ikid.FRAME_STATUS["per_frame"] != 0
    # The oracle: the true angles' change from each window's older half to its newer half
    # against the card's limit (10 % margin, RELIABILITY.md), frame by frame.
    limit = 1.1 * np.array(model.card["envelope"]["window_change"])
    change = np.zeros((n, 3))
    for i in range(window - 1, n):
        w = q[i - window + 1 : i + 1]
        change[i] = np.abs(w[-half:].mean(axis=0) - w[:half].mean(axis=0))
    excess = (change - limit).max(axis=1)
    expected = excess > 0
    assert expected[window:].sum() >= 20  # the sweep is beyond the limit for a while
    differ = np.flatnonzero(per_frame[window:] != expected[window:]) + window
    assert np.all(np.abs(excess[differ]) < 1e-3), differ  # only where float32 features tie the limit
    err = np.degrees(np.abs(run.values - q[run.frame])).max(axis=1)
    assert err[per_frame].max() < 0.05  # the markers' own angles: exact on clean markers
    trial = ikid.simulate("random", seed=9507, duration=10.0)
    calm = run_model("wrist-ik", trial.markers, trial.time)
    assert not (calm.status[window - 1 :] & ikid.FRAME_STATUS["per_frame"]).any()


@pytest.mark.parametrize("pair", [("MC2", "MC5"), ("RSP", "USP")])
def test_labels_swapped_throughout_after_a_clean_calibration_write_nothing_and_say_why(tmp_path, pair):
    """A recording whose two metacarpal heads (or styloids) carry each other's labels from the
    first frame, calibrated from a static trial labelled right: the segment's shape is the
    same, so only the posture tells. Every frame reads the hand turned over; ``ik`` and
    ``track`` write no file and say why (before, ``track`` wrote 0 rows and exited 0)."""
    import shutil
    import subprocess
    import sys

    cli = shutil.which("ikid", path=str(Path(sys.executable).parent)) or "ikid"
    trial = simulate(seed=41, duration=1.5)
    names = list(ikid.marker_names())
    a, b = (names.index(n) for n in pair)
    markers = np.asarray(trial.markers, np.float64).copy()
    markers[:, 3 * a : 3 * a + 3], markers[:, 3 * b : 3 * b + 3] = (
        trial.markers[:, 3 * b : 3 * b + 3],
        trial.markers[:, 3 * a : 3 * a + 3],
    )
    ikid.io.write_trc(tmp_path / "swapped.trc", trial.time, markers)
    ikid.io.write_trc(tmp_path / "right.trc", trial.time, trial.markers)
    cal = ikid.Calibration.from_neutral(_native.forward_markers(np.zeros((10, 3))))
    ikid.save_calibration(cal, tmp_path / "cal.json")
    for cmd in (["ik", "-o", "out.mot"], ["track", "-o", "out"]):
        argv = [cli, cmd[0], "swapped.trc", *cmd[1:], "--calibration", "cal.json"]
        r = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert r.returncode == 2, (cmd, r.stdout, r.stderr)
        assert "turned over" in r.stderr and "MC2/MC5 or RSP/USP" in r.stderr, (cmd, r.stderr)
        assert not list(tmp_path.glob("out*")), cmd
        # The same trial labelled right runs and writes every row.
        argv[2] = "right.trc"
        r = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0 and "turned over" not in r.stdout, (cmd, r.stdout, r.stderr)
        for p in tmp_path.glob("out*"):
            p.unlink()


@pytest.mark.parametrize("reference", [False, True], ids=["wrist-id", "reference"])
def test_id_fed_angles_that_turn_the_hand_over_writes_none_of_them_and_says_it_is_the_angles(
    tmp_path, reference
):
    """``ikid id`` (the network, or the exact Newton-Euler reference) on angles whose middle
    turns the hand past 130 degrees (supination run 150 degrees further: a convention whose
    zero is elsewhere): those rows are not written, and the reason names the angles, not
    marker labels (there are none)."""
    import shutil
    import subprocess
    import sys

    from scipy.spatial.transform import Rotation

    cli = shutil.which("ikid", path=str(Path(sys.executable).parent)) or "ikid"
    trial = simulate(seed=43, duration=3.0)
    time, q = np.asarray(trial.time), np.asarray(trial.q, np.float64).copy()
    # A smooth excursion of s_p by +150 degrees over the middle second and back.
    phase = np.clip((time - time[0] - 0.8) / 1.4, 0.0, 1.0)
    q[:, 0] += np.radians(150.0) * np.sin(np.pi * phase) ** 2
    ikid.io.write_mot(tmp_path / "angles.mot", time, q)
    argv = [cli, "id", "angles.mot", "-o", "tau.sto"] + (["--reference"] if reference else [])
    r = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, (r.stdout, r.stderr)
    said = r.stdout + r.stderr
    why = "angles or torques no wrist gives" if reference else "input angles turn the hand"
    assert why in said and "MC2/MC5" not in said, said
    # Oracle: the hand's turn from scipy's rotations about the body model's axes.
    axes = [np.array(a) for a in ([0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])]
    turn = np.degrees(
        (
            Rotation.from_rotvec(q[:, :1] * axes[0])
            * Rotation.from_rotvec(q[:, 1:2] * axes[1])
            * Rotation.from_rotvec(q[:, 2:3] * axes[2])
        ).magnitude()
    )
    written, _ = ikid.io.read_sto(tmp_path / "tau.sto")
    over = time[turn > 130.0]
    assert len(over) > 100
    assert not np.isin(np.round(written, 6), np.round(over, 6)).any()
    # Before the excursion every row is written (the window filling and the ends aside).
    calm = time[(time > time[0] + 0.2) & (time < time[0] + 0.7)]
    assert np.isin(np.round(calm, 6), np.round(written, 6)).all()


@pytest.mark.parametrize("reference", [False, True], ids=["wrist-id", "reference"])
def test_id_refuses_angles_in_degrees_read_as_radians_and_writes_nothing(tmp_path, reference):
    """A .mot in degrees whose header says radians (``inDegrees=no``): nearly every angle lies
    where no wrist goes. Before, the network wrote 1 row of 9,370 and exited 0, and the
    reference wrote torques of thousands of N·m; now both refuse the file, naming the units."""
    import shutil
    import subprocess
    import sys

    cli = shutil.which("ikid", path=str(Path(sys.executable).parent)) or "ikid"
    trial = simulate(seed=44, duration=2.0)
    ikid.io.write_mot(tmp_path / "degrees.mot", trial.time, trial.q)
    text = (tmp_path / "degrees.mot").read_text()
    assert "inDegrees=yes" in text
    (tmp_path / "said_radians.mot").write_text(text.replace("inDegrees=yes", "inDegrees=no"))
    for name, refused in (("said_radians.mot", True), ("degrees.mot", False)):
        argv = [cli, "id", name, "-o", "tau.sto"] + (["--reference"] if reference else [])
        r = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=300)
        if refused:
            assert r.returncode == 2, (r.stdout, r.stderr)
            assert "inDegrees" in r.stderr and "nothing written" in r.stderr, r.stderr
            assert not (tmp_path / "tau.sto").exists()
        else:
            assert r.returncode == 0 and "no wrist" not in r.stdout, (r.stdout, r.stderr)
            time, tau = ikid.io.read_sto(tmp_path / "tau.sto")
            assert len(time) >= len(trial.time) - 10 and np.isfinite(tau).all()
