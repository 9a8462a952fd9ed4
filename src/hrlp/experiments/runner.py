"""``hrlp reproduce``: run a preset's runs x seeds grid on a process pool or a Ray cluster, idempotently.

Each run lives in ``OUT/PRESET/RUN/sSEED``: the training run (checkpoint, logs) and, once it is
finished and evaluated, ``result.json``. Runs with a result for at least the requested budget are
skipped; interrupted runs resume from their checkpoints; a larger ``--budget`` continues finished
runs. A run whose full config (seed and budget included) matches a finished run of another preset under the
same ``OUT`` is copied from it instead of trained again: training is deterministic given the config, so the copy
is the run this job would have made. Every job trains in its own process with one torch thread.

A job holds the OS lock of its run directory (:func:`hrlp.atomic.directory_lock`) from the moment it decides what to
do until its ``result.json`` is written, so two ``hrlp reproduce`` on one ``--out`` never write one run at once: the
second fails with a one-line error naming the run directory (and the jobs it has not started are cancelled).
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import logging
import os
import re
import shutil
import signal
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from hrlp import bounds
from hrlp.arm.research.imitate import ImitationConfig
from hrlp.atomic import LOCK_FILE, atomic_path, directory_lock
from hrlp.checkpoint import checkpoint_exists
from hrlp.experiments.presets import PRESETS, Preset
from hrlp.stopping import (
    STOP_SIGNALS,
    Stopped,
    as_stop,
    children_ignore_stop_signals,
    ignore_stop_signals,
    raise_if_stopping,
)
from hrlp.train import TrainConfig
from hrlp.training.sources import resolve_skills

BACKENDS = ("process", "ray")


@dataclass(frozen=True)
class Job:
    """One training run of a preset: where it lives and its full settings."""

    preset: str
    run: str
    seed: int
    run_dir: Path
    config: TrainConfig
    eval_episodes: int
    paper: float | None
    imitation: ImitationConfig | None = None
    """The run's imitation stage before TRPO (:attr:`hrlp.experiments.presets.Run.imitation`), or None."""


def run_dir_name(run: str) -> str:
    """A directory name for a run name (``c2=3,tr=0.03`` -> ``c2=3,tr=0.03``; unsafe characters become ``_``)."""
    return re.sub(r"[^A-Za-z0-9_.,=+-]", "_", run)


def plan(preset: Preset, out: Path, seeds: tuple[int, ...] | None = None) -> list[Job]:
    """The preset's jobs, runs x seeds, in a stable order."""
    return [
        Job(
            preset.name,
            r.name,
            s,
            out / preset.name / run_dir_name(r.name) / f"s{s}",
            preset.config(r, s),
            preset.eval_episodes,
            r.paper,
            r.imitation,
        )
        for r in preset.runs
        for s in (seeds if seeds is not None else preset.seeds)
    ]


def read_result(run_dir: Path) -> dict[str, Any] | None:
    """A finished run's ``result.json``, or None."""
    path = run_dir / "result.json"
    return json.loads(path.read_text()) if path.is_file() else None


def training_seconds(progress: dict[str, np.ndarray]) -> float:
    """Wall seconds of a run's training iterations, from its ``progress.csv`` columns (``read_progress``): each
    iteration's new environment steps over its steps per second. A resumed run's log holds every iteration once."""
    steps = np.diff(progress["env_steps"], prepend=0.0)
    return float(np.sum(steps / progress["time/steps_per_s"]))


def find_same_run(job: Job) -> Path | None:
    """A finished run of another preset or run name under the same root whose config equals ``job``'s, or None."""
    root = job.run_dir.parents[2]
    want = json.loads(json.dumps(job.config.to_json()))  # tuples -> lists, as read back from result.json
    for path in sorted(root.glob(f"*/*/s{job.seed}/result.json")):
        if path.parent == job.run_dir:
            continue
        try:
            found = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        if (_same_config(found.get("config"), want) and found.get("env_steps", 0) >= job.config.steps
                and found.get("imitation") == _imitation_json(job)):  # fmt: skip
            return path.parent
    return None


