"""Any parameterised action space, in the one form hrlp's hierarchical policy acts in.

A parameterised action is a discrete choice ``k`` among ``n`` and continuous parameters for that choice. Environments
write it in one of three forms, all accepted:

* ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))`` (the flat form), actions ``(k, x_1, ..., x_n)``;
* ``Tuple(Discrete(n), Tuple(Box(d_1), ..., Box(d_n)))`` (the nested form of Platform, Goal and Soccer), actions
  ``(k, (x_1, ..., x_n))``;
* ``OneOf((Box(d_1), ..., Box(d_n)))`` (Gymnasium 1.x), actions ``(k, x_k)``.

:class:`NormalisedParameters` turns each into the canonical ``Tuple(Discrete(n), Box(-1, 1, (d_1,)), ...,
Box(-1, 1, (d_n,)))`` that :class:`~hrlp.policies.mlp.HierarchicalPolicy` (and its hierarchical KL) acts in, and maps
the policy's actions back to the environment's form and units: a parameter whose bounds are both finite is acted in
``[-1, 1]`` and mapped affinely onto ``[low, high]`` (-1 -> low, 0 -> the midpoint, 1 -> high); one with an infinite
bound is passed through in the environment's own units. The wrapper holds no state (observations, rewards and the
environment's saved state are the environment's own), so returns stay native and runs resume exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import gymnasium as gym
import numpy as np

__all__ = ["ACCEPTED_ACTION_SPACES", "NormalisedParameters", "is_parameterised", "make_normalised", "parameter_blocks"]

#: The action spaces hrlp trains on, as the error message for any other one lists them.
ACCEPTED_ACTION_SPACES = (
    "Box, Discrete, Tuple(Discrete(n), Box(d_1), ..., Box(d_n)), Tuple(Discrete(n), Tuple(Box(d_1), ..., Box(d_n))) "
    "or OneOf((Box(d_1), ..., Box(d_n)))"
)

Kind = Literal["flat", "nested", "oneof"]


def is_parameterised(space: gym.Space) -> bool:
    """Whether ``space`` has the shape of a parameterised action space (a Tuple starting with a Discrete, or a
    OneOf); :func:`parameter_blocks` then says whether it is a valid one."""
    one_of = getattr(gym.spaces, "OneOf", None)
    if one_of is not None and isinstance(space, one_of):
        return True
    return isinstance(space, gym.spaces.Tuple) and len(space.spaces) >= 1 and isinstance(space.spaces[0], gym.spaces.Discrete)


def parameter_blocks(space: gym.Space) -> tuple[Kind, tuple[gym.spaces.Box, ...]]:
    """The form (``"flat"``, ``"nested"`` or ``"oneof"``) and the parameter blocks ``(Box(d_1), ..., Box(d_n))`` of a
    parameterised action space. Raises ValueError, one line without the environment's name, naming the problem: not a
    parameterised space, a Discrete that does not start at 0, a block count other than n, a block that is not a 1-d
    Box, NaN bounds or a low bound above its high one."""
    kind: Kind
    if not is_parameterised(space):
        raise ValueError(f"unsupported action space {space}: use {ACCEPTED_ACTION_SPACES}")
    if isinstance(space, gym.spaces.Tuple):
        choice, rest = space.spaces[0], space.spaces[1:]
        assert isinstance(choice, gym.spaces.Discrete)
        if int(choice.start) != 0:
            raise ValueError(f"action space {space}: its Discrete choice must start at 0, not {int(choice.start)}")
        if len(rest) == 1 and isinstance(rest[0], gym.spaces.Tuple):
            kind, blocks = "nested", tuple(rest[0].spaces)
        else:
            kind, blocks = "flat", tuple(rest)
        if len(blocks) != int(choice.n):
            raise ValueError(f"action space {space}: Discrete({int(choice.n)}) needs {int(choice.n)} parameter blocks "
                             f"(one per choice), got {len(blocks)}")  # fmt: skip
    else:
        kind, blocks = "oneof", tuple(space.spaces)  # type: ignore[attr-defined]
    for k, b in enumerate(blocks):
        if not isinstance(b, gym.spaces.Box) or len(b.shape) != 1:
            raise ValueError(f"action space {space}: parameter block {k} must be a 1-d Box, got {b}")
        if np.isnan(b.low).any() or np.isnan(b.high).any():
            raise ValueError(f"action space {space}: parameter block {k} has NaN bounds")
        if (b.low > b.high).any():
            raise ValueError(f"action space {space}: parameter block {k} has a low bound above its high bound")
    return kind, blocks


class _Block:
    """One parameter block's map between the policy's units and the environment's."""

    def __init__(self, box: gym.spaces.Box) -> None:
        self.box = box
        self.low, self.high = box.low.astype(np.float64), box.high.astype(np.float64)
        self.finite = np.isfinite(self.low) & np.isfinite(self.high)
        self.low_f, self.high_f = np.where(self.finite, self.low, 0.0), np.where(self.finite, self.high, 0.0)
        self.integer = np.issubdtype(box.dtype, np.integer)

    def canonical(self) -> gym.spaces.Box:
        """The block as the policy acts in it: [-1, 1] where both bounds are finite, the native bounds elsewhere."""
        low = np.where(self.finite, -1.0, self.low).astype(np.float32)
        high = np.where(self.finite, 1.0, self.high).astype(np.float32)
        return gym.spaces.Box(low, high, self.low.shape, np.float32)

    def to_native(self, a: Any) -> np.ndarray:
        """Policy units -> the environment's (clipped into its bounds, in its dtype)."""
        a = np.asarray(a, dtype=np.float64).reshape(self.low.shape)
        x = np.where(self.finite, self.low_f * (1.0 - a) / 2.0 + self.high_f * (1.0 + a) / 2.0, a)
        x = np.clip(x, self.low, self.high)
        return (np.round(x) if self.integer else x).astype(self.box.dtype)

    def to_policy(self, x: Any) -> np.ndarray:
        """The environment's units -> the policy's (the inverse of :meth:`to_native` inside the bounds)."""
        x = np.asarray(x, dtype=np.float64).reshape(self.low.shape)
        width = self.high_f - self.low_f
        safe = np.where(width > 0, width, 1.0)
        a = np.where(width > 0, (2.0 * x - self.low_f - self.high_f) / safe, 0.0)
        return np.where(self.finite, a, x).astype(np.float32)


