"""The Manager's macro-action environment: skills run k steps, rewards are discounted inside a macro."""

import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from hrlp.arm import make
from hrlp.arm.skill_files import add_run
from hrlp.config import MicroAction
from hrlp.skills import SkillLibrary
from hrlp.skills.macro_env import MacroEnv
from hrlp.train import TrainConfig, train


@pytest.fixture(scope="module")
def skills(tmp_path_factory):
    root = tmp_path_factory.mktemp("skills")
    lib = SkillLibrary(root / "lib")
    for task in ("Reacher", "Gripper"):
        run = root / task
        list(train(TrainConfig(task=task, steps=100, batch_steps=100, num_envs=2, episode_steps=10), run))
        add_run(lib, run, task.lower(), k=5)
    return [lib.load("gripper"), lib.load("reacher")]


def test_action_space_is_a_parameterised_tuple_and_the_env_checker_passes(skills):
    env = MacroEnv(make("ReachAndGrip2", episode_steps=40), skills, micro=MicroAction())
    assert env.param_dims == (0, 3, 9) and env.names == ["gripper", "reacher", "micro"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*Box observation space (minimum|maximum) value is")
        check_env(env, skip_render_check=True)


def test_a_macro_step_is_k_low_level_steps_with_discounted_reward(skills):
    gamma, k = 0.9, 4
    macro = MacroEnv(make("ReachAndGrip2", episode_steps=40), skills, k=k, gamma=gamma)
    low = make("ReachAndGrip2", episode_steps=40)
    macro.reset(seed=3)
    low_obs, _ = low.reset(seed=3)
    goal = np.array([0.1, 0.05, 0.1])
    block = macro.block(1, goal)  # the Manager's [-1, 1] block that passes this goal
    assert np.abs(block).max() <= 1 and macro.parameters(1, block) == pytest.approx(goal)
    _, r, _, _, info = macro.step((1, np.zeros(0), block))
    expected, g = 0.0, 1.0
    for _ in range(k):  # the same skill, driven by hand on a twin environment
        low_obs, lr, *_ = low.step(skills[1].torques(low_obs[None, :24], goal[None])[0])
        expected += g * lr
        g *= gamma
    assert info["tau"] == k and info["discount"] == pytest.approx(gamma**k) and info["macro"] == "reacher"
    assert r == pytest.approx(expected)
    np.testing.assert_allclose(macro.env.physics.hand, low.physics.hand)


def test_macro_stops_at_the_episode_end_and_micro_is_penalised(skills):
    def run(penalty):
        env = MacroEnv(make("ReachAndGrip1", episode_steps=7), skills, k=5, micro=MicroAction(3, penalty), gamma=1.0)
        env.reset(seed=0)
        _, _, _, trunc1, info1 = env.step((0, np.zeros(0), np.zeros(3), np.zeros(9)))
        _, r, _, trunc2, info2 = env.step((2, np.zeros(0), np.zeros(3), np.full(9, 0.2)))
        return (trunc1, info1["tau"], trunc2, info2["tau"]), r

    shape, r_pen = run(0.5)
    assert shape == (False, 5, True, 2)  # 7 steps in all: the 3-step micro-action is cut by the episode's end
    shape_free, r_free = run(0.0)
    assert shape_free == shape and r_pen == pytest.approx(r_free - 0.5)


def test_manager_only_micro_is_the_flat_baseline_through_the_same_code():
    flat = make("Gripper", episode_steps=10)
    macro = MacroEnv(make("Gripper", episode_steps=10), [], micro=MicroAction(duration=1), gamma=0.99)
    flat.reset(seed=1)
    macro.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(10):
        a = rng.uniform(-1, 1, 9)
        o1, r1, *_ = flat.step(a)
        o2, r2, _, _, info = macro.step((0, a))
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2 and info["discount"] == pytest.approx(0.99)


def test_bad_manager_actions_raise_clear_errors(skills):
    env = MacroEnv(make("ReachAndGrip1"), skills)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"choice must be in \[0, 2\)"):
        env.step((5, np.zeros(0), np.zeros(3)))
    with pytest.raises(ValueError, match=r"parameters of reacher must have shape \(3,\)"):
        env.step((1, np.zeros(0), np.zeros(2)))
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step((1, np.zeros(0), np.array([np.nan, 0, 0])))
    with pytest.raises(ValueError, match="at least one skill or the micro-action"):
        MacroEnv(make("ReachAndGrip1"), [])
    with pytest.raises(ValueError, match=r"MicroAction\.duration"):
        MicroAction(duration=0)
