"""BatchedArmEnv against the reference VectorEnv (N ordinary ArmEnvs): the same seed gives the same episodes.

The loop backend keeps every world's full MuJoCo state and computes the tasks' numbers in their own floating-point
order, so its episodes are compared bit for bit. The rollout backend restarts the constraint solver's warm start at
every control step (``mujoco.rollout`` does not return it), so it agrees to the solver's tolerance: 1e-6 here
(measured: at most 1e-7 over these episodes), with every flag (truncation, success) exact.
"""

from __future__ import annotations

import json
import math

import mujoco
import numpy as np
import pytest

from hrlp.arm import PhysicsConfig, make
from hrlp.arm.batched import (
    BatchedArmEnv,
    Measurements,
    capsule_pose_rows,
    claw_closure_rows,
    claw_pose_rows,
    dist_rows,
    hand_to_capsule_axis_rows,
    make_batched,
    math_dist_rows,
    measured_model,
)
from hrlp.arm.physics import ArmPhysics, load_model
from hrlp.arm.tasks import GripperTask, GripReward, ReachAndGripTask, Task
from hrlp.envs.vector import SerialVectorEnv, VectorEnv, VectorStep, check_actions, info_arrays

ROLLOUT_ATOL = 1e-6
#: Success thresholds loose enough that random torques reach them, so the success flags are compared both ways.
LOOSE = {"Reacher": {"success_tol": 0.3}, "Gripper": {"tr1": 0.15, "tr2": 0.03}, "ReachAndGrip2": {"tr1": 0.3, "tr2": 0.03}}
FIELDS = ("obs", "next_obs", "rewards", "discount", "tau", "terminated", "truncated", "success")


# --- small pure functions, known answers ---------------------------------------------------------------------------


def _meas(n: int = 1, **rows: list[float]) -> Measurements:
    z = np.zeros((n, 3))
    arrays = {k: np.atleast_2d(np.asarray(v, dtype=float)) for k, v in rows.items()}
    fields = ("capsule_vel", "hand", "tip_right", "tip_left", "capsule", "capsule_axis", "forearm_axis", "claw_x", "claw_y")
    fields += ("target",)
    return Measurements(qpos=arrays.get("qpos", np.zeros((n, 9))), qvel=np.zeros((n, 9)),
                        **{f: arrays.get(f, z) for f in fields}, capsule_half_length=0.035)  # fmt: skip


def test_distances_match_the_scalar_formulas_bit_for_bit():
    a, b = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 2.0]]), np.array([[3.0, 4.0, 12.0], [1.0, 2.0, 2.0]])
    np.testing.assert_array_equal(dist_rows(a, b), [13.0, 0.0])
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(200, 3)), rng.normal(size=(200, 3))
    # math.dist rounds correctly where the plain formula may be one ulp off: each task keeps the one it uses.
    assert math_dist_rows(a, b).tolist() == [math.dist(x, y) for x, y in zip(a.tolist(), b.tolist(), strict=True)]
    plain = [math.sqrt(sum((x - y) ** 2 for x, y in zip(p, q, strict=True))) for p, q in zip(a, b, strict=True)]
    np.testing.assert_allclose(dist_rows(a, b), plain, rtol=1e-15)


def test_hand_to_capsule_axis_known_answers():
    # Capsule at the origin along x (half-length 0.035): beside the segment the distance is the offset; past its end
    # the distance is to the end point (0.035, 0, 0).
    m = _meas(2, hand=[[0.01, 0.02, 0.0], [0.1, 0.0, 0.03]], capsule_axis=[[1.0, 0, 0], [1.0, 0, 0]])
    np.testing.assert_allclose(hand_to_capsule_axis_rows(m), [0.02, math.hypot(0.065, 0.03)], rtol=1e-14)


