"""OpenSim storage files: coordinates ``.mot`` (degrees) and generalized forces ``.sto``
(N·m). A header of ``key=value`` lines up to ``endheader``, a line of column names starting
with ``time``, then one row per frame. Column names come from the body model
(``ikid.coordinate_names``; torques as OpenSim's inverse dynamics names them,
``<coordinate>_moment``). A non-finite value is refused, never written."""

from __future__ import annotations

import io
import os
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ikid import _native
from ikid.io._atomic import atomic_output, check_size
from ikid.io._common import check_time_increases, numbered_lines
from ikid.io.markers import MAX_FILE_BYTES, FileFormatError, check_readable


def coordinate_names() -> list[str]:
    return [c[0] for c in _native.COORDINATES]


def moment_names() -> list[str]:
    return [f"{c}_moment" for c in coordinate_names()]


@dataclass(frozen=True)
class Storage:
    """The table of a ``.mot``/``.sto`` file, values as written (degrees if ``in_degrees``)."""

    time: np.ndarray
    columns: tuple[str, ...]
    values: np.ndarray
    in_degrees: bool
    source: str = ""
    header: dict[str, str] = field(default_factory=dict)

    def column(self, name: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(name)]
        except ValueError:
            raise _native.InputError(
                f"{self.source}: no column {name!r}; it has {', '.join(self.columns)}"
            ) from None

    def select(self, names: list[str]) -> np.ndarray:
        """``(n, len(names))`` of the named columns; the error lists every absent one."""
        absent = [n for n in names if n not in self.columns]
        if absent:
            raise _native.InputError(
                f"{self.source}: no column(s) {', '.join(absent)}; it has {', '.join(self.columns)}"
            )
        return np.column_stack([self.column(n) for n in names]) if names else np.empty((len(self.time), 0))


#: Rows per block when a storage file is read in blocks (:func:`open_storage`).
BLOCK_ROWS = 65536


@dataclass(frozen=True)
class StorageFile:
    """A ``.mot``/``.sto`` file opened for reading in blocks: its header and column names,
    checked, and its rows as :class:`Storage` blocks in order (:meth:`blocks`, each checked as
    it is read: a bad row raises when its block is reached, naming its line)."""

    columns: tuple[str, ...]
    in_degrees: bool
    source: str
    header: dict[str, str]
    _blocks: Callable[[], Iterator[Storage]]

    def blocks(self) -> Iterator[Storage]:
        """The file's rows, a block at a time (a new pass over the file on each call)."""
        return self._blocks()


def open_storage(
    path: str | os.PathLike[str], block_rows: int | None = None, max_bytes: int | None = None
) -> StorageFile:
    """A ``.mot``/``.sto`` file's header, checked, and its rows in blocks of ``block_rows``
    (default :data:`BLOCK_ROWS`): memory independent of the file's length (OpenSim 3 and 4
    headers). ``max_bytes`` refuses a larger file (:func:`read_storage`'s whole-file limit)."""
    block_rows = block_rows or BLOCK_ROWS
    path = Path(path)
    src = str(path)
    check_readable(path, ".mot/.sto are text", limit=1 << 62 if max_bytes is None else max_bytes)
    header: dict[str, str] = {}
    lines = numbered_lines(path, ".mot/.sto are text, one row per line")
    try:
        lineno, line = next(lines, (0, None))
        while line is not None and line.strip().lower() != "endheader":
            key, sep, value = line.partition("=")
            if sep:
                header[key.strip()] = value.strip()
            lineno, line = next(lines, (lineno, None))
        if line is None:
            raise FileFormatError(f"{src}: no 'endheader' line: not an OpenSim storage file")
        lineno, col_line = next(lines, (lineno, None))
        while col_line is not None and not col_line.strip():
            lineno, col_line = next(lines, (lineno, None))
        if col_line is None:
            raise FileFormatError(f"{src}: no column names after 'endheader'")
    finally:
        lines.close()
    columns = tuple(c.strip() for c in (col_line.split("\t") if "\t" in col_line else col_line.split()))
    if not columns or columns[0].lower() != "time":
        raise FileFormatError(f"{src}:{lineno}: the first column must be 'time', got {columns[:1]}")
    if len(set(columns)) != len(columns):
        raise FileFormatError(f"{src}:{lineno}: repeated column names")
    expected = None
    if "nRows" in header:
        try:
            expected = int(header["nRows"])
        except ValueError:
            raise FileFormatError(f"{src}: nRows={header['nRows']!r} is not a number") from None
    in_degrees = header.get("inDegrees", "no").lower() == "yes"

    def blocks() -> Iterator[Storage]:
        yield from _storage_blocks(path, lineno, columns, in_degrees, header, expected, block_rows)

    return StorageFile(columns[1:], in_degrees, src, header, blocks)