def _imitation_json(job: Job) -> dict[str, Any] | None:
    """The job's imitation stage as ``result.json`` records it (None for a run that TRPO trains from scratch)."""
    return None if job.imitation is None else json.loads(json.dumps(asdict(job.imitation)))


def _same_config(found: Any, want: dict[str, Any]) -> bool:
    """Whether a result's config is ``want``, read as :class:`TrainConfig` reads it: a field added to the config after
    the run was made takes the value the run trained with (its default then: TrainConfig.from_json)."""
    if not isinstance(found, dict):
        return False
    try:
        return json.loads(json.dumps(TrainConfig.from_json(found).to_json())) == want
    except (TypeError, ValueError, KeyError, AttributeError):
        return False


def copy_run(job: Job, source: Path) -> dict[str, Any]:
    """Copy the finished run ``source`` into ``job.run_dir`` with its result relabelled to ``job``'s preset and run, and
    return that result.

    The copy is made in a temporary sibling, then moved into ``job.run_dir`` (which may exist, holding the job's lock)
    entry by entry, the checkpoint next to last and ``result.json`` last: a copy killed half-way leaves no result and
    no checkpoint, so the next attempt copies again."""
    found = read_result(source)
    assert found is not None
    result = {**found, "preset": job.preset, "run": job.run, "paper": job.paper}
    # A copy of a copy names the run that was trained.
    result["copied_from"] = found.get("copied_from") or str(source.relative_to(job.run_dir.parents[2]))
    job.run_dir.mkdir(parents=True, exist_ok=True)
    tmp = job.run_dir.with_name(job.run_dir.name + ".copying")
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(source, tmp, ignore=shutil.ignore_patterns(LOCK_FILE, "result.json"))
    entries = sorted(tmp.iterdir(), key=lambda p: p.name == "checkpoint")
    for entry in entries:
        target = job.run_dir / entry.name
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target)
        os.replace(entry, target)
    tmp.rmdir()
    _write_json(job.run_dir / "result.json", result)
    return result


def run_job(job: Job, reuse: bool = True) -> dict[str, Any]:
    """Train (or resume) and evaluate one job, write ``result.json`` atomically and return it; skip if done, copy
    if ``reuse`` and another preset under the same root has finished the same run (:func:`find_same_run`)."""
    done = read_result(job.run_dir)
    if done is not None and done["env_steps"] >= job.config.steps:
        return {**done, "skipped": True}
    with directory_lock(job.run_dir):
        return _run_job_locked(job, reuse)


