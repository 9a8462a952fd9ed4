"""Short-episode parameterised-action tasks: hrlp TRPO with the short-episode settings against the optimum.

Trains each task of :mod:`hrlp.envs.param_tasks` (a contextual bandit, a parameter-matching task, a sparse-reward
reaching task) with :data:`~hrlp.envs.param_tasks.SHORT_EPISODE_SETTINGS` for ``--episodes`` training episodes
per seed (``TrainConfig.episodes``: the run stops after the iteration that reaches the budget), evaluates the
greedy policy over ``--eval-episodes`` episodes (environment seeds 10,000 + index, :func:`hrlp.evaluate.evaluate_run`)
and prints per task: the optimal return, a uniformly random policy's, the
hand-written heuristic's (both over the same evaluation episodes), hrlp's mean and min over seeds, the mean as a
share of the optimum, the training episodes used and the wall time. One torch thread.

    python benchmarks/short_episodes.py [--seeds 3] [--episodes 20000] [--eval-episodes 1000]
                                        [--tasks ParamBandit,ParamMatch,ParamReach] [--out FILE.json [--overwrite]]

Parameters are acted in [-1, 1] and mapped onto each Box's bounds by hrlp's action wrapper (``hrlp.envs.actions``).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from hrlp.envs.param_tasks import PARAM_TASKS, SHORT_EPISODE_SETTINGS, heuristic_action, random_action, short_episode_config


def baseline_return(name: str, policy: str, episodes: int, seed: int = 10_000) -> float:
    """Mean return of the ``random`` or ``heuristic`` policy over the evaluation episodes (seeds ``seed + i``)."""
    env = gym.make(f"hrlp/{name}-v0")
    rng = np.random.default_rng(seed)
    total = 0.0
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        while True:
            a = random_action(env, rng) if policy == "random" else heuristic_action(env, obs)
            obs, r, terminated, truncated, _ = env.step(a)
            total += float(r)
            if terminated or truncated:
                break
    env.close()
    return total / episodes


def train_and_evaluate(name: str, seed: int, episodes: int, eval_episodes: int, workdir: Path,
                       settings: dict[str, Any] | None = None) -> dict[str, Any]:  # fmt: skip
    """Train ``name`` with the short-episode settings (or ``settings``) for ``episodes`` episodes, greedy-evaluate it."""
    from hrlp.evaluate import evaluate_run
    from hrlp.train import train

    horizon = PARAM_TASKS[name]().horizon
    cfg = short_episode_config(f"hrlp/{name}-v0", steps=episodes * horizon + 10**6, seed=seed, episodes=episodes,
                               **(settings or {}))  # fmt: skip
    run_dir = workdir / f"{name}-seed{seed}"
    t0 = time.perf_counter()
    done, iterations, decisions = 0, 0, 0
    for stats in train(cfg, run_dir, on_warning=lambda message: None):
        done, iterations, decisions = int(stats["episodes_total"]), int(stats["iteration"]), int(stats["env_steps"])
    train_s = time.perf_counter() - t0
    ev = evaluate_run(run_dir, episodes=eval_episodes, deterministic=True)
    return {"seed": seed, "return": ev.ret.mean, "episodes": done, "iterations": iterations, "decisions": decisions,
            "train_s": train_s, "wall_s": time.perf_counter() - t0}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="seeds per task (0, 1, ...)")
    ap.add_argument("--episodes", type=int, default=20_000, help="training episodes per run")
    ap.add_argument("--eval-episodes", type=int, default=1000, help="greedy evaluation episodes per run")
    ap.add_argument("--tasks", default=",".join(PARAM_TASKS), help="comma-separated task names")
    ap.add_argument("--settings", default=None, help="JSON of overrides of the short-episode settings (for tuning)")
    ap.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    ap.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    args = ap.parse_args(argv)
    tasks = [t.strip() for t in args.tasks.split(",") if t.strip()]
    if unknown := [t for t in tasks if t not in PARAM_TASKS]:
        ap.error(f"unknown tasks {unknown}; known: {', '.join(PARAM_TASKS)}")
    if args.seeds < 1 or args.episodes < 1 or args.eval_episodes < 1:
        ap.error("--seeds, --episodes and --eval-episodes must be positive")
    if args.out is not None and args.out.exists() and not args.overwrite:
        ap.error(f"{args.out} exists; pass --overwrite to replace it")
    overrides = json.loads(args.settings) if args.settings else {}
    torch.set_num_threads(1)
    settings = {**SHORT_EPISODE_SETTINGS, **overrides}
    print(f"settings: {json.dumps(settings)}", flush=True)
    results: dict[str, Any] = {"settings": settings, "episodes": args.episodes,
                               "eval_episodes": args.eval_episodes, "command": " ".join(sys.argv), "tasks": {}}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="short_episodes_") as tmp:
        for name in tasks:
            optimal = PARAM_TASKS[name]().optimal_return()
            rand = baseline_return(name, "random", args.eval_episodes)
            heur = baseline_return(name, "heuristic", args.eval_episodes)
            print(f"{name}: optimal {optimal:.4g}, random {rand:.4g}, heuristic {heur:.4g}", flush=True)
            runs = []
            for seed in range(args.seeds):
                run = train_and_evaluate(name, seed, args.episodes, args.eval_episodes, Path(tmp), overrides)
                runs.append(run)
                print(f"  {name} seed {seed}: greedy return {run['return']:.4g} ({run['return'] / optimal:.1%} of optimal), "
                      f"{run['episodes']:,} episodes, {run['iterations']} iterations, {run['decisions']:,} decisions, "
                      f"{run['wall_s']:.0f} s", flush=True)  # fmt: skip
            rets = [r["return"] for r in runs]
            results["tasks"][name] = {"optimal": optimal, "random": rand, "heuristic": heur, "runs": runs,
                                      "mean": float(np.mean(rets)), "min": float(np.min(rets))}  # fmt: skip
    print()
    head = f"{'task':<12} {'optimal':>8} {'random':>8} {'heuristic':>9} {'hrlp mean':>9} {'hrlp min':>9} {'% opt':>6} " \
           f"{'% opt min':>9} {'episodes':>9} {'wall s':>7}"  # fmt: skip
    print(head)
    for name, t in results["tasks"].items():
        eps = max(r["episodes"] for r in t["runs"])
        wall = sum(r["wall_s"] for r in t["runs"]) / len(t["runs"])
        print(f"{name:<12} {t['optimal']:>8.4g} {t['random']:>8.4g} {t['heuristic']:>9.4g} {t['mean']:>9.4g} "
              f"{t['min']:>9.4g} {t['mean'] / t['optimal']:>6.1%} {t['min'] / t['optimal']:>9.1%} {eps:>9,} "
              f"{wall:>7.0f}")  # fmt: skip
    ok = all(t["min"] >= 0.95 * t["optimal"] for t in results["tasks"].values())
    print(f"every seed of every task at >= 95% of optimal: {'yes' if ok else 'no'}", flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
