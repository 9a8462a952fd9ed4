"""Action distributions behind one interface: diagonal Gaussian, categorical, and the Manager's hierarchical one.

Every algorithm (TRPO in :mod:`hrlp.algos.trpo`) talks to a policy only through :class:`Distribution`, so the
Manager's hierarchical distribution is just another implementation and the trust region of Lemma 1 falls out of
its :meth:`Hierarchical.kl`. All methods are batched: parameters carry a leading batch dimension ``B`` and every
scalar quantity (log-density, KL, entropy) comes back as a ``[B]`` tensor.

Hierarchical action encoding (one float row per sample, ``S = sum_k d_k``)::

    action = [k, u_1 (d_1 numbers), u_2 (d_2 numbers), ..., u_n (d_n numbers)]      # [1 + S]

Column 0 holds the chosen macro-action index ``k`` (an exact small integer stored as a float), the remaining columns
hold every macro-action's parameter block. This is the flat image of a gymnasium sample from
``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))``; :func:`tuple_to_flat` and :func:`flat_to_tuple` convert.
"""

from __future__ import annotations

import functools
import itertools
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Self

import numpy as np
import torch
from torch import Tensor

__all__ = [
    "Categorical",
    "DiagGaussian",
    "Distribution",
    "Hierarchical",
    "HybridSquashed",
    "SquashedGaussian",
    "flat_to_tuple",
    "flat_to_tuples",
    "tuple_to_flat",
    "tuples_to_flat",
]

_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)
_HALF_LOG_2PIE = 0.5 * math.log(2.0 * math.pi * math.e)


class Distribution(ABC):
    """A batch of ``B`` action distributions ``pi(. | s_b)``, one per state in the batch.

    Implementations hold only tensors (no modules), so building one is cheap and the graph of its parameters is
    whatever produced them. TRPO uses ``log_prob`` for the surrogate, ``kl`` for the trust region and the Fisher
    matrix, ``entropy`` for the optional bonus and statistics, and ``detach`` for the fixed "old" policy.
    """

    @property
    @abstractmethod
    def batch_size(self) -> int:
        """Number ``B`` of distributions in the batch."""

    @abstractmethod
    def log_prob(self, actions: Tensor) -> Tensor:
        """Log-density (or log-probability) of ``actions`` (``[B, ...]`` in this distribution's encoding) -> ``[B]``."""

    @abstractmethod
    def kl(self, other: Self) -> Tensor:
        """``KL(self || other)`` per batch element -> ``[B]``. ``other`` must be of the same type and shape."""

    @abstractmethod
    def entropy(self) -> Tensor:
        """Differential (or Shannon) entropy per batch element -> ``[B]``."""

    @abstractmethod
    def sample(self, generator: torch.Generator | None = None) -> Tensor:
        """One action per batch element, drawn with ``generator`` (the global RNG if ``None``); no gradient."""

    @abstractmethod
    def mode(self) -> Tensor:
        """The most likely action per batch element (deterministic evaluation); no gradient."""

    @abstractmethod
    def detach(self) -> Self:
        """A snapshot with parameters cut from the autograd graph and copied (the fixed "old" policy in TRPO).

        Copied, not just detached: a state-independent ``log_std`` is a view of an ``nn.Parameter``, and the old
        policy must not move when TRPO writes new values into the parameters in place.
        """


def _gaussian_log_density(x: Tensor, mean: Tensor, log_std: Tensor) -> Tensor:
    """Elementwise ``log N(x; mean, exp(log_std)^2)``; all ``[B, D]`` (``log_std`` may broadcast) -> ``[B, D]``."""
    z = (x - mean) * torch.exp(-log_std)
    return -0.5 * z.square() - log_std - _HALF_LOG_2PI


