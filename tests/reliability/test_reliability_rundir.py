"""Run directories: one writer at a time under an OS lock, every entry point resolving checkpoints alike, --resume
refusing other settings, and honest step budgets (docs/reliability.md, items 4-7)."""

import csv
import subprocess
import sys
import time

import pytest
import torch
from typer.testing import CliRunner

from hrlp.atomic import LOCK_FILE, DirectoryLockedError, directory_lock
from hrlp.checkpoint import checkpoint_exists, load_checkpoint, save_checkpoint
from hrlp.cli import app
from hrlp.config import Handover, MacroSpec, MicroAction
from hrlp.experiments.runner import Job, run_job
from hrlp.train import TrainConfig, plan_steps, train

FLAT = ["--batch-steps", "16", "--num-envs", "4", "--episode-steps", "20"]
MANAGER = ["--micro", "--micro-duration", "3", "--batch-steps", "8", "--num-envs", "4", "--episode-steps", "30"]


def invoke(*args: str):
    return CliRunner().invoke(app, list(args))


def iterations(run):
    with (run / "progress.csv").open() as f:
        return [row["iteration"] for row in csv.DictReader(f)]


def hold_lock(directory):
    """Another process holding ``directory``'s lock until killed."""
    code = ("import sys, time\nfrom hrlp.atomic import directory_lock\nwith directory_lock(sys.argv[1]):\n"
            "    print('locked', flush=True)\n    time.sleep(120)\n")  # fmt: skip
    proc = subprocess.Popen([sys.executable, "-c", code, str(directory)], stdout=subprocess.PIPE)
    assert proc.stdout.readline().strip() == b"locked"
    return proc


# --- 4: the lock --------------------------------------------------------------------------------------------------


def test_a_resume_or_a_second_trainer_beside_a_running_one_fails_at_once(tmp_path):
    run = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "hrlp", "train", "Reacher", "--steps", "100000000", *FLAT,
                             "--run-dir", str(run)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
    try:
        deadline = time.monotonic() + 180
        while not ((run / LOCK_FILE).is_file() and (run / LOCK_FILE).read_text().strip() == str(proc.pid)):
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the trainer took no lock"
            time.sleep(0.1)
        # A second fresh trainer: refused by the lock (or, once the first checkpoint is there, as a run that exists).
        r = invoke("train", "Reacher", *FLAT, "--steps", "16", "--run-dir", str(run))
        assert r.exit_code == 2 and ("in use by another process" in r.output or "already holds a run" in r.output)
        while not checkpoint_exists(run / "checkpoint"):
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the trainer wrote no checkpoint"
            time.sleep(0.2)
        done = load_checkpoint(run / "checkpoint")[1]["env_steps"]
        r = invoke("train", "Reacher", "--run-dir", str(run), "--resume", "--steps", str(done + 16))
        assert r.exit_code == 2, r.output
        assert f"{run}: this run directory is in use by another process (pid {proc.pid})" in r.output, r.output
        cfg = TrainConfig(task="Reacher", steps=100_000_000, batch_steps=16, num_envs=4, episode_steps=20)
        with pytest.raises(DirectoryLockedError, match=f"pid {proc.pid}"):
            list(train(cfg, run, resume=True))
        assert proc.poll() is None  # the running trainer was not disturbed
    finally:
        proc.kill()
        proc.wait()
    # The kernel dropped the lock with the killed process (even mid-save): the run resumes.
    done = load_checkpoint(run / "checkpoint")[1]["env_steps"]
    r = invoke("train", "Reacher", "--run-dir", str(run), "--resume", "--steps", str(done + 16))
    assert r.exit_code == 0, r.output
    assert load_checkpoint(run / "checkpoint")[1]["env_steps"] == done + 16


def test_a_save_never_deletes_another_writers_temporary_checkpoint(tmp_path):
    holder = hold_lock(tmp_path)
    in_progress = tmp_path / ".checkpoint.tmp-other"  # another writer's save, half done
    in_progress.mkdir()
    (in_progress / "weights.safetensors").write_bytes(b"partial")
    try:
        with pytest.raises(DirectoryLockedError, match=f"in use by another process \\(pid {holder.pid}\\)"):
            save_checkpoint(tmp_path / "checkpoint", {"x": torch.zeros(2)}, {})
        assert (in_progress / "weights.safetensors").read_bytes() == b"partial"
        assert not (tmp_path / "checkpoint").exists()
    finally:
        holder.kill()
        holder.wait()
    save_checkpoint(tmp_path / "checkpoint", {"x": torch.zeros(2)}, {})  # the lock is free: leftovers are ours to clear
    assert not in_progress.exists() and load_checkpoint(tmp_path / "checkpoint")[1] == {}


