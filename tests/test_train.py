"""The flat training loop end to end at tiny budgets: logs, checkpoints, evaluation, determinism, bad input."""

import copy
import csv
import dataclasses
import json
import math

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from hrlp.algos.value import ValueFitConfig, fit_value
from hrlp.checkpoint import load_checkpoint
from hrlp.cli import app
from hrlp.config import MacroSpec
from hrlp.evaluate import evaluate_run, mean_interval, wilson_interval
from hrlp.rollout import Sampler
from hrlp.train import TrainConfig, Trainer, env_factory, load_policy, load_trained, resolve_config, train
from hrlp.training.loop import batch_values

TINY = {"steps": 400, "batch_steps": 200, "num_envs": 4, "episode_steps": 30}


def test_training_writes_logs_and_a_checkpoint_that_evaluates(tmp_path):
    cfg = TrainConfig(task="Gripper", **TINY)
    rows = list(train(cfg, tmp_path))
    assert [r["iteration"] for r in rows] == [1, 2] and rows[-1]["env_steps"] == 400
    for r in rows:
        assert 0 <= r["trpo/kl"] <= cfg.trpo.max_kl * 1.5
        assert r["episodes"] > 0 and math.isfinite(r["return_mean"]) and 0 <= r["success_rate"] <= 1
        shares = sum(r[f"time/{k}_share"] for k in ("env", "inference", "value_fit", "update"))
        assert 0.5 < shares <= 1.0 + 1e-9
    with (tmp_path / "progress.csv").open() as f:
        logged = list(csv.DictReader(f))
    assert len(logged) == 2 and float(logged[1]["env_steps"]) == 400
    assert any((tmp_path / "tb").iterdir())
    # The config as run: workers left to the machine (0) are recorded as the count used ($HRLP_WORKERS=1 in the tests).
    assert TrainConfig.from_json(json.loads((tmp_path / "config.json").read_text())) == resolve_config(cfg) != cfg
    assert resolve_config(cfg).workers == 1
    tensors, meta = load_checkpoint(tmp_path / "checkpoint")
    assert meta["iteration"] == 2 and "policy.log_std" in tensors
    ev = evaluate_run(tmp_path, episodes=3)
    assert ev.episodes == 3 and math.isfinite(ev.ret.mean) and ev.success is not None


def test_evaluation_uses_the_gripper_start_set_of_a_distance_curriculum_run(tmp_path):
    kwargs = {"start_distance": [0.0, 0.09], "distance_curriculum": 100_000, "finger_opening": [0.8, 1.0]}
    list(train(TrainConfig(task="Gripper", task_kwargs=kwargs, **TINY), tmp_path))
    env = load_trained(tmp_path).make_env()
    assert env.unwrapped.task.distance_curriculum == 0  # in training the first episodes start within 3 cm
    far = []
    for k in range(20):
        env.reset(seed=k)
        far.append(env.unwrapped.physics.hand_to_capsule())
    assert max(far) > 0.05


def test_evaluation_uses_the_full_start_set_of_a_curriculum_run(tmp_path):
    cfg = TrainConfig(task="ReachAndGrip2", task_kwargs={"curriculum_alpha": 1e-6}, **TINY)
    list(train(cfg, tmp_path))
    trained = load_trained(tmp_path)
    env = trained.make_env()
    # In training the first episodes start within 1e-6 rad of angle 0; evaluation draws from the whole circle.
    assert env.unwrapped.task.curriculum_alpha is None
    angles = []
    for k in range(8):
        env.reset(seed=k)
        c = env.unwrapped.physics.capsule
        angles.append(math.atan2(c[1], c[0]))
    assert max(abs(a) for a in angles) > 0.5
    env.close()


def test_the_baseline_is_fitted_on_each_batch_during_the_next_iteration():
    trainer = Trainer(TrainConfig(task="Reacher", **TINY))
    first = trainer.iterate()
    assert math.isnan(first["value/explained_variance_after"]) and trainer.pending_value_fit is not None
    expected = copy.deepcopy(trainer.value_net)
    vstats = fit_value(expected, *trainer.pending_value_fit, trainer.cfg.value)
    second = trainer.iterate()  # fits the baseline on the first batch; nothing else changes it
    for a, b in zip(trainer.value_net.parameters(), expected.parameters(), strict=True):
        assert torch.equal(a, b)
    assert second["value/explained_variance_after"] == vstats.explained_variance_after
    trainer.sampler.close()


