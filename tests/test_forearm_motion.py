"""`ikid run` says how much torque its network leaves out when the forearm moves."""

from __future__ import annotations

import re

import numpy as np
import pytest

import ikid
from ikid import io
from ikid.cli import main as cli
from ikid.forearm_motion import NEGLIGIBLE_NM, ForearmMotion

NAMES = ["RSP", "USP", "FAP", "MC2", "MC5", "MCB"]


def _swung(rate: float, seconds: float, amplitude: float, hz: float, noise: float = 0.0, seed: int = 0):
    """The body model's arm at a slowly changing posture, carried bodily along lab x by
    ``amplitude`` · sin(2π · hz · t): its acceleration is known, ``amplitude`` (2π hz)² sin."""
    t = np.arange(round(seconds * rate)) / rate
    q = np.stack([0.3 * np.sin(1.1 * t), 0.4 * np.sin(0.7 * t), 0.1 * np.cos(0.9 * t)], axis=1)
    frames = ikid.forward_markers(q)
    shift = amplitude * np.sin(2 * np.pi * hz * t)
    frames[:, 0::3] += shift[:, None]
    frames += np.random.default_rng(seed).normal(0.0, noise, frames.shape)
    return t, frames


@pytest.mark.parametrize("rate", [70.0, 1000.0])
def test_the_forearms_acceleration_is_measured_whatever_the_rate_and_blocks(rate):
    # 2 Hz, 3 cm: 4.74 m/s² peak, 3.35 RMS (the oracle: the motion's own second derivative).
    t, frames = _swung(rate, 6.0, 0.03, 2.0)
    want = 0.03 * (2 * np.pi * 2.0) ** 2 / np.sqrt(2)
    motion = ForearmMotion()
    for block in np.array_split(np.arange(len(t)), 7):  # a file read in uneven blocks
        motion.add(t[block], frames[block])
    acc = motion.acceleration()
    assert np.sqrt(np.mean(acc**2)) == pytest.approx(want, rel=0.05)
    # The note's torque: the hand's mass × its centre's lever × the acceleration.
    hand = ikid.body_model()["segments"]["hand"]
    carried = hand["mass"] * np.linalg.norm(hand["com"]) * want
    note = motion.note()
    assert note is not None and f"about {carried:.2f} N·m RMS" in note, note


def test_a_still_forearm_under_marker_noise_is_not_mentioned():
    # 0.5 mm of noise at 1 kHz differentiated twice is 1000 m/s² raw: the fit must hold it
    # well under what would be worth saying.
    t, frames = _swung(1000.0, 6.0, 0.0, 2.0, noise=0.0005)
    motion = ForearmMotion()
    motion.add(t, frames)
    acc = motion.acceleration()
    hand = ikid.body_model()["segments"]["hand"]
    assert hand["mass"] * np.linalg.norm(hand["com"]) * np.sqrt(np.mean(acc**2)) < NEGLIGIBLE_NM / 3
    assert motion.note() is None
    # A forearm marker gone for a while: those fits are left out, not read as motion.
    frames[2000:2300, 0:3] = np.nan
    gone = ForearmMotion()
    gone.add(t, frames)
    assert len(gone.acceleration()) < len(acc) and gone.note() is None


def test_run_says_the_torque_its_network_leaves_out_when_the_forearm_moves(tmp_path, capsys):
    for amplitude, said in ((0.0, False), (0.03, True)):
        t, frames = _swung(1000.0, 3.0, amplitude, 2.0)
        path = io.write_trc(tmp_path / f"arm{amplitude}.trc", t, frames, 1000.0, NAMES)
        assert cli(["run", str(path), "-o", str(tmp_path / f"out{amplitude}")]) == 0
        out = capsys.readouterr().out
        got = re.search(r"the forearm moves \(its markers accelerate ([0-9.]+) m/s² RMS", out)
        assert (got is not None) == said, out
        assert ("the torque to carry the hand with it" in out) == said, out
        if said:
            assert float(got.group(1)) == pytest.approx(0.03 * (4 * np.pi) ** 2 / np.sqrt(2), rel=0.05)


def test_two_takes_a_long_time_apart_are_measured_each_alone():
    # Joined 30 years apart (and the second arm elsewhere in the lab): nothing is held
    # for the time between, and no fit spans the join, which would read as a huge acceleration.
    t, frames = _swung(1000.0, 2.0, 0.0, 2.0)
    motion = ForearmMotion()
    motion.add(t, frames)
    motion.add(t + 1e9, frames + 0.5)
    acc = motion.acceleration()
    bins = int(np.floor(t[-1] / 0.005 + 0.5)) + 1  # 5-ms bins of one take; a fit spans 21 of them
    assert len(acc) == 2 * (bins - 20) and acc.max() < 1e-6
