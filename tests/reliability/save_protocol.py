"""Real training processes killed with SIGKILL at random times or just before a chosen step of the checkpoint save
protocol, then checked and resumed: the machinery of ``benchmarks/reliability.py``'s kill figure and of
``test_reliability_cli.py``'s kill test (docs/reliability.md, "Figures").

The save protocol's steps are found, not listed: :func:`instrument` wraps the primitives :mod:`hrlp.checkpoint` calls
(``tempfile.mkdtemp``, its synced writes and fsyncs, ``os.replace``, ``shutil.rmtree``) and the call of
``save_checkpoint`` in :mod:`hrlp.training.loop`, so every step announces itself just before it runs; the checkpoint code is
unchanged. A training process started by :func:`run_child` (this file run as a script) kills itself before the chosen
step of the chosen save; a write step has a second kill point, after half the bytes are on disk.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HALF = " (half of it)"
"""The suffix of the kill point after half of a file is written."""


def kill_config(iterations: int, seed: int = 0) -> Any:
    """The run that is killed: Reacher, 16 environment steps per iteration, a checkpoint after each of ``iterations``."""
    from hrlp.train import TrainConfig

    return TrainConfig(task="Reacher", steps=16 * iterations, batch_steps=16, num_envs=4, episode_steps=20, seed=seed)


class _Proxy:
    """A module whose attributes named in ``funcs`` are replaced (the rest is the module's own)."""

    def __init__(self, module: Any, **funcs: Any) -> None:
        self._module, self._funcs = module, funcs

    def __getattr__(self, name: str) -> Any:
        return self._funcs[name] if name in self._funcs else getattr(self._module, name)


def instrument(on_event: Any) -> Any:
    """Make every step of :func:`hrlp.checkpoint.save_checkpoint` call ``on_event(label, save, proceed)`` just before
    it runs (``save`` counts this process's saves from 1; ``proceed()`` runs the step). Returns a function that
    undoes it."""
    import hrlp.checkpoint as ck
    import hrlp.training.loop as tr  # where Trainer.save looks save_checkpoint up

    saved = (ck._write_synced, ck._fsync_directory, ck.os, ck.tempfile, ck.shutil, tr.save_checkpoint)
    real_save, real_write, real_fsync = tr.save_checkpoint, ck._write_synced, ck._fsync_directory
    count = {"save": 0}

    def event(label: str, proceed: Any) -> Any:
        return on_event(label, count["save"], proceed)

    def write(path: Path, data: bytes) -> None:
        def half() -> None:  # a write cut short: half the bytes on disk
            with open(path, "wb") as f:
                f.write(data[: len(data) // 2])
                f.flush()
                os.fsync(f.fileno())

        event(f"write {Path(path).name}{HALF}", half)
        event(f"write {Path(path).name}", lambda: real_write(path, data))

    def fsync(path: Path) -> None:
        event("fsync the new directory" if ".tmp-" in Path(path).name else "fsync the parent", lambda: real_fsync(path))

    def replace(src: Any, dst: Any) -> None:
        label = ("rename the checkpoint aside" if ".old-" in Path(dst).name else
                 "rename the new one into place" if ".tmp-" in Path(src).name else "rename the old copy back")  # fmt: skip
        event(label, lambda: os.replace(src, dst))

    def mkdtemp(*args: Any, **kwargs: Any) -> str:
        out: list[str] = []
        event("create the temporary directory", lambda: out.append(tempfile.mkdtemp(*args, **kwargs)))
        return out[0]

    def rmtree(path: Any, *args: Any, **kwargs: Any) -> None:
        event("delete the old copy" if ".old-" in Path(path).name else "delete a leftover",
              lambda: shutil.rmtree(path, *args, **kwargs))  # fmt: skip

    def save(*args: Any, **kwargs: Any) -> Any:
        count["save"] += 1
        out = real_save(*args, **kwargs)
        event("after the save", lambda: None)
        return out

    ck._write_synced, ck._fsync_directory = write, fsync
    ck.os = _Proxy(os, replace=replace)  # type: ignore[assignment]
    ck.tempfile = _Proxy(tempfile, mkdtemp=mkdtemp)  # type: ignore[assignment]
    ck.shutil = _Proxy(shutil, rmtree=rmtree)  # type: ignore[assignment]
    tr.save_checkpoint = save

    def undo() -> None:
        ck._write_synced, ck._fsync_directory, ck.os, ck.tempfile, ck.shutil, tr.save_checkpoint = saved

    return undo


def protocol_steps(scratch: Path, saves: tuple[int, ...], iterations: int) -> dict[int, list[str]]:
    """The labelled steps of each save in ``saves``, recorded from a real run of ``iterations`` in this process."""
    from hrlp.train import train

    steps: dict[int, list[str]] = {}

    def record(label: str, save: int, proceed: Any) -> Any:
        steps.setdefault(save, []).append(label)
        return None if label.endswith(HALF) else proceed()  # a half write is a kill point only

    undo = instrument(record)
    try:
        for _ in train(kill_config(iterations), scratch / "record-protocol"):
            pass
    finally:
        undo()
    return {s: steps[s] for s in saves}


def child_main(run_dir: Path, iterations: int, seed: int, kill_save: int, kill_step: int) -> None:
    """Train (or resume) the :func:`kill_config` run; with ``kill_save``, kill this process (SIGKILL) just before step
    ``kill_step`` of that save. Prints ``ready`` when training starts and ``iteration N`` after each iteration."""
    import torch

    from hrlp.checkpoint import checkpoint_exists
    from hrlp.train import train

    torch.set_num_threads(1)
    seen: Counter[int] = Counter()

    def kill_at(label: str, save: int, proceed: Any) -> Any:
        seen[save] += 1
        half = label.endswith(HALF)
        if save == kill_save and seen[save] == kill_step:
            if half:
                proceed()
            os.kill(os.getpid(), signal.SIGKILL)
        return None if half else proceed()

    if kill_save:
        instrument(kill_at)
    resume = checkpoint_exists(run_dir / "checkpoint")
    ready = lambda plan: print("ready", flush=True)  # noqa: E731 - after setup, before the first iteration
    for stats in train(kill_config(iterations, seed), run_dir, resume=resume, on_start=ready):
        print(f"iteration {int(stats['iteration'])}", flush=True)


@dataclass(frozen=True)
class Child:
    """What a training process did: whether it was killed, and when (seconds after ``ready``) each iteration ended."""

    killed: bool
    iteration_ends: tuple[float, ...]


def run_child(run_dir: Path, iterations: int, kill_save: int = 0, kill_step: int = 0, kill_after_s: float | None = None,
              limit_s: float = 300.0) -> Child:  # fmt: skip
    """Start a training process (its own session) and let it kill itself at a save step, or kill it ``kill_after_s``
    seconds after it said ``ready``, or let it finish."""
    cmd = [sys.executable, __file__, str(run_dir), "--iterations", str(iterations), "--kill-save", str(kill_save),
           "--kill-step", str(kill_step)]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    assert proc.stdout is not None
    ends: list[float] = []
    try:
        if proc.stdout.readline().strip() != "ready":
            proc.wait(timeout=limit_s)
            if proc.returncode == -signal.SIGKILL:  # it killed itself before training started (a first-save step
                return Child(True, ())  # cannot come before ready: this is only reached on an error)
            raise RuntimeError(f"the training process did not start: {proc.stderr.read()[-2000:]}")  # type: ignore[union-attr]
        start = time.perf_counter()
        if kill_after_s is not None:
            time.sleep(max(0.0, kill_after_s))
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
        for line in proc.stdout:
            if line.startswith("iteration "):
                ends.append(time.perf_counter() - start)
        proc.wait(timeout=limit_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise RuntimeError("the training process did not end") from None
    err = proc.stderr.read() if proc.stderr else ""
    killed = proc.returncode == -signal.SIGKILL
    if not killed and proc.returncode != 0:
        raise RuntimeError(f"the training process failed ({proc.returncode}): {err[-2000:]}")
    return Child(killed, tuple(ends))


def check_and_resume(run_dir: Path, iterations: int, reference: dict[str, Any]) -> dict[str, Any]:
    """What a kill left in ``run_dir``: a checkpoint that exists must load (hash verified, every tensor finite); then a
    resume to the end (a fresh start if there is none), compared tensor by tensor with ``reference`` (the checkpoint
    of an uninterrupted run), and its ``progress.csv``, which must list every iteration once."""
    import torch

    from hrlp.checkpoint import checkpoint_exists, load_checkpoint
    from hrlp.train import train

    out: dict[str, Any] = {"corrupt": False, "failed_resume": False, "bit_exact": False, "log_ok": False, "problem": "",
                           "iteration_at_kill": 0}  # fmt: skip
    had = checkpoint_exists(run_dir / "checkpoint")
    if had:
        try:
            tensors, meta = load_checkpoint(run_dir / "checkpoint")
            if bad := [n for n, t in tensors.items() if t.is_floating_point() and not torch.isfinite(t).all()]:
                raise ValueError(f"non-finite tensors {bad[:3]}")
            out["iteration_at_kill"] = int(meta["iteration"])
        except Exception as e:  # counted: a checkpoint that is there but cannot be used
            out["corrupt"], out["problem"] = True, f"corrupt checkpoint: {' '.join(str(e).split())[:200]}"
            return out
    try:
        for _ in train(kill_config(iterations), run_dir, resume=had):
            pass
        tensors, _ = load_checkpoint(run_dir / "checkpoint")
    except Exception as e:  # counted: a resume (or fresh start) that does not reach the end
        out["failed_resume"], out["problem"] = True, f"resume failed: {' '.join(str(e).split())[:200]}"
        return out
    out["bit_exact"] = sorted(tensors) == sorted(reference) and all(torch.equal(tensors[n], reference[n]) for n in tensors)
    with (run_dir / "progress.csv").open() as f:
        out["log_ok"] = [int(r["iteration"]) for r in csv.DictReader(f)] == list(range(1, iterations + 1))
    if not out["bit_exact"]:
        out["problem"] = "the resumed run differs from the uninterrupted one"
    elif not out["log_ok"]:
        out["problem"] = "progress.csv does not list every iteration once"
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="a training process to kill (see the module docstring)")
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--iterations", type=int, required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--kill-save", type=int, default=0)
    ap.add_argument("--kill-step", type=int, default=0)
    a = ap.parse_args()
    child_main(a.run_dir, a.iterations, a.seed, a.kill_save, a.kill_step)
