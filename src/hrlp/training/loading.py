"""Loading runs: a run's checkpoint read and checked, its policy ready to act (:class:`TrainedPolicy`), and a
skill's weights as a run's starting point (:func:`warm_start`).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
import torch

from hrlp.checkpoint import (
    CheckpointError,
    load_module,
    read_run_checkpoint,
)
from hrlp.config import OFF_POLICY, TrainConfig
from hrlp.envs.vector import VectorEnv
from hrlp.policies.mlp import GaussianPolicy, Policy, policy_for_space
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.policies.sac import SACActor
from hrlp.rollout import (
    Episode,
    action_decoder,
    build_vector_env,
    mean_or_nan,
)
from hrlp.skills.core import ObsLayout, ParamBox, own_observation_space
from hrlp.skills.library import GAUSSIAN_ACTOR, SQUASHED_ACTOR
from hrlp.skills.macro_env import MacroEnv
from hrlp.skills.policy import PolicySkill, param_box
from hrlp.training.environments import (
    TRAINING_ONLY_TASK_ARGS,
    action_units,
    check_skill_hashes,
    env_factory,
    run_factory,
    skill_hashes,
)

if TYPE_CHECKING:
    from hrlp.skills.library import SkillLibrary


def warm_start(policy: Policy, normalizer: RunningNormalizer, cfg: TrainConfig) -> str:
    """Copy the skill ``cfg.init_from`` (its policy's weights and its observation statistics, thawed) into a fresh
    flat run's ``policy`` and ``normalizer``; returns the skill's content hash (its lineage). Raises ValueError naming
    the skill when it does not fit the run."""
    from hrlp.skills.library import SkillLibrary, locate_skill, search_roots

    assert cfg.init_from is not None
    if cfg.macro is not None:
        raise ValueError("init_from starts a flat run from a skill; a Manager cannot start from one")
    where = Path(cfg.init_from)
    library, name = (SkillLibrary(where.parent), where.name) if (where / "meta.json").is_file() else (
        locate_skill(cfg.init_from, search_roots()), cfg.init_from)  # fmt: skip
    skill = library.load(name)
    task = cfg.task.removeprefix("hrlp/").removesuffix("-v0")
    if not isinstance(policy, GaussianPolicy) or skill.obs_dim != normalizer.mean.shape[0] or task != skill.task:
        raise ValueError(f"init_from: skill {skill.name} ({skill.task}, {skill.obs_dim} observations) does not fit a "
                         f"{task} run with {normalizer.mean.shape[0]} observations{_trained_with(library, name)}")  # fmt: skip
    try:
        policy.load_state_dict(skill.policy.state_dict())
    except RuntimeError:
        raise ValueError(f"init_from: skill {skill.name}'s network does not have hidden layers "
                         f"{cfg.hidden}{_trained_with(library, name)}") from None  # fmt: skip
    normalizer.load_state_dict(skill.normalizer.state_dict())
    return skill.content_hash


def _trained_with(library: SkillLibrary, name: str) -> str:
    """``"; it was trained ..."``: the task arguments and hidden layers of the skill's own training run, as options to
    give a run that starts from it ("" where its manifest records no training config)."""
    config = (library.manifest(name).get("trained") or {}).get("config") or {}
    if not isinstance(config, dict) or "task" not in config:
        return ""
    args = " ".join(
        f"--task-arg {k}={json.dumps(v, separators=(',', ':'))}" for k, v in (config.get("task_kwargs") or {}).items()
    )
    hidden = ",".join(map(str, config.get("hidden") or ()))
    return f"; it was trained on {config['task']} with {args or 'no task arguments'} --hidden {hidden}"


def check_action_units(meta: dict[str, Any], units: str, where: Path) -> None:
    """Raise :class:`CheckpointError` if a checkpoint's policy acts in other units than its environment now takes: a
    parameterised-action run saved before parameters were normalised (no ``action_units``) acted in native units."""
    saved = meta.get("action_units", "native")
    if saved != units:
        raise CheckpointError(f"{where}: its policy acts in {saved} units, and {meta['config']['task']}'s parameterised "
                              f"actions are now taken in {units} ones (a run saved before hrlp took parameters in [-1, 1] "
                              "acted in the environment's own units); train the run again")  # fmt: skip


@dataclass
class TrainedPolicy:
    """A trained run's policy ready to act in its environment: frozen normaliser, actions decoded for the env."""

    policy: Policy
    normalizer: RunningNormalizer
    config: TrainConfig
    meta: dict[str, Any]
    _decoder: tuple[gym.Space, Callable] | None = field(default=None, repr=False)

    def make_env(self, **kwargs: Any) -> gym.Env:
        """A fresh environment of the run (a :class:`MacroEnv` for a Manager); ``kwargs`` go to the task.

        Training-only task arguments (:data:`TRAINING_ONLY_TASK_ARGS`, e.g. the angle curriculum) are dropped, so
        a run is evaluated and shown on the task's full start distribution."""
        return self._factory(kwargs)()

    def vector_env(self, n: int, **kwargs: Any) -> VectorEnv:
        """``n`` environments of the run as one :class:`~hrlp.envs.vector.VectorEnv`, stepped by the run's backend
        (environment ``i`` as :meth:`make_env`'s); ``kwargs`` go to the task, as for :meth:`make_env`."""
        return build_vector_env([self._factory(kwargs)] * n, self.config.advantage.gamma)

    def _factory(self, kwargs: dict[str, Any]) -> Callable[[], gym.Env]:
        """The run's environment constructor (its backend's), without the training-only task arguments, with
        ``kwargs`` over the run's task arguments."""
        cfg = self.config
        task_kwargs = {k: v for k, v in cfg.task_kwargs.items() if k not in TRAINING_ONLY_TASK_ARGS}
        return run_factory(cfg, {**task_kwargs, **kwargs})

    def act_rows(self, obs: np.ndarray, generator: torch.Generator | None = None, deterministic: bool = True) -> np.ndarray:
        """Flat action rows ``[N, act_dim]`` for raw observations ``[N, obs_dim]`` (what a VectorEnv steps)."""
        return self.policy.act_numpy(self.normalizer(obs, update=False).astype(np.float32), generator, deterministic)

    def act(self, env: gym.Env, obs: np.ndarray, generator: torch.Generator | None = None, deterministic: bool = True) -> Any:
        """The action for one raw observation, in ``env``'s action space (clipped / a parameterised tuple)."""
        a = self.policy.act_numpy(self.normalizer(obs, update=False)[None].astype(np.float32), generator, deterministic)
        if self._decoder is None or self._decoder[0] is not env.action_space:  # built once per environment, not per step
            self._decoder = (env.action_space, action_decoder(env.action_space))
        return self._decoder[1](a)[0]


def load_trained(run_dir: Path) -> TrainedPolicy:
    """The policy of the run in ``run_dir`` (its ``checkpoint``), ready to act."""
    policy, normalizer, meta = load_policy(Path(run_dir) / "checkpoint")
    return TrainedPolicy(policy, normalizer, TrainConfig.from_json(meta["config"]), meta)  # checked by load_policy


def run_meta(trainer: Any) -> dict[str, Any]:
    """The metadata every trainer's checkpoint holds (on-policy or off-policy alike): its sampler's state, what it trains
    (flat or Manager, the skills' hashes, the action units, the config), its progress counters and its normaliser."""
    cfg = trainer.cfg
    return {
        "sampler": trainer.sampler.get_state(),
        "kind": "flat" if cfg.macro is None else "manager",
        "skills": trainer.skill_hashes,
        "action_units": trainer.action_units,
        "config": cfg.to_json(),
        "iteration": trainer.iteration,
        "env_steps": trainer.env_steps,
        "episodes_done": trainer.episodes_done,
        "normalizer": trainer.normalizer.config(),
        "obs_dim": trainer.obs_dim,
    }


def iteration_stats(trainer: Any, episodes: list[Episode]) -> dict[str, float]:
    """The statistics every trainer logs for an iteration that finished ``episodes``: its counters, and the episodes'
    mean return, length, success rate and TargetDistSum (NaN where none ended or none has the figure)."""
    return {
        "iteration": trainer.iteration,
        "env_steps": trainer.env_steps,
        "episodes": len(episodes),
        "episodes_total": trainer.episodes_done,
        "return_mean": mean_or_nan([e.ret for e in episodes]),
        "episode_length": mean_or_nan([e.length for e in episodes]),
        "success_rate": mean_or_nan([e.success for e in episodes]),
        "target_dist_sum": mean_or_nan([e.target_dist_sum for e in episodes]),
    }


def make_policy(cfg: TrainConfig, obs_dim: int, space: gym.Space) -> Policy:
    """The policy network of ``cfg``'s runs for ``space``: SAC's squashed actor for an off-policy run, else
    :func:`~hrlp.policies.mlp.policy_for_space`'s (with ``cfg.init_log_std``)."""
    if cfg.algo in OFF_POLICY:
        return SACActor(obs_dim, space, cfg.sac.hidden)
    return policy_for_space(obs_dim, space, cfg.hidden, cfg.init_log_std)


def load_policy(directory: Path) -> tuple[Policy, RunningNormalizer, dict[str, Any]]:
    """The trained policy (flat or Manager) and its frozen observation normaliser from a checkpoint directory."""
    tensors, meta, cfg = read_run_checkpoint(directory)
    env = env_factory(cfg.task, cfg.episode_steps, cfg.macro, cfg.advantage.gamma, **cfg.task_kwargs)()
    obs_dim = int(np.prod(env.observation_space.shape))
    if isinstance(env, MacroEnv):
        check_skill_hashes(meta.get("skills", {}), skill_hashes(env.skills), directory)
    check_action_units(meta, action_units(env), directory)
    policy = make_policy(cfg, obs_dim, env.action_space)
    env.close()
    load_module("policy", policy, tensors)
    normalizer = RunningNormalizer.from_config(
        meta["normalizer"], {k.removeprefix("normalizer."): v for k, v in tensors.items() if k.startswith("normalizer.")}
    )
    normalizer.freeze()
    return policy, normalizer, meta


def from_run(run_dir: str | Path, name: str | None = None, *, param: str | None = "desired_goal", low: object = None,
             high: object = None, k: int = 10, done_part: str | None = None, done_within: float | None = None,
             bind: Mapping[str, Sequence[str]] | None = None) -> PolicySkill:  # fmt: skip
    """A skill from a flat run hrlp trained on any Gymnasium environment (its checkpoint: safetensors + JSON).

    ``param`` names the part of the run's Dict observation its parameters replace (default ``desired_goal``; None
    for none, and for a run on a Box observation, which reads the part ``observation``); ``low``/``high`` bound them
    (default: that part's bounds in the run's environment, when finite); ``done_part``/``done_within`` end it early;
    ``bind`` reads its parts under the names they have where it runs (:class:`~hrlp.skills.policy.PolicySkill`).
    :func:`policy_skill_files` writes the same skill into a library."""
    run = Path(run_dir)
    trained, parts, param, box, action_space = _run_skill(run, param, low, high)

    def policy(x: np.ndarray) -> np.ndarray:
        return trained.act_rows(x, None, True)

    return PolicySkill(name or run.name, parts, param, box, policy, action_space.low, action_space.high, k=k,
                       done_part=done_part, done_within=done_within, bind=bind)  # fmt: skip


def policy_skill_files(run_dir: str | Path, *, param: str | None = "desired_goal", low: object = None, high: object = None,
                       k: int = 10, done_part: str | None = None, done_within: float | None = None,
                       bind: Mapping[str, Sequence[str]] | None = None,
                       ) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:  # fmt: skip
    """The tensors and manifest of :func:`from_run`'s skill as a library file (``hrlp skills add RUN --param ...``;
    :meth:`hrlp.skills.library.SkillLibrary.save` writes them): the run's policy and frozen normaliser, the observation
    parts it reads, its parameter part and box, its action bounds and its early end. Raises a one-line ValueError for a
    run that cannot be one (checked as :func:`from_run` checks it)."""
    run = Path(run_dir)
    trained, parts, param, box, action_space = _run_skill(run, param, low, high)
    squashed = isinstance(trained.policy, SACActor)
    checked = dict(k=k, done_part=done_part, done_within=done_within, bind=bind)  # PolicySkill checks them
    skill = PolicySkill(run.name, parts, param, box, lambda x: x, action_space.low, action_space.high, **checked)  # type: ignore[arg-type]
    tensors, meta, cfg = read_run_checkpoint(run / "checkpoint")
    kept = {key: v for key, v in tensors.items() if key.startswith(("policy.", "normalizer."))}
    manifest = {
        "task": cfg.task,
        "k": skill.k,
        "parts": [list(p) for p in parts],
        "param_part": param,
        "param": box.to_json(),
        "done": None if done_part is None else {"part": done_part, "within": float(done_within)},  # type: ignore[arg-type]
        "bind": {own: list(src) for own, src in skill.bind.items()},
        "action_low": [float(v) for v in np.asarray(action_space.low, np.float64).reshape(-1)],
        "action_high": [float(v) for v in np.asarray(action_space.high, np.float64).reshape(-1)],
        "obs_dim": int(meta["obs_dim"]),
        "act_dim": int(meta["act_dim"]),
        "actor": SQUASHED_ACTOR if squashed else GAUSSIAN_ACTOR,
        "hidden": list(cfg.sac.hidden if squashed else cfg.hidden),
        "normalizer": meta["normalizer"],
        "trained": {"config": meta["config"], "iteration": meta["iteration"], "env_steps": meta["env_steps"]},
    }
    return kept, manifest


_RunSkill = tuple["TrainedPolicy", list[tuple[str, int]], str | None, ParamBox, gym.spaces.Box]


def _run_skill(run: Path, param: str | None, low: object, high: object) -> _RunSkill:
    """The trained run, the observation parts its policy reads, its parameter part and box, and its action space."""
    trained = load_trained(run)
    if trained.config.macro is not None:
        raise ValueError(f"{run}: a skill is a flat policy; this run trained a Manager")
    env = trained.make_env()
    space, action_space = own_observation_space(env), env.action_space
    env.close()
    if not isinstance(action_space, gym.spaces.Box):
        raise ValueError(f"{run}: a skill emits Box actions; this run's action space is {action_space}")
    layout = ObsLayout.of_space(space)  # the row its policy reads: the keys, without parts named inside them
    parts = [(n, layout.width(n)) for n in layout.names]
    if param is not None and param not in layout.names:
        if isinstance(space, gym.spaces.Dict):
            raise ValueError(f"{run}: no observation part {param!r} to take the parameters (its parts: "
                             f"{', '.join(layout.names)}); name another")  # fmt: skip
        param = None
    recorded = None
    if param is not None and isinstance(space, gym.spaces.Dict):
        sub = space.spaces[param]
        recorded = (np.asarray(sub.low, np.float64).reshape(-1), np.asarray(sub.high, np.float64).reshape(-1))
    box = param_box(low, high, layout.width(param) if param else 0, recorded, str(run))
    return trained, parts, param, box, action_space
