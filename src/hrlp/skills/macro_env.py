"""The environment the Manager acts in: each action runs a frozen skill for k low-level steps.

Section 1.1 and Figure 1: the Manager selects one of N macro-actions and passes it a vector of
parameters; the macro-action then emits the environment's actions for k steps (8, 10 or 15 in the paper),
until it says it is done, or until the episode ends, and the Manager sees the state after it. The optional
micro-action gives the Manager direct control of the environment's action for ``duration`` steps.

Action space: ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))``: the choice, then one parameter
block per choice (the hierarchical distribution fills every block; only the chosen one is
used). Every block is normalised to ``[-1, 1]``: a skill's block maps affinely onto its
parameter box (:class:`~hrlp.skills.core.ParamBox`, e.g. the arm's Reacher's reachable workspace
in metres) and the micro-action's block onto the action space, shrunk by its bound. A macro-action lasting
tau low-level steps returns the discounted in-macro reward ``sum_j gamma^j r_j`` and
``info['discount'] = gamma^tau``, the factor the Manager's return and advantage estimator apply
to the next decision (semi-Markov discounting).

:class:`ManagerVectorEnv` is the :class:`~hrlp.envs.vector.VectorEnv` of a Manager's ``N`` environments over any
backend's :class:`Worlds` (any Gymnasium environments through :class:`SerialWorlds`, the arm's batched physics): every
low-level step evaluates each skill once for all the worlds running it (batched skill inference). :func:`step_macros`
runs one decision of a few :class:`MacroEnv` the same way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from hrlp.config import MicroAction
from hrlp.envs.faults import EnvError, raised_in, reset_env, step_env
from hrlp.envs.vector import NO_SUCCESS_TEST, VectorStep, check_num_envs, info_arrays, info_success, physics_seconds
from hrlp.skills.core import (
    DirectControl,
    Hierarchy,
    MacroStep,
    ObsLayout,
    ObsView,
    ParamBox,
    Skill,
    decide,
    initiated,
    observation_parts,
)


class MacroEnv(gym.Env):
    """A Manager's view of any environment: choose a skill (or the direct control) and its parameters.

    Args:
        env: the low-level environment: any Gymnasium environment with a Box action space and a Box or Dict-of-Box
            observation (a Dict is flattened for the Manager, :func:`gymnasium.spaces.flatten`; skills read its keys by
            name). An environment may name parts of a flat observation (``observation_parts``, as hrlp's arm tasks) and
            measure parts outside it (``measurable`` and ``measure(name)``).
        skills: the frozen skills the Manager may choose, in order (:class:`hrlp.skills.core.Skill`).
        k: steps per skill call (None: each skill's own default k).
        micro: the micro-action (:class:`~hrlp.skills.core.DirectControl` over the environment's action space), or None.
            With no skills and a micro-action this is the flat baseline through the same code.
        gamma: the low-level discount used inside a macro-action.
        chain: enforce the skills' initiation tests (:func:`~hrlp.skills.core.initiated`).

    A domain drives its skills before they get here (the arm's hand-over: :func:`hrlp.arm.handover.drive`).

    ``on_substep``, if set, is called with the active macro-action's name after every low-level step
    (rendering uses it to record every frame and label it).
    """

    metadata = {"render_modes": ["rgb_array"]}  # noqa: RUF012 (Gymnasium's convention)

    def __init__(self, env: gym.Env, skills: Sequence[Skill], k: int | None = None, micro: MicroAction | None = None,
                 gamma: float = 0.99, chain: bool = False) -> None:  # fmt: skip
        if not skills and micro is None:
            raise ValueError("MacroEnv needs at least one skill or the micro-action")
        if k is not None and (isinstance(k, bool) or not isinstance(k, int) or k < 1):
            raise ValueError(f"k must be a positive integer, got {k!r}")
        if not (0 < gamma <= 1):
            raise ValueError(f"gamma must be in (0, 1], got {gamma!r}")
        if not isinstance(env.action_space, gym.spaces.Box):
            raise ValueError(f"a Manager's skills emit Box actions; this environment's action space is {env.action_space}")
        self.env, self.skills, self.micro, self.gamma = env, list(skills), micro, float(gamma)
        space = env.observation_space
        self._dict = isinstance(space, gym.spaces.Dict)
        layout = ObsLayout.of_space(space, observation_parts(env))
        entries: list[Skill] = list(self.skills)
        if micro:
            entries.append(DirectControl(env.action_space, micro.duration, micro.penalty, micro.max_torque))
        measurable = tuple(getattr(env.unwrapped, "measurable", ()))
        for e in entries:
            e.check(layout, env.action_space, measurable)
        durations = np.array([k or s.k for s in self.skills] + ([micro.duration] if micro else []), dtype=np.int64)
        self.hierarchy = Hierarchy(tuple(entries), durations, layout, self.gamma, int(np.prod(env.action_space.shape)),
                                   chain)  # fmt: skip
        self.durations, self.names = durations, self.hierarchy.names
        self.param_dims, self.offsets = self.hierarchy.param_dims, self.hierarchy.offsets
        blocks = [gym.spaces.Box(-1.0, 1.0, shape=(d,), dtype=np.float64) for d in self.param_dims]
        self.action_space = gym.spaces.Tuple((gym.spaces.Discrete(len(blocks)), *blocks))
        self.observation_space = gym.spaces.flatten_space(space) if self._dict else space
        self.render_mode = env.render_mode
        self.on_substep: Callable[[str], None] | None = None
        self._obs = np.zeros(layout.dim)
        self._ran = -1  # the macro-action the last decision of this episode ran (-1: none yet)

    @property
    def layout(self) -> ObsLayout:
        """The named parts of the (flattened) observation."""
        return self.hierarchy.layout

    @property
    def param_boxes(self) -> list[ParamBox]:
        """What the Manager's block of each macro-action means: each skill's :class:`~hrlp.skills.core.ParamBox`."""
        return [s.params for s in self.hierarchy.skills]

    def observe(self, obs: Any) -> np.ndarray:
        """The environment's observation as the Manager's flat row (a Dict flattened in its space's key order)."""
        if self._dict:
            return gym.spaces.flatten(self.env.observation_space, obs).astype(np.float64)
        return np.asarray(obs, dtype=np.float64).reshape(-1)

    def parameters(self, choice: int, block: np.ndarray, obs: np.ndarray | None = None) -> np.ndarray:
        """The chosen macro-action's parameters in its own units (metres in the world frame, torques) from its block in
        [-1, 1], in state ``obs`` (default: the current one; it matters for parameters relative to a body)."""
        return self.hierarchy.skills[choice].params.to_user(np.asarray(block, dtype=np.float64)) + self._origin(choice, obs)

    def block(self, choice: int, params: np.ndarray, obs: np.ndarray | None = None) -> np.ndarray:
        """Inverse of :meth:`parameters`: the block in [-1, 1] that passes ``params`` to macro-action ``choice``."""
        box = self.hierarchy.skills[choice].params
        return box.to_unit(np.asarray(params, dtype=np.float64) - self._origin(choice, obs))

    def _origin(self, choice: int, obs: np.ndarray | None) -> np.ndarray:
        box = self.hierarchy.skills[choice].params
        if box.frame is None:
            return np.zeros(box.dim)
        state = self._obs if obs is None else np.asarray(obs, dtype=np.float64)
        return state.reshape(-1)[self.layout.span(box.frame)].copy()

    @property
    def ran_last(self) -> int:
        """The macro-action the previous decision of this episode ran (-1 before the episode's first decision)."""
        return self._ran

    def would_run(self, choice: int) -> int:
        """The macro-action that ``choice`` runs from the current state: itself, or under initiation sets the one
        :func:`~hrlp.skills.core.initiated` picks."""
        if not self.hierarchy.chain:
            return int(choice)
        view = ObsView(self._obs[None], self.layout, np.zeros(1, dtype=np.int64), self._measure)
        return int(initiated(self.hierarchy.skills, view, np.array([choice]), np.array([self._ran]))[0])

    def _measure(self, name: str, idx: np.ndarray) -> np.ndarray:
        return np.stack([self.env.unwrapped.measure(name) for _ in idx])  # type: ignore[attr-defined]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Reset the low-level task."""
        super().reset(seed=seed)
        obs, info = reset_env(self.env, 0, seed=seed, options=options)  # SerialWorlds names the environment's index
        self._obs = self.observe(obs)
        self._ran = -1
        return self._obs.copy(), info

    def step(self, action: tuple) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Run the chosen macro-action; returns the discounted in-macro reward and ``info['discount']`` = gamma^tau."""
        n = len(self.param_dims)
        if not isinstance(action, tuple | list) or len(action) != 1 + n:
            raise ValueError(f"Manager action must be a tuple (choice, {n} parameter blocks), got {action!r}")
        choice = int(action[0])
        if not 0 <= choice < n:
            raise ValueError(f"Manager choice must be in [0, {n}), got {choice}")
        row = np.zeros(1 + int(self.offsets[-1]))
        row[0] = choice
        for j, (d, a) in enumerate(zip(self.param_dims, action[1:], strict=True)):
            block = np.asarray(a, dtype=np.float64).reshape(-1)
            if block.shape != (d,):
                raise ValueError(f"parameters of {self.names[j]} must have shape ({d},), got {block.shape}")
            row[1 + self.offsets[j] : 1 + self.offsets[j + 1]] = block
        res = step_macros([self], row[None])
        info = {**res.infos[0], "tau": int(res.tau[0]), "discount": float(res.discount[0]),
                "macro": self.names[int(res.choice[0])], "task_reward": float(res.task_reward[0]),
                "skill_done": bool(res.skill_done[0])}  # fmt: skip
        return res.obs[0].copy(), float(res.rewards[0]), bool(res.terminated[0]), bool(res.truncated[0]), info

    @property
    def physics_seconds(self) -> float:
        """CPU seconds the low-level task has spent inside ``mj_step`` (NaN where it does not count them)."""
        return float(getattr(self.env.unwrapped, "physics_seconds", np.nan))

    @property
    def resumable(self) -> bool:
        """Whether the low-level environment can save its exact state (hrlp's arm tasks can)."""
        return hasattr(self.env.unwrapped, "get_state")

    def get_state(self) -> dict[str, Any]:
        """The low-level task's exact state (JSON-serialisable); see :meth:`ArmEnv.get_state`."""
        return {"env": self.env.unwrapped.get_state(), "obs": self._obs.tolist(), "ran": self._ran}  # type: ignore[attr-defined]

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state` (a state saved before ``ran`` was recorded: none yet)."""
        self.env.unwrapped.set_state(state["env"])  # type: ignore[attr-defined]
        self._obs = np.asarray(state["obs"], dtype=np.float64)
        self._ran = int(state.get("ran", -1))

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """The low-level task's frame."""
        return self.env.render()

    def close(self) -> None:
        """Close the low-level task."""
        self.env.close()


def step_macros(envs: Sequence[MacroEnv], actions: np.ndarray) -> MacroStep:
    """Run one Manager decision in each of ``N`` environments that share their skills, in lockstep, without resetting
    the ones whose episode ends (:meth:`ManagerVectorEnv.decision` over :class:`SerialWorlds`).

    ``actions`` are flat hierarchical actions ``[N, 1 + S]``: the choice, then every parameter block (values
    in [-1, 1]; clipped). At every low-level step each skill is evaluated once, on the ``M`` environments running it,
    and an environment whose macro-action has ended (its duration, its done test, or its episode) waits
    (:func:`~hrlp.skills.core.decide`). ``infos`` are each environment's last low-level info. Raises ValueError for a
    wrong shape, NaN/inf, or a choice that is not one of the macro-actions.
    """
    worlds = SerialWorlds(envs)
    vec = ManagerVectorEnv(worlds, envs[0], on_substep=[e.on_substep for e in envs])
    vec._obs = np.stack([e._obs for e in envs]).astype(np.float64)
    vec._ran = np.array([e._ran for e in envs], dtype=np.int64)
    res, _, _, _ = vec.decision(actions)
    for e, o, c in zip(envs, res.obs, res.choice, strict=True):
        e._obs, e._ran = o.copy(), int(c)
    return dataclasses.replace(res, infos=worlds.last_infos)


class Worlds(Protocol):
    """``N`` worlds a Manager steps one low-level step at a time, the worlds whose macro-action has ended waiting: the
    seam between :class:`ManagerVectorEnv` and a backend (:class:`SerialWorlds` for any Gymnasium environments, the
    arm's batched :class:`~hrlp.arm.batched.BatchedArmEnv`)."""

    @property
    def num_envs(self) -> int:
        """N."""
        ...

    @property
    def measurable(self) -> tuple[str, ...]:
        """Parts measured outside the observation (:meth:`measure`)."""
        ...

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Start every world's episode (world ``i`` seeded with ``seed + i``); ``obs [N, obs_dim]``."""
        ...

    def advance(self, actions: np.ndarray, active: np.ndarray | None = None) -> VectorStep:
        """One low-level step of the worlds where ``active [N]``; the rows of the others are not meaningful, and a world
        whose episode ends waits until :meth:`reset_worlds`."""
        ...

    def reset_worlds(self, worlds: np.ndarray) -> np.ndarray:
        """Start the next episode of the worlds ``worlds``; their observations ``[M, obs_dim]``."""
        ...

    def measure(self, name: str, worlds: np.ndarray) -> np.ndarray:
        """Part ``name`` of the worlds ``worlds`` in their current state, ``[M, width]``."""
        ...

    def get_state(self) -> dict[str, Any]:
        """``{"envs": [one state per world]}``, JSON-serialisable."""
        ...

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state`."""
        ...

    def close(self) -> None:
        """Release the worlds."""
        ...


class SerialWorlds:
    """The low-level environments of ``N`` :class:`MacroEnv` as :class:`Worlds`: each stepped on its own, its
    observation flattened as its Manager sees it (:meth:`MacroEnv.observe`), parts outside the observation from its
    ``measure(name)``. ``last_infos`` holds each environment's last low-level info."""

    def __init__(self, envs: Sequence[MacroEnv]) -> None:
        self.envs = list(envs)
        check_num_envs(len(self.envs), "SerialWorlds")
        self.last_infos: list[dict[str, Any]] = [{} for _ in self.envs]
        self.measurable = tuple(getattr(self.envs[0].env.unwrapped, "measurable", ()))

    @property
    def num_envs(self) -> int:
        """N."""
        return len(self.envs)

    @property
    def resumable(self) -> bool:
        """Whether every environment can save its exact state (hrlp's arm tasks can; most Gymnasium ids not)."""
        return all(e.resumable for e in self.envs)

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Reset every environment (``i`` with ``seed + i``)."""
        return np.stack([self._reset(i, None if seed is None else seed + i) for i in range(self.num_envs)])

    def advance(self, actions: np.ndarray, active: np.ndarray | None = None) -> VectorStep:
        """Step the environments where ``active``, one after another, in index order."""
        n = self.num_envs
        idx = np.arange(n) if active is None else np.flatnonzero(active)
        envs = [self.envs[i] for i in idx]
        physics0 = physics_seconds([e.env for e in envs])
        next_obs = np.zeros((n, self.envs[0].layout.dim))
        rewards = np.zeros(n)
        terminated, truncated, success = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool)
        infos: list[Mapping[str, Any]] = [{} for _ in range(n)]
        for i, e in zip(idx, envs, strict=True):
            o, r, term, trunc, info = step_env(e.env, actions[i], int(i))  # a fault of the user's environment: EnvError
            next_obs[i], rewards[i] = e.observe(o), r
            terminated[i], truncated[i] = term, trunc and not term
            success[i] = bool(info_success(info))
            infos[i] = self.last_infos[i] = info
        arrays = info_arrays(infos)
        silent = np.array([info_success(infos[i]) is None for i in range(n)]) & np.isin(np.arange(n), idx)
        if silent.any():
            arrays[NO_SUCCESS_TEST] = silent
        return VectorStep(obs=next_obs, next_obs=next_obs, rewards=rewards, discount=np.ones(n), tau=np.ones(n, np.int64),
                          terminated=terminated, truncated=truncated, success=success, infos=arrays,
                          physics_seconds=physics_seconds([e.env for e in envs]) - physics0)  # fmt: skip

    def reset_worlds(self, worlds: np.ndarray) -> np.ndarray:
        """Reset the environments ``worlds`` (each continuing its own random stream)."""
        return np.stack([self._reset(int(i)) for i in worlds])

    def _reset(self, i: int, seed: int | None = None) -> np.ndarray:
        """Environment ``i``'s reset; a fault of the user's environment is an EnvError naming ``i``."""
        try:
            return self.envs[i].reset(seed=seed)[0]
        except EnvError as e:
            raise EnvError(dataclasses.replace(e.fault, index=i)) from None
        except Exception as e:
            raise raised_in(self.envs[i].env, i, "reset", e) from e

    def measure(self, name: str, worlds: np.ndarray) -> np.ndarray:
        """Each environment's ``measure(name)``."""
        return np.stack([self.envs[i].env.unwrapped.measure(name) for i in worlds])  # type: ignore[attr-defined]

    def get_state(self) -> dict[str, Any]:
        """Each environment's exact state (its ``get_state()``)."""
        return {"envs": [e.env.unwrapped.get_state() for e in self.envs]}  # type: ignore[attr-defined]

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state`."""
        for e, s in zip(self.envs, state["envs"], strict=True):
            e.env.unwrapped.set_state(s)  # type: ignore[attr-defined]

    def close(self) -> None:
        """Close every environment."""
        for e in self.envs:
            e.close()


class ManagerVectorEnv:
    """A Manager's ``N`` environments as one :class:`~hrlp.envs.vector.VectorEnv` over any :class:`Worlds`: a step is
    one decision in every world (:func:`~hrlp.skills.core.decide`: batched skill inference, the worlds whose
    macro-action has ended waiting), with same-step autoreset (:mod:`hrlp.envs.vector`). One class for every backend:
    :class:`SerialWorlds` of any Gymnasium environments, or the arm's batched physics.

    Args:
        worlds: the ``N`` worlds; this object resets and steps them from now on.
        layout: a :class:`MacroEnv` of the same environment giving the macro-actions (skills, durations, parameter
            blocks, gamma, the observation's parts); its own environment is not stepped (unless it is one of the
            worlds').
        on_substep: per world, called with the running macro-action's name after each of its low-level steps
            (rendering labels its frames so), or None.

    A step maps :class:`~hrlp.skills.core.MacroStep` onto :class:`~hrlp.envs.vector.VectorStep`: ``rewards`` the
    discounted in-macro reward ``sum_j gamma^j r_j``, ``discount = gamma^tau``, ``tau`` the low-level steps taken;
    ``next_obs`` the state after the macro-action (an ended episode's real last observation), ``obs`` the reset one
    where an episode ended. ``infos`` holds each world's last low-level values of its environment's scalar infos,
    ``task_reward`` (the undiscounted sum of the task's rewards, what an episode's return counts), ``choice`` (the
    macro-action run) and ``skill_done`` (it ended by its done test); ``success`` is the environment's own success test
    at its last low-level step. :meth:`get_state` is ``{"envs": [{"env": world state, "obs": [obs_dim], "ran": int}],
    "obs": [N, obs_dim]}``.
    """

    def __init__(self, worlds: Worlds, layout: MacroEnv,
                 on_substep: Sequence[Callable[[str], None] | None] | None = None) -> None:  # fmt: skip
        if not isinstance(layout, MacroEnv):
            raise ValueError(f"ManagerVectorEnv: the layout must be a MacroEnv, got {type(layout).__name__}")
        h = layout.hierarchy
        measured = set(worlds.measurable)
        read = dict.fromkeys(p for s in h.skills for p in s.reads if p not in h.layout.names)
        if missing := [p for p in read if p not in measured]:
            raise ValueError(f"ManagerVectorEnv: the skills read {', '.join(missing)}, which the worlds do not measure; "
                             f"build them with features={tuple(read)!r}")  # fmt: skip
        self.worlds, self.layout, self.hierarchy, self.gamma = worlds, layout, h, layout.gamma
        self._on_substep = list(on_substep) if on_substep is not None else [None] * worlds.num_envs
        self._obs: np.ndarray | None = None
        self._ran = np.full(worlds.num_envs, -1, dtype=np.int64)  # the macro-action each world's last decision ran
        self.record_paths = False
        """Whether a step also returns the observations after each low-level step (:attr:`VectorStep.path`)."""

    @property
    def num_envs(self) -> int:
        """N."""
        return self.worlds.num_envs

    @property
    def names(self) -> list[str]:
        """The macro-actions' names, in the order of the Manager's choices."""
        return self.hierarchy.names

    @property
    def obs_dim(self) -> int:
        """Length of one observation (the environment's, flattened)."""
        return self.hierarchy.layout.dim

    @property
    def act_dim(self) -> int:
        """``1 + S``: the choice, then every parameter block."""
        return self.hierarchy.act_dim

    @property
    def resumable(self) -> bool:
        """Whether the worlds can save their exact state."""
        return bool(getattr(self.worlds, "resumable", True))

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Reset every world (``i`` with ``seed + i``); returns ``obs [N, obs_dim]``."""
        self._obs = np.asarray(self.worlds.reset(seed=seed), dtype=np.float64).reshape(self.num_envs, self.obs_dim)
        self._ran[:] = -1
        return self._obs.copy()

    def decision(self, actions: np.ndarray) -> tuple[MacroStep, dict[str, np.ndarray], np.ndarray, float]:
        """One decision in every world from the current observations, without resets: the :class:`MacroStep`, the
        worlds' last low-level infos as arrays, their success, and the seconds spent in physics."""
        if self._obs is None:
            raise RuntimeError("ManagerVectorEnv: call reset() before step()")
        n, h, worlds = self.num_envs, self.hierarchy, self.worlds
        last: dict[str, np.ndarray] = {}
        success = np.zeros(n, dtype=bool)
        full, mask = np.zeros((n, h.action_dim)), np.zeros(n, dtype=bool)
        seconds = 0.0
        labels = self._labels(actions) if any(f is not None for f in self._on_substep) else None

        def step(running: np.ndarray, lows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
            nonlocal seconds
            full[:], mask[:] = 0.0, False
            full[running], mask[running] = lows, True
            out = worlds.advance(full, mask)
            seconds += out.physics_seconds
            for k, v in out.infos.items():
                if k not in last:
                    last[k] = np.zeros(n, dtype=bool) if v.dtype == bool else np.full(n, np.nan)
                last[k][running] = v[running]
            success[running] = out.success[running]
            if labels is not None:
                for i in running:
                    if (f := self._on_substep[i]) is not None:
                        f(labels[i])
            return out.next_obs[running], out.rewards[running], out.terminated[running], out.truncated[running]

        res = decide(h, self._obs, actions, step, worlds.measure, self._ran, self.record_paths)
        return res, last, success, seconds

    def _labels(self, actions: np.ndarray) -> list[str]:
        """The name of the macro-action each world's decision runs (its choice, or under initiation sets the one
        :func:`~hrlp.skills.core.initiated` picks), for ``on_substep``."""
        assert self._obs is not None
        choice = np.asarray(actions, dtype=np.float64)[:, 0].astype(np.int64)
        if self.hierarchy.chain:
            view = ObsView(self._obs, self.hierarchy.layout, np.arange(self.num_envs), self.worlds.measure)
            choice = initiated(self.hierarchy.skills, view, choice, self._ran)
        return [self.names[int(c)] for c in choice]

    def step(self, actions: np.ndarray) -> VectorStep:
        """One decision in every world from flat hierarchical actions ``[N, 1 + S]`` (checked by
        :func:`~hrlp.skills.core.decide`); restarts the worlds whose episode ended."""
        res, last, success, seconds = self.decision(actions)
        next_obs = res.obs
        obs = next_obs.copy()
        self._ran[:] = res.choice
        ended = np.flatnonzero(res.terminated | res.truncated)
        if ended.size:
            obs[ended] = self.worlds.reset_worlds(ended)
            self._ran[ended] = -1
        self._obs = obs
        infos = {**last, "task_reward": res.task_reward, "choice": res.choice, "skill_done": res.skill_done}
        return VectorStep(obs=obs.copy(), next_obs=next_obs, rewards=res.rewards, discount=res.discount, tau=res.tau,
                          terminated=res.terminated, truncated=res.truncated, success=success, infos=infos,
                          physics_seconds=seconds, path=res.path)  # fmt: skip

    def get_state(self) -> dict[str, Any]:
        """``{"envs": [{"env": world state, "obs": ..., "ran": ...}], "obs": [N, obs_dim]}``."""
        if self._obs is None:
            raise RuntimeError("ManagerVectorEnv: call reset() before get_state()")
        worlds = self.worlds.get_state()["envs"]
        return {"envs": [{"env": w, "obs": o, "ran": int(r)} for w, o, r in zip(worlds, self._obs.tolist(), self._ran,
                                                                              strict=True)],
                "obs": self._obs.tolist()}  # fmt: skip

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state` (a state saved before ``ran`` was recorded: none yet)."""
        if len(state["envs"]) != self.num_envs:
            raise ValueError(f"ManagerVectorEnv: the saved state has {len(state['envs'])} environments, this one "
                             f"{self.num_envs}")  # fmt: skip
        self.worlds.set_state({"envs": [s["env"] for s in state["envs"]]})
        self._obs = np.asarray(state["obs"], dtype=np.float64).reshape(self.num_envs, self.obs_dim)
        self._ran = np.array([int(s.get("ran", -1)) for s in state["envs"]], dtype=np.int64)

    def close(self) -> None:
        """Close the worlds and the layout's environment."""
        self.worlds.close()
        self.layout.close()


def manager_vector_env(envs: Sequence[MacroEnv]) -> ManagerVectorEnv:
    """``N`` :class:`MacroEnv` of one Manager stepped together (:class:`SerialWorlds`); a one-line ValueError for
    environments whose macro-actions, durations or gamma differ."""
    check_num_envs(len(envs), "manager_vector_env")
    first = envs[0]
    for i, e in enumerate(envs):
        if not isinstance(e, MacroEnv):
            raise ValueError(f"manager_vector_env: environment {i} is a {type(e).__name__}, not a MacroEnv")
        same = (e.names == first.names and np.array_equal(e.durations, first.durations)
                and e.param_dims == first.param_dims and e.gamma == first.gamma)  # fmt: skip
        if not same:
            raise ValueError(f"manager_vector_env: environment {i} has other macro-actions, durations or gamma than "
                             "environment 0; the environments of one Manager must share them")  # fmt: skip
    return ManagerVectorEnv(SerialWorlds(envs), first, on_substep=[e.on_substep for e in envs])
