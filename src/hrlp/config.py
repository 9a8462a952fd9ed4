"""The settings of a training run: :class:`TrainConfig`, with the advantage estimate's (:class:`AdvantageConfig`), the
policy optimiser's (:class:`TRPOConfig`, :class:`PPOConfig`) and the value fit's (:class:`ValueFitConfig`), and their
checks.

This module imports neither torch nor gymnasium, so ``hrlp --help`` can build the options of ``hrlp train`` and
``hrlp train-manager`` from these dataclasses (:func:`field_docs` reads each field's docstring, the string literal
right after it, which is also the option's help). The classes are also importable from their old places:
``hrlp.train.TrainConfig``, ``hrlp.algos.trpo.TRPOConfig``, ``hrlp.algos.value.ValueFitConfig``.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import inspect
import itertools
import math
import os
import sys
from dataclasses import dataclass, field
from typing import Any

from hrlp import bounds

__all__ = [
    "ALGOS",
    "PAPER_SETTINGS",
    "WORKERS_VARIABLE",
    "AdvantageConfig",
    "PPOConfig",
    "SACConfig",
    "TRPOConfig",
    "TrainConfig",
    "ValueFitConfig",
    "auto_workers",
    "field_docs",
    "with_settings",
]


@dataclass(frozen=True)
class TRPOConfig:
    """TRPO settings. Defaults: the paper's Appendix D where it states a value, modular_rl's TRPO runs otherwise, but
    Fisher-vector products on 10% of the batch (Schulman et al. 2015; the paper's settings: every state)."""

    max_kl: float = 0.01
    """Trust-region radius delta: bound on the mean KL(old || new) over the batch's states (Appendix D: 0.01)."""
    cg_iters: int = 10
    """Conjugate-gradient iterations for the natural-gradient direction F^-1 g (modular_rl: 10)."""
    cg_damping: float = 0.1
    """Multiple of the identity added to the Fisher matrix in CG; keeps F + lambda I well conditioned for small
    batches. modular_rl's code default is 1e-3, its published TRPO runs (experiments/2-trpo-scripts.txt) use 0.1."""
    cg_residual_tol: float = 1e-10
    """CG stops early once the squared residual norm falls below this."""
    line_search_backtracks: int = 10
    """Number of step sizes tried by the backtracking line search (modular_rl: 10)."""
    line_search_shrink: float = 0.5
    """Factor by which the step shrinks after each rejected candidate (modular_rl: 0.5)."""
    entropy_coef: float = 0.0
    """Weight of the mean-entropy bonus added to the surrogate (TRPO as published: 0)."""
    normalize_advantages: bool = True
    """Standardise advantages to zero mean and unit variance over the batch before the update (modular_rl does)."""
    fisher_fraction: float = 0.1
    """Share of the batch's states on which the Fisher-vector products of conjugate gradient are estimated
    (every ``round(1 / fraction)``-th state). Default 0.1, as Schulman et al. (2015, Section 6): the products
    dominate the update's cost while the gradient, the step length's KL and the line search still use the whole
    batch. 1.0: every state (exact, modular_rl's and the presets': ``--paper-settings``)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.max_kl) and self.max_kl > 0):
            raise ValueError(f"max_kl must be a positive finite number, got {self.max_kl}")
        if self.cg_iters < 1:
            raise ValueError(f"cg_iters must be >= 1, got {self.cg_iters}")
        if not self.cg_damping >= 0:
            raise ValueError(f"cg_damping must be >= 0, got {self.cg_damping}")
        if not self.cg_residual_tol >= 0:
            raise ValueError(f"cg_residual_tol must be >= 0, got {self.cg_residual_tol}")
        if self.line_search_backtracks < 1:
            raise ValueError(f"line_search_backtracks must be >= 1, got {self.line_search_backtracks}")
        if not 0 < self.line_search_shrink < 1:
            raise ValueError(f"line_search_shrink must be in (0, 1), got {self.line_search_shrink}")
        if not self.entropy_coef >= 0:
            raise ValueError(f"entropy_coef must be >= 0, got {self.entropy_coef}")
        if not 0 < self.fisher_fraction <= 1:
            raise ValueError(f"fisher_fraction must be in (0, 1], got {self.fisher_fraction}")


@dataclass(frozen=True)
class AdvantageConfig:
    """How returns and advantages are estimated, whatever the optimiser (TRPO or PPO)."""

    gamma: float = 0.99
    """Discount per (decision) step for returns and GAE (Appendix D: 0.99). For the Manager the effective per-step
    discount is gamma ** tau for a macro-action of tau low-level steps, passed to GAE as ``discount``."""
    gae_lambda: float = 0.97
    """GAE lambda (1: plain Monte-Carlo advantages). The paper does not state one; 0.97 is what modular_rl's published
    TRPO runs use (its ``--lam=0.97``; its code default is 1.0)."""

    def __post_init__(self) -> None:
        if not 0 <= self.gamma <= 1:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma}")
        if not 0 <= self.gae_lambda <= 1:
            raise ValueError(f"gae_lambda must be in [0, 1], got {self.gae_lambda}")


@dataclass(frozen=True)
class PPOConfig:
    """PPO's settings (``algo="ppo"``): CleanRL's and Stable-Baselines3's defaults for continuous control, with an early
    stop on the exact mean KL (Lemma 1's for a Manager)."""

    clip: float = 0.2
    """Clipping range epsilon of the probability ratio."""
    epochs: int = 10
    """Passes over the batch per update."""
    minibatches: int = 32
    """Minibatches per epoch (the batch is shuffled and split into this many)."""
    lr: float = 3e-4
    """Adam's learning rate."""
    max_grad_norm: float = 0.5
    """Gradients are clipped to this Euclidean norm (0: no clipping)."""
    target_kl: float = 0.02
    """Stop an update after the epoch whose exact mean KL(old || new) over the batch exceeds this (0: never stop)."""
    entropy_coef: float = 0.0
    """Weight of the mean entropy bonus in PPO's objective."""
    normalize_advantages: bool = True
    """Standardise the advantages over the whole batch before PPO's update."""

    def __post_init__(self) -> None:
        for name in ("clip", "lr"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        for name in ("max_grad_norm", "target_kl", "entropy_coef"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")
        for name in ("epochs", "minibatches"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")


@dataclass(frozen=True)
class SACConfig:
    """Soft actor-critic's settings (``algo="sac"``): off-policy, from a replay buffer. Stable-Baselines3's defaults where
    SAC has them; for parameterised actions and Managers, hybrid SAC (a categorical choice with squashed Gaussian
    parameters, a temperature for each; Delalleau et al. 2019, MAPLE 2022); goals relabelled (HER, Andrychowicz et al.
    2017, its ``future`` strategy) on goal-conditioned environments."""

    lr: float = 3e-4
    """Adam's learning rate for the actor, the critics and the temperatures."""
    batch_size: int = 256
    """Transitions per gradient step, drawn uniformly from the replay buffer."""
    buffer_size: int = 1_000_000
    """Transitions the replay buffer holds (the oldest are overwritten); a Manager's transition is one decision."""
    learning_starts: int = 1_000
    """Decisions collected before the first gradient step."""
    updates_per_step: float = 1.0
    """Gradient steps per decision collected (the update-to-data ratio)."""
    tau: float = 0.005
    """Polyak factor of the target critics: ``target <- (1 - tau) target + tau critic`` after each gradient step."""
    hidden: tuple[int, ...] = (256, 256)
    """Hidden layer widths of the actor and of each critic (ReLU)."""
    init_alpha: float = 0.1
    """Initial temperature of both entropy terms (both are then tuned to their targets; Stable-Baselines3 starts at 1,
    which holds a choice near uniform for thousands of steps on rewards of order 1)."""
    choice_entropy: float = 0.5
    """Target entropy of the discrete choice, as a fraction of its maximum log(n); the parameters' target is -d per
    block of d parameters (SAC's -dim(A))."""
    her_future: int = 4
    """Goals relabelled per real one on a goal-conditioned environment (a Dict observation with ``observation``,
    ``achieved_goal`` and ``desired_goal``, and ``compute_reward``): a share her_future / (her_future + 1) of each
    minibatch gets a goal achieved later in its episode (HER's ``future``, k = 4). 0: no relabelling."""

    def __post_init__(self) -> None:
        for name in ("lr", "tau", "init_alpha"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        if not self.tau <= 1:
            raise ValueError(f"tau must be in (0, 1], got {self.tau!r}")
        for name in ("updates_per_step", "choice_entropy"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")
        if not self.choice_entropy <= 1:
            raise ValueError(f"choice_entropy must be in [0, 1] (a fraction of log n), got {self.choice_entropy!r}")
        for name, low in (("batch_size", 1), ("buffer_size", 1), ("learning_starts", 0), ("her_future", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {v!r}")
        if not self.hidden or any(isinstance(h, bool) or not isinstance(h, int) or h <= 0 for h in self.hidden):
            raise ValueError(f"hidden must be positive layer widths, got {self.hidden!r}")


#: The policy optimisers a run may use (``TrainConfig.algo``).
ALGOS = ("trpo", "ppo", "sac")

#: The off-policy ones among :data:`ALGOS`: they learn from a replay buffer, not from each batch alone.
OFF_POLICY = ("sac",)


@dataclass(frozen=True)
class ValueFitConfig:
    """Settings of the L-BFGS value fit."""

    max_iter: int = 10
    """L-BFGS iterations per fit (default 10; modular_rl and the presets: 25, ``--paper-settings``)."""
    l2_coef: float = 1e-3
    """Weight of the L2 penalty ``sum_w ||w||^2`` over all value-net parameters (modular_rl: 1e-3)."""
    history_size: int = 10
    """Number of curvature pairs L-BFGS keeps (scipy's L-BFGS-B default, as in modular_rl)."""
    fraction: float = 0.25
    """Share of the batch's time steps the trainer fits on (every ``round(1 / fraction)``-th step of every
    environment; default 0.25). The fit is the costliest part of a flat iteration after sampling, and a baseline needs
    fewer samples than the policy step: consecutive states of one episode carry nearly the same targets. 1.0: every
    state (modular_rl and the presets, ``--paper-settings``)."""

    def __post_init__(self) -> None:
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")
        if not (math.isfinite(self.l2_coef) and self.l2_coef >= 0):
            raise ValueError(f"l2_coef must be a finite number >= 0, got {self.l2_coef}")
        if self.history_size < 1:
            raise ValueError(f"history_size must be >= 1, got {self.history_size}")
        if not 0 < self.fraction <= 1:
            raise ValueError(f"value fraction must be in (0, 1], got {self.fraction}")


@dataclass(frozen=True)
class MicroAction:
    """The micro-action: direct torques for ``duration`` steps, optionally penalised."""

    duration: int = 1
    """Low-level steps the torques are held for."""
    penalty: float = 0.0
    """Subtracted from the Manager's reward each time the micro-action is chosen (Appendix C)."""
    max_torque: float = 1.0
    """Bound on the micro-action's torques (Appendix C: bounds on micro-actions), in (0, 1]."""

    def __post_init__(self) -> None:
        if isinstance(self.duration, bool) or not isinstance(self.duration, int) or self.duration < 1:
            raise ValueError(f"MicroAction.duration must be a positive integer, got {self.duration!r}")
        if not (self.penalty >= 0):
            raise ValueError(f"MicroAction.penalty must be >= 0, got {self.penalty!r}")
        if not (0 < self.max_torque <= 1):
            raise ValueError(f"MicroAction.max_torque must be in (0, 1], got {self.max_torque!r}")


@dataclass(frozen=True)
class Handover:
    """How a point skill (a Reacher) is driven so that the next skill can take over from where it stops.

    The paper's interface (``MacroSpec.handover = None``) passes the Reacher an absolute point anywhere in the
    workspace and runs it as trained. A Reacher trained on -d(H, goal) alone leaves the claw closed or skewed and
    pushes through the capsule; these three changes make the state it leaves one the Gripper grips from
    (docs/skills.md, "Skills that hand over").
    """

    relative: bool = True
    """The Manager's goal is an offset from the capsule's centre in :data:`~hrlp.arm.skill.HANDOVER_POINT`'s box
    (5 cm aside, 0-20 cm above), taken at the macro-action's start, instead of a point of the whole workspace."""
    approach_height: float = 0.11
    """Metres the goal is raised until the hand is above it (within ``approach_radius`` horizontally), so the hand
    comes down onto the capsule from above instead of pushing through it from the side; 0 goes straight."""
    approach_radius: float = 0.02
    """Horizontal distance from the goal, metres, at which the hand counts as above it (then the goal drops)."""
    open_torque: float = 0.2
    """While a point skill runs, its two finger torques are replaced by this torque opening the claw (rc_close < 0,
    lc_close > 0; ARM_CLAW facts): a weak push that keeps the claw open without sweeping the capsule; 0 leaves the
    skill's own finger torques."""
    target_relative: bool = False
    """A moving skill's (a Mover's) target is an offset from the task's own target T in
    :data:`~hrlp.arm.skill.HANDOVER_TARGET`'s box (10 cm each way), instead of a point of the whole workspace: the
    Manager's first targets fall near T. Only on tasks that observe a target (reach-and-move)."""
    initiation: bool = False
    """Each skill starts only from its initiation set (:attr:`Skill.initiation`: the states like those it was trained
    from, e.g. a Mover trained from held starts while the capsule is lifted): a choice outside its skill's set runs the
    nearest skill before it in the Manager's order whose set holds (list skills in the order they chain: a Mover chosen
    before the capsule is held runs the Gripper, or the Reacher while the hand is far), else the first skill whose set
    holds, each with its own parameter block; the choice run is the one reported (``info['macro']``, the decision
    shares). The skill that ran last counts as available wherever it has taken the arm (a Gripper's swing may leave its
    starts' 9 cm), so a Mover chosen while the Gripper is still at work lets it go on; a choice runs as made where no
    skill is available, and the micro-action always does."""

    pregrasp: bool = False
    """A point skill's goal is an offset in :data:`~hrlp.arm.skill.HANDOVER_PREGRASP`'s box (3 cm aside, 0-8 cm above
    the capsule's centre) instead of HANDOVER_POINT's (5 cm, 0-20 cm): the Manager's first goals, the box's centre 4 cm
    above C, leave the palm where a Gripper starts. Only with ``relative``."""

    def __post_init__(self) -> None:
        if self.pregrasp is True and self.relative is False:
            raise ValueError("Handover.pregrasp is a box of capsule-relative goals: it needs relative=True")
        for name in ("relative", "target_relative", "initiation", "pregrasp"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"Handover.{name} must be true or false, got {getattr(self, name)!r}")
        for name in ("open_torque", "approach_height", "approach_radius"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (0 <= v <= 1):
                raise ValueError(f"Handover.{name} must be a number in [0, 1], got {v!r}")
        if self.approach_height > 0 and self.approach_radius <= 0:
            raise ValueError("Handover.approach_radius must be positive when approach_height is")


@dataclass(frozen=True)
class MacroSpec:
    """Which skills a Manager commands, for how long, and its micro-action (a field of the training config)."""

    skills: tuple[str, ...] = ()
    """Skill references (:mod:`hrlp.training.sources`): library names, looked up in ``library``, then in
    ``$HRLP_SKILLS`` / ``~/.hrlp/skills``, then among the skills shipped with hrlp (``hrlp skills list``); or
    ``MODULE:NAME`` Python references."""
    k: int | None = None
    """Low-level steps per skill call (None: each skill's default)."""
    micro: MicroAction | None = None
    """The micro-action, or None."""
    library: str | None = None
    """A skill library directory searched first."""
    handover: Handover | None = None
    """How point skills hand over (:class:`Handover`); None runs them as the paper does (absolute goals, as trained)."""
    chain: bool = False
    """Enforce the skills' initiation tests: a choice outside its skill's set runs the nearest skill before it whose set
    holds (:func:`hrlp.skills.core.initiated`; the arm's ``Handover.initiation`` does the same)."""

    def __post_init__(self) -> None:
        if not self.skills and self.micro is None:
            raise ValueError("a Manager needs at least one skill or the micro-action (--micro)")
        if len(set(self.skills)) != len(self.skills):
            raise ValueError(f"skills are listed twice: {', '.join(self.skills)}")
        if self.k is not None and (isinstance(self.k, bool) or not isinstance(self.k, int) or self.k < 1):
            raise ValueError(f"k must be a positive integer, got {self.k!r}")

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable form (``chain`` only when set, so configs written before it read back unchanged)."""
        d = dataclasses.asdict(self)
        if not self.chain:
            del d["chain"]
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> MacroSpec:
        """Inverse of :meth:`to_json`."""
        micro, handover = d.get("micro"), d.get("handover")
        return cls(tuple(d["skills"]), d.get("k"), MicroAction(**micro) if micro else None, d.get("library"),
                   Handover(**handover) if handover else None, bool(d.get("chain", False)))  # fmt: skip


@dataclass(frozen=True)
class TrainConfig:
    """Settings of a training run, flat or Manager: the paper's (Appendix D: TRPO) where they decide what is learned,
    faster ones where docs/benchmarks.md shows that they learn as well (sampling workers, 64 environments, Fisher-vector
    products on 10% of the batch, a shorter baseline fit on a quarter of it); :data:`PAPER_SETTINGS` gives back the
    paper's, as every preset runs them."""

    task: str
    """An hrlp task name (``hrlp tasks``) or a Gymnasium id, e.g. Pusher-v5."""
    steps: int = 1_000_000
    """Low-level environment steps in total (a Manager's macro-action of tau steps counts tau)."""
    batch_steps: int = 50_000
    """Decisions per TRPO iteration (the paper: 50,000 for flat runs, 5,000 for Managers)."""
    num_envs: int = 64
    """Environments stepped together with batched inference (default 64; the paper's settings, 16)."""
    workers: int = 0
    """Processes that sample at the same time, each stepping its share of the environments. Default 0: one per CPU core
    this process may use (or $HRLP_WORKERS), at most num_envs; 1: in this process (the paper's settings). A run records
    the number it used, and a resume keeps it."""
    backend: str = "auto"
    """How each process steps its environments: ``batched`` (the worlds of an hrlp arm task in one
    :class:`~hrlp.arm.batched.BatchedArmEnv`, MuJoCo's rollout module, task arithmetic as arrays; a Manager's skills
    act on every world at once), ``serial`` (one environment object each, the paper's settings: bit for bit the runs
    made before the batched backend) or ``auto`` (the default: batched for an hrlp task, serial for a Gymnasium id).
    A run records the one it used."""
    seed: int = 0
    """Seed of the environments, the network initialisation and the action noise."""
    episode_steps: int | None = None
    """Episode length: an hrlp task's (None: its default, 300) or a Gymnasium id's time limit (None: its own)."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layer widths of the policy and value networks."""
    init_log_std: float = 0.0
    """Initial log standard deviation of the policy's Gaussian action noise (0: std 1 on [-1, 1] torques)."""
    algo: str = "trpo"
    """The policy optimiser: ``trpo`` (the paper's, settings in ``trpo``), ``ppo`` (clipped surrogate, ``ppo``) or
    ``sac`` (off-policy soft actor-critic from a replay buffer, hybrid for parameterised actions and Managers, with goal
    relabelling; settings in ``sac``; it samples in the training process, and a batch is then the decisions between two
    log rows and checkpoints)."""
    advantage: AdvantageConfig = field(default_factory=AdvantageConfig)
    """Return and advantage settings (gamma 0.99, GAE lambda 0.97)."""
    trpo: TRPOConfig = field(default_factory=TRPOConfig)
    """TRPO settings (max KL 0.01, ...)."""
    ppo: PPOConfig = field(default_factory=PPOConfig)
    """PPO settings, used with ``algo="ppo"``."""
    sac: SACConfig = field(default_factory=SACConfig)
    """SAC settings, used with ``algo="sac"``."""
    value: ValueFitConfig = field(default_factory=ValueFitConfig)
    """Value-baseline fit settings."""
    macro: MacroSpec | None = None
    """For a Manager: its skills, their duration k and the micro-action; None for a flat policy."""
    task_kwargs: dict[str, Any] = field(default_factory=dict)
    """Arguments of the task, e.g. ``{"c1": -10.0}`` (Gripper reward constants) or ``{"curriculum_alpha": 1e-4}``."""
    init_from: str | None = None
    """For a flat run: a skill (a name in the libraries a Manager searches, or a skill directory) whose policy and
    observation statistics the run starts from instead of a fresh network: fine-tuning a skill, and DAgger retraining
    (``hrlp dagger``). The run must have the skill's task, observations and hidden layers."""
    episodes: int | None = None
    """Training episodes in total (None: no episode budget). The run stops after the iteration in which the step budget
    or this one is reached, whichever comes first; an episode counts when it ends (terminated or truncated)."""
    reward_scale: float = 1.0
    """Factor on every reward before advantages and value targets are computed: training only. Logged returns,
    success and evaluation (``hrlp eval``) stay in the task's own units."""

    def __post_init__(self) -> None:
        for name in ("steps", "batch_steps", "num_envs"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 0:
            raise ValueError(f"workers must be a positive integer (or 0: one per core), got {self.workers!r}")
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {self.backend!r}")
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
        if self.episodes is not None and (isinstance(self.episodes, bool) or not isinstance(self.episodes, int)
                                          or self.episodes <= 0):  # fmt: skip
            raise ValueError(f"episodes must be a positive integer (or None: no episode budget), got {self.episodes!r}")
        if not (isinstance(self.reward_scale, int | float) and math.isfinite(self.reward_scale) and self.reward_scale > 0):
            raise ValueError(f"reward_scale must be a positive finite number, got {self.reward_scale!r}")
        if self.algo not in ALGOS:
            raise ValueError(f"algo must be one of {', '.join(ALGOS)}, got {self.algo!r}")
        if self.algo in OFF_POLICY and self.workers > 1:
            raise ValueError(f"algo {self.algo} samples in the training process: workers must be 1 (or 0), got {self.workers}")
        if self.algo in OFF_POLICY and self.init_from is not None:
            raise ValueError(f"init_from starts a Gaussian policy trained on-policy; algo {self.algo} cannot start from it")
        if self.algo == "ppo" and self.steps_per_env * self.num_envs < self.ppo.minibatches:
            raise ValueError(f"PPO's {self.ppo.minibatches} minibatches need a batch of at least as many decisions, "
                             f"got {self.steps_per_env * self.num_envs}")  # fmt: skip
        if not isinstance(self.task_kwargs, dict) or not all(isinstance(k, str) for k in self.task_kwargs):
            raise ValueError(f"task_kwargs must map argument names to values, got {self.task_kwargs!r}")
        self._check_bounds()

    def _check_bounds(self) -> None:
        """What a config may ask for (:mod:`hrlp.bounds`), and settings that would be silently meaningless."""
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed <= bounds.MAX_SEED:
            raise ValueError(f"seed must be an integer in [0, {bounds.MAX_SEED}] (seeds are 32-bit), got {self.seed!r}")
        for name, high, why in (("steps", bounds.MAX_STEPS, bounds.WHY_STEPS),
                                ("batch_steps", bounds.MAX_BATCH_STEPS, bounds.WHY_BATCH_STEPS),
                                ("num_envs", bounds.MAX_NUM_ENVS, bounds.WHY_NUM_ENVS)):  # fmt: skip
            if (problem := bounds.count_problem(getattr(self, name), 1, high, why)) is not None:
                raise ValueError(f"{name} {problem}")
        if "episode_steps" in self.task_kwargs:
            raise ValueError("give the episode length as episode_steps (--episode-steps), not as a task argument")
        batch = self.steps_per_env * self.num_envs
        problems = []
        if self.algo not in OFF_POLICY:  # the Fisher matrix and the baseline fit are on-policy
            problems += [
                bounds.fraction_problem("fisher_fraction", self.trpo.fisher_fraction, batch, "decisions"),
                bounds.fraction_problem("value fraction", self.value.fraction, self.steps_per_env, "time steps"),
            ]
        if self.macro is not None:
            episode = self.episode_steps or bounds.DEFAULT_EPISODE_STEPS
            micro = None if self.macro.micro is None else self.macro.micro.duration
            problems += [
                bounds.duration_problem("k", self.macro.k, episode),
                bounds.duration_problem("the micro-action's duration", micro, episode),
            ]
        if problem := next((p for p in problems if p is not None), None):
            raise ValueError(problem)

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
        for name in ("trpo", "value", "advantage", "ppo", "sac"):
            if name in d and not isinstance(d[name], dict):
                raise TypeError(f"{name} must be a mapping of settings, got {type(d[name]).__name__}")
        trpo, value = dict(d["trpo"]), dict(d["value"])
        # Configs saved before the advantage settings had their own record kept them in TRPO's.
        moved = {k: trpo.pop(k) for k in ("gamma", "gae_lambda") if k in trpo}
        # A setting of PAPER_SETTINGS that a config lacks was saved before the setting existed, and ran with the paper's
        # value, the default until then (the shipped skills' configs have no fisher_fraction nor value fraction).
        for name, v in PAPER_SETTINGS.items():
            record, _, key = name.rpartition(".")
            {"": d, "trpo": trpo, "value": value}[record].setdefault(key, v)
        d["advantage"] = AdvantageConfig(**{**moved, **d.get("advantage", {})})
        d["trpo"] = TRPOConfig(**trpo)
        d["ppo"] = PPOConfig(**d.get("ppo", {}))
        sac = dict(d.get("sac", {}))
        if "hidden" in sac:
            sac["hidden"] = tuple(sac["hidden"])
        d["sac"] = SACConfig(**sac)
        d["value"] = ValueFitConfig(**value)
        if d.get("macro"):
            d["macro"] = MacroSpec.from_json(d["macro"])
        else:
            d["macro"] = None
        return cls(**d)


BACKENDS = ("auto", "batched", "serial")
"""The values of :attr:`TrainConfig.backend`."""


WORKERS_VARIABLE = "HRLP_WORKERS"
"""The environment variable that sets the number of sampling workers a run with ``workers`` 0 (the default) uses."""


def auto_workers(num_envs: int) -> int:
    """The sampling workers of a run with ``workers`` 0 and ``num_envs`` environments: ``$HRLP_WORKERS`` if set, else
    one per CPU core this process may use (:func:`hrlp.bounds.cores`), at most ``num_envs``. Raises ValueError, naming
    the variable, for a value that is not a positive integer within :func:`hrlp.bounds.max_processes`."""
    raw = os.environ.get(WORKERS_VARIABLE, "").strip()
    if not raw:
        return max(1, min(bounds.cores(), num_envs))
    what = f"{WORKERS_VARIABLE} (the sampling workers of a run whose workers are left out)"
    try:
        count = int(raw)
    except ValueError:
        raise ValueError(f"{what} must be a positive integer, got {raw!r}") from None
    if (problem := bounds.count_problem(count, 1, bounds.max_processes(), bounds.why_processes())) is not None:
        raise ValueError(f"{what} {problem}")
    return min(count, num_envs)


PAPER_SETTINGS: dict[str, Any] = {
    "workers": 1,
    "backend": "serial",
    "num_envs": 16,
    "trpo.fisher_fraction": 1.0,
    "value.max_iter": 25,
    "value.fraction": 1.0,
}
"""The settings the paper's runs and every preset use where :class:`TrainConfig`'s defaults are faster: one process
and 16 environments, each its own environment object, exact Fisher-vector products, the baseline fitted by
modular_rl's 25 L-BFGS iterations on every state. Names are those of :meth:`TrainConfig.to_json`, nested ones
dotted (``trpo.fisher_fraction``); apply them with :func:`with_settings`. ``hrlp train --paper-settings`` sets the
options they name that are left out."""


def with_settings(config: TrainConfig, settings: dict[str, Any]) -> TrainConfig:
    """``config`` with each of ``settings`` replaced: a :class:`TrainConfig` field by its name, a field of a nested
    record (``trpo``, ``value``, ``advantage``, ``ppo``, ``sac``) as ``record.field``. Raises ValueError for an unknown
    name."""
    nested = {"advantage", "trpo", "ppo", "sac", "value"}
    top: dict[str, Any] = {}
    inner: dict[str, dict[str, Any]] = {}
    for name, value in settings.items():
        record, dot, field_name = name.partition(".")
        if dot and record in nested and field_name in {f.name for f in dataclasses.fields(getattr(config, record))}:
            inner.setdefault(record, {})[field_name] = value
        elif not dot and name in {f.name for f in dataclasses.fields(TrainConfig)} and name not in nested:
            top[name] = value
        else:
            raise ValueError(f"unknown setting {name!r}: use a TrainConfig field or {', '.join(sorted(nested))}.<field>")
    for record, values in inner.items():
        top[record] = dataclasses.replace(getattr(config, record), **values)
    return dataclasses.replace(config, **top)


@functools.cache
def field_docs(cls: type) -> dict[str, str]:
    """The docstring of each field of the dataclass ``cls`` that has one (the string literal written right after the
    field), by field name, with its whitespace collapsed to single spaces. Read from the source of ``cls``'s module
    (``ast``), so nothing is copied by hand; empty when the source is not available."""
    tree = _module_tree(cls.__module__)
    node = next((n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls.__name__), None)
    names = {f.name for f in dataclasses.fields(cls)}
    body = node.body if node is not None else []
    docs: dict[str, str] = {}
    for stmt, after in itertools.pairwise(body):
        if (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and stmt.target.id in names
                and isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)):  # fmt: skip
            docs[stmt.target.id] = " ".join(after.value.value.split())
    return docs


@functools.cache
def _module_tree(name: str) -> ast.Module:
    """The parsed source of module ``name`` (parsed once); an empty module when its source is not available."""
    try:
        return ast.parse(inspect.getsource(sys.modules[name]))
    except (OSError, TypeError):  # no source shipped (e.g. only bytecode)
        return ast.Module(body=[], type_ignores=[])
