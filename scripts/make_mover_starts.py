"""Record the Mover's start states from a Gripper skill (the start banks ``grip`` and ``held``, hrlp.arm.banks).

    python scripts/make_mover_starts.py [--out src/hrlp/arm/assets/mover_starts.npz]
    python scripts/make_mover_starts.py --held      # the "held" starts, src/hrlp/arm/assets/mover_held_starts.npz

plain: the capsule within 0.2 rad of straight ahead; noised: anywhere on the circle (hrlp.arm.research.starts). The grip
starts follow ``gripper``'s successful episodes from start to end; the held starts (``--held``) keep the states of
``gripper-imitated``'s episodes in which the capsule is in the claw. The skill is looked up as hrlp looks skills up
(``--library``, ``$HRLP_SKILLS``, the shipped ones). ``hrlp skills build`` records these banks itself, into the
library, when it rebuilds the Gripper they come from. An existing ``--out`` is never replaced.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hrlp.arm.banks import BANKS
from hrlp.skills.library import load_skill

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--held", action="store_true", help="only states with the capsule held, from gripper-imitated")
    ap.add_argument("--library", default=None, help="the skill library to take the Gripper from first")
    ap.add_argument("--scale", type=float, default=1.0, help="share of the recipe's 2,000 states per variant")
    ap.add_argument("--out", type=Path, default=None, help="default: the package's asset for the chosen start set")
    args = ap.parse_args()
    recipe = BANKS["held" if args.held else "grip"]
    out = args.out or Path("src/hrlp/arm") / recipe.asset
    if out.exists():
        sys.exit(f"make_mover_starts: {out} exists; move it away or give another --out")
    if not 0 < args.scale <= 1:
        sys.exit("make_mover_starts: --scale must be in (0, 1]")
    skill = load_skill(recipe.source, args.library)
    print("wrote", recipe.write(skill, out, args.scale, print))  # type: ignore[arg-type]
