"""Data that poisons a run: NaN, inf or out-of-range numbers stop training where they enter, in one line naming the
environment, the step and the field, before anything of that iteration is saved (docs/reliability.md, item 1)."""

import csv
import functools
import math

import numpy as np
import pytest
import torch
from reliability_envs import ENV_ID, make_poisoned
from typer.testing import CliRunner

from hrlp.checkpoint import load_checkpoint
from hrlp.cli import app
from hrlp.config import MicroAction
from hrlp.policies.mlp import policy_for_space
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.rollout import NonFiniteError, ParallelSampler, Sampler
from hrlp.skills.macro_env import MacroEnv
from hrlp.train import TrainConfig, Trainer, train

# 4 environments x 10 decisions per iteration, 30-step episodes.
SMALL = {"steps": 400, "batch_steps": 40, "num_envs": 4}


def _rows(path):
    with path.open() as f:
        return list(csv.DictReader(f))


def _poisoned(**task_kwargs):
    return TrainConfig(task=ENV_ID, task_kwargs=task_kwargs, **SMALL)


@pytest.mark.parametrize(
    ("poison", "iteration", "expected"),
    [
        ({"field": "reward", "at_step": 15, "value": "nan"}, 2,
         "non-finite reward (nan) from environment 2 at step 15 of its episode (decision 5 of this batch)"),
        ({"field": "observation", "at_step": 24, "index": 3, "value": "inf"}, 3,
         "non-finite observation[3] (inf) from environment 2 at step 24 of its episode (decision 4 of this batch)"),
        ({"field": "reward", "at_step": 12, "value": 1e39}, 2,
         "non-finite reward (1e+39, beyond float32's range) from environment 2 at step 12 of its episode"),
        # The reset that starts environment 2's second episode, at its 30th decision (decision 10 of iteration 3).
        ({"field": "reset", "at_step": 2, "index": 5, "value": "-inf"}, 3,
         "non-finite reset observation[5] (-inf) from environment 2 at the reset that starts an episode (decision 10 of "
         "this batch)"),
    ],
)  # fmt: skip
def test_non_finite_data_stops_the_run_naming_environment_step_and_field_before_anything_is_saved(
    tmp_path, poison, iteration, expected
):
    cfg = _poisoned(poison_seed=2, **poison)
    rows = []
    with pytest.raises(NonFiniteError) as info:
        for row in train(cfg, tmp_path):
            rows.append(row)
    message = str(info.value)
    assert "\n" not in message and expected in message and f"iteration {iteration}:" in message, message
    assert len(rows) == iteration - 1
    # The checkpoint and the log are those of the last good iteration, every tensor finite, the meta strict JSON.
    tensors, meta = load_checkpoint(tmp_path / "checkpoint")
    assert meta["iteration"] == iteration - 1
    assert all(torch.isfinite(t).all() for t in tensors.values() if t.is_floating_point())
    assert [r["iteration"] for r in _rows(tmp_path / "progress.csv")] == [str(i) for i in range(1, iteration)]


def test_a_bad_observation_at_the_first_reset_stops_before_the_first_iteration_saves_anything(tmp_path):
    cfg = _poisoned(field="reset", at_step=1, index=0, value="nan", poison_seed=1)
    with pytest.raises(NonFiniteError, match=r"non-finite observation\[0\] \(nan\) from environment 1 at the reset"):
        list(train(cfg, tmp_path))
    assert not (tmp_path / "checkpoint").exists() and not (tmp_path / "progress.csv").exists()