def _storage_blocks(
    path: Path,
    lineno: int,
    columns: tuple[str, ...],
    in_degrees: bool,
    header: dict[str, str],
    expected: int | None,
    block_rows: int,
) -> Iterator[Storage]:
    """The rows after a storage file's column names, ``block_rows`` at a time, checked as they
    are read: one number per column, finite, time increasing, as many rows as ``nRows``."""
    src = str(path)
    seen = 0
    last_time = -np.inf
    lines = numbered_lines(path, ".mot/.sto are text, one row per line", after=lineno)
    try:
        done = False
        while not done:
            numbered: list[tuple[int, str]] = []
            while len(numbered) < block_rows:
                got = next(lines, None)
                if got is None:
                    done = True
                    break
                if got[1].strip():
                    numbered.append(got)
            if not numbered:
                break
            rows = _parse_storage_rows(numbered, len(columns), src)
            if not np.all(np.isfinite(rows)):
                k = int(np.argwhere(~np.isfinite(rows))[0][0])
                raise FileFormatError(f"{src}:{numbered[k][0]}: non-finite value")
            time = rows[:, 0]
            check_time_increases(time, [n for n, _ in numbered], last_time, src)
            last_time = float(time[-1])
            seen += len(rows)
            if expected is not None and seen > expected:
                raise FileFormatError(
                    f"{src}:{numbered[len(rows) - (seen - expected)][0]}: more rows than the header's "
                    f"nRows={expected}"
                )
            yield Storage(time, columns[1:], rows[:, 1:], in_degrees, src, header)
    finally:
        lines.close()
    if expected is not None and seen != expected:
        raise FileFormatError(f"{src}: header says nRows={expected}, the file has {seen} rows (truncated?)")


def _parse_storage_rows(numbered: list[tuple[int, str]], width: int, src: str) -> np.ndarray:
    """Rows ``(n, width)`` of numbered non-blank lines: numpy's parser when every row is whole,
    else line by line, naming the first bad one."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            rows = np.loadtxt(
                io.StringIO("\n".join(line for _, line in numbered)), ndmin=2, comments=None, dtype=np.float64
            )
        if rows.shape == (len(numbered), width):
            return rows
    except ValueError:
        pass
    rows = np.empty((len(numbered), width))
    for k, (lineno, line) in enumerate(numbered):
        parts = line.split()
        if len(parts) != width:
            raise FileFormatError(f"{src}:{lineno}: {len(parts)} values, expected {width} (one per column)")
        try:
            rows[k] = [float(p) for p in parts]
        except ValueError:
            raise FileFormatError(f"{src}:{lineno}: not all numbers: {line.strip()[:60]!r}") from None
    return rows


def read_storage(path: str | os.PathLike[str]) -> Storage:
    """Read any ``.mot``/``.sto`` file (OpenSim 3 and 4 headers) whole: :func:`open_storage`
    reads one of any length in blocks."""
    file = open_storage(path, max_bytes=MAX_FILE_BYTES)
    blocks = list(file.blocks())
    width = len(file.columns)
    return Storage(
        np.concatenate([b.time for b in blocks]) if blocks else np.empty(0),
        file.columns,
        np.concatenate([b.values for b in blocks]) if blocks else np.empty((0, width)),
        file.in_degrees,
        file.source,
        file.header,
    )


#: The header key naming the columns a file does not have because the markers did not
#: determine them (a one-marker hand's s_p): ``ikid_not_determined=ra_wr_s_p``.
NOT_DETERMINED_KEY = "ikid_not_determined"


def not_determined(table: Storage | StorageFile) -> list[str]:
    """The coordinates (or moments) ``table``'s header declares not determined (not written)."""
    value = table.header.get(NOT_DETERMINED_KEY, "")
    return [n.strip() for n in value.split(",") if n.strip()]


