"""The replay buffer of off-policy learning, with semi-Markov transitions and goal relabelling.

A transition is one decision of one environment: for a flat policy one environment step; for a Manager one
macro-action of ``tau`` low-level steps, whose reward is the discounted sum inside it and whose discount is
``gamma ** tau`` (:class:`~hrlp.envs.vector.VectorStep`'s fields, stored as they come). The buffer is a ring of
``ceil(capacity / N)`` rows of ``N`` environments, the layout of Stable-Baselines3's buffers; observations are kept
raw (``float32``) and normalised when a minibatch is drawn, with the statistics of that moment.

Memory: ``4 (2 D + A + 2) + 11`` bytes per transition for ``D`` observation numbers and ``A`` action numbers
(:meth:`ReplayBuffer.nbytes`), allocated when the run starts.

Goal relabelling (HER, Andrychowicz et al. 2017, the ``future`` strategy) applies where the environment is
goal-conditioned (:class:`GoalSpec`): a share ``her_future / (her_future + 1)`` of each minibatch gets, in place of
its desired goal, the goal achieved after a transition drawn uniformly from itself to the end of its episode (so
far, for an episode still running), and the reward the environment's ``compute_reward`` gives for it. A Manager's
macro-transition is relabelled with the goal achieved at its end; its reward is that of every low-level step inside
it, ``sum_{j < tau} gamma^j r(achieved_j, goal)``, from the achieved goals of those steps, which the buffer keeps
(``path_len`` of them per transition, ``4 path_len G`` bytes for a ``G``-number goal). Without them (``path_len`` 0)
the end state stands for every step, ``r(achieved_tau, goal) sum_{j < tau} gamma^j``, which scores a macro-action that
reaches the goal only at its last step as if it had been there throughout. A skill whose parameters are offsets from
the desired goal (its ``ParamBox.frame`` lies there) keeps the points it was given: its stored block is re-expressed
from the relabelled goal (:attr:`GoalSpec.reframe`), and a transition whose point lies outside the box seen from there
keeps its own goal.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

__all__ = ["GoalSpec", "Reframe", "ReplayBuffer"]

#: ``reframe(actions [B, A], obs [B, D], relabelled obs [B, D]) -> (actions, representable [B] bool)``.
Reframe = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class GoalSpec:
    """Where a goal-conditioned environment's goals sit in its flat observation, and how it scores them."""

    achieved: slice
    """The columns of ``achieved_goal``."""
    desired: slice
    """The columns of ``desired_goal``."""
    compute_reward: Callable[[np.ndarray, np.ndarray, dict], Any]
    """The environment's ``compute_reward(achieved [B, G], desired [B, G], info)`` -> ``[B]`` (Gymnasium's GoalEnv
    convention: batched goals; ``info`` is given as ``{}``)."""
    compute_terminated: Callable[[np.ndarray, np.ndarray, dict], Any] | None = None
    """Its ``compute_terminated`` where it has one: a relabelled transition's end; without one the stored flag stays."""
    reframe: Reframe | None = None
    """For a Manager whose parameters are offsets from a part of the desired goal: ``reframe(actions [B, A], obs [B, D],
    relabelled obs [B, D]) -> (actions, representable [B] bool)``, the actions that pass the same points from the
    relabelled goal, and whether they fit the parameters' box (a transition whose do not keeps its own goal)."""


_FIELDS = ("obs", "next_obs", "actions", "rewards", "discount", "terminated", "tau", "episode_end")