def _gaussian_kl(mean0: Tensor, log_std0: Tensor, mean1: Tensor, log_std1: Tensor) -> Tensor:
    """Elementwise ``KL(N(mean0, std0^2) || N(mean1, std1^2))`` of 1-d Gaussians -> ``[B, D]``.

    ``log(s1/s0) + (s0^2 + (m0 - m1)^2) / (2 s1^2) - 1/2``, written with ``exp(2 (ls0 - ls1))`` so that it stays
    accurate when both standard deviations are small.
    """
    var_ratio = torch.exp(2.0 * (log_std0 - log_std1))
    return log_std1 - log_std0 + 0.5 * (var_ratio + (mean0 - mean1).square() * torch.exp(-2.0 * log_std1)) - 0.5


def _gaussian_entropy(log_std: Tensor) -> Tensor:
    """Elementwise entropy ``log std + 0.5 log(2 pi e)`` of 1-d Gaussians -> same shape as ``log_std``."""
    return log_std + _HALF_LOG_2PIE


class DiagGaussian(Distribution):
    """Diagonal Gaussian ``N(mean, diag(exp(log_std)^2))``.

    Args:
        mean: ``[B, D]`` means.
        log_std: ``[B, D]`` or ``[D]`` log standard deviations (a state-independent parameter broadcasts).
    """

    def __init__(self, mean: Tensor, log_std: Tensor) -> None:
        if mean.ndim != 2:
            raise ValueError(f"mean must be [B, D], got shape {tuple(mean.shape)}")
        self.mean = mean
        self.log_std = log_std.expand_as(mean)

    @property
    def batch_size(self) -> int:
        """Number ``B`` of distributions in the batch."""
        return self.mean.shape[0]

    @property
    def dim(self) -> int:
        """Action dimension ``D``."""
        return self.mean.shape[1]

    @property
    def std(self) -> Tensor:
        """``[B, D]`` standard deviations."""
        return torch.exp(self.log_std)

    def log_prob(self, actions: Tensor) -> Tensor:
        """``sum_i log N(a_i; mu_i, sigma_i^2)`` for ``actions`` ``[B, D]`` -> ``[B]``."""
        return _gaussian_log_density(actions, self.mean, self.log_std).sum(-1)

    def kl(self, other: DiagGaussian) -> Tensor:
        """Closed-form ``KL(self || other)`` summed over dimensions -> ``[B]``."""
        return _gaussian_kl(self.mean, self.log_std, other.mean, other.log_std).sum(-1)

    def entropy(self) -> Tensor:
        """``sum_i (log sigma_i + 0.5 log(2 pi e))`` -> ``[B]``."""
        return _gaussian_entropy(self.log_std).sum(-1)

    @torch.no_grad()
    def sample(self, generator: torch.Generator | None = None) -> Tensor:
        """``mean + std * eps`` with ``eps ~ N(0, I)`` from ``generator`` -> ``[B, D]``."""
        eps = torch.randn(self.mean.shape, generator=generator, dtype=self.mean.dtype, device=self.mean.device)
        return self.mean + self.std * eps

    @torch.no_grad()
    def mode(self) -> Tensor:
        """The mean -> ``[B, D]``."""
        return self.mean.clone()

    def detach(self) -> DiagGaussian:
        """Snapshot with detached, copied parameters."""
        return DiagGaussian(self.mean.detach().clone(), self.log_std.detach().clone())


