"""Record the Mover's "grip" start states from the shipped Gripper skill (``src/hrlp/envs/assets/mover_starts.npz``).

    python scripts/make_mover_starts.py [--states 2000] [--seed 0] [--out src/hrlp/envs/assets/mover_starts.npz]

plain: the capsule within 0.2 rad of straight ahead; noised: anywhere on the circle (hrlp.skills.starts).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from hrlp.skills.library import load_skill
from hrlp.skills.starts import record_grip_starts, write_start_bank

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=2000, help="states per variant")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("src/hrlp/envs/assets/mover_starts.npz"))
    args = ap.parse_args()
    gripper = load_skill("gripper")
    banks = {}
    for name, angle_range, seed in (("plain", 0.2, args.seed), ("noised", math.pi, args.seed + 1000)):
        banks[name] = record_grip_starts(gripper, angle_range, args.states, seed=seed)
        print(f"{name}: {len(banks[name][0])} states")
    meta = {"skill": "gripper", "skill_sha256": gripper.content_hash, "states": str(args.states), "seed": str(args.seed),
            "command": f"python scripts/make_mover_starts.py --states {args.states} --seed {args.seed}"}  # fmt: skip
    print("wrote", write_start_bank(args.out, banks, meta))
