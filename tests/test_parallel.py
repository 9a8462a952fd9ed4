"""Sampling in worker processes: same batch layout as in-process sampling, exact resume, errors surface."""

import functools
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from hrlp.arm import make
from hrlp.policies.mlp import GaussianPolicy
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.rollout import ParallelSampler, Sampler
from hrlp.train import TrainConfig, train


def test_workers_sample_the_same_environments_as_one_process():
    factory = functools.partial(make, "Reacher", episode_steps=20)
    policy = GaussianPolicy(27, 9)
    one = Sampler([factory] * 4, policy, RunningNormalizer(27), seed=5)
    par = ParallelSampler([factory] * 4, policy, RunningNormalizer(27), seed=5, workers=2)
    try:
        b1, e1 = one.collect(30)
        b2, e2 = par.collect(30)
        assert b1.obs.shape == b2.obs.shape == (30, 4, 27) and b1.env_steps == b2.env_steps == 120
        # Environment i starts from seed 5 + i in both; the action noise differs (one generator per worker).
        np.testing.assert_array_equal(one.last_raw_obs[0], par.last_raw_obs[0])
        assert len(e1) == len(e2) == 4  # episodes of 20 steps
        assert par.normalizer.count == pytest.approx(120)  # updated here with every raw observation
        assert not torch.equal(b1.actions, b2.actions)
        # Time inside mj_step is counted in every environment, the workers' summed: part of the time stepping them.
        for sampler in (one, par):
            assert 0 < sampler.timing.physics < sampler.timing.env * 2
        assert 0 < one.timing.physics < one.timing.env
    finally:
        one.close()
        par.close()


def test_parallel_training_resumes_exactly(tmp_path):
    cfg = TrainConfig(task="Gripper", steps=240, batch_steps=80, num_envs=4, workers=2, episode_steps=25, seed=2)
    full = list(train(cfg, tmp_path / "full"))
    part = list(train(TrainConfig(**{**cfg.__dict__, "steps": 80}), tmp_path / "part"))
    rest = list(train(cfg, tmp_path / "part", resume=True))
    assert len(full) == len(part) + len(rest) == 3
    for a, b in zip(full, part + rest, strict=True):
        for key in ("return_mean", "trpo/kl", "trpo/surrogate_after", "value/explained_variance_after"):
            assert a[key] == b[key] or (np.isnan(a[key]) and np.isnan(b[key])), key


def test_a_failing_worker_raises_its_error():
    bad = functools.partial(make, "Reacher", episode_steps=-1)
    with pytest.raises(RuntimeError, match="sampler worker failed: ValueError"):
        ParallelSampler([bad] * 2, GaussianPolicy(27, 9), RunningNormalizer(27), workers=2)
    with pytest.raises(ValueError, match="workers"):
        TrainConfig(task="Reacher", num_envs=2, workers=3)


_ORPHAN_SCRIPT = """
import functools, os, signal, sys
from hrlp.arm import make
from hrlp.policies.mlp import GaussianPolicy
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.rollout import ParallelSampler
sampler = ParallelSampler([functools.partial(make, "Reacher", episode_steps=20)] * 2, GaussianPolicy(27, 9),
                          RunningNormalizer(27), workers=2)
sampler.request(10_000_000)  # minutes of sampling: the workers are busy when this process dies
open(sys.argv[1], "w").write(" ".join(str(p.pid) for p in sampler._procs))
os.kill(os.getpid(), signal.SIGKILL)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_workers_die_with_a_killed_trainer(tmp_path):
    # A trainer killed with SIGKILL in the middle of a batch used to leave its workers sampling until the batch ended.
    pid_file = tmp_path / "pids"
    with open(tmp_path / "stderr", "w") as err:  # a file, not a pipe: orphans holding a pipe would stall the test
        out = subprocess.run([sys.executable, "-c", _ORPHAN_SCRIPT, str(pid_file)], stdout=subprocess.DEVNULL,
                             stderr=err, timeout=120)  # fmt: skip
    assert out.returncode == -signal.SIGKILL, (tmp_path / "stderr").read_text()
    pids = [int(p) for p in pid_file.read_text().split()]
    assert len(pids) == 2
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.1)
    alive = [p for p in pids if _alive(p)]
    for p in alive:
        os.kill(p, signal.SIGKILL)
    assert not alive, f"workers {alive} outlived their killed trainer"


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"  # a zombie has exited
    except FileNotFoundError:
        return False
