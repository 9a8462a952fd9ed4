"""The vector-environment seam: one typed step record and one protocol that every batch of environments implements.

A :class:`VectorEnv` steps ``N`` environments together: ``reset(seed) -> obs [N, obs_dim]`` and
``step(actions [N, act_dim]) -> VectorStep``. The sampler (:class:`hrlp.rollout.Sampler`) sees only this protocol,
whether the ``N`` environments are ordinary Gymnasium environments stepped one by one (:class:`SerialVectorEnv`, the
reference implementation here), hrlp's batched MuJoCo backend (:class:`hrlp.arm.batched.BatchedArmEnv`), a
Manager's macro-action environments (:class:`hrlp.skills.macro_env.ManagerVectorEnv`) or, later, a GPU backend.

Actions are flat float rows: a Box action as it is, a Discrete one as one number, a parameterised
``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))`` one as ``[k, u_1, ..., u_n]`` (the policy's encoding);
:func:`action_decoder` turns them into the environment's own actions.

Autoreset convention (Gymnasium's "same-step" mode): when a step ends an episode (terminated or truncated), the
environment is reset within that step. :attr:`VectorStep.next_obs` holds the observation the step produced (an
ended episode's real last observation, the one to bootstrap from after a truncation) and :attr:`VectorStep.obs` the
observation the next action acts on (the new episode's first where one ended, else the same as ``next_obs``). Every
other field (reward, success, ``infos``) belongs to the step taken, so to the ended episode where one ended. There is
no step whose action is ignored (Gymnasium's default "next-step" mode has one per episode), so every step is a
transition of the MDP and a batch of ``T`` steps holds ``T * N`` transitions.

Seeds: ``reset(seed)`` seeds environment ``i`` with ``seed + i`` (the sampler's convention); later episodes continue
each environment's own random stream.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np

from hrlp.envs.check import parameterised_dims
from hrlp.envs.faults import reset_env, step_env

NO_SUCCESS_TEST = "no_success_test"
"""Key of :attr:`VectorStep.infos`, ``[N]`` bool, present only on a step where some environment reports no success
test (no ``info['success']``, as Gymnasium's own tasks): True for those environments, whose ``success`` is then False."""


@dataclass(frozen=True)
class VectorStep:
    """One step of ``N`` environments (see the module docstring for the autoreset convention).

    For a flat step ``tau = 1`` and ``discount = gamma``; a macro-action of ``tau`` low-level steps has
    ``discount = gamma ** tau`` (the discount to apply to the value of ``next_obs``).
    """

    obs: np.ndarray  # [N, obs_dim] float64: what the next action acts on (a new episode's first where one ended)
    next_obs: np.ndarray  # [N, obs_dim] float64: what this step produced (an ended episode's real last observation)
    rewards: np.ndarray  # [N] float64
    discount: np.ndarray  # [N] float64: gamma ** tau
    tau: np.ndarray  # [N] int64: low-level steps taken (1 for a flat step)
    terminated: np.ndarray  # [N] bool: the MDP ended (no bootstrap)
    truncated: np.ndarray  # [N] bool: cut by a time limit or a physics fault (bootstrap from next_obs); never with terminated
    success: np.ndarray  # [N] bool: whether the episode has succeeded at any step up to and including this one
    infos: Mapping[str, np.ndarray]  # each [N]: reward terms ``reward_<term>``, ``physics_unstable``, tracked sums/maxima
    physics_seconds: float  # seconds inside MuJoCo's step during this step, all N environments together (NaN: unknown)
    path: np.ndarray | None = None  # [N, T, obs_dim]: a Manager's observations after each low-level step (MacroStep.path)

    @property
    def done(self) -> np.ndarray:
        """[N] bool: the episode ended at this step (terminated or truncated); ``obs`` then starts a new one."""
        return self.terminated | self.truncated


class VectorConstructor:
    """Base of an environment constructor that can also build ``n`` of its environments as one :class:`VectorEnv`
    (:meth:`vector`); a sampler given ``n`` copies of one such constructor steps them that way
    (:func:`hrlp.rollout.build_vector_env`)."""

    def vector(self, n: int, gamma: float) -> VectorEnv:
        """``n`` environments (the ``i``-th as the ``i``-th built one by one), discounting a low-level step by ``gamma``."""
        raise NotImplementedError


@runtime_checkable
class VectorEnv(Protocol):
    """``N`` environments stepped together, auto-resetting in the same step (see the module docstring)."""

    @property
    def num_envs(self) -> int:
        """N."""
        ...

    @property
    def obs_dim(self) -> int:
        """Length of one observation."""
        ...

    @property
    def act_dim(self) -> int:
        """Length of one action."""
        ...

    @property
    def resumable(self) -> bool:
        """Whether :meth:`get_state` and :meth:`set_state` continue exactly (False where an environment cannot save its
        state, as most Gymnasium ids)."""
        ...

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Start a new episode in every environment (environment ``i`` seeded with ``seed + i``); returns
        ``obs [N, obs_dim]``."""
        ...

    def step(self, actions: np.ndarray) -> VectorStep:
        """Apply ``actions [N, act_dim]``, one row per environment; ends and restarts episodes as they finish."""
        ...

    def get_state(self) -> dict[str, Any]:
        """Everything needed to continue exactly (JSON-serialisable)."""
        ...

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state`."""
        ...

    def close(self) -> None:
        """Release resources (threads, renderers)."""
        ...


def check_actions(actions: np.ndarray, n: int, act_dim: int, who: str) -> np.ndarray:
    """``actions`` as a float64 array ``[n, act_dim]``; a one-line ValueError naming ``who`` for a wrong shape or a
    NaN or inf (with the first environment that has one)."""
    a = np.asarray(actions, dtype=np.float64)
    if a.shape != (n, act_dim):
        raise ValueError(f"{who}: actions must have shape ({n}, {act_dim}) (one row per environment), got {a.shape}")
    finite = np.isfinite(a)
    if not finite.all():
        bad = int(np.flatnonzero(~finite.all(axis=1))[0])
        raise ValueError(f"{who}: actions contain NaN or inf (environment {bad}: {a[bad].tolist()})")
    return a


def check_num_envs(n: object, who: str) -> int:
    """``n`` as an int if it is a positive integer; else a one-line ValueError naming ``who``."""
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"{who}: the number of environments n must be a positive integer, got {n!r}")
    return int(n)


