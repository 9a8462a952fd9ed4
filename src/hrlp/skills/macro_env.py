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

:func:`step_macros` runs one decision in each of ``N`` environments together, so every
low-level step evaluates each skill once for all the environments running it (batched skill
inference); :class:`MacroVectorEnv` is the :class:`~hrlp.envs.vector.VectorEnv` built on it, the
one the sampler steps a Manager's environments through.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from hrlp.config import MicroAction
from hrlp.envs.vector import VectorStep, check_num_envs, info_arrays, info_success, physics_seconds
from hrlp.skills.core import DirectControl, Hierarchy, MacroStep, ObsLayout, ObsView, ParamBox, Skill, decide, initiated


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
        layout = ObsLayout.of_space(space, getattr(env.unwrapped, "observation_parts", None))
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
        obs, info = self.env.reset(seed=seed, options=options)
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
    """Run one Manager decision in each of ``N`` environments that share their skills, in lockstep.

    ``actions`` are flat hierarchical actions ``[N, 1 + S]``: the choice, then every parameter block (values
    in [-1, 1]; clipped). At every low-level step each skill is evaluated once, on the ``M`` environments running it,
    and an environment whose macro-action has ended (its duration, its done test, or its episode) waits
    (:func:`~hrlp.skills.core.decide`). Raises ValueError for a wrong shape, NaN/inf, or a choice that is not one of
    the macro-actions.
    """
    infos: list[dict[str, Any]] = [{} for _ in envs]
    runs: list[int] | None = None  # the macro-actions run, for on_substep's labels

    def step(running: np.ndarray, torques: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        nonlocal runs
        rows = []
        for i, t in zip(running, torques, strict=True):
            env = envs[i]
            o, r, term, trunc, info = env.env.step(t)
            rows.append((env.observe(o), r, term, trunc))
            infos[i] = info
            if env.on_substep is not None:
                if runs is None:  # decide() has checked the actions; the envs are still at the decision's start
                    runs = [e.would_run(int(a[0])) for e, a in zip(envs, np.asarray(actions), strict=True)]
                env.on_substep(env.names[runs[i]])
        obs, r, term, trunc = zip(*rows, strict=True)
        return np.stack(obs), np.array(r, dtype=np.float64), np.array(term, dtype=bool), np.array(trunc, dtype=bool)

    def measure(name: str, idx: np.ndarray) -> np.ndarray:
        return np.stack([envs[i].env.unwrapped.measure(name) for i in idx])  # type: ignore[attr-defined]

    ran = np.array([e._ran for e in envs], dtype=np.int64)
    res = decide(envs[0].hierarchy, np.stack([e._obs for e in envs]), actions, step, measure, ran)
    for e, o, c in zip(envs, res.obs, res.choice, strict=True):
        e._obs, e._ran = o.copy(), int(c)
    return dataclasses.replace(res, infos=infos)


class MacroVectorEnv:
    """``N`` Manager environments as one :class:`~hrlp.envs.vector.VectorEnv`: a step is one decision in each, run by
    :func:`step_macros` (batched skill inference), with same-step autoreset (:mod:`hrlp.envs.vector`).

    Args:
        envs: :class:`MacroEnv`s over the same skills, durations, micro-action and gamma (the Manager's environments
            of one run); they are reset and stepped by this object from now on.

    A step maps :class:`MacroStep` onto :class:`~hrlp.envs.vector.VectorStep`: ``rewards`` the discounted in-macro
    reward ``sum_j gamma^j r_j``, ``discount = gamma^tau``, ``tau`` the low-level steps taken; ``next_obs`` the state
    after the macro-action (an ended episode's real last observation), ``obs`` the reset one where an episode ended.
    ``infos`` holds the scalar values of each environment's last low-level info (:func:`~hrlp.envs.vector.info_arrays`),
    ``task_reward`` (the undiscounted sum of the task's rewards, what an episode's return counts) and ``choice`` (the
    macro-action run); ``success`` is the last low-level ``info['success']``. :meth:`get_state` is
    ``{"envs": [MacroEnv.get_state() per environment], "obs": [N, obs_dim]}``.
    """

    def __init__(self, envs: Sequence[MacroEnv]) -> None:
        self.envs = list(envs)
        check_num_envs(len(self.envs), "MacroVectorEnv")
        first = self.envs[0]
        for i, e in enumerate(self.envs):
            if not isinstance(e, MacroEnv):
                raise ValueError(f"MacroVectorEnv: environment {i} is a {type(e).__name__}, not a MacroEnv")
            same = (e.names == first.names and np.array_equal(e.durations, first.durations)
                    and e.param_dims == first.param_dims and e.gamma == first.gamma)  # fmt: skip
            if not same:
                raise ValueError(f"MacroVectorEnv: environment {i} has other macro-actions, durations or gamma than "
                                 "environment 0; the environments of one Manager must share them")  # fmt: skip
        self.gamma = first.gamma
        self._obs_dim = int(np.prod(first.observation_space.shape))
        self._act_dim = 1 + int(first.offsets[-1])
        self._obs: np.ndarray | None = None

    @property
    def num_envs(self) -> int:
        """N."""
        return len(self.envs)

    @property
    def names(self) -> list[str]:
        """The macro-actions' names, in the order of the Manager's choices."""
        return self.envs[0].names

    @property
    def obs_dim(self) -> int:
        """Length of one observation (the low-level task's)."""
        return self._obs_dim

    @property
    def act_dim(self) -> int:
        """``1 + S``: the choice, then every parameter block."""
        return self._act_dim

    @property
    def resumable(self) -> bool:
        """Whether every MacroEnv can save its low-level environment's exact state (hrlp's arm tasks can)."""
        return all(e.resumable for e in self.envs)

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Reset every environment (``i`` with ``seed + i``); returns ``obs [N, obs_dim]``."""
        obs = [env.reset(seed=None if seed is None else seed + i)[0] for i, env in enumerate(self.envs)]
        self._obs = np.stack(obs).astype(np.float64).reshape(self.num_envs, self._obs_dim)
        return self._obs.copy()

    def step(self, actions: np.ndarray) -> VectorStep:
        """One decision in every environment from flat hierarchical actions ``[N, 1 + S]`` (checked by
        :func:`step_macros`); resets those whose episode ended."""
        if self._obs is None:
            raise RuntimeError("MacroVectorEnv: call reset() before step()")
        physics0 = physics_seconds(self.envs)
        res = step_macros(self.envs, actions)
        next_obs = np.asarray(res.obs, dtype=np.float64).reshape(self.num_envs, self._obs_dim)
        obs = next_obs.copy()
        for i in np.flatnonzero(res.terminated | res.truncated):
            obs[i] = np.ravel(self.envs[i].reset()[0])
        physics = physics_seconds(self.envs) - physics0
        self._obs = obs
        infos = info_arrays(res.infos)
        infos["task_reward"] = res.task_reward
        infos["choice"] = res.choice
        infos["skill_done"] = res.skill_done
        return VectorStep(
            obs=obs.copy(),
            next_obs=next_obs,
            rewards=res.rewards,
            discount=res.discount,
            tau=res.tau,
            terminated=res.terminated,
            truncated=res.truncated,
            success=np.array([bool(info_success(info)) for info in res.infos]),
            infos=infos,
            physics_seconds=physics,
        )

    def get_state(self) -> dict[str, Any]:
        """Each environment's :meth:`MacroEnv.get_state` and the current observations (JSON-serialisable)."""
        if self._obs is None:
            raise RuntimeError("MacroVectorEnv: call reset() before get_state()")
        return {"envs": [env.get_state() for env in self.envs], "obs": self._obs.tolist()}

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state`."""
        if len(state["envs"]) != self.num_envs:
            raise ValueError(f"MacroVectorEnv: the saved state has {len(state['envs'])} environments, this one "
                             f"{self.num_envs}")  # fmt: skip
        for env, s in zip(self.envs, state["envs"], strict=True):
            env.set_state(s)
        self._obs = np.asarray(state["obs"], dtype=np.float64).reshape(self.num_envs, self._obs_dim)

    def close(self) -> None:
        """Close every environment."""
        for env in self.envs:
            env.close()
