"""The defaults are the fast settings (issue 17): sampling workers that follow the cores ($HRLP_WORKERS overrides the
count, at most num_envs, recorded as the count used and kept on resume), 64 environments, Fisher-vector products on
10% of the batch and the baseline by 10 L-BFGS iterations on every 4th time step; ``--paper-settings`` gives back the
paper's, which every preset pins (``tests/test_preset_configs.py``)."""

import dataclasses
import json

import pytest
import typer
from typer.testing import CliRunner

from hrlp import bounds
from hrlp.cli import app
from hrlp.config import PAPER_SETTINGS, WORKERS_VARIABLE, TrainConfig, auto_workers, with_settings
from hrlp.train import read_run_checkpoint, resolve_config, train

TINY = ["--steps", "64", "--batch-steps", "64", "--num-envs", "4", "--episode-steps", "10"]
"""A run of one iteration: 16 decisions per environment (the default fractions fit)."""


def _saved(run) -> TrainConfig:
    return TrainConfig.from_json(json.loads((run / "config.json").read_text()))


def test_the_defaults_are_the_fast_settings():
    cfg = TrainConfig(task="Reacher")
    assert (cfg.workers, cfg.num_envs, cfg.trpo.fisher_fraction) == (0, 64, 0.1)
    assert (cfg.value.max_iter, cfg.value.fraction) == (10, 0.25)
    paper = with_settings(cfg, PAPER_SETTINGS)
    assert (paper.workers, paper.num_envs, paper.trpo.fisher_fraction) == (1, 16, 1.0)
    assert (paper.value.max_iter, paper.value.fraction) == (25, 1.0)
    assert cfg.backend == "auto" and paper.backend == "serial"
    assert dataclasses.replace(paper, workers=0, num_envs=64, trpo=cfg.trpo, value=cfg.value, backend="auto") == cfg


def test_a_small_batch_works_with_the_defaults():
    cfg = TrainConfig(task="Reacher", batch_steps=200)  # 4 decisions per environment, 256 in all
    assert cfg.steps_per_env == 4 and resolve_config(cfg).workers == 1  # $HRLP_WORKERS=1 in the tests
    with pytest.raises(ValueError, match=r"value fraction 0\.25 keeps every 4th of the batch's 2 time steps"):
        TrainConfig(task="Reacher", batch_steps=128)


def test_the_worker_count_follows_the_cores_capped_by_the_environments(monkeypatch):
    monkeypatch.delenv(WORKERS_VARIABLE)
    monkeypatch.setattr(bounds, "cores", lambda: 3)
    assert auto_workers(64) == 3 and auto_workers(2) == 2 and auto_workers(1) == 1
    assert resolve_config(TrainConfig(task="Reacher", num_envs=8, batch_steps=80)).workers == 3
    assert resolve_config(TrainConfig(task="Reacher", num_envs=2, batch_steps=80)).workers == 2
    explicit = TrainConfig(task="Reacher", num_envs=8, batch_steps=80, workers=1)
    assert resolve_config(explicit).workers == 1  # a count given is used as given


def test_the_backend_is_batched_for_arm_tasks_and_serial_elsewhere():
    from hrlp.config import MacroSpec

    assert resolve_config(TrainConfig(task="Reacher")).backend == "batched"
    assert resolve_config(TrainConfig(task="hrlp/ReachAndGrip2-v0")).backend == "batched"
    manager = TrainConfig(task="ReachAndGrip1", macro=MacroSpec(skills=("gripper", "reacher"), k=10))
    assert resolve_config(manager).backend == "batched"
    assert resolve_config(TrainConfig(task="Pendulum-v1")).backend == "serial"
    assert resolve_config(TrainConfig(task="ParamMatch")).backend == "serial"  # an hrlp task without the arm
    assert resolve_config(TrainConfig(task="Reacher", backend="serial")).backend == "serial"
    with pytest.raises(ValueError, match=r"^backend batched steps hrlp's arm tasks; Pendulum-v1 is not one: use serial"):
        resolve_config(TrainConfig(task="Pendulum-v1", backend="batched"))
    with pytest.raises(ValueError, match=r"^backend must be one of auto, batched, serial, got 'gpu'"):
        TrainConfig(task="Reacher", backend="gpu")


MANAGER = ["train-manager", "ReachAndGrip1", "--skills", "gripper,reacher", "--k", "3", "--handover", "--micro"]


