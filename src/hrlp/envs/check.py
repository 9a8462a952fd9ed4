"""Checking a task before any compute, without torch: its name, its arguments, the optional dependencies it needs and
the spaces hrlp can train on. :func:`probe_task` builds the environment once and turns whatever goes wrong into one
``ValueError`` line that says what to do (the pip extra to install, the valid arguments, the supported spaces)."""

from __future__ import annotations

import inspect
import re
from typing import Any

import gymnasium as gym

from hrlp import bounds

#: Keyword arguments of ``gymnasium.make`` itself (besides the environment's own).
_GYM_MAKE_ARGUMENTS = ("max_episode_steps", "autoreset", "apply_api_compatibility", "disable_env_checker", "render_mode")


def default_episode_steps() -> int:
    """The episode length of hrlp tasks when none is given (:data:`hrlp.bounds.DEFAULT_EPISODE_STEPS`)."""
    return bounds.DEFAULT_EPISODE_STEPS


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


PROBE_EPISODES, PROBE_STEPS = 5, 2_000
""":func:`measured_episode_steps` plays at most this many episodes and steps in all."""


def measured_episode_steps(env: gym.Env, seed: int = 0) -> int | None:
    """The longest of :data:`PROBE_EPISODES` episodes of ``env`` under uniformly random actions (seeded), for an
    environment whose registration declares no episode length; None when they take more than :data:`PROBE_STEPS`
    steps in all (long episodes: the defaults suit them). ``env`` is reset and stepped, not closed."""
    env.action_space.seed(seed)
    longest, total = 0, 0
    for i in range(PROBE_EPISODES):
        env.reset(seed=seed + i)
        length = 0
        while True:
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            length, total = length + 1, total + 1
            if terminated or truncated:
                break
            if total >= PROBE_STEPS:
                return None
        longest = max(longest, length)
    return longest


FEW_UPDATES = 20
"""A run whose budget allows fewer policy updates than this is told so before it starts (``hrlp train``)."""


def dependency_line(env_id: str, error: Exception) -> str:
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
