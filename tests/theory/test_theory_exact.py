"""Exact V, Q, A, eta, rho, L, D_TV, D_KL against brute force on tiny MDPs."""

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from theory_strategies import mdp_and_pair, policies_for, tiny_mdps

from hrlp.theory import (
    action_value,
    advantage,
    eta,
    kl_divergence,
    pair_quantities,
    surrogate,
    tv_distance,
    value,
    visitation,
)
from hrlp.theory.exact import expected_reward, state_transition


def _horizon(gamma: float) -> int:
    """Steps after which gamma^t * (any bounded quantity) is below 1e-13."""
    return int(np.ceil(np.log(1e-13) / np.log(gamma))) + 1


def _propagate(mdp, pi, d0):
    """Brute force: push the state distribution d0 through P_pi; return sum_t gamma^t d_t and sum_t gamma^t d_t r_pi."""
    P_pi, r_pi = state_transition(mdp, pi), expected_reward(mdp, pi)
    d, rho, ret = d0.copy(), np.zeros_like(d0), 0.0
    for t in range(_horizon(mdp.gamma)):
        rho += mdp.gamma**t * d
        ret += mdp.gamma**t * float(d @ r_pi)
        d = d @ P_pi
    return rho, ret


@settings(max_examples=30, deadline=None)
@given(st.data())
def test_value_matches_value_iteration(data):
    mdp = data.draw(tiny_mdps())
    pi = data.draw(policies_for(mdp)).flat()
    P_pi, r_pi = state_transition(mdp, pi), expected_reward(mdp, pi)
    V = np.zeros(mdp.n_states)
    for _ in range(_horizon(mdp.gamma)):
        V = r_pi + mdp.gamma * P_pi @ V
    np.testing.assert_allclose(value(mdp, pi), V, atol=1e-10)


@settings(max_examples=30, deadline=None)
@given(st.data())
def test_q_rho_eta_match_distribution_propagation(data):
    mdp = data.draw(tiny_mdps())
    pi = data.draw(policies_for(mdp)).flat()
    rho_bf, eta_bf = _propagate(mdp, pi, mdp.rho0)
    np.testing.assert_allclose(visitation(mdp, pi), rho_bf, atol=1e-10)
    assert abs(visitation(mdp, pi).sum() - 1.0 / (1.0 - mdp.gamma)) < 1e-9  # rho_pi is unnormalised
    assert abs(eta(mdp, pi) - eta_bf) < 1e-10
    # Q(s, a): reward of (s, a), then follow pi from the next-state distribution P(.|s, a).
    Q = action_value(mdp, pi)
    for s, a in itertools.product(range(mdp.n_states), range(mdp.n_actions)):
        _, ret = _propagate(mdp, pi, mdp.P[s, a])
        assert abs(Q[s, a] - (mdp.r[s, a] + mdp.gamma * ret)) < 1e-10


@settings(max_examples=30, deadline=None)
@given(mdp_and_pair())
def test_advantage_surrogate_and_performance_difference(case):
    mdp, pi, pi_tilde = case
    A = advantage(mdp, pi)
    np.testing.assert_allclose((pi * A).sum(axis=1), 0.0, atol=1e-10)  # E_pi A_pi(s, .) = 0
    np.testing.assert_allclose(A, action_value(mdp, pi) - value(mdp, pi)[:, None], atol=1e-12)
    assert abs(surrogate(mdp, pi, pi) - eta(mdp, pi)) < 1e-10  # L_pi(pi) = eta(pi)
    # Kakade & Langford: eta(pi~) = eta(pi) + sum_s rho_pi~(s) sum_a pi~(a|s) A_pi(s, a); L uses rho_pi instead.
    kakade = eta(mdp, pi) + visitation(mdp, pi_tilde) @ (pi_tilde * A).sum(axis=1)
    assert abs(eta(mdp, pi_tilde) - kakade) < 1e-9
    L = eta(mdp, pi) + visitation(mdp, pi) @ (pi_tilde * A).sum(axis=1)
    assert abs(surrogate(mdp, pi, pi_tilde) - L) < 1e-10


@settings(max_examples=30, deadline=None)
@given(mdp_and_pair())
def test_distances_match_their_definitions(case):
    mdp, pi, pi_tilde = case
    tv, kl = tv_distance(pi, pi_tilde), kl_divergence(pi, pi_tilde)
    for s in range(mdp.n_states):
        # D_TV = sup_B |pi(B) - pi~(B)| over every subset B of the (finite) action set.
        sup_b = max(
            abs(pi[s, list(B)].sum() - pi_tilde[s, list(B)].sum())
            for n in range(mdp.n_actions + 1)
            for B in itertools.combinations(range(mdp.n_actions), n)
        )
        assert abs(tv[s] - sup_b) < 1e-12
        assert abs(kl[s] - sum(p * np.log(p / q) for p, q in zip(pi[s], pi_tilde[s], strict=True))) < 1e-12
        assert tv[s] <= np.sqrt(kl[s] / 2.0) + 1e-12  # Pinsker


@settings(max_examples=30, deadline=None)
@given(mdp_and_pair())
def test_pair_quantities_agree_with_the_single_functions(case):
    mdp, pi, pi_tilde = case
    q = pair_quantities(mdp, pi, pi_tilde)
    A = advantage(mdp, pi)
    assert abs(q.eta_pi - eta(mdp, pi)) < 1e-12
    assert abs(q.eta_pi_tilde - eta(mdp, pi_tilde)) < 1e-12
    assert abs(q.L - surrogate(mdp, pi, pi_tilde)) < 1e-12
    assert abs(q.epsilon - np.max(np.abs((pi_tilde * A).sum(axis=1)))) < 1e-12
    assert abs(q.epsilon_max - np.max(np.abs(A))) < 1e-12
    assert q.epsilon <= q.epsilon_max + 1e-12
    assert q.tv_max == np.max(tv_distance(pi, pi_tilde))
    assert q.kl_max == np.max(kl_divergence(pi, pi_tilde))
    assert q.R == np.max(np.abs(mdp.r))


def test_known_values_two_state_chain():
    """Known answers for the two-state MDP of hrlp.theory.examples, worked out by hand."""
    from hrlp.theory import two_state_example

    gamma = 0.5
    case = two_state_example(0.1, gamma)
    V = value(case.mdp, case.pi)
    np.testing.assert_allclose(V, [1.0 / 3.0, 1.0])  # V(s1) = 1/(2(1-gamma)), V(s0) = gamma V(s1)/(2-gamma)
    np.testing.assert_allclose(visitation(case.mdp, case.pi), [4.0 / 3.0, 2.0 - 4.0 / 3.0])
    np.testing.assert_allclose(advantage(case.mdp, case.pi), [[-1.0 / 6.0, 1.0 / 6.0], [-0.5, 0.5]])
