"""Atomic output: a file appears whole or not at all, and files that belong together appear
together or not at all. Every writer in ikid goes through here.

A file is written to a temporary name beside its target, flushed to the disk (``fsync``) and
checked — its size against the bytes meant for it, or a read-back ``verify`` for writers that
hide their own write errors (ezc3d) — and only then renamed onto the target; the folder is
synced after the rename where the OS allows it. Any failure removes the temporary file,
leaves the previous file byte for byte as it was and raises :class:`WriteError` naming the
file (never a bare ``[Errno 27] File too large``).

Inside ``with atomic_outputs():`` the renames wait for the end of the block: outputs that go
together (``ikid run``'s ``.mot`` and ``.sto``) replace the old ones only when every one of
them was written and checked, and if a rename fails part-way the ones already renamed are
put back.
"""

from __future__ import annotations

import errno
import glob
import os
import secrets
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path

from ikid import _native


class WriteError(_native.IkidError, OSError):
    """A file could not be written whole (a full disk, a file size limit, no permission, a
    writer that stopped short); the message names it. The previous file, if any, is unchanged.
    Also an ``OSError``; ``errno`` is the system's error number when there was one."""


class Incomplete(Exception):
    """Raised by a ``verify`` check with the reason a written file is not what was meant."""


#: A check of a written temporary file before it is renamed: raises :class:`Incomplete` (or an
#: ``OSError``) with the reason if the file is not what was meant.
Verify = Callable[[Path], None]


@contextmanager
def atomic_output(
    path: str | os.PathLike[str], suffix: str = "", *, verify: Verify | None = None
) -> Iterator[Path]:
    """A temporary path beside ``path`` to write to. When the block ends the file is synced to
    the disk, checked by ``verify`` (if given) and renamed onto ``path`` (inside
    :func:`atomic_outputs`, at the end of that block). If the block, the sync or the check
    fails, the temporary file is removed, ``path`` is untouched and the error is raised — an
    ``OSError`` as a :class:`WriteError` naming ``path``."""
    path = Path(path)
    tmp = _temp_beside(path, suffix)
    try:
        yield tmp
        _sync_file(tmp)
        if verify is not None:
            verify(tmp)
        # mkstemp makes the file private (0600); the output gets what open() would give it.
        os.chmod(tmp, 0o666 & ~_umask())
    except BaseException as e:
        tmp.unlink(missing_ok=True)
        if isinstance(e, Incomplete):
            raise _write_error(path, e) from None
        if isinstance(e, _native.IkidError) or not isinstance(e, OSError):
            raise
        raise _write_error(path, e) from e
    staged = _STAGED.get()
    if staged is not None:
        staged.add(_Staged(tmp, path))
    else:
        _commit([_Staged(tmp, path)])


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """``text`` as UTF-8 (whatever the locale says), atomically; the file's size is checked
    against the bytes meant for it."""
    data = text.encode("utf-8")
    return write_bytes_atomic(path, data)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> Path:
    """``data``, atomically and checked (see the module doc)."""
    with atomic_output(path, verify=lambda tmp: check_size(tmp, len(data))) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    return Path(path)


def check_size(tmp: Path, expected: int) -> None:
    """:class:`Incomplete` if the file at ``tmp`` does not hold exactly ``expected`` bytes."""
    size = os.stat(tmp).st_size
    if size != expected:
        raise Incomplete(f"{size} of its {expected} bytes reached the disk")


@contextmanager
def atomic_outputs() -> Iterator[list[Path]]:
    """Outputs that belong together: every :func:`atomic_output` inside the block (in this
    thread or task) is written and checked as usual, but renamed onto its target only when
    the whole block succeeded, all in a row; if the block raises, none is renamed and the
    temporary files are removed. Yields the list of target paths staged so far.

    A rename failing part-way (rare: the files are beside their targets) puts back the files
    already replaced. Nested blocks join the outermost one."""
    if _STAGED.get() is not None:  # nested: the outer block commits
        outer = _STAGED.get()
        assert outer is not None
        yield outer.paths
        return
    group = _Group()
    token = _STAGED.set(group)
    try:
        yield group.paths
    except BaseException as e:
        _STAGED.reset(token)
        group.discard()
        if isinstance(e, WriteError) and group.staged:
            others = ", ".join(str(s.path) for s in group.staged)
            raise WriteError(
                f"{e}; so none of the outputs that go with it was replaced either ({others})"
            ) from e
        raise
    _STAGED.reset(token)
    _commit(group.staged)


# --- private helpers ---------------------------------------------------------------------------


@dataclass
class _Staged:
    tmp: Path
    path: Path