def test_claw_closure_and_capsule_pose_known_answers():
    q = np.zeros((3, 9))
    q[0, 7:], q[1, 7:], q[2, 7:] = (0.2, -0.1), (-0.3, 0.3), (0.1, 0.1)  # closing + asymmetric; open symmetric; mixed
    np.testing.assert_allclose(claw_closure_rows(q), [0.2 + 0.1 + 0.1, 0.0, 0.1 + 0.0 + 0.2], rtol=1e-14)
    theta = 0.4
    m = _meas(1, capsule_axis=[math.cos(theta), math.sin(theta), 0.0])
    np.testing.assert_allclose(capsule_pose_rows(m)[0], [math.cos(2 * theta), math.sin(2 * theta), 0, 0, 0, 0], atol=1e-15)


def test_claw_pose_known_answer():
    m = _meas(1, hand=[1.0, 2.0, 3.0], tip_right=[1.5, 2.0, 3.0], tip_left=[0.5, 2.0, 3.0], capsule=[1.0, 1.0, 1.0],
              claw_x=[0.0, 0.0, -1.0], claw_y=[0.0, 1.0, 0.0])  # fmt: skip
    np.testing.assert_array_equal(claw_pose_rows(m)[0], [0, 1, 2, 0.5, 1, 2, -0.5, 1, 2, 0, 0, -1, 0, 1, 0])


def test_the_clearance_sensors_are_added_only_to_worlds_that_read_them():
    # Five distance sensors (one number each) after the eight 3-number ones, only where the task or a skill reads them.
    assert measured_model(PhysicsConfig()).nsensordata == 24
    assert measured_model(PhysicsConfig(), clearance=True).nsensordata == 24 + 5
    plain, seeing = make_batched("Gripper", 2), make_batched("Gripper", 2, observe_clearance=True)
    extra = make_batched("Reacher", 2, features=("arm_clearance",))
    assert "arm_clearance" not in plain.measured_features and plain.model.nsensordata == 24
    assert "arm_clearance" in seeing.measured_features and "arm_clearance" in extra.measured_features
    extra.reset(seed=0)
    assert extra.features("arm_clearance").shape == (2, 5)
    plain.reset(seed=0)
    with pytest.raises(ValueError, match="needs the worlds' distance sensors"):
        plain.features("arm_clearance")


def test_info_arrays_and_action_checks():
    out = info_arrays([{"a": 1.0, "b": True, "success": True, "w": {"x": 1}}, {"a": 2.0}])
    assert set(out) == {"a", "b", "physics_unstable"}
    np.testing.assert_array_equal(out["a"], [1.0, 2.0])
    assert out["b"].dtype == bool and out["b"].tolist() == [True, False]
    assert out["physics_unstable"].tolist() == [False, False]
    huge = np.full((2, 9), 1e308)  # finite, though their sum overflows
    assert check_actions(huge, 2, 9, "x").shape == (2, 9)
    step = VectorStep(*(np.zeros(2),) * 5, np.array([True, False]), np.array([False, True]), np.zeros(2, bool), {}, 0.0)
    assert step.done.tolist() == [True, True]


def test_measured_model_steps_as_the_arm_model_and_its_sensors_read_what_armphysics_reads():
    config = PhysicsConfig()
    plain, measured = load_model(config), measured_model(config)
    p = ArmPhysics(config)
    p.set_arm(np.full(9, 0.3))
    p.forward()
    d = mujoco.MjData(measured)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    s = np.empty(mujoco.mj_stateSize(plain, spec))
    mujoco.mj_getState(plain, p.data, s, spec)
    mujoco.mj_setState(measured, d, s, spec)
    rng = np.random.default_rng(0)
    for _ in range(40):
        u = rng.uniform(-1, 1, 9)
        p.step(u)
        d.ctrl[:] = u
        mujoco.mj_step(measured, d, config.substeps)
        np.testing.assert_array_equal(d.qpos, p.data.qpos)
        np.testing.assert_array_equal(d.qvel, p.data.qvel)
        ax = p.data.geom_xmat[measured.geom("object").id].reshape(3, 3)[:, 2]
        palm = p.data.xmat[measured.body("claw").id].reshape(3, 3)
        expected = [p.hand, *p.fingertips, p.capsule, ax, p.forearm_axis, palm[:, 0], palm[:, 1]]
        np.testing.assert_array_equal(d.sensordata, np.concatenate(expected))


