"""Evaluating a trained policy: returns and success rate with 95% confidence intervals."""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from scipy import stats as sstats

from hrlp.envs.vector import NO_SUCCESS_TEST, VectorStep
from hrlp.rollout import Episode
from hrlp.skills.core import ObsLayout
from hrlp.skills.macro_env import MacroEnv
from hrlp.training.loading import load_trained


@dataclass(frozen=True)
class Interval:
    """A point estimate with a 95% confidence interval."""

    mean: float
    low: float
    high: float

    def __str__(self) -> str:
        return f"{self.mean:.4g} [{self.low:.4g}, {self.high:.4g}]"


def mean_interval(xs: list[float], confidence: float = 0.95) -> Interval:
    """Mean with a Student-t confidence interval (a point interval for a single value)."""
    a = np.asarray(xs, dtype=float)
    if a.size == 0:
        return Interval(math.nan, math.nan, math.nan)
    m = float(a.mean())
    if a.size == 1 or a.std() == 0:
        return Interval(m, m, m)
    half = float(sstats.t.ppf(0.5 + confidence / 2, a.size - 1) * a.std(ddof=1) / math.sqrt(a.size))
    return Interval(m, m - half, m + half)


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> Interval:
    """Success rate with the Wilson score interval (sound near 0 and 1, unlike the normal approximation)."""
    if n == 0:
        return Interval(math.nan, math.nan, math.nan)
    z = float(sstats.norm.ppf(0.5 + confidence / 2))
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # At p = 0 (p = 1) the bound is exactly 0 (1); computed, it comes out as rounding noise such as 3.5e-18.
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == n else min(1.0, centre + half)
    return Interval(p, low, high)


@dataclass(frozen=True)
class Evaluation:
    """Results over ``episodes`` evaluation episodes."""

    episodes: int
    ret: Interval
    success: Interval | None
    target_dist_sum: Interval | None
    macro_usage: dict[str, float] | None = None
    """For a Manager: the share of its decisions that chose each skill (and the micro-action)."""
    move: MoveStats | None = None
    """For tasks that move the capsule to a target (reach-and-move, the Movers): what TargetDistSum alone hides."""


#: The capsule counts as lifted when it rose this far above its resting height (metres) during an episode.
LIFT_HEIGHT = 0.03


@dataclass(frozen=True)
class MoveStats:
    """reach-and-move beyond the paper's TargetDistSum (a capsule left untouched on the table scores about -45 on
    reach-and-move, the paper's own success threshold)."""

    min_target_dist: Interval
    """min_t d(C, T) over an episode, metres."""
    lift_rate: Interval
    """Share of episodes in which the capsule rose more than :data:`LIFT_HEIGHT` above its resting height (Wilson)."""
    untouched_target_dist_sum: Interval
    """TargetDistSum the same episodes would score with the capsule left where it started: -length * d(C_0, T)."""
    relative_target_dist_sum: Interval
    """TargetDistSum minus the untouched one: 0 for a capsule never moved, > 0 for one moved towards the target."""


@dataclass(frozen=True)
class EvalProgress:
    """How far an evaluation has got: what :func:`evaluate_run` passes to ``on_progress`` after each episode."""

    done: int
    """Episodes finished."""
    total: int
    """Episodes asked for."""
    return_mean: float
    """Mean return of the episodes finished so far."""
    success_rate: float | None
    """Success rate of the episodes finished so far (None for tasks without a success flag)."""
    target_dist_sum: float | None = None
    """Mean TargetDistSum so far, for tasks that report it."""


def progress_line(label: str, p: EvalProgress, elapsed_s: float) -> str:
    """One line for an evaluation's progress, in the style of :func:`hrlp.train.progress_line`, e.g. ``eval runs/x:
    100/1,000 episodes (10%), return -40.2, success 0.12, 3.1 episodes/s, 32 s``."""
    out = f"{label}: {p.done:,}/{p.total:,} episodes ({p.done / max(p.total, 1):.0%}), return {p.return_mean:.1f}"
    if p.success_rate is not None:
        out += f", success {p.success_rate:.2f}"
    if p.target_dist_sum is not None:
        out += f", TargetDistSum {p.target_dist_sum:.1f}"
    return out + f", {p.done / max(elapsed_s, 1e-9):.1f} episodes/s, {elapsed_s:.0f} s"


