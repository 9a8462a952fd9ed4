"""Writing a file all or nothing: a temporary file beside it, fsynced, then renamed into place.

Checkpoint directories have their own protocol (:mod:`hrlp.checkpoint`); every other file hrlp writes (result JSON,
plots, videos, start banks, counterexamples) goes through :func:`atomic_path`.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary file beside ``path`` (same suffix) to write ``path``'s contents to, all or nothing.

    When the block ends normally the file is fsynced, given the usual permissions (``mkstemp`` creates 0600) and
    renamed onto ``path``; if it raises, the file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
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


__all__ = ["atomic_path"]
