"""Search random and adversarial cases for violations of the statements of Section 3.

For every MDP index the search

1. draws a small MDP (2 to 5 states, a hierarchical action space with 2 to 6 flat actions, ``gamma`` from
   0.1 to 0.999, transitions from nearly uniform to nearly deterministic);
2. checks every statement on several policy pairs: near pairs (as TRPO's steps are), far pairs, mixtures
   ``(1 - alpha) pi + alpha pi'`` and near pairs of nearly deterministic policies;
3. hill-climbs on one statement (round robin over the statements): random perturbations of the MDP
   (transitions, rewards, initial state) and of both policies, accepted when they lower the statement's
   score ``slack / (allowance + 1e-3 R/(1-gamma))``. The ``1e-3 R/(1-gamma)`` term keeps the climb from
   chasing violations that shrink to round-off as the two policies merge;
4. checks Lemma 1 on a sparse pair of discrete hierarchical policies and, by Monte-Carlo, on a pair of
   hierarchical distributions with Gaussian parameters.

Before the random MDPs, the two hand-made examples of :mod:`hrlp.theory.examples` are checked on the grid
``EXAMPLE_ALPHAS x EXAMPLE_GAMMAS``. Every evaluated case counts for every statement. For each statement the
search keeps the smallest counterexample: fewest states, then fewest actions, then lowest score.
"""

from __future__ import annotations

import itertools
import math
import pathlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hrlp.theory.counterexample import Counterexample, GaussianCase, PolicyPairCase
from hrlp.theory.exact import PairQuantities, pair_quantities
from hrlp.theory.examples import two_state_example
from hrlp.theory.gaussian import GaussianHierarchical, random_gaussian_hierarchical
from hrlp.theory.mdp import FiniteMDP, HierarchicalActionSpace, HierarchicalPolicy, softmax
from hrlp.theory.statements import PAIR_CHECKS, STATEMENTS, StatementCheck, lemma1_exact, lemma1_monte_carlo

ACTION_SPACES: tuple[tuple[int, ...], ...] = ((2,), (1, 1), (3,), (1, 2), (1, 1, 1), (2, 2), (1, 3), (2, 3), (1, 2, 3))
STATE_COUNTS: tuple[int, ...] = (2, 2, 2, 3, 3, 4, 5)
GAMMAS: tuple[float, ...] = (0.1, 0.3, 0.5, 0.8, 0.9, 0.95, 0.99, 0.999)
#: Grid on which the two hand-made examples of :mod:`hrlp.theory.examples` are checked as well.
EXAMPLE_ALPHAS: tuple[float, ...] = (0.3, 0.1, 0.03, 0.01)
EXAMPLE_GAMMAS: tuple[float, ...] = (0.1, 0.3, 0.5, 0.9)
_LOGIT_MAX = 15.0
_PAIR_KINDS = ("near", "far", "mixture", "peaked_near")


@dataclass(frozen=True)
class SearchConfig:
    """Settings of :func:`search`."""

    mdps: int = 200
    """Number of random MDPs (each gets several policy pairs and one hill climb)."""
    seed: int = 0
    """Seed of the whole search; MDP ``i`` uses the ``i``-th child of ``SeedSequence(seed)``."""
    pairs_per_mdp: int = 8
    """Random policy pairs per MDP, cycling through near, far, mixture and nearly deterministic pairs."""
    climb_steps: int = 100
    """Hill-climbing proposals per MDP."""
    mc_samples: int = 20_000
    """Monte-Carlo samples for the Gaussian Lemma 1 check."""
    mc_z: float = 5.0
    """Lemma 1 (Gaussian) holds when Monte-Carlo and closed form agree within this many standard errors."""

    def __post_init__(self) -> None:
        if self.mdps <= 0:
            raise ValueError(f"mdps must be a positive integer, got {self.mdps}")
        if self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed}")
        if self.pairs_per_mdp <= 0 or self.climb_steps < 0 or self.mc_samples < 2 or self.mc_z <= 0:
            raise ValueError("pairs_per_mdp must be > 0, climb_steps >= 0, mc_samples >= 2 and mc_z > 0")


