"""A short-episode environment outside hrlp whose registration declares no episode length: ``AngleShot-v0``."""

import gymnasium as gym
import numpy as np


class AngleShot(gym.Env):
    """Four shots at a target angle in [0, 720] degrees; the episode ends itself (no time limit registered).

    The action space is nested, ``Tuple(Discrete(2), Tuple(Box(0, 720, (1,)), Box(-1, 1, (1,))))``: choice 0 aims
    (its parameter the angle, paying ``1 - (error / 120)^2``, at least 0), choice 1 holds (paying 0.25). Aiming at the
    target every time is optimal: a return of 4.
    """

    OPTIMUM = 4.0

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(0.0, 720.0, shape=(1,), dtype=np.float64)
        blocks = gym.spaces.Tuple((gym.spaces.Box(0.0, 720.0, shape=(1,)), gym.spaces.Box(-1.0, 1.0, shape=(1,))))
        self.action_space = gym.spaces.Tuple((gym.spaces.Discrete(2), blocks))
        self._t, self._target = 0, np.zeros(1)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._t, self._target = 0, self.np_random.uniform(0.0, 720.0, size=1)
        return self._target.copy(), {}

    def step(self, action):
        k, (angle, _) = action
        error = abs(float(np.asarray(angle)[0]) - float(self._target[0]))
        r = max(0.0, 1.0 - (error / 120.0) ** 2) if int(k) == 0 else 0.25
        self._t += 1
        self._target = self.np_random.uniform(0.0, 720.0, size=1)
        return self._target.copy(), r, self._t >= 4, False, {}


if "AngleShot-v0" not in gym.registry:
    gym.register("AngleShot-v0", entry_point=AngleShot)
