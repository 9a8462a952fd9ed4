"""Hierarchical distributions with Gaussian parameters, the setting of the paper's experiments (Section 3.1).

A distribution on ``A = R^{d_1} ⊔ ... ⊔ R^{d_n}`` picks macro-action ``k`` with probability ``p_k`` and then its
parameter ``u ~ N(mean_k, diag(exp(log_std_k))^2)``; ``d_k = 0`` is a parameterless macro-action.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import rel_entr

_LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True, eq=False)
class GaussianHierarchical:
    """A distribution on ``⊔_k R^{d_k}`` with diagonal-Gaussian parameters.

    Attributes:
        p: macro-action probabilities ``[n]``.
        mean: ``mean[k]`` is the parameter mean of macro-action ``k``, ``[d_k]``.
        log_std: ``log_std[k]`` is the log standard deviation per coordinate, ``[d_k]``.
    """

    p: np.ndarray
    mean: tuple[np.ndarray, ...]
    log_std: tuple[np.ndarray, ...]

    def __post_init__(self) -> None:
        p = np.asarray(self.p, dtype=float)
        mean = tuple(np.asarray(m, dtype=float).reshape(-1) for m in self.mean)
        log_std = tuple(np.asarray(s, dtype=float).reshape(-1) for s in self.log_std)
        if p.ndim != 1 or len(mean) != p.shape[0] or len(log_std) != p.shape[0]:
            raise ValueError("p, mean and log_std must describe the same number of macro-actions")
        if np.any(p < 0) or abs(p.sum() - 1.0) > 1e-9:
            raise ValueError("p must be a probability distribution")
        if any(m.shape != s.shape for m, s in zip(mean, log_std, strict=True)):
            raise ValueError("mean[k] and log_std[k] must have the same shape [d_k]")
        object.__setattr__(self, "p", p)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "log_std", log_std)

    @property
    def dims(self) -> tuple[int, ...]:
        """Parameter dimensions ``(d_1, ..., d_n)``."""
        return tuple(m.shape[0] for m in self.mean)

    def _padded(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d_max = max(self.dims)
        mean = np.zeros((len(self.dims), d_max))
        log_std = np.zeros((len(self.dims), d_max))
        mask = np.zeros((len(self.dims), d_max), dtype=bool)
        for k, d in enumerate(self.dims):
            mean[k, :d], log_std[k, :d], mask[k, :d] = self.mean[k], self.log_std[k], True
        return mean, log_std, mask

    def sample(self, rng: np.random.Generator, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
        """Draw ``n_samples`` actions: macro indices ``k`` ``[N]`` and parameters ``u`` ``[N, max_k d_k]``.

        Coordinates of ``u`` beyond ``d_k`` are zero and ignored by :meth:`log_prob`.
        """
        k = rng.choice(len(self.dims), size=n_samples, p=self.p)
        mean, log_std, mask = self._padded()
        u = (mean[k] + np.exp(log_std[k]) * rng.standard_normal((n_samples, mean.shape[1]))) * mask[k]
        return k, u

    def log_prob(self, k: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Log density w.r.t. counting x Lebesgue measure on ``⊔_k R^{d_k}``, ``[N]``."""
        mean, log_std, mask = self._padded()
        z = (u - mean[k]) * np.exp(-log_std[k])
        log_normal = np.where(mask[k], -0.5 * z**2 - log_std[k] - 0.5 * _LOG_2PI, 0.0).sum(axis=1)
        with np.errstate(divide="ignore"):
            return np.log(self.p[k]) + log_normal


def gaussian_kl(mean: np.ndarray, log_std: np.ndarray, mean_tilde: np.ndarray, log_std_tilde: np.ndarray) -> float:
    """Closed-form ``D_KL(N(mean, diag std^2), N(mean~, diag std~^2))``; 0 for ``d = 0``."""
    var_ratio = np.exp(2.0 * (log_std - log_std_tilde))
    maha = ((mean - mean_tilde) * np.exp(-log_std_tilde)) ** 2
    return float(0.5 * np.sum(var_ratio + maha - 1.0) + np.sum(log_std_tilde - log_std))


def lemma1_rhs(mu: GaussianHierarchical, mu_tilde: GaussianHierarchical) -> float:
    """Lemma 1, right-hand side of (1): ``D_KL(p, p~) + sum_k p_k D_KL(mu_k, mu~_k)``, in closed form."""
    if mu.dims != mu_tilde.dims:
        raise ValueError(f"both distributions must live on the same space, got dims {mu.dims} and {mu_tilde.dims}")
    total = float(rel_entr(mu.p, mu_tilde.p).sum())
    for k, p_k in enumerate(mu.p):
        if p_k > 0:
            total += p_k * gaussian_kl(mu.mean[k], mu.log_std[k], mu_tilde.mean[k], mu_tilde.log_std[k])
    return total


def kl_monte_carlo(
    mu: GaussianHierarchical, mu_tilde: GaussianHierarchical, rng: np.random.Generator, n_samples: int
) -> tuple[float, float]:
    """Monte-Carlo estimate of ``D_KL(mu, mu~) = E_{a ~ mu} log(dmu/dmu~)(a)`` from the joint densities.

    Returns ``(estimate, standard_error)``.
    """
    if n_samples < 2:
        raise ValueError(f"n_samples must be >= 2, got {n_samples}")
    k, u = mu.sample(rng, n_samples)
    log_ratio = mu.log_prob(k, u) - mu_tilde.log_prob(k, u)
    return float(log_ratio.mean()), float(log_ratio.std(ddof=1) / np.sqrt(n_samples))


def random_gaussian_hierarchical(
    rng: np.random.Generator, dims: tuple[int, ...], *, concentration: float = 1.0
) -> GaussianHierarchical:
    """A random distribution on ``⊔_k R^{d_k}``: Dirichlet macro probabilities, standard-normal means, log-std in [-1, 0.5]."""
    p = rng.dirichlet(np.full(len(dims), concentration))
    mean = tuple(rng.standard_normal(d) for d in dims)
    log_std = tuple(rng.uniform(-1.0, 0.5, size=d) for d in dims)
    return GaussianHierarchical(p, mean, log_std)
