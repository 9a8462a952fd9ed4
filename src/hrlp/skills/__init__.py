"""Frozen, parameterised skills (the paper's macro-actions) and the skill library on disk."""

from hrlp.skills.library import (
    SkillLibrary,
    default_library_root,
    load_skill,
    locate_skill,
    shipped_library_root,
    skill_from_run,
)
from hrlp.skills.skill import PARAM_SPECS, ParamSpec, Skill

__all__ = [
    "PARAM_SPECS",
    "ParamSpec",
    "Skill",
    "SkillLibrary",
    "default_library_root",
    "load_skill",
    "locate_skill",
    "shipped_library_root",
    "skill_from_run",
]
