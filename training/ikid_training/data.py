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


# --- sessions: what labs record beyond the random protocol -------------------------------------

#: Defaults of a ``[data.sessions]`` table (see :func:`session_specs`).
SESSION_DEFAULTS: dict[str, Any] = {
    "seeds": [2000],
    "duration": 60.0,
    # Target postures, degrees, per coordinate (s_p, e_f, ad_ab): past the anatomical ranges of
    # the body model, where real wrists and their calibrations go (docs/realdata.md: pyomeca's
    # ulnar deviation to 46°, racing's supination to 120° and, near e_f = -80° where the Y-Z-X
    # angles couple, ad_ab to -107°). e_f stays 10° short of the decomposition's singularity.
    "ranges_deg": [[-125.0, 125.0], [-80.0, 80.0], [-110.0, 55.0]],
    # Share of targets drawn from the anatomical ranges instead (most of a session is there).
    "anatomical_share": 0.5,
    # Movement durations, s: ordinary reaches, fast bursts (real racing turns the forearm 60° in
    # 40 ms) and slow drifts; and the holds between them (sessions rest between movements).
    "move_s": [0.25, 1.0],
    "burst_s": [0.04, 0.25],
    "burst_share": 0.3,
    "drift_s": [1.5, 4.0],
    "drift_share": 0.1,
    "hold_s": [0.0, 2.0],
    "hold_share": 0.4,
    # Share of moves along the shortest rotation of the hand (min-jerk in its rotation angle)
    # instead of each angle on its own: near e_f = ±90° the Y-Z-X angles s_p and ad_ab then swing
    # together and fast, as real ones do (racing: > 1200°/s on a fifth of its frames). Moves whose
    # angles would leave ranges_deg are made angle by angle. 0: none (the default).
    "rotation_share": 0.0,
    # Bodies: shoulder poses (degrees of flexion) and subject sizes of the sessions; by default
    # the [data] table's.
    "shoulders_deg": None,
    "length_scales": None,
}


