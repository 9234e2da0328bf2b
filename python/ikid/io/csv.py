"""CSV tables: marker trajectories in, angles or torques out, for tools that speak neither
TRC nor OpenSim storage (spreadsheets, pandas, MATLAB ``readtable``).

Layout (comma-separated, one header row, one row per frame)::

    # units=mm
    time,RSP.x,RSP.y,RSP.z,USP.x,...
    0.000,412.3,1201.9,18.2,...

The first column is ``time`` in seconds. Marker columns are ``<label>.x``, ``.y``, ``.z``
(``_x``/``_X`` accepted), in any order; an empty cell or ``nan`` is a missing value. An
optional first line ``# units=mm`` (``cm``, ``m``) states the length unit, default metres.
The frame rate is read from the time column (it must be uniform to 1 %).
"""

from __future__ import annotations

import io
import itertools
import os
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ikid.io._atomic import write_text_atomic
from ikid.io._common import check_time_increases, numbered_lines
from ikid.io.markers import (
    MAX_FILE_BYTES,
    FileFormatError,
    MarkerData,
    MarkerFile,
    check_readable,
    concatenate_blocks,
    ikid_marker_names,
    is_float,
    unit_scale,
)

_AXIS = re.compile(r"^(?P<label>.+?)[._](?P<axis>[xyzXYZ])$")


#: Frames per block when a marker CSV is read in blocks (:func:`open_csv_markers`).
BLOCK_FRAMES = 65536
_WHAT = "CSV is comma-separated text"


def read_csv_markers(path: str | os.PathLike[str]) -> MarkerData:
    """Read a marker ``.csv`` (layout in the module doc); positions in metres. The whole file in
    memory: :func:`open_csv_markers` reads one of any length in blocks."""
    csv = open_csv_markers(path, max_bytes=MAX_FILE_BYTES)
    return concatenate_blocks(csv, list(csv.blocks()))


def open_csv_markers(
    path: str | os.PathLike[str], block_frames: int | None = None, max_bytes: int | None = None
) -> MarkerFile:
    """A marker ``.csv``'s header, checked, its rate (the median step of its first block of
    ``block_frames`` rows, default :data:`BLOCK_FRAMES`) and its frames in blocks
    (:meth:`MarkerFile.blocks`, each checked as it is read: numbers, increasing time, every step
    within 1 % of the rate's): memory independent of the file's length. ``max_bytes`` refuses a
    larger file (:func:`read_csv_markers`' whole-file limit)."""
    block_frames = max(2, block_frames or BLOCK_FRAMES)
    path = Path(path)
    src = str(path)
    check_readable(path, _WHAT, limit=1 << 62 if max_bytes is None else max_bytes)
    lines = numbered_lines(path, _WHAT)
    try:
        first = next(lines, None)
        units, header_at, declared = "m", first, False
        if first is not None and first[1].startswith("#"):
            m = re.search(r"units\s*=\s*(\S+)", first[1])
            if m:
                units, declared = m.group(1), True
            header_at = next(lines, None)
    finally:
        lines.close()
    scale = unit_scale(units, src)
    if header_at is None:
        raise FileFormatError(f"{src}: no header row (expected 'time,<label>.x,<label>.y,<label>.z,...')")
    start, header_line = header_at
    header = [c.strip() for c in header_line.split(",")]
    if header[0].lower() != "time":
        raise FileFormatError(
            f"{src}:{start}: the first column must be 'time' (seconds), found {header[0]!r}"
        )
    labels: list[str] = []
    columns: dict[tuple[str, str], int] = {}
    for j, name in enumerate(header[1:], start=1):
        m = _AXIS.match(name)
        if not m:
            raise FileFormatError(f"{src}:{start}: column {name!r} is not '<label>.x', '.y' or '.z'")
        key = (m.group("label"), m.group("axis").lower())
        if key in columns:
            raise FileFormatError(f"{src}:{start}: column {name!r} appears more than once")
        columns[key] = j
        if key[0] not in labels:
            labels.append(key[0])
    incomplete = [lab for lab in labels if any((lab, a) not in columns for a in "xyz")]
    if incomplete:
        raise FileFormatError(f"{src}:{start}: marker(s) {', '.join(incomplete)} lack an x, y or z column")
    order = [columns[(lab, a)] for lab in labels for a in "xyz"]

    def tables() -> Iterator[tuple[np.ndarray, list[int]]]:
        """The rows after the header, ``block_frames`` at a time, with their line numbers."""
        rows = numbered_lines(path, _WHAT, after=start)
        try:
            data = (r for r in rows if r[1].strip())
            while block := list(itertools.islice(data, block_frames)):
                yield _csv_rows(block, len(header), src), [n for n, _ in block]
        finally:
            rows.close()

    # The rate: the median step of the first block; the frames: the data rows, counted.
    first_block = next(tables(), None)
    n_frames = _count_rows(path, start)
    if first_block is None or n_frames < 2:
        raise FileFormatError(f"{src}: {n_frames} data row(s); at least 2 are needed")
    head_time, head_lines = first_block[0][:, 0], first_block[1]
    _check_time(head_time, head_lines, -np.inf, src)
    step = float(np.median(np.diff(head_time)))

    # Undeclared units are metres by default: a units error says so, and how to declare them.
    metadata = {} if declared else {"units_assumed": "no '# units=' line: metres assumed"}

    def blocks() -> Iterator[MarkerData]:
        last = -np.inf
        for table, linenos in tables():
            time = table[:, 0]
            _check_time(time, linenos, last, src)
            steps = np.diff(np.concatenate([[last], time]))[0 if np.isfinite(last) else 1 :]
            if np.any(np.abs(steps - step) > 0.01 * step):
                raise FileFormatError(
                    f"{src}: frames are not evenly spaced in time (steps {steps.min():.6g}-"
                    f"{steps.max():.6g} s by line {linenos[-1]}, the first rows' {step:.6g} s)"
                )
            last = float(time[-1])
            positions = (table[:, order] * scale).reshape(len(time), len(labels), 3)
            yield MarkerData(
                tuple(labels), time, positions, 1.0 / step, src, file_units=units, metadata=metadata
            )

    return MarkerFile(tuple(labels), 1.0 / step, src, units, metadata, n_frames, blocks)


