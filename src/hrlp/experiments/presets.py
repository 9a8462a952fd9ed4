"""Every experiment of the paper as a named preset: a grid of training runs, each with its seeds.

A preset lists runs (a name and a :class:`~hrlp.train.TrainConfig` without its seed) and the
paper's number for each run where the paper gives one, so ``hrlp tables`` can print ours beside
it. ``budget`` is the default number of environment steps per run; the paper's own budgets
(50 million steps for a flat reach-and-grip run) are far beyond one machine, and
``hrlp reproduce --budget`` overrides it.

Every run is built with the paper's settings, :data:`~hrlp.config.PAPER_SETTINGS` (one process, 16 environments,
exact Fisher-vector products, the baseline by 25 L-BFGS iterations on every state), written into its config rather
than taken from :class:`~hrlp.train.TrainConfig`'s defaults, which are faster: a preset keeps the settings its runs
ran with (``tests/test_preset_configs.py`` compares every run's config with a snapshot).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from hrlp.arm.research.imitate import ImitationConfig
from hrlp.config import PAPER_SETTINGS, Handover, MacroSpec, MicroAction, with_settings
from hrlp.fetch import REACH_BIND
from hrlp.train import TrainConfig

#: The shipped Gripper skill's start set (its recipe: the ``shipped-skills`` preset).
GRIPPER_START = {"start_distance": [0.0, 0.09], "finger_opening": [0.0, 1.0]}


@dataclass(frozen=True)
class Run:
    """One cell of a preset: a name, its settings (the seed is set per seed), and the paper's figure for it."""

    name: str
    config: TrainConfig
    paper: float | None = None
    """The paper's value of the preset's metric for this run (None where the paper gives none)."""
    steps: int | None = None
    """This run's own budget, environment steps (None: the preset's ``budget``; ``--budget`` overrides both)."""
    skill: tuple[str, int] | None = None
    """For a run that trains a shipped skill: the skill's name and default duration k (``hrlp skills build``)."""
    imitation: ImitationConfig | None = None
    """For a run that starts from a student of the scripted grasp: the imitation (:func:`hrlp.arm.research.imitate.imitate`,
    behaviour cloning and DAgger) written as the run's iteration 0, which TRPO then continues to the budget (None: TRPO
    from a fresh network). Its expert and student episodes are not counted in the run's environment steps."""
    seed_offset: int = 0
    """Added to each of the preset's seeds for this run (its directory keeps the preset's seed): a recipe whose skill
    was trained with a seed other than the preset's, rebuilt with that seed."""
    skill_args: Mapping[str, Any] | None = None
    """For a skill trained on an environment outside the arm: the settings of ``hrlp skills add`` that make the run a
    library skill (``param``, ``low``, ``high``, ``done_part``, ``done_within``, ``bind``; ``hrlp skills build``)."""


@dataclass(frozen=True)
class Preset:
    """A named experiment: runs x seeds, the metric its table reports, and where it is in the paper."""

    name: str
    description: str
    source: str
    """Where in the paper (section, figure)."""
    runs: tuple[Run, ...]
    metric: str = "success"
    """'success' (Definition 1, evaluation episodes) or 'target_dist_sum'."""
    seeds: tuple[int, ...] = (0, 1, 2)
    budget: int = 1_000_000
    """Default environment steps per run."""
    eval_episodes: int = 100
    tags: tuple[str, ...] = field(default_factory=tuple)
    thresholds: tuple[float, ...] | None = None
    """Training success rates of its sample-efficiency table (``hrlp tables``; None: the tables' defaults)."""

    def with_budget(self, steps: int) -> Preset:
        """The preset with every run's step budget set to ``steps``."""
        return replace(self, budget=steps, runs=tuple(replace(r, steps=None) for r in self.runs))

    def config(self, run: Run, seed: int) -> TrainConfig:
        """The full config of ``run`` with ``seed`` (plus the run's ``seed_offset``) and its budget (its own, else the
        preset's)."""
        return replace(run.config, seed=seed + run.seed_offset, steps=run.steps or self.budget)


def _paper(task: str, batch: int, **kw: object) -> TrainConfig:
    """A run's config with the paper's settings (:data:`PAPER_SETTINGS`), then ``kw``."""
    return replace(with_settings(TrainConfig(task=task), PAPER_SETTINGS), batch_steps=batch, **kw)  # type: ignore[arg-type]


def _flat(task: str, batch: int = 50_000, **kw: object) -> TrainConfig:
    return _paper(task, batch, **kw)


def _manager(task: str, skills: tuple[str, ...], k: int, micro: bool = False, **kw: object) -> TrainConfig:
    spec = MacroSpec(skills, k=k, micro=MicroAction() if micro else None)
    return _paper(task, 5_000, macro=spec, **kw)


def _tuned(config: TrainConfig) -> TrainConfig:
    """A Manager's config with the demo's settings: 2,000 decisions per batch and max KL 0.02 (more, larger updates
    than the paper's 5,000 decisions and 0.01 at the budgets one machine affords)."""
    return _kl(replace(config, batch_steps=2_000), 0.02)


def _tuned_manager(skills: tuple[str, ...], micro: bool) -> TrainConfig:
    """A reach-and-grip-2 Manager (k = 15) with the demo's settings (:func:`_tuned`)."""
    return _tuned(_manager("ReachAndGrip2", skills, 15, micro))


def _experiment_1(c2: float, tr: float) -> TrainConfig:
    """reach-and-grip Experiment 1 at one cell of Figure 6: a Manager over gripper + reacher, k = 10."""
    return _manager("ReachAndGrip1", ("gripper", "reacher"), 10, task_kwargs={"c2": c2, "tr": tr})