class Categorical(Distribution):
    """Categorical distribution over ``{0, ..., n-1}`` given unnormalised ``logits`` ``[B, n]``.

    Actions are integer-valued ``[B]`` tensors (``long`` from :meth:`sample`; float tensors holding integers are
    accepted by :meth:`log_prob`).
    """

    def __init__(self, logits: Tensor) -> None:
        if logits.ndim != 2:
            raise ValueError(f"logits must be [B, n], got shape {tuple(logits.shape)}")
        # Normalised once: log_prob, kl and entropy all want log p, and log_softmax is the stable way to get it.
        self.log_p = torch.log_softmax(logits, dim=-1)

    @property
    def batch_size(self) -> int:
        """Number ``B`` of distributions in the batch."""
        return self.log_p.shape[0]

    @property
    def n(self) -> int:
        """Number of categories."""
        return self.log_p.shape[1]

    @property
    def logits(self) -> Tensor:
        """``[B, n]`` normalised logits (``log p``)."""
        return self.log_p

    @property
    def probs(self) -> Tensor:
        """``[B, n]`` probabilities ``p``."""
        return torch.exp(self.log_p)

    def log_prob(self, actions: Tensor) -> Tensor:
        """``log p_a`` for integer-valued ``actions`` ``[B]`` -> ``[B]``."""
        index = actions.reshape(-1, 1).long()
        return self.log_p.gather(-1, index).squeeze(-1)

    def kl(self, other: Categorical) -> Tensor:
        """``sum_k p_k (log p_k - log q_k)`` -> ``[B]``."""
        return (self.probs * (self.log_p - other.log_p)).sum(-1)

    def entropy(self) -> Tensor:
        """``-sum_k p_k log p_k`` -> ``[B]``."""
        return -(self.probs * self.log_p).sum(-1)

    @torch.no_grad()
    def sample(self, generator: torch.Generator | None = None) -> Tensor:
        """Indices drawn with ``generator`` -> ``[B]`` long."""
        return torch.multinomial(self.probs, 1, generator=generator).squeeze(-1)

    @torch.no_grad()
    def mode(self) -> Tensor:
        """``argmax_k p_k`` -> ``[B]`` long."""
        return self.log_p.argmax(-1)

    def detach(self) -> Categorical:
        """Snapshot with detached, copied parameters."""
        return Categorical(self.log_p.detach().clone())


@functools.lru_cache(maxsize=64)
def _block_layout(param_dims: tuple[int, ...], dtype: torch.dtype, device: torch.device) -> tuple[Tensor, Tensor]:
    """``owner [S]`` (long: the macro-action owning each parameter column) and ``blocks [S, n]`` (0/1 matrix, entry
    ``(j, k)`` = 1 iff column ``j`` belongs to macro-action ``k``).

    Right-multiplying an elementwise ``[B, S]`` quantity by ``blocks`` sums each block -> ``[B, n]``; a parameterless
    macro-action gets an all-zero column. Cached (read-only) because the Manager builds a distribution at every
    acting call; built outside inference mode so the cached tensors stay usable by autograd.
    """
    with torch.inference_mode(False):
        owner = torch.repeat_interleave(torch.arange(len(param_dims), device=device), torch.tensor(param_dims, device=device))
        return owner, torch.nn.functional.one_hot(owner, len(param_dims)).to(dtype)