def check_gamma(gamma: object, who: str) -> float:
    """``gamma`` as a float if it is a number in [0, 1] (0: a bandit's, every step its own episode for the returns);
    else a one-line ValueError naming ``who``."""
    if isinstance(gamma, bool) or not isinstance(gamma, int | float) or not 0 <= gamma <= 1:
        raise ValueError(f"{who}: gamma must be a number in [0, 1], got {gamma!r}")
    return float(gamma)


def info_success(info: Mapping[str, Any]) -> bool | None:
    """An environment's own success test from one step's ``info``: hrlp's ``success``, or Gymnasium-Robotics'
    ``is_success`` (a float 0 or 1); None where it reports neither."""
    if "success" in info:
        return bool(info["success"])
    if "is_success" in info:
        return bool(info["is_success"])
    return None


def info_arrays(infos: Sequence[Mapping[str, Any]], skip: frozenset[str] = frozenset({"success"})) -> dict[str, np.ndarray]:
    """Per-environment info dicts as arrays ``[N]``, one per key that any of them reports as a scalar.

    A key whose values are all bools gives a bool array (False where missing); any other scalar key a float64
    array (NaN where missing). Non-scalar values (e.g. ``physics_warnings``, a dict) and the keys in ``skip`` are
    left out. ``physics_unstable`` is always present (False where missing)."""
    n = len(infos)
    keys: dict[str, bool] = {"physics_unstable": True}  # key -> all values bool so far
    for info in infos:
        for k, v in info.items():
            if k in skip or not isinstance(v, bool | int | float | np.bool_ | np.number):
                continue
            keys[k] = keys.get(k, True) and isinstance(v, bool | np.bool_)
    out: dict[str, np.ndarray] = {}
    for k, is_bool in keys.items():
        arr = np.zeros(n, dtype=bool) if is_bool else np.full(n, np.nan)
        for i, info in enumerate(infos):
            if k in info:
                arr[i] = info[k]
        out[k] = arr
    return out


