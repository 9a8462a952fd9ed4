"""Invariants over every registered task (as dm_control's suite test), plus each task's specifics."""

import logging
import math
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import hrlp.arm  # noqa: F401  (registers the ids)
from hrlp.arm import TASKS, make
from hrlp.arm.physics import CLEARANCE_BODIES
from hrlp.arm.tasks import GripperTask, GripReward, ReachAndGripTask, SparseSuccess

NAMES = list(TASKS)


@pytest.mark.parametrize("name", NAMES)
def test_gymnasium_env_checker_passes(name):
    env = gym.make(f"hrlp/{name}-v0", episode_steps=20).unwrapped
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # Joint velocities and positions in space are unbounded, as in Gymnasium's own MuJoCo tasks.
        warnings.filterwarnings("ignore", message=".*Box observation space (minimum|maximum) value is")
        check_env(env, skip_render_check=True)


@pytest.mark.parametrize("name", NAMES)
def test_reward_is_the_sum_of_its_terms_and_episode_truncates(name):
    env = make(name, episode_steps=40)
    obs, info = env.reset(seed=3)
    assert obs.shape == env.observation_space.shape and np.isfinite(obs).all()
    assert isinstance(info["success"], bool)
    rng = np.random.default_rng(0)
    for t in range(1, 41):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 9))
        terms = {k: v for k, v in info.items() if k.startswith("reward_")}
        assert terms, "every reward reports its terms"
        assert reward == pytest.approx(sum(terms.values()), abs=1e-12)
        assert not terminated
        assert truncated == (t == 40)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(9))


@pytest.mark.parametrize("name", NAMES)
def test_same_seed_gives_the_same_episode(name):
    def episode(seed):
        env = make(name, episode_steps=25)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        out = [obs]
        for _ in range(25):
            obs, r, *_ = env.step(rng.uniform(-1, 1, 9))
            out.append(np.append(obs, r))
        return np.concatenate(out)

    a, b, c = episode(7), episode(7), episode(8)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("name", NAMES)
def test_bad_actions_raise_clear_errors_naming_the_task(name):
    env = make(name)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=rf"{TASKS[name].build().name}: action must have shape \(9,\), got \(8,\)"):
        env.step(np.zeros(8))
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.full(9, np.nan))
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.array([0, 0, 0, np.inf, 0, 0, 0, 0, 0]))
    # A huge finite action is valid (the motors clamp it to [-1, 1]).
    env.step(np.full(9, 1e300))


def test_physics_blow_up_truncates_with_a_flag_and_a_logged_warning(caplog):
    env = make("Gripper")
    _obs0, _ = env.reset(seed=0)
    obs1, *_ = env.step(np.zeros(9))
    env.physics.data.qvel[:] = 1e12
    with caplog.at_level(logging.WARNING, logger="hrlp.arm.env"):
        obs, reward, terminated, truncated, info = env.step(np.zeros(9))
    assert truncated and not terminated and info["physics_unstable"]
    assert "unstable" in caplog.text
    np.testing.assert_array_equal(obs, obs1)  # the last good observation, not MuJoCo's reset state
    assert reward == sum(v for k, v in info.items() if k.startswith("reward_"))
    with pytest.raises(RuntimeError):
        env.step(np.zeros(9))


@pytest.mark.parametrize(
    ("name", "kwargs", "match"),
    [
        ("Gripper", {"c1": 1.0}, "c1, c3 < 0 < c2"),
        ("Gripper", {"c2": -3.0}, "c1, c3 < 0 < c2"),
        ("Gripper", {"tr": 0.0}, "tr must be a positive"),
        ("ReachAndGrip2", {"tr1": -0.1}, "tr1 must be a positive"),
        ("ReachAndGrip1", {"curriculum_alpha": -1.0}, "curriculum_alpha"),
        ("Reacher", {"success_tol": math.nan}, "success_tol"),
        ("ReachAndMove", {"target_coeff": -1.0}, "target_coeff"),
        ("MoverPlain", {"bogus": 1}, "MoverPlain: invalid argument"),
        ("Gripper", {"episode_steps": 0}, "episode_steps must be a positive integer"),
        ("Nope", {}, "unknown task 'Nope'"),
    ],
)
def test_bad_task_arguments_fail_before_any_compute(name, kwargs, match):
    with pytest.raises(ValueError, match=match):
        make(name, **kwargs)