class Hierarchical(Distribution):
    """The Manager's distribution on the disjoint union ``A = A_1 ⊔ ... ⊔ A_n`` with ``A_k = R^{d_k}`` (Section 3.1).

    A macro-action ``k ~ p = softmax(logits)`` and, for it, parameters ``u_k ~ mu_k = N(mean_k, diag(std_k^2))``.
    Density: ``log mu(k, u_k) = log p_k + log N(u_k; mean_k, std_k)``; only the chosen block counts.

    Args:
        logits: ``[B, n]`` unnormalised macro-action logits.
        means: ``[B, S]`` all parameter means, blocks concatenated in macro-action order (``S = sum_k d_k``).
        log_std: ``[S]`` or ``[B, S]`` log standard deviations, same layout.
        param_dims: ``(d_1, ..., d_n)``; zeros allowed (parameterless macro-actions).

    Actions are float ``[B, 1 + S]`` rows ``[k, u_1, ..., u_n]`` (module docstring).
    """

    def __init__(self, logits: Tensor, means: Tensor, log_std: Tensor, param_dims: Sequence[int]) -> None:
        param_dims = tuple(int(d) for d in param_dims)
        if not param_dims or any(d < 0 for d in param_dims):
            raise ValueError(f"param_dims must be a non-empty tuple of non-negative ints, got {param_dims}")
        if logits.ndim != 2 or logits.shape[1] != len(param_dims):
            raise ValueError(f"logits must be [B, {len(param_dims)}], got shape {tuple(logits.shape)}")
        if means.ndim != 2 or means.shape != (logits.shape[0], sum(param_dims)):
            raise ValueError(f"means must be [B, {sum(param_dims)}], got shape {tuple(means.shape)}")
        self.param_dims = param_dims
        self.categorical = Categorical(logits)
        self.gaussian = DiagGaussian(means, log_std)
        self._owner, self._blocks = _block_layout(param_dims, means.dtype, means.device)  # [S], [S, n]

    @property
    def batch_size(self) -> int:
        """Number ``B`` of distributions in the batch."""
        return self.categorical.batch_size

    @property
    def n(self) -> int:
        """Number of macro-actions."""
        return len(self.param_dims)

    @property
    def action_dim(self) -> int:
        """Width ``1 + S`` of the flat action encoding."""
        return 1 + sum(self.param_dims)

    @property
    def offsets(self) -> tuple[int, ...]:
        """Start column of each block inside the parameter part (columns ``1:`` of an action), length ``n + 1``."""
        return tuple(int(o) for o in np.concatenate([[0], np.cumsum(self.param_dims)]))

    def block_kl(self, other: Hierarchical) -> Tensor:
        """``KL(mu_k || mu~_k)`` for every macro-action -> ``[B, n]`` (zero for parameterless ones)."""
        g, h = self.gaussian, other.gaussian
        return _gaussian_kl(g.mean, g.log_std, h.mean, h.log_std) @ self._blocks

    def block_entropy(self) -> Tensor:
        """``H(mu_k)`` for every macro-action -> ``[B, n]`` (zero for parameterless ones)."""
        return _gaussian_entropy(self.gaussian.log_std) @ self._blocks

    def log_prob(self, actions: Tensor) -> Tensor:
        """``log p_k + log N(u_k; mean_k, std_k)`` with ``k = actions[:, 0]`` -> ``[B]``; other blocks are ignored."""
        k = actions[:, 0].long()
        per_column = _gaussian_log_density(actions[:, 1:], self.gaussian.mean, self.gaussian.log_std)  # [B, S]
        # A mask rather than a matmul so that whatever sits in the other blocks (even nan) cannot leak in.
        chosen = self._owner.unsqueeze(0) == k.unsqueeze(-1)  # [B, S]
        return self.categorical.log_prob(k) + torch.where(chosen, per_column, 0.0).sum(-1)

    def kl(self, other: Hierarchical) -> Tensor:
        """Lemma 1: ``KL(mu, mu~) = KL(p, p~) + sum_k p_k KL(mu_k, mu~_k)`` -> ``[B]``."""
        if other.param_dims != self.param_dims:
            raise ValueError(f"param_dims differ: {self.param_dims} vs {other.param_dims}")
        return self.categorical.kl(other.categorical) + (self.categorical.probs * self.block_kl(other)).sum(-1)

    def entropy(self) -> Tensor:
        """``H(mu) = H(p) + sum_k p_k H(mu_k)`` (the chain rule behind Lemma 1) -> ``[B]``."""
        return self.categorical.entropy() + (self.categorical.probs * self.block_entropy()).sum(-1)

    @torch.no_grad()
    def sample(self, generator: torch.Generator | None = None) -> Tensor:
        """Draw ``k`` and every block's parameters (as a gymnasium ``Tuple`` sample would) -> ``[B, 1 + S]`` float."""
        k = self.categorical.sample(generator)
        u = self.gaussian.sample(generator)
        return torch.cat([k.to(u.dtype).unsqueeze(-1), u], dim=-1)

    @torch.no_grad()
    def mode(self) -> Tensor:
        """Most likely macro-action with every block at its mean -> ``[B, 1 + S]`` float."""
        k = self.categorical.mode()
        u = self.gaussian.mode()
        return torch.cat([k.to(u.dtype).unsqueeze(-1), u], dim=-1)

    def detach(self) -> Hierarchical:
        """Snapshot with detached, copied parameters."""
        g, log_p = self.gaussian.detach(), self.categorical.log_p.detach().clone()
        return Hierarchical(log_p, g.mean, g.log_std, self.param_dims)


