"""Lemma 1, (1): exactly for discrete parameters, by Monte-Carlo for Gaussian parameters."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from theory_strategies import policies_for, tiny_mdps

from hrlp.theory import (
    GaussianHierarchical,
    HierarchicalPolicy,
    gaussian_kl,
    hierarchical_kl,
    kl_divergence,
    kl_monte_carlo,
    lemma1_exact,
    lemma1_monte_carlo,
    lemma1_rhs,
)
from hrlp.theory.gaussian import random_gaussian_hierarchical


@settings(max_examples=50, deadline=None)
@given(st.data())
def test_lemma1_identity_exact(data):
    """KL of the flattened distributions = KL(p, p~) + sum_k p_k KL(mu_k, mu~_k), also where pi has zeros."""
    mdp = data.draw(tiny_mdps())
    policy = data.draw(policies_for(mdp, full_support=False))
    policy_tilde = data.draw(policies_for(mdp))
    flat_kl = kl_divergence(policy.flat(), policy_tilde.flat())
    np.testing.assert_allclose(hierarchical_kl(policy, policy_tilde), flat_kl, rtol=1e-10, atol=1e-12)
    check = lemma1_exact(policy, policy_tilde)
    assert check.holds
    assert check.relation == "=="
    assert check.slack == check.lhs - check.rhs
    assert abs(check.slack) <= check.tol


def test_lemma1_known_answer_and_a_wrong_decomposition_fails():
    p, p_t = np.array([[0.5, 0.5]]), np.array([[0.25, 0.75]])
    mu, mu_t = (np.array([[1.0]]), np.array([[0.5, 0.5]])), (np.array([[1.0]]), np.array([[0.9, 0.1]]))
    policy, policy_tilde = HierarchicalPolicy(p, mu), HierarchicalPolicy(p_t, mu_t)
    expected = 0.5 * math.log(2.0) + 0.5 * math.log(0.5 / 0.75) + 0.5 * (0.5 * math.log(0.5 / 0.9) + 0.5 * math.log(0.5 / 0.1))
    assert abs(hierarchical_kl(policy, policy_tilde)[0] - expected) < 1e-15
    assert lemma1_exact(policy, policy_tilde).holds
    # Without the weights p_k the identity is false: the check must be able to tell.
    unweighted = 0.5 * math.log(2.0) + 0.5 * math.log(0.5 / 0.75) + (0.5 * math.log(0.5 / 0.9) + 0.5 * math.log(0.5 / 0.1))
    assert abs(kl_divergence(policy.flat(), policy_tilde.flat())[0] - unweighted) > 0.1


def test_lemma1_not_absolutely_continuous_is_infinite_on_both_sides():
    policy = HierarchicalPolicy(np.array([[0.5, 0.5]]), (np.array([[0.5, 0.5]]), np.array([[1.0]])))
    policy_tilde = HierarchicalPolicy(np.array([[0.5, 0.5]]), (np.array([[1.0, 0.0]]), np.array([[1.0]])))
    check = lemma1_exact(policy, policy_tilde)
    assert math.isinf(check.lhs) and math.isinf(check.rhs)
    assert check.holds


def test_gaussian_kl_known_answers():
    assert gaussian_kl(np.zeros(1), np.zeros(1), np.ones(1), np.zeros(1)) == pytest.approx(0.5)
    # KL(N(0, 1), N(0, 2^2)) = log 2 + 1/8 - 1/2
    assert gaussian_kl(np.zeros(1), np.zeros(1), np.zeros(1), np.log([2.0])) == pytest.approx(math.log(2.0) - 0.375)
    assert gaussian_kl(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0)) == 0.0  # parameterless


def test_lemma1_monte_carlo_agrees_with_closed_form():
    rng = np.random.default_rng(0)
    for _ in range(5):
        dims = (0, 1, 3)
        mu, mu_tilde = random_gaussian_hierarchical(rng, dims), random_gaussian_hierarchical(rng, dims)
        check = lemma1_monte_carlo(mu, mu_tilde, rng, n_samples=20_000, z=5.0)
        assert check.holds, check
        assert check.tol < 0.1 * max(check.rhs, 0.1)  # the check is sharp enough to mean something


def test_monte_carlo_detects_a_wrong_closed_form():
    """The Monte-Carlo estimate separates Lemma 1's right-hand side from a plausible wrong one."""
    mu = GaussianHierarchical(np.array([0.2, 0.8]), (np.zeros(1), np.zeros(2)), (np.zeros(1), np.zeros(2)))
    mu_tilde = GaussianHierarchical(np.array([0.6, 0.4]), (np.ones(1), np.zeros(2)), (np.zeros(1), np.log([2.0, 2.0])))
    estimate, stderr = kl_monte_carlo(mu, mu_tilde, np.random.default_rng(1), 20_000)
    right = lemma1_rhs(mu, mu_tilde)
    kl_p = float(np.sum(mu.p * np.log(mu.p / mu_tilde.p)))
    wrong = kl_p + sum(gaussian_kl(mu.mean[k], mu.log_std[k], mu_tilde.mean[k], mu_tilde.log_std[k]) for k in range(2))
    assert abs(estimate - right) < 5 * stderr
    assert abs(estimate - wrong) > 10 * stderr


def test_gaussian_distribution_rejects_bad_input():
    with pytest.raises(ValueError):
        GaussianHierarchical(np.array([0.5, 0.6]), (np.zeros(1), np.zeros(1)), (np.zeros(1), np.zeros(1)))
    with pytest.raises(ValueError):
        GaussianHierarchical(np.array([1.0]), (np.zeros(2),), (np.zeros(1),))
    with pytest.raises(ValueError):
        kl_monte_carlo(
            random_gaussian_hierarchical(np.random.default_rng(0), (1,)),
            random_gaussian_hierarchical(np.random.default_rng(1), (1,)),
            np.random.default_rng(2),
            1,
        )