@pytest.mark.parametrize("command", [["train", "Reacher"], MANAGER], ids=["flat", "manager"])
def test_the_batched_backend_trains_the_same_iteration_as_serial(tmp_path, command):
    # World i of the BatchedArmEnv is environment i of the serial run (same seeds, same action noise; a Manager's skills
    # act on the same rows); the rollout backend agrees with ArmEnv to about 1e-7 (tests/envs/test_batched.py), so the
    # first iteration's figures agree.
    rows = {}
    for backend in ("serial", "batched"):
        run = tmp_path / backend
        r = CliRunner().invoke(app, [*command, *TINY, "--workers", "1", "--backend", backend, "--run-dir", str(run)])
        assert r.exit_code == 0, r.output
        assert _saved(run).backend == backend
        rows[backend] = (run / "progress.csv").read_text().splitlines()
    header = rows["serial"][0].split(",")
    serial, batched = (dict(zip(header, rows[b][1].split(","), strict=True)) for b in ("serial", "batched"))
    for key in ("return_mean", "episodes", "env_steps", "trpo/kl", "trpo/surrogate_after", "trpo/grad_norm"):
        assert float(batched[key]) == pytest.approx(float(serial[key]), rel=1e-5, abs=1e-8), key


def test_hrlp_workers_sets_the_count(monkeypatch):
    monkeypatch.setattr(bounds, "cores", lambda: 3)  # max_processes: 6
    monkeypatch.setenv(WORKERS_VARIABLE, "5")
    assert auto_workers(64) == 5 and auto_workers(4) == 4
    assert resolve_config(TrainConfig(task="Reacher", num_envs=8, batch_steps=80, workers=2)).workers == 2
    for value, match in (("two", "must be a positive integer, got 'two'"), ("0", "must be a positive integer, got 0"),
                         ("7", "must be at most 6, got 7")):  # fmt: skip
        monkeypatch.setenv(WORKERS_VARIABLE, value)
        with pytest.raises(ValueError, match=f"^{WORKERS_VARIABLE} .*{match}"):
            auto_workers(64)


def test_a_bad_hrlp_workers_is_one_line_before_any_compute(tmp_path, monkeypatch):
    monkeypatch.setenv(WORKERS_VARIABLE, "many")
    r = CliRunner().invoke(app, ["train", "Reacher", *TINY, "--run-dir", str(tmp_path / "r")])
    assert r.exit_code == 2 and r.output.strip().splitlines() == [
        f"error: {WORKERS_VARIABLE} (the sampling workers of a run whose workers are left out) must be a positive "
        "integer, got 'many'"
    ], r.output
    assert not (tmp_path / "r").exists()
    ok = CliRunner().invoke(app, ["train", "Reacher", *TINY, "--workers", "1", "--run-dir", str(tmp_path / "r")])
    assert ok.exit_code == 0, ok.output  # a count given does not read the variable


def test_a_run_records_the_count_it_used_and_a_resume_keeps_it(tmp_path, monkeypatch):
    run = tmp_path / "run"
    r = CliRunner().invoke(app, ["train", "Reacher", *TINY, "--run-dir", str(run)])
    assert r.exit_code == 0, r.output
    assert _saved(run).workers == 1 and read_run_checkpoint(run / "checkpoint")[2].workers == 1
    # On a machine (or with a variable) that would give another count, a resume without --workers keeps the run's.
    monkeypatch.setenv(WORKERS_VARIABLE, "2")
    more = CliRunner().invoke(app, ["train", "Reacher", "--run-dir", str(run), "--resume", "--steps", "128"])
    assert more.exit_code == 0, more.output
    resumed = read_run_checkpoint(run / "checkpoint")[2]
    assert resumed.workers == 1 and resumed.steps == 128 and _saved(run) == resumed
    # A count given that differs from the run's is refused by name, as any other setting; the same count continues it.
    other = CliRunner().invoke(app, ["train", "Reacher", "--run-dir", str(run), "--resume", "--workers", "2"])
    assert other.exit_code == 2 and "--workers 2 (the run: 1)" in " ".join(other.output.split()), other.output
    same = CliRunner().invoke(app, ["train", "Reacher", "--run-dir", str(run), "--resume", "--workers", "1",
                                    "--steps", "192"])  # fmt: skip
    assert same.exit_code == 0, same.output
    # In Python, a config whose workers are left to the machine (0) resumes with the run's count too.
    rows = list(train(dataclasses.replace(_saved(run), workers=0, steps=256), run, resume=True))
    assert len(rows) == 1 and read_run_checkpoint(run / "checkpoint")[2].workers == 1 and _saved(run).workers == 1


