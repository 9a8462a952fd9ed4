"""Building a run's environments: the constructor of one (flat, Gymnasium or a Manager's MacroEnv) and the
batched backend's constructors of N at once.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym

from hrlp.config import TrainConfig
from hrlp.envs.batched import BatchedFactory, make_batched
from hrlp.envs.registry import ArmEnvFactory
from hrlp.envs.vector import VectorConstructor, VectorEnv
from hrlp.skills.macro_env import BatchedMacroVectorEnv, MacroEnv, MacroSpec


def env_factory(
    task: str, episode_steps: int | None = None, macro: MacroSpec | None = None, gamma: float = 0.99, **kwargs: Any
) -> Callable[[], gym.Env]:
    """A constructor for ``task`` (an hrlp task name/id or a Gymnasium id), wrapped in a :class:`MacroEnv` of
    ``macro``'s skills (loaded once, shared, frozen) for a Manager. Raises ValueError, one line, before any compute,
    for an unknown task, an unknown or invalid argument, a missing optional dependency, an unsupported space
    (:func:`hrlp.envs.check.probe_task`) or a missing skill; for a Gymnasium id, ``episode_steps`` is its time limit,
    and a parameterised action space (flat or nested Tuple, OneOf) is presented in the policy's canonical form with
    parameters in [-1, 1] (:class:`hrlp.envs.actions.NormalisedParameters`).
    The constructor can be pickled (sampler worker processes rebuild it; a Manager's skills are then loaded again
    there, from the same files)."""
    from hrlp.envs import TASKS
    from hrlp.envs.actions import is_parameterised, make_normalised
    from hrlp.envs.check import gym_kwargs, probe_task

    name = task.removeprefix("hrlp/").removesuffix("-v0")
    if name not in TASKS and macro is not None:
        raise ValueError(f"{task}: a Manager commands arm skills, so its task must be an hrlp task (see 'hrlp tasks')")
    _, action_space = probe_task(task, episode_steps, **kwargs)  # validate arguments and spaces now, before any compute
    if name in TASKS:
        kw = dict(kwargs)
        if episode_steps is not None:
            kw["episode_steps"] = episode_steps
        if macro is None:
            return ArmEnvFactory(name, kw)
        return _MacroFactory(name, kw, macro, gamma, macro.load_skills())
    if is_parameterised(action_space):  # the policy acts in [-1, 1] per bounded parameter (hrlp.envs.actions)
        return functools.partial(make_normalised, task, **gym_kwargs(task, episode_steps, kwargs))
    return functools.partial(gym.make, task, **gym_kwargs(task, episode_steps, kwargs))


class _MacroFactory:
    """Builds a Manager's environment; its skills are loaded once per process (not pickled: a worker process reloads
    them from disk and checks they are the same skills, by content hash)."""

    def __init__(self, name: str, kwargs: dict[str, Any], macro: MacroSpec, gamma: float, skills: list) -> None:
        self.name, self.kwargs, self.macro, self.gamma, self._skills = name, kwargs, macro, gamma, skills
        self.hashes = {s.name: s.content_hash for s in skills}

    def __call__(self) -> MacroEnv:
        from hrlp.envs import make

        if self._skills is None:
            self._skills = self.macro.load_skills()
            check_skill_hashes(self.hashes, {s.name: s.content_hash for s in self._skills}, Path("skill library"))
        return MacroEnv(
            make(self.name, **self.kwargs), self._skills, self.macro.k, self.macro.micro, self.gamma, self.macro.handover
        )

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_skills": None}


class _BatchedMacroFactory(_MacroFactory, VectorConstructor):
    """A Manager's environment constructor whose ``n`` copies a sampler steps as one
    :class:`~hrlp.skills.macro_env.BatchedMacroVectorEnv` (the batched backend)."""

    def vector(self, n: int, gamma: float) -> VectorEnv:
        if gamma != self.gamma:
            raise ValueError(f"the Manager's environments discount by {self.gamma}, not {gamma}")
        layout = self()
        features = tuple(dict.fromkeys(f for s in layout.skills for f in s.features))  # what the skills read
        return BatchedMacroVectorEnv(make_batched(self.name, n, features=features, **self.kwargs), layout)


def run_factory(cfg: TrainConfig, task_kwargs: dict[str, Any] | None = None) -> Callable[[], gym.Env]:
    """The constructor of one environment of ``cfg``'s run through its backend (:func:`batched_factory`'s for
    ``backend`` batched, else :func:`env_factory`'s); ``task_kwargs`` replace the config's task arguments."""
    kwargs = cfg.task_kwargs if task_kwargs is None else task_kwargs
    factory = env_factory(cfg.task, cfg.episode_steps, cfg.macro, cfg.advantage.gamma, **kwargs)
    return batched_factory(factory) if cfg.backend == "batched" else factory


def batched_factory(factory: Callable[[], gym.Env]) -> VectorConstructor:
    """The batched backend's version of :func:`env_factory`'s constructor of an hrlp arm task (flat or a Manager's):
    the same environment built alone, and ``n`` of them stepped as one (:class:`~hrlp.envs.vector.VectorConstructor`).
    Raises ValueError for any other constructor."""
    if isinstance(factory, _MacroFactory):
        return _BatchedMacroFactory(factory.name, factory.kwargs, factory.macro, factory.gamma, factory._skills)
    if isinstance(factory, ArmEnvFactory):
        return BatchedFactory(factory.name, factory.kwargs)
    raise ValueError("the batched backend steps hrlp's arm tasks only")


def action_units(env: gym.Env) -> str:
    """``"normalised"`` for an environment whose parameterised actions the policy takes in [-1, 1]
    (:class:`hrlp.envs.actions.NormalisedParameters`), else ``"native"``: recorded in a run's checkpoint."""
    from hrlp.envs.actions import NormalisedParameters

    return "normalised" if isinstance(env, NormalisedParameters) else "native"


#: Task arguments that shape training only; evaluation and rendering leave them out. The angle curriculum of
#: Section 4.3.2 and the Gripper's start-distance curriculum narrow the start set for the first episodes of every
#: environment, so a fresh evaluation environment would otherwise see only the easiest starts.
TRAINING_ONLY_TASK_ARGS = frozenset({"curriculum_alpha", "distance_curriculum", "curriculum_from"})


def check_skill_hashes(saved: dict[str, str], loaded: dict[str, str], where: Path) -> None:
    """Raise ValueError if a skill a Manager was trained with has changed since (its content hash differs)."""
    for name, h in saved.items():
        if loaded.get(name) != h:
            raise ValueError(
                f"{where}: skill {name!r} has changed since this Manager was trained "
                f"(sha256 {h[:12]} then, {str(loaded.get(name))[:12]} now)"
            )
