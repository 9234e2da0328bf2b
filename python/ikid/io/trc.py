"""TRC marker files (OpenSim, Mokka, Vicon/Cortex exports): tab-separated text, a 5-line
header (``PathFileType``, the ``DataRate ... Units`` key and value lines, the marker labels,
the ``X1 Y1 Z1`` line), then one row per frame. Missing markers are empty cells."""

from __future__ import annotations

import io
import os
import re
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ikid.io._atomic import write_text_atomic
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

_HEADER_LINES = 5


#: Frames per block when a TRC is read in blocks (:func:`open_trc`): ~20 MB of float64 for
#: 20 markers, whatever the file's length.
BLOCK_FRAMES = 65536


def read_trc(path: str | os.PathLike[str]) -> MarkerData:
    """Read a ``.trc`` file; positions in metres whatever its ``Units`` (mm, cm, m). The whole
    file in memory: :func:`open_trc` reads one of any length in blocks."""
    trc = open_trc(path, max_bytes=MAX_FILE_BYTES)
    return concatenate_blocks(trc, list(trc.blocks()))


def open_trc(
    path: str | os.PathLike[str], block_frames: int | None = None, max_bytes: int | None = None
) -> MarkerFile:
    """A ``.trc`` file's header, checked, and its frames in blocks of ``block_frames``
    (:meth:`MarkerFile.blocks`, each checked as it is read: a bad row raises when its block is
    reached, naming its line): memory is independent of the file's length. ``block_frames``
    defaults to :data:`BLOCK_FRAMES`; ``max_bytes`` refuses a larger file (:func:`read_trc`'s
    whole-file limit)."""
    block_frames = block_frames or BLOCK_FRAMES
    path = Path(path)
    src = str(path)
    if max_bytes is None:
        check_readable(path, "TRC is tab-separated text", limit=1 << 62)
    else:
        check_readable(path, "TRC is tab-separated text", limit=max_bytes)
    with _open_text(path) as f:
        raw = [f.readline(MAX_LINE_BYTES + 1) for _ in range(_HEADER_LINES)]
    for k, r in enumerate(raw):
        _check_line_length(r, src, k + 1)
    lines = [_decoded(r, src, k).rstrip("\r\n") for k, r in enumerate(raw, start=1)]
    if not all(raw) or not lines[0].startswith("PathFileType"):
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

    def blocks() -> Iterator[MarkerData]:
        yield from _trc_blocks(path, labels, rate, n_frames, scale, header, block_frames)

    return MarkerFile(labels, rate, src, header["Units"], {"header": header}, n_frames, blocks)


#: Longest line a TRC reader takes, bytes: a row of 1,000 markers is ~40 kB.
MAX_LINE_BYTES = 1 << 20


def _check_line_length(raw: bytes, src: str, lineno: int) -> None:
    if len(raw) > MAX_LINE_BYTES:
        raise FileFormatError(
            f"{src}:{lineno}: a line longer than {MAX_LINE_BYTES} bytes: not TRC text "
            "(tab-separated rows, one per frame)"
        )


def _open_text(path: Path):
    return open(path, "rb")


def _decoded(raw: bytes, src: str, lineno: int) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise FileFormatError(
            f"{src}:{lineno}: not a text file: bytes that are not UTF-8 (TRC is tab-separated text)"
        ) from None


#: An empty cell (a missing marker) between tabs, or before the end of a line.
_EMPTY_CELL = re.compile(r"(?<=\t)(?=\t|\n|$)", re.M)


