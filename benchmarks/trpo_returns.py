"""Final returns on Reacher-v5: sb3-contrib TRPO (defaults) against hrlp TRPO at the same number of env steps.

Each library trains one policy per seed; every final policy is then scored on the same evaluation episodes
(deterministic actions, environment seeds 10,000 + episode index). Printed: per-seed scores and mean +- 95% CI
(Student t over seeds) per library. One torch thread.

    python benchmarks/trpo_returns.py [--steps 200000] [--seeds 3] [--batch-steps 5000] [--episodes 20]
                                      [--hrlp paper|defaults|fastest[,...]]

hrlp's settings (``HRLP_SETTINGS``): ``paper``, the paper's (``hrlp.config.PAPER_SETTINGS``: one process, 16
environments, exact Fisher-vector products, the baseline by 25 L-BFGS iterations on every state); ``defaults``,
``TrainConfig``'s (a sampling worker per core, 64 environments, Fisher-vector products on 10% of the batch, the baseline
by 10 iterations on every 4th time step); ``fastest``, the defaults with 2 workers whatever the cores. Every setting
trains with ``--batch-steps`` decisions per iteration.
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

from runlog import add_argument, record

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


def _hrlp_settings() -> dict[str, dict[str, object]]:
    from hrlp.config import PAPER_SETTINGS

    fastest = {"workers": 2, "num_envs": 64, "trpo.fisher_fraction": 0.1, "value.max_iter": 10, "value.fraction": 0.25}
    return {"paper": dict(PAPER_SETTINGS), "defaults": {}, "fastest": fastest}


#: hrlp settings compared (``hrlp.config.with_settings``' names): the paper's, TrainConfig's defaults, and
#: benchmarks/trpo_speed.py's fastest (2 sampling workers, Fisher-vector products on 10% of the batch, 64 environments,
#: the baseline fitted by 10 L-BFGS iterations on every 4th time step: the defaults on a two-core machine).
HRLP_SETTINGS = _hrlp_settings()


def hrlp_score(steps: int, seed: int, episodes: int, batch_steps: int, num_envs: int | None, settings: str = "paper"
               ) -> tuple[float, float]:  # fmt: skip
    from hrlp.config import with_settings
    from hrlp.train import TrainConfig, Trainer

    kw = {**HRLP_SETTINGS[settings], "batch_steps": batch_steps, **({} if num_envs is None else {"num_envs": num_envs})}
    trainer = Trainer(with_settings(TrainConfig(task=TASK, steps=steps, seed=seed), kw))
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
    ap.add_argument("--num-envs", type=int, default=None, help="hrlp environments stepped together (default: the setting's)")
    ap.add_argument("--episodes", type=int, default=20, help="evaluation episodes per final policy")
    ap.add_argument("--libs", default="hrlp,sb3", help="comma-separated subset of hrlp,sb3")
    ap.add_argument("--hrlp", default="paper", help=f"hrlp's settings, comma-separated: {', '.join(HRLP_SETTINGS)}")
    add_argument(ap)
    args = ap.parse_args()
    settings = [s.strip() for s in args.hrlp.split(",") if s.strip()]
    if unknown := [s for s in settings if s not in HRLP_SETTINGS]:
        ap.error(f"--hrlp: unknown settings {unknown}; known: {', '.join(HRLP_SETTINGS)}")
    torch.set_num_threads(1)

    def hrlp(setting: str) -> Callable[[int], tuple[float, float]]:
        return lambda s: hrlp_score(args.steps, s, args.episodes, args.batch_steps, args.num_envs, setting)

    runners: dict[str, Callable[[int], tuple[float, float]]] = {}  # one label per hrlp setting ("hrlp" for one alone)
    for lib in args.libs.split(","):
        if lib == "hrlp":
            runners.update({"hrlp": hrlp(settings[0])} if len(settings) == 1 else {f"hrlp-{s}": hrlp(s) for s in settings})
        else:
            runners["sb3"] = lambda s: sb3_score(args.steps, s, args.episodes)
    scores: dict[str, list[float]] = {}
    for label, run in runners.items():
        scores[label] = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            score, wall = run(seed)
            scores[label].append(score)
            print(f"{label:<5} seed {seed}: return {score:8.2f}  (training {wall:.0f} s)", flush=True)

    print(
        f"\n{TASK}, {args.steps} env steps, {args.seeds} seeds, {args.episodes} deterministic episodes each; hrlp: "
        f"{', '.join(settings)}"
    )
    for lib, xs in scores.items():
        m, h = ci95(xs)
        print(f"{lib:<5} {m:8.2f} +- {h:.2f}")
    record(__file__, {"task": TASK, "steps": args.steps, "episodes": args.episodes, "returns": scores,
                      "mean_ci95": {lib: ci95(xs) for lib, xs in scores.items()}}, args.runs_dir)  # fmt: skip


if __name__ == "__main__":
    main()
