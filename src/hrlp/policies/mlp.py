"""Multilayer perceptrons, the policies built on them, and the value network.

Every policy maps a batch of observations ``[B, obs_dim]`` to a :class:`~hrlp.policies.distributions.Distribution`.
The Manager (:class:`HierarchicalPolicy`) is ONE network, as in the paper's Figure 9: two dense hidden layers whose
output layer holds the macro-action logits and all parameter means, plus a state-independent log-std vector.

Acting is batched: :meth:`Policy.act_numpy` takes ``[N, obs_dim]`` observations of ``N`` environments and returns
``N`` actions in one no-grad call, because per-observation torch calls (about 0.17 ms each, whatever the batch:
``benchmarks/policy_call.py``) dominate sampling time. :class:`NumpyMLP` is a frozen NumPy copy of a network for
single-observation loops.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence

import gymnasium as gym
import numpy as np
import torch
from torch import Tensor, nn

from hrlp.policies.distributions import Categorical, DiagGaussian, Distribution, Hierarchical, flat_to_tuples

__all__ = [
    "CategoricalPolicy",
    "GaussianPolicy",
    "HierarchicalPolicy",
    "NumpyMLP",
    "Policy",
    "ValueNet",
    "mlp",
    "policy_for_space",
]


def mlp(
    in_dim: int,
    out_dim: int,
    hidden: Sequence[int] = (64, 64),
    activation: type[nn.Module] = nn.Tanh,
    output_gain: float = 1.0,
) -> nn.Sequential:
    """``Linear -> activation`` for each hidden width, then a linear output layer: ``[B, in_dim] -> [B, out_dim]``.

    Weights are orthogonal (gain sqrt(2) in hidden layers, ``output_gain`` in the last), biases zero, following
    CleanRL/SB3's on-policy defaults; a small ``output_gain`` (0.01) starts a policy close to uniform/centred.
    """
    layers: list[nn.Module] = []
    width = in_dim
    for h in hidden:
        layers += [_orthogonal(nn.Linear(width, h), math.sqrt(2.0)), activation()]
        width = h
    layers.append(_orthogonal(nn.Linear(width, out_dim), output_gain))
    return nn.Sequential(*layers)


def _orthogonal(layer: nn.Linear, gain: float) -> nn.Linear:
    """Orthogonal weights with ``gain``, zero bias; returns ``layer``."""
    nn.init.orthogonal_(layer.weight, gain)
    nn.init.zeros_(layer.bias)
    return layer


class Policy(nn.Module, ABC):
    """A stochastic policy: ``forward(obs [B, obs_dim]) -> Distribution`` over ``B`` states."""

    @abstractmethod
    def forward(self, obs: Tensor) -> Distribution:
        """The action distribution for each of the ``B`` observations ``[B, obs_dim]``."""

    @torch.inference_mode()
    def act(self, obs: Tensor, generator: torch.Generator | None = None, deterministic: bool = False) -> Tensor:
        """Actions for a batch ``[B, obs_dim]`` without autograd: a sample (``generator``) or the mode -> ``[B, ...]``."""
        dist = self(obs)
        return dist.mode() if deterministic else dist.sample(generator)

    def act_numpy(self, obs: np.ndarray, generator: torch.Generator | None = None, deterministic: bool = False) -> np.ndarray:
        """Batched acting for ``N`` environments at once: ``[N, obs_dim]`` (or ``[obs_dim]``) NumPy in, NumPy out.

        Returns ``[N, ...]`` actions in the distribution's encoding (``[...]`` for a single observation).
        """
        x = np.asarray(obs)
        single = x.ndim == 1
        param = next(self.parameters())
        t = torch.as_tensor(x[None] if single else x, dtype=param.dtype, device=param.device)
        actions = self.act(t, generator, deterministic).cpu().numpy()
        return actions[0] if single else actions

    def numpy_actor(self) -> Callable[[np.ndarray, torch.Generator | None], np.ndarray]:
        """``act(obs [N, obs_dim], generator) -> [N, ...]``: stochastic :meth:`act_numpy` with the weights as they are now.

        For a sampler, whose weights stay fixed for a whole batch. Policies with a NumPy forward pass (the Gaussian
        and the hierarchical MLP) override it: the same random numbers from ``generator``, a few microseconds per
        call instead of torch's per-operation overhead. Later changes to the weights are not seen; ask again after
        an update.
        """
        return lambda obs, generator=None: self.act_numpy(obs, generator)


class GaussianPolicy(Policy):
    """``pi(a|s) = N(mu_theta(s), diag(exp(log_std)^2))`` with a state-independent ``log_std`` parameter ``[act_dim]``."""

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden: Sequence[int] = (64, 64),
        activation: type[nn.Module] = nn.Tanh,
        init_log_std: float = 0.0,
    ) -> None:
        super().__init__()
        self.mean_net = mlp(obs_dim, act_dim, hidden, activation, output_gain=0.01)
        self.log_std = nn.Parameter(torch.full((act_dim,), float(init_log_std)))

    def forward(self, obs: Tensor) -> DiagGaussian:
        """``[B, obs_dim] -> DiagGaussian`` with mean ``[B, act_dim]``."""
        return DiagGaussian(self.mean_net(obs), self.log_std)

    def numpy_actor(self) -> Callable[[np.ndarray, torch.Generator | None], np.ndarray]:
        """NumPy sampling ``mean + std * eps``, ``eps`` drawn from ``generator`` as :meth:`DiagGaussian.sample` draws it."""
        numpy_net = _numpy_copy(self.mean_net, self.log_std)
        if numpy_net is None:
            return super().numpy_actor()
        mean_net, std = numpy_net

        def act(obs: np.ndarray, generator: torch.Generator | None = None) -> np.ndarray:
            x = np.asarray(obs, dtype=std.dtype)
            mean = mean_net(x[None] if x.ndim == 1 else x)
            out = mean + std * _randn(mean.shape, generator, self.log_std)
            return out[0] if x.ndim == 1 else out

        return act


class CategoricalPolicy(Policy):
    """``pi(a|s) = softmax(logits_theta(s))`` over ``n`` discrete actions."""

    def __init__(self, obs_dim: int, n: int, hidden: Sequence[int] = (64, 64), activation: type[nn.Module] = nn.Tanh) -> None:
        super().__init__()
        self.logits_net = mlp(obs_dim, n, hidden, activation, output_gain=0.01)

    def forward(self, obs: Tensor) -> Categorical:
        """``[B, obs_dim] -> Categorical`` with logits ``[B, n]``."""
        return Categorical(self.logits_net(obs))


class HierarchicalPolicy(Policy):
    """The Manager: one network ``[B, obs_dim] -> [B, n + S]`` split into macro-action logits ``[B, n]`` and all
    parameter means ``[B, S]`` (``S = sum_k d_k``), plus a state-independent ``log_std`` ``[S]``.

    Its distribution is :class:`~hrlp.policies.distributions.Hierarchical`; actions are ``[B, 1 + S]`` rows
    ``[k, u_1, ..., u_n]``, and :meth:`act_tuples` returns gymnasium ``Tuple(Discrete(n), Box(d_1), ...)`` samples.
    """

    def __init__(
        self,
        obs_dim: int,
        n: int,
        param_dims: Sequence[int],
        hidden: Sequence[int] = (64, 64),
        activation: type[nn.Module] = nn.Tanh,
        init_log_std: float = 0.0,
    ) -> None:
        super().__init__()
        self.param_dims = tuple(int(d) for d in param_dims)
        if len(self.param_dims) != n:
            raise ValueError(f"param_dims must have n={n} entries, got {self.param_dims}")
        self.n = n
        self.net = mlp(obs_dim, n + sum(self.param_dims), hidden, activation, output_gain=0.01)
        self.log_std = nn.Parameter(torch.full((sum(self.param_dims),), float(init_log_std)))

    def forward(self, obs: Tensor) -> Hierarchical:
        """``[B, obs_dim] -> Hierarchical`` (logits ``[B, n]``, means ``[B, S]``, log_std ``[S]``)."""
        out = self.net(obs)
        return Hierarchical(out[:, : self.n], out[:, self.n :], self.log_std, self.param_dims)

    def numpy_actor(self) -> Callable[[np.ndarray, torch.Generator | None], np.ndarray]:
        """NumPy sampling of ``[k, u]`` rows; ``k`` and the noise of ``u`` drawn from ``generator`` in
        :meth:`Hierarchical.sample`'s order (categorical first)."""
        numpy_net = _numpy_copy(self.net, self.log_std)
        if numpy_net is None:
            return super().numpy_actor()
        net, std = numpy_net
        n = self.n

        def act(obs: np.ndarray, generator: torch.Generator | None = None) -> np.ndarray:
            x = np.asarray(obs, dtype=std.dtype)
            out = net(x[None] if x.ndim == 1 else x)
            logits = out[:, :n]
            p = np.exp(logits - logits.max(-1, keepdims=True))
            p /= p.sum(-1, keepdims=True)
            k = torch.multinomial(torch.from_numpy(p), 1, generator=generator).numpy().astype(std.dtype)
            u = out[:, n:] + std * _randn(out[:, n:].shape, generator, self.log_std)
            rows = np.concatenate([k, u], axis=1)
            return rows[0] if x.ndim == 1 else rows

        return act

    def act_tuples(
        self, obs: np.ndarray, generator: torch.Generator | None = None, deterministic: bool = False
    ) -> list[tuple]:
        """:meth:`act_numpy` for ``[N, obs_dim]`` converted to ``N`` gymnasium ``Tuple`` samples ``(k, u_1, ..., u_n)``."""
        return flat_to_tuples(self.act_numpy(np.atleast_2d(obs), generator, deterministic), self.param_dims)


