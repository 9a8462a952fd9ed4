"""Final returns on Reacher-v5: sb3-contrib TRPO (defaults) against hrlp TRPO at the same number of env steps.

Each library trains one policy per seed; every final policy is then scored on the same evaluation episodes
(deterministic actions, environment seeds 10,000 + episode index). Printed: per-seed scores and mean +- 95% CI
(Student t over seeds) per library. One torch thread.

    python benchmarks/trpo_returns.py [--steps 200000] [--seeds 3] [--batch-steps 5000] [--episodes 20]
                                      [--hrlp default|fastest]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np
import torch

TASK = "Reacher-v5"
T975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306, 9: 2.262, 10: 2.228}


def evaluate(act: Callable[[np.ndarray], np.ndarray], episodes: int) -> float:
    """Mean undiscounted return of ``act`` over ``episodes`` episodes."""
    env = gym.make(TASK)
    low, high = env.action_space.low, env.action_space.high
    returns = []
    for i in range(episodes):
        obs, _ = env.reset(seed=10_000 + i)
        total, done = 0.0, False
        while not done:
            obs, r, terminated, truncated, _ = env.step(np.clip(act(obs), low, high))
            total += float(r)
            done = terminated or truncated
        returns.append(total)
    env.close()
    return float(np.mean(returns))


def sb3_score(steps: int, seed: int, episodes: int) -> tuple[float, float]:
    from sb3_contrib import TRPO

    model = TRPO("MlpPolicy", TASK, seed=seed, device="cpu")
    t = time.perf_counter()
    model.learn(total_timesteps=steps)
    wall = time.perf_counter() - t
    return evaluate(lambda o: model.predict(o, deterministic=True)[0], episodes), wall


#: hrlp settings compared: its defaults, and benchmarks/trpo_speed.py's fastest (2 sampling workers, Fisher-vector
#: products on 10% of the batch, 64 environments, the baseline fitted by 10 L-BFGS iterations on every 4th time step).
HRLP_SETTINGS = {
    "default": {},
    "fastest": {"workers": 2, "num_envs": 64, "fisher_fraction": 0.1, "value_iters": 10, "value_fraction": 0.25},
}


def hrlp_score(steps: int, seed: int, episodes: int, batch_steps: int, num_envs: int, settings: str = "default"
               ) -> tuple[float, float]:  # fmt: skip
    from hrlp.algos.trpo import TRPOConfig
    from hrlp.algos.value import ValueFitConfig
    from hrlp.train import TrainConfig, Trainer

    kw = dict(HRLP_SETTINGS[settings])
    trpo = TRPOConfig(fisher_fraction=kw.pop("fisher_fraction", 1.0))
    value = ValueFitConfig(max_iter=kw.pop("value_iters", 25), fraction=kw.pop("value_fraction", 1.0))
    kw.setdefault("num_envs", num_envs)
    trainer = Trainer(TrainConfig(task=TASK, steps=steps, batch_steps=batch_steps, seed=seed, trpo=trpo, value=value, **kw))
    t = time.perf_counter()
    try:
        while trainer.env_steps < trainer.cfg.steps:
            trainer.iterate()
    finally:
        trainer.sampler.close()
    wall = time.perf_counter() - t
    policy, norm = trainer.policy, trainer.normalizer

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return policy.act_numpy(norm.normalize(obs).astype(np.float32), deterministic=True)

    return evaluate(act, episodes), wall


def ci95(xs: list[float]) -> tuple[float, float]:
    """Mean and half-width of the 95% Student-t interval (nan for one sample)."""
    m = statistics.fmean(xs)
    if len(xs) < 2:
        return m, math.nan
    return m, T975.get(len(xs) - 1, 1.96) * statistics.stdev(xs) / math.sqrt(len(xs))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200_000, help="training env steps per run")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per library: first-seed .. first-seed + seeds - 1")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--batch-steps", type=int, default=5_000, help="hrlp env steps per TRPO iteration")
    ap.add_argument("--num-envs", type=int, default=16, help="hrlp environments stepped together")
    ap.add_argument("--episodes", type=int, default=20, help="evaluation episodes per final policy")
    ap.add_argument("--libs", default="hrlp,sb3", help="comma-separated subset of hrlp,sb3")
    ap.add_argument("--hrlp", choices=list(HRLP_SETTINGS), default="default", help="hrlp's settings (see HRLP_SETTINGS)")
    args = ap.parse_args()
    torch.set_num_threads(1)

    runners = {
        "hrlp": lambda s: hrlp_score(args.steps, s, args.episodes, args.batch_steps, args.num_envs, args.hrlp),
        "sb3": lambda s: sb3_score(args.steps, s, args.episodes),
    }
    scores: dict[str, list[float]] = {}
    for lib in args.libs.split(","):
        scores[lib] = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            score, wall = runners[lib](seed)
            scores[lib].append(score)
            print(f"{lib:<5} seed {seed}: return {score:8.2f}  (training {wall:.0f} s)", flush=True)

    print(f"\n{TASK}, {args.steps} env steps, {args.seeds} seeds, {args.episodes} deterministic episodes each")
    for lib, xs in scores.items():
        m, h = ci95(xs)
        print(f"{lib:<5} {m:8.2f} +- {h:.2f}")


if __name__ == "__main__":
    main()
