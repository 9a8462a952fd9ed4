"""How a run ends when something outside it ends it (docs/reliability.md, "How a run stops"): SIGINT, SIGTERM and SIGHUP sent
to the whole process group at several moments of real ``python -m hrlp`` processes (start-up, worker start-up, after a
checkpoint with two sampling workers, during a save, a second signal while stopping) end in one line, no traceback,
exit code 128 + the signal, and a run that ``--resume`` continues from its last completed iteration; a user's
environment that fails is named with its context; progress lines never print ``nan``; a damaged log names its line.

These tests start processes because the processes are what is tested; each takes seconds."""

import csv
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from hrlp.checkpoint import load_checkpoint
from hrlp.cli import app
from hrlp.envs.faults import EnvError
from hrlp.envs.vector import SerialVectorEnv
from hrlp.stopping import Stopped, handling_stop_signals
from hrlp.train import TrainConfig, train
from hrlp.training.logs import progress_line

TESTS = Path(__file__).parent
if str(TESTS / "reliability") not in sys.path:  # save_protocol: the kill tests' instrumented checkpoint save
    sys.path.append(str(TESTS / "reliability"))
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), str(TESTS / "reliability"), os.environ.get("PYTHONPATH", "")])}
FLAT = ["--batch-steps", "16", "--num-envs", "4", "--episode-steps", "20"]
MANAGER = ["--skills", "gripper,reacher", "--batch-steps", "16", "--num-envs", "4"]
CODES = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGHUP: 129}

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process groups and /proc are Linux's")


def start(*args: str, cwd: Path, nohup: bool = False) -> subprocess.Popen:
    """``python -m hrlp ARGS`` in a session of its own (its process group is what a terminal's Ctrl-C reaches); with
    ``nohup``, as ``nohup`` starts it: SIGHUP ignored."""
    ignore_hup = (lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN)) if nohup else None
    return subprocess.Popen([sys.executable, "-m", "hrlp", *args], cwd=cwd, env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=ignore_hup)  # fmt: skip


def group(pgid: int) -> list[int]:
    """The processes of group ``pgid`` still running (zombies, which have exited, left out)."""
    return _running(2, pgid)


def session(sid: int) -> list[int]:
    """The processes of session ``sid`` still running (Ray puts each trial's worker in a process group of its own)."""
    return _running(3, sid)


