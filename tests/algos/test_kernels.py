"""Known-answer tests for the TRPO kernels; each runs in milliseconds."""

import math

import numpy as np
import pytest
import torch

from hrlp.algos.kernels import (
    backtracking_line_search,
    conjugate_gradient,
    discounted_returns,
    explained_variance,
    fisher_vector_product,
    flat_grad,
    gae,
    get_flat_params,
    make_fisher_vector_product,
    max_step_length,
    set_flat_params,
    standardize,
)
from hrlp.policies.distributions import DiagGaussian, Hierarchical

F64 = torch.float64


def t(x):
    return torch.tensor(x, dtype=F64)


# ---------------------------------------------------------------------------------------------------------- flat params


def test_flat_grad_known_answer_and_unused_params():
    a, b, unused = t([1.0, 2.0]).requires_grad_(), t([[3.0], [-1.0]]).requires_grad_(), t([7.0]).requires_grad_()
    out = (a * b.squeeze(-1) ** 2).sum()  # d/da = b^2, d/db = 2ab
    torch.testing.assert_close(flat_grad(out, [a, b, unused]), t([9.0, 1.0, 6.0, -4.0, 0.0]))


def test_get_and_set_flat_params_round_trip():
    params = [torch.zeros(2, 3, dtype=F64), torch.zeros(4, dtype=F64)]
    flat = torch.arange(10, dtype=F64)
    set_flat_params(params, flat)
    torch.testing.assert_close(params[0], flat[:6].view(2, 3))
    got = get_flat_params(params)
    torch.testing.assert_close(got, flat)
    got += 1  # a copy: editing it leaves the parameters alone
    assert params[1][0].item() == 6.0
    with pytest.raises(ValueError, match="10"):
        set_flat_params(params, torch.zeros(9, dtype=F64))


# ---------------------------------------------------------------------------------------------------------- Fisher


def test_fisher_vector_product_equals_hessian_of_kl_on_tiny_net():
    """F v from double backprop == H v with H the exact Hessian of mean KL(pi_fixed || pi_theta) at theta."""
    g = torch.Generator().manual_seed(0)
    obs = torch.randn(5, 3, generator=g, dtype=F64)
    dims = (1, 0, 2)
    shapes = [(3, 3), (3,), (3, 3), (3,)]  # logits weight and bias, means weight, log_std
    params = [torch.randn(s, generator=g, dtype=F64).mul(0.5).requires_grad_() for s in shapes]
    sizes = [math.prod(s) for s in shapes]

    def unflatten(flat):
        chunks = torch.split(flat, sizes)
        return [c.view(s) for c, s in zip(chunks, shapes, strict=True)]

    def dist_of_params(ps):
        return Hierarchical(obs @ ps[0] + ps[1], obs @ ps[2], ps[3], dims)

    theta = get_flat_params(params)
    fixed = dist_of_params([p.detach() for p in params])
    hessian = torch.autograd.functional.hessian(lambda flat: fixed.kl(dist_of_params(unflatten(flat))).mean(), theta)
    v = torch.randn(theta.numel(), generator=g, dtype=F64)

    def kl_fn():
        d = dist_of_params(params)
        return d.detach().kl(d).mean()

    torch.testing.assert_close(fisher_vector_product(kl_fn, params, v), hessian @ v)
    torch.testing.assert_close(fisher_vector_product(kl_fn, params, v, damping=0.3), hessian @ v + 0.3 * v)


def test_fisher_vector_product_analytic_gaussian():
    """One state, theta = (mu, log sigma): F = diag(1 / sigma^2, 2) per dimension."""
    mean, log_std = t([[0.5, -1.0]]).requires_grad_(), t([0.3, -0.7]).requires_grad_()

    def kl_fn():
        d = DiagGaussian(mean, log_std)
        return d.detach().kl(d).mean()

    v = t([1.0, 2.0, 3.0, 4.0])
    sigma2 = torch.exp(2 * log_std.detach())
    expected = torch.cat([v[:2] / sigma2, 2 * v[2:]])
    torch.testing.assert_close(fisher_vector_product(kl_fn, [mean, log_std], v), expected)
    fvp = make_fisher_vector_product(kl_fn, [mean, log_std], damping=0.1)  # reusable closure
    torch.testing.assert_close(fvp(v), expected + 0.1 * v)
    torch.testing.assert_close(fvp(2 * v), 2 * (expected + 0.1 * v))