# --- the same episodes -----------------------------------------------------------------------------------------------


def _run(env: VectorEnv, actions: np.ndarray, seed: int | None = 11) -> tuple[np.ndarray, list[VectorStep]]:
    obs = env.reset(seed=seed) if seed is not None else np.empty(0)
    return obs, [env.step(a) for a in actions]


def _compare(ref: list[VectorStep], got: list[VectorStep], atol: float) -> None:
    for t, (r, g) in enumerate(zip(ref, got, strict=True)):
        for f in FIELDS:
            x, y = getattr(r, f), getattr(g, f)
            if atol == 0 or x.dtype == bool:
                np.testing.assert_array_equal(y, x, err_msg=f"{f} at step {t}")
            else:
                np.testing.assert_allclose(y, x, rtol=0, atol=atol, err_msg=f"{f} at step {t}")
        assert set(g.infos) == set(r.infos), f"info keys at step {t}"
        for k, x in r.infos.items():
            if atol == 0 or x.dtype == bool:
                np.testing.assert_array_equal(g.infos[k], x, err_msg=f"infos[{k!r}] at step {t}")
            else:
                np.testing.assert_allclose(g.infos[k], x, rtol=0, atol=atol, err_msg=f"infos[{k!r}] at step {t}")


def _actions(steps: int, n: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, size=(steps, n, 9))


@pytest.mark.parametrize("backend", ["loop", "rollout"])
@pytest.mark.parametrize("name", ["Reacher", "Gripper", "ReachAndGrip2"])
def test_same_seed_same_episodes_as_the_reference(name, backend):
    n, steps, episode = 3, 300, 100  # three episodes per world: two resets inside the run
    actions = _actions(steps, n)
    kw = LOOSE[name]
    ref_obs, ref = _run(SerialVectorEnv([make(name, episode_steps=episode, **kw) for _ in range(n)]), actions)
    obs, got = _run(make_batched(name, n, episode_steps=episode, backend=backend, **kw), actions)
    np.testing.assert_array_equal(obs, ref_obs)
    assert sum(int(s.truncated.sum()) for s in ref) == 3 * n
    success = np.array([s.success for s in ref])
    assert success.any() and not success.all()  # the flags are compared where they differ between worlds and steps
    _compare(ref, got, 0.0 if backend == "loop" else ROLLOUT_ATOL)


@pytest.mark.parametrize(
    "name", ["ReacherStabilised", "Reacher3D", "ReacherHandover", "MoverPlain", "MoverNoised", "ReachAndGrip1", "ReachAndMove"]
)
def test_every_other_registered_arm_task_gives_the_same_episodes_bit_for_bit(name):
    n, steps, episode = 2, 80, 30
    actions = _actions(steps, n, seed=2)
    _, ref = _run(SerialVectorEnv([make(name, episode_steps=episode) for _ in range(n)]), actions)
    _, got = _run(make_batched(name, n, episode_steps=episode, backend="loop"), actions)
    _compare(ref, got, 0.0)


@pytest.mark.parametrize(
    "task",
    [
        GripperTask(reward=GripReward(c4=1.0, distance="axis"), push_coeff=2.0, observe_capsule=True),
        GripperTask(observe_capsule=True, observe_claw=True),
        GripperTask(observe_claw=True),
        GripperTask(observe_clearance=True, start_distance=(0.0, 0.03), finger_opening=(0.0, 1.0)),
        ReachAndGripTask(experiment=2, reward=GripReward(c4=0.5), curriculum_alpha=0.05),
    ],
    ids=[
        "gripper-axis-c4-push-observed",
        "gripper-capsule-and-claw-observed",
        "gripper-claw-observed",
        "gripper-clearance-observed-close-starts",
        "reach-and-grip-curriculum-c4",
    ],
)
def test_task_options_give_the_same_episodes_bit_for_bit(task: Task):
    n, steps, episode = 2, 120, 40
    actions = _actions(steps, n, seed=3)
    _, ref = _run(SerialVectorEnv([_arm_env(task, episode) for _ in range(n)]), actions)
    _, got = _run(BatchedArmEnv(task, n, episode_steps=episode, backend="loop"), actions)
    _compare(ref, got, 0.0)


