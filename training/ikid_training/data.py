"""Datasets for training: simulated recordings, augmentation (occlusion), windows.

Recordings, the thesis split, added noise and a lab's own trials are the runtime's
(:mod:`ikid.recordings`, which ``ikid report --data`` uses too); they are re-exported here so
training code reads one module. Features are computed by the Rust core
(``ikid.compute_features``) exactly as at inference. A *window* is ``window`` consecutive
frames' features, concatenated oldest first, labelled with the newest frame's target (causal,
no look-ahead).

Splits, all per recording so that no window straddles two parts:

- ``thesis``: the first 80 % of every recording trains, the next 10 % validates, the last
  10 % tests, unshuffled (the thesis' protocol; :data:`SPLIT_FRACTIONS`).
- held-out sets (movement types, a shoulder pose, subject sizes) are whole recordings that
  training never sees; see :func:`recording_set`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

import ikid
from ikid.recordings import MIN_LAB_FRAMES as MIN_LAB_FRAMES
from ikid.recordings import SPLIT_FRACTIONS as SPLIT_FRACTIONS
from ikid.recordings import TASKS as TASKS
from ikid.recordings import Recording as Recording
from ikid.recordings import add_noise as add_noise
from ikid.recordings import lab_trials as lab_trials
from ikid.recordings import load_lab_recordings as load_lab_recordings
from ikid.recordings import target as target

# --- building recordings ---------------------------------------------------------------------


def simulate_one(spec: dict[str, Any]) -> Recording:
    """Simulates ``spec`` (keyword arguments of :func:`ikid.simulate` plus ``name``)."""
    spec = dict(spec)
    name = spec.pop("name")
    if "shoulder_deg" in spec:
        spec["shoulder_flexion"] = math.radians(spec.pop("shoulder_deg"))
    return Recording.from_trial(name, ikid.simulate(**spec))


def simulate_all(specs: Sequence[dict[str, Any]], threads: int | None = None) -> list[Recording]:
    """Simulates every spec, in parallel threads (the simulator releases the GIL)."""
    threads = threads or min(len(specs), os.cpu_count() or 1)
    with ThreadPoolExecutor(max_workers=max(threads, 1)) as pool:
        return list(pool.map(simulate_one, specs))


def recording_set(
    kind: str,
    *,
    seeds: Iterable[int],
    shoulders_deg: Sequence[float],
    length_scales: Sequence[float],
    duration: float = 60.0,
    octants: list[str] | None = None,
    mass_follows_length: bool = True,
) -> list[dict[str, Any]]:
    """Specs for every (seed, shoulder, size) combination of protocol ``kind``.

    With ``mass_follows_length`` a subject ``s`` times longer is ``s³`` times heavier
    (geometric similarity), so torques stay predictable from markers alone.
    """
    seeds = list(seeds)
    specs = []
    k = 0
    for shoulder in shoulders_deg:
        for scale in length_scales:
            for seed in seeds if kind == "random" else [0]:
                spec: dict[str, Any] = {
                    "name": f"{kind}_s{shoulder:+.0f}_x{scale:.2f}"
                    + (f"_seed{seed + k}" if kind == "random" else ""),
                    "protocol": kind,
                    "shoulder_deg": shoulder,
                    "length_scale": scale,
                    "mass_scale": scale**3 if mass_follows_length else 1.0,
                }
                if kind == "random":
                    # A distinct seed per combination: no two recordings share a trajectory.
                    spec.update(seed=seed + k, duration=duration)
                    if octants:
                        spec["octants"] = octants
                specs.append(spec)
            k += 1000
    return specs


def load_recordings(folder: str | os.PathLike[str]) -> list[Recording]:
    """Every ``*.npz`` trial in ``folder`` (written by ``Trial.save`` / ``ikid dataset``)."""
    paths = sorted(Path(folder).glob("*.npz"))
    if not paths:
        raise FileNotFoundError(f"no .npz trials in {folder}")
    return [Recording.from_trial(p.stem, ikid.Trial.load(p)) for p in paths]


# --- noise -------------------------------------------------------------------------------------


def add_occlusion(
    rec: Recording, bursts_per_s: float, min_s: float, max_s: float, seed: int, warmup_s: float = 3.0
) -> Recording:
    """``rec`` with bursts in which one marker (drawn per burst) is missing (NaN), never two at
    once, none in the first ``warmup_s`` (the gap filler learns the joint centre there)."""
    rate = float(rec.meta.get("rate_hz", 1000.0))
    rng = np.random.default_rng(seed)
    markers = np.array(rec.markers, dtype=np.float64)
    n, start = len(markers), int(warmup_s * rate)
    gap_mean = rate / bursts_per_s if bursts_per_s > 0 else np.inf
    f = start + int(rng.exponential(gap_mean))
    while f < n:
        length = max(1, int(round(rng.uniform(min_s, max_s) * rate)))
        k = int(rng.integers(len(ikid.MARKERS)))
        markers[f : f + length, 3 * k : 3 * k + 3] = np.nan
        f += length + 1 + int(rng.exponential(gap_mean))
    # Bursts the gap filler cannot fill yet (joint centre not located) are put back: a stream
    # would refuse those frames, so they teach nothing.
    _, filled = ikid.fill_gaps(markers, unfillable="keep", rate_hz=rate)
    unfillable = np.isnan(markers).any(axis=1) & (filled == 0)
    markers[unfillable] = rec.markers[unfillable]
    return rec.with_markers(
        markers, occlusion={"bursts_per_s": bursts_per_s, "s": [min_s, max_s], "seed": seed}
    )


# --- windows -----------------------------------------------------------------------------------


def features(rec: Recording, task: str, feature_set: str) -> np.ndarray:
    """Per-frame features ``(n, F)`` float32, computed by the core; missing markers are
    first filled by the core's gap filler, as a ``"fill"`` stream does."""
    frames = rec.frames(feature_set)
    if ikid.feature_set_info(feature_set)["frame_kind"] == "markers" and np.isnan(frames).any():
        # At the recording's rate: the filler's time constants are in seconds.
        rate = float(rec.meta.get("rate_hz", 1000.0))
        filled = ikid.fill_gaps(frames, unfillable="keep", rate_hz=rate)[0]
        # A complete frame the filler takes for a jump (at 100 Hz a fast reach can move 8x the
        # segment's RMS step in one frame) keeps its own markers: training learns the motion.
        frames = np.where(np.isnan(filled) & ~np.isnan(frames), frames, filled)
        if np.isnan(frames).any():
            # Rare (a put-back burst changes what the filler accepts after it): hold the
            # marker's last value, so the recording stays whole.
            frames = _hold_last(frames)
    return ikid.compute_features(frames, feature_set)


