"""Simulated trials (rapier wrist model in the Rust core) and their files.

``simulate`` runs one trial; ``Trial.save`` writes ``<stem>.npz`` (all arrays + metadata)
and the OpenSim files ``<stem>.trc`` (markers, mm), ``<stem>.mot`` (angles, degrees) and
``<stem>.sto`` (torques), so the same trial opens in OpenSim.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ikid import _native
from ikid.io import write_mot, write_sto, write_trc
from ikid.io._atomic import Incomplete, atomic_output, atomic_outputs

#: Noise models by name, each ``fn(markers, seed, **params) -> markers``.
NOISE: dict[str, Callable[..., np.ndarray]] = {
    "uniform": lambda m, seed, fraction: _native.noise_uniform(m, fraction, seed),
    "gaussian": lambda m, seed, sigma: _native.noise_gaussian(m, sigma, seed),
    "drift": lambda m, seed, amplitude, rate_hz: _native.noise_drift(m, amplitude, rate_hz, seed),
    "occlusion": lambda m, seed, bursts_per_second, min_s, max_s, rate_hz, markers_affected=(): (
        _native.noise_occlusion(m, bursts_per_second, min_s, max_s, rate_hz, seed, list(markers_affected))
    ),
}


@dataclass
class Trial:
    """One simulated recording: ground truth per frame, SI units."""

    time: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    markers: np.ndarray
    q_ref: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def rate_hz(self) -> float:
        return float(self.metadata["rate_hz"])

    def with_noise(self, kind: str, seed: int, **params: Any) -> Trial:
        """A copy whose markers carry noise model ``kind`` (see ``NOISE``), recorded in metadata."""
        if kind not in NOISE:
            raise _native.InputError(f"unknown noise {kind!r} (known: {', '.join(NOISE)})")
        markers = NOISE[kind](self.markers, seed, **params)
        meta = {
            **self.metadata,
            "noise": [*self.metadata.get("noise", []), {"kind": kind, "seed": seed, **params}],
        }
        return Trial(self.time, self.q, self.qd, self.qdd, self.tau, markers, self.q_ref, meta)

    def save(self, stem: str | os.PathLike[str]) -> list[Path]:
        """Write ``stem.npz``, ``.trc``, ``.mot``, ``.sto``; returns the paths. The four files
        replace any old ones together, only once all of them are written and checked (see
        :func:`ikid.io._atomic.atomic_outputs`); a failed write is an :class:`ikid.WriteError`
        naming the file and leaves the old four as they were."""
        stem = Path(stem)
        stem.parent.mkdir(parents=True, exist_ok=True)

        def named(ext: str) -> Path:  # stem + ext, even if the stem holds a dot ("trial.v2")
            return stem.with_name(stem.name + ext)

        npz = named(".npz")
        arrays = {k: getattr(self, k) for k in ("time", "q", "qd", "qdd", "tau", "markers", "q_ref")}
        with atomic_outputs():
            with atomic_output(
                npz, suffix=".npz", verify=lambda tmp: _check_npz(tmp, [*arrays, "metadata"])
            ) as tmp:
                np.savez_compressed(tmp, **arrays, metadata=np.array(json.dumps(self.metadata)))
            return [
                npz,
                write_trc(named(".trc"), self.time, self.markers, self.rate_hz),
                write_mot(named(".mot"), self.time, self.q),
                write_sto(named(".sto"), self.time, self.tau),
            ]

    @staticmethod
    def load(path: str | os.PathLike[str]) -> Trial:
        """Read a trial written by :meth:`save` (its ``.npz``). Like every reader, only a
        regular file within ikid's size limit is opened (:func:`ikid.io.markers.check_readable`:
        a directory, a pipe or ``/dev/zero`` is an :class:`ikid.ReadError` at once); a file that
        is not such an archive is a :class:`ikid.io.FileFormatError` naming it."""
        import zipfile

        from ikid.io.markers import FileFormatError, check_readable

        path = Path(path)
        check_readable(path, "a trial's .npz archive (Trial.save)")
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["metadata"]))
                time, q, qd, qdd, tau, markers, q_ref = (
                    z[k] for k in ("time", "q", "qd", "qdd", "tau", "markers", "q_ref")
                )
        except (ValueError, EOFError, KeyError, TypeError, zipfile.BadZipFile) as e:
            # A .npy (no context manager), pickled data, a truncated archive, a missing array.
            raise FileFormatError(f"{path}: not a trial archive written by Trial.save ({e})") from None
        return Trial(time, q, qd, qdd, tau, markers, q_ref, metadata=meta)


def _check_npz(path: Path, names: list[str]) -> None:
    """:class:`Incomplete` unless ``path`` is a whole zip archive holding an array per name
    (its central directory, at the end of the file, lists them)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            held = {n.removesuffix(".npy") for n in z.namelist()}
    except (zipfile.BadZipFile, OSError) as e:
        raise Incomplete(f"read back an unreadable archive ({e})") from None
    if missing := [n for n in names if n not in held]:
        raise Incomplete(f"read back an archive without {', '.join(missing)}")


def simulate(
    protocol: str = "random",
    *,
    seed: int = 0,
    duration: float = 10.0,
    shoulder_flexion: float = 0.0,
    length_scale: float = 1.0,
    mass_scale: float = 1.0,
    dt: float = 0.001,
    output_every: int = 1,
    substeps: int = 1,
    octants: list[str] | None = None,
) -> Trial:
    """Simulate one trial. ``protocol``: ``"thesis"`` (42 single-DoF sigmoid movements) or
    ``"random"`` (smooth multi-DoF reaching for ``duration`` s, seeded). ``shoulder_flexion``
    in radians; the subject is the default one scaled by ``length_scale`` / ``mass_scale``.
    ``octants`` restricts the random protocol's targets to joint-sign octants given as sign
    strings of (s_p, e_f, ad_ab), e.g. ``["+-+"]`` (hold-out movement types)."""
    raw = _native.simulate(
        protocol,
        seed,
        duration,
        shoulder_flexion,
        length_scale,
        mass_scale,
        dt,
        substeps,
        output_every,
        octants,
    )
    meta = {
        "simulator": _native.SIMULATOR,
        "protocol": raw.pop("protocol"),
        "seed": seed if protocol == "random" else None,
        "octants": octants,
        # The random protocol runs at least `duration`: record what was simulated.
        "duration_s": float(len(raw["time"]) * dt),
        "shoulder_flexion_rad": shoulder_flexion,
        "length_scale": length_scale,
        "mass_scale": mass_scale,
        "dt": dt,
        "substeps": substeps,
        "rate_hz": 1.0 / (dt * output_every),
        "coordinates": [c[0] for c in _native.COORDINATES],
        "markers": [m[0] for m in _native.MARKERS],
        "units": {"q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau": "N*m", "markers": "m", "time": "s"},
    }
    return Trial(**raw, metadata=meta)


__all__ = ["NOISE", "Trial", "simulate"]
