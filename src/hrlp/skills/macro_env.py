"""The environment the Manager acts in: each action runs a frozen skill for k low-level steps.

Section 1.1 and Figure 1: the Manager selects one of N macro-actions and passes it a vector of
parameters; the macro-action then emits joint torques for k steps (8, 10 or 15 in the paper),
or until the episode ends, and the Manager sees the state after it. The optional micro-action
gives the Manager direct torque control for ``micro_k`` steps.

Action space: ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))``: the choice, then one parameter
block per choice (the hierarchical distribution fills every block; only the chosen one is
used). A macro-action lasting tau low-level steps returns the discounted in-macro reward
``sum_j gamma^j r_j`` and ``info['discount'] = gamma^tau``, the factor the Manager's return and
advantage estimator apply to the next decision (semi-Markov discounting).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from hrlp.envs.arm_env import ArmEnv
from hrlp.envs.physics import BASE_OBS_DIM, N_JOINTS
from hrlp.skills.skill import Skill


@dataclass(frozen=True)
class MicroAction:
    """The micro-action: direct torques for ``duration`` steps, optionally penalised."""

    duration: int = 1
    """Low-level steps the torques are held for."""
    penalty: float = 0.0
    """Subtracted from the Manager's reward each time the micro-action is chosen (Appendix C)."""
    max_torque: float = 1.0
    """Bound on the micro-action's torques (Appendix C: bounds on micro-actions), in (0, 1]."""

    def __post_init__(self) -> None:
        if isinstance(self.duration, bool) or not isinstance(self.duration, int) or self.duration < 1:
            raise ValueError(f"MicroAction.duration must be a positive integer, got {self.duration!r}")
        if not (self.penalty >= 0):
            raise ValueError(f"MicroAction.penalty must be >= 0, got {self.penalty!r}")
        if not (0 < self.max_torque <= 1):
            raise ValueError(f"MicroAction.max_torque must be in (0, 1], got {self.max_torque!r}")


class MacroEnv(gym.Env):
    """A Manager's view of an arm task: choose a skill (or the micro-action) and its parameters.

    Args:
        env: the low-level task (an :class:`ArmEnv`).
        skills: the frozen skills the Manager may choose, in order.
        k: steps per skill call (None: each skill's own default k).
        micro: the micro-action, or None for none. With no skills and a micro-action this is the flat
            baseline through the same code.
        gamma: the low-level discount used inside a macro-action.
    """

    metadata = {"render_modes": ["rgb_array"]}  # noqa: RUF012 (Gymnasium's convention)

    def __init__(self, env: ArmEnv, skills: Sequence[Skill], k: int | None = None, micro: MicroAction | None = None,
                 gamma: float = 0.99) -> None:  # fmt: skip
        if not skills and micro is None:
            raise ValueError("MacroEnv needs at least one skill or the micro-action")
        if k is not None and (isinstance(k, bool) or not isinstance(k, int) or k < 1):
            raise ValueError(f"k must be a positive integer, got {k!r}")
        if not (0 < gamma <= 1):
            raise ValueError(f"gamma must be in (0, 1], got {gamma!r}")
        self.env, self.skills, self.micro, self.gamma = env, list(skills), micro, float(gamma)
        self.durations = [k or s.k for s in self.skills] + ([micro.duration] if micro else [])
        self.names = [s.name for s in self.skills] + (["micro"] if micro else [])
        blocks = [gym.spaces.Box(np.array(s.param.low), np.array(s.param.high), dtype=np.float64) for s in self.skills]
        if micro:
            blocks.append(gym.spaces.Box(-micro.max_torque, micro.max_torque, shape=(N_JOINTS,), dtype=np.float64))
        self.param_dims = tuple(int(b.shape[0]) for b in blocks)
        self.action_space = gym.spaces.Tuple((gym.spaces.Discrete(len(blocks)), *blocks))
        self.observation_space = env.observation_space
        self.render_mode = env.render_mode
        self._obs = np.zeros(env.observation_space.shape)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Reset the low-level task."""
        super().reset(seed=seed)
        self._obs, info = self.env.reset(seed=seed, options=options)
        return self._obs.copy(), info

    def step(self, action: tuple) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Run the chosen macro-action; returns the discounted in-macro reward and ``info['discount']`` = gamma^tau."""
        if not isinstance(action, tuple | list) or len(action) != 1 + len(self.param_dims):
            raise ValueError(
                f"Manager action must be a tuple (choice, {len(self.param_dims)} parameter blocks), got {action!r}"
            )
        choice = int(action[0])
        if not 0 <= choice < len(self.param_dims):
            raise ValueError(f"Manager choice must be in [0, {len(self.param_dims)}), got {choice}")
        block = self.action_space.spaces[1 + choice]
        params = np.asarray(action[1 + choice], dtype=np.float64).reshape(-1)
        if params.shape != block.shape:
            raise ValueError(f"parameters of {self.names[choice]} must have shape {block.shape}, got {params.shape}")
        if not np.isfinite(params).all():
            raise ValueError(f"parameters of {self.names[choice]} contain NaN or inf: {params.tolist()}")
        params = np.clip(params, block.low, block.high)
        is_micro = choice == len(self.skills)
        total, discount, tau = 0.0, 1.0, 0
        terminated = truncated = False
        info: dict[str, Any] = {}
        for _ in range(self.durations[choice]):
            if is_micro:
                torques = params
            else:
                torques = self.skills[choice].act(self._obs[None, :BASE_OBS_DIM], params[None])[0]
            self._obs, r, terminated, truncated, info = self.env.step(torques)
            total += discount * r
            discount *= self.gamma
            tau += 1
            if terminated or truncated:
                break
        if is_micro and self.micro is not None:
            total -= self.micro.penalty
        info = {**info, "tau": tau, "discount": discount, "macro": self.names[choice]}
        return self._obs.copy(), total, terminated, truncated, info

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """The low-level task's frame."""
        return self.env.render()

    def close(self) -> None:
        """Close the low-level task."""
        self.env.close()
