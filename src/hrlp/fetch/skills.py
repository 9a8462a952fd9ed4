"""Skills for Gymnasium-Robotics' Fetch arm, from all three sources of the generic core (docs/fetch.md).

* ``reach``: moves the gripper to a point near the object, fingers held open; its parameters are the point's offset
  from the object (m). Trained by hrlp (SAC + HER on FetchReach-v4), shipped as the library skill ``fetch-reach``.
* ``grasp``: goes over the object, descends onto it and closes the fingers; no parameters. Scripted.
* ``carry``: moves the gripper to a point in the workspace (m, world frame), fingers held closed, carrying what they
  hold. Trained by Stable-Baselines3 (SAC + HER on FetchReach-v4), shipped as its ``.zip``.
* ``push``: pushes the object along the table toward a point (x, y; m, world frame): round behind it, lifted, then
  down and through. Scripted. ``push_near_goal`` is the same push aiming at an offset of at most 5 cm from the task's
  goal (``goal_xy``, a named part of ``desired_goal``): the Push Manager's, which starts from the goal itself.

Each is a :class:`~hrlp.skills.core.Skill` reading the parts :mod:`hrlp.fetch` names (``grip_pos``, ``object_pos``,
``gripper_state``, ...), so one definition serves FetchPush, FetchPickAndPlace and FetchSlide. Use them by reference,
``--skills hrlp.fetch.skills:reach,hrlp.fetch.skills:grasp,hrlp.fetch.skills:carry``. The two learned skills were
trained on FetchReach, where the fingers are blocked; they read FetchReach's observation through ``bind``
(:data:`hrlp.fetch.REACH_BIND`) and run with the gripper entry of their action held (:class:`~hrlp.skills.core.Holding`).

Fetch's action is a displacement of the gripper, ``0.05 m`` per unit per step, and a finger command (+1 opens, -1
closes); an episode is 50 steps.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np

from hrlp.fetch import REACH_BIND
from hrlp.skills.core import Holding, ObsView, ParamBox, ScriptedSkill, Seeing, Skill, Wrapped
from hrlp.skills.library import load_skill
from hrlp.skills.policy import from_sb3

#: Metres the gripper moves per unit of action per step (Fetch's ``pos_ctrl * 0.05``).
STEP_M = 0.05
#: Where Fetch's tasks put goals and objects: the initial gripper position (1.342, 0.749, 0.535) +- 0.15 m, the table's
#: top at z 0.425 and goals in the air up to 0.45 m above it (FetchPickAndPlace), with a margin.
WORKSPACE_LOW, WORKSPACE_HIGH = (1.05, 0.45, 0.40), (1.65, 1.05, 0.90)
#: Half the width of the Fetch tasks' object, metres (a 5 cm cube).
HALF_OBJECT = 0.025
OPEN, CLOSED = 1.0, -1.0
#: How high above the object's centre the closed fingers push it (m), and at most how fast (action units).
PUSH_HEIGHT, PUSH_SPEED = 0.0, 0.3
#: Within this distance of its point (m) the object is pushed: the push ends, and a push begun there stays still.
PUSHED_M = 0.02
#: The strike's run-up: how far behind the object's near side the gripper starts it (m).
RUN_UP_M = 0.05
#: The push begins only for a point at least this far from the object (m): a point moved a little, as a Manager's next
#: decision may move it, is not worth going round the object for.
BEGIN_M = 0.05
#: How far from the task's goal :data:`push_near_goal` may aim (m).
AIM_M = 0.05
#: What FetchReach's blocked fingers always read: its policies see them so wherever they run (:class:`Seeing`); shown
#: the fingers as they are (open, 0.05 m each), hrlp's reach stopped 8.5 to 10.9 cm from its points instead of 0.2 to 1.1 cm.
BLOCKED_FINGERS = {"gripper_state": (0.0, 0.0), "gripper_vel": (0.0, 0.0)}
#: The shipped Stable-Baselines3 file of the ``carry`` skill.
SB3_REACH = "fetch-reach-sb3.zip"


def _toward(target: np.ndarray, grip: np.ndarray, gain: float = 0.8) -> np.ndarray:
    """The displacement action that moves the gripper ``gain`` of the way to ``target`` this step, clipped to [-1, 1]."""
    return np.clip(gain * (target - grip) / STEP_M, -1.0, 1.0)


def _width(obs: ObsView) -> np.ndarray:
    """The fingers' opening, metres (both fingers' joint positions summed; 0.1 wide open)."""
    return obs["gripper_state"].sum(axis=1)


def _grasp_act(obs: ObsView, params: np.ndarray) -> np.ndarray:
    grip, obj = obs["grip_pos"], obs["object_pos"]
    rel = obj - grip
    above = np.linalg.norm(rel[:, :2], axis=1) > 0.01
    target = obj.copy()
    target[above, 2] += 0.03  # over the object first, then straight down onto it
    low = above & (grip[:, 2] < obj[:, 2] + 0.02)
    target[low] = np.concatenate([grip[low, :2], obj[low, 2:3] + 0.04], axis=1)  # up first: never sweep into it
    closing = (np.linalg.norm(rel, axis=1) < 0.01) | ((_width(obs) < 0.09) & (np.linalg.norm(rel, axis=1) < 0.02))
    out = np.empty((len(grip), 4))
    out[:, :3] = np.where(closing[:, None], 0.0, _toward(target, grip))
    out[:, 3] = np.where(closing, CLOSED, OPEN)
    return out


def _holding(obs: ObsView, params: np.ndarray | None = None) -> np.ndarray:
    """The object is between closed fingers: within 2 cm of the gripper with the fingers stopped on it."""
    width = _width(obs)
    return (np.linalg.norm(obs["object_rel_pos"], axis=1) < 0.02) & (width > 0.03) & (width < 0.07)


#: Descends onto the object from wherever it is near and closes the fingers; ends once it holds the object (scripted).
grasp = ScriptedSkill(
    "grasp", ParamBox((), ()), _grasp_act, reads=("grip_pos", "object_pos", "object_rel_pos", "gripper_state"), k=10,
    initiable=lambda obs: np.linalg.norm(obs["object_rel_pos"][:, :2], axis=1) < 0.05, done=_holding,
)  # fmt: skip


def _push_act(obs: ObsView, params: np.ndarray) -> np.ndarray:
    grip, obj = obs["grip_pos"], obs["object_pos"]
    d = params[:, :2] - obj[:, :2]
    dist = np.linalg.norm(d, axis=1, keepdims=True)
    u = np.where(dist > 1e-6, d / np.maximum(dist, 1e-6), np.array([1.0, 0.0]))
    g = grip[:, :2] - obj[:, :2]
    along = (g * u).sum(axis=1)
    lateral = np.linalg.norm(g - along[:, None] * u, axis=1)
    behind = obj[:, :2] - u * (HALF_OBJECT + 0.02)  # where the closed fingers touch the object's far side from the point
    low = grip[:, 2] < obj[:, 2] + PUSH_HEIGHT + 0.015
    in_line = (along < -HALF_OBJECT) & (lateral < 0.012)
    target = np.concatenate([behind, obj[:, 2:3] + 0.05], axis=1)  # around the object, above it
    at_behind = np.linalg.norm(grip[:, :2] - behind, axis=1) < 0.01
    target[at_behind | in_line, 2] = obj[at_behind | in_line, 2] + PUSH_HEIGHT  # down behind it
    lift = ~in_line & ~at_behind & low  # free the object before going round it
    target[lift] = np.concatenate([grip[lift, :2], obj[lift, 2:3] + 0.05], axis=1)
    pushing = in_line & low
    target[pushing, :2] = params[pushing, :2] - u[pushing] * (HALF_OBJECT + 0.015)
    out = np.empty((len(grip), 4))
    out[:, :3] = _toward(target, grip)
    out[pushing, :3] = np.clip(out[pushing, :3], -PUSH_SPEED, PUSH_SPEED)  # slowly: a pushed cube slides on
    # There, or near enough not to begin a push (one under way goes on to PUSHED_M): stay still rather than go round it
    # again and knock it off.
    out[(dist[:, 0] < PUSHED_M) | ((dist[:, 0] < BEGIN_M) & ~pushing), :3] = 0.0
    out[:, 3] = CLOSED
    return out


def _pushed(obs: ObsView, params: np.ndarray) -> np.ndarray:
    return np.linalg.norm(obs["object_pos"][:, :2] - params[:, :2], axis=1) < PUSHED_M


#: Pushes the object along the table toward a point: goes round behind it (lifted), lowers, and pushes through (scripted).
push = ScriptedSkill(
    "push", ParamBox(WORKSPACE_LOW[:2], WORKSPACE_HIGH[:2], "point to push the object to (x, y), metres"), _push_act,
    reads=("grip_pos", "object_pos"), k=25, done=_pushed,
)  # fmt: skip
#: :data:`push` aiming at a point given as an offset of at most :data:`AIM_M` from the task's goal (frame ``goal_xy``):
#: a Manager learns where near the goal to aim, starting from the goal itself (offset 0).
push_near_goal = ScriptedSkill(
    "push_near_goal", ParamBox((-AIM_M, -AIM_M), (AIM_M, AIM_M), "point to push the object to (x, y), offset from the "
                               "task's goal (m)", frame="goal_xy"), _push_act,
    reads=("grip_pos", "object_pos"), k=25, done=_pushed,
)  # fmt: skip


class Strike(Skill):
    """Strikes the object so that it slides along the table toward a point (scripted; FetchSlide's puck): goes round
    behind it, lifted, lowers to the table and moves through the object's start at a chosen speed, then stops. Its
    parameters: the point (x, y; m, world frame) and the strike's speed (action units, 0.05 m per step each)."""

    name, k, reads = "strike", 20, ("grip_pos", "object_pos")
    params = ParamBox((*WORKSPACE_LOW[:2], 0.1), (*WORKSPACE_HIGH[:2] + np.array([0.4, 0.0]), 1.0),
                      "point to slide the object toward (x, y; m) and the strike's speed (action units)")  # fmt: skip

    def __init__(self) -> None:
        self._start: dict[int, np.ndarray] = {}  # each world's object position when the strike began
        self._phase: dict[int, int] = {}  # 0: getting behind it, 1: striking, 2: struck

    def begin(self, obs: ObsView, params: np.ndarray) -> None:
        for i, pos in zip(obs.idx.tolist(), obs["object_pos"], strict=True):
            self._start[i], self._phase[i] = pos.copy(), 0

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        grip = obs["grip_pos"]
        start = np.stack([self._start[i] for i in obs.idx.tolist()])
        d = params[:, :2] - start[:, :2]
        u = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-6)
        g = grip[:, :2] - start[:, :2]
        along = (g * u).sum(axis=1)
        lateral = np.linalg.norm(g - along[:, None] * u, axis=1)
        behind = start[:, :2] - u * (HALF_OBJECT + RUN_UP_M)  # a run-up before the object
        low = grip[:, 2] < start[:, 2] + 0.015
        in_line = (along < -HALF_OBJECT) & (lateral < 0.01)
        target = np.concatenate([behind, start[:, 2:3] + 0.06], axis=1)
        at_behind = np.linalg.norm(grip[:, :2] - behind, axis=1) < 0.01
        target[at_behind | in_line, 2] = start[at_behind | in_line, 2]
        lift = ~in_line & ~at_behind & (grip[:, 2] < start[:, 2] + 0.04)  # clear of the object before going round it
        target[lift] = np.concatenate([grip[lift, :2], start[lift, 2:3] + 0.06], axis=1)
        out = np.zeros((len(grip), 4))
        out[:, :3] = _toward(target, grip)
        striking = in_line & low
        for row, i in enumerate(obs.idx.tolist()):
            if self._phase[i] == 0 and striking[row]:
                self._phase[i] = 1
            if self._phase[i] == 1 and along[row] > HALF_OBJECT:  # through the object's start: the strike is over
                self._phase[i] = 2
            if self._phase[i] == 2:
                out[row, :3] = 0.0
            elif self._phase[i] == 1:
                out[row, :2] = u[row] * params[row, 2]
                out[row, 2] = _toward(start[row, 2:3], grip[row, 2:3])[0]
        out[:, 3] = CLOSED
        return out