def _hold_last(frames: np.ndarray) -> np.ndarray:
    """``frames`` with each NaN replaced by its column's last finite value (the first finite one
    before any)."""
    out = np.array(frames, dtype=np.float64)
    for c in np.flatnonzero(np.isnan(out).any(axis=0)):
        col = out[:, c]
        ok = np.flatnonzero(~np.isnan(col))
        last = np.maximum.accumulate(np.where(~np.isnan(col), np.arange(len(col)), -1))
        out[:, c] = col[np.where(last >= 0, last, ok[0])]
    return out


def feature_len(feature_set: str) -> int:
    """Features per frame of ``feature_set`` (from the core)."""
    return len(ikid.feature_set_info(feature_set)["feature_names"])


def window_index(n: int, window: int, stride: int = 1, offset: int = 0) -> np.ndarray:
    """Indices ``(m, window)`` of the windows of an ``n``-frame recording, newest last."""
    newest = np.arange(window - 1 + offset, n, stride)
    return newest[:, None] - np.arange(window - 1, -1, -1)[None, :]


def windows(rec: Recording, task: str, feature_set: str, window: int, stride: int = 1, offset: int = 0):
    """``(x, y)``: flattened feature windows ``(m, window·F)`` and newest-frame targets ``(m, k)``."""
    f = features(rec, task, feature_set)
    idx = window_index(len(f), window, stride, offset)
    return f[idx].reshape(len(idx), -1), target(rec, task)[idx[:, -1]].astype(np.float32)


def stack_windows(
    recs: Sequence[Recording], task: str, feature_set: str, window: int, stride: int = 1, offset: int = 0
):
    parts = [windows(r, task, feature_set, window, stride, offset) for r in recs]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
