"""The scripted grasp expert: it grips from close starts, and its action is a function of the state alone."""

import mujoco
import numpy as np
import pytest

from hrlp.arm.env import ArmEnv
from hrlp.arm.research.scripted import ScriptedGrasp
from hrlp.arm.tasks import GripperTask
from hrlp.experiments.presets import GRIPPER_START


def _env() -> ArmEnv:
    return ArmEnv(GripperTask(**GRIPPER_START), episode_steps=100)


# 44, 111 and 149 start with the claw low beside the capsule, its arm far from the grasp's configuration: a move over
# the capsule that turned the palm dipped the fingers into it, and rising and moving took turns until the episode ended.
@pytest.mark.parametrize("seed", [2, 4, 10, 44, 111, 149])
def test_expert_grips_from_fixed_close_starts(seed):
    env = _env()
    expert = ScriptedGrasp(env.physics)
    env.reset(seed=seed)
    c0 = env.physics.capsule.copy()
    info = {"success": False}
    for _ in range(100):
        _, _, _, trunc, info = env.step(expert.act())
        if info["success"] or trunc:
            break
    assert info["success"], f"seed {seed}: no grip within 100 steps"
    # The capsule is held, not knocked away: between the tips (a closed claw with nothing in it ends nearer than 1 cm)
    # and within 3 cm of where it lay.
    p = env.physics
    assert 0.01 < p.finger_gap() < 0.03
    assert np.hypot(*(p.capsule[:2] - c0[:2])) < 0.03


def test_act_is_a_pure_function_of_the_state():
    env = _env()
    expert = ScriptedGrasp(env.physics)
    env.reset(seed=3)
    for _ in range(15):
        env.step(expert.act())
    state = env.get_state()
    qpos = env.physics.data.qpos.copy()
    a = expert.act()
    assert np.array_equal(env.physics.data.qpos, qpos)  # acting reads the state, never changes it
    assert np.array_equal(expert.act(), a)
    # Elsewhere, then back: the same state gets the same action, from this controller and from a fresh one.
    for _ in range(10):
        env.step(expert.act())
    assert not np.allclose(expert.act(), a)
    env.set_state(state)
    assert np.array_equal(expert.act(), a)
    assert np.array_equal(ScriptedGrasp(env.physics).act(), a)


def test_action_shape_and_range_on_own_starts_and_odd_states():
    env = _env()
    expert = ScriptedGrasp(env.physics)
    p = env.physics
    for seed in range(3):
        env.reset(seed=seed)
        for _ in range(5):
            a = expert.act()
            assert a.shape == (9,) and np.isfinite(a).all() and np.abs(a).max() <= 1.0
            env.step(a)
    # A capsule out of reach: the controller waits (arm held still, fingers open) rather than planning.
    p.set_capsule(np.array([0.5, 0.5, 0.025]))
    p.forward()
    assert expert.situation()["phase"] == "wait"
    a = expert.act()
    assert a.shape == (9,) and np.abs(a).max() <= 1.0


def test_imitation_writes_a_run_that_eval_reads_and_trpo_fine_tunes(tmp_path):
    import dataclasses

    from hrlp.arm.research.imitate import ImitationConfig, imitate
    from hrlp.config import TrainConfig
    from hrlp.evaluate import evaluate_run
    from hrlp.experiments.presets import GRIPPER_START
    from hrlp.train import load_trained, resolve_config, train

    cfg = TrainConfig(task="Gripper", steps=200, batch_steps=100, num_envs=2, episode_steps=20, init_log_std=-1.0,
                      task_kwargs={**GRIPPER_START, "c3": -8, "c4": 10})  # fmt: skip
    summary = imitate(cfg, tmp_path / "run", ImitationConfig(expert_episodes=2, dagger_rounds=1, dagger_episodes=1,
                                                             epochs=30, lr_decay=True), log=lambda line: None)  # fmt: skip
    first, last = summary["rounds"]
    assert first["acting"] == "expert" and first["states"] == 40 and last["states"] == 60  # 20 steps per episode
    assert first["fit_mse"] < 0.1  # the student's mean follows the expert's torques on the states it saw
    trained = load_trained(tmp_path / "run")
    assert trained.meta["iteration"] == 0 and trained.config == resolve_config(cfg)  # the workers it used
    assert evaluate_run(tmp_path / "run", episodes=1).episodes == 1
    rows = list(train(dataclasses.replace(cfg, steps=100), tmp_path / "run", resume=True))  # TRPO from the student
    assert len(rows) == 1 and rows[0]["iteration"] == 1
    with pytest.raises(ValueError, match="already holds a run"):
        imitate(cfg, tmp_path / "run", ImitationConfig(expert_episodes=1, dagger_rounds=0), log=lambda line: None)
    with pytest.raises(ValueError, match="flat Gripper"):
        imitate(dataclasses.replace(cfg, task="Reacher", task_kwargs={}), tmp_path / "other")
    with pytest.raises(ValueError, match="epochs"):
        ImitationConfig(epochs=0)
    with pytest.raises(ValueError, match="lr_decay must be true or false"):
        ImitationConfig(lr_decay=1)  # type: ignore[arg-type]