def test_gripper_reward_constants_are_constructor_arguments():
    env = make("Gripper", c1=-2.0, c2=4.0, c3=-1.0, tr=10.0)  # tr large: the bonus is always on
    env.reset(seed=0)
    _, _r, _, _, info = env.step(np.zeros(9))
    d, gap = env.physics.hand_to_capsule(), env.physics.finger_gap()
    assert info["reward_bonus"] == 4.0
    assert info["reward_distance"] == pytest.approx(-2.0 * d)
    assert info["reward_fingers"] == pytest.approx(-1.0 * gap)


def test_sparse_success_follows_definition_1_and_latches():
    env = make("Gripper", tr1=10.0, tr2=10.0)  # thresholds that every state meets
    _, info = env.reset(seed=0)
    assert info["success"]
    env = make("Gripper", tr1=1e-6, tr2=1e-6)  # thresholds no state meets
    env.reset(seed=0)
    assert not any(env.step(np.zeros(9))[4]["success"] for _ in range(5))
    check = SparseSuccess(tr1=0.05, tr2=0.03)
    env = make("Gripper")
    env.reset(seed=0)
    p = env.physics
    assert check(p) == (p.hand_to_capsule() < 0.05 and p.finger_gap() < 0.03)


def test_target_dist_sum_is_the_sum_of_minus_d_c_t():
    env = make("ReachAndMove", episode_steps=30, target_coeff=2.0)
    env.reset(seed=0)
    total = 0.0
    for _ in range(30):
        _, _r, _, _, info = env.step(np.zeros(9))
        d = env.physics.capsule_to_target()
        total -= d
        assert info["reward_move"] == pytest.approx(-2.0 * d)
        assert info["target_dist_sum"] == pytest.approx(total)
    # The target sits above the fixed capsule: 15 cm at the start.
    assert env.physics.target[2] - 0.025 == pytest.approx(0.15)


def test_curriculum_grows_the_start_angle_by_alpha_per_episode():
    task = ReachAndGripTask(experiment=2, curriculum_alpha=0.1)
    assert [task.angle_half_width(k) for k in (0, 1, 5)] == pytest.approx([0.0, 0.1, 0.5])
    assert task.angle_half_width(10_000) == pytest.approx(math.pi)
    env = make("ReachAndGrip2", curriculum_alpha=0.05)
    angles = []
    for k in range(30):
        env.reset(seed=k)
        c = env.physics.capsule
        angles.append(abs(math.atan2(c[1], c[0] + 0.15)))
        assert angles[-1] <= k * 0.05 + 1e-9
    assert max(angles) > 0.3  # it does widen
    assert ReachAndGripTask(experiment=1).angle_half_width(0) == pytest.approx(math.pi)


@pytest.mark.parametrize("seed", [0, 2, 6])
def test_a_curriculum_at_its_narrowest_always_finds_a_start(seed):
    # Regression: with w ~ 0 the palm was drawn right above the capsule, where ~7% of IK poses are
    # contact-free, and resets after some random steps raised StartError (seeds 0, 2 and 6 did).
    env = make("ReachAndGrip2", curriculum_alpha=1e-6)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    for _ in range(30):
        for _ in range(30):
            env.step(rng.uniform(-1, 1, size=env.action_space.shape).astype(np.float32))
        env.reset()
        c = env.physics.capsule
        assert abs(math.atan2(c[1], c[0] + 0.15)) < 1e-3  # the capsule stays at the curriculum's angle


def test_reach_and_grip_experiment_1_fixes_the_capsule_and_experiment_2_does_not():
    def capsules(name):
        env = make(name)
        return np.array([env.reset(seed=s)[0][21:24] for s in range(6)])

    c1, c2 = capsules("ReachAndGrip1"), capsules("ReachAndGrip2")
    assert np.ptp(c1[:, :2], axis=0).max() < 1e-9
    assert np.ptp(c2[:, :2], axis=0).max() > 0.1