def flat_action_dim(space: gym.Space) -> int:
    """Length of one flat action row for ``space``: a Box's size, 1 for Discrete, ``1 + d_1 + ... + d_n`` for a
    parameterised ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))``; ValueError for any other space."""
    if isinstance(space, gym.spaces.Box):
        return int(np.prod(space.shape))
    if isinstance(space, gym.spaces.Discrete):
        return 1
    return 1 + sum(parameterised_dims(space))


def action_decoder(space: gym.Space) -> Callable[[np.ndarray], Sequence]:
    """How the policy's batched actions ``[N, ...]`` become ``N`` environment actions for ``space``.

    Box: clipped to the bounds. Discrete: integers. ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))`` (a parameterised
    action space): ``(k, u_1, ..., u_n)`` tuples with each block clipped to its bounds. Other spaces raise ValueError.
    """
    if isinstance(space, gym.spaces.Box):
        low, high, shape = space.low, space.high, space.shape
        return lambda a: np.clip(a.reshape(a.shape[0], *shape), low, high)
    if isinstance(space, gym.spaces.Discrete):
        start = int(space.start)
        return lambda a: (a.reshape(-1).astype(np.int64) + start).tolist()
    dims = parameterised_dims(space)
    blocks = space.spaces[1:]
    bounds = list(itertools.pairwise(np.cumsum([1, *dims])))

    def decode(a: np.ndarray) -> list[tuple]:
        # The hierarchical encoding of hrlp.policies.distributions.flat_to_tuple: the choice rounded, float32 blocks.
        return [(round(float(row[0])), *(np.clip(row[lo:hi].astype(np.float32), b.low, b.high)
                                          for (lo, hi), b in zip(bounds, blocks, strict=True)))
                for row in np.asarray(a).reshape(len(a), -1)]  # fmt: skip

    return decode


def physics_seconds(envs: Sequence[gym.Env]) -> float:
    """CPU seconds ``envs`` have spent inside ``mj_step`` so far, summed (their ``physics_seconds`` counters); NaN if
    any of them does not count it (Gymnasium's own environments do not)."""
    return sum(float(getattr(env.unwrapped, "physics_seconds", math.nan)) for env in envs)