def _gripper_env(steps: int = 15):
    from hrlp.arm.registry import make
    from hrlp.experiments.presets import GRIPPER_START

    return make("Gripper", episode_steps=steps, **GRIPPER_START).unwrapped


def test_collect_noise_moves_the_states_but_not_the_labels_and_is_reproducible():
    from hrlp.arm.research.imitate import collect

    env = _gripper_env()
    expert = ScriptedGrasp(env.physics)
    clean_obs, clean_act, _ = collect(env, expert, 1, seed=7)
    noisy_obs, noisy_act, _ = collect(env, expert, 1, seed=7, noise=0.3)
    again_obs, again_act, _ = collect(env, expert, 1, seed=7, noise=0.3)
    np.testing.assert_array_equal(noisy_obs, again_obs)  # the noise comes from a generator seeded by the call
    np.testing.assert_array_equal(noisy_act, again_act)
    np.testing.assert_array_equal(clean_obs[0], noisy_obs[0])  # same start, same clean label there
    np.testing.assert_array_equal(clean_act[0], noisy_act[0])
    assert np.abs(clean_obs[-1] - noisy_obs[-1]).max() > 1e-3  # the executed actions were perturbed
    # each label is the expert's noise-free action at the state it labels: relabelling a visited state agrees
    env.reset(seed=7)
    np.testing.assert_allclose(np.clip(expert.act(), -1, 1), noisy_act[0])


def test_collect_with_the_expert_always_mixed_in_is_the_expert_rollout():
    from hrlp.arm.research.imitate import collect

    env = _gripper_env()
    expert = ScriptedGrasp(env.physics)
    obs, act, success = collect(env, expert, 2, seed=3)
    mixed_obs, mixed_act, mixed_success = collect(env, expert, 2, seed=3, student=lambda o: np.zeros(9), expert_prob=1.0)
    np.testing.assert_array_equal(obs, mixed_obs)
    np.testing.assert_array_equal(act, mixed_act)
    assert success == mixed_success
    student_obs, _, _ = collect(env, expert, 2, seed=3, student=lambda o: np.zeros(9))  # the student alone: other states
    assert np.abs(student_obs[-1] - obs[-1]).max() > 1e-3


def test_imitation_keeps_the_best_evaluated_round(tmp_path):
    from hrlp.arm.research.imitate import ImitationConfig, greedy_success, imitate
    from hrlp.config import TrainConfig
    from hrlp.experiments.presets import GRIPPER_START
    from hrlp.train import load_trained

    cfg = TrainConfig(task="Gripper", steps=200, batch_steps=100, num_envs=2, episode_steps=20, task_kwargs=GRIPPER_START)
    icfg = ImitationConfig(expert_episodes=1, noisy_expert_episodes=1, expert_noise=0.3, dagger_rounds=2, dagger_episodes=1,
                           epochs=5, beta=0.5, eval_episodes=2)  # fmt: skip
    summary = imitate(cfg, tmp_path / "run", icfg, log=lambda line: None)
    scores = [r["student_success"] for r in summary["rounds"]]
    assert len(scores) == 3 and all(s in (0.0, 0.5, 1.0) for s in scores)
    assert summary["rounds"][0]["states"] == 40  # the clean and the noisy expert episode, 20 steps each
    assert summary["kept_round"] == max(range(3), key=lambda r: (scores[r], r))  # the best, the later on ties
    assert summary["rounds"][1]["acting"] == "student, expert w.p. 0.5"
    # the written student is the kept round's: alone on the same seeds it scores what that round scored
    trained = load_trained(tmp_path / "run")
    env = _gripper_env(20)
    seed = 1_000_000 + 10_000 * cfg.seed - 10_000
    assert greedy_success(env, lambda o: trained.act_rows(o[None])[0], 2, seed) == scores[summary["kept_round"]]
    with pytest.raises(ValueError, match="beta"):
        ImitationConfig(beta=1.5)
    with pytest.raises(ValueError, match="expert_noise"):
        ImitationConfig(expert_noise=-0.1)
    with pytest.raises(ValueError, match="needs expert_noise"):
        ImitationConfig(noisy_expert_episodes=5)


