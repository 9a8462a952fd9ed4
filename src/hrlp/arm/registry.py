"""Every task of the paper as a registered Gymnasium id (``hrlp tasks`` lists them).

``gymnasium.make("hrlp/Gripper-v0", c2=4.0, tr=0.06, episode_steps=500)`` builds an
:class:`~hrlp.arm.env.ArmEnv`; keyword arguments go to the environment (``episode_steps``,
``physics``, ``render_mode``, ``width``, ``height``, ``camera``) or, for the rest, to the task.
"""

from __future__ import annotations

import dataclasses
import inspect
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

from hrlp.arm.env import ArmEnv
from hrlp.arm.tasks import (
    GripperTask,
    GripReward,
    MoverTask,
    ReachAndGripTask,
    ReachAndMoveTask,
    ReacherTask,
    SparseSuccess,
    Task,
)
from hrlp.envs.check import (
    check_spaces,
    default_episode_steps,
    dependency_line,
    gym_arguments,
    gym_kwargs,
    invalid_arguments_line,
    registered_gym_id,
)

NAMESPACE = "hrlp"
_ENV_KWARGS = frozenset(inspect.signature(ArmEnv.__init__).parameters) - {"self", "task"}
_GRIP_KWARGS = frozenset(f.name for f in dataclasses.fields(GripReward))
_SPARSE_KWARGS = {"tr1", "tr2"}


@dataclass(frozen=True)
class TaskSpec:
    """A registered task: its id, a one-line description, and how to build it."""

    name: str
    description: str
    build: Callable[..., Task]

    @property
    def env_id(self) -> str:
        """The Gymnasium id, e.g. 'hrlp/Gripper-v0'."""
        return f"{NAMESPACE}/{self.name}-v0"

    @property
    def arguments(self) -> tuple[str, ...]:
        """The task's own arguments (``--task-arg NAME=VALUE``), e.g. ``c1``, ``tr`` for a gripping task."""
        return self.build.arguments() if isinstance(self.build, _Build) else ()

    @property
    def task_type(self) -> type | None:
        """The task's class (None for a build function that does not say)."""
        return self.build.cls if isinstance(self.build, _Build) else None


@dataclass(frozen=True, eq=False)  # compared and hashed by identity, as the functions it replaces
class _Build:
    """Builds a task class with some arguments fixed (e.g. a Reacher's variant); knows the arguments it takes."""

    cls: type
    fixed: dict[str, Any]
    grip: bool = False
    """Gripping tasks take the reward constants (c1, c2, c3, tr, ...) and the sparse thresholds (tr1, tr2) as flat
    keyword arguments, as the paper's tables name them."""

    def __call__(self, **kw: Any) -> Task:
        if self.grip:
            reward = GripReward(**{k: kw.pop(k) for k in list(kw) if k in _GRIP_KWARGS})
            sparse = SparseSuccess(**{k: kw.pop(k) for k in list(kw) if k in _SPARSE_KWARGS})
            kw = {"reward": reward, "sparse": sparse, **kw}
        return self.cls(**self.fixed, **kw)

    def arguments(self) -> tuple[str, ...]:
        """The task's own arguments (not the environment's, such as ``episode_steps``), in the class's order."""
        names = [n for n in inspect.signature(self.cls).parameters if n not in self.fixed]
        if self.grip:
            names = [n for n in names if n not in ("reward", "sparse")] + sorted(_GRIP_KWARGS) + sorted(_SPARSE_KWARGS)
        return tuple(names)


def _task(cls: type, **fixed: Any) -> _Build:
    return _Build(cls, fixed)


def _grip(cls: type, **fixed: Any) -> _Build:
    return _Build(cls, fixed, grip=True)


TASKS: dict[str, TaskSpec] = {
    s.name: s
    for s in (
        TaskSpec(
            "Reacher",
            "hand to a 3-d goal above a capsule on the table (ReacherNormal)",
            _task(ReacherTask, variant="normal"),
        ),
        TaskSpec(
            "ReacherStabilised",
            "Reacher with a reward for a forearm parallel to the table",
            _task(ReacherTask, variant="stabilised"),
        ),
        TaskSpec("Reacher3D", "hand to a goal anywhere in the reachable space", _task(ReacherTask, variant="3d")),
        TaskSpec(
            "ReacherHandover",
            "Reacher to a pre-grasp point above the capsule, leaving the capsule in place and the claw open",
            _task(ReacherTask, variant="handover"),
        ),
        TaskSpec("Gripper", "grip the capsule, palm starting near it (Figure 6 reward)", _grip(GripperTask)),
        TaskSpec("MoverPlain", "move the capsule to a target, small start set", _task(MoverTask, variant="plain")),
        TaskSpec("MoverNoised", "move the capsule to a target, large start set", _task(MoverTask, variant="noised")),
        TaskSpec(
            "ReachAndGrip1",
            "reach-and-grip Experiment 1: capsule fixed, palm on a circle",
            _grip(ReachAndGripTask, experiment=1),
        ),
        TaskSpec(
            "ReachAndGrip2",
            "reach-and-grip Experiment 2: capsule and palm on the circle independently",
            _grip(ReachAndGripTask, experiment=2),
        ),
        TaskSpec("ReachAndMove", "reach-and-move: capsule fixed, target above it, random arm start", _task(ReachAndMoveTask)),
    )
}


