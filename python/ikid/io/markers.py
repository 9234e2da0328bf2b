"""Marker trajectories as read from a lab's file, before they become ikid frames.

:class:`MarkerData` holds any labels in metres (NaN = missing); :meth:`MarkerData.frames`
turns it into ikid's ``(n, 18)`` frames through a :class:`~ikid.io.mapping.MarkerMap`,
checking what a network cannot: a label that is not there, a marker that is never seen,
coordinates that cannot be in the units the file claims.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ikid import _native
from ikid.io._common import (
    MAX_FILE_BYTES,
    UNITS,
    FileFormatError,
    check_readable,
    ikid_marker_names,
    is_float,
    read_bytes,
    read_text,
    read_text_lines,
    unit_scale,
)
from ikid.io.mapping import MarkerMap

#: The readers' shared names live in :mod:`ikid.io._common` (below ``mapping`` and this module,
#: which imports ``mapping``); re-exported here, where the readers have always found them.
__all__ = [
    "MarkerData",
    "MarkerMap",
    "suffix",
    "MAX_FILE_BYTES",
    "UNITS",
    "FileFormatError",
    "check_readable",
    "ikid_marker_names",
    "is_float",
    "read_bytes",
    "read_text",
    "read_text_lines",
    "unit_scale",
]


@dataclass(frozen=True)
class MarkerData:
    """Marker trajectories: ``positions[i, j]`` is marker ``labels[j]`` at ``time[i]``, metres;
    NaN where the marker was not seen."""

    labels: tuple[str, ...]
    time: np.ndarray
    positions: np.ndarray
    rate_hz: float
    source: str = ""
    #: Units the file stated (before conversion to metres).
    file_units: str = "m"
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.time)
        if self.positions.shape != (n, len(self.labels), 3):
            raise FileFormatError(
                f"{self.source or 'markers'}: positions {self.positions.shape} do not match {n} frames "
                f"x {len(self.labels)} labels x 3"
            )
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise FileFormatError(
                f"{self.source or 'markers'}: frame rate {self.rate_hz} Hz is not a positive number"
            )

    def __len__(self) -> int:
        return len(self.time)

    def marker(self, label: str) -> np.ndarray:
        """``(n, 3)`` trajectory of one label."""
        try:
            return self.positions[:, self.labels.index(label)]
        except ValueError:
            raise _native.InputError(
                f"{self.source}: no marker {label!r}; the file has {', '.join(self.labels)}"
            ) from None

    def frames(self, mapping: MarkerMap | None = None) -> np.ndarray:
        """ikid's ``(n, 18)`` frames (metres, float64, NaN = missing). ``mapping`` says which
        label is which ikid marker (default: the labels are ikid's own names)."""
        mapping = mapping or MarkerMap.identity()
        columns = np.concatenate([self.marker(label) for label in mapping.labels_in_ikid_order(self)], axis=1)
        source = self.source or "markers"
        for j, name in enumerate(mapping.marker_names()):
            seen = np.isfinite(columns[:, 3 * j : 3 * j + 3]).all(axis=1)
            if not seen.any():
                raise _native.InputError(
                    f"{source}: marker {name} (label {mapping.label_of(name)!r}) is missing in every frame; "
                    "ikid needs each marker in at least some frames"
                )
        frames = mapping.ikid_frames(columns)
        if mapping.one_hand_marker and not np.isfinite(frames[:, 9:]).all(axis=1).any():
            raise _native.InputError(
                f"{source}: no frame gives the hand's direction from its one marker "
                f"({mapping.label_of(_native.HAND_POINT[0])}): it is never 3 cm or more from the wrist "
                "markers' midpoint and off their line"
            )
        # Units: the core's one check (the markers' spread against what an arm spans), named
        # with the file and what its header claims.
        try:
            _native.check_marker_units(frames)
        except _native.InputError as e:
            raise _native.InputError(
                f"{source}: {e.reason or e} (the file says its units are {self.file_units!r})"
            ) from None
        return frames


def suffix(path: str | os.PathLike[str]) -> str:
    return Path(path).suffix.lower()