def test_the_baseline_fit_on_a_fraction_of_the_batch_keeps_whole_time_steps():
    cfg = TrainConfig(task="Reacher", value=ValueFitConfig(fraction=0.25), **TINY)  # 50 time steps x 4 environments
    trainer = Trainer(cfg)
    trainer.iterate()
    obs, returns = trainer.pending_value_fit
    assert obs.shape == (13 * 4, trainer.obs_dim) and returns.shape == (13 * 4,)
    full = Trainer(TrainConfig(task="Reacher", value=ValueFitConfig(fraction=1.0), **TINY))
    full.iterate()
    full_obs, full_returns = full.pending_value_fit
    # The same seed samples the same batch; the fraction keeps time steps 0, 4, ..., 48 of every environment.
    assert torch.equal(obs, full_obs.reshape(50, 4, -1)[::4].reshape(-1, full_obs.shape[-1]))
    assert torch.equal(returns, full_returns.reshape(50, 4)[::4].reshape(-1))
    trainer.sampler.close()
    full.sampler.close()


def test_iterations_report_the_share_of_time_in_mj_step():
    trainer = Trainer(TrainConfig(task="Reacher", **TINY))
    assert 0 < trainer.iterate()["time/physics_share"] < 1
    trainer.sampler.close()
    manager = Trainer(TrainConfig(task="ReachAndGrip2", macro=MacroSpec(skills=("gripper",), k=5), **TINY))
    assert 0 < manager.iterate()["time/physics_share"] < 1  # the low-level steps inside the Manager's decisions
    manager.sampler.close()
    gym_task = Trainer(TrainConfig(task="Pendulum-v1", **TINY))  # Gymnasium's environments do not report it
    assert math.isnan(gym_task.iterate()["time/physics_share"])
    gym_task.sampler.close()


def test_a_resumed_log_gains_the_columns_a_later_version_adds(tmp_path):
    """A run logged before a statistic existed, resumed by a version that logs it: no row is misaligned."""
    from hrlp.plots import read_progress
    from hrlp.train import RunLogger

    (tmp_path / "progress.csv").write_text("iteration,env_steps,time/steps_per_s,gone\n1,100,50.0,7\n")
    logger = RunLogger(tmp_path)
    logger.log({"iteration": 2, "env_steps": 200, "time/physics_share": 0.5, "time/steps_per_s": 40.0})
    logger.log({"iteration": 3, "env_steps": 300, "time/physics_share": 0.6, "time/steps_per_s": 30.0})
    logger.close()
    log = read_progress(tmp_path)
    assert list(log) == ["iteration", "env_steps", "time/steps_per_s", "gone", "time/physics_share"]
    assert log["time/steps_per_s"].tolist() == [50.0, 40.0, 30.0]
    assert math.isnan(log["time/physics_share"][0]) and log["time/physics_share"][1:].tolist() == [0.5, 0.6]
    assert log["gone"][0] == 7 and np.isnan(log["gone"][1:]).all()


def test_saved_policy_acts_like_the_trained_one(tmp_path):
    trainer = Trainer(TrainConfig(task="Reacher", **TINY))
    trainer.iterate()
    trainer.save(tmp_path / "checkpoint")
    policy, normalizer, _ = load_policy(tmp_path / "checkpoint")
    obs = np.random.default_rng(0).normal(size=(5, 27))
    a = trainer.policy.act_numpy(trainer.normalizer.normalize(obs).astype(np.float32), deterministic=True)
    b = policy.act_numpy(normalizer(obs, update=False).astype(np.float32), deterministic=True)
    np.testing.assert_allclose(a, b, rtol=1e-6)
    assert normalizer.frozen


def test_same_seed_gives_the_same_first_iterations():
    def first_two(seed):
        trainer = Trainer(TrainConfig(task="ReachAndGrip1", seed=seed, **TINY))
        return [{k: v for k, v in trainer.iterate().items() if not k.startswith("time/")} for _ in range(2)]

    a, b, c = first_two(3), first_two(3), first_two(4)
    assert a == b
    assert a != c


def test_truncated_steps_bootstrap_from_the_real_final_observation():
    factory = env_factory("Reacher", episode_steps=5)
    cfg = TrainConfig(task="Reacher", num_envs=2, batch_steps=20, steps=20)
    trainer = Trainer(cfg)
    sampler = Sampler([factory, factory], trainer.policy, trainer.normalizer, seed=0)
    batch, episodes = sampler.collect(7)
    assert batch.truncated[4].all() and not batch.truncated[3].any() and not batch.terminated.any()
    assert len(episodes) == 2 and all(e.length == 5 for e in episodes)
    # After a reset the next step's input is the new episode's first observation, not the final one.
    assert not torch.equal(batch.next_obs[4], batch.obs[5])
    assert torch.equal(batch.next_obs[3], batch.obs[4])