class NormalisedParameters(gym.ActionWrapper):
    """Presents a parameterised-action environment (flat Tuple, nested Tuple or OneOf, see :mod:`hrlp.envs.actions`)
    with the canonical ``Tuple(Discrete(n), Box(-1, 1, (d_1,)), ..., Box(-1, 1, (d_n,)))`` action space.

    An action ``(k, u_1, ..., u_n)`` of that space becomes the environment's ``(k, x_1, ..., x_n)``,
    ``(k, (x_1, ..., x_n))`` or ``(k, x_k)``, each ``x_j = low_j (1 - u_j) / 2 + high_j (1 + u_j) / 2`` clipped into
    ``[low_j, high_j]`` per parameter with both bounds finite, ``x_j = u_j`` clipped otherwise. Stateless.

    Example::

        env = NormalisedParameters(gym.make("MyPlatform-v0"))  # Tuple(Discrete(3), Tuple(Box(0, 30, (1,)), ...))
        env.step((1, np.zeros(1), np.ones(1), -np.ones(1)))  # choice 1 at the midpoint of its bounds
    """

    def __init__(self, env: gym.Env, name: str | None = None) -> None:
        """Wrap ``env``; ValueError, one line naming ``name`` (default: the env's id) for an unsupported space."""
        super().__init__(env)
        if name is None:
            name = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
        try:
            self.kind, boxes = parameter_blocks(env.action_space)
        except ValueError as e:
            raise ValueError(f"{name}: {e}") from None
        self.native_space = env.action_space
        self._blocks = tuple(_Block(b) for b in boxes)
        self.n = len(self._blocks)
        self.action_space = gym.spaces.Tuple((gym.spaces.Discrete(self.n), *(b.canonical() for b in self._blocks)))

    def action(self, action: Sequence) -> Any:
        """The policy's ``(k, u_1, ..., u_n)`` -> the environment's action, in its form and units."""
        if len(action) != 1 + self.n:
            raise ValueError(f"expected an action (k, u_1, ..., u_{self.n}) of {1 + self.n} entries, got {len(action)}")
        k = int(action[0])
        if not 0 <= k < self.n:
            raise ValueError(f"the action's choice must be in [0, {self.n}), got {k}")
        if self.kind == "oneof":
            return np.int64(k), self._blocks[k].to_native(action[1 + k])
        xs = tuple(b.to_native(u) for b, u in zip(self._blocks, action[1:], strict=True))
        return (k, xs) if self.kind == "nested" else (k, *xs)

    def reverse_action(self, action: Any) -> tuple:
        """The environment's action -> the policy's ``(k, u_1, ..., u_n)`` (for a OneOf, the blocks not chosen are 0)."""
        k = int(action[0])
        if self.kind == "oneof":
            us = [np.zeros(b.low.shape, np.float32) for b in self._blocks]
            us[k] = self._blocks[k].to_policy(action[1])
        else:
            xs = action[1] if self.kind == "nested" else action[1:]
            us = [b.to_policy(x) for b, x in zip(self._blocks, xs, strict=True)]
        return (k, *us)


def make_normalised(env_id: str, /, **kwargs: Any) -> NormalisedParameters:
    """``gymnasium.make(env_id, **kwargs)`` wrapped in :class:`NormalisedParameters` (a picklable constructor, with
    :func:`functools.partial`, for sampler worker processes)."""
    return NormalisedParameters(gym.make(env_id, **kwargs), env_id)
