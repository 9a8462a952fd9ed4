"""Section 3 of the paper as executable checks: Lemma 1, Theorem 1, Lemma 2 and Corollary 1.

- :mod:`~hrlp.theory.mdp`: finite MDPs with a hierarchical action space, hierarchical <-> flat policies.
- :mod:`~hrlp.theory.exact`: ``V``, ``Q``, ``A``, ``eta``, ``rho``, ``L``, ``D_TV``, ``D_KL`` by linear algebra.
- :mod:`~hrlp.theory.gaussian`: hierarchical distributions with Gaussian parameters (Lemma 1 by Monte-Carlo).
- :mod:`~hrlp.theory.statements`: one function per statement, plus the corrected bounds.
- :mod:`~hrlp.theory.search`: random and hill-climbing search for counterexamples.
- :mod:`~hrlp.theory.counterexample`: counterexamples as JSON files that reproduce the violation.
- :mod:`~hrlp.theory.examples`: a two-state MDP, solvable by hand, on which (2) and (4)-(6) fail.
- :func:`run_theory`: the ``hrlp theory`` command.

See ``docs/theory.md`` for what holds, what fails and why.
"""

from hrlp.theory.counterexample import (
    Counterexample,
    GaussianCase,
    PolicyPairCase,
    check_case,
    load_counterexample,
    recheck,
    save_counterexample,
)
from hrlp.theory.exact import (
    PairQuantities,
    action_value,
    advantage,
    eta,
    hierarchical_kl,
    kl_divergence,
    pair_quantities,
    surrogate,
    tv_distance,
    value,
    visitation,
)
from hrlp.theory.examples import two_state_example, two_state_gap
from hrlp.theory.gaussian import GaussianHierarchical, gaussian_kl, kl_monte_carlo, lemma1_rhs
from hrlp.theory.mdp import (
    FiniteMDP,
    HierarchicalActionSpace,
    HierarchicalPolicy,
    random_hierarchical_policy,
    random_mdp,
)
from hrlp.theory.report import run_theory, statement_table
from hrlp.theory.search import SearchConfig, SearchResult, StatementSummary, search
from hrlp.theory.statements import (
    PAIR_CHECKS,
    STATEMENTS,
    Statement,
    StatementCheck,
    check_pair,
    corollary1_kl_epsilon,
    corollary1_kl_epsilon_corrected,
    corollary1_kl_epsilon_max,
    corollary1_kl_reward,
    corollary1_kl_reward_corrected,
    corollary1_tv,
    corollary1_tv_corrected,
    lemma1_exact,
    lemma1_monte_carlo,
    lemma2,
    schulman_kl,
    schulman_theorem1,
    theorem1,
    theorem1_corrected,
    theorem1_epsilon_max,
)

__all__ = [
    "PAIR_CHECKS",
    "STATEMENTS",
    "Counterexample",
    "FiniteMDP",
    "GaussianCase",
    "GaussianHierarchical",
    "HierarchicalActionSpace",
    "HierarchicalPolicy",
    "PairQuantities",
    "PolicyPairCase",
    "SearchConfig",
    "SearchResult",
    "Statement",
    "StatementCheck",
    "StatementSummary",
    "action_value",
    "advantage",
    "check_case",
    "check_pair",
    "corollary1_kl_epsilon",
    "corollary1_kl_epsilon_corrected",
    "corollary1_kl_epsilon_max",
    "corollary1_kl_reward",
    "corollary1_kl_reward_corrected",
    "corollary1_tv",
    "corollary1_tv_corrected",
    "eta",
    "gaussian_kl",
    "hierarchical_kl",
    "kl_divergence",
    "kl_monte_carlo",
    "lemma1_exact",
    "lemma1_monte_carlo",
    "lemma1_rhs",
    "lemma2",
    "load_counterexample",
    "pair_quantities",
    "random_hierarchical_policy",
    "random_mdp",
    "recheck",
    "run_theory",
    "save_counterexample",
    "schulman_kl",
    "schulman_theorem1",
    "search",
    "statement_table",
    "surrogate",
    "theorem1",
    "theorem1_corrected",
    "theorem1_epsilon_max",
    "tv_distance",
    "two_state_example",
    "two_state_gap",
    "value",
    "visitation",
]
