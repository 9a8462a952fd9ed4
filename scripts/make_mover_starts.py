"""Record the Mover's start states from a Gripper skill (``src/hrlp/arm/assets/mover_starts.npz``).

    python scripts/make_mover_starts.py [--states 2000] [--seed 0] [--out src/hrlp/arm/assets/mover_starts.npz]
    python scripts/make_mover_starts.py --held      # the "held" starts, src/hrlp/arm/assets/mover_held_starts.npz

plain: the capsule within 0.2 rad of straight ahead; noised: anywhere on the circle (hrlp.arm.research.starts). The grip
starts follow the shipped ``gripper``'s successful episodes from start to end; the held starts (``--held``) keep the
states of ``gripper-imitated``'s episodes in which the capsule is in the claw.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from hrlp.arm.research.starts import record_grip_starts, write_start_bank
from hrlp.arm.tasks import MOVER_HELD_STARTS_FILE, MOVER_STARTS_FILE
from hrlp.skills.library import load_skill

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=2000, help="states per variant")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--held", action="store_true", help="only states with the capsule held, from gripper-imitated")
    ap.add_argument("--out", type=Path, default=None, help="default: the package's asset for the chosen start set")
    args = ap.parse_args()
    out = args.out or Path("src/hrlp/envs") / (MOVER_HELD_STARTS_FILE if args.held else MOVER_STARTS_FILE)
    skill = "gripper-imitated" if args.held else "gripper"
    gripper = load_skill(skill)
    banks = {}
    for name, angle_range, seed in (("plain", 0.2, args.seed), ("noised", math.pi, args.seed + 1000)):
        banks[name] = record_grip_starts(gripper, angle_range, args.states, seed=seed, held=args.held)
        print(f"{name}: {len(banks[name][0])} states", flush=True)
    held = " --held" if args.held else ""
    command = f"python scripts/make_mover_starts.py --states {args.states} --seed {args.seed}{held}"
    meta = {"skill": skill, "skill_sha256": gripper.content_hash, "states": str(args.states), "seed": str(args.seed),
            "held": str(args.held), "command": command}  # fmt: skip
    print("wrote", write_start_bank(out, banks, meta))
