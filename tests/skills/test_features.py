"""Skills that read named observation features (the capsule's pose, the claw's pose relative to it, the arm's distances
to it) beyond the 24 base numbers and their parameters.

A Gripper trained with ``observe_capsule``, ``observe_claw`` and ``observe_clearance`` observes 50 numbers; as a skill it
is given the 24 base numbers by the Manager and the 6 + 15 + 5 feature numbers by the environment it acts in, computed
from that environment's physics. These tests check that every place a skill acts gives it the same 50 numbers its training
task did: alone, inside a MacroEnv, and over the batched backend (including the first step after a reset, where the
batched worlds' sensors must be current, and the distance sensors that only worlds built for such a skill carry).
"""

from __future__ import annotations

import numpy as np
import pytest

from hrlp.arm import make
from hrlp.arm.batched import make_batched
from hrlp.arm.manager import batched_manager
from hrlp.arm.skill_files import add_run
from hrlp.config import MacroSpec
from hrlp.skills import SkillLibrary
from hrlp.skills.macro_env import MacroEnv, manager_vector_env
from hrlp.train import TrainConfig, load_policy, train

SEEING = {"observe_capsule": True, "observe_claw": True, "observe_clearance": True}
FEATURES = ("capsule_pose", "claw_pose", "arm_clearance")
F = 6 + 15 + 5
N, EPISODE, K = 3, 12, 5


@pytest.fixture(scope="module")
def seeing(tmp_path_factory):
    """``(run, library)``: a short Gripper run that observes the capsule's pose, added to a library as ``seeing``."""
    run = tmp_path_factory.mktemp("seeing_run")
    list(train(TrainConfig(task="Gripper", steps=200, batch_steps=200, num_envs=4, episode_steps=25, task_kwargs=SEEING), run))
    lib = SkillLibrary(tmp_path_factory.mktemp("seeing_lib"))
    add_run(lib, run, "seeing", k=K)
    return run, lib


def test_a_skill_records_the_features_its_task_observed_and_acts_on_them_like_the_policy(seeing):
    run, lib = seeing
    skill, manifest = lib.load("seeing"), lib.manifest("seeing")
    assert (skill.features, skill.feature_dim, skill.obs_dim) == (FEATURES, F, 24 + F)
    assert (manifest["features"], manifest["obs_dim"]) == (list(FEATURES), 24 + F)
    env = make("Gripper", episode_steps=25, **SEEING)
    obs, _ = env.reset(seed=3)
    # The environment computes the features from its physics exactly as the task observes them.
    np.testing.assert_array_equal(skill.features_of([env.unwrapped.physics])[0], obs[24:])
    policy, normalizer, _ = load_policy(run / "checkpoint")
    expected = np.clip(policy.act_numpy(normalizer(obs, update=False).astype(np.float32), deterministic=True), -1, 1)
    got = skill.torques(obs[None, :24], np.zeros((1, 0)), obs[None, 24:])
    np.testing.assert_allclose(got[0], expected, atol=1e-5)
    other = obs[None, 24:] + np.linspace(-1.0, 1.0, F)[None]
    assert not np.allclose(skill.torques(obs[None, :24], np.zeros((1, 0)), other), got)  # the features reach the network


def test_a_skill_without_the_features_it_reads_is_refused_with_one_line(seeing):
    skill = seeing[1].load("seeing")
    names = "capsule_pose, claw_pose, arm_clearance"
    with pytest.raises(ValueError, match=rf"reads the observation features {names}; pass them \(\[N, 26\]\)"):
        skill.torques(np.zeros((2, 24)), np.zeros((2, 0)))
    with pytest.raises(ValueError, match=rf"features \({names}\) must have shape \[2, 26\], got \[2, 6\]"):
        skill.torques(np.zeros((2, 24)), np.zeros((2, 0)), np.zeros((2, 6)))
    with pytest.raises(ValueError, match="NaN or inf"):
        skill.torques(np.zeros((1, 24)), np.zeros((1, 0)), np.full((1, F), np.nan))


