"""Goal relabelling on a robot: hrlp's SAC + HER against Stable-Baselines3's SAC + HER on FetchReach-v4.

Both learners run with their own defaults (hrlp: ``--algo sac``'s, 4 environments, HER's future strategy with 4
relabelled goals per real one; SB3: ``SAC("MultiInputPolicy")`` with ``HerReplayBuffer(n_sampled_goal=4,
goal_selection_strategy="future")``, one environment) for the same number of environment steps and the same seeds,
then each policy is evaluated greedily on the same ``--eval-episodes`` episodes (environment seeds 10,000 + i). One torch
thread each. Needs gymnasium-robotics and a MuJoCo it runs on (3.3 to 3.11 with gymnasium-robotics 1.4.2).

    python benchmarks/her_fetch_reach.py [--steps 8000] [--seeds 3] [--eval-episodes 100] [--out FILE.json [--overwrite]]
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

from fetch_her import sb3_greedy_success

TASK = "FetchReach-v4"


def hrlp_run(seed: int, steps: int, eval_episodes: int, workdir: Path) -> dict[str, Any]:
    """hrlp's SAC + HER with ``--algo sac``'s defaults; greedy success over the evaluation episodes."""
    from hrlp.config import TrainConfig
    from hrlp.evaluate import evaluate_run
    from hrlp.train import train

    cfg = TrainConfig(task=f"gymnasium_robotics:{TASK}", algo="sac", num_envs=4, batch_steps=2_000, steps=steps, seed=seed)
    run = workdir / f"hrlp-{seed}"
    t0 = time.perf_counter()
    curve = [(int(s["env_steps"]), float(s["success_rate"])) for s in train(cfg, run)]
    train_s = time.perf_counter() - t0
    ev = evaluate_run(run, episodes=eval_episodes)
    assert ev.success is not None
    return {"seed": seed, "success": ev.success.mean, "train_s": train_s, "training_success": curve}


def sb3_run(seed: int, steps: int, eval_episodes: int) -> dict[str, Any]:
    """Stable-Baselines3's SAC + HER with its defaults; greedy success over the evaluation episodes."""
    from stable_baselines3 import SAC, HerReplayBuffer

    env = gym.make(TASK)
    model = SAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, seed=seed, verbose=0,
                replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"})  # fmt: skip
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    train_s = time.perf_counter() - t0
    success = sb3_greedy_success(model, env, eval_episodes)
    env.close()
    return {"seed": seed, "success": success, "train_s": train_s}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=8_000, help="environment steps per run")
    ap.add_argument("--seeds", type=int, default=3, help="seeds (0, 1, ...)")
    ap.add_argument("--eval-episodes", type=int, default=100, help="greedy evaluation episodes per run")
    ap.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    ap.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    args = ap.parse_args(argv)
    if min(args.steps, args.seeds, args.eval_episodes) < 1:
        ap.error("--steps, --seeds and --eval-episodes must be positive")
    if args.out is not None and args.out.exists() and not args.overwrite:
        ap.error(f"{args.out} exists; pass --overwrite to replace it")
    try:
        import gymnasium_robotics
        import mujoco

        gym.register_envs(gymnasium_robotics)
        gym.make(TASK).reset(seed=0)
    except Exception as e:  # a missing package, or a MuJoCo gymnasium-robotics does not run on
        print(f"{TASK} does not run here ({type(e).__name__}: {e}); gymnasium-robotics 1.4.2 needs mujoco 3.3 to 3.11")
        return 1
    torch.set_num_threads(1)
    results: dict[str, Any] = {"task": TASK, "steps": args.steps, "eval_episodes": args.eval_episodes,
                               "mujoco": mujoco.__version__, "command": " ".join(sys.argv), "hrlp": [], "sb3": []}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="her_fetch_reach_") as tmp:
        for seed in range(args.seeds):
            for name in ("hrlp", "sb3"):
                run = hrlp_run(seed, args.steps, args.eval_episodes, Path(tmp)) if name == "hrlp" else sb3_run(
                    seed, args.steps, args.eval_episodes)  # fmt: skip
                results[name].append(run)
                print(f"{name} seed {seed}: greedy success {run['success']:.2f} after {args.steps:,} steps, "
                      f"{run['train_s']:.0f} s", flush=True)  # fmt: skip
    for name in ("hrlp", "sb3"):
        s = [r["success"] for r in results[name]]
        t = [r["train_s"] for r in results[name]]
        results[f"{name}_mean"] = float(np.mean(s))
        print(f"{name}: greedy success mean {np.mean(s):.3f} (per seed {', '.join(f'{x:.2f}' for x in s)}), "
              f"training {np.mean(t):.0f} s per run ({args.steps / np.mean(t):.0f} steps/s)")  # fmt: skip
    if results["sb3_mean"] > 0:
        print(f"hrlp / sb3 success: {results['hrlp_mean'] / results['sb3_mean']:.2f}")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
