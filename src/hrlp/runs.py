"""Find and summarise run directories (``hrlp runs``): task, skills, steps, success, and whether a trainer holds them.

Reads only ``config.json``, the last row of ``progress.csv`` and, for runs of ``hrlp reproduce``, ``result.json``: no
checkpoint is loaded and nothing is written, so listing is fast, torch-free and safe beside running trainers.
"""

from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

from hrlp.atomic import LOCK_FILE

try:
    import fcntl
except ImportError:  # pragma: no cover (not POSIX)
    fcntl = None  # type: ignore[assignment]

#: Folders never searched for runs (TensorBoard logs, checkpoints).
_SKIP = frozenset({"tb", "checkpoint", "checkpoint.old", "__pycache__"})


@dataclass(frozen=True)
class RunInfo:
    """What ``hrlp runs`` shows for one run directory."""

    path: Path
    task: str
    """The task id, with the Manager's skills for a Manager run, e.g. ``ReachAndGrip1 [gripper, reacher]``."""
    steps: int
    """Environment steps trained (the last logged iteration)."""
    budget: int
    """Environment steps asked for (the config's ``steps``)."""
    train_success: float | None
    """Success rate of the last iteration's training episodes (None: the task reports none, or nothing logged yet)."""
    eval_success: float | None
    """Greedy evaluation success of ``hrlp reproduce``'s ``result.json`` (None: not evaluated)."""
    state: str
    """``running`` (a trainer holds the directory's lock), ``finished`` (steps >= budget, or the episode budget spent)
    or ``stopped``."""
    problem: str | None = None
    """Why a file could not be read (the other fields are then what could be read)."""


def _locked(directory: Path) -> bool:
    """Whether a process holds the directory's lock (probed with a shared, non-blocking lock; nothing is written)."""
    if fcntl is None:  # pragma: no cover
        return False
    try:
        fd = os.open(directory / LOCK_FILE, os.O_RDONLY | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)


def _last_row(path: Path) -> dict[str, str] | None:
    try:
        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
    except FileNotFoundError:
        return None
    return rows[-1] if rows else None


def _number(value: str | None) -> float | None:
    try:
        v = float(value) if value not in (None, "") else math.nan
    except ValueError:
        return None
    return None if math.isnan(v) else v


def read_run(directory: Path) -> RunInfo:
    """The :class:`RunInfo` of one run directory (one holding ``config.json``)."""
    directory = Path(directory)
    problem = None
    try:
        config = json.loads((directory / "config.json").read_text())
        macro = config.get("macro")
        task = str(config["task"]) + (f" [{', '.join(macro['skills'])}]" if macro else "")
        budget = int(config["steps"])
    except (OSError, ValueError, KeyError, TypeError) as e:
        config, task, budget, problem = {}, "?", 0, f"config.json: {e}"
    steps, train_success, episodes_done = 0, None, 0
    try:
        row = _last_row(directory / "progress.csv")
        if row is not None:
            steps = int(float(row.get("env_steps") or 0))
            train_success = _number(row.get("success_rate"))
            episodes_done = int(float(row.get("episodes_total") or 0))
    except (OSError, ValueError, csv.Error) as e:
        problem = problem or f"progress.csv: {e}"
    eval_success = None
    result = directory / "result.json"
    if result.exists():
        try:
            found = json.loads(result.read_text())
            eval_success = _number(str((found.get("success") or {}).get("mean", "")))
            steps = max(steps, int(found.get("env_steps", 0)))
        except (OSError, ValueError, AttributeError, TypeError) as e:
            problem = problem or f"result.json: {e}"
    episodes = config.get("episodes")  # an episode budget ends a run too (TrainConfig.episodes)
    spent = (budget and steps >= budget) or (isinstance(episodes, int) and episodes_done >= episodes)
    state = "running" if _locked(directory) else "finished" if spent else "stopped"
    return RunInfo(directory, task, steps, budget, train_success, eval_success, state, problem)


def find_runs(root: Path) -> list[RunInfo]:
    """Every run directory under ``root`` (``root`` itself included), sorted by path. Raises ValueError if ``root``
    is not a directory."""
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"{root}: no such directory")
    found = []
    for here, dirs, files in os.walk(root):
        trained = "progress.csv" in files or "result.json" in files or "checkpoint" in dirs
        dirs[:] = sorted(d for d in dirs if d not in _SKIP and not d.startswith("."))
        if "config.json" in files and trained:
            found.append(read_run(Path(here)))
    return sorted(found, key=lambda r: str(r.path))


__all__ = ["RunInfo", "find_runs", "read_run"]
