"""Start states recorded from a frozen skill's rollouts: the Mover's "palm close to the capsule" and "held" starts.

The paper trains the Mover from starts with the palm close to the capsule (Section 4.1, Experiment 2). On this arm a
Mover trained from hand-placed starts (claw at rest, 5-6.5 cm above the capsule) never learns to grip, and so never
moves the capsule (docs/research/skills-lineage.md). :func:`record_grip_starts` runs the shipped Gripper skill from the
Gripper task's close, open-claw starts and keeps the physics states of the episodes in which it grips the capsule, from
their first step to their last: states on the way to a grip, and gripped ones. ``MoverTask(starts="grip")`` draws from them;
``MoverTask(starts="held")`` from the states of ``gripper-imitated``'s episodes in which the capsule is held
(``held=True``): a Mover that only has to carry.

The states are stored as plain float arrays in an ``.npz`` file read with ``allow_pickle=False``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hrlp.arm import make
from hrlp.arm.research.scripted import ScriptedGrasp, ScriptedGraspConfig
from hrlp.arm.skill import ArmSkill
from hrlp.atomic import atomic_path

#: The Gripper task arguments of the shipped Gripper skill's training starts (the `shipped-skills` preset).
GRIP_START_TASK_ARGS: dict[str, object] = {"start_distance": (0.0, 0.09), "finger_opening": (0.0, 1.0)}


def record_grip_starts(
    gripper: ArmSkill | ScriptedGraspConfig,
    angle_range: float,
    states: int,
    *,
    seed: int = 0,
    every: int = 5,
    episode_steps: int = 100,
    num_envs: int = 16,
    held: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Physics states ``(qpos [states, nq], qvel [states, nv])`` along the ``gripper``'s successful Gripper episodes.

    Episodes start from the Gripper task's close, open-claw starts with the capsule's angle in
    ``[-angle_range, angle_range]``; a skill acts with its mean action, a :class:`ScriptedGraspConfig` stands for the
    scripted grasp (:class:`~hrlp.arm.research.scripted.ScriptedGrasp`, one per environment): its states show a top-down
    approach and grip that a policy trained from them can start from (demonstration starts). Every ``every``-th state
    of an episode in which Definition 1 held at some step is kept, until ``states`` are collected; with ``held``, only
    those in which it holds (the capsule in the claw: the starts of a Mover that carries what a Gripper gripped).
    ``progress(kept, episodes)`` is called after every finished episode.
    """
    if states < 1 or every < 1 or episode_steps < 1 or num_envs < 1:
        raise ValueError("states, every, episode_steps and num_envs must be positive integers")
    if not 0 <= angle_range <= math.pi:
        raise ValueError(f"angle_range must be in [0, pi], got {angle_range}")
    envs = [
        make("Gripper", episode_steps=episode_steps, angle_range=angle_range, **GRIP_START_TASK_ARGS) for _ in range(num_envs)
    ]
    obs = np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(envs)])
    if isinstance(gripper, ScriptedGraspConfig):
        experts = [ScriptedGrasp(env.unwrapped.physics, gripper) for env in envs]

        def act(o: np.ndarray) -> np.ndarray:
            return np.clip(np.stack([e.act() for e in experts]), -1.0, 1.0)
    else:

        def act(o: np.ndarray) -> np.ndarray:
            return gripper.torques(o, np.zeros((num_envs, 0)), gripper.features_of([env.unwrapped.physics for env in envs]))

    traj: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in envs]
    gripped = [False] * num_envs
    kept_q: list[np.ndarray] = []
    kept_v: list[np.ndarray] = []
    episodes = 0
    steps = [0] * num_envs
    while len(kept_q) < states:
        for i, env in enumerate(envs):
            if steps[i] % every == 0 and (not held or env.unwrapped.task.success(env.unwrapped.physics)):
                d = env.unwrapped.physics.data
                traj[i].append((d.qpos.copy(), d.qvel.copy()))
        actions = act(obs)
        for i, env in enumerate(envs):
            o, _, term, trunc, info = env.step(actions[i])
            steps[i] += 1
            gripped[i] = gripped[i] or bool(info["success"])
            if term or trunc:
                if gripped[i]:
                    kept_q.extend(q for q, _ in traj[i])
                    kept_v.extend(v for _, v in traj[i])
                episodes += 1
                if progress is not None:
                    progress(min(len(kept_q), states), episodes)
                traj[i], gripped[i], steps[i] = [], False, 0
                o, _ = env.reset()
            obs[i] = o
    for env in envs:
        env.close()
    return np.stack(kept_q[:states]), np.stack(kept_v[:states])


def write_start_bank(path: Path, banks: dict[str, tuple[np.ndarray, np.ndarray]], meta: dict[str, str]) -> Path:
    """Write ``{name: (qpos, qvel)}`` as ``NAME_qpos``/``NAME_qvel`` float32 arrays plus string ``meta`` (atomic)."""
    path = Path(path)
    arrays: dict[str, np.ndarray] = {}
    for name, (q, v) in banks.items():
        arrays[f"{name}_qpos"], arrays[f"{name}_qvel"] = q.astype(np.float32), v.astype(np.float32)
    arrays.update({f"meta_{k}": np.array(str(v)) for k, v in meta.items()})
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path


__all__ = ["GRIP_START_TASK_ARGS", "record_grip_starts", "write_start_bank"]