def test_batch_values_run_the_baseline_on_next_observations_only_where_episodes_end():
    factory = env_factory("Reacher", episode_steps=5)
    trainer = Trainer(TrainConfig(task="Reacher", num_envs=2, batch_steps=20, steps=20))
    torch.nn.init.normal_(trainer.value_net.net[-1].weight)  # a baseline that is not zero everywhere
    sampler = Sampler([factory, factory], trainer.policy, trainer.normalizer, seed=0)
    batch, _ = sampler.collect(12)  # episodes end at steps 4 and 9; the batch at 11
    T, N, D = batch.obs.shape
    rows: list[int] = []
    net = trainer.value_net

    def counting(x: torch.Tensor) -> torch.Tensor:
        rows.append(x.shape[0])
        return net(x)

    values, next_values = batch_values(counting, batch)
    with torch.no_grad():
        assert torch.equal(values, net(batch.obs.reshape(T * N, D)).reshape(T, N))
        two_passes = net(batch.next_obs.reshape(T * N, D)).reshape(T, N)
    assert torch.allclose(next_values, two_passes, rtol=0, atol=1e-6) and not torch.equal(next_values[4], values[5])
    assert rows == [T * N, 3 * N]  # the batch, then the next observations of steps 4, 9 and 11 only
    # An environment whose next observation is not the next step's input: the second pass over every step.
    rows.clear()
    moved = dataclasses.replace(batch, next_obs=batch.next_obs + 1.0)
    _, next_moved = batch_values(counting, moved)
    with torch.no_grad():
        assert torch.equal(next_moved, net(moved.next_obs.reshape(T * N, D)).reshape(T, N)) and rows == [T * N, T * N]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"task": "Reacher", "steps": 0}, "steps must be a positive integer"),
        ({"task": "Reacher", "batch_steps": 2, "num_envs": 4}, "at least num_envs"),
        ({"task": "Reacher", "hidden": (64, 0)}, "hidden"),
    ],
)
def test_bad_configs_fail_with_one_line_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TrainConfig(**kwargs)


def test_cli_rejects_bad_input_before_any_compute(tmp_path):
    runner = CliRunner()
    for args, message in (
        (["train", "NoSuchTask"], "unknown task"),
        (["train", "Reacher", "--max-kl", "-0.1"], "--max-kl must be > 0"),
        (["train", "Reacher", "--batch-steps", "0"], "batch_steps"),
        (["train", "Reacher", "--fisher-fraction", "0"], "--fisher-fraction must be in (0, 1]"),
        (["train-manager", "ReachAndGrip2", "--skills", "gripper", "--value-iters", "0"], "--value-iters must be a positive"),
        (["train", "Reacher", "--value-fraction", "1.5"], "--value-fraction must be in (0, 1]"),
        (["train", "hrlp_test/MultiDiscreteAction-v0"], "unsupported action space"),
        (["eval", str(tmp_path / "missing")], "no checkpoint"),
    ):
        result = runner.invoke(app, [*args, "--run-dir", str(tmp_path / "r")] if args[0].startswith("train") else args)
        assert result.exit_code == 2, (args, result.output)
        assert message in result.output
    assert not (tmp_path / "r").exists()


def test_cli_train_eval_render_on_a_gymnasium_task_and_an_hrlp_task(tmp_path):
    runner = CliRunner()
    run = tmp_path / "run"
    r = runner.invoke(app, ["train", "Gripper", "--steps", "200", "--batch-steps", "200", "--num-envs", "4",
                            "--episode-steps", "25", "--run-dir", str(run)])  # fmt: skip
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["eval", str(run), "--episodes", "2"])
    assert r.exit_code == 0 and "success rate" in r.output
    r = runner.invoke(app, ["render", str(run), "--out", str(tmp_path / "v.mp4"), "--steps", "5", "--width", "32",
                            "--height", "32"])  # fmt: skip
    assert r.exit_code == 0 and (tmp_path / "v.mp4").stat().st_size > 0
    r = runner.invoke(app, ["train", "Pendulum-v1", "--steps", "200", "--batch-steps", "200", "--num-envs", "2",
                            "--run-dir", str(tmp_path / "pend")])  # fmt: skip
    assert r.exit_code == 0, r.output


