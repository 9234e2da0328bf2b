"""OpenSim storage files: coordinates ``.mot`` (degrees) and generalized forces ``.sto``
(N·m). A header of ``key=value`` lines up to ``endheader``, a line of column names starting
with ``time``, then one row per frame. Column names come from the body model
(``ikid.coordinate_names``; torques as OpenSim's inverse dynamics names them,
``<coordinate>_moment``). A non-finite value is refused, never written."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ikid import _native
from ikid.io._atomic import atomic_output, check_size
from ikid.io.markers import FileFormatError, read_text_lines


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


def read_storage(path: str | os.PathLike[str]) -> Storage:
    """Read any ``.mot``/``.sto`` file (OpenSim 3 and 4 headers)."""
    path = Path(path)
    src = str(path)
    lines = read_text_lines(path, ".mot/.sto are text")
    try:
        end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    except StopIteration:
        raise FileFormatError(f"{src}: no 'endheader' line: not an OpenSim storage file") from None
    header = {}
    for line in lines[:end]:
        key, sep, value = line.partition("=")
        if sep:
            header[key.strip()] = value.strip()
    in_degrees = header.get("inDegrees", "no").lower() == "yes"
    body = [(i + 1, line) for i, line in enumerate(lines[end + 1 :], start=end + 1) if line.strip()]
    if not body:
        raise FileFormatError(f"{src}: no column names after 'endheader'")
    col_lineno, col_line = body[0]
    columns = tuple(c.strip() for c in (col_line.split("\t") if "\t" in col_line else col_line.split()))
    if not columns or columns[0].lower() != "time":
        raise FileFormatError(f"{src}:{col_lineno}: the first column must be 'time', got {columns[:1]}")
    if len(set(columns)) != len(columns):
        raise FileFormatError(f"{src}:{col_lineno}: repeated column names")
    rows = np.empty((len(body) - 1, len(columns)))
    for k, (lineno, line) in enumerate(body[1:]):
        parts = line.split()
        if len(parts) != len(columns):
            raise FileFormatError(
                f"{src}:{lineno}: {len(parts)} values, expected {len(columns)} (one per column)"
            )
        try:
            rows[k] = [float(p) for p in parts]
        except ValueError:
            raise FileFormatError(f"{src}:{lineno}: not all numbers: {line.strip()[:60]!r}") from None
    if "nRows" in header:
        try:
            expected = int(header["nRows"])
        except ValueError:
            raise FileFormatError(f"{src}: nRows={header['nRows']!r} is not a number") from None
        if expected != len(rows):
            raise FileFormatError(
                f"{src}: header says nRows={expected}, the file has {len(rows)} rows (truncated?)"
            )
    if not np.all(np.isfinite(rows)):
        k = int(np.argwhere(~np.isfinite(rows))[0][0])
        raise FileFormatError(f"{src}:{body[k + 1][0]}: non-finite value")
    time = rows[:, 0]
    if np.any(np.diff(time) <= 0):
        k = int(np.argwhere(np.diff(time) <= 0)[0][0]) + 1
        raise FileFormatError(
            f"{src}:{body[k + 1][0]}: time {time[k]:g} s does not come after the row before's "
            f"({time[k - 1]:g} s): time must increase from row to row"
        )
    return Storage(time, columns[1:], rows[:, 1:], in_degrees, src, header)


#: The header key naming the columns a file does not have because the markers did not
#: determine them (a one-marker hand's s_p): ``ikid_not_determined=ra_wr_s_p``.
NOT_DETERMINED_KEY = "ikid_not_determined"


def not_determined(table: Storage) -> list[str]:
    """The coordinates (or moments) ``table``'s header declares not determined (not written)."""
    value = table.header.get(NOT_DETERMINED_KEY, "")
    return [n.strip() for n in value.split(",") if n.strip()]


def read_mot(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(time, q)``: the wrist angles ``(n, 3)`` in radians, columns found by name; NaN in a
    column the header declares not determined (``ikid_not_determined``), and only there."""
    table = read_storage(path)
    absent = set(not_determined(table)) - set(table.columns)
    present = [c for c in coordinate_names() if c not in absent]
    q = np.full((len(table.time), len(coordinate_names())), np.nan)
    q[:, [coordinate_names().index(c) for c in present]] = table.select(present)
    return table.time, np.radians(q) if table.in_degrees else q


def read_sto(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(time, tau)``: the wrist torques ``(n, 3)`` in N·m (``<coordinate>_moment`` columns; NaN
    in one the header declares not determined, as :func:`read_mot`)."""
    table = read_storage(path)
    absent = set(not_determined(table)) - set(table.columns)
    present = [c for c in moment_names() if c not in absent]
    tau = np.full((len(table.time), len(moment_names())), np.nan)
    tau[:, [moment_names().index(c) for c in present]] = table.select(present)
    return table.time, tau


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