def _running(field: int, value: int) -> list[int]:
    """The running processes whose ``/proc/PID/stat`` field ``field`` (after the name; 2: group, 3: session) is ``value``."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(") ", 1)[1].split()
            except (OSError, IndexError):
                continue
            if int(fields[field]) == value and fields[0] != "Z":
                out.append(int(entry.name))
    return out


def signal_group(proc: subprocess.Popen, sig: int, again_after_s: float | None = None) -> tuple[int, str]:
    """Send ``sig`` to ``proc``'s whole process group (and once more after ``again_after_s``); its exit code and its
    stdout and stderr together, once it and every process of its group have ended."""
    os.killpg(proc.pid, sig)
    if again_after_s is not None:
        time.sleep(again_after_s)
        os.killpg(proc.pid, sig)
    try:
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        raise
    deadline = time.monotonic() + 10
    while group(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = group(proc.pid)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert not left, f"processes of the stopped run still running: {left}"
    return proc.returncode, out + err


def wait_until(proc: subprocess.Popen, ready, what: str, limit_s: float = 180) -> None:
    deadline = time.monotonic() + limit_s
    while not ready():
        if proc.poll() is not None:
            raise AssertionError(f"the run ended before {what}: {proc.communicate()}")
        if time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            raise AssertionError(f"no {what} within {limit_s} s")
        time.sleep(0.02)


def handlers_installed(pid: int) -> bool:
    """Whether ``pid`` catches SIGTERM (hrlp.stopping's handlers are in place; Python alone catches only SIGINT)."""
    caught = int(re.search(r"SigCgt:\s*([0-9a-f]+)", Path(f"/proc/{pid}/status").read_text()).group(1), 16)
    return bool(caught >> (signal.SIGTERM - 1) & 1)


def the_line(output: str, sig: int) -> str:
    """The output's one stop line (asserting there is exactly one, and no traceback anywhere)."""
    assert "Traceback" not in output and "KeyboardInterrupt" not in output, output
    assert "nan" not in output, output  # progress lines show '-' where no episode ended
    lines = [line for line in output.splitlines() if line.startswith("stopped ")]
    assert len(lines) == 1 and signal.Signals(sig).name in lines[0], output
    return lines[0]


def logged(run: Path) -> list[int]:
    with (run / "progress.csv").open() as f:
        return [int(row["iteration"]) for row in csv.DictReader(f)]


def invoke(*args: str):
    return CliRunner().invoke(app, list(args))


def assert_same_checkpoints(run: Path, reference: Path) -> None:
    """Every tensor of the two runs' checkpoints equal, bit for bit (the run resumed as if never stopped)."""
    ours, theirs = load_checkpoint(run / "checkpoint")[0], load_checkpoint(reference / "checkpoint")[0]
    assert ours.keys() == theirs.keys()
    assert [k for k in ours if not torch.equal(ours[k], theirs[k])] == []


# --- stop signals ---------------------------------------------------------------------------------------------------


def test_a_stop_signal_while_the_command_imports_is_one_line(tmp_path):
    proc = start("train", "Reacher", *FLAT, "--steps", "64", "--run-dir", str(tmp_path / "run"), cwd=tmp_path)
    wait_until(proc, lambda: handlers_installed(proc.pid), "stop handlers")
    code, output = signal_group(proc, signal.SIGINT)  # typer, rich, then torch are still being imported
    line = the_line(output, signal.SIGINT)
    assert code == 130 and line in ("stopped by SIGINT during start-up; nothing was written",
                                    "stopped by SIGINT before its first iteration was saved: there is nothing to resume, "
                                    "and the same command starts the run again"), output  # fmt: skip


def test_a_closed_terminal_while_the_sampling_workers_start_stops_them_too(tmp_path):
    run = str(tmp_path / "run")
    proc = start("train", "Reacher", *FLAT, "--steps", "64", "--workers", "2", "--run-dir", run, cwd=tmp_path)

    def workers_started() -> bool:  # the workers import torch and build their environments for a second or more
        return sum("spawn_main" in Path(f"/proc/{pid}/cmdline").read_text() for pid in group(proc.pid)) == 2

    wait_until(proc, workers_started, "sampling workers")
    code, output = signal_group(proc, signal.SIGHUP)  # signal_group checks that none of them is left
    assert code == 129 and the_line(output, signal.SIGHUP).startswith("stopped by SIGHUP before its first iteration"), output
    r = invoke("train", "Reacher", *FLAT, "--steps", "16", "--run-dir", run)  # the same command again
    assert r.exit_code == 0 and logged(tmp_path / "run") == [1], r.output


STOPS = [("train", signal.SIGINT), ("train", signal.SIGTERM), ("train-manager", signal.SIGINT),
         ("train-manager", signal.SIGTERM)]  # fmt: skip


@pytest.mark.parametrize("command,sig", STOPS, ids=[f"{c}-{signal.Signals(s).name}" for c, s in STOPS])
def test_a_stop_signal_after_the_first_checkpoint_with_two_workers_keeps_the_last_iteration_and_resumes(tmp_path, command,
                                                                                                       sig):  # fmt: skip
    run = tmp_path / "run"
    task, options = ("Reacher", FLAT) if command == "train" else ("ReachAndGrip1", MANAGER)
    nohup = (command, sig) == ("train", signal.SIGTERM)  # started with SIGHUP ignored, as nohup does: it stays ignored
    proc = start(command, task, *options, "--steps", "10000000", "--workers", "2", "--run-dir", str(run), cwd=tmp_path,
                 nohup=nohup)  # fmt: skip
    wait_until(proc, lambda: (run / "checkpoint" / "meta.json").is_file(), "first checkpoint")
    if nohup:
        os.killpg(proc.pid, signal.SIGHUP)
        time.sleep(0.5)
        assert proc.poll() is None, proc.communicate()
    code, output = signal_group(proc, sig)  # in whatever the run does then: sampling, the update, the fit or a save
    assert code == CODES[sig]
    line = the_line(output, sig)
    m = re.fullmatch(rf"stopped by {signal.Signals(sig).name} at iteration (\d+) \(([\d,]+) steps\); hrlp {command} {task} "
                     rf"--run-dir {re.escape(str(run))} --resume continues it", line)  # fmt: skip
    assert m, line
    n, steps = int(m.group(1)), int(m.group(2).replace(",", ""))
    meta = load_checkpoint(run / "checkpoint")[1]  # whole: its hash checked
    assert (meta["iteration"], meta["env_steps"]) == (n, steps) and logged(run) == list(range(1, n + 1))
    if sig == signal.SIGINT:  # (what --resume reads is checked above; the SIGINT cases resume, one iteration more;
        r = invoke(command, task, "--run-dir", str(run), "--resume", "--steps", str(steps + 1))  # to the same numbers as
        assert r.exit_code == 0, r.output  # a run never stopped: test_a_signal_during_a_save_waits_for_it_...)
        assert load_checkpoint(run / "checkpoint")[1]["iteration"] == n + 1 and logged(run) == list(range(1, n + 2))


@pytest.mark.extended  # a preset's run with the paper's settings: its first checkpoint takes most of a minute
def test_a_ctrl_c_during_a_reproduce_grid_keeps_every_runs_last_checkpoint_in_one_line(tmp_path):
    out = tmp_path / "grid"
    proc = start("reproduce", "shipped-skills", "--only", "reacher", "--seeds", "2", "--budget", "10000000", "--workers",
                 "2", "--out", str(out), cwd=tmp_path)  # fmt: skip
    wait_until(proc, lambda: len(list(out.glob("**/checkpoint/meta.json"))) == 2, "both runs' first checkpoints", 300)
    code, output = signal_group(proc, signal.SIGINT)
    assert code == 130
    line = the_line(output, signal.SIGINT)
    assert line == ("stopped by SIGINT; finished runs are kept, and the same command continues the others from their last "
                    "checkpoints"), line  # fmt: skip
    for meta in out.glob("**/checkpoint/meta.json"):  # each run whole at its last completed iteration
        run = meta.parent.parent
        assert load_checkpoint(run / "checkpoint")[1]["iteration"] == logged(run)[-1] >= 1


@pytest.mark.extended  # starting Ray takes most of a minute
def test_a_sigterm_during_a_ray_sweep_cancels_its_trials_and_keeps_their_last_checkpoints(tmp_path):
    pytest.importorskip("ray")
    out = tmp_path / "grid"
    proc = start("reproduce", "shipped-skills", "--only", "reacher", "--seeds", "2", "--budget", "10000000", "--backend",
                 "ray", "--out", str(out), cwd=tmp_path)  # fmt: skip
    wait_until(proc, lambda: len(list(out.glob("**/checkpoint/meta.json"))) == 2, "both trials' first checkpoints", 300)
    t0 = time.monotonic()
    code, output = signal_group(proc, signal.SIGTERM)
    assert code == 143 and time.monotonic() - t0 < 30, output
    assert the_line(output, signal.SIGTERM) == ("stopped by SIGTERM; finished runs are kept, and the same command continues "
                                                "the others from their last checkpoints")  # fmt: skip
    assert not session(proc.pid)  # Ray's trials and the local instance's processes are gone too
    for meta in out.glob("**/checkpoint/meta.json"):
        run = meta.parent.parent
        assert load_checkpoint(run / "checkpoint")[1]["iteration"] == logged(run)[-1] >= 1


def test_a_second_ctrl_c_while_stopping_exits_at_once(tmp_path):
    run = tmp_path / "run"
    # SlowClose takes 20 s to close: with one worker (sampling in the main process) the first Ctrl-C is still being
    # acted on, the environments closing, when the second comes.
    proc = start("train", "fault_envs:SlowClose-v0", "--batch-steps", "16", "--num-envs", "4", "--steps", "10000000",
                 "--workers", "1", "--run-dir", str(run), cwd=tmp_path)  # fmt: skip
    wait_until(proc, lambda: (run / "checkpoint" / "meta.json").is_file(), "first checkpoint")
    t0 = time.monotonic()
    code, output = signal_group(proc, signal.SIGINT, again_after_s=1.0)
    assert code == 130 and time.monotonic() - t0 < 10, output
    line = the_line(output, signal.SIGINT)
    m = re.fullmatch(r"stopped at once by a second signal \(SIGINT\) at iteration (\d+) \([\d,]+ steps\); hrlp train "
                     rf"fault_envs:SlowClose-v0 --run-dir {re.escape(str(run))} --resume continues it", line)  # fmt: skip
    assert m, line
    n = int(m.group(1))
    assert load_checkpoint(run / "checkpoint")[1]["iteration"] == n and logged(run) == list(range(1, n + 1))


def test_a_signal_during_a_save_waits_for_it_and_the_run_resumes_exactly(tmp_path):
    from save_protocol import HALF, instrument

    cfg = TrainConfig(task="Reacher", steps=48, batch_steps=16, num_envs=4, episode_steps=20)

    def signal_in_save_2(label, save, proceed):
        if label.endswith(HALF):  # (a kill point of the kill tests, not a step)
            return None
        if save == 2 and label == "write weights.safetensors":
            os.kill(os.getpid(), signal.SIGTERM)  # acted on only once the save and its log row are done
        return proceed()

    undo = instrument(signal_in_save_2)
    try:
        with handling_stop_signals(), pytest.raises(Stopped) as stopped:
            for _ in train(cfg, tmp_path / "run"):
                pass
    finally:
        undo()
    assert stopped.value.signum == signal.SIGTERM and stopped.value.exit_code == 143
    assert load_checkpoint(tmp_path / "run" / "checkpoint")[1]["iteration"] == 2 and logged(tmp_path / "run") == [1, 2]
    for _ in train(cfg, tmp_path / "run", resume=True):
        pass
    for _ in train(cfg, tmp_path / "reference"):
        pass
    assert_same_checkpoints(tmp_path / "run", tmp_path / "reference")
    assert logged(tmp_path / "run") == [1, 2, 3]


SECOND_SIGNAL_IN_A_SAVE = textwrap.dedent("""
    import os, signal, sys
    import torch
    from save_protocol import HALF, instrument, kill_config
    from hrlp.stopping import install_stop_handlers
    from hrlp.train import train

    install_stop_handlers()
    torch.set_num_threads(1)  # as the suite's process, which resumes it and trains the reference

    def two_signals(label, save, proceed):
        if label.endswith(HALF):
            return None
        if save == 2 and label in ("write weights.safetensors", "write meta.json"):
            os.kill(os.getpid(), signal.SIGINT)  # the first waits for the save; the second ends the process mid-save
        return proceed()

    instrument(two_signals)
    for _ in train(kill_config(3), sys.argv[1]):
        pass
""")


def test_a_second_signal_during_a_save_ends_at_once_and_leaves_the_previous_checkpoint_whole(tmp_path):
    from save_protocol import kill_config

    script = tmp_path / "child.py"
    script.write_text(SECOND_SIGNAL_IN_A_SAVE)
    r = subprocess.run([sys.executable, str(script), str(tmp_path / "run")], env=ENV, capture_output=True, text=True,
                       timeout=120)  # fmt: skip
    line = the_line(r.stdout + r.stderr, signal.SIGINT)
    assert r.returncode == 130 and line == "stopped at once by a second signal (SIGINT)", r.stderr
    assert load_checkpoint(tmp_path / "run" / "checkpoint")[1]["iteration"] == 1  # save 2 was cut: the first is whole
    for _ in train(kill_config(3), tmp_path / "run", resume=True):  # drops the row of iteration 2 and trains it again
        pass
    for _ in train(kill_config(3), tmp_path / "reference"):
        pass
    assert_same_checkpoints(tmp_path / "run", tmp_path / "reference")
    assert logged(tmp_path / "run") == [1, 2, 3]
    assert not list((tmp_path / "run").glob(".checkpoint.*"))  # the cut save's temporary directory was cleared


# --- a user's environment that fails --------------------------------------------------------------------------------


def test_an_environment_that_raises_at_step_30_is_named_with_its_step_and_iteration_from_a_worker(tmp_path):
    run = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "hrlp", "train", "fault_envs:Faulty-v0", "--batch-steps", "64", "--num-envs",
                        "4", "--steps", "256", "--workers", "2", "--run-dir", str(run)], cwd=tmp_path, env=ENV,
                       capture_output=True, text=True, timeout=180)  # fmt: skip
    output = r.stdout + r.stderr
    assert r.returncode == 2 and "Traceback" not in output, output
    errors = [line for line in output.splitlines() if line.startswith("error:")]
    source = TESTS / "fault_envs.py"
    lines = source.read_text().splitlines()
    raised, called = (next(n for n, line in enumerate(lines, 1) if text in line)
                      for text in ("raise RuntimeError", "self._physics()"))  # fmt: skip
    assert errors == [f"error: Faulty-v0, environment 1, step 30 of its episode, iteration 2: step() raised RuntimeError: the "
                      f"solver diverged (at {source}:{raised} in _physics <- {source}:{called} in step); the run's last "
                      "checkpoint (iteration 1, 64 steps) is intact; --resume continues it"], output  # fmt: skip
    assert load_checkpoint(run / "checkpoint")[1]["iteration"] == 1 and logged(run) == [1]


