"""gripper-claw's recipe with the scripted grasp's escape from tight starts in its expert.

Builds the ``gripper-claw`` run of the ``shipped-skills`` preset (its network, task arguments, TRPO settings and budget;
imitation with ``CLAW_GRIPPER``) with one change, ``ImitationConfig.expert_escape_clearance`` (default 0.01 m: the
expert's ``ScriptedGraspConfig.escape_clearance``), through the preset runner: the imitation as the run's iteration 0,
then TRPO, then the run's greedy evaluation, written to ``--out/claw-escape/gripper-claw-escape/s0`` (``result.json``;
an interrupted build resumes). Freeze it with ``hrlp skills add RUN --name gripper-claw-escape --library LIB`` and
evaluate it with ``benchmarks/gripper_diagnosis.py`` and ``benchmarks/gripper_handover.py``.

With ``--observe-clearance`` the student (and so the skill) also sees each arm body's distance to the capsule
(``GripperTask.observe_clearance``, 5 numbers: what the expert's escape decides on), and the run is named
``gripper-claw-clearance``. The shipped ``gripper-clearance`` is that run with five times the imitation's data
(``--expert-episodes 1000 --noisy-expert-episodes 1000 --dagger-episodes 400``; its recipe in ``shipped-skills``).

    python benchmarks/claw_escape.py --out runs/claw-escape
    python benchmarks/claw_escape.py --out runs/claw-escape --observe-clearance
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from hrlp.experiments.presets import PRESETS
from hrlp.experiments.runner import plan, run_job


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("runs/claw-escape"))
    ap.add_argument("--escape-clearance", type=float, default=0.01, help="the expert's escape clearance, metres")
    ap.add_argument("--observe-clearance", action="store_true", help="the skill also sees the arm's distances to the capsule")
    ap.add_argument("--steps", type=int, default=None, help="TRPO environment steps (default: the recipe's)")
    ap.add_argument("--expert-episodes", type=int, default=None, help="(default: the recipe's; smaller for a quick check)")
    ap.add_argument("--noisy-expert-episodes", type=int, default=None)
    ap.add_argument("--dagger-rounds", type=int, default=None)
    ap.add_argument("--dagger-episodes", type=int, default=None, help="episodes per DAgger round (default: the recipe's)")
    ap.add_argument("--eval-episodes", type=int, default=None, help="imitation rounds' evaluation episodes")
    args = ap.parse_args()
    shipped = PRESETS["shipped-skills"]
    run = next(r for r in shipped.runs if r.name == "gripper-claw")
    assert run.imitation is not None
    changes = {k: v for k, v in {"expert_episodes": args.expert_episodes, "noisy_expert_episodes": args.noisy_expert_episodes,
                                 "dagger_rounds": args.dagger_rounds, "dagger_episodes": args.dagger_episodes,
                                 "eval_episodes": args.eval_episodes}.items()
               if v is not None}  # fmt: skip
    try:
        imitation = dataclasses.replace(run.imitation, expert_escape_clearance=args.escape_clearance, **changes)
    except ValueError as e:
        ap.error(str(e))
    name = "gripper-claw-clearance" if args.observe_clearance else "gripper-claw-escape"
    config = run.config
    if args.observe_clearance:
        config = dataclasses.replace(config, task_kwargs={**config.task_kwargs, "observe_clearance": True})
    run = dataclasses.replace(run, name=name, skill=(name, 15), imitation=imitation, config=config,
                              steps=args.steps or run.steps)  # fmt: skip
    preset = dataclasses.replace(shipped, name="claw-escape", runs=(run,))
    (job,) = plan(preset, args.out, seeds=(0,))
    result = run_job(job, reuse=False)
    s = result["success"]
    print(f"{name}: {result['env_steps']:,} TRPO steps, greedy success {s['mean']:.2f} [{s['low']:.2f}, "
          f"{s['high']:.2f}] over {result['episodes']} episodes; run in {job.run_dir}")  # fmt: skip


if __name__ == "__main__":
    main()
