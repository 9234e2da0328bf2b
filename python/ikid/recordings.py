"""Recordings with known truth: a trial's markers beside its angles (and torques), as
``ikid report --data`` scores a model on them and training learns from them.

A *recording* is one simulated or recorded trial with ground truth per frame. A lab's own
trials (marker files with same-stem ``.mot`` angles and optional ``.sto`` torques) are read by
:func:`load_lab_recordings`; simulated ones come from :meth:`Recording.from_trial`. Noise comes
from the core's seeded noise models (:func:`add_noise`).

The thesis' split, per recording so that no window straddles two parts
(:data:`SPLIT_FRACTIONS`): the first 80 % of every recording trains, the next 10 % validates,
the last 10 % tests, unshuffled.
"""

from __future__ import annotations

import os
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


def target(rec: Recording, task: str) -> np.ndarray:
    return getattr(rec, TASKS[task])


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
        filled, _ = ikid.fill_gaps(markers, unfillable="keep", rate_hz=rate)  # its time constants are in s
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
