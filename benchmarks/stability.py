"""Stability and speed of integrator / timestep / substep choices under random torques.

For each setting, runs random-torque episodes on several tasks (the arm whacking the capsule at
full torque is the hardest case for the solver) and counts physics instabilities (MuJoCo's
bad-qacc/qvel/qpos resets, which the environment turns into truncated episodes).

    python benchmarks/stability.py [--steps 15000] [--tasks Reacher,MoverNoised,ReachAndMove,Gripper]
"""

from __future__ import annotations

import argparse
import logging
import time

import mujoco
import numpy as np

from hrlp.arm import PhysicsConfig, make

SETTINGS = [
    ("euler", 0.002, 5),
    ("implicitfast", 0.002, 5),
    ("euler", 0.001, 10),
    ("rk4", 0.002, 5),
    ("implicitfast", 0.005, 2),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=15000, help="control steps per task and setting")
    ap.add_argument("--tasks", default="Reacher,MoverNoised,ReachAndMove,Gripper")
    ap.add_argument("--seed", type=int, default=0, help="seed of the start states and the random torques")
    args = ap.parse_args()
    logging.disable(logging.WARNING)  # the environment logs every instability; we count them instead
    print(f"{'integrator':<13} {'timestep':>8} {'substeps':>8} {'unstable episodes':>18} {'env steps/s':>12}")
    for integrator, dt, nsub in SETTINGS:
        bad = steps = 0
        t = time.perf_counter()
        for task in args.tasks.split(","):
            env = make(task, physics=PhysicsConfig(timestep=dt, substeps=nsub))
            env.physics.model.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{integrator.upper()}")
            rng = np.random.default_rng(args.seed)
            env.reset(seed=args.seed)
            for _ in range(args.steps):
                _, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 9))
                steps += 1
                bad += bool(info.get("physics_unstable"))
                if terminated or truncated:
                    env.reset()
        print(f"{integrator:<13} {dt:>8} {nsub:>8} {bad:>18} {steps / (time.perf_counter() - t):>12,.0f}")


if __name__ == "__main__":
    main()
