"""Proximal Policy Optimization (Schulman et al. 2017) over the :class:`~hrlp.policies.distributions.Distribution`
interface: the paper's "any optimisation algorithm" (Section 3.1) beside TRPO.

The clipped surrogate is maximised by minibatch Adam steps over several epochs. After every epoch the exact mean
KL(old || new) over the whole batch is measured with the distribution's own ``kl``; for the Manager's
:class:`~hrlp.policies.distributions.Hierarchical` that is Lemma 1's KL(categorical) + sum_k p_k KL(Gaussian_k), so
the early stop (``target_kl``) bounds the same divergence TRPO's trust region does. Like :func:`trpo_update`, only
the tensors in ``policy_params`` move.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from hrlp.algos.kernels import standardize
from hrlp.config import PPOConfig  # torch-free (for `hrlp --help`); importable from here too
from hrlp.policies.distributions import Distribution

__all__ = ["PPOConfig", "PPOStats", "clipped_surrogate", "ppo_update"]


@dataclass(frozen=True)
class PPOStats:
    """What one :func:`ppo_update` did; every field is a plain number, ready for a logger."""

    kl: float
    """Exact mean KL(old || new) over the batch after the update."""
    kl_max: float
    """Largest per-state KL(old || new) after the update."""
    surrogate_before: float
    """Clipped surrogate at the old parameters (= mean advantage, + entropy bonus)."""
    surrogate_after: float
    """Clipped surrogate over the whole batch at the final parameters."""
    epochs: int
    """Epochs run (fewer than configured when the KL early stop fired)."""
    early_stopped: bool
    """Whether the KL early stop ended the update."""
    clip_fraction: float
    """Share of the batch whose ratio lies outside [1 - clip, 1 + clip] after the update."""
    entropy_before: float
    """Mean policy entropy over the batch before the update."""
    entropy: float
    """Mean policy entropy over the batch after the update."""
    grad_norm: float
    """Mean over minibatch steps of the gradient norm before clipping."""

    def to_dict(self) -> dict[str, float | int | bool]:
        """Fields as a flat dict (for CSV/JSONL/TensorBoard loggers)."""
        return dataclasses.asdict(self)


def clipped_surrogate(
    dist: Distribution, actions: Tensor, old_log_prob: Tensor, advantages: Tensor, clip: float, entropy_coef: float = 0.0
) -> Tensor:
    """PPO's objective ``mean_b min(r_b A_b, clip(r_b, 1 - eps, 1 + eps) A_b)`` (+ entropy bonus), to be maximised.

    Args:
        dist: current policy on ``B`` states; actions ``[B, ...]`` in its encoding; old_log_prob ``[B]`` (detached);
        advantages ``[B]``; clip: epsilon; entropy_coef: weight of ``mean_b H(pi(.|s_b))``.
    """
    ratio = torch.exp(dist.log_prob(actions) - old_log_prob)
    objective = torch.minimum(ratio * advantages, ratio.clamp(1.0 - clip, 1.0 + clip) * advantages).mean()
    if entropy_coef:
        objective = objective + entropy_coef * dist.entropy().mean()
    return objective


def ppo_update(
    policy_params: Sequence[Tensor],
    dist_fn: Callable[[Tensor | None], Distribution],
    old_dist: Distribution,
    actions: Tensor,
    advantages: Tensor,
    optimizer: torch.optim.Optimizer,
    cfg: PPOConfig | None = None,
    generator: torch.Generator | None = None,
) -> PPOStats:
    """One PPO update in place on ``policy_params``: ``cfg.epochs`` shuffled passes of minibatch steps of
    ``optimizer`` (built over ``policy_params``; its state, e.g. Adam's moments, carries over between updates)
    on the clipped surrogate, stopping after an epoch whose exact mean KL(old || new) exceeds ``cfg.target_kl``.

    Args:
        dist_fn: the policy's distribution on the batch's states at the given indices (``None``: every state), from
            the current parameter values, e.g. ``lambda i: policy(obs if i is None else obs[i])``.
        old_dist: the distribution that generated the data, on every state.
        actions: ``[B, ...]``; advantages: ``[B]`` (standardised here if ``cfg.normalize_advantages``).
        generator: the minibatch shuffle's random source (a seeded one makes the update reproducible).
    """
    cfg = cfg or PPOConfig()
    params = list(policy_params)
    if not params or not all(p.requires_grad for p in params):
        raise ValueError("policy_params must be a non-empty list of tensors that require grad")
    old_dist = old_dist.detach()
    adv = advantages.detach().reshape(-1)
    if cfg.normalize_advantages:
        adv = standardize(adv)
    n = adv.shape[0]
    if n < cfg.minibatches:
        raise ValueError(f"PPO needs at least as many states as minibatches ({cfg.minibatches}), got a batch of {n}")
    old_log_prob = old_dist.log_prob(actions).detach()
    with torch.no_grad():
        surrogate_before = float(clipped_surrogate(dist_fn(None), actions, old_log_prob, adv, cfg.clip, cfg.entropy_coef))
        entropy_before = float(old_dist.entropy().mean())
    grad_norms: list[float] = []
    epochs, stopped = 0, False
    for _ in range(cfg.epochs):
        order = torch.randperm(n, generator=generator)
        for idx in order.tensor_split(cfg.minibatches):
            loss = -clipped_surrogate(dist_fn(idx), actions[idx], old_log_prob[idx], adv[idx], cfg.clip, cfg.entropy_coef)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            norm = torch.nn.utils.clip_grad_norm_(params, cfg.max_grad_norm if cfg.max_grad_norm else math.inf)
            grad_norms.append(float(norm))
            optimizer.step()
        epochs += 1
        if cfg.target_kl:
            with torch.no_grad():
                if float(old_dist.kl(dist_fn(None)).mean()) > cfg.target_kl:
                    stopped = True
                    break
    with torch.no_grad():
        new_dist = dist_fn(None)
        kl = old_dist.kl(new_dist)
        ratio = torch.exp(new_dist.log_prob(actions) - old_log_prob)
        return PPOStats(
            kl=float(kl.mean()),
            kl_max=float(kl.max()),
            surrogate_before=surrogate_before,
            surrogate_after=float(clipped_surrogate(new_dist, actions, old_log_prob, adv, cfg.clip, cfg.entropy_coef)),
            epochs=epochs,
            early_stopped=stopped,
            clip_fraction=float(((ratio - 1.0).abs() > cfg.clip).float().mean()),
            entropy_before=entropy_before,
            entropy=float(new_dist.entropy().mean()),
            grad_norm=sum(grad_norms) / len(grad_norms),
        )
