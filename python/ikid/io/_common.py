"""What every reader shares, below them all: the file-format error, bounded reads of a file
(never a directory, a pipe or ``/dev/zero``), length units, ikid's marker names. A leaf: it
imports no other module of ``ikid.io``, so ``markers`` and ``mapping`` both import it and
not each other in a circle."""

from __future__ import annotations

import os
import stat
from collections.abc import Generator, Sequence
from pathlib import Path

import numpy as np

from ikid import _native

#: Length units a marker file may state, and their size in metres.
UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


class FileFormatError(_native.InputError):
    """A file that cannot be read as what it claims to be; the message names the file and
    what is wrong (and the line, for text formats)."""


class MarkerMapWarning(UserWarning):
    """A marker map that the recording's markers contradict
    (:meth:`ikid.io.mapping.MarkerMap.stretched_segments`, a cluster's marker off its shape)."""


class UndeterminedWarning(UserWarning):
    """Frames whose markers do not determine a coordinate (a one-marker hand's ``ra_wr_s_p``,
    :attr:`ikid.io.mapping.MarkerMap.undetermined`) that the models, the Tracker and streams
    nevertheless give a value for: leave that coordinate out (the CLI does; this warning is
    for the Python API)."""


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
    ``/dev/zero`` never end) or larger than ``limit``. A missing file is an
    :class:`ikid.NotFoundError` (a ``FileNotFoundError`` too) naming it."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise _native.NotFoundError(f"{path}: no such file or directory") from None
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


#: Longest line a text reader takes, characters (a file of NUL bytes is one endless "line").
MAX_LINE_CHARS = 1 << 20


def numbered_lines(path: Path, what: str, after: int = 0) -> Generator[tuple[int, str], None, None]:
    """A UTF-8 text file's numbered lines from line ``after + 1`` on, without their ends
    (``\n``, ``\r\n`` or ``\r``, as :func:`read_text_lines` splits them), read one at a time
    (a reader in blocks). A line over :data:`MAX_LINE_CHARS` is refused (a file of NUL bytes is
    not read whole as one line), and so is a file that is not UTF-8; ``what`` says what the file
    should be (``".mot/.sto are text"``).
    Close it (``.close()``) when stopping early."""
    src = str(path)
    lineno = 0
    # Undecodable bytes are kept as surrogates and named with their line (a strict decoder
    # fails on the whole 8 KB chunk it decodes, lines before the bad one).
    with open(path, encoding="utf-8", errors="surrogateescape", newline=None) as f:
        while line := f.readline(MAX_LINE_CHARS + 1):
            lineno += 1
            if len(line) > MAX_LINE_CHARS:
                raise FileFormatError(
                    f"{src}:{lineno}: a line longer than {MAX_LINE_CHARS} characters ({what})"
                )
            if not line.isascii():
                try:
                    line.encode("utf-8")
                except UnicodeEncodeError:
                    raise FileFormatError(
                        f"{src}:{lineno}: not a text file: bytes that are not UTF-8 ({what})"
                    ) from None
            if lineno > after:
                yield lineno, line.rstrip("\n")


def check_time_increases(time: np.ndarray, linenos: Sequence[int], last: float, src: str) -> None:
    """A text reader's block of row times, each after the one before (``last``: the block
    before's last, ``-inf`` for the first); an error naming the first row's line that is not."""
    steps = np.diff(np.concatenate([[last], time]))
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        before = last if k == 0 else time[k - 1]
        raise FileFormatError(
            f"{src}:{linenos[k]}: time {time[k]:g} s does not come after the row before's "
            f"({before:g} s): time must increase from row to row"
        )


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


#: The axes a lab may name as its vertical (pointing up, against gravity). ikid's own lab — its
#: simulator, body model and torque networks — has +Y up, as OpenSim's; a lab with another up
#: axis is turned into it before frames reach the core (:func:`to_ikid_lab`). Angles do not
#: depend on it (they are relative between segments); torques do, through gravity.
UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")


def parse_up(value: object, source: str) -> str:
    """A lab's up axis as one of :data:`UP_AXES` from ``"z"``, ``"+Z"``, ``"-y"``…; an error
    naming ``source`` otherwise. The grammar is the core's (``body::up_axis``, what
    ``ikid.Tracker(up=)`` and ``model.stream(up=)`` read)."""
    try:
        axis = _native.lab_up_axis(value) if isinstance(value, str) else None
    except _native.InputError:
        axis = None
    if axis is None:
        raise FileFormatError(
            f"{source}: up = {value!r}; expected the lab axis pointing up, one of {', '.join(UP_AXES)} "
            '(Vicon and Qualisys labs are usually "+z", OpenSim\'s "+y")'
        )
    return UP_AXES[2 * int(np.argmax(np.abs(axis))) + (1 if min(axis) < 0 else 0)]


def to_ikid_lab(positions: np.ndarray, up: str) -> np.ndarray:
    """``positions`` of a lab whose ``up`` axis (one of :data:`UP_AXES`) points up, in ikid's
    lab (+Y up): points ``(..., 3)`` or ikid's marker frames ``(..., 18)``. What ``ikid.Tracker``
    and the torque models take (the readers turn a file's frames themselves, :meth:`MarkerData.lab_up`)."""
    positions = np.asarray(positions, np.float64)
    if up == "+y":
        return positions
    # The core's turn (body::lab_turn), the one ikid.Tracker(up=) and model.stream(up=) make.
    rotation = _native.lab_turn(parse_up(up, "up"))
    if positions.shape[-1] == 18:
        return (positions.reshape(*positions.shape[:-1], 6, 3) @ rotation.T).reshape(positions.shape)
    return positions @ rotation.T
