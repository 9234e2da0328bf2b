"""Marker layouts on an exam model and the artefacts laid on them.

Layouts (each six markers in ikid's order — three on the forearm, three on the hand — plus
four forearm landmarks, the epicondyles and styloids, probed in the static trial only):

* ``anatomical``: ikid's six points as the model places them (radial and ulnar styloid, dorsal
  forearm; 2nd and 5th metacarpal heads, 3rd metacarpal base).
* ``cluster``: a rigid three-marker plate on the forearm (50 mm triangle, 30 mm above the
  dorsum, 45 % of the way to the elbow) and one on the hand (35 mm triangle, 15 mm above the
  dorsum), each turned at random about its normal and tilted up to 25° (seeded).
* ``skin``: the anatomical points with soft-tissue artefact: each marker displaced, in its
  segment's frame, by a smooth function of the joint coordinates, ``Σ_j v_kj sin(π/2 ·
  (q_j − q0_j)/h_j)`` (h_j the coordinate's largest excursion from neutral), up to 5–15 mm per
  marker (amplitude uniform, directions random, seeded).

Artefacts: ``clean``; ``noise1``/``noise5``: uniform noise ± 1 % / 5 % of each coordinate
column's range over the task trial (ikid's definition, ``crates/ikid/src/noise.rs``: a fixed
forearm's columns have no range, so no noise), the same amplitudes on the calibration trials;
``dropout``: one marker (seeded) missing (NaN) in bursts of 50 ms – 1 s, about one per 3 s
after the first 2 s, one always within the scored last 10 %, and one in each calibration
trial's movement; ``gauss1mm``: Gaussian noise of 1 mm on every marker coordinate, the
forearm's too (what a lab's cameras give: ikid's own noise leaves a fixed forearm clean, and
the Tracker took the forearm's fitted pose as exact until this condition showed the cost), the
same on the calibration trials.
"""

from __future__ import annotations

import math

import numpy as np

from studies.exam.models import WristModel, body_poses, forearm_frame

LAYOUTS = ("anatomical", "cluster", "skin")
ARTEFACTS = ("clean", "noise1", "noise5", "dropout", "gauss1mm")
IKID_ORDER = ("RSP", "USP", "FAP", "MC2", "MC5", "MCB")
LANDMARKS = {  # ikid's landmark name -> the model point and the lab's label
    "lateral_epicondyle": "EPI_LAT",
    "medial_epicondyle": "EPI_MED",
    "radial_styloid": "STY_RAD",
    "ulnar_styloid": "STY_ULN",
}
_ANAT = ("radial_styloid", "ulnar_styloid", "forearm_dorsal", "mc2_head", "mc5_head", "mc3_base")
_ANAT_LABELS = ("R_RSTY", "R_USTY", "R_FA", "R_MCP2", "R_MCP5", "R_MCB3")


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def _plate(rng, centre, normal, side) -> list[np.ndarray]:
    """Three markers of a triangular plate at ``centre``, turned at random about ``normal``
    and tilted up to 25°."""
    normal = normal / np.linalg.norm(normal)
    u = np.cross(normal, (1.0, 0.0, 0.0))
    if np.linalg.norm(u) < 0.3:
        u = np.cross(normal, (0.0, 1.0, 0.0))
    u /= np.linalg.norm(u)
    turn = _rot(normal, rng.uniform(0, 2 * math.pi)) @ _rot(u, rng.uniform(-25, 25) * math.pi / 180)
    radius = side / math.sqrt(3)
    pts = []
    for k, scale in enumerate((1.0, 1.0, 0.8)):  # not equilateral: the order is unambiguous
        ang = 2 * math.pi * k / 3
        p = radius * scale * (math.cos(ang) * u + math.sin(ang) * np.cross(normal, u))
        pts.append(centre + turn @ p)
    return pts


def layout(model: WristModel, name: str, seed: int) -> dict[str, tuple[str, np.ndarray]]:
    """The six markers of layout ``name``: lab label -> (body, point in its frame), ikid's order."""
    pts = {k: np.array(v[1]) for k, v in model.points.items()}
    if name in ("anatomical", "skin"):
        return {lab: (model.points[p][0], pts[p]) for lab, p in zip(_ANAT_LABELS, _ANAT, strict=True)}
    if name != "cluster":
        raise ValueError(f"unknown layout {name!r}; the layouts are {', '.join(LAYOUTS)}")
    rng = np.random.default_rng(seed)
    f, origin = forearm_frame(model)
    mid_epi = (pts["lateral_epicondyle"] + pts["medial_epicondyle"]) / 2
    dorsal = -f[:, 0]
    fore = _plate(rng, origin + 0.45 * (mid_epi - origin) + 0.03 * dorsal, dorsal, 0.05)
    # The hand's dorsum at the neutral posture, in the hand's own frame.
    r0 = body_poses(model, np.array(model.neutral))[model.hand][0]
    hand_dorsal = r0.T @ dorsal
    hand_centre = (pts["mc2_head"] + pts["mc5_head"] + pts["mc3_base"]) / 3 + 0.015 * hand_dorsal
    hand = _plate(rng, hand_centre, hand_dorsal, 0.035)
    out = {f"FA_C{k + 1}": ("ulna", p) for k, p in enumerate(fore)}
    out.update({f"HD_C{k + 1}": (model.hand, p) for k, p in enumerate(hand)})
    return out