class ProgressLines:
    """An ``on_progress`` callback for :func:`evaluate_run` that writes a :func:`progress_line` every ``every`` episodes
    (default: every tenth of the total), whenever ``interval_s`` seconds passed since the last line, and after the
    last episode: readable where a progress bar is not, such as stderr written to a file.

    Args:
        label: what the lines start with, e.g. ``eval RUN_DIR``.
        write: where a line goes, e.g. ``lambda line: print(line, file=sys.stderr, flush=True)``.
        every: episodes between lines; None: ``ceil(total / 10)``; 0: no lines by count.
        interval_s: seconds after which the next episode writes a line whatever the count; None: never by time.
    """

    def __init__(self, label: str, write: Callable[[str], None], every: int | None = None,
                 interval_s: float | None = 10.0) -> None:  # fmt: skip
        self.label, self.write, self.every, self.interval_s = label, write, every, interval_s
        self._start = self._last = time.perf_counter()

    def __call__(self, p: EvalProgress) -> None:
        now = time.perf_counter()
        every = math.ceil(p.total / 10) if self.every is None else self.every
        due = p.done >= p.total or (every > 0 and p.done % every == 0)
        if due or (self.interval_s is not None and now - self._last >= self.interval_s):
            self.write(progress_line(self.label, p, now - self._start))
            self._last = now


EVAL_ENVS = 64
"""Environments an evaluation steps together (one episode each, batched inference; fewer for fewer episodes)."""


def evaluate_run(run_dir: Path, episodes: int = 20, seed: int = 10_000, deterministic: bool = True,
                 task_kwargs: dict[str, Any] | None = None,
                 on_progress: Callable[[EvalProgress], None] | None = None) -> Evaluation:  # fmt: skip
    """Run ``episodes`` episodes of the run's policy (normaliser frozen) and summarise them (``task_kwargs`` override
    the run's task arguments, e.g. to evaluate a skill from another start set).

    Episode ``k`` starts from ``reset(seed=seed + k)``. The episodes run through the run's
    :class:`~hrlp.envs.vector.VectorEnv` (its backend, :meth:`hrlp.train.TrainedPolicy.vector_env`), up to
    :data:`EVAL_ENVS` at a time, each environment running one episode, with the policy's actions for all of them
    computed at once. Returns count the task's own rewards, undiscounted, over low-level steps, for flat policies and
    Managers alike. ``on_progress``, if given, is called after every episode with the running :class:`EvalProgress`
    (the last call has ``done == episodes``); :class:`ProgressLines` turns those calls into log lines.
    """
    if episodes <= 0:
        raise ValueError(f"episodes must be a positive integer, got {episodes}")
    trained = load_trained(run_dir)
    n = min(episodes, EVAL_ENVS)
    gap = _capsule_target_spans(trained.make_env(**(task_kwargs or {})))
    env = trained.vector_env(n, **(task_kwargs or {}))
    names = getattr(env, "names", None)  # a Manager's environments name their macro-actions
    gen = torch.Generator().manual_seed(seed)
    done_eps: list[Episode] = []
    usage: Counter[str] = Counter()
    moves: list[tuple[float, float, float]] = []  # (min d(C, T), max lift, untouched TargetDistSum) per episode
    try:
        for first in range(0, episodes, n):
            m = min(n, episodes - first)  # the environments whose first episode counts
            obs = env.reset(seed=seed + first)
            start_gap = None if gap is None else np.linalg.norm(obs[:, gap[0]] - obs[:, gap[1]], axis=1)
            ret, length = np.zeros(n), np.zeros(n, dtype=np.int64)
            running = np.arange(n) < m
            while running.any():
                step = env.step(trained.act_rows(obs, gen, deterministic))
                obs = step.obs
                rewards = step.infos.get("task_reward", step.rewards)
                ret[running] += rewards[running]
                length[running] += step.tau[running]
                if names is not None and "choice" in step.infos:
                    usage.update(names[int(c)] for c in step.infos["choice"][running])
                for i in np.flatnonzero(running & (step.terminated | step.truncated)):
                    running[i] = False
                    done_eps.append(_episode(step, i, float(ret[i]), int(length[i]), moves,
                                             None if start_gap is None else float(start_gap[i])))  # fmt: skip
                    if on_progress is not None:
                        on_progress(_running(done_eps, episodes))
    finally:
        env.close()
    succ = [e.success for e in done_eps if e.success is not None]
    tds = [e.target_dist_sum for e in done_eps if e.target_dist_sum is not None]
    total = sum(usage.values())
    return Evaluation(
        episodes=episodes,
        ret=mean_interval([e.ret for e in done_eps]),
        success=wilson_interval(sum(succ), len(succ)) if succ else None,
        target_dist_sum=mean_interval(tds) if tds else None,
        macro_usage={n: usage[n] / total for n in names} if names and total else None,
        move=_move_stats(moves, tds) if moves and len(moves) == len(tds) else None,
    )