class SerialVectorEnv:
    """The reference :class:`VectorEnv`: ``N`` ordinary Gymnasium environments stepped one after another.

    Args:
        envs: the environments (hrlp's :class:`~hrlp.arm.env.ArmEnv` or any Gymnasium environment with a Box
            observation space and a Box, Discrete or parameterised ``Tuple`` action space); they are reset and
            stepped by this object from now on.
        gamma: the discount per step (``discount = gamma``, ``tau = 1``).

    Each step decodes the flat action rows with :func:`action_decoder` (in the dtype they come in), calls
    ``env.step`` on every environment and ``env.reset()`` (no seed: the environment's own stream continues) on those
    whose episode ended. Observations are flattened to float64 rows. ``success`` is ``info['success']`` (False where
    absent; :data:`NO_SUCCESS_TEST` then marks it), ``infos`` holds the scalar info values as arrays
    (:func:`info_arrays`), ``physics_seconds`` the growth of the environments' own ``physics_seconds`` counters over
    the step and its resets (ArmEnv: CPU seconds inside ``mj_step``; NaN if an environment has none). An environment
    that raises, returns another number of values (the old Gym API) or an observation of another size than its space
    is an :class:`~hrlp.envs.faults.EnvError` naming its index (:func:`~hrlp.envs.faults.step_env`).
    """

    def __init__(self, envs: Sequence[gym.Env], gamma: float = 0.99) -> None:
        self.envs = list(envs)
        check_num_envs(len(self.envs), "SerialVectorEnv")
        self.gamma = check_gamma(gamma, "SerialVectorEnv")
        first = self.envs[0]
        self._obs_dim = int(np.prod(first.observation_space.shape))
        self._act_dim = flat_action_dim(first.action_space)
        self._decode = action_decoder(first.action_space)
        self._obs: np.ndarray | None = None

    @property
    def num_envs(self) -> int:
        """N."""
        return len(self.envs)

    @property
    def obs_dim(self) -> int:
        """Length of one observation."""
        return self._obs_dim

    @property
    def act_dim(self) -> int:
        """Length of one flat action row (:func:`flat_action_dim`)."""
        return self._act_dim

    @property
    def resumable(self) -> bool:
        """Whether every environment can save and restore its exact state (hrlp tasks can; most Gymnasium ids not)."""
        return all(hasattr(env.unwrapped, "get_state") for env in self.envs)

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Reset every environment (``i`` with ``seed + i``); returns ``obs [N, obs_dim]``."""
        obs = [reset_env(env, i, self._obs_dim, seed=None if seed is None else seed + i)[0] for i, env in enumerate(self.envs)]
        self._obs = np.stack(obs)
        return self._obs.copy()

    def step(self, actions: np.ndarray) -> VectorStep:
        """Step every environment with its row of ``actions [N, act_dim]``; reset those whose episode ended."""
        if self._obs is None:
            raise RuntimeError("SerialVectorEnv: call reset() before step()")
        n = self.num_envs
        check_actions(actions, n, self._act_dim, "SerialVectorEnv")
        decoded = self._decode(np.asarray(actions))
        next_obs = np.empty((n, self._obs_dim))
        rewards = np.empty(n)
        terminated, truncated, success = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool)
        infos: list[Mapping[str, Any]] = []
        physics0 = physics_seconds(self.envs)
        for i, env in enumerate(self.envs):  # a fault of an environment (it raises, or its result does not fit): EnvError
            next_obs[i], rewards[i], term, trunc, info = step_env(env, decoded[i], i, self._obs_dim)
            terminated[i], truncated[i] = term, trunc and not term
            success[i] = bool(info_success(info))
            infos.append(info)
        obs = next_obs.copy()
        for i in np.flatnonzero(terminated | truncated):
            obs[i] = reset_env(self.envs[i], int(i), self._obs_dim)[0]
        physics = physics_seconds(self.envs) - physics0
        self._obs = obs
        arrays = info_arrays(infos)
        reported = np.array([info_success(info) is not None for info in infos])
        if not reported.all():
            arrays[NO_SUCCESS_TEST] = ~reported
        return VectorStep(
            obs=obs.copy(),
            next_obs=next_obs,
            rewards=rewards,
            discount=np.full(n, self.gamma),
            tau=np.ones(n, dtype=np.int64),
            terminated=terminated,
            truncated=truncated,
            success=success,
            infos=arrays,
            physics_seconds=physics,
        )

    def get_state(self) -> dict[str, Any]:
        """Each environment's ``get_state()`` (they must have one, as ArmEnv does) and the current observations."""
        if self._obs is None:
            raise RuntimeError("SerialVectorEnv: call reset() before get_state()")
        return {"envs": [env.unwrapped.get_state() for env in self.envs], "obs": self._obs.tolist()}

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state` (also a :class:`~hrlp.arm.batched.BatchedArmEnv`'s, whose format is the same)."""
        if len(state["envs"]) != self.num_envs:
            raise ValueError(
                f"SerialVectorEnv: the saved state has {len(state['envs'])} environments, this one {self.num_envs}"
            )
        for env, s in zip(self.envs, state["envs"], strict=True):
            env.unwrapped.set_state(s)
        self._obs = np.asarray(state["obs"], dtype=np.float64).reshape(self.num_envs, self._obs_dim)

    def close(self) -> None:
        """Close every environment."""
        for env in self.envs:
            env.close()


__all__ = [
    "NO_SUCCESS_TEST",
    "SerialVectorEnv",
    "VectorEnv",
    "VectorStep",
    "action_decoder",
    "check_actions",
    "check_gamma",
    "check_num_envs",
    "flat_action_dim",
    "info_arrays",
    "info_success",
    "physics_seconds",
]
