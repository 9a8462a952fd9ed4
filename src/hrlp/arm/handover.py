"""The arm's hand-over drives (docs/skills.md, "Skills that hand over"): how the arm's point and moving skills are run
so that the next skill can take over from where they stop, as skill wrappers over the generic interface.

:func:`drive` wraps each arm skill as :class:`~hrlp.config.Handover` says: a point skill (a Reacher) gets its goal as an
offset from the capsule in :data:`~hrlp.arm.skill.HANDOVER_POINT`'s box (or :data:`~hrlp.arm.skill.HANDOVER_PREGRASP`'s),
its goal raised until the hand is above it, and the claw held open; a moving skill (a Mover) with ``target_relative``
its target as an offset from the task's target T. Other skills pass through unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from hrlp.arm.physics import N_JOINTS
from hrlp.arm.skill import HANDOVER_POINT, HANDOVER_PREGRASP, HANDOVER_TARGET, MOVE_TASKS, POINT_TASKS, ArmSkill, ParamSpec
from hrlp.config import Handover, MicroAction
from hrlp.skills.core import ObsLayout, ObsView, ParamBox, Skill
from hrlp.skills.macro_env import MacroEnv


class Driven(Skill):
    """An arm skill driven for hand-over (:class:`Handover`): its parameters in another box (``box``, e.g. offsets from
    the capsule), and for a point skill the goal raised until the hand is above it and the claw held open."""

    def __init__(self, skill: ArmSkill, box: ParamBox, handover: Handover | None) -> None:
        self.skill, self.handover, self.params = skill, handover, box
        self.name, self.k, self.reads, self.chains, self.cost = skill.name, skill.k, skill.reads, skill.chains, skill.cost
        self._raised = np.zeros(0, dtype=bool)  # per world: the goal is still raised (until the hand is above it)

    def begin(self, obs: ObsView, params: np.ndarray) -> None:
        if self._raised.size <= (top := int(obs.idx.max(initial=-1))):
            self._raised = np.resize(self._raised, top + 1)
        self._raised[obs.idx] = True

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        h, block = self.handover, params
        if h is None:
            return self.skill.act(obs, block)
        if h.approach_height > 0:
            off = np.linalg.norm(obs["hand"][:, :2] - block[:, :2], axis=1)
            self._raised[obs.idx] &= off >= h.approach_radius
            block = block + np.outer(self._raised[obs.idx], (0.0, 0.0, h.approach_height))
        torques = self.skill.act(obs, block)
        if h.open_torque > 0:
            torques[:, N_JOINTS - 2 :] = (-h.open_torque, h.open_torque)
        return torques

    def initiable(self, obs: ObsView) -> np.ndarray | None:
        return self.skill.initiable(obs)

    def check(self, layout: ObsLayout, action_space: gym.spaces.Box, measured: Sequence[str] = ()) -> None:
        if self.params.frame == "target" and "target" not in layout.names:
            raise ValueError(f"Handover.target_relative needs a task that observes a target (reach-and-move, the Movers); "
                             f"skill {self.name} is run on one that does not")  # fmt: skip
        super().check(layout, action_space, measured)

    def __getattr__(self, name: str) -> Any:
        """The driven skill's own facts (its task, features, content hash, initiation set)."""
        if name == "skill":
            raise AttributeError(name)
        return getattr(self.skill, name)


def handover_spec(skill: ArmSkill, handover: Handover | None) -> ParamSpec:
    """What the Manager's block of ``skill`` means under ``handover``: its own specification, or the capsule-relative box
    for point skills (``relative``; ``pregrasp``'s smaller one) and the target-relative box for moving skills
    (``target_relative``)."""
    h = handover
    if h and h.relative and skill.task in POINT_TASKS:
        return HANDOVER_PREGRASP if h.pregrasp else HANDOVER_POINT
    if h and h.target_relative and skill.task in MOVE_TASKS:
        return HANDOVER_TARGET
    return skill.param


def drive(skills: Sequence[Skill], handover: Handover | None) -> list[Skill]:
    """The skills as a Manager runs them under ``handover`` (module docstring): an arm skill whose box changes or that
    is driven wrapped in :class:`Driven`; any other skill as it is."""
    out: list[Skill] = []
    for s in skills:
        if not isinstance(s, ArmSkill):
            out.append(s)
            continue
        spec, point = handover_spec(s, handover), s.task in POINT_TASKS
        wrap = handover if point else None
        out.append(s if spec == s.param and wrap is None else Driven(s, spec.box(), wrap))
    return out


def arm_macro_env(env: gym.Env, skills: Sequence[Skill], k: int | None = None, micro: MicroAction | None = None,
                  gamma: float = 0.99, handover: Handover | None = None) -> MacroEnv:  # fmt: skip
    """A Manager's environment over an arm task with its skills driven by ``handover`` (:func:`drive`), initiation sets
    enforced where ``handover.initiation`` says so."""
    return MacroEnv(env, drive(skills, handover), k, micro, gamma, chain=bool(handover and handover.initiation))
