"""Imitating the scripted grasp: behaviour cloning with DAgger relabelling into an ordinary flat Gripper run.

Round 0 rolls the expert (:class:`~hrlp.arm.research.scripted.ScriptedGrasp`) out from the task's starts and records every
state's observation with the expert's action. Each DAgger round (Ross et al., 2011) then rolls the current student out
and labels the states *it* visits with the expert's actions, so the student learns to recover from its own mistakes;
the student is refitted on everything gathered so far. Two standard refinements are options:
round 0 may add episodes in which the expert's executed actions carry Gaussian noise while its labels stay clean
(DART, Laskey et al., 2017), so that it already shows how the expert recovers from states off its own path; and in
DAgger round ``r`` the expert may still act at each step with probability ``beta**r`` (Ross et al.'s mixture policy),
so that the early students' states stay near the expert's. The student is the network a flat TRPO run trains
(:func:`hrlp.policies.mlp.policy_for_space`, with the run's hidden layers and initial log std) behind the run's
observation normaliser, fitted by mean squared error of its mean action on the expert's (clipped) torques.

The result is written as iteration 0 of a training run of ``train_config`` (a checkpoint, ``config.json`` and
``imitation.json``): ``hrlp eval RUN`` evaluates it, and ``hrlp train TASK --run-dir RUN --resume --steps N``
fine-tunes it with TRPO from there.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from hrlp.arm.env import ArmEnv
from hrlp.arm.registry import make
from hrlp.arm.research.scripted import ScriptedGrasp, ScriptedGraspConfig
from hrlp.atomic import writing
from hrlp.config import TrainConfig

__all__ = ["ImitationConfig", "collect", "fit_mean", "greedy_success", "imitate"]


@dataclass(frozen=True)
class ImitationConfig:
    """Budgets of :func:`imitate`."""

    expert_episodes: int = 200
    """Episodes the expert acts in (round 0)."""
    dagger_rounds: int = 2
    """DAgger rounds after round 0: the student acts, the expert labels."""
    dagger_episodes: int = 100
    """Episodes per DAgger round."""
    epochs: int = 40
    """Passes over the gathered data per fit."""
    minibatch: int = 256
    """States per Adam step."""
    lr: float = 1e-3
    """Adam's learning rate."""
    lr_decay: bool = False
    """Anneal the learning rate of each fit from ``lr`` to 0 on a cosine over its steps (False: constant)."""
    noisy_expert_episodes: int = 0
    """More round-0 episodes, in which the expert's executed actions carry Gaussian noise of std ``expert_noise`` (its
    labels stay clean; DART): they show how the expert recovers from states off its own path."""
    expert_noise: float = 0.0
    """Std of that noise, in action units (the action box is [-1, 1])."""
    beta: float = 0.0
    """In DAgger round r (1, 2, ...) the expert acts at each step with probability beta**r, else the student (0: the
    student alone, plain DAgger)."""
    expert_keep_clear: bool = True
    """The expert's :attr:`hrlp.arm.research.scripted.ScriptedGraspConfig.keep_clear` (False: the first version's motion, from
    which the shipped ``gripper-imitated`` was imitated)."""
    expert_escape_clearance: float = 0.0
    """The expert's :attr:`hrlp.arm.research.scripted.ScriptedGraspConfig.escape_clearance`, metres (0: no escape from tight
    starts, the expert the shipped ``gripper-claw`` was imitated from)."""
    eval_episodes: int = 0
    """If > 0, each round's student is evaluated greedily over this many episodes (seeds apart from the collected
    ones) and the best round's student is the one written (ties: the later round); 0: the last round's, unevaluated."""

    def __post_init__(self) -> None:
        for name in ("expert_episodes", "epochs", "minibatch"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"imitation {name} must be a positive integer, got {v!r}")
        for name in ("dagger_rounds", "dagger_episodes", "eval_episodes", "noisy_expert_episodes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"imitation {name} must be an integer >= 0, got {v!r}")
        if not (math.isfinite(self.lr) and self.lr > 0):
            raise ValueError(f"imitation lr must be a positive number, got {self.lr!r}")
        try:  # the expert's own check of the value
            ScriptedGraspConfig(escape_clearance=self.expert_escape_clearance)
        except ValueError as e:
            raise ValueError(f"imitation expert_escape_clearance: {e}") from None
        if not (math.isfinite(self.expert_noise) and self.expert_noise >= 0):
            raise ValueError(f"imitation expert_noise must be a number >= 0, got {self.expert_noise!r}")
        if self.noisy_expert_episodes and not self.expert_noise:
            raise ValueError("imitation noisy_expert_episodes needs expert_noise > 0 (the noise's std)")
        for flag in ("expert_keep_clear", "lr_decay"):
            if not isinstance(getattr(self, flag), bool):
                raise ValueError(f"imitation {flag} must be true or false, got {getattr(self, flag)!r}")
        if not (math.isfinite(self.beta) and 0 <= self.beta <= 1):
            raise ValueError(f"imitation beta must be in [0, 1], got {self.beta!r}")


def collect(
    env: ArmEnv,
    expert: ScriptedGrasp,
    episodes: int,
    seed: int,
    student: Callable[[np.ndarray], np.ndarray] | None = None,
    *,
    expert_prob: float = 0.0,
    noise: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Roll out ``episodes`` episodes (environment seeds ``seed + i``), acting with ``student`` (a function of the raw
    observation) or, if None, with the expert; label every visited state with the expert's (noise-free) action.

    With a student, the expert still acts at each step with probability ``expert_prob``. Where the expert acts, its
    action gets Gaussian noise of std ``noise`` (clipped to the action box). The draws come from a generator seeded
    with ``seed``, so a call is reproducible.

    Returns ``(obs [M, D], expert actions [M, 9], success rate of the acting policy)``."""
    rng = np.random.default_rng(seed)
    obs_rows, act_rows, wins = [], [], 0
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        done, success = False, False
        while not done:
            label = expert.act()
            obs_rows.append(obs.copy())
            act_rows.append(label)
            if student is None or (expert_prob > 0 and rng.random() < expert_prob):
                action = np.clip(label + noise * rng.standard_normal(label.shape), -1.0, 1.0) if noise else label
            else:
                action = student(obs)
            obs, _, terminated, truncated, info = env.step(action)
            success = success or bool(info["success"])
            done = terminated or truncated
        wins += success
    return np.asarray(obs_rows), np.clip(np.asarray(act_rows), -1.0, 1.0), wins / max(episodes, 1)


def greedy_success(env: ArmEnv, student: Callable[[np.ndarray], np.ndarray], episodes: int, seed: int) -> float | None:
    """Success rate of ``student`` acting alone over ``episodes`` episodes (environment seeds ``seed + i``); None for 0."""
    if episodes == 0:
        return None
    wins = 0
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        done, success = False, False
        while not done:
            obs, _, terminated, truncated, info = env.step(student(obs))
            success = success or bool(info["success"])
            done = terminated or truncated
        wins += success
    return wins / episodes


def fit_mean(policy: Any, obs: torch.Tensor, actions: torch.Tensor, cfg: ImitationConfig, generator: torch.Generator) -> float:
    """Fit ``policy``'s mean action on normalised ``obs [M, D]`` to ``actions [M, A]`` by mean squared error (Adam,
    ``cfg.epochs`` shuffled passes, the learning rate annealed to 0 with ``cfg.lr_decay``); returns the final mean
    squared error over all the data."""
    params = list(policy.mean_net.parameters())
    opt = torch.optim.Adam(params, lr=cfg.lr)
    n = obs.shape[0]
    steps = cfg.epochs * -(-n // cfg.minibatch)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps) if cfg.lr_decay else None
    for _ in range(cfg.epochs):
        for idx in torch.randperm(n, generator=generator).split(cfg.minibatch):
            loss = ((policy.mean_net(obs[idx]) - actions[idx]) ** 2).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            if schedule is not None:
                schedule.step()
    with torch.no_grad():
        return float(((policy.mean_net(obs) - actions) ** 2).mean())


def imitate(
    train_config: TrainConfig,
    run_dir: Path,
    cfg: ImitationConfig = ImitationConfig(),
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Imitate the scripted grasp on ``train_config``'s Gripper task and write the student as iteration 0 of that run
    in ``run_dir`` (which must not hold a run). Returns what each round gathered and reached (also ``imitation.json``)."""
    from hrlp.checkpoint import checkpoint_exists
    from hrlp.train import Trainer

    if train_config.task.removeprefix("hrlp/").removesuffix("-v0") != "Gripper" or train_config.macro is not None:
        raise ValueError(f"imitation trains a flat Gripper (the scripted grasp's task), not {train_config.task}")
    run_dir = Path(run_dir)
    if checkpoint_exists(run_dir / "checkpoint"):
        raise ValueError(f"{run_dir} already holds a run; choose another directory")
    trainer = Trainer(train_config)  # the run's policy, normaliser and sampler, as TRPO would start them
    try:
        return _imitate(trainer, trainer.cfg, run_dir, cfg, log)  # with the workers it uses (resolve_config)
    finally:
        trainer.sampler.close()


def _imitate(trainer: Any, train_config: TrainConfig, run_dir: Path, cfg: ImitationConfig,
             log: Callable[[str], None]) -> dict[str, Any]:  # fmt: skip
    env = make("Gripper", episode_steps=train_config.episode_steps or 100, **train_config.task_kwargs).unwrapped
    expert = ScriptedGrasp(
        env.physics, ScriptedGraspConfig(keep_clear=cfg.expert_keep_clear, escape_clearance=cfg.expert_escape_clearance)
    )
    policy, normalizer = trainer.policy, trainer.normalizer
    generator = torch.Generator().manual_seed(train_config.seed)

    def student(o: np.ndarray) -> np.ndarray:
        x = normalizer(o, update=False)[None].astype(np.float32)
        return policy.act_numpy(x, None, True)[0]

    rounds: list[dict[str, Any]] = []
    seed = 1_000_000 + 10_000 * train_config.seed  # apart from evaluation's seeds (10,000 + episode)
    obs, act, success = collect(env, expert, cfg.expert_episodes, seed)
    all_obs, all_act = [obs], [act]
    if cfg.noisy_expert_episodes:
        obs, act, _ = collect(env, expert, cfg.noisy_expert_episodes, seed + 50_000, noise=cfg.expert_noise)
        all_obs.append(obs)
        all_act.append(act)
    normalizer.update(np.concatenate(all_obs))
    best: tuple[float, int, dict[str, torch.Tensor]] | None = None
    for r in range(cfg.dagger_rounds + 1):
        x = torch.as_tensor(normalizer.normalize(np.concatenate(all_obs)), dtype=torch.float32)
        y = torch.as_tensor(np.concatenate(all_act), dtype=torch.float32)
        mse = fit_mean(policy, x, y, cfg, generator)
        alone = greedy_success(env, student, cfg.eval_episodes, seed - 10_000)
        acting = "expert" if r == 0 else ("student" if not cfg.beta else f"student, expert w.p. {cfg.beta**r:.3g}")
        rounds.append({"round": r, "acting": acting, "acting_success": success, "states": int(x.shape[0]),
                       "fit_mse": mse, "student_success": alone})  # fmt: skip
        log(f"imitation round {r}: {acting} acted, success {success:.2f}; {x.shape[0]:,} labelled states, fit MSE "
            f"{mse:.4f}" + ("" if alone is None else f"; the student alone succeeds {alone:.2f}"))  # fmt: skip
        if alone is not None and (best is None or alone >= best[0]):
            best = (alone, r, {k: v.clone() for k, v in policy.mean_net.state_dict().items()})
        if r == cfg.dagger_rounds:
            break
        obs, act, success = collect(env, expert, cfg.dagger_episodes, seed + 100_000 * (r + 1), student,
                                    expert_prob=cfg.beta ** (r + 1))  # fmt: skip
        all_obs.append(obs)
        all_act.append(act)
    kept = cfg.dagger_rounds
    if best is not None:
        kept = best[1]
        policy.mean_net.load_state_dict(best[2])
        log(f"imitation keeps round {kept}'s student (alone {best[0]:.2f})")
    env.close()
    run_dir.mkdir(parents=True, exist_ok=True)
    trainer.save(run_dir / "checkpoint")
    config_path = run_dir / "config.json"
    with writing(config_path):
        config_path.write_text(json.dumps(train_config.to_json(), indent=2))
    summary = {"imitation": asdict(cfg), "rounds": rounds, "kept_round": kept}
    out = run_dir / "imitation.json"
    with writing(out):
        out.write_text(json.dumps(summary, indent=1))
    return summary