def session_q(spec: dict[str, Any], rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angles, velocities and accelerations ``(n, 3)`` of one session at ``rate_hz``: minimum-jerk
    moves between targets (the simulator's profile, ``crates/ikid-sim/src/protocol.rs``), each
    coordinate moving with probability 0.8, a return to neutral 15 % of the time, reaches, bursts
    and drifts mixed, holds between them. Seeded by ``spec["seed"]``."""
    rng = np.random.default_rng(int(spec["seed"]))
    wide = np.radians(np.asarray(spec["ranges_deg"], np.float64))
    rotation_share = float(spec.get("rotation_share", 0.0))
    anat = 0.95 * np.array([c["range"] for c in ikid.body_model()["coordinates"]], np.float64)
    at = np.zeros(3)
    t, steps = 0.0, []  # (from, to, start, duration)
    while t < spec["duration"]:
        u = rng.uniform()
        if u < spec["burst_share"]:
            duration = rng.uniform(*spec["burst_s"])
        elif u < spec["burst_share"] + spec["drift_share"]:
            duration = rng.uniform(*spec["drift_s"])
        else:
            duration = rng.uniform(*spec["move_s"])
        if rng.uniform() < 0.15:
            to = np.zeros(3)
        else:
            box = anat if rng.uniform() < spec["anatomical_share"] else wide
            to = np.where(rng.uniform(size=3) < 0.8, rng.uniform(box[:, 0], box[:, 1]), at)
            if duration >= spec["drift_s"][0]:  # a drift: a slow, small change
                to = at + 0.15 * (to - at)
        # Drawn only with a share (a share of 0 keeps the sessions made before it existed).
        by_rotation = rotation_share > 0 and rng.uniform() < rotation_share and not np.array_equal(at, to)
        steps.append((at, to, t, duration, by_rotation))
        t += duration
        if rng.uniform() < spec["hold_share"]:
            hold = rng.uniform(*spec["hold_s"])
            steps.append((to, to, t, hold, False))
            t += hold
        at = to
    time = np.arange(int(np.floor(t * rate_hz)) + 1) / rate_hz
    starts = np.array([s[2] for s in steps])
    i = np.clip(np.searchsorted(starts, time, side="right") - 1, 0, len(steps) - 1)
    a = np.array([s[0] for s in steps])[i]
    b = np.array([s[1] for s in steps])[i]
    d = np.array([s[3] for s in steps])[i][:, None]
    x = np.clip((time[:, None] - starts[i][:, None]) / np.maximum(d, 1e-12), 0.0, 1.0)
    p = x**3 * (10 - 15 * x + 6 * x**2)
    dp = 30 * x**2 * (1 - x) ** 2 / d
    ddp = 60 * x * (1 - x) * (1 - 2 * x) / d**2
    q, qd, qdd = a + (b - a) * p, (b - a) * dp, (b - a) * ddp
    turned = np.zeros(len(time), bool)
    for k, (q0, q1, _, _, by_rotation) in enumerate(steps):
        rows = np.flatnonzero(i == k)
        if not by_rotation or len(rows) == 0:
            continue
        r0 = hand_rotation(q0[None])[0]
        turn = rotation_vector(r0.T @ hand_rotation(q1[None])[0])
        path = hand_angles(r0[None] @ rotation_matrix(p[rows] * turn[None]))
        if np.all((path >= wide[:, 0] - 1e-9) & (path <= wide[:, 1] + 1e-9)):
            q[rows], turned[rows] = path, True
    if turned.any():  # rates along a turned path: differences of its angles
        qd[turned] = np.gradient(q, 1.0 / rate_hz, axis=0)[turned]
        qdd[turned] = np.gradient(qd, 1.0 / rate_hz, axis=0)[turned]
    return q, qd, qdd


def _axis_rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    r = np.zeros(angle.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[..., axis, axis] = 1.0
    r[..., i, i] = c
    r[..., j, j] = c
    r[..., i, j] = -s
    r[..., j, i] = s
    return r


def hand_rotation(q: np.ndarray) -> np.ndarray:
    """The hand's rotation in the forearm for angles ``q`` ``(n, 3)``: Rot(-y, s_p) Rot(z, e_f)
    Rot(x, ad_ab), the body model's Y-Z-X (``crates/ikid/src/body.rs``)."""
    return _axis_rotation(1, -q[:, 0]) @ _axis_rotation(2, q[:, 1]) @ _axis_rotation(0, q[:, 2])


def hand_angles(r: np.ndarray) -> np.ndarray:
    """The angles ``(n, 3)`` of rotations ``r`` ``(n, 3, 3)`` (:func:`hand_rotation` inverted; e_f in
    [-90°, 90°], the others in (-180°, 180°]), as the ``angles`` feature set reads them."""
    e_f = np.arcsin(np.clip(r[:, 1, 0], -1.0, 1.0))
    return np.stack([-np.arctan2(-r[:, 2, 0], r[:, 0, 0]), e_f, np.arctan2(-r[:, 1, 2], r[:, 1, 1])], axis=1)


def rotation_vector(r: np.ndarray) -> np.ndarray:
    """The rotation vector (axis × angle, angle < 180°) of rotation matrix ``r``."""
    angle = np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    n = np.linalg.norm(axis)
    return np.zeros(3) if n < 1e-12 else axis / n * angle


def rotation_matrix(v: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(n, 3, 3)`` of rotation vectors ``v`` ``(n, 3)`` (Rodrigues)."""
    angle = np.linalg.norm(v, axis=1)
    k = v / np.where(angle > 0, angle, 1.0)[:, None]
    kx = np.zeros((len(v), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    kx[:, 1, 0], kx[:, 2, 0], kx[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * kx + (1 - c) * kx @ kx


def session_specs(sessions: dict[str, Any], shoulders_deg: Sequence[float], length_scales: Sequence[float]):
    """Specs for every (seed, shoulder, size) combination of a ``[data.sessions]`` table (keys and
    defaults: :data:`SESSION_DEFAULTS`), a distinct seed per combination as :func:`recording_set`.
    A session's seed seeds :func:`session_q` (NumPy), not the simulator's random protocol: it
    shares no trajectory with a ``random`` recording of the same number."""
    unknown = set(sessions) - set(SESSION_DEFAULTS)
    if unknown:
        known = sorted(SESSION_DEFAULTS)
        raise ValueError(f"unknown [data.sessions] keys {sorted(unknown)} (known: {known})")
    cfg = {**SESSION_DEFAULTS, **sessions}
    specs, k = [], 0
    for shoulder in cfg["shoulders_deg"] or shoulders_deg:
        for scale in cfg["length_scales"] or length_scales:
            for seed in cfg["seeds"]:
                bodies = ("seeds", "shoulders_deg", "length_scales")
                spec = {key: v for key, v in cfg.items() if key not in bodies}
                spec.update(
                    name=f"session_s{shoulder:+.0f}_x{scale:.2f}_seed{seed + k}",
                    seed=seed + k,
                    shoulder_deg=shoulder,
                    length_scale=scale,
                    mass_scale=scale**3,
                )
                specs.append(spec)
            k += 1000
    return specs


def simulate_session(spec: dict[str, Any], rate_hz: float = 1000.0) -> Recording:
    """One session (:func:`session_q`) as the simulator records it: the body model's markers for
    the prescribed angles (what ``ikid.simulate`` gives for a prescribed motion, to 1e-16 m) and
    the torques of its inverse dynamics."""
    q, qd, qdd = session_q(spec, rate_hz)
    body = {
        "shoulder_flexion": math.radians(spec["shoulder_deg"]),
        "length_scale": spec["length_scale"],
        "mass_scale": spec["mass_scale"],
    }
    markers = ikid._native.forward_markers(q, **body)
    tau = ikid._native.reference_id(q, qd, qdd, **body)
    meta = {
        "simulator": ikid.SIMULATOR,
        "protocol": "session",
        "seed": spec["seed"],
        "duration_s": len(q) / rate_hz,
        "shoulder_flexion_rad": body["shoulder_flexion"],
        "length_scale": spec["length_scale"],
        "mass_scale": spec["mass_scale"],
        "rate_hz": rate_hz,
    }
    return Recording(spec["name"], markers, q, qd, qdd, tau, meta)


def resampled(rec: Recording, from_hz: float, kind: str, level: float, seed: int) -> Recording:
    """``rec`` (at the simulator's 1 kHz) as a recording at ``from_hz`` reaches a 1 kHz model
    through ``ikid.pipeline``: every ``1000 / from_hz``-th frame kept, noise added to those
    (:func:`add_noise`), the frames between made by the pipeline's own cubic Hermite
    (``_local_slopes``, ``_hermite``), the truth left at 1 kHz. Ends at the last kept frame."""
    from ikid.pipeline import _hermite, _local_slopes

    step = int(round(1000.0 / from_hz))
    if step < 1 or abs(1000.0 / step - from_hz) > 1e-9 * from_hz:
        raise ValueError(f"resampled_from_hz {from_hz} is not 1000 Hz divided by a whole number")
    kept = np.arange(0, len(rec), step)
    at_low_rate = Recording(
        rec.name, rec.markers[kept], rec.q[kept], rec.qd[kept], rec.qdd[kept], rec.tau[kept]
    )
    low = add_noise(at_low_rate, kind, level, seed)
    n = int(kept[-1]) + 1
    t_low, t = kept / 1000.0, np.arange(n) / 1000.0
    slopes = _local_slopes(t_low, low.markers, gap=1.5 * step / 1000.0)
    markers, _ = _hermite(t_low, low.markers, slopes, t, np.inf)
    markers[kept] = low.markers  # a frame on a kept one is that frame, exactly (as the pipeline)
    noise = {"kind": kind, "level": level, "seed": seed}
    meta = {**rec.meta, "resampled_from_hz": from_hz, "noise": noise}
    return Recording(rec.name, markers, rec.q[:n], rec.qd[:n], rec.qdd[:n], rec.tau[:n], meta)


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