def test_fisher_vector_product_when_kl_ignores_params():
    p = t([1.0]).requires_grad_()
    out = fisher_vector_product(lambda: (p * 0).sum().detach(), [p], t([2.0]), damping=0.5)
    torch.testing.assert_close(out, t([1.0]))


# ---------------------------------------------------------------------------------------------------------- CG and step


def test_conjugate_gradient_solves_spd_system():
    rng = np.random.default_rng(0)
    m = rng.normal(size=(6, 6))
    a = m @ m.T + np.eye(6)
    b = rng.normal(size=6)
    a_t = torch.as_tensor(a)
    x = conjugate_gradient(lambda v: a_t @ v, torch.as_tensor(b), iters=20)
    np.testing.assert_allclose(x.numpy(), np.linalg.solve(a, b), rtol=1e-8, atol=1e-10)


def test_conjugate_gradient_early_stop_and_zero_rhs():
    calls = []

    def identity(v):
        calls.append(1)
        return v

    x = conjugate_gradient(identity, t([3.0, -4.0]), iters=10)
    torch.testing.assert_close(x, t([3.0, -4.0]))
    assert len(calls) == 1  # exact after one step, residual 0 < tol
    torch.testing.assert_close(conjugate_gradient(identity, t([0.0, 0.0])), t([0.0, 0.0]))
    assert len(calls) == 1


def test_conjugate_gradient_respects_iteration_budget():
    a = torch.diag(t([1.0, 2.0, 3.0]))
    calls = []

    def avp(v):
        calls.append(1)
        return a @ v

    conjugate_gradient(avp, t([1.0, 1.0, 1.0]), iters=2)
    assert len(calls) == 2


def test_max_step_length_known_answer():
    s, fs = t([1.0, 2.0]), t([2.0, 1.0])  # F = diag(2, 0.5): s^T F s = 4
    beta = max_step_length(s, fs, max_kl=0.02)
    assert beta == pytest.approx(math.sqrt(2 * 0.02 / 4))  # = 0.1
    assert 0.5 * beta**2 * 4 == pytest.approx(0.02)  # the quadratic KL model sits on the boundary
    assert max_step_length(t([0.0, 0.0]), t([0.0, 0.0]), 0.01) == 0.0
    assert max_step_length(t([1.0]), t([-1.0]), 0.01) == 0.0


# ---------------------------------------------------------------------------------------------------------- line search


def _quadratic_problem(x0: float, optimum: float):
    """``x``, and the line search's ``evaluate_fn``: surrogate ``-(x - optimum)^2``, KL ``(x - x0)^2 / 2``."""
    x = t([x0])
    return x, lambda: (-((x - optimum) ** 2).sum(), 0.5 * ((x - x0) ** 2).sum())


def test_line_search_accepts_full_step_on_quadratic():
    x, evaluate = _quadratic_problem(0.0, 1.0)
    res = backtracking_line_search([x], evaluate, t([1.0]), max_kl=1.0)
    assert res.accepted and res.steps_tried == 1 and res.step_fraction == 1.0
    assert x.item() == 1.0 and res.surrogate == 0.0 and res.surrogate_before == -1.0 and res.kl == 0.5


def test_line_search_shrinks_until_kl_fits():
    x, evaluate = _quadratic_problem(0.0, 1.0)
    res = backtracking_line_search([x], evaluate, t([1.0]), max_kl=0.1)  # KL 0.5, 0.125, then 0.03125
    assert res.accepted and res.steps_tried == 3 and res.step_fraction == 0.25
    assert x.item() == 0.25 and res.kl == pytest.approx(0.03125)


def test_line_search_rejects_and_restores_exactly():
    x0 = 0.1234567890123
    x, evaluate = _quadratic_problem(x0, x0)  # already optimal: every step makes it worse
    before = x.clone()
    res = backtracking_line_search([x], evaluate, t([0.7]), max_kl=10.0, max_backtracks=4)
    assert not res.accepted and res.steps_tried == 4 and res.step_fraction == 0.0
    assert torch.equal(x, before) and res.surrogate == res.surrogate_before and res.kl == 0.0


def test_line_search_rejects_non_finite_kl():
    x, evaluate = _quadratic_problem(0.0, 1.0)
    res = backtracking_line_search([x], lambda: (evaluate()[0], t(float("nan"))), t([1.0]), max_kl=1.0, max_backtracks=3)
    assert not res.accepted and x.item() == 0.0


