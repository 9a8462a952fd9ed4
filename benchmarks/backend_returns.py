"""Learning with the batched backend against the serial one: the same runs (task, seeds, settings) with
``--backend serial`` and ``--backend batched``, every final policy scored by ``hrlp eval``.

The batched backend steps the same episode streams (world ``i`` is environment ``i``) with physics that agrees with a
lone ArmEnv to about 1e-7 (MuJoCo's rollout module restarts the constraint solver's warm start every control step),
so a run's numbers drift apart from the serial run's as training amplifies that difference: what must match is the
learning, over seeds. Printed: per-seed return and success, mean +- 95% CI (Student t over seeds) per backend, and
Welch's t-test p-value of the returns.

    python benchmarks/backend_returns.py [--task Reacher] [--steps 300000] [--seeds 3] [--first-seed 0] [--episodes 50]
    python benchmarks/backend_returns.py --manager [--steps 200000]   # ReachAndGrip1, gripper + reacher, hand-over
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import torch
from scipy import stats

from hrlp.config import Handover, MacroSpec, TrainConfig
from hrlp.evaluate import evaluate_run
from hrlp.train import train


def interval(xs: list[float]) -> str:
    m = statistics.fmean(xs)
    if len(xs) < 2:
        return f"{m:.3f}"
    half = stats.t.ppf(0.975, len(xs) - 1) * statistics.stdev(xs) / len(xs) ** 0.5
    return f"{m:.3f} +- {half:.3f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", default="Reacher", help="an hrlp arm task (flat runs)")
    ap.add_argument("--manager", action="store_true", help="a Manager on ReachAndGrip1 (gripper + reacher, k = 10)")
    ap.add_argument("--steps", type=int, default=300_000)
    ap.add_argument(
        "--batch-steps", type=int, default=None, help="decisions per iteration (default 25,000 flat, 2,000 Manager)"
    )
    ap.add_argument("--num-envs", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=3, help="seeds per backend: first-seed .. first-seed + seeds - 1")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=50)
    args = ap.parse_args()
    torch.set_num_threads(1)
    macro = MacroSpec(("gripper", "reacher"), k=10, handover=Handover()) if args.manager else None
    task = "ReachAndGrip1" if args.manager else args.task
    batch = args.batch_steps or (2_000 if args.manager else 25_000)
    results: dict[str, list[tuple[float, float | None]]] = {"serial": [], "batched": []}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            for backend in results:
                cfg = TrainConfig(task=task, macro=macro, steps=args.steps, batch_steps=batch, num_envs=args.num_envs,
                                  seed=seed, backend=backend)  # fmt: skip
                run = Path(tmp) / f"{backend}-{seed}"
                t = time.perf_counter()
                for _ in train(cfg, run):  # one item per iteration
                    pass
                ev = evaluate_run(run, episodes=args.episodes)
                success = None if ev.success is None else ev.success.mean
                results[backend].append((ev.ret.mean, success))
                print(f"{task} seed {seed} {backend}: return {ev.ret.mean:.3f}, success {success}, "
                      f"{time.perf_counter() - t:.0f} s", flush=True)  # fmt: skip
    print(f"\n{task}{' Manager' if macro else ''}, {args.steps:,} steps, {args.seeds} seeds, {args.episodes} episodes each")
    for backend, rows in results.items():
        line = f"{backend:>8}: return {interval([r for r, _ in rows])}"
        if rows[0][1] is not None:
            line += f", success {interval([s for _, s in rows])}"
        print(line)
    a, b = ([r for r, _ in results[k]] for k in ("serial", "batched"))
    p = stats.ttest_ind(a, b, equal_var=False).pvalue if len(a) > 1 else float("nan")
    print(f"Welch t-test on the returns, serial vs batched: p = {p:.2f}")


if __name__ == "__main__":
    main()
