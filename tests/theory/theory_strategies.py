"""Hypothesis strategies for tiny finite MDPs with hierarchical action spaces."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from hrlp.theory import FiniteMDP, HierarchicalActionSpace, HierarchicalPolicy, random_hierarchical_policy, random_mdp

action_spaces = st.lists(st.integers(1, 3), min_size=1, max_size=3).map(lambda m: HierarchicalActionSpace(tuple(m)))


@st.composite
def tiny_mdps(draw: st.DrawFn, max_states: int = 3, max_gamma: float = 0.9) -> FiniteMDP:
    """An MDP with 1 to ``max_states`` states, up to 9 flat actions, ``gamma`` in [0.05, max_gamma]."""
    n_states = draw(st.integers(1, max_states))
    space = draw(action_spaces)
    gamma = draw(st.floats(0.05, max_gamma))
    concentration = draw(st.sampled_from([0.2, 1.0, 5.0]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    return random_mdp(rng, n_states, space, gamma, concentration=concentration)


@st.composite
def policies_for(draw: st.DrawFn, mdp: FiniteMDP, full_support: bool = True) -> HierarchicalPolicy:
    """A random hierarchical policy for ``mdp``; with ``full_support=False`` it may have zeros."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    policy = random_hierarchical_policy(
        rng, mdp.n_states, mdp.action_space, concentration=draw(st.sampled_from([0.3, 1.0, 3.0]))
    )
    if full_support:
        return policy
    keep_p = rng.random(policy.p.shape) < 0.7
    keep_p[np.arange(mdp.n_states), rng.integers(policy.p.shape[1], size=mdp.n_states)] = True
    p = policy.p * keep_p
    mu = []
    for mu_k in policy.mu:
        keep = rng.random(mu_k.shape) < 0.7
        keep[np.arange(mdp.n_states), rng.integers(mu_k.shape[1], size=mdp.n_states)] = True
        mu.append(mu_k * keep / (mu_k * keep).sum(axis=1, keepdims=True))
    return HierarchicalPolicy(p / p.sum(axis=1, keepdims=True), tuple(mu))


@st.composite
def mdp_and_pair(draw: st.DrawFn, max_states: int = 3, max_gamma: float = 0.9) -> tuple[FiniteMDP, np.ndarray, np.ndarray]:
    """An MDP and two full-support flat policies ``pi``, ``pi~`` ``[S, A]``, near (as TRPO's steps) or far apart."""
    mdp = draw(tiny_mdps(max_states=max_states, max_gamma=max_gamma))
    pi = draw(policies_for(mdp)).flat()
    if draw(st.booleans()):
        pi_tilde = draw(policies_for(mdp)).flat()
    else:
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        logits = np.log(pi) + draw(st.sampled_from([1e-3, 1e-2, 1e-1])) * rng.standard_normal(pi.shape)
        pi_tilde = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    return mdp, pi, pi_tilde
