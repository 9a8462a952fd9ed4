"""A run whose TRPO steps are all rejected says so: a warning after N in a row, and the final summary
(docs/reliability.md, item 3)."""

import warnings

import pytest
from typer.testing import CliRunner

from hrlp.algos.trpo import TRPOConfig
from hrlp.cli import app
from hrlp.train import REJECTED_STEPS_WARNING, TrainConfig, TrainingWarning, train

# A trust region so small that no step changes a float32 parameter: every line search fails, every step is rejected.
NO_STEP = TRPOConfig(max_kl=1e-30)


def test_train_warns_once_after_n_consecutive_rejected_steps(tmp_path):
    cfg = TrainConfig(task="Reacher", steps=64, batch_steps=16, num_envs=4, episode_steps=20, trpo=NO_STEP)
    with pytest.warns(TrainingWarning, match=r"the last 3 TRPO steps \(iterations 1-3\) were all rejected") as record:
        rows = list(train(cfg, tmp_path, warn_after_rejected=3))
    assert [r["trpo/accepted"] for r in rows] == [0.0] * 4
    assert len([w for w in record if issubclass(w.category, TrainingWarning)]) == 1  # once per run of rejections


def test_accepted_steps_raise_no_warning(tmp_path):
    cfg = TrainConfig(task="Reacher", steps=48, batch_steps=16, num_envs=4, episode_steps=20)
    with warnings.catch_warnings():
        warnings.simplefilter("error", TrainingWarning)
        rows = list(train(cfg, tmp_path, warn_after_rejected=1))
    assert all(r["trpo/accepted"] for r in rows)


def test_the_cli_warns_and_its_summary_says_every_step_was_rejected(tmp_path):
    n = REJECTED_STEPS_WARNING
    r = CliRunner().invoke(app, ["train", "Reacher", "--max-kl", "1e-30", "--steps", str(16 * n), "--batch-steps", "16",
                                 "--num-envs", "4", "--episode-steps", "20", "--run-dir", str(tmp_path / "run")])  # fmt: skip
    assert r.exit_code == 0, r.output
    assert f"warning: Reacher: the last {n} TRPO steps (iterations 1-{n}) were all rejected" in r.output, r.output
    assert f"trained {n} iterations, {16 * n} environment steps ({16 * n} in the run); warning: all {n} TRPO steps were " \
           "rejected, the policy did not change" in r.output, r.output  # fmt: skip