@pytest.mark.parametrize("command", ["train", "train-manager"])
def test_paper_settings_gives_the_papers_values_for_the_options_left_out(command, tmp_path):
    task = ["train-manager", "ReachAndGrip2", "--micro"] if command == "train-manager" else ["train", "Reacher"]
    small = ["--steps", "32", "--batch-steps", "32", "--episode-steps", "10"]
    r = CliRunner().invoke(app, [*task, *small, "--paper-settings", "--run-dir", str(tmp_path / "paper")])
    assert r.exit_code == 0, r.output
    cfg = _saved(tmp_path / "paper")
    assert (cfg.workers, cfg.num_envs, cfg.trpo.fisher_fraction, cfg.value.max_iter, cfg.value.fraction) == (
        1, 16, 1.0, 25, 1.0)  # fmt: skip
    # An option given keeps its value; the others still take the paper's.
    given = ["--num-envs", "4", "--value-iters", "7"]
    r = CliRunner().invoke(app, [*task, *small, *given, "--paper-settings", "--run-dir", str(tmp_path / "given")])
    assert r.exit_code == 0, r.output
    cfg = _saved(tmp_path / "given")
    assert (cfg.workers, cfg.num_envs, cfg.trpo.fisher_fraction, cfg.value.max_iter, cfg.value.fraction) == (
        1, 4, 1.0, 7, 1.0)  # fmt: skip


def test_paper_settings_on_resume_are_compared_with_the_run(tmp_path):
    run = tmp_path / "run"
    assert CliRunner().invoke(app, ["train", "Reacher", *TINY, "--run-dir", str(run)]).exit_code == 0
    r = CliRunner().invoke(app, ["train", "Reacher", "--run-dir", str(run), "--resume", "--paper-settings"])
    line = " ".join(r.output.split())
    assert r.exit_code == 2 and "--fisher-fraction 1.0 (the run: 0.1; from --paper-settings)" in line, r.output
    assert "--value-iters 25 (the run: 10; from --paper-settings)" in line and "--workers" not in line  # both 1


@pytest.mark.parametrize("command", ["train", "train-manager"])
def test_the_help_names_what_paper_settings_sets(command):
    params = {p.name: p for p in typer.main.get_command(app).commands[command].params}  # type: ignore[attr-defined]
    expected = "--workers 1 --backend serial --num-envs 16 --fisher-fraction 1 --value-iters 25 --value-fraction 1"
    assert expected in params["paper_settings"].help


def test_a_batch_too_small_for_the_default_fractions_uses_every_state_with_a_note(tmp_path):
    tiny = ["--steps", "4", "--batch-steps", "4", "--num-envs", "2", "--episode-steps", "10"]
    r = CliRunner().invoke(app, ["train", "Reacher", *tiny, "--run-dir", str(tmp_path / "r")])
    assert r.exit_code == 0, r.output
    assert ("note: a batch of 4 decisions (2 per environment) is too small for the default --fisher-fraction 0.1 and "
            "--value-fraction 0.25: every state is used (--fisher-fraction 1 --value-fraction 1)") in " ".join(
        r.output.split())  # fmt: skip
    cfg = _saved(tmp_path / "r")
    assert (cfg.trpo.fisher_fraction, cfg.value.fraction) == (1.0, 1.0)
    # A fraction given is checked as given.
    bad = CliRunner().invoke(app, ["train", "Reacher", *tiny, "--fisher-fraction", "0.1", "--run-dir", str(tmp_path / "b")])
    assert bad.exit_code == 2 and "fisher_fraction 0.1 keeps every 10th of the batch's 4 decisions" in bad.output


def test_configs_saved_before_a_paper_setting_existed_read_back_with_the_papers_value():
    cfg = with_settings(TrainConfig(task="Reacher"), PAPER_SETTINGS)
    old = json.loads(json.dumps(cfg.to_json()))
    del old["trpo"]["fisher_fraction"], old["value"]["fraction"], old["value"]["max_iter"]
    assert TrainConfig.from_json(old) == cfg
    with pytest.raises(ValueError, match=r"unknown setting 'trpo\.nonsense'"):
        with_settings(cfg, {"trpo.nonsense": 1})
