"""Manager training throughput against flat training on the same task, in one run.

Both train on ReachAndGrip2, with the paper's settings (``--settings paper``, ``hrlp.config.PAPER_SETTINGS``: 16
environments, one process, one environment object each) or with no options (``--settings defaults``: a worker per
core, 64 environments, the batched backend, where a Manager's skills act on every world at once): the flat
policy with batches of ``--flat-batch`` environment steps, the Manager (shipped skills gripper + reacher, k = 15) with
batches of ``--manager-batch`` decisions (about 15 environment steps each). Iterations of the two alternate so that
machine noise hits both alike. Reported per kind: environment steps per second of sampling alone and of whole
iterations (sampling + update), the share of the cores' time spent inside ``mj_step`` (``time/physics_share``), and the
Manager / flat ratio.

    python benchmarks/manager_speed.py [--settings defaults] [--rounds 3] [--flat-batch 15000] [--manager-batch 1000]
                                       [--workers 2] [--num-envs N]

Goal: the Manager's environment steps/s within 1.2x of flat training with the defaults (ratio >= 0.83).
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import replace

import torch

from hrlp.config import PAPER_SETTINGS, MacroSpec, with_settings
from hrlp.train import TrainConfig, Trainer
from runlog import add_argument, record


def main() -> None:  # run under `if __name__ == "__main__"`: sampling workers are spawned processes
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3, help="alternating iterations per kind (after one warm-up each)")
    ap.add_argument("--flat-batch", type=int, default=15_000, help="environment steps per flat iteration")
    ap.add_argument("--manager-batch", type=int, default=1_000, help="decisions per Manager iteration")
    ap.add_argument("--workers", type=int, default=2,
                    help="with --settings paper, also time the Manager with this many sampling processes")  # fmt: skip
    ap.add_argument("--settings", choices=("defaults", "paper"), default="defaults",
                    help="TrainConfig's defaults or the paper's")  # fmt: skip
    ap.add_argument("--num-envs", type=int, default=None, help="environments of every run (default: the settings')")
    add_argument(ap)
    args = ap.parse_args()
    torch.set_num_threads(1)
    spec = MacroSpec(("gripper", "reacher"), k=15)

    def config(**kw: object) -> TrainConfig:
        base = TrainConfig(task="ReachAndGrip2")
        base = with_settings(base, PAPER_SETTINGS) if args.settings == "paper" else base
        if args.num_envs is not None:
            kw = {"num_envs": args.num_envs, **kw}
        return replace(base, **kw)  # type: ignore[arg-type]

    trainers = {
        "flat": Trainer(config(batch_steps=args.flat_batch)),
        "Manager": Trainer(config(batch_steps=args.manager_batch, macro=spec)),
    }
    if args.workers > 1 and args.settings == "paper":
        trainers[f"Manager, {args.workers} workers"] = Trainer(config(batch_steps=args.manager_batch, macro=spec,
                                                                      workers=args.workers))  # fmt: skip
    sample: dict[str, list[float]] = {k: [] for k in trainers}
    whole: dict[str, list[float]] = {k: [] for k in trainers}
    physics: dict[str, list[float]] = {k: [] for k in trainers}
    for r in range(args.rounds + 1):
        for kind, tr in trainers.items():
            t0 = time.perf_counter()
            st = tr.iterate()
            wall = time.perf_counter() - t0
            if r == 0:
                continue  # warm-up
            batch_steps = st["time/steps_per_s"] * wall
            sample[kind].append(batch_steps / (wall * (st["time/env_share"] + st["time/inference_share"])))
            whole[kind].append(st["time/steps_per_s"])
            physics[kind].append(st["time/physics_share"])
    print(f"{'kind':<20} {'sampling steps/s':>17} {'whole-iteration steps/s':>24} {'mj_step share':>14}")
    for kind in trainers:
        print(f"{kind:<20} {statistics.median(sample[kind]):>17,.0f} {statistics.median(whole[kind]):>24,.0f} "
              f"{statistics.median(physics[kind]):>14.1%}")  # fmt: skip
    rs = statistics.median(sample["Manager"]) / statistics.median(sample["flat"])
    rw = statistics.median(whole["Manager"]) / statistics.median(whole["flat"])
    workers = {kind: tr.cfg.workers for kind, tr in trainers.items()}
    print(f"settings: {args.settings}; workers {workers}; backend {trainers['flat'].cfg.backend}")
    print(f"Manager / flat: sampling {rs:.2f}x, whole iteration {rw:.2f}x (goal: >= 0.83, i.e. within 1.2x)")
    medians = {kind: {"sampling_steps_per_s": statistics.median(sample[kind]), "steps_per_s": statistics.median(whole[kind]),
                      "mj_step_share": statistics.median(physics[kind])} for kind in trainers}  # fmt: skip
    record(__file__, {"settings": args.settings, "workers": workers, "kinds": medians, "manager_over_flat_sampling": rs,
                      "manager_over_flat_whole": rw}, args.runs_dir)  # fmt: skip
    for tr in trainers.values():
        tr.sampler.close()


if __name__ == "__main__":
    main()
