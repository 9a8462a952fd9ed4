"""Skills: from a training run into the library, loaded frozen, acting like the trained policy."""

import numpy as np
import pytest
from typer.testing import CliRunner

from hrlp.arm import make
from hrlp.arm.skill_files import add_run
from hrlp.checkpoint import CheckpointError
from hrlp.cli import app
from hrlp.experiments.presets import PRESETS
from hrlp.skills import SkillLibrary
from hrlp.train import TrainConfig, load_policy, train


@pytest.fixture(scope="module")
def reacher_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("reacher_run")
    list(train(TrainConfig(task="Reacher", steps=200, batch_steps=200, num_envs=4, episode_steps=25), run))
    return run


def test_a_skill_acts_like_the_trained_policy_on_the_same_observation(reacher_run, tmp_path):
    lib = SkillLibrary(tmp_path)
    add_run(lib, reacher_run, "reacher", k=8)
    skill = lib.load("reacher")
    assert (skill.task, skill.k, skill.param.dim, skill.obs_dim) == ("Reacher", 8, 3, 27)
    env = make("Reacher")
    obs, _ = env.reset(seed=0)
    policy, normalizer, _ = load_policy(reacher_run / "checkpoint")
    expected = np.clip(policy.act_numpy(normalizer(obs, update=False).astype(np.float32), deterministic=True), -1, 1)
    # The Manager passes the goal as the skill's parameter; it enters the observation at 24:27.
    got = skill.torques(obs[None, :24], env.task.goal[None])
    np.testing.assert_allclose(got[0], expected, atol=1e-5)
    assert not any(p.requires_grad for p in skill.policy.parameters())


def test_skill_inputs_are_checked(reacher_run, tmp_path):
    lib = SkillLibrary(tmp_path)
    add_run(lib, reacher_run, "r")
    skill = lib.load("r")
    with pytest.raises(ValueError, match="NaN or inf"):
        skill.torques(np.zeros((1, 24)), np.array([[np.nan, 0, 0]]))
    with pytest.raises(ValueError, match=r"shape \[N, >=24\]"):
        skill.torques(np.zeros((1, 20)), np.zeros((1, 3)))


def test_library_errors_tampering_and_names(reacher_run, tmp_path):
    lib = SkillLibrary(tmp_path)
    add_run(lib, reacher_run, "r1")
    with pytest.raises(ValueError, match="already exists"):
        add_run(lib, reacher_run, "r1")
    with pytest.raises(ValueError, match="skill name"):
        add_run(lib, reacher_run, "../escape")
    with pytest.raises(ValueError, match="no skill 'nope'"):
        lib.load("nope")
    h = lib.manifest("r1")["sha256"]
    assert lib.load("r1").content_hash == h
    weights = tmp_path / "r1" / "weights.safetensors"
    data = bytearray(weights.read_bytes())
    data[-3] ^= 0xFF
    weights.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match=r"weights\.safetensors"):
        lib.load("r1")
    weights.write_bytes(bytes(data[: len(data) // 2]))
    with pytest.raises(CheckpointError):
        lib.load("r1")


def test_only_skill_tasks_become_skills(tmp_path):
    run = tmp_path / "rg"
    list(train(TrainConfig(task="ReachAndGrip1", steps=100, batch_steps=100, num_envs=2, episode_steps=10), run))
    with pytest.raises(ValueError, match="a skill must be trained on one of"):
        add_run(SkillLibrary(tmp_path / "lib"), run, "x")


def test_skills_cli_add_list_show(reacher_run, tmp_path):
    runner = CliRunner()
    lib = str(tmp_path / "lib")
    r = runner.invoke(app, ["skills", "add", str(reacher_run), "--name", "reach8", "--k", "8", "--library", lib])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["skills", "list", "--library", lib], env={"COLUMNS": "200"})
    assert r.exit_code == 0 and "reach8" in r.output and "Reacher" in r.output
    r = runner.invoke(app, ["skills", "show", "reach8", "--library", lib])
    assert r.exit_code == 0 and '"meaning"' in r.output and '"sha256"' in r.output
    r = runner.invoke(app, ["skills", "show", "missing", "--library", lib])
    assert r.exit_code == 2 and "no skill 'missing'" in r.output
    r = runner.invoke(app, ["skills", "add", str(reacher_run), "--name", "bad", "--k", "0", "--library", lib])
    assert r.exit_code == 2 and "positive integer" in r.output


def test_shipped_skills_load_frozen_and_the_reacher_reaches():
    from hrlp.arm.skill_files import shipped_library_root
    from hrlp.skills import load_skill

    shipped = SkillLibrary(shipped_library_root())
    assert {"gripper", "reacher", "reacher3d", "s-reacher", "mover-noised", "mover-plain"} <= set(shipped.names())
    recipes = {r.skill[0]: r for r in PRESETS["shipped-skills"].runs}
    for name in shipped.names():
        m = shipped.manifest(name)  # trained with the recipe's seed: the preset's 0 plus the run's seed_offset
        assert m["trained"]["config"]["seed"] == recipes[name].seed_offset and m["trained"]["env_steps"] > 1_000_000
        assert shipped.load(name).content_hash == m["sha256"]
    reacher = load_skill("reacher", library=shipped.root)
    env = make("Reacher")
    for seed in (0, 1):
        obs, _ = env.reset(seed=seed)
        for _ in range(300):
            obs, _, _, truncated, info = env.step(reacher.torques(obs[None, :24], env.task.goal[None])[0])
            if truncated:
                break
        assert info["success"], seed


def test_the_shipped_noised_mover_moves_the_capsule_towards_its_target():
    from hrlp.skills import load_skill

    mover = load_skill("mover-noised")
    env = make("MoverNoised", episode_steps=100)

    def target_dist_sum(act) -> float:
        total = 0.0
        for seed in range(10):
            obs, _ = env.reset(seed=seed)
            truncated = False
            while not truncated:
                obs, _, _, truncated, info = env.step(act(obs))
            total += info["target_dist_sum"]
        return total / 10

    moved = target_dist_sum(lambda obs: mover.torques(obs[None, :24], env.physics.target[None])[0])
    still = target_dist_sum(lambda obs: np.zeros(9))
    assert moved > still + 2.0  # measured: -9.98 against -13.14 with zero torques
