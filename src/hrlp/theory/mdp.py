"""Finite MDPs with a hierarchical action space (Section 3 of the paper).

A hierarchical action space is the disjoint union ``A = A_1 ⊔ ... ⊔ A_n`` (Section 3.1). Here every
``A_k`` is finite with ``m_k`` elements (a parameterless macro-action has ``m_k = 1``), and the union is
flattened in macro order into ``|A| = sum_k m_k`` flat actions: flat action ``offset_k + u`` is
macro-action ``k`` run with parameter ``u``.

A hierarchical policy is the pair ``(p(k|s), mu_k(u|s))``; its flat form is
``pi(offset_k + u | s) = p(k|s) mu_k(u|s)``.

Reward convention: ``r[s, a]`` is the expected reward ``r_{t+1}`` received after taking action ``a`` in
state ``s``. An MDP whose rewards depend on the next state as well is reduced to this form by
:meth:`FiniteMDP.from_transition_rewards`; the values ``V``, ``Q``, ``A``, ``eta`` do not change, and the
reward bound ``R = max_{s,a} |r(s, a)|`` used by :attr:`FiniteMDP.R` is the smallest constant with
``|E[r_{t+1} | s_t, a_t]| <= R``, hence never larger than the paper's ``R`` for the same MDP.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

_ATOL = 1e-9


@dataclass(frozen=True)
class HierarchicalActionSpace:
    """``A = A_1 ⊔ ... ⊔ A_n`` with ``|A_k| = m[k]``, flattened in macro order.

    Attributes:
        m: number of parameters of every macro-action, ``m[k] >= 1``; ``len(m) = n >= 1``.
    """

    m: tuple[int, ...]

    def __post_init__(self) -> None:
        m = tuple(int(v) for v in self.m)
        if not m or min(m) < 1:
            raise ValueError(f"every macro-action needs at least one parameter value, got m={self.m!r}")
        object.__setattr__(self, "m", m)

    @classmethod
    def flat(cls, n_actions: int) -> HierarchicalActionSpace:
        """The non-hierarchical space: ``n_actions`` parameterless macro-actions."""
        return cls((1,) * n_actions)

    @property
    def n(self) -> int:
        """Number of macro-actions."""
        return len(self.m)

    @property
    def size(self) -> int:
        """Number of flat actions ``|A| = sum_k m_k``."""
        return sum(self.m)

    @cached_property
    def offsets(self) -> tuple[int, ...]:
        """Flat index of the first parameter of every macro-action, length ``n + 1`` (last = ``|A|``)."""
        return tuple(int(v) for v in np.concatenate([[0], np.cumsum(self.m)]))

    @cached_property
    def macro_of(self) -> np.ndarray:
        """Macro-action of every flat action, ``[|A|]`` ints."""
        macro_of = np.repeat(np.arange(self.n), self.m)
        macro_of.setflags(write=False)
        return macro_of


@dataclass(frozen=True, eq=False)
class FiniteMDP:
    """A finite MDP ``(S, A, P, r, rho_0, gamma)`` with a hierarchical action space.

    Attributes:
        P: transition kernel ``P[s, a, s'] = P(s_{t+1} = s' | s_t = s, a_t = a)``, ``[S, A, S]``.
        r: expected reward ``r[s, a] = E[r_{t+1} | s_t = s, a_t = a]``, ``[S, A]``.
        rho0: initial state distribution, ``[S]``.
        gamma: discount factor in ``(0, 1)``.
        action_space: how the ``A`` flat actions group into macro-actions; defaults to ``A``
            parameterless macro-actions.
    """

    P: np.ndarray
    r: np.ndarray
    rho0: np.ndarray
    gamma: float
    action_space: HierarchicalActionSpace = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        P = np.asarray(self.P, dtype=float)
        r = np.asarray(self.r, dtype=float)
        rho0 = np.asarray(self.rho0, dtype=float)
        if P.ndim != 3 or P.shape[0] != P.shape[2] or P.shape[0] < 1 or P.shape[1] < 1:
            raise ValueError(f"P must have shape [S, A, S], got {P.shape}")
        S, A = P.shape[:2]
        if r.shape != (S, A):
            raise ValueError(f"r must have shape [S, A] = {(S, A)}, got {r.shape}")
        if rho0.shape != (S,):
            raise ValueError(f"rho0 must have shape [S] = {(S,)}, got {rho0.shape}")
        if not np.isfinite(r).all():
            raise ValueError("r must be finite")
        if not _is_simplex(P):
            raise ValueError("every row P[s, a, :] must be a probability distribution")
        if not _is_simplex(rho0):
            raise ValueError("rho0 must be a probability distribution")
        gamma = float(self.gamma)
        if not 0.0 < gamma < 1.0:
            raise ValueError(f"gamma must lie in (0, 1), got {self.gamma}")
        space = self.action_space if self.action_space is not None else HierarchicalActionSpace.flat(A)
        if space.size != A:
            raise ValueError(f"action space has {space.size} flat actions but P has {A}")
        for name, value in (("P", P), ("r", r), ("rho0", rho0), ("gamma", gamma), ("action_space", space)):
            object.__setattr__(self, name, value)
        for array in (P, r, rho0):
            array.setflags(write=False)

    @classmethod
    def from_transition_rewards(
        cls,
        P: np.ndarray,
        r_sas: np.ndarray,
        rho0: np.ndarray,
        gamma: float,
        action_space: HierarchicalActionSpace | None = None,
    ) -> FiniteMDP:
        """Build an MDP from rewards ``r_sas[s, a, s']`` ``[S, A, S]`` by taking ``r(s, a) = E_{s'} r(s, a, s')``."""
        P = np.asarray(P, dtype=float)
        r = np.einsum("ijk,ijk->ij", P, np.asarray(r_sas, dtype=float))
        return cls(P, r, rho0, gamma, action_space)  # type: ignore[arg-type]

    @property
    def n_states(self) -> int:
        """Number of states ``|S|``."""
        return self.P.shape[0]

    @property
    def n_actions(self) -> int:
        """Number of flat actions ``|A|``."""
        return self.P.shape[1]

    @property
    def R(self) -> float:
        """Reward bound ``R = max_{s,a} |r(s, a)|`` (the paper's "maximal reward", as an absolute value)."""
        return float(np.max(np.abs(self.r)))


@dataclass(frozen=True, eq=False)
class HierarchicalPolicy:
    """A hierarchical policy ``(p(k|s), mu_k(u|s))`` over a finite hierarchical action space.

    Attributes:
        p: macro-action probabilities ``p[s, k] = p(k|s)``, ``[S, n]``.
        mu: parameter probabilities, ``mu[k][s, u] = mu_k(u|s)``, each ``[S, m_k]``.
    """

    p: np.ndarray
    mu: tuple[np.ndarray, ...]

    def __post_init__(self) -> None:
        p = np.asarray(self.p, dtype=float)
        mu = tuple(np.asarray(m, dtype=float) for m in self.mu)
        if p.ndim != 2 or p.shape[1] != len(mu):
            raise ValueError(f"p must have shape [S, n] with n = len(mu) = {len(mu)}, got {p.shape}")
        _check_simplex(p, "p")
        for k, mu_k in enumerate(mu):
            if mu_k.ndim != 2 or mu_k.shape[0] != p.shape[0] or mu_k.shape[1] < 1:
                raise ValueError(f"mu[{k}] must have shape [S, m_k] with S = {p.shape[0]}, got {mu_k.shape}")
            _check_simplex(mu_k, f"mu[{k}]")
        object.__setattr__(self, "p", p)
        object.__setattr__(self, "mu", mu)

    @property
    def action_space(self) -> HierarchicalActionSpace:
        """The action space the policy acts in."""
        return HierarchicalActionSpace(tuple(m.shape[1] for m in self.mu))

    def flat(self) -> np.ndarray:
        """Flat policy ``pi(offset_k + u | s) = p(k|s) mu_k(u|s)``, ``[S, |A|]``."""
        return np.concatenate([self.p[:, k : k + 1] * mu_k for k, mu_k in enumerate(self.mu)], axis=1)

    @classmethod
    def from_flat(cls, pi: np.ndarray, action_space: HierarchicalActionSpace) -> HierarchicalPolicy:
        """Split a flat policy ``pi`` ``[S, |A|]`` into ``(p, mu)``.

        Where ``p(k|s) = 0`` the conditional ``mu_k(.|s)`` is not determined by ``pi``; it is set uniform.
        """
        pi = np.asarray(pi, dtype=float)
        if pi.ndim != 2 or pi.shape[1] != action_space.size:
            raise ValueError(f"pi must have shape [S, {action_space.size}], got {pi.shape}")
        _check_simplex(pi, "pi")
        o = np.asarray(action_space.offsets)
        p = np.add.reduceat(pi, o[:-1], axis=1)  # [S, n]
        p_flat = p[:, action_space.macro_of]  # [S, |A|]
        m_flat = np.asarray(action_space.m)[action_space.macro_of]
        mu_flat = np.where(p_flat > 0, pi / np.where(p_flat > 0, p_flat, 1.0), 1.0 / m_flat)
        # Renormalise so that rounding leaves p(.|s) and every mu_k(.|s) exactly on the simplex.
        p = p / p.sum(axis=1, keepdims=True)
        mu = [b / b.sum(axis=1, keepdims=True) for b in np.split(mu_flat, o[1:-1], axis=1)]
        return cls(p, tuple(mu))


def _is_simplex(x: np.ndarray) -> bool:
    """Whether every row (last axis) of ``x`` is a probability vector; NaN and inf fail both comparisons."""
    return bool(x.size > 0 and x.min() >= 0.0 and np.abs(x.sum(axis=-1) - 1.0).max() <= _ATOL)


def _check_simplex(x: np.ndarray, name: str) -> None:
    if not _is_simplex(x):
        raise ValueError(f"every row of {name} must be a probability distribution")


def check_policy(pi: np.ndarray, mdp: FiniteMDP) -> np.ndarray:
    """Validate a flat policy ``pi`` ``[S, A]`` for ``mdp`` and return it as a float array."""
    pi = np.asarray(pi, dtype=float)
    if pi.shape != (mdp.n_states, mdp.n_actions):
        raise ValueError(f"policy must have shape [S, A] = {(mdp.n_states, mdp.n_actions)}, got {pi.shape}")
    _check_simplex(pi, "pi")
    return pi


def softmax(logits: np.ndarray, axis: int = -1) -> np.ndarray:
    """Numerically stable softmax along ``axis``."""
    z = logits - np.max(logits, axis=axis, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=axis, keepdims=True)


def random_mdp(
    rng: np.random.Generator,
    n_states: int,
    action_space: HierarchicalActionSpace,
    gamma: float,
    *,
    concentration: float = 1.0,
    reward_scale: float = 1.0,
) -> FiniteMDP:
    """A random MDP: Dirichlet(``concentration``) transition rows and initial state, uniform rewards.

    Small ``concentration`` gives nearly deterministic transitions. Rewards are uniform on
    ``[-reward_scale, reward_scale]``.
    """
    if n_states < 1:
        raise ValueError(f"n_states must be >= 1, got {n_states}")
    A = action_space.size
    P = rng.dirichlet(np.full(n_states, concentration), size=(n_states, A))
    rho0 = rng.dirichlet(np.full(n_states, concentration))
    r = rng.uniform(-reward_scale, reward_scale, size=(n_states, A))
    return FiniteMDP(P, r, rho0, gamma, action_space)


def random_hierarchical_policy(
    rng: np.random.Generator,
    n_states: int,
    action_space: HierarchicalActionSpace,
    *,
    concentration: float = 1.0,
) -> HierarchicalPolicy:
    """A random hierarchical policy with Dirichlet(``concentration``) ``p(.|s)`` and ``mu_k(.|s)``."""
    p = rng.dirichlet(np.full(action_space.n, concentration), size=n_states)
    mu = tuple(rng.dirichlet(np.full(m_k, concentration), size=n_states) for m_k in action_space.m)
    return HierarchicalPolicy(p, mu)