def strike() -> Skill:
    """A new :class:`Strike` (``--skills hrlp.fetch.skills:strike``): each keeps its own worlds' strike state, so two
    Managers in one process never share it."""
    return Strike()


def reach() -> Skill:
    """The gripper to a point near the object, held open: the shipped ``fetch-reach`` skill, trained by hrlp with SAC +
    HER on FetchReach-v4 (its recipe: the ``fetch-skills`` preset), its parameters offsets from ``object_pos``."""
    learned = load_skill("fetch-reach")
    near_object = ParamBox((-0.1, -0.1, -0.02), (0.1, 0.1, 0.1), "point to move the gripper to, offset from the object (m)",
                           frame="object_pos")  # fmt: skip
    return Holding(Seeing(Wrapped(learned, params=near_object), BLOCKED_FINGERS), {3: OPEN}, "reach")


def carry() -> Skill:
    """The gripper to a point in the workspace, held closed (carrying what it holds): a Stable-Baselines3 SAC + HER
    policy trained on FetchReach-v4, read from its ``.zip`` without unpickling (``benchmarks/fetch_skills.py`` trains
    it)."""
    path = Path(str(resources.files("hrlp.fetch") / "pretrained" / SB3_REACH))
    learned = from_sb3(path, "carry", param="desired_goal", low=WORKSPACE_LOW, high=WORKSPACE_HIGH, k=15,
                       done_part="grip_pos", done_within=0.02, bind=REACH_BIND)  # fmt: skip
    return Holding(Seeing(learned, BLOCKED_FINGERS), {3: CLOSED}, "carry")


__all__ = ["CLOSED", "OPEN", "STEP_M", "WORKSPACE_HIGH", "WORKSPACE_LOW", "Strike", "carry", "grasp", "push",
           "push_near_goal", "reach", "strike"]  # fmt: skip
