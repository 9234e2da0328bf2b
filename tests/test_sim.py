"""The simulator from Python: ground truth consistent with the reference solvers,
deterministic, OpenSim files, noise models, bad parameters, and the CLI."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

import ikid
from ikid.io import write_mot


@pytest.fixture(scope="module")
def trial():
    return ikid.simulate(
        "random", seed=11, duration=4.0, shoulder_flexion=math.radians(45), length_scale=1.1, mass_scale=1.2
    )


def test_reference_ik_recovers_the_simulated_angles(trial):
    q = ikid.reference_ik(trial.markers, length_scale=1.1)
    assert np.sqrt(np.mean((q - trial.q) ** 2)) <= 1e-6


def test_reference_id_reproduces_the_recorded_torques(trial):
    tau = ikid.reference_id(
        trial.q, trial.qd, trial.qdd, shoulder_flexion=math.radians(45), length_scale=1.1, mass_scale=1.2
    )
    span = trial.tau.max(axis=0) - trial.tau.min(axis=0)
    rms = np.sqrt(np.mean((tau - trial.tau) ** 2, axis=0))
    assert np.all(rms <= 0.01 * span), (rms, span)


def test_same_seed_same_bits_other_seed_other_motion(tmp_path):
    a = ikid.simulate("random", seed=5, duration=1.0)
    b = ikid.simulate("random", seed=5, duration=1.0)
    c = ikid.simulate("random", seed=6, duration=1.0)
    for k in ("q", "tau", "markers"):
        assert getattr(a, k).tobytes() == getattr(b, k).tobytes()
    assert not np.array_equal(a.q, c.q)
    a.save(tmp_path / "a")
    b.save(tmp_path / "b")
    for ext in (".trc", ".mot", ".sto"):
        assert (tmp_path / f"a{ext}").read_bytes().replace(b"a" + ext.encode(), b"") == (
            tmp_path / f"b{ext}"
        ).read_bytes().replace(b"b" + ext.encode(), b"")


def test_thesis_protocol_covers_the_thesis_ranges():
    t = ikid.simulate("thesis")
    assert len(t.time) > 20_000 and t.metadata["protocol"] == "thesis"
    peak_v = np.abs(t.qd).max(axis=0)
    assert np.all(peak_v > 2.0) and peak_v.max() > 8.0  # thesis: up to ~13 rad/s
    assert np.abs(t.qdd).max() > 100.0  # thesis: up to ~210 rad/s²


def test_files_open_as_opensim_expects(trial, tmp_path):
    noisy = trial.with_noise(
        "occlusion", seed=1, bursts_per_second=2.0, min_s=0.05, max_s=0.1, rate_hz=trial.rate_hz
    )
    paths = noisy.save(tmp_path / "t")
    assert [p.suffix for p in paths] == [".npz", ".trc", ".mot", ".sto"]
    trc = (tmp_path / "t.trc").read_text().splitlines()
    assert trc[2].split("\t")[4] == "mm" and trc[3].split("\t")[2] == "RSP"
    rows = [ln.split("\t") for ln in trc[6:]]
    assert len(rows) == len(trial.time) and all(len(r) == 20 for r in rows)
    gaps = sum(c == "" for r in rows for c in r[2:])
    assert gaps == np.isnan(noisy.markers).sum() > 0
    first = np.array(rows[0][2:5], float) / 1000.0
    np.testing.assert_allclose(first, trial.markers[0, :3], atol=1e-8)
    mot = (tmp_path / "t.mot").read_text().splitlines()
    assert "inDegrees=yes" in mot and mot[6] == "time\tra_wr_s_p\tra_wr_e_f\tra_wr_ad_ab"
    np.testing.assert_allclose(
        np.array(mot[-1].split("\t")[1:], float), np.degrees(trial.q[-1]), rtol=1e-6, atol=1e-9
    )
    sto = (tmp_path / "t.sto").read_text().splitlines()
    assert sto[6] == "time\tra_wr_s_p_moment\tra_wr_e_f_moment\tra_wr_ad_ab_moment"
    back = ikid.Trial.load(tmp_path / "t.npz")
    np.testing.assert_array_equal(back.markers, noisy.markers)
    assert back.metadata["noise"][0]["kind"] == "occlusion" and back.metadata["length_scale"] == 1.1


def test_a_file_that_is_not_a_trial_archive_is_named(trial, tmp_path):
    trial.save(tmp_path / "t")
    whole = (tmp_path / "t.npz").read_bytes()
    cases = {
        "text.npz": b"time,q\n0,1\n",
        "truncated.npz": whole[: len(whole) // 2],
        "empty.npz": b"",
        "array.npy": None,
    }
    for name, data in cases.items():
        path = tmp_path / name
        if data is None:
            np.save(path, trial.q)
        else:
            path.write_bytes(data)
        with pytest.raises(ikid.io.FileFormatError, match="not a trial archive") as caught:
            ikid.Trial.load(path)
        assert str(path) in str(caught.value), name


def test_nan_is_never_written_silently(trial, tmp_path):
    q = trial.q.copy()
    q[7, 1] = np.nan
    with pytest.raises(ikid.InputError, match="ra_wr_e_f at row 7"):
        write_mot(tmp_path / "bad.mot", trial.time, q)
    assert list(tmp_path.iterdir()) == []


def test_noise_models_are_seeded_and_bounded(trial):
    a = trial.with_noise("uniform", seed=3, fraction=0.05).markers
    b = trial.with_noise("uniform", seed=3, fraction=0.05).markers
    assert a.tobytes() == b.tobytes()
    span = trial.markers.max(0) - trial.markers.min(0)
    assert np.all(np.abs(a - trial.markers) <= 0.05 * span + 1e-12)
    g = trial.with_noise("gaussian", seed=3, sigma=0.002).markers - trial.markers
    assert abs(g.std() - 0.002) < 2e-4
    with pytest.raises(ikid.InputError, match="unknown noise"):
        trial.with_noise("pink", seed=1)
    with pytest.raises(ikid.InputError, match="sigma"):
        trial.with_noise("gaussian", seed=1, sigma=-1.0)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"protocol": "dance"}, "unknown protocol"),
        ({"mass_scale": -1.0}, "mass_scale"),
        ({"shoulder_flexion": float("nan")}, "shoulder_flexion is NaN"),
        ({"dt": -0.001}, "dt is -0.001"),
        ({"duration": 0.0}, "duration"),
    ],
)
def test_bad_parameters_are_named(kwargs, message):
    with pytest.raises(ikid.InputError, match=message):
        ikid.simulate(**{"protocol": "random", **kwargs})


def test_cli_simulate_writes_the_trial(tmp_path):
    out = tmp_path / "cli"
    cmd = [
        sys.executable,
        "-m",
        "ikid",
        "simulate",
        "--seed",
        "2",
        "--duration",
        "1",
        "--shoulder-deg",
        "-20",
        "--noise",
        "uniform:0.01",
        "-o",
        str(out),
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    t = ikid.Trial.load(out.with_suffix(".npz"))
    assert t.metadata["noise"] == [{"kind": "uniform", "seed": 2001, "fraction": 0.01}]
    assert math.isclose(t.metadata["shoulder_flexion_rad"], math.radians(-20))
    bad = subprocess.run(
        [sys.executable, "-m", "ikid", "simulate", "--length-scale", "-1", "-o", str(out)],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2 and "length_scale" in bad.stderr


def test_metadata_records_what_was_simulated_and_dotted_stems(tmp_path):
    t = ikid.simulate("random", seed=1, duration=0.05)
    assert t.metadata["duration_s"] == pytest.approx(len(t.time) * 0.001)
    assert t.metadata["simulator"] == ikid.SIMULATOR and "rapier" in ikid.SIMULATOR
    paths = t.save(tmp_path / "trial.v2")
    assert [p.name for p in paths] == ["trial.v2.npz", "trial.v2.trc", "trial.v2.mot", "trial.v2.sto"]
