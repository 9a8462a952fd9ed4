"""Small pure kernels that TRPO is assembled from; each has a known-answer test in ``tests/algos/test_kernels.py``.

Parameter vectors: ``P`` is the total number of scalars in the list of trainable tensors ``params``; flat vectors
are ``[P]`` and follow the order of ``params``.

Time-indexed kernels (returns, GAE) take ``[T, N]`` tensors: ``T`` steps of ``N`` parallel environments (``[T]``
works too). Step ``t`` is the transition ``s_t --a_t--> s_{t+1}`` and ``next_values[t] = V(s_{t+1})``, where for a
truncated step ``s_{t+1}`` is the real final observation (before any auto-reset), not the first one of the next
episode.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import torch
from torch import Tensor

__all__ = [
    "GAEResult",
    "LineSearchResult",
    "backtracking_line_search",
    "conjugate_gradient",
    "discounted_returns",
    "explained_variance",
    "fisher_vector_product",
    "flat_grad",
    "gae",
    "get_flat_params",
    "make_fisher_vector_product",
    "max_step_length",
    "set_flat_params",
    "standardize",
]


# --------------------------------------------------------------------------------------------------------------------
# Flat parameter vectors
# --------------------------------------------------------------------------------------------------------------------


def flat_grad(
    output: Tensor, params: Sequence[Tensor], *, retain_graph: bool | None = None, create_graph: bool = False
) -> Tensor:
    """Gradient of the scalar ``output`` w.r.t. every tensor in ``params``, concatenated -> ``[P]``.

    Parameters that ``output`` does not depend on get zeros (not an error), so a policy whose graph skips some
    tensor for a given batch still yields a full-length vector.
    """
    grads = torch.autograd.grad(output, list(params), retain_graph=retain_graph, create_graph=create_graph, allow_unused=True)
    return torch.cat([(torch.zeros_like(p) if g is None else g).reshape(-1) for g, p in zip(grads, params, strict=True)])


def get_flat_params(params: Sequence[Tensor]) -> Tensor:
    """A detached copy of all ``params`` concatenated -> ``[P]``."""
    return torch.cat([p.detach().reshape(-1) for p in params])


def set_flat_params(params: Sequence[Tensor], flat: Tensor) -> None:
    """Copy the ``[P]`` vector ``flat`` into ``params`` in place (no autograd record)."""
    total = sum(p.numel() for p in params)
    if flat.numel() != total:
        raise ValueError(f"flat vector has {flat.numel()} entries, params have {total}")
    offset = 0
    with torch.no_grad():
        for p in params:
            p.copy_(flat[offset : offset + p.numel()].view_as(p))
            offset += p.numel()


# --------------------------------------------------------------------------------------------------------------------
# Natural-gradient step
# --------------------------------------------------------------------------------------------------------------------


def make_fisher_vector_product(
    kl_fn: Callable[[], Tensor], params: Sequence[Tensor], damping: float = 0.0
) -> Callable[[Tensor], Tensor]:
    """Build ``v -> (F + damping I) v`` for the Fisher matrix ``F`` at the current ``params``.

    ``F`` is the Hessian of the mean KL (Schulman et al. 2015, Appendix C): ``kl_fn()`` must return the scalar
    ``mean_b KL(pi_fixed(.|s_b) || pi_theta(.|s_b))`` whose first argument equals the current policy with its graph
    cut (``dist.detach().kl(dist)``), so its gradient vanishes and its Hessian is exactly ``F``. ``kl_fn`` runs once;
    each product is one extra backward pass through the retained graph (double backprop), ``[P] -> [P]``.
    """
    params = list(params)
    kl = kl_fn()
    # A KL that does not depend on params (e.g. every parameter frozen out of the graph) has F = 0.
    grads = flat_grad(kl, params, create_graph=True) if kl.requires_grad else None

    def fvp(v: Tensor) -> Tensor:
        grad_dot_v = None if grads is None else (grads * v.detach()).sum()
        if grad_dot_v is None or not grad_dot_v.requires_grad:
            return damping * v
        return flat_grad(grad_dot_v, params, retain_graph=True) + damping * v

    return fvp


def fisher_vector_product(kl_fn: Callable[[], Tensor], params: Sequence[Tensor], v: Tensor, damping: float = 0.0) -> Tensor:
    """One product ``(F + damping I) v`` -> ``[P]``; see :func:`make_fisher_vector_product` (use that inside CG)."""
    return make_fisher_vector_product(kl_fn, params, damping)(v)


def conjugate_gradient(Avp: Callable[[Tensor], Tensor], b: Tensor, iters: int = 10, residual_tol: float = 1e-10) -> Tensor:
    """Approximately solve ``A x = b`` for symmetric positive-definite ``A`` given only ``Avp: v -> A v`` -> ``[P]``.

    Starts from ``x = 0`` and stops after ``iters`` iterations or when ``||r||^2 < residual_tol`` (Demmel p. 312, as
    in modular_rl); in exact arithmetic ``P`` iterations solve the system.
    """
    x = torch.zeros_like(b)
    r = b.clone()
    p = b.clone()
    r_dot_r = torch.dot(r, r)
    for _ in range(iters):
        if r_dot_r < residual_tol:
            break
        z = Avp(p)
        alpha = r_dot_r / torch.dot(p, z)
        x += alpha * p
        r -= alpha * z
        new_r_dot_r = torch.dot(r, r)
        p = r + (new_r_dot_r / r_dot_r) * p
        r_dot_r = new_r_dot_r
    return x


def max_step_length(step_dir: Tensor, fvp_of_step_dir: Tensor, max_kl: float) -> float:
    """Largest ``beta`` with ``0.5 (beta s)^T F (beta s) = max_kl``: ``beta = sqrt(2 max_kl / s^T F s)``.

    ``step_dir`` is ``s`` ``[P]`` and ``fvp_of_step_dir`` is ``F s`` ``[P]``. Returns 0.0 when ``s^T F s`` is not a
    positive finite number (zero gradient, or a degenerate Fisher), meaning "take no step".
    """
    shs = float(torch.dot(step_dir, fvp_of_step_dir))
    if not math.isfinite(shs) or shs <= 0.0:
        return 0.0
    return math.sqrt(2.0 * max_kl / shs)


class LineSearchResult(NamedTuple):
    """Outcome of :func:`backtracking_line_search`."""

    accepted: bool
    """Whether a step was taken (``False``: the parameters were restored exactly)."""
    steps_tried: int
    """Number of candidate steps evaluated (1 = the full step was accepted)."""
    step_fraction: float
    """Fraction of the full step applied (``shrink ** (steps_tried - 1)``, or 0.0 when rejected)."""
    surrogate_before: float
    """Surrogate at the starting parameters."""
    surrogate: float
    """Surrogate at the final parameters."""
    kl: float
    """The KL ``evaluate_fn`` returned at the final parameters."""


def backtracking_line_search(
    params: Sequence[Tensor],
    evaluate_fn: Callable[[], tuple[Tensor | float, Tensor | float]],
    full_step: Tensor,
    max_kl: float,
    max_backtracks: int = 10,
    shrink: float = 0.5,
    surrogate_before: float | None = None,
) -> LineSearchResult:
    """Try ``theta + shrink^i full_step`` for ``i = 0, 1, ...`` and keep the first that is feasible and better.

    ``evaluate_fn()`` returns ``(surrogate, kl)`` at the current values of ``params`` (the surrogate to be maximised and
    the exact mean KL from the starting policy), so that a caller computes the policy once per candidate. A candidate
    is accepted only if ``kl <= max_kl`` (the trust region actually holds, not just its quadratic model) AND the
    surrogate strictly exceeds its value at the start; non-finite values are rejected. If no candidate passes, the
    original parameters are restored bit for bit. ``evaluate_fn`` is called under ``torch.no_grad``, and its last call
    is at the final parameters (the accepted candidate, or the restored start), so a caller may keep what it computed
    there. ``surrogate_before``: the surrogate at the start, if already known (else one more call).
    """
    params = list(params)
    theta_old = get_flat_params(params)
    with torch.no_grad():
        f_old = float(evaluate_fn()[0]) if surrogate_before is None else float(surrogate_before)
        for i in range(max_backtracks):
            fraction = shrink**i
            set_flat_params(params, theta_old + fraction * full_step)
            f_new, kl = (float(v) for v in evaluate_fn())
            if math.isfinite(f_new) and math.isfinite(kl) and kl <= max_kl and f_new > f_old:
                return LineSearchResult(True, i + 1, fraction, f_old, f_new, kl)
        set_flat_params(params, theta_old)
        return LineSearchResult(False, max_backtracks, 0.0, f_old, f_old, float(evaluate_fn()[1]))


# --------------------------------------------------------------------------------------------------------------------
# Returns and advantages
# --------------------------------------------------------------------------------------------------------------------


def _check_time_major(**tensors: Tensor | None) -> torch.Size:
    """All given tensors must share one shape ``[T, ...]``; returns it."""
    shapes = {name: t.shape for name, t in tensors.items() if t is not None}
    first = next(iter(shapes.values()))
    if any(s != first for s in shapes.values()):
        raise ValueError(f"time-major inputs must share one shape, got {dict(shapes)}")
    if len(first) == 0:
        raise ValueError("time-major inputs need a leading time dimension")
    return first


def _step_discount(rewards: Tensor, gamma: float, discount: Tensor | None) -> Tensor:
    """Per-step discount ``[T, N]``: ``discount`` when given (semi-Markov), else ``gamma`` everywhere."""
    if discount is None:
        return torch.full_like(rewards, gamma)
    return discount.to(rewards.dtype)


def discounted_returns(
    rewards: Tensor,
    terminated: Tensor,
    truncated: Tensor,
    next_values: Tensor,
    gamma: float,
    discount: Tensor | None = None,
) -> Tensor:
    """Bootstrapped discounted returns ``R_t = r_t + g_t * C_t`` -> ``[T, N]``.

    The continuation ``C_t`` is 0 if step ``t`` terminated, ``next_values[t]`` (bootstrap) if it was truncated or is
    the last step of the batch, and ``R_{t+1}`` otherwise. ``g_t`` is ``gamma`` or, in the semi-Markov setting,
    ``discount[t]`` (``gamma ** tau_t`` for a macro-action lasting ``tau_t`` low-level steps, whose reward ``r_t``
    is already its in-macro discounted sum).

    Args:
        rewards: ``[T, N]`` rewards.
        terminated: ``[T, N]`` bool, episode ended in a terminal state after step ``t`` (no bootstrap).
        truncated: ``[T, N]`` bool, episode was cut after step ``t`` (time limit; bootstrap). ``terminated`` wins.
        next_values: ``[T, N]`` ``V(s_{t+1})``; only read where truncated or at ``t = T-1``.
        gamma: discount per step when ``discount`` is ``None``.
        discount: optional ``[T, N]`` per-step discounts replacing ``gamma``.
    """
    _check_time_major(rewards=rewards, terminated=terminated, truncated=truncated, next_values=next_values, discount=discount)
    g = _step_discount(rewards, gamma, discount)
    term, trunc = terminated.bool(), truncated.bool()
    returns = torch.empty_like(rewards)
    following = next_values[-1]
    for t in reversed(range(rewards.shape[0])):
        bootstrap = trunc[t] if t < rewards.shape[0] - 1 else torch.ones_like(trunc[t])
        continuation = torch.where(bootstrap, next_values[t], following)
        continuation = torch.where(term[t], torch.zeros_like(continuation), continuation)
        returns[t] = rewards[t] + g[t] * continuation
        following = returns[t]
    return returns


class GAEResult(NamedTuple):
    """Output of :func:`gae`."""

    advantages: Tensor
    """``[T, N]`` ``A_t^{GAE(gamma, lambda)}``."""
    returns: Tensor
    """``[T, N]`` value targets ``A_t + V(s_t)`` (TD(lambda) returns)."""


def gae(
    rewards: Tensor,
    values: Tensor,
    next_values: Tensor,
    terminated: Tensor,
    truncated: Tensor,
    gamma: float,
    lam: float,
    discount: Tensor | None = None,
) -> GAEResult:
    """Generalized advantage estimation (Schulman et al. 2016) with terminal/truncated handling and semi-Markov steps.

    ``delta_t = r_t + g_t (1 - terminated_t) V(s_{t+1}) - V(s_t)`` and
    ``A_t = delta_t + g_t lam (1 - done_t) A_{t+1}`` with ``done = terminated | truncated`` and ``A_T = 0``:
    a terminal step does not bootstrap, a truncated one bootstraps from the value of its real final observation and
    stops the recursion, and the last step of the batch bootstraps from ``next_values[-1]``. ``g_t`` is ``gamma``,
    or ``discount[t]`` when given (``gamma ** tau_t`` for a macro-action of ``tau_t`` low-level steps); ``lam``
    applies once per decision step.

    Args:
        rewards: ``[T, N]``; values: ``[T, N]`` ``V(s_t)``; next_values: ``[T, N]`` ``V(s_{t+1})``.
        terminated, truncated: ``[T, N]`` bool (see :func:`discounted_returns`).
        gamma, lam: discount and GAE lambda; discount: optional ``[T, N]`` per-step discounts replacing ``gamma``.
    """
    _check_time_major(
        rewards=rewards, values=values, next_values=next_values, terminated=terminated, truncated=truncated, discount=discount
    )
    g = _step_discount(rewards, gamma, discount)
    not_terminal = (~terminated.bool()).to(rewards.dtype)
    not_done = (~(terminated.bool() | truncated.bool())).to(rewards.dtype)
    deltas = rewards + g * not_terminal * next_values - values
    decay = g * lam * not_done
    advantages = torch.empty_like(rewards)
    running = torch.zeros_like(rewards[0])
    for t in reversed(range(rewards.shape[0])):
        running = deltas[t] + decay[t] * running
        advantages[t] = running
    return GAEResult(advantages, advantages + values)


# --------------------------------------------------------------------------------------------------------------------
# Statistics
# --------------------------------------------------------------------------------------------------------------------


def standardize(x: Tensor, eps: float = 1e-8) -> Tensor:
    """``(x - mean) / (std + eps)`` over all entries (population std) -> same shape as ``x``."""
    return (x - x.mean()) / (x.std(unbiased=False) + eps)


def explained_variance(y_pred: Tensor, y_true: Tensor) -> float:
    """``1 - Var[y_true - y_pred] / Var[y_true]`` over all entries: 1 perfect, 0 no better than a constant.

    Returns ``nan`` when ``y_true`` is constant (the ratio is undefined).
    """
    var_y = float(y_true.var(unbiased=False))
    if var_y == 0.0:
        return math.nan
    return 1.0 - float((y_true - y_pred).var(unbiased=False)) / var_y