class _Group:
    """The files an :func:`atomic_outputs` block has written and not yet renamed."""

    def __init__(self) -> None:
        self.staged: list[_Staged] = []
        self.paths: list[Path] = []

    def add(self, item: _Staged) -> None:
        for old in [s for s in self.staged if s.path == item.path]:  # written twice: the last wins
            old.tmp.unlink(missing_ok=True)
            self.staged.remove(old)
            self.paths.remove(old.path)
        self.staged.append(item)
        self.paths.append(item.path)

    def discard(self) -> None:
        for s in self.staged:
            s.tmp.unlink(missing_ok=True)


_STAGED: ContextVar[_Group | None] = ContextVar("ikid_atomic_outputs", default=None)

#: A target that exists but could not be kept aside (not a regular file, or no hard links here).
_NOT_KEPT = Path()


def _commit(staged: list[_Staged]) -> None:
    """Rename every temporary file onto its target, in order; if one rename fails, put back
    what the earlier ones replaced and remove every temporary file."""
    kept: list[tuple[Path, Path | None]] = []  # (target, its previous file kept aside, or None: none)
    try:
        for s in staged:
            old = _keep_aside(s.path) if len(staged) > 1 else _NOT_KEPT
            try:
                os.replace(s.tmp, s.path)
            except OSError as e:
                _drop(old)  # this target was not replaced
                _put_back(kept)
                raise _write_error(s.path, e) from e
            kept.append((s.path, old))
    finally:
        for s in staged:
            s.tmp.unlink(missing_ok=True)  # those not renamed
    for _, old in kept:
        _drop(old)
    for folder in {s.path.parent for s in staged}:
        _sync_dir(folder)


def _drop(old: Path | None) -> None:
    if old is not None and old is not _NOT_KEPT:
        old.unlink(missing_ok=True)


def _keep_aside(path: Path) -> Path | None:
    """A hard link to the file at ``path`` under a temporary name (so it can be put back),
    None if there is no file there, :data:`_NOT_KEPT` if it cannot be kept."""
    if not os.path.lexists(path):
        return None
    if not (path.is_file() or path.is_symlink()):
        return _NOT_KEPT
    for _ in range(100):
        aside = path.with_name(f".{path.name}.{secrets.token_hex(4)}.old")
        try:
            os.link(path, aside, follow_symlinks=False)
            return aside
        except FileExistsError:
            continue
        except OSError:
            return _NOT_KEPT
    return _NOT_KEPT


def _put_back(kept: list[tuple[Path, Path | None]]) -> None:
    for target, old in reversed(kept):
        try:
            if old is None:
                target.unlink(missing_ok=True)  # it was new: nothing was there before
            elif old is not _NOT_KEPT:
                os.replace(old, target)
        except OSError:  # pragma: no cover - best effort; the original error is raised
            pass


def remove_temporaries(path: str | os.PathLike[str], since: float) -> list[Path]:
    """Remove the temporary files a writer of ``path`` left beside it, modified at or after
    ``since`` (``time.time()``; less a second, the file system's clock steps): what a process
    killed outright (SIGKILL, which no clean-up sees) leaves while writing. Older ones are left
    alone. Returns the files removed."""
    path = Path(path)
    removed: list[Path] = []
    try:
        candidates = list((path.parent or Path(".")).glob(f".{glob.escape(path.name)}.*"))
    except OSError:
        return removed
    for tmp in candidates:
        try:
            if tmp.is_file() and not tmp.is_symlink() and tmp.stat().st_mtime >= since - 1.0:
                tmp.unlink()
                removed.append(tmp)
        except OSError:
            pass
    return removed


def _temp_beside(path: Path, suffix: str) -> Path:
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent or ".")
    except OSError as e:
        if not (path.parent or Path(".")).is_dir():
            raise WriteError(f"{path}: cannot write it: no folder {path.parent}") from e
        raise _write_error(path, e) from e
    os.close(fd)
    return Path(tmp)


def _sync_file(path: Path) -> None:
    """Flush ``path``'s bytes to the disk (a write error the kernel deferred shows up here)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _sync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable, where the OS and file system allow it."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems refuse fsync on a folder; the rename itself is done
    finally:
        os.close(fd)


def _write_error(path: Path, e: OSError | Incomplete) -> WriteError:
    code = e.errno if isinstance(e, OSError) else None
    reason = (e.strerror if isinstance(e, OSError) else None) or str(e) or type(e).__name__
    if code == errno.EFBIG:
        reason += " (a file size limit)"
    elif code == errno.ENOSPC:
        reason += " (the disk is full)"
    err = WriteError(f"{path}: could not write it whole: {reason}; the previous file, if any, is unchanged")
    err.errno = code
    return err


def _umask() -> int:
    mask = os.umask(0)  # the only way to read it; set straight back
    os.umask(mask)
    return mask
