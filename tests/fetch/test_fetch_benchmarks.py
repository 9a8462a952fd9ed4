"""The Fetch benchmark scripts run end to end at tiny budgets (their figures come from full runs: docs/fetch.md), on a
MuJoCo Gymnasium-Robotics' Fetch runs on (skipped elsewhere, saying so; CI's Fetch pass runs them)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import mujoco
import pytest

pytest.importorskip("gymnasium_robotics")
if tuple(int(v) for v in mujoco.__version__.split(".")[:2]) >= (3, 12):
    pytest.skip(f"Gymnasium-Robotics' Fetch fails at reset on mujoco {mujoco.__version__} (>= 3.12)", allow_module_level=True)
pytestmark = pytest.mark.extended

ROOT = Path(__file__).resolve().parents[2]


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=600, cwd=ROOT)


def test_fetch_her_runs_each_method_writes_its_results_and_skips_finished_runs_and_the_report_reads_them(tmp_path):
    out = tmp_path / "pick.json"
    args = ("benchmarks/fetch_her.py", "--task", "PickAndPlace", "--methods", "manager,sb3", "--steps", "200",
            "--seeds", "1", "--eval-every", "200", "--eval-episodes", "2", "--out", str(out))  # fmt: skip
    r = _run(*args)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(out.read_text())
    assert set(res["runs"]) == {"manager-0", "sb3-0"} and res["skill_steps"] == 30_000
    assert all(run["curve"] and 0 <= run["curve"][-1][1] <= 1 for run in res["runs"].values())
    again = _run(*args)  # everything is in --out already: nothing trains
    assert again.returncode == 0 and "steps, greedy success" not in again.stdout, again.stdout
    page = tmp_path / "fetch.md"
    r = _run("benchmarks/fetch_report.py", str(out), "--out", str(page))
    assert r.returncode == 0, r.stderr
    text = page.read_text()
    assert "## FetchPickAndPlace-v4" in text and "hrlp Manager" in text and "Stable-Baselines3 SAC + HER" in text
    assert _run("benchmarks/fetch_report.py", str(out), "--out", str(page)).returncode == 2  # never overwrites unasked


def test_an_hrlp_run_stopped_part_way_continues_from_its_checkpoint_and_its_evaluations(tmp_path):
    base = ("benchmarks/fetch_her.py", "--task", "Push", "--methods", "sac", "--seeds", "1", "--eval-every", "2000",
            "--eval-episodes", "2", "--workdir", str(tmp_path / "runs"))  # fmt: skip
    first = _run(*base, "--steps", "2000", "--out", str(tmp_path / "a.json"))  # as a run stopped after 2,000 steps leaves it
    assert first.returncode == 0, first.stderr[-3000:]
    later = _run(*base, "--steps", "4000", "--out", str(tmp_path / "b.json"))
    assert later.returncode == 0, later.stderr[-3000:]
    assert "continuing" in later.stdout and "2,000 steps, greedy success" not in later.stdout, later.stdout
    assert [s for s, _ in json.loads((tmp_path / "b.json").read_text())["runs"]["sac-0"]["curve"]] == [2000, 4000]


def test_fetch_speed_compares_hrlp_and_sb3_sampling_and_records_the_run(tmp_path):
    r = _run("benchmarks/fetch_speed.py", "--task", "Push", "--num-envs", "2", "--steps", "200", "--runs-dir", str(tmp_path))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "hrlp VectorEnv:" in r.stdout and "SB3 DummyVecEnv:" in r.stdout and "hrlp / SB3:" in r.stdout
    (run,) = tmp_path.glob("fetch_speed-*.json")
    figures = json.loads(run.read_text())["figures"]
    assert figures["task"] == "FetchPush-v4" and figures["hrlp_over_sb3"] > 0


def test_the_report_says_when_the_managers_first_evaluation_already_reached_0_9():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from fetch_report import report

    runs = {f"manager-{s}": {"method": "manager", "seed": s, "curve": [[1000, 0.95], [2000, 0.8]], "wall_s": 1.0,
                             "steps_to_0.9": 1000} for s in range(3)}  # fmt: skip
    res = {"task": "Push", "steps": 2000, "eval_every": 1000, "eval_episodes": 100, "skill_steps": 0, "runs": runs}
    text = report([res])
    assert "| 0.80, 0.80, 0.80 | 0.95, 0.95, 0.95 | 1,000, 1,000, 1,000 |" in text
    assert "Every Manager reached 0.9 at its first evaluation" in text and "**not met** (0.800 over 3 seed(s))" in text
    runs["manager-0"]["steps_to_0.9"] = 2000
    assert "Every Manager reached 0.9" not in report([res])
