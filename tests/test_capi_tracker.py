"""libikid's tracker from C: the C test program (tests/c/test_tracker.c) and the host example
(examples/c/track_csv.c), built by `make c` (nothing is built here), run natively and under
valgrind, their outputs bit-identical to ``ikid.Tracker(...).run`` on the same simulated trial
(noisy markers, a late start and a missing-marker gap), with and without the refiner."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import ikid
from conftest import ROOT, make_model
from test_capi import built, run, run_checked

SUBJECT = {"length_scale": 1.1, "mass_scale": 1.2}  # tests/c/test_tracker.c uses the same
KEYS = ("q", "qd", "qdd", "tau")


def expected_rows(out: dict) -> np.ndarray:
    """Per frame: q, qd, qdd, tau, missing, refined, noise, status (the C test's EXPECTED layout)."""
    return np.column_stack(
        [*(out[k] for k in KEYS), out["missing"], out["refined"], out["noise"], out["status"]]
    )


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    d = tmp_path_factory.mktemp("tracker")
    sim = ikid.simulate(seed=20, duration=2.0, shoulder_flexion=0.3, **SUBJECT)
    rng = np.random.default_rng(20)
    frames = sim.markers + rng.uniform(-1e-3, 1e-3, sim.markers.shape)  # ±1 mm of noise
    frames[:3, 4] = np.nan  # USP.y missing on the first three frames: the tracker starts at frame 3
    frames[800:950, 12:15] = np.nan  # MC5 gone for 150 ms
    np.savetxt(d / "frames.csv", frames, fmt="%.17g", delimiter=",")
    # %.17g reads back as the same doubles: C and Python see identical frames.
    np.testing.assert_array_equal(np.loadtxt(d / "frames.csv", delimiter=","), frames)

    ikid.load("wrist-track").save(d / "wrist-track.safetensors")
    refiner = ikid.load(d / "wrist-track.safetensors")
    make_model().save(d / "ik.safetensors")  # a model that cannot refine a tracker

    plain = ikid.Tracker(**SUBJECT, rate_hz=1000.0)
    out = plain.run(frames)
    refined = ikid.Tracker(**SUBJECT, rate_hz=1000.0, refiner=refiner).run(frames)
    assert out["start"] == 3 and refined["start"] == 3
    assert (out["missing"][800:950] == 1 << 4).all() and refined["refined"][1000:].all()
    for name, o in (("expected", out), ("expected_refined", refined)):
        np.savetxt(d / f"{name}.csv", expected_rows(o), fmt="%.17g", delimiter=",")
    sd = plain.output_sd
    assert sd is not None
    noise_and_sd = np.concatenate([plain.marker_noise, sd.ravel()])[None]
    np.savetxt(d / "noise.csv", noise_and_sd, fmt="%.17g", delimiter=",")
    return d, frames, {None: out, "wrist-track": refined}


def test_c_tracker_program_passes_under_valgrind(trial):
    d = trial[0]
    files = [
        "frames.csv",
        "expected.csv",
        "noise.csv",
        "wrist-track.safetensors",
        "expected_refined.csv",
        "ik.safetensors",
    ]
    cmd = [built("test_tracker"), *(d / f for f in files)]

    def check(result):
        assert result.returncode == 0, result.stdout + result.stderr
        last = result.stdout.strip().splitlines()[-1]
        passed, failed = int(last.split()[0]), int(last.split()[2])
        # Every CHECK in the source ran (none skipped by an early exit); tests/c/check.h defines it.
        n_checks = (ROOT / "tests" / "c" / "test_tracker.c").read_text().count("CHECK(")
        assert failed == 0 and passed == n_checks, last

    run_checked(cmd, check)


LATENCY = re.compile(
    r"^(\d+) frames, (\d+) estimated; ikid_tracker_push latency p50 (\S+) us, p99 (\S+) us$", re.M
)


@pytest.mark.parametrize("refiner", [None, "wrist-track"])
def test_host_example_equals_python_bit_for_bit(trial, refiner):
    d, frames, outs = trial
    py = outs[refiner]
    cmd = [built("track_csv"), d / "frames.csv", "--rate", "1000", "--every", "1"]
    cmd += ["--length-scale", str(SUBJECT["length_scale"]), "--mass-scale", str(SUBJECT["mass_scale"])]
    if refiner:
        cmd += ["--refiner", d / f"{refiner}.safetensors"]

    def check(result):
        assert result.returncode == 0, result.stderr
        lines = result.stdout.strip().splitlines()
        names = ikid.coordinate_names()
        header = ["frame", *(f"q.{c}" for c in names), *(f"tau.{c}" for c in names), "missing", "refined"]
        assert lines[0].split(",") == header
        rows = [ln.split(",") for ln in lines[1:]]
        # Printed with %.17g: float() gives back exactly the doubles C computed.
        got = np.array([[float(v) for v in r[1:7]] for r in rows])
        index = np.array([int(r[0]) for r in rows])
        start = py["start"]
        np.testing.assert_array_equal(index, np.arange(start, len(frames)))
        assert got.tobytes() == np.hstack([py["q"][start:], py["tau"][start:]]).tobytes()
        np.testing.assert_array_equal([int(r[7]) for r in rows], py["missing"][start:])
        np.testing.assert_array_equal([r[8] == "1" for r in rows], py["refined"][start:])
        assert any(r[8] == "1" for r in rows) == (refiner is not None)
        ((n, estimated, p50, p99),) = LATENCY.findall(result.stderr)
        p50, p99 = float(p50), float(p99)
        assert int(n) == len(frames) and int(estimated) == len(frames) - start
        assert np.isfinite([p50, p99]).all() and 0 < p50 <= p99, result.stderr

    run_checked(cmd, check)


def test_host_example_reports_a_refused_frame(trial):
    d, frames = trial[0], trial[1].copy()
    frames[9, 0] = np.inf
    np.savetxt(d / "inf.csv", frames, fmt="%.17g", delimiter=",")
    result = run([built("track_csv"), d / "inf.csv", "--rate", "1000"])
    assert result.returncode == 1 and "frame 9" in result.stderr and "RSP.x" in result.stderr, result.stderr
    # A model that cannot refine a tracker is refused with the reason.
    result = run([built("track_csv"), d / "frames.csv", "--rate", "1000", "--refiner", d / "ik.safetensors"])
    assert result.returncode == 1 and "cannot refine" in result.stderr, result.stderr
    # Without its rate the tracker is refused, saying so.
    result = run([built("track_csv"), d / "frames.csv"])
    assert result.returncode == 1 and "rate_hz: is not set" in result.stderr, result.stderr


def test_python_run_equals_python_push(trial):
    """The C tests compare with ``run``; ``push`` gives the same (the core's run is push one by one)."""
    frames, out = trial[1][:600], trial[2][None]
    tracker = ikid.Tracker(**SUBJECT, rate_hz=1000.0)
    pushed = [tracker.push(f) for f in frames]
    assert all(p is None for p in pushed[:3])
    stacked = np.stack([p.values for p in pushed[3:] if p is not None])
    for k, name in enumerate(KEYS):
        assert stacked[:, k].tobytes() == out[name][3:600].tobytes()


def _c_tracker_run(
    frames: np.ndarray, calibration, side: bytes | None, shapes: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, int]:
    """The C tracker (default subject, 100 Hz) calibrated through ``ikid_tracker_set_calibration``
    (``ikid_tracker_set_calibration_shapes`` with ``shapes``, a calibration file's
    ``marker_shapes_m``): its (n, 12) values and (n,) status bits, and the start."""
    import ctypes as C

    from faults.capi import Flags, f64p, last_error, lib

    settings = lib().ikid_tracker_settings_default()
    settings.rate_hz = 100.0
    tracker = C.c_void_p()
    assert lib().ikid_tracker_new(C.byref(settings), None, C.byref(tracker)) == 0, last_error()
    try:
        forearm = np.ascontiguousarray(calibration.forearm, np.float64)
        hand = np.ascontiguousarray(calibration.hand, np.float64)
        if shapes is None:
            status = lib().ikid_tracker_set_calibration(
                tracker, forearm.ctypes.data_as(f64p), hand.ctypes.data_as(f64p), side
            )
        else:
            rows = np.ascontiguousarray(shapes, np.float64)
            status = lib().ikid_tracker_set_calibration_shapes(
                tracker,
                forearm.ctypes.data_as(f64p),
                hand.ctypes.data_as(f64p),
                side,
                rows.ctypes.data_as(f64p),
            )
        assert status == 0, last_error()
        values = np.ascontiguousarray(frames, np.float64)
        out = np.full((len(frames), 12), np.nan)
        flags = (Flags * len(frames))()
        start = C.c_size_t(0)
        status = lib().ikid_tracker_run(
            tracker, values.ctypes.data_as(f64p), values.size, out.ctypes.data_as(f64p), out.size,
            flags, len(frames), C.byref(start),
        )  # fmt: skip
        assert status == 0, last_error()
        return out, np.array([f.status for f in flags]), start.value
    finally:
        lib().ikid_tracker_free(tracker)


@pytest.mark.parametrize("side", ["right", "left"])
def test_the_c_tracker_calibrated_for_either_arm_equals_python(side):
    # A subject at 100 Hz whose markers the body model does not fit, calibrated from neutral
    # frames; a left arm is the right one's mirror image, and the calibration says so.
    shift = np.zeros((6, 3))
    shift[3:] = [[0.012, -0.01, 0.004], [-0.008, 0.015, 0.0], [0.0, 0.02, -0.01]]
    sim = ikid.simulate(seed=21, duration=3.0, dt=0.001, output_every=10)
    q = np.asarray(sim.q)
    frames = ikid.forward_markers(q, 0.4, 1.0, 1.0, shift)
    neutral = ikid.forward_markers(np.zeros((10, 3)), 0.4, 1.0, 1.0, shift)
    if side == "left":
        mirror = np.tile([1.0, 1.0, -1.0], 6)
        frames, neutral = frames * mirror, neutral * mirror
    measured = ikid.Calibration.from_neutral(neutral, side=side)
    # As a C host gets it: the file's two matrices and side (both sides read them back alike).
    calibration = ikid.Calibration.from_matrices(measured.forearm, measured.hand, side=side)
    py = ikid.Tracker(rate_hz=100.0, calibration=calibration).run(frames)
    out, status, start = _c_tracker_run(frames, measured, side.encode())  # the same two matrices
    assert start == py["start"] == 0
    expected = np.hstack([py[k] for k in KEYS])
    assert out.tobytes() == expected.tobytes()  # bit for bit
    np.testing.assert_array_equal(status, py["status"])
    # And it tracks: the calibration's whole point (the simulation's own angles as the oracle).
    assert np.degrees(np.abs(py["q"][50:] - q[50:])).max() < 0.5  # after 0.5 s of settling
    # A side the C caller misspells is refused by name.
    import ctypes as C

    from faults.capi import f64p, last_error, lib

    settings = lib().ikid_tracker_settings_default()
    settings.rate_hz = 1000.0
    tracker = C.c_void_p()
    assert lib().ikid_tracker_new(C.byref(settings), None, C.byref(tracker)) == 0
    identity = np.eye(3)  # kept alive while C reads it
    eye = identity.ctypes.data_as(f64p)
    status = lib().ikid_tracker_set_calibration(tracker, eye, eye, b"lft")
    assert status != 0 and "side" in last_error()
    lib().ikid_tracker_free(tracker)


def _slid_trial() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A trial at 100 Hz starting flexed whose MC2 and MC5 slide 8 mm along their lines to MCB
    with the flexion (none at neutral), its neutral frames, and its true angles."""
    t = np.arange(300) / 100.0
    q = np.stack([0.3 * np.sin(1.1 * t), 0.5 * np.cos(0.8 * t), 0.15 * np.sin(1.9 * t)], axis=1)
    frames = ikid.forward_markers(q, 0.4).reshape(len(q), 6, 3)
    for m in (3, 4):
        along = frames[:, 5] - frames[:, m]
        along /= np.linalg.norm(along, axis=1, keepdims=True)
        frames[:, m] += along * (0.008 * q[:, 1:2] / 0.5)
    return frames.reshape(len(q), 18), ikid.forward_markers(np.zeros((10, 3)), 0.4), q


def test_a_c_host_given_the_calibration_files_marker_shapes_equals_python_bit_for_bit():
    # Review 5: a calibration file keeps each segment's marker shape ("marker_shapes_m"); ik,
    # track and Python fit to it, while C could pass only the two matrices, so a C host read
    # the same file otherwise (a real trial cut 1.5 s in: 2.3° instead of 0.7°).
    # ikid_tracker_set_calibration_shapes and ikid_stream_set_calibration_shapes take them.
    import ctypes as C

    from faults.capi import f32p, f64p, last_error, lib

    frames, neutral, q = _slid_trial()
    measured = ikid.Calibration.from_neutral(neutral).with_shapes_of(neutral)
    shapes = np.asarray(measured.marker_shapes).reshape(18)
    calibration = ikid.Calibration.from_matrices(measured.forearm, measured.hand).with_marker_shapes(
        shapes.reshape(6, 3)
    )
    py = ikid.Tracker(rate_hz=100.0, calibration=calibration).run(frames)
    out, status, _ = _c_tracker_run(frames, measured, None, shapes)
    assert out.tobytes() == np.hstack([py[k] for k in KEYS]).tobytes()  # bit for bit
    np.testing.assert_array_equal(status, py["status"])
    # The shapes matter here: without them C (and Python) fit the trial's slid start.
    without, _, _ = _c_tracker_run(frames, measured, None)
    err = {
        name: np.degrees(np.abs(o[50:, :3] - q[50:])).max()
        for name, o in (("with", out), ("without", without))
    }
    assert err["without"] > 2 * err["with"], err
    # The stream: C's outputs equal Python's ikid.Model.stream with the same calibration.
    model = ikid.load("wrist-ik-100hz")
    stream = model.stream(calibration=calibration)
    expected = [stream.push(f) for f in frames.astype(np.float32)]
    handle = C.c_void_p()
    path = str(
        Path(__file__).resolve().parents[1] / "python" / "ikid" / "models" / "wrist-ik-100hz.safetensors"
    )
    loaded = C.c_void_p()
    assert lib().ikid_model_load(path.encode(), C.byref(loaded)) == 0, last_error()
    try:
        assert lib().ikid_stream_new(loaded, C.byref(handle)) == 0, last_error()
        fa = np.ascontiguousarray(measured.forearm, np.float64)
        ha = np.ascontiguousarray(measured.hand, np.float64)
        rows = np.ascontiguousarray(shapes, np.float64)
        assert (
            lib().ikid_stream_set_calibration_shapes(
                handle, fa.ctypes.data_as(f64p), ha.ctypes.data_as(f64p), None, rows.ctypes.data_as(f64p)
            )
            == 0
        ), last_error()
        row = np.zeros(model.n_outputs, np.float32)
        ready = C.c_bool(False)
        for f, want in zip(frames.astype(np.float32), expected, strict=True):
            f = np.ascontiguousarray(f)
            assert (
                lib().ikid_stream_push(
                    handle, f.ctypes.data_as(f32p), 18, row.ctypes.data_as(f32p), row.size, C.byref(ready)
                )
                == 0
            ), last_error()
            if want is None:
                assert not ready.value
            else:
                assert ready.value and row.tobytes() == np.asarray(want, np.float32).tobytes()
        # Shapes without the matrices, or not finite, are refused by name, nothing changed.
        assert (
            lib().ikid_stream_set_calibration_shapes(handle, None, None, None, rows.ctypes.data_as(f64p)) != 0
        )
        assert "shapes" in last_error()
    finally:
        lib().ikid_stream_free(handle)
        lib().ikid_model_free(loaded)
