"""Demonstration starts for the Gripper: physics states along the scripted grasp's successful episodes, as a start bank.

A Gripper trained with a share of its episodes starting from these states (``--task-arg starts=BANK --task-arg
starts_fraction=F``) starts some episodes part-way along a top-down approach the scripted grasp
(:class:`hrlp.arm.research.scripted.ScriptedGrasp`) took to a grip, or from the grip itself: demonstration states without
imitating the demonstrator's actions. The episodes start from the shipped Gripper's own start set (H 0-9 cm from C,
fingers opened 0-1 rad, the capsule anywhere on the start circle).

    python benchmarks/demonstration_starts.py --states 4000 --out runs/demo-starts.npz
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from hrlp.arm.research.scripted import ScriptedGraspConfig
from hrlp.arm.research.starts import record_grip_starts, write_start_bank
from hrlp.arm.tasks import HANDOVER_BANK


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=4000, help="states to keep")
    ap.add_argument("--every", type=int, default=5, help="keep every N-th state of a successful episode")
    ap.add_argument("--episode-steps", type=int, default=100)
    ap.add_argument("--num-envs", type=int, default=4)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, required=True, help="the .npz bank to write (must not exist)")
    a = ap.parse_args()
    if a.out.exists():
        raise SystemExit(f"{a.out} exists; choose another path")
    t0 = time.perf_counter()

    def progress(kept: int, episodes: int) -> None:
        if episodes % 20 == 0:
            print(f"{episodes} episodes, {kept:,} states kept, {time.perf_counter() - t0:.0f} s", flush=True)

    q, v = record_grip_starts(ScriptedGraspConfig(), math.pi, a.states, seed=a.seed, every=a.every,
                              episode_steps=a.episode_steps, num_envs=a.num_envs, progress=progress)  # fmt: skip
    write_start_bank(a.out, {HANDOVER_BANK: (q, v)}, {"source": "scripted grasp, successful episodes",
                                                      "every": str(a.every), "seed": str(a.seed)})  # fmt: skip
    print(f"wrote {len(q):,} states to {a.out} in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
