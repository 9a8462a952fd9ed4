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
from dataclasses import dataclass
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
    max_episodes: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Physics states ``(qpos [states, nq], qvel [states, nv])`` along the ``gripper``'s successful Gripper episodes.

    Episodes start from the Gripper task's close, open-claw starts with the capsule's angle in
    ``[-angle_range, angle_range]``; a skill acts with its mean action, a :class:`ScriptedGraspConfig` stands for the
    scripted grasp (:class:`~hrlp.arm.research.scripted.ScriptedGrasp`, one per environment): its states show a top-down
    approach and grip that a policy trained from them can start from (demonstration starts). Every ``every``-th state
    of an episode in which Definition 1 held at some step is kept, until ``states`` are collected; with ``held``, only
    those in which it holds (the capsule in the claw: the starts of a Mover that carries what a Gripper gripped).
    ``progress(kept, episodes)`` is called after every finished episode. A ValueError once ``max_episodes`` episodes
    (None: no limit) have not given ``states`` states: a skill that seldom grips cannot fill the bank.
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
                if max_episodes is not None and episodes >= max_episodes and len(kept_q) < states:
                    for e in envs:
                        e.close()
                    what = "held the capsule" if held else "gripped"
                    raise ValueError(f"the Gripper {what} in too few of {episodes} episodes to record {states} start "
                                     f"states (got {len(kept_q)})")  # fmt: skip
                traj[i], gripped[i], steps[i] = [], False, 0
                o, _ = env.reset()
            obs[i] = o
    for env in envs:
        env.close()
    return np.stack(kept_q[:states]), np.stack(kept_v[:states])


@dataclass(frozen=True)
class RecoveryStarts:
    """What :func:`record_recovery_starts` recorded, and how the skill fared."""

    qpos: np.ndarray  # [S, nq]
    qvel: np.ndarray  # [S, nv]
    episodes: int
    wins: int
    """Episodes in which the skill gripped (Definition 1 at some step)."""
    pushed: int
    """Episodes in which it pushed the capsule away."""
    gripped_after_push: int


def record_recovery_starts(
    skill: ArmSkill,
    episodes: int = 3000,
    *,
    first_seed: int = 20_000,
    steps: int = 100,
    push: float = 0.03,
    every: int = 5,
    per_episode: int = 4,
    progress: Callable[[int, int], None] | None = None,
) -> RecoveryStarts:
    """The states just after a Gripper ``skill``'s own greedy episodes pushed the capsule away (its recovery starts).

    Runs the skill from the Gripper task's close, open-claw starts (:data:`GRIP_START_TASK_ARGS`; environment seeds
    ``first_seed`` + index) and records the physics state at the first step at which the capsule lies more than ``push``
    metres (across the table) from where it lay at the start while Definition 1 does not hold, then every ``every``
    steps after it while the capsule is still not held (at most ``per_episode`` states per episode).
    ``progress(states, episodes)`` is called after every episode."""
    if min(episodes, steps, every, per_episode) < 1:
        raise ValueError("episodes, steps, every and per_episode must be positive integers")
    if not push > 0:
        raise ValueError(f"push must be a positive distance in metres, got {push}")
    env = make("Gripper", episode_steps=steps, **GRIP_START_TASK_ARGS)
    task, p = env.unwrapped.task, env.unwrapped.physics
    qpos: list[np.ndarray] = []
    qvel: list[np.ndarray] = []
    pushed = gripped_after_push = wins = 0
    try:
        for ep in range(episodes):
            obs, _ = env.reset(seed=first_seed + ep)
            c0 = p.capsule.copy()
            push_step, kept, won = -1, 0, False
            for t in range(steps):
                held = task.success(p)
                if not held and push_step < 0 and math.hypot(*(p.capsule[:2] - c0[:2])) > push:
                    push_step = t
                if push_step >= 0 and not held and (t - push_step) % every == 0 and kept < per_episode:
                    qpos.append(p.data.qpos.copy())
                    qvel.append(p.data.qvel.copy())
                    kept += 1
                torques = skill.torques(obs[None], np.zeros((1, 0)), skill.features_of([p]))[0]
                obs, _, _, truncated, info = env.step(torques)
                won |= bool(info["success"])
                if truncated:
                    break
            wins += won
            if push_step >= 0:
                pushed += 1
                gripped_after_push += won
            if progress is not None:
                progress(len(qpos), ep + 1)
    finally:
        env.close()
    nq, nv = p.model.nq, p.model.nv
    return RecoveryStarts(np.stack(qpos) if qpos else np.zeros((0, nq)), np.stack(qvel) if qvel else np.zeros((0, nv)),
                          episodes, wins, pushed, gripped_after_push)  # fmt: skip


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


__all__ = ["GRIP_START_TASK_ARGS", "RecoveryStarts", "record_grip_starts", "record_recovery_starts", "write_start_bank"]
