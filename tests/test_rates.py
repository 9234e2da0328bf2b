"""Models per rate (issue #19, item 2): the shipped wrist-ik family, the choice of a model by the
recording's rate (ikid.pipeline.pick_model), and `ikid ik` at a file's own rate and frames.

Expected angles come from the simulator's ground truth, never from ikid's outputs.
"""

from __future__ import annotations

import numpy as np
import pytest

import ikid
from ikid import pipeline
from ikid.cli import main as cli
from ikid.io import read_storage, write_trc

#: Held-out trajectory (studies/rates.py's test seeds start at 9500; training used < 9500).
SEED = 9504


def _trial(rate_every: int, seconds: float = 8.0) -> ikid.Trial:
    return ikid.simulate("random", seed=SEED, duration=seconds, output_every=rate_every)


def _ik(tmp_path, time, markers, rate, *extra):
    """`ikid ik` on a TRC at ``rate``: (rows' time, angles rad, status, stdout)."""
    write_trc(tmp_path / "t.trc", time, markers, rate)
    code = cli(["ik", str(tmp_path / "t.trc"), "-o", str(tmp_path / "t.mot"), *extra])
    assert code in (0, 3)
    table = read_storage(tmp_path / "t.mot")
    q = table.select(ikid.coordinate_names())
    q = np.radians(q) if table.in_degrees else q
    return table.time, q, table.column("ikid_status").astype(int)


def test_the_shipped_family_has_a_model_per_rate_and_the_cards_say_so():
    members = pipeline.family_members("wrist-ik")
    assert [(m.name, m.frame_rate_hz) for m in members] == [
        ("wrist-ik-100hz", 100.0),
        ("wrist-ik-250hz", 250.0),
        ("wrist-ik", 1000.0),
    ]
    for m in members:
        assert m.task == "ik" and m.feature_set == "angles" and m.missing_markers == "fill"
        assert ikid.load(m.name).card["frame_rate_hz"] == m.frame_rate_hz
    # A per-rate name or a path is one model, not a family.
    assert pipeline.family_members("wrist-ik-100hz") == []
    assert pipeline.family_members("./wrist-ik") == []


@pytest.mark.parametrize(
    ("rate", "name", "how"),
    [
        (100.0, "wrist-ik-100hz", "native"),
        (100.05, "wrist-ik-100hz", "native"),  # within 0.1 %
        (250.0, "wrist-ik-250hz", "native"),
        (1000.0, "wrist-ik", "native"),
        (70.0, "wrist-ik", "at_frames"),  # no member at the rate: the fastest
        (120.0, "wrist-ik", "at_frames"),
        (500.0, "wrist-ik", "at_frames"),
        (2000.0, "wrist-ik", "at_frames"),  # faster than every member: the fastest
    ],
)
def test_a_family_name_picks_the_model_for_the_rate(rate, name, how):
    model, got = pipeline.pick_model("wrist-ik", rate)
    assert (model.name, got) == (name, how)


def test_an_explicit_model_is_that_model():
    with pytest.raises(ikid.InputError, match="resample"):
        pipeline.pick_model("wrist-ik-100hz", 1000.0)
    model, how = pipeline.pick_model("wrist-ik-100hz", 1000.0, resample_to_model=True)
    assert (model.name, how) == ("wrist-ik-100hz", "resample")
    model, how = pipeline.pick_model(ikid.load("wrist-ik"), 100.0, resample_to_model=True)
    assert (model.name, how) == ("wrist-ik", "resample")


def test_ik_on_a_100hz_file_runs_the_100hz_model_at_the_files_frames(tmp_path, capsys):
    trial = _trial(10)
    assert trial.rate_hz == 100.0
    t, q, status = _ik(tmp_path, trial.time, trial.markers, 100.0)
    out = capsys.readouterr().out
    assert "model wrist-ik-100hz (100 Hz) at the recording's rate" in out
    window = ikid.load("wrist-ik-100hz").window
    # One row per frame, at exactly the file's frame times: the first window's per-frame
    # solutions (flagged), then the network's (nothing unusual on this clean trial).
    np.testing.assert_allclose(t, trial.time, atol=1e-9)
    assert (status[: window - 1] == ikid.FRAME_STATUS["per_frame"]).all()
    assert not status[window - 1 :].any()
    # Measured: angle MSE 4.7e-06 rad² (0.12° RMS) on this clean held-out trial; bound ~2x.
    mse = float(np.mean((q - trial.q) ** 2))
    assert mse < 1e-5, mse


