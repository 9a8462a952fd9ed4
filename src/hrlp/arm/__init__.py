"""The arm with a claw, hrlp's first domain: its physics (the MJCF model and measurements), the paper's tasks, their
batched backend and the Gymnasium ids ``hrlp/<Task>-v0`` (registered on import); its skills (:mod:`~hrlp.arm.skill`:
parameter specifications, initiation sets, named features), their files and shipped library
(:mod:`~hrlp.arm.skill_files`, which the skill library loads through the ``hrlp.domains`` entry point), the hand-over
drives (:mod:`~hrlp.arm.handover`), the batched Manager backend (:mod:`~hrlp.arm.manager`) and the research tools of the
shipped skills' recipes (:mod:`~hrlp.arm.research`)."""

from hrlp.arm.env import ArmEnv
from hrlp.arm.physics import BASE_OBS_DIM, JOINTS, N_JOINTS, ArmPhysics, PhysicsConfig
from hrlp.arm.registry import TASKS, TaskSpec, make, register_all
from hrlp.arm.tasks import GripReward, SparseSuccess, StartError, Task

register_all()

__all__ = [
    "BASE_OBS_DIM",
    "JOINTS",
    "N_JOINTS",
    "TASKS",
    "ArmEnv",
    "ArmPhysics",
    "GripReward",
    "PhysicsConfig",
    "SparseSuccess",
    "StartError",
    "Task",
    "TaskSpec",
    "make",
    "register_all",
]