def _arm_env(task: Task, episode: int):
    import copy

    from hrlp.arm.env import ArmEnv

    return ArmEnv(copy.deepcopy(task), episode_steps=episode)


def test_rollout_threads_do_not_change_the_numbers():
    actions = _actions(60, 5, seed=4)
    _, one = _run(make_batched("Gripper", 5, episode_steps=25, threads=1), actions)
    _, two = _run(make_batched("Gripper", 5, episode_steps=25, threads=2), actions)
    _compare(one, two, 0.0)


# --- exact resume, across implementations -----------------------------------------------------------------------------


@pytest.mark.parametrize("backend", ["loop", "rollout"])
def test_states_move_between_the_reference_and_the_batched_env(backend):
    name, n, episode = "MoverPlain", 3, 50  # tracked sums and maxima, a target in the observation
    first, rest = _actions(70, n, seed=5), _actions(60, n, seed=6)
    ref = SerialVectorEnv([make(name, episode_steps=episode) for _ in range(n)])
    _run(ref, first)
    saved = json.loads(json.dumps(ref.get_state()))
    batched = make_batched(name, n, episode_steps=episode, backend=backend)
    batched.set_state(saved)
    _, cont_ref = _run(ref, rest, seed=None)
    _, cont = _run(batched, rest, seed=None)
    _compare(cont_ref, cont, 0.0 if backend == "loop" else ROLLOUT_ATOL)
    # ...and back: the batched env's state continues in ArmEnvs as in itself.
    back = SerialVectorEnv([make(name, episode_steps=episode) for _ in range(n)])
    back.set_state(json.loads(json.dumps(batched.get_state())))
    _, a = _run(back, rest[:20], seed=None)
    _, b = _run(batched, rest[:20], seed=None)
    _compare(a, b, 0.0 if backend == "loop" else ROLLOUT_ATOL)


@pytest.mark.parametrize("backend", ["loop", "rollout"])
def test_exact_resume_of_the_batched_env(backend):
    actions = _actions(90, 3, seed=7)
    whole = make_batched("ReachAndGrip2", 3, episode_steps=40, backend=backend)
    _, straight = _run(whole, actions)
    part = make_batched("ReachAndGrip2", 3, episode_steps=40, backend=backend)
    _run(part, actions[:50])
    resumed = make_batched("ReachAndGrip2", 3, episode_steps=40, backend=backend)
    resumed.set_state(json.loads(json.dumps(part.get_state())))
    _, after = _run(resumed, actions[50:], seed=None)
    _compare(straight[50:], after, 0.0)


# --- physics instability ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("backend", ["loop", "rollout"])
@pytest.mark.parametrize(
    ("when", "substeps"), [(0, 5), (7, 5), (7, 1)], ids=["first-step", "mid-episode", "mid-episode-1-substep"]
)
def test_a_physics_blow_up_truncates_that_world_as_armenv_does(backend, when, substeps, caplog):
    name, n, physics = "MoverPlain", 3, PhysicsConfig(substeps=substeps)
    ref = SerialVectorEnv([make(name, physics=physics) for _ in range(n)])
    _run(ref, _actions(when, n, seed=8))
    state = ref.get_state()
    state["envs"][1]["physics"][1 + 16] = 1e12  # world 1's first joint velocity (after time and 16 qpos): bad qvel
    batched = make_batched(name, n, backend=backend, physics=physics)
    ref.set_state(state)
    batched.set_state(json.loads(json.dumps(state)))
    actions = _actions(3, n, seed=9)
    _, a = _run(ref, actions, seed=None)
    _, b = _run(batched, actions, seed=None)
    assert a[0].infos["physics_unstable"].tolist() == [False, True, False]
    assert a[0].truncated.tolist() == [False, True, False] and a[0].rewards[1] == 0.0
    np.testing.assert_array_equal(a[0].next_obs[1], state["envs"][1]["obs"])  # the last good observation
    assert np.isnan(b[0].infos["target_dist_sum"][1]) and np.isnan(a[0].infos["target_dist_sum"][1])
    _compare(a, b, 0.0 if backend == "loop" else ROLLOUT_ATOL)