def test_a_missing_sample_at_100hz_stays_one_frame(tmp_path):
    """Natively at 100 Hz a missing sample is that frame's alone (through --resample to 1 kHz
    it spread over ~37 ms of input): one marker missing in one frame is filled in that frame
    only; a whole frame missing is that frame without output, plus at most the window's refill
    (the stream restarts its window after a lost frame, as live)."""
    trial = _trial(10)
    k = 500
    markers = trial.markers.copy()
    markers[k, 9:12] = np.nan  # MC2, one frame
    t, _, status = _ik(tmp_path, trial.time, markers, 100.0)
    np.testing.assert_allclose(t, trial.time, atol=1e-9)  # every frame has its row
    flagged = t[status & ikid.FRAME_STATUS["filled"] != 0]
    np.testing.assert_allclose(flagged, [trial.time[k]], atol=1e-9)  # only that frame is filled

    markers = trial.markers.copy()
    markers[k] = np.nan  # the whole frame
    t, _, status = _ik(tmp_path, trial.time, markers, 100.0)
    rows = np.round(t * 100).astype(int)
    lost = sorted(set(range(len(trial.time))) - set(rows.tolist()))
    assert lost == [k], lost  # that frame only: the refilling window gives per-frame solutions
    window = ikid.load("wrist-ik-100hz").window
    refill = (rows > k) & (rows < k + window)
    assert (status[refill] & ikid.FRAME_STATUS["per_frame"] != 0).all()
    # Through --resample to 1 kHz, the same frame lost is more: input missing on both sides.
    r = pipeline.run_model(ikid.load("wrist-ik"), markers, trial.time, resample_to_model=True)
    missing_input = r.refused.total() - r.refused["window filling"]
    assert missing_input > 10  # 1 kHz frames whose input is missing (~19 around one 100 Hz frame)


def test_a_70hz_file_runs_the_fastest_model_with_outputs_at_its_own_frames(tmp_path, capsys):
    fine = _trial(1)
    time = np.arange(0.0, fine.time[-1], 1.0 / 70.0)
    markers = np.column_stack([np.interp(time, fine.time, c) for c in fine.markers.T])
    truth = np.column_stack([np.interp(time, fine.time, c) for c in fine.q.T])
    t, q, _ = _ik(tmp_path, time, markers, 70.0)
    out = capsys.readouterr().out
    assert "model wrist-ik (1000 Hz), the 70 Hz recording resampled to it" in out
    # Rows only at the 70 Hz frames: every row's time is a frame's, and all but the first
    # ~0.1 s (the window filling) have one.
    k = np.round(t * 70.0)
    np.testing.assert_allclose(t, time[k.astype(int)], atol=1e-6)  # the .mot keeps 6 decimals
    assert len(t) >= len(time) - 8
    # Measured (the 1 kHz member): angle MSE 5.1e-06 rad² against the simulation's angles at
    # those times; bound ~2x.
    mse = float(np.mean((q - truth[k.astype(int)]) ** 2))
    assert mse < 1e-5, mse


def test_a_stream_at_100_or_250hz_runs_the_familys_member_at_that_rate(monkeypatch, capsys):
    """Live streams are never resampled: `ikid.load(family, rate_hz=...)` and `ikid stream --rate`
    run the member trained at the source's rate, and its outputs track the simulator's truth."""
    import io as text_io
    import sys

    for every, rate in ((10, 100.0), (4, 250.0)):
        model = ikid.load("wrist-ik", rate_hz=rate)
        assert model.name == f"wrist-ik-{rate:g}hz" and model.frame_rate_hz == rate
        trial = _trial(every, seconds=4.0)
        lines = "".join(",".join(f"{v:.6f}" for v in row) + "\n" for row in trial.markers)
        monkeypatch.setattr(sys, "stdin", text_io.StringIO(lines))
        assert cli(["stream", "--rate", f"{rate:g}"]) == 0
        rows = [r.split(",") for r in capsys.readouterr().out.strip().splitlines()[1:]]
        ok = [(int(r[0]), [float(v) for v in r[2:]]) for r in rows if r[1] == "ok"]
        assert len(ok) == len(trial.markers) - model.window + 1
        frame, q = np.array([k for k, _ in ok]), np.array([v for _, v in ok])
        q = np.radians(q) if "deg" in model.output_units[0] else q
        # Measured on this held-out trial (clean): 0.1-0.2° RMS; bound ~2x of the 1 kHz family's.
        assert np.degrees(np.sqrt(np.mean((q - trial.q[frame]) ** 2))) < 0.5
    with pytest.raises(ikid.InputError, match=r"120 Hz.*100 Hz \(wrist-ik-100hz\).*not resampled"):
        ikid.load("wrist-ik", rate_hz=120)
    with pytest.raises(ikid.InputError, match="1000 Hz"):
        ikid.load("wrist-ik-100hz", rate_hz=1000)  # a member is itself, not its family
    with pytest.raises(ikid.ArgumentError, match="greater than 0"):
        ikid.load("wrist-ik", rate_hz=0)


def test_track_at_100hz_runs_the_bare_filter_and_refuses_a_refiner_of_another_rate(tmp_path, capsys):
    """`ikid track --refiner auto` (the default) takes the shipped refiner at the file's rate,
    and there is none at 100 Hz (ikid_training/refine.py says why): the bare filter, said in
    the summary; a refiner trained at another rate is refused naming both rates."""
    t = _trial(10, seconds=3.0)
    write_trc(tmp_path / "t.trc", t.time, t.markers, 100.0)
    assert cli(["track", str(tmp_path / "t.trc"), "-o", str(tmp_path / "auto")]) == 0
    assert "not refined" in capsys.readouterr().out
    assert cli(["track", str(tmp_path / "t.trc"), "-o", str(tmp_path / "r"), "--refiner", "wrist-track"]) == 2
    err = capsys.readouterr().err
    assert "trained at 1000 Hz, the tracker runs at 100 Hz" in err, err
