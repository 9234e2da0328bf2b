"""OpenSim text formats: markers ``.trc`` (mm), coordinates ``.mot`` (degrees), generalized
forces ``.sto`` (N·m). Column names come from the body model (``ikid.marker_names`` and
``ikid.coordinate_names``). Missing markers become empty TRC cells (OpenSim's gap); a
non-finite angle or torque is refused, never written."""

from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np

from ikid import _native
from ikid.io._atomic import write_text_atomic


def _names(kind: str) -> list[str]:
    return [c[0] for c in (_native.COORDINATES if kind == "coordinates" else _native.MARKERS)]


def _check_rows(name: str, time: np.ndarray, values: np.ndarray, cols: int) -> tuple[np.ndarray, np.ndarray]:
    time = np.asarray(time, np.float64)
    values = np.asarray(values, np.float64)
    if time.ndim != 1 or values.shape != (len(time), cols):
        raise _native.InputError(f"{name}: expected time (n,) and values (n, {cols}), got {time.shape} and {values.shape}")
    if not np.all(np.isfinite(time)) or np.any(np.diff(time) <= 0):
        raise _native.InputError(f"{name}: time must be finite and strictly increasing")
    return time, values


def write_trc(path: str | os.PathLike[str], time, markers, rate_hz: float | None = None) -> Path:
    """Markers ``(n, 18)`` in metres -> ``.trc`` in millimetres (NaN -> empty cells)."""
    names = _names("markers")
    time, markers = _check_rows("markers", time, markers, 3 * len(names))
    rate = rate_hz if rate_hz is not None else (1.0 / np.median(np.diff(time)) if len(time) > 1 else 1.0)
    n = len(time)
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:.6g}\t{rate:.6g}\t{n}\t{len(names)}\tmm\t{rate:.6g}\t1\t{n}",
        "Frame#\tTime\t" + "\t".join(f"{m}\t\t" for m in names).rstrip("\t"),
        "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(len(names))),
        "",
    ]
    table = np.column_stack([np.arange(1, n + 1), time, markers * 1000.0])
    buf = io.StringIO()
    np.savetxt(buf, table, fmt=["%d", "%.6f"] + ["%.6f"] * markers.shape[1], delimiter="\t")
    # A missing marker is an empty cell in TRC (what OpenSim and Mokka read as a gap).
    body = re.sub(r"(?<=\t)(?:-?nan|-?inf)(?=\t|\n)", "", buf.getvalue())
    return write_text_atomic(path, "\n".join(lines) + "\n" + body)


def _storage(path, time, values, columns: list[str], in_degrees: bool) -> Path:
    if not np.all(np.isfinite(values)):
        row, col = np.argwhere(~np.isfinite(values))[0]
        raise _native.InputError(f"{Path(path).name}: value {columns[col]} at row {row} is {values[row, col]}; not written")
    header = [
        Path(path).name,
        "version=1",
        f"nRows={len(time)}",
        f"nColumns={len(columns) + 1}",
        f"inDegrees={'yes' if in_degrees else 'no'}",
        "endheader",
        "time\t" + "\t".join(columns),
    ]
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack([time, values]), fmt=["%.6f"] + ["%.8g"] * values.shape[1], delimiter="\t")
    return write_text_atomic(path, "\n".join(header) + "\n" + buf.getvalue())


def write_mot(path: str | os.PathLike[str], time, q) -> Path:
    """Wrist angles ``(n, 3)`` in radians -> ``.mot`` in degrees (``inDegrees=yes``)."""
    names = _names("coordinates")
    time, q = _check_rows("angles", time, q, len(names))
    return _storage(path, time, np.degrees(q), names, in_degrees=True)


def write_sto(path: str | os.PathLike[str], time, tau) -> Path:
    """Joint torques ``(n, 3)`` in N·m -> ``.sto`` with OpenSim's ``<coordinate>_moment`` columns."""
    names = _names("coordinates")
    time, tau = _check_rows("torques", time, tau, len(names))
    return _storage(path, time, tau, [f"{c}_moment" for c in names], in_degrees=False)