# --- bad input ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("backend", ["loop", "rollout"])
def test_bad_actions_give_one_line_errors_naming_the_problem(backend):
    env = make_batched("Reacher", 3, backend=backend)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros((3, 9)))
    env.reset(seed=0)
    bad = np.zeros((3, 9))
    bad[1, 4] = np.nan
    cases = [(np.zeros((3, 8)), r"shape \(3, 9\).*got \(3, 8\)"), (np.zeros(9), r"shape \(3, 9\)"),
             (bad, r"NaN or inf \(environment 1"), (np.full((3, 9), np.inf), r"NaN or inf \(environment 0")]  # fmt: skip
    for actions, message in cases:
        with pytest.raises(ValueError, match=message) as e:
            env.step(actions)
        assert "\n" not in str(e.value) and "Reacher" in str(e.value)
    ref = SerialVectorEnv([make("Reacher") for _ in range(3)])
    ref.reset(seed=0)
    with pytest.raises(ValueError, match=r"NaN or inf \(environment 1"):
        ref.step(bad)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n": 0}, "n must be a positive integer, got 0"),
        ({"n": -2}, "n must be a positive integer"),
        ({"n": 2.0}, "n must be a positive integer"),
        ({"n": True}, "n must be a positive integer"),
        ({"n": 2, "backend": "gpu"}, "backend must be one of rollout, loop"),
        ({"n": 2, "threads": 0}, "threads must be a positive integer"),
        ({"n": 2, "backend": "loop", "threads": 2}, "threads must be 1"),
        ({"n": 2, "gamma": 1.5}, r"gamma must be a number in \[0, 1\]"),
        ({"n": 2, "episode_steps": 0}, "episode_steps must be a positive integer"),
        ({"n": 2, "bogus": 1}, "unknown argument"),
    ],
)
def test_bad_settings_give_one_line_errors(kwargs, message):
    n = kwargs.pop("n")
    with pytest.raises(ValueError, match=message) as e:
        make_batched("ReachAndGrip2", n, **kwargs)
    assert "\n" not in str(e.value)


def test_unsupported_tasks_and_names_are_refused():
    class Custom(ReachAndGripTask):  # a subclass may change the formulas: not assumed vectorisable
        pass

    with pytest.raises(ValueError, match="no vectorised version of Custom"):
        BatchedArmEnv(Custom(), 2)
    with pytest.raises(ValueError, match="unknown task 'Nope'"):
        make_batched("Nope", 2)
    with pytest.raises(ValueError, match="n must be a positive integer"):
        SerialVectorEnv([])


def test_both_implement_the_protocol_and_report_flat_discounts():
    env = make_batched("Reacher", 2, gamma=0.9)
    ref = SerialVectorEnv([make("Reacher") for _ in range(2)], gamma=0.9)
    assert isinstance(env, VectorEnv) and isinstance(ref, VectorEnv)
    assert (env.num_envs, env.obs_dim, env.act_dim) == (ref.num_envs, ref.obs_dim, ref.act_dim) == (2, 27, 9)
    env.reset(seed=0)
    step = env.step(np.zeros((2, 9)))
    assert step.discount.tolist() == [0.9, 0.9] and step.tau.tolist() == [1, 1] and step.physics_seconds > 0
    env.close()
