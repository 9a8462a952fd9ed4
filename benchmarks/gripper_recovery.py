"""Recovery starts for a Gripper: the states just after its own greedy episodes pushed the capsule away.

Runs the Gripper skill ``--skill`` greedily from its own start set (``GripperTask(**GRIPPER_START)``, environment seeds
``--first-seed`` + index, by default 20,000 on: clear of the evaluation starts of ``gripper_diagnosis.py`` and
``gripper_handover.py``, which begin at 10,000) and records the physics state at the first step at which the capsule
lies more than ``--push`` metres (across the table) from where it lay at the start while Definition 1 does not hold,
then every ``--every`` steps after it while the capsule is still not held (at most ``--per-episode`` states per
episode). Writes them as a start bank (``write_start_bank``; ``GripperTask(starts=BANK, starts_fraction=F)`` begins a
share F of its episodes from it: ``hrlp train Gripper --task-arg starts=BANK --task-arg starts_fraction=F``) and prints
how often the skill pushed, and how often it gripped all the same after a push.

    python benchmarks/gripper_recovery.py --out runs/recovery.npz

With its defaults it writes the bank shipped as ``src/hrlp/arm/assets/gripper_recovery_starts.npz``
(``GripperTask(starts="recovery")``, on which the shipped ``gripper-recovery`` was trained).

An existing ``--out`` is never replaced.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from hrlp.arm.env import ArmEnv
from hrlp.arm.research.starts import write_start_bank
from hrlp.arm.tasks import HANDOVER_BANK, GripperTask
from hrlp.evaluate import wilson_interval
from hrlp.experiments.presets import GRIPPER_START
from hrlp.skills import load_skill


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skill", default="gripper-clearance")
    ap.add_argument("--library", default=None)
    ap.add_argument("--episodes", type=int, default=3000)
    ap.add_argument("--steps", type=int, default=100, help="control steps per episode (the Gripper recipes' 100)")
    ap.add_argument("--first-seed", type=int, default=20_000)
    ap.add_argument("--push", type=float, default=0.03, help="capsule displacement that counts as a push, metres")
    ap.add_argument("--every", type=int, default=5, help="steps between the states recorded after a push")
    ap.add_argument("--per-episode", type=int, default=4, help="most states recorded per episode")
    ap.add_argument("--out", type=Path, required=True, help="the start bank to write (.npz)")
    args = ap.parse_args()
    if args.out.exists():
        sys.exit(f"gripper_recovery: {args.out} exists; give another --out")
    for name in ("episodes", "steps", "every", "per_episode"):
        if getattr(args, name) < 1:
            sys.exit(f"gripper_recovery: --{name.replace('_', '-')} must be at least 1")
    if not args.push > 0:
        sys.exit("gripper_recovery: --push must be a positive distance in metres")
    skill = load_skill(args.skill, args.library)
    task = GripperTask(**GRIPPER_START)
    env = ArmEnv(task, episode_steps=args.steps)
    p = env.physics
    qpos: list[np.ndarray] = []
    qvel: list[np.ndarray] = []
    pushed = gripped_after_push = wins = 0
    for ep in range(args.episodes):
        obs, _ = env.reset(seed=args.first_seed + ep)
        c0 = p.capsule.copy()
        push_step, kept, won = -1, 0, False
        for t in range(args.steps):
            held = task.success(p)
            if not held and push_step < 0 and math.hypot(*(p.capsule[:2] - c0[:2])) > args.push:
                push_step = t
            if push_step >= 0 and not held and (t - push_step) % args.every == 0 and kept < args.per_episode:
                qpos.append(p.data.qpos.copy())
                qvel.append(p.data.qvel.copy())
                kept += 1
            obs, _, _, truncated, info = env.step(skill.torques(obs[None, :24], np.zeros((1, 0)), skill.features_of([p]))[0])
            won |= bool(info["success"])
            if truncated:
                break
        wins += won
        if push_step >= 0:
            pushed += 1
            gripped_after_push += won
        if (ep + 1) % 500 == 0:
            print(f"{ep + 1}/{args.episodes} episodes, {len(qpos)} states", flush=True)
    env.close()
    print(f"{args.skill}: success {wilson_interval(wins, args.episodes)} over {args.episodes} episodes; pushed more than "
          f"{args.push * 100:.0f} cm in {pushed} ({pushed / args.episodes:.1%}), gripped after the push in "
          f"{gripped_after_push} of them")  # fmt: skip
    if not qpos:
        sys.exit("gripper_recovery: no push in these episodes; nothing written")
    write_start_bank(args.out, {HANDOVER_BANK: (np.stack(qpos), np.stack(qvel))},
                     {"skill": args.skill, "skill_sha256": skill.content_hash, "source": "gripper_recovery",
                      "push": str(args.push), "episodes": str(args.episodes), "first_seed": str(args.first_seed)})  # fmt: skip
    print(f"wrote {len(qpos)} states to {args.out}")


if __name__ == "__main__":
    main()