def test_a_capsule_at_rest_gets_one_plan_whatever_the_last_digits_of_its_height():
    env = _env()
    expert = ScriptedGrasp(env.physics)
    p = env.physics
    env.reset(seed=0)
    c = p.capsule.copy()
    keys = set()
    for dz in (-2e-4, 0.0, 2e-4):  # a capsule settling on the table: its centre at its radius, give or take
        p.set_capsule(np.array([c[0], c[1], 0.025 + dz]))
        p.forward()
        expert.plan()
        keys.add(expert._key())
    assert len(keys) == 1


def test_the_first_version_stays_reachable_and_is_what_gripper_imitated_was_imitated_from():
    from hrlp.arm.research.imitate import ImitationConfig
    from hrlp.arm.research.scripted import ScriptedGraspConfig
    from hrlp.experiments.presets import IMITATED_GRIPPER

    def grips(cfg: ScriptedGraspConfig, seed: int) -> bool:
        env = _env()
        expert = ScriptedGrasp(env.physics, cfg)
        env.reset(seed=seed)
        for _ in range(100):
            _, _, _, trunc, info = env.step(expert.act())
            if info["success"] or trunc:
                return bool(info["success"])
        return False

    # From start 149 the first version's rising and moving over take turns for the whole episode (measured: it never
    # grips); the current one grips.
    assert grips(ScriptedGraspConfig(), 149) and not grips(ScriptedGraspConfig(keep_clear=False), 149)
    assert IMITATED_GRIPPER.expert_keep_clear is False  # the shipped gripper-imitated's recipe keeps its expert
    assert ImitationConfig().expert_keep_clear is True
    with pytest.raises(ValueError, match="expert_keep_clear"):
        ImitationConfig(expert_keep_clear="yes")  # type: ignore[arg-type]


# Starts 10,042 and 10,085 (gripper_handover.py's own-start seeds) put a finger within a centimetre of the capsule:
# the default expert's first moves push the capsule away; with the escape the hand goes up first and then grips.
@pytest.mark.parametrize("seed", [10_042, 10_085])
def test_the_escape_takes_the_claw_out_of_a_tight_start_and_grips(seed):
    from hrlp.arm.research.scripted import ScriptedGraspConfig

    def episode(cfg: ScriptedGraspConfig) -> tuple[bool, float, float]:
        env = _env()
        expert = ScriptedGrasp(env.physics, cfg)
        env.reset(seed=seed)
        clearance, c0 = expert.arm_clearance(), env.physics.capsule.copy()
        won = False
        for _ in range(100):
            _, _, _, trunc, info = env.step(expert.act())
            won |= bool(info["success"])
            if won or trunc:
                break
        return won, clearance, float(np.hypot(*(env.physics.capsule[:2] - c0[:2])))

    won, clearance, pushed = episode(ScriptedGraspConfig())
    assert clearance < 0.01 and not won and pushed > 0.03
    won, _, pushed = episode(ScriptedGraspConfig(escape_clearance=0.01))
    assert won and pushed < 0.03


def test_arm_clearance_is_the_nearest_arm_geom_distance():
    env = _env()
    expert = ScriptedGrasp(env.physics)
    env.reset(seed=10_042)
    p = env.physics
    m, d = p.model, p.data
    want = min(mujoco.mj_geomDistance(m, d, g, m.geom("object").id, 0.05, None) for g in range(1, 12))
    assert expert.arm_clearance() == pytest.approx(want)
    # Far from the capsule (the arm at its zero pose) the distance is capped at 5 cm.
    d.qpos[:9] = 0
    mujoco.mj_forward(m, d)
    assert expert.arm_clearance() == pytest.approx(0.05)


def test_imitation_escape_clearance_is_validated_and_off_in_the_shipped_recipes():
    from hrlp.arm.research.imitate import ImitationConfig
    from hrlp.arm.research.scripted import ScriptedGraspConfig
    from hrlp.experiments.presets import CLAW_GRIPPER, IMITATED_GRIPPER

    assert ScriptedGraspConfig().escape_clearance == 0.0
    assert CLAW_GRIPPER.expert_escape_clearance == 0.0 and IMITATED_GRIPPER.expert_escape_clearance == 0.0
    for bad in (-0.01, float("nan"), 0.5, True, "0.01"):
        with pytest.raises(ValueError, match="expert_escape_clearance"):
            ImitationConfig(expert_escape_clearance=bad)  # type: ignore[arg-type]
    for name, bad in (("escape_clearance", -0.01), ("escape_step", float("inf")), ("escape_opening", 2.0)):
        with pytest.raises(ValueError, match=f"ScriptedGraspConfig.{name}"):
            ScriptedGraspConfig(**{name: bad})
