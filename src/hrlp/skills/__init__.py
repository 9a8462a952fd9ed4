"""Frozen, parameterised skills (the paper's macro-actions): the generic interface (:mod:`hrlp.skills.core`), skills
from learned policies (:mod:`hrlp.skills.policy`, Stable-Baselines3 files through :mod:`hrlp.skills.sb3`), and the
skill library on disk."""

from hrlp.skills.core import DirectControl, ObsLayout, ObsView, ParamBox, ScriptedSkill, Skill
from hrlp.skills.library import (
    SkillLibrary,
    default_library_root,
    load_skill,
    locate_skill,
    shipped_library_root,
    skill_from_run,
)
from hrlp.skills.policy import PolicySkill, from_sb3
from hrlp.skills.skill import PARAM_SPECS, ParamSpec
from hrlp.skills.skill import Skill as ArmSkill

__all__ = [
    "PARAM_SPECS",
    "ArmSkill",
    "DirectControl",
    "ObsLayout",
    "ObsView",
    "ParamBox",
    "ParamSpec",
    "PolicySkill",
    "ScriptedSkill",
    "Skill",
    "SkillLibrary",
    "default_library_root",
    "from_sb3",
    "load_skill",
    "locate_skill",
    "shipped_library_root",
    "skill_from_run",
]
