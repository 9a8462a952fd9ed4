"""Exact quantities of Section 3 for finite MDPs, by linear algebra (no sampling).

Definitions (Section 3, "Markov Decision Processes"), with ``r_{t+1} = r(s_t, a_t)`` in expectation:

- ``V_pi = (I - gamma P_pi)^{-1} r_pi``, ``Q_pi(s, a) = r(s, a) + gamma sum_s' P(s'|s, a) V_pi(s')``,
  ``A_pi = Q_pi - V_pi``, ``eta(pi) = E_{s_0 ~ rho_0} V_pi(s_0)``.
- ``rho_pi(s) = sum_t gamma^t P_pi(s_t = s)`` (unnormalised, sums to ``1 / (1 - gamma)``), i.e.
  ``rho_pi^T = rho_0^T (I - gamma P_pi)^{-1}``.
- ``L_pi(pi~) = eta(pi) + sum_s rho_pi(s) sum_a pi~(a|s) A_pi(s, a)``.
- ``D_TV(pi(.|s), pi~(.|s)) = sup_B |pi(B|s) - pi~(B|s)| = 1/2 sum_a |pi(a|s) - pi~(a|s)|``; ``D_KL`` is
  ``D_KL(pi(.|s), pi~(.|s)) = sum_a pi(a|s) log(pi(a|s) / pi~(a|s))`` (the paper's argument order).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import rel_entr

from hrlp.theory.mdp import FiniteMDP, HierarchicalPolicy, check_policy


def state_transition(mdp: FiniteMDP, pi: np.ndarray) -> np.ndarray:
    """``P_pi[s, s'] = sum_a pi(a|s) P(s'|s, a)``, ``[S, S]``."""
    return np.einsum("sa,sat->st", pi, mdp.P)


def expected_reward(mdp: FiniteMDP, pi: np.ndarray) -> np.ndarray:
    """``r_pi[s] = sum_a pi(a|s) r(s, a)``, ``[S]``."""
    return np.einsum("sa,sa->s", pi, mdp.r)


def _resolvent_matrix(mdp: FiniteMDP, pi: np.ndarray) -> np.ndarray:
    return np.eye(mdp.n_states) - mdp.gamma * state_transition(mdp, pi)


def value(mdp: FiniteMDP, pi: np.ndarray) -> np.ndarray:
    """``V_pi`` ``[S]``, the solution of ``V = r_pi + gamma P_pi V``."""
    pi = check_policy(pi, mdp)
    return np.linalg.solve(_resolvent_matrix(mdp, pi), expected_reward(mdp, pi))


def action_value(mdp: FiniteMDP, pi: np.ndarray) -> np.ndarray:
    """``Q_pi(s, a) = r(s, a) + gamma sum_s' P(s'|s, a) V_pi(s')``, ``[S, A]``."""
    return mdp.r + mdp.gamma * mdp.P @ value(mdp, pi)


def advantage(mdp: FiniteMDP, pi: np.ndarray) -> np.ndarray:
    """``A_pi(s, a) = Q_pi(s, a) - V_pi(s)``, ``[S, A]``."""
    V = value(mdp, pi)
    return mdp.r + mdp.gamma * mdp.P @ V - V[:, None]


def eta(mdp: FiniteMDP, pi: np.ndarray) -> float:
    """Expected discounted return ``eta(pi) = E_{s_0 ~ rho_0} V_pi(s_0)``."""
    return float(mdp.rho0 @ value(mdp, pi))


def visitation(mdp: FiniteMDP, pi: np.ndarray) -> np.ndarray:
    """Unnormalised discounted visitation ``rho_pi(s) = sum_t gamma^t P_pi(s_t = s)``, ``[S]``."""
    pi = check_policy(pi, mdp)
    return np.linalg.solve(_resolvent_matrix(mdp, pi).T, mdp.rho0)


def surrogate(mdp: FiniteMDP, pi: np.ndarray, pi_tilde: np.ndarray) -> float:
    """``L_pi(pi~) = eta(pi) + sum_s rho_pi(s) sum_a pi~(a|s) A_pi(s, a)``."""
    pi_tilde = check_policy(pi_tilde, mdp)
    A_bar = np.einsum("sa,sa->s", pi_tilde, advantage(mdp, pi))
    return eta(mdp, pi) + float(visitation(mdp, pi) @ A_bar)


def tv_distance(pi: np.ndarray, pi_tilde: np.ndarray) -> np.ndarray:
    """``D_TV(pi(.|s), pi~(.|s)) = 1/2 sum_a |pi(a|s) - pi~(a|s)|`` for every state, ``[S]``."""
    return 0.5 * np.abs(np.asarray(pi) - np.asarray(pi_tilde)).sum(axis=-1)


def kl_divergence(pi: np.ndarray, pi_tilde: np.ndarray) -> np.ndarray:
    """``D_KL(pi(.|s), pi~(.|s)) = sum_a pi log(pi / pi~)`` for every state, ``[S]`` (``inf`` if not abs. continuous).

    Clipped at 0: rows that sum to 1 only up to round-off can give values like ``-1e-16``.
    """
    return np.maximum(rel_entr(np.asarray(pi), np.asarray(pi_tilde)).sum(axis=-1), 0.0)


def hierarchical_kl(policy: HierarchicalPolicy, policy_tilde: HierarchicalPolicy) -> np.ndarray:
    """Right-hand side of Lemma 1, ``D_KL(p, p~) + sum_k p_k D_KL(mu_k, mu~_k)`` for every state, ``[S]``."""
    if policy.action_space != policy_tilde.action_space or policy.p.shape != policy_tilde.p.shape:
        raise ValueError("both policies must act in the same action space with the same number of states")
    kl_macro = rel_entr(policy.p, policy_tilde.p).sum(axis=1)
    kl_params = np.stack([rel_entr(m, mt).sum(axis=1) for m, mt in zip(policy.mu, policy_tilde.mu, strict=True)], axis=1)
    # 0 * inf must count as 0: a macro-action never chosen by pi contributes nothing (abs. continuity).
    weighted = np.where(policy.p > 0, policy.p * np.where(policy.p > 0, kl_params, 0.0), 0.0)
    return np.maximum(kl_macro + weighted.sum(axis=1), 0.0)


@dataclass(frozen=True, eq=False)
class PairQuantities:
    """Every exact quantity that Theorem 1, Lemma 2 and Corollary 1 need for one pair ``(pi, pi~)``.

    Attributes:
        gamma: discount factor.
        R: reward bound ``max_{s,a} |r(s, a)|``.
        V: ``V_pi`` ``[S]``.
        A: ``A_pi`` ``[S, A]``.
        rho: ``rho_pi`` ``[S]`` (unnormalised).
        A_bar: ``E_{a ~ pi~(.|s)} A_pi(s, a)`` ``[S]``.
        eta_pi: ``eta(pi)``.
        eta_pi_tilde: ``eta(pi~)``.
        L: ``L_pi(pi~)``.
        epsilon: the paper's ``epsilon = sup_s |E_{a ~ pi~} A_pi(s, a)|`` (Theorem 1).
        epsilon_max: Schulman et al.'s ``epsilon = max_{s,a} |A_pi(s, a)|``.
        tv: ``D_TV(pi(.|s), pi~(.|s))`` ``[S]``.
        kl: ``D_KL(pi(.|s), pi~(.|s))`` ``[S]``.
    """

    gamma: float
    R: float
    V: np.ndarray
    A: np.ndarray
    rho: np.ndarray
    A_bar: np.ndarray
    eta_pi: float
    eta_pi_tilde: float
    L: float
    epsilon: float
    epsilon_max: float
    tv: np.ndarray
    kl: np.ndarray

    @property
    def tv_max(self) -> float:
        """``D_TV^max(pi, pi~) = max_s D_TV(pi(.|s), pi~(.|s))``."""
        return float(np.max(self.tv))

    @property
    def kl_max(self) -> float:
        """``D_KL^max(pi, pi~) = max_s D_KL(pi(.|s), pi~(.|s))``."""
        return float(np.max(self.kl))

    @property
    def value_scale(self) -> float:
        """``R / (1 - gamma)``, the largest possible ``|V|``; used to scale numerical tolerances."""
        return self.R / (1.0 - self.gamma)


def pair_quantities(mdp: FiniteMDP, pi: np.ndarray, pi_tilde: np.ndarray) -> PairQuantities:
    """Compute :class:`PairQuantities` for the flat policies ``pi``, ``pi~`` ``[S, A]`` with two linear solves."""
    pi = check_policy(pi, mdp)
    pi_tilde = check_policy(pi_tilde, mdp)
    M = _resolvent_matrix(mdp, pi)
    V = np.linalg.solve(M, expected_reward(mdp, pi))
    rho = np.linalg.solve(M.T, mdp.rho0)
    A = mdp.r + mdp.gamma * mdp.P @ V - V[:, None]
    A_bar = np.einsum("sa,sa->s", pi_tilde, A)
    V_tilde = np.linalg.solve(_resolvent_matrix(mdp, pi_tilde), expected_reward(mdp, pi_tilde))
    eta_pi = float(mdp.rho0 @ V)
    return PairQuantities(
        gamma=mdp.gamma,
        R=mdp.R,
        V=V,
        A=A,
        rho=rho,
        A_bar=A_bar,
        eta_pi=eta_pi,
        eta_pi_tilde=float(mdp.rho0 @ V_tilde),
        L=eta_pi + float(rho @ A_bar),
        epsilon=float(np.max(np.abs(A_bar))),
        epsilon_max=float(np.max(np.abs(A))),
        tv=tv_distance(pi, pi_tilde),
        kl=kl_divergence(pi, pi_tilde),
    )
