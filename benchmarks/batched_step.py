"""Env steps/s and MuJoCo's share of the wall time: one ArmEnv, the reference VectorEnv and BatchedArmEnv's backends.

Every variant runs the same ``N`` episode streams (world ``i`` seeded with ``i``) with the same pre-drawn uniform random
torques for the same number of steps per world (resets at truncation included), in one process, interleaved over the
repeats, so the ratios to the single ArmEnv loop (today's way of stepping an arm task) are robust to the machine's
noise. "in MuJoCo" is the share of the
variant's own running time spent inside MuJoCo's step, on the clock each environment counts it with: ArmEnv and the
reference count CPU seconds of ``mj_step``, and so does BatchedArmEnv on one thread (its C calls), taken over the
process's CPU time; with 2 threads BatchedArmEnv counts wall seconds of its C calls, taken over the wall time (so time
spent waiting for a core on a loaded machine counts for neither side).
``cpu/wall`` is the process's CPU time over the wall time (above 1: a second thread ran; below 1: the process waited
for a core, and the steps/s are the loaded machine's). Goal (issue 17): at least 75% of the wall time inside
MuJoCo's step and at least 2x the single ArmEnv's steps/s on ReachAndGrip2.

    python benchmarks/batched_step.py [--task ReachAndGrip2] [--n 16,64] [--world-steps 400] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hrlp.arm import make
from hrlp.arm.batched import make_batched
from hrlp.envs.vector import SerialVectorEnv, VectorEnv
from runlog import add_argument, record


@dataclass(frozen=True)
class Run:
    """One timed run of one variant."""

    steps_per_s: float
    mujoco_share: float
    cpu_per_wall: float


def time_single(task: str, actions: np.ndarray, episode_steps: int) -> Run:
    """One ArmEnv running each world's episodes in turn: world ``i`` reset with seed ``i`` (untimed, as the vector
    variants' first reset), then its column of ``actions [T, N, 9]``, reset at truncation. The same work as the
    vector variants (the same episodes, bit for bit with the loop backend)."""
    env = make(task, episode_steps=episode_steps)
    physics = cpu = wall = 0.0
    for i in range(actions.shape[1]):
        env.reset(seed=i)
        physics0, cpu0, t0 = env.physics_seconds, time.process_time(), time.perf_counter()
        for a in actions[:, i]:
            if env.step(a)[3]:
                env.reset()
        wall += time.perf_counter() - t0
        cpu += time.process_time() - cpu0
        physics += env.physics_seconds - physics0
    env.close()
    return Run(actions.shape[0] * actions.shape[1] / wall, physics / cpu, cpu / wall)  # ArmEnv counts CPU seconds


def time_vector(build: Callable[[], VectorEnv], actions: np.ndarray, cpu_clock: bool) -> Run:
    """A VectorEnv stepped ``T`` times with ``actions [T, N, 9]``; ``cpu_clock``: its physics seconds are CPU seconds."""
    env = build()
    env.reset(seed=0)
    physics, cpu0, t0 = 0.0, time.process_time(), time.perf_counter()
    for a in actions:
        physics += env.step(a).physics_seconds
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    run = Run(actions.shape[0] * actions.shape[1] / wall, physics / (cpu if cpu_clock else wall), cpu / wall)
    env.close()
    return run


def variants(task: str, n: int, episode_steps: int) -> dict[str, Callable[[], VectorEnv]]:
    """The vector variants at ``n`` environments, by name."""
    batched = lambda **kw: lambda: make_batched(task, n, episode_steps=episode_steps, **kw)  # noqa: E731
    return {
        "reference (SerialVectorEnv)": lambda: SerialVectorEnv([make(task, episode_steps=episode_steps) for _ in range(n)]),
        "BatchedArmEnv loop": batched(backend="loop"),
        "BatchedArmEnv rollout, 1 thread": batched(backend="rollout", threads=1),
        "BatchedArmEnv rollout, 2 threads": batched(backend="rollout", threads=2),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", default="ReachAndGrip2")
    ap.add_argument("--n", default="16,64", help="comma-separated numbers of environments")
    ap.add_argument("--world-steps", type=int, default=400, help="steps per world and run (more than an episode: a reset)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--episode-steps", type=int, default=300)
    add_argument(ap)
    args = ap.parse_args()
    print(f"{args.task}, {args.world_steps} steps per world and run ({args.episode_steps}-step episodes), "
          f"median of {args.repeats} interleaved runs")  # fmt: skip
    print(f"{'variant':<34} {'N':>3} {'steps/s':>9} {'x ArmEnv':>9} {'in MuJoCo':>10} {'cpu/wall':>9}")
    best: tuple[float, float, str] = (0.0, 0.0, "")
    rows: list[dict[str, object]] = []
    for n in (int(x) for x in args.n.split(",")):
        actions = np.random.default_rng(0).uniform(-1, 1, size=(args.world_steps, n, 9))
        vecs = variants(args.task, n, args.episode_steps)
        runs: dict[str, list[Run]] = {"single ArmEnv loop": [], **{k: [] for k in vecs}}
        for _ in range(args.repeats):
            runs["single ArmEnv loop"].append(time_single(args.task, actions, args.episode_steps))
            for name, build in vecs.items():
                runs[name].append(time_vector(build, actions, cpu_clock=not name.endswith("2 threads")))
        base = statistics.median(r.steps_per_s for r in runs["single ArmEnv loop"])
        for name, rs in runs.items():
            sps = statistics.median(r.steps_per_s for r in rs)
            share = statistics.median(r.mujoco_share for r in rs)
            cpu = statistics.median(r.cpu_per_wall for r in rs)
            print(f"{name:<34} {n:>3} {sps:>9,.0f} {sps / base:>8.2f}x {share:>9.0%} {cpu:>9.2f}")
            rows.append({"variant": name, "n": n, "steps_per_s": sps, "over_single": sps / base, "mujoco_share": share,
                         "cpu_per_wall": cpu})  # fmt: skip
            if name != "single ArmEnv loop" and sps / base > best[0]:
                best = (sps / base, share, f"{name}, N = {n}")
    print(f"fastest: {best[2]}: {best[0]:.2f}x the single ArmEnv loop, {best[1]:.0%} of its time in MuJoCo "
          "(goal: >= 2x and >= 75%)")  # fmt: skip
    fastest = {"variant": best[2], "over_single": best[0], "mujoco_share": best[1]}
    record(__file__, {"task": args.task, "world_steps": args.world_steps, "rows": rows, "fastest": fastest}, args.runs_dir)


if __name__ == "__main__":
    main()
