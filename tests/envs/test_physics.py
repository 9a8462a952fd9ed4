"""The arm model against ARM_CLAW's physical facts, and its measurements."""

import math

import mujoco
import numpy as np
import pytest

from hrlp.arm import BASE_OBS_DIM, JOINTS, ArmPhysics, PhysicsConfig

GEARS = [100, 100, 100, 70, 70, 30, 30, 10, 10]
RANGES = [
    (-1.57, 0.70),
    (-0.85, 1.57),
    (-0.85, 0.85),
    (-1.50, 1.05),
    (-1.50, 1.57),
    (-0.50, 0.50),
    (-1.05, 1.05),
    (-1.05, 1.05),
    (-1.05, 1.05),
]


@pytest.fixture
def physics() -> ArmPhysics:
    return ArmPhysics()


def test_model_has_nine_hinges_with_the_papers_gears_and_ranges(physics):
    m = physics.model
    hinges = [m.joint(j) for j in JOINTS]
    assert all(int(h.type[0]) == mujoco.mjtJoint.mjJNT_HINGE for h in hinges)
    assert m.nu == 9
    np.testing.assert_allclose(m.actuator_gear[:, 0], GEARS)
    np.testing.assert_allclose(m.actuator_ctrlrange, [[-1, 1]] * 9)
    np.testing.assert_allclose(physics.joint_range, RANGES)
    # Shoulder and elbow joints are damped 5, the wrist and fingers 1; armature 0.1 everywhere.
    np.testing.assert_allclose(m.dof_damping[:9], [5, 5, 5, 5, 5, 1, 1, 1, 1])
    np.testing.assert_allclose(m.dof_armature[:9], 0.1)
    assert BASE_OBS_DIM == 24


def test_capsule_is_about_0_2_kg(physics):
    mass = physics.model.body_mass[physics.model.body("object").id]
    assert 0.18 < mass < 0.23


def test_fingertips_are_4cm_apart_open_and_close_with_rc_positive_lc_negative(physics):
    physics.forward()
    assert physics.finger_gap() == pytest.approx(0.04, abs=1e-6)
    q = np.zeros(9)
    q[7], q[8] = 0.3, -0.3
    physics.set_arm(q)
    physics.forward()
    assert physics.finger_gap() < 0.03


def test_arm_parts_never_collide_with_each_other_but_touch_table_and_capsule(physics):
    m = physics.model
    arm = [
        g
        for g in range(m.ngeom)
        if m.geom_bodyid[g] in {m.body(b).id for b in ("upperarm", "forearm", "claw", "rightclaw", "leftclaw")}
    ]
    table, capsule = m.geom("table").id, m.geom("object").id

    def collides(a, b):
        return bool(m.geom_contype[a] & m.geom_conaffinity[b]) or bool(m.geom_contype[b] & m.geom_conaffinity[a])

    assert not any(collides(a, b) for a in arm for b in arm)
    assert all(collides(a, table) and collides(a, capsule) for a in arm)
    assert collides(capsule, table)
    assert not collides(m.geom("target").id, capsule)


def test_capsule_comes_to_rest_on_the_table(physics):
    physics.set_capsule(np.array([0.15, 0.0, 0.05]))
    physics.set_arm(np.array([0, -0.5, 0, 0, 0, 0, 0, 0, 0.0]))  # arm swung back, out of the way
    for _ in range(150):
        assert physics.step(np.zeros(9))
    c = physics.capsule
    assert c[2] == pytest.approx(0.025, abs=0.004)  # lying on its side: centre one radius up
    assert np.linalg.norm(physics.data.qvel[9:15]) < 1e-2


def test_base_observation_layout(physics):
    rng = np.random.default_rng(0)
    physics.set_arm(rng.uniform(physics.joint_range[:, 0], physics.joint_range[:, 1]), rng.normal(size=9))
    physics.forward()
    obs = physics.base_observation(np.empty(24))
    np.testing.assert_array_equal(obs[:9], physics.qpos)
    np.testing.assert_array_equal(obs[9:18], physics.qvel)
    np.testing.assert_array_equal(obs[18:21], physics.hand)
    np.testing.assert_array_equal(obs[21:24], physics.capsule)


def test_hand_point_lies_between_the_fingers(physics):
    physics.forward()
    a, b = physics.fingertips
    mid = (a + b) / 2
    # H is on the claw's axis, 3 cm short of the tips (inside the grip).
    assert np.linalg.norm(physics.hand - mid) == pytest.approx(0.03, abs=1e-6)


def test_inverse_kinematics_reaches_a_point_and_leaves_state_untouched(physics):
    rng = np.random.default_rng(1)
    before = physics.data.qpos.copy()
    goal = np.array([0.1, 0.1, 0.1])
    errs = [
        physics.solve_hand_ik(goal, rng.uniform(physics.joint_range[:, 0], physics.joint_range[:, 1]))[1] for _ in range(10)
    ]
    assert min(errs) < 0.005
    np.testing.assert_array_equal(physics.data.qpos, before)
    q, err = physics.solve_hand_ik(goal, np.zeros(9))
    if err < 0.005:
        np.testing.assert_allclose(physics.hand_at(q), goal, atol=0.005)


def test_step_reports_a_physics_blow_up(physics):
    assert physics.step(np.zeros(9))
    physics.data.qvel[:] = 1e12  # MuJoCo resets the state on such a velocity (mjWARN_BADQVEL)
    assert not physics.step(np.zeros(9))
    assert sum(physics.instability_warnings().values()) >= 1


@pytest.mark.parametrize("bad", [{"timestep": 0.0}, {"timestep": math.nan}, {"substeps": 0}, {"substeps": 2.5}])
def test_physics_config_rejects_bad_values(bad):
    with pytest.raises(ValueError, match="PhysicsConfig"):
        PhysicsConfig(**bad)


def test_gravity_can_be_switched_off():
    p = ArmPhysics(PhysicsConfig(gravity=False))
    p.set_capsule(np.array([0.0, 0.35, 0.2]))  # away from the arm
    p.forward()
    for _ in range(20):
        p.step(np.zeros(9))
    np.testing.assert_allclose(p.capsule, [0.0, 0.35, 0.2], atol=1e-6)


@pytest.mark.parametrize(
    ("offset", "yaw", "expected"),
    [
        ((0.05, 0.0, 0.02), 0.0, 0.025),  # beyond the axis' end (3.5 cm): measured to the end point, (1.5, 0, 2) cm
        ((0.01, 0.03, 0.0), 0.0, 0.03),  # beside the axis: only the perpendicular 3 cm count
        ((0.01, 0.03, 0.0), math.pi / 2, 0.01),  # the axis along y runs through the hand's y: 1 cm in x remains
        ((0.0, 0.0, 0.0), 1.0, 0.0),  # on the centre
    ],
)
def test_hand_to_capsule_axis_is_the_distance_to_the_capsules_core_segment(physics, offset, yaw, expected):
    physics.forward()
    h = physics.hand.copy()
    physics.set_capsule(h + np.array(offset), yaw=yaw)
    physics.forward()
    assert physics.hand_to_capsule_axis() == pytest.approx(expected, abs=1e-9)
    assert physics.hand_to_capsule() == pytest.approx(float(np.linalg.norm(offset)), abs=1e-9)
