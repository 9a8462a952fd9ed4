"""Control steps per second of ``env.step`` against raw ``mujoco.mj_step`` on the same model.

Both loops run the same physics (same model, timestep and substeps) with the same pre-drawn
random actions, in one process, interleaved, so the ratio is robust to the machine's noise.
Goal: env.step costs at most 1.5x the physics alone.

    python benchmarks/env_step.py [--steps 20000] [--repeats 3] [--tasks Gripper,ReachAndMove]
"""

from __future__ import annotations

import argparse
import statistics
import time

import mujoco
import numpy as np

from hrlp.arm import TASKS, make


def physics_only(env, actions: np.ndarray) -> float:
    """Seconds for len(actions) control steps of bare mj_step (from the env's start state)."""
    model, data, nsub = env.physics.model, env.physics.data, env.physics.config.substeps
    t = time.perf_counter()
    for a in actions:
        data.ctrl[:] = a
        mujoco.mj_step(model, data, nsub)
    return time.perf_counter() - t


def env_steps(env, actions: np.ndarray) -> float:
    """Seconds for len(actions) env.step calls, resets at truncation included."""
    t = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tasks", default=",".join(TASKS))
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(args.steps, 9))
    print(f"{'task':<18} {'physics steps/s':>16} {'env steps/s':>12} {'env/physics time':>17}")
    ratios = []
    for name in args.tasks.split(","):
        env = make(name)
        phys, full = [], []
        for r in range(args.repeats):
            env.reset(seed=r)
            phys.append(physics_only(env, actions))
            env.reset(seed=r)
            full.append(env_steps(env, actions))
        p, f = statistics.median(phys), statistics.median(full)
        ratios.append(f / p)
        print(f"{name:<18} {args.steps / p:>16,.0f} {args.steps / f:>12,.0f} {f / p:>16.2f}x")
    print(f"median env/physics time ratio: {statistics.median(ratios):.2f}x (goal <= 1.5x)")


if __name__ == "__main__":
    main()
