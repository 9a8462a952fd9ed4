"""A benchmark run as a dated file: ``benchmarks/runs/SCRIPT-YYYY-MM-DDTHHMMSS.json`` under the directory the script
runs in (the repository root, as docs/benchmarks.md runs them), or ``--runs-dir DIR``.

Each file holds what the run measured (the figures it printed, by name), the command, the commit of the code that
ran (and whether the tree had uncommitted changes), the versions of the libraries and the machine: the dated record
docs/benchmarks.md cites, written by the script rather than copied into prose. A file is never replaced.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import json
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

from hrlp.atomic import atomic_path

#: Where runs go, relative to the directory the script runs in.
RUNS_DIR = Path("benchmarks/runs")
#: The libraries whose versions a run records.
PACKAGES = ("hrlp", "torch", "mujoco", "numpy", "gymnasium", "gymnasium-robotics", "stable-baselines3", "sb3-contrib",
            "tianshou")  # fmt: skip


def add_argument(ap: argparse.ArgumentParser) -> None:
    """``--runs-dir``: where the run's file goes."""
    ap.add_argument("--runs-dir", type=Path, default=RUNS_DIR, help=f"where the dated run file goes (default {RUNS_DIR})")


def _commit() -> dict[str, Any]:
    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here, capture_output=True,
                               text=True, timeout=10)  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return {"commit": None}
    if sha.returncode:
        return {"commit": None}
    return {"commit": sha.stdout.strip(), "uncommitted_changes": bool(dirty.stdout.strip())}


def _versions() -> dict[str, str]:
    out = {}
    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            pass
    return out


def record(script: str, figures: dict[str, Any], runs_dir: Path = RUNS_DIR) -> Path:
    """Write the run of ``script`` (its file name) with its ``figures`` to a new dated file in ``runs_dir``; returns
    the file."""
    now = datetime.datetime.now(datetime.UTC)
    stem = f"{Path(script).stem}-{now:%Y-%m-%dT%H%M%S}"
    runs_dir.mkdir(parents=True, exist_ok=True)
    path, n = runs_dir / f"{stem}.json", 1
    while path.exists():
        n += 1
        path = runs_dir / f"{stem}-{n}.json"
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    doc = {
        "script": Path(script).name,
        "date": now.isoformat(timespec="seconds"),
        "command": " ".join(["python", f"benchmarks/{Path(script).name}", *sys.argv[1:]]),
        **_commit(),
        "versions": _versions(),
        "machine": {
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "load_average_1min_at_end": None if load is None else round(load[0], 2),
        },
        "figures": figures,
    }
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"run recorded in {path}")
    return path


__all__ = ["RUNS_DIR", "add_argument", "record"]
