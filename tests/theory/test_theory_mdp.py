"""Hierarchical action spaces, MDP validation, hierarchical <-> flat policies."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from theory_strategies import policies_for, tiny_mdps

from hrlp.theory import FiniteMDP, HierarchicalActionSpace, HierarchicalPolicy


def test_action_space_flattens_in_macro_order():
    space = HierarchicalActionSpace((2, 1, 3))
    assert space.n == 3
    assert space.size == 6
    assert space.offsets == (0, 2, 3, 6)
    np.testing.assert_array_equal(space.macro_of, [0, 0, 1, 2, 2, 2])
    assert HierarchicalActionSpace.flat(4).m == (1, 1, 1, 1)


@pytest.mark.parametrize("m", [(), (0,), (2, -1)])
def test_action_space_rejects_empty_macro_actions(m):
    with pytest.raises(ValueError):
        HierarchicalActionSpace(m)


def test_flat_policy_is_product_of_macro_and_parameter_probabilities():
    policy = HierarchicalPolicy(np.array([[0.25, 0.75]]), (np.array([[0.5, 0.5]]), np.array([[0.1, 0.2, 0.7]])))
    np.testing.assert_allclose(policy.flat(), [[0.125, 0.125, 0.075, 0.15, 0.525]])
    assert policy.action_space == HierarchicalActionSpace((2, 3))


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_hierarchical_flat_round_trip(data):
    mdp = data.draw(tiny_mdps())
    policy = data.draw(policies_for(mdp, full_support=False))
    pi = policy.flat()
    np.testing.assert_allclose(pi.sum(axis=1), 1.0)
    back = HierarchicalPolicy.from_flat(pi, mdp.action_space)
    np.testing.assert_allclose(back.p, policy.p, atol=1e-12)
    np.testing.assert_allclose(back.flat(), pi, atol=1e-12)
    for k, (mu_k, mu_back) in enumerate(zip(policy.mu, back.mu, strict=True)):
        chosen = policy.p[:, k] > 0  # mu_k(.|s) is determined by pi only where p(k|s) > 0
        np.testing.assert_allclose(mu_back[chosen], mu_k[chosen], atol=1e-12)
        np.testing.assert_allclose(mu_back[~chosen], 1.0 / mu_k.shape[1])


def _valid_parts():
    P = np.zeros((2, 2, 2))
    P[:, :, 0] = 1.0
    return P, np.zeros((2, 2)), np.array([1.0, 0.0])


@pytest.mark.parametrize(
    "change",
    [
        lambda P, r, rho0, g: (P[:, :, :1], r, rho0, g),  # P not [S, A, S]
        lambda P, r, rho0, g: (P * 0.5, r, rho0, g),  # rows do not sum to 1
        lambda P, r, rho0, g: (P, r[:, :1], rho0, g),  # r has the wrong shape
        lambda P, r, rho0, g: (P, r + np.nan, rho0, g),  # r not finite
        lambda P, r, rho0, g: (P, r, np.array([0.5, 0.6]), g),  # rho0 not a distribution
        lambda P, r, rho0, g: (P, r, rho0, 1.0),  # gamma outside (0, 1)
        lambda P, r, rho0, g: (P, r, rho0, 0.0),
    ],
)
def test_mdp_rejects_bad_input(change):
    P, r, rho0 = _valid_parts()
    assert FiniteMDP(P, r, rho0, 0.9).n_states == 2  # the unchanged parts are valid
    with pytest.raises(ValueError):
        FiniteMDP(*change(P, r, rho0, 0.9))


def test_mdp_rejects_action_space_of_wrong_size():
    P, r, rho0 = _valid_parts()
    with pytest.raises(ValueError, match="flat actions"):
        FiniteMDP(P, r, rho0, 0.9, HierarchicalActionSpace((1, 2)))


def test_transition_rewards_are_averaged_over_next_states():
    P = np.array([[[0.25, 0.75]], [[1.0, 0.0]]])  # 2 states, 1 action
    r_sas = np.array([[[4.0, 8.0]], [[-2.0, 100.0]]])
    mdp = FiniteMDP.from_transition_rewards(P, r_sas, np.array([1.0, 0.0]), 0.5)
    np.testing.assert_allclose(mdp.r, [[7.0], [-2.0]])
    assert mdp.R == 7.0


def test_mdp_arrays_are_read_only():
    mdp = FiniteMDP(*_valid_parts(), 0.9)
    with pytest.raises(ValueError):
        mdp.r[0, 0] = 1.0
