"""Tiny networks run fastest on one intra-op thread (benchmarks/policy_call.py: a call on 64 observations took 1.84x
as long with two)."""

import torch

torch.set_num_threads(1)