def test_task_parameters_enter_the_observation():
    env = make("Reacher")
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs[24:27], env.task.goal)
    env = make("MoverNoised")
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs[24:27], env.physics.target)


def test_stabilised_reacher_rewards_a_level_forearm():
    env = make("ReacherStabilised", level_coeff=0.5)
    env.reset(seed=0)
    p = env.physics
    q = np.zeros(9)  # hanging upper arm, forearm straight forward: level
    p.set_arm(q)
    p.forward()
    assert env.task.reward_terms(p)["level"] == pytest.approx(0.0, abs=1e-9)
    q[3] = 1.0  # bend the elbow: the forearm tilts
    p.set_arm(q)
    p.forward()
    assert env.task.reward_terms(p)["level"] == pytest.approx(-0.5 * math.sin(1.0), abs=1e-6)


def test_gripper_grid_values_of_the_paper_are_accepted():
    for c2 in (3.0, 4.0):
        for tr in (0.03, 0.06):
            assert make("Gripper", c2=c2, tr=tr).task.reward == GripReward(c2=c2, tr=tr)
    assert make("ReachAndGrip2", tr=0.08, c1=-1, c2=2.1, c3=-4).task.reward.c2 == 2.1


def test_gripper_close_starts_open_the_fingers_around_the_capsule():
    env = make("Gripper", start_distance=[0.0, 0.03], finger_opening=[0.8, 1.0])
    for seed in range(5):
        env.reset(seed=seed)
        p = env.physics
        assert p.hand_to_capsule() <= 0.03 + 0.01  # IK tolerance
        assert 0.8 <= -p.data.qpos[7] <= 1.0 and p.data.qpos[7] == pytest.approx(-p.data.qpos[8])
        assert p.finger_gap() > 0.05 and p.arm_contacts() == 0  # the capsule (5 cm) fits between the tips
    default = make("Gripper")
    default.reset(seed=0)
    assert 0.05 - 0.01 <= default.physics.hand_to_capsule() <= 0.09 + 0.01 and default.physics.data.qpos[7] == 0


def test_gripper_distance_curriculum_starts_close_and_widens_to_the_start_set():
    task = GripperTask(start_distance=(0.0, 0.09), distance_curriculum=100, curriculum_from=0.03)
    assert [task.start_distance_high(e) for e in (0, 50, 100, 10_000)] == pytest.approx([0.03, 0.06, 0.09, 0.09])
    assert GripperTask(start_distance=(0.05, 0.09), distance_curriculum=10).start_distance_high(0) == 0.05  # clipped
    assert GripperTask(start_distance=(0.0, 0.09)).start_distance_high(0) == 0.09  # no curriculum: the paper's set
    env = make("Gripper", start_distance=[0.0, 0.09], distance_curriculum=1000, finger_opening=[0.8, 1.0])
    first = []
    for seed in range(8):  # the first episodes of fresh environments start within the curriculum's 3 cm
        env.reset(seed=seed)
        first.append(env.physics.hand_to_capsule())
        env = make("Gripper", start_distance=[0.0, 0.09], distance_curriculum=1000, finger_opening=[0.8, 1.0])
    assert max(first) <= 0.03 + 0.01  # IK tolerance
    resumed = make("Gripper", start_distance=[0.0, 0.09], distance_curriculum=1000)
    state = resumed.get_state()
    state["episodes"] = 1000  # a restored environment is past the curriculum: starts from the whole set again
    resumed.set_state(state)
    far = []
    for seed in range(20):
        resumed.reset(seed=seed)
        far.append(resumed.physics.hand_to_capsule())
    assert max(far) > 0.05
    with pytest.raises(ValueError, match="distance_curriculum"):
        make("Gripper", distance_curriculum=-1)
    with pytest.raises(ValueError, match="curriculum_from"):
        make("Gripper", curriculum_from=0.0)


