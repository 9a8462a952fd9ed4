"""The handover Reacher: pre-grasp goals outside the capsule, a cost for moving it, an open, symmetric claw."""

import numpy as np
import pytest

from hrlp.arm import make
from hrlp.arm.physics import CAPSULE_RADIUS
from hrlp.arm.skill import PARAM_SPECS, POINT_TASKS
from hrlp.arm.tasks import HANDOVER_GOAL_HIGH, HANDOVER_GOAL_LOW, claw_closure


def test_goals_are_pre_grasp_points_in_the_handover_box_never_inside_the_capsule():
    env = make("ReacherHandover")
    for seed in range(30):
        obs, _ = env.reset(seed=seed)
        offset = obs[24:27] - env.unwrapped.task.start_capsule
        assert (offset >= HANDOVER_GOAL_LOW - 1e-9).all() and (offset <= HANDOVER_GOAL_HIGH + 1e-9).all()
        assert offset[2] > CAPSULE_RADIUS
    assert "ReacherHandover" in POINT_TASKS and PARAM_SPECS["ReacherHandover"].dim == 3


def test_claw_closure_is_zero_for_a_symmetric_opening_and_grows_with_closing_or_skew():
    env = make("ReacherHandover")
    env.reset(seed=0)
    p = env.unwrapped.physics

    def closure(rc, lc):
        q = p.qpos.copy()
        q[7:] = rc, lc
        p.set_arm(q)
        return claw_closure(p)

    assert closure(-0.5, 0.5) == 0 and closure(0.0, 0.0) == 0
    assert closure(0.4, -0.4) == pytest.approx(0.8) and closure(-0.5, 0.1) == pytest.approx(0.4)


def test_moving_the_capsule_costs_and_voids_success_and_the_start_survives_a_saved_state():
    env = make("ReacherHandover", episode_steps=20)
    env.reset(seed=3)
    task, p = env.unwrapped.task, env.unwrapped.physics
    assert env.step(np.zeros(9))[4]["reward_capsule"] > -0.05  # a capsule left alone costs (almost) nothing
    twin = make("ReacherHandover", episode_steps=20)
    twin.set_state(env.get_state())
    np.testing.assert_array_equal(twin.unwrapped.task.start_capsule, task.start_capsule)
    p.set_capsule(task.start_capsule + np.array([0.05, 0.0, 0.0]))
    p.forward()
    task.goal[:] = p.hand  # the hand is at its goal, but the capsule was pushed 5 cm
    assert not task.success(p)
    assert task.reward_terms(p)["capsule"] == pytest.approx(-5.0 * 0.05, rel=1e-6)
    p.set_capsule(task.start_capsule)
    p.forward()
    assert task.success(p)
