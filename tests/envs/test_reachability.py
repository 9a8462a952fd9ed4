"""Start distributions stay inside the reachable workspace: sample starts and reach every point."""

import math

import numpy as np
import pytest

from hrlp.arm import TASKS, ArmPhysics, make
from hrlp.arm.tasks import CIRCLE_RADIUS, PALM_CIRCLE_Z, circle_point, is_reachable

SAMPLES = 12


def reachable(physics: ArmPhysics, point: np.ndarray, rng: np.random.Generator) -> bool:
    # Tighter than the start distributions' own check (1 cm), with more restarts.
    return is_reachable(physics, point, rng, tol=0.008, tries=40)


def points_to_reach(env) -> dict[str, np.ndarray]:
    p, name = env.physics, env.task.name
    pts = {"capsule": p.capsule.copy()}
    if name.startswith("Reacher"):
        pts["goal"] = env.task.goal.copy()
    if name.startswith("Mover") or name == "ReachAndMove":
        pts["target"] = p.target.copy()
    return pts


@pytest.mark.parametrize("name", list(TASKS))
def test_every_sampled_start_can_be_reached(name):
    env = make(name)
    rng = np.random.default_rng(0)
    for seed in range(SAMPLES):
        env.reset(seed=seed)
        for what, point in points_to_reach(env).items():
            assert reachable(env.physics, point, rng), f"{name} seed {seed}: {what} at {point} is out of reach"
        if getattr(env.task, "starts", None) == "grip":
            continue  # recorded mid-episode: the claw may hold the capsule and the arm move (tests/skills/test_starts.py)
        # The arm starts clear of the table and the capsule, and still (velocities zero).
        assert env.physics.arm_contacts() == 0
        assert not env.physics.qvel.any()


@pytest.mark.parametrize("angle", np.linspace(-math.pi, math.pi, 13))
def test_the_full_capsule_circle_and_palm_circle_are_reachable(angle):
    physics = ArmPhysics()
    rng = np.random.default_rng(1)
    assert reachable(physics, circle_point(angle), rng)
    assert reachable(physics, circle_point(angle, z=PALM_CIRCLE_Z), rng)


def test_reach_and_grip_palm_starts_on_its_circle():
    env = make("ReachAndGrip2")
    for seed in range(SAMPLES):
        env.reset(seed=seed)
        h = env.physics.hand
        r = math.hypot(h[0] + 0.15, h[1])
        assert r == pytest.approx(CIRCLE_RADIUS, abs=0.01)
        assert h[2] == pytest.approx(PALM_CIRCLE_Z, abs=0.01)


@pytest.mark.parametrize("starts", ["grip", "placed"])
def test_gripper_and_mover_start_with_the_palm_near_the_capsule(starts):
    for name, far in (("Gripper", 0.10), ("MoverPlain", 0.10), ("MoverNoised", 0.11)):
        env = make(name, starts=starts) if name.startswith("Mover") else make(name)
        for seed in range(SAMPLES):
            env.reset(seed=seed)
            assert env.physics.hand_to_capsule() < far, name