def test_confidence_intervals():
    iv = wilson_interval(0, 10)
    assert iv.mean == 0 and iv.low == 0 and 0.25 < iv.high < 0.35  # Wilson: 0/10 -> [0, 0.278]
    assert wilson_interval(0, 100).low == 0.0 and wilson_interval(100, 100).high == 1.0  # not rounding noise
    assert wilson_interval(0, 100).high == pytest.approx(0.037, abs=1e-3)
    iv = wilson_interval(5, 10)
    assert iv.low == pytest.approx(0.2366, abs=1e-3) and iv.high == pytest.approx(0.7634, abs=1e-3)
    m = mean_interval([1.0, 2.0, 3.0])
    assert m.mean == 2.0 and m.low == pytest.approx(2 - 4.303 / math.sqrt(3), abs=1e-3)


@pytest.mark.slow
def test_flat_trpo_learns_pendulum(tmp_path):
    cfg = TrainConfig(task="Pendulum-v1", steps=300_000, batch_steps=10_000, num_envs=10, seed=0)
    rows = list(train(cfg, tmp_path))
    first, last = rows[0]["return_mean"], max(r["return_mean"] for r in rows[-5:])
    assert last > first + 400, (first, last)  # random policy ~ -1200; learning reaches ~ -200 to -600


def test_resume_reproduces_an_uninterrupted_run_exactly(tmp_path):
    cfg = TrainConfig(task="ReacherStabilised", steps=600, batch_steps=200, num_envs=4, episode_steps=70, seed=5)
    full = list(train(cfg, tmp_path / "full"))
    part = list(train(dataclasses.replace(cfg, steps=400), tmp_path / "cut"))
    assert part == [] or len(part) == 2
    # A kill between checkpoint and log: an extra log row that the resume must drop.
    with (tmp_path / "cut" / "progress.csv").open("a") as f:
        f.write("3,600,0\n")
    rest = list(train(cfg, tmp_path / "cut", resume=True))

    def strip(rows):
        return [{k: v for k, v in r.items() if not k.startswith("time/")} for r in rows]

    assert strip(part + rest) == strip(full)
    a, _ = load_checkpoint(tmp_path / "full" / "checkpoint")
    b, _ = load_checkpoint(tmp_path / "cut" / "checkpoint")
    assert all(torch.equal(a[k], b[k]) for k in a)
    with (tmp_path / "cut" / "progress.csv").open() as f:
        assert [row["iteration"] for row in csv.DictReader(f)] == ["1", "2", "3"]


def test_resume_refuses_other_settings_and_fresh_runs_refuse_to_overwrite(tmp_path):
    cfg = TrainConfig(task="Reacher", **TINY)
    list(train(cfg, tmp_path))
    with pytest.raises(ValueError, match="only --steps and --episodes may change"):
        list(train(dataclasses.replace(cfg, seed=9), tmp_path, resume=True))
    with pytest.raises(ValueError, match="already holds a run"):
        list(train(cfg, tmp_path))
    r = CliRunner().invoke(app, ["train", "Reacher", "--run-dir", str(tmp_path / "none"), "--resume"])
    assert r.exit_code == 2 and "no checkpoint" in r.output


def test_progress_written_to_a_file_is_a_line_per_iteration(tmp_path):
    import io

    from rich.console import Console

    from hrlp.train import train_with_progress

    log = io.StringIO()  # not a terminal: a progress bar would leave nothing readable here
    summary = train_with_progress(TrainConfig(task="Reacher", **TINY), tmp_path / "run", console=Console(file=log),
                                  description="train Reacher")  # fmt: skip
    lines = log.getvalue().splitlines()
    assert summary.iterations == 2 and len(lines) == 2, lines
    assert lines[0].startswith("train Reacher: iteration 1, 200/400 steps (50%), return ")
    assert lines[1].startswith("train Reacher: iteration 2, 400/400 steps (100%), return ")
    assert all("success" in line and " steps/s, " in line for line in lines)


def test_reproduce_jobs_report_a_line_per_iteration(tmp_path, capfd):
    from hrlp.experiments.runner import Job, run_job

    cfg = TrainConfig(task="Reacher", **TINY)
    job = Job(preset="p", run="normal", seed=0, config=cfg, run_dir=tmp_path / "p" / "normal" / "s0", paper=None,
              eval_episodes=1)  # fmt: skip
    run_job(job)
    err = capfd.readouterr().err.splitlines()
    assert [line.split(",")[0] for line in err] == ["p / normal / seed 0: iteration 1", "p / normal / seed 0: iteration 2",
                                                    "eval p / normal / seed 0: 1/1 episodes (100%)"]  # fmt: skip
