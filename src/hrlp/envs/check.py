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
    """The block sizes ``(d_1, ..., d_n)`` of a ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))`` space, the form hrlp's
    hierarchical policy acts in (the nested Tuple and OneOf forms reach it through
    :class:`~hrlp.envs.actions.NormalisedParameters`); ValueError otherwise (:func:`~hrlp.envs.actions.parameter_blocks`)."""
    from hrlp.envs.actions import parameter_blocks

    kind, blocks = parameter_blocks(space)
    if kind != "flat":
        raise ValueError(f"action space {space}: hrlp's policy acts in Tuple(Discrete(n), Box(d_1), ..., Box(d_n)); "
                         "wrap the environment in hrlp.envs.actions.NormalisedParameters")  # fmt: skip
    return tuple(int(b.shape[0]) for b in blocks)


def check_spaces(task: str, observation_space: gym.Space, action_space: gym.Space) -> None:
    """Raise ValueError naming ``task`` unless hrlp's policies can read its observations (a Box, or a Dict of Boxes such
    as a goal-conditioned environment's, flattened in its key order) and produce its actions (Box, Discrete or a
    parameterised space: flat or nested Tuple, or OneOf, see :mod:`hrlp.envs.actions`)."""
    if isinstance(observation_space, gym.spaces.Dict):
        if bad := [k for k, s in observation_space.spaces.items() if not isinstance(s, gym.spaces.Box)]:
            raise ValueError(f"{task}: unsupported observation part(s) {', '.join(map(repr, bad))}: hrlp reads a Dict "
                             "observation whose parts are all Boxes of numbers")  # fmt: skip
    elif not isinstance(observation_space, gym.spaces.Box) or observation_space.shape is None:
        raise ValueError(f"{task}: unsupported observation space {observation_space}: hrlp's policies read a Box of "
                         "numbers or a Dict of them (wrap the environment so that it observes one, e.g. a one-hot Box "
                         "for a Discrete state)")  # fmt: skip
    if not isinstance(action_space, gym.spaces.Box | gym.spaces.Discrete):
        from hrlp.envs.actions import parameter_blocks

        try:
            parameter_blocks(action_space)
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


def registered_gym_id(task: str) -> str:
    """The Gymnasium id that ``task`` names: a registered id (``Pendulum-v1``), or ``module:id`` (``my_pkg.envs:MyEnv-v0``:
    the module is imported first, so that its ``gymnasium.register`` calls run, as ``gymnasium.make`` does). Raises
    ValueError, one line, for a module that cannot be imported or an id that nothing registered."""
    module, sep, env_id = task.rpartition(":")
    if sep:
        if not module or not env_id:
            raise ValueError(f"task {task!r}: write a module's environment as MODULE:ID, e.g. my_pkg.envs:MyEnv-v0")
        import importlib

        try:
            importlib.import_module(module)
        except Exception as e:  # ImportError, or the module's own code failing: either way, one line naming it
            raise ValueError(f"task {task!r}: cannot import module {module!r} ({type(e).__name__}: "
                             f"{' '.join(str(e).split())}); is it installed or on PYTHONPATH?") from None  # fmt: skip
        if env_id not in gym.registry:
            near = sorted(k for k in gym.registry if k.split("-v")[0].lower() == env_id.split("-v")[0].lower())
            also = f" (registered: {', '.join(near)})" if near else ""
            raise ValueError(f"task {task!r}: module {module!r} registers no Gymnasium id {env_id!r}{also}")
        return env_id
    if task not in gym.registry:
        hint = " (Atari ids need pip install 'gymnasium[atari]')" if task.startswith("ALE/") else ""
        raise ValueError(f"unknown task {task!r}: not an hrlp task (see 'hrlp tasks'), a registered Gymnasium id, nor "
                         f"MODULE:ID of a module that registers one{hint}")  # fmt: skip
    return task


SHORT_EPISODE_STEPS = 50
"""Episodes declared to last at most this many decisions are short: for a Gymnasium id registered with such a
``max_episode_steps``, ``hrlp train`` uses :data:`SHORT_EPISODE_SETTINGS` unless the options they set are given."""
SHORT_EPISODE_SETTINGS: dict[str, Any] = {
    "batch_steps": 500,
    "max_kl": 0.05,
    "num_envs": 16,
    "fisher_fraction": 1.0,
    "value_iters": 25,
    "value_fraction": 1.0,
}
"""``hrlp train``'s settings for short episodes (measured on the tasks of :mod:`hrlp.envs.param_tasks` by
``benchmarks/short_episodes.py``: docs/benchmarks.md); the defaults otherwise are 50,000 decisions and 0.01. The
last four are the paper's (:data:`hrlp.config.PAPER_SETTINGS`), with which these settings were measured: the faster
defaults are shown to learn as well on Reacher-v5, not on short episodes."""


def declared_episode_steps(task: str, episode_steps: int | None = None) -> int | None:
    """The most decisions an episode of ``task`` may last, as declared: ``episode_steps`` if given, else a Gymnasium
    id's registered time limit (``max_episode_steps``), else the hrlp tasks' default; None when nothing declares one."""
    from hrlp.envs import TASKS

    if episode_steps is not None:
        return episode_steps
    if task.removeprefix("hrlp/").removesuffix("-v0") in TASKS:
        return default_episode_steps()
    return gym.spec(registered_gym_id(task)).max_episode_steps


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
    env_id = registered_gym_id(task)
    kwargs = gym_kwargs(task, episode_steps, kwargs)
    try:
        env = gym.make(task, **kwargs)
    except gym.error.DependencyNotInstalled as e:
        raise ValueError(_dependency_line(task, e)) from None
    except ImportError as e:
        raise ValueError(f"{task} needs the Python package {e.name or e}, which is not installed") from None
    except TypeError as e:
        valid = gym_arguments(env_id)
        if unknown := [k for k in kwargs if k not in valid]:
            raise ValueError(invalid_arguments_line(task, unknown, valid)) from None
        raise ValueError(f"{task}: invalid task arguments {kwargs}: {' '.join(str(e).split())}") from None
    except Exception as e:  # a third-party constructor given the user's arguments: say so in one line
        raise ValueError(f"{task}: cannot be built with the task arguments {kwargs}: {' '.join(str(e).split())}") from None
    spaces = env.observation_space, env.action_space
    env.close()
    check_spaces(task, *spaces)
    return spaces
