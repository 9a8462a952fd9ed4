"""The training loop: collect, advantages, fit the baseline, policy step, log (:class:`Trainer`), and the run
around it (:func:`train`: budgets, checkpoints, resume, warnings; :func:`train_with_progress`: its progress bar).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from hrlp.algos.kernels import gae
from hrlp.algos.update import make_update
from hrlp.algos.value import fit_value
from hrlp.atomic import directory_lock, writing
from hrlp.checkpoint import (
    checkpoint_exists,
    load_module,
    module_tensors,
    pack_generators,
    read_run_checkpoint,
    save_checkpoint,
    unpack_generators,
)
from hrlp.config import OFF_POLICY, TrainConfig
from hrlp.envs.faults import EnvError
from hrlp.policies.mlp import GaussianPolicy, ValueNet
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.rollout import (
    Batch,
    NonFiniteError,
    ParallelSampler,
    Sampler,
    first_non_finite,
)
from hrlp.skills.macro_env import MacroEnv
from hrlp.stopping import raise_if_stopping, shielded
from hrlp.training.environments import action_units, check_skill_hashes, resolve_config, run_factory, skill_hashes
from hrlp.training.loading import check_action_units, iteration_stats, make_policy, run_meta, warm_start
from hrlp.training.logs import RunLogger, progress_line, shown, truncate_log, update_stat
from hrlp.training.offpolicy import OffPolicyTrainer


class Trainer:
    """TRPO on one task, flat or Manager: owns the policy, the baseline, the normaliser and the sampler.

    With ``cfg.workers > 1`` this process computes with one torch thread while the workers sample (the baseline fit
    runs then, and more threads would only compete with them for the cores), and with one thread per worker (at most
    one per core) for the TRPO step, while the workers wait for the next batch's weights. A config whose ``workers``
    is 0 (the default) is run with the count :func:`~hrlp.training.environments.resolve_config` gives, which
    ``self.cfg`` records.
    """

    def __init__(self, cfg: TrainConfig, *, from_checkpoint: bool = False) -> None:
        """``from_checkpoint``: the weights will be loaded from a checkpoint (:meth:`resume`), so ``cfg.init_from`` is
        not read again (the skill it names may have changed or gone since the run started)."""
        self.cfg = cfg = resolve_config(cfg)
        factory = run_factory(cfg)  # batched: every world of a process's share in one VectorEnv (build_vector_env)
        torch.manual_seed(cfg.seed)
        probe = factory()
        obs_dim = int(np.prod(probe.observation_space.shape))
        self.skill_hashes = skill_hashes(probe.skills) if isinstance(probe, MacroEnv) else {}
        self.action_units = action_units(probe)
        self.policy = make_policy(cfg, obs_dim, probe.action_space)
        self.obs_dim = obs_dim
        probe.close()
        self.value_net = ValueNet(obs_dim, cfg.hidden)
        self.normalizer = RunningNormalizer(obs_dim)
        self.init_from_sha256: str | None = None
        """The content hash of the skill the run started from (``cfg.init_from``), recorded in every checkpoint."""
        if cfg.init_from is not None and not from_checkpoint:
            self.init_from_sha256 = warm_start(self.policy, self.normalizer, cfg)
        envs = [factory] * cfg.num_envs
        self.sampler: Sampler | ParallelSampler
        self._update_threads: int | None = None
        """Torch threads of this process during the TRPO step (one while workers sample); None: torch's own throughout."""
        if cfg.workers > 1:
            # While the workers sample they keep the cores busy, and a second torch thread here only competes with them
            # (fewer steps/s with the demo's Manager on two cores); during the TRPO step they wait, and the cores are free.
            self._update_threads = max(1, min(cfg.workers, os.cpu_count() or 1))
            torch.set_num_threads(1)
            self.sampler = ParallelSampler(envs, self.policy, self.normalizer, seed=cfg.seed, workers=cfg.workers,
                                           gamma=cfg.advantage.gamma)  # fmt: skip
        else:
            self.sampler = Sampler(envs, self.policy, self.normalizer, seed=cfg.seed, gamma=cfg.advantage.gamma)
        self.update = make_update(cfg, self.policy)
        """The policy step (TRPO or PPO, ``cfg.algo``)."""
        self.iteration = 0
        self.env_steps = 0
        self.episodes_done = 0
        """Training episodes finished so far (those that ended within a batch)."""
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
        try:
            batch, episodes = self.sampler.receive()
        except NonFiniteError as e:
            raise NonFiniteError(f"{cfg.task}, iteration {self.iteration + 1}: {e}") from None
        t1 = time.perf_counter()
        if self._update_threads is not None:
            torch.set_num_threads(self._update_threads)
        T, N, D = batch.obs.shape
        obs = batch.obs.reshape(T * N, D)
        values, next_values = batch_values(self.value_net, batch)
        rewards = batch.rewards if cfg.reward_scale == 1 else batch.rewards * cfg.reward_scale  # training only
        a = cfg.advantage
        adv = gae(rewards, values, next_values, batch.terminated, batch.truncated, a.gamma, a.gae_lambda,
                  discount=batch.discount)  # fmt: skip
        self._check_value_targets(values, next_values, adv.advantages, adv.returns)
        actions = batch.actions.reshape(T * N, *batch.actions.shape[2:])
        stats = self.update(obs, actions, adv.advantages.reshape(-1))
        vstride = round(1 / cfg.value.fraction)  # whole time steps, so every environment's episodes stay in the fit
        self.pending_value_fit = (batch.obs[::vstride].reshape(-1, D), adv.returns[::vstride].reshape(-1).detach())
        if self._update_threads is not None:
            torch.set_num_threads(1)
        t2 = time.perf_counter()
        self.iteration += 1
        self.env_steps += batch.env_steps
        self.episodes_done += len(episodes)
        wall = t2 - t0
        out: dict[str, float] = {
            **iteration_stats(self, episodes),
            **{f"{self.update.name}/{k}": v for k, v in stats.items()},
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

    def _check_value_targets(self, values: torch.Tensor, next_values: torch.Tensor, advantages: torch.Tensor,
                             returns: torch.Tensor) -> None:  # fmt: skip
        """Raise :class:`NonFiniteError` naming the environment, the step and the field if the baseline's predictions,
        the advantages or the value targets (GAE returns) of the batch ``[T, N]`` hold a NaN or inf (the rewards and
        observations were checked by the sampler; this catches a diverged baseline or an overflow)."""
        for name, values_ in (("baseline value", values), ("baseline value of the next observation", next_values),
                              ("advantage", advantages), ("value target (GAE return)", returns)):  # fmt: skip
            where = first_non_finite(values_)
            if where is not None:
                t, i = where
                raise NonFiniteError(
                    f"{self.cfg.task}, iteration {self.iteration + 1}: non-finite {name} ({float(values_[t, i])}) for "
                    f"environment {i} at decision {t + 1} of the batch; stopped before the policy step, the baseline fit "
                    "and the checkpoint"
                )

    # --- persistence --------------------------------------------------------------------------
    def state(self) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
        """Tensors and JSON metadata of the whole training state."""
        tensors = {**module_tensors("policy", self.policy), **module_tensors("value", self.value_net)}
        tensors.update({f"normalizer.{k}": v for k, v in self.normalizer.state_dict().items()})
        rng_tensors, rng_meta = pack_generators({}, self._generators())
        tensors.update(rng_tensors)
        tensors.update(self.update.state())
        if self.pending_value_fit is not None:
            tensors["pending_value_fit.obs"], tensors["pending_value_fit.returns"] = self.pending_value_fit
        meta = {**rng_meta, **run_meta(self)}
        if isinstance(self.policy, GaussianPolicy):
            meta["act_dim"] = int(self.policy.log_std.numel())
        if self.init_from_sha256 is not None:
            meta["init_from_sha256"] = self.init_from_sha256
        return tensors, meta

    @classmethod
    def resume(cls, directory: Path) -> Trainer:
        """A trainer restored from a checkpoint written by :meth:`save`: it continues exactly where that run was.

        On CPU, with hrlp tasks (whose environments save their exact state), the resumed run produces the same
        numbers as an uninterrupted one. Other Gymnasium environments restart their episodes.
        """
        return cls.restore(directory, *read_run_checkpoint(directory, {"sampler": dict}))

    @classmethod
    def restore(cls, directory: Path, tensors: dict[str, torch.Tensor], meta: dict[str, Any], cfg: TrainConfig) -> Trainer:
        """The trainer of a checkpoint read from ``directory`` (:meth:`resume`)."""
        trainer = cls(cfg, from_checkpoint=True)
        check_skill_hashes(meta.get("skills", {}), trainer.skill_hashes, directory)
        check_action_units(meta, trainer.action_units, directory)
        if isinstance(meta.get("init_from_sha256"), str):  # the skill it started from
            trainer.init_from_sha256 = meta["init_from_sha256"]
        load_module("policy", trainer.policy, tensors)
        load_module("value", trainer.value_net, tensors)
        trainer.normalizer.load_state_dict({k.removeprefix("normalizer."): v for k, v in tensors.items()
                                            if k.startswith("normalizer.")})  # fmt: skip
        unpack_generators(tensors, meta, {}, trainer._generators())
        if cfg.algo != "trpo":
            trainer.update.load_state(tensors)
        trainer.sampler.set_state(meta["sampler"])
        trainer.iteration, trainer.env_steps = int(meta["iteration"]), int(meta["env_steps"])
        trainer.episodes_done = int(meta.get("episodes_done", 0))  # checkpoints before the episode budget lack it
        if "pending_value_fit.obs" in tensors:
            trainer.pending_value_fit = (tensors["pending_value_fit.obs"], tensors["pending_value_fit.returns"])
        return trainer

    def close(self) -> None:
        """Stop the sampler (and its worker processes)."""
        self.sampler.close()

    def _generators(self) -> dict[str, torch.Generator]:
        # Worker processes keep their own generators, saved with the sampler's state.
        gen = self.sampler.generator
        return {} if gen is None else {"actions": gen}

    def save(self, directory: Path) -> Path:
        """Write the policy, baseline, normaliser and progress atomically to ``directory``.

        Refuses (:class:`~hrlp.rollout.NonFiniteError`, nothing written) a state holding a NaN or inf, so a checkpoint
        is never poisoned: the previous one stays."""
        tensors, meta = self.state()
        for name, tensor in tensors.items():
            if tensor.is_floating_point() and (where := first_non_finite(tensor)) is not None:
                raise NonFiniteError(f"{self.cfg.task}, iteration {self.iteration}: {name}{list(where)} is "
                                     f"{float(tensor[where])}; refusing to save it over the checkpoint in "
                                     f"{directory}")  # fmt: skip
        return save_checkpoint(directory, tensors, meta)


def resume_trainer(directory: Path) -> Trainer | OffPolicyTrainer:
    """The trainer of the checkpoint in ``directory``, on-policy or off-policy as its run was trained."""
    tensors, meta, cfg = read_run_checkpoint(directory, {"sampler": dict})
    return (OffPolicyTrainer if cfg.algo in OFF_POLICY else Trainer).restore(directory, tensors, meta, cfg)


def batch_values(value_net: Callable[[torch.Tensor], torch.Tensor], batch: Batch) -> tuple[torch.Tensor, torch.Tensor]:
    """The baseline's ``V(s_t)`` and ``V(s_{t+1})`` over a batch, ``[T, N]`` each.

    Within an episode the next observation is the next step's observation (the normaliser's statistics stay fixed
    during a batch), so ``V(s_{t+1})`` is read from ``V(s_t)`` there and the network runs on ``next_obs`` only where an
    episode ended and at the batch's last step: one forward pass over the batch instead of two. A batch that breaks
    that rule (an environment whose next observation is not the one it steps from) gets the second pass."""
    T, N, D = batch.obs.shape
    with torch.no_grad():
        values = value_net(batch.obs.reshape(T * N, D)).reshape(T, N)
        ends = batch.terminated | batch.truncated
        ends[-1] = True
        inside = ~ends[:-1]
        if not torch.equal(batch.next_obs[:-1][inside], batch.obs[1:][inside]):
            return values, value_net(batch.next_obs.reshape(T * N, D)).reshape(T, N)
        next_values = torch.empty_like(values)
        next_values[:-1] = values[1:]
        next_values[ends] = value_net(batch.next_obs[ends]).reshape(-1)
    return values, next_values


def config_differences(saved: TrainConfig, given: TrainConfig, ignore: tuple[str, ...] = ("steps",)) -> list[str]:
    """The settings in which ``given`` differs from ``saved``, as ``"trpo.max_kl: 0.02 in the run, 0.01 given"``
    (dotted names of :meth:`TrainConfig.to_json`; the top-level names in ``ignore`` are left out). The task is compared
    by name (``Gripper``, ``hrlp/Gripper-v0`` and ``Gripper-v0`` are one task)."""

    def flat(d: Any, prefix: str = "") -> dict[str, Any]:
        if isinstance(d, dict) and d:
            return {k: v for key, value in d.items() for k, v in flat(value, f"{prefix}{key}.").items()}
        return {prefix.removesuffix("."): d}

    def task_name(task: str) -> str:
        return task.removeprefix("hrlp/").removesuffix("-v0")

    a = json.loads(json.dumps(saved.to_json()))  # tuples -> lists on both sides
    b = json.loads(json.dumps(given.to_json()))
    a["task"], b["task"] = task_name(a["task"]), task_name(b["task"])
    if (a["macro"] is None) != (b["macro"] is None):
        kind = {True: "a flat policy", False: "a Manager"}
        return [f"kind: {kind[a['macro'] is None]} in the run, {kind[b['macro'] is None]} given"]
    fa, fb = flat(a), flat(b)
    out = []
    for name in sorted(set(fa) | set(fb)):
        if name.split(".")[0] in ignore:
            continue
        va, vb = fa.get(name, "(unset)"), fb.get(name, "(unset)")
        if va != vb:
            out.append(f"{name}: {json.dumps(va)} in the run, {json.dumps(vb)} given")
    return out


@dataclass(frozen=True)
class StepPlan:
    """What a run will actually train: its step budget rounded up to whole iterations."""

    requested: int
    """``cfg.steps``: the low-level environment steps asked for."""
    done: int
    """Low-level steps already trained (a resumed run's)."""
    decisions_per_iteration: int
    """Decisions per iteration: ``ceil(batch_steps / num_envs) * num_envs``."""
    manager: bool
    """A Manager's decisions last one or more low-level steps each, so its total is known only as it runs."""

    @property
    def iterations(self) -> int | None:
        """Iterations still to run (None for a Manager: it depends on the macro-actions' lengths)."""
        if self.manager:
            return None
        return max(0, math.ceil((self.requested - self.done) / self.decisions_per_iteration))

    @property
    def total(self) -> int | None:
        """Low-level steps at the end of the run, exactly (None for a Manager)."""
        its = self.iterations
        return None if its is None else self.done + its * self.decisions_per_iteration

    def note(self) -> str | None:
        """A one-line explanation when the run will not train exactly ``requested`` steps; None when it will."""
        per = self.decisions_per_iteration
        if self.done >= self.requested:
            return (f"the run already has {self.done:,} of the {self.requested:,} steps asked for: nothing to train "
                    "(raise --steps to continue it)")  # fmt: skip
        if self.manager:  # its decisions last tau >= 1 low-level steps each: the total is known only at the end
            return (f"--steps {self.requested:,}: a Manager iteration is {per:,} decisions of one or more low-level steps "
                    f"each, so the run stops after the first iteration that reaches {self.requested:,} steps (up to one "
                    "iteration more)")  # fmt: skip
        total = self.total
        assert total is not None
        if total == self.requested:
            return None
        its = self.iterations
        return (f"--steps {self.requested:,} runs {total - self.done:,} steps: {its} iteration{'s' if its != 1 else ''} "
                f"of {per:,} ({self.done + (its or 0) * per:,} in total); training runs whole iterations of "
                "--batch-steps rounded up to a multiple of --num-envs")  # fmt: skip


def budget_spent(cfg: TrainConfig, env_steps: int, episodes: int) -> bool:
    """Whether a run of ``cfg`` that has trained ``env_steps`` steps and finished ``episodes`` episodes is done."""
    return env_steps >= cfg.steps or (cfg.episodes is not None and episodes >= cfg.episodes)


def plan_steps(cfg: TrainConfig, done: int = 0) -> StepPlan:
    """The :class:`StepPlan` of ``cfg`` from ``done`` steps already trained."""
    return StepPlan(cfg.steps, done, cfg.steps_per_env * cfg.num_envs, cfg.macro is not None)


#: Consecutive rejected TRPO steps after which :func:`train` warns that the policy is not learning.
REJECTED_STEPS_WARNING = 5


class TrainingWarning(UserWarning):
    """Training runs but does not learn (e.g. every TRPO step rejected)."""


def rejected_steps_message(streak: int, cfg: TrainConfig, iteration: int) -> str:
    """The warning for ``streak`` consecutive rejected TRPO steps ending at ``iteration``."""
    return (f"{cfg.task}: the last {streak} TRPO steps (iterations {iteration - streak + 1}-{iteration}) were all rejected: "
            f"no step within max KL {cfg.trpo.max_kl:g} improved the surrogate, so the policy has not changed; check "
            "--init-log-std, --max-kl and the rewards")  # fmt: skip


def train(
    cfg: TrainConfig,
    run_dir: Path,
    resume: bool = False,
    *,
    on_start: Callable[[StepPlan], None] | None = None,
    on_warning: Callable[[str], None] | None = None,
    warn_after_rejected: int = REJECTED_STEPS_WARNING,
) -> Iterator[dict[str, float]]:
    """Train, yielding each iteration's statistics; writes logs, a checkpoint per iteration, and ``config.json``.

    With ``resume``, continue from ``run_dir/checkpoint`` (its config must equal ``cfg`` except the budgets ``steps``
    and ``episodes``, which may grow, ``workers`` 0 in ``cfg``, which takes the run's own count, and ``backend`` ``auto``,
    which takes the run's own backend; a difference raises
    ValueError naming every differing setting); log rows written
    after that checkpoint are dropped so the log matches the restored state. Without it, a directory that holds a
    checkpoint -- or only the ``.old`` copy a kill between a save's renames leaves
    (:func:`hrlp.checkpoint.checkpoint_exists`) -- is refused.

    The run holds an OS lock on ``run_dir`` (:func:`hrlp.atomic.directory_lock`) from before it reads the checkpoint
    until it ends: a second trainer, or a ``--resume`` beside a running one, fails at once with a one-line error.
    Non-finite data stops the run with :class:`~hrlp.rollout.NonFiniteError` before anything of that iteration is
    saved; a full disk or read-only directory raises :class:`hrlp.atomic.StorageError` naming the path.

    ``on_start`` receives the :class:`StepPlan` (what will actually run) before the first iteration. After
    ``warn_after_rejected`` consecutive rejected TRPO steps ``on_warning`` gets a one-line warning (default:
    :func:`warnings.warn` with :class:`TrainingWarning`), once per run of rejections.
    """
    run_dir = Path(run_dir)
    warn = on_warning or (lambda message: warnings.warn(message, TrainingWarning, stacklevel=3))
    if resume and not checkpoint_exists(run_dir / "checkpoint"):  # before the lock, which would create run_dir
        raise ValueError(f"--resume: {run_dir} has no checkpoint to continue from")
    with directory_lock(run_dir):
        checkpoint = run_dir / "checkpoint"
        if resume:
            if not checkpoint_exists(checkpoint):
                raise ValueError(f"--resume: {run_dir} has no checkpoint to continue from")
            trainer = _reporting_env_faults(lambda: resume_trainer(checkpoint), resume)
        else:
            if checkpoint_exists(checkpoint):
                raise ValueError(f"{run_dir} already holds a run; pass --resume to continue it or choose another --run-dir")
            trainer = _reporting_env_faults(lambda: OffPolicyTrainer(cfg) if cfg.algo in OFF_POLICY else Trainer(cfg), resume)
            cfg = trainer.cfg  # with the number of workers it uses: config.json and the checkpoint record it
        logger: RunLogger | None = None
        try:  # from here on, whatever fails, the sampler (and its worker processes) is closed
            if resume:
                if cfg.workers == 0:  # left to the machine: the run continues with the count it was trained with
                    cfg = replace(cfg, workers=trainer.cfg.workers)
                if cfg.backend == "auto":  # likewise: the run continues with the backend it was trained with
                    cfg = replace(cfg, backend=trainer.cfg.backend)
                differences = config_differences(trainer.cfg, cfg, ignore=("steps", "episodes"))
                if differences:
                    raise ValueError(f"{run_dir}: --resume needs the run's own settings (only --steps and --episodes "
                                     f"may change); {'; '.join(differences)}")  # fmt: skip
                trainer.cfg = cfg
            # Rows past the checkpoint (all of them for a run killed before its first one) are written again.
            truncate_log(run_dir / "progress.csv", trainer.iteration)
            config_path = run_dir / "config.json"
            with shielded(), writing(config_path):  # a stop signal waits for the file to be whole
                config_path.write_text(json.dumps(cfg.to_json(), indent=2))
            if on_start is not None:
                on_start(plan_steps(cfg, trainer.env_steps))
            logger = RunLogger(run_dir)
            streak = 0
            while not budget_spent(cfg, trainer.env_steps, trainer.episodes_done):
                raise_if_stopping()  # a stop signal whose exception went astray (hrlp.stopping) is acted on here
                try:
                    stats = trainer.iterate()
                except EnvError as e:  # the user's environment failed: which iteration, and where the run stands
                    raise e.adding(iteration=trainer.iteration + 1, run_state=run_state(trainer)) from None
                # The log row first, then the checkpoint: a kill between the two leaves a row past the checkpoint,
                # which a resume drops and writes again; the other order would leave the iteration out of the log.
                # A stop signal (hrlp.stopping) waits for both: the iteration is kept whole, or dropped before this.
                with shielded():
                    logger.log(stats)
                    try:
                        trainer.save(checkpoint)
                    except BaseException:  # a refused or failed save: the log goes back to the checkpoint it matches
                        with contextlib.suppress(OSError):
                            truncate_log(run_dir / "progress.csv", trainer.iteration - 1)
                        raise
                streak = 0 if update_stat(stats, "accepted", 1.0) else streak + 1
                if warn_after_rejected > 0 and streak == warn_after_rejected:
                    warn(rejected_steps_message(streak, cfg, trainer.iteration))
                yield stats
        finally:
            if logger is not None:
                logger.close()
            trainer.close()


def run_state(trainer: Trainer | OffPolicyTrainer | None, resumed: bool = False) -> str:
    """Where a run that ends in an error stands on disk: its last checkpoint (every iteration is saved as it ends), or
    that nothing was saved."""
    if trainer is None:
        return "the run's checkpoint is as it was; --resume continues it" if resumed else "nothing was saved"
    if trainer.iteration == 0:
        return "nothing was saved (the first iteration had not ended)"
    return (f"the run's last checkpoint (iteration {trainer.iteration}, {trainer.env_steps:,} steps) is intact; --resume "
            "continues it")  # fmt: skip


def _reporting_env_faults(build: Callable[[], Trainer | OffPolicyTrainer], resumed: bool) -> Trainer | OffPolicyTrainer:
    """``build()``; a fault of the user's environment while it starts (its first reset) says where the run stands."""
    try:
        return build()
    except EnvError as e:
        raise e.adding(run_state=run_state(None, resumed)) from None


@dataclass
class RunSummary:
    """What a session of :func:`train_with_progress` did."""

    iterations: int = 0
    """Iterations trained in this session."""
    env_steps: int = 0
    """The run's low-level environment steps at the end (a resumed run's earlier ones included)."""
    env_steps_this_session: int = 0
    """Low-level steps trained in this session."""
    episodes: int | None = None
    """With an episode budget, the training episodes the run has finished at the end (None: no budget, or no iteration
    ran in this session)."""
    rejected: int = 0
    """TRPO steps of this session that were rejected (the policy unchanged)."""
    longest_rejected_streak: int = 0
    """The longest run of consecutive rejected TRPO steps."""
    warnings: list[str] = field(default_factory=list)
    """Warnings raised while training (e.g. :func:`rejected_steps_message`)."""

    def line(self) -> str:
        """One line: iterations, steps, and the rejected TRPO steps if any."""
        out = (
            f"trained {self.iterations} iteration{'s' if self.iterations != 1 else ''}, {self.env_steps_this_session:,} "
            f"environment steps ({self.env_steps:,} in the run)"
        )
        if self.episodes is not None:
            out += f", {self.episodes:,} training episodes in the run"
        if self.iterations and self.rejected == self.iterations:
            out += f"; warning: all {self.rejected} TRPO steps were rejected, the policy did not change"
        elif self.rejected:
            out += f"; {self.rejected} of {self.iterations} TRPO steps rejected (longest run {self.longest_rejected_streak})"
        return out


def train_with_progress(cfg: TrainConfig, run_dir: Path, resume: bool = False, console: Any = None,
                        description: str | None = None, notes: Sequence[str] = ()) -> RunSummary:  # fmt: skip
    """:func:`train` behind a rich progress bar on ``console`` (return, success, KL and steps/s so far); when
    ``console`` is not a terminal (output written to a file or a pipe), a :func:`progress_line` per iteration instead.

    Before the first iteration it prints what will actually run when that differs from ``cfg.steps``
    (:meth:`StepPlan.note`); the bar counts the run's real steps against the real total (a Manager's total, unknown
    until it ends, is ``cfg.steps`` until passed). Warnings (:data:`REJECTED_STEPS_WARNING` rejected TRPO steps in a
    row) are printed above the bar, and ``notes`` once the run is set up. Returns the :class:`RunSummary`."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    console = console or Console(stderr=True)
    columns = [TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
               TextColumn("{task.fields[status]}")]  # fmt: skip
    summary = RunSummary()
    streak = 0
    lines = not console.is_terminal
    label = description or f"train {cfg.task}"
    t0 = time.perf_counter()
    with Progress(*columns, console=console, disable=lines) as progress:
        start, bar_total, bar = 0, cfg.steps, None

        def started(plan: StepPlan) -> None:  # the bar appears once the run is set up (an error before: one line only)
            nonlocal start, bar_total, bar
            start, bar_total = plan.done, plan.total or max(plan.requested, plan.done)
            for line in notes:
                progress.console.print(line, soft_wrap=True, highlight=False)
            if cfg.episodes is None and (note := plan.note()) is not None:
                progress.console.print(f"[bold]note:[/] {note}", soft_wrap=True)
            if cfg.episodes is not None:
                progress.console.print(
                    f"[bold]note:[/] the run stops after the iteration that reaches {cfg.episodes:,} "
                    f"training episodes or {cfg.steps:,} steps, whichever comes first",
                    soft_wrap=True,
                )
            bar = progress.add_task(label, total=bar_total, completed=plan.done, status="")

        def warned(message: str) -> None:
            summary.warnings.append(message)
            progress.console.print(f"[bold yellow]warning:[/] {message}", soft_wrap=True)

        for st in train(cfg, run_dir, resume=resume, on_start=started, on_warning=warned):
            status = f"return {shown(st['return_mean'], '.1f')}"  # '-': no episode ended in the iteration
            if not math.isnan(st["success_rate"]):
                status += f"  success {st['success_rate']:.2f}"
            if cfg.episodes is not None:
                status += f"  episodes {int(st['episodes_total']):,}/{cfg.episodes:,}"
            if not math.isnan(kl := update_stat(st, "kl")):
                status += f"  kl {kl:.4f}"
            status += f"  {st['time/steps_per_s']:.0f} steps/s"
            done = int(st["env_steps"])
            bar_total = max(bar_total, done)  # a Manager's last iteration passes cfg.steps: the bar says by how much
            assert bar is not None
            progress.update(bar, completed=done, total=bar_total, status=status)
            if lines:
                line = progress_line(label, st, bar_total, time.perf_counter() - t0, cfg.episodes)
                console.print(line, soft_wrap=True, highlight=False)
            summary.iterations += 1
            summary.env_steps, summary.env_steps_this_session = done, done - start
            if cfg.episodes is not None:  # the summary names the episodes when they are a budget
                summary.episodes = int(st["episodes_total"])
            streak = 0 if update_stat(st, "accepted", 1.0) else streak + 1
            summary.rejected += streak > 0
            summary.longest_rejected_streak = max(summary.longest_rejected_streak, streak)
        if summary.iterations == 0:
            summary.env_steps = start
    return summary