@dataclass(frozen=True)
class StatementSummary:
    """What the search found for one statement.

    Attributes:
        name, label, formula, source, corrects: as in :class:`~hrlp.theory.statements.Statement`.
        cases: number of cases checked.
        held: number of cases on which the statement held.
        min_slack: smallest ``lhs - rhs`` seen.
        min_relative_slack: smallest ``slack / allowance`` seen (0 = tight, < 0 = violated), over the cases
            whose allowance is resolvable (see :attr:`~hrlp.theory.statements.StatementCheck.relative_slack`).
        max_abs_slack: largest ``|lhs - rhs|`` seen (the error of an identity).
        max_abs_slack_over_tol: largest ``|lhs - rhs| / tol`` seen (an identity holds where this is <= 1).
        counterexample_size: ``(|S|, |A|)`` of the smallest counterexample, if any.
        counterexample_slack: its slack.
        counterexample_path: the JSON file it was saved to, if saved.
    """

    name: str
    label: str
    formula: str
    source: str
    corrects: str | None
    cases: int
    held: int
    min_slack: float
    min_relative_slack: float
    max_abs_slack: float
    max_abs_slack_over_tol: float
    counterexample_size: tuple[int, int] | None = None
    counterexample_slack: float | None = None
    counterexample_path: pathlib.Path | None = None

    @property
    def violations(self) -> int:
        """Number of cases on which the statement failed."""
        return self.cases - self.held

    @property
    def holds(self) -> bool:
        """Whether the statement held on every case checked."""
        return self.held == self.cases


@dataclass(frozen=True)
class SearchResult:
    """Summaries in :data:`~hrlp.theory.statements.STATEMENTS` order and the smallest counterexample per failing statement."""

    summaries: list[StatementSummary]
    counterexamples: dict[str, Counterexample]


@dataclass
class _Tally:
    cases: int = 0
    held: int = 0
    min_slack: float = math.inf
    min_relative_slack: float = math.inf
    max_abs_slack: float = 0.0
    max_abs_slack_over_tol: float = 0.0
    best_key: tuple[float, ...] | None = None
    best: Counterexample | None = None

    def add(self, statement: str, check: StatementCheck, case: PolicyPairCase | GaussianCase, score: float) -> None:
        self.cases += 1
        self.held += check.holds
        if not math.isnan(check.slack):
            self.min_slack = min(self.min_slack, check.slack)
            if not math.isinf(check.slack):
                self.max_abs_slack = max(self.max_abs_slack, abs(check.slack))
                self.max_abs_slack_over_tol = max(self.max_abs_slack_over_tol, abs(check.slack) / max(check.tol, 1e-300))
        if not math.isnan(check.relative_slack):
            self.min_relative_slack = min(self.min_relative_slack, check.relative_slack)
        if not check.holds:
            key = (*case.size, score)
            if self.best_key is None or key < self.best_key:
                self.best_key, self.best = key, Counterexample(statement, case, check)


@dataclass(frozen=True, eq=False)
class _Params:
    """Unconstrained parameters of one (MDP, pi, pi~) case: ``pi~ = softmax(theta + delta)``."""

    P_logits: np.ndarray  # [S, A, S]
    r: np.ndarray  # [S, A], in [-1, 1]
    rho0_logits: np.ndarray  # [S]
    theta: np.ndarray  # [S, A]
    delta: np.ndarray  # [S, A]
    gamma: float
    space: HierarchicalActionSpace

    def case(self) -> PolicyPairCase:
        mdp = FiniteMDP(softmax(self.P_logits), self.r, softmax(self.rho0_logits), self.gamma, self.space)
        theta = np.clip(self.theta, -_LOGIT_MAX, _LOGIT_MAX)
        theta_tilde = np.clip(theta + self.delta, -_LOGIT_MAX, _LOGIT_MAX)
        return PolicyPairCase(mdp, softmax(theta), softmax(theta_tilde))


def _climb_score(check: StatementCheck, q: PairQuantities) -> float:
    score = check.slack / (check.scale + 1e-3 * q.value_scale + 1e-300)
    return math.inf if math.isnan(score) else score


def _random_params(rng: np.random.Generator, S: int, space: HierarchicalActionSpace, gamma: float) -> _Params:
    A = space.size
    return _Params(
        P_logits=rng.standard_normal((S, A, S)) * rng.uniform(0.5, 5.0),
        r=rng.uniform(-1.0, 1.0, size=(S, A)),
        rho0_logits=rng.standard_normal(S),
        theta=rng.standard_normal((S, A)) * rng.uniform(0.5, 3.0),
        delta=np.zeros((S, A)),
        gamma=gamma,
        space=space,
    )


