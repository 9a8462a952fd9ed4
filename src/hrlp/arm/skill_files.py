"""The arm's skill files: the manifest of a skill trained on one of the arm's tasks, checked against the layout its task
declares (24 base numbers, its parameters, its named features; 9 torques), and the frozen :class:`ArmSkill` built from
it. Registered with the skill library (:func:`hrlp.skills.library.register_format`) as the format of manifests that name
none, with the arm's shipped skills (``src/hrlp/arm/pretrained``) searched after the user's library.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from hrlp.arm.physics import BASE_OBS_DIM, N_JOINTS
from hrlp.arm.registry import TASKS
from hrlp.arm.skill import PARAM_SPECS, ArmSkill, Initiation, ParamSpec, check_features, features_dim, initiation_for
from hrlp.checkpoint import META_FILE, read_run_checkpoint, require_keys, save_checkpoint
from hrlp.skills.library import (
    MAX_K,
    UNNAMED_FORMAT,
    SkillFormat,
    SkillLibrary,
    SkillProblem,
    _check_network,
    _integer,
    _short,
    check_skill_name,
    frozen_network,
    register_format,
    register_shipped,
)


def shipped_library_root() -> Path:
    """The arm's small pretrained skills that come with hrlp (their recipes: the ``shipped-skills`` preset)."""
    return Path(__file__).parent / "pretrained"


