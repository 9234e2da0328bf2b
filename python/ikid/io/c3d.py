"""C3D marker files, read and written with ezc3d.

ezc3d's C++ parser can crash the process on a corrupted parameter section (measured: 3 of
200 single-byte flips in a valid file segfaulted ezc3d 1.7.2) and silently returns fewer
frames from a truncated file. So :func:`read_c3d` parses in a child process — a crash or
hang there becomes a :class:`FileFormatError` naming the file — and checks the frame count
against the header. Points with a negative residual (C3D's "not seen") are NaN.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from ikid._native import InputError
from ikid.io._atomic import Incomplete, atomic_output
from ikid.io._common import parse_up
from ikid.io.markers import FileFormatError, MarkerData, check_readable, unit_scale

#: Wall-clock limit of the child that parses one file, seconds (a corrupt header can make a
#: parser loop or allocate without end).
PARSE_TIMEOUT_S = 120.0


#: What the child process runs: parse ``argv[1]`` into ``argv[2]``.
_CHILD = "import sys; from ikid.io.c3d import _parse_into; _parse_into(sys.argv[1], sys.argv[2])"


def _ezc3d():
    try:
        import ezc3d
    except ImportError:  # pragma: no cover - ezc3d is a dependency of the wheel
        raise ImportError("reading C3D needs ezc3d: pip install ezc3d") from None
    return ezc3d


def _parse_into(path: str, out: str) -> None:
    """Child side: parse ``path`` with ezc3d and save the arrays to ``out`` (.npz)."""
    ezc3d = _ezc3d()
    c = ezc3d.c3d(path)
    point = c["parameters"]["POINT"]
    header = c["header"]["points"]
    labels = list(point["LABELS"]["value"])
    # More than 255 labels continue in LABELS2, LABELS3, ...
    k = 2
    while f"LABELS{k}" in point:
        labels += list(point[f"LABELS{k}"]["value"])
        k += 1
    units = point["UNITS"]["value"][0] if "UNITS" in point and len(point["UNITS"]["value"]) else ""
    # The axis the lab displays upwards (Vicon and Qualisys write "+Z", OpenSim's exports "+Y").
    screen = point.get("Y_SCREEN", {}).get("value", [])
    np.savez(
        out,
        points=np.asarray(c["data"]["points"], np.float64),
        residuals=np.asarray(c["data"]["meta_points"]["residuals"], np.float64),
        labels=np.array(labels, dtype=str),
        units=np.array(units),
        rate=np.array(
            float(point["RATE"]["value"][0]) if len(point["RATE"]["value"]) else float(header["frame_rate"])
        ),
        first_frame=np.array(int(header["first_frame"])),
        y_screen=np.array(str(screen[0]).strip() if len(screen) else ""),
    )


def _header_frame_count(path: Path) -> tuple[int, bool] | None:
    """Frames the file's own 512-byte header announces (ezc3d reports what it managed to
    read instead), and whether the 16-bit field is saturated (long files). None if the
    header is too broken to say; the parser then reports why."""
    with open(path, "rb") as f:
        head = f.read(512)
        if len(head) < 10 or head[1] != 0x50 or head[0] < 2:
            return None
        f.seek((head[0] - 1) * 512 + 3)
        processor = f.read(1)
    # Parameter section byte 4: 84 Intel, 85 DEC (both little-endian), 86 MIPS (big-endian).
    endian = ">" if processor == b"\x56" else "<"
    first, last = struct.unpack(endian + "HH", head[6:10])
    return last - first + 1, last == 0xFFFF


def _unreadable_because(path: Path, parser_said: str) -> str:
    """Why ezc3d could not read ``path``, in a lab's words: its message without the advice to
    set ezc3d's ``ignoreBadFormatting`` (no ikid option) and without the Python exception's name,
    and, where the file is shorter than a header or stops before what it announces, that first."""
    said = parser_said.split(": ", 1)[1] if parser_said.split(": ", 1)[0].isidentifier() else parser_said
    said = said.replace(" If you want to ignore this error, set ignoreBadFormatting to true", "")
    size = path.stat().st_size
    if size < 512:
        return f"{size} bytes, shorter than a C3D file's 512-byte header (cut short, or not a C3D file)"
    if "iostream error" in said or said.startswith("Could not read"):
        return (
            f"it stops ({size} bytes) before the parameters or data its header announces: the file was "
            f"cut short (an interrupted copy or export) or is not a C3D file (the parser: {said})"
        )
    return said


def read_c3d(path: str | os.PathLike[str]) -> MarkerData:
    """Read the 3D points of a ``.c3d`` file; positions in metres, NaN where not seen."""
    path = Path(path)
    src = str(path)
    if not path.exists():
        raise FileNotFoundError(f"{src}: no such file")
    check_readable(path, "a C3D file")
    with tempfile.TemporaryDirectory(prefix="ikid-c3d-") as tmp:
        out = os.path.join(tmp, "points.npz")
        try:
            run = subprocess.run(
                [sys.executable, "-c", _CHILD, src, out],
                capture_output=True,
                text=True,
                timeout=PARSE_TIMEOUT_S,
            )
        except subprocess.TimeoutExpired:
            raise FileFormatError(
                f"{src}: reading it took over {PARSE_TIMEOUT_S:.0f} s; the file is corrupt"
            ) from None
        if run.returncode != 0:
            last = (run.stderr.strip().splitlines() or ["no message"])[-1]
            if run.returncode < 0:
                last = f"the C3D parser crashed (signal {-run.returncode})"
            raise FileFormatError(f"{src}: not a readable C3D file: {_unreadable_because(path, last)}")
        with np.load(out) as z:
            points, residuals = z["points"], z["residuals"]
            labels = tuple(str(s).strip() for s in z["labels"])
            units, rate = str(z["units"]), float(z["rate"])
            first_frame = int(z["first_frame"])
            y_screen = str(z["y_screen"]) if "y_screen" in z else ""
    n_frames = points.shape[2]
    announced = _header_frame_count(path)
    if announced is not None:
        count, saturated = announced
        if n_frames < count or (n_frames > count and not saturated):
            raise FileFormatError(
                f"{src}: header says {count} frames, the file holds {n_frames} (truncated?)"
            )
    if points.shape[1] != len(labels):
        raise FileFormatError(f"{src}: {points.shape[1]} points but {len(labels)} labels")
    if len(set(labels)) != len(labels):
        dup = sorted({lab for lab in labels if labels.count(lab) > 1})
        raise FileFormatError(f"{src}: point label(s) {', '.join(dup)} appear more than once")
    if not units:
        raise FileFormatError(f"{src}: POINT:UNITS is empty; cannot tell mm from m")
    scale = unit_scale(units, src)
    positions = np.transpose(points[:3], (2, 1, 0)) * scale
    positions[(residuals[0].T < 0) | ~np.isfinite(positions).all(axis=2)] = np.nan
    metadata: dict = {"first_frame": first_frame}
    try:
        metadata |= {"up": parse_up(y_screen, src), "up_from": f"the C3D's POINT:Y_SCREEN = {y_screen!r}"}
    except FileFormatError:
        pass  # none, or not an axis: the file does not say which way is up
    return MarkerData(labels, np.arange(n_frames) / rate, positions, rate, src, units, metadata)


def write_c3d(path: str | os.PathLike[str], data: MarkerData, units: str = "mm") -> Path:
    """Write marker trajectories as a ``.c3d`` file (float points; NaN stays NaN, read back as unseen).
    Written to a temporary name, read back (header, point and frame counts, size) and only then
    renamed: ezc3d does not report write errors (a full disk gives a short file and success),
    so a file that did not reach the disk whole is a :class:`ikid.WriteError` naming ``path``,
    and the previous file stays as it was."""
    ezc3d = _ezc3d()
    path = Path(path)
    scale = unit_scale(units, str(path))
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(data.rate_hz)]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(data.labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    if data.metadata.get("up"):  # the lab's up axis, declared as Vicon and Qualisys declare it
        c.add_parameter("POINT", "Y_SCREEN", [str(data.metadata["up"]).upper()])
    if data.metadata.get("first_frame"):  # a capture cut from a longer one keeps its numbering
        c["header"]["points"]["first_frame"] = int(data.metadata["first_frame"])
    positions = _on_frame_grid(data, path)
    pts = np.ones((4, len(data.labels), len(positions)))
    pts[:3] = np.transpose(positions / scale, (2, 1, 0))
    c["data"]["points"] = pts
    n_frames, n_points = len(positions), len(data.labels)
    with atomic_output(path, suffix=".c3d", verify=lambda tmp: check_c3d(tmp, n_frames, n_points)) as tmp:
        try:
            c.write(str(tmp))
        except RuntimeError as e:  # ezc3d's own complaints (it raises few)
            raise Incomplete(f"ezc3d: {e}") from None
    return path


def _on_frame_grid(data: MarkerData, path: Path) -> np.ndarray:
    """``data``'s positions one row per frame of its rate from its first time: a C3D's frames
    are evenly spaced, its times implied, so frames a gap in ``data.time`` left out are
    written as frames without markers (NaN), never closed up (every later time would move).
    Times off that grid are an :class:`ikid.InputError` naming ``path``."""
    time = np.asarray(data.time, np.float64)
    if len(time) == 0:
        return np.asarray(data.positions, np.float64)
    slots = (time - time[0]) * float(data.rate_hz)
    index = np.rint(slots).astype(np.int64)
    off = np.flatnonzero(np.abs(slots - index) > 0.25)
    if len(off) or np.any(np.diff(index) <= 0):
        at = int(off[0]) if len(off) else int(np.flatnonzero(np.diff(index) <= 0)[0]) + 1
        raise InputError(
            f"{path}: row {at}'s time {time[at]:g} s is not a frame of {float(data.rate_hz):g} Hz after the "
            "previous rows (a C3D's frames are evenly spaced, their times implied): resample the "
            "trajectories to the rate first (ikid.io.resample)"
        )
    positions = np.full((int(index[-1]) + 1, *np.shape(data.positions)[1:]), np.nan)
    positions[index] = data.positions
    return positions


def check_c3d(path: Path, n_frames: int, n_points: int) -> None:
    """:class:`~ikid.io._atomic.Incomplete` unless the C3D file at ``path`` has a header
    announcing ``n_points`` points and ``n_frames`` frames and is long enough to hold them
    (parameter blocks, then every frame's points). A light parse of the 512-byte header, not
    ezc3d: the writer's own reader would not be an independent check."""
    size = os.stat(path).st_size
    with open(path, "rb") as f:
        head = f.read(512)
        if len(head) < 512 or head[1] != 0x50 or head[0] < 2:
            raise Incomplete(f"read back {size} bytes without a C3D header")
        f.seek((head[0] - 1) * 512 + 3)
        processor = f.read(1)
    endian = ">" if processor == b"\x56" else "<"
    points, analog, first, last = struct.unpack(endian + "HHHH", head[2:10])
    (scale,) = struct.unpack(endian + "f", head[12:16])
    (data_start,) = struct.unpack(endian + "H", head[16:18])
    if points != n_points:
        raise Incomplete(f"read back {points} points in the header, {n_points} were written")
    if last != 0xFFFF and last - first + 1 != n_frames:
        raise Incomplete(f"read back {last - first + 1} frames in the header, {n_frames} were written")
    if data_start <= head[0]:
        raise Incomplete(f"read back {size} bytes; the header places the data at block {data_start}")
    word = 4 if scale < 0 else 2  # float or 16-bit integer data
    need = (data_start - 1) * 512 + n_frames * (4 * points + analog) * word
    if size < need:
        raise Incomplete(
            f"read back {size} bytes, the header's {n_points} points x {n_frames} frames need {need}"
        )