def test_the_lock_is_reentrant_in_one_thread_and_a_reproduce_job_on_a_held_directory_fails(tmp_path):
    with directory_lock(tmp_path / "a"), directory_lock(tmp_path / "a"):
        save_checkpoint(tmp_path / "a" / "checkpoint", {"x": torch.ones(1)}, {})
    assert (tmp_path / "a" / LOCK_FILE).is_file()
    cfg = TrainConfig(task="Reacher", steps=16, batch_steps=16, num_envs=4, episode_steps=20)
    job = Job("p", "r", 0, tmp_path / "p" / "r" / "s0", cfg, 1, None)
    holder = hold_lock(job.run_dir)
    try:
        with pytest.raises(DirectoryLockedError, match="in use by another process"):
            run_job(job)
    finally:
        holder.kill()
        holder.wait()
    assert sorted(p.name for p in job.run_dir.iterdir()) == [LOCK_FILE]  # nothing trained, nothing written


def test_a_lock_on_a_new_directory_that_nothing_was_written_to_leaves_no_directory(tmp_path):
    with pytest.raises(ValueError, match="refused"), directory_lock(tmp_path / "new"):
        raise ValueError("refused before anything was written")
    assert not (tmp_path / "new").exists()
    (tmp_path / "mine").mkdir()  # a directory that was there before stays, with its lock file
    with directory_lock(tmp_path / "mine"):
        pass
    assert (tmp_path / "mine" / LOCK_FILE).is_file()
    with directory_lock(tmp_path / "used"):
        (tmp_path / "used" / "log.txt").write_text("x")
    assert sorted(q.name for q in (tmp_path / "used").iterdir()) == [LOCK_FILE, "log.txt"]


# --- 5: one way to resolve a checkpoint ---------------------------------------------------------------------------


def test_a_kill_between_the_renames_is_continued_by_resume_and_never_overwritten(tmp_path):
    run = tmp_path / "run"
    assert invoke("train", "Reacher", *FLAT, "--steps", "16", "--run-dir", str(run)).exit_code == 0
    (run / "checkpoint").rename(run / ".checkpoint.old-0123abcd")  # what a kill between the save's renames leaves
    r = invoke("train", "Reacher", *FLAT, "--steps", "16", "--run-dir", str(run))  # would overwrite the progress
    assert r.exit_code == 2 and "already holds a run; pass --resume" in r.output, r.output
    assert invoke("eval", str(run), "--episodes", "1").exit_code == 0
    r = invoke("train", "Reacher", *FLAT, "--steps", "32", "--run-dir", str(run), "--resume")
    assert r.exit_code == 0, r.output
    assert iterations(run) == ["1", "2"] and load_checkpoint(run / "checkpoint")[1]["iteration"] == 2
    assert not list(run.glob(".checkpoint.*"))


def test_the_reproduce_runner_continues_the_old_copy_too(tmp_path):
    cfg = TrainConfig(task="Reacher", steps=16, batch_steps=16, num_envs=4, episode_steps=20)
    job = Job("p", "r", 0, tmp_path / "p" / "r" / "s0", cfg, 1, None)
    list(train(cfg, job.run_dir))
    (job.run_dir / "checkpoint").rename(job.run_dir / ".checkpoint.old-0123abcd")
    result = run_job(Job(**{**vars(job), "config": TrainConfig(**{**vars(cfg), "steps": 32})}))
    assert result["env_steps"] == 32 and iterations(job.run_dir) == ["1", "2"]


# --- 6: --resume keeps the run's own settings -----------------------------------------------------------------------


def test_resume_refuses_every_differing_option_by_name_and_keeps_the_runs_own(tmp_path):
    run = tmp_path / "run"
    assert invoke("train", "Reacher", *FLAT, "--steps", "16", "--max-kl", "0.02", "--seed", "3",
                  "--run-dir", str(run)).exit_code == 0  # fmt: skip
    r = invoke("train", "Reacher", "--run-dir", str(run), "--resume", "--max-kl", "0.01", "--num-envs", "8",
               "--task-arg", "c1=-5")  # fmt: skip
    assert r.exit_code == 2
    lines = [line for line in r.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0] == (
        f"error: --resume: {run} was trained with other settings: --max-kl 0.01 (the run: 0.02), --num-envs 8 (the run: "
        "4), --task-arg c1=-5 (the run: (none)); only --steps and --episodes may change (leave the other options out to "
        "continue with the run's own)"
    )
    r = invoke("train", "Gripper", "--run-dir", str(run), "--resume")
    assert r.exit_code == 2 and "TASK Gripper (the run: Reacher)" in r.output
    # Options left out are the run's own; options given with the run's values are accepted.
    assert invoke("train", "Reacher", "--run-dir", str(run), "--resume", "--steps", "32").exit_code == 0
    r = invoke("train", "hrlp/Reacher-v0", "--run-dir", str(run), "--resume", "--steps", "48", "--max-kl", "0.02",
               "--seed", "3", *FLAT)  # fmt: skip
    assert r.exit_code == 0, r.output
    meta = load_checkpoint(run / "checkpoint")[1]
    assert meta["config"]["trpo"]["max_kl"] == 0.02 and meta["config"]["seed"] == 3 and meta["env_steps"] == 48
    # The API says which settings differ too.
    cfg = TrainConfig.from_json(meta["config"])
    with pytest.raises(ValueError, match=r"only --steps and --episodes may change\); seed: 3 in the run, 4 given"):
        list(train(TrainConfig(**{**vars(cfg), "seed": 4}), run, resume=True))


