"""docs/tutorial-skills.md runs as written: its three files, each shell command and the SB3 training script, in a fresh
directory. The default suite cuts the budgets (the commands work, the files they name exist, the Manager composes the
three kinds of skills); the slow test runs the page as written and checks the figures it quotes (the Manager learns)."""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[1] / "docs" / "tutorial-skills.md"
FILES = ("plane_env.py", "train_sb3.py", "my_skills.py")  # the page's Python blocks, in order


def _blocks(kind: str) -> list[str]:
    return re.findall(rf"```{kind}\n(.*?)```", DOC.read_text(), flags=re.S)


def _short(text: str) -> str:
    """The page's budgets cut: a few thousand steps of each training, 20 evaluation episodes."""
    text = re.sub(r"--steps \d+", "--steps 4000", text)
    text = re.sub(r"total_timesteps=[\d_]+", "total_timesteps=256", text)
    return re.sub(r"--episodes \d+", "--episodes 20", text)


def test_the_skills_tutorial_runs(tmp_path):
    _run_tutorial(tmp_path, full=False)


@pytest.mark.slow
def test_the_skills_tutorial_runs_as_written(tmp_path):
    _run_tutorial(tmp_path, full=True)


def _run_tutorial(tmp_path: Path, full: bool) -> None:
    pytest.importorskip("stable_baselines3")
    files = _blocks("python")
    assert len(files) == len(FILES)
    for name, text in zip(FILES, files, strict=True):
        (tmp_path / name).write_text(text if full else _short(text))
    environ = {**os.environ, "PYTHONPATH": os.pathsep.join([".", os.environ.get("PYTHONPATH", "")])}

    def run(words: list[str]) -> str:
        r = subprocess.run(words, cwd=tmp_path, env=environ, capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, f"{words}\n{r.stderr}"
        return r.stdout + r.stderr

    first, second = _blocks("bash")
    for line in filter(None, (raw.strip() for raw in first.splitlines())):
        run(_command(line, full))
    run([sys.executable, "train_sb3.py"])
    outputs = [run(_command(line, full)) for line in filter(None, (raw.strip() for raw in second.splitlines()))]
    _, eval_out, _, runs_out = outputs
    success = float(re.search(r"success rate \(95% Wilson CI\): ([\d.]+)", eval_out).group(1))
    shares = dict(re.findall(r"(\w+) (\d+)%", eval_out.split("decisions per macro-action:")[1]))
    assert set(shares) == {"reach", "sb3_reach", "home_in"}, eval_out
    if full:  # the page quotes 1.00 [0.963, 1]
        assert success >= 0.95, eval_out
    assert (tmp_path / "plane.mp4").stat().st_size > 0
    assert (tmp_path / "skills" / "reach" / "meta.json").is_file()
    assert re.search(r"manager\s+plane_env:Plane-v0 \[reach, my_skills:sb3_reach, my_skills:home_in\]", runs_out), runs_out


def _command(line: str, full: bool) -> list[str]:
    words = shlex.split(line if full else _short(line))
    if words[0].startswith("PYTHONPATH="):
        words = words[1:]  # the test sets it (to '.' and the suite's own path) for every command
    assert words[0] == "hrlp", line
    return [sys.executable, "-m", "hrlp", *words[1:]]
