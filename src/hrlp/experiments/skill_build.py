"""``hrlp skills build``: train skills from their recipes (a preset whose every run makes a skill) and add them to a
library, a whole recipe chain in one command.

A recipe may start from another skill's weights (``init_from``) or from a start bank recorded from another skill
(:data:`hrlp.arm.banks.BANKS`: the Movers from the Gripper's grips, ``gripper-recovery`` from ``gripper-clearance``'s
pushes). The build runs the recipes in stages, each after the skills it needs; before a stage it records every bank
that stage reads whose skill the library holds (into ``LIBRARY/.banks/``), unless the bank there was recorded from that
very skill. While it runs, ``$HRLP_SKILLS`` is the library, so ``init_from`` and the tasks' banks find what it built;
a skill or bank it needs and did not build is the library's, else the shipped one.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from hrlp.arm.banks import BANKS, banks_read
from hrlp.arm.skill import ArmSkill
from hrlp.arm.skill_files import add_run
from hrlp.arm.tasks import BANKS_DIR, bank_file
from hrlp.experiments.presets import Preset, Run
from hrlp.experiments.runner import plan, reproduce
from hrlp.paths import SKILLS_ENV
from hrlp.skills.library import SkillLibrary
from hrlp.training.loading import policy_skill_files

__all__ = ["build_skills", "needs", "stages"]


def needs(run: Run) -> tuple[set[str], tuple[str, ...]]:
    """The skills a recipe starts from (its ``init_from`` and its banks' sources) and the banks it reads."""
    cfg = run.config
    banks = banks_read(cfg.task, cfg.task_kwargs)
    skills = {BANKS[b].source for b in banks} | ({cfg.init_from} if cfg.init_from else set())
    return skills, banks


def stages(runs: tuple[Run, ...]) -> list[tuple[Run, ...]]:
    """The recipes in stages: each after the recipes of the skills it starts from (others come from the library)."""
    made = {r.skill[0]: r.name for r in runs if r.skill}
    after = {r.name: {made[s] for s in needs(r)[0] if s in made} for r in runs}
    out, done = [], set()
    while len(done) < len(runs):
        ready = tuple(r for r in runs if r.name not in done and after[r.name] <= done)
        if not ready:
            raise ValueError(f"the recipes {', '.join(sorted(set(after) - done))} start from each other")
        out.append(ready)
        done |= {r.name for r in ready}
    return out


@contextlib.contextmanager
def _library_first(library: Path) -> Iterator[None]:
    """``$HRLP_SKILLS`` set to ``library`` (the training processes inherit it), restored afterwards."""
    old = os.environ.get(SKILLS_ENV)
    os.environ[SKILLS_ENV] = str(library.resolve())
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(SKILLS_ENV, None)
        else:
            os.environ[SKILLS_ENV] = old


def _bank_skill(path: Path) -> str | None:
    """The sha256 of the skill a bank was recorded from (None: not recorded)."""
    with np.load(path, allow_pickle=False) as z:
        return str(z["meta_skill_sha256"]) if "meta_skill_sha256" in z else None


def build_skills(preset: Preset, library: Path, out: Path, budget: int | None = None, workers: int = 2,
                 overwrite: bool = False, bank_scale: float = 1.0, echo: Callable[[str], None] = print) -> None:  # fmt: skip
    """Train the preset's recipes in :func:`stages` and add each skill to ``library``; record the banks a stage reads
    first. ValueError, before any training, for a skill or a bank that would replace one in ``library`` without
    ``overwrite``."""
    lib = SkillLibrary(library)
    runs = tuple(r for r in preset.runs if r.skill)
    built = {r.skill[0] for r in runs if r.skill}
    if not overwrite and (taken := sorted(built & set(lib.names()))):
        raise ValueError(f"{library} already has {', '.join(taken)}; pass --overwrite to replace them")
    banks_dir = Path(library) / BANKS_DIR
    read = dict.fromkeys(b for r in runs for b in needs(r)[1])
    if not overwrite and (stale := [b for b in read if BANKS[b].source in built and (banks_dir / BANKS[b].file).exists()]):
        raise ValueError(f"{banks_dir} already has the banks {', '.join(BANKS[b].file for b in stale)}, recorded from "
                         "skills this build replaces; pass --overwrite to record them again")  # fmt: skip
    with _library_first(Path(library)):
        for stage in stages(runs):
            for b in dict.fromkeys(b for r in stage for b in needs(r)[1]):
                _record_bank(b, lib, banks_dir, overwrite, bank_scale, echo)
            for r in stage:
                for b in needs(r)[1]:
                    echo(f"{r.name} starts from the bank {bank_file(BANKS[b].asset)}")
            chosen = replace(preset, runs=stage)
            reproduce(chosen, out, None, budget, "process", workers, None, reuse=False)
            if budget is not None:
                chosen = chosen.with_budget(budget)
            for job, run in zip(plan(chosen, out), chosen.runs, strict=True):
                assert run.skill is not None
                if run.skill_args is None:  # the arm's: the task declares the parameters
                    add_run(lib, job.run_dir, run.skill[0], k=run.skill[1], overwrite=overwrite)
                else:
                    tensors, manifest = policy_skill_files(job.run_dir, k=run.skill[1], **run.skill_args)
                    lib.save(run.skill[0], tensors, manifest, overwrite=overwrite)
                echo(f"skill {run.skill[0]!r} (k = {run.skill[1]}) from {job.run_dir} added to {library}")


def _record_bank(name: str, lib: SkillLibrary, banks_dir: Path, overwrite: bool, scale: float,
                 echo: Callable[[str], None]) -> None:  # fmt: skip
    """Record bank ``name`` into ``banks_dir`` from the library's skill, unless the library has no such skill (the
    shipped bank is then read) or the bank there was recorded from it."""
    recipe = BANKS[name]
    if recipe.source not in lib.names():
        return
    skill = lib.load(recipe.source)
    assert isinstance(skill, ArmSkill)
    path = banks_dir / recipe.file
    if path.exists():
        if _bank_skill(path) == skill.content_hash:
            return
        if not overwrite:
            raise ValueError(f"{path} was recorded from another {recipe.source} than {lib.root}'s; pass --overwrite to "
                             "record it again")  # fmt: skip
    echo(f"recording the bank {name!r} from {recipe.source} into {path}")
    recipe.write(skill, path, scale, lambda line: echo(f"  {line}"))