def _handover(config: TrainConfig) -> TrainConfig:
    """A Manager's config with its point skills driven for hand-over (:class:`~hrlp.skills.macro_env.Handover`: goals
    relative to the capsule, approach from above, claw held open) and its parameters' initial std e^-1 of their box's
    half-width, so that its first goals fall near the capsule."""
    assert config.macro is not None
    return replace(config, macro=replace(config.macro, handover=Handover()), init_log_std=-1.0)


def _swap(config: TrainConfig, old: str, new: str) -> TrainConfig:
    """A Manager's config with the skill ``new`` in place of ``old`` (its other settings kept)."""
    assert config.macro is not None
    return replace(config, macro=replace(config.macro, skills=tuple(new if s == old else s for s in config.macro.skills)))


def _relative_only(config: TrainConfig, reacher: str) -> TrainConfig:
    """:func:`_handover`'s config with the skill ``reacher`` in place of the paper's Reacher and only the goals made
    capsule-relative: a Reacher trained to hand over needs neither the approach drive nor the claw held open."""
    config = _swap(_handover(config), "reacher", reacher)
    assert config.macro is not None
    return replace(config, macro=replace(config.macro, handover=Handover(approach_height=0.0, open_torque=0.0)))


def _figure_6_with(gripper: str) -> tuple[Run, ...]:
    """Figure 6's grid (Experiment 1, k = 10) over ``gripper`` + reacher-handover, capsule-relative goals, both skills
    run as trained, the headline's Manager settings."""
    return tuple(
        Run(
            f"{gripper}+reacher-handover,c2={c2},tr={tr}",
            _swap(_relative_only(_tuned(_experiment_1(c2, tr)), "reacher-handover"), "gripper", gripper),
            _FIG6[(c2, tr)],
        )
        for c2, tr in _GRID
    )


def _figure_7_with(gripper: str, s_reacher: bool = False) -> tuple[Run, ...]:
    """Figure 7's grid (Experiment 2, k = 15) with ``gripper`` in place of the paper's Gripper and reacher-handover (goals
    capsule-relative, run as trained) in place of its Reacher, the headline's Manager settings; with ``s_reacher``, also
    gripper + s-reacher, the paper's Stabilised Reacher driven for hand-over (:func:`_handover`)."""
    labels = ("gripper+reacher", "gripper+reacher+micro", "gripper+micro") + (("gripper+s-reacher",) if s_reacher else ())

    def config(label: str) -> TrainConfig:
        manager = _tuned_manager(*_FIG7_SKILLS[label])
        if label == "gripper+s-reacher":
            return _handover(manager)
        return manager if label == "gripper+micro" else _relative_only(manager, "reacher-handover")

    return tuple(
        Run(
            f"{label.replace('gripper', gripper).replace('+reacher', '+reacher-handover')},c2={c2},tr={tr}",
            _swap(replace(config(label), task_kwargs={"c2": c2, "tr": tr}), "gripper", gripper),
            paper,
        )
        for label, cells in _FIG7.items()
        if label in labels
        for (c2, tr), paper in cells.items()
    )


def _figure_7_chained(gripper: str) -> tuple[Run, ...]:
    """Figure 7's gripper + reacher cells with ``gripper`` and reacher-handover (run as trained) chained: initiation sets
    and pre-grasp goals (:class:`~hrlp.skills.macro_env.Handover`), so that the Gripper runs only from the states it was
    trained from (or goes on where it has taken the arm), the headline's Manager settings."""
    base = _swap(_relative_only(_tuned_manager(("gripper", "reacher"), False), "reacher-handover"), "gripper", gripper)
    assert base.macro is not None
    handover = Handover(approach_height=0.0, open_torque=0.0, initiation=True, pregrasp=True)
    return tuple(
        Run(
            f"{gripper}+reacher-handover,c2={c2},tr={tr},chained",
            replace(base, task_kwargs={"c2": c2, "tr": tr}, macro=replace(base.macro, handover=handover)),
            paper,
        )
        for (c2, tr), paper in _FIG7["gripper+reacher"].items()
    )


def _target_relative(config: TrainConfig) -> TrainConfig:
    """A hand-over Manager's config whose Mover targets are offsets from the task's target T (``Handover.target_relative``)."""
    assert config.macro is not None and config.macro.handover is not None
    return replace(config, macro=replace(config.macro, handover=replace(config.macro.handover, target_relative=True)))


def _chained(coeff: float) -> TrainConfig:
    """A reach-and-move Manager over the chain reacher-handover -> gripper-imitated -> mover-held (docs/skills.md,
    "Initiation sets and skill chains"): initiation sets, capsule-relative pre-grasp goals for a Reacher run as trained,
    Mover targets relative to the task's, k = 50, initial log std -2 (about 1.4 cm of a Mover's target), 600 decisions
    per batch at max KL 0.02, TrainConfig's fast defaults of 3 Dec 2026 in one process on the batched backend."""
    handover = Handover(approach_height=0.0, open_torque=0.0, target_relative=True, initiation=True, pregrasp=True)
    spec = MacroSpec(("reacher-handover", "gripper-imitated", "mover-held"), k=50, handover=handover)
    config = TrainConfig(task="ReachAndMove", workers=1, backend="batched", batch_steps=600, init_log_std=-2.0, macro=spec,
                         task_kwargs={"target_coeff": coeff})  # fmt: skip
    return _kl(config, 0.02)


def _kl(config: TrainConfig, max_kl: float) -> TrainConfig:
    """``config`` with the trust region's radius ``max_kl`` (its other TRPO settings kept)."""
    return replace(config, trpo=replace(config.trpo, max_kl=max_kl))