def _run_job_locked(job: Job, reuse: bool) -> dict[str, Any]:
    """:func:`run_job` under the run directory's lock (another process may have finished the job meanwhile)."""
    import torch

    from hrlp.evaluate import ProgressLines, evaluate_run
    from hrlp.plots import read_progress
    from hrlp.train import progress_line, train

    done = read_result(job.run_dir)
    if done is not None and done["env_steps"] >= job.config.steps:
        return {**done, "skipped": True}
    resume = checkpoint_exists(job.run_dir / "checkpoint")  # the .old copy a kill between renames leaves counts
    if reuse and not resume and done is None and (source := find_same_run(job)) is not None:
        return copy_run(job, source)
    torch.set_num_threads(1)
    label, started = f"{job.preset} / {job.run} / seed {job.seed}", time.perf_counter()
    if job.imitation is not None and not resume:  # the student of the scripted grasp, as the run's iteration 0
        from hrlp.arm.research.imitate import imitate

        imitate(job.config, job.run_dir, job.imitation,
                log=lambda line: print(f"{label}: {line}", file=sys.stderr, flush=True))  # fmt: skip
        resume = True
    for st in train(job.config, job.run_dir, resume=resume):  # a line per iteration: jobs run in parallel, bars would mix
        print(progress_line(label, st, job.config.steps, time.perf_counter() - started), file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    # The evaluation's progress: a line when 30 s pass without one, and one at the end (these jobs run in parallel).
    lines = ProgressLines(f"eval {label}", lambda line: print(line, file=sys.stderr, flush=True), every=0, interval_s=30.0)
    ev = evaluate_run(job.run_dir, episodes=job.eval_episodes, on_progress=lines)
    progress = read_progress(job.run_dir)
    result = {
        "preset": job.preset,
        "run": job.run,
        "seed": job.seed,
        "config": job.config.to_json(),
        "env_steps": int(progress["env_steps"][-1]),
        # Every logged iteration's wall time (an interrupted run's earlier sessions included) and this evaluation's.
        "wall_s": training_seconds(progress) + time.perf_counter() - t0,
        "episodes": ev.episodes,
        "success": None if ev.success is None else vars(ev.success),
        "return": vars(ev.ret),
        "target_dist_sum": None if ev.target_dist_sum is None else vars(ev.target_dist_sum),
        "macro_usage": ev.macro_usage,
        "move": None if ev.move is None else {k: vars(v) for k, v in vars(ev.move).items()},
        "paper": job.paper,
        "imitation": _imitation_json(job),
    }
    _write_json(job.run_dir / "result.json", result)
    return result


def _write_json(path: Path, data: dict[str, Any]) -> None:
    with atomic_path(path) as tmp, open(tmp, "w") as f:
        json.dump(data, f, indent=2)


def process_pool(workers: int) -> ProcessPoolExecutor:
    """A pool of ``workers`` spawned processes that die with this one (``PR_SET_PDEATHSIG`` on Linux): a ``hrlp
    reproduce`` stopped by SIGTERM or SIGKILL leaves no run training on behind it. They ignore the stop signals
    (:mod:`hrlp.stopping`): this process stops them (:func:`kill_pool`)."""
    import multiprocessing as mp

    return ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"), initializer=_pool_worker_start,
                               initargs=(os.getpid(),))  # fmt: skip


def _pool_worker_start(parent_pid: int) -> None:
    """A pool process's first step: ignore the stop signals, and die with the parent."""
    from hrlp.rollout import die_with_parent

    ignore_stop_signals()
    die_with_parent(parent_pid)


def kill_pool(pool: ProcessPoolExecutor) -> None:
    """Kill the pool's processes at once (SIGKILL: they ignore the stop signals) and cancel the jobs not started. A
    job killed mid-way keeps its last checkpoint, which is whole whenever the kill comes (:mod:`hrlp.checkpoint`), and
    resumes from it the next time."""
    processes = list((getattr(pool, "_processes", None) or {}).values())  # the executor keeps no public list
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in processes:
        if proc.is_alive():
            proc.kill()
    for proc in processes:
        proc.join(timeout=10)


#: How long the driver waits on Ray at a time (s): between waits a stop signal is acted on.
RAY_WAIT_S = 0.5


def _on_ray(jobs: list[Job], reuse: bool, address: str | None,
            on_result: Callable[[dict[str, Any]], None] | None) -> list[dict[str, Any]]:  # fmt: skip
    """Run ``jobs`` as Ray tasks of one CPU each, on the cluster at ``address`` or on a local instance started here
    (and shut down after). A stop signal cancels the tasks still running (their runs keep their last checkpoints, whole
    whenever the kill comes) and is raised here, as with the process backend."""
    import ray

    local = address is None and not ray.is_initialized()
    handlers = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    try:
        with children_ignore_stop_signals():  # a local instance's processes start with the stop signals held back
            ray.init(address=address, ignore_reinit_error=True, include_dashboard=False, log_to_driver=False,
                     logging_level=logging.ERROR)  # fmt: skip
    finally:
        for s, handler in handlers.items():  # ray.init sets its own SIGTERM handler in the driver (sys.exit)
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
    results: list[dict[str, Any]] = []
    pending: dict[Any, Job] = {}
    try:
        remote = ray.remote(num_cpus=1)(run_job)
        pending = {remote.remote(j, reuse): j for j in jobs}
        while pending:  # waits of RAY_WAIT_S: a blocking wait runs in Ray's C++ and would leave a signal unseen
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=RAY_WAIT_S)
            raise_if_stopping()
            for ref in ready:
                pending.pop(ref)
                results.append(res := ray.get(ref))
                if on_result:
                    on_result(res)
    except BaseException as error:
        for ref in pending:  # the runs in progress keep their last checkpoints; the next reproduce resumes them
            with contextlib.suppress(Exception):
                ray.cancel(ref, force=True)
        stop = as_stop(error)
        if stop is not None and stop is not error:
            raise stop from None
        raise
    finally:
        if local:
            ray.shutdown()
    return results


