"""A Manager's environment alone, without training: environment steps per second of one decision after another on the
arm's batched backend (64 worlds of ReachAndGrip2, the shipped gripper and reacher with hand-over, k = 15, random
Manager actions), in this process on one core. Run it in two checkouts one after the other, several rounds, to compare
them on the same machine and hour:

    git worktree add /tmp/before COMMIT
    for i in 1 2 3; do for c in /tmp/before .; do (cd $c && PYTHONPATH=src python benchmarks/manager_env_speed.py); done; done

Prints ``<env steps/s> env steps/s, <decisions/s> decisions/s``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

try:  # the settings records moved into hrlp.config; an older checkout has them beside the Manager's environment
    from hrlp.config import Handover, MacroSpec
except ImportError:  # pragma: no cover - older checkouts
    from hrlp.skills.macro_env import Handover, MacroSpec  # type: ignore[no-redef]
from hrlp.train import batched_factory, env_factory


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=8.0, help="how long to step (after three warm-up decisions)")
    ap.add_argument("--num-envs", type=int, default=64)
    args = ap.parse_args()
    torch.set_num_threads(1)
    spec = MacroSpec(("gripper", "reacher"), 15, None, None, Handover())
    vec = batched_factory(env_factory("ReachAndGrip2", macro=spec)).vector(args.num_envs, 0.99)
    rng = np.random.default_rng(0)
    vec.reset(seed=0)

    def actions() -> np.ndarray:
        a = rng.uniform(-1, 1, (args.num_envs, vec.act_dim))
        a[:, 0] = rng.integers(0, 2, args.num_envs)
        return a

    for _ in range(3):
        vec.step(actions())
    start, steps, decisions = time.perf_counter(), 0, 0
    while time.perf_counter() - start < args.seconds:
        steps += int(vec.step(actions()).tau.sum())
        decisions += args.num_envs
    wall = time.perf_counter() - start
    vec.close()
    print(f"{steps / wall:,.0f} env steps/s, {decisions / wall:,.0f} decisions/s")


if __name__ == "__main__":
    main()
