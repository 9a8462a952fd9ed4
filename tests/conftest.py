"""Shared test settings: one torch thread (faster on these tiny networks), quiet logs."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

try:
    import torch

    torch.set_num_threads(1)
except ImportError:  # pragma: no cover - torch is a core dependency
    pass

from param_envs import register

register()
