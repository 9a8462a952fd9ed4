"""A Gripper imitated from the scripted grasp (behaviour cloning + DAgger), then optionally fine-tuned with TRPO.

Imitates :class:`hrlp.arm.research.scripted.ScriptedGrasp` into the shipped Gripper recipe's run (its network, normaliser,
task arguments and seed: the ``gripper`` run of the ``shipped-skills`` preset) with :func:`hrlp.arm.research.imitate.imitate`,
evaluates the student greedily from the hand-over bank, the recipe's own starts and the paper's default starts
(``benchmarks/gripper_variants.py``'s start sets), and with ``--fine-tune-steps N`` continues the run with TRPO for N
environment steps and evaluates it again. ``--hidden``, ``--init-log-std``, ``--backend`` and ``--task-arg KEY=VALUE``
(a JSON value) change the recipe's run for both stages.

    python benchmarks/imitate_gripper.py --bank runs/dagger/round1/starts.npz --out runs/gripper-imitated
    python benchmarks/imitate_gripper.py --bank runs/dagger/round1/starts.npz --out runs/gripper-imitated2 \
        --task-arg observe_capsule=true --hidden 256,256 --expert-episodes 150 --noisy-expert-episodes 250 \
        --expert-noise 0.3 --beta 0.5 --dagger-rounds 2 --dagger-episodes 200 --epochs 30 --minibatch 512 --eval-episodes 100 \
        --init-log-std -2 --backend batched --fine-tune-steps 8000000
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from gripper_variants import evaluate_gripper
from hrlp.arm.research.imitate import ImitationConfig, imitate
from hrlp.cli import parse_task_args
from hrlp.experiments.presets import PRESETS
from hrlp.train import train


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--bank",
        type=Path,
        help="start bank of hand-over states (hrlp dagger's starts.npz); without it, "
        "evaluation from the recipe's own and the paper's starts only",
    )
    ap.add_argument("--out", type=Path, required=True, help="the run directory to write (must not hold a run)")
    ap.add_argument("--expert-episodes", type=int, default=ImitationConfig.expert_episodes)
    ap.add_argument("--dagger-rounds", type=int, default=ImitationConfig.dagger_rounds)
    ap.add_argument("--dagger-episodes", type=int, default=ImitationConfig.dagger_episodes)
    ap.add_argument("--epochs", type=int, default=ImitationConfig.epochs)
    ap.add_argument("--minibatch", type=int, default=ImitationConfig.minibatch)
    ap.add_argument("--noisy-expert-episodes", type=int, default=ImitationConfig.noisy_expert_episodes,
                    help="round-0 episodes with DART noise")  # fmt: skip
    ap.add_argument("--expert-noise", type=float, default=ImitationConfig.expert_noise, help="DART noise std")
    ap.add_argument("--beta", type=float, default=ImitationConfig.beta, help="expert's share in DAgger round r: beta**r")
    ap.add_argument("--eval-episodes", type=int, default=ImitationConfig.eval_episodes, help="keep the best round")
    ap.add_argument("--hidden", type=lambda s: tuple(int(w) for w in s.split(",")), default=None, help="e.g. 256,256")
    ap.add_argument("--init-log-std", type=float, default=None)
    ap.add_argument("--backend", choices=("auto", "batched", "serial"), default=None)
    ap.add_argument("--task-arg", action="append", default=[], metavar="KEY=VALUE", help="as hrlp train reads it")
    ap.add_argument("--episodes", type=int, default=200, help="greedy evaluation episodes per start set")
    ap.add_argument("--fine-tune-steps", type=int, default=0, help="TRPO environment steps after imitation (0: none)")
    a = ap.parse_args()
    recipe = next(r.config for r in PRESETS["shipped-skills"].runs if r.name == "gripper")
    options = (("hidden", a.hidden), ("init_log_std", a.init_log_std), ("backend", a.backend))
    changes = {k: v for k, v in options if v is not None}
    try:
        given = parse_task_args(a.task_arg)  # hrlp train's own reading of --task-arg (JSON values, else strings)
    except ValueError as e:
        ap.error(str(e))
    recipe = dataclasses.replace(recipe, task_kwargs={**recipe.task_kwargs, **given}, **changes)
    cfg = ImitationConfig(a.expert_episodes, a.dagger_rounds, a.dagger_episodes, a.epochs, a.minibatch,
                          noisy_expert_episodes=a.noisy_expert_episodes, expert_noise=a.expert_noise, beta=a.beta,
                          eval_episodes=a.eval_episodes)  # fmt: skip
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
