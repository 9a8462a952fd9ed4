"""Where hrlp keeps a user's files (imports nothing heavy: the command line's option checks and the arm's tasks read it)."""

from __future__ import annotations

import os
from pathlib import Path

#: The environment variable that names the user's skill library.
SKILLS_ENV = "HRLP_SKILLS"


def default_library_root() -> Path:
    """``$HRLP_SKILLS`` if set, else ``~/.hrlp/skills``."""
    return Path(os.environ.get(SKILLS_ENV, Path.home() / ".hrlp" / "skills"))


__all__ = ["SKILLS_ENV", "default_library_root"]