def policy_for_space(obs_dim: int, space: gym.Space, hidden: Sequence[int] = (64, 64), init_log_std: float = 0.0) -> Policy:
    """The policy for an action space: Box -> Gaussian, Discrete -> categorical, ``Tuple(Discrete(n), Box(d_1), ...,
    Box(d_n))`` -> hierarchical (the Manager). Raises ValueError for any other space."""
    from hrlp.envs.check import parameterised_dims

    if isinstance(space, gym.spaces.Box):
        return GaussianPolicy(obs_dim, int(np.prod(space.shape)), hidden, init_log_std=init_log_std)
    if isinstance(space, gym.spaces.Discrete):
        return CategoricalPolicy(obs_dim, int(space.n), hidden)
    dims = parameterised_dims(space)
    return HierarchicalPolicy(obs_dim, len(dims), dims, hidden, init_log_std=init_log_std)


class ValueNet(nn.Module):
    """State-value baseline ``V_phi(s)``: ``[B, obs_dim] -> [B]``; a module of its own, never in the policy's trust region."""

    def __init__(self, obs_dim: int, hidden: Sequence[int] = (64, 64), activation: type[nn.Module] = nn.Tanh) -> None:
        super().__init__()
        self.net = mlp(obs_dim, 1, hidden, activation, output_gain=1.0)

    def forward(self, obs: Tensor) -> Tensor:
        """``[B, obs_dim] -> [B]``."""
        return self.net(obs).squeeze(-1)

    @torch.inference_mode()
    def predict_numpy(self, obs: np.ndarray) -> np.ndarray:
        """Batched no-grad evaluation: ``[N, obs_dim]`` NumPy -> ``[N]`` NumPy."""
        param = next(self.parameters())
        return self(torch.as_tensor(np.asarray(obs), dtype=param.dtype, device=param.device)).cpu().numpy()


