"""Marker trajectories as read from a lab's file, before they become ikid frames.

:class:`MarkerData` holds any labels in metres (NaN = missing); :meth:`MarkerData.frames`
turns it into ikid's ``(n, 18)`` frames through a :class:`~ikid.io.mapping.MarkerMap`,
checking what a network cannot: a label that is not there, a marker that is never seen,
coordinates that cannot be in the units the file claims.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ikid import _native
from ikid.io._common import (
    MAX_FILE_BYTES,
    UNITS,
    UP_AXES,
    FileFormatError,
    UndeterminedWarning,
    check_readable,
    ikid_marker_names,
    is_float,
    read_bytes,
    read_text,
    read_text_lines,
    to_ikid_lab,
    unit_scale,
)
from ikid.io.mapping import MarkerMap

#: The readers' shared names live in :mod:`ikid.io._common` (below ``mapping`` and this module,
#: which imports ``mapping``); re-exported here, where the readers have always found them.
__all__ = [
    "MarkerData",
    "MarkerFile",
    "concatenate_blocks",
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
    "UP_AXES",
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

    def marker(self, label: str, up: str | None = None) -> np.ndarray:
        """``(n, 3)`` trajectory of one label in ikid's lab (+Y up): turned from the file's lab,
        whose up axis is ``up`` (a map's), else the one the file declares, else +Y (:meth:`lab_up`)."""
        try:
            positions = self.positions[:, self.labels.index(label)]
        except ValueError:
            raise _native.InputError(
                f"{self.source}: no marker {label!r}; the file has {', '.join(self.labels)}"
            ) from None
        return to_ikid_lab(positions, self.lab_up(up)[0])

    def lab_up(self, up: str | None = None) -> tuple[str, str]:
        """The lab axis pointing up (one of :data:`UP_AXES`) and where that comes from: ``up``
        (a map's ``up``), else the file's own declaration (a C3D's ``POINT:Y_SCREEN``), else
        ikid's +Y, assumed."""
        declared = self.metadata.get("up")
        if up:
            if declared and declared != up:  # the map decides, and says what it overrode
                return up, f"the map's up, over {self.metadata.get('up_from', 'the file')}"
            return up, "the map's up"
        if declared:
            return declared, self.metadata.get("up_from", "the file")
        return "+y", "assumed: neither the file nor the map says; set up in the map"

    def frames(
        self, mapping: MarkerMap | str | os.PathLike[str] | None = None, *, whole: bool = True
    ) -> np.ndarray:
        """ikid's ``(n, 18)`` frames (metres, float64, NaN = missing), in ikid's lab (+Y up:
        turned by the map's ``up``, else the file's declared one, as :meth:`marker`; do not turn
        them again with :func:`ikid.io.to_ikid_lab`). ``mapping`` says which
        label is which ikid marker (a :class:`MarkerMap` or the path of its TOML file; default:
        the labels are ikid's own names). ``whole=False``
        for one block of a file read in blocks: a marker missing throughout the block is not an
        error there (:func:`check_markers_seen` checks the file once every block is read), and
        the units are checked only if the block has a complete frame."""
        if isinstance(mapping, str | os.PathLike):
            mapping = MarkerMap.load(mapping)
        elif mapping is not None and not isinstance(mapping, MarkerMap):
            raise _native.ArgumentError(
                f"mapping: expected a MarkerMap or the path of a marker map, got {type(mapping).__name__}"
            )
        mapping = mapping or MarkerMap.identity()
        columns = np.concatenate(
            [self.marker(label, mapping.up) for label in mapping.labels_in_ikid_order(self)], axis=1
        )
        source = self.source or "markers"
        if whole:
            check_markers_seen(seen_markers(columns), mapping, source)
        frames = mapping.ikid_frames(mapping.fit_clusters(self, columns))
        if whole and (undetermined := mapping.undetermined):
            # The frames are six markers all the same; what they do not show is said here, where
            # the map is known (run_model, Tracker and Stream see frames only).
            warnings.warn(
                f"{source}: {', '.join(undetermined)} is not determined by these frames ("
                f"{' '.join(undetermined.values())}); the models, the Tracker and streams still give "
                "it a value (about 0, with status 0): leave it out (MarkerMap.undetermined names it)",
                UndeterminedWarning,
                stacklevel=2,
            )
        if whole:
            if mapping.one_hand_marker and not np.isfinite(frames[:, 9:]).all(axis=1).any():
                raise _native.InputError(
                    f"{source}: no frame gives the hand's direction from its one marker "
                    f"({mapping.label_of(_native.HAND_POINT[0])}): it is never 3 cm or more from the wrist "
                    "markers' midpoint and off their line"
                )
        elif not np.isfinite(frames).all(axis=1).any():
            return frames
        # Units: the core's one check (the markers' spread against what an arm spans), named
        # with the file and what its header claims.
        try:
            _native.check_marker_units(frames)
        except _native.InputError as e:
            said = (
                f"{self.metadata['units_assumed']}; declare the file's unit with a first line '# units=mm' "
                "(or cm, m)"
                if "units_assumed" in self.metadata
                else f"the file says its units are {self.file_units!r}"
            )
            raise _native.InputError(f"{source}: {e.reason or e} ({said})") from None
        return frames


def seen_markers(frames: np.ndarray) -> np.ndarray:
    """``(6,)``: whether each of ikid's markers is seen in some frame of ``frames``."""
    return np.isfinite(frames.reshape(len(frames), -1, 3)).all(axis=2).any(axis=0)


def check_markers_seen(seen: np.ndarray, mapping: MarkerMap, source: str) -> None:
    """An error naming the first of ikid's markers never seen (``seen`` as :func:`seen_markers`,
    over every frame of a file: the map's own markers, or ikid's six as a block's frames have
    them)."""
    mapped = mapping.marker_names()
    names = mapped if len(seen) == len(mapped) else ikid_marker_names()
    for name, ok in zip(names, seen, strict=True):
        if not ok:
            label = f"label {mapping.label_of(name)!r}" if name in mapped else "made from the map's markers"
            raise _native.InputError(
                f"{source}: marker {name} ({label}) is missing in every frame; "
                "ikid needs each marker in at least some frames"
            )


@dataclass(frozen=True)
class MarkerFile:
    """A marker file opened for reading in blocks: what its header says, and its frames as
    :class:`MarkerData` blocks in order (:meth:`blocks`, each checked as it is read), so a file
    of any length is read in bounded memory."""

    labels: tuple[str, ...]
    rate_hz: float
    source: str
    file_units: str
    metadata: dict
    #: Frames the header declares (the blocks end with an error if the file has another number).
    n_frames: int
    _blocks: Callable[[], Iterator[MarkerData]]

    def blocks(self) -> Iterator[MarkerData]:
        """The file's frames, a block at a time (a new pass over the file on each call)."""
        return self._blocks()

    @staticmethod
    def whole(data: MarkerData) -> MarkerFile:
        """A file read whole (a reader without blocks), as one block."""
        return MarkerFile(
            data.labels,
            data.rate_hz,
            data.source,
            data.file_units,
            data.metadata,
            len(data),
            lambda: iter([data]),
        )


def concatenate_blocks(file: MarkerFile, blocks: list[MarkerData]) -> MarkerData:
    """The blocks of ``file`` as one :class:`MarkerData`."""
    n_labels = len(file.labels)
    time = np.concatenate([b.time for b in blocks]) if blocks else np.empty(0)
    positions = np.concatenate([b.positions for b in blocks]) if blocks else np.empty((0, n_labels, 3))
    return MarkerData(file.labels, time, positions, file.rate_hz, file.source, file.file_units, file.metadata)


def suffix(path: str | os.PathLike[str]) -> str:
    return Path(path).suffix.lower()
