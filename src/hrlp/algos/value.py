"""Fitting the value-function baseline V(s) used by GAE.

modular_rl (the paper's framework) fits its neural baseline by full-batch L-BFGS on the mean squared error plus a
small L2 penalty, 25 iterations per policy iteration (``NnRegression`` in modular_rl/core.py); this module does the
same with ``torch.optim.LBFGS`` and a strong-Wolfe line search, so the fit has no learning rate to tune and is
deterministic given the batch. The value network is its own module, never part of the policy's trust region.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from hrlp.algos.kernels import explained_variance
from hrlp.config import ValueFitConfig  # torch-free (for `hrlp --help`); importable from here as before

__all__ = ["ValueFitConfig", "ValueFitStats", "fit_value"]


@dataclass(frozen=True)
class ValueFitStats:
    """What one :func:`fit_value` did."""

    explained_variance_before: float
    """``1 - Var[R - V] / Var[R]`` before the fit (how well the old baseline predicts the new returns)."""
    explained_variance_after: float
    """The same after the fit (nan when the targets are constant)."""
    mse_before: float
    """Mean squared error before the fit."""
    mse_after: float
    """Mean squared error after the fit."""
    loss_evaluations: int
    """Number of loss/gradient evaluations L-BFGS used."""


def fit_value(value_net: nn.Module, obs: Tensor, targets: Tensor, cfg: ValueFitConfig | None = None) -> ValueFitStats:
    """Fit ``value_net`` to regression ``targets`` by full-batch L-BFGS on ``mean (V(s) - R)^2 + l2 sum ||w||^2``.

    Args:
        value_net: module mapping ``[B, obs_dim]`` to ``[B]`` (e.g. :class:`hrlp.policies.mlp.ValueNet`); all its
            parameters that require grad are fitted, in place.
        obs: ``[B, obs_dim]`` inputs (normalised the same way as when the baseline is evaluated).
        targets: ``[B]`` value targets, e.g. GAE returns ``A + V``.
        cfg: settings; ``ValueFitConfig()`` if ``None``.
    """
    cfg = cfg or ValueFitConfig()
    params = [p for p in value_net.parameters() if p.requires_grad]
    obs, targets = obs.detach(), targets.detach().reshape(-1)
    with torch.no_grad():
        pred_before = value_net(obs).reshape(-1)
    evaluations = 0

    def closure() -> Tensor:
        nonlocal evaluations
        evaluations += 1
        optimizer.zero_grad(set_to_none=True)
        mse = (value_net(obs).reshape(-1) - targets).square().mean()
        loss = mse + cfg.l2_coef * sum(p.square().sum() for p in params)
        loss.backward()
        return loss

    optimizer = torch.optim.LBFGS(
        params, lr=1.0, max_iter=cfg.max_iter, history_size=cfg.history_size, line_search_fn="strong_wolfe"
    )
    optimizer.step(closure)
    optimizer.zero_grad(set_to_none=True)  # leave no stale .grad behind on the value net
    with torch.no_grad():
        pred_after = value_net(obs).reshape(-1)
    return ValueFitStats(
        explained_variance_before=explained_variance(pred_before, targets),
        explained_variance_after=explained_variance(pred_after, targets),
        mse_before=float((pred_before - targets).square().mean()),
        mse_after=float((pred_after - targets).square().mean()),
        loss_evaluations=evaluations,
    )