@pytest.mark.parametrize(("optimum", "max_kl", "calls"), [(1.0, 0.1, 3), (0.0, 10.0, 5)])  # accepted third; rejected
def test_line_search_evaluates_last_at_the_final_parameters(optimum, max_kl, calls):
    """Its last call is at the parameters it leaves (a caller reuses what it computed there), accepted or not."""
    x, evaluate = _quadratic_problem(0.0, optimum)
    seen: list[float] = []
    res = backtracking_line_search([x], lambda: (seen.append(x.item()), evaluate())[1], t([1.0]), max_kl=max_kl,
                                   max_backtracks=4, surrogate_before=float(evaluate()[0]))  # fmt: skip
    assert res.accepted == (calls == 3) and seen[-1] == x.item() and len(seen) == calls


# ---------------------------------------------------------------------------------------------------------- returns / GAE


def _col(*xs):
    return t([[x] for x in xs])


def test_discounted_returns_terminal_truncated_and_cut():
    """Worked by hand with gamma = 0.5, rewards 1, 2, 3, 4 in three environments (columns)."""
    rewards = t([[1.0] * 3, [2.0] * 3, [3.0] * 3, [4.0] * 3])
    #             col 0: ends terminal at t=3;  col 1: truncated at t=1, cut at t=3;  col 2: terminal at t=1, cut at t=3
    terminated = torch.tensor([[0, 0, 0], [0, 0, 1], [0, 0, 0], [1, 0, 0]], dtype=torch.bool)
    truncated = torch.tensor([[0, 0, 0], [0, 1, 0], [0, 0, 0], [0, 0, 0]], dtype=torch.bool)
    next_values = t([[99.0] * 3, [99.0, 10.0, 99.0], [99.0] * 3, [99.0, 8.0, 8.0]])  # 99 = must not be read
    got = discounted_returns(rewards, terminated, truncated, next_values, gamma=0.5)
    # col 0: R3 = 4, R2 = 3 + 2 = 5, R1 = 2 + 2.5 = 4.5, R0 = 1 + 2.25 = 3.25
    # col 1: R3 = 4 + 4 = 8, R2 = 3 + 4 = 7, R1 = 2 + 0.5 * 10 = 7, R0 = 1 + 3.5 = 4.5
    # col 2: R3 = 8, R2 = 7, R1 = 2, R0 = 1 + 1 = 2
    torch.testing.assert_close(got, t([[3.25, 4.5, 2.0], [4.5, 7.0, 2.0], [5.0, 7.0, 7.0], [4.0, 8.0, 8.0]]))


def test_discounted_returns_semi_markov():
    """Macro-actions of 2, 1 and 3 low-level steps with gamma = 0.5: per-step discounts 0.25, 0.5, 0.125."""
    got = discounted_returns(
        _col(1.0, 1.0, 1.0), _col(0, 0, 1).bool(), _col(0, 0, 0).bool(), _col(0.0, 0.0, 99.0), 0.5, _col(0.25, 0.5, 0.125)
    )
    # R2 = 1 (terminal), R1 = 1 + 0.5 * 1 = 1.5, R0 = 1 + 0.25 * 1.5 = 1.375
    torch.testing.assert_close(got, _col(1.375, 1.5, 1.0))


def _gae_case():
    """gamma = lam = 0.5, rewards 1, V(s_t) = 1, 2, 3 and V(s_{t+1}) = 2, 3, 4; columns: no end, terminal, truncated."""
    rewards = t([[1.0] * 3] * 3)
    values = t([[1.0] * 3, [2.0] * 3, [3.0] * 3])
    next_values = t([[2.0] * 3, [3.0, 100.0, 6.0], [4.0] * 3])  # after step 1: terminal (ignored) / final obs worth 6
    terminated = torch.tensor([[0, 0, 0], [0, 1, 0], [0, 0, 0]], dtype=torch.bool)
    truncated = torch.tensor([[0, 0, 0], [0, 0, 1], [0, 0, 0]], dtype=torch.bool)
    return rewards, values, next_values, terminated, truncated


