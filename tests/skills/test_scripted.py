"""The scripted grasp expert: it grips from close starts, and its action is a function of the state alone."""

import numpy as np
import pytest

from hrlp.envs.arm_env import ArmEnv
from hrlp.envs.tasks import GripperTask
from hrlp.experiments.presets import GRIPPER_START
from hrlp.skills.scripted import ScriptedGrasp


def _env() -> ArmEnv:
    return ArmEnv(GripperTask(**GRIPPER_START), episode_steps=100)


@pytest.mark.parametrize("seed", [2, 4, 10])
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

    from hrlp.config import TrainConfig
    from hrlp.evaluate import evaluate_run
    from hrlp.experiments.presets import GRIPPER_START
    from hrlp.skills.imitate import ImitationConfig, imitate
    from hrlp.train import load_trained, train

    cfg = TrainConfig(task="Gripper", steps=200, batch_steps=100, num_envs=2, episode_steps=20, init_log_std=-1.0,
                      task_kwargs={**GRIPPER_START, "c3": -8, "c4": 10})  # fmt: skip
    summary = imitate(cfg, tmp_path / "run", ImitationConfig(expert_episodes=2, dagger_rounds=1, dagger_episodes=1,
                                                             epochs=30), log=lambda line: None)  # fmt: skip
    first, last = summary["rounds"]
    assert first["acting"] == "expert" and first["states"] == 40 and last["states"] == 60  # 20 steps per episode
    assert first["fit_mse"] < 0.1  # the student's mean follows the expert's torques on the states it saw
    trained = load_trained(tmp_path / "run")
    assert trained.meta["iteration"] == 0 and trained.config == cfg.resolved()  # the workers it used
    assert evaluate_run(tmp_path / "run", episodes=1).episodes == 1
    rows = list(train(dataclasses.replace(cfg, steps=100), tmp_path / "run", resume=True))  # TRPO from the student
    assert len(rows) == 1 and rows[0]["iteration"] == 1
    with pytest.raises(ValueError, match="already holds a run"):
        imitate(cfg, tmp_path / "run", ImitationConfig(expert_episodes=1, dagger_rounds=0), log=lambda line: None)
    with pytest.raises(ValueError, match="flat Gripper"):
        imitate(dataclasses.replace(cfg, task="Reacher", task_kwargs={}), tmp_path / "other")
    with pytest.raises(ValueError, match="epochs"):
        ImitationConfig(epochs=0)
