"""The exam's own motion generator (not ikid's ``simulate``): what a session looks like.

A task trial strings together, at random (seeded), the things real sessions hold and ikid's
random trajectories lack: long rests (1.5–4 s, a small postural sway), slow drifts (2–5 s to a
new posture), ordinary movements (0.5–1.2 s, minimum jerk) and fast bursts (0.15–0.35 s), every
coordinate moving at once, targets over 85 % of each of the model's ranges around its neutral.
The calibration trials: a static trial (the neutral posture held, sway below 1°) and a
functional trial (1 s neutral, then circles and figure-eights of flexion and deviation with
pronation held at neutral, as a lab would record for a functional fit).
"""

from __future__ import annotations

import math

import numpy as np

from studies.exam.models import WristModel

DEG = math.pi / 180


def _min_jerk(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)[:, None]
    return a + (b - a) * (10 * s**3 - 15 * s**4 + 6 * s**5)


def _sway(rng: np.random.Generator, n: int, rate: float, amplitude: float) -> np.ndarray:
    """Smooth small sway (sum of three slow sines per coordinate, ± ``amplitude`` rad)."""
    t = np.arange(n)[:, None] / rate
    out = np.zeros((n, 3))
    for _ in range(3):
        f = rng.uniform(0.1, 0.6, 3)
        out += np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi, 3))
    return amplitude / 3 * out


def task(model: WristModel, seed: int, duration: float, rate: float) -> np.ndarray:
    """Model coordinates ``(n, 3)`` of a task trial (see the module docstring)."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate))
    lo, hi = model.ranges().T
    q0 = np.array(model.neutral)
    span_lo, span_hi = q0 + 0.85 * (lo - q0), q0 + 0.85 * (hi - q0)
    pieces, here = [np.repeat(q0[None], int(0.5 * rate), 0)], q0.copy()
    while sum(len(p) for p in pieces) < n:
        kind = rng.choice(["rest", "drift", "move", "burst"], p=[0.3, 0.2, 0.35, 0.15])
        if kind == "rest":
            m = int(rng.uniform(1.5, 4.0) * rate)
            pieces.append(here + _sway(rng, m, rate, 0.5 * DEG))
            continue
        if kind == "drift":
            target = np.clip(here + rng.normal(0, 10 * DEG, 3), span_lo, span_hi)
            m = int(rng.uniform(2.0, 5.0) * rate)
        else:
            target = rng.uniform(span_lo, span_hi)
            m = int((rng.uniform(0.5, 1.2) if kind == "move" else rng.uniform(0.15, 0.35)) * rate)
            if kind == "burst":  # a quick flick: a third of the way, not across the range
                target = here + (target - here) / 3
        start = pieces[-1][-1]
        pieces.append(_min_jerk(start, target, m))
        here = target
    q = np.concatenate(pieces)[:n]
    # Sways end where they started only approximately: smooth every joint (5 ms mean twice).
    return _smooth(q, max(1, int(0.005 * rate)))


def _smooth(q: np.ndarray, w: int) -> np.ndarray:
    for _ in range(2):
        pad = np.concatenate([np.repeat(q[:1], w, 0), q, np.repeat(q[-1:], w, 0)])
        c = np.cumsum(pad, axis=0)
        q = (c[2 * w :] - c[: -2 * w]) / (2 * w)
    return q


def static(model: WristModel, seed: int, duration: float, rate: float) -> np.ndarray:
    """The neutral posture held ``duration`` s, sway < 1°."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate))
    return np.array(model.neutral) + _sway(rng, n, rate, 0.8 * DEG)


def functional(model: WristModel, seed: int, duration: float, rate: float) -> np.ndarray:
    """1 s neutral, then flexion and deviation together (circles, figure-eights), pronation held."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate))
    n0 = int(rate)
    lo, hi = model.ranges().T
    q0 = np.array(model.neutral)
    t = np.arange(n - n0) / rate
    f = rng.uniform(0.4, 0.6)
    ramp = np.minimum(1.0, t / 1.0)  # start from neutral
    amp_f = 0.5 * min(q0[1] - lo[1], hi[1] - q0[1])
    amp_d = 0.6 * min(q0[2] - lo[2], hi[2] - q0[2])
    mv = np.zeros((n - n0, 3))
    mv[:, 1] = amp_f * ramp * np.sin(2 * np.pi * f * t)
    # circles for the first half, figure-eights (deviation at twice the rate) after
    half = t < t[-1] / 2
    mv[:, 2] = amp_d * ramp * np.where(half, np.cos(2 * np.pi * f * t), np.sin(4 * np.pi * f * t))
    q = np.concatenate([np.repeat(q0[None], n0, 0), q0 + mv])
    q += _sway(rng, n, rate, 0.3 * DEG) * np.array([1.0, 0.0, 0.0])  # pronation held, not frozen
    return _smooth(q, max(1, int(0.005 * rate)))


def derivatives(q: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations by central differences (the trajectories are smooth)."""
    qd = np.gradient(q, 1.0 / rate, axis=0)
    return qd, np.gradient(qd, 1.0 / rate, axis=0)