def make(name: str, **kwargs: Any) -> ArmEnv:
    """Build the task ``name`` (a key of :data:`TASKS`) as an :class:`ArmEnv`.

    Raises ValueError, naming the task, for an unknown name or an unknown or invalid argument.
    """
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; known tasks: {', '.join(TASKS)}")
    env_kw = {k: kwargs.pop(k) for k in list(kwargs) if k in _ENV_KWARGS}
    valid = TASKS[name].arguments
    if unknown := [k for k in kwargs if valid and k not in valid]:
        raise ValueError(invalid_arguments_line(name, unknown, valid))
    try:
        task = TASKS[name].build(**kwargs)
    except TypeError as e:  # a value of the wrong type reaches a task's arithmetic
        raise ValueError(f"{name}: invalid argument ({e})") from None
    return ArmEnv(task, **env_kw)


@dataclass(frozen=True, eq=False)
class ArmEnvFactory:
    """A picklable constructor of the registered task ``name`` with ``kwargs``: ``factory()`` is
    ``make(name, **kwargs)``."""

    name: str
    kwargs: Mapping[str, Any] = field(default_factory=dict)

    def __call__(self) -> ArmEnv:
        return make(self.name, **self.kwargs)


def register_all() -> None:
    """Register every task under the 'hrlp' namespace (idempotent)."""
    for spec in TASKS.values():
        if spec.env_id not in gym.registry:
            gym.register(
                id=spec.env_id, entry_point="hrlp.arm.registry:make", kwargs={"name": spec.name}, disable_env_checker=True
            )


def declared_episode_steps(task: str, episode_steps: int | None = None) -> int | None:
    """The most decisions an episode of ``task`` may last, as declared: ``episode_steps`` if given, else a Gymnasium
    id's registered time limit (``max_episode_steps``), else the hrlp tasks' default; None when nothing declares one."""
    if episode_steps is not None:
        return episode_steps
    if task.removeprefix("hrlp/").removesuffix("-v0") in TASKS:
        return default_episode_steps()
    return gym.spec(registered_gym_id(task)).max_episode_steps


def probe_task(task: str, episode_steps: int | None = None, /, **kwargs: Any) -> tuple[gym.Space, gym.Space]:
    """Build ``task`` (an hrlp task name or id, or a Gymnasium id) once with ``kwargs`` and return its observation
    and action spaces; raise ValueError, one line naming the task, for an unknown task, an unknown or invalid argument
    (listing the valid ones), a missing optional dependency (naming the pip extra) or a space hrlp cannot train on. For
    a Gymnasium id, ``episode_steps`` is its time limit (:func:`gym_kwargs`)."""
    name = task.removeprefix("hrlp/").removesuffix("-v0")
    if name in TASKS:
        if "episode_steps" in kwargs:
            raise ValueError(f"{name}: give the episode length as episode_steps (--episode-steps), not as a task argument")
        kw = dict(kwargs)
        if episode_steps is not None:
            kw["episode_steps"] = episode_steps
        try:
            env = make(name, **kw)
        except (TypeError, AttributeError) as e:  # e.g. physics=3: a value of the wrong kind
            raise ValueError(f"{name}: invalid task arguments {kwargs}: {e}") from None
        spaces = env.observation_space, env.action_space
        env.close()
        return spaces
    env_id = registered_gym_id(task)
    kwargs = gym_kwargs(task, episode_steps, kwargs)
    try:
        env = gym.make(task, **kwargs)
    except gym.error.DependencyNotInstalled as e:
        raise ValueError(dependency_line(task, e)) from None
    except ImportError as e:
        raise ValueError(f"{task} needs the Python package {e.name or e}, which is not installed") from None
    except TypeError as e:
        valid = gym_arguments(env_id)
        if unknown := [k for k in kwargs if k not in valid]:
            raise ValueError(invalid_arguments_line(task, unknown, valid)) from None
        raise ValueError(f"{task}: invalid task arguments {kwargs}: {' '.join(str(e).split())}") from None
    except Exception as e:  # a third-party constructor given the user's arguments: say so in one line
        raise ValueError(f"{task}: cannot be built with the task arguments {kwargs}: {_raised(e)}") from None
    spaces = env.observation_space, env.action_space
    env.close()
    check_spaces(task, *spaces)
    return spaces


def _raised(e: BaseException) -> str:
    """``Type: message (in file.py:line, function)``, the innermost frame of ``e``: what failed and where, also for an
    exception without a message (an ``assert`` in a third-party constructor)."""
    message = " ".join(str(e).split())
    frames = traceback.extract_tb(e.__traceback__)
    where = f" (in {Path(frames[-1].filename).name}:{frames[-1].lineno}, {frames[-1].name})" if frames else ""
    return f"{type(e).__name__}{': ' + message if message else ''}{where}"