def _with_pair(rng: np.random.Generator, base: _Params, kind: str) -> _Params:
    S, A = base.theta.shape
    theta = base.theta
    if kind == "near":
        delta = rng.standard_normal((S, A)) * 10.0 ** rng.uniform(-2.5, -0.5)
    elif kind == "far":
        delta = rng.standard_normal((S, A)) * rng.uniform(1.0, 4.0)
    elif kind == "mixture":
        alpha = 10.0 ** rng.uniform(-2.0, 0.0)
        pi, pi_prime = softmax(theta), softmax(rng.standard_normal((S, A)) * 2.0)
        delta = np.log((1.0 - alpha) * pi + alpha * pi_prime) - np.log(pi)
    elif kind == "peaked_near":
        theta = theta * 4.0
        delta = rng.standard_normal((S, A)) * 10.0 ** rng.uniform(-2.0, 0.0)
    else:
        raise ValueError(f"unknown pair kind {kind!r}")
    return _Params(base.P_logits, base.r, base.rho0_logits, theta, delta, base.gamma, base.space)


def _perturb(rng: np.random.Generator, x: _Params) -> _Params:
    sigma = 10.0 ** rng.uniform(-2.0, 0.0)
    block = rng.choice(5, p=[0.2, 0.2, 0.1, 0.25, 0.25])
    P_logits, r, rho0_logits, theta, delta = x.P_logits, x.r, x.rho0_logits, x.theta, x.delta
    if block == 0:
        P_logits = P_logits + 3.0 * sigma * rng.standard_normal(P_logits.shape)
    elif block == 1:
        r = np.clip(r + sigma * rng.standard_normal(r.shape), -1.0, 1.0)
    elif block == 2:
        rho0_logits = rho0_logits + 3.0 * sigma * rng.standard_normal(rho0_logits.shape)
    elif block == 3:
        theta = theta + 3.0 * sigma * rng.standard_normal(theta.shape)
    elif rng.random() < 0.5:
        rms = float(np.sqrt(np.mean(delta**2)))
        delta = delta + sigma * (rms + 1e-2) * rng.standard_normal(delta.shape)
    else:
        delta = delta * math.exp(2.0 * sigma * rng.standard_normal())
    return _Params(P_logits, r, rho0_logits, theta, delta, x.gamma, x.space)


