"""Progress of long evaluations: the callback of evaluate_run, its log lines, and `hrlp eval` with stderr in a file."""

import io
import subprocess
import sys

import pytest
from rich.console import Console

from hrlp.evaluate import EvalProgress, ProgressLines, evaluate_run, evaluate_with_progress, progress_line
from hrlp.train import TrainConfig, train


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """16 steps of Reacher: a real run to evaluate."""
    run = tmp_path_factory.mktemp("eval") / "run"
    list(train(TrainConfig(task="Reacher", steps=16, batch_steps=16, num_envs=2, episode_steps=10), run))
    return run


def test_the_callback_reports_monotone_progress_ending_at_the_total(tiny_run):
    seen: list[EvalProgress] = []
    ev = evaluate_run(tiny_run, episodes=5, on_progress=seen.append)
    assert [p.done for p in seen] == [1, 2, 3, 4, 5] and all(p.total == 5 for p in seen)
    last = seen[-1]
    assert last.return_mean == pytest.approx(ev.ret.mean) and last.success_rate == pytest.approx(ev.success.mean)
    assert all(0 <= p.success_rate <= 1 for p in seen) and last.target_dist_sum is None  # Reacher has no TargetDistSum
    assert evaluate_run(tiny_run, episodes=5) == ev  # the callback changes nothing


def test_progress_lines_come_every_tenth_every_interval_and_at_the_end():
    def lines(total, **kw):
        out: list[str] = []
        report = ProgressLines("eval r", out.append, **kw)
        for done in range(1, total + 1):
            report(EvalProgress(done, total, -float(done), done / total))
        return out

    by_tenth = lines(1000, interval_s=None)
    assert len(by_tenth) == 10 and by_tenth[0].startswith("eval r: 100/1,000 episodes (10%), return -100.0, success 0.10, ")
    assert by_tenth[-1].startswith("eval r: 1,000/1,000 episodes (100%), return -1000.0, success 1.00, ")
    assert len(lines(7, interval_s=None)) == 7  # ceil(7 / 10) = 1: a line per episode
    assert len(lines(50, every=0, interval_s=None)) == 1  # only the last
    assert len(lines(50, every=0, interval_s=0.0)) == 50  # the interval always passed: every episode
    line = progress_line("eval r", EvalProgress(3, 4, -2.5, None, -41.25), elapsed_s=2.0)
    assert line == "eval r: 3/4 episodes (75%), return -2.5, TargetDistSum -41.2, 1.5 episodes/s, 2 s"


def test_progress_written_to_a_file_is_lines_not_a_bar(tiny_run):
    log = io.StringIO()  # not a terminal
    ev = evaluate_with_progress(tiny_run, episodes=20, console=Console(file=log), description="eval [run]")
    lines = log.getvalue().splitlines()
    assert len(lines) == 10 and lines[0].startswith("eval [run]: 2/20 episodes (10%), return ")  # markup left alone
    assert lines[-1].startswith("eval [run]: 20/20 episodes (100%), return ") and ev.episodes == 20


def test_cli_eval_with_stderr_in_a_file_shows_progress_lines(tiny_run, tmp_path):
    err = tmp_path / "stderr.log"
    with err.open("w") as f:
        r = subprocess.run([sys.executable, "-m", "hrlp", "eval", str(tiny_run), "--episodes", "30"], stdout=subprocess.PIPE,
                           stderr=f, text=True, timeout=300)  # fmt: skip
    assert r.returncode == 0 and "success rate (95% Wilson CI)" in r.stdout, err.read_text()
    lines = err.read_text().splitlines()
    done = [int(line.split(": ")[1].split("/")[0]) for line in lines]
    # Every tenth of the episodes (and, on a slow machine, a line whenever 10 s pass without one), ending at the total.
    assert set(range(3, 31, 3)) <= set(done) and done == sorted(set(done)) and done[-1] == 30, lines
    assert all(line.startswith(f"eval {tiny_run}: ") and "/30 episodes (" in line and ", success " in line for line in lines)
