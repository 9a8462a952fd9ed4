"""Does the Gripper's reward hold it back? Retrain the shipped gripper under reward variants and measure it.

Each variant continues the shipped gripper's own training run (its recipe, warm-started from its weights, as a DAgger
round does: :func:`hrlp.arm.research.dagger.skill_config`), half the episodes from a hand-over start bank, with task
arguments changed: ``centre`` (the recipe as it is), ``axis`` (``distance="axis"``), ``axis+push``
(``distance="axis", push_coeff=10``). After the budget, greedy success (Definition 1) over ``--episodes`` episodes
from the bank and from the recipe's own start set, with Wilson 95% intervals. The figures in
``docs/results/gripper-variants.json`` came from ``--steps 1500000`` (axis also 3000000) with DAgger round 1's bank.

    python benchmarks/gripper_variants.py --bank runs/dagger/round1/starts.npz --variant axis --out runs/gripper-axis

Each run is also evaluated from the paper's default starts (H 5-9 cm from C, the claw at rest). ``--evaluate RUN``
evaluates a finished Gripper run of any recipe instead of training one (the from-scratch Grippers of
``gripper-variants.json``'s ``from_scratch``, trained with ``hrlp train Gripper ...``: docs/research/results-notes.md).
``--graspable D V`` adds the bank's states from which a grip can start (d(H, C) <= D metres, the capsule slower than
V m/s: :func:`hrlp.arm.research.dagger.graspable`), written to ``OUT/graspable.npz``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np
from rich.console import Console

from hrlp.arm.research.dagger import DaggerConfig, skill_config
from hrlp.checkpoint import checkpoint_exists
from hrlp.evaluate import evaluate_run
from hrlp.skills.library import locate_skill, search_roots
from hrlp.train import train_with_progress

VARIANTS = {"centre": {}, "axis": {"distance": "axis"}, "axis+push": {"distance": "axis", "push_coeff": 10.0}}


START_SETS = (
    ("handover", {"starts_fraction": 1.0}),
    ("own", {"starts_fraction": 0.0}),
    ("paper_default", {"starts": None, "start_distance": [0.05, 0.09], "finger_opening": [0, 0]}),
)
"""Where evaluation episodes start: the bank's hand-over states, the run's own start set, the paper's default starts."""


def graspable_bank(bank: Path, out: Path, max_hand_distance: float, max_capsule_speed: float) -> Path:
    """Write the states of ``bank`` from which a grip can start (:func:`hrlp.arm.research.dagger.graspable`) to ``out``."""
    from hrlp.arm import make
    from hrlp.arm.research.dagger import graspable
    from hrlp.arm.research.starts import write_start_bank
    from hrlp.arm.tasks import HANDOVER_BANK, start_bank

    qpos, qvel = start_bank(str(bank))
    env = make("Gripper")
    env.reset(seed=0)
    physics = env.unwrapped.physics
    keep = []
    for q, v in zip(qpos, qvel, strict=True):
        physics.set_state_vectors(q, v)
        physics.forward()
        keep.append(graspable(physics, max_hand_distance, max_capsule_speed))
    env.close()
    mask = np.array(keep)
    if not mask.any():
        raise SystemExit(f"--graspable: none of the {len(mask)} states of {bank} is within the limits")
    print(f"{bank}: {mask.sum()} of {len(mask)} states with d(H, C) <= {max_hand_distance} m and the capsule slower than "
          f"{max_capsule_speed} m/s", flush=True)  # fmt: skip
    meta = {"source": str(bank), "max_hand_distance": str(max_hand_distance), "max_capsule_speed": str(max_capsule_speed)}
    return write_start_bank(out, {HANDOVER_BANK: (qpos[mask], qvel[mask])}, meta)


def evaluate_gripper(
    run: Path, bank: Path | None, episodes: int, label: str, graspable: Path | None = None
) -> dict[str, list[float]]:
    """Greedy success of the Gripper run ``run`` from each of :data:`START_SETS` (without a ``bank``, the two that need
    none; given a ``graspable`` bank, also from its states as ``graspable_handover``): ``[mean, Wilson low, high]``."""
    results = {}
    sets = [*START_SETS, *([("graspable_handover", {"starts": str(graspable.resolve()), "starts_fraction": 1.0})]
                           if graspable is not None else [])]  # fmt: skip
    if bank is None:
        sets = [(where, kwargs) for where, kwargs in sets if where != "handover"]
    for where, kwargs in sets:
        bank_kwargs = {} if bank is None else {"starts": str(bank.resolve())}
        ev = evaluate_run(run, episodes=episodes, task_kwargs={**bank_kwargs, **kwargs})
        assert ev.success is not None
        results[where] = [ev.success.mean, ev.success.low, ev.success.high]
        print(f"{label}, from {where} starts: success {ev.success.mean:.2f} [{ev.success.low:.2f}, {ev.success.high:.2f}]",
              flush=True)  # fmt: skip
    return results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bank", required=True, help="start bank of hand-over states (hrlp dagger's starts.npz)")
    ap.add_argument("--variant", choices=sorted(VARIANTS), default="axis")
    ap.add_argument("--steps", type=int, default=1_500_000)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--evaluate", type=Path, help="a finished Gripper run to evaluate (nothing is trained)")
    ap.add_argument(
        "--graspable",
        type=float,
        nargs=2,
        metavar=("D", "V"),
        help="also evaluate from the bank's states with d(H, C) <= D m and the capsule slower than V m/s",
    )
    args = ap.parse_args()
    bank = Path(args.bank) if Path(args.bank).is_file() else ap.error(f"--bank {args.bank}: no such file")
    if (args.out / "results.json").exists():
        ap.error(f"{args.out / 'results.json'} exists; choose another --out")
    args.out.mkdir(parents=True, exist_ok=True)
    graspable = None if args.graspable is None else graspable_bank(bank, args.out / "graspable.npz", *args.graspable)
    if args.evaluate is not None:
        if not checkpoint_exists(args.evaluate / "checkpoint"):
            ap.error(f"--evaluate {args.evaluate}: no checkpoint there")
        results = evaluate_gripper(args.evaluate, bank, args.episodes, str(args.evaluate), graspable)
        (args.out / "results.json").write_text(json.dumps(results, indent=2))
        return
    library = locate_skill("gripper", search_roots())
    parent, manifest = library.root / "gripper", library.manifest("gripper")
    dc = DaggerConfig(manager_run="-", skill="gripper", name="gripper-variant", skill_steps=args.steps, workers=args.workers)
    cfg = skill_config(manifest, bank.resolve(), dc, str(parent.resolve()))
    cfg = dataclasses.replace(cfg, task_kwargs={**cfg.task_kwargs, **VARIANTS[args.variant]})
    run = args.out / "skill"
    train_with_progress(cfg, run, checkpoint_exists(run / "checkpoint"), Console(stderr=True), f"gripper {args.variant}")
    results = evaluate_gripper(run, bank, args.episodes, f"{args.variant}, {args.steps:,} steps", graspable)
    (args.out / "results.json").write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
