"""The search, the counterexample files and run_theory."""

import io
import json
import math

import numpy as np
import pytest
from rich.console import Console

from hrlp.theory import (
    STATEMENTS,
    Counterexample,
    SearchConfig,
    check_case,
    load_counterexample,
    recheck,
    run_theory,
    save_counterexample,
    search,
    theorem1,
    two_state_example,
)
from hrlp.theory.counterexample import GaussianCase
from hrlp.theory.exact import pair_quantities
from hrlp.theory.gaussian import random_gaussian_hierarchical
from hrlp.theory.search import EXAMPLE_ALPHAS, EXAMPLE_GAMMAS

SMALL = SearchConfig(mdps=4, seed=3, pairs_per_mdp=4, climb_steps=20, mc_samples=2_000)


@pytest.mark.parametrize("mdps", [0, -5])
def test_run_theory_rejects_non_positive_mdps(mdps, tmp_path):
    with pytest.raises(ValueError, match="mdps") as info:
        run_theory(mdps, out_dir=tmp_path, console=Console(file=io.StringIO()))
    assert "\n" not in str(info.value)
    assert not any(tmp_path.iterdir())


def test_search_config_rejects_bad_settings():
    with pytest.raises(ValueError):
        SearchConfig(mdps=0)
    with pytest.raises(ValueError):
        SearchConfig(pairs_per_mdp=0)
    with pytest.raises(ValueError, match="seed"):
        SearchConfig(seed=-1)


def test_search_is_deterministic_and_consistent():
    a, b = search(SMALL), search(SMALL)
    assert [s.name for s in a.summaries] == list(STATEMENTS)
    assert a.summaries == b.summaries
    for s in a.summaries:
        assert 0 <= s.held <= s.cases
        assert s.cases > 0
        assert (s.counterexample_size is None) == s.holds == (s.name not in a.counterexamples)
    cases = {s.name: s.cases for s in a.summaries}
    assert cases["lemma1_monte_carlo"] == SMALL.mdps
    n_examples = len(EXAMPLE_ALPHAS) * len(EXAMPLE_GAMMAS) * 2
    assert cases["theorem1"] == n_examples + SMALL.mdps * (SMALL.pairs_per_mdp + SMALL.climb_steps)
    assert cases["lemma1_exact"] == n_examples + SMALL.mdps * (SMALL.pairs_per_mdp + 1)
    assert search(SearchConfig(mdps=4, seed=4, pairs_per_mdp=4, climb_steps=20, mc_samples=2_000)).summaries != a.summaries


def test_search_finds_violations_of_theorem1_on_random_mdps():
    """(2) fails on random MDPs too, not only on the hand-made examples the search starts with."""
    grid_failures = sum(
        not theorem1(pair_quantities(c.mdp, c.pi, c.pi_tilde)).holds
        for c in (two_state_example(a, g, signed) for a in EXAMPLE_ALPHAS for g in EXAMPLE_GAMMAS for signed in (False, True))
    )
    summary = next(s for s in search(SMALL).summaries if s.name == "theorem1")
    assert summary.violations > grid_failures


def test_search_counterexamples_are_genuine():
    result = search(SMALL)
    assert "theorem1" in result.counterexamples
    for name, cx in result.counterexamples.items():
        check = recheck(cx)
        assert not check.holds
        assert check.slack == cx.check.slack
        assert cx.case.size == next(s.counterexample_size for s in result.summaries if s.name == name)


def test_saved_counterexample_reproduces_the_violation(tmp_path):
    case = two_state_example(0.05, 0.5)
    check = theorem1(pair_quantities(case.mdp, case.pi, case.pi_tilde))
    assert not check.holds
    path = save_counterexample(Counterexample("theorem1", case, check), tmp_path / "sub" / "theorem1.json")
    assert [p.name for p in path.parent.iterdir()] == ["theorem1.json"]  # no temporary file left behind
    data = json.loads(path.read_text())
    assert data["statement"] == "theorem1" and data["case"]["kind"] == "policy_pair"
    loaded = load_counterexample(path)
    np.testing.assert_array_equal(loaded.case.mdp.P, case.mdp.P)
    np.testing.assert_array_equal(loaded.case.pi_tilde, case.pi_tilde)
    again = recheck(loaded)
    assert not again.holds
    assert again.slack == loaded.check.slack == check.slack  # bit for bit


def test_gaussian_case_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    case = GaussianCase(random_gaussian_hierarchical(rng, (0, 2)), random_gaussian_hierarchical(rng, (0, 2)), 7, 500, 5.0)
    check = check_case("lemma1_monte_carlo", case)
    loaded = load_counterexample(save_counterexample(Counterexample("lemma1_monte_carlo", case, check), tmp_path / "g.json"))
    assert recheck(loaded) == check


def test_bad_counterexample_files_are_rejected(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"format_version": 99, "statement": "theorem1"}))
    with pytest.raises(ValueError, match="format"):
        load_counterexample(path)
    with pytest.raises(ValueError, match="unknown statement"):
        check_case("theorem9", two_state_example(0.1, 0.5))


def test_run_theory_prints_a_table_per_statement_and_saves_counterexamples(tmp_path):
    out = io.StringIO()
    summaries = run_theory(mdps=3, seed=0, out_dir=tmp_path, console=Console(file=out, width=200))
    text = out.getvalue()
    assert [s.name for s in summaries] == list(STATEMENTS)
    for s in summaries:
        assert s.label in text
        if s.holds:
            assert s.counterexample_path is None
        else:
            assert s.counterexample_path == tmp_path / f"{s.name}.json"
            assert str(s.counterexample_path) in text
            assert not recheck(load_counterexample(s.counterexample_path)).holds
    assert {p.name for p in tmp_path.iterdir()} == {f"{s.name}.json" for s in summaries if not s.holds}
    by_name = {s.name: s for s in summaries}
    assert not by_name["theorem1"].holds
    for name in ("lemma1_exact", "lemma1_monte_carlo", "lemma2", "schulman_theorem1", "theorem1_corrected"):
        assert by_name[name].holds
    assert math.isfinite(by_name["theorem1"].min_slack) and by_name["theorem1"].min_slack < 0