def test_a_manager_gives_the_skill_the_features_its_task_observed(seeing):
    # A Manager on the paper's 24-number Gripper task calls the seeing skill; its episodes are those of the skill acting
    # alone on the task that observes the pose, step for step.
    skill = seeing[1].load("seeing")
    manager = MacroEnv(make("Gripper", episode_steps=EPISODE), [skill], k=K)
    alone = make("Gripper", episode_steps=EPISODE, **SEEING)
    obs, _ = manager.reset(seed=5)
    low, _ = alone.reset(seed=5)
    np.testing.assert_array_equal(obs, low[:24])
    for _ in range(EPISODE // K + 1):
        obs, _, term, trunc, info = manager.step((0, np.zeros(0)))
        total = 0.0
        for _ in range(info["tau"]):
            low, r, *_ = alone.step(skill.torques(low[None, :24], np.zeros((1, 0)), low[None, 24:])[0])
            total += r
        np.testing.assert_array_equal(obs, low[:24])
        assert info["task_reward"] == pytest.approx(total, rel=1e-12)
        if term or trunc:
            break
    assert trunc


@pytest.mark.parametrize("backend", ["loop", "rollout"])
def test_the_batched_manager_gives_the_skill_the_same_features_after_every_reset(seeing, backend):
    # Decisions of k = 5 in episodes of 12 steps: every world resets twice, and the decision after a reset reads the
    # pose of the new start (a batched world's sensors are refreshed when it is reset).
    skill = seeing[1].load("seeing")
    layout = MacroEnv(make("Gripper", episode_steps=EPISODE), [skill], k=K)
    serial = manager_vector_env([MacroEnv(make("Gripper", episode_steps=EPISODE), [skill], k=K) for _ in range(N)])
    batched = batched_manager(make_batched("Gripper", N, episode_steps=EPISODE, backend=backend, features=FEATURES),
                                    layout)  # fmt: skip
    np.testing.assert_array_equal(serial.reset(seed=7), batched.reset(seed=7))
    atol = 1e-7 if backend == "loop" else 1e-6
    ended = 0
    for _ in range(8):
        a, b = serial.step(np.zeros((N, 1))), batched.step(np.zeros((N, 1)))
        np.testing.assert_allclose(b.next_obs, a.next_obs, atol=atol)
        np.testing.assert_allclose(b.obs, a.obs, atol=atol)  # after the resets: the new starts
        np.testing.assert_array_equal(b.tau, a.tau)
        ended += int(a.truncated.sum())
    assert ended >= 2 * N


def test_batched_worlds_without_the_clearance_sensors_are_refused_for_a_skill_that_reads_them(seeing):
    skill = seeing[1].load("seeing")
    layout = MacroEnv(make("Gripper", episode_steps=EPISODE), [skill], k=K)
    plain = make_batched("Gripper", N, episode_steps=EPISODE)
    assert plain.measured_features == ("capsule_pose", "claw_pose")
    with pytest.raises(ValueError, match=r"the skills read arm_clearance, which the worlds do not measure; build them with "
                                         r"features=\('capsule_pose', 'claw_pose', 'arm_clearance'\)"):  # fmt: skip
        batched_manager(plain, layout)
    with pytest.raises(ValueError, match="unknown observation feature"):
        make_batched("Gripper", N, features=("arm_distance",))


def test_a_manager_trains_with_a_seeing_gripper_on_both_backends(seeing, tmp_path):
    lib = seeing[1]
    for backend in ("serial", "batched"):
        cfg = TrainConfig(task="ReachAndGrip2", steps=300, batch_steps=60, num_envs=4, episode_steps=30, workers=1,
                          backend=backend, macro=MacroSpec(("seeing", "reacher"), k=K, library=str(lib.root)))  # fmt: skip
        stats = list(train(cfg, tmp_path / backend))
        assert stats[-1]["env_steps"] >= 300 and all(s["trpo/accepted"] == 1.0 and np.isfinite(s["return_mean"])
                                                     for s in stats)  # fmt: skip