# Figure 6: reach-and-grip Experiment 1 (a Manager over gripper + reacher, k = 10; "Table 6 presents results of
# Experiment 1", Section 4.3.1) over the Gripper reward's c2 x tr (Section 4.1), success per cell.
_FIG6 = {(3, 0.03): 0.984, (3, 0.06): 0.955, (4, 0.03): 0.989, (4, 0.06): 0.902}
# Figure 7: reach-and-grip Experiment 2, Manager success per skill set and reward cell (c2, tr).
_FIG7 = {
    "gripper+micro": {(3, 0.03): 0.86, (3, 0.06): 0.74, (4, 0.03): 0.80, (4, 0.06): 0.65},
    "gripper+reacher": {(3, 0.03): 0.17, (3, 0.06): 0.08, (4, 0.03): 0.32, (4, 0.06): 0.15},
    "gripper+reacher+micro": {(3, 0.03): 0.92, (3, 0.06): 0.01, (4, 0.03): 0.75, (4, 0.06): 0.01},
    "gripper+s-reacher": {(3, 0.03): 0.88, (3, 0.06): 0.69, (4, 0.03): 0.87, (4, 0.06): 0.70},
}
_FIG7_SKILLS = {
    "gripper+micro": (("gripper",), True),
    "gripper+reacher": (("gripper", "reacher"), False),
    "gripper+reacher+micro": (("gripper", "reacher"), True),
    "gripper+s-reacher": (("gripper", "s-reacher"), False),
}
_GRID = list(itertools.product((3, 4), (0.03, 0.06)))
_FIG8_REWARD = {"tr": 0.08, "c2": 2.1}  # Figure 8's caption: tr 0.08, c1 -1, c2 2.1, c3 -4 (c1, c3: the defaults)
# Figure 5: reach-and-move TargetDistSum per Mover (rows) and Reacher (Normal, Stabilised, 3D).
_FIG5 = {"mover-plain": (-52.778, -43.552, -56.989), "mover-noised": (-42.239, -41.470, -55.369)}

#: The reward cell the tuned Appendix C sweeps run at: the environment's default (c2 3, tr 0.03), written out so
#: that their base cell has the same config as the matching cell of ``reach-and-grip-2-tuned`` (and is reused from it).
_BASE_CELL = {"c2": 3, "tr": 0.03}
_MICRO_VARIANTS = (
    ("free", MicroAction()),
    ("torque<=0.3", MicroAction(max_torque=0.3)),
    ("duration=5", MicroAction(duration=5)),
    ("penalty=0.5", MicroAction(penalty=0.5)),
)


def _appendix_c_tuned() -> tuple[Preset, ...]:
    """Appendix C's sweeps around the headline's Manager settings (2,000 decisions per batch, max KL 0.02, k = 15,
    64 x 64 units), 3M steps per run. The KL, k and size sweeps use gripper + s-reacher, whose seeds agree within
    0.12 in Figure 7's grid, so that a sweep can rank its settings; the micro-action sweep uses gripper + reacher +
    micro, the skill set whose Managers abandon the Reacher (Section 4.3.1)."""
    base = replace(_tuned_manager(("gripper", "s-reacher"), False), task_kwargs=_BASE_CELL)
    micro_base = replace(_tuned_manager(("gripper", "reacher"), True), task_kwargs=_BASE_CELL)
    what = "at the headline's Manager settings: gripper + s-reacher (Experiment 2, c2 3, tr 0.03)"
    return (
        Preset(
            "manager-kl-tuned",
            f"{what} over the maximal KL",
            "Appendix C",
            tuple(Run(f"max_kl={kl:g}", _kl(base, kl)) for kl in (0.005, 0.02, 0.08)),
            budget=3_000_000,
        ),
        Preset(
            "manager-k-tuned",
            f"{what} over the macro length k",
            "Appendix C",
            tuple(Run(f"k={k}", replace(base, macro=replace(base.macro, k=k))) for k in (5, 10, 15, 25)),  # type: ignore[type-var]
            budget=3_000_000,
        ),
        Preset(
            "manager-size-tuned",
            f"{what} over its hidden layer width",
            "Appendix C",
            tuple(Run(f"hidden={h}", replace(base, hidden=(h, h))) for h in (32, 64, 128)),
            budget=3_000_000,
        ),
        Preset(
            "micro-bounds-tuned",
            "at the headline's Manager settings: gripper + reacher + micro (Experiment 2, c2 3, tr 0.03) with "
            "bounded or penalised micro-actions",
            "Appendix C",
            tuple(
                Run(name, replace(micro_base, macro=replace(micro_base.macro, micro=micro)))  # type: ignore[type-var]
                for name, micro in _MICRO_VARIANTS
            ),
            budget=3_000_000,
        ),
    )


#: The imitated Gripper's imitation (docs/research/results-notes.md, "Imitation, then TRPO"): 150 expert episodes and 250 with
#: DART noise of std 0.3, two DAgger rounds of 200 episodes (the expert acting with probability 0.5, then 0.25), 30 epochs
#: per fit on minibatches of 512, the best round's student (100 episodes alone) kept; the expert's first version
#: (``expert_keep_clear=False``: the shipped ``gripper-imitated`` was imitated from it, before its moves kept clear).
IMITATED_GRIPPER = ImitationConfig(expert_episodes=150, dagger_rounds=2, dagger_episodes=200, epochs=30, minibatch=512,
                                   noisy_expert_episodes=250, expert_noise=0.3, beta=0.5, eval_episodes=100,
                                   expert_keep_clear=False)  # fmt: skip

#: The imitation of the Gripper that sees its claw relative to the capsule (``gripper-claw``,
#: docs/research/skills-lineage.md): 300 expert episodes and 300 with DART noise of std 0.3, four DAgger rounds of 200
#: episodes in which the student acts alone, 40 epochs per fit on minibatches of 512 with the learning rate annealed to
#: 0, the best round's student (100 episodes alone) kept; the expert whose moves keep clear.
CLAW_GRIPPER = ImitationConfig(expert_episodes=300, noisy_expert_episodes=300, expert_noise=0.3, dagger_rounds=4,
                               dagger_episodes=200, epochs=40, minibatch=512, lr_decay=True, eval_episodes=100)  # fmt: skip
