"""SAC against TRPO at equal environment steps: the demo's reach-and-grip Manager, and Pendulum-v1.

``--task manager``: the demo's Manager (ReachAndGrip1, the shipped gripper and reacher, k = 10, the Reacher driven for
hand-over: :func:`hrlp.experiments.demo.demo_config`), TRPO with the demo's settings; the level is a greedy success of
0.95. ``--task pendulum``: Pendulum-v1, TRPO with 16 environments and 4,000-decision batches (as
``benchmarks/ppo_vs_trpo.py``); the level is a greedy return of -200. SAC runs with ``--algo sac``'s settings (4
environments; 2,000-decision iterations here, so that it is evaluated as often as TRPO). Both train for ``--steps``
low-level steps on the same seeds; after each iteration that passes a multiple of ``--eval-every`` steps the greedy
policy is evaluated on ``--eval-episodes`` episodes (seeds 10,000 + i). The table gives the steps each needed to reach
the level and the figure at the end.

    python benchmarks/sac_vs_trpo.py --task manager [--steps 300000] [--seeds 2] [--eval-every 50000]
                                     [--eval-episodes 50] [--out FILE.json [--overwrite]]
    python benchmarks/sac_vs_trpo.py --task pendulum --steps 30000 --eval-every 5000 --eval-episodes 20
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

LEVELS = {"manager": 0.95, "pendulum": -200.0}
"""The greedy figure (success, return) each task counts as reached."""


def config(task: str, algo: str, seed: int, steps: int) -> Any:
    """The run's config: TRPO's settings of the task, or SAC's."""
    from hrlp.config import TrainConfig
    from hrlp.experiments.demo import demo_config

    if task == "manager":
        cfg = demo_config(steps=steps, seed=seed)
    else:
        cfg = TrainConfig(task="Pendulum-v1", steps=steps, seed=seed, num_envs=16, batch_steps=4_000)
    if algo == "sac":
        cfg = dataclasses.replace(cfg, algo="sac", workers=1, num_envs=4, batch_steps=2_000)
    return cfg


def run(task: str, algo: str, seed: int, steps: int, eval_every: int, eval_episodes: int, workdir: Path) -> dict[str, Any]:
    """Train ``task`` with ``algo``; the greedy figure every ``eval_every`` steps."""
    from hrlp.evaluate import evaluate_run
    from hrlp.train import train

    cfg = config(task, algo, seed, steps)
    run_dir = workdir / f"{algo}-{seed}"
    curve: list[tuple[int, float]] = []
    mark = eval_every
    t0 = time.perf_counter()
    for stats in train(cfg, run_dir, on_warning=lambda message: None):
        done = int(stats["env_steps"])
        if done >= mark or done >= steps:
            ev = evaluate_run(run_dir, episodes=eval_episodes)
            figure = ev.ret.mean if task == "pendulum" else ev.success.mean  # type: ignore[union-attr]
            curve.append((done, figure))
            print(f"  {task} {algo} seed {seed}: {done:,} steps, greedy {figure:.3f}", flush=True)
            mark = (done // eval_every + 1) * eval_every
    return {"seed": seed, "curve": curve, "wall_s": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", choices=sorted(LEVELS), default="manager", help="the Manager or Pendulum-v1")
    ap.add_argument("--steps", type=int, default=300_000, help="low-level environment steps per run")
    ap.add_argument("--seeds", type=int, default=2, help="seeds (0, 1, ...)")
    ap.add_argument("--eval-every", type=int, default=50_000, help="greedy evaluation every this many steps")
    ap.add_argument("--eval-episodes", type=int, default=50, help="greedy evaluation episodes")
    ap.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    ap.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    args = ap.parse_args(argv)
    if min(args.steps, args.seeds, args.eval_every, args.eval_episodes) < 1:
        ap.error("--steps, --seeds, --eval-every and --eval-episodes must be positive")
    if args.out is not None and args.out.exists() and not args.overwrite:
        ap.error(f"{args.out} exists; pass --overwrite to replace it")
    torch.set_num_threads(1)
    level = LEVELS[args.task]
    results: dict[str, Any] = {"task": args.task, "level": level, "steps": args.steps, "eval_every": args.eval_every,
                               "eval_episodes": args.eval_episodes, "command": " ".join(sys.argv)}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="sac_vs_trpo_") as tmp:
        for algo in ("sac", "trpo"):
            results[algo] = [
                run(args.task, algo, s, args.steps, args.eval_every, args.eval_episodes, Path(tmp)) for s in range(args.seeds)
            ]
    print()
    print(f"{'optimiser':<10} {f'steps to {level:g}':>15} {'final':>10} {'per seed (steps to level / final)'}")
    for algo in ("sac", "trpo"):
        reach = [next((float(s) for s, v in r["curve"] if v >= level), math.inf) for r in results[algo]]
        final = [r["curve"][-1][1] for r in results[algo]]
        seeds = ", ".join(f"{a:,.0f} / {b:.2f}" for a, b in zip(reach, final, strict=True))
        print(f"{algo:<10} {np.mean(reach):>15,.0f} {np.mean(final):>10.3f} {seeds}")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
