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
import sys
from pathlib import Path

from hrlp.arm.research.starts import record_recovery_starts, write_start_bank
from hrlp.arm.tasks import HANDOVER_BANK
from hrlp.evaluate import wilson_interval
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

    def progress(states: int, episodes: int) -> None:
        if episodes % 500 == 0:
            print(f"{episodes}/{args.episodes} episodes, {states} states", flush=True)

    rec = record_recovery_starts(skill, args.episodes, first_seed=args.first_seed, steps=args.steps, push=args.push,
                                 every=args.every, per_episode=args.per_episode, progress=progress)  # fmt: skip
    print(f"{args.skill}: success {wilson_interval(rec.wins, rec.episodes)} over {rec.episodes} episodes; pushed more "
          f"than {args.push * 100:.0f} cm in {rec.pushed} ({rec.pushed / rec.episodes:.1%}), gripped after the push in "
          f"{rec.gripped_after_push} of them")  # fmt: skip
    if not len(rec.qpos):
        sys.exit("gripper_recovery: no push in these episodes; nothing written")
    write_start_bank(args.out, {HANDOVER_BANK: (rec.qpos, rec.qvel)},
                     {"skill": args.skill, "skill_sha256": skill.content_hash, "source": "gripper_recovery",
                      "push": str(args.push), "episodes": str(args.episodes), "first_seed": str(args.first_seed)})  # fmt: skip
    print(f"wrote {len(rec.qpos)} states to {args.out}")


if __name__ == "__main__":
    main()
