"""One function per statement of Section 3, each returning both sides, the slack and whether it holds.

Every inequality is written as ``lhs >= rhs`` with ``slack = lhs - rhs``; it holds when
``slack >= -tol``. Lemma 1 is an identity: ``slack = lhs - rhs`` and it holds when ``|slack| <= tol``.

Besides the paper's statements (Lemma 1, Theorem 1, Lemma 2, Corollary 1) the module checks the
inequalities that replace the ones that fail (see ``docs/theory.md``):

- Schulman et al. 2015, Theorem 1 and its KL form (their (9)), with ``epsilon_max = max_{s,a} |A_pi(s, a)|``,
  and (5) read with ``epsilon_max`` (which follows from their Theorem 1 and Pinsker's inequality).
- (2) read with ``epsilon_max``: half of Schulman et al.'s penalty; a variant that no proof covers.
- (2'), (4'), (5'), (6'): Theorem 1 and Corollary 1 with the exponents that the coupling proof gives.

With ``alpha = D_TV^max(pi, pi~)``, ``epsilon = max_s |E_{pi~} A_pi(s, .)|``, ``R = max |r|``:

==========================  =================================================================
statement                   lower bound on ``eta(pi~)``
==========================  =================================================================
Theorem 1 (2)               ``L - 2 epsilon gamma / (1-gamma)^2 alpha^2``
Corollary 1 (4)             ``L - 8 R gamma / (1-gamma)^3 alpha^3``
Corollary 1 (5)             ``L - 2 epsilon gamma / (1-gamma)^2 D_KL^max``
Corollary 1 (6)             ``L - 2 sqrt(2) R gamma / (1-gamma)^3 (D_KL^max)^(3/2)``
Schulman Thm 1              ``L - 4 epsilon_max gamma / (1-gamma)^2 alpha^2``
Schulman (9)                ``L - 4 epsilon_max gamma / (1-gamma)^2 D_KL^max``
(5) with epsilon_max        ``L - 2 epsilon_max gamma / (1-gamma)^2 D_KL^max``
(2) with epsilon_max        ``L - 2 epsilon_max gamma / (1-gamma)^2 alpha^2``  (variant)
(2')                        ``L - 2 epsilon gamma / (1-gamma)^2 alpha``
(4')                        ``L - 8 R gamma / (1-gamma)^3 alpha^2``
(5')                        ``L - sqrt(2) epsilon gamma / (1-gamma)^2 sqrt(D_KL^max)``
(6')                        ``L - 4 R gamma / (1-gamma)^3 D_KL^max``
==========================  =================================================================
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hrlp.theory.exact import PairQuantities, hierarchical_kl, kl_divergence
from hrlp.theory.gaussian import GaussianHierarchical, kl_monte_carlo, lemma1_rhs
from hrlp.theory.mdp import HierarchicalPolicy

#: Relative tolerance for exact checks: well above the round-off of solving ``(I - gamma P) V = r``.
REL_TOL = 1e-9
#: :attr:`StatementCheck.relative_slack` is reported only when the allowance exceeds this many tolerances.
RESOLVABLE = 1e3


@dataclass(frozen=True)
class Statement:
    """Description of one checked statement.

    Attributes:
        name: identifier, e.g. ``"theorem1"``.
        label: where it comes from, e.g. ``"Theorem 1 (2)"``.
        formula: the inequality or identity in plain text.
        source: ``"paper"`` for the paper's statements, ``"corrected"`` for proven replacements,
            ``"variant"`` for another reading of a paper statement that no proof here covers.
        corrects: for a replacement or variant, the name of the paper statement it stands for.
        relation: ``">="`` for an inequality, ``"=="`` for an identity.
    """

    name: str
    label: str
    formula: str
    source: str
    corrects: str | None = None
    relation: str = ">="


@dataclass(frozen=True)
class StatementCheck:
    """Outcome of checking one statement on one case.

    Attributes:
        name: the statement's name (a key of :data:`STATEMENTS`).
        lhs: the side claimed to be larger (or equal, for an identity).
        rhs: the other side.
        slack: ``lhs - rhs`` (0 for an identity whose sides are the same infinity).
        holds: ``slack >= -tol`` for an inequality, ``|slack| <= tol`` for an identity.
        tol: numerical tolerance (round-off for exact checks, a few standard errors for Monte-Carlo).
        relation: ``">="`` or ``"=="``.
        scale: the size of the bound's allowance (e.g. the penalty term), used for :attr:`relative_slack`.
    """

    name: str
    lhs: float
    rhs: float
    slack: float
    holds: bool
    tol: float
    relation: str
    scale: float

    @property
    def relative_slack(self) -> float:
        """``slack / scale``: 0 means tight, negative means violated by that fraction of the allowance.

        NaN when the allowance is below ``RESOLVABLE * tol``: a ratio of round-off to round-off says nothing.
        """
        if math.isnan(self.slack) or not math.isfinite(self.scale) or self.scale < RESOLVABLE * self.tol:
            return math.nan
        return self.slack / self.scale


def _geq(name: str, lhs: float, rhs: float, tol: float, scale: float) -> StatementCheck:
    slack = lhs - rhs
    holds = bool(slack >= -tol) if not math.isnan(slack) else False
    return StatementCheck(name, float(lhs), float(rhs), float(slack), holds, float(tol), ">=", float(scale))


def _eq(name: str, lhs: float, rhs: float, tol: float) -> StatementCheck:
    slack = lhs - rhs
    if math.isinf(lhs) and math.isinf(rhs) and lhs == rhs:
        slack = 0.0
    holds = bool(abs(slack) <= tol)
    return StatementCheck(name, float(lhs), float(rhs), float(slack), holds, float(tol), "==", max(abs(float(rhs)), tol))


def _value_tol(q: PairQuantities) -> float:
    return REL_TOL * max(q.value_scale, 1e-300)


def _lower_bound(name: str, q: PairQuantities, penalty: float) -> StatementCheck:
    """``eta(pi~) >= L_pi(pi~) - penalty``."""
    rhs = q.L - penalty if not math.isinf(penalty) else -math.inf
    return _geq(name, q.eta_pi_tilde, rhs, _value_tol(q), penalty)


def _c2(gamma: float) -> float:
    return gamma / (1.0 - gamma) ** 2


def _c3(gamma: float) -> float:
    return gamma / (1.0 - gamma) ** 3


def _safe_mul(coefficient: float, distance: float) -> float:
    """``coefficient * distance`` with ``0 * inf = 0`` (a zero coefficient makes the bound exact)."""
    return 0.0 if coefficient == 0.0 else coefficient * distance


# --- Lemma 1 ---------------------------------------------------------------------------------------


def lemma1_exact(policy: HierarchicalPolicy, policy_tilde: HierarchicalPolicy) -> StatementCheck:
    """Lemma 1, (1): ``D_KL(mu, mu~) = D_KL(p, p~) + sum_k p_k D_KL(mu_k, mu~_k)``, exactly, at every state.

    The left side is the KL of the flattened distributions over ``|A| = sum_k m_k`` actions; the check
    reports the state with the largest ``|lhs - rhs|``.
    """
    lhs = kl_divergence(policy.flat(), policy_tilde.flat())
    rhs = hierarchical_kl(policy, policy_tilde)
    with np.errstate(invalid="ignore"):
        gap = np.where(np.isinf(lhs) & (lhs == rhs), 0.0, np.abs(lhs - rhs))
    s = int(np.nanargmax(np.where(np.isnan(gap), np.inf, gap)))
    return _eq("lemma1_exact", float(lhs[s]), float(rhs[s]), REL_TOL * (1.0 + abs(float(rhs[s]))))


def lemma1_monte_carlo(
    mu: GaussianHierarchical,
    mu_tilde: GaussianHierarchical,
    rng: np.random.Generator,
    n_samples: int = 20_000,
    z: float = 5.0,
) -> StatementCheck:
    """Lemma 1, (1), with Gaussian parameters: Monte-Carlo ``E_mu log(dmu/dmu~)`` against the closed form.

    ``lhs`` is the Monte-Carlo estimate of ``D_KL(mu, mu~)`` from the joint densities, ``rhs`` the closed-form
    right-hand side of (1); the identity holds when they agree within ``z`` standard errors (``tol``).
    """
    estimate, stderr = kl_monte_carlo(mu, mu_tilde, rng, n_samples)
    rhs = lemma1_rhs(mu, mu_tilde)
    # The round-off term matters only when every sample gives the same log-ratio (stderr = 0).
    return _eq("lemma1_monte_carlo", estimate, rhs, z * stderr + REL_TOL * (1.0 + abs(rhs)))


# --- the paper's Theorem 1, Lemma 2, Corollary 1 -----------------------------------------------------


def theorem1(q: PairQuantities) -> StatementCheck:
    """Theorem 1, (2): ``eta(pi~) >= L_pi(pi~) - 2 eps gamma / (1-gamma)^2 (D_TV^max)^2``, ``eps = max_s |E_{pi~} A_pi|``."""
    return _lower_bound("theorem1", q, 2.0 * q.epsilon * _c2(q.gamma) * q.tv_max**2)


def lemma2(q: PairQuantities) -> StatementCheck:
    """Lemma 2, (3): ``max_s |E_{a ~ pi~} A_pi(s, a)| <= 4R / (1-gamma) D_TV^max``.

    Checked as ``lhs = 4R / (1-gamma) D_TV^max >= rhs = max_s |E_{pi~} A_pi(s, .)|``.
    """
    bound = 4.0 * q.R / (1.0 - q.gamma) * q.tv_max
    return _geq("lemma2", bound, q.epsilon, _value_tol(q), bound)


def corollary1_tv(q: PairQuantities) -> StatementCheck:
    """Corollary 1, (4): ``eta(pi~) >= L_pi(pi~) - 8 R gamma / (1-gamma)^3 (D_TV^max)^3``."""
    return _lower_bound("corollary1_tv", q, 8.0 * q.R * _c3(q.gamma) * q.tv_max**3)


def corollary1_kl_epsilon(q: PairQuantities) -> StatementCheck:
    """Corollary 1, (5): ``eta(pi~) >= L_pi(pi~) - 2 eps gamma / (1-gamma)^2 D_KL^max``."""
    return _lower_bound("corollary1_kl_epsilon", q, _safe_mul(2.0 * q.epsilon * _c2(q.gamma), q.kl_max))


def corollary1_kl_reward(q: PairQuantities) -> StatementCheck:
    """Corollary 1, (6): ``eta(pi~) >= L_pi(pi~) - 2 sqrt(2) R gamma / (1-gamma)^3 (D_KL^max)^(3/2)``."""
    return _lower_bound("corollary1_kl_reward", q, _safe_mul(2.0 * math.sqrt(2.0) * q.R * _c3(q.gamma), q.kl_max**1.5))


# --- replacements that hold ----------------------------------------------------------------------------


def schulman_theorem1(q: PairQuantities) -> StatementCheck:
    """Schulman et al. 2015, Theorem 1: ``eta(pi~) >= L_pi(pi~) - 4 eps gamma / (1-gamma)^2 alpha^2``.

    Here ``eps = max_{s,a} |A_pi(s, a)|`` and ``alpha = D_TV^max(pi, pi~)``.
    """
    return _lower_bound("schulman_theorem1", q, 4.0 * q.epsilon_max * _c2(q.gamma) * q.tv_max**2)


def schulman_kl(q: PairQuantities) -> StatementCheck:
    """Schulman et al. 2015, (9): ``eta(pi~) >= L_pi(pi~) - 4 eps gamma / (1-gamma)^2 D_KL^max``, ``eps = max |A_pi|``."""
    return _lower_bound("schulman_kl", q, _safe_mul(4.0 * q.epsilon_max * _c2(q.gamma), q.kl_max))


def corollary1_kl_epsilon_max(q: PairQuantities) -> StatementCheck:
    """(5) with Schulman's ``eps = max_{s,a} |A_pi(s, a)|``: ``eta(pi~) >= L_pi(pi~) - 2 eps gamma / (1-gamma)^2 D_KL^max``.

    Follows from Schulman et al.'s Theorem 1 and Pinsker's ``alpha^2 <= D_KL / 2``.
    """
    return _lower_bound("corollary1_kl_epsilon_max", q, _safe_mul(2.0 * q.epsilon_max * _c2(q.gamma), q.kl_max))


def theorem1_epsilon_max(q: PairQuantities) -> StatementCheck:
    """(2) with Schulman's ``eps = max_{s,a} |A_pi(s, a)|``: ``eta(pi~) >= L_pi(pi~) - 2 eps gamma / (1-gamma)^2 alpha^2``.

    Half of Schulman et al.'s penalty. Not implied by any proof here; checked to see whether the paper's
    constant 2 survives with Schulman's ``eps``.
    """
    return _lower_bound("theorem1_epsilon_max", q, 2.0 * q.epsilon_max * _c2(q.gamma) * q.tv_max**2)


def theorem1_corrected(q: PairQuantities) -> StatementCheck:
    """(2'): ``eta(pi~) >= L_pi(pi~) - 2 eps gamma / (1-gamma)^2 D_TV^max`` with the paper's ``eps = max_s |E_{pi~} A_pi|``.

    This is what the coupling proof gives: with ``alpha = D_TV^max``,
    ``|eta(pi~) - L_pi(pi~)| <= sum_t gamma^t 2 eps (1 - (1 - alpha)^t)
    = 2 eps gamma alpha / ((1-gamma)(1-gamma+gamma alpha)) <= 2 eps gamma alpha / (1-gamma)^2``.
    """
    return _lower_bound("theorem1_corrected", q, 2.0 * q.epsilon * _c2(q.gamma) * q.tv_max)


def corollary1_tv_corrected(q: PairQuantities) -> StatementCheck:
    """(4'): ``eta(pi~) >= L_pi(pi~) - 8 R gamma / (1-gamma)^3 (D_TV^max)^2``, i.e. (2') combined with Lemma 2 (3)."""
    return _lower_bound("corollary1_tv_corrected", q, 8.0 * q.R * _c3(q.gamma) * q.tv_max**2)


def corollary1_kl_epsilon_corrected(q: PairQuantities) -> StatementCheck:
    """(5'): ``eta(pi~) >= L_pi(pi~) - sqrt(2) eps gamma / (1-gamma)^2 sqrt(D_KL^max)``, (2') with Pinsker."""
    return _lower_bound(
        "corollary1_kl_epsilon_corrected", q, _safe_mul(math.sqrt(2.0) * q.epsilon * _c2(q.gamma), math.sqrt(q.kl_max))
    )


def corollary1_kl_reward_corrected(q: PairQuantities) -> StatementCheck:
    """(6'): ``eta(pi~) >= L_pi(pi~) - 4 R gamma / (1-gamma)^3 D_KL^max``, (4') with Pinsker."""
    return _lower_bound("corollary1_kl_reward_corrected", q, _safe_mul(4.0 * q.R * _c3(q.gamma), q.kl_max))


#: Every checked statement, in report order.
STATEMENTS: dict[str, Statement] = {
    s.name: s
    for s in (
        Statement(
            "lemma1_exact", "Lemma 1 (1), discrete", "D_KL(μ, μ̃) = D_KL(p, p̃) + Σ_k p_k D_KL(μ_k, μ̃_k)", "paper", relation="=="
        ),
        Statement(
            "lemma1_monte_carlo",
            "Lemma 1 (1), Gaussian",
            "E_μ log dμ/dμ̃ (Monte-Carlo) = D_KL(p, p̃) + Σ_k p_k D_KL(N_k, Ñ_k), within 5 standard errors",
            "paper",
            relation="==",
        ),
        Statement("theorem1", "Theorem 1 (2)", "η(π̃) ≥ L_π(π̃) − 2εγ/(1−γ)² · (D_TV^max)²,  ε = max_s |E_π̃ A_π(s,·)|", "paper"),
        Statement("lemma2", "Lemma 2 (3)", "max_s |E_π̃ A_π(s,·)| ≤ 4R/(1−γ) · D_TV^max", "paper"),
        Statement("corollary1_tv", "Corollary 1 (4)", "η(π̃) ≥ L_π(π̃) − 8Rγ/(1−γ)³ · (D_TV^max)³", "paper"),
        Statement("corollary1_kl_epsilon", "Corollary 1 (5)", "η(π̃) ≥ L_π(π̃) − 2εγ/(1−γ)² · D_KL^max", "paper"),
        Statement("corollary1_kl_reward", "Corollary 1 (6)", "η(π̃) ≥ L_π(π̃) − 2√2 Rγ/(1−γ)³ · (D_KL^max)^(3/2)", "paper"),
        Statement(
            "schulman_theorem1",
            "Schulman et al. 2015, Theorem 1",
            "η(π̃) ≥ L_π(π̃) − 4ε'γ/(1−γ)² · (D_TV^max)²,  ε' = max_{s,a} |A_π(s,a)|",
            "corrected",
            "theorem1",
        ),
        Statement(
            "schulman_kl",
            "Schulman et al. 2015, (9)",
            "η(π̃) ≥ L_π(π̃) − 4ε'γ/(1−γ)² · D_KL^max,  ε' = max_{s,a} |A_π(s,a)|",
            "corrected",
            "corollary1_kl_epsilon",
        ),
        Statement(
            "corollary1_kl_epsilon_max",
            "(5) with Schulman's ε",
            "η(π̃) ≥ L_π(π̃) − 2ε'γ/(1−γ)² · D_KL^max,  ε' = max_{s,a} |A_π(s,a)|",
            "corrected",
            "corollary1_kl_epsilon",
        ),
        Statement(
            "theorem1_epsilon_max",
            "(2) with Schulman's ε (unproven variant)",
            "η(π̃) ≥ L_π(π̃) − 2ε'γ/(1−γ)² · (D_TV^max)²,  ε' = max_{s,a} |A_π(s,a)|",
            "variant",
            "theorem1",
        ),
        Statement(
            "theorem1_corrected", "(2') corrected Theorem 1", "η(π̃) ≥ L_π(π̃) − 2εγ/(1−γ)² · D_TV^max", "corrected", "theorem1"
        ),
        Statement(
            "corollary1_tv_corrected",
            "(4') corrected Corollary 1",
            "η(π̃) ≥ L_π(π̃) − 8Rγ/(1−γ)³ · (D_TV^max)²",
            "corrected",
            "corollary1_tv",
        ),
        Statement(
            "corollary1_kl_epsilon_corrected",
            "(5') corrected Corollary 1",
            "η(π̃) ≥ L_π(π̃) − √2 εγ/(1−γ)² · (D_KL^max)^(1/2)",
            "corrected",
            "corollary1_kl_epsilon",
        ),
        Statement(
            "corollary1_kl_reward_corrected",
            "(6') corrected Corollary 1",
            "η(π̃) ≥ L_π(π̃) − 4Rγ/(1−γ)³ · D_KL^max",
            "corrected",
            "corollary1_kl_reward",
        ),
    )
}

#: The statements about a pair of policies in an MDP, as functions of :class:`PairQuantities`.
PAIR_CHECKS: dict[str, Callable[[PairQuantities], StatementCheck]] = {
    "theorem1": theorem1,
    "lemma2": lemma2,
    "corollary1_tv": corollary1_tv,
    "corollary1_kl_epsilon": corollary1_kl_epsilon,
    "corollary1_kl_reward": corollary1_kl_reward,
    "schulman_theorem1": schulman_theorem1,
    "schulman_kl": schulman_kl,
    "corollary1_kl_epsilon_max": corollary1_kl_epsilon_max,
    "theorem1_epsilon_max": theorem1_epsilon_max,
    "theorem1_corrected": theorem1_corrected,
    "corollary1_tv_corrected": corollary1_tv_corrected,
    "corollary1_kl_epsilon_corrected": corollary1_kl_epsilon_corrected,
    "corollary1_kl_reward_corrected": corollary1_kl_reward_corrected,
}


def check_pair(q: PairQuantities) -> dict[str, StatementCheck]:
    """Check every statement of :data:`PAIR_CHECKS` on one pair of policies."""
    return {name: check(q) for name, check in PAIR_CHECKS.items()}