def _numpy_copy(net: nn.Sequential, log_std: Tensor) -> tuple[NumpyMLP, np.ndarray] | None:
    """``(NumPy copy of net, exp(log_std))`` in the policy's precision, or None if ``net`` has a layer NumPy lacks."""
    std = torch.exp(log_std.detach()).cpu().numpy()
    try:
        return NumpyMLP(net, std.dtype), std
    except TypeError:
        return None


def _randn(shape: tuple[int, ...], generator: torch.Generator | None, like: Tensor) -> np.ndarray:
    """Standard normal noise in ``like``'s dtype, drawn from ``generator`` as :meth:`DiagGaussian.sample` draws it."""
    return torch.randn(shape, generator=generator, dtype=like.dtype).numpy()


_NUMPY_ACTIVATIONS: dict[type[nn.Module], Callable[[np.ndarray], np.ndarray]] = {
    nn.Tanh: np.tanh,
    nn.ReLU: lambda x: np.maximum(x, 0.0),
    nn.Identity: lambda x: x,
}


class NumpyMLP:
    """A frozen NumPy copy of an :func:`mlp` (``Linear``/``Tanh``/``ReLU``/``Identity`` layers): ``[..., in] -> [..., out]``.

    For loops that evaluate one observation at a time (a frozen skill inside the macro-action wrapper), where a
    NumPy matmul of a 64x64 network costs a few microseconds against ~0.35 ms for a torch call. Later changes to the
    source module are not seen.
    """

    def __init__(self, module: nn.Sequential, dtype: np.dtype | type = np.float64) -> None:
        self.layers: list[tuple[np.ndarray, np.ndarray] | Callable[[np.ndarray], np.ndarray]] = []
        for layer in module:
            if isinstance(layer, nn.Linear):
                w = layer.weight.detach().cpu().numpy().astype(dtype).T.copy()
                b = layer.bias.detach().cpu().numpy().astype(dtype).copy()
                self.layers.append((w, b))
            elif type(layer) in _NUMPY_ACTIVATIONS:
                self.layers.append(_NUMPY_ACTIVATIONS[type(layer)])
            else:
                raise TypeError(f"NumpyMLP supports Linear, Tanh, ReLU and Identity layers, got {type(layer).__name__}")

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Forward pass on ``[..., in_dim]`` -> ``[..., out_dim]``."""
        for layer in self.layers:
            x = x @ layer[0] + layer[1] if isinstance(layer, tuple) else layer(x)
        return x