_ATANH_LIMIT = 1.0 - 1e-6
"""Squashed actions are clipped to ``[-limit, limit]`` before ``atanh`` (a float32 ``tanh`` reaches +-1 exactly)."""


def _squashed_log_density(u: Tensor, mean: Tensor, log_std: Tensor) -> tuple[Tensor, Tensor]:
    """``(a, log density of a)`` elementwise for pre-tanh values ``u``: ``a = tanh(u)`` and
    ``log N(u; mean, std) - log(1 - tanh(u)^2)`` (the change of variables of Haarnoja et al. 2018, Appendix C), the
    Jacobian written ``2 (log 2 - u - softplus(-2u))`` as it stays finite for large ``|u|`` -> ``[B, D]`` each."""
    jacobian = 2.0 * (math.log(2.0) - u - torch.nn.functional.softplus(-2.0 * u))
    return torch.tanh(u), _gaussian_log_density(u, mean, log_std) - jacobian


class SquashedGaussian(Distribution):
    """``a = tanh(u)``, ``u ~ N(mean, diag(exp(log_std)^2))``: SAC's bounded action distribution on ``(-1, 1)^D``
    (Haarnoja et al. 2018, "Soft Actor-Critic Algorithms and Applications", Appendix C).

    Args:
        mean: ``[B, D]`` means of ``u``.
        log_std: ``[B, D]`` (or broadcastable) log standard deviations of ``u``.

    ``kl`` is exact: ``tanh`` is a bijection, which leaves a KL divergence unchanged, so it is the Gaussians' KL.
    ``entropy`` has no closed form; it is a one-sample estimate ``-log pi(a)`` with ``a`` reparameterised.
    """

    def __init__(self, mean: Tensor, log_std: Tensor) -> None:
        if mean.ndim != 2:
            raise ValueError(f"mean must be [B, D], got shape {tuple(mean.shape)}")
        self.mean = mean
        self.log_std = log_std.expand_as(mean)

    @property
    def batch_size(self) -> int:
        """Number ``B`` of distributions in the batch."""
        return self.mean.shape[0]

    def rsample(self, generator: torch.Generator | None = None) -> tuple[Tensor, Tensor]:
        """A reparameterised sample ``a = tanh(mean + std * eps)`` ``[B, D]`` and its elementwise log density ``[B, D]``
        (gradients flow into ``mean`` and ``log_std``)."""
        eps = torch.randn(self.mean.shape, generator=generator, dtype=self.mean.dtype, device=self.mean.device)
        return _squashed_log_density(self.mean + torch.exp(self.log_std) * eps, self.mean, self.log_std)

    def log_prob(self, actions: Tensor) -> Tensor:
        """``sum_i log pi(a_i)`` for squashed ``actions`` ``[B, D]`` in ``(-1, 1)`` -> ``[B]``."""
        u = torch.atanh(actions.clamp(-_ATANH_LIMIT, _ATANH_LIMIT))
        return _squashed_log_density(u, self.mean, self.log_std)[1].sum(-1)

    def kl(self, other: SquashedGaussian) -> Tensor:
        """``KL(self || other)`` -> ``[B]``: the pre-tanh Gaussians' (exact)."""
        return _gaussian_kl(self.mean, self.log_std, other.mean, other.log_std).sum(-1)

    def entropy(self) -> Tensor:
        """A one-sample estimate ``-log pi(a)``, ``a`` drawn from the global generator -> ``[B]``."""
        return -self.rsample()[1].sum(-1)

    @torch.no_grad()
    def sample(self, generator: torch.Generator | None = None) -> Tensor:
        """``tanh(mean + std * eps)`` -> ``[B, D]``."""
        return self.rsample(generator)[0]

    @torch.no_grad()
    def mode(self) -> Tensor:
        """``tanh(mean)`` (the image of the Gaussian's mode, SAC's deterministic action) -> ``[B, D]``."""
        return torch.tanh(self.mean)

    def detach(self) -> SquashedGaussian:
        """Snapshot with detached, copied parameters."""
        return SquashedGaussian(self.mean.detach().clone(), self.log_std.detach().clone())


