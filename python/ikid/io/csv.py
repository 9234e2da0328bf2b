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
import os
import re
from pathlib import Path

import numpy as np

from ikid.io._atomic import write_text_atomic
from ikid.io.markers import (
    FileFormatError,
    MarkerData,
    ikid_marker_names,
    is_float,
    read_text_lines,
    unit_scale,
)

_AXIS = re.compile(r"^(?P<label>.+?)[._](?P<axis>[xyzXYZ])$")


def read_csv_markers(path: str | os.PathLike[str]) -> MarkerData:
    """Read a marker ``.csv`` (layout in the module doc); positions in metres."""
    path = Path(path)
    src = str(path)
    lines = read_text_lines(path, "CSV is comma-separated text")
    units, start = "m", 0
    if lines and lines[0].startswith("#"):
        m = re.search(r"units\s*=\s*(\S+)", lines[0])
        if m:
            units = m.group(1)
        start = 1
    scale = unit_scale(units, src)
    if len(lines) <= start:
        raise FileFormatError(f"{src}: no header row (expected 'time,<label>.x,<label>.y,<label>.z,...')")
    header = [c.strip() for c in lines[start].split(",")]
    if header[0].lower() != "time":
        raise FileFormatError(
            f"{src}:{start + 1}: the first column must be 'time' (seconds), found {header[0]!r}"
        )
    labels: list[str] = []
    columns: dict[tuple[str, str], int] = {}
    for j, name in enumerate(header[1:], start=1):
        m = _AXIS.match(name)
        if not m:
            raise FileFormatError(f"{src}:{start + 1}: column {name!r} is not '<label>.x', '.y' or '.z'")
        key = (m.group("label"), m.group("axis").lower())
        if key in columns:
            raise FileFormatError(f"{src}:{start + 1}: column {name!r} appears more than once")
        columns[key] = j
        if key[0] not in labels:
            labels.append(key[0])
    incomplete = [lab for lab in labels if any((lab, a) not in columns for a in "xyz")]
    if incomplete:
        raise FileFormatError(
            f"{src}:{start + 1}: marker(s) {', '.join(incomplete)} lack an x, y or z column"
        )
    rows: list[list[float]] = []
    linenos: list[int] = []
    for lineno, line in enumerate(lines[start + 1 :], start=start + 2):
        if not line.strip():
            continue
        linenos.append(lineno)
        cells = line.split(",")
        if len(cells) != len(header):
            raise FileFormatError(f"{src}:{lineno}: {len(cells)} values, the header names {len(header)}")
        try:
            rows.append([float(c) if c.strip() else np.nan for c in cells])
        except ValueError:
            bad = next(c for c in cells if c.strip() and not is_float(c))
            raise FileFormatError(f"{src}:{lineno}: {bad.strip()!r} is not a number") from None
    if len(rows) < 2:
        raise FileFormatError(f"{src}: {len(rows)} data row(s); at least 2 are needed")
    table = np.array(rows, np.float64)
    time = table[:, 0]
    if not np.all(np.isfinite(time)):
        k = int(np.argwhere(~np.isfinite(time))[0][0])
        raise FileFormatError(f"{src}:{linenos[k]}: time {time[k]} is not a number")
    if np.any(np.diff(time) <= 0):
        k = int(np.argwhere(np.diff(time) <= 0)[0][0]) + 1
        raise FileFormatError(
            f"{src}:{linenos[k]}: time {time[k]:g} s does not come after the row before's "
            f"({time[k - 1]:g} s): time must increase from row to row"
        )
    dt = np.diff(time)
    if np.max(np.abs(dt - np.median(dt))) > 0.01 * np.median(dt):
        raise FileFormatError(
            f"{src}: frames are not evenly spaced in time (steps {dt.min():.6g}-{dt.max():.6g} s)"
        )
    order = [columns[(lab, a)] for lab in labels for a in "xyz"]
    positions = (table[:, order] * scale).reshape(len(time), len(labels), 3)
    return MarkerData(tuple(labels), time, positions, 1.0 / float(np.median(dt)), src, file_units=units)


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
