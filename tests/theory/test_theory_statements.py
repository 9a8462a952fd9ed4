"""Each statement's check: consistent fields, known answers on the two-state MDP, corrected bounds hold."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from theory_strategies import mdp_and_pair

from hrlp.theory import (
    PAIR_CHECKS,
    STATEMENTS,
    check_pair,
    lemma2,
    pair_quantities,
    schulman_theorem1,
    theorem1,
    theorem1_epsilon_max,
    two_state_example,
    two_state_gap,
)

PAPER = ["theorem1", "corollary1_tv", "corollary1_kl_epsilon", "corollary1_kl_reward"]
HOLDING = [name for name in PAIR_CHECKS if STATEMENTS[name].source == "corrected"] + ["lemma2"]


def test_every_statement_is_described():
    assert set(PAIR_CHECKS) | {"lemma1_exact", "lemma1_monte_carlo"} == set(STATEMENTS)
    for s in STATEMENTS.values():
        assert s.source in ("paper", "corrected", "variant")
        assert (s.corrects is None) == (s.source == "paper")
        assert s.corrects is None or STATEMENTS[s.corrects].source == "paper"


@settings(max_examples=40, deadline=None)
@given(mdp_and_pair())
def test_check_fields_are_consistent(case):
    q = pair_quantities(*case)
    for name, check in check_pair(q).items():
        assert check.name == name
        assert check.relation == ">="
        assert check.slack == check.lhs - check.rhs
        assert check.holds == (check.slack >= -check.tol)
        assert check.tol > 0
        if not math.isnan(check.relative_slack):
            assert check.relative_slack == pytest.approx(check.slack / check.scale)
    # Every lower bound on eta(pi~) has eta(pi~) on the left and L_pi(pi~) - penalty on the right.
    assert theorem1(q).lhs == q.eta_pi_tilde
    assert theorem1(q).rhs == pytest.approx(q.L - 2 * q.epsilon * q.gamma / (1 - q.gamma) ** 2 * q.tv_max**2)
    assert lemma2(q).rhs == q.epsilon


@settings(max_examples=60, deadline=None)
@given(mdp_and_pair(max_states=3, max_gamma=0.99))
def test_lemma2_schulman_and_corrected_bounds_hold(case):
    checks = check_pair(pair_quantities(*case))
    for name in HOLDING:
        assert checks[name].holds, checks[name]


@pytest.mark.parametrize("signed", [False, True])
def test_two_state_examples_match_their_closed_forms(signed):
    for alpha, gamma in [(0.1, 0.5), (0.01, 0.9), (0.3, 0.99), (0.0, 0.7), (0.2, 0.05)]:
        case = two_state_example(alpha, gamma, signed)
        q = pair_quantities(case.mdp, case.pi, case.pi_tilde)
        assert q.eta_pi_tilde - q.L == pytest.approx(two_state_gap(alpha, gamma, signed), rel=1e-9, abs=1e-15)
        assert q.tv_max == pytest.approx(alpha)
        assert q.epsilon == pytest.approx(2 * alpha if signed else alpha)  # the paper's epsilon
        assert q.epsilon_max == pytest.approx(1.0 if signed else 0.5)  # Schulman's epsilon
        assert q.R == 1.0


def test_example_b_breaks_the_epsilon_max_reading_and_schulman_constant_is_sharp():
    """(2) with eps = max|A| and constant 2 fails; Schulman's constant 4 is approached as gamma, alpha -> 0."""
    case = two_state_example(0.1, 0.1, signed=True)
    check = theorem1_epsilon_max(pair_quantities(case.mdp, case.pi, case.pi_tilde))
    assert not check.holds
    assert check.slack == pytest.approx(two_state_gap(0.1, 0.1, True) + 2 * 0.1 * 0.01 / 0.81, rel=1e-9)
    case = two_state_example(0.01, 0.01, signed=True)
    schulman = schulman_theorem1(pair_quantities(case.mdp, case.pi, case.pi_tilde))
    assert schulman.holds
    assert 0 < schulman.relative_slack < 0.02


def test_theorem1_fails_on_two_state_example_known_numbers():
    """alpha = 0.1, gamma = 0.5: gap = -0.04 / 3.15, penalty of (2) = 4 alpha^3 = 0.004."""
    case = two_state_example(0.1, 0.5)
    check = theorem1(pair_quantities(case.mdp, case.pi, case.pi_tilde))
    assert check.scale == pytest.approx(0.004, rel=1e-9)
    assert check.slack == pytest.approx(-0.04 / 3.15 + 0.004, rel=1e-9)
    assert not check.holds
    assert check.slack < -1e6 * check.tol  # far beyond round-off


@pytest.mark.parametrize("signed", [False, True])
@pytest.mark.parametrize(
    ("gamma", "failing"), [(0.1, PAPER), (0.3, PAPER), (0.5, PAPER), (0.9, ["theorem1", "corollary1_kl_epsilon"])]
)
def test_paper_bounds_fail_for_small_steps_and_replacements_hold(gamma, failing, signed):
    """(2), (4), (5), (6) penalise alpha^3 while eta(pi~) - L_pi(pi~) is of order alpha^2.

    (4) and (6) carry 1/(1-gamma)^3, so at gamma = 0.9 they fail only for alpha below about 1e-3.
    """
    case = two_state_example(0.01, gamma, signed)
    checks = check_pair(pair_quantities(case.mdp, case.pi, case.pi_tilde))
    for name in failing:
        assert not checks[name].holds, (name, checks[name])
        assert checks[name].slack < -100 * checks[name].tol
    for name in HOLDING:
        assert checks[name].holds, (name, checks[name])


def test_paper_bound_holds_for_large_step_on_two_state_example():
    """The failure is a small-step phenomenon here: at alpha = 0.3, gamma = 0.99 every bound holds."""
    case = two_state_example(0.3, 0.99)
    checks = check_pair(pair_quantities(case.mdp, case.pi, case.pi_tilde))
    assert all(c.holds for c in checks.values())


def test_identical_policies_make_every_bound_exact():
    case = two_state_example(0.0, 0.8)
    for check in check_pair(pair_quantities(case.mdp, case.pi, case.pi_tilde)).values():
        assert check.holds
        assert abs(check.slack) <= check.tol


def test_two_state_example_rejects_bad_alpha():
    with pytest.raises(ValueError):
        two_state_example(0.6, 0.5)
    assert np.all(two_state_example(0.5, 0.5).pi_tilde >= 0)
