"""The arm with a claw (physics) and the paper's tasks, as Gymnasium environments."""

from hrlp.envs.arm_env import ArmEnv
from hrlp.envs.param_tasks import register_param_tasks
from hrlp.envs.physics import BASE_OBS_DIM, JOINTS, N_JOINTS, ArmPhysics, PhysicsConfig
from hrlp.envs.registry import TASKS, TaskSpec, make, register_all
from hrlp.envs.tasks import GripReward, SparseSuccess, StartError, Task

register_all()
register_param_tasks()

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
