"""Real hrlp MuJoCo environments that turn one number bad at a chosen step, for the reliability tests.

:class:`Poisoned` wraps a real task (physics, rewards and resets untouched) and, in the environment reset first with
``poison_seed`` (the sampler resets environment ``i`` first with ``seed + i``), replaces one number: the reward or an
observation entry at steps ``at_step`` to ``at_step + repeat - 1`` of its first episode, or an observation entry at its
``at_step``-th reset. ``value`` may be a string (``"nan"``, ``"inf"``) so that the training config stays strict JSON.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

ENV_ID = "hrlp_reliability/Poisoned-v0"


class Poisoned(gym.Wrapper):
    """``env`` with one number replaced by ``value`` (see the module docstring)."""

    def __init__(self, env: gym.Env, field: str = "reward", at_step: int = 1, poison_seed: int = 0, value: float | str = "nan",
                 index: int = 0, repeat: int = 1) -> None:  # fmt: skip
        super().__init__(env)
        if field not in ("reward", "observation", "reset"):
            raise ValueError(f"field must be reward, observation or reset, got {field!r}")
        # A string ("nan", "inf", "-inf") keeps the training config that carries it strict JSON.
        self.field, self.at_step, self.poison_seed, self.value, self.index = field, at_step, poison_seed, float(value), index
        self.repeat = repeat
        self._armed, self._t, self._resets = False, 0, 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        if seed is not None:
            self._armed = seed == self.poison_seed
        obs, info = self.env.reset(seed=seed, options=options)
        self._t = 0
        self._resets += 1
        if self.field != "reset" and self._resets > 1:  # steps are poisoned in the first episode only
            self._armed = False
        if self._armed and self.field == "reset" and self._resets == self.at_step:
            obs = obs.copy()
            obs[self.index] = self.value
            self._armed = False
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._t += 1
        if self._armed and self.field != "reset" and self.at_step <= self._t < self.at_step + self.repeat:
            if self.field == "reward":
                reward = self.value
            else:
                obs = obs.copy()
                obs[self.index] = self.value
        return obs, reward, terminated, truncated, info


def make_poisoned(task: str = "Reacher", episode_steps: int = 30, **kwargs: Any) -> Poisoned:
    """A real hrlp task (``hrlp.envs.make``) behind :class:`Poisoned`."""
    from hrlp.arm import make

    return Poisoned(make(task, episode_steps=episode_steps), **kwargs)


def register() -> None:
    """Register :data:`ENV_ID` (idempotent)."""
    if ENV_ID not in gym.registry:
        gym.register(ENV_ID, entry_point=make_poisoned, disable_env_checker=True)


register()
