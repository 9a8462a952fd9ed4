"""Off-policy training (``algo="sac"``): :class:`OffPolicyTrainer` collects one decision of every environment at a time
into a replay buffer and makes gradient steps from it, with the same face as the on-policy
:class:`~hrlp.training.loop.Trainer` (``iterate``, ``save``, ``resume``), so :func:`hrlp.training.loop.train` runs
either with its budgets, logs, checkpoints and resume.

An iteration is ``batch_steps`` decisions (rounded up to whole steps of the ``num_envs`` environments): after each
step of all of them, once ``learning_starts`` decisions are in the buffer, ``updates_per_step`` gradient steps per
decision collected. Observations enter the buffer raw and are normalised when drawn, with the running statistics
of that moment (those the actor acts with). Rewards are multiplied by ``reward_scale`` as they enter the buffer.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from hrlp.algos.replay import GoalSpec, Reframe, ReplayBuffer
from hrlp.algos.sac import SACBatch, SACStats, SACUpdate
from hrlp.checkpoint import load_module, module_tensors, pack_generators, save_checkpoint, unpack_generators
from hrlp.config import TrainConfig
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.policies.sac import SACActor, TwinQ
from hrlp.rollout import Episode, NonFiniteError, Sampler, first_non_finite, mean_or_nan
from hrlp.skills.core import ObsLayout
from hrlp.skills.macro_env import MacroEnv
from hrlp.training.environments import action_units, check_skill_hashes, resolve_config, run_factory, skill_hashes
from hrlp.training.loading import check_action_units, iteration_stats, run_meta

__all__ = ["GOAL_KEYS", "OffPolicyTrainer", "goal_framed_skills", "goal_reframer", "goal_spec"]

GOAL_KEYS = ("achieved_goal", "desired_goal", "observation")
"""The keys of a goal-conditioned environment's Dict observation (Gymnasium-Robotics' ``GoalEnv``)."""


def goal_spec(env: gym.Env) -> GoalSpec | None:
    """Where ``env``'s (flattened) observation holds its achieved and desired goals and how it scores them, when it is
    goal-conditioned: a Dict observation with :data:`GOAL_KEYS` somewhere down its wrappers (or under a Manager) and a
    ``compute_reward``; None otherwise."""
    e: Any = env.env if isinstance(env, MacroEnv) else env
    while e is not None:
        space = e.observation_space
        if isinstance(space, gym.spaces.Dict) and set(GOAL_KEYS) <= set(space.spaces):
            scorer = e.unwrapped
            if not callable(getattr(scorer, "compute_reward", None)):
                return None
            layout = env.layout if isinstance(env, MacroEnv) else ObsLayout.of_space(space)
            terminated = getattr(scorer, "compute_terminated", None)
            return GoalSpec(layout.span("achieved_goal"), layout.span("desired_goal"), scorer.compute_reward,
                            terminated if callable(terminated) else None)  # fmt: skip
        e = getattr(e, "env", None)
    return None


def goal_framed_skills(env: MacroEnv, desired: slice) -> list[int]:
    """The skills of ``env`` (their indices) whose parameters are offsets from a part that lies in the desired goal's
    numbers (``desired``): relabelling a decision's goal moves the point their stored parameters meant."""
    out = []
    for i, skill in enumerate(env.skills):
        if skill.params.frame is not None:
            frame = env.layout.span(skill.params.frame)
            if max(frame.start, desired.start) < min(frame.stop, desired.stop):
                out.append(i)
    return out