def test_gae_known_answers():
    rewards, values, next_values, terminated, truncated = _gae_case()
    adv, ret = gae(rewards, values, next_values, terminated, truncated, gamma=0.5, lam=0.5)
    # col 0: deltas 1, 0.5, 0 -> A2 = 0, A1 = 0.5, A0 = 1 + 0.25 * 0.5 = 1.125
    # col 1: delta1 = 1 + 0 - 2 = -1 (no bootstrap), A1 = -1, A0 = 1 + 0.25 * (-1) = 0.75, A2 = 0 (new episode)
    # col 2: delta1 = 1 + 0.5 * 6 - 2 = 2 (bootstrap from the final observation), A1 = 2, A0 = 1 + 0.25 * 2 = 1.5
    expected = t([[1.125, 0.75, 1.5], [0.5, -1.0, 2.0], [0.0, 0.0, 0.0]])
    torch.testing.assert_close(adv, expected)
    torch.testing.assert_close(ret, expected + values)


def test_gae_semi_markov_known_answer():
    rewards, values, next_values, _, _ = _gae_case()
    no = torch.zeros(3, 1, dtype=torch.bool)
    adv, _ = gae(rewards[:, :1], values[:, :1], next_values[:, :1], no, no, gamma=0.5, lam=0.5, discount=_col(0.25, 0.5, 0.5))
    # deltas: 1 + 0.25 * 2 - 1 = 0.5, 1 + 0.5 * 3 - 2 = 0.5, 1 + 0.5 * 4 - 3 = 0
    # A1 = 0.5, A0 = 0.5 + (0.25 * 0.5) * 0.5 = 0.5625
    torch.testing.assert_close(adv, _col(0.5625, 0.5, 0.0))
    constant = gae(rewards, values, next_values, *_gae_case()[3:], gamma=0.5, lam=0.5, discount=torch.full((3, 3), 0.5))
    torch.testing.assert_close(constant.advantages, gae(*_gae_case(), gamma=0.5, lam=0.5).advantages)


def test_gae_lambda_limits_match_td_error_and_returns():
    g = torch.Generator().manual_seed(0)
    T, N = 12, 4
    rewards = torch.randn(T, N, generator=g, dtype=F64)
    values = torch.randn(T + 1, N, generator=g, dtype=F64)
    final_values = torch.randn(T, N, generator=g, dtype=F64)  # V of the real last observation of truncated episodes
    terminated = torch.rand(T, N, generator=g) < 0.15
    truncated = (torch.rand(T, N, generator=g) < 0.15) & ~terminated
    next_values = torch.where(truncated, final_values, values[1:])
    discount = 0.9 ** torch.randint(1, 5, (T, N), generator=g).to(F64)
    for disc in (None, discount):
        gamma_t = torch.full((T, N), 0.9, dtype=F64) if disc is None else disc
        adv0, _ = gae(rewards, values[:-1], next_values, terminated, truncated, 0.9, 0.0, disc)
        torch.testing.assert_close(adv0, rewards + gamma_t * (~terminated) * next_values - values[:-1])
        _, ret1 = gae(rewards, values[:-1], next_values, terminated, truncated, 0.9, 1.0, disc)
        torch.testing.assert_close(ret1, discounted_returns(rewards, terminated, truncated, next_values, 0.9, disc))


def test_gae_accepts_one_dimensional_inputs_and_checks_shapes():
    adv, _ = gae(t([1.0, 1.0]), t([0.0, 0.0]), t([0.0, 0.0]), torch.zeros(2).bool(), torch.zeros(2).bool(), 0.5, 1.0)
    torch.testing.assert_close(adv, t([1.5, 1.0]))
    with pytest.raises(ValueError, match="shape"):
        gae(t([1.0, 1.0]), t([0.0]), t([0.0, 0.0]), torch.zeros(2).bool(), torch.zeros(2).bool(), 0.5, 1.0)


# ---------------------------------------------------------------------------------------------------------- statistics


def test_explained_variance_and_standardize():
    y = t([1.0, 2.0, 3.0, 4.0])
    assert explained_variance(t([1.0, 2.0, 3.0, 5.0]), y) == pytest.approx(1 - 0.1875 / 1.25)
    assert explained_variance(y, y) == 1.0
    assert math.isnan(explained_variance(y, t([2.0] * 4)))
    z = standardize(y)
    assert z.mean().item() == pytest.approx(0.0, abs=1e-12) and z.std(unbiased=False).item() == pytest.approx(1.0)
