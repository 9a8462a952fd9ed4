"""Soft actor-critic: the update learns a one-step problem with a choice and a parameter, its settings are checked,
runs (flat, Manager, goal-conditioned with relabelling) log SAC's statistics and resume exactly, and the command line
trains and evaluates one."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from goal_envs import _NEAR
from hrlp.algos.sac import SACBatch, SACUpdate
from hrlp.checkpoint import load_checkpoint
from hrlp.cli import app
from hrlp.config import MacroSpec, SACConfig, TrainConfig
from hrlp.policies.sac import SACActor, TwinQ
from hrlp.train import train
from hrlp.training.offpolicy import OffPolicyTrainer


def test_the_hybrid_update_learns_the_best_choice_and_its_parameter():
    # One decision: choice 1 with its parameter at 0.5 pays 1, anything else pays less; no bootstrap (terminated).
    space = gym.spaces.Tuple((gym.spaces.Discrete(3), gym.spaces.Box(-1, 1, (1,)), gym.spaces.Box(-1, 1, (1,)),
                              gym.spaces.Box(-1, 1, (1,))))  # fmt: skip
    torch.manual_seed(0)
    actor = SACActor(2, space, (32, 32))
    update = SACUpdate(actor, TwinQ(2, actor.param_dims, (32, 32)), SACConfig(lr=3e-3, init_alpha=0.05), seed=0)
    g = torch.Generator().manual_seed(1)
    for _ in range(300):
        obs = torch.randn(128, 2, generator=g)
        a = actor.hybrid(obs).sample(g)
        k, x = a[:, 0].long(), a[:, 1:].gather(1, a[:, :1].long())[:, 0]
        reward = torch.where(k == 1, 1 - (x - 0.5).square(), 0.3 - 0.1 * x.square())
        stats = update.step(SACBatch(obs, a, reward, torch.full((128,), 0.99), torch.ones(128), obs))
    greedy = actor.act(torch.randn(64, 2, generator=g), deterministic=True)
    assert (greedy[:, 0] == 1).all()
    assert greedy[:, 2].mean().item() == pytest.approx(0.5, abs=0.1)
    assert stats.q == pytest.approx(1.0, abs=0.15)
    # Each temperature follows its own target: the choice's entropy fell below 0.5 log 3 (alpha up), the parameters'
    # stays above -1 (alpha down).
    assert stats.choice_entropy < 0.5 * np.log(3) and stats.alpha_choice > 0.05 > stats.alpha_params


def test_sac_settings_are_checked():
    for bad in ({"lr": 0}, {"tau": 1.5}, {"batch_size": 0}, {"buffer_size": -1}, {"updates_per_step": -1.0},
                {"choice_entropy": 2.0}, {"her_future": -1}, {"hidden": ()}, {"init_alpha": float("nan")}):  # fmt: skip
        with pytest.raises(ValueError):
            SACConfig(**bad)
    with pytest.raises(ValueError, match=r"^algo sac samples in the training process: workers must be 1"):
        TrainConfig(task="Pendulum-v1", algo="sac", workers=2, num_envs=4, batch_steps=8)
    with pytest.raises(ValueError, match="init_from"):
        TrainConfig(task="Reacher", algo="sac", init_from="reacher")


def _strip(rows):
    return [{k: v for k, v in r.items() if not k.startswith("time/")} for r in rows]


def _resumes_exactly(cfg, tmp_path):
    full = list(train(cfg, tmp_path / "full"))
    part = list(train(dataclasses.replace(cfg, steps=cfg.steps // 2), tmp_path / "cut"))
    rest = list(train(cfg, tmp_path / "cut", resume=True))
    assert len(part) and len(rest)
    assert _strip(part + rest) == _strip(full)
    a, _ = load_checkpoint(tmp_path / "full" / "checkpoint")
    b, _ = load_checkpoint(tmp_path / "cut" / "checkpoint")
    assert {"sac.log_alpha", "replay.obs", "sac.target.q1.0.weight"} <= set(a)
    assert sorted(a) == sorted(b) and all(torch.equal(a[k], b[k]) for k in a)
    return full


def test_a_flat_sac_run_logs_sac_statistics_and_resumes_exactly(tmp_path):
    sac = SACConfig(batch_size=16, learning_starts=40, hidden=(16, 16))
    cfg = TrainConfig(task="Reacher", algo="sac", sac=sac, steps=240, batch_steps=60, num_envs=2, episode_steps=50, seed=3)
    full = _resumes_exactly(cfg, tmp_path)
    assert full[-1]["sac/gradient_steps"] == 240 - 40 and full[-1]["sac/buffer_size"] == 240
    assert np.isfinite(full[-1]["sac/critic_loss"]) and "trpo/kl" not in full[-1]


def test_a_manager_sac_run_resumes_exactly(tmp_path):
    sac = SACConfig(batch_size=16, learning_starts=10, hidden=(16, 16))
    macro = MacroSpec(skills=("gripper", "reacher"), k=5)
    cfg = TrainConfig(task="ReachAndGrip1", algo="sac", sac=sac, macro=macro, steps=200, batch_steps=8, num_envs=2,
                      episode_steps=40, seed=1)  # fmt: skip
    full = _resumes_exactly(cfg, tmp_path)
    assert full[-1]["manager/mean_tau"] > 1


def test_goals_are_relabelled_on_a_goal_conditioned_environment_for_flat_runs_and_managers(tmp_path):
    sac = SACConfig(batch_size=32, learning_starts=16, hidden=(16,))
    flat = OffPolicyTrainer(TrainConfig(task="goal_envs:PointGoal-v0", algo="sac", sac=sac, num_envs=2,
                                        batch_steps=40, seed=0))  # fmt: skip
    macro = MacroSpec(skills=("goal_envs:reach",))
    manager = OffPolicyTrainer(TrainConfig(task="goal_envs:PointGoal-v0", algo="sac", sac=sac, macro=macro,
                                           num_envs=2, batch_steps=16, seed=0))  # fmt: skip
    off = OffPolicyTrainer(TrainConfig(task="goal_envs:PointGoal-v0", algo="sac", num_envs=2, batch_steps=16,
                                       sac=dataclasses.replace(sac, her_future=0)))  # fmt: skip
    try:
        assert flat.relabels and manager.relabels and not off.relabels
        for trainer in (flat, manager):
            trainer.iterate()
            goals = trainer.buffer.goals
            drawn = trainer.buffer.sample(400, np.random.default_rng(0))
            stored = trainer.buffer.sample(400, np.random.default_rng(0))
            assert goals is not None and stored["obs"].shape[1] == trainer.obs_dim
            moved = (drawn["obs"][:, goals.desired] != trainer.buffer.obs[0, 0, goals.desired]).any(axis=1)
            assert moved.mean() > 0.5  # relabelled goals come from where the point went, not the episodes' own goals
        assert manager.iterate()["manager/mean_tau"] > 1
    finally:
        for t in (flat, manager, off):
            t.close()


def test_the_command_line_trains_a_sac_run_with_its_defaults_noted_and_evaluates_it(tmp_path):
    run = tmp_path / "bandit"
    r = CliRunner().invoke(app, ["train", "hrlp/ParamBandit-v0", "--algo", "sac", "--steps", "300", "--batch-steps", "100",
                                 "--sac-learning-starts", "50", "--sac-hidden", "16,16", "--run-dir", str(run)])  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "note: --algo sac runs with --num-envs 4" in r.output and "kl " not in r.output
    assert "sac/critic_loss" in (run / "progress.csv").read_text().splitlines()[0]
    e = CliRunner().invoke(app, ["eval", str(run), "--episodes", "5"])
    assert e.exit_code == 0, e.output
    bad = CliRunner().invoke(
        app, ["train", "Pendulum-v1", "--algo", "sac", "--workers", "2", "--run-dir", str(tmp_path / "x")]
    )
    assert bad.exit_code != 0 and "workers must be 1" in bad.output and "Traceback" not in bad.output


def test_a_discrete_space_goes_through_the_same_learner(tmp_path):
    sac = SACConfig(batch_size=16, learning_starts=20, hidden=(16,))
    cfg = TrainConfig(task="CartPole-v1", algo="sac", sac=sac, steps=120, batch_steps=60, num_envs=2, seed=0)
    last = list(train(cfg, tmp_path / "cartpole"))[-1]
    assert last["sac/gradient_steps"] == 100 and np.isfinite(last["sac/critic_loss"])
    assert last["sac/params_log_prob"] == 0 and last["sac/alpha_params"] == pytest.approx(0.1)  # no parameters to tune


def test_a_relabelled_decision_of_a_skill_framed_on_the_goal_keeps_the_point_it_was_given():
    # near_goal's parameters are offsets of at most 5 cm from desired_goal: relabelling the goal re-expresses them.
    macro = MacroSpec(skills=("goal_envs:near_goal",))
    sac = SACConfig(batch_size=16, learning_starts=8, hidden=(16,))
    manager = OffPolicyTrainer(TrainConfig(task="goal_envs:PointGoal-v0", algo="sac", sac=sac, macro=macro, num_envs=2,
                                           batch_steps=40, seed=0))  # fmt: skip
    try:
        manager.iterate()
        b, box = manager.buffer, _NEAR
        assert b.goals is not None and b.goals.reframe is not None
        desired = b.goals.desired
        b.her_future = 0  # the same rows drawn, without relabelling
        own = b.sample(2000, np.random.default_rng(7))
        b.her_future = 1000
        drawn = b.sample(2000, np.random.default_rng(7))
        moved = (drawn["obs"][:, desired] != own["obs"][:, desired]).any(axis=1)
        kept = ~moved  # drawn for relabelling, but the point lies outside the box seen from the new goal
        assert moved.sum() > 100 and kept.sum() > 100
        point = box.to_user(own["actions"][:, 1:]) + own["obs"][:, desired]
        seen = box.to_user(drawn["actions"][:, 1:]) + drawn["obs"][:, desired]
        assert np.allclose(seen, point, atol=1e-5)  # the same point, from either goal
        assert not np.array_equal(drawn["actions"][moved], own["actions"][moved])
    finally:
        manager.close()


def test_a_managers_buffer_keeps_the_goal_achieved_after_each_low_level_step_of_its_decisions():
    sac = SACConfig(batch_size=16, learning_starts=8, hidden=(16,))
    macro = MacroSpec(skills=("goal_envs:reach",), k=6)
    manager = OffPolicyTrainer(TrainConfig(task="goal_envs:PointGoal-v0", algo="sac", sac=sac, macro=macro, num_envs=2,
                                           batch_steps=16, seed=0))  # fmt: skip
    try:
        manager.iterate()
        b = manager.buffer
        assert b.goals is not None and b.path is not None and b.path.shape[2:] == (6, 2)
        held = min(b.written, b.rows)
        tau, path = b.tau[:held].astype(int), b.path[:held]
        end = b.next_obs[:held, :, b.goals.achieved]
        start = b.obs[:held, :, b.goals.achieved]
        rows, envs = np.indices(tau.shape)
        assert np.array_equal(path[rows, envs, tau - 1], end)  # the last step taken is where the decision ended
        for j in range(6):  # past tau, the end repeats
            past = tau <= j
            assert np.array_equal(path[:, :, j][past], end[past])
        first_moved = np.linalg.norm(path[:, :, 0] - start, axis=-1)
        assert ((first_moved > 0) & (first_moved < np.linalg.norm(end - start, axis=-1))).mean() > 0.5  # steps in between
        manager.sampler.keep_paths = False  # as an on-policy sampler runs: the steps are neither computed nor kept
        manager.sampler.collect(2)
        assert manager.sampler.last_path is None and not manager.sampler.vector_env.record_paths
    finally:
        manager.close()
