"""A user's environments that fail, registered on import (``hrlp train fault_envs:Faulty-v0``): tests/test_clean_stops.py.

Each is a point on a line that moves by its action; the environment seeded with 1 at its first reset (the run's
environment 1: the sampler seeds environment ``i`` with ``seed + i``) is the faulty one where only one is."""

import time

import gymnasium as gym
import numpy as np


class Line(gym.Env):
    """Three numbers of observation, one of action; reward -|x|; never ends by itself (the time limit ends it)."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), dtype=np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), dtype=np.float32)

    def __init__(self) -> None:
        self._x, self._t, self.faulty = 0.0, 0, None

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if self.faulty is None and seed is not None:
            self.faulty = seed == 1
        self._x, self._t = 0.0, 0
        return self._obs(), {}

    def step(self, action):
        self._t += 1
        self._x += 0.1 * float(np.asarray(action).reshape(-1)[0])
        return self._obs(), -abs(self._x), False, False, {}

    def _obs(self) -> np.ndarray:
        return np.array([self._x, self._t / 100, 1.0])


class Faulty(Line):
    """Environment 1 raises at step 30 of its first episode, deep in the user's own code."""

    def step(self, action):
        out = super().step(action)
        if self.faulty and self._t == 30:
            self._physics()
        return out

    def _physics(self) -> None:
        raise RuntimeError("the solver diverged")


class WrongShape(Line):
    """Every step returns 5 numbers where the space declares 3."""

    def step(self, action):
        _, *rest = super().step(action)
        return (np.zeros(5), *rest)


class OldReset(Line):
    """``reset`` returns the observation alone, as the old Gym API (before 0.26) did."""

    def reset(self, *, seed=None, options=None):
        return super().reset(seed=seed, options=options)[0]


class SlowClose(Line):
    """Takes 20 s to close once it has stepped: a run stopped with it in this process (one sampling worker) is still
    stopping by then. (Built only to read its spaces, it closes at once.)"""

    def close(self) -> None:
        if self._t:
            time.sleep(20)


for name, cls in (("Faulty", Faulty), ("WrongShape", WrongShape), ("OldReset", OldReset), ("SlowClose", SlowClose)):
    gym.register(f"{name}-v0", entry_point=cls, max_episode_steps=100)
