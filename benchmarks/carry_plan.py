"""A scripted reach-grip-carry plan on reach-and-move with the skills made to hand over: the ceiling a Manager can reach.

Every episode of reach-and-move (Section 4.2: the capsule fixed, the target 15 cm above it, the arm starting anywhere)
runs, one macro-action of ``--k`` steps at a time: the Reacher to 4 cm above the capsule (capsule-relative goal, run as
trained) for ``--reach-calls`` calls, then the Gripper until the capsule is held (Definition 1), then the Mover with the
task's target T (obs[24:27]) while it is held, the Gripper again if it is dropped. Prints success (d(C, T) < 3 cm at
some step) with its 95% Wilson interval, the share of episodes in which the capsule was ever held, and the mean
TargetDistSum beside the capsule left untouched. ``--initiation`` runs the plan under the skills' initiation sets
(``Handover.initiation``, what a Manager of the preset reach-and-move-initiation sees): the plan's choices are all in
their sets, so it must score the same.

    python benchmarks/carry_plan.py --episodes 100 [--reacher reacher-handover --gripper gripper-imitated --mover mover-held]
        [--initiation]
"""

from __future__ import annotations

import argparse

import numpy as np

from hrlp.arm import make
from hrlp.arm.handover import arm_macro_env
from hrlp.arm.tasks import SparseSuccess
from hrlp.config import Handover
from hrlp.evaluate import wilson_interval
from hrlp.skills import load_skill
from hrlp.skills.macro_env import step_macros

C, T = slice(21, 24), slice(24, 27)


def carry(reacher: str, gripper: str, mover: str, episodes: int, k: int, reach_calls: int,
          library: str | None = None, initiation: bool = False) -> dict[str, float]:  # fmt: skip
    """Success rate, held share and mean TargetDistSum (and the untouched capsule's) over ``episodes`` seeds."""
    skills = [load_skill(name, library) for name in (reacher, gripper, mover)]
    handover = Handover(approach_height=0.0, open_torque=0.0, initiation=initiation)
    envs = [arm_macro_env(make("ReachAndMove"), skills, k=k, handover=handover) for _ in range(episodes)]
    for i, e in enumerate(envs):
        e.reset(seed=i)
    untouched = np.array([-np.linalg.norm(e._obs[C] - e._obs[T]) for e in envs]) * envs[0].env.unwrapped.episode_steps
    success, held_ever, done = np.zeros(episodes, bool), np.zeros(episodes, bool), np.zeros(episodes, bool)
    dist_sum, gripped = np.zeros(episodes), SparseSuccess()  # Definition 1: the capsule is held
    for t in range(10_000):
        rows = []
        for i, e in enumerate(envs):
            held = gripped(e.env.unwrapped.physics)
            held_ever[i] |= held and not done[i]
            choice = 2 if held else (0 if t < reach_calls else 1)
            blocks = np.clip(np.concatenate([e.block(0, e._obs[C] + (0, 0, 0.04)), e.block(2, e._obs[T])]), -1, 1)
            rows.append(np.concatenate([[choice], blocks]))
        res = step_macros(envs, np.array(rows))
        for i, info in enumerate(res.infos):
            if not done[i]:
                success[i] |= bool(info.get("success"))
                if res.terminated[i] or res.truncated[i]:
                    dist_sum[i] = info["target_dist_sum"]
        done |= res.terminated | res.truncated
        if done.all():
            break
    ci = wilson_interval(int(success.sum()), episodes)
    return {"success": ci.mean, "low": ci.low, "high": ci.high, "held": float(held_ever.mean()),
            "target_dist_sum": float(dist_sum.mean()), "untouched": float(untouched.mean())}  # fmt: skip


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--k", type=int, default=15)
    ap.add_argument("--reach-calls", type=int, default=3)
    ap.add_argument("--reacher", default="reacher-handover")
    ap.add_argument("--gripper", default="gripper-imitated")
    ap.add_argument("--mover", default="mover-held")
    ap.add_argument("--library", default=None, help="a skill library searched before the shipped skills")
    ap.add_argument("--initiation", action="store_true", help="run under the skills' initiation sets")
    args = ap.parse_args()
    r = carry(args.reacher, args.gripper, args.mover, args.episodes, args.k, args.reach_calls, args.library, args.initiation)
    sets = ", initiation sets" if args.initiation else ""
    print(f"{args.reacher} -> {args.gripper} -> {args.mover}, {args.episodes} episodes, k = {args.k}{sets}: "
          f"success {r['success']:.2f} [{r['low']:.2f}, {r['high']:.2f}], held {r['held']:.2f}, "
          f"TargetDistSum {r['target_dist_sum']:.1f} (untouched {r['untouched']:.1f})")  # fmt: skip
