"""The skill library on disk: one checkpoint directory per skill (safetensors + JSON manifest).

A skill file never runs code when loaded (safetensors, JSON; no pickle), and a tampered or
truncated file fails with a one-line error naming it (the manifest holds the weights' sha256).
The library lives in ``$HRLP_SKILLS`` or ``~/.hrlp/skills``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from hrlp.checkpoint import CheckpointError, load_checkpoint, load_module, save_checkpoint
from hrlp.policies.mlp import GaussianPolicy
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.skills.skill import PARAM_SPECS, ParamSpec, Skill

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


def default_library_root() -> Path:
    """``$HRLP_SKILLS`` if set, else ``~/.hrlp/skills``."""
    return Path(os.environ.get("HRLP_SKILLS", Path.home() / ".hrlp" / "skills"))


def shipped_library_root() -> Path:
    """The small pretrained skills that come with hrlp (trained by ``scripts/train_shipped_skills.sh``)."""
    return Path(__file__).parent / "pretrained"


def load_skill(name: str, library: str | Path | None = None) -> Skill:
    """The named skill, frozen, from ``library`` (if given), the user's library, or the shipped skills, in that order."""
    roots = [Path(library)] if library is not None else []
    roots += [default_library_root(), shipped_library_root()]
    for root in roots:
        lib = SkillLibrary(root)
        if name in lib.names():
            return lib.load(name)
    known = sorted({n for r in roots for n in SkillLibrary(r).names()})
    raise ValueError(f"no skill {name!r} in {', '.join(map(str, roots))} (known: {', '.join(known) or 'none'})")


def skill_from_run(run_dir: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """The trained policy's tensors and the facts about it, from a run directory written by ``hrlp train``."""
    tensors, meta = load_checkpoint(Path(run_dir) / "checkpoint")
    if meta.get("kind", "flat") != "flat":
        raise ValueError(f"{run_dir}: a skill is a flat policy; this run trained a {meta['kind']}")
    task = meta["config"]["task"].removeprefix("hrlp/").removesuffix("-v0")
    if task not in PARAM_SPECS:
        raise ValueError(f"{run_dir}: a skill must be trained on one of {', '.join(PARAM_SPECS)}, this run trained {task}")
    kept = {k: v for k, v in tensors.items() if k.startswith(("policy.", "normalizer."))}
    return kept, {"task": task, "source": meta}


def _param_spec(where: Path, manifest: dict[str, Any]) -> ParamSpec:
    """The skill's parameter specification: the one declared in code for its task (:data:`PARAM_SPECS`); the manifest's
    copy must agree on the layout (dimension, where it enters the observation), so a skill file cannot redefine it."""
    task = manifest.get("task")
    if task not in PARAM_SPECS:
        raise CheckpointError(f"{where}: skill of unknown task {task!r} (known: {', '.join(PARAM_SPECS)})")
    spec = PARAM_SPECS[task]
    try:
        recorded = ParamSpec.from_json(manifest["param"])
    except (KeyError, TypeError, ValueError) as e:
        raise CheckpointError(f"{where}: manifest's 'param' is malformed ({e})") from None
    if (recorded.dim, recorded.obs_start) != (spec.dim, spec.obs_start):
        raise CheckpointError(f"{where}: manifest's parameters (dim {recorded.dim} at {recorded.obs_start}) do not match "
                              f"task {task}'s (dim {spec.dim} at {spec.obs_start})")  # fmt: skip
    return spec


class SkillLibrary:
    """Named skills in a directory: ``add`` from a finished run, ``load`` frozen, ``list`` and ``manifest``."""

    def __init__(self, root: Path | None = None) -> None:
        self.root = Path(root) if root is not None else default_library_root()

    def names(self) -> list[str]:
        """Names of the skills in the library, sorted."""
        if not self.root.is_dir():
            return []
        return sorted(p.name for p in self.root.iterdir() if (p / "meta.json").is_file() and not p.name.startswith("."))

    def add(self, run_dir: Path, name: str, k: int = 15, overwrite: bool = False) -> Path:
        """Turn a finished training run into the named skill with default duration ``k``; returns its directory."""
        if not _NAME.match(name):
            raise ValueError(f"skill name {name!r}: use letters, digits, '_', '-', '.' (at most 64 characters)")
        if isinstance(k, bool) or not isinstance(k, int) or k < 1:
            raise ValueError(f"skill {name}: default duration k must be a positive integer, got {k!r}")
        target = self.root / name
        if target.exists() and not overwrite:
            raise ValueError(f"skill {name!r} already exists in {self.root}; pass overwrite to replace it")
        tensors, facts = skill_from_run(run_dir)
        src = facts["source"]
        manifest = {
            "kind": "skill",
            "name": name,
            "task": facts["task"],
            "k": k,
            "param": PARAM_SPECS[facts["task"]].to_json(),
            "obs_dim": src["obs_dim"],
            "act_dim": src["act_dim"],
            "hidden": src["config"]["hidden"],
            "normalizer": src["normalizer"],
            "trained": {"config": src["config"], "iteration": src["iteration"], "env_steps": src["env_steps"]},
        }
        return save_checkpoint(target, tensors, manifest)

    def manifest(self, name: str) -> dict[str, Any]:
        """The skill's manifest (with its content hash under ``sha256``)."""
        import json

        path = self.root / name / "meta.json"
        if not path.is_file():
            raise ValueError(f"no skill {name!r} in {self.root} (known: {', '.join(self.names()) or 'none'})")
        try:
            raw = json.loads(path.read_text())
        except json.JSONDecodeError as e:
            raise CheckpointError(f"{path}: invalid JSON ({e.msg})") from None
        return {**raw["meta"], "sha256": raw["sha256"]}

    def load(self, name: str) -> Skill:
        """The named skill, frozen. Raises a one-line error for a missing, tampered or truncated skill."""
        if name not in self.names():
            raise ValueError(f"no skill {name!r} in {self.root} (known: {', '.join(self.names()) or 'none'})")
        tensors, m = load_checkpoint(self.root / name)
        if m.get("kind") != "skill":
            raise CheckpointError(f"{self.root / name}: not a skill (kind {m.get('kind')!r})")
        param = _param_spec(self.root / name, m)
        policy = GaussianPolicy(int(m["obs_dim"]), int(m["act_dim"]), tuple(m["hidden"]))
        load_module("policy", policy, tensors)
        norm = RunningNormalizer.from_config(
            m["normalizer"], {k.removeprefix("normalizer."): v for k, v in tensors.items() if k.startswith("normalizer.")}
        )
        return Skill(name, m["task"], param, int(m["k"]), policy, norm, self.manifest(name)["sha256"])


__all__ = ["SkillLibrary", "default_library_root", "load_skill", "shipped_library_root", "skill_from_run"]
