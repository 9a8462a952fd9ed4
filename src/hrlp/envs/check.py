"""Checking a task before any compute, without torch: its name, its arguments, the optional dependencies it needs and
the spaces hrlp can train on. :func:`probe_task` builds the environment once and turns whatever goes wrong into one
``ValueError`` line that says what to do (the pip extra to install, the valid arguments, the supported spaces)."""

from __future__ import annotations

import inspect
import re
from typing import Any

import gymnasium as gym

#: Keyword arguments of ``gymnasium.make`` itself (besides the environment's own).
_GYM_MAKE_ARGUMENTS = ("max_episode_steps", "autoreset", "apply_api_compatibility", "disable_env_checker", "render_mode")


def default_episode_steps() -> int:
    """The episode length of hrlp tasks when none is given (:class:`~hrlp.envs.arm_env.ArmEnv`'s default)."""
    from hrlp.envs.arm_env import ArmEnv

    return int(inspect.signature(ArmEnv).parameters["episode_steps"].default)


def parameterised_dims(space: gym.Space) -> tuple[int, ...]:
    """The block sizes ``(d_1, ..., d_n)`` of a ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))`` space; ValueError otherwise."""
    ok = (
        isinstance(space, gym.spaces.Tuple)
        and len(space.spaces) >= 2
        and isinstance(space.spaces[0], gym.spaces.Discrete)
        and int(space.spaces[0].start) == 0
        and int(space.spaces[0].n) == len(space.spaces) - 1
        and all(isinstance(b, gym.spaces.Box) and len(b.shape) == 1 for b in space.spaces[1:])
    )
    if not ok:
        raise ValueError(
            f"unsupported action space {space}: use Box, Discrete, or Tuple(Discrete(n), Box(d_1), ..., Box(d_n))"
        )
    return tuple(int(b.shape[0]) for b in space.spaces[1:])


def check_spaces(task: str, observation_space: gym.Space, action_space: gym.Space) -> None:
    """Raise ValueError naming ``task`` unless hrlp's policies can read its observations (a Box) and produce its actions
    (Box, Discrete or a parameterised Tuple)."""
    if not isinstance(observation_space, gym.spaces.Box) or observation_space.shape is None:
        raise ValueError(f"{task}: unsupported observation space {observation_space}: hrlp's policies read a Box of "
                         "numbers (wrap the environment so that it observes one, e.g. a one-hot Box for a Discrete "
                         "state)")  # fmt: skip
    if not isinstance(action_space, gym.spaces.Box | gym.spaces.Discrete):
        try:
            parameterised_dims(action_space)
        except ValueError as e:
            raise ValueError(f"{task}: {e}") from None


def invalid_arguments_line(task: str, unknown: list[str], valid: tuple[str, ...]) -> str:
    """The one line for task arguments ``unknown`` that ``task`` does not take, listing the ``valid`` ones."""
    names = ", ".join(map(repr, unknown))
    return f"{task}: invalid argument{'s' if len(unknown) > 1 else ''} {names} (no such task argument); valid arguments: " + (
        ", ".join(valid)
    )


def gym_arguments(env_id: str) -> tuple[str, ...]:
    """The keyword arguments a Gymnasium id's environment takes (its constructor's, then ``gymnasium.make``'s)."""
    names: list[str] = []
    try:
        creator = gym.envs.registration.load_env_creator(gym.spec(env_id).entry_point)
        params = inspect.signature(creator).parameters.values()
        names = [p.name for p in params if p.name != "self" and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)]
    except Exception:  # a creator that cannot be inspected: name gymnasium.make's arguments only
        pass
    return tuple(dict.fromkeys([*names, *_GYM_MAKE_ARGUMENTS]))


def _dependency_line(env_id: str, error: Exception) -> str:
    """One line for a Gymnasium environment whose optional dependency is missing, naming the pip extra."""
    text = " ".join(str(error).split())
    if match := re.search(r"gymnasium\[([\w-]+)\]", text):
        extra = match.group(1)
        what = {"box2d": "Box2D", "mujoco": "MuJoCo's Gymnasium bindings", "atari": "the Arcade Learning Environment"}
        hint = " (Box2D builds with SWIG: pip install swig first)" if extra == "box2d" else ""
        return f"{env_id} needs {what.get(extra, extra)}, which is not installed: pip install 'gymnasium[{extra}]'{hint}"
    return f"{env_id} needs a package that is not installed: {text}"


def gym_kwargs(task: str, episode_steps: int | None, kwargs: dict[str, Any]) -> dict[str, Any]:
    """``gymnasium.make``'s arguments for a Gymnasium id: ``episode_steps`` becomes its time limit
    (``max_episode_steps``); ValueError if both are given."""
    if episode_steps is None:
        return kwargs
    if "max_episode_steps" in kwargs:
        raise ValueError(f"{task}: give the episode length once, as episode_steps (--episode-steps) or as the task "
                         "argument max_episode_steps, not both")  # fmt: skip
    return {**kwargs, "max_episode_steps": episode_steps}


def probe_task(task: str, episode_steps: int | None = None, /, **kwargs: Any) -> tuple[gym.Space, gym.Space]:
    """Build ``task`` (an hrlp task name or id, or a Gymnasium id) once with ``kwargs`` and return its observation
    and action spaces; raise ValueError, one line naming the task, for an unknown task, an unknown or invalid argument
    (listing the valid ones), a missing optional dependency (naming the pip extra) or a space hrlp cannot train on. For
    a Gymnasium id, ``episode_steps`` is its time limit (:func:`gym_kwargs`)."""
    from hrlp.envs import TASKS, make

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
    if task not in gym.registry:
        hint = " (Atari ids need pip install 'gymnasium[atari]')" if task.startswith("ALE/") else ""
        raise ValueError(f"unknown task {task!r}: not an hrlp task (see 'hrlp tasks') nor a registered Gymnasium id{hint}")
    kwargs = gym_kwargs(task, episode_steps, kwargs)
    try:
        env = gym.make(task, **kwargs)
    except gym.error.DependencyNotInstalled as e:
        raise ValueError(_dependency_line(task, e)) from None
    except ImportError as e:
        raise ValueError(f"{task} needs the Python package {e.name or e}, which is not installed") from None
    except TypeError as e:
        valid = gym_arguments(task)
        if unknown := [k for k in kwargs if k not in valid]:
            raise ValueError(invalid_arguments_line(task, unknown, valid)) from None
        raise ValueError(f"{task}: invalid task arguments {kwargs}: {' '.join(str(e).split())}") from None
    except Exception as e:  # a third-party constructor given the user's arguments: say so in one line
        raise ValueError(f"{task}: cannot be built with the task arguments {kwargs}: {' '.join(str(e).split())}") from None
    spaces = env.observation_space, env.action_space
    env.close()
    check_spaces(task, *spaces)
    return spaces
