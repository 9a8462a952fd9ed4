"""A Gripper skill from the states where a trained Manager hands over to it, beside its own and the paper's starts.

Collects ``--states`` hand-over states of the Manager run ``MANAGER`` to its Gripper (``--gripper``, default the Manager's
one skill named ``gripper*``; the Manager samples
its actions, as in training: :func:`hrlp.arm.research.dagger.collect_handover_states`) into four start banks under ``--out``:

- ``all``: every hand-over;
- ``not_held``: those where the capsule is not yet held (Definition 1 false; a Manager often calls the Gripper again
  while it holds the capsule, and those episodes start as successes);
- ``initiation_not_held``: those also inside the Gripper's initiation set (``ArmSkill.initiation``: the hand within the
  training starts' 9 cm of the capsule, the capsule resting), the states a Manager with ``Handover(initiation=True)``
  may hand over from;
- ``switch_not_held``: those of ``not_held`` at which control passes to the Gripper (the episode's first decision or one
  after another macro-action ran): the others continue a Gripper the Manager chose before, from wherever its own steps
  took the arm, often after it has pushed the capsule away.

Then evaluates each skill of ``--skills`` (default: the Gripper the Manager used) greedily, ``--episodes`` episodes of
``--steps`` control steps (the Gripper recipes' 100) from each bank, from the Gripper's own start set
(``GRIPPER_START``) and from the paper's default starts (H 5-9 cm away, claw at rest); environment seeds 10,000 +
index. Prints success with 95% Wilson intervals and writes ``results.json``; an existing ``results.json`` is never
replaced.

    python benchmarks/gripper_handover.py runs/reproduce/reach-and-grip-2-imitated/RUN/s0 --states 300 --episodes 300
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from hrlp.arm.env import ArmEnv
from hrlp.arm.physics import ArmPhysics
from hrlp.arm.research.dagger import collect_handover_states
from hrlp.arm.research.starts import write_start_bank
from hrlp.arm.skill import ArmSkill
from hrlp.arm.tasks import HANDOVER_BANK, GripperTask, SparseSuccess
from hrlp.evaluate import Interval, wilson_interval
from hrlp.experiments.presets import GRIPPER_START
from hrlp.skills import load_skill
from hrlp.train import TrainConfig

PAPER_STARTS = {"start_distance": [0.05, 0.09], "finger_opening": [0.0, 0.0]}


def success(skill: ArmSkill, task_kwargs: dict[str, Any], episodes: int, steps: int) -> Interval:
    """Greedy success (Definition 1 at any step) of ``skill`` on ``GripperTask(**task_kwargs)``."""
    env = ArmEnv(GripperTask(**task_kwargs), episode_steps=steps)
    p, wins = env.physics, 0
    for ep in range(episodes):
        obs, _ = env.reset(seed=10_000 + ep)
        won = False
        for _ in range(steps):
            features = skill.features_of([p])
            obs, _, _, truncated, info = env.step(skill.torques(obs[None, :24], np.zeros((1, 0)), features)[0])
            won |= bool(info["success"])
            if truncated:
                break
        wins += won
    env.close()
    return wilson_interval(wins, episodes)


def banks(manager: Path, gripper: ArmSkill, states: int, out: Path) -> dict[str, Path]:
    """Collect the four hand-over banks (module docstring) into ``out``; returns their paths."""
    held = SparseSuccess()

    def in_set(p: ArmPhysics) -> bool:
        obs = np.zeros((1, 24))
        obs[0, 18:21], obs[0, 21:24] = p.hand, p.capsule
        return bool(gripper.initiation.holds(obs)[0])

    filters = {
        "all": (None, False),
        "not_held": (lambda p: not held(p), False),
        "initiation_not_held": (lambda p: in_set(p) and not held(p), False),
        "switch_not_held": (lambda p: not held(p), True),
    }
    paths = {}
    for name, (keep, switches_only) in filters.items():
        qpos, qvel, episodes, refused = collect_handover_states(
            manager, gripper.name, states, seed=1, keep=keep, switches_only=switches_only
        )
        paths[name] = write_start_bank(out / f"{name}.npz", {HANDOVER_BANK: (qpos, qvel)},
                                       {"manager_run": str(manager), "filter": name})  # fmt: skip
        print(f"bank {name}: {len(qpos)} hand-over states from {episodes} Manager episodes ({refused} refused)", flush=True)
    return paths


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("manager", type=Path, help="a trained Manager's run directory")
    ap.add_argument("--gripper", default=None, help="the Manager's Gripper skill (default: its one skill named gripper*)")
    ap.add_argument("--skills", default=None, help="comma-separated Gripper skills to evaluate (default: --gripper)")
    ap.add_argument("--library", default=None, help="where the skills of --skills are looked up first")
    ap.add_argument("--states", type=int, default=300)
    ap.add_argument("--episodes", type=int, default=300)
    ap.add_argument("--steps", type=int, default=100, help="control steps per episode (the Gripper recipes' 100)")
    ap.add_argument("--out", type=Path, default=Path("runs/gripper-handover"))
    args = ap.parse_args()
    if not (args.manager / "checkpoint").exists():
        ap.error(f"{args.manager}: no Manager run there (no checkpoint)")
    if (args.out / "results.json").exists():
        ap.error(f"{args.out / 'results.json'} exists; choose another --out")
    if args.gripper is None:
        config = TrainConfig.from_json(json.loads((args.manager / "config.json").read_text()))
        grippers = [s for s in (config.macro.skills if config.macro else ()) if s.startswith("gripper")]
        if len(grippers) != 1:
            ap.error(f"{args.manager}: the Manager's Gripper is not one skill named gripper* ({grippers}); give --gripper")
        args.gripper = grippers[0]
    args.out.mkdir(parents=True, exist_ok=True)
    skills = [load_skill(name, args.library) for name in (args.skills or args.gripper).split(",")]
    sets = {"own": dict(GRIPPER_START), "paper": PAPER_STARTS}
    for name, path in banks(args.manager, load_skill(args.gripper, args.library), args.states, args.out).items():
        sets[name] = {**GRIPPER_START, "starts": str(path.resolve()), "starts_fraction": 1.0}
    results: dict[str, Any] = {"manager": str(args.manager), "episodes": args.episodes}
    for skill in skills:
        for where, kwargs in sets.items():
            iv = success(skill, kwargs, args.episodes, args.steps)
            results.setdefault(skill.name, {})[where] = [iv.mean, iv.low, iv.high]
            print(f"{skill.name}, from {where} starts: success {iv.mean:.2f} [{iv.low:.2f}, {iv.high:.2f}]", flush=True)
    (args.out / "results.json").write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
