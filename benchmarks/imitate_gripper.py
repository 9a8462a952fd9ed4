"""A Gripper imitated from the scripted grasp (behaviour cloning + DAgger), then optionally fine-tuned with TRPO.

Imitates :class:`hrlp.skills.scripted.ScriptedGrasp` into the shipped Gripper recipe's run (its network, normaliser,
task arguments and seed: the ``gripper`` run of the ``shipped-skills`` preset) with :func:`hrlp.skills.imitate.imitate`,
evaluates the student greedily from the hand-over bank, the recipe's own starts and the paper's default starts
(``benchmarks/gripper_variants.py``'s start sets), and with ``--fine-tune-steps N`` continues the run with TRPO for N
environment steps and evaluates it again.

    python benchmarks/imitate_gripper.py --bank runs/dagger/round1/starts.npz --out runs/gripper-imitated
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from gripper_variants import evaluate_gripper
from hrlp.experiments.presets import PRESETS
from hrlp.skills.imitate import ImitationConfig, imitate
from hrlp.train import train


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bank", type=Path, required=True, help="start bank of hand-over states (hrlp dagger's starts.npz)")
    ap.add_argument("--out", type=Path, required=True, help="the run directory to write (must not hold a run)")
    ap.add_argument("--expert-episodes", type=int, default=ImitationConfig.expert_episodes)
    ap.add_argument("--dagger-rounds", type=int, default=ImitationConfig.dagger_rounds)
    ap.add_argument("--dagger-episodes", type=int, default=ImitationConfig.dagger_episodes)
    ap.add_argument("--epochs", type=int, default=ImitationConfig.epochs)
    ap.add_argument("--episodes", type=int, default=200, help="greedy evaluation episodes per start set")
    ap.add_argument("--fine-tune-steps", type=int, default=0, help="TRPO environment steps after imitation (0: none)")
    a = ap.parse_args()
    recipe = next(r.config for r in PRESETS["shipped-skills"].runs if r.name == "gripper")
    cfg = ImitationConfig(a.expert_episodes, a.dagger_rounds, a.dagger_episodes, a.epochs)
    summary = imitate(recipe, a.out, cfg, log=lambda line: print(line, flush=True))
    summary["evaluation"] = {"imitated": evaluate_gripper(a.out, a.bank, a.episodes, "imitated")}
    if a.fine_tune_steps:
        for row in train(dataclasses.replace(recipe, steps=a.fine_tune_steps), a.out, resume=True):
            print(f"fine-tune iteration {row['iteration']}: {int(row['env_steps']):,} steps, training success "
                  f"{row['success_rate']:.2f}", flush=True)  # fmt: skip
        label = f"imitated + {a.fine_tune_steps:,} TRPO steps"
        summary["evaluation"][label] = evaluate_gripper(a.out, a.bank, a.episodes, label)
    (a.out / "imitation.json").write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
