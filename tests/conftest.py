"""Shared test settings: one torch thread (faster on these tiny networks), quiet logs, and runs that leave their
sampling workers to the machine (TrainConfig's default) sample in the test's own process: no worker processes start
unless a test asks for them (``workers=2``), whatever the cores (the suite stays within CI's time)."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ["HRLP_WORKERS"] = "1"  # hrlp.config.WORKERS_VARIABLE; subprocesses the tests start inherit it

try:
    import torch

    torch.set_num_threads(1)
except ImportError:  # pragma: no cover - torch is a core dependency
    pass

from param_envs import register

register()