def _csv_rows(block: list[tuple[int, str]], width: int, src: str) -> np.ndarray:
    """Rows ``(n, width)`` of numbered non-blank CSV lines (an empty cell is NaN), naming the
    first bad line."""
    rows = np.empty((len(block), width))
    for k, (lineno, line) in enumerate(block):
        cells = line.split(",")
        if len(cells) != width:
            raise FileFormatError(f"{src}:{lineno}: {len(cells)} values, the header names {width}")
        try:
            rows[k] = [float(c) if c.strip() else np.nan for c in cells]
        except ValueError:
            bad = next(c for c in cells if c.strip() and not is_float(c))
            raise FileFormatError(f"{src}:{lineno}: {bad.strip()!r} is not a number") from None
    return rows


def _check_time(time: np.ndarray, linenos: list[int], last: float, src: str) -> None:
    """Every time a number and after the one before (``last``, the block before's last)."""
    if not np.all(np.isfinite(time)):
        k = int(np.argwhere(~np.isfinite(time))[0][0])
        raise FileFormatError(f"{src}:{linenos[k]}: time {time[k]} is not a number")
    check_time_increases(time, linenos, last, src)


def _count_rows(path: Path, after: int) -> int:
    """The non-blank lines after line ``after`` (a pass over the bytes, to say how many frames)."""
    with open(path, "rb") as f:
        return sum(1 for k, line in enumerate(f, start=1) if k > after and line.strip())


def write_csv(path: str | os.PathLike[str], time, values, columns: list[str] | tuple[str, ...]) -> Path:
    """Any table (``values`` ``(n, len(columns))``) with a leading ``time`` column, atomically;
    refuses non-finite times or values (nothing written)."""
    time = np.asarray(time, np.float64)
    values = np.asarray(values, np.float64).reshape(len(time), -1)
    name = Path(path).name
    if values.shape[1] != len(columns):
        raise FileFormatError(f"{name}: {values.shape[1]} value columns but {len(columns)} names")
    if not np.all(np.isfinite(time)) or not np.all(np.isfinite(values)):
        raise FileFormatError(f"{name}: non-finite time or value; not written")
    buf = io.StringIO()
    buf.write(",".join(["time", *columns]) + "\n")
    np.savetxt(
        buf, np.column_stack([time, values]), fmt=["%.6f"] + ["%.10g"] * values.shape[1], delimiter=","
    )
    return write_text_atomic(path, buf.getvalue())


def write_csv_markers(
    path: str | os.PathLike[str], time, markers, labels: list[str] | None = None, units: str = "m"
) -> Path:
    """Markers ``(n, 3 · len(labels))`` in metres -> marker ``.csv`` in ``units`` (NaN -> empty cell)."""
    labels = list(labels) if labels is not None else ikid_marker_names()
    time = np.asarray(time, np.float64)
    markers = np.asarray(markers, np.float64).reshape(len(time), -1)
    if markers.shape[1] != 3 * len(labels):
        raise FileFormatError(
            f"{Path(path).name}: markers have {markers.shape[1]} columns, {len(labels)} labels "
            f"need {3 * len(labels)}"
        )
    values = markers / unit_scale(units, str(path))
    buf = io.StringIO()
    buf.write(f"# units={units}\n")
    buf.write(",".join(["time", *(f"{lab}.{a}" for lab in labels for a in "xyz")]) + "\n")
    for t, row in zip(time, values, strict=True):
        buf.write(f"{t:.6f}," + ",".join("" if not np.isfinite(v) else f"{v:.10g}" for v in row) + "\n")
    return write_text_atomic(path, buf.getvalue())
