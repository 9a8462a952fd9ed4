"""Fetch: the hrlp Manager over the Fetch skills against flat learners and Stable-Baselines3's SAC + HER, at equal
environment-step budgets and the same seeds.

Methods (``--methods``, comma-separated):

* ``manager``: ``hrlp train-manager`` with the ``fetch`` preset's run for the task (SAC + HER over
  :mod:`hrlp.fetch.skills`); its skills' own training steps are counted apart (``skill_steps``: the ``fetch-reach``
  skill's 10,000 and the Stable-Baselines3 ``carry`` policy's 20,000 on FetchReach; the scripted skills none).
* ``sac``: flat hrlp SAC + HER (``--algo sac``, 4 environments, 2,000-step iterations).
* ``trpo``, ``ppo``: flat hrlp TRPO and PPO with their defaults for the task.
* ``sb3``: Stable-Baselines3's SAC with ``HerReplayBuffer`` (future strategy, 4 goals), ``learning_starts`` 1,000,
  ``gamma`` 0.95, ``tau`` 0.05, ``learning_rate`` 1e-3, ``batch_size`` 256, 256 x 256 networks (rl-baselines3-zoo's
  Fetch settings for its TQC, with SAC's networks and batch; the zoo's TQC uses 3 x 512 and batches of 2,048, about
  20 times the compute per step, out of reach of two cores).

Each run trains for ``--steps`` low-level steps; whenever it passes a multiple of ``--eval-every`` steps its greedy
policy is evaluated on ``--eval-episodes`` episodes (seeds 10,000 + i) and the success rate recorded. One torch thread
per run. Results are written to ``--out`` (JSON) after every finished run, and a run already there is skipped: an
interrupted benchmark continues where it stopped when started again with the same ``--out``; with a ``--workdir``, an
hrlp run stopped part-way continues from its last checkpoint and evaluations (``curve.json`` in its directory).
Needs the ``fetch`` extra (``pip install "hrlp[fetch]"``: gymnasium-robotics and a MuJoCo it runs on).

    python benchmarks/fetch_her.py --task PickAndPlace --methods manager,sb3 --steps 100000 --seeds 3 \\
        --out docs/results/fetch-pickandplace.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

TASKS = ("PickAndPlace", "Push", "Slide")
METHODS = ("manager", "sac", "trpo", "ppo", "sb3")
#: Environment steps the Manager's learned skills were trained for (``fetch-skills`` preset; benchmarks/fetch_sb3_skill.py).
SKILL_STEPS = {"PickAndPlace": 10_000 + 20_000, "Push": 0, "Slide": 0}


def hrlp_config(task: str, method: str, seed: int, steps: int) -> Any:
    """The hrlp run's config for ``method`` on ``task``."""
    from hrlp.config import TrainConfig
    from hrlp.experiments.presets import FETCH, PRESETS

    if method == "manager":
        run = next(r for r in PRESETS["fetch"].runs if r.name == f"manager-{task}")
        return dataclasses.replace(run.config, seed=seed, steps=steps)
    if method == "sac":
        return TrainConfig(task=FETCH.format(task), algo="sac", num_envs=4, batch_steps=2_000, workers=1, seed=seed,
                           steps=steps)  # fmt: skip
    return TrainConfig(task=FETCH.format(task), algo=method, workers=1, seed=seed, steps=steps)


