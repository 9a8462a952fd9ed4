"""Does the Gripper's reward hold it back? Retrain the shipped gripper under reward variants and measure it.

Each variant continues the shipped gripper's own training run (its recipe, warm-started from its weights, as a DAgger
round does: :func:`hrlp.skills.dagger.skill_config`), half the episodes from a hand-over start bank, with task
arguments changed: ``centre`` (the recipe as it is), ``axis`` (``distance="axis"``), ``axis+push``
(``distance="axis", push_coeff=10``). After the budget, greedy success (Definition 1) over ``--episodes`` episodes
from the bank and from the recipe's own start set, with Wilson 95% intervals. The figures in
``docs/results/gripper-variants.json`` came from ``--steps 1500000`` (axis also 3000000) with DAgger round 1's bank.

    python benchmarks/gripper_variants.py --bank runs/dagger/round1/starts.npz --variant axis --out runs/gripper-axis
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from rich.console import Console

from hrlp.checkpoint import checkpoint_exists
from hrlp.evaluate import evaluate_run
from hrlp.skills.dagger import DaggerConfig, _skill_dir, skill_config
from hrlp.skills.library import SkillLibrary
from hrlp.train import train_with_progress

VARIANTS = {"centre": {}, "axis": {"distance": "axis"}, "axis+push": {"distance": "axis", "push_coeff": 10.0}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bank", required=True, help="start bank of hand-over states (hrlp dagger's starts.npz)")
    ap.add_argument("--variant", choices=sorted(VARIANTS), default="axis")
    ap.add_argument("--steps", type=int, default=1_500_000)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    bank = args.bank if Path(args.bank).is_file() else ap.error(f"--bank {args.bank}: no such file")
    parent = _skill_dir("gripper", None)
    manifest = SkillLibrary(parent.parent).manifest("gripper")
    dc = DaggerConfig(manager_run="-", skill="gripper", name="gripper-variant", skill_steps=args.steps, workers=args.workers)
    cfg = skill_config(manifest, Path(bank).resolve(), dc, str(parent.resolve()))
    cfg = dataclasses.replace(cfg, task_kwargs={**cfg.task_kwargs, **VARIANTS[args.variant]})
    run = args.out / "skill"
    train_with_progress(cfg, run, checkpoint_exists(run / "checkpoint"), Console(stderr=True), f"gripper {args.variant}")
    results = {}
    for label, fraction in (("handover", 1.0), ("own", 0.0)):
        ev = evaluate_run(
            run, episodes=args.episodes, task_kwargs={"starts": str(Path(bank).resolve()), "starts_fraction": fraction}
        )
        assert ev.success is not None
        results[label] = [ev.success.mean, ev.success.low, ev.success.high]
        print(f"{args.variant}, {args.steps:,} steps, from {label} starts: success {ev.success.mean:.2f} "
              f"[{ev.success.low:.2f}, {ev.success.high:.2f}]")  # fmt: skip
    (args.out / "results.json").write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
