"""``hrlp runs``: run directories found and summarised from their files alone, beside running trainers."""

import json
import shutil

import pytest

from hrlp.atomic import directory_lock
from hrlp.runs import find_runs, read_run
from hrlp.train import TrainConfig, train

TINY = {"steps": 400, "batch_steps": 200, "num_envs": 4, "episode_steps": 30}


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("runs")
    for _ in train(TrainConfig(task="Reacher", **TINY), root / "reacher"):
        pass
    return root


def test_runs_are_found_with_task_steps_success_and_state(trained, tmp_path):
    root = tmp_path / "root"
    shutil.copytree(trained, root)
    shutil.copytree(root / "reacher", root / "nested" / "longer")
    cfg = json.loads((root / "nested" / "longer" / "config.json").read_text())
    (root / "nested" / "longer" / "config.json").write_text(json.dumps({**cfg, "steps": 800}))  # asked for more
    (root / "not-a-run").mkdir()
    runs = find_runs(root)
    assert [r.path.relative_to(root).as_posix() for r in runs] == ["nested/longer", "reacher"]
    longer, reacher = runs
    assert (reacher.task, reacher.steps, reacher.budget, reacher.state) == ("Reacher", 400, 400, "finished")
    assert reacher.train_success is not None and 0 <= reacher.train_success <= 1 and reacher.eval_success is None
    assert (longer.steps, longer.budget, longer.state) == (400, 800, "stopped")
    with directory_lock(root / "reacher"):  # a trainer holds it
        assert read_run(root / "reacher").state == "running"
    assert read_run(root / "reacher").state == "finished"


def test_a_broken_run_is_listed_with_its_problem_and_the_others_still_are(trained, tmp_path):
    root = tmp_path / "root"
    shutil.copytree(trained / "reacher", root / "good")
    shutil.copytree(trained / "reacher", root / "bad")
    (root / "bad" / "config.json").write_text("{not json")
    bad, good = find_runs(root)
    assert bad.problem is not None and bad.problem.startswith("config.json:") and bad.task == "?"
    assert good.problem is None and good.task == "Reacher"
    with pytest.raises(ValueError, match="no such directory"):
        find_runs(tmp_path / "missing")


def test_hrlp_runs_prints_one_whole_line_per_run_and_version_prints_the_package_version(trained, tmp_path):
    import subprocess
    import sys
    import tomllib
    from pathlib import Path

    import hrlp

    root = tmp_path / "root"
    shutil.copytree(trained / "reacher", root / "a" / "very-long-run-name-that-a-terminal-table-would-cut" / "s0")
    out = subprocess.run([sys.executable, "-m", "hrlp", "runs", str(root)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    header, row, total = out.stdout.splitlines()
    assert header.split() == ["run", "task", "steps", "train", "success", "eval", "success", "state"]
    assert row.startswith("a/very-long-run-name-that-a-terminal-table-would-cut/s0  ") and row.split()[1:3] == [
        "Reacher",
        "400/400",
    ]
    assert row.endswith("finished") and total == f"1 run under {root}"
    missing = subprocess.run([sys.executable, "-m", "hrlp", "runs", str(tmp_path / "nope")], capture_output=True, text=True)
    assert missing.returncode == 2 and missing.stderr.strip() == f"error: {tmp_path / 'nope'}: no such directory"
    version = subprocess.run([sys.executable, "-m", "hrlp", "--version"], capture_output=True, text=True, timeout=60)
    pyproject = tomllib.loads((Path(hrlp.__file__).parents[2] / "pyproject.toml").read_text())
    assert version.stdout == f"hrlp {hrlp.__version__}\n" and hrlp.__version__ == pyproject["project"]["version"]
