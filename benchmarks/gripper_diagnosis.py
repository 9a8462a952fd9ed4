"""Why a Gripper fails and what its reward pays for: a skill's greedy episodes on its own start set.

Prints, for the skill (default: the shipped ``gripper``; a skill that reads observation features, such as
``gripper-imitated``, is given them from the physics) on ``Gripper`` with the shipped recipe's start set:

- success (Definition 1) over ``--episodes`` episodes of ``--steps`` control steps, and the step of first success;
- where the capsule sits in the palm's frame while the claw is closed on it (finger gap < 3 cm, H within 8 cm of C),
  d(H, C) there against d(H, capsule axis) (``GripReward(distance="axis")``);
- the reward per step the paper's terms pay in gripped, lifted states (capsule centre above 3 cm) under
  ``distance="centre"`` and ``"axis"``;
- success by the start distance d(H, C), and by the start clearance: how close the arm's nearest geom (a finger, the
  palm, the forearm) comes to the capsule at the start (``ArmPhysics.arm_clearance``);
- the failed episodes by kind: capsule pushed more than 3 cm across the table, hand never within 5 cm, claw closed
  beside the capsule.

    python benchmarks/gripper_diagnosis.py --episodes 100

Episode ``i`` is seeded ``--first-seed + i`` (``benchmarks/gripper_handover.py`` starts its own starts at 10,000).
"""

from __future__ import annotations

import argparse

import numpy as np

from hrlp.arm.env import ArmEnv
from hrlp.arm.tasks import GripperTask, GripReward
from hrlp.experiments.presets import GRIPPER_START
from hrlp.skills import load_skill


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skill", default="gripper")
    ap.add_argument("--library", default=None)
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--first-seed", type=int, default=0, help="seed of the first episode (the next ones count up)")
    args = ap.parse_args()
    skill = load_skill(args.skill, args.library)
    env = ArmEnv(GripperTask(**GRIPPER_START), episode_steps=args.steps)
    p = env.physics
    m, d = p.model, p.data
    claw = m.body("claw").id
    centre, axis = GripReward(), GripReward(distance="axis")
    held_c, held_d, held_axis, lifted = [], [], [], []
    episodes = []
    for ep in range(args.episodes):
        obs, _ = env.reset(seed=args.first_seed + ep)
        c0, d0 = p.capsule.copy(), p.hand_to_capsule()
        clear0 = p.arm_clearance()
        first, min_d = -1, np.inf
        info: dict = {}
        for t in range(args.steps):
            features = skill.features_of([p])
            obs, _, _, trunc, info = env.step(skill.torques(obs[None, :24], np.zeros((1, 0)), features)[0])
            min_d = min(min_d, p.hand_to_capsule())
            if info["success"] and first < 0:
                first = t + 1
            if p.finger_gap() < 0.03 and p.hand_to_capsule() < 0.08:
                rot = d.xmat[claw].reshape(3, 3)
                held_c.append(rot.T @ (p.capsule - d.xpos[claw]))
                held_d.append(p.hand_to_capsule())
                held_axis.append(p.hand_to_capsule_axis())
                if p.capsule[2] > 0.03 and p.hand_to_capsule_axis() < 0.03:
                    lifted.append((sum(centre.terms(p).values()), sum(axis.terms(p).values())))
            if trunc:
                break
        pushed = float(np.hypot(*(p.capsule[:2] - c0[:2])))
        episodes.append((bool(info["success"]), first, pushed, min_d, d0, clear0))
    ok = np.array([e[0] for e in episodes])
    firsts = np.array([e[1] for e in episodes if e[0]])
    print(
        f"{args.skill}: success {ok.mean():.2f} over {len(ok)} episodes of {args.steps} steps"
        + (f"; first success at step {np.median(firsts):.0f} (median), {firsts.max()} (latest)" if len(firsts) else "")
    )
    if held_c:
        c = np.array(held_c)
        print(
            f"claw closed on the capsule: {len(c)} states; capsule centre in the palm frame (m), median "
            f"{np.round(np.median(c, 0), 3).tolist()}, 10-90% along the palm's z (the capsule's axis) "
            f"{np.percentile(c[:, 2], 10):.3f} to {np.percentile(c[:, 2], 90):.3f}"
        )
        print(
            f"  d(H, C) median {np.median(held_d) * 100:.1f} cm; d(H, capsule axis) median {np.median(held_axis) * 100:.1f} cm"
        )
    if lifted:
        r = np.array(lifted)
        print(
            f"gripped and lifted: {len(r)} states; the paper's reward per step {r[:, 0].mean():.2f} (distance to the "
            f"centre), {r[:, 1].mean():.2f} (distance to the axis)"
        )
    starts = np.array([e[4] for e in episodes])
    bins = [(lo, hi) for lo, hi in ((0.0, 0.03), (0.03, 0.06), (0.06, 0.3)) if ((starts >= lo) & (starts < hi)).any()]
    print("success by start distance d(H, C): " + ", ".join(
        f"{lo * 100:.0f}-{min(hi, 0.09) * 100:.0f} cm {ok[(starts >= lo) & (starts < hi)].mean():.2f} "
        f"({((starts >= lo) & (starts < hi)).sum()})" for lo, hi in bins))  # fmt: skip
    clear = np.array([e[5] for e in episodes])
    edges = (("under 3 mm", -1.0, 0.003), ("3-10 mm", 0.003, 0.01), ("10-20 mm", 0.01, 0.02), ("20 mm or more", 0.02, 1.0))
    print("success by start clearance (the arm's nearest point to the capsule): " + ", ".join(
        f"{name} {ok[(clear >= lo) & (clear < hi)].mean():.2f} ({((clear >= lo) & (clear < hi)).sum()})"
        for name, lo, hi in edges if ((clear >= lo) & (clear < hi)).any()))  # fmt: skip
    fails = [e for e in episodes if not e[0]]
    if fails:
        n = len(fails)
        pushed = sum(e[2] > 0.03 for e in fails)
        far = sum(e[3] >= 0.05 for e in fails)
        print(
            f"failed episodes: {n}; capsule pushed > 3 cm across the table in {pushed / n:.0%}, hand never within 5 cm "
            f"of C in {far / n:.0%}"
        )


if __name__ == "__main__":
    main()