class HybridSquashed(Distribution):
    """A choice ``k ~ softmax(logits)`` and, for it, squashed Gaussian parameters ``x_k = tanh(u_k)`` in ``(-1, 1)^{d_k}``:
    the actor of hybrid SAC (Delalleau et al. 2019, "Discrete and Continuous Action Representation for Practical RL in
    Video Games", Section 3; MAPLE, Nasiriany et al. 2022, Section IV-B). Actions use :class:`Hierarchical`'s encoding,
    ``[k, x_1, ..., x_n]`` rows ``[B, 1 + S]``.

    ``pi(k, x | s) = p_k(s) pi_k(x_k | s)``; :meth:`kl` is Lemma 1's (exact, as for :class:`SquashedGaussian`);
    :meth:`entropy` is ``H(p) + sum_k p_k H(pi_k)`` with each ``H(pi_k)`` a one-sample estimate. A plain Box space is
    the case ``n = 1``, a Discrete one the case ``d_k = 0`` for every ``k``.

    Args:
        logits: ``[B, n]`` unnormalised choice logits.
        means: ``[B, S]`` pre-tanh means of every block, concatenated in choice order.
        log_std: ``[B, S]`` pre-tanh log standard deviations.
        param_dims: ``(d_1, ..., d_n)``; zeros allowed.
    """

    def __init__(self, logits: Tensor, means: Tensor, log_std: Tensor, param_dims: Sequence[int]) -> None:
        self.param_dims = tuple(int(d) for d in param_dims)
        if not self.param_dims or any(d < 0 for d in self.param_dims):
            raise ValueError(f"param_dims must be a non-empty tuple of non-negative ints, got {self.param_dims}")
        if logits.ndim != 2 or logits.shape[1] != len(self.param_dims):
            raise ValueError(f"logits must be [B, {len(self.param_dims)}], got shape {tuple(logits.shape)}")
        if means.ndim != 2 or means.shape != (logits.shape[0], sum(self.param_dims)):
            raise ValueError(f"means must be [B, {sum(self.param_dims)}], got shape {tuple(means.shape)}")
        self.categorical = Categorical(logits)
        self.squashed = SquashedGaussian(means, log_std)
        self._owner, self._blocks = _block_layout(self.param_dims, means.dtype, means.device)  # [S], [S, n]

    @property
    def batch_size(self) -> int:
        """Number ``B`` of distributions in the batch."""
        return self.categorical.batch_size

    @property
    def n(self) -> int:
        """Number of choices."""
        return len(self.param_dims)

    def rsample_blocks(self, generator: torch.Generator | None = None) -> tuple[Tensor, Tensor]:
        """Reparameterised parameters for every choice at once, ``x [B, S]``, and each block's log density
        ``log pi_k(x_k | s)`` ``[B, n]`` (0 for a parameterless choice): what the hybrid SAC losses sum over ``k``."""
        x, log_density = self.squashed.rsample(generator)
        return x, log_density @ self._blocks

    def log_prob(self, actions: Tensor) -> Tensor:
        """``log p_k + log pi_k(x_k)`` with ``k = actions[:, 0]`` -> ``[B]``; the other blocks are ignored."""
        k = actions[:, 0].long()
        x = actions[:, 1:].clamp(-_ATANH_LIMIT, _ATANH_LIMIT)
        per_column = _squashed_log_density(torch.atanh(x), self.squashed.mean, self.squashed.log_std)[1]
        chosen = self._owner.unsqueeze(0) == k.unsqueeze(-1)
        return self.categorical.log_prob(k) + torch.where(chosen, per_column, 0.0).sum(-1)

    def kl(self, other: HybridSquashed) -> Tensor:
        """Lemma 1: ``KL(p, p~) + sum_k p_k KL(pi_k, pi~_k)`` -> ``[B]`` (exact)."""
        g, h = self.squashed, other.squashed
        block_kl = _gaussian_kl(g.mean, g.log_std, h.mean, h.log_std) @ self._blocks
        return self.categorical.kl(other.categorical) + (self.categorical.probs * block_kl).sum(-1)

    def entropy(self) -> Tensor:
        """``H(p) + sum_k p_k H(pi_k)``, each ``H(pi_k)`` a one-sample estimate -> ``[B]``."""
        return self.categorical.entropy() - (self.categorical.probs * self.rsample_blocks()[1]).sum(-1)

    @torch.no_grad()
    def sample(self, generator: torch.Generator | None = None) -> Tensor:
        """The choice, then every block's parameters (as :meth:`Hierarchical.sample`) -> ``[B, 1 + S]``."""
        k = self.categorical.sample(generator)
        x = self.squashed.sample(generator)
        return torch.cat([k.to(x.dtype).unsqueeze(-1), x], dim=-1)

    @torch.no_grad()
    def mode(self) -> Tensor:
        """The most likely choice with every block at ``tanh(mean)`` -> ``[B, 1 + S]``."""
        x = self.squashed.mode()
        return torch.cat([self.categorical.mode().to(x.dtype).unsqueeze(-1), x], dim=-1)

    def detach(self) -> HybridSquashed:
        """Snapshot with detached, copied parameters."""
        s = self.squashed.detach()
        return HybridSquashed(self.categorical.log_p.detach().clone(), s.mean, s.log_std, self.param_dims)