def skill_from_run(run_dir: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """The trained policy's tensors and the facts about it, from a run directory written by ``hrlp train``."""
    tensors, meta, cfg = read_run_checkpoint(Path(run_dir) / "checkpoint")
    if meta.get("kind", "flat") != "flat":
        raise ValueError(f"{run_dir}: a skill is a flat policy; this run trained a {meta['kind']}")
    task = cfg.task.removeprefix("hrlp/").removesuffix("-v0")
    if task not in PARAM_SPECS:
        raise ValueError(f"{run_dir}: a skill must be trained on one of {', '.join(PARAM_SPECS)}, this run trained {task}")
    require_keys(meta, {"obs_dim": int, "act_dim": int}, Path(run_dir) / "checkpoint" / META_FILE)
    features: tuple[str, ...] = ()
    if meta["obs_dim"] != BASE_OBS_DIM + PARAM_SPECS[task].dim:  # the task observed more: which named features
        features = TASKS[task].build(**cfg.task_kwargs).observed_features
        if meta["obs_dim"] != (want := BASE_OBS_DIM + PARAM_SPECS[task].dim + features_dim(features)):
            named = ", ".join(features) or "none"
            raise ValueError(f"{run_dir}: its policy observes {meta['obs_dim']} numbers, a {task} skill {want} (24, its "
                             f"parameters and its task's named features: {named})")  # fmt: skip
    kept = {k: v for k, v in tensors.items() if k.startswith(("policy.", "normalizer."))}
    return kept, {"task": task, "source": meta, "features": list(features)}


def add_run(
    library: SkillLibrary,
    run_dir: Path,
    name: str,
    k: int = 15,
    overwrite: bool = False,
    lineage: dict[str, Any] | None = None,
) -> Path:
    """Turn a finished training run of an arm skill task into the skill ``name`` of ``library``, with default duration
    ``k``; returns its directory.

    ``lineage`` (JSON), if given, is recorded in the manifest: where the skill came from (``hrlp dagger`` records
    the parent skill and its sha256, the Manager whose hand-over states it was retrained from, and the round). A
    run started from a skill (``init_from``) records that skill and the sha256 it had then when none is given."""
    check_skill_name(name)
    if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= MAX_K:
        raise ValueError(f"skill {name}: default duration k must be a positive integer (at most {MAX_K:,}), got {k!r}")
    target = library.root / name
    if target.exists() and not overwrite:
        raise ValueError(f"skill {name!r} already exists in {library.root}; pass overwrite to replace it")
    tensors, facts = skill_from_run(run_dir)
    src = facts["source"]
    manifest = {
        "kind": "skill",
        "name": name,
        "task": facts["task"],
        "k": k,
        "param": PARAM_SPECS[facts["task"]].to_json(),
        "features": facts["features"],
        "obs_dim": src["obs_dim"],
        "act_dim": src["act_dim"],
        "hidden": src["config"]["hidden"],
        "normalizer": src["normalizer"],
        "trained": {"config": src["config"], "iteration": src["iteration"], "env_steps": src["env_steps"]},
    }
    init_from = src["config"].get("init_from")
    if lineage is None and isinstance(init_from, str):  # fine-tuned from a skill (hrlp train --init-from)
        lineage = {"parent": init_from, "parent_sha256": src.get("init_from_sha256")}
    if lineage is not None:
        manifest["lineage"] = lineage
    try:
        _check_manifest(manifest)
    except SkillProblem as e:
        raise ValueError(f"skill {name!r}: {e}") from None
    return save_checkpoint(target, tensors, manifest)


def _param_spec(manifest: dict[str, Any]) -> ParamSpec:
    """The skill's parameter specification: the one declared in code for its task (:data:`PARAM_SPECS`); the manifest's
    copy must agree on the layout (dimension, where it enters the observation), so a skill file cannot redefine it."""
    task = manifest.get("task")
    if not isinstance(task, str) or task not in PARAM_SPECS:
        raise SkillProblem(f"skill of unknown task {_short(task)} (known: {', '.join(PARAM_SPECS)})")
    spec = PARAM_SPECS[task]
    try:
        recorded = ParamSpec.from_json(manifest["param"])
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise SkillProblem(f"manifest's 'param' is malformed ({_short(e, 80)})") from None
    if (recorded.dim, recorded.obs_start) != (spec.dim, spec.obs_start):
        raise SkillProblem(f"manifest's parameters (dim {recorded.dim} at {recorded.obs_start}) do not match "
                            f"task {task}'s (dim {spec.dim} at {spec.obs_start})")  # fmt: skip
    return spec


def _check_manifest(m: dict[str, Any]) -> tuple[ParamSpec, int, tuple[int, ...], tuple[str, ...]]:
    """``(param, k, hidden, features)`` of an arm skill's manifest, whose every number is checked; raises
    :class:`SkillProblem`. A manifest without ``features`` (every skill written before them) reads none."""
    if m.get("kind") != "skill":
        raise SkillProblem(f"not a skill (kind {_short(m.get('kind'))})")
    param = _param_spec(m)
    k = _integer(m, "k", 1, MAX_K, "default duration")
    try:
        features = check_features(m.get("features", []), "manifest's 'features'")
    except ValueError as e:
        raise SkillProblem(_short(e, 200)) from None
    obs_dim = BASE_OBS_DIM + param.dim + features_dim(features)
    with_features = f" reading {', '.join(features)}" if features else ""
    _integer(m, "obs_dim", obs_dim, obs_dim, f"observation size of a {m['task']} skill{with_features}")
    _integer(m, "act_dim", N_JOINTS, N_JOINTS, "torques of the arm's joints")
    hidden = _check_network(m, obs_dim)
    _initiation(m)
    return param, k, hidden, features


def _initiation(m: dict[str, Any]) -> Initiation:
    """The skill's initiation set from its training task and settings (:func:`~hrlp.arm.skill.initiation_for`)."""
    kwargs = m["trained"]["config"].get("task_kwargs")
    if kwargs is not None and not isinstance(kwargs, dict):
        raise SkillProblem(f"manifest's training 'task_kwargs' must be an object, got {_short(kwargs)}")
    try:
        return initiation_for(m["task"], kwargs)
    except ValueError as e:
        raise SkillProblem(f"manifest's training task settings: {_short(e, 200)}") from None


def _build(name: str, tensors: dict[str, torch.Tensor], m: dict[str, Any], sha256: str) -> ArmSkill:
    """The frozen arm skill of checked files."""
    param, k, hidden, features = _check_manifest(m)
    policy, norm = frozen_network(tensors, m, hidden)
    return ArmSkill(name, m["task"], param, k, policy, norm, sha256, features, _initiation(m))


register_format(UNNAMED_FORMAT, SkillFormat(_check_manifest, _build))
register_shipped(shipped_library_root())
