"""Sparse success on reach-and-grip Experiment 2: a Manager over the shipped skills against a flat policy,
both trained for the same number of environment steps, over several seeds.

Runs train two at a time in worker processes (one torch thread each); each finished run is evaluated on
``--episodes`` episodes (mean actions, Definition 1 success). Prints one row per run and the pooled success
rate of each kind with a Wilson 95% interval, and writes a learning-curve plot.

    python benchmarks/manager_vs_flat.py [--steps 1500000] [--seeds 3] [--workers 2] [--out runs/manager_vs_flat]

Runs already finished in ``--out`` are reused, so an interrupted comparison continues where it stopped.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path


def _run(kind: str, seed: int, steps: int, out: Path, episodes: int, flat_batch: int) -> tuple[str, int, int, int, float]:
    import torch

    from hrlp.algos.trpo import TRPOConfig
    from hrlp.checkpoint import checkpoint_exists
    from hrlp.config import PAPER_SETTINGS, MacroSpec, with_settings
    from hrlp.evaluate import evaluate_run
    from hrlp.train import TrainConfig, train

    torch.set_num_threads(1)
    run = out / f"{kind}-s{seed}"
    if kind == "manager":
        # The headline's Manager settings (2,000 decisions per batch, max KL 0.02) over the Gripper and the Reacher, k = 15.
        cfg = TrainConfig(task="ReachAndGrip2", steps=steps, batch_steps=2_000, seed=seed,
                          macro=MacroSpec(("gripper", "reacher"), k=15), trpo=TRPOConfig(max_kl=0.02))  # fmt: skip
    else:
        cfg = TrainConfig(task="ReachAndGrip2", steps=steps, batch_steps=flat_batch, seed=seed)
    cfg = with_settings(cfg, PAPER_SETTINGS)  # one process, 16 environments: the settings its figures were measured with
    resume = checkpoint_exists(run / "checkpoint")
    for _ in train(cfg, run, resume=resume):
        pass
    ev = evaluate_run(run, episodes=episodes)
    assert ev.success is not None
    return kind, seed, round(ev.success.mean * episodes), episodes, ev.ret.mean


def main() -> None:
    from hrlp.evaluate import wilson_interval
    from hrlp.plots import plot_learning_curves

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=1_500_000, help="environment steps per run")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--episodes", type=int, default=100, help="evaluation episodes per run")
    ap.add_argument("--out", type=Path, default=Path("runs/manager_vs_flat"))
    ap.add_argument("--flat-batch", type=int, default=50_000, help="environment steps per flat TRPO iteration (the paper's)")
    args = ap.parse_args()
    jobs = [(kind, s) for s in range(args.seeds) for kind in ("manager", "flat")]
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(
            pool.map(
                _run,
                *zip(*jobs, strict=True),
                *[[x] * len(jobs) for x in (args.steps, args.out, args.episodes, args.flat_batch)],
            )
        )
    print(f"{'kind':<8} {'seed':>4} {'success':>9} {'return':>9}")
    for kind, seed, k, n, ret in results:
        print(f"{kind:<8} {seed:>4} {k:>4}/{n:<4} {ret:>9.1f}")
    for kind in ("manager", "flat"):
        ks = [r for r in results if r[0] == kind]
        print(f"{kind}: pooled success {wilson_interval(sum(r[2] for r in ks), sum(r[3] for r in ks))} over {len(ks)} seeds")
    runs = {kind: [args.out / f"{kind}-s{s}" for s in range(args.seeds)] for kind in ("manager", "flat")}
    plot = plot_learning_curves(runs, args.out / "manager_vs_flat.png", title=f"ReachAndGrip2, {args.steps:,} steps")
    print(f"plot: {plot}")


if __name__ == "__main__":
    main()
