"""Soft actor-critic for any action space hrlp trains on: one gradient step of :class:`SACUpdate` per call.

For hybrid actions (a choice ``k`` among ``n`` with parameters ``x_k``; a Box is ``n = 1``, a Discrete ``d_k = 0``),
with ``pi(k, x | s) = p_k(s) pi_k(x_k | s)`` (:class:`~hrlp.policies.distributions.HybridSquashed`), the losses of hybrid
SAC (Delalleau et al. 2019, Section 3; MAPLE, Nasiriany et al. 2022, Section IV-B), the sum over choices taken exactly and
the parameters reparameterised (Haarnoja et al. 2018, eqs. 5, 7 and 17, with a temperature per part):

* critic target: ``y = r + gamma^tau (1 - d) V(s')``,
  ``V(s') = sum_k p'_k [min_i Q'_i(s', k, x'_k) - alpha_p log pi'_k(x'_k) - alpha_c log p'_k]``, with
  ``x' ~ pi(. | s')`` and ``Q'`` the target critics (for a Manager, ``r`` is the discounted reward inside the
  macro-action and ``gamma^tau`` its discount: the semi-Markov form);
* critics: ``sum_i (Q_i(s, k, x) - y)^2 / 2``, averaged;
* actor: ``sum_k p_k [alpha_c log p_k + alpha_p log pi_k(x_k) - min_i Q_i(s, k, x_k)]``, averaged;
* temperatures: ``log alpha_c (H(p) - H_c)`` and ``log alpha_p (-sum_k p_k log pi_k(x_k) - H_p)``, averaged, with targets
  ``H_c = choice_entropy * log n`` and ``H_p = -sum_k p_k d_k`` (SAC's ``-dim(A)`` per block).
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass

import torch
from torch import Tensor

from hrlp.algos.update import adam_tensors, load_adam
from hrlp.config import SACConfig
from hrlp.policies.sac import SACActor, TwinQ

__all__ = ["SACBatch", "SACStats", "SACUpdate"]


@dataclass(frozen=True)
class SACBatch:
    """A minibatch of transitions: normalised observations, hybrid action rows in ``(-1, 1)``, and ``[B]`` vectors."""

    obs: Tensor
    actions: Tensor
    rewards: Tensor
    discount: Tensor
    """``gamma ** tau``."""
    terminated: Tensor
    """1 where the episode ended in a terminal state (no bootstrap)."""
    next_obs: Tensor


@dataclass(frozen=True)
class SACStats:
    """One gradient step's numbers."""

    critic_loss: float
    actor_loss: float
    q: float
    """Mean ``Q_1(s, a)`` of the minibatch's actions."""
    alpha_choice: float
    """Temperature of the choice's entropy (1 and unused with one choice)."""
    alpha_params: float
    """Temperature of the parameters' entropy (unused without parameters)."""
    choice_entropy: float
    """Mean entropy of the choice, ``H(p)``."""
    params_log_prob: float
    """Mean ``sum_k p_k log pi_k(x_k)``."""

    def to_dict(self) -> dict[str, float]:
        """The numbers by name."""
        return asdict(self)