@pytest.mark.parametrize(
    "task,message",
    [("WrongShape-v0", "WrongShape-v0, environment 0, step 1 of its episode, iteration 1: step() returned an observation of "
                       "shape (5,); the observation space is Box(-inf, inf, (3,), float64) (3 numbers); nothing was saved "
                       "(the first iteration had not ended)"),
     ("OldReset-v0", "OldReset-v0, environment 0, at the reset that starts an episode: reset() must return (observation, "
                     "info); it returned an array of shape (3,), the observation alone, as the old Gym API (before 0.26) "
                     "returned it; nothing was saved")],
)  # fmt: skip
def test_an_observation_that_does_not_fit_or_the_old_reset_api_is_named(tmp_path, task, message):
    import fault_envs  # noqa: F401 - registers the ids

    r = invoke("train", f"fault_envs:{task}", "--batch-steps", "16", "--num-envs", "4", "--steps", "16", "--run-dir",
               str(tmp_path / "run"))  # fmt: skip
    assert r.exit_code == 2 and r.output.splitlines()[-1] == f"error: {message}", r.output


def test_the_vector_environment_names_a_step_that_returns_the_old_four_values():
    class FourValues(gym.Env):
        observation_space = gym.spaces.Box(-1, 1, (2,))
        action_space = gym.spaces.Box(-1, 1, (1,))

        def reset(self, *, seed=None, options=None):
            return np.zeros(2), {}

        def step(self, action):
            return np.zeros(2), 0.0, False, {}

    vec = SerialVectorEnv([FourValues(), FourValues()])
    vec.reset(seed=0)
    with pytest.raises(EnvError, match=r"^FourValues, environment 0: step\(\) must return \(observation, reward, terminated, "
                                       r"truncated, info\); it returned a tuple of 4 values \(the old Gym API's observation, "
                                       r"reward, done, info\)$"):  # fmt: skip
        vec.step(np.zeros((2, 1)))


