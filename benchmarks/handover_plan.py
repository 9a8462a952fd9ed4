"""What each part of the hand-over interface does: a scripted reach-then-grip plan with the shipped skills.

On reach-and-grip Experiment 1, every episode runs "reach 4 cm above the capsule for ``--reach-calls`` macro-actions of
``--k`` steps, then grip" and counts Definition 1 successes and episodes in which the Reacher pushed the capsule more
than 1 cm. Rows: the paper's interface (absolute goals, the skill as trained) and :class:`hrlp.skills.macro_env.Handover`
with each of its parts alone and all together.

    python benchmarks/handover_plan.py --episodes 48 --reacher reacher
    python benchmarks/handover_plan.py --reacher reacher-handover --library runs/lib   # a skill of your library
"""

from __future__ import annotations

import argparse

import numpy as np

from hrlp.arm import make
from hrlp.arm.handover import arm_macro_env
from hrlp.config import Handover
from hrlp.skills import load_skill
from hrlp.skills.macro_env import step_macros

C = slice(21, 24)


def scripted(reacher: str, handover: Handover | None, episodes: int, k: int, reach_calls: int,
             library: str | None = None) -> tuple[float, float]:  # fmt: skip
    """(success rate, share of episodes whose capsule moved > 1 cm while reaching)."""
    skills = [load_skill("gripper", library), load_skill(reacher, library)]
    envs = [arm_macro_env(make("ReachAndGrip1"), skills, k=k, handover=handover) for _ in range(episodes)]
    for i, e in enumerate(envs):
        e.reset(seed=i)
    start = np.stack([e._obs[C] for e in envs])
    success, done, pushed = np.zeros(episodes, bool), np.zeros(episodes, bool), np.zeros(episodes, bool)
    for t in range(1000):
        rows = [np.concatenate([[1 if t < reach_calls else 0], e.block(1, e._obs[C] + (0, 0, 0.04))]) for e in envs]
        res = step_macros(envs, np.clip(np.array(rows), -1, 1))
        if t == reach_calls - 1:
            pushed = np.linalg.norm(res.obs[:, C] - start, axis=1) > 0.01
        success |= ~done & np.array([bool(i.get("success")) for i in res.infos])
        done |= res.terminated | res.truncated
        if done.all():
            break
    return float(success.mean()), float(pushed.mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=48)
    ap.add_argument("--reacher", default="reacher")
    ap.add_argument("--k", type=int, default=10)
    ap.add_argument("--reach-calls", type=int, default=8)
    ap.add_argument("--library", help="a skill library to look in first (default: yours, then the shipped skills)")
    a = ap.parse_args()
    rows = [
        ("the paper's (absolute goals, as trained)", None),
        ("capsule-relative goals only", Handover(approach_height=0.0, open_torque=0.0)),
        ("claw held open only", Handover(relative=False, approach_height=0.0)),
        ("approach from above only", Handover(relative=False, open_torque=0.0)),
        ("all three (Handover())", Handover()),
    ]
    print(f"| interface ({a.reacher}) | success | capsule pushed > 1 cm while reaching |\n|---|---:|---:|")
    for name, h in rows:
        s, m = scripted(a.reacher, h, a.episodes, a.k, a.reach_calls, a.library)
        print(f"| {name} | {s:.2f} | {m:.2f} |", flush=True)


if __name__ == "__main__":
    main()