def reproduce(
    preset_name: str | Preset,
    out: Path = Path("runs/reproduce"),
    seeds: int | None = None,
    budget: int | None = None,
    backend: str = "process",
    workers: int = 2,
    address: str | None = None,
    on_result: Callable[[dict[str, Any]], None] | None = None,
    reuse: bool = True,
    only: tuple[str, ...] = (),
) -> list[dict[str, Any]]:
    """Run every job of the preset (a name or a :class:`Preset`; its first ``seeds`` seeds, ``budget`` steps each)
    and return their results. With ``reuse``, a job whose config matches a finished run of another preset under
    ``out`` is copied from it (:func:`find_same_run`) rather than trained again. ``only``: shell-style patterns
    (``fnmatch``) of the run names to run, e.g. ``"*,c2=3,tr=0.03"`` (default: every run); each must match one.

    Raises ValueError for an unknown preset, backend or bad numbers, and for a missing skill, before any compute.
    """
    if isinstance(preset_name, str) and preset_name not in PRESETS:
        raise ValueError(f"unknown preset {preset_name!r}; known: {', '.join(PRESETS)}")
    if backend not in BACKENDS:
        raise ValueError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if (seeds is not None and seeds < 1) or (budget is not None and budget < 1) or workers < 1:
        raise ValueError("--seeds, --budget and --workers must be positive")
    if workers > bounds.max_processes():
        raise ValueError(f"--workers must be at most {bounds.max_processes()}, got {workers:,}: {bounds.why_processes()}")
    if address is not None and backend != "ray":
        raise ValueError(f"--address {address} is a Ray cluster's; it needs --backend ray (the {backend} backend ignores it)")
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a directory")
    if address is not None and (problem := bounds.ray_address_problem(address)) is not None:
        raise ValueError(problem)
    preset = PRESETS[preset_name] if isinstance(preset_name, str) else preset_name
    if only:
        names = [r.name for r in preset.runs]
        if unmatched := [pat for pat in only if not fnmatch.filter(names, pat)]:
            raise ValueError(f"--only {', '.join(map(repr, unmatched))} matches no run of {preset.name} (runs: "
                             f"{', '.join(names)})")  # fmt: skip
        preset = replace(preset, runs=tuple(r for r in preset.runs if any(fnmatch.fnmatchcase(r.name, p) for p in only)))
    if budget is not None:
        preset = preset.with_budget(budget)
    jobs = plan(preset, out, None if seeds is None else tuple(range(seeds)))
    for spec in {j.config.macro for j in jobs if j.config.macro is not None}:
        resolve_skills(spec.skills, spec.library)  # a missing skill fails now
    results: list[dict[str, Any]] = []
    if backend == "ray":
        return _on_ray(jobs, reuse, address, on_result)
    with process_pool(workers) as pool:
        futures = []
        try:
            with children_ignore_stop_signals():  # the pool's processes start here, and a Ctrl-C is this process's
                futures += [pool.submit(run_job, j, reuse) for j in jobs]
            for f in as_completed(futures):
                res = f.result()
                results.append(res)
                if on_result:
                    on_result(res)
        except Stopped:  # the runs in progress keep their last checkpoints; the next reproduce resumes them
            kill_pool(pool)
            raise
        except BaseException:
            for f in futures:  # a failed job (e.g. a run directory another process holds) stops the jobs not started
                f.cancel()
            raise
    return results
