"""Frozen, parameterised skills (the paper's macro-actions) on any environment: the generic interface
(:mod:`hrlp.skills.core`), skills from learned policies (:mod:`hrlp.skills.policy`, Stable-Baselines3 files through
:mod:`hrlp.skills.sb3`), the skill library on disk (:mod:`hrlp.skills.library`) and the Manager's environment
(:mod:`hrlp.skills.macro_env`). The arm's skills are in :mod:`hrlp.arm`."""

from hrlp.skills.core import DirectControl, Holding, ObsLayout, ObsView, ParamBox, ScriptedSkill, Skill
from hrlp.skills.library import SkillLibrary, default_library_root, load_skill, locate_skill, shipped_roots
from hrlp.skills.policy import PolicySkill, from_sb3

__all__ = [
    "DirectControl",
    "Holding",
    "ObsLayout",
    "ObsView",
    "ParamBox",
    "PolicySkill",
    "ScriptedSkill",
    "Skill",
    "SkillLibrary",
    "default_library_root",
    "from_sb3",
    "load_skill",
    "locate_skill",
    "shipped_roots",
]
