"""Building a run's environments: the constructor of one (flat, Gymnasium or a Manager's MacroEnv) and the
batched backend's constructors of N at once.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym

from hrlp.arm.batched import VECTORISED, BatchedFactory, make_batched
from hrlp.arm.handover import drive
from hrlp.arm.manager import batched_manager
from hrlp.arm.registry import TASKS, ArmEnvFactory, make, probe_task
from hrlp.config import OFF_POLICY, MacroSpec, TrainConfig, auto_workers
from hrlp.envs.actions import NormalisedParameters, is_parameterised, make_normalised
from hrlp.envs.check import gym_kwargs
from hrlp.envs.vector import VectorConstructor, VectorEnv
from hrlp.skills.macro_env import MacroEnv
from hrlp.training.sources import resolve_skills


def env_factory(
    task: str, episode_steps: int | None = None, macro: MacroSpec | None = None, gamma: float = 0.99, **kwargs: Any
) -> Callable[[], gym.Env]:
    """A constructor for ``task`` (an hrlp task name/id, a Gymnasium id or ``MODULE:ID``), wrapped in a :class:`MacroEnv`
    of ``macro``'s skills (resolved once, shared, frozen: :mod:`hrlp.training.sources`) for a Manager. Raises
    ValueError, one line, before any compute, for an unknown task, an unknown or invalid argument, a missing optional
    dependency, an unsupported space (:func:`hrlp.arm.registry.probe_task`) or a bad skill reference; for a Gymnasium id,
    ``episode_steps`` is its time limit, a Dict observation is flattened in its key order (for a flat policy; a
    Manager's skills read its parts by name), and a parameterised action space (flat or nested Tuple, OneOf) is
    presented in the policy's canonical form with parameters in [-1, 1] (:class:`hrlp.envs.actions.NormalisedParameters`).
    The constructor can be pickled (sampler worker processes rebuild it; a Manager's skills are then resolved again
    there, from the same references)."""
    name = task.removeprefix("hrlp/").removesuffix("-v0")
    observation_space, action_space = probe_task(task, episode_steps, **kwargs)  # validate now, before any compute
    if name in TASKS:
        kw = dict(kwargs)
        if episode_steps is not None:
            kw["episode_steps"] = episode_steps
        if macro is None:
            return ArmEnvFactory(name, kw)
        return _MacroFactory(name, kw, macro, gamma, resolve_skills(macro.skills, macro.library))
    gkw = gym_kwargs(task, episode_steps, kwargs)
    if macro is not None:
        if is_parameterised(action_space) or not isinstance(action_space, gym.spaces.Box):
            raise ValueError(f"{task}: a Manager's skills emit Box actions; this environment's action space is {action_space}")
        return _MacroFactory(task, gkw, macro, gamma, resolve_skills(macro.skills, macro.library), gym_id=True)
    if is_parameterised(action_space):  # the policy acts in [-1, 1] per bounded parameter (hrlp.envs.actions)
        return functools.partial(make_normalised, task, **gkw)
    if isinstance(observation_space, gym.spaces.Dict):
        return functools.partial(_flattened, task, **gkw)
    return functools.partial(gym.make, task, **gkw)


def _flattened(task: str, **kwargs: Any) -> gym.Env:
    """``gymnasium.make(task)`` with its Dict observation flattened in its key order (a flat policy reads a Box)."""
    return gym.wrappers.FlattenObservation(gym.make(task, **kwargs))


class _MacroFactory:
    """Builds a Manager's environment; its skills are resolved once per process (not pickled: a worker process resolves
    them again from their references and checks library skills are the same, by content hash)."""

    def __init__(self, name: str, kwargs: dict[str, Any], macro: MacroSpec, gamma: float, skills: list,
                 gym_id: bool = False) -> None:  # fmt: skip
        self.name, self.kwargs, self.macro, self.gamma, self._skills = name, kwargs, macro, gamma, skills
        self.gym_id = gym_id
        self.hashes = skill_hashes(skills)

    def __call__(self) -> MacroEnv:
        if self._skills is None:
            self._skills = resolve_skills(self.macro.skills, self.macro.library)
            check_skill_hashes(self.hashes, skill_hashes(self._skills), Path("skill library"))
        low = gym.make(self.name, **self.kwargs) if self.gym_id else make(self.name, **self.kwargs)
        m = self.macro
        chain = m.chain or bool(m.handover and m.handover.initiation)
        return MacroEnv(low, drive(self._skills, m.handover), m.k, m.micro, self.gamma, chain)

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_skills": None}


def skill_hashes(skills: list) -> dict[str, str]:
    """The content hash of each skill that has one (a library skill's weights), by name."""
    return {s.name: s.content_hash for s in skills if isinstance(getattr(s, "content_hash", None), str)}


class _BatchedMacroFactory(_MacroFactory, VectorConstructor):
    """A Manager's environment constructor whose ``n`` copies a sampler steps as one
    :func:`~hrlp.arm.manager.batched_manager` (the batched backend)."""

    def vector(self, n: int, gamma: float) -> VectorEnv:
        if gamma != self.gamma:
            raise ValueError(f"the Manager's environments discount by {self.gamma}, not {gamma}")
        layout = self()
        features = tuple(dict.fromkeys(f for s in layout.skills for f in getattr(s, "features", ())))  # what skills read
        return batched_manager(make_batched(self.name, n, features=features, **self.kwargs), layout)


def batchable_task(task: str) -> bool:
    """Whether ``task`` (a name or id) is an hrlp arm task, whose worlds the batched backend steps together, flat or
    under a Manager (:data:`hrlp.arm.batched.VECTORISED`)."""
    name = task.removeprefix("hrlp/").removesuffix("-v0")
    return name in TASKS and TASKS[name].task_type in VECTORISED


def resolve_config(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with a concrete number of sampling workers and a concrete backend: ``workers`` 0 becomes
    :func:`hrlp.config.auto_workers`'s count for ``num_envs`` (1 for an off-policy run: it samples in its own process),
    ``backend`` ``auto`` the batched backend for an arm task (:func:`batchable_task`) and the serial one otherwise; what
    a run records and resumes with. Raises ValueError for ``batched`` where it does not apply."""
    if cfg.workers == 0:  # an off-policy run samples in its own process
        cfg = dataclasses.replace(cfg, workers=1 if cfg.algo in OFF_POLICY else auto_workers(cfg.num_envs))
    batchable = batchable_task(cfg.task)
    if cfg.backend == "auto":
        cfg = dataclasses.replace(cfg, backend="batched" if batchable else "serial")
    elif cfg.backend == "batched" and not batchable:
        raise ValueError(f"backend batched steps hrlp's arm tasks; {cfg.task} is not one: use serial or auto")
    return cfg


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
    if isinstance(factory, _MacroFactory) and not factory.gym_id:
        return _BatchedMacroFactory(factory.name, factory.kwargs, factory.macro, factory.gamma, factory._skills)
    if isinstance(factory, ArmEnvFactory):
        return BatchedFactory(factory.name, factory.kwargs)
    raise ValueError("the batched backend steps hrlp's arm tasks only")


def action_units(env: gym.Env) -> str:
    """``"normalised"`` for an environment whose parameterised actions the policy takes in [-1, 1]
    (:class:`hrlp.envs.actions.NormalisedParameters`), else ``"native"``: recorded in a run's checkpoint."""
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
