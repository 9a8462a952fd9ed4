"""Counterexamples as JSON files that reproduce a violation.

A file holds the statement's name, the case (an MDP with two flat policies, or two Gaussian hierarchical
distributions with the Monte-Carlo seed) and the check as recorded when it was found. Floats are written
with ``repr`` precision, so loading a file and calling :func:`recheck` recomputes the same numbers.
"""

from __future__ import annotations

import json
import math
import pathlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from hrlp.atomic import atomic_path
from hrlp.theory.exact import pair_quantities
from hrlp.theory.gaussian import GaussianHierarchical
from hrlp.theory.mdp import FiniteMDP, HierarchicalActionSpace, HierarchicalPolicy
from hrlp.theory.statements import PAIR_CHECKS, STATEMENTS, StatementCheck, lemma1_exact, lemma1_monte_carlo

FORMAT_VERSION = 1


@dataclass(frozen=True, eq=False)
class PolicyPairCase:
    """An MDP with two flat policies ``pi``, ``pi~`` ``[S, A]``."""

    mdp: FiniteMDP
    pi: np.ndarray
    pi_tilde: np.ndarray

    @property
    def size(self) -> tuple[int, int]:
        """``(|S|, |A|)``."""
        return self.mdp.n_states, self.mdp.n_actions


@dataclass(frozen=True, eq=False)
class GaussianCase:
    """Two Gaussian hierarchical distributions and the Monte-Carlo settings of a Lemma 1 check."""

    mu: GaussianHierarchical
    mu_tilde: GaussianHierarchical
    seed: int
    n_samples: int
    z: float

    @property
    def size(self) -> tuple[int, int]:
        """``(1, sum_k d_k)``: one "state", and the total parameter dimension."""
        return 1, sum(self.mu.dims)


@dataclass(frozen=True, eq=False)
class Counterexample:
    """A case on which a statement was found to fail, with the check as recorded."""

    statement: str
    case: PolicyPairCase | GaussianCase
    check: StatementCheck


def check_case(statement: str, case: PolicyPairCase | GaussianCase) -> StatementCheck:
    """Check ``statement`` (a key of :data:`~hrlp.theory.statements.STATEMENTS`) on ``case``."""
    if statement not in STATEMENTS:
        raise ValueError(f"unknown statement {statement!r}; expected one of {sorted(STATEMENTS)}")
    if statement == "lemma1_monte_carlo":
        if not isinstance(case, GaussianCase):
            raise ValueError("lemma1_monte_carlo needs a GaussianCase")
        rng = np.random.default_rng(case.seed)
        return lemma1_monte_carlo(case.mu, case.mu_tilde, rng, case.n_samples, case.z)
    if not isinstance(case, PolicyPairCase):
        raise ValueError(f"{statement} needs a PolicyPairCase")
    if statement == "lemma1_exact":
        space = case.mdp.action_space
        return lemma1_exact(HierarchicalPolicy.from_flat(case.pi, space), HierarchicalPolicy.from_flat(case.pi_tilde, space))
    return PAIR_CHECKS[statement](pair_quantities(case.mdp, case.pi, case.pi_tilde))


def recheck(counterexample: Counterexample) -> StatementCheck:
    """Recompute the check of a (loaded) counterexample from its case alone."""
    return check_case(counterexample.statement, counterexample.case)


def _float(x: float) -> float | str:
    return float(x) if math.isfinite(x) else repr(float(x))


def _unfloat(x: float | str) -> float:
    return float(x)


def _case_to_json(case: PolicyPairCase | GaussianCase) -> dict[str, Any]:
    if isinstance(case, PolicyPairCase):
        m = case.mdp
        return {
            "kind": "policy_pair",
            "mdp": {
                "P": m.P.tolist(),
                "r": m.r.tolist(),
                "rho0": m.rho0.tolist(),
                "gamma": m.gamma,
                "action_space": list(m.action_space.m),
            },
            "pi": case.pi.tolist(),
            "pi_tilde": case.pi_tilde.tolist(),
        }

    def dist(d: GaussianHierarchical) -> dict[str, Any]:
        return {"p": d.p.tolist(), "mean": [x.tolist() for x in d.mean], "log_std": [x.tolist() for x in d.log_std]}

    return {
        "kind": "gaussian",
        "mu": dist(case.mu),
        "mu_tilde": dist(case.mu_tilde),
        "seed": case.seed,
        "n_samples": case.n_samples,
        "z": case.z,
    }


def _case_from_json(data: dict[str, Any]) -> PolicyPairCase | GaussianCase:
    if data["kind"] == "policy_pair":
        m = data["mdp"]
        mdp = FiniteMDP(
            np.array(m["P"], dtype=float),
            np.array(m["r"], dtype=float),
            np.array(m["rho0"], dtype=float),
            float(m["gamma"]),
            HierarchicalActionSpace(tuple(m["action_space"])),
        )
        return PolicyPairCase(mdp, np.array(data["pi"], dtype=float), np.array(data["pi_tilde"], dtype=float))
    if data["kind"] == "gaussian":

        def dist(d: dict[str, Any]) -> GaussianHierarchical:
            return GaussianHierarchical(
                np.array(d["p"], dtype=float),
                tuple(np.array(x, dtype=float) for x in d["mean"]),
                tuple(np.array(x, dtype=float) for x in d["log_std"]),
            )

        return GaussianCase(
            dist(data["mu"]), dist(data["mu_tilde"]), int(data["seed"]), int(data["n_samples"]), float(data["z"])
        )
    raise ValueError(f"unknown case kind {data['kind']!r}")


def counterexample_to_json(counterexample: Counterexample) -> dict[str, Any]:
    """The JSON-ready dictionary written by :func:`save_counterexample`."""
    statement = STATEMENTS[counterexample.statement]
    c = counterexample.check
    return {
        "format_version": FORMAT_VERSION,
        "statement": statement.name,
        "label": statement.label,
        "formula": statement.formula,
        "size": {"states": counterexample.case.size[0], "actions": counterexample.case.size[1]},
        "check": {
            "lhs": _float(c.lhs),
            "rhs": _float(c.rhs),
            "slack": _float(c.slack),
            "relative_slack": _float(c.relative_slack),
            "tol": _float(c.tol),
            "scale": _float(c.scale),
            "relation": c.relation,
            "holds": c.holds,
        },
        "case": _case_to_json(counterexample.case),
    }


def save_counterexample(counterexample: Counterexample, path: pathlib.Path) -> pathlib.Path:
    """Write ``counterexample`` to ``path`` as JSON, atomically (temporary file, then ``os.replace``)."""
    path = pathlib.Path(path)
    text = json.dumps(counterexample_to_json(counterexample), indent=1, allow_nan=False)
    with atomic_path(path) as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    return path


def load_counterexample(path: pathlib.Path) -> Counterexample:
    """Read a file written by :func:`save_counterexample`."""
    data = json.loads(pathlib.Path(path).read_text(encoding="utf-8"))
    if data.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{path}: unsupported counterexample format {data.get('format_version')!r}")
    statement = data["statement"]
    if statement not in STATEMENTS:
        raise ValueError(f"{path}: unknown statement {statement!r}")
    c = data["check"]
    lhs, rhs, slack, tol, scale = (_unfloat(c[k]) for k in ("lhs", "rhs", "slack", "tol", "scale"))
    recorded = StatementCheck(statement, lhs, rhs, slack, bool(c["holds"]), tol, c["relation"], scale)
    return Counterexample(statement, _case_from_json(data["case"]), recorded)
