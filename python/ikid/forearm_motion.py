"""How much a recording's forearm moves: the torque the networks leave out.

The torque networks (``wrist-chain``, ``wrist-id``) learned a hand on a forearm at rest. A hand
carried by an accelerating forearm takes torque to follow it, which their torques do not hold
(``ikid track`` carries it: ``crates/ikid/src/tracker/motion.rs``). :class:`ForearmMotion`
measures the forearm markers' acceleration over a recording read in blocks, so ``ikid run``
can say how large the part left out is instead of writing it as if it were nothing (real
wheelchair racing: the forearm plate at 47 m/s² RMS, about 1.4 N·m RMS to carry the hand).
"""

from __future__ import annotations

import numpy as np

from ikid import _native

#: The forearm markers' centroid is averaged over bins this long, s (or a frame's period, if
#: longer), before it is differentiated: the motion that matters is slow next to marker rates.
BIN_S = 0.005
#: The acceleration is the second derivative of a quadratic fitted over this long, s (a
#: Savitzky-Golay filter passing ~10 Hz): marker noise of 0.5 mm at 1 kHz reads ~0.3 m/s².
FIT_S = 0.1
#: Carried torque below this RMS, N·m, is not mentioned: under what the torque networks' own
#: standard deviations hold (e.g. `wrist-chain`'s 0.03-0.09 N·m).
NEGLIGIBLE_NM = 0.05


class ForearmMotion:
    """The forearm markers' (RSP, USP, FAP) centroid over a recording fed a block at a time
    (:meth:`add`, times in s, frames ``(n, 18)`` in m, ikid's lab), binned so memory grows by
    :data:`BIN_S` bins, not frames; :meth:`acceleration` its acceleration where every bin of a
    fit has a frame."""

    def __init__(self) -> None:
        self._t0: float | None = None
        self._bin_s = BIN_S
        self._bins: list[np.ndarray] = []
        self._sums: list[np.ndarray] = []

    def add(self, time: np.ndarray, frames: np.ndarray) -> None:
        time = np.asarray(time, np.float64)
        centroid = np.asarray(frames, np.float64)[:, :9].reshape(-1, 3, 3).mean(axis=1)
        seen = np.all(np.isfinite(centroid), axis=1) & np.isfinite(time)
        if not seen.any():
            return
        if self._t0 is None:
            self._t0 = float(time[seen][0])
            if len(time) > 1:
                self._bin_s = max(BIN_S, float(np.median(np.diff(time))))
        bins = np.floor((time[seen] - self._t0) / self._bin_s + 0.5).astype(np.int64)
        # One row per bin touched in this block: x, y, z sums and the count.
        uniq, inverse = np.unique(bins, return_inverse=True)
        sums = np.zeros((len(uniq), 4))
        np.add.at(sums, inverse, np.column_stack([centroid[seen], np.ones(len(bins))]))
        self._bins.append(uniq)
        self._sums.append(sums)

    def acceleration(self) -> np.ndarray:
        """The centroid's acceleration magnitude, m/s², one value per bin whose whole fit
        window was seen (none if the recording is shorter than a fit). Only the bins seen are
        held: a time gap of any length (two takes joined) costs nothing, and no fit spans it."""
        if not self._bins:
            return np.empty(0)
        bins, inverse = np.unique(np.concatenate(self._bins), return_inverse=True)
        total = np.zeros((len(bins), 4))
        np.add.at(total, inverse, np.concatenate(self._sums))
        centre = total[:, :3] / total[:, 3:]
        half = max(2, round(FIT_S / self._bin_s / 2))
        # The second derivative at the middle of a least-squares quadratic over 2·half + 1 bins.
        j = np.arange(-half, half + 1, dtype=np.float64) * self._bin_s
        second = 2.0 * np.linalg.pinv(np.vander(j, 3, increasing=True))[2]
        runs = np.split(np.arange(len(bins)), np.flatnonzero(np.diff(bins) != 1) + 1)
        found = [
            np.linalg.norm(
                np.stack([np.convolve(centre[run, k], second[::-1], mode="valid") for k in range(3)], axis=1),
                axis=1,
            )
            for run in runs
            if len(run) >= 2 * half + 1
        ]
        return np.concatenate(found) if found else np.empty(0)

    def note(self, length_scale: float = 1.0, mass_scale: float = 1.0) -> str | None:
        """What the torques leave out, for a run's summary; ``None`` if it is negligible
        (:data:`NEGLIGIBLE_NM`). The size is the hand's mass times the acceleration times its
        centre of mass's distance from the wrist: what carrying it takes when the acceleration
        is across the hand (the largest share; the forearm's own turn adds to it)."""
        acc = self.acceleration()
        if len(acc) == 0:
            return None
        hand = _native.body_model(length_scale, mass_scale)["segments"]["hand"]
        lever = float(np.linalg.norm(hand["com"]))
        rms = float(np.sqrt(np.mean(acc**2)))
        carried = hand["mass"] * lever * rms
        if carried < NEGLIGIBLE_NM:
            return None
        p95 = float(np.quantile(acc, 0.95))
        return (
            f"the forearm moves (its markers accelerate {rms:.1f} m/s² RMS, {p95:.0f} at the 95th "
            f"percentile): the torque model takes it at rest, so the torque to carry the hand with it "
            f"(about {carried:.2f} N·m RMS here) is not in these torques; ikid track includes it"
        )
