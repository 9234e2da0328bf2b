"""The Tracker's standard deviations (``Tracker.output_sd``): there once the filter runs, and
of the size of its real errors on a simulated trial with marker noise (the simulation's own
angles and torques are the oracle)."""

from __future__ import annotations

import numpy as np

import ikid


def test_sd_is_none_before_the_start_and_of_the_size_of_the_errors():
    trial = ikid.simulate(seed=9720, duration=2.0)
    noisy = trial.with_noise("gaussian", 9721, sigma=1e-3)
    tracker = ikid.Tracker()
    assert tracker.output_sd is None
    q_ratio, tau_ratio = [], []
    for i, frame in enumerate(noisy.markers):
        out = tracker.push(frame)
        sd = tracker.output_sd
        if out is None:
            assert sd is None
            continue
        assert sd is not None and sd.shape == (2, 3) and np.all(np.isfinite(sd)) and np.all(sd > 0)
        if i >= 500:
            q_ratio.append(np.abs(out[0] - trial.q[i]) / sd[0])
            tau_ratio.append(np.abs(out[3] - trial.tau[i]) / sd[1])
    # Not a calibration claim (studies/sigma_coverage.py measures that): σ is neither a tiny nor
    # a huge multiple of the error it stands for.
    for ratio in (np.array(q_ratio), np.array(tau_ratio)):
        assert 0.3 < np.mean(ratio <= 1.0) < 0.95, np.mean(ratio <= 1.0)
