"""Small Gymnasium environments with action spaces other than Box, registered for the tests."""

import gymnasium as gym
import numpy as np


class PickAndPoint(gym.Env):
    """A parameterised-action bandit: observe x in [-1, 1]; choose arm 0 with a 1-d parameter, or arm 1 with none.

    Arm 0 pays 1 - (u - x)^2 (best: u = x, worth up to 1), arm 1 pays 0.5. An optimal policy always takes arm 0 and
    copies x into its parameter (mean reward 1); a policy that ignores the parameter earns less than arm 1 does.
    """

    def __init__(self, horizon: int = 8) -> None:
        self.observation_space = gym.spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float64)
        self.action_space = gym.spaces.Tuple(
            (gym.spaces.Discrete(2), gym.spaces.Box(-2.0, 2.0, shape=(1,)), gym.spaces.Box(-1.0, 1.0, shape=(0,)))
        )
        self.horizon, self._t, self._x = horizon, 0, np.zeros(1)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._t = 0
        self._x = self.np_random.uniform(-1, 1, size=1)
        return self._x.copy(), {}

    def step(self, action):
        k, u, _ = action
        r = 1.0 - float((np.asarray(u)[0] - self._x[0]) ** 2) if int(k) == 0 else 0.5
        self._t += 1
        self._x = self.np_random.uniform(-1, 1, size=1)
        return self._x.copy(), r, False, self._t >= self.horizon, {}


class MultiDiscreteAction(gym.Env):
    """An environment whose MultiDiscrete action space hrlp does not train on."""

    observation_space = gym.spaces.Box(-1.0, 1.0, shape=(1,))
    action_space = gym.spaces.MultiDiscrete([2, 3])

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(1, dtype=np.float32), {}

    def step(self, action):
        return np.zeros(1, dtype=np.float32), 0.0, True, False, {}


def register() -> None:
    """Register the environments (idempotent)."""
    for name, cls in (("PickAndPoint", PickAndPoint), ("MultiDiscreteAction", MultiDiscreteAction)):
        env_id = f"hrlp_test/{name}-v0"
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=cls)
