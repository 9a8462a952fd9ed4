"""Two two-state MDPs, solvable by hand, on which Theorem 1 (2) and Corollary 1 (4)-(6) fail.

States ``s0`` (start) and ``s1`` (absorbing); two parameterless macro-actions, ``a = 0`` and ``a = 1``. In
``s0`` action 0 stays in ``s0`` and action 1 moves to ``s1``; in ``s1`` both actions stay in ``s1``. ``pi`` plays
each action with probability 1/2 in both states; ``pi~`` plays action 0 in ``s0`` and action 1 in ``s1`` with
probability ``1/2 + alpha``, so ``D_TV^max(pi, pi~) = alpha``.

**Example A** (``signed=False``): reward 1 for action 1 in ``s1``, 0 otherwise (``R = 1``). By hand,
``V_pi(s1) - V_pi(s0) = 1 / (2 - gamma)``, ``E_{pi~} A_pi(s1, .) = alpha``,
``E_{pi~} A_pi(s0, .) = -alpha gamma / (2 - gamma)`` (so the paper's ``epsilon = alpha``),
``max_{s,a} |A_pi(s, a)| = 1/2`` and

    eta(pi~) - L_pi(pi~) = -8 gamma alpha^2 / ((2 - gamma)^2 (2 - gamma - 2 gamma alpha)).

**Example B** (``signed=True``): reward ``-1`` for action 0 and ``+1`` for action 1 in both states
(``R = 1``). Then ``V_pi = 0``, ``A_pi(s, a) = r(s, a) = -1, +1``, ``E_{pi~} A_pi(s0, .) = -2 alpha``,
``E_{pi~} A_pi(s1, .) = 2 alpha`` (so ``epsilon = 2 alpha`` and ``max |A_pi| = 1``) and

    eta(pi~) - L_pi(pi~) = -16 gamma alpha^2 / ((2 - gamma) (2 - gamma - 2 gamma alpha)).

In both the gap is of order ``alpha^2`` while the penalties of (2), (4), (5), (6) are of order ``alpha^3``, so
all four fail for small ``alpha``. Example B also breaks (2) read with Schulman et al.'s
``epsilon = max |A_pi| = 1``: the penalty ``2 gamma alpha^2 / (1 - gamma)^2`` is below the gap whenever
``8 (1 - gamma)^2 > (2 - gamma)(2 - gamma - 2 gamma alpha)`` (e.g. ``gamma < 0.45`` for small ``alpha``), and as
``gamma, alpha -> 0`` the gap approaches Schulman et al.'s penalty ``4 gamma alpha^2 / (1 - gamma)^2``: their
constant 4 cannot be lowered.
"""

from __future__ import annotations

import numpy as np

from hrlp.theory.counterexample import PolicyPairCase
from hrlp.theory.mdp import FiniteMDP, HierarchicalActionSpace


def two_state_example(alpha: float, gamma: float, signed: bool = False) -> PolicyPairCase:
    """Example A (``signed=False``) or B (``signed=True``) of this module, for ``0 <= alpha <= 1/2``."""
    if not 0.0 <= alpha <= 0.5:
        raise ValueError(f"alpha must lie in [0, 1/2], got {alpha}")
    P = np.zeros((2, 2, 2))
    P[0, 0, 0] = 1.0  # s0, action 0: stay
    P[0, 1, 1] = 1.0  # s0, action 1: move to s1
    P[1, :, 1] = 1.0  # s1 is absorbing
    r = np.array([[-1.0, 1.0], [-1.0, 1.0]]) if signed else np.array([[0.0, 0.0], [0.0, 1.0]])
    mdp = FiniteMDP(P, r, np.array([1.0, 0.0]), gamma, HierarchicalActionSpace((1, 1)))
    pi = np.full((2, 2), 0.5)
    pi_tilde = np.array([[0.5 + alpha, 0.5 - alpha], [0.5 - alpha, 0.5 + alpha]])
    return PolicyPairCase(mdp, pi, pi_tilde)


def two_state_gap(alpha: float, gamma: float, signed: bool = False) -> float:
    """Closed form of ``eta(pi~) - L_pi(pi~)`` for :func:`two_state_example`."""
    if signed:
        return -16.0 * gamma * alpha**2 / ((2.0 - gamma) * (2.0 - gamma - 2.0 * gamma * alpha))
    return -8.0 * gamma * alpha**2 / ((2.0 - gamma) ** 2 * (2.0 - gamma - 2.0 * gamma * alpha))
