"""A full disk or a read-only directory gives one line naming the path, never an OSError traceback, and the previous
checkpoint stays intact (docs/reliability.md, item 9)."""

import os
import resource
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from hrlp.checkpoint import load_checkpoint
from hrlp.cli import app
from hrlp.train import TrainConfig, train

FLAT = ["--batch-steps", "16", "--num-envs", "4", "--episode-steps", "20"]
FILE_SIZE_LIMIT = 8192
"""Bytes a file may grow to in the limited process: more than its config and log need, less than a checkpoint's weights
(the kernel then fails the write with EFBIG, as a full disk fails it with ENOSPC; Python ignores SIGXFSZ)."""


def _limit_file_size() -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (FILE_SIZE_LIMIT, FILE_SIZE_LIMIT))


def test_a_full_disk_while_saving_gives_one_line_and_keeps_the_previous_checkpoint(tmp_path):
    run = tmp_path / "run"
    list(train(TrainConfig(task="Reacher", steps=16, batch_steps=16, num_envs=4, episode_steps=20), run))
    weights = (run / "checkpoint" / "weights.safetensors").read_bytes()
    assert len(weights) > FILE_SIZE_LIMIT
    r = subprocess.run([sys.executable, "-m", "hrlp", "train", "Reacher", "--run-dir", str(run), "--resume", "--steps", "32"],
                       capture_output=True, text=True, timeout=300, preexec_fn=_limit_file_size)  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr + r.stdout, r.stderr
    errors = [line for line in r.stderr.splitlines() if "error" in line.lower()]
    assert errors == [f"error: cannot write {run / 'checkpoint'}: File too large (the previous checkpoint is unchanged)"]
    assert (run / "checkpoint" / "weights.safetensors").read_bytes() == weights
    assert load_checkpoint(run / "checkpoint")[1]["iteration"] == 1
    assert not list(run.glob(".checkpoint.*"))  # the half-written new checkpoint was removed


@pytest.fixture
def read_only_dir(tmp_path):
    """A directory this process cannot write to: mode 0555, or (as root, which ignores modes) a read-only tmpfs."""
    d = tmp_path / "read-only"
    d.mkdir()
    if os.geteuid() != 0:
        d.chmod(0o555)
        yield d
        d.chmod(0o755)
        return
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(d)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip("running as root without the right to mount a read-only file system")
    try:
        yield d
    finally:
        subprocess.run(["umount", str(d)], check=True)


def test_a_read_only_directory_gives_one_line_naming_the_path(read_only_dir):
    runner = CliRunner()
    r = runner.invoke(app, ["train", "Reacher", *FLAT, "--steps", "16", "--run-dir", str(read_only_dir / "run")])
    assert r.exit_code == 2, r.output
    lines = [line for line in r.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"error: cannot write {read_only_dir / 'run'}: "), r.output
    assert lines[0].endswith(("Read-only file system", "Permission denied")), r.output
    r = runner.invoke(app, ["tables", "--root", str(read_only_dir), "--out", str(read_only_dir / "t")])
    assert r.exit_code == 2 and "no finished runs" in r.output  # reading needs no write access
