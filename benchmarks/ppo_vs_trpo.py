"""PPO against TRPO through the same update seam: a flat task and a Manager task, several seeds.

Each (task, optimiser, seed) trains one run with hrlp's own trainer (``TrainConfig.algo``); everything but the policy
step is shared (sampler, GAE, the L-BFGS baseline, the normaliser). Each final policy is then evaluated greedily on the
same episodes (``hrlp.evaluate.evaluate_run``, environment seeds 10,000 + episode index). Printed per cell: the mean
over seeds of the greedy return (flat) or success (Manager), each seed's figure, environment steps and wall seconds.

- flat: Pendulum-v1, 16 environments, 4,000 decisions per iteration (TRPO at max KL 0.01, PPO at its defaults);
- Manager: reach-and-grip Experiment 1 over the shipped gripper + reacher with the hand-over interface, k = 10: the
  demo's Manager (``hrlp.experiments.demo.demo_config``), 2 sampling workers.

    python benchmarks/ppo_vs_trpo.py --seeds 3 --flat-steps 200000 --manager-steps 500000 --out runs/ppo-vs-trpo
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import time
from pathlib import Path

from hrlp.config import PAPER_SETTINGS, PPOConfig, TrainConfig, with_settings
from hrlp.evaluate import evaluate_run
from hrlp.experiments.demo import demo_config
from hrlp.train import train


def flat_config(algo: str, steps: int, seed: int, batch: int = 4_000) -> TrainConfig:
    """Pendulum-v1 with ``batch``-decision batches, policy step ``algo``, the paper's settings otherwise (16
    environments, one process: those its figures were measured with)."""
    cfg = TrainConfig(task="Pendulum-v1", steps=steps, batch_steps=batch, seed=seed, algo=algo, ppo=PPOConfig())
    return with_settings(cfg, PAPER_SETTINGS)


def manager_config(algo: str, steps: int, seed: int, batch: int = 2_000, workers: int = 2) -> TrainConfig:
    """The demo's Manager (ReachAndGrip1, gripper + reacher, hand-over, k = 10, ``batch`` decisions per batch)."""
    return dataclasses.replace(demo_config(steps=steps, seed=seed, workers=workers), algo=algo, batch_steps=batch)


def run_cell(kind: str, algo: str, steps: int, seeds: int, out: Path, episodes: int, batch: int, workers: int) -> dict:
    """Train and evaluate one (task, optimiser) cell over ``seeds`` seeds; returns its figures."""
    scores, walls = [], []
    for seed in range(seeds):
        cfg = flat_config(algo, steps, seed, batch) if kind == "flat" else manager_config(algo, steps, seed, batch, workers)
        run_dir = out / f"{kind}-{algo}-s{seed}"
        t = time.perf_counter()
        rows = list(train(cfg, run_dir, resume=(run_dir / "checkpoint").exists()))
        walls.append(time.perf_counter() - t)
        ev = evaluate_run(run_dir, episodes=episodes)
        score = ev.ret.mean if kind == "flat" else ev.success.mean  # type: ignore[union-attr]
        scores.append(score)
        last = rows[-1] if rows else {}
        print(f"{kind} {algo} seed {seed}: {'return' if kind == 'flat' else 'success'} {score:.3f}, "
              f"{int(last.get('env_steps', steps)):,} steps, {walls[-1]:.0f} s", flush=True)  # fmt: skip
    return {"kind": kind, "algo": algo, "steps": steps, "scores": scores, "mean": statistics.fmean(scores),
            "wall_s": walls}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--flat-steps", type=int, default=200_000)
    ap.add_argument("--manager-steps", type=int, default=500_000)
    ap.add_argument("--episodes", type=int, default=100, help="greedy evaluation episodes per run")
    ap.add_argument("--flat-batch", type=int, default=4_000, help="decisions per iteration of the flat runs")
    ap.add_argument("--manager-batch", type=int, default=2_000, help="decisions per iteration of the Manager runs")
    ap.add_argument("--workers", type=int, default=2, help="sampling processes of the Manager runs (the demo's 2)")
    ap.add_argument("--only", choices=("flat", "manager"), default=None)
    ap.add_argument("--out", type=Path, default=Path("runs/ppo-vs-trpo"))
    a = ap.parse_args()
    cells = []
    for kind, steps, batch in (("flat", a.flat_steps, a.flat_batch), ("manager", a.manager_steps, a.manager_batch)):
        if a.only not in (None, kind):
            continue
        for algo in ("trpo", "ppo"):
            cells.append(run_cell(kind, algo, steps, a.seeds, a.out, a.episodes, batch, a.workers))
    print("\n| task | optimiser | steps | mean over seeds | seeds |\n|---|---|---:|---:|---|")
    for c in cells:
        task = "Pendulum-v1 (greedy return)" if c["kind"] == "flat" else "ReachAndGrip1 Manager (greedy success)"
        print(f"| {task} | {c['algo']} | {c['steps']:,} | {c['mean']:.3f} | {', '.join(f'{s:.3f}' for s in c['scores'])} |")
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "ppo_vs_trpo.json").write_text(json.dumps(cells, indent=1))


if __name__ == "__main__":
    main()