#: gripper-clearance's imitation: the scripted grasp with its escape from tight starts, and five times the round-0 data of
#: CLAW_GRIPPER (1,000 expert and 1,000 noisy-expert episodes, 400 per DAgger round); docs/research/skills-lineage.md.
CLEARANCE_GRIPPER = replace(CLAW_GRIPPER, expert_episodes=1000, noisy_expert_episodes=1000, dagger_episodes=400,
                            expert_escape_clearance=0.01)  # fmt: skip


def _shipped_skills() -> Preset:
    """The recipes of the skills shipped in ``src/hrlp/arm/pretrained/`` (``hrlp skills build`` trains them and adds
    them to a library; a test checks that every shipped skill's manifest records exactly its run's config)."""
    gripper = _flat("Gripper", 25_000, episode_steps=100, init_log_std=-1.0, task_kwargs={**GRIPPER_START, "c3": -8, "c4": 10})
    claw = TrainConfig(task="Gripper", workers=1, backend="batched", batch_steps=25_000, episode_steps=100,
                       hidden=(256, 256), init_log_std=-2.0,
                       task_kwargs={**gripper.task_kwargs, "observe_capsule": True, "observe_claw": True})  # fmt: skip
    clearance = replace(claw, task_kwargs={**claw.task_kwargs, "observe_clearance": True})
    return Preset(
        "shipped-skills",
        "the shipped skills: Reacher; Gripper from many close, open-claw starts (c3 -8 and a bonus c4 10 while gripped: "
        "with the paper's three-term reward alone it hovers); Reacher3D; ReacherStabilised (level_coeff 0.1: with 0.5 no "
        "goal near the table is reached); the Movers from grip starts (hrlp skills build records them from "
        "the Gripper); a Reacher trained for hand-over (ReacherHandover: pre-grasp goals above the capsule, the capsule left "
        "in place, the claw open); a Gripper seeing the capsule's pose, imitated from the scripted grasp, then TRPO, and one "
        "also seeing the arm's distances to the capsule, imitated from the grasp that escapes tight starts, then trained on "
        "from the states just after it pushed the capsule away, in two rounds; a "
        "Mover from held starts (the capsule in that Gripper's claw); docs/skills.md",
        "Section 4.1",
        (
            Run("reacher", _flat("Reacher", 25_000), steps=3_000_000, skill=("reacher", 15)),
            Run("gripper", gripper, steps=8_000_000, skill=("gripper", 15)),
            Run("reacher3d", _flat("Reacher3D", 25_000), steps=2_000_000, skill=("reacher3d", 15)),
            Run("s-reacher", _flat("ReacherStabilised", 25_000, task_kwargs={"level_coeff": 0.1}), steps=2_000_000,
                skill=("s-reacher", 15)),
            Run("mover-noised", _flat("MoverNoised", 25_000, episode_steps=100, init_log_std=-1.0), steps=8_000_000,
                skill=("mover-noised", 8)),
            Run("mover-plain", _flat("MoverPlain", 25_000, episode_steps=100, init_log_std=-1.0), steps=8_000_000,
                skill=("mover-plain", 8)),
            # Trained with the fast defaults of 3 Dec 2026 (64 environments, 50,000-step batches, Fisher products on 10%,
            # the baseline by 10 L-BFGS iterations on every 4th step), in one process on the batched backend.
            Run("reacher-handover", TrainConfig(task="ReacherHandover", workers=1, backend="batched"), steps=10_000_000,
                skill=("reacher-handover", 15)),
            # The Gripper's recipe seeing the capsule's pose (a skill that reads the capsule_pose feature), 256 x 256, started
            # from the scripted grasp's student (IMITATED_GRIPPER), then TRPO with log-std -2 on the batched backend.
            Run("gripper-imitated", replace(gripper, hidden=(256, 256), init_log_std=-2.0, backend="batched",
                                            task_kwargs={**gripper.task_kwargs, "observe_capsule": True}),
                steps=8_000_000, skill=("gripper-imitated", 15), imitation=IMITATED_GRIPPER),
            # The same task seeing the claw's pose relative to the capsule too (claw_pose: H, FT1, FT2 less C, the palm's
            # axes), imitated with CLAW_GRIPPER, then TRPO with the fast defaults of 3 Dec 2026 in one process.
            Run("gripper-claw", claw, steps=8_000_000, skill=("gripper-claw", 15), imitation=CLAW_GRIPPER),
            # gripper-claw's run that also sees each arm body's distance to the capsule (observe_clearance), imitated
            # from the escaping expert with five times the data (CLEARANCE_GRIPPER), then the same TRPO.
            Run("gripper-clearance", clearance, steps=8_000_000, skill=("gripper-clearance", 15), imitation=CLEARANCE_GRIPPER),
            # gripper-clearance trained on (warm-started from its weights and statistics), 30% of its episodes from the
            # shipped recovery bank (states just after gripper-clearance pushed the capsule away), the same settings.
            Run("gripper-recovery", replace(clearance, init_from="gripper-clearance", task_kwargs={
                **clearance.task_kwargs, "starts": "recovery", "starts_fraction": 0.3}), steps=8_000_000,
                skill=("gripper-recovery", 15)),
            # The second round: gripper-recovery trained on the same way, 30% of its episodes from the states just after
            # gripper-recovery itself pushed the capsule away (the shipped bank "recovery-2"), with seed 200.
            Run("gripper-recovery-2", replace(clearance, init_from="gripper-recovery", task_kwargs={
                **clearance.task_kwargs, "starts": "recovery-2", "starts_fraction": 0.3}), steps=8_000_000,
                skill=("gripper-recovery-2", 15), seed_offset=200),
            # MoverNoised's recipe from the held starts (the capsule in gripper-imitated's claw): a Mover that carries what
            # the Gripper gripped, one process on the batched backend.
            Run("mover-held", replace(_flat("MoverNoised", 25_000, episode_steps=100, init_log_std=-1.0), workers=1,
                                      backend="batched", task_kwargs={"starts": "held"}),
                steps=6_000_000, skill=("mover-held", 15)),
        ),
        seeds=(0,),
        budget=8_000_000,
    )  # fmt: skip


