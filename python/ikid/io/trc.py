"""TRC marker files (OpenSim, Mokka, Vicon/Cortex exports): tab-separated text, a 5-line
header (``PathFileType``, the ``DataRate ... Units`` key and value lines, the marker labels,
the ``X1 Y1 Z1`` line), then one row per frame. Missing markers are empty cells."""

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

_HEADER_LINES = 5


def read_trc(path: str | os.PathLike[str]) -> MarkerData:
    """Read a ``.trc`` file; positions in metres whatever its ``Units`` (mm, cm, m)."""
    path = Path(path)
    src = str(path)
    lines = read_text_lines(path, "TRC is tab-separated text")
    if len(lines) < _HEADER_LINES or not lines[0].startswith("PathFileType"):
        raise FileFormatError(f"{src}:1: not a TRC file (expected a 'PathFileType' line and a 5-line header)")
    keys = lines[1].split("\t")
    values = lines[2].split("\t")
    header = {k.strip(): v.strip() for k, v in zip(keys, values, strict=False) if k.strip()}
    for key in ("DataRate", "NumFrames", "NumMarkers", "Units"):
        if key not in header:
            raise FileFormatError(f"{src}:2: header has no {key} (has {', '.join(header) or 'nothing'})")
    try:
        rate = float(header["DataRate"])
        n_frames = int(header["NumFrames"])
        n_markers = int(header["NumMarkers"])
    except ValueError:
        raise FileFormatError(
            f"{src}:3: DataRate/NumFrames/NumMarkers must be numbers, got "
            f"{header['DataRate']!r}/{header['NumFrames']!r}/{header['NumMarkers']!r}"
        ) from None
    if not (np.isfinite(rate) and rate > 0) or n_frames < 0 or n_markers <= 0:
        raise FileFormatError(
            f"{src}:3: DataRate {rate}, NumFrames {n_frames}, NumMarkers {n_markers} are not valid"
        )
    scale = unit_scale(header["Units"], src)
    cells = lines[3].split("\t")
    if len(cells) < 2 or cells[0].strip() != "Frame#":
        raise FileFormatError(f"{src}:4: expected 'Frame#<tab>Time<tab>labels...'")
    labels = tuple(c.strip() for c in cells[2:] if c.strip())
    if len(labels) != n_markers:
        raise FileFormatError(f"{src}:4: {len(labels)} marker labels, but NumMarkers says {n_markers}")
    if len(set(labels)) != len(labels):
        dup = sorted({lab for lab in labels if labels.count(lab) > 1})
        raise FileFormatError(f"{src}:4: marker label(s) {', '.join(dup)} appear more than once")

    width = 2 + 3 * n_markers
    parsed: list[list[float]] = []  # not preallocated from NumFrames: the header may lie
    for lineno, line in enumerate(lines[_HEADER_LINES:], start=_HEADER_LINES + 1):
        if not line.strip():
            continue
        parts = line.split("\t")
        # Some writers drop trailing empty cells of missing markers.
        if len(parts) > width and any(p.strip() for p in parts[width:]):
            raise FileFormatError(f"{src}:{lineno}: {len(parts)} columns, expected at most {width}")
        if len(parsed) >= n_frames:
            raise FileFormatError(f"{src}:{lineno}: more rows than NumFrames ({n_frames})")
        try:
            row = [float(p) if p.strip() else np.nan for p in parts[:width]]
        except ValueError:
            bad = next(p for p in parts[:width] if p.strip() and not is_float(p))
            raise FileFormatError(f"{src}:{lineno}: {bad!r} is not a number") from None
        parsed.append(row + [np.nan] * (width - len(row)))
    if len(parsed) != n_frames:
        raise FileFormatError(
            f"{src}: header says {n_frames} frames, the file has {len(parsed)} (truncated?)"
        )
    rows = np.array(parsed, np.float64).reshape(n_frames, width)
    time = rows[:, 1]
    if not np.all(np.isfinite(time)):
        raise FileFormatError(
            f"{src}:{_HEADER_LINES + 1 + int(np.argmin(np.isfinite(time)))}: a row has no time"
        )
    if np.any(np.diff(time) <= 0):
        i = int(np.argmax(np.diff(time) <= 0))
        raise FileFormatError(
            f"{src}: time goes from {time[i]} to {time[i + 1]} s at frame {i + 2}; it must increase"
        )
    positions = rows[:, 2:].reshape(n_frames, n_markers, 3) * scale
    positions[~np.isfinite(positions)] = np.nan
    # A marker is seen or not: a frame with a partial xyz is missing.
    positions[~np.isfinite(positions).all(axis=2)] = np.nan
    return MarkerData(labels, time, positions, rate, src, header["Units"], {"header": header})


def write_trc(
    path: str | os.PathLike[str],
    time,
    markers,
    rate_hz: float | None = None,
    labels: list[str] | tuple[str, ...] | None = None,
    units: str = "mm",
) -> Path:
    """Markers ``(n, 3 * len(labels))`` in metres (default labels: ikid's six) -> ``.trc`` in
    ``units`` (NaN -> empty cells). Written atomically."""
    labels = list(labels) if labels is not None else ikid_marker_names()
    time = np.asarray(time, np.float64)
    markers = np.asarray(markers, np.float64).reshape(len(time), -1)
    if time.ndim != 1 or markers.shape[1] != 3 * len(labels):
        raise FileFormatError(
            f"{path}: expected time (n,) and markers (n, {3 * len(labels)}), "
            f"got {time.shape} and {markers.shape}"
        )
    if not np.all(np.isfinite(time)) or np.any(np.diff(time) <= 0):
        raise FileFormatError(f"{path}: time must be finite and strictly increasing")
    scale = unit_scale(units, str(path))
    rate = rate_hz if rate_hz is not None else (1.0 / np.median(np.diff(time)) if len(time) > 1 else 1.0)
    n = len(time)
    header = [
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:.10g}\t{rate:.10g}\t{n}\t{len(labels)}\t{units}\t{rate:.10g}\t1\t{n}",
        "Frame#\tTime\t" + "\t".join(f"{m}\t\t" for m in labels).rstrip("\t"),
        "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(len(labels))),
        "",
    ]
    table = np.column_stack([np.arange(1, n + 1), time, markers / scale])
    buf = io.StringIO()
    np.savetxt(buf, table, fmt=["%d", "%.6f"] + ["%.6f"] * markers.shape[1], delimiter="\t")
    # A missing marker is an empty cell in TRC (what OpenSim and Mokka read as a gap).
    body = re.sub(r"(?<=\t)(?:-?nan|-?inf)(?=\t|\n)", "", buf.getvalue())
    return write_text_atomic(path, "\n".join(header) + "\n" + body)
