"""`hrlp train` on any Gymnasium environment with a Box, Discrete or parameterised Tuple action space."""

import math

import pytest
from typer.testing import CliRunner

from hrlp.algos.trpo import TRPOConfig
from hrlp.cli import app, parse_task_args
from hrlp.policies.mlp import CategoricalPolicy, HierarchicalPolicy
from hrlp.train import TrainConfig, load_trained, train


def test_hierarchical_trpo_learns_a_parameterised_bandit(tmp_path):
    # Optimal: arm 0 with its parameter copying x (reward 1 per step); arm 1 pays 0.5; random play about 0.1.
    # The parameter is acted in [-1, 1] mapped onto its Box(-2, 2) (hrlp.envs.actions): std 0.5 there is std 1 natively.
    cfg = TrainConfig(task="hrlp_test/PickAndPoint-v0", steps=24_000, batch_steps=2_000, num_envs=8,
                      init_log_std=math.log(0.5), trpo=TRPOConfig(max_kl=0.05))  # fmt: skip
    stats = list(train(cfg, tmp_path / "run"))
    per_step = [s["return_mean"] / 8 for s in stats]
    assert per_step[0] < 0.4 and per_step[-1] > 0.8, per_step
    assert isinstance(load_trained(tmp_path / "run").policy, HierarchicalPolicy)


def test_discrete_actions_train_through_the_same_loop(tmp_path):
    stats = list(train(TrainConfig(task="CartPole-v1", steps=4_000, batch_steps=2_000, num_envs=4), tmp_path / "run"))
    assert len(stats) == 2 and stats[-1]["env_steps"] == 4_000
    assert isinstance(load_trained(tmp_path / "run").policy, CategoricalPolicy)


def test_task_arguments_from_the_command_line(tmp_path):
    assert parse_task_args(["c1=-10", "start_distance=[0, 0.09]", "name=abc"]) == {
        "c1": -10, "start_distance": [0, 0.09], "name": "abc"}  # fmt: skip
    with pytest.raises(ValueError, match="NAME=VALUE"):
        parse_task_args(["c1"])
    runner = CliRunner()
    r = runner.invoke(app, ["train", "Gripper", "--task-arg", "c1=3", "--run-dir", str(tmp_path / "r")])
    assert r.exit_code == 2 and "c1, c3 < 0 < c2" in r.output and not (tmp_path / "r").exists()
    r = runner.invoke(app, ["train", "Gripper", "--task-arg", "c1=-2", "--steps", "100", "--batch-steps", "100",
                            "--num-envs", "2", "--episode-steps", "20", "--run-dir", str(tmp_path / "ok")])  # fmt: skip
    assert r.exit_code == 0, r.output
    trained = load_trained(tmp_path / "ok")
    assert trained.config.task_kwargs == {"c1": -2} and trained.make_env().unwrapped.task.reward.c1 == -2