def _trc_blocks(
    path: Path,
    labels: tuple[str, ...],
    rate: float,
    n_frames: int,
    scale: float,
    header: dict,
    block_frames: int,
) -> Iterator[MarkerData]:
    """The rows of a TRC after its header, ``block_frames`` at a time, checked as
    :func:`read_trc` always has (columns, numbers, NumFrames, increasing time)."""
    src = str(path)
    width = 2 + 3 * len(labels)
    seen = 0
    last_time = -np.inf
    lineno = _HEADER_LINES
    with _open_text(path) as f:
        for _ in range(_HEADER_LINES):
            f.readline(MAX_LINE_BYTES + 1)
        while True:
            # Lines of at most MAX_LINE_BYTES (a file of NUL bytes is one endless "line").
            raw_lines: list[bytes] = []
            size = 0
            while len(raw_lines) < block_frames and size < 1 << 22:
                r = f.readline(MAX_LINE_BYTES + 1)
                if not r:
                    break
                _check_line_length(r, src, lineno + len(raw_lines) + 1)
                raw_lines.append(r)
                size += len(r)
            if not raw_lines:
                break
            # Up to block_frames rows per block (a chunk of ~4 MB of text, split as needed).
            for at in range(0, len(raw_lines), block_frames):
                chunk = [
                    _decoded(r, src, lineno + k).rstrip("\r\n")
                    for k, r in enumerate(raw_lines[at : at + block_frames], start=1)
                ]
                rows = _parse_rows(chunk, lineno, width, src)
                lineno += len(chunk)
                if len(rows) == 0:
                    continue
                if seen + len(rows) > n_frames:
                    extra = n_frames - seen  # the first row beyond NumFrames
                    nonblank = [k for k, line in enumerate(chunk) if line.strip()]
                    bad = lineno - len(chunk) + nonblank[extra] + 1
                    raise FileFormatError(f"{src}:{bad}: more rows than NumFrames ({n_frames})")
                time = rows[:, 1]
                if not np.all(np.isfinite(time)):
                    k = int(np.argmin(np.isfinite(time)))
                    raise FileFormatError(f"{src}:{_HEADER_LINES + 1 + seen + k}: a row has no time")
                steps = np.diff(np.concatenate([[last_time], time]))
                if np.any(steps <= 0):
                    k = int(np.argmax(steps <= 0))
                    before = last_time if k == 0 else time[k - 1]
                    raise FileFormatError(
                        f"{src}: time goes from {before} to {time[k]} s at frame {seen + k + 1}; "
                        "it must increase"
                    )
                if seen == 0:
                    _check_rate_against_times(time, rate, src)
                last_time = float(time[-1])
                positions = rows[:, 2:].reshape(len(rows), len(labels), 3) * scale
                positions[~np.isfinite(positions)] = np.nan
                # A marker is seen or not: a frame with a partial xyz is missing.
                positions[~np.isfinite(positions).all(axis=2)] = np.nan
                # Some exporters write a gap as 0, 0, 0: a marker exactly at the lab's origin in
                # some frames and elsewhere in others was not seen there (one at the origin
                # throughout is left as it is: a file in a marker's own frame).
                at_origin = (positions == 0.0).all(axis=2)
                positions[at_origin & ~at_origin.all(axis=0)] = np.nan
                seen += len(rows)
                yield MarkerData(labels, time, positions, rate, src, header["Units"], {"header": header})
    if seen != n_frames:
        raise FileFormatError(f"{src}: header says {n_frames} frames, the file has {seen} (truncated?)")


def _check_rate_against_times(time: np.ndarray, rate: float, src: str) -> None:
    """Refuses a file whose header's DataRate contradicts its Time column by more than 1 %:
    which one is right cannot be known, and every rate-dependent result (the model's member,
    velocities, torques) would follow the header. The step is the mean of the regular steps
    (under 1.5 of the median: time gaps left out), so times printed to a few decimals (8 and
    9 ms at 120 Hz) average to the true one."""
    steps = np.diff(time)
    if len(steps) < 10:
        return
    regular = steps[steps < 1.5 * np.median(steps)]
    step = float(regular.mean()) if len(regular) >= 10 else float(np.median(steps))
    if abs(step * rate - 1.0) > 0.01:
        raise FileFormatError(
            f"{src}: its header's DataRate is {rate:g} Hz but its Time column steps {1e3 * step:.4g} ms "
            f"({1.0 / step:.5g} Hz): which one is right cannot be known; correct the one that is wrong "
            "(DataRate and CameraRate on the header's third line, or the times)"
        )


def _parse_rows(chunk: list[str], first_lineno: int, width: int, src: str) -> np.ndarray:
    """Rows ``(n, width)`` of a chunk of TRC lines (blank lines skipped, empty cells NaN): numpy's
    parser when every row is whole, else row by row, naming the first bad line."""
    text = "\n".join(line for line in chunk if line.strip())
    if not text:
        return np.empty((0, width))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            rows = np.loadtxt(
                io.StringIO(_EMPTY_CELL.sub("nan", text)), delimiter="\t", ndmin=2, dtype=np.float64
            )
        if rows.shape[1] == width:
            return rows
    except ValueError:
        pass
    parsed: list[list[float]] = []
    for lineno, line in enumerate(chunk, start=first_lineno + 1):
        if not line.strip():
            continue
        parts = line.split("\t")
        # Some writers drop trailing empty cells of missing markers.
        if len(parts) > width and any(p.strip() for p in parts[width:]):
            raise FileFormatError(f"{src}:{lineno}: {len(parts)} columns, expected at most {width}")
        try:
            row = [float(p) if p.strip() else np.nan for p in parts[:width]]
        except ValueError:
            bad = next(p for p in parts[:width] if p.strip() and not is_float(p))
            raise FileFormatError(f"{src}:{lineno}: {bad!r} is not a number") from None
        parsed.append(row + [np.nan] * (width - len(row)))
    return np.array(parsed, np.float64).reshape(len(parsed), width)


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
