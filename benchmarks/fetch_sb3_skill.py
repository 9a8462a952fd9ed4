"""Train the Fetch ``carry`` skill's policy with Stable-Baselines3: SAC + HER on FetchReach-v4, saved as an SB3 ``.zip``
that hrlp reads without unpickling (:func:`hrlp.skills.from_sb3`; :mod:`hrlp.fetch.skills`). SB3's SAC with
``HerReplayBuffer(n_sampled_goal=4, goal_selection_strategy="future")``, ``learning_starts=1000``, otherwise SB3's
defaults; one torch thread. Prints the greedy success over ``--eval-episodes`` episodes (seeds 10,000 + i).

    python benchmarks/fetch_sb3_skill.py --out src/hrlp/fetch/pretrained/fetch-reach-sb3.zip [--steps 20000] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import gymnasium as gym
import torch

from fetch_her import sb3_greedy_success


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="the .zip to write (refused if it exists, unless --overwrite)")
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--eval-episodes", type=int, default=100)
    ap.add_argument("--overwrite", action="store_true")
    args = ap.parse_args()
    if args.out.exists() and not args.overwrite:
        sys.exit(f"{args.out} exists; give --overwrite to replace it")
    from stable_baselines3 import SAC, HerReplayBuffer

    torch.set_num_threads(1)
    env = gym.make("gymnasium_robotics:FetchReach-v4")
    model = SAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, learning_starts=1000, seed=args.seed,
                replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"}, verbose=0)  # fmt: skip
    t0 = time.perf_counter()
    model.learn(total_timesteps=args.steps)
    print(f"trained {args.steps:,} steps in {time.perf_counter() - t0:.0f} s")
    print(f"greedy success over {args.eval_episodes} episodes: {sb3_greedy_success(model, env, args.eval_episodes):.2f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    model.save(args.out)
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
