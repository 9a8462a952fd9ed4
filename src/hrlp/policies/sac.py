"""The networks of soft actor-critic: a squashed actor for any action space hrlp trains on, and twin Q critics.

One actor serves every space (Box, Discrete, a parameterised ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))`` and a
Manager's skill choice with its parameters): inside, it is always a :class:`~hrlp.policies.distributions.HybridSquashed`
over ``n`` choices with ``d_k`` parameters each, a Box being ``n = 1`` and a Discrete ``d_k = 0``
(:attr:`SACActor.param_dims`). Its actions come out in the environment's encoding and units (a Box's bounds are
mapped from ``(-1, 1)`` affinely, as Stable-Baselines3's SAC does); :meth:`SACActor.to_hybrid` maps them back into the
``[k, x_1, ..., x_n]`` rows in ``(-1, 1)`` that the critics and the losses read.
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np
import torch
from torch import Tensor, nn

from hrlp.envs.check import parameterised_dims
from hrlp.policies.distributions import Categorical, Distribution, HybridSquashed
from hrlp.policies.mlp import Policy, mlp

__all__ = ["LOG_STD_MAX", "LOG_STD_MIN", "SACActor", "TwinQ", "action_kind"]

LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0
"""The actor's pre-tanh log standard deviations are clamped to this range (Stable-Baselines3's and the SAC authors')."""


def action_kind(space: gym.Space) -> tuple[str, tuple[int, ...]]:
    """``("box", (d,))``, ``("discrete", (0,) * n)`` or ``("hybrid", (d_1, ..., d_n))`` for an action space hrlp
    trains on; ValueError (one line) for any other."""
    if isinstance(space, gym.spaces.Box):
        return "box", (int(np.prod(space.shape)),)
    if isinstance(space, gym.spaces.Discrete):
        return "discrete", (0,) * int(space.n)
    return "hybrid", tuple(parameterised_dims(space))


class SACActor(Policy):
    """``obs [B, obs_dim]`` -> a :class:`~hrlp.policies.distributions.HybridSquashed` (:meth:`hybrid`): one MLP whose
    output holds the choice logits (none when ``n = 1``), every block's pre-tanh means and their log standard
    deviations (state-dependent, clamped to [:data:`LOG_STD_MIN`, :data:`LOG_STD_MAX`]).

    :meth:`forward` gives the distribution in the space's own encoding, in ``(-1, 1)`` units (a Box:
    :class:`~hrlp.policies.distributions.SquashedGaussian`; a Discrete: a categorical; a parameterised space or a
    Manager: the hybrid itself); :meth:`act` maps a Box's actions onto its bounds (an unbounded dimension stays in
    ``(-1, 1)``).
    """

    def __init__(self, obs_dim: int, space: gym.Space, hidden: Sequence[int] = (256, 256)) -> None:
        super().__init__()
        self.kind, self.param_dims = action_kind(space)
        self.n, self.s = len(self.param_dims), sum(self.param_dims)
        self._logits = self.n if self.n > 1 else 0
        self.net = mlp(obs_dim, self._logits + 2 * self.s, hidden, nn.ReLU, output_gain=0.01)
        scale, offset = np.ones(self.s), np.zeros(self.s)
        if self.kind == "box":
            assert isinstance(space, gym.spaces.Box)
            low, high = (np.asarray(b, np.float64).reshape(-1) for b in (space.low, space.high))
            finite = np.isfinite(low) & np.isfinite(high)
            scale[finite], offset[finite] = (high - low)[finite] / 2, (high + low)[finite] / 2
        # Not saved with the weights: they follow from the action space, which a run records.
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32), persistent=False)
        self.register_buffer("offset", torch.as_tensor(offset, dtype=torch.float32), persistent=False)

    def hybrid(self, obs: Tensor) -> HybridSquashed:
        """The actor's distribution over ``[k, x_1, ..., x_n]`` rows in ``(-1, 1)``."""
        out = self.net(obs)
        logits = out[:, : self._logits] if self._logits else out.new_zeros((out.shape[0], 1))
        mean, log_std = out[:, self._logits : self._logits + self.s], out[:, self._logits + self.s :]
        return HybridSquashed(logits, mean, log_std.clamp(LOG_STD_MIN, LOG_STD_MAX), self.param_dims)

    def forward(self, obs: Tensor) -> Distribution:
        """The distribution in the space's encoding, ``(-1, 1)`` units."""
        h = self.hybrid(obs)
        if self.kind == "box":
            return h.squashed
        if self.kind == "discrete":
            return Categorical(h.categorical.log_p)
        return h

    @torch.inference_mode()
    def act(self, obs: Tensor, generator: torch.Generator | None = None, deterministic: bool = False) -> Tensor:
        """Actions in the environment's encoding and units: a sample (``generator``) or the mode."""
        dist = self(obs)
        a = dist.mode() if deterministic else dist.sample(generator)
        return a * self.scale + self.offset if self.kind == "box" else a

    def to_hybrid(self, actions: Tensor) -> Tensor:
        """Actions as the environment got them (``[B, d]``, ``[B]`` or ``[B, 1 + S]``) -> ``[B, 1 + S]`` hybrid rows in
        ``(-1, 1)`` units."""
        b = actions.shape[0]
        if self.kind == "box":
            x = (actions.reshape(b, -1) - self.offset) / self.scale
            return torch.cat([x.new_zeros((b, 1)), x], dim=-1)
        if self.kind == "discrete":
            return actions.reshape(b, 1).float()
        return actions.reshape(b, 1 + self.s)


