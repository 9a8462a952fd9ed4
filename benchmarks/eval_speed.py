"""Evaluation through the run's VectorEnv (``hrlp eval``) against one episode at a time, on the same run.

Both run episode ``k`` from ``reset(seed=10_000 + k)`` with the policy's mean actions and must give the same return,
success and skill use; the script prints both and the time each took. Without ``--run`` it first trains a short
Manager (ReachAndGrip1, shipped gripper + reacher, hand-over interface, k = 10) with the defaults.

    python benchmarks/eval_speed.py [--run RUN_DIR] [--episodes 40] [--steps 100000] [--batch-steps 5000]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from collections import Counter
from pathlib import Path

import torch

from hrlp.evaluate import evaluate_run, mean_interval, wilson_interval
from hrlp.train import load_trained


def one_at_a_time(run: Path, episodes: int, seed: int = 10_000) -> tuple[str, str, dict[str, float] | None]:
    """The evaluation loop before it went through a VectorEnv: one environment, episode after episode."""
    trained = load_trained(run)
    env = trained.make_env()
    rets, succ, usage = [], [], Counter()
    for k in range(episodes):
        obs, _ = env.reset(seed=seed + k)
        ret = 0.0
        while True:
            obs, r, term, trunc, info = env.step(trained.act(env, obs, None, True))
            ret += float(info.get("task_reward", r))
            if "macro" in info:
                usage[info["macro"]] += 1
            if term or trunc:
                break
        rets.append(ret)
        succ.append(bool(info.get("success", False)))
    env.close()
    total = sum(usage.values())
    return str(mean_interval(rets)), str(wilson_interval(sum(succ), len(succ))), (
        {n: c / total for n, c in usage.items()} if total else None)  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, help="a run directory (default: train a short Manager first)")
    ap.add_argument("--episodes", type=int, default=40)
    ap.add_argument("--steps", type=int, default=100_000, help="training steps of the Manager trained without --run")
    ap.add_argument("--batch-steps", type=int, default=5_000, help="decisions per iteration of that Manager")
    ap.add_argument("--num-envs", type=int, default=64, help="environments of that Manager")
    args = ap.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        run = args.run
        if run is None:
            from hrlp.config import Handover, MacroSpec, TrainConfig
            from hrlp.train import train

            run = Path(tmp) / "manager"
            spec = MacroSpec(("gripper", "reacher"), k=10, handover=Handover())
            cfg = TrainConfig(task="ReachAndGrip1", macro=spec, steps=args.steps, batch_steps=args.batch_steps,
                              num_envs=args.num_envs)  # fmt: skip
            for _ in train(cfg, run):  # a generator: one item per iteration
                pass
        t = time.perf_counter()
        old = one_at_a_time(run, args.episodes)
        t_old = time.perf_counter() - t
        t = time.perf_counter()
        ev = evaluate_run(run, episodes=args.episodes)
        t_new = time.perf_counter() - t
    usage = ev.macro_usage
    print(f"one at a time:   return {old[0]}, success {old[1]}, usage {old[2]}: {t_old:.1f} s")
    print(f"hrlp eval:       return {ev.ret}, success {ev.success}, usage {usage}: {t_new:.1f} s")
    same = old[0] == str(ev.ret) and old[1] == str(ev.success) and (
        old[2] is None or all(math.isclose(old[2][k], usage[k]) for k in old[2]))  # fmt: skip
    print(f"same results: {same}; speed-up {t_old / t_new:.2f}x")


if __name__ == "__main__":
    main()