@pytest.mark.parametrize(
    "kwargs", [{"start_distance": (0.1, 0.05)}, {"finger_opening": (0.0, 2.0)}, {"start_distance": (0.0,)}]
)
def test_gripper_start_ranges_are_checked(kwargs):
    with pytest.raises(ValueError, match="must be a range"):
        make("Gripper", **kwargs)


def test_optional_gripped_term_pays_only_while_definition_1_holds():
    plain = make("Gripper")
    plain.reset(seed=0)
    assert "reward_gripped" not in plain.step(np.zeros(9))[4]  # the paper's three terms by default
    env = make("Gripper", c4=5.0, tr1=10.0, tr2=10.0)  # thresholds so loose that Definition 1 always holds
    env.reset(seed=0)
    _, r, _, _, info = env.step(np.zeros(9))
    assert info["reward_gripped"] == 5.0
    assert r == pytest.approx(sum(v for k, v in info.items() if k.startswith("reward_")))
    with pytest.raises(ValueError, match="c4"):
        make("Gripper", c4=-1.0)


def test_reach_and_grip_starts_never_fail_when_palm_and_capsule_angles_meet():
    # Palm and capsule angles drawn close together can leave no contact-free start pose; such palm angles are
    # redrawn. These 16 episode streams (those of a 16-environment run with seed 0) met one in training.
    for i in range(16):
        env = make("ReachAndGrip2")
        env.reset(seed=i)
        for _ in range(170):
            env.reset()


def test_grip_reward_measures_the_distance_to_the_centre_or_to_the_axis():
    env = make("Gripper", distance="axis")
    assert env.task.reward == GripReward(distance="axis")
    p = env.physics
    p.forward()
    p.set_capsule(p.hand + np.array([0.0, 0.02, 0.0]) + np.array([0.03, 0.0, 0.0]), yaw=0.0)  # 3 cm along the axis, 2 cm off
    p.forward()
    centre, axis = GripReward(tr=0.025).terms(p), GripReward(tr=0.025, distance="axis").terms(p)
    assert centre["distance"] == pytest.approx(-p.hand_to_capsule()) and centre["bonus"] == 0.0  # d(H, C) = 3.6 cm
    assert axis["distance"] == pytest.approx(-0.02) and axis["bonus"] == 3.0  # 2 cm from the axis: inside tr
    with pytest.raises(ValueError, match="distance must be one of centre, axis"):
        GripReward(distance="surface")


def test_gripper_push_term_charges_knocking_the_capsule_away_not_holding_it():
    env = make("Gripper", push_coeff=10.0)
    env.reset(seed=0)
    p, task = env.physics, env.task
    assert "push" in task.reward_terms(p) and task.reward_terms(p)["push"] == 0.0  # where it lay
    c0 = task.start_capsule.copy()
    p.set_capsule(c0 + np.array([0.03, -0.04, 0.0]))  # knocked 5 cm across the table
    p.forward()
    assert not task.sparse(p) and task.reward_terms(p)["push"] == pytest.approx(-0.5)
    state = env.get_state()
    env.reset(seed=1)
    env.set_state(state)
    assert np.array_equal(env.task.start_capsule, c0)  # the episode's start travels with the state (exact resume)
    held = make("Gripper", push_coeff=10.0, tr1=1.0, tr2=1.0)  # thresholds so wide that Definition 1 always holds
    held.reset(seed=0)
    held.physics.set_capsule(held.task.start_capsule + np.array([0.03, -0.04, 0.0]))
    held.physics.forward()
    assert held.task.reward_terms(held.physics)["push"] == 0.0
    assert "push" not in make("Gripper").task.reward_terms(make("Gripper").physics)  # default: the paper's terms
    with pytest.raises(ValueError, match="push_coeff"):
        make("Gripper", push_coeff=-1.0)


