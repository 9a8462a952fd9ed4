"""Scripted skills for Gymnasium-Robotics' PointMaze (``PointMaze_Open-v3``, ``PointMaze_UMaze-v3``, ...), the
``MODULE:NAME`` references of ``tests/skills/test_robotics_slow.py``.

PointMaze: a Dict observation with ``observation`` [x, y, vx, vy], ``achieved_goal`` [x, y] and ``desired_goal``
[gx, gy] (metres); a Box(2) action in [-1, 1], a force on the ball (gear 100 on 4.19 kg: about 24 m/s^2 at full force,
speed clipped at 5 m/s, 0.01 s a step); sparse reward 1 while within 0.45 m of the goal, ``info['success']`` the same
test; by default a continuing task of 300 steps (no termination), so an episode succeeds when the ball is at the goal
at its last step. The open maze's free floor is x in [-2.5, 2.5], y in [-1.5, 1.5]; the ball's radius is 0.1 m.

Skills (each a PD controller on the ball's position and velocity, or an open-loop push):

* ``goto_goal``: go to a point at most 0.2 m from the goal (its parameters: the offset, frame ``desired_goal``), ending
  once within 5 cm of it: the useful skill.
* ``goto_point``: go to any point of the open maze's floor (absolute parameters), ending once within 5 cm of it: useful
  if the Manager learns to aim it at the goal.
* ``goto_point_u``: the same on the U-maze's floor (``PointMaze_UMaze-v3``), where the goal may lie behind the inner
  wall from the ball: a waypoint round it.
* ``push``: push with a constant force (its parameters) for 20 steps, whatever the goal: not useful on its own.
"""

from __future__ import annotations

import numpy as np

from hrlp.skills import ObsView, ParamBox, ScriptedSkill, Skill

#: PD gains on the position error (per metre) and the velocity (per m/s), in the action's units: checked by hand to
#: reach any point of the open maze in at most about 100 steps and to stay within 5 cm of it.
KP, KD = 5.0, 0.8
#: A goto skill ends once the ball is this close to its point (metres).
WITHIN = 0.05


def _pd(obs: ObsView, target: np.ndarray) -> np.ndarray:
    """Force towards ``target [M, 2]``, damped by the ball's velocity (``observation``'s last two numbers)."""
    return np.clip(KP * (target - obs["achieved_goal"]) - KD * obs["observation"][:, 2:4], -1.0, 1.0)


class Goto(Skill):
    """Go to a point (its parameters, in ``params``' box and frame) under PD control, for at most ``k`` steps, ending
    once within :data:`WITHIN` of it if it started farther away: started at its point, it holds the ball there for its
    ``k`` steps rather than ending after one (which would make a Manager at the goal decide at every step)."""

    def __init__(self, name: str, params: ParamBox, k: int = 50) -> None:
        self.name, self.params, self.k = name, params, k
        self.reads = ("achieved_goal", "observation")
        self._travels = np.zeros(0, dtype=bool)  # per world (ObsView.idx): started farther than WITHIN from its point

    def begin(self, obs: ObsView, params: np.ndarray) -> None:
        if len(self._travels) <= obs.idx.max():
            self._travels = np.concatenate([self._travels, np.zeros(obs.idx.max() + 1 - len(self._travels), dtype=bool)])
        self._travels[obs.idx] = np.linalg.norm(obs["achieved_goal"] - params, axis=1) >= WITHIN

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        return _pd(obs, params)

    def done(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        return self._travels[obs.idx] & (np.linalg.norm(obs["achieved_goal"] - params, axis=1) < WITHIN)


def goto(name: str, params: ParamBox, k: int = 50) -> Goto:
    """A :class:`Goto` skill (a function, so that a test can build one with another box or duration)."""
    return Goto(name, params, k)


#: Go to a point near the goal: the offset (at most 0.2 m each way, well inside the 0.45 m success radius).
_NEAR_GOAL = ParamBox.of([-0.2, -0.2], [0.2, 0.2], "offset from the goal (x, y), metres", frame="desired_goal")
goto_goal = goto("goto_goal", _NEAR_GOAL)

#: Go to any point of the open maze's floor (ball centre at least 0.1 m from the outer walls).
goto_point = goto("goto_point", ParamBox.of([-2.4, -1.4], [2.4, 1.4], "point to go to (x, y), metres"))

#: Go to any point of the U-maze's floor (x, y in [-1.5, 1.5] but for the inner wall x in [-1.5, 0.5], y in
#: [-0.5, 0.5]; a point inside the wall leaves the ball pressed against it): a waypoint round the wall.
goto_point_u = goto("goto_point_u", ParamBox.of([-1.4, -1.4], [1.4, 1.4], "point to go to (x, y), metres"))

#: Push with a constant force for 20 steps (open loop: it neither aims at the goal nor stops).
push = ScriptedSkill("push", ParamBox.of([-1.0, -1.0], [1.0, 1.0], "force (fx, fy), action units"),
                     lambda obs, p: p, k=20)  # fmt: skip

#: Brake: damp the ball's velocity to a stop where it is, for 20 steps (no parameters; it never moves towards a goal).
brake = ScriptedSkill(
    "brake",
    ParamBox((), (), "no parameters"),
    lambda obs, p: np.clip(-KD * obs["observation"][:, 2:4], -1.0, 1.0),
    reads=("observation",),
    k=20,
)