class _Searcher:
    def __init__(self) -> None:
        self.tallies = {name: _Tally() for name in STATEMENTS}

    def evaluate(self, params: _Params, with_lemma1: bool = False) -> dict[str, float]:
        """Check every pair statement (and Lemma 1 if asked) on ``params``; return each pair statement's climb score."""
        return self.evaluate_case(params.case(), with_lemma1)

    def evaluate_case(self, case: PolicyPairCase, with_lemma1: bool = False) -> dict[str, float]:
        """:meth:`evaluate` for a case given directly."""
        q = pair_quantities(case.mdp, case.pi, case.pi_tilde)
        scores = {}
        for name, check_fn in PAIR_CHECKS.items():
            check = check_fn(q)
            scores[name] = _climb_score(check, q)
            self.tallies[name].add(name, check, case, scores[name])
        if with_lemma1:
            space = case.mdp.action_space
            policies = (HierarchicalPolicy.from_flat(case.pi, space), HierarchicalPolicy.from_flat(case.pi_tilde, space))
            self._lemma1_exact(case, *policies)
        return scores

    def _lemma1_exact(self, case: PolicyPairCase, policy: HierarchicalPolicy, policy_tilde: HierarchicalPolicy) -> None:
        check = lemma1_exact(policy, policy_tilde)
        self.tallies["lemma1_exact"].add("lemma1_exact", check, case, -abs(check.slack))

    def lemma1_sparse(self, rng: np.random.Generator, mdp: FiniteMDP) -> None:
        """Lemma 1 where pi has zeros (a whole macro-action and single parameters) and pi~ has full support."""
        S, space = mdp.n_states, mdp.action_space
        pi = rng.dirichlet(np.ones(space.size), size=S) * (rng.random((S, space.size)) < 0.6)
        if space.n > 1:
            pi[space.macro_of[None, :] == rng.integers(space.n, size=(S, 1))] = 0.0
        for s in np.flatnonzero(pi.sum(axis=1) == 0.0):
            pi[s, rng.integers(space.size)] = 1.0
        pi = pi / pi.sum(axis=1, keepdims=True)
        pi_tilde = rng.dirichlet(np.ones(space.size), size=S)
        case = PolicyPairCase(mdp, pi, pi_tilde)
        self._lemma1_exact(case, HierarchicalPolicy.from_flat(pi, space), HierarchicalPolicy.from_flat(pi_tilde, space))

    def lemma1_gaussian(self, rng: np.random.Generator, config: SearchConfig) -> None:
        """Lemma 1 by Monte-Carlo for Gaussian parameters (near or far pair)."""
        dims = tuple(int(d) for d in rng.integers(0, 4, size=rng.integers(1, 4)))
        mu = random_gaussian_hierarchical(rng, dims)
        if rng.random() < 0.5:
            mu_tilde = random_gaussian_hierarchical(rng, dims)
        else:
            step = 10.0 ** rng.uniform(-2.0, -0.5)
            p = softmax(np.log(mu.p) + step * rng.standard_normal(len(dims)))
            mu_tilde = GaussianHierarchical(
                p,
                tuple(m + step * rng.standard_normal(m.shape) for m in mu.mean),
                tuple(s + step * rng.standard_normal(s.shape) for s in mu.log_std),
            )
        case = GaussianCase(mu, mu_tilde, int(rng.integers(2**63)), config.mc_samples, config.mc_z)
        check = lemma1_monte_carlo(mu, mu_tilde, np.random.default_rng(case.seed), case.n_samples, case.z)
        self.tallies["lemma1_monte_carlo"].add("lemma1_monte_carlo", check, case, -abs(check.slack) / max(check.tol, 1e-300))

    def climb(self, rng: np.random.Generator, start: _Params, target: str, start_score: float, steps: int) -> None:
        """Random hill climbing that lowers ``target``'s climb score."""
        x, best = start, start_score
        for _ in range(steps):
            y = _perturb(rng, x)
            score = self.evaluate(y)[target]
            if score < best:
                x, best = y, score


def search(config: SearchConfig, progress: Callable[[int], None] | None = None) -> SearchResult:
    """Run the search of this module; ``progress(i)`` is called after MDP ``i`` is done."""
    searcher = _Searcher()
    for alpha, gamma, signed in itertools.product(EXAMPLE_ALPHAS, EXAMPLE_GAMMAS, (False, True)):
        searcher.evaluate_case(two_state_example(alpha, gamma, signed), with_lemma1=True)
    targets = list(PAIR_CHECKS)
    for i, child in enumerate(np.random.SeedSequence(config.seed).spawn(config.mdps)):
        rng = np.random.default_rng(child)
        space = HierarchicalActionSpace(ACTION_SPACES[rng.integers(len(ACTION_SPACES))])
        S = int(STATE_COUNTS[rng.integers(len(STATE_COUNTS))])
        gamma = float(GAMMAS[rng.integers(len(GAMMAS))])
        base = _random_params(rng, S, space, gamma)
        target = targets[i % len(targets)]
        start, start_score = base, math.inf
        for j in range(config.pairs_per_mdp):
            params = _with_pair(rng, base, _PAIR_KINDS[j % len(_PAIR_KINDS)])
            score = searcher.evaluate(params, with_lemma1=True)[target]
            if score < start_score:
                start, start_score = params, score
        searcher.climb(rng, start, target, start_score, config.climb_steps)
        searcher.lemma1_sparse(rng, start.case().mdp)
        searcher.lemma1_gaussian(rng, config)
        if progress is not None:
            progress(i)
    summaries, counterexamples = [], {}
    for name, statement in STATEMENTS.items():
        t = searcher.tallies[name]
        if t.best is not None:
            counterexamples[name] = t.best
        summaries.append(
            StatementSummary(
                name=name,
                label=statement.label,
                formula=statement.formula,
                source=statement.source,
                corrects=statement.corrects,
                cases=t.cases,
                held=t.held,
                min_slack=t.min_slack,
                min_relative_slack=t.min_relative_slack,
                max_abs_slack=t.max_abs_slack,
                max_abs_slack_over_tol=t.max_abs_slack_over_tol,
                counterexample_size=None if t.best is None else t.best.case.size,
                counterexample_slack=None if t.best is None else t.best.check.slack,
            )
        )
    return SearchResult(summaries, counterexamples)
