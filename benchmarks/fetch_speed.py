"""Fetch's sampling speed through hrlp's ``VectorEnv`` seam against Stable-Baselines3's ``DummyVecEnv``, on the same
task, the same number of environments and the same random actions: environment steps per second, one process, ratios
within one run. hrlp flattens each Dict observation into its row (what its policies read); SB3 stacks each key.

    python benchmarks/fetch_speed.py [--task PickAndPlace] [--num-envs 4] [--steps 4000]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

from runlog import add_argument, record


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", default="PickAndPlace", choices=("Reach", "Push", "PickAndPlace", "Slide"))
    ap.add_argument("--num-envs", type=int, default=4)
    ap.add_argument("--steps", type=int, default=4_000, help="environment steps per measurement (all environments)")
    add_argument(ap)
    args = ap.parse_args()
    from stable_baselines3.common.vec_env import DummyVecEnv

    from hrlp.fetch import check_installed
    from hrlp.rollout import build_vector_env
    from hrlp.train import env_factory

    check_installed()
    task = f"gymnasium_robotics:Fetch{args.task}-v4"
    n, calls = args.num_envs, args.steps // args.num_envs
    actions = np.random.default_rng(0).uniform(-1, 1, (calls, n, 4))

    hrlp_env = build_vector_env([env_factory(task)] * n)
    hrlp_env.reset(seed=0)
    t0 = time.perf_counter()
    for a in actions:
        hrlp_env.step(a)
    hrlp_s = time.perf_counter() - t0

    sb3_env = DummyVecEnv([lambda: gym.make(task) for _ in range(n)])
    sb3_env.seed(0)
    sb3_env.reset()
    t0 = time.perf_counter()
    for a in actions:
        sb3_env.step(a)
    sb3_s = time.perf_counter() - t0

    steps = calls * n
    print(f"Fetch{args.task}-v4, {n} environments, {steps:,} random steps each way")
    print(f"hrlp VectorEnv:     {steps / hrlp_s:8.0f} steps/s")
    print(f"SB3 DummyVecEnv:    {steps / sb3_s:8.0f} steps/s")
    print(f"hrlp / SB3:         {sb3_s / hrlp_s:8.2f}x")
    record(__file__, {"task": f"Fetch{args.task}-v4", "envs": n, "steps": steps, "hrlp_steps_per_s": steps / hrlp_s,
                      "sb3_steps_per_s": steps / sb3_s, "hrlp_over_sb3": sb3_s / hrlp_s}, args.runs_dir)  # fmt: skip


if __name__ == "__main__":
    main()
