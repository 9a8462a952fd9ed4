"""Batched sampling: many environments stepped together, one policy call per step for all of them.

Per-observation policy calls, not physics, are what make RL libraries slow on small networks
(shared/PERFORMANCE.md), so the sampler keeps ``N`` environments in one process and asks the
policy for ``N`` actions at once. Time is accounted per phase (environment, inference) so a
training run can report where its wall time goes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import torch

from hrlp.policies.mlp import Policy
from hrlp.policies.normalizer import RunningNormalizer


@dataclass(frozen=True)
class Batch:
    """``T`` steps of ``N`` environments, time-major. Observations are normalised as the policy saw them."""

    obs: torch.Tensor  # [T, N, obs_dim] policy inputs
    next_obs: torch.Tensor  # [T, N, obs_dim] the observation after each step (the real final one at episode ends)
    actions: torch.Tensor  # [T, N, act_dim] actions as sampled (before clipping to the action space)
    rewards: torch.Tensor  # [T, N]
    terminated: torch.Tensor  # [T, N] bool: the MDP ended (no bootstrap)
    truncated: torch.Tensor  # [T, N] bool: cut by a time limit or fault (bootstrap from next_obs)

    @property
    def steps(self) -> int:
        """Environment steps in the batch (T * N)."""
        return self.rewards.numel()


@dataclass(frozen=True)
class Episode:
    """One finished episode's summary."""

    ret: float
    """Undiscounted return."""
    length: int
    """Steps."""
    success: bool | None
    """``info['success']`` at the end (Definition 1 on gripping tasks), None if the task has no success test."""
    target_dist_sum: float | None = None
    """TargetDistSum (reach-and-move, Movers), None elsewhere."""


@dataclass
class Timing:
    """Seconds spent per phase of sampling."""

    env: float = 0.0
    inference: float = 0.0


class Sampler:
    """Steps ``N`` environments with batched policy inference.

    Args:
        env_fns: one constructor per environment.
        policy: the policy; called once per step on ``[N, obs_dim]``.
        normalizer: observation normaliser. Its statistics stay fixed during a batch, so the policy and the value
            baseline see every observation of the batch normalised alike; they are updated with the batch's raw
            observations at its end (unless frozen).
        seed: environment ``i`` is reset first with ``seed + i``; actions use a torch generator seeded with ``seed``.
    """

    def __init__(
        self,
        env_fns: Sequence[Callable[[], gym.Env]],
        policy: Policy,
        normalizer: RunningNormalizer,
        seed: int = 0,
    ) -> None:
        if not env_fns:
            raise ValueError("Sampler needs at least one environment")
        self.envs = [fn() for fn in env_fns]
        self.policy = policy
        self.normalizer = normalizer
        space = self.envs[0].action_space
        if not isinstance(space, gym.spaces.Box):
            raise ValueError(f"flat training needs a Box action space, got {space}")
        self._low, self._high = space.low, space.high
        self.generator = torch.Generator().manual_seed(seed)
        self._obs = np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(self.envs)]).astype(np.float64)
        n = len(self.envs)
        self._ret = np.zeros(n)
        self._len = np.zeros(n, dtype=np.int64)
        self.timing = Timing()

    @property
    def num_envs(self) -> int:
        """N, the number of environments."""
        return len(self.envs)

    def collect(self, steps_per_env: int) -> tuple[Batch, list[Episode]]:
        """Run ``steps_per_env`` steps in every environment; returns the batch and the episodes that finished."""
        n, dim = self.num_envs, self._obs.shape[1]
        obs_buf = np.empty((steps_per_env, n, dim))
        next_buf = np.empty((steps_per_env, n, dim))
        rewards = np.empty((steps_per_env, n))
        terminated = np.zeros((steps_per_env, n), dtype=bool)
        truncated = np.zeros((steps_per_env, n), dtype=bool)
        actions_buf: np.ndarray | None = None
        episodes: list[Episode] = []
        next_raw = np.empty((n, dim))
        raw_buf = np.empty((steps_per_env, n, dim))
        for t in range(steps_per_env):
            t0 = time.perf_counter()
            raw_buf[t] = self._obs
            obs_buf[t] = self.normalizer.normalize(self._obs)
            actions = self.policy.act_numpy(obs_buf[t].astype(np.float32), self.generator)
            if actions_buf is None:
                actions_buf = np.empty((steps_per_env, *actions.shape))
            actions_buf[t] = actions
            clipped = np.clip(actions, self._low, self._high)
            t1 = time.perf_counter()
            for i, env in enumerate(self.envs):
                obs, r, term, trunc, info = env.step(clipped[i])
                rewards[t, i] = r
                next_raw[i] = obs
                self._ret[i] += r
                self._len[i] += 1
                if term or trunc:
                    terminated[t, i], truncated[t, i] = term, (trunc and not term)
                    episodes.append(self._finish(i, info))
                    obs, _ = env.reset()
                self._obs[i] = obs
            t2 = time.perf_counter()
            next_buf[t] = self.normalizer.normalize(next_raw)
            self.timing.inference += t1 - t0
            self.timing.env += t2 - t1
        assert actions_buf is not None
        if not self.normalizer.frozen:
            self.normalizer.update(raw_buf.reshape(-1, dim))
        f32 = torch.float32
        batch = Batch(
            obs=torch.as_tensor(obs_buf, dtype=f32),
            next_obs=torch.as_tensor(next_buf, dtype=f32),
            actions=torch.as_tensor(actions_buf, dtype=f32),
            rewards=torch.as_tensor(rewards, dtype=f32),
            terminated=torch.as_tensor(terminated),
            truncated=torch.as_tensor(truncated),
        )
        return batch, episodes

    @property
    def resumable(self) -> bool:
        """Whether every environment can save and restore its exact state (hrlp tasks can; most Gymnasium ids not)."""
        return all(hasattr(env.unwrapped, "get_state") for env in self.envs)

    def get_state(self) -> dict:
        """The sampler's progress (JSON): current observations, running returns, and each environment's exact state."""
        return {
            "obs": self._obs.tolist(),
            "ret": self._ret.tolist(),
            "len": self._len.tolist(),
            "envs": [env.unwrapped.get_state() for env in self.envs] if self.resumable else None,
        }

    def set_state(self, state: dict) -> None:
        """Restore :meth:`get_state`. Environments that cannot be restored keep their fresh episodes."""
        if state["envs"] is None or not self.resumable:
            return
        if len(state["envs"]) != self.num_envs:
            raise ValueError(f"saved sampler has {len(state['envs'])} environments, this one {self.num_envs}")
        for env, env_state in zip(self.envs, state["envs"], strict=True):
            env.unwrapped.set_state(env_state)
        self._obs[:] = state["obs"]
        self._ret[:] = state["ret"]
        self._len[:] = state["len"]

    def _finish(self, i: int, info: dict) -> Episode:
        success = info.get("success")
        tds = info.get("target_dist_sum")
        ep = Episode(
            ret=float(self._ret[i]),
            length=int(self._len[i]),
            success=None if success is None else bool(success),
            target_dist_sum=None if tds is None else float(tds),
        )
        self._ret[i] = 0.0
        self._len[i] = 0
        return ep

    def close(self) -> None:
        """Close every environment."""
        for env in self.envs:
            env.close()


def mean_or_nan(values: Sequence[float | None]) -> float:
    """Mean of the non-None values, NaN if there are none."""
    xs = [float(v) for v in values if v is not None]
    return sum(xs) / len(xs) if xs else math.nan