# --- progress lines and the run's files ------------------------------------------------------------------------------


def test_a_progress_line_shows_a_dash_where_no_episode_ended():
    stats = {"iteration": 1, "env_steps": 16, "return_mean": float("nan"), "success_rate": float("nan"), "trpo/kl": 0.01,
             "time/steps_per_s": 500.0}  # fmt: skip
    line = progress_line("train Reacher", stats, 64, 3.0)
    assert line == "train Reacher: iteration 1, 16/64 steps (25%), return -, kl 0.0100, 500 steps/s, 3 s"


def test_a_damaged_progress_csv_blocks_resume_with_its_file_and_line(tmp_path):
    run = tmp_path / "run"
    assert invoke("train", "Reacher", *FLAT, "--steps", "32", "--run-dir", str(run)).exit_code == 0
    with (run / "progress.csv").open("a") as f:
        f.write("garbage\n")
    r = invoke("train", "Reacher", "--run-dir", str(run), "--resume", "--steps", "48")
    assert r.exit_code == 2 and r.output.splitlines() == [
        f"error: {run / 'progress.csv'}, line 4: 'garbage' where an iteration number belongs; the log is damaged: repair or "
        "remove that line"]  # fmt: skip


def test_no_test_starts_the_cli_by_its_bare_name():
    bare = re.compile(r"""(Popen|run|check_output|check_call|call)\(\s*\[\s*["']hrlp["']""")
    found = [f"{p.relative_to(TESTS)}" for p in TESTS.rglob("*.py") if bare.search(p.read_text())]
    assert not found, f"start the CLI as [sys.executable, '-m', 'hrlp', ...]: {found}"
