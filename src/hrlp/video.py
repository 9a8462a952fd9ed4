"""Writing rollouts to video files, atomically (a killed process never leaves a half-written file)."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

VIDEO_SUFFIXES = (".mp4", ".gif")


def check_video_path(path: Path) -> None:
    """Raise ValueError, before any compute, if ``path`` cannot hold a video."""
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise ValueError(f"video file must end in {' or '.join(VIDEO_SUFFIXES)}, got {path.name!r}")
    parent = path.parent if str(path.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise ValueError(f"cannot write {path}: {parent} is not a directory")


def write_video(path: Path, frames: Iterable[np.ndarray], fps: int) -> int:
    """Write RGB frames [H, W, 3] (uint8) to ``path`` (.mp4 or .gif); returns the number of frames.

    The video is written to a temporary file in the same directory and renamed into place.
    """
    import imageio.v2 as imageio

    check_video_path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file the usual permissions
    n = 0
    try:
        if path.suffix.lower() == ".mp4":
            writer = imageio.get_writer(tmp, fps=fps, codec="libx264", quality=7, macro_block_size=8)
        else:
            writer = imageio.get_writer(tmp, mode="I", duration=1000 / fps, loop=0)
        with writer:
            for frame in frames:
                writer.append_data(frame)
                n += 1
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return n
