"""TRPO training throughput (env steps/s): sb3-contrib, Tianshou and hrlp on Pusher-v5, plus physics alone.

Every library trains TRPO for the same number of environment steps in this one process, one torch thread each (hrlp
with sampling workers computes its TRPO step with one thread per worker, while the workers wait for it).
Also reported: hrlp's time breakdown (env / inference / update), its fraction of the raw ``mujoco.mj_step``
ceiling, the same on the arm task ReachAndGrip2, and the peak resident memory of a 50,000-step hrlp batch
(measured in a subprocess, so the figure is hrlp's alone).

    python benchmarks/trpo_speed.py [--steps 100000] [--batch-steps 25000] [--arm-steps 150000] [--workers 2]
                                    [--fisher-fraction 0.1] [--fast-envs 64] [--skip tianshou]

hrlp runs five ways: "paper", the paper's settings in one process (``hrlp.config.PAPER_SETTINGS``, ``hrlp train
--paper-settings``: 16 environments, exact Fisher-vector products, the baseline by 25 L-BFGS iterations on every state);
with ``--workers`` sampling processes; "fast", which adds Fisher-vector products on a 10% subsample (Schulman et al.
2015, Section 6) and 64 environments; "fastest", which also fits the baseline with 10 L-BFGS iterations instead of 25,
on every 4th time step of the batch; and "defaults", ``TrainConfig``'s defaults with no option at all (what ``hrlp
train Pusher-v5`` runs: a worker per core, its 50,000-step batch unless ``--defaults-batch-steps``). On the arm task
the defaults step each worker's environments as one batched MuJoCo backend (``--backend batched``); "defaults, serial
backend" is the same run with one environment object each (the defaults before the batched backend; the paper's, fast
and fastest runs are serial too, as PAPER_SETTINGS is), and "defaults, one worker" the same run in one process.
``benchmarks/trpo_returns.py --hrlp fastest`` (and ``--hrlp defaults``) checks that they still learn as well.

Goals: hrlp's defaults >= 10x sb3-contrib and >= 5x Tianshou in env steps/s; on the arm task >= 75% of the cores'
time in physics and >= 2x the fastest serial run's steps/s; a 50,000-step batch within 1 GB RSS.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import torch

from runlog import add_argument, record

TASK = "Pusher-v5"
ARM_TASK = "ReachAndGrip2"


def sb3_steps_per_s(steps: int, seed: int) -> float:
    """sb3-contrib TRPO with its defaults (one env, n_steps 2048)."""
    from sb3_contrib import TRPO

    model = TRPO("MlpPolicy", TASK, seed=seed, device="cpu")
    t = time.perf_counter()
    model.learn(total_timesteps=steps)
    return model.num_timesteps / (time.perf_counter() - t)


def tianshou_steps_per_s(steps: int, seed: int, num_envs: int = 16) -> float:
    """Tianshou TRPO as in its mujoco_trpo example: 16 DummyVectorEnv envs, 1024 steps per update, full-batch."""
    from tianshou.algorithm import TRPO
    from tianshou.algorithm.modelfree.reinforce import ProbabilisticActorPolicy
    from tianshou.algorithm.optim import AdamOptimizerFactory
    from tianshou.data import Collector, CollectStats, VectorReplayBuffer
    from tianshou.env import DummyVectorEnv
    from tianshou.utils.net.common import Net
    from tianshou.utils.net.continuous import ContinuousActorProbabilistic, ContinuousCritic
    from tianshou.utils.torch_utils import policy_within_training_step
    from torch.distributions import Independent, Normal

    env = gym.make(TASK)
    envs = DummyVectorEnv([lambda: gym.make(TASK) for _ in range(num_envs)])
    envs.seed(seed)
    torch.manual_seed(seed)
    obs_shape, act_shape = env.observation_space.shape, env.action_space.shape
    actor = ContinuousActorProbabilistic(
        preprocess_net=Net(state_shape=obs_shape, hidden_sizes=[64, 64], activation=torch.nn.Tanh),
        action_shape=act_shape,
        unbounded=True,
    )
    critic = ContinuousCritic(preprocess_net=Net(state_shape=obs_shape, hidden_sizes=[64, 64], activation=torch.nn.Tanh))
    policy = ProbabilisticActorPolicy(
        actor=actor,
        dist_fn=lambda loc_scale: Independent(Normal(*loc_scale), 1),
        action_scaling=True,
        action_bound_method="clip",
        action_space=env.action_space,
    )
    algorithm = TRPO(
        policy=policy,
        critic=critic,
        optim=AdamOptimizerFactory(lr=1e-3),
        gamma=0.99,
        gae_lambda=0.95,
        return_scaling=True,
        advantage_normalization=True,
        optim_critic_iters=20,
        max_kl=0.01,
        backtrack_coeff=0.8,
        max_backtracks=10,
    )
    collect_steps = 1024
    collector = Collector[CollectStats](algorithm, envs, VectorReplayBuffer(4096, num_envs), exploration_noise=True)
    collector.reset()
    done = 0
    t = time.perf_counter()
    while done < steps:
        with policy_within_training_step(algorithm.policy):
            done += collector.collect(n_step=collect_steps).n_collected_steps
            algorithm.update(buffer=collector.buffer, batch_size=None, repeat=1)
        collector.reset_buffer(keep_statistics=True)
    return done / (time.perf_counter() - t)


def hrlp_run(task: str, steps: int, seed: int, settings: dict[str, object]) -> dict[str, float]:
    """hrlp TRPO with ``TrainConfig``'s defaults but ``settings`` (``hrlp.config.with_settings``' names, e.g.
    ``trpo.fisher_fraction``): steps/s and step-weighted time shares (with workers, the env and inference shares are
    those of the slowest worker; they overlap with the value fit, which runs in the main process meanwhile).
    ``physics`` is the time measured inside ``mj_step`` in the run (hrlp's tasks report it; NaN on Gymnasium ids) over
    cores x wall; ``workers`` the sampling processes the run used."""
    from hrlp.algos.value import fit_value
    from hrlp.config import with_settings
    from hrlp.train import TrainConfig, Trainer

    trainer = Trainer(with_settings(TrainConfig(task=task, steps=steps, seed=seed), settings))
    wall = 0.0
    shares = {"env": 0.0, "inference": 0.0, "value_fit": 0.0, "update": 0.0, "physics": 0.0}
    try:
        while trainer.env_steps < steps:
            t = time.perf_counter()
            s = trainer.iterate()
            dt = time.perf_counter() - t
            wall += dt
            for k in shares:
                shares[k] += s[f"time/{k}_share"] * dt
        # Each batch's baseline fit runs in the next iteration; the last batch's is timed here so every batch pays.
        t = time.perf_counter()
        fit_value(trainer.value_net, *trainer.pending_value_fit, trainer.cfg.value)
        dt = time.perf_counter() - t
        wall += dt
        shares["value_fit"] += dt
    finally:
        trainer.sampler.close()
    return {"steps": trainer.env_steps, "wall": wall, "steps_per_s": trainer.env_steps / wall,
            "workers": trainer.cfg.workers, **{k: v / wall for k, v in shares.items()}}  # fmt: skip


#: The arm task's fastest settings as the benchmark of an older checkout runs them (``hrlp_run``'s keywords at commit
#: 436d424, 24 Nov 2026, when issue 17 set the goal ">= 2x today's fastest steps/s on ReachAndGrip2": two sampling
#: workers, 64 environments, Fisher products on 10%, the baseline by 10 L-BFGS iterations on every 4th step).
BASELINE_FASTEST = {"workers": 2, "fisher_fraction": 0.1, "num_envs": 64, "value_iters": 10, "value_fraction": 0.25}


def check_checkout(checkout: str) -> Path:
    """``checkout`` resolved, or SystemExit in one line when it holds no hrlp code to run."""
    root = Path(checkout).resolve()
    if not (root / "benchmarks" / "trpo_speed.py").is_file() or not (root / "src" / "hrlp").is_dir():
        raise SystemExit(f"--baseline-checkout {checkout}: not an hrlp checkout (no benchmarks/trpo_speed.py, src/hrlp)")
    return root


def baseline_run(checkout: str, steps: int, batch_steps: int, seed: int) -> dict[str, float]:
    """The fastest settings on ReachAndGrip2 with an older checkout's code (``checkout``: a ``git worktree`` of it),
    through that checkout's own ``benchmarks/trpo_speed.py`` in a subprocess, so that this run compares today's
    defaults with the code of the day the goal was set, on the same host at the same hour."""
    import json
    import os

    root = check_checkout(checkout)
    code = ("import json, sys, torch; torch.set_num_threads(1); sys.path.insert(0, 'benchmarks'); "
            "from trpo_speed import hrlp_run; "
            f"print(json.dumps(hrlp_run({ARM_TASK!r}, {steps}, {batch_steps}, {seed}, **{BASELINE_FASTEST!r})))")  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(root / "src")}
    out = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def physics_step_seconds(model: mujoco.MjModel, data: mujoco.MjData, nsub: int, n: int, episode: int,
                         reset: Callable[[], object] | None = None) -> float:  # fmt: skip
    """Seconds per control step of bare ``mj_step`` (``nsub`` substeps) with random controls, ``reset`` (default
    ``mj_resetData``) every ``episode`` steps; only the steps are timed."""
    ctrls = np.random.default_rng(0).uniform(*model.actuator_ctrlrange.T, size=(n, model.nu))
    reset = reset or (lambda: mujoco.mj_resetData(model, data))
    total = 0.0
    for start in range(0, n, episode):
        reset()
        t = time.perf_counter()
        for c in ctrls[start : start + episode]:
            data.ctrl[:] = c
            mujoco.mj_step(model, data, nsub)
        total += time.perf_counter() - t
    return total / n


def pusher_physics(n: int) -> float:
    env = gym.make(TASK)
    env.reset(seed=0)
    u = env.unwrapped
    return physics_step_seconds(u.model, u.data, u.frame_skip, n, 100)


def arm_physics(n: int, episode: int = 300) -> float:
    """Seconds per control step of bare ``mj_step`` on the arm task from its own start states (the task resets every
    ``episode`` steps), random controls: the physics a training run on it pays for, without anything around it."""
    from hrlp.arm import make

    env = make(ARM_TASK)
    env.reset(seed=0)
    p = env.unwrapped.physics
    return physics_step_seconds(p.model, p.data, p.config.substeps, n, episode, reset=env.reset)


def peak_rss_mib(task: str, batch_steps: int, baseline: bool) -> tuple[float, float]:
    """Peak RSS (MiB) of a fresh interpreter running one hrlp iteration of ``batch_steps`` (or only the imports).

    Returns ``(ru_maxrss, VmHWM)``. Linux carries ``ru_maxrss`` over ``fork``/``exec`` from the parent, so it is
    at least the parent's RSS at the fork; ``VmHWM`` is the child's own high-water mark.
    """
    cmd = [sys.executable, __file__, "--rss-child", task, "--batch-steps", str(batch_steps)]
    if baseline:
        cmd.append("--rss-baseline")
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    maxrss, hwm = out.strip().splitlines()[-1].split()
    return float(maxrss), float(hwm)


def rss_child(task: str, batch_steps: int, baseline: bool) -> None:
    torch.set_num_threads(1)
    from hrlp.train import TrainConfig, Trainer

    if not baseline:  # one process (the paper's settings), so that the whole batch is this process's memory
        from hrlp.config import PAPER_SETTINGS, with_settings

        cfg = with_settings(TrainConfig(task=task, steps=batch_steps, batch_steps=batch_steps, seed=0), PAPER_SETTINGS)
        trainer = Trainer(cfg)
        trainer.iterate()
        trainer.sampler.close()
    hwm = next(line for line in open("/proc/self/status") if line.startswith("VmHWM:"))
    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, int(hwm.split()[1]) / 1024)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=100_000, help="env steps per library on Pusher-v5")
    ap.add_argument("--batch-steps", type=int, default=25_000, help="hrlp env steps per TRPO iteration")
    ap.add_argument("--arm-steps", type=int, default=150_000, help="hrlp env steps on ReachAndGrip2")
    ap.add_argument("--physics-steps", type=int, default=20_000, help="control steps of raw mj_step per timing")
    ap.add_argument("--rss-batch", type=int, default=50_000, help="batch_steps of the memory measurement")
    ap.add_argument("--rss-task", default=ARM_TASK)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2, help="also run hrlp with this many sampling processes (1: skip)")
    ap.add_argument("--fisher-fraction", type=float, default=0.1, help="Fisher subsample of the fast hrlp run")
    ap.add_argument("--fast-envs", type=int, default=64, help="environments of the fast hrlp run")
    ap.add_argument("--fastest-value-iters", type=int, default=10, help="L-BFGS iterations of the fastest run's value fit")
    ap.add_argument("--fastest-value-fraction", type=float, default=0.25, help="share of time steps the fastest run fits on")
    ap.add_argument("--defaults-batch-steps", type=int, default=None,
                    help="batch of the defaults run (default: TrainConfig's, as hrlp train runs it)")  # fmt: skip
    ap.add_argument(
        "--baseline-checkout",
        default=None,
        help="an older hrlp checkout (git worktree) whose fastest ReachAndGrip2 settings (BASELINE_FASTEST) "
        "also run, in a subprocess with its own code; the defaults' steps/s are then given as a ratio to it",
    )
    ap.add_argument("--skip", default="", help="comma-separated: pusher (hrlp on it),sb3,tianshou,arm,rss")
    add_argument(ap)
    ap.add_argument("--rss-child", help=argparse.SUPPRESS)
    ap.add_argument("--rss-baseline", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.rss_child:
        rss_child(args.rss_child, args.batch_steps, args.rss_baseline)
        return
    torch.set_num_threads(1)
    skip = set(filter(None, args.skip.split(",")))
    if args.baseline_checkout is not None:
        if "arm" in skip:
            raise SystemExit("--baseline-checkout compares the ReachAndGrip2 rows; it cannot go with --skip arm")
        check_checkout(args.baseline_checkout)

    from hrlp.config import PAPER_SETTINGS, TrainConfig

    rates: dict[str, float] = {}
    runs: dict[str, dict[str, float]] = {}
    figures: dict[str, object] = {"pusher_steps_per_s": rates, "pusher_runs": runs}
    paper = {**PAPER_SETTINGS, "batch_steps": args.batch_steps}
    paper_name = "hrlp paper (--paper-settings: 1 process, 16 envs, exact Fisher, baseline 25 L-BFGS iterations)"
    fast = {**paper, "workers": args.workers, "trpo.fisher_fraction": args.fisher_fraction, "num_envs": args.fast_envs}
    fast_name = f"hrlp fast ({args.workers} workers, Fisher {args.fisher_fraction:g}, {args.fast_envs} envs)"
    fastest = {**fast, "value.max_iter": args.fastest_value_iters, "value.fraction": args.fastest_value_fraction}
    fastest_name = (f"hrlp fastest (fast, baseline: {args.fastest_value_iters} L-BFGS iterations on "
                    f"{args.fastest_value_fraction:.0%} of the steps)")  # fmt: skip
    defaults = {} if args.defaults_batch_steps is None else {"batch_steps": args.defaults_batch_steps}
    defaults_name = (f"hrlp defaults (no options: batch {args.defaults_batch_steps or TrainConfig.batch_steps:,}, "
                     "a worker per core)")  # fmt: skip
    configs = {paper_name: paper, f"hrlp {args.workers} workers": {**paper, "workers": args.workers}, fast_name: fast,
               fastest_name: fastest, defaults_name: defaults}  # fmt: skip
    with_workers = {f"hrlp {args.workers} workers", fast_name, fastest_name}  # skipped with --workers 1
    for name, kw in configs.items():
        if "pusher" in skip or (name in with_workers and args.workers < 2):
            continue
        runs[name] = hrlp_run(TASK, args.steps, args.seed, kw)
        rates[name] = runs[name]["steps_per_s"]
        print(f"{name}: {rates[name]:.0f} steps/s", flush=True)
    if "sb3" not in skip:
        rates["sb3-contrib"] = sb3_steps_per_s(args.steps, args.seed)
        print(f"sb3-contrib: {rates['sb3-contrib']:.0f} steps/s", flush=True)
    if "tianshou" not in skip:
        try:
            rates["tianshou"] = tianshou_steps_per_s(args.steps, args.seed)
            print(f"tianshou: {rates['tianshou']:.0f} steps/s", flush=True)
        except ImportError as e:
            print(f"tianshou skipped: {e}")
    phys = pusher_physics(args.physics_steps)
    rates["physics alone"] = 1 / phys

    print(f"\n{TASK}, {args.steps} env steps each, torch threads 1")
    print(f"{'':<52} {'steps/s':>8} " + " ".join(f"{n.split(' (')[0] + ' / this':>20}" for n in runs))
    for name, r in rates.items():
        print(f"{name:<52} {r:>8.0f} " + " ".join(f"{rates[n] / r:>19.2f}x" for n in runs))
    for name, hr in runs.items():
        cores = int(hr["workers"])
        share = hr["steps"] * phys / (hr["wall"] * cores)
        print(
            f"{name}: time shares env {hr['env']:.1%}, inference {hr['inference']:.1%}, value fit {hr['value_fit']:.1%}, "
            f"update {hr['update']:.1%}; mj_step share of {cores} core(s) x wall: {share:.1%}"
        )

    if "arm" not in skip:
        aphys = arm_physics(args.physics_steps)
        serial_name = "hrlp defaults, serial backend (--backend serial)"
        one_name = "hrlp defaults, one worker (--workers 1)"
        arm_rates: dict[str, float] = {}
        arm_runs = ((paper_name, paper), (fast_name, fast), (fastest_name, fastest),
                    (serial_name, {**defaults, "backend": "serial"}), (defaults_name, defaults),
                    (one_name, {**defaults, "workers": 1}))  # fmt: skip
        for name, kw in arm_runs:
            if name in with_workers and args.workers < 2:
                continue
            arm = hrlp_run(ARM_TASK, args.arm_steps, args.seed, kw)
            arm_rates[name] = arm["steps_per_s"]
            figures.setdefault("arm_runs", {})[name] = arm  # type: ignore[union-attr]
            cores = int(arm["workers"])
            print(
                f"\n{ARM_TASK}, {name}, {arm['steps']} env steps: {arm['steps_per_s']:.0f} steps/s, physics alone "
                f"{1 / aphys:.0f} per core ({aphys * 1e6:.0f} us/step)"
            )
            print(
                f"time shares: env {arm['env']:.1%}, inference {arm['inference']:.1%}, value fit {arm['value_fit']:.1%}, "
                f"update {arm['update']:.1%}; mj_step share of {cores} core(s) x wall: measured in the run "
                f"{arm['physics']:.1%}, estimated from bare mj_step {arm['steps'] * aphys / (arm['wall'] * cores):.1%}"
            )

        if args.baseline_checkout is not None:
            commit = subprocess.run(["git", "-C", args.baseline_checkout, "rev-parse", "--short", "HEAD"],
                                    capture_output=True, text=True).stdout.strip() or "?"  # fmt: skip
            base = baseline_run(args.baseline_checkout, args.arm_steps, args.batch_steps, args.seed)
            figures["baseline"] = {"checkout_commit": commit, **base,
                                   "defaults_over_baseline": arm_rates[defaults_name] / base["steps_per_s"]}  # fmt: skip
            print(
                f"\n{ARM_TASK}, fastest settings with the code of {Path(args.baseline_checkout).name} (commit {commit}), "
                f"{base['steps']:.0f} env steps: {base['steps_per_s']:.0f} steps/s; today's defaults / it: "
                f"{arm_rates[defaults_name] / base['steps_per_s']:.2f}x, today's fastest / it: "
                f"{arm_rates.get(fastest_name, float('nan')) / base['steps_per_s']:.2f}x"
            )

    if "rss" not in skip:
        base = peak_rss_mib(args.rss_task, args.rss_batch, baseline=True)
        peak = peak_rss_mib(args.rss_task, args.rss_batch, baseline=False)
        figures["peak_rss_mib"] = {"task": args.rss_task, "batch_steps": args.rss_batch, "vmhwm": peak[1],
                                   "imports_alone": base[1], "ru_maxrss": peak[0]}  # fmt: skip
        print(
            f"\npeak RSS (VmHWM), hrlp {args.rss_task} batch_steps={args.rss_batch}: {peak[1]:.0f} MiB "
            f"(imports alone {base[1]:.0f} MiB); ru_maxrss {peak[0]:.0f} MiB (includes the parent's RSS at fork)"
        )

    record(__file__, figures, args.runs_dir)


if __name__ == "__main__":
    main()