def goal_reframer(env: MacroEnv, desired: slice) -> Reframe | None:
    """The :attr:`GoalSpec.reframe` of a Manager over ``env``'s skills: for the decisions that chose a skill framed on
    the desired goal, the block that passes the same point from the relabelled goal; None when no skill is so framed."""
    framed = goal_framed_skills(env, desired)
    if not framed:
        return None
    h = env.hierarchy
    spans = {s: (h.skills[s].params, env.layout.span(str(h.skills[s].params.frame)),
                 slice(1 + int(h.offsets[s]), 1 + int(h.offsets[s + 1]))) for s in framed}  # fmt: skip

    def reframe(actions: np.ndarray, obs: np.ndarray, relabelled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        actions, ok = np.array(actions, dtype=np.float32), np.ones(len(actions), dtype=bool)
        choice = actions[:, 0].astype(np.int64)
        for s, (box, frame, cols) in spans.items():
            rows = np.flatnonzero(choice == s)
            point = box.to_user(actions[rows, cols]) + obs[rows, frame]
            block = box.to_unit(point - relabelled[rows, frame])
            ok[rows] = (np.abs(block) <= 1.0).all(axis=1)
            actions[rows, cols] = np.clip(block, -1.0, 1.0)
        return actions, ok

    return reframe


class OffPolicyTrainer:
    """SAC on one task, flat or Manager: owns the actor, the critics (in :class:`~hrlp.algos.sac.SACUpdate`), the
    normaliser, the replay buffer and a :class:`~hrlp.rollout.Sampler` in this process."""

    def __init__(self, cfg: TrainConfig, *, from_checkpoint: bool = False) -> None:
        self.cfg = cfg = resolve_config(cfg)
        factory = run_factory(cfg)
        torch.manual_seed(cfg.seed)
        probe = factory()
        self.obs_dim = obs_dim = int(np.prod(probe.observation_space.shape))
        self.skill_hashes = skill_hashes(probe.skills) if isinstance(probe, MacroEnv) else {}
        self.action_units = action_units(probe)
        self.policy = SACActor(obs_dim, probe.action_space, cfg.sac.hidden)
        self.critic = TwinQ(obs_dim, self.policy.param_dims, cfg.sac.hidden)
        goals = goal_spec(probe) if cfg.sac.her_future > 0 else None
        if goals is not None and isinstance(probe, MacroEnv):
            goals = dataclasses.replace(goals, reframe=goal_reframer(probe, goals.desired))
        self._scorer = probe if goals is not None else None  # compute_reward is the probe's: it stays open
        if self._scorer is None:
            probe.close()
        self.normalizer = RunningNormalizer(obs_dim)
        self.sampler = Sampler([factory] * cfg.num_envs, self.policy, self.normalizer, seed=cfg.seed,
                               gamma=cfg.advantage.gamma)  # fmt: skip
        self.update = SACUpdate(self.policy, self.critic, cfg.sac, cfg.seed)
        path_len = int(probe.hierarchy.durations.max()) if isinstance(probe, MacroEnv) and goals is not None else 0
        self.sampler.keep_paths = path_len > 0  # a relabelled macro-transition is scored at each of its steps
        self.buffer = ReplayBuffer(cfg.sac.buffer_size, cfg.num_envs, obs_dim, 1 + self.policy.s, cfg.advantage.gamma,
                                   goals, cfg.sac.her_future, path_len, cfg.reward_scale)  # fmt: skip
        self.relabels = goals is not None
        """Whether minibatches get relabelled goals (a goal-conditioned environment and ``her_future`` > 0)."""
        self.rng = np.random.default_rng(cfg.seed + 15_485_863)  # minibatch draws and goal relabelling
        self.iteration = 0
        self.env_steps = 0
        self.episodes_done = 0
        self.decisions = 0
        """Decisions collected so far (transitions added to the buffer)."""
        self.gradient_steps = 0
        self._owed = 0.0  # gradient steps due but not yet made (updates_per_step may be fractional)

    def iterate(self) -> dict[str, float]:
        """One iteration: ``steps_per_env`` steps of every environment, each followed by its gradient steps."""
        cfg, n = self.cfg, self.cfg.num_envs
        t0 = time.perf_counter()
        timing = self.sampler.timing
        env0, inf0 = timing.env, timing.inference
        episodes: list[Episode] = []
        stats: list[SACStats] = []
        env_steps = 0
        t_update = 0.0
        for _ in range(cfg.steps_per_env):
            try:
                batch, finished = self.sampler.collect(1)
            except NonFiniteError as e:
                raise NonFiniteError(f"{cfg.task}, iteration {self.iteration + 1}: {e}") from None
            s = self.sampler
            assert s.last_raw_obs is not None and s.last_raw_next_obs is not None and s.last_tau is not None
            rewards = batch.rewards[0].numpy() * cfg.reward_scale
            terminated = batch.terminated[0].numpy()
            done = terminated | batch.truncated[0].numpy()
            actions = self.policy.to_hybrid(batch.actions[0]).numpy()
            path = s.last_path[0] if s.last_path is not None else None
            self.buffer.add(s.last_raw_obs[0], s.last_raw_next_obs[0], actions, rewards, batch.discount[0].numpy(),
                            terminated, done, s.last_tau[0], path)  # fmt: skip
            episodes += finished
            env_steps += batch.env_steps
            self.decisions += n
            if self.decisions > cfg.sac.learning_starts:  # the decisions collected past learning_starts each earn updates
                self._owed += (self.decisions - max(self.decisions - n, cfg.sac.learning_starts)) * cfg.sac.updates_per_step
                t1 = time.perf_counter()
                while self._owed >= 1:
                    self._owed -= 1
                    stats.append(self.update.step(self._minibatch()))
                    self.gradient_steps += 1
                t_update += time.perf_counter() - t1
        self.iteration += 1
        self.env_steps += env_steps
        self.episodes_done += len(episodes)
        wall = time.perf_counter() - t0
        out: dict[str, float] = {
            **iteration_stats(self, episodes),
            **{f"sac/{k}": mean_or_nan([getattr(st, k) for st in stats]) for k in SACStats.__dataclass_fields__},
            "sac/gradient_steps": self.gradient_steps,
            "sac/buffer_size": self.buffer.size,
            "time/env_share": (timing.env - env0) / wall,
            "time/inference_share": (timing.inference - inf0) / wall,
            "time/update_share": t_update / wall,
            "time/steps_per_s": env_steps / wall,
        }
        if cfg.macro is not None:
            out["manager/decisions"] = cfg.steps_per_env * n
            out["manager/mean_tau"] = env_steps / (cfg.steps_per_env * n)
        return out

    def _minibatch(self) -> SACBatch:
        raw = self.buffer.sample(self.cfg.sac.batch_size, self.rng)
        f32 = torch.float32

        def norm(x: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(self.normalizer.normalize(x), dtype=f32)

        def tensor(name: str) -> torch.Tensor:
            return torch.as_tensor(raw[name], dtype=f32)

        return SACBatch(norm(raw["obs"]), tensor("actions"), tensor("rewards"), tensor("discount"), tensor("terminated"),
                        norm(raw["next_obs"]))  # fmt: skip

    # --- persistence --------------------------------------------------------------------------
    def state(self) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
        """Tensors and JSON metadata of the whole training state, the replay buffer included."""
        tensors = {**module_tensors("policy", self.policy), **self.update.state()}
        tensors.update({f"normalizer.{k}": v for k, v in self.normalizer.state_dict().items()})
        rng_tensors, rng_meta = pack_generators({"replay": self.rng}, {"actions": self.sampler.generator})
        tensors.update(rng_tensors)
        buffer_tensors, buffer_meta = self.buffer.state()
        tensors.update(buffer_tensors)
        meta = {
            **rng_meta,
            **run_meta(self),
            "replay": buffer_meta,
            "decisions": self.decisions,
            "gradient_steps": self.gradient_steps,
            "owed_updates": self._owed,
        }
        if self.policy.kind == "box":
            meta["act_dim"] = self.policy.s
        return tensors, meta

    @classmethod
    def restore(cls, directory: Path, tensors: dict[str, torch.Tensor], meta: dict[str, Any], cfg: TrainConfig
                ) -> OffPolicyTrainer:  # fmt: skip
        """The trainer of a checkpoint read from ``directory``: it continues exactly where that run was (on CPU, with
        environments that save their exact state, as hrlp's do)."""
        trainer = cls(cfg, from_checkpoint=True)
        check_skill_hashes(meta.get("skills", {}), trainer.skill_hashes, directory)
        check_action_units(meta, trainer.action_units, directory)
        load_module("policy", trainer.policy, tensors)
        trainer.update.load_state(tensors)
        trainer.normalizer.load_state_dict({k.removeprefix("normalizer."): v for k, v in tensors.items()
                                            if k.startswith("normalizer.")})  # fmt: skip
        unpack_generators(tensors, meta, {"replay": trainer.rng}, {"actions": trainer.sampler.generator})
        trainer.buffer.load_state(tensors, meta["replay"])
        trainer.sampler.set_state(meta["sampler"])
        trainer.iteration, trainer.env_steps = int(meta["iteration"]), int(meta["env_steps"])
        trainer.episodes_done, trainer.decisions = int(meta["episodes_done"]), int(meta["decisions"])
        trainer.gradient_steps, trainer._owed = int(meta["gradient_steps"]), float(meta["owed_updates"])
        return trainer

    def save(self, directory: Path) -> Path:
        """Write the whole state atomically to ``directory``; a NaN or inf in the networks or the optimisers is refused
        (:class:`~hrlp.rollout.NonFiniteError`, nothing written: the previous checkpoint stays)."""
        tensors, meta = self.state()
        for name, tensor in tensors.items():  # the buffer's data was checked as it was sampled
            if name.startswith("replay.") or not tensor.is_floating_point():
                continue
            if (where := first_non_finite(tensor)) is not None:
                raise NonFiniteError(f"{self.cfg.task}, iteration {self.iteration}: {name}{list(where)} is "
                                     f"{float(tensor[where])}; refusing to save it over the checkpoint in "
                                     f"{directory}")  # fmt: skip
        return save_checkpoint(directory, tensors, meta)

    def close(self) -> None:
        """Close the environments."""
        self.sampler.close()
        if self._scorer is not None:
            self._scorer.close()
