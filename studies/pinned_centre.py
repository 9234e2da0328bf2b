"""Does turning the hand about the mid-styloids help on real markers? (issue #28)

On the exam's skin markers (docs/exam.md, Gonzalez) the lab-model EKF, whose hand turns about
the mid-styloids, is as good as ikid although its model is 4° off on clean markers: pinning the
hand's turn to that point damps the skin's slide there. Before adopting such a constraint for
ikid's hand measurement, this measures it where the truth is real: the recordings of
``../shared/realdata`` against their independent references, scored as ``tools/realdata.py``
scores (geodesic RMS over the reference's gimbal-safe frames).

Per frame, both ways from the same calibration (the landmarks' ISB forearm frame at the
reference's neutral frames, the hand's markers there as the neutral hand):

- **free**: the hand's orientation in the forearm by a rigid least-squares fit of its three
  markers (what ikid's calibrated per-frame solution does);
- **pinned**: the same fit with the mid-styloids held fixed (a turn about that point only, the
  EKF model's joint).

    python -m studies.pinned_centre      # one line per recording; no file written
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "realdata"


def _tool():
    spec = importlib.util.spec_from_file_location("realdata_tool", REPO / "tools" / "realdata.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["realdata_tool"] = module
    spec.loader.exec_module(module)
    return module


def fit_rotation(template: np.ndarray, seen: np.ndarray, pinned: bool) -> np.ndarray:
    """The rotation carrying ``template`` (k, 3) onto ``seen`` (k, 3) by least squares (Kabsch):
    about their centroids, or about the origin (``pinned``)."""
    p, q = (template, seen) if pinned else (template - template.mean(0), seen - seen.mean(0))
    u, _, vt = np.linalg.svd(p.T @ q)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def ikid_angles(r: np.ndarray) -> np.ndarray:
    """ikid's (s_p, e_f, ad_ab) of ``R = Rot(-y, s_p) Rot(z, e_f) Rot(x, ad_ab)`` (body.rs)."""
    e_f = np.arcsin(np.clip(r[1, 0], -1.0, 1.0))
    return np.array([np.arctan2(r[2, 0], r[0, 0]), e_f, np.arctan2(-r[1, 2], r[1, 1])])


def run(tool, rec) -> dict[str, float]:
    from ikid.io import read_markers

    ref = tool.read_reference(DATA, rec.reference)
    neutral = ref["meta"]["neutral_frames"]
    static = read_markers(DATA / rec.calibration_file)

    def median(label: str) -> np.ndarray:
        return np.nanmedian(static.marker(label)[neutral], axis=0)

    forearm_labels = [rec.markers[m] for m in ("RSP", "USP", "FAP")]
    hand_labels = [rec.markers[m] for m in ("MC2", "MC5", "MCB")]
    lm = {k: median(v) for k, v in rec.landmarks.items()}
    wrist = (lm["radial_styloid"] + lm["ulnar_styloid"]) / 2
    y = (lm["lateral_epicondyle"] + lm["medial_epicondyle"]) / 2 - wrist
    y /= np.linalg.norm(y)
    x = np.cross(y, lm["radial_styloid"] - lm["ulnar_styloid"])
    x /= np.linalg.norm(x)
    axes = np.stack([x, y, np.cross(x, y)], axis=1)  # the ISB forearm frame, columns
    forearm = (np.array([median(v) for v in forearm_labels]) - wrist) @ axes
    hand = (np.array([median(v) for v in hand_labels]) - wrist) @ axes

    trial = read_markers(DATA / rec.trial)
    out: dict[str, float] = {}
    for name, pinned in (("free", False), ("pinned", True)):
        q = np.full((len(trial), 3), np.nan)
        for i in range(len(trial)):
            f = np.array([trial.marker(v)[i] for v in forearm_labels])
            h = np.array([trial.marker(v)[i] for v in hand_labels])
            if not (np.isfinite(f).all() and np.isfinite(h).all()):
                continue
            rf = fit_rotation(forearm, f - f.mean(0), pinned=False)
            origin = f.mean(0) - rf @ forearm.mean(0)  # lab = rf · forearm-frame + origin
            q[i] = ikid_angles(fit_rotation(hand, (h - origin) @ rf, pinned))
        out[name] = tool.score(trial.time, q, ref, tol=1.5 / trial.rate_hz).rms_gimbal
    return out


def main() -> int:
    tool = _tool()
    for rec in tool.RECORDINGS:
        r = run(tool, rec)
        print(
            f"{rec.name}: free rigid fit {r['free']:.2f}°, pinned at the mid-styloids {r['pinned']:.2f}° "
            "geodesic RMS"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
