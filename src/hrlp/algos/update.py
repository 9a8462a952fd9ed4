"""The policy update seam: what the training loop calls once per batch, whatever the optimiser.

A :class:`PolicyUpdate` takes the batch's states, actions and advantages, changes the policy's parameters in place and
returns its statistics as plain numbers. :class:`TRPOUpdate` (the paper's, Section 3.1) and :class:`PPOUpdate` implement
it; :func:`make_update` picks one from ``TrainConfig.algo``. Both see the policy only through the
:class:`~hrlp.policies.distributions.Distribution` it returns, so a Manager's hierarchical distribution (Lemma 1's KL)
needs no special case. An update that keeps state between batches (PPO's Adam moments and minibatch shuffle) saves it
with the run, so that a resumed run continues exactly.
"""

from __future__ import annotations

from typing import Protocol

import torch
from torch import Tensor, nn

from hrlp.algos.ppo import ppo_update
from hrlp.algos.trpo import trpo_update
from hrlp.config import PPOConfig, TrainConfig, TRPOConfig
from hrlp.policies.distributions import Distribution

__all__ = ["PPOUpdate", "PolicyUpdate", "TRPOUpdate", "adam_tensors", "load_adam", "make_update"]


class PolicyUpdate(Protocol):
    """One policy step per batch."""

    name: str
    """The prefix of its statistics in the run's logs (``trpo/kl``, ``ppo/kl``)."""

    def __call__(self, obs: Tensor, actions: Tensor, advantages: Tensor) -> dict[str, float]:
        """Update the policy on the batch's normalised observations ``[B, D]``, actions ``[B, ...]`` and advantages
        ``[B]``; returns the statistics (they include ``kl``, the exact mean KL(old || new), and ``accepted``)."""
        ...

    def state(self) -> dict[str, Tensor]:
        """Tensors of the state the update keeps between batches (empty if none)."""
        ...

    def load_state(self, tensors: dict[str, Tensor]) -> None:
        """Restore :meth:`state`'s tensors."""
        ...


class TRPOUpdate:
    """:func:`~hrlp.algos.trpo.trpo_update` on the whole batch, with the Fisher matrix on every
    ``round(1 / fisher_fraction)``-th state. Keeps no state between batches."""

    name = "trpo"

    def __init__(self, policy: nn.Module, cfg: TRPOConfig) -> None:
        self.policy, self.cfg = policy, cfg

    def __call__(self, obs: Tensor, actions: Tensor, advantages: Tensor) -> dict[str, float]:
        stride = round(1 / self.cfg.fisher_fraction)
        stats = trpo_update(  # old_dist None: the policy's own, from the update's first forward pass
            list(self.policy.parameters()), lambda: self.policy(obs), None, actions, advantages, self.cfg,
            fisher_dist_fn=None if stride == 1 else lambda: self.policy(obs[::stride]),
        )  # fmt: skip
        return {k: float(v) for k, v in stats.to_dict().items()}

    def state(self) -> dict[str, Tensor]:
        return {}

    def load_state(self, tensors: dict[str, Tensor]) -> None:
        pass


class PPOUpdate:
    """:func:`~hrlp.algos.ppo.ppo_update` with one Adam optimiser over the policy's parameters for the whole run and a
    seeded minibatch shuffle; both are saved with the run."""

    name = "ppo"

    def __init__(self, policy: nn.Module, cfg: PPOConfig, seed: int) -> None:
        self.policy, self.cfg = policy, cfg
        self.params = list(policy.parameters())
        self.optimizer = torch.optim.Adam(self.params, lr=cfg.lr, eps=1e-5)
        self.generator = torch.Generator().manual_seed(seed + 7919)  # apart from the action noise's stream

    def _dist(self, obs: Tensor, index: Tensor | None) -> Distribution:
        return self.policy(obs if index is None else obs[index])

    def __call__(self, obs: Tensor, actions: Tensor, advantages: Tensor) -> dict[str, float]:
        with torch.no_grad():
            old_dist = self.policy(obs)
        stats = ppo_update(self.params, lambda i: self._dist(obs, i), old_dist, actions, advantages, self.optimizer,
                           self.cfg, self.generator)  # fmt: skip
        return {**{k: float(v) for k, v in stats.to_dict().items()}, "accepted": 1.0}

    def state(self) -> dict[str, Tensor]:
        return {"ppo.generator": self.generator.get_state(), **adam_tensors("ppo.adam", self.optimizer)}

    def load_state(self, tensors: dict[str, Tensor]) -> None:
        if "ppo.generator" not in tensors:
            raise ValueError("the checkpoint holds no PPO state (was it trained with --algo trpo?)")
        self.generator.set_state(tensors["ppo.generator"])
        load_adam("ppo.adam", self.optimizer, tensors)


def adam_tensors(prefix: str, optimizer: torch.optim.Optimizer) -> dict[str, Tensor]:
    """An optimiser's per-parameter state (Adam's moments and step counts) as tensors ``<prefix>.<i>.<key>``."""
    out = {}
    for i, s in optimizer.state_dict()["state"].items():
        for key, value in s.items():
            out[f"{prefix}.{i}.{key}"] = value.detach().clone().reshape(value.shape or (1,))
    return out


def load_adam(prefix: str, optimizer: torch.optim.Optimizer, tensors: dict[str, Tensor]) -> None:
    """Restore :func:`adam_tensors`'s state into ``optimizer`` (its settings stay its own)."""
    full = optimizer.state_dict()
    state: dict[int, dict[str, Tensor]] = {}
    for name, value in tensors.items():
        if name.startswith(f"{prefix}."):
            i, key = name.removeprefix(f"{prefix}.").split(".", 1)
            state.setdefault(int(i), {})[key] = value.reshape(()) if key == "step" else value
    full["state"] = state
    optimizer.load_state_dict(full)


def make_update(cfg: TrainConfig, policy: nn.Module) -> PolicyUpdate:
    """The update ``cfg.algo`` names, over ``policy``'s parameters."""
    if cfg.algo == "ppo":
        return PPOUpdate(policy, cfg.ppo, cfg.seed)
    if cfg.algo != "trpo":
        raise ValueError(f"{cfg.algo} is not an on-policy update (hrlp.training.offpolicy trains it)")
    return TRPOUpdate(policy, cfg.trpo)
