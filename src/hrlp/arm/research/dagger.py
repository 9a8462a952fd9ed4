"""DAgger-style retraining of a skill from the states where a Manager hands over to it (the paper's Appendix C).

"In the process of training the Manager collect points from which more difficult non-hierarchical tasks ... should be
retrained. Use this idea combined with the DAGGER algorithm." A skill trained from its own start set meets other
states when a Manager calls it: the Gripper, for instance, is called wherever the Reacher stopped. One round:

1. **collect**: run the trained Manager (sampling its actions, as in training) and record the physics state at every
   decision that chose the skill, into a start bank (``starts.npz``, no pickle);
2. **retrain**: continue the skill's own training run (same task, reward and settings, warm-started from the frozen
   skill's weights and observation statistics: ``TrainConfig.init_from``) with a share of its episodes starting from
   the bank (``GripperTask.starts``);
3. **freeze**: add it to the library as a new skill whose manifest records its lineage (the parent's name and sha256,
   the Manager run, the round, the bank's size);
4. **retrain the Manager** with the new skill in the parent's place, and evaluate old and new (skill from the
   hand-over states, Manager on its task).

Every stage's output is kept in the round's directory, and running the round again resumes from the first stage not
yet finished.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from hrlp.arm.physics import N_JOINTS, ArmPhysics
from hrlp.arm.research.starts import write_start_bank
from hrlp.arm.skill_files import add_run
from hrlp.arm.tasks import HANDOVER_BANK
from hrlp.atomic import atomic_path
from hrlp.skills.library import SkillLibrary, default_library_root, locate_skill, search_roots

#: The tasks whose skills can be retrained from hand-over states (their task reads a start bank).
RETRAINABLE_TASKS = frozenset({"Gripper"})


@dataclass(frozen=True)
class DaggerConfig:
    """One DAgger round: which Manager, which of its skills, how much to collect and train."""

    manager_run: str
    """Run directory of a trained Manager (``hrlp train-manager`` or ``hrlp reproduce``)."""
    skill: str
    """The Manager's skill to retrain (e.g. gripper)."""
    name: str
    """Name of the retrained skill in the library (a new name: no skill is overwritten)."""
    library: str | None = None
    """Library the new skill goes to (default: ``$HRLP_SKILLS`` or ``~/.hrlp/skills``)."""
    states: int = 2_000
    """Hand-over states to collect."""
    skill_steps: int = 2_000_000
    """Environment steps of the skill's retraining."""
    starts_fraction: float = 0.5
    """Share of the retraining episodes that start from a hand-over state (the rest: the skill's own start set)."""
    manager_steps: int | None = None
    """Environment steps of the new Manager (default: the old Manager's budget)."""
    workers: int = 2
    """Sampling processes of both trainings."""
    eval_episodes: int = 100
    """Evaluation episodes for each success rate the round reports."""
    seed: int = 0
    """Seed of the collection and both trainings."""
    max_hand_distance: float | None = None
    """Keep only hand-over states with d(H, C) at most this, metres (None: every state the Manager hands over at)."""
    max_capsule_speed: float | None = None
    """Keep only hand-over states whose capsule moves slower than this across the table, m/s (None: any speed)."""
    switches_only: bool = False
    """Keep only the decisions at which control passes to the skill (the episode's first decision or one after another
    macro-action), not those at which the Manager chooses the skill again to continue its own run."""

    def __post_init__(self) -> None:
        for name in ("max_hand_distance", "max_capsule_speed"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int | float) or not 0 < v < float("inf")):
                raise ValueError(f"dagger: {name} must be a positive number, got {v!r}")
        for name in ("states", "skill_steps", "workers", "eval_episodes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise ValueError(f"dagger: {name} must be a positive integer, got {v!r}")
        if self.manager_steps is not None and (not isinstance(self.manager_steps, int) or self.manager_steps <= 0):
            raise ValueError(f"dagger: manager_steps must be a positive integer, got {self.manager_steps!r}")
        if not (isinstance(self.starts_fraction, int | float) and 0 < self.starts_fraction <= 1):
            raise ValueError(f"dagger: starts_fraction must be in (0, 1], got {self.starts_fraction!r}")
        if not isinstance(self.switches_only, bool):
            raise ValueError(f"dagger: switches_only must be true or false, got {self.switches_only!r}")
        if self.name == self.skill:
            raise ValueError(f"dagger: the retrained skill needs a new name, not {self.skill!r}")


def graspable(physics: ArmPhysics, max_hand_distance: float | None, max_capsule_speed: float | None) -> bool:
    """Whether a grip can start from ``physics``'s state: H within ``max_hand_distance`` of C and the capsule moving
    slower than ``max_capsule_speed`` across the table (None: no limit)."""
    if max_hand_distance is not None and physics.hand_to_capsule() > max_hand_distance:
        return False
    if max_capsule_speed is not None:
        vx, vy = physics.data.qvel[N_JOINTS : N_JOINTS + 2]  # the capsule's free joint: linear velocity first
        if math.hypot(vx, vy) > max_capsule_speed:
            return False
    return True


def collect_handover_states(
    manager_run: Path,
    skill: str,
    states: int,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    keep: Callable[[ArmPhysics], bool] | None = None,
    switches_only: bool = False,
) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Physics states ``(qpos [states, nq], qvel [states, nv])`` at which the Manager of ``manager_run``, sampling
    its actions, ran ``skill`` (its choice, or under initiation sets the skill the choice ran) and, with ``keep``, for
    which ``keep(physics)`` holds (e.g. :func:`graspable`), the number of episodes it took and the number of hand-overs
    ``keep`` refused. With ``switches_only`` only the decisions at which control passes to ``skill`` count: the
    episode's first decision, or one after a decision that ran another macro-action (a Manager choosing the same skill
    again continues it from wherever its own steps took the arm). Raises ValueError if the Manager has no
    such skill or never chooses it (or no state is kept) in 200 episodes."""
    from hrlp.train import load_trained

    trained = load_trained(manager_run)
    if trained.config.macro is None:
        raise ValueError(f"{manager_run}: not a Manager run")
    env = trained.make_env()
    if skill not in env.names:
        raise ValueError(f"{manager_run}: the Manager has no skill {skill!r} (its skills: {', '.join(env.names)})")
    index = env.names.index(skill)
    physics = env.env.unwrapped.physics
    gen = torch.Generator().manual_seed(seed)
    qpos: list[np.ndarray] = []
    qvel: list[np.ndarray] = []
    episodes, refused = 0, 0
    while len(qpos) < states:
        if episodes >= 200 and not qpos:
            kept = f" at a state the filter keeps ({refused} refused)" if refused else ""
            raise ValueError(f"{manager_run}: the Manager did not choose {skill!r}{kept} in {episodes} episodes")
        obs, _ = env.reset(seed=seed * 100_003 + episodes)
        episodes += 1
        while True:
            action = trained.act(env, obs, gen, deterministic=False)
            switch = env.ran_last != index or not switches_only
            if env.would_run(int(action[0])) == index and switch and len(qpos) < states:  # the skill run (initiation sets)
                if keep is not None and not keep(physics):
                    refused += 1
                else:
                    qpos.append(physics.data.qpos.copy())
                    qvel.append(physics.data.qvel.copy())
                    if progress is not None:
                        progress(len(qpos), states)
            obs, _, term, trunc, _ = env.step(action)
            if term or trunc:
                break
    env.close()
    return np.stack(qpos), np.stack(qvel), episodes, refused


def skill_config(parent: dict[str, Any], bank: Path, cfg: DaggerConfig, init_from: str) -> Any:
    """The retraining run's config: the parent skill's own training config, warm-started from it, with a share
    ``cfg.starts_fraction`` of its episodes starting from ``bank``."""
    from hrlp.train import TrainConfig

    trained = TrainConfig.from_json(parent["trained"]["config"])
    if trained.task.removeprefix("hrlp/").removesuffix("-v0") not in RETRAINABLE_TASKS:
        raise ValueError(f"dagger: skill {parent['name']} was trained on {trained.task}; hand-over retraining "
                         f"supports {', '.join(sorted(RETRAINABLE_TASKS))}")  # fmt: skip
    kwargs = {**trained.task_kwargs, "starts": str(bank), "starts_fraction": cfg.starts_fraction}
    return dataclasses.replace(trained, steps=cfg.skill_steps, seed=cfg.seed, workers=min(cfg.workers, trained.num_envs),
                               task_kwargs=kwargs, init_from=init_from)  # fmt: skip


def run_round(cfg: DaggerConfig, out_dir: Path, console: Any = None) -> dict[str, Any]:
    """Run (or finish) one DAgger round into ``out_dir``; returns and writes ``round.json``: the success rates of the
    old and new skill from the hand-over states and from the skill's own starts, and of the old and new Manager."""
    from rich.console import Console

    from hrlp.checkpoint import checkpoint_exists
    from hrlp.evaluate import evaluate_run
    from hrlp.train import read_run_checkpoint, train_with_progress

    console = console or Console(stderr=True)
    out_dir, manager_run = Path(out_dir), Path(cfg.manager_run)
    library = SkillLibrary(Path(cfg.library) if cfg.library else default_library_root())
    manager_cfg = read_run_checkpoint(manager_run / "checkpoint")[2]
    if manager_cfg.macro is None or cfg.skill not in manager_cfg.macro.skills:
        raise ValueError(f"{manager_run}: not a Manager over skill {cfg.skill!r}")
    parent_library = locate_skill(cfg.skill, search_roots(manager_cfg.macro.library))
    parent, parent_manifest = parent_library.load(cfg.skill), parent_library.manifest(cfg.skill)
    parent_dir = parent_library.root / cfg.skill
    if cfg.name in library.names() and library.manifest(cfg.name).get("lineage", {}).get("round_dir") != str(out_dir):
        raise ValueError(f"skill {cfg.name!r} already exists in {library.root}; choose another --name")
    out_dir.mkdir(parents=True, exist_ok=True)
    plan = out_dir / "dagger.json"
    defaults = {f.name: f.default for f in dataclasses.fields(DaggerConfig) if f.default is not dataclasses.MISSING}
    if plan.exists() and {**defaults, **json.loads(plan.read_text())} != dataclasses.asdict(cfg):
        raise ValueError(f"{out_dir} holds a round with other settings ({plan}); choose another directory")
    with atomic_path(plan) as tmp:
        tmp.write_text(json.dumps(dataclasses.asdict(cfg), indent=2))
    started = time.perf_counter()

    bank = out_dir / "starts.npz"
    if not bank.exists():
        console.print(f"collecting {cfg.states} states where {manager_run} chooses {cfg.skill}")
        keep = None
        if cfg.max_hand_distance is not None or cfg.max_capsule_speed is not None:
            keep = functools.partial(graspable, max_hand_distance=cfg.max_hand_distance,
                                     max_capsule_speed=cfg.max_capsule_speed)  # fmt: skip
        qpos, qvel, episodes, refused = collect_handover_states(
            manager_run, cfg.skill, cfg.states, cfg.seed, keep=keep, switches_only=cfg.switches_only
        )
        meta = {"manager_run": str(manager_run), "skill": cfg.skill, "skill_sha256": parent.content_hash,
                "episodes": str(episodes), "refused": str(refused), "max_hand_distance": str(cfg.max_hand_distance),
                "max_capsule_speed": str(cfg.max_capsule_speed), "switches_only": str(cfg.switches_only)}  # fmt: skip
        write_start_bank(bank, {HANDOVER_BANK: (qpos, qvel)}, meta)
        refusals = f" ({refused} hand-overs refused by the filter)" if keep is not None else ""
        console.print(f"{len(qpos)} states from {episodes} episodes{refusals} -> {bank}")

    skill_run = out_dir / "skill"
    scfg = skill_config(parent_manifest, bank.resolve(), cfg, str(parent_dir.resolve()))
    if not _finished(skill_run, scfg.steps):
        train_with_progress(scfg, skill_run, checkpoint_exists(skill_run / "checkpoint"), console, f"retrain {cfg.skill}")
    if cfg.name not in library.names():
        lineage = {"parent": cfg.skill, "parent_sha256": parent.content_hash, "manager_run": str(manager_run),
                   "states": cfg.states, "starts_fraction": cfg.starts_fraction, "round_dir": str(out_dir)}  # fmt: skip
        add_run(library, skill_run, cfg.name, k=parent.k, lineage=lineage)
        console.print(f"skill {cfg.name} added to {library.root}")

    skills = tuple(cfg.name if s == cfg.skill else s for s in manager_cfg.macro.skills)
    mcfg = dataclasses.replace(
        manager_cfg,
        steps=cfg.manager_steps or manager_cfg.steps,
        seed=cfg.seed,
        workers=cfg.workers,
        macro=dataclasses.replace(manager_cfg.macro, skills=skills, library=str(library.root)),
    )
    manager_out = out_dir / "manager"
    if not _finished(manager_out, mcfg.steps):
        train_with_progress(mcfg, manager_out, checkpoint_exists(manager_out / "checkpoint"), console, "retrain Manager")

    console.print("evaluating")
    n = cfg.eval_episodes
    handover, own = {"starts_fraction": 1.0}, {"starts_fraction": 0.0}

    def skill_success(run: Path, starts: dict[str, Any]) -> dict[str, float]:
        ev = evaluate_run(run, episodes=n, task_kwargs={"starts": str(bank.resolve()), **starts})
        assert ev.success is not None
        return {"mean": ev.success.mean, "low": ev.success.low, "high": ev.success.high}

    def manager_success(run: Path) -> dict[str, Any]:
        ev = evaluate_run(run, episodes=n)
        assert ev.success is not None
        return {"mean": ev.success.mean, "low": ev.success.low, "high": ev.success.high, "decisions": ev.macro_usage}

    parent_run = _parent_as_run(scfg, out_dir / "parent-eval")
    result = {
        "round_dir": str(out_dir),
        "manager_run": str(manager_run),
        "skill": cfg.skill,
        "new_skill": cfg.name,
        "new_skill_sha256": library.load(cfg.name).content_hash,
        "parent_sha256": parent.content_hash,
        "episodes": n,
        "skill_from_handover": {"old": skill_success(parent_run, handover), "new": skill_success(skill_run, handover)},
        "skill_from_own_starts": {"old": skill_success(parent_run, own), "new": skill_success(skill_run, own)},
        "manager": {"old": manager_success(manager_run), "new": manager_success(manager_out)},
        "skill_steps": scfg.steps,
        "manager_steps": mcfg.steps,
        "wall_s_this_session": time.perf_counter() - started,
    }
    with atomic_path(out_dir / "round.json") as tmp:
        tmp.write_text(json.dumps(result, indent=2))
    return result


def _finished(run_dir: Path, steps: int) -> bool:
    from hrlp.checkpoint import checkpoint_exists
    from hrlp.train import read_run_checkpoint

    return checkpoint_exists(run_dir / "checkpoint") and read_run_checkpoint(run_dir / "checkpoint")[1]["env_steps"] >= steps


def _parent_as_run(retrain: Any, run_dir: Path) -> Path:
    """A run directory holding the parent skill unchanged: the retraining run's config (``retrain``, warm-started from
    the parent) saved before its first iteration, so that the parent is evaluated exactly as the retrained skill is
    (same task, same starts, same evaluation code)."""
    from hrlp.checkpoint import checkpoint_exists
    from hrlp.train import Trainer

    if checkpoint_exists(run_dir / "checkpoint"):
        return run_dir
    trainer = Trainer(dataclasses.replace(retrain, workers=1))
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        trainer.save(run_dir / "checkpoint")
    finally:
        trainer.sampler.close()
    return run_dir


__all__ = ["DaggerConfig", "collect_handover_states", "graspable", "run_round", "skill_config"]
