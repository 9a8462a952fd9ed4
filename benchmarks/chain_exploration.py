"""What an untrained Manager finds on reach-and-move over the skill chain, under each part of the chained interface.

A Manager starts from uniform choices and parameter blocks drawn around the box's centre with the initial log-std.
This script runs that policy (``--policy random``: each choice uniform over reacher-handover, gripper-imitated and
mover-held, each block ``N(0, exp(log_std))`` clipped to [-1, 1]) or the state-independent plan "always the Mover"
(``--policy mover``, which under initiation sets runs the chain: reach, grip, carry) on reach-and-move (300-step
episodes, the capsule fixed, the target 15 cm above it) and prints the success rate (d(C, T) < 3 cm at some step) with
its 95% Wilson interval and the share of episodes in which the capsule was lifted more than 1.5 cm: how often the
plan a Manager must learn shows up in its first batches. Settings: ``--k`` steps per decision, ``--log-std``,
``--no-initiation`` (skills start anywhere), ``--no-pregrasp`` (Reacher goals in HANDOVER_POINT's box, centred 10 cm
above the capsule, instead of the pre-grasp box centred 4 cm above it).

    python benchmarks/chain_exploration.py --episodes 60 [--k 50] [--log-std -2] [--policy random|mover]
        [--no-initiation] [--no-pregrasp]
"""

from __future__ import annotations

import argparse

import numpy as np

from hrlp.arm import make
from hrlp.arm.handover import arm_macro_env
from hrlp.arm.physics import CAPSULE_REST_Z
from hrlp.config import Handover
from hrlp.evaluate import wilson_interval
from hrlp.skills import load_skill
from hrlp.skills.macro_env import step_macros

CHAIN = ("reacher-handover", "gripper-imitated", "mover-held")


def explore(episodes: int, k: int, log_std: float, policy: str, initiation: bool, pregrasp: bool,
            seed: int = 0) -> dict[str, float]:  # fmt: skip
    """Success rate (with its Wilson interval) and lifted share over ``episodes`` seeds."""
    skills = [load_skill(name) for name in CHAIN]
    handover = Handover(approach_height=0.0, open_torque=0.0, target_relative=True, initiation=initiation,
                        pregrasp=pregrasp)  # fmt: skip
    envs = [arm_macro_env(make("ReachAndMove"), skills, k=k, handover=handover) for _ in range(episodes)]
    for i, e in enumerate(envs):
        e.reset(seed=i)
    rng = np.random.default_rng(seed)
    n_blocks = int(envs[0].offsets[-1])
    success, lifted, done = (np.zeros(episodes, dtype=bool) for _ in range(3))
    while not done.all():
        choice = rng.integers(0, len(CHAIN), episodes) if policy == "random" else np.full(episodes, CHAIN.index(CHAIN[-1]))
        blocks = np.clip(rng.normal(0.0, np.exp(log_std), (episodes, n_blocks)), -1.0, 1.0)
        res = step_macros(envs, np.concatenate([choice[:, None], blocks], axis=1))
        for i, info in enumerate(res.infos):
            if not done[i]:
                success[i] |= bool(info.get("success"))
                lifted[i] |= envs[i]._obs[23] - CAPSULE_REST_Z > 0.015
        done |= res.terminated | res.truncated
    ci = wilson_interval(int(success.sum()), episodes)
    return {"success": ci.mean, "low": ci.low, "high": ci.high, "lifted": float(lifted.mean())}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--k", type=int, default=50)
    ap.add_argument("--log-std", type=float, default=-2.0)
    ap.add_argument("--policy", choices=("random", "mover"), default="random")
    ap.add_argument("--no-initiation", dest="initiation", action="store_false")
    ap.add_argument("--no-pregrasp", dest="pregrasp", action="store_false")
    args = ap.parse_args()
    r = explore(args.episodes, args.k, args.log_std, args.policy, args.initiation, args.pregrasp)
    on = {True: "on", False: "off"}
    print(f"policy {args.policy}, k = {args.k}, log-std {args.log_std:g}, initiation sets {on[args.initiation]}, "
          f"pre-grasp goals {on[args.pregrasp]}, {args.episodes} episodes: success {r['success']:.3f} "
          f"[{r['low']:.2f}, {r['high']:.2f}], capsule lifted {r['lifted']:.2f}")  # fmt: skip
