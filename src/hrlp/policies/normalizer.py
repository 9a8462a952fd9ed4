"""Running mean/variance observation normaliser (modular_rl's ``ZFilter``, with a batched parallel-merge update).

Statistics are kept in float64 NumPy so that millions of updates do not drift; :meth:`RunningNormalizer.normalize`
returns the input's own type and dtype. ``state_dict()`` holds only tensors (save with ``safetensors``) and
``config()`` only JSON numbers/booleans, so a normaliser is stored without pickle.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, overload

import numpy as np
import torch
from torch import Tensor

__all__ = ["RunningNormalizer"]


class RunningNormalizer:
    """Per-dimension running mean and (population) variance of observations; ``(x - mean) / sqrt(var + eps)``, clipped.

    Args:
        shape: shape of one observation, e.g. ``(obs_dim,)``.
        clip: outputs are clipped to ``[-clip, clip]`` (``None`` or ``inf``: no clipping; modular_rl: 5, SB3: 10).
        eps: added to the variance before the square root.
        frozen: if ``True``, :meth:`update` is a no-op (evaluation, or a normaliser shipped with a frozen skill).
    """

    def __init__(self, shape: int | Sequence[int], clip: float | None = 10.0, eps: float = 1e-8, frozen: bool = False) -> None:
        self.shape: tuple[int, ...] = (shape,) if isinstance(shape, int) else tuple(int(s) for s in shape)
        if clip is not None and not clip > 0:
            raise ValueError(f"clip must be positive or None, got {clip}")
        if not eps >= 0:
            raise ValueError(f"eps must be >= 0, got {eps}")
        self.clip = math.inf if clip is None else float(clip)
        self.eps = float(eps)
        self.frozen = bool(frozen)
        self.mean = np.zeros(self.shape, dtype=np.float64)
        self.var = np.ones(self.shape, dtype=np.float64)  # identity transform until the first update
        self.count = 0.0

    @property
    def std(self) -> np.ndarray:
        """``sqrt(var + eps)``, the divisor used by :meth:`normalize`."""
        return np.sqrt(self.var + self.eps)

    def freeze(self) -> None:
        """Stop updating the statistics."""
        self.frozen = True

    def unfreeze(self) -> None:
        """Resume updating the statistics."""
        self.frozen = False

    def update(self, obs: np.ndarray | Tensor) -> None:
        """Merge a batch ``[B, *shape]`` (or a single ``[*shape]`` observation) into the statistics, unless frozen.

        Parallel merge of Chan et al. (1979): with ``delta = mean_b - mean`` and ``n = count + B``,
        ``mean += delta * B / n`` and ``M2 = var * count + var_b * B + delta^2 * count * B / n``, ``var = M2 / n``;
        exact for any split of the data into batches.

        Raises ValueError naming the first row and dimension holding a NaN or inf, before changing anything: one such
        value would make the statistics NaN for good.
        """
        if self.frozen:
            return
        x = obs.detach().cpu().numpy() if isinstance(obs, Tensor) else np.asarray(obs)
        x = x.astype(np.float64, copy=False).reshape(-1, *self.shape)
        if x.shape[0] == 0:
            return
        if not np.isfinite(x).all():
            row, *dim = (int(i) for i in np.argwhere(~np.isfinite(x))[0])
            where = dim[0] if len(dim) == 1 else tuple(dim)
            raise ValueError(f"normaliser update: non-finite observation (row {row} of {x.shape[0]}, dimension {where}: "
                             f"{x[(row, *dim)]}); statistics left unchanged")  # fmt: skip
        batch_count = float(x.shape[0])
        batch_mean = x.mean(axis=0)
        batch_var = x.var(axis=0)
        total = self.count + batch_count
        delta = batch_mean - self.mean
        m2 = self.var * self.count + batch_var * batch_count + delta**2 * (self.count * batch_count / total)
        self.mean = self.mean + delta * (batch_count / total)
        self.var = m2 / total
        self.count = total

    @overload
    def normalize(self, obs: np.ndarray) -> np.ndarray: ...
    @overload
    def normalize(self, obs: Tensor) -> Tensor: ...
    def normalize(self, obs: np.ndarray | Tensor) -> np.ndarray | Tensor:
        """``clip((obs - mean) / sqrt(var + eps))`` for ``[..., *shape]`` input; same type, dtype and shape out."""
        if isinstance(obs, Tensor):
            mean = torch.as_tensor(self.mean, dtype=obs.dtype, device=obs.device)
            std = torch.as_tensor(self.std, dtype=obs.dtype, device=obs.device)
            return torch.clamp((obs - mean) / std, -self.clip, self.clip)
        x = np.asarray(obs)
        dtype = x.dtype if np.issubdtype(x.dtype, np.floating) else np.float64
        out = np.clip((x - self.mean) / self.std, -self.clip, self.clip)
        return out.astype(dtype, copy=False)

    def __call__(self, obs: np.ndarray | Tensor, update: bool = True) -> np.ndarray | Tensor:
        """Update with ``obs`` (if ``update`` and not frozen), then normalise it."""
        if update:
            self.update(obs)
        return self.normalize(obs)

    def state_dict(self) -> dict[str, Tensor]:
        """Statistics as float64 tensors ``{"mean": [*shape], "var": [*shape], "count": []}`` (safetensors-ready)."""
        return {
            "mean": torch.from_numpy(self.mean.copy()),
            "var": torch.from_numpy(self.var.copy()),
            "count": torch.tensor(self.count, dtype=torch.float64),
        }

    def load_state_dict(self, state: Mapping[str, Tensor | np.ndarray | float | Sequence[float]]) -> None:
        """Restore statistics from :meth:`state_dict` output (tensors, arrays, lists or numbers)."""
        mean = np.asarray(_to_numpy(state["mean"]), dtype=np.float64).reshape(self.shape)
        var = np.asarray(_to_numpy(state["var"]), dtype=np.float64).reshape(self.shape)
        count = float(np.asarray(_to_numpy(state["count"])))
        if not (math.isfinite(count) and np.isfinite(mean).all() and np.isfinite(var).all()):
            raise ValueError("normaliser statistics must be finite (mean, var and count hold NaN or inf)")
        if count < 0 or np.any(var < 0):
            raise ValueError("count and var must be non-negative")
        self.mean, self.var, self.count = mean.copy(), var.copy(), count

    def config(self) -> dict[str, Any]:
        """Constructor arguments as JSON-serialisable values (``clip`` is ``None`` when disabled)."""
        return {
            "shape": list(self.shape),
            "clip": None if math.isinf(self.clip) else self.clip,
            "eps": self.eps,
            "frozen": self.frozen,
        }

    @classmethod
    def from_config(cls, config: Mapping[str, Any], state: Mapping[str, Any] | None = None) -> RunningNormalizer:
        """Rebuild from :meth:`config` output and, optionally, a :meth:`state_dict`."""
        out = cls(
            tuple(config["shape"]), clip=config.get("clip"), eps=config.get("eps", 1e-8), frozen=config.get("frozen", False)
        )
        if state is not None:
            out.load_state_dict(state)
        return out


def _to_numpy(value: Any) -> Any:
    """Tensor -> NumPy; anything else unchanged."""
    return value.detach().cpu().numpy() if isinstance(value, Tensor) else value
