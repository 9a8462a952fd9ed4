"""DAgger retraining: hand-over states collected from a Manager, a warm-started skill frozen with its lineage."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from hrlp.arm import make
from hrlp.arm.research.dagger import DaggerConfig, collect_handover_states, graspable, run_round
from hrlp.arm.research.starts import write_start_bank
from hrlp.arm.tasks import start_bank
from hrlp.cli import app
from hrlp.config import Handover, MacroSpec
from hrlp.skills import SkillLibrary, load_skill
from hrlp.train import TrainConfig, Trainer, load_trained, train


@pytest.fixture(scope="module")
def manager_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("dagger") / "manager"
    cfg = TrainConfig(task="ReachAndGrip1", steps=400, batch_steps=32, num_envs=4, episode_steps=40, init_log_std=-1.0,
                      macro=MacroSpec(("gripper", "reacher"), k=5, handover=Handover()))  # fmt: skip
    list(train(cfg, run))
    return run


def test_collected_states_are_where_the_manager_chose_the_skill_and_gripper_episodes_start_there(manager_run, tmp_path):
    qpos, qvel, episodes, refused = collect_handover_states(manager_run, "gripper", 12, seed=1)
    assert refused == 0
    assert qpos.shape == (12, 16) and qvel.shape == (12, 15) and episodes >= 1 and np.isfinite(qpos).all()
    again = collect_handover_states(manager_run, "gripper", 12, seed=1)
    np.testing.assert_array_equal(again[0], qpos)  # the collection is reproducible from its seed
    bank = write_start_bank(tmp_path / "b.npz", {"handover": (qpos, qvel)}, {"what": "test"})
    env = make("Gripper", starts=str(bank), starts_fraction=1.0)
    for seed in range(5):
        env.reset(seed=seed)
        d = env.unwrapped.physics.data
        assert np.abs(qpos.astype(np.float32) - d.qpos.astype(np.float32)).max(axis=1).min() < 1e-6
    with pytest.raises(ValueError, match="no skill 'mover'"):
        collect_handover_states(manager_run, "mover", 5)


def test_switches_only_keeps_the_decisions_at_which_control_passes_to_the_skill(manager_run):
    every = collect_handover_states(manager_run, "gripper", 120, seed=3)[0]
    switches, _, episodes, refused = collect_handover_states(manager_run, "gripper", 10, seed=3, switches_only=True)
    assert refused == 0 and episodes >= 1
    rows = {q.tobytes() for q in every}
    assert all(q.tobytes() in rows for q in switches)  # the same episodes, fewer of their decisions
    assert not np.array_equal(switches, every[: len(switches)])  # the Manager chose the Gripper twice in a row somewhere
    trained = load_trained(manager_run)
    env = trained.make_env()
    env.reset(seed=0)
    assert env.ran_last == -1
    blocks = [np.zeros(d) for d in env.param_dims]
    env.step((1, *blocks))
    assert env.ran_last == 1
    env.reset(seed=0)
    assert env.ran_last == -1


def test_the_graspable_filter_keeps_only_close_states_with_the_capsule_at_rest(manager_run):
    env = make("Gripper")
    env.reset(seed=0)
    physics = env.unwrapped.physics
    everything = collect_handover_states(manager_run, "gripper", 30, seed=2)
    d = []
    for q, v in zip(everything[0], everything[1], strict=True):
        physics.set_state_vectors(q.astype(np.float64), v.astype(np.float64))
        physics.forward()
        d.append(physics.hand_to_capsule())
    limit = float(np.median(d))  # half of the unfiltered hand-overs are farther than this
    qpos, qvel, _, refused = collect_handover_states(
        manager_run, "gripper", 10, seed=2, keep=lambda p: graspable(p, limit, 0.1)
    )
    assert refused > 0
    for q, v in zip(qpos, qvel, strict=True):
        physics.set_state_vectors(q.astype(np.float64), v.astype(np.float64))
        physics.forward()
        assert physics.hand_to_capsule() <= limit + 1e-6 and np.hypot(*v[9:11]) <= 0.1 + 1e-6
    physics.data.qvel[9] = 0.5  # the capsule sliding at 0.5 m/s is refused, at rest kept
    assert not graspable(physics, None, 0.1) and graspable(physics, None, 1.0) and graspable(physics, None, None)


@pytest.mark.parametrize("bank", ["recovery", "recovery-2"])
def test_the_shipped_recovery_banks_are_start_sets_by_name(bank):
    from hrlp.arm.tasks import gripper_start_bank

    qpos, _ = gripper_start_bank(bank)
    env = make("Gripper", starts=bank, starts_fraction=1.0)
    for seed in range(3):
        env.reset(seed=seed)
        d = env.unwrapped.physics.data
        assert np.abs(qpos.astype(np.float32) - d.qpos.astype(np.float32)).max(axis=1).min() < 1e-6


def test_bad_start_banks_are_refused_when_the_task_is_made(tmp_path):
    with pytest.raises(ValueError, match=r"start bank .*nope\.npz"):
        make("Gripper", starts=str(tmp_path / "nope.npz"))
    bad = write_start_bank(tmp_path / "nan.npz", {"handover": (np.full((3, 16), np.nan), np.zeros((3, 15)))}, {})
    with pytest.raises(ValueError, match="NaN or inf"):
        make("Gripper", starts=str(bad))
    with pytest.raises(ValueError, match="starts_fraction"):
        make("Gripper", starts_fraction=1.5)


def test_a_warm_started_run_begins_as_the_skill_acts():
    parent = load_skill("gripper")
    trainer = Trainer(
        TrainConfig(task="Gripper", steps=100, batch_steps=16, num_envs=2, episode_steps=10, init_from="gripper")
    )
    obs, _ = make("Gripper").reset(seed=3)
    mean = trainer.policy.act_numpy(trainer.normalizer(obs, update=False)[None].astype(np.float32), deterministic=True)
    np.testing.assert_allclose(np.clip(mean, -1, 1)[0], parent.torques(obs[None, :24], np.zeros((1, 0)))[0], atol=1e-5)
    assert all(p.requires_grad for p in trainer.policy.parameters()) and not trainer.normalizer.frozen
    trainer.sampler.close()
    with pytest.raises(ValueError, match="does not fit a Reacher run"):
        Trainer(TrainConfig(task="Reacher", steps=100, batch_steps=16, num_envs=2, init_from="gripper"))


def test_a_round_retrains_freezes_with_lineage_retrains_the_manager_and_resumes(manager_run, tmp_path):
    library = tmp_path / "lib"
    cfg = DaggerConfig(str(manager_run), "gripper", "gripper-d1", str(library), states=16, skill_steps=1_000,
                       manager_steps=400, workers=1, eval_episodes=2, switches_only=True)  # fmt: skip
    res = run_round(cfg, tmp_path / "round")
    with np.load(tmp_path / "round" / "starts.npz") as bank:  # the collection's settings travel with the states
        assert str(bank["meta_switches_only"]) == "True" and str(bank["meta_skill"]) == "gripper"
    lib = SkillLibrary(library)
    new, parent = lib.load("gripper-d1"), load_skill("gripper")
    lineage = lib.manifest("gripper-d1")["lineage"]
    assert lineage["parent"] == "gripper" and lineage["parent_sha256"] == parent.content_hash
    assert lineage["manager_run"] == str(manager_run) and new.k == parent.k
    assert any((a != b).any() for a, b in zip(new.policy.parameters(), parent.policy.parameters(), strict=True))
    skill_cfg = json.loads((tmp_path / "round" / "skill" / "config.json").read_text())
    assert skill_cfg["task_kwargs"]["starts_fraction"] == 0.5 and skill_cfg["init_from"].endswith("gripper")
    assert start_bank(skill_cfg["task_kwargs"]["starts"])[0].shape == (16, 16)
    manager_cfg = json.loads((tmp_path / "round" / "manager" / "config.json").read_text())
    assert manager_cfg["macro"]["skills"] == ["gripper-d1", "reacher"] and manager_cfg["macro"]["library"] == str(library)
    for key in ("skill_from_handover", "skill_from_own_starts", "manager"):
        assert all(0 <= res[key][v]["mean"] <= 1 for v in ("old", "new"))
    assert json.loads((tmp_path / "round" / "round.json").read_text())["new_skill_sha256"] == new.content_hash
    # Running the round again retrains nothing; another round may not take the same name.
    stamp = (tmp_path / "round" / "skill" / "checkpoint").stat().st_mtime_ns
    run_round(cfg, tmp_path / "round")
    assert (tmp_path / "round" / "skill" / "checkpoint").stat().st_mtime_ns == stamp
    r = CliRunner().invoke(app, ["dagger", str(manager_run), "--name", "gripper-d1", "--library", str(library),
                                 "--out", str(tmp_path / "other"), "--switches-only"])  # fmt: skip
    assert r.exit_code == 2 and "already exists" in r.output


def test_dagger_settings_are_checked():
    with pytest.raises(ValueError, match="new name"):
        DaggerConfig("m", "gripper", "gripper")
    with pytest.raises(ValueError, match="starts_fraction"):
        DaggerConfig("m", "gripper", "g2", starts_fraction=0.0)
    with pytest.raises(ValueError, match="states"):
        DaggerConfig("m", "gripper", "g2", states=0)
    with pytest.raises(ValueError, match="max_hand_distance must be a positive number"):
        DaggerConfig("m", "gripper", "g2", max_hand_distance=0.0)
    with pytest.raises(ValueError, match="max_capsule_speed must be a positive number"):
        DaggerConfig("m", "gripper", "g2", max_capsule_speed=float("nan"))
    with pytest.raises(ValueError, match="switches_only must be true or false"):
        DaggerConfig("m", "gripper", "g2", switches_only="yes")
