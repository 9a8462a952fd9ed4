"""Gymnasium-Robotics' Fetch arm as a domain of hrlp: the named parts of its observation, its skills
(:mod:`hrlp.fetch.skills`) and their recipes.

Fetch's tasks (``FetchReach``, ``FetchPush``, ``FetchPickAndPlace``, ``FetchSlide``, version 4) give a Dict observation
whose ``observation`` key packs the gripper's and the object's state into one row. This module names those numbers
(``grip_pos``, ``object_pos``, ...) so that skills read them by name, on any of the four tasks. It declares facts only
and imports neither Gymnasium-Robotics nor MuJoCo: it is imported through the ``hrlp.domains`` entry point whenever hrlp
looks up an environment's parts (``pip install "hrlp[fetch]"`` installs the environments).
"""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

from hrlp.skills.core import register_observation_parts
from hrlp.skills.library import register_shipped

#: Fetch's ``observation`` row on the tasks with an object (``FetchEnv._get_obs``), ``name -> (start, stop)``.
OBJECT_PARTS = {
    "grip_pos": (0, 3),  # the gripper's position, metres (world frame)
    "object_pos": (3, 6),  # the object's position
    "object_rel_pos": (6, 9),  # object_pos - grip_pos
    "gripper_state": (9, 11),  # the two fingers' joint positions, metres (about 0.05 each when open)
    "object_rot": (11, 14),  # the object's Euler angles
    "object_velp": (14, 17),  # the object's linear velocity relative to the gripper's, times dt
    "object_velr": (17, 20),  # the object's angular velocity, times dt
    "grip_velp": (20, 23),  # the gripper's linear velocity, times dt
    "gripper_vel": (23, 25),  # the fingers' joint velocities, times dt
}
#: The same on FetchReach, which has no object.
REACH_PARTS = {"grip_pos": (0, 3), "gripper_state": (3, 5), "grip_velp": (5, 8), "gripper_vel": (8, 10)}
#: The Fetch task ids this domain names the parts of (sparse and dense rewards).
TASKS = {f"Fetch{task}{reward}-v4": parts for task, parts in (("Reach", REACH_PARTS), ("Push", OBJECT_PARTS),
                                                               ("PickAndPlace", OBJECT_PARTS), ("Slide", OBJECT_PARTS))
         for reward in ("", "Dense")}  # fmt: skip
#: Named parts of the goal keys on the tasks with an object, ``name -> (key, start, stop)``.
GOAL_PARTS = {"goal_xy": ("desired_goal", 0, 2)}  # where the object must go, on the table's plane (x, y)
#: FetchReach's own observation parts expressed in the other tasks' named parts (``--bind`` of a skill trained there).
REACH_BIND = {"achieved_goal": ("grip_pos",), "observation": ("grip_pos", "gripper_state", "grip_velp", "gripper_vel")}

#: The first MuJoCo release on which Gymnasium-Robotics 1.4.2's Fetch fails at reset (an assertion on a joint's type).
FIRST_FAILING_MUJOCO = (3, 12)


def check_installed() -> None:
    """Raise a one-line ValueError unless Gymnasium-Robotics is installed with a MuJoCo its Fetch runs on."""
    try:
        importlib.metadata.version("gymnasium-robotics")
    except importlib.metadata.PackageNotFoundError:
        raise ValueError('Fetch needs Gymnasium-Robotics: pip install "hrlp[fetch]"') from None
    mujoco = importlib.metadata.version("mujoco")
    if tuple(int(v) for v in mujoco.split(".")[:2]) >= FIRST_FAILING_MUJOCO:
        raise ValueError(f"Gymnasium-Robotics' Fetch fails at reset on mujoco {mujoco} (from 3.12 on): "
                         'pip install "hrlp[fetch]" installs one it runs on (3.11)')  # fmt: skip


for _task, _parts in TASKS.items():
    register_observation_parts(_task, {**{name: ("observation", lo, hi) for name, (lo, hi) in _parts.items()},
                                       **(GOAL_PARTS if _parts is OBJECT_PARTS else {})})  # fmt: skip
register_shipped(Path(__file__).parent / "pretrained")  # fetch-reach (hrlp); the carry skill's SB3 .zip is read by path

__all__ = ["FIRST_FAILING_MUJOCO", "GOAL_PARTS", "OBJECT_PARTS", "REACH_BIND", "REACH_PARTS", "TASKS", "check_installed"]