def hrlp_run(task: str, method: str, seed: int, steps: int, eval_every: int, eval_episodes: int, workdir: Path) -> dict:
    """Train with hrlp; the greedy success every ``eval_every`` steps. A run stopped part-way (its directory under
    ``workdir`` holds a checkpoint, and ``curve.json`` the evaluations so far) continues from its last checkpoint."""
    from hrlp.atomic import atomic_path
    from hrlp.checkpoint import checkpoint_exists
    from hrlp.evaluate import evaluate_run
    from hrlp.train import train

    run_dir = workdir / f"{method}-{seed}"
    sidecar = run_dir / "curve.json"
    resume = checkpoint_exists(run_dir / "checkpoint")  # stopped before its first evaluation: no curve.json yet
    so_far = json.loads(sidecar.read_text()) if resume and sidecar.exists() else {"curve": [], "wall_s": 0.0}
    curve: list[tuple[int, float]] = [tuple(c) for c in so_far["curve"]]
    if resume:
        print(f"  {task} {method} seed {seed}: continuing {run_dir} ({len(curve)} evaluations so far)", flush=True)
    mark = (curve[-1][0] // eval_every + 1) * eval_every if curve else eval_every
    t0, before = time.perf_counter(), float(so_far["wall_s"])
    for stats in train(hrlp_config(task, method, seed, steps), run_dir, resume=resume, on_warning=lambda message: None):
        done = int(stats["env_steps"])
        if done >= mark or done >= steps:
            ev = evaluate_run(run_dir, episodes=eval_episodes)
            assert ev.success is not None
            curve.append((done, ev.success.mean))
            print(f"  {task} {method} seed {seed}: {done:,} steps, greedy success {ev.success.mean:.2f}", flush=True)
            mark = (done // eval_every + 1) * eval_every
            with atomic_path(sidecar) as tmp:
                tmp.write_text(json.dumps({"curve": curve, "wall_s": before + time.perf_counter() - t0}))
    return {"curve": curve, "wall_s": before + time.perf_counter() - t0}


def sb3_greedy_success(model: Any, env: Any, episodes: int) -> float:
    """A Stable-Baselines3 model's greedy success rate on ``env`` over ``episodes`` episodes (seeds 10,000 + i)."""
    wins = []
    for i in range(episodes):
        obs, _ = env.reset(seed=10_000 + i)
        done, info = False, {}
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, term, trunc, info = env.step(action)
            done = term or trunc
        wins.append(float(info["is_success"]))
    return float(np.mean(wins))


def sb3_run(task: str, seed: int, steps: int, eval_every: int, eval_episodes: int) -> dict:
    """Stable-Baselines3's SAC + HER (the module docstring's settings); the greedy success every ``eval_every`` steps."""
    import gymnasium as gym
    from stable_baselines3 import SAC, HerReplayBuffer
    from stable_baselines3.common.callbacks import BaseCallback

    env_id = f"gymnasium_robotics:Fetch{task}-v4"
    eval_env = gym.make(env_id)
    curve: list[tuple[int, float]] = []

    class Every(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % eval_every == 0 or self.num_timesteps == steps:
                curve.append((self.num_timesteps, sb3_greedy_success(self.model, eval_env, eval_episodes)))
                print(f"  {task} sb3 seed {seed}: {self.num_timesteps:,} steps, greedy success {curve[-1][1]:.2f}", flush=True)
            return True

    model = SAC("MultiInputPolicy", gym.make(env_id), replay_buffer_class=HerReplayBuffer, seed=seed, verbose=0,
                replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"}, learning_starts=1_000,
                gamma=0.95, tau=0.05, learning_rate=1e-3, batch_size=256, device="cpu")  # fmt: skip
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps, callback=Every())
    return {"curve": curve, "wall_s": time.perf_counter() - t0}


def steps_to(curve: list[tuple[int, float]], level: float) -> int | None:
    """The first evaluated step count whose greedy success is at least ``level`` (None: not within the run)."""
    return next((s for s, v in curve if v >= level), None)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", choices=TASKS, required=True)
    ap.add_argument("--methods", default=",".join(METHODS), help=f"comma-separated, of {', '.join(METHODS)}")
    ap.add_argument("--steps", type=int, default=100_000, help="low-level environment steps per run")
    ap.add_argument("--seeds", type=int, default=3, help="seeds (0, 1, ...)")
    ap.add_argument("--eval-every", type=int, default=10_000, help="greedy evaluation every this many steps")
    ap.add_argument("--eval-episodes", type=int, default=100, help="greedy evaluation episodes")
    ap.add_argument("--workdir", type=Path, default=None, help="where hrlp's runs go (default: a temporary directory)")
    ap.add_argument("--out", type=Path, required=True, help="the results (JSON); runs already in it are skipped")
    args = ap.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    if unknown := sorted(set(methods) - set(METHODS)):
        print(f"--methods: unknown {', '.join(unknown)} (known: {', '.join(METHODS)})", file=sys.stderr)
        return 2
    torch.set_num_threads(1)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    results: dict[str, Any] = json.loads(args.out.read_text()) if args.out.exists() else {}
    if results and results.get("task") != args.task:
        print(f"{args.out} holds results of Fetch{results.get('task')}, not Fetch{args.task}", file=sys.stderr)
        return 2
    results.update(task=args.task, steps=args.steps, eval_every=args.eval_every, eval_episodes=args.eval_episodes,
                   skill_steps=SKILL_STEPS[args.task], torch=torch.__version__)  # fmt: skip
    runs = results.setdefault("runs", {})
    with tempfile.TemporaryDirectory() as tmp:
        workdir = args.workdir or Path(tmp)
        for method in methods:
            for seed in range(args.seeds):
                key = f"{method}-{seed}"
                if key in runs:
                    continue
                print(f"Fetch{args.task} {method} seed {seed}: {args.steps:,} steps", flush=True)
                if method == "sb3":
                    out = sb3_run(args.task, seed, args.steps, args.eval_every, args.eval_episodes)
                else:
                    out = hrlp_run(args.task, method, seed, args.steps, args.eval_every, args.eval_episodes, workdir)
                runs[key] = {"method": method, "seed": seed, **out, "steps_to_0.9": steps_to(out["curve"], 0.9)}
                tmp_out = args.out.with_suffix(".json.part")
                tmp_out.write_text(json.dumps(results, indent=1) + "\n")
                tmp_out.replace(args.out)
    print(f"{'method':<8} {'seed':>4} {'final':>6} {'steps to 0.9':>13} {'wall s':>7}")
    for r in runs.values():
        final = r["curve"][-1][1] if r["curve"] else float("nan")
        print(f"{r['method']:<8} {r['seed']:>4} {final:>6.2f} {r['steps_to_0.9'] or '-':>13} {r['wall_s']:>7.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
