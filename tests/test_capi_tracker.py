"""libikid's tracker from C: the C test program (tests/c/test_tracker.c) and the host example
(examples/c/track_csv.c), built by `make c` (nothing is built here), run natively and under
valgrind, their outputs bit-identical to ``ikid.Tracker(...).run`` on the same simulated trial
(noisy markers, a late start and a missing-marker gap), with and without the refiner."""

from __future__ import annotations

import re

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

    plain = ikid.Tracker(**SUBJECT)
    out = plain.run(frames)
    refined = ikid.Tracker(**SUBJECT, refiner=refiner).run(frames)
    assert out["start"] == 3 and refined["start"] == 3
    assert (out["missing"][800:950] == 1 << 4).all() and refined["refined"][1000:].all()
    for name, o in (("expected", out), ("expected_refined", refined)):
        np.savetxt(d / f"{name}.csv", expected_rows(o), fmt="%.17g", delimiter=",")
    np.savetxt(d / "noise.csv", plain.marker_noise[None], fmt="%.17g", delimiter=",")
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
    cmd = [built("track_csv"), d / "frames.csv", "--every", "1"]
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
    result = run([built("track_csv"), d / "inf.csv"])
    assert result.returncode == 1 and "frame 9" in result.stderr and "RSP.x" in result.stderr, result.stderr
    # A model that cannot refine a tracker is refused with the reason.
    result = run([built("track_csv"), d / "frames.csv", "--refiner", d / "ik.safetensors"])
    assert result.returncode == 1 and "cannot refine" in result.stderr, result.stderr


def test_python_run_equals_python_push(trial):
    """The C tests compare with ``run``; ``push`` gives the same (the core's run is push one by one)."""
    frames, out = trial[1][:600], trial[2][None]
    tracker = ikid.Tracker(**SUBJECT)
    pushed = [tracker.push(f) for f in frames]
    assert all(p is None for p in pushed[:3])
    stacked = np.stack(pushed[3:])  # type: ignore[arg-type]
    for k, name in enumerate(KEYS):
        assert stacked[:, k].tobytes() == out[name][3:600].tobytes()