class ReplayBuffer:
    """``capacity`` transitions of ``num_envs`` environments stepped together (rounded up to whole rows of ``N``).

    Args:
        capacity: transitions kept; the oldest row is overwritten once full.
        num_envs: ``N``, the environments of each :meth:`add`.
        obs_dim: ``D``, raw observation numbers.
        act_dim: ``A``, numbers of a stored action row.
        gamma: the low-level discount (for a relabelled macro-transition's reward).
        goals: the environment's goals (None: no relabelling).
        her_future: relabelled goals per real one (0: none).
        path_len: a Manager's longest macro-action, in low-level steps: the achieved goals of its steps are kept to
            score a relabelled macro-transition step by step (0: scored by its end state; used only with ``goals``).
        reward_scale: the factor the stored rewards were multiplied by, applied to relabelled rewards alike.
    """

    def __init__(self, capacity: int, num_envs: int, obs_dim: int, act_dim: int, gamma: float,
                 goals: GoalSpec | None = None, her_future: int = 4, path_len: int = 0,
                 reward_scale: float = 1.0) -> None:  # fmt: skip
        if capacity < 1 or num_envs < 1:
            raise ValueError(f"a replay buffer needs capacity and num_envs >= 1, got {capacity} and {num_envs}")
        self.rows, self.num_envs, self.gamma = math.ceil(capacity / num_envs), num_envs, float(gamma)
        self.goals, self.her_future = goals, int(her_future) if goals is not None else 0
        self.reward_scale = float(reward_scale)
        r, n = self.rows, num_envs
        self.obs = np.zeros((r, n, obs_dim), np.float32)
        self.next_obs = np.zeros((r, n, obs_dim), np.float32)
        self.actions = np.zeros((r, n, act_dim), np.float32)
        self.rewards = np.zeros((r, n), np.float32)
        self.discount = np.zeros((r, n), np.float32)
        self.terminated = np.zeros((r, n), np.bool_)
        self.tau = np.zeros((r, n), np.int16)
        self.episode_end = np.full((r, n), -1, np.int64)
        """The absolute row (counted from the first row ever written) of each transition's episode's last transition,
        -1 while the episode runs."""
        self.written = 0
        """Rows written so far (absolute); the row of the next :meth:`add` is ``written % rows``."""
        self.current_start = np.zeros(n, np.int64)
        """Per environment, the absolute row where its running episode started."""
        self.path: np.ndarray | None = None
        """``[rows, N, path_len, G]``: the goal achieved after each low-level step of a macro-transition (rows past its
        ``tau`` repeat its last); None unless relabelling with ``path_len`` > 0."""
        if self.her_future > 0 and goals is not None and path_len > 0:
            g = goals.achieved.stop - goals.achieved.start
            self.path = np.zeros((r, n, int(path_len), g), np.float32)

    @property
    def size(self) -> int:
        """Transitions held."""
        return min(self.written, self.rows) * self.num_envs

    def nbytes(self) -> int:
        """Bytes of the stored arrays (the whole capacity, allocated up front)."""
        return sum(getattr(self, name).nbytes for name in self._fields)

    @property
    def _fields(self) -> tuple[str, ...]:
        return (*_FIELDS, "path") if self.path is not None else _FIELDS

    def add(self, obs: np.ndarray, next_obs: np.ndarray, actions: np.ndarray, rewards: np.ndarray, discount: np.ndarray,
            terminated: np.ndarray, done: np.ndarray, tau: np.ndarray, path: np.ndarray | None = None) -> None:  # fmt: skip
        """One decision of every environment: raw ``obs``/``next_obs`` ``[N, D]`` (``next_obs`` the real last one where an
        episode ended), ``actions`` ``[N, A]``, ``rewards``, ``discount`` (gamma^tau), ``terminated``, ``done``
        (terminated or truncated: the episode ended) and ``tau``, each ``[N]``; ``path`` ``[N, K, D]`` the raw
        observations after each low-level step of a macro-transition, rows past ``tau`` repeating the last (kept where
        the buffer keeps paths; None: ``next_obs`` stands for every step)."""
        row, t = self.written % self.rows, self.written
        self.obs[row], self.next_obs[row], self.actions[row] = obs, next_obs, np.asarray(actions).reshape(self.num_envs, -1)
        if self.path is not None:
            assert self.goals is not None
            k = self.path.shape[2]
            if path is None:
                self.path[row] = np.asarray(next_obs)[:, None, self.goals.achieved]
            else:
                path = np.asarray(path)
                if path.shape[:2] != (self.num_envs, k) or path.shape[2] != self.obs.shape[2]:
                    raise ValueError(f"a macro-transition's path has shape {list(path.shape)}, expected "
                                     f"{[self.num_envs, k, self.obs.shape[2]]}")  # fmt: skip
                self.path[row] = path[:, :, self.goals.achieved]
        self.rewards[row], self.discount[row], self.terminated[row], self.tau[row] = rewards, discount, terminated, tau
        self.episode_end[row] = -1
        for i in np.flatnonzero(done):
            first = max(int(self.current_start[i]), t - self.rows + 1)  # rows of the episode still held
            self.episode_end[np.arange(first, t + 1) % self.rows, i] = t
            self.current_start[i] = t + 1
        self.written += 1

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """``batch_size`` transitions drawn uniformly (with replacement), goals relabelled where the buffer relabels:
        ``obs``, ``next_obs`` (raw), ``actions``, ``rewards``, ``discount``, ``terminated`` (float 0/1)."""
        if self.written == 0:
            raise ValueError("the replay buffer is empty")
        held = min(self.written, self.rows)
        t = self.written - held + rng.integers(0, held, batch_size)  # absolute rows
        env = rng.integers(0, self.num_envs, batch_size)
        row = t % self.rows
        out = {
            "obs": self.obs[row, env].copy(),
            "next_obs": self.next_obs[row, env].copy(),
            "actions": self.actions[row, env],
            "rewards": self.rewards[row, env].astype(np.float32),
            "discount": self.discount[row, env],
            "terminated": self.terminated[row, env].astype(np.float32),
        }
        if self.her_future > 0 and self.goals is not None:
            self._relabel(out, t, env, rng)
        return out

    def _relabel(self, out: dict[str, np.ndarray], t: np.ndarray, env: np.ndarray, rng: np.random.Generator) -> None:
        g = self.goals
        assert g is not None
        share = self.her_future / (self.her_future + 1)
        chosen = np.flatnonzero(rng.random(len(t)) < share)
        if chosen.size == 0:
            return
        t, env = t[chosen], env[chosen]
        end = self.episode_end[t % self.rows, env]
        end = np.where(end < 0, self.written - 1, end)  # an episode still running: so far
        future = t + np.floor(rng.random(len(t)) * (end - t + 1)).astype(np.int64)
        goal = self.next_obs[future % self.rows, env, g.achieved]
        obs, next_obs = out["obs"], out["next_obs"]
        if g.reframe is not None:  # parameters framed on the goal: the same points, seen from the relabelled goal
            relabelled = obs[chosen].copy()
            relabelled[:, g.desired] = goal
            actions, ok = g.reframe(out["actions"][chosen], obs[chosen], relabelled)
            out["actions"] = out["actions"].copy()
            out["actions"][chosen[ok]] = actions[ok]
            chosen, t, env, goal = chosen[ok], t[ok], env[ok], goal[ok]
            if chosen.size == 0:
                return
        obs[chosen, g.desired] = goal
        next_obs[chosen, g.desired] = goal
        achieved = next_obs[chosen, g.achieved]
        tau = self.tau[t % self.rows, env].astype(np.float64)
        rewards = out["rewards"].copy()
        if self.path is not None:  # every low-level step scored: sum_{j < tau} gamma^j r(achieved_j, goal)
            steps = self.path[t % self.rows, env]  # [B, K, G]
            b, k, width = steps.shape
            per_step = g.compute_reward(steps.reshape(b * k, width), np.repeat(goal, k, axis=0), {})
            per_step = np.asarray(per_step, np.float64).reshape(b, k)
            j = np.arange(k)
            weights = np.where(j[None] < tau[:, None], self.gamma ** j[None], 0.0)
            rewards[chosen] = self.reward_scale * (per_step * weights).sum(axis=1)
        else:
            reward = np.asarray(g.compute_reward(achieved, goal, {}), np.float64).reshape(-1)
            # sum_{j < tau} gamma^j: 1 for a flat step (tau = 1); tau itself when gamma is 1.
            span = (1 - self.gamma**tau) / (1 - self.gamma) if self.gamma < 1 else tau
            rewards[chosen] = self.reward_scale * reward * span
        out["rewards"] = rewards
        if g.compute_terminated is not None:
            ended = np.broadcast_to(np.asarray(g.compute_terminated(achieved, goal, {}), np.float32), (len(chosen),))
            terminated = out["terminated"].copy()
            terminated[chosen] = ended
            out["terminated"] = terminated

    # --- persistence --------------------------------------------------------------------------
    def state(self) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
        """The rows written so far as tensors (``replay.<field>``) and the counters as JSON: a resumed buffer draws the
        same minibatches."""
        held = min(self.written, self.rows)
        tensors = {f"replay.{name}": torch.from_numpy(np.ascontiguousarray(getattr(self, name)[:held]))
                   for name in self._fields}  # fmt: skip
        tensors["replay.current_start"] = torch.from_numpy(self.current_start.copy())
        return tensors, {"written": self.written, "rows": self.rows, "num_envs": self.num_envs}

    def load_state(self, tensors: dict[str, torch.Tensor], meta: dict[str, Any]) -> None:
        """Restore :meth:`state` (the capacity and the number of environments must be those saved)."""
        if meta.get("rows") != self.rows or meta.get("num_envs") != self.num_envs:
            raise ValueError(f"the saved replay buffer has {meta.get('rows')} rows of {meta.get('num_envs')} environments, "
                             f"this run's {self.rows} of {self.num_envs}")  # fmt: skip
        written = int(meta["written"])
        held = min(written, self.rows)
        for name in self._fields:
            if name == "path" and "replay.path" not in tensors:  # saved without paths: the end state stands for each step
                assert self.path is not None and self.goals is not None
                self.path[:held] = self.next_obs[:held, :, None, self.goals.achieved]
                continue
            saved = tensors[f"replay.{name}"].numpy()
            target = getattr(self, name)
            if saved.shape != (held, *target.shape[1:]):
                raise ValueError(f"replay.{name} has shape {list(saved.shape)}, expected {[held, *target.shape[1:]]}")
            target[:held] = saved
        self.current_start[:] = tensors["replay.current_start"].numpy()
        self.written = written