def test_gripper_can_observe_the_capsules_pose():
    # The paper's 24 numbers hold C but not how the capsule lies: a pushed capsule's yaw is invisible. With
    # observe_capsule, 6 numbers follow: (cos 2 yaw, sin 2 yaw, a_z^2) of its axis, then its linear velocity.
    plain, seen = make("Gripper"), make("Gripper", observe_capsule=True)
    assert plain.observation_space.shape == (24,) and seen.observation_space.shape == (30,)
    obs, _ = seen.reset(seed=3)
    c = seen.unwrapped.physics.capsule
    yaw = math.atan2(c[1], c[0] + 0.15) + math.pi / 2  # lies tangent to the start circle around the base axis
    np.testing.assert_allclose(obs[24:27], [math.cos(2 * yaw), math.sin(2 * yaw), 0.0], atol=1e-9)
    np.testing.assert_allclose(obs[27:30], 0.0, atol=1e-9)  # at rest
    seen.unwrapped.physics.data.qvel[9:12] = [0.1, -0.2, 0.3]
    np.testing.assert_allclose(seen.unwrapped.physics.capsule_pose_features(np.zeros(6))[3:], [0.1, -0.2, 0.3])
    with pytest.raises(ValueError, match="observe_capsule must be true or false"):
        make("Gripper", observe_capsule="yes")


def test_gripper_can_observe_the_claw_relative_to_the_capsule():
    # observe_claw appends 15 numbers after the capsule's pose: H, FT1 and FT2 less C, then the palm's x and y axes.
    env = make("Gripper", observe_capsule=True, observe_claw=True)
    assert env.observation_space.shape == (45,) and env.unwrapped.task.observed_features == ("capsule_pose", "claw_pose")
    obs, _ = env.reset(seed=3)
    p = env.unwrapped.physics
    c, (ft1, ft2) = p.capsule, p.fingertips
    palm = p.data.xmat[p.model.body("claw").id].reshape(3, 3)
    np.testing.assert_allclose(obs[30:], np.concatenate([p.hand - c, ft1 - c, ft2 - c, palm[:, 0], palm[:, 1]]), atol=1e-12)
    assert np.linalg.norm(obs[30:33]) == pytest.approx(p.hand_to_capsule(), abs=1e-12)
    assert np.linalg.norm(obs[33:36] - obs[36:39]) == pytest.approx(p.finger_gap(), abs=1e-12)
    np.testing.assert_allclose(np.linalg.norm(obs[39:42]), 1.0, atol=1e-12)  # unit axes, at right angles
    assert abs(obs[39:42] @ obs[42:45]) < 1e-12
    only_claw = make("Gripper", observe_claw=True)
    assert only_claw.observation_space.shape == (39,) and only_claw.unwrapped.task.observed_features == ("claw_pose",)
    with pytest.raises(ValueError, match="observe_claw must be true or false"):
        make("Gripper", observe_claw=1)


def test_gripper_can_observe_each_arm_bodys_distance_to_the_capsule():
    # observe_clearance appends 5 numbers, last: for the upper arm, forearm, palm and the two fingers, the smallest
    # mj_geomDistance of the body's geoms to the capsule, cut off at 5 cm.
    env = make("Gripper", observe_claw=True, observe_clearance=True, start_distance=(0.0, 0.02), finger_opening=(0.5, 1.0))
    assert env.observation_space.shape == (44,) and env.unwrapped.task.observed_features == ("claw_pose", "arm_clearance")
    p = env.unwrapped.physics
    m, cap = p.model, p.model.geom("object").id
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        want = [min(mujoco.mj_geomDistance(m, p.data, g, cap, 0.05, None) for g in range(m.ngeom)
                    if m.body(int(m.geom_bodyid[g])).name == body) for body in CLEARANCE_BODIES]  # fmt: skip
        np.testing.assert_array_equal(obs[39:], want)
        assert obs[39:].min() == p.arm_clearance()  # the expert's escape reads the smallest of them
        assert obs[41:].max() < 0.05 and obs[39] == 0.05  # the claw within 2 cm of the capsule; the upper arm far
    # The capsule moved a metre away: every body reads the cut-off.
    qpos = p.data.qpos.copy()
    qpos[p._obj_qpos] += 1.0
    p.set_state_vectors(qpos, p.data.qvel.copy())
    p.forward()
    np.testing.assert_array_equal(p.feature("arm_clearance"), np.full(5, 0.05))
    with pytest.raises(ValueError, match="observe_clearance must be true or false"):
        make("Gripper", observe_clearance="no")
