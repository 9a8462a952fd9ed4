"""Writing files safely: all or nothing, under a lock, and with one-line errors when the file system refuses.

* :func:`atomic_path` -- a file written all or nothing: a temporary file beside it, fsynced, then renamed into place.
  Checkpoint directories have their own protocol (:mod:`hrlp.checkpoint`); every other file hrlp writes (result JSON,
  plots, videos, start banks, counterexamples, logs rewritten on resume) goes through it.
* :func:`directory_lock` -- an OS lock (``fcntl.flock``) on a directory, held for as long as a run writes to it, so
  two processes never write one run directory at once.
* :class:`StorageError` -- what a full disk, a read-only directory or a missing permission becomes: an ``OSError``
  whose message is one line naming the path (``cannot write runs/x/checkpoint: No space left on device``).
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: no advisory locks; directory_lock is then a no-op
    fcntl = None  # type: ignore[assignment]

LOCK_FILE = ".hrlp-lock"
"""The file in a locked directory that holds the lock (and, for information, the holder's pid)."""


class StorageError(OSError):
    """The file system refused a write (full disk, read-only directory, permissions): one line naming the path."""

    def __init__(self, path: Path | str, error: OSError, note: str = "") -> None:
        super().__init__(error.errno, error.strerror or str(error), str(path))
        self.path = Path(path)
        self.note = note

    def __str__(self) -> str:
        return f"cannot write {self.path}: {self.strerror}" + (f" ({self.note})" if self.note else "")


@contextlib.contextmanager
def writing(path: Path | str, note: str = "") -> Iterator[None]:
    """Turn an ``OSError`` raised inside the block into a :class:`StorageError` naming ``path`` (or the file the
    error names, if it names one inside ``path``)."""
    try:
        yield
    except StorageError:
        raise
    except OSError as error:
        raise StorageError(_named(path, error), error, note) from error


def _named(path: Path | str, error: OSError) -> Path:
    """The more precise of ``path`` and the file an OSError names (when that lies at or below ``path``)."""
    path = Path(path)
    if error.filename:
        named = Path(os.fsdecode(error.filename))
        if named == path or path in named.parents:
            return named
    return path


class DirectoryLockedError(ValueError):
    """Another process holds the lock of a directory (see :func:`directory_lock`)."""


_held: dict[tuple[str, int], list[int]] = {}  # (real path, thread id) -> [fd, depth]
_held_guard = threading.Lock()


@contextlib.contextmanager
def directory_lock(directory: Path | str, what: str = "run directory") -> Iterator[None]:
    """Hold an exclusive OS lock (``fcntl.flock`` on ``DIRECTORY/.hrlp-lock``) on ``directory`` for the block.

    Creates ``directory`` if needed. Raises :class:`DirectoryLockedError` at once (never waits) when another process
    -- or another thread of this one -- holds it, naming the directory and the holder's pid. Re-entrant within one
    thread, so a run that holds its directory's lock can save checkpoints (which take it too). The lock is released
    when the block ends or the process dies (the kernel drops it with the file descriptor, so a killed run never
    leaves a stale lock); the lock file itself stays, harmless, but a directory this call created and the block left
    empty (but for the lock file) is removed again. Raises :class:`StorageError` if the directory cannot be created or
    the lock file not written (e.g. a read-only directory).
    """
    directory = Path(directory)
    if fcntl is None:  # pragma: no cover
        yield
        return
    created = not directory.exists()
    with writing(directory):
        directory.mkdir(parents=True, exist_ok=True)
    key = (os.path.realpath(directory), threading.get_ident())
    with _held_guard:
        if key in _held:
            _held[key][1] += 1
            reentered = True
        else:
            reentered = False
    if reentered:
        try:
            yield
        finally:
            with _held_guard:
                _held[key][1] -= 1
        return
    lock_path = directory / LOCK_FILE
    with writing(lock_path):
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as error:
            if error.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise StorageError(lock_path, error) from error
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
            raise DirectoryLockedError(
                f"{directory}: this {what} is in use by another process (pid {holder}); wait for it to finish, "
                "or choose another directory"
            ) from None
        with contextlib.suppress(OSError):  # the pid is for the message above only
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        with _held_guard:
            _held[key] = [fd, 1]
        try:
            yield
        finally:
            with _held_guard:
                del _held[key]
            if created:  # a block that wrote nothing (a run refused before it began) leaves no directory behind
                with contextlib.suppress(OSError):
                    if [q.name for q in directory.iterdir()] == [LOCK_FILE]:
                        lock_path.unlink()
                        directory.rmdir()
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def holds_lock(directory: Path | str) -> bool:
    """Whether this thread holds :func:`directory_lock` on ``directory``."""
    with _held_guard:
        return (os.path.realpath(directory), threading.get_ident()) in _held


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary file beside ``path`` (same suffix) to write ``path``'s contents to, all or nothing.

    When the block ends normally the file is fsynced, given the usual permissions (``mkstemp`` creates 0600) and
    renamed onto ``path``; if it raises, the file is removed and ``path`` is left as it was.
    A file system error (full disk, read-only directory) raises :class:`StorageError` naming ``path``.
    """
    path = Path(path)
    with writing(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        with writing(path):
            yield tmp
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
            os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


__all__ = ["LOCK_FILE", "DirectoryLockedError", "StorageError", "atomic_path", "directory_lock", "holds_lock", "writing"]
