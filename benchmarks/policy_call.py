"""What one policy call costs: why hrlp batches its policy calls over environments and runs small networks on one
torch thread. Times a 64 x 64 Gaussian policy's action (``Policy.act_numpy``, no grad) for a batch of 1 and of 64
observations, the same network as a frozen NumPy copy (``NumpyMLP``) on one observation, and the batch of 64 with two
intra-op threads; ratios are within one run.

    python benchmarks/policy_call.py [--obs-dim 24] [--act-dim 9] [--calls 2000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from hrlp.policies.mlp import GaussianPolicy, NumpyMLP


def per_call(fn, calls: int) -> float:
    """Mean seconds per call of ``fn`` over ``calls`` calls, after 50 warm-up calls."""
    for _ in range(50):
        fn()
    t0 = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - t0) / calls


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--obs-dim", type=int, default=24)
    ap.add_argument("--act-dim", type=int, default=9)
    ap.add_argument("--calls", type=int, default=2000)
    args = ap.parse_args()
    policy = GaussianPolicy(args.obs_dim, args.act_dim, (64, 64))
    gen = torch.Generator().manual_seed(0)
    one, batch = np.zeros((1, args.obs_dim)), np.zeros((64, args.obs_dim))
    frozen = NumpyMLP(policy.mean_net)
    torch.set_num_threads(1)
    t_one = per_call(lambda: policy.act_numpy(one, gen), args.calls)
    t_batch = per_call(lambda: policy.act_numpy(batch, gen), args.calls)
    t_numpy = per_call(lambda: frozen(one[0]), args.calls)
    torch.set_num_threads(2)
    t_two = per_call(lambda: policy.act_numpy(batch, gen), args.calls)
    print(f"torch call, 1 observation:          {t_one * 1e3:.3f} ms")
    print(f"torch call, 64 observations:        {t_batch * 1e3:.3f} ms  ({64 * t_one / t_batch:.1f}x the actions per second)")
    print(f"NumPy copy, 1 observation:          {t_numpy * 1e3:.3f} ms  ({t_one / t_numpy:.1f}x faster than torch)")
    print(f"torch call, 64 observations, 2 threads: {t_two * 1e3:.3f} ms  ({t_two / t_batch:.2f}x the one-thread time)")


if __name__ == "__main__":
    main()