def landmark_points(model: WristModel) -> dict[str, tuple[str, np.ndarray]]:
    """The four forearm landmarks: lab label -> (body, point)."""
    return {lab: (model.points[k][0], np.array(model.points[k][1])) for k, lab in LANDMARKS.items()}


class SoftTissue:
    """Each marker's smooth displacement in its segment's frame as a function of the model's
    coordinates (see the module docstring)."""

    def __init__(self, model: WristModel, n_markers: int, seed: int):
        rng = np.random.default_rng(seed)
        self.q0 = np.array(model.neutral)
        lo, hi = model.ranges().T
        self.h = np.maximum(self.q0 - lo, hi - self.q0)
        amp = rng.uniform(0.005, 0.015, n_markers)
        dirs = rng.normal(size=(n_markers, 3, 3))
        dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
        self.v = dirs * (amp / math.sqrt(3))[:, None, None]  # (marker, coordinate, xyz)

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """Displacements ``(n, markers, 3)`` at coordinates ``q`` ``(n, 3)``."""
        s = np.sin(0.5 * math.pi * (q - self.q0) / self.h)
        return np.einsum("nj,mjx->nmx", s, self.v)


def marker_frames(
    points: dict[str, tuple[str, np.ndarray]],
    q: np.ndarray,
    ulna: tuple[np.ndarray, np.ndarray],
    hand: tuple[np.ndarray, np.ndarray],
    sta: SoftTissue | None = None,
) -> np.ndarray:
    """Marker positions ``(n, 3 · markers)`` in the lab from OpenSim's body poses: the ulna's
    (one rotation, translation) and the hand's per frame ``((n, 3, 3), (n, 3))``."""
    n = len(q)
    d = sta(q) if sta is not None else np.zeros((n, len(points), 3))
    out = np.empty((n, 3 * len(points)))
    for k, (body, p) in enumerate(points.values()):
        local = p[None] + d[:, k]
        if body == "ulna":
            pos = local @ ulna[0].T + ulna[1]
        else:
            pos = np.einsum("nij,nj->ni", hand[0], local) + hand[1]
        out[:, 3 * k : 3 * k + 3] = pos
    return out


def noise_amplitude(task: np.ndarray, fraction: float) -> np.ndarray:
    """± ``fraction`` × each column's range over the task trial (NaN ignored)."""
    return fraction * (np.nanmax(task, axis=0) - np.nanmin(task, axis=0))


def add_noise(frames: np.ndarray, amplitude: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return frames + rng.uniform(-1.0, 1.0, frames.shape) * amplitude


#: ``gauss1mm``'s standard deviation, m.
GAUSS_SD_M = 1e-3


def add_gaussian(frames: np.ndarray, sd: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return frames + rng.normal(0.0, 1.0, frames.shape) * sd


def dropouts(n: int, rate: float, rng: np.random.Generator, scored_from: int | None) -> list[tuple[int, int]]:
    """Bursts (start, stop) of 50 ms – 1 s, about one per 3 s after the first 2 s; one starting
    inside the frames from ``scored_from`` when given."""
    bursts, t = [], 2.0 + rng.uniform(0, 3.0)
    while t * rate < n:
        a = int(t * rate)
        bursts.append((a, min(n, a + int(rng.uniform(0.05, 1.0) * rate))))
        t += rng.uniform(2.0, 4.0)
    if scored_from is not None:
        a = int(rng.uniform(scored_from, scored_from + 0.4 * (n - scored_from)))
        bursts.append((a, min(n, a + int(rng.uniform(0.2, 1.0) * rate))))
    return bursts


def drop(frames: np.ndarray, marker: int, bursts: list[tuple[int, int]]) -> np.ndarray:
    out = frames.copy()
    for a, b in bursts:
        out[a:b, 3 * marker : 3 * marker + 3] = np.nan
    return out
