"""Trust Region Policy Optimization (Schulman et al. 2015) over the :class:`~hrlp.policies.distributions.Distribution`
interface.

The update never learns what kind of distribution it optimises: for the Manager, ``dist_fn`` returns a
:class:`~hrlp.policies.distributions.Hierarchical`, whose ``kl`` is Lemma 1, so the trust region and the Fisher
matrix are the hierarchical ones of Section 3.1 without any special case here. Only the tensors passed as
``policy_params`` move; frozen skills and the value network never enter the trust region.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from hrlp.algos.kernels import (
    backtracking_line_search,
    conjugate_gradient,
    flat_grad,
    get_flat_params,
    make_fisher_vector_product,
    max_step_length,
    standardize,
)
from hrlp.config import TRPOConfig  # torch-free (for `hrlp --help`); importable from here as before
from hrlp.policies.distributions import Distribution

__all__ = ["TRPOConfig", "TRPOStats", "surrogate_objective", "trpo_update"]


@dataclass(frozen=True)
class TRPOStats:
    """What one :func:`trpo_update` did; every field is a plain number, ready for a logger."""

    kl: float
    """Mean KL(old || new) over the batch after the update (<= max_kl when accepted; ~0 when not)."""
    kl_max: float
    """Largest per-state KL(old || new) after the update (the D_KL^max of Theorem 1, on the batch)."""
    surrogate_before: float
    """Surrogate L(theta_old) = mean(A) (+ entropy bonus) at the old parameters."""
    surrogate_after: float
    """Surrogate mean(pi_new/pi_old * A) (+ entropy bonus) at the final parameters."""
    expected_improvement: float
    """First-order prediction g^T (full step) of the surrogate gain for the full step."""
    line_search_steps: int
    """Candidate steps evaluated by the line search (1 = full step accepted; 0 = no step attempted)."""
    step_fraction: float
    """Fraction of the full natural-gradient step that was applied (0.0 when rejected)."""
    accepted: bool
    """Whether the parameters changed."""
    entropy_before: float
    """Mean policy entropy over the batch before the update."""
    entropy: float
    """Mean policy entropy over the batch after the update."""
    grad_norm: float
    """Euclidean norm of the surrogate gradient g."""
    step_norm: float
    """Euclidean norm of the parameter change actually applied."""
    beta: float
    """Full-step length sqrt(2 delta / s^T F s) along the CG direction s."""
    cg_relative_residual: float
    """||(F + damping I) s - g|| / ||g||: how well CG solved for the natural gradient."""

    @property
    def improvement(self) -> float:
        """Actual surrogate gain ``surrogate_after - surrogate_before``."""
        return self.surrogate_after - self.surrogate_before

    def to_dict(self) -> dict[str, float | int | bool]:
        """Fields as a flat dict (for CSV/JSONL/TensorBoard loggers)."""
        return dataclasses.asdict(self)


def surrogate_objective(
    dist: Distribution, actions: Tensor, old_log_prob: Tensor, advantages: Tensor, entropy_coef: float = 0.0
) -> Tensor:
    """Importance-sampled surrogate ``L(theta) = mean_b (pi_theta(a_b|s_b) / pi_old(a_b|s_b)) A_b`` (+ entropy bonus).

    Args:
        dist: current policy on the batch (``B`` states).
        actions: ``[B, ...]`` taken actions in ``dist``'s encoding.
        old_log_prob: ``[B]`` ``log pi_old(a_b | s_b)`` (detached).
        advantages: ``[B]``.
        entropy_coef: weight of ``mean_b H(pi_theta(.|s_b))``.

    Returns a scalar to be maximised.
    """
    ratio = torch.exp(dist.log_prob(actions) - old_log_prob)
    objective = (ratio * advantages).mean()
    if entropy_coef:
        objective = objective + entropy_coef * dist.entropy().mean()
    return objective


def trpo_update(
    policy_params: Sequence[Tensor],
    dist_fn: Callable[[], Distribution],
    old_dist: Distribution | None,
    actions: Tensor,
    advantages: Tensor,
    cfg: TRPOConfig | None = None,
    fisher_dist_fn: Callable[[], Distribution] | None = None,
) -> TRPOStats:
    """One TRPO step: maximise the surrogate subject to ``mean KL(old || new) <= max_kl``, in place on ``policy_params``.

    Natural-gradient direction ``s = (F + damping I)^-1 g`` by conjugate gradient on exact Fisher-vector products of
    the mean KL, full step ``beta s`` with ``beta = sqrt(2 delta / s^T F s)``, then a backtracking line search that
    accepts only a step that keeps the exact mean KL within ``delta`` and improves the surrogate (otherwise the
    parameters are restored). The policy is computed on the batch once at the start (with its graph, for ``g``), once
    per line-search candidate (surrogate and KL from the same forward pass), and the statistics of the final parameters
    reuse the last candidate's.

    Args:
        policy_params: the trainable tensors; nothing else is changed.
        dist_fn: recomputes the policy's distribution on the batch's ``B`` states from the current parameter values
            (a closure such as ``lambda: policy(obs)``).
        old_dist: the distribution that generated the data, detached here; ``None``: ``dist_fn()`` at the current
            parameters (the usual case: the batch was sampled by the policy being updated), taken from the forward pass
            the gradient needs rather than a second one.
        actions: ``[B, ...]`` taken actions in the distribution's encoding.
        advantages: ``[B]`` advantage estimates (standardised here if ``cfg.normalize_advantages``).
        cfg: settings; ``TRPOConfig()`` if ``None``.
        fisher_dist_fn: the distribution on the states the Fisher matrix is estimated on, e.g. a subsample
            (``lambda: policy(obs[::10])``); ``None``: ``dist_fn``'s, every state. The step length
            ``beta`` still uses the subsample's ``s^T F s``; the line search checks the exact KL on every state.
    """
    cfg = cfg or TRPOConfig()
    params = list(policy_params)
    if not params or not all(p.requires_grad for p in params):
        raise ValueError("policy_params must be a non-empty list of tensors that require grad")
    dist = dist_fn()
    old_dist = dist.detach() if old_dist is None else old_dist.detach()
    adv = advantages.detach().reshape(-1)
    if cfg.normalize_advantages:
        adv = standardize(adv)
    old_log_prob = old_dist.log_prob(actions).detach()
    theta_old = get_flat_params(params)

    surrogate = surrogate_objective(dist, actions, old_log_prob, adv, cfg.entropy_coef)
    surrogate_before = float(surrogate.detach())
    entropy_before = float(dist.entropy().mean().detach())
    g = flat_grad(surrogate, params, retain_graph=True)
    grad_norm = float(torch.linalg.vector_norm(g))

    def no_step(beta: float = 0.0, residual: float = math.nan, expected: float = 0.0) -> TRPOStats:
        return TRPOStats(
            kl=0.0, kl_max=0.0, surrogate_before=surrogate_before, surrogate_after=surrogate_before,
            expected_improvement=expected, line_search_steps=0, step_fraction=0.0, accepted=False,
            entropy_before=entropy_before, entropy=entropy_before, grad_norm=grad_norm, step_norm=0.0, beta=beta,
            cg_relative_residual=residual,
        )  # fmt: skip

    if not math.isfinite(grad_norm) or grad_norm == 0.0:
        return no_step()

    # Hessian of KL(dist_fixed || dist) at the current parameters = Fisher matrix (first argument held fixed).
    fisher_dist = dist if fisher_dist_fn is None else fisher_dist_fn()
    fvp = make_fisher_vector_product(lambda: fisher_dist.detach().kl(fisher_dist).mean(), params, cfg.cg_damping)
    step_dir = conjugate_gradient(fvp, g, cfg.cg_iters, cfg.cg_residual_tol)
    f_step_dir = fvp(step_dir)
    residual = float(torch.linalg.vector_norm(f_step_dir - g)) / grad_norm
    beta = max_step_length(step_dir, f_step_dir, cfg.max_kl)
    full_step = beta * step_dir
    expected = float(torch.dot(g, full_step))
    if beta == 0.0:
        return no_step(beta, residual, expected)

    last: list[tuple[Distribution, Tensor]] = []  # the policy and per-state KL at the line search's last candidate

    def evaluate() -> tuple[Tensor, Tensor]:
        candidate = dist_fn()
        kl_states = old_dist.kl(candidate)
        last[:] = [(candidate, kl_states)]
        return surrogate_objective(candidate, actions, old_log_prob, adv, cfg.entropy_coef), kl_states.mean()

    result = backtracking_line_search(
        params,
        evaluate,
        full_step=full_step,
        max_kl=cfg.max_kl,
        max_backtracks=cfg.line_search_backtracks,
        shrink=cfg.line_search_shrink,
        surrogate_before=surrogate_before,
    )
    new_dist, kl = last[0]  # the line search's last call is at the final parameters
    with torch.no_grad():
        entropy = float(new_dist.entropy().mean())
    return TRPOStats(
        kl=float(kl.mean()),
        kl_max=float(kl.max()),
        surrogate_before=surrogate_before,
        surrogate_after=result.surrogate,
        expected_improvement=expected,
        line_search_steps=result.steps_tried,
        step_fraction=result.step_fraction,
        accepted=result.accepted,
        entropy_before=entropy_before,
        entropy=entropy,
        grad_norm=grad_norm,
        step_norm=float(torch.linalg.vector_norm(get_flat_params(params) - theta_old)),
        beta=beta,
        cg_relative_residual=residual,
    )