def flat_to_tuple(action: np.ndarray | Tensor, param_dims: Sequence[int]) -> tuple:
    """One flat hierarchical action ``[1 + S]`` -> ``(k, u_1, ..., u_n)`` with ``k`` an ``int``, ``u_k`` ``[d_k]`` arrays.

    The result is a valid sample of gymnasium ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))`` when the ``Box``
    dtypes are float32 (the parameter blocks are returned as float32 arrays).
    """
    a = action.detach().cpu().numpy() if isinstance(action, Tensor) else np.asarray(action)
    if a.shape != (1 + sum(param_dims),):
        raise ValueError(f"expected a flat action of shape ({1 + sum(param_dims)},), got {a.shape}")
    k = round(float(a[0]))
    bounds = np.cumsum([1, *param_dims])
    return (k, *(a[lo:hi].astype(np.float32) for lo, hi in itertools.pairwise(bounds)))


def tuple_to_flat(sample: Sequence, param_dims: Sequence[int], dtype: np.dtype | type = np.float32) -> np.ndarray:
    """``(k, u_1, ..., u_n)`` (a gymnasium ``Tuple`` sample) -> flat ``[1 + S]`` array in the hierarchical encoding."""
    if len(sample) != 1 + len(param_dims):
        raise ValueError(f"expected {1 + len(param_dims)} entries (k and one block per macro-action), got {len(sample)}")
    blocks = [np.asarray(u, dtype=dtype).reshape(-1) for u in sample[1:]]
    for k, (u, d) in enumerate(zip(blocks, param_dims, strict=True)):
        if u.shape != (d,):
            raise ValueError(f"block {k} must have {d} entries, got {u.shape[0]}")
    return np.concatenate([np.asarray([int(sample[0])], dtype=dtype), *blocks])


def flat_to_tuples(actions: np.ndarray | Tensor, param_dims: Sequence[int]) -> list[tuple]:
    """Batched :func:`flat_to_tuple`: ``[B, 1 + S]`` -> ``B`` tuples ``(k, u_1, ..., u_n)``."""
    a = actions.detach().cpu().numpy() if isinstance(actions, Tensor) else np.asarray(actions)
    return [flat_to_tuple(row, param_dims) for row in a]


def tuples_to_flat(samples: Sequence[Sequence], param_dims: Sequence[int], dtype: np.dtype | type = np.float32) -> np.ndarray:
    """Batched :func:`tuple_to_flat`: ``B`` tuples -> ``[B, 1 + S]`` array."""
    rows = [tuple_to_flat(s, param_dims, dtype) for s in samples]
    return np.stack(rows) if rows else np.zeros((0, 1 + sum(param_dims)), dtype=dtype)
