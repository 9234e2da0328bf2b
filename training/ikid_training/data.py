"""Datasets for training and evaluation: recordings, splits, noise, windows.

A *recording* is one simulated (or loaded) trial with ground truth per frame. Features are
computed by the Rust core (``ikid.compute_features``) exactly as at inference; noise comes
from the core's seeded noise models. A *window* is ``window`` consecutive frames' features,
concatenated oldest first, labelled with the newest frame's target (causal, no look-ahead).

Splits, all per recording so that no window straddles two parts:

- ``thesis``: the first 80 % of every recording trains, the next 10 % validates, the last
  10 % tests, unshuffled (the thesis' protocol).
- held-out sets (movement types, a shoulder pose, subject sizes) are whole recordings that
  training never sees; see :func:`recording_set`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import ikid

#: What each task predicts (the recording's array); its inputs follow from the feature set.
TASKS = {"ik": "q", "id": "tau", "chain": "tau"}

SPLIT_FRACTIONS = {"train": (0.0, 0.8), "val": (0.8, 0.9), "test": (0.9, 1.0)}


@dataclass
class Recording:
    """One trial: markers (m) and ground truth (rad, rad/s, rad/s², N·m), one row per frame."""

    name: str
    markers: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.q)

    @staticmethod
    def from_trial(name: str, trial: ikid.Trial) -> Recording:
        return Recording(name, trial.markers, trial.q, trial.qd, trial.qdd, trial.tau, dict(trial.metadata))

    def part(self, split: str) -> Recording:
        """The frames of one part of the thesis split (``train``, ``val``, ``test``, ``all``)."""
        if split == "all":
            return self
        lo, hi = SPLIT_FRACTIONS[split]
        a, b = int(round(lo * len(self))), int(round(hi * len(self)))
        markers, q, qd, qdd, tau = (x[a:b] for x in self.arrays())
        return Recording(f"{self.name}[{split}]", markers, q, qd, qdd, tau, meta=self.meta)

    def frames(self, feature_set: str) -> np.ndarray:
        """The raw frames a model on ``feature_set`` reads: joint states (q, q̇, q̈) or markers."""
        if ikid.feature_set_info(feature_set)["frame_kind"] == "joint_state":
            return np.concatenate([self.q, self.qd, self.qdd], axis=1)
        return self.markers

    def arrays(self) -> tuple[np.ndarray, ...]:
        return self.markers, self.q, self.qd, self.qdd, self.tau

    def with_markers(self, markers: np.ndarray, **note: Any) -> Recording:
        return Recording(self.name, markers, self.q, self.qd, self.qdd, self.tau, {**self.meta, **note})


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


def add_noise(rec: Recording, kind: str, level: float, seed: int) -> Recording:
    """``rec`` with marker noise from the core: ``uniform`` (±level of each column's range, the
    thesis' definition) or ``gaussian`` (σ = level metres). Level 0 returns ``rec``."""
    if level == 0:
        return rec
    if kind == "uniform":
        markers = ikid._native.noise_uniform(rec.markers, level, seed)
    elif kind == "gaussian":
        markers = ikid._native.noise_gaussian(rec.markers, level, seed)
    else:
        raise ValueError(f"unknown noise kind {kind!r} (uniform, gaussian)")
    return rec.with_markers(markers, noise={"kind": kind, "level": level, "seed": seed})


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
    _, filled = ikid.fill_gaps(markers, unfillable="keep")
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
        filled = ikid.fill_gaps(frames, unfillable="keep")[0]
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


def target(rec: Recording, task: str) -> np.ndarray:
    return getattr(rec, TASKS[task])


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


# --- a lab's own files -----------------------------------------------------------------------

#: Shortest stretch of usable frames kept as a recording (shorter ones teach little and
#: cannot be split 80/10/10 into whole windows).
MIN_LAB_FRAMES = 200


def lab_trials(folder: str | os.PathLike[str]) -> list[Path]:
    """The marker files (``.c3d``/``.trc``) of a lab folder that have their angles (``.mot``) beside them."""
    from ikid.io import MARKER_READERS

    folder = Path(folder)
    if not folder.is_dir():
        raise ikid.InputError(f"{folder}: not a folder (expected marker files with same-stem .mot angles)")
    markers = sorted(p for p in folder.iterdir() if p.suffix.lower() in MARKER_READERS and p.is_file())
    if not markers:
        raise ikid.InputError(f"{folder}: no marker files ({', '.join(MARKER_READERS)})")
    without = [p.name for p in markers if not p.with_suffix(".mot").exists()]
    if without:
        raise ikid.InputError(
            f"{folder}: {', '.join(without[:5])}{' ...' if len(without) > 5 else ''} "
            f"ha{'s' if len(without) == 1 else 've'} no same-stem .mot beside it (the angles "
            "to learn); every trial needs one"
        )
    return markers


def _aligned(
    name: str, what: str, t_markers: np.ndarray, t: np.ndarray, values: np.ndarray, rate_hz: float
) -> np.ndarray:
    """``values`` if sampled at the marker frames' times (to a quarter frame), else an error."""
    if len(t) != len(t_markers) or np.max(np.abs(t - t_markers)) > 0.25 / rate_hz:
        raise ikid.InputError(
            f"{name}: {what} has {len(t)} rows ({t[0]:.4g}-{t[-1]:.4g} s) but the marker file has "
            f"{len(t_markers)} frames ({t_markers[0]:.4g}-{t_markers[-1]:.4g} s at {rate_hz:g} Hz); "
            "write them at the marker frames' times"
        )
    return values


def load_lab_recordings(
    folder: str | os.PathLike[str],
    marker_map: str | os.PathLike[str] | None = None,
    rate_hz: float | None = None,
) -> list[Recording]:
    """A lab's trials as recordings: every marker file in ``folder`` with its same-stem ``.mot``
    (angles, required) and ``.sto`` (torques, optional: NaN without), labels mapped by
    ``marker_map`` (TOML, see ``ikid map-template``).

    All trials must share one frame rate, or ``rate_hz`` resamples them all (cubic Hermite,
    see :mod:`ikid.io.resample`). Missing markers are filled by the core's gap filler exactly
    as a ``"fill"`` stream does; stretches it cannot fill split a trial into recordings
    (``stem@first_frame``), shorter ones than :data:`MIN_LAB_FRAMES` are left out.
    Velocities and accelerations are central differences of the angles (offline labels).
    """
    from ikid.io import MarkerMap, read_markers, read_mot, read_sto, resample
    from ikid.pipeline import same_rate

    mapping = MarkerMap.load(marker_map) if marker_map else None
    recs: list[Recording] = []
    rates: dict[str, float] = {}
    for path in lab_trials(folder):
        data = read_markers(path)
        markers = data.frames(mapping)
        time = data.time
        q = _aligned(
            path.name, path.with_suffix(".mot").name, time, *read_mot(path.with_suffix(".mot")), data.rate_hz
        )
        sto = path.with_suffix(".sto")
        tau = (
            _aligned(path.name, sto.name, time, *read_sto(sto), data.rate_hz)
            if sto.exists()
            else np.full_like(q, np.nan)
        )
        rate = data.rate_hz
        if rate_hz is not None and not same_rate(rate, rate_hz):
            table = np.concatenate([markers, q, tau], axis=1)
            time, table = resample(time, table, rate_hz)
            markers, q, tau = table[:, :18], table[:, 18:21], table[:, 21:24]
            rate = rate_hz
        rates[path.name] = rate
        filled, _ = ikid.fill_gaps(markers, unfillable="keep")
        usable = np.isfinite(filled).all(axis=1) & np.isfinite(q).all(axis=1)
        # Contiguous runs of usable frames.
        edges = np.flatnonzero(np.diff(np.concatenate([[0], usable.astype(np.int8), [0]])))
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            if stop - start < MIN_LAB_FRAMES:
                continue
            sl = slice(start, stop)
            t = time[sl]
            qd = np.gradient(q[sl], t, axis=0)
            name = path.stem if (start, stop) == (0, len(time)) else f"{path.stem}@{start}"
            meta = {
                "source": str(path),
                "rate_hz": rate,
                "first_frame": int(start),
                "filled_frames": int((~np.isfinite(markers[sl]).all(axis=1)).sum()),
            }
            recs.append(
                Recording(
                    name, filled[sl].astype(np.float64), q[sl], qd, np.gradient(qd, t, axis=0), tau[sl], meta
                )
            )
    first = next(iter(rates.values()))
    if not all(same_rate(r, first) for r in rates.values()):
        listing = ", ".join(f"{k} {v:g} Hz" for k, v in rates.items())
        raise ikid.InputError(
            f"{folder}: trials at different frame rates ({listing}); resample them to one (rate_hz / --rate)"
        )
    if not recs:
        raise ikid.InputError(
            f"{folder}: no stretch of {MIN_LAB_FRAMES}+ frames with every marker present or fillable"
        )
    return recs
