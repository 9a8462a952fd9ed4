"""A Manager's worlds on the arm's batched backend: one :class:`~hrlp.skills.macro_env.ManagerVectorEnv` over a
:class:`~hrlp.arm.batched.BatchedArmEnv`, every world's physics stepped in one call per low-level step."""

from __future__ import annotations

from hrlp.arm.batched import BatchedArmEnv
from hrlp.skills.macro_env import MacroEnv, ManagerVectorEnv


def batched_manager(worlds: BatchedArmEnv, layout: MacroEnv) -> ManagerVectorEnv:
    """The Manager's ``N`` environments over the batched ``worlds`` of the task ``layout`` runs (its skills, durations,
    parameter blocks and gamma). Its steps are those of ``N`` :class:`MacroEnv` of the same task and seeds stepped
    serially, to within the batched physics' agreement with ArmEnv's (about 1e-7, :mod:`hrlp.arm.batched`); a one-line
    ValueError for worlds of another task than the layout's, or that do not measure a feature the skills read."""
    if not isinstance(layout, MacroEnv):
        raise ValueError(f"batched_manager: the layout must be a MacroEnv, got {type(layout).__name__}")
    if type(worlds.task) is not type(layout.env.unwrapped.task):  # type: ignore[attr-defined]
        raise ValueError(f"batched_manager: the worlds run {type(worlds.task).__name__}, the layout's "
                         f"macro-actions {type(layout.env.unwrapped.task).__name__}")  # type: ignore[attr-defined]  # fmt: skip
    return ManagerVectorEnv(worlds, layout)