def test_the_cli_reports_poisoned_data_in_one_line(tmp_path):
    args = ["train", ENV_ID, "--task-arg", "field=reward", "--task-arg", "at_step=3", "--task-arg", "poison_seed=1",
            "--steps", "400", "--batch-steps", "40", "--num-envs", "4", "--run-dir", str(tmp_path / "run")]  # fmt: skip
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output
    errors = [line for line in r.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "reward (nan) from environment 1 at step 3 of its episode" in errors[0], r.output


def test_sampling_workers_name_the_environment_by_its_index_in_the_run():
    fns = [functools.partial(make_poisoned, field="observation", at_step=2, poison_seed=3, index=1)] * 4
    probe = fns[0]()
    policy = policy_for_space(probe.observation_space.shape[0], probe.action_space, (8,))
    probe.close()
    sampler = ParallelSampler(fns, policy, RunningNormalizer(probe.observation_space.shape[0]), seed=0, workers=2)
    try:
        with pytest.raises(NonFiniteError, match=r"observation\[1\] \(nan\) from environment 3 at step 2 of its episode"):
            sampler.collect(5)
    finally:
        sampler.close()


def test_a_managers_macro_steps_are_checked_too():
    def manager():  # the micro-action only: three low-level steps per decision, no skill files involved
        return MacroEnv(make_poisoned("ReachAndGrip2", field="reward", at_step=5, poison_seed=1), [], None,
                        MicroAction(duration=3))  # fmt: skip

    probe = manager()
    policy = policy_for_space(probe.observation_space.shape[0], probe.action_space, (8,))
    sampler = Sampler([manager] * 2, policy, RunningNormalizer(probe.observation_space.shape[0]), seed=0)
    probe.close()
    # Low-level step 5 lies in decision 2 (steps 4-6); the Manager's reward of that decision is NaN.
    with pytest.raises(NonFiniteError, match=r"reward \(nan\) from environment 1 at step 6 of its episode \(decision 2"):
        sampler.collect(4)
    sampler.close()


def test_the_normaliser_refuses_non_finite_observations_and_keeps_its_statistics():
    norm = RunningNormalizer(3)
    norm.update(np.arange(6.0).reshape(2, 3))
    before = {k: v.clone() for k, v in norm.state_dict().items()}
    bad = np.ones((4, 3))
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"non-finite observation \(row 2 of 4, dimension 1: nan\)"):
        norm.update(bad)
    assert all(torch.equal(before[k], v) for k, v in norm.state_dict().items())
    with pytest.raises(ValueError, match="must be finite"):
        norm.load_state_dict({"mean": torch.tensor([0.0, math.inf, 0.0]), "var": torch.ones(3), "count": torch.tensor(2.0)})


def test_value_targets_that_overflow_stop_the_run_before_the_policy_step(tmp_path):
    # Rewards at float32's edge, finite each, overflow once GAE adds two of them: the advantages become inf.
    cfg = _poisoned(field="reward", at_step=4, repeat=2, value=3e38, poison_seed=2)
    with pytest.raises(NonFiniteError, match=r"iteration 1: non-finite advantage \(inf\) for environment 2 at decision"):
        list(train(cfg, tmp_path))
    assert not (tmp_path / "checkpoint").exists()


def test_a_diverged_baseline_is_named_and_a_nan_state_is_never_saved(tmp_path):
    trainer = Trainer(TrainConfig(task="Reacher", steps=40, batch_steps=40, num_envs=4, episode_steps=30))
    try:
        trainer.save(tmp_path / "checkpoint")
        with torch.no_grad():
            next(trainer.value_net.parameters()).fill_(math.nan)
        with pytest.raises(NonFiniteError, match=r"non-finite baseline value \(nan\) for environment 0 at decision 1"):
            trainer.iterate()
        with pytest.raises(NonFiniteError, match="refusing to save it"):
            trainer.save(tmp_path / "checkpoint")
    finally:
        trainer.sampler.close()
    tensors, meta = load_checkpoint(tmp_path / "checkpoint")  # the good one, untouched
    assert meta["iteration"] == 0 and all(torch.isfinite(t).all() for t in tensors.values() if t.is_floating_point())


def test_an_infinite_action_noise_is_named_not_trained_on(tmp_path):
    # --init-log-std 1000: std e^1000 = inf, every sampled action infinite (the old loop clipped them and "trained").
    r = CliRunner().invoke(app, ["train", "Reacher", "--init-log-std", "1000", "--steps", "40", "--batch-steps", "40",
                                 "--num-envs", "4", "--run-dir", str(tmp_path / "run")])  # fmt: skip
    assert r.exit_code == 2 and "Traceback" not in r.output
    assert "non-finite action[" in r.output and "from environment 0 at step 1 of its episode" in r.output, r.output
