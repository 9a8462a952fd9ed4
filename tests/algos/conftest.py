"""Tiny networks run fastest on one intra-op thread (PERFORMANCE.md: 2-5x slower with two)."""

import torch

torch.set_num_threads(1)