#: Gymnasium-Robotics' Fetch tasks, as hrlp names them (``pip install "hrlp[fetch]"``).
FETCH = "gymnasium_robotics:Fetch{}-v4"
#: Where the Fetch skills' points lie (:data:`hrlp.fetch.skills.WORKSPACE_LOW` / ``_HIGH``).
_FETCH_WORKSPACE = ((1.05, 0.45, 0.40), (1.65, 1.05, 0.90))
#: The Fetch Managers' skills, per task (:mod:`hrlp.fetch.skills`).
FETCH_SKILLS = {
    "PickAndPlace": ("hrlp.fetch.skills:reach", "hrlp.fetch.skills:grasp", "hrlp.fetch.skills:carry"),
    "Push": ("hrlp.fetch.skills:push_near_goal",),
    "Slide": ("hrlp.fetch.skills:strike",),
}


#: Environment steps of each Fetch Manager's run: pick-and-place meets its 0.95 target at 150,000 (docs/fetch.md).
FETCH_BUDGETS = {"PickAndPlace": 150_000, "Push": 100_000, "Slide": 200_000}


def _fetch_sac(task: str, **kw: Any) -> TrainConfig:
    """SAC on a Fetch task: 4 environments, 500 decisions (a flat run: 2,000 steps) per iteration; ``kw`` on top."""
    return TrainConfig(**{"task": FETCH.format(task), "algo": "sac", "num_envs": 4, "batch_steps": 500, "workers": 1, **kw})


def _fetch_presets() -> tuple[Preset, ...]:
    """The Fetch skills' recipe and the Managers on FetchPickAndPlace, FetchPush and FetchSlide (docs/fetch.md)."""
    low, high = _FETCH_WORKSPACE
    reach = Run("fetch-reach", _fetch_sac("Reach", batch_steps=10_000), steps=10_000, skill=("fetch-reach", 10),
                skill_args={"param": "desired_goal", "low": low, "high": high, "done_part": "grip_pos", "done_within": 0.02,
                            "bind": REACH_BIND})  # fmt: skip
    managers = tuple(Run(f"manager-{task}", _fetch_sac(task, macro=MacroSpec(sk)), steps=FETCH_BUDGETS[task])
                     for task, sk in FETCH_SKILLS.items())  # fmt: skip
    return (
        Preset("fetch-skills", "the Fetch skill hrlp trains: reach (SAC + HER on FetchReach-v4; the goal is its parameter, "
               "read on the other Fetch tasks through the parts hrlp.fetch names)", "hrlp's own (docs/fetch.md)",
               (reach,), seeds=(0,), budget=10_000, eval_episodes=100),
        Preset("fetch", "Managers over the Fetch skills (hrlp.fetch.skills) on FetchPickAndPlace, FetchPush and FetchSlide, "
               "SAC + HER, the tasks' own sparse reward and success test", "hrlp's own (docs/fetch.md)",
               managers, budget=100_000, eval_episodes=100),
    )  # fmt: skip


#: The tag of a preset kept for the research record (``docs/research/``): an exploration, a rung of a recipe or a setting
#: a later preset superseded. It still runs; ``hrlp presets`` lists it only with ``--all``.
RESEARCH = "research"
#: The presets of the research record.
RESEARCH_PRESETS = frozenset({
    "reach-and-move-imitated", "reach-and-grip-1-tuned", "reach-and-grip-1-imitated", "reach-and-grip-2-handover",
    "reach-and-grip-2-reacher-handover", "reach-and-grip-2-imitated", "reach-and-grip-2-clearance", "reach-and-grip-2-chained",
    "reach-and-grip-2-tuned", "manager-kl-tuned", "manager-k-tuned", "manager-size-tuned", "micro-bounds-tuned",
})  # fmt: skip

