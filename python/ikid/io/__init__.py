"""File formats at ikid's boundaries, one module per format. Units convert here only (TRC
and C3D in their stated length unit, MOT in degrees); everything in memory is SI.

    data = ikid.io.read_markers("trial.c3d")          # any labels, metres, NaN = not seen
    frames = data.frames(ikid.io.MarkerMap.load("lab.toml"))   # ikid's (n, 18)
"""

from __future__ import annotations

import os

from ikid.io._atomic import WriteError, atomic_outputs
from ikid.io._common import UP_AXES, MarkerMapWarning, UndeterminedWarning, to_ikid_lab
from ikid.io.c3d import read_c3d, write_c3d
from ikid.io.csv import open_csv_markers, read_csv_markers, write_csv, write_csv_markers
from ikid.io.mapping import MarkerMap
from ikid.io.markers import FileFormatError, MarkerData, MarkerFile
from ikid.io.resample import resample, resample_stretches
from ikid.io.storage import (
    Storage,
    StorageFile,
    mot_blocks,
    mot_writer,
    open_storage,
    read_mot,
    read_sto,
    read_storage,
    sto_writer,
    write_mot,
    write_sto,
    write_storage,
)
from ikid.io.trc import open_trc, read_trc, write_trc

#: Marker file readers by suffix.
MARKER_READERS = {".trc": read_trc, ".c3d": read_c3d, ".csv": read_csv_markers}


def read_markers(path: str | os.PathLike[str]) -> MarkerData:
    """Read a marker file by its suffix (``.trc``, ``.c3d`` or ``.csv``)."""
    from pathlib import Path

    reader = MARKER_READERS.get(Path(path).suffix.lower())
    if reader is None:
        raise FileFormatError(f"{path}: unknown marker file type (known: {', '.join(MARKER_READERS)})")
    return reader(path)


def open_markers(path: str | os.PathLike[str]) -> MarkerFile:
    """A marker file to read in blocks (:class:`MarkerFile`): a ``.trc`` or ``.csv`` a block at
    a time, in memory independent of its length; a ``.c3d`` read whole (ezc3d reads whole
    files), as one block."""
    from pathlib import Path

    opener = {".trc": open_trc, ".csv": open_csv_markers}.get(Path(path).suffix.lower())
    return opener(path) if opener else MarkerFile.whole(read_markers(path))


__all__ = [
    "MARKER_READERS",
    "FileFormatError",
    "MarkerData",
    "MarkerFile",
    "MarkerMap",
    "MarkerMapWarning",
    "Storage",
    "StorageFile",
    "UndeterminedWarning",
    "WriteError",
    "atomic_outputs",
    "read_c3d",
    "read_csv_markers",
    "open_csv_markers",
    "write_csv",
    "write_csv_markers",
    "read_markers",
    "open_markers",
    "open_trc",
    "open_storage",
    "mot_blocks",
    "read_mot",
    "read_storage",
    "read_sto",
    "read_trc",
    "resample",
    "resample_stretches",
    "write_c3d",
    "write_mot",
    "mot_writer",
    "sto_writer",
    "write_storage",
    "write_sto",
    "write_trc",
    "to_ikid_lab",
    "UP_AXES",
]
