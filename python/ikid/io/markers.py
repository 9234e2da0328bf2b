"""Marker trajectories as read from a lab's file, before they become ikid frames.

:class:`MarkerData` holds any labels in metres (NaN = missing); :meth:`MarkerData.frames`
turns it into ikid's ``(n, 18)`` frames through a :class:`~ikid.io.mapping.MarkerMap`,
checking what a network cannot: a label that is not there, a marker that is never seen,
coordinates that cannot be in the units the file claims.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ikid import _native

if TYPE_CHECKING:
    from ikid.io.mapping import MarkerMap

#: Length units a marker file may state, and their size in metres.
UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


class FileFormatError(_native.InputError):
    """A file that cannot be read as what it claims to be; the message names the file and
    what is wrong (and the line, for text formats)."""


def is_float(text: str) -> bool:
    """Whether a text cell reads as a number (the text readers' check before naming a bad cell)."""
    try:
        float(text)
    except ValueError:
        return False
    return True


#: Largest file any reader takes, bytes: an hour of 100 markers at 250 Hz as text is ~1 GB.
MAX_FILE_BYTES = 2 << 30


def check_readable(path: Path, what: str, limit: int = MAX_FILE_BYTES) -> int:
    """The size of the regular file at ``path``; a :class:`ikid.ReadError` naming it when it is
    a directory, a pipe or a device (refused before it is opened: a FIFO would block and
    ``/dev/zero`` never end) or larger than ``limit``. A missing file raises
    ``FileNotFoundError`` as Python does."""
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else "not a regular file (a pipe, socket or device)"
        raise _native.ReadError(f"{path}: it is {kind}; expected {what}")
    if st.st_size > limit:
        size = st.st_size
        raise _native.ReadError(f"{path}: it is {size} bytes, over the {limit} bytes ikid reads ({what})")
    return st.st_size


def read_bytes(path: Path, what: str, limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (see :func:`check_readable`); a
    file that grows past it while being read is refused too."""
    check_readable(path, what, limit)
    with open(path, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise _native.ReadError(f"{path}: it grew past {limit} bytes while being read ({what})")
    return data


def read_text(path: Path, what: str) -> str:
    """A UTF-8 text file, bounded (see :func:`read_bytes`), or a :class:`FileFormatError`
    saying it is not ``what``."""
    try:
        return read_bytes(path, what).decode("utf-8")
    except UnicodeDecodeError:
        raise FileFormatError(f"{path}: not a text file ({what})") from None


def read_text_lines(path: Path, what: str) -> list[str]:
    """The lines of a UTF-8 text file (see :func:`read_text`)."""
    return read_text(path, what).splitlines()


def unit_scale(units: str, source: str) -> float:
    """Metres per file unit, or a :class:`FileFormatError` listing the known units."""
    key = units.strip().lower()
    aliases = {"millimeters": "mm", "millimetres": "mm", "meters": "m", "metres": "m", "centimeters": "cm"}
    key = aliases.get(key, key)
    if key not in UNITS:
        raise FileFormatError(f"{source}: unknown length unit {units!r} (known: {', '.join(UNITS)})")
    return UNITS[key]


def ikid_marker_names() -> list[str]:
    return [m[0] for m in _native.MARKERS]


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
        from ikid.io.mapping import MarkerMap

        mapping = mapping or MarkerMap.identity()
        frames = np.concatenate([self.marker(label) for label in mapping.labels_in_ikid_order(self)], axis=1)
        source = self.source or "markers"
        for j, name in enumerate(ikid_marker_names()):
            seen = np.isfinite(frames[:, 3 * j : 3 * j + 3]).all(axis=1)
            if not seen.any():
                raise _native.InputError(
                    f"{source}: marker {name} (label {mapping.label_of(name)!r}) is missing in every frame; "
                    "ikid needs each marker in at least some frames"
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
