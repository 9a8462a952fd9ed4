"""Where a Manager's skills come from: a skill library entry, a Python object (``MODULE:NAME``), or a run hrlp trained.

A skill reference is what ``--skills`` lists and :attr:`hrlp.skills.macro_env.MacroSpec.skills` records:

* a library name (``gripper``): a skill file (safetensors + JSON) in ``--library``, ``$HRLP_SKILLS`` or the skills
  shipped with hrlp (:mod:`hrlp.skills.library`);
* ``MODULE:NAME``: an attribute of an importable module that is a :class:`hrlp.skills.core.Skill`, or a function of no
  arguments returning one: a scripted controller (:class:`~hrlp.skills.core.ScriptedSkill`), a policy of another
  library (:func:`hrlp.skills.policy.from_sb3`), or a run of hrlp's (:func:`hrlp.training.loading.from_run`).

Each failure is one line naming the reference, before any compute.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from pathlib import Path

from hrlp.skills.core import Skill
from hrlp.skills.library import load_skill


def resolve_skill(ref: str, library: str | Path | None = None) -> Skill:
    """The skill ``ref`` names (see the module docstring); a one-line ValueError for a bad reference."""
    if not isinstance(ref, str) or not ref:
        raise ValueError(f"a skill reference must be a library name or MODULE:NAME, got {ref!r}")
    if ":" not in ref:
        return load_skill(ref, library)
    module_name, _, attr = ref.rpartition(":")
    if not module_name or not attr:
        raise ValueError(f"skill {ref!r}: write a Python skill as MODULE:NAME, e.g. my_pkg.skills:reach")
    try:
        module = importlib.import_module(module_name)
    except Exception as e:  # ImportError, or the module's own code failing: one line naming it
        raise ValueError(f"skill {ref!r}: cannot import module {module_name!r} ({type(e).__name__}: "
                         f"{' '.join(str(e).split())}); is it installed or on PYTHONPATH?") from None  # fmt: skip
    if not hasattr(module, attr):
        raise ValueError(f"skill {ref!r}: module {module_name!r} has no attribute {attr!r}")
    obj = getattr(module, attr)
    if not isinstance(obj, Skill) and callable(obj) and not isinstance(obj, type):
        try:
            obj = obj()
        except Exception as e:
            why = " ".join(str(e).split())
            raise ValueError(f"skill {ref!r}: calling {attr}() failed ({type(e).__name__}: {why})") from None
    if not isinstance(obj, Skill):
        raise ValueError(f"skill {ref!r} is a {type(obj).__name__}, not an hrlp.skills.Skill (nor a function of no "
                         "arguments returning one)")  # fmt: skip
    return obj


def resolve_skills(refs: Sequence[str], library: str | Path | None = None) -> list[Skill]:
    """:func:`resolve_skill` for each reference; a one-line ValueError for two skills of one name."""
    skills = [resolve_skill(r, library) for r in refs]
    names = [s.name for s in skills]
    if len(set(names)) != len(names):
        raise ValueError(f"two skills share a name: {', '.join(names)} (a Manager's skills need distinct names)")
    return skills