def test_flat_and_manager_commands_refuse_to_resume_each_others_runs(tmp_path):
    flat, manager = tmp_path / "flat", tmp_path / "manager"
    assert invoke("train", "Reacher", *FLAT, "--steps", "16", "--run-dir", str(flat)).exit_code == 0
    r = invoke("train-manager", "ReachAndGrip2", *MANAGER, "--steps", "24", "--run-dir", str(manager))
    assert r.exit_code == 0, r.output
    r = invoke("train", "ReachAndGrip2", "--run-dir", str(manager), "--resume")
    assert r.exit_code == 2
    assert f"holds a Manager run; continue it with 'hrlp train-manager ReachAndGrip2 --run-dir {manager} --resume'" in r.output
    r = invoke("train-manager", "Reacher", "--run-dir", str(flat), "--resume")
    assert r.exit_code == 2 and "holds a flat run; continue it with 'hrlp train Reacher" in r.output
    r = invoke("train-manager", "ReachAndGrip2", "--run-dir", str(manager), "--resume", "--skills", "gripper", "--k", "10",
               "--micro-penalty", "0.5")  # fmt: skip
    assert r.exit_code == 2
    assert "--skills gripper (the run: (none)), --k 10 (the run: (default)), --micro-penalty 0.5 (the run: 0.0)" in r.output
    r = invoke("train-manager", "ReachAndGrip2", "--run-dir", str(manager), "--resume", "--micro", "--micro-duration",
               "3", "--steps", "48")  # fmt: skip
    assert r.exit_code == 0, r.output
    assert TrainConfig.from_json(load_checkpoint(manager / "checkpoint")[1]["config"]).macro == MacroSpec(
        (),
        None,
        MicroAction(duration=3),
        None,
        Handover(),  # train-manager drives point skills for hand-over by default
    )


# --- 7: step budgets ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("command", [["train", "Reacher"], ["train-manager", "ReachAndGrip2", "--micro"]])
def test_zero_steps_is_an_error_not_a_million(tmp_path, command):
    # A subprocess with a deadline: the old command trained 1,000,000 steps here.
    r = subprocess.run([sys.executable, "-m", "hrlp", *command, "--steps", "0", "--batch-steps", "16", "--num-envs", "4",
                        "--run-dir", str(tmp_path / "run")], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 2 and "--steps must be a positive number of environment steps, got 0" in r.stderr, r.stderr
    assert not (tmp_path / "run").exists()


def test_an_overshooting_budget_says_what_will_run_and_the_bar_counts_it(tmp_path):
    r = invoke("train", "Reacher", "--steps", "20", "--batch-steps", "30", "--num-envs", "4", "--episode-steps", "20",
               "--run-dir", str(tmp_path / "run"))  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "note: --steps 20 runs 32 steps: 1 iteration of 32 (32 in total)" in r.output, r.output
    assert "32/32" in r.output and "20/20" not in r.output
    assert "trained 1 iteration, 32 environment steps (32 in the run)" in r.output
    # Resuming with no more steps than the run has says there is nothing to train.
    r = invoke("train", "Reacher", "--steps", "30", "--run-dir", str(tmp_path / "run"), "--resume")
    assert r.exit_code == 0 and "the run already has 32 of the 30 steps asked for: nothing to train" in r.output


def test_a_manager_budget_below_one_iteration_says_so_and_the_bar_ends_at_the_real_count(tmp_path):
    r = invoke("train-manager", "ReachAndGrip2", *MANAGER, "--steps", "10", "--run-dir", str(tmp_path / "run"))
    assert r.exit_code == 0, r.output
    assert "--steps 10: a Manager iteration is 8 decisions of one or more low-level steps each, so the run stops after " \
           "the first iteration that reaches 10 steps" in r.output, r.output  # fmt: skip
    steps = load_checkpoint(tmp_path / "run" / "checkpoint")[1]["env_steps"]
    assert steps >= 24 and f"{steps}/{steps}" in r.output and "10/10" not in r.output


def test_the_step_plan_rounds_up_to_whole_iterations():
    cfg = TrainConfig(task="Reacher", steps=100, batch_steps=30, num_envs=4)
    plan = plan_steps(cfg)
    assert (plan.decisions_per_iteration, plan.iterations, plan.total) == (32, 4, 128)
    assert plan_steps(cfg, done=96).total == 128 and plan_steps(cfg, done=128).iterations == 0
    assert plan_steps(TrainConfig(task="Reacher", steps=128, batch_steps=32, num_envs=4)).note() is None
