"""A goal-conditioned environment outside hrlp for the generic-skill tests and the tutorial: a point on a plane.

``PointGoal-v0``: Gymnasium-Robotics' conventions (a Dict observation with ``observation`` [x, y, vx, vy],
``achieved_goal`` [x, y] and ``desired_goal`` [gx, gy]; ``info['is_success']``; ``compute_reward``), a Box(2)
action (the velocity, at most 1 per axis), positions in [-1, 1]^2, steps of 0.1 s, 40 steps an episode, success
within 0.1 of the goal, sparse reward -1 until then. The module also holds scripted skills (``reach``, ``near_goal``)
and a function that returns one (``wander``), the ``MODULE:NAME`` references the tests use.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from hrlp.skills import ObsView, ParamBox, ScriptedSkill

DT, RADIUS = 0.1, 0.1


class PointGoal(gym.Env):
    """A point steered by its velocity towards a goal on the plane (see the module docstring)."""

    def __init__(self) -> None:
        box = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)
        whole = gym.spaces.Box(-np.inf, np.inf, shape=(4,), dtype=np.float64)
        self.observation_space = gym.spaces.Dict({"observation": whole, "achieved_goal": box, "desired_goal": box})
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)
        self._pos, self._vel, self._goal = np.zeros(2), np.zeros(2), np.zeros(2)

    def _obs(self) -> dict[str, np.ndarray]:
        return {"observation": np.concatenate([self._pos, self._vel]), "achieved_goal": self._pos.copy(),
                "desired_goal": self._goal.copy()}  # fmt: skip

    def compute_reward(self, achieved: np.ndarray, desired: np.ndarray, info: Any) -> np.ndarray:
        return -(np.linalg.norm(np.asarray(achieved) - desired, axis=-1) > RADIUS).astype(np.float64)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        self._pos = self.np_random.uniform(-0.9, 0.9, 2)
        self._goal = self.np_random.uniform(-0.9, 0.9, 2)
        self._vel = np.zeros(2)
        return self._obs(), {"is_success": 0.0}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        self._vel = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        self._pos = np.clip(self._pos + DT * self._vel, -1.0, 1.0)
        success = bool(np.linalg.norm(self._pos - self._goal) <= RADIUS)
        reward = float(self.compute_reward(self._pos, self._goal, None))
        return self._obs(), reward, success, False, {"is_success": float(success)}


gym.register("PointGoal-v0", entry_point=PointGoal, max_episode_steps=40)


def _towards(obs: ObsView, params: np.ndarray) -> np.ndarray:
    return np.clip(8.0 * (params - obs["achieved_goal"]), -1.0, 1.0)


#: A scripted skill: drive the point to the parameter (a point of the plane), ending once within 2 cm of it.
reach = ScriptedSkill("reach", ParamBox.of([-1, -1], [1, 1], "the point to go to (x, y)"), _towards,
                      reads=("achieved_goal",), k=10,
                      done=lambda obs, p: np.linalg.norm(obs["achieved_goal"] - p, axis=1) < 0.02)  # fmt: skip


#: A scripted skill whose parameters are offsets of at most 5 cm from the goal (its frame, ``desired_goal``).
_NEAR = ParamBox.of([-0.05, -0.05], [0.05, 0.05], "offset from the goal (x, y)", frame="desired_goal")
near_goal = ScriptedSkill("near_goal", _NEAR, _towards, reads=("achieved_goal",), k=10)


def wander() -> ScriptedSkill:
    """A skill built by a function: move at a constant velocity (its parameters) for 5 steps."""
    return ScriptedSkill("wander", ParamBox.of([-1, -1], [1, 1], "velocity (vx, vy)"), lambda obs, p: p, k=5)
