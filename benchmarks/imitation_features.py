"""What a student of the scripted grasp needs to see: behaviour cloning on the same expert data with three observations.

Records ``--episodes`` episodes of the scripted grasp (:class:`hrlp.arm.research.scripted.ScriptedGrasp`, the moves that keep
clear) and ``--noisy-episodes`` with DART noise of std 0.3 on its executed torques from the Gripper's own start set
(``GRIPPER_START``), every state labelled with the expert's torques. On that one data set it fits a student's mean
action (:func:`hrlp.arm.research.imitate.fit_mean`, ``--epochs`` passes, the learning rate annealed) for each observation:

- ``paper``: the 24 base numbers;
- ``capsule_pose``: and the capsule's pose (30, as ``gripper-imitated`` sees);
- ``capsule_pose+claw_pose``: and the claw's pose relative to the capsule (45, as ``gripper-claw`` sees).

For each, prints the mean squared error on the states fitted and on a tenth held out (per torque, the fingers last)
and the student's greedy success alone over ``--eval-episodes`` episodes (environment seeds 990,000 + index) with its
95% Wilson interval, beside the expert's on the same episodes. Writes ``--out`` as JSON (never replaces a file).

    python benchmarks/imitation_features.py --episodes 300 --noisy-episodes 300 --out imitation_features.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from hrlp.arm.registry import make
from hrlp.arm.research.imitate import ImitationConfig, collect, fit_mean, greedy_success
from hrlp.arm.research.scripted import ScriptedGrasp
from hrlp.evaluate import wilson_interval
from hrlp.experiments.presets import GRIPPER_START
from hrlp.policies.mlp import policy_for_space
from hrlp.policies.normalizer import RunningNormalizer

#: Observations compared: name -> how many of the 45 numbers (the base 24, capsule_pose's 6, claw_pose's 15) it keeps.
OBSERVATIONS = {"paper": 24, "capsule_pose": 30, "capsule_pose+claw_pose": 45}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=300, help="expert episodes")
    ap.add_argument("--noisy-episodes", type=int, default=300, help="expert episodes with DART noise of std 0.3")
    ap.add_argument("--epochs", type=int, default=100)
    ap.add_argument("--hidden", type=lambda s: tuple(int(w) for w in s.split(",")), default=(256, 256))
    ap.add_argument("--eval-episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="write the figures here as JSON (must not exist)")
    a = ap.parse_args()
    if a.out is not None and a.out.exists():
        ap.error(f"{a.out} exists; choose another file")
    torch.set_num_threads(1)
    env = make("Gripper", episode_steps=100, observe_capsule=True, observe_claw=True, **GRIPPER_START).unwrapped
    expert = ScriptedGrasp(env.physics)
    t0 = time.perf_counter()
    obs, act, expert_success = collect(env, expert, a.episodes, 1_000_000 + 10_000 * a.seed)
    if a.noisy_episodes:
        o2, a2, _ = collect(env, expert, a.noisy_episodes, 1_050_000 + 10_000 * a.seed, noise=0.3)
        obs, act = np.concatenate([obs, o2]), np.concatenate([act, a2])
    print(f"{len(obs):,} labelled states in {time.perf_counter() - t0:.0f} s; the expert succeeded in {expert_success:.2f} "
          f"of its clean episodes", flush=True)  # fmt: skip
    held = np.random.default_rng(a.seed).permutation(len(obs))
    val, fit = held[: len(obs) // 10], held[len(obs) // 10 :]
    ev_seed = 990_000
    expert_eval = greedy_success(env, lambda o: expert.act(), a.eval_episodes, ev_seed)
    report: dict = {"states": len(obs), "expert_clean_success": expert_success, "eval_episodes": a.eval_episodes,
                    "expert_eval": expert_eval, "hidden": list(a.hidden), "epochs": a.epochs, "students": {}}  # fmt: skip
    icfg = ImitationConfig(epochs=a.epochs, minibatch=512, lr_decay=True)
    box = gym.spaces.Box(-1.0, 1.0, (9,), np.float32)
    for name, width in OBSERVATIONS.items():
        t1 = time.perf_counter()
        torch.manual_seed(a.seed)
        policy = policy_for_space(width, box, a.hidden)
        norm = RunningNormalizer(width)
        norm.update(obs[fit, :width])

        xf, xv = (torch.as_tensor(norm.normalize(obs[rows, :width]), dtype=torch.float32) for rows in (fit, val))
        yf, yv = torch.as_tensor(act[fit], dtype=torch.float32), torch.as_tensor(act[val], dtype=torch.float32)
        fit_mse = fit_mean(policy, xf, yf, icfg, torch.Generator().manual_seed(a.seed))
        with torch.no_grad():
            per = ((policy.mean_net(xv) - yv) ** 2).mean(0).numpy()

        def student(o: np.ndarray, policy=policy, norm=norm, width=width) -> np.ndarray:
            x = norm.normalize(o[None, :width]).astype(np.float32)
            return policy.act_numpy(x, None, True)[0]

        wins = greedy_success(env, student, a.eval_episodes, ev_seed)
        ci = wilson_interval(round(wins * a.eval_episodes), a.eval_episodes)
        report["students"][name] = {"inputs": width, "fit_mse": fit_mse, "held_out_mse": float(per.mean()),
                                    "held_out_mse_per_torque": per.round(4).tolist(), "success": ci.__dict__}  # fmt: skip
        print(f"{name} ({width} numbers): MSE {fit_mse:.4f} fitted, {per.mean():.4f} held out (fingers "
              f"{per[7]:.3f}, {per[8]:.3f}); alone {ci} ({time.perf_counter() - t1:.0f} s)", flush=True)  # fmt: skip
    print(f"the expert on the same episodes: {expert_eval:.2f}")
    if a.out is not None:
        a.out.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