class SACUpdate:
    """The critics, their targets, three Adam optimisers and the two temperatures of one SAC run; :meth:`step` makes one
    gradient step. Its state (:meth:`state`) goes into the run's checkpoint so that a resumed run continues exactly."""

    name = "sac"

    def __init__(self, actor: SACActor, critic: TwinQ, cfg: SACConfig, seed: int) -> None:
        self.actor, self.critic, self.cfg = actor, critic, cfg
        self.target = copy.deepcopy(critic).requires_grad_(False)
        self.actor_optimizer = torch.optim.Adam(actor.parameters(), lr=cfg.lr)
        self.critic_optimizer = torch.optim.Adam(critic.parameters(), lr=cfg.lr)
        self.log_alpha = torch.full((2,), math.log(cfg.init_alpha), requires_grad=True)  # [choice, parameters]
        self.alpha_optimizer = torch.optim.Adam([self.log_alpha], lr=cfg.lr)
        dims = torch.tensor(actor.param_dims, dtype=torch.float32)
        self.param_target = -dims  # per block
        self.choice_target = cfg.choice_entropy * math.log(actor.n) if actor.n > 1 else 0.0
        self.tuned = torch.tensor([actor.n > 1, actor.s > 0])
        self.generator = torch.Generator().manual_seed(seed + 104_729)  # the reparameterisation noise

    def step(self, batch: SACBatch) -> SACStats:
        """One gradient step of the critics, the actor and the temperatures on ``batch``, then the targets' Polyak step."""
        alpha = self.log_alpha.detach().exp()
        a_choice, a_params = alpha[0], alpha[1]
        with torch.no_grad():
            nd = self.actor.hybrid(batch.next_obs)
            x2, lp2 = nd.rsample_blocks(self.generator)
            q1t, q2t = self.target.every_choice(batch.next_obs, x2)
            p2, logp2 = nd.categorical.probs, nd.categorical.log_p
            v = (p2 * (torch.minimum(q1t, q2t) - a_params * lp2 - a_choice * logp2)).sum(-1)
            y = batch.rewards + batch.discount * (1 - batch.terminated) * v
        q1, q2 = self.critic(batch.obs, batch.actions)
        critic_loss = 0.5 * ((q1 - y).square() + (q2 - y).square()).mean()
        self.critic_optimizer.zero_grad(set_to_none=True)
        critic_loss.backward()
        self.critic_optimizer.step()

        self.critic.requires_grad_(False)  # the actor's loss moves the actor only
        d = self.actor.hybrid(batch.obs)
        x, lp = d.rsample_blocks(self.generator)
        qa1, qa2 = self.critic.every_choice(batch.obs, x)
        self.critic.requires_grad_(True)
        p, logp = d.categorical.probs, d.categorical.log_p
        actor_loss = (p * (a_choice * logp + a_params * lp - torch.minimum(qa1, qa2))).sum(-1).mean()
        self.actor_optimizer.zero_grad(set_to_none=True)
        actor_loss.backward()
        self.actor_optimizer.step()

        with torch.no_grad():
            p = p.detach()
            entropy = -(p * logp.detach()).sum(-1)
            params_lp = (p * lp.detach()).sum(-1)
            gaps = torch.stack([(entropy - self.choice_target).mean(), (-params_lp - (p * self.param_target).sum(-1)).mean()])
        alpha_loss = (self.log_alpha * torch.where(self.tuned, gaps, 0.0)).sum()
        self.alpha_optimizer.zero_grad(set_to_none=True)
        alpha_loss.backward()
        self.alpha_optimizer.step()

        with torch.no_grad():
            for t, c in zip(self.target.parameters(), self.critic.parameters(), strict=True):
                t.lerp_(c, self.cfg.tau)
        return SACStats(critic_loss.item(), actor_loss.item(), q1.detach().mean().item(), a_choice.item(), a_params.item(),
                        entropy.mean().item(), params_lp.mean().item())  # fmt: skip

    # --- persistence --------------------------------------------------------------------------
    def state(self) -> dict[str, Tensor]:
        """The critics, targets, optimisers, temperatures and noise generator as tensors (``sac.*``)."""
        out = {f"sac.critic.{k}": v for k, v in self.critic.state_dict().items()}
        out.update({f"sac.target.{k}": v for k, v in self.target.state_dict().items()})
        out["sac.log_alpha"] = self.log_alpha.detach().clone()
        out["sac.generator"] = self.generator.get_state()
        for name, optimizer in self._optimizers().items():
            out.update(adam_tensors(f"sac.{name}", optimizer))
        return out

    def load_state(self, tensors: dict[str, Tensor]) -> None:
        """Restore :meth:`state`."""
        if "sac.log_alpha" not in tensors:
            raise ValueError("the checkpoint holds no SAC state")
        for prefix, module in (("sac.critic.", self.critic), ("sac.target.", self.target)):
            module.load_state_dict({k.removeprefix(prefix): v for k, v in tensors.items() if k.startswith(prefix)})
        with torch.no_grad():
            self.log_alpha.copy_(tensors["sac.log_alpha"])
        self.generator.set_state(tensors["sac.generator"])
        for name, optimizer in self._optimizers().items():
            load_adam(f"sac.{name}", optimizer, tensors)

    def _optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"actor_adam": self.actor_optimizer, "critic_adam": self.critic_optimizer, "alpha_adam": self.alpha_optimizer}