PRESETS: dict[str, Preset] = {
    p.name: replace(p, tags=(*p.tags, RESEARCH)) if p.name in RESEARCH_PRESETS else p
    for p in (
        _shipped_skills(),
        *_fetch_presets(),
        Preset(
            "gripper-grid",
            "Gripper over the reward grid c2 x tr of Figure 6, the paper's start set widened to close, open-claw starts "
            "(the paper reports no success rates for the Gripper itself)",
            "Section 4.1, Experiment 1",
            tuple(
                Run(
                    f"c2={c2},tr={tr}",
                    _flat(
                        "Gripper",
                        25_000,
                        episode_steps=100,
                        init_log_std=-1.0,
                        task_kwargs={**GRIPPER_START, "c2": c2, "tr": tr},
                    ),
                )
                for c2, tr in _GRID
            ),
            budget=4_000_000,
        ),
        Preset(
            "reachers",
            "Reacher Normal, Stabilised and 3D",
            "Section 4.1, Experiment 3",
            tuple(Run(t, _flat(t, 25_000)) for t in ("Reacher", "ReacherStabilised", "Reacher3D")),
            budget=2_000_000,
        ),
        Preset(
            "movers",
            "Mover Plain (small start set) and Noised (large start set), from grip starts, with the shipped Movers' "
            "settings (100-step episodes, initial log std -1)",
            "Section 4.1, Experiment 2",
            tuple(Run(t, _flat(t, 25_000, episode_steps=100, init_log_std=-1.0)) for t in ("MoverPlain", "MoverNoised")),
            metric="target_dist_sum",
            budget=4_000_000,
        ),
        Preset(
            "reach-and-move-flat",
            "reach-and-move, flat, over TargetCoeff",
            "Section 4.2.1, Figure 4",
            tuple(Run(f"target_coeff={c}", _flat("ReachAndMove", task_kwargs={"target_coeff": c})) for c in (1, 2, 5, 10)),
            metric="target_dist_sum",
        ),
        Preset(
            "reach-and-move",
            "reach-and-move, Manager over every shipped Reacher x Mover pair, k = 8",
            "Section 4.2.2, Figure 5",
            tuple(
                Run(f"{reacher}+{mover}", _manager("ReachAndMove", (reacher, mover), 8), paper)
                for mover, row in _FIG5.items()
                for reacher, paper in zip(("reacher", "s-reacher", "reacher3d"), row, strict=True)
            ),
            metric="target_dist_sum",
        ),
        Preset(
            "reach-and-move-imitated",
            "reach-and-move, Manager over the hand-over Reacher, the imitated Gripper and the Mover from held starts "
            "(reacher-handover + gripper-imitated + mover-held: reach, grip, carry; the Mover's target relative to the "
            "task's), k = 15, the headline's Manager settings, TargetCoeff 1 and 10; paper: its best pair (s-reacher + "
            "mover-noised)",
            "Section 4.2.2, Figure 5",
            tuple(
                Run(
                    f"reacher-handover+gripper-imitated+mover-held,target_coeff={coeff}",
                    _target_relative(
                        _relative_only(
                            _tuned(
                                _manager(
                                    "ReachAndMove",
                                    ("reacher", "gripper-imitated", "mover-held"),
                                    15,
                                    task_kwargs={"target_coeff": coeff},
                                )
                            ),
                            "reacher-handover",
                        )
                    ),
                    _FIG5["mover-noised"][1],
                )
                # TargetCoeff 1 (the task's default) and 10 (the largest of Figure 4's): the weight of d(C, T) in the
                # reward, against d(H, C)'s 1; TargetDistSum, the metric, does not depend on it.
                for coeff in (1, 10)
            ),
            metric="target_dist_sum",
            budget=3_000_000,
        ),
        Preset(
            "reach-and-move-chained",
            "reach-and-move, Manager over the skill chain reacher-handover -> gripper-imitated -> mover-held with "
            "initiation sets (each skill starts only from states like those it was trained from; a choice outside its "
            "set runs the nearest skill before it whose set holds), Reacher goals in the pre-grasp box, Mover targets "
            "relative to the task's, k = 50, initial log std -2, 600 decisions per batch, TargetCoeff 1 and 10; paper: "
            "its best pair (s-reacher + mover-noised)",
            "Section 4.2.2, Figure 5",
            tuple(
                Run(
                    f"reacher-handover+gripper-imitated+mover-held,target_coeff={coeff},chained",
                    _chained(coeff),
                    _FIG5["mover-noised"][1],
                )
                for coeff in (1, 10)
            ),
            metric="target_dist_sum",
            budget=3_000_000,
        ),
        Preset(
            "reach-and-move-samples",
            "Samples to success on reach-and-move at TargetCoeff 1: the chained Manager (as in reach-and-move-chained, 3M "
            "steps) against flat TRPO with the paper's settings (as in reach-and-move-flat) run for 16M steps, long enough to "
            "show a 10x ratio at 50% training success",
            "Sections 4.2, 4.3.2 ('up to 10x fewer samples'); Figures 4 and 5",
            (
                Run("manager:reacher-handover+gripper-imitated+mover-held,chained", _chained(1), steps=3_000_000),
                Run("flat", _flat("ReachAndMove", task_kwargs={"target_coeff": 1})),
            ),
            budget=16_000_000,
            thresholds=(0.2, 0.5, 0.8),  # the samples targets' 20% and 50%, and Figure 5's 80%
        ),
        Preset(
            "reach-and-grip-1",
            "reach-and-grip Experiment 1 (capsule fixed), Manager over gripper + reacher, k = 10, over the Gripper "
            "reward's c2 x tr",
            "Section 4.3.1, Figure 6",
            tuple(Run(f"gripper+reacher,c2={c2},tr={tr}", _experiment_1(c2, tr), _FIG6[(c2, tr)]) for c2, tr in _GRID),
            # "every experiment required 1 million of samples ... 5 to 10 millions of interactions" (Section 4.3.1)
            budget=10_000_000,
        ),
        Preset(
            "reach-and-grip-1-tuned",
            "Figure 6's grid (Experiment 1, gripper + reacher, k = 10, c2 x tr) with the headline's Manager settings: "
            "2,000 decisions per batch and max KL 0.02 instead of the paper's 5,000 and 0.01",
            "Section 4.3.1, Figure 6",
            tuple(Run(f"gripper+reacher,c2={c2},tr={tr}", _tuned(_experiment_1(c2, tr)), _FIG6[(c2, tr)]) for c2, tr in _GRID),
            budget=3_000_000,
        ),
        Preset(
            "reach-and-grip-1-handover",
            "Figure 6's grid (Experiment 1, gripper + reacher, k = 10, c2 x tr) at the headline's Manager settings, the "
            "Reacher driven for hand-over (capsule-relative goals, approach from above, claw held open)",
            "Section 4.3.1, Figure 6",
            tuple(
                Run(f"gripper+reacher,c2={c2},tr={tr}", _handover(_tuned(_experiment_1(c2, tr))), _FIG6[(c2, tr)])
                for c2, tr in _GRID
            ),
            budget=1_000_000,
        ),
        Preset(
            "reach-and-grip-1-imitated",
            "Figure 6's grid (Experiment 1, k = 10, c2 x tr) with the skills made to hand over: the imitated Gripper "
            "(gripper-imitated) and the Reacher trained for hand-over (reacher-handover, capsule-relative goals only); the "
            "headline's Manager settings; paper: its figure with its own gripper + reacher",
            "Section 4.3.1, Figure 6",
            _figure_6_with("gripper-imitated"),
            budget=2_000_000,
        ),
        Preset(
            "reach-and-grip-1-claw",
            "Figure 6's grid (Experiment 1, k = 10, c2 x tr) as reach-and-grip-1-imitated with the Gripper that also sees "
            "its claw's pose (gripper-claw) in place of gripper-imitated; paper: its figure with its own gripper + reacher",
            "Section 4.3.1, Figure 6",
            _figure_6_with("gripper-claw"),
            budget=2_000_000,
        ),
        Preset(
            "reach-and-grip-1-samples",
            "Samples to success on Figure 6's c2 3, tr 0.03 cell (Experiment 1): the hand-over Manager over gripper + "
            "reacher (as in reach-and-grip-1-handover, 1M steps) against flat TRPO with the paper's settings (3M steps)",
            "Sections 4.3.1-4.3.2 ('up to 10x fewer samples')",
            (
                Run("manager:gripper+reacher", _handover(_tuned(_experiment_1(3, 0.03))), _FIG6[(3, 0.03)], steps=1_000_000),
                Run("flat", _flat("ReachAndGrip1", task_kwargs={"c2": 3, "tr": 0.03})),
            ),
            budget=3_000_000,
            thresholds=(0.05, 0.2, 0.5, 0.9),  # the 20% and 50%, the flat run's first 5%, the Manager's 90%
        ),
        Preset(
            "reach-and-grip-2-handover",
            "Figure 7's grid (Experiment 2, k = 15) for the skill sets with a Reacher, at the headline's Manager "
            "settings, the Reacher driven for hand-over (capsule-relative goals, approach from above, claw held open)",
            "Section 4.3.1, Figure 7",
            tuple(
                Run(
                    f"{label},c2={c2},tr={tr}",
                    _handover(replace(_tuned_manager(*_FIG7_SKILLS[label]), task_kwargs={"c2": c2, "tr": tr})),
                    paper,
                )
                for label, cells in _FIG7.items()
                if label != "gripper+micro"
                for (c2, tr), paper in cells.items()
            ),
            budget=2_000_000,
        ),
        Preset(
            "reach-and-grip-2-reacher-handover",
            "Figure 7's grid (Experiment 2, k = 15) with the Reacher trained for hand-over (reacher-handover) in place of "
            "the paper's: capsule-relative goals only, the skill run as trained (no approach drive, its own finger "
            "torques); the headline's Manager settings; paper: its figure for the same set with its own Reacher",
            "Section 4.3.1, Figure 7",
            tuple(
                Run(
                    f"{label.replace('reacher', 'reacher-handover')},c2={c2},tr={tr}",
                    _relative_only(
                        replace(_tuned_manager(*_FIG7_SKILLS[label]), task_kwargs={"c2": c2, "tr": tr}), "reacher-handover"
                    ),
                    paper,
                )
                for label, cells in _FIG7.items()
                if label in ("gripper+reacher", "gripper+reacher+micro")
                for (c2, tr), paper in cells.items()
            ),
            budget=3_000_000,
        ),
        Preset(
            "reach-and-grip-2-imitated",
            "Figure 7's grid (Experiment 2, k = 15) with the imitated Gripper (gripper-imitated: it sees the capsule's pose) "
            "in place of the paper's, beside the Reacher trained for hand-over as in reach-and-grip-2-reacher-handover, "
            "and with the micro-action as in the headline; the headline's Manager settings; paper: its figure for the same "
            "set with its own skills",
            "Section 4.3.1, Figure 7",
            _figure_7_with("gripper-imitated"),
            budget=3_000_000,
        ),
        Preset(
            "reach-and-grip-2-claw",
            "Figure 7's grid (Experiment 2, k = 15) as reach-and-grip-2-imitated with the Gripper that also sees its "
            "claw's pose (gripper-claw) in place of gripper-imitated, and gripper + s-reacher with the paper's Stabilised "
            "Reacher driven for hand-over (as in reach-and-grip-2-handover); paper: its figure for the same set with its "
            "own skills",
            "Section 4.3.1, Figure 7",
            _figure_7_with("gripper-claw", s_reacher=True),
            budget=3_000_000,
        ),
        Preset(
            "reach-and-grip-2-clearance",
            "reach-and-grip-2-claw with gripper-clearance (the Gripper that also sees the arm's distances to the capsule) "
            "in place of gripper-claw; paper: its figure for the same set with its own skills",
            "Section 4.3.1, Figure 7",
            _figure_7_with("gripper-clearance", s_reacher=True),
            budget=3_000_000,
        ),
        Preset(
            "reach-and-grip-2-chained",
            "Figure 7's gripper + reacher cells (Experiment 2, k = 15) with gripper-clearance and reacher-handover chained "
            "as reach-and-move-chained chains its skills: initiation sets (a Gripper chosen while the palm is out of its "
            "9 cm runs the Reacher) and pre-grasp goals (3 cm aside, 0-8 cm above the capsule), the headline's Manager "
            "settings; paper: its figure for gripper + reacher with its own skills",
            "Section 4.3.1, Figure 7; Appendix C (hand-over states)",
            _figure_7_chained("gripper-clearance"),
            budget=3_000_000,
        ),
        Preset(
            "reach-and-grip-2-chained-recovery",
            "reach-and-grip-2-chained with gripper-recovery (gripper-clearance trained on from the states just after it "
            "pushed the capsule away) in place of gripper-clearance; paper: its figure for gripper + reacher",
            "Section 4.3.1, Figure 7; Appendix C (hand-over states)",
            _figure_7_chained("gripper-recovery"),
            budget=3_000_000,
        ),
        Preset(
            "reach-and-grip-2-chained-recovery-2",
            "reach-and-grip-2-chained with gripper-recovery-2 (gripper-recovery trained on from the states just after its "
            "own pushes: a second recovery round) in place of gripper-clearance; paper: its figure for gripper + reacher",
            "Section 4.3.1, Figure 7; Appendix C (hand-over states)",
            _figure_7_chained("gripper-recovery-2"),
            budget=3_000_000,
        ),
        Preset(
            "reach-and-grip-2",
            "reach-and-grip Experiment 2, Manager over four skill sets x the reward grid c2 x tr, k = 15",
            "Section 4.3.1, Figure 7",
            tuple(
                Run(
                    f"{name},c2={c2},tr={tr}",
                    _manager("ReachAndGrip2", skills, 15, micro, task_kwargs={"c2": c2, "tr": tr}),
                    _FIG7[name][(c2, tr)],
                )
                for name, (skills, micro) in _FIG7_SKILLS.items()
                for c2, tr in _GRID
            ),
        ),
        Preset(
            "reach-and-grip-2-tuned",
            "Figure 7's grid (four skill sets x c2 x tr, k = 15) with the headline's Manager settings: 2,000 decisions "
            "per batch and max KL 0.02 instead of the paper's 5,000 and 0.01",
            "Section 4.3.1, Figure 7",
            tuple(
                Run(
                    f"{name},c2={c2},tr={tr}",
                    replace(_tuned_manager(skills, micro), task_kwargs={"c2": c2, "tr": tr}),
                    _FIG7[name][(c2, tr)],
                )
                for name, (skills, micro) in _FIG7_SKILLS.items()
                for c2, tr in _GRID
            ),
            budget=3_000_000,
        ),
        Preset(
            "headline",
            "The paper's headline claims at one reward cell (c2 3, tr 0.03): Managers over gripper + reacher, "
            "gripper + s-reacher (gluing), gripper + micro and gripper + reacher + micro against flat TRPO "
            "without and with the angle curriculum, all at equal environment steps",
            "Sections 4.3.1-4.3.2, Figures 7 and 8",
            (
                *(
                    Run(f"manager:{name}", _tuned_manager(skills, micro), _FIG7[name][(3, 0.03)])
                    for name, (skills, micro) in _FIG7_SKILLS.items()
                ),
                Run("flat", _flat("ReachAndGrip2")),
                Run("flat:alpha=pi*10/1e5", _flat("ReachAndGrip2", task_kwargs={"curriculum_alpha": math.pi * 10 / 1e5})),
            ),
            budget=3_000_000,
        ),
        Preset(
            "headline-wide-bonus",
            "The headline comparison at Figure 8's reward (tr 0.08, c2 2.1), whose wider bonus lets flat TRPO find "
            "grips: the Manager over gripper + micro (the headline's settings) against flat TRPO, at equal environment "
            "steps",
            "Sections 4.3.1-4.3.2, Figures 7 and 8",
            (
                Run("manager:gripper+micro", replace(_tuned_manager(("gripper",), True), task_kwargs=_FIG8_REWARD)),
                Run("flat", _flat("ReachAndGrip2", task_kwargs=_FIG8_REWARD)),
            ),
            budget=3_000_000,
        ),
        Preset(
            "reach-and-grip-2-flat",
            "reach-and-grip Experiment 2, flat, with the angle curriculum over alpha (tr 0.08, c2 2.1)",
            "Section 4.3.2, Figure 8",
            tuple(
                Run(
                    f"alpha=pi*{a:g}/1e5",
                    _flat("ReachAndGrip2", task_kwargs={"curriculum_alpha": math.pi * a / 1e5, **_FIG8_REWARD}),
                )
                for a in (0.1, 1, 10, 100)
            ),
        ),
        Preset(
            "reach-and-grip-2-flat-kl",
            "reach-and-grip Experiment 2, flat, over the maximal KL (curriculum alpha = pi / 1e5)",
            "Appendix B.2, Figure 10",
            tuple(
                Run(f"max_kl={kl:g}", _kl(_flat("ReachAndGrip2", task_kwargs={"curriculum_alpha": math.pi / 1e5}), kl))
                for kl in (0.001, 0.01, 0.1)
            ),
        ),
        Preset(
            "manager-kl",
            "the Manager (gripper + reacher, Experiment 2) over the maximal KL",
            "Appendix C",
            tuple(
                Run(f"max_kl={kl:g}", _kl(_manager("ReachAndGrip2", ("gripper", "reacher"), 15), kl))
                for kl in (0.003, 0.01, 0.03)
            ),
        ),
        Preset(
            "manager-k",
            "the Manager (gripper + reacher, Experiment 2) over the macro length k",
            "Appendix C",
            tuple(Run(f"k={k}", _manager("ReachAndGrip2", ("gripper", "reacher"), k)) for k in (5, 10, 15, 25)),
        ),
        Preset(
            "manager-size",
            "the Manager (gripper + reacher, Experiment 2) over its hidden layer width",
            "Appendix C",
            tuple(
                Run(f"hidden={h}", _manager("ReachAndGrip2", ("gripper", "reacher"), 15, hidden=(h, h))) for h in (32, 64, 128)
            ),
        ),
        Preset(
            "micro-bounds",
            "gripper + reacher + micro with bounded or penalised micro-actions",
            "Appendix C",
            tuple(
                Run(
                    name,
                    replace(
                        _manager("ReachAndGrip2", ("gripper", "reacher"), 15),
                        macro=MacroSpec(("gripper", "reacher"), k=15, micro=micro),
                    ),
                )
                for name, micro in _MICRO_VARIANTS
            ),
        ),
        *_appendix_c_tuned(),
    )
}
