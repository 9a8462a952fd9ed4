"""The arm with a claw, hrlp's first domain: its physics (the MJCF model and measurements), the paper's tasks, their
batched backend, and the Gymnasium ids ``hrlp/<Task>-v0`` (registered on import)."""

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
