"""The start banks of the arm's skill recipes: which skill each is recorded from, how, and which tasks read it.

A start bank is a set of recorded physics states a task can begin its episodes from (``MoverTask(starts="grip")``,
``GripperTask(starts="recovery")``). Four come with hrlp, each recorded from a shipped skill; the skills trained from
them (the Movers, ``gripper-recovery``, ...) are the next rungs of their recipes. ``hrlp skills build`` records a bank
again, into the skill library's ``.banks/`` folder, whenever the skill it comes from is in that library (rebuilt), so
that a whole recipe chain rebuilds with one command; tasks read the library's bank before the shipped one
(:func:`hrlp.arm.tasks.bank_file`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hrlp.arm.registry import TASKS
from hrlp.arm.research.starts import record_grip_starts, record_recovery_starts, write_start_bank
from hrlp.arm.skill import ArmSkill
from hrlp.arm.tasks import (
    GRIPPER_RECOVERY_2_STARTS_FILE,
    GRIPPER_RECOVERY_STARTS_FILE,
    HANDOVER_BANK,
    MOVER_HELD_STARTS_FILE,
    MOVER_STARTS_FILE,
    GripperTask,
    MoverTask,
)

#: A start bank's states by name, ``{name: (qpos [S, nq], qvel [S, nv])}``.
Banks = dict[str, tuple[np.ndarray, np.ndarray]]
#: How many episodes a Mover bank may take per state asked for before a skill that seldom grips is given up on.
EPISODES_PER_STATE = 5


@dataclass(frozen=True)
class BankRecipe:
    """How one start bank is recorded."""

    name: str
    """The value of a task's ``starts`` that reads it."""
    asset: str
    """Its file under the package (``assets/NAME.npz``); the library keeps it as ``.banks/NAME.npz``."""
    source: str
    """The skill whose greedy episodes it records."""
    size: int
    """States per variant (a Mover bank: ``plain`` and ``noised``) or episodes run (a recovery bank)."""
    first_seed: int = 0
    """The environment seed of the first episode."""

    @property
    def file(self) -> str:
        """The bank's file name."""
        return Path(self.asset).name

    def record(
        self, skill: ArmSkill, scale: float = 1.0, progress: Callable[[str], None] | None = None
    ) -> tuple[Banks, dict[str, str]]:
        """The bank's states ``{name: (qpos, qvel)}`` and its metadata, recorded from ``skill`` at ``scale`` times the
        recipe's size. A one-line ValueError where the skill gives no states."""
        size = max(1, round(self.size * scale))
        meta = {"skill": self.source, "skill_sha256": skill.content_hash, "size": str(size),
                "first_seed": str(self.first_seed), "source": f"hrlp skills build (bank {self.name})"}  # fmt: skip
        if self.name in ("grip", "held"):
            banks = {}
            for variant, angle_range, seed in (("plain", 0.2, self.first_seed), ("noised", math.pi, self.first_seed + 1000)):
                banks[variant] = record_grip_starts(skill, angle_range, size, seed=seed, held=self.name == "held",
                                                    max_episodes=EPISODES_PER_STATE * size)  # fmt: skip
                if progress is not None:
                    progress(f"{variant}: {len(banks[variant][0])} states")
            return banks, meta
        rec = record_recovery_starts(skill, size, first_seed=self.first_seed)
        if progress is not None:
            progress(f"{rec.pushed} of {rec.episodes} episodes pushed the capsule away: {len(rec.qpos)} states")
        if not len(rec.qpos):
            raise ValueError(f"bank {self.name}: {self.source} pushed the capsule away in none of {rec.episodes} episodes, "
                             "so there is no state to record")  # fmt: skip
        return {HANDOVER_BANK: (rec.qpos, rec.qvel)}, meta

    def write(self, skill: ArmSkill, path: Path, scale: float = 1.0, progress: Callable[[str], None] | None = None) -> Path:
        """Record the bank from ``skill`` and write it to ``path`` (atomically)."""
        banks, meta = self.record(skill, scale, progress)
        return write_start_bank(path, banks, meta)


#: The arm's start banks, by the name a task's ``starts`` gives them.
BANKS: dict[str, BankRecipe] = {
    b.name: b
    for b in (
        BankRecipe("grip", MOVER_STARTS_FILE, "gripper", 2000),
        BankRecipe("held", MOVER_HELD_STARTS_FILE, "gripper-imitated", 2000),
        BankRecipe("recovery", GRIPPER_RECOVERY_STARTS_FILE, "gripper-clearance", 3000, first_seed=20_000),
        BankRecipe("recovery-2", GRIPPER_RECOVERY_2_STARTS_FILE, "gripper-recovery", 3000, first_seed=1_000_000),
    )
}


def banks_read(task: str, task_kwargs: dict[str, Any]) -> tuple[str, ...]:
    """The banks (:data:`BANKS`) an arm task made with ``task_kwargs`` starts from; () for any other task."""
    spec = TASKS.get(task)
    cls = spec.task_type if spec is not None else None
    if cls is None or not issubclass(cls, MoverTask | GripperTask):
        return ()
    starts = task_kwargs.get("starts", MoverTask.starts if issubclass(cls, MoverTask) else None)
    return (starts,) if starts in BANKS else ()


__all__ = ["BANKS", "EPISODES_PER_STATE", "BankRecipe", "banks_read"]
