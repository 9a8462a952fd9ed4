"""Evaluating a trained policy: returns and success rate with 95% confidence intervals."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy import stats as sstats

from hrlp.rollout import Episode


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


def evaluate_run(run_dir: Path, episodes: int = 20, seed: int = 10_000, deterministic: bool = True,
                 task_kwargs: dict[str, Any] | None = None) -> Evaluation:  # fmt: skip
    """Run ``episodes`` episodes of the run's policy (normaliser frozen) and summarise them (``task_kwargs`` override
    the run's task arguments, e.g. to evaluate a skill from another start set).

    Returns count the task's own rewards, undiscounted, over low-level steps, for flat policies and Managers alike.
    """
    from hrlp.train import load_trained

    if episodes <= 0:
        raise ValueError(f"episodes must be a positive integer, got {episodes}")
    trained = load_trained(run_dir)
    env = trained.make_env(**(task_kwargs or {}))
    gen = torch.Generator().manual_seed(seed)
    done_eps: list[Episode] = []
    usage: Counter[str] = Counter()
    moves: list[tuple[float, float, float]] = []  # (min d(C, T), max lift, untouched TargetDistSum) per episode
    for k in range(episodes):
        obs, info = env.reset(seed=seed + k)
        start_gap = float(np.linalg.norm(obs[21:24] - obs[24:27])) if obs.shape[-1] >= 27 else math.nan
        ret, length = 0.0, 0
        while True:
            obs, r, term, trunc, info = env.step(trained.act(env, obs, gen, deterministic))
            ret += float(info.get("task_reward", r))
            length += int(info.get("tau", 1))
            if "macro" in info:
                usage[info["macro"]] += 1
            if term or trunc:
                break
        s, tds = info.get("success"), info.get("target_dist_sum")
        if tds is not None and "closest_max" in info:
            moves.append((-float(info["closest_max"]), float(info["lift_max"]), -length * start_gap))
        done_eps.append(Episode(ret, length, None if s is None else bool(s), None if tds is None else float(tds)))
    names = getattr(env, "names", None)
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


def _move_stats(moves: list[tuple[float, float, float]], tds: list[float]) -> MoveStats:
    closest, lift, untouched = (list(x) for x in zip(*moves, strict=True))
    return MoveStats(
        min_target_dist=mean_interval(closest),
        lift_rate=wilson_interval(sum(h > LIFT_HEIGHT for h in lift), len(lift)),
        untouched_target_dist_sum=mean_interval(untouched),
        relative_target_dist_sum=mean_interval([t - u for t, u in zip(tds, untouched, strict=True)]),
    )