def _named_columns(
    table: Storage | StorageFile, names: list[str], angles: bool
) -> Callable[[Storage], np.ndarray]:
    """For a file whose columns include ``names`` (or whose header declares them not
    determined: ``ikid_not_determined``): a block -> its ``(n, len(names))`` values of them, in
    SI (``angles`` in a file in degrees: radians), NaN in a column not determined, and only there. An
    absent column is named when the file is opened, not when its first block is read."""
    absent = set(not_determined(table)) - set(table.columns)
    present = [n for n in names if n not in absent]
    lacking = [n for n in present if n not in table.columns]
    if lacking:
        raise _native.InputError(
            f"{table.source}: no column(s) {', '.join(lacking)}; it has {', '.join(table.columns)}"
        )
    where = [names.index(n) for n in present]

    def values(block: Storage) -> np.ndarray:
        out = np.full((len(block.time), len(names)), np.nan)
        out[:, where] = block.select(present)
        return np.radians(out) if angles and block.in_degrees else out

    return values


def read_mot(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(time, q)``: the wrist angles ``(n, 3)`` in radians, columns found by name; NaN in a
    column the header declares not determined (``ikid_not_determined``), and only there."""
    table = read_storage(path)
    return table.time, _named_columns(table, coordinate_names(), angles=True)(table)


def mot_blocks(
    path: str | os.PathLike[str], block_rows: int | None = None
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """:func:`read_mot` a block of ``block_rows`` rows at a time (see :func:`open_storage`):
    ``(time, q)`` blocks in order, in memory independent of the file's length. The header and
    columns are checked at once; each block's rows as it is read."""
    file = open_storage(path, block_rows)
    angles = _named_columns(file, coordinate_names(), angles=True)
    return ((block.time, angles(block)) for block in file.blocks())


def read_sto(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(time, tau)``: the wrist torques ``(n, 3)`` in N·m (``<coordinate>_moment`` columns; NaN
    in one the header declares not determined, as :func:`read_mot`)."""
    table = read_storage(path)
    return table.time, _named_columns(table, moment_names(), angles=False)(table)


def _check_rows(name: str, time, values, cols: int) -> tuple[np.ndarray, np.ndarray]:
    time = np.asarray(time, np.float64)
    values = np.asarray(values, np.float64)
    if time.ndim != 1 or values.shape != (len(time), cols):
        raise _native.InputError(
            f"{name}: expected time (n,) and values (n, {cols}), got {time.shape} and {values.shape}"
        )
    if not np.all(np.isfinite(time)) or np.any(np.diff(time) <= 0):
        raise _native.InputError(f"{name}: time must be finite and strictly increasing")
    return time, values


def write_storage(
    path: str | os.PathLike[str], time, values, columns: list[str], in_degrees: bool, notes=()
) -> Path:
    """Any table -> OpenSim storage text (atomically). Refuses non-finite values. ``notes``:
    more ``key=value`` header lines."""
    time, values = _check_rows(Path(path).name, time, values, len(columns))
    with storage_writer(path, columns, in_degrees, notes) as table:
        table.write(time, values)
    return Path(path)


class StorageWriter:
    """The rows of one storage file, written a block at a time (:func:`storage_writer`)."""

    def __init__(self, body, name: str, columns: list[str]) -> None:
        self._body, self.name, self.columns = body, name, columns
        self.rows = 0
        self._last_time = -np.inf

    def write(self, time, values) -> None:
        """Appends rows ``time`` ``(k,)``, ``values`` ``(k, len(columns))``; refuses non-finite
        values and time that does not increase (from the rows before, too)."""
        time, values = _check_rows(self.name, time, values, len(self.columns))
        if len(time) == 0:
            return
        if not time[0] > self._last_time:
            raise _native.InputError(f"{self.name}: time must be finite and strictly increasing")
        if not np.all(np.isfinite(values)):
            row, col = np.argwhere(~np.isfinite(values))[0]
            raise _native.InputError(
                f"{self.name}: value {self.columns[col]} at row {self.rows + row} is "
                f"{values[row, col]}; not written"
            )
        # Straight into the file: savetxt makes a class per call (a reference cycle), which
        # would hold a text buffer of each block until the garbage collector ran.
        np.savetxt(
            self._body,
            np.column_stack([time, values]),
            fmt=["%.6f"] + ["%.10g"] * values.shape[1],
            delimiter="\t",
            encoding="utf-8",
        )
        self.rows += len(time)
        self._last_time = float(time[-1])


@contextmanager
def storage_writer(
    path: str | os.PathLike[str], columns: list[str], in_degrees: bool, notes=()
) -> Iterator[StorageWriter]:
    """A storage file written a block at a time, atomically (see :mod:`ikid.io._atomic`): the
    rows go to an unnamed temporary file as they come, and when the block ends the header (its
    ``nRows`` known then) and the rows become the file, checked for size, or nothing does. Memory
    is one block's, whatever the number of rows."""
    name = Path(path).name
    with atomic_output(path) as tmp, tempfile.TemporaryFile(dir=tmp.parent) as body:
        table = StorageWriter(body, name, list(columns))
        yield table
        header = (
            "\n".join(
                [
                    name,
                    "version=1",
                    f"nRows={table.rows}",
                    f"nColumns={len(columns) + 1}",
                    f"inDegrees={'yes' if in_degrees else 'no'}",
                    *notes,
                    "endheader",
                    "time\t" + "\t".join(columns),
                ]
            )
            + "\n"
        )
        head = header.encode("utf-8")
        size = body.tell()
        body.seek(0)
        with open(tmp, "wb") as out:
            out.write(head)
            shutil.copyfileobj(body, out, 1 << 16)
            out.flush()
            os.fsync(out.fileno())
        check_size(tmp, len(head) + size)


#: The column of per-frame ``ikid.FRAME_STATUS`` bits that ikid's writers add (0: nothing
#: unusual); OpenSim reads it as one more column, readers here by name skip it.
STATUS_COLUMN = "ikid_status"


def _with_status(values: np.ndarray, columns: list[str], status) -> tuple[np.ndarray, list[str]]:
    if status is None:
        return values, columns
    status = np.asarray(status)
    if status.shape != (len(values),):
        raise _native.InputError(f"status: expected one value per row ({len(values)}), got {status.shape}")
    return np.column_stack([values, status.astype(np.float64)]), [*columns, STATUS_COLUMN]


def write_mot(path: str | os.PathLike[str], time, q, status=None, undetermined=None) -> Path:
    """Wrist angles ``(n, 3)`` in radians -> ``.mot`` in degrees (``inDegrees=yes``); with
    ``status`` ``(n,)``, each row's ``ikid.FRAME_STATUS`` bits in a last column
    (:data:`STATUS_COLUMN`). Coordinates in ``undetermined`` (names) are not written: the
    header names them (:data:`NOT_DETERMINED_KEY`)."""
    with mot_writer(path, with_status=status is not None, undetermined=undetermined) as write:
        write(time, q, status)
    return Path(path)


def write_sto(path: str | os.PathLike[str], time, tau, status=None, undetermined=None) -> Path:
    """Joint torques ``(n, 3)`` in N·m -> ``.sto`` with OpenSim's ``<coordinate>_moment`` columns
    (and ``status`` and ``undetermined``, as :func:`write_mot`)."""
    with sto_writer(path, with_status=status is not None, undetermined=undetermined) as write:
        write(time, tau, status)
    return Path(path)


#: Writes one block of rows: ``(time, values, status)`` (``status`` ``None`` for a file
#: without the status column).
BlockWrite = Callable[..., None]


def _skipped(names: list[str], undetermined) -> tuple[list[int], list[str]]:
    """The indices of ``names`` (one per coordinate) the markers determine, and the header line
    naming the others (not written)."""
    skip = [k for k, c in enumerate(coordinate_names()) if c in (undetermined or ())]
    notes = [f"{NOT_DETERMINED_KEY}={','.join(names[k] for k in skip)}"] if skip else []
    return [k for k in range(len(names)) if k not in skip], notes


#: Suffix of the column holding the standard deviation of the column before it (same unit).
SD_SUFFIX = "_sd"
#: The header key listing a file's standard-deviation columns: ``ikid_sd=ra_wr_s_p_sd,...``.
SD_KEY = "ikid_sd"


def sd_columns(table: Storage) -> list[str]:
    """The standard-deviation columns ``table``'s header declares (:data:`SD_KEY`)."""
    return [n.strip() for n in table.header.get(SD_KEY, "").split(",") if n.strip()]


@contextmanager
def _coordinate_writer(
    path: str | os.PathLike[str],
    names: list[str],
    in_degrees: bool,
    with_status: bool,
    undetermined,
    with_sd: bool = False,
) -> Iterator[BlockWrite]:
    keep, notes = _skipped(names, undetermined)
    # Each coordinate followed by its standard deviation; a coordinate not written has none.
    columns = [c for k in keep for c in ([names[k], names[k] + SD_SUFFIX] if with_sd else [names[k]])]
    if with_sd:
        notes = [*notes, f"{SD_KEY}={','.join(names[k] + SD_SUFFIX for k in keep)}"]
    columns += [STATUS_COLUMN] if with_status else []
    with storage_writer(path, columns, in_degrees=in_degrees, notes=notes) as table:

        def write(time, values, status=None, sd=None) -> None:
            values = np.asarray(values, np.float64)
            if values.ndim == 2 and values.shape[1] == len(names):
                values = values[:, keep]  # a wrong shape is named by the table's row check
            if with_sd:
                if sd is None:
                    raise _native.InputError(
                        f"{table.name}: declares standard deviations but none were given"
                    )
                sd = np.asarray(sd, np.float64)
                if sd.shape != (len(values), len(names)):
                    raise _native.InputError(
                        f"{table.name}: standard deviations: expected ({len(values)}, {len(names)}), "
                        f"got {sd.shape}"
                    )
                # Each value then its σ; an empty block (every row refused) stays empty.
                values = np.stack([values, sd[:, keep]], axis=2).reshape(len(values), 2 * len(keep))
            elif sd is not None:
                raise _native.InputError(
                    f"{table.name}: standard deviations given to a file without their columns"
                )
            if in_degrees:
                values = np.degrees(values)
            values, _ = _with_status(values, [], status if with_status else None)
            table.write(time, values)

        yield write


@contextmanager
def mot_writer(
    path: str | os.PathLike[str], with_status: bool = True, undetermined=None, with_sd: bool = False
) -> Iterator[BlockWrite]:
    """:func:`write_mot` a block of rows at a time (see :func:`storage_writer`). With ``with_sd``
    each angle is followed by its standard deviation (``<coordinate>_sd``, degrees, listed in the
    header's :data:`SD_KEY` line), given to each write as ``sd`` ``(k, 3)`` in radians."""
    with _coordinate_writer(path, coordinate_names(), True, with_status, undetermined, with_sd) as write:
        yield write


@contextmanager
def sto_writer(
    path: str | os.PathLike[str], with_status: bool = True, undetermined=None, with_sd: bool = False
) -> Iterator[BlockWrite]:
    """:func:`write_sto` a block of rows at a time (see :func:`storage_writer`; ``with_sd`` as
    :func:`mot_writer`: ``<coordinate>_moment_sd``, N·m)."""
    with _coordinate_writer(path, moment_names(), False, with_status, undetermined, with_sd) as write:
        yield write
