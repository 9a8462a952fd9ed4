"""Off-policy against on-policy on short-episode parameterised-action tasks: hrlp's hybrid SAC against its TRPO.

Trains each task of :mod:`hrlp.envs.param_tasks` with ``--algo sac``'s defaults (4 environments) and with TRPO's
short-episode settings (:data:`~hrlp.envs.param_tasks.SHORT_EPISODE_SETTINGS`, what ``hrlp train`` picks for these
tasks), for the same ``--episodes`` and seeds. After each iteration that passes a multiple
of ``--eval-every`` training episodes, the greedy policy is evaluated on ``--eval-episodes`` episodes (environment seeds
10,000 + i); the table gives the training episodes each needed to reach 90% of the optimum, the greedy return at the
end, and their ratio. One torch thread.

    python benchmarks/sac_short_episodes.py [--seeds 2] [--episodes 6000] [--eval-every 500] [--eval-episodes 300]
                                            [--tasks ParamBandit,ParamMatch] [--out FILE.json [--overwrite]]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from hrlp.envs.param_tasks import PARAM_TASKS, short_episode_config

SAC_SETTINGS = {"algo": "sac", "num_envs": 4, "batch_steps": 250, "workers": 1}
"""``hrlp train --algo sac``'s 4 environments, with iterations (log rows, checkpoints and here evaluations: they change
nothing that is learned) of 250 decisions, so that the curve is measured as finely as TRPO's 500-decision batches."""


def run(name: str, algo: str, seed: int, episodes: int, eval_every: int, eval_episodes: int, workdir: Path) -> dict[str, Any]:
    """Train ``name`` with ``algo`` for ``episodes`` episodes; the greedy return every ``eval_every`` episodes."""
    from hrlp.config import TrainConfig
    from hrlp.evaluate import evaluate_run
    from hrlp.train import train

    horizon = PARAM_TASKS[name]().horizon
    steps = episodes * horizon + 10**6
    task = f"hrlp/{name}-v0"
    if algo == "sac":
        cfg = TrainConfig(task=task, steps=steps, seed=seed, episodes=episodes, **SAC_SETTINGS)  # type: ignore[arg-type]
    else:
        cfg = short_episode_config(task, steps=steps, seed=seed, episodes=episodes)
    run_dir = workdir / f"{name}-{algo}-{seed}"
    curve: list[tuple[int, int, float]] = []
    mark = eval_every
    t0 = time.perf_counter()
    for stats in train(cfg, run_dir, on_warning=lambda message: None):
        done = int(stats["episodes_total"])
        if done >= mark or done >= episodes:
            curve.append((done, int(stats["env_steps"]), evaluate_run(run_dir, episodes=eval_episodes).ret.mean))
            mark = (done // eval_every + 1) * eval_every
    return {"seed": seed, "curve": curve, "wall_s": time.perf_counter() - t0}


def episodes_to(curve: list[tuple[int, int, float]], level: float) -> float:
    """The training episodes of the first evaluation at or above ``level`` (inf if none)."""
    return next((float(e) for e, _, r in curve if r >= level), math.inf)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2, help="seeds per task and algorithm (0, 1, ...)")
    ap.add_argument("--episodes", type=int, default=6_000, help="training episodes per run")
    ap.add_argument("--eval-every", type=int, default=500, help="greedy evaluation every this many training episodes")
    ap.add_argument("--eval-episodes", type=int, default=300, help="greedy evaluation episodes")
    ap.add_argument("--tasks", default="ParamBandit,ParamMatch", help="comma-separated task names")
    ap.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    ap.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    args = ap.parse_args(argv)
    tasks = [t.strip() for t in args.tasks.split(",") if t.strip()]
    if unknown := [t for t in tasks if t not in PARAM_TASKS]:
        ap.error(f"unknown tasks {unknown}; known: {', '.join(PARAM_TASKS)}")
    if min(args.seeds, args.episodes, args.eval_every, args.eval_episodes) < 1:
        ap.error("--seeds, --episodes, --eval-every and --eval-episodes must be positive")
    if args.out is not None and args.out.exists() and not args.overwrite:
        ap.error(f"{args.out} exists; pass --overwrite to replace it")
    torch.set_num_threads(1)
    results: dict[str, Any] = {"episodes": args.episodes, "eval_every": args.eval_every, "eval_episodes": args.eval_episodes,
                               "command": " ".join(sys.argv), "tasks": {}}  # fmt: skip
    rows = []
    with tempfile.TemporaryDirectory(prefix="sac_short_episodes_") as tmp:
        for name in tasks:
            optimal = PARAM_TASKS[name]().optimal_return()
            task: dict[str, Any] = {"optimal": optimal}
            for algo in ("sac", "trpo"):
                runs = [
                    run(name, algo, s, args.episodes, args.eval_every, args.eval_episodes, Path(tmp))
                    for s in range(args.seeds)
                ]
                for r in runs:
                    r["episodes_to_90"] = episodes_to(r["curve"], 0.9 * optimal)
                    last = r["curve"][-1]
                    print(f"{name} {algo} seed {r['seed']}: 90% of the optimum after {r['episodes_to_90']:,.0f} "
                          f"episodes, greedy {last[2]:.4g} at {last[0]:,}, {r['wall_s']:.0f} s", flush=True)  # fmt: skip
                task[algo] = runs
            results["tasks"][name] = task
            to90 = {a: float(np.mean([r["episodes_to_90"] for r in task[a]])) for a in ("sac", "trpo")}
            final = {a: float(np.mean([r["curve"][-1][2] for r in task[a]])) for a in ("sac", "trpo")}
            rows.append((name, optimal, to90, final))
    print()
    print(f"{'task':<12} {'optimal':>8} {'SAC eps to 90%':>15} {'TRPO eps to 90%':>16} {'ratio':>6} {'SAC final':>10} "
          f"{'TRPO final':>11}")  # fmt: skip
    for name, optimal, to90, final in rows:
        ratio = to90["trpo"] / to90["sac"] if math.isfinite(to90["sac"]) else math.nan
        print(f"{name:<12} {optimal:>8.4g} {to90['sac']:>15,.0f} {to90['trpo']:>16,.0f} {ratio:>6.1f} {final['sac']:>10.4g} "
              f"{final['trpo']:>11.4g}")  # fmt: skip
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2, default=str) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
