"""The one training loop: collect, advantages, fit the baseline, policy step, log.

Flat policies (any hrlp task, any Gymnasium id with a Box, Discrete or parameterised
``Tuple(Discrete(n), Box, ...)`` action space) and Managers (an hrlp task wrapped in a
:class:`~hrlp.skills.macro_env.MacroEnv` of frozen skills) go through the same loop; the
Manager's batch carries the per-decision discount gamma^tau that GAE applies.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import json
import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from hrlp.algos.kernels import gae
from hrlp.algos.trpo import TRPOConfig, trpo_update
from hrlp.algos.value import ValueFitConfig, fit_value
from hrlp.atomic import atomic_path
from hrlp.checkpoint import load_checkpoint, load_module, module_tensors, pack_generators, save_checkpoint, unpack_generators
from hrlp.policies.mlp import GaussianPolicy, Policy, ValueNet, policy_for_space
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.rollout import ParallelSampler, Sampler, action_decoder, mean_or_nan
from hrlp.skills.macro_env import MacroEnv, MacroSpec


@dataclass(frozen=True)
class TrainConfig:
    """Settings of a TRPO run, flat or Manager (defaults from the paper's Appendix D)."""

    task: str
    """An hrlp task name (``hrlp tasks``) or a Gymnasium id, e.g. Pusher-v5."""
    steps: int = 1_000_000
    """Low-level environment steps in total (a Manager's macro-action of tau steps counts tau)."""
    batch_steps: int = 50_000
    """Decisions per TRPO iteration (the paper: 50,000 for flat runs, 5,000 for Managers)."""
    num_envs: int = 16
    """Environments stepped together with batched inference."""
    workers: int = 1
    """Processes that sample at the same time, each stepping its share of the environments (1: in this process)."""
    seed: int = 0
    """Seed of the environments, the network initialisation and the action noise."""
    episode_steps: int | None = None
    """Episode length for hrlp tasks (None: the task's default, 300)."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layer widths of the policy and value networks."""
    init_log_std: float = 0.0
    """Initial log standard deviation of the policy's Gaussian action noise (0: std 1 on [-1, 1] torques)."""
    trpo: TRPOConfig = field(default_factory=TRPOConfig)
    """TRPO settings (max KL 0.01, gamma 0.99, ...)."""
    value: ValueFitConfig = field(default_factory=ValueFitConfig)
    """Value-baseline fit settings."""
    macro: MacroSpec | None = None
    """For a Manager: its skills, their duration k and the micro-action; None for a flat policy."""
    task_kwargs: dict[str, Any] = field(default_factory=dict)
    """Arguments of the task, e.g. ``{"c1": -10.0}`` (Gripper reward constants) or ``{"curriculum_alpha": 1e-4}``."""

    def __post_init__(self) -> None:
        for name in ("steps", "batch_steps", "num_envs", "workers"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        if self.workers > self.num_envs:
            raise ValueError(f"workers ({self.workers}) must be at most num_envs ({self.num_envs})")
        if self.batch_steps < self.num_envs:
            raise ValueError(f"batch_steps ({self.batch_steps}) must be at least num_envs ({self.num_envs})")
        if self.episode_steps is not None and (not isinstance(self.episode_steps, int) or self.episode_steps <= 0):
            raise ValueError(f"episode_steps must be a positive integer, got {self.episode_steps!r}")
        if not self.hidden or any(h <= 0 for h in self.hidden):
            raise ValueError(f"hidden must be positive layer widths, got {self.hidden!r}")
        if not (isinstance(self.init_log_std, int | float) and math.isfinite(self.init_log_std)):
            raise ValueError(f"init_log_std must be a finite number, got {self.init_log_std!r}")
        if not isinstance(self.task_kwargs, dict) or not all(isinstance(k, str) for k in self.task_kwargs):
            raise ValueError(f"task_kwargs must map argument names to values, got {self.task_kwargs!r}")

    @property
    def steps_per_env(self) -> int:
        """Decisions each environment takes per iteration."""
        return math.ceil(self.batch_steps / self.num_envs)

    def to_json(self) -> dict[str, Any]:
        """A JSON-serialisable dict of every setting."""
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_json`."""
        d = dict(d)
        d["hidden"] = tuple(d["hidden"])
        d["trpo"] = TRPOConfig(**d["trpo"])
        d["value"] = ValueFitConfig(**d["value"])
        d["macro"] = MacroSpec.from_json(d["macro"]) if d.get("macro") else None
        return cls(**d)


def env_factory(
    task: str, episode_steps: int | None = None, macro: MacroSpec | None = None, gamma: float = 0.99, **kwargs: Any
) -> Callable[[], gym.Env]:
    """A constructor for ``task`` (an hrlp task name/id or a Gymnasium id), wrapped in a :class:`MacroEnv` of
    ``macro``'s skills (loaded once, shared, frozen) for a Manager. Raises ValueError for an unknown task, a
    missing skill, or an unsupported action space, before any compute. The constructor can be pickled (sampler
    worker processes rebuild it; a Manager's skills are then loaded again there, from the same files)."""
    from hrlp.envs import TASKS, make

    name = task.removeprefix("hrlp/").removesuffix("-v0")
    if name in TASKS:
        kw = dict(kwargs)
        if episode_steps is not None:
            kw["episode_steps"] = episode_steps
        make(name, **kw).close()  # validate arguments now, before any compute
        if macro is None:
            return functools.partial(make, name, **kw)
        return _MacroFactory(name, kw, macro, gamma, macro.load_skills())
    if macro is not None:
        raise ValueError(f"{task}: a Manager commands arm skills, so its task must be an hrlp task (see 'hrlp tasks')")
    if task not in gym.registry:
        raise ValueError(f"unknown task {task!r}: not an hrlp task (see 'hrlp tasks') nor a registered Gymnasium id")
    probe = gym.make(task, **kwargs)
    space = probe.action_space
    probe.close()
    try:
        action_decoder(space)
    except ValueError as e:
        raise ValueError(f"{task}: {e}") from None
    return functools.partial(gym.make, task, **kwargs)


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
        return MacroEnv(make(self.name, **self.kwargs), self._skills, self.macro.k, self.macro.micro, self.gamma,
                        self.macro.handover)

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_skills": None}


class Trainer:
    """TRPO on one task, flat or Manager: owns the policy, the baseline, the normaliser and the sampler.

    With ``cfg.workers > 1`` this process computes with one torch thread while the workers sample (the baseline fit
    runs then, and more threads would only compete with them for the cores), and with one thread per worker (at most
    one per core) for the TRPO step, while the workers wait for the next batch's weights.
    """

    def __init__(self, cfg: TrainConfig) -> None:
        self.cfg = cfg
        factory = env_factory(cfg.task, cfg.episode_steps, cfg.macro, cfg.trpo.gamma, **cfg.task_kwargs)
        torch.manual_seed(cfg.seed)
        probe = factory()
        obs_dim = int(np.prod(probe.observation_space.shape))
        self.skill_hashes = {s.name: s.content_hash for s in probe.skills} if isinstance(probe, MacroEnv) else {}
        self.policy = policy_for_space(obs_dim, probe.action_space, cfg.hidden, cfg.init_log_std)
        self.obs_dim = obs_dim
        probe.close()
        self.value_net = ValueNet(obs_dim, cfg.hidden)
        self.normalizer = RunningNormalizer(obs_dim)
        envs = [factory] * cfg.num_envs
        self.sampler: Sampler | ParallelSampler
        self._update_threads: int | None = None
        """Torch threads of this process during the TRPO step (one while workers sample); None: torch's own throughout."""
        if cfg.workers > 1:
            # While the workers sample they keep the cores busy, and a second torch thread here only competes with them
            # (fewer steps/s with the demo's Manager on two cores); during the TRPO step they wait, and the cores are free.
            self._update_threads = max(1, min(cfg.workers, os.cpu_count() or 1))
            torch.set_num_threads(1)
            self.sampler = ParallelSampler(envs, self.policy, self.normalizer, seed=cfg.seed, workers=cfg.workers)
        else:
            self.sampler = Sampler(envs, self.policy, self.normalizer, seed=cfg.seed)
        self.iteration = 0
        self.env_steps = 0
        self.pending_value_fit: tuple[torch.Tensor, torch.Tensor] | None = None
        """``(obs [B, D], returns [B])`` of the last batch, which the baseline is fitted on in the next iteration."""

    def iterate(self) -> dict[str, float]:
        """One iteration: collect, GAE, TRPO step; returns its statistics.

        The baseline is fitted on each batch while the next batch is being sampled (the value function plays no
        part in sampling, so the numbers are those of fitting it right after the TRPO step; with sampling
        workers, the fit runs while they sample). The ``value/*`` statistics are those of the fit finished in
        this iteration, on the previous batch (NaN in the first iteration).
        """
        cfg = self.cfg
        t0 = time.perf_counter()
        timing = self.sampler.timing
        env0, inf0, phys0 = timing.env, timing.inference, timing.physics
        self.sampler.request(cfg.steps_per_env)
        vstats = None
        if self.pending_value_fit is not None:
            vstats = fit_value(self.value_net, *self.pending_value_fit, cfg.value)
            self.pending_value_fit = None
        t_fit = time.perf_counter() - t0
        batch, episodes = self.sampler.receive()
        t1 = time.perf_counter()
        if self._update_threads is not None:
            torch.set_num_threads(self._update_threads)
        T, N, D = batch.obs.shape
        obs = batch.obs.reshape(T * N, D)
        with torch.no_grad():
            values = self.value_net(obs).reshape(T, N)
            next_values = self.value_net(batch.next_obs.reshape(T * N, D)).reshape(T, N)
        adv = gae(batch.rewards, values, next_values, batch.terminated, batch.truncated, cfg.trpo.gamma, cfg.trpo.gae_lambda,
                  discount=batch.discount)  # fmt: skip
        actions = batch.actions.reshape(T * N, *batch.actions.shape[2:])
        with torch.no_grad():
            old_dist = self.policy(obs)
        stride = round(1 / cfg.trpo.fisher_fraction)
        stats = trpo_update(
            list(self.policy.parameters()), lambda: self.policy(obs), old_dist, actions, adv.advantages.reshape(-1), cfg.trpo,
            fisher_dist_fn=None if stride == 1 else lambda: self.policy(obs[::stride]),
        )  # fmt: skip
        vstride = round(1 / cfg.value.fraction)  # whole time steps, so every environment's episodes stay in the fit
        self.pending_value_fit = (batch.obs[::vstride].reshape(-1, D), adv.returns[::vstride].reshape(-1).detach())
        if self._update_threads is not None:
            torch.set_num_threads(1)
        t2 = time.perf_counter()
        self.iteration += 1
        self.env_steps += batch.env_steps
        wall = t2 - t0
        out: dict[str, float] = {
            "iteration": self.iteration,
            "env_steps": self.env_steps,
            "episodes": len(episodes),
            "return_mean": mean_or_nan([e.ret for e in episodes]),
            "episode_length": mean_or_nan([e.length for e in episodes]),
            "success_rate": mean_or_nan([e.success for e in episodes]),
            "target_dist_sum": mean_or_nan([e.target_dist_sum for e in episodes]),
            **{f"trpo/{k}": float(v) for k, v in stats.to_dict().items()},
            "value/explained_variance_before": math.nan if vstats is None else vstats.explained_variance_before,
            "value/explained_variance_after": math.nan if vstats is None else vstats.explained_variance_after,
            "time/env_share": (timing.env - env0) / wall,
            "time/inference_share": (timing.inference - inf0) / wall,
            "time/value_fit_share": t_fit / wall,
            "time/update_share": (t2 - t1) / wall,
            # mj_step's share of the cores' time: of one core, or of one core per sampling worker.
            "time/physics_share": (timing.physics - phys0) / (wall * max(1, cfg.workers)),
            "time/steps_per_s": batch.env_steps / wall,
        }
        if cfg.macro is not None:
            out["manager/decisions"] = batch.steps
            out["manager/mean_tau"] = batch.env_steps / batch.steps
        return out

    # --- persistence --------------------------------------------------------------------------
    def state(self) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
        """Tensors and JSON metadata of the whole training state."""
        tensors = {**module_tensors("policy", self.policy), **module_tensors("value", self.value_net)}
        tensors.update({f"normalizer.{k}": v for k, v in self.normalizer.state_dict().items()})
        rng_tensors, rng_meta = pack_generators({}, self._generators())
        tensors.update(rng_tensors)
        if self.pending_value_fit is not None:
            tensors["pending_value_fit.obs"], tensors["pending_value_fit.returns"] = self.pending_value_fit
        meta = {
            **rng_meta,
            "sampler": self.sampler.get_state(),
            "kind": "flat" if self.cfg.macro is None else "manager",
            "skills": self.skill_hashes,
            "config": self.cfg.to_json(),
            "iteration": self.iteration,
            "env_steps": self.env_steps,
            "normalizer": self.normalizer.config(),
            "obs_dim": self.obs_dim,
        }
        if isinstance(self.policy, GaussianPolicy):
            meta["act_dim"] = int(self.policy.log_std.numel())
        return tensors, meta

    @classmethod
    def resume(cls, directory: Path) -> Trainer:
        """A trainer restored from a checkpoint written by :meth:`save`: it continues exactly where that run was.

        On CPU, with hrlp tasks (whose environments save their exact state), the resumed run produces the same
        numbers as an uninterrupted one. Other Gymnasium environments restart their episodes.
        """
        tensors, meta = load_checkpoint(directory)
        trainer = cls(TrainConfig.from_json(meta["config"]))
        check_skill_hashes(meta.get("skills", {}), trainer.skill_hashes, directory)
        load_module("policy", trainer.policy, tensors)
        load_module("value", trainer.value_net, tensors)
        trainer.normalizer.load_state_dict({k.removeprefix("normalizer."): v for k, v in tensors.items()
                                            if k.startswith("normalizer.")})  # fmt: skip
        unpack_generators(tensors, meta, {}, trainer._generators())
        trainer.sampler.set_state(meta["sampler"])
        trainer.iteration, trainer.env_steps = int(meta["iteration"]), int(meta["env_steps"])
        if "pending_value_fit.obs" in tensors:
            trainer.pending_value_fit = (tensors["pending_value_fit.obs"], tensors["pending_value_fit.returns"])
        return trainer

    def _generators(self) -> dict[str, torch.Generator]:
        # Worker processes keep their own generators, saved with the sampler's state.
        gen = self.sampler.generator
        return {} if gen is None else {"actions": gen}

    def save(self, directory: Path) -> Path:
        """Write the policy, baseline, normaliser and progress atomically to ``directory``."""
        tensors, meta = self.state()
        return save_checkpoint(directory, tensors, meta)


def check_skill_hashes(saved: dict[str, str], loaded: dict[str, str], where: Path) -> None:
    """Raise ValueError if a skill a Manager was trained with has changed since (its content hash differs)."""
    for name, h in saved.items():
        if loaded.get(name) != h:
            raise ValueError(
                f"{where}: skill {name!r} has changed since this Manager was trained "
                f"(sha256 {h[:12]} then, {str(loaded.get(name))[:12]} now)"
            )


#: Task arguments that shape training only; evaluation and rendering leave them out. The angle curriculum of
#: Section 4.3.2 narrows the start set for the first episodes of every environment, so a fresh evaluation
#: environment would otherwise see only the easiest starts.
TRAINING_ONLY_TASK_ARGS = frozenset({"curriculum_alpha"})


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
        cfg = self.config
        task_kwargs = {k: v for k, v in cfg.task_kwargs.items() if k not in TRAINING_ONLY_TASK_ARGS}
        return env_factory(cfg.task, cfg.episode_steps, cfg.macro, cfg.trpo.gamma, **{**task_kwargs, **kwargs})()

    def act(self, env: gym.Env, obs: np.ndarray, generator: torch.Generator | None = None, deterministic: bool = True) -> Any:
        """The action for one raw observation, in ``env``'s action space (clipped / a parameterised tuple)."""
        a = self.policy.act_numpy(self.normalizer(obs, update=False)[None].astype(np.float32), generator, deterministic)
        if self._decoder is None or self._decoder[0] is not env.action_space:  # built once per environment, not per step
            self._decoder = (env.action_space, action_decoder(env.action_space))
        return self._decoder[1](a)[0]


def load_trained(run_dir: Path) -> TrainedPolicy:
    """The policy of the run in ``run_dir`` (its ``checkpoint``), ready to act."""
    policy, normalizer, meta = load_policy(Path(run_dir) / "checkpoint")
    return TrainedPolicy(policy, normalizer, TrainConfig.from_json(meta["config"]), meta)


def load_policy(directory: Path) -> tuple[Policy, RunningNormalizer, dict[str, Any]]:
    """The trained policy (flat or Manager) and its frozen observation normaliser from a checkpoint directory."""
    tensors, meta = load_checkpoint(directory)
    cfg = TrainConfig.from_json(meta["config"])
    env = env_factory(cfg.task, cfg.episode_steps, cfg.macro, cfg.trpo.gamma, **cfg.task_kwargs)()
    obs_dim = int(np.prod(env.observation_space.shape))
    if isinstance(env, MacroEnv):
        check_skill_hashes(meta.get("skills", {}), {s.name: s.content_hash for s in env.skills}, directory)
    policy = policy_for_space(obs_dim, env.action_space, cfg.hidden)
    env.close()
    load_module("policy", policy, tensors)
    normalizer = RunningNormalizer.from_config(
        meta["normalizer"], {k.removeprefix("normalizer."): v for k, v in tensors.items() if k.startswith("normalizer.")}
    )
    normalizer.freeze()
    return policy, normalizer, meta


class RunLogger:
    """Writes each iteration's statistics to ``progress.csv`` and TensorBoard under the run directory."""

    def __init__(self, run_dir: Path) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.run_dir = run_dir
        self._csv_path = run_dir / "progress.csv"
        self._fields: list[str] | None = None
        self._tb = SummaryWriter(str(run_dir / "tb"))

    def log(self, stats: dict[str, float]) -> None:
        """Append one row. The header comes from the first row, or from the file a resumed run already wrote; a
        statistic that file lacks (logged by a later version of hrlp) widens its header, older rows leaving it empty."""
        if self._fields is None:
            rows = _read_csv(self._csv_path)
            if rows:
                added = [k for k in stats if k not in rows[0]]
                if added:
                    _write_csv(self._csv_path, [rows[0] + added] + [r + [""] * len(added) for r in rows[1:]])
                self._fields = rows[0] + added
            else:
                self._fields = list(stats)
                _write_csv(self._csv_path, [self._fields])
        with self._csv_path.open("a", newline="") as f:
            csv.writer(f).writerow([stats.get(k, math.nan) for k in self._fields])
        step = int(stats["env_steps"])
        for k, v in stats.items():
            if isinstance(v, int | float) and math.isfinite(v):
                self._tb.add_scalar(k, v, step)
        self._tb.flush()

    def close(self) -> None:
        """Flush and close TensorBoard."""
        self._tb.close()


def train(cfg: TrainConfig, run_dir: Path, resume: bool = False) -> Iterator[dict[str, float]]:
    """Train, yielding each iteration's statistics; writes logs, a checkpoint per iteration, and ``config.json``.

    With ``resume``, continue from ``run_dir/checkpoint`` (its config must equal ``cfg`` except ``steps``, which
    may grow); log rows written after that checkpoint are dropped so the log matches the restored state.
    """
    if resume:
        trainer = Trainer.resume(run_dir / "checkpoint")
        saved = trainer.cfg
        if dataclasses.replace(saved, steps=cfg.steps) != cfg:
            raise ValueError(f"{run_dir}: --resume needs the run's own settings (only --steps may change)")
        trainer.cfg = cfg
        _truncate_log(run_dir / "progress.csv", trainer.iteration)
    else:
        if (run_dir / "checkpoint").exists():
            raise ValueError(f"{run_dir} already holds a run; pass --resume to continue it or choose another --run-dir")
        run_dir.mkdir(parents=True, exist_ok=True)
        trainer = Trainer(cfg)
    (run_dir / "config.json").write_text(json.dumps(cfg.to_json(), indent=2))
    logger = RunLogger(run_dir)
    try:
        while trainer.env_steps < cfg.steps:
            stats = trainer.iterate()
            trainer.save(run_dir / "checkpoint")
            logger.log(stats)
            yield stats
    finally:
        logger.close()
        trainer.sampler.close()


def train_with_progress(cfg: TrainConfig, run_dir: Path, resume: bool = False, console: Any = None,
                        description: str | None = None) -> None:  # fmt: skip
    """:func:`train` behind a rich progress bar on ``console`` (return, success, KL and steps/s so far)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    columns = [TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
               TextColumn("{task.fields[status]}")]  # fmt: skip
    with Progress(*columns, console=console) as progress:
        bar = progress.add_task(description or f"train {cfg.task}", total=cfg.steps, status="")
        for st in train(cfg, run_dir, resume=resume):
            status = f"return {st['return_mean']:.1f}"
            if not math.isnan(st["success_rate"]):
                status += f"  success {st['success_rate']:.2f}"
            status += f"  kl {st['trpo/kl']:.4f}  {st['time/steps_per_s']:.0f} steps/s"
            progress.update(bar, completed=min(st["env_steps"], cfg.steps), status=status)


def _truncate_log(path: Path, iteration: int) -> None:
    """Keep the header and the rows up to ``iteration`` (a kill between checkpoint and log leaves at most one gap)."""
    rows = _read_csv(path)
    if rows:
        _write_csv(path, [rows[0]] + [r for r in rows[1:] if r and int(float(r[0])) <= iteration])


def _read_csv(path: Path) -> list[list[str]]:
    """Every row of a CSV file, the header first; [] if there is no file."""
    if not path.exists():
        return []
    with path.open(newline="") as f:
        return list(csv.reader(f))


def _write_csv(path: Path, rows: list[list[str]]) -> None:
    """Replace ``path`` with ``rows``, atomically."""
    with atomic_path(path) as tmp, tmp.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