def _capsule_target_spans(env: gym.Env) -> tuple[slice, slice] | None:
    """Where the capsule C and the target T lie in the observation of a task that names both parts (the arm's moving
    tasks, :attr:`hrlp.arm.env.ArmEnv.observation_parts`), for the reach-and-move figures; None for any other
    environment. Closes ``env``."""
    try:
        layout = env.layout if isinstance(env, MacroEnv) else ObsLayout.of_env(env)
    finally:
        env.close()
    if "capsule" in layout.names and "target" in layout.names:
        return layout.span("capsule"), layout.span("target")
    return None


def _episode(step: VectorStep, i: int, ret: float, length: int, moves: list, start_gap: float | None) -> Episode:
    """Environment ``i``'s episode that ended in ``step`` (a :class:`~hrlp.envs.vector.VectorStep`); appends its
    reach-and-move figures to ``moves`` where the task reports them."""

    def value(key: str) -> float | None:  # absent, or NaN (not reported on this step, e.g. a physics blow-up): None
        v = float(step.infos[key][i]) if key in step.infos else math.nan
        return None if math.isnan(v) else v

    no_test = step.infos.get(NO_SUCCESS_TEST)
    success = None if no_test is not None and no_test[i] else bool(step.success[i])
    tds, closest, lift = value("target_dist_sum"), value("closest_max"), value("lift_max")
    if tds is not None and closest is not None and lift is not None and start_gap is not None:
        moves.append((-closest, lift, -length * start_gap))
    return Episode(ret, length, success, tds)


def evaluate_with_progress(run_dir: Path, episodes: int = 20, seed: int = 10_000, deterministic: bool = True,
                           console: Any = None, description: str | None = None) -> Evaluation:  # fmt: skip
    """:func:`evaluate_run` behind a rich progress bar on ``console`` (default: stderr) with the running return and
    success rate, as :func:`hrlp.train.train_with_progress` shows training; when ``console`` is not a terminal (stderr
    written to a file or a pipe), :class:`ProgressLines` instead: a line every tenth of the episodes, at least every
    10 s, and at the end."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    console = console or Console(stderr=True)
    label = description or f"eval {run_dir}"
    if not console.is_terminal:
        lines = ProgressLines(label, lambda line: console.print(line, soft_wrap=True, markup=False, highlight=False))
        return evaluate_run(run_dir, episodes, seed, deterministic, on_progress=lines)
    columns = [TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
               TextColumn("{task.fields[status]}", markup=False)]  # fmt: skip
    with Progress(*columns, console=console) as progress:
        bar = None  # added after the first episode: an error loading the run leaves its one line, no empty bar

        def show(p: EvalProgress) -> None:
            nonlocal bar
            if bar is None:
                bar = progress.add_task(label, total=p.total, status="")
            status = f"return {p.return_mean:.1f}" + ("" if p.success_rate is None else f", success {p.success_rate:.2f}")
            progress.update(bar, completed=p.done, status=status)

        return evaluate_run(run_dir, episodes, seed, deterministic, on_progress=show)


def _running(done_eps: list[Episode], total: int) -> EvalProgress:
    succ = [e.success for e in done_eps if e.success is not None]
    tds = [e.target_dist_sum for e in done_eps if e.target_dist_sum is not None]
    return EvalProgress(
        done=len(done_eps),
        total=total,
        return_mean=sum(e.ret for e in done_eps) / len(done_eps),
        success_rate=sum(succ) / len(succ) if succ else None,
        target_dist_sum=sum(tds) / len(tds) if tds else None,
    )


def _move_stats(moves: list[tuple[float, float, float]], tds: list[float]) -> MoveStats:
    closest, lift, untouched = (list(x) for x in zip(*moves, strict=True))
    return MoveStats(
        min_target_dist=mean_interval(closest),
        lift_rate=wilson_interval(sum(h > LIFT_HEIGHT for h in lift), len(lift)),
        untouched_target_dist_sum=mean_interval(untouched),
        relative_target_dist_sum=mean_interval([t - u for t, u in zip(tds, untouched, strict=True)]),
    )