class TwinQ(nn.Module):
    """Two critics ``Q_i(s, k, x_k)``, each an MLP on ``[obs, one-hot k (when n > 1), x]`` where ``x`` keeps only the
    chosen block's parameters (the others zero), as MAPLE's critic reads a primitive and its parameters."""

    def __init__(self, obs_dim: int, param_dims: Sequence[int], hidden: Sequence[int] = (256, 256)) -> None:
        super().__init__()
        self.param_dims = tuple(int(d) for d in param_dims)
        self.n, self.s = len(self.param_dims), sum(self.param_dims)
        width = obs_dim + (self.n if self.n > 1 else 0) + self.s
        self.q1 = mlp(width, 1, hidden, nn.ReLU)
        self.q2 = mlp(width, 1, hidden, nn.ReLU)
        owner = torch.repeat_interleave(torch.arange(self.n), torch.tensor(self.param_dims, dtype=torch.long))
        self.register_buffer("owner", owner, persistent=False)

    def _inputs(self, obs: Tensor, k: Tensor, x: Tensor) -> Tensor:
        parts = [obs]
        if self.n > 1:
            parts.append(nn.functional.one_hot(k, self.n).to(obs.dtype))
        if self.s:
            parts.append(torch.where(self.owner.unsqueeze(0) == k.unsqueeze(-1), x, 0.0))
        return torch.cat(parts, dim=-1)

    def forward(self, obs: Tensor, actions: Tensor) -> tuple[Tensor, Tensor]:
        """``(Q_1, Q_2)`` ``[B]`` each for hybrid rows ``actions`` ``[B, 1 + S]``."""
        z = self._inputs(obs, actions[:, 0].long(), actions[:, 1:])
        return self.q1(z).squeeze(-1), self.q2(z).squeeze(-1)

    def every_choice(self, obs: Tensor, x: Tensor) -> tuple[Tensor, Tensor]:
        """``(Q_1, Q_2)`` ``[B, n]`` each: every choice ``k`` with its own block of ``x`` ``[B, S]``."""
        b = obs.shape[0]
        k = torch.arange(self.n, device=obs.device).repeat_interleave(b)
        z = self._inputs(obs.repeat(self.n, 1), k, x.repeat(self.n, 1))
        return self.q1(z).reshape(self.n, b).T, self.q2(z).reshape(self.n, b).T
