"""The Mover's recorded "grip" starts: states along the shipped Gripper skill's successful episodes."""

import math
from importlib import resources

import numpy as np
import pytest

from hrlp.arm import make
from hrlp.arm.research.starts import record_grip_starts, write_start_bank
from hrlp.arm.tasks import MOVER_HELD_STARTS_FILE, MOVER_STARTS_FILE, grip_starts
from hrlp.skills.library import load_skill


def _gripped(env, q, v) -> bool:
    p = env.unwrapped.physics
    p.set_state_vectors(q, v)
    p.forward()
    return env.unwrapped.task.success(p)


def test_recorded_states_come_from_episodes_in_which_the_gripper_grips():
    gripper = load_skill("gripper")
    q, v = record_grip_starts(gripper, math.pi, 120, seed=3, every=1, episode_steps=60, num_envs=4)
    assert q.shape == (120, 16) and v.shape == (120, 15)
    env = make("Gripper")
    env.reset(seed=0)
    for block in range(2):  # two whole episodes of 60 steps each, each gripped at some step
        assert any(_gripped(env, q[i], v[i]) for i in range(60 * block, 60 * (block + 1)))
    with pytest.raises(ValueError, match="angle_range"):
        record_grip_starts(gripper, 4.0, 10)


def test_shipped_bank_matches_the_shipped_gripper_and_its_variants():
    with resources.files("hrlp.arm").joinpath(MOVER_STARTS_FILE).open("rb") as f, np.load(f, allow_pickle=False) as z:
        assert str(z["meta_skill_sha256"]) == load_skill("gripper").content_hash
    env = make("Gripper")
    env.reset(seed=0)
    for variant, widest in (("plain", 0.2), ("noised", math.pi)):
        q, v = grip_starts(variant)
        assert len(q) >= 1000
        c = q[:, 9:12]  # the capsule's free joint position
        angles = np.abs(np.arctan2(c[:, 1], c[:, 0] + 0.15))
        # Episodes start within `widest` of straight ahead; the claw may push the capsule on afterwards.
        assert np.median(angles) <= widest and (variant == "plain" or angles.max() > 2.5)
        gripped = np.mean([_gripped(env, q[i], v[i]) for i in range(0, len(q), 7)])
        assert 0.1 < gripped < 0.95  # on the way to a grip, and gripped


def test_held_recording_keeps_only_states_with_the_capsule_in_the_claw():
    gripper = load_skill("gripper-imitated")
    q, v = record_grip_starts(gripper, math.pi, 40, seed=3, every=2, episode_steps=60, num_envs=4, held=True)
    assert q.shape == (40, 16)
    env = make("Gripper")
    env.reset(seed=0)
    assert all(_gripped(env, q[i], v[i]) for i in range(40))


def test_shipped_held_bank_matches_gripper_imitated_and_every_state_is_held():
    with resources.files("hrlp.arm").joinpath(MOVER_HELD_STARTS_FILE).open("rb") as f, np.load(f, allow_pickle=False) as z:
        assert str(z["meta_skill_sha256"]) == load_skill("gripper-imitated").content_hash
        assert str(z["meta_held"]) == "True"
    env = make("Gripper")
    env.reset(seed=0)
    for variant in ("plain", "noised"):
        q, v = grip_starts(variant, held=True)
        assert len(q) >= 1000
        assert all(_gripped(env, q[i], v[i]) for i in range(0, len(q), 23))


def test_a_held_mover_start_keeps_the_capsule_while_the_claw_stays_closed():
    env = make("MoverNoised", starts="held", episode_steps=30)
    q, _ = grip_starts("noised", held=True)
    for seed in range(3):
        env.reset(seed=seed)
        p = env.unwrapped.physics
        assert np.abs(q - p.data.qpos).sum(axis=1).min() < 1e-5  # a recorded state, restored
        assert 0.05 - 1e-9 <= p.target[2] - p.capsule[2] <= 0.20 + 1e-9
        for _ in range(30):
            env.step(np.r_[np.zeros(7), 1.0, -1.0])  # the arm limp, the fingers closing
        assert p.finger_gap() < 0.03 and p.hand_to_capsule() < 0.05  # Definition 1 still holds


def test_mover_grip_starts_restore_a_recorded_state_and_place_the_target():
    q, _ = grip_starts("plain")
    env = make("MoverPlain")
    for seed in range(5):
        env.reset(seed=seed)
        p = env.physics
        i = int(np.argmin(np.abs(q - p.data.qpos).sum(axis=1)))
        np.testing.assert_allclose(p.data.qpos, q[i])
        offset = p.target - p.capsule
        assert np.all(np.abs(offset - [0, 0, 0.10]) <= 0.02 + 1e-9)
    with pytest.raises(ValueError, match="starts"):
        make("MoverPlain", starts="teleport")


def test_start_bank_files_are_written_atomically_and_read_without_pickle(tmp_path):
    q, v = np.zeros((3, 16)), np.ones((3, 15))
    path = write_start_bank(tmp_path / "b.npz", {"plain": (q, v)}, {"skill": "x"})
    with np.load(path, allow_pickle=False) as z:
        np.testing.assert_array_equal(z["plain_qvel"], v)
        assert str(z["meta_skill"]) == "x"
    assert [p.name for p in tmp_path.iterdir()] == ["b.npz"]


def test_scripted_grasp_records_demonstration_starts_from_its_successful_episodes():
    from hrlp.arm.research.scripted import ScriptedGraspConfig

    q, v = record_grip_starts(ScriptedGraspConfig(), math.pi, 50, seed=0, every=4, episode_steps=100, num_envs=2)
    assert q.shape == (50, 16) and v.shape == (50, 15)
    env = make("Gripper")
    env.reset(seed=0)
    assert any(_gripped(env, q[i], v[i]) for i in range(25))  # the first whole episode (25 states) grips
    assert not _gripped(env, q[0], v[0])  # and starts from an open start, not a grip
