"""The environment the Manager acts in: each action runs a frozen skill for k low-level steps.

Section 1.1 and Figure 1: the Manager selects one of N macro-actions and passes it a vector of
parameters; the macro-action then emits joint torques for k steps (8, 10 or 15 in the paper),
or until the episode ends, and the Manager sees the state after it. The optional micro-action
gives the Manager direct torque control for ``duration`` steps.

Action space: ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))``: the choice, then one parameter
block per choice (the hierarchical distribution fills every block; only the chosen one is
used). Every block is normalised to ``[-1, 1]``: a skill's block maps affinely onto its
parameter box (:class:`~hrlp.skills.skill.ParamSpec`, e.g. the Reacher's reachable workspace
in metres) and the micro-action's block is scaled by its torque bound. A macro-action lasting
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
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from hrlp.envs.arm_env import ArmEnv
from hrlp.envs.batched import BatchedArmEnv
from hrlp.envs.physics import BASE_OBS_DIM, N_JOINTS
from hrlp.envs.vector import VectorStep, check_num_envs, info_arrays, physics_seconds
from hrlp.skills.skill import (
    HANDOVER_POINT,
    HANDOVER_PREGRASP,
    HANDOVER_TARGET,
    MOVE_TASKS,
    POINT_TASKS,
    ParamSpec,
    Skill,
)

_HAND_XY = slice(18, 20)  # the hand H's x, y in the base observation


@dataclass(frozen=True)
class MicroAction:
    """The micro-action: direct torques for ``duration`` steps, optionally penalised."""

    duration: int = 1
    """Low-level steps the torques are held for."""
    penalty: float = 0.0
    """Subtracted from the Manager's reward each time the micro-action is chosen (Appendix C)."""
    max_torque: float = 1.0
    """Bound on the micro-action's torques (Appendix C: bounds on micro-actions), in (0, 1]."""

    def __post_init__(self) -> None:
        if isinstance(self.duration, bool) or not isinstance(self.duration, int) or self.duration < 1:
            raise ValueError(f"MicroAction.duration must be a positive integer, got {self.duration!r}")
        if not (self.penalty >= 0):
            raise ValueError(f"MicroAction.penalty must be >= 0, got {self.penalty!r}")
        if not (0 < self.max_torque <= 1):
            raise ValueError(f"MicroAction.max_torque must be in (0, 1], got {self.max_torque!r}")


@dataclass(frozen=True)
class Handover:
    """How a point skill (a Reacher) is driven so that the next skill can take over from where it stops.

    The paper's interface (``MacroSpec.handover = None``) passes the Reacher an absolute point anywhere in the
    workspace and runs it as trained. A Reacher trained on -d(H, goal) alone leaves the claw closed or skewed and
    pushes through the capsule; these three changes make the state it leaves one the Gripper grips from
    (docs/skills.md, "Skills that hand over").
    """

    relative: bool = True
    """The Manager's goal is an offset from the capsule's centre in :data:`~hrlp.skills.skill.HANDOVER_POINT`'s box
    (5 cm aside, 0-20 cm above), taken at the macro-action's start, instead of a point of the whole workspace."""
    approach_height: float = 0.11
    """Metres the goal is raised until the hand is above it (within ``approach_radius`` horizontally), so the hand
    comes down onto the capsule from above instead of pushing through it from the side; 0 goes straight."""
    approach_radius: float = 0.02
    """Horizontal distance from the goal, metres, at which the hand counts as above it (then the goal drops)."""
    open_torque: float = 0.2
    """While a point skill runs, its two finger torques are replaced by this torque opening the claw (rc_close < 0,
    lc_close > 0; ARM_CLAW facts): a weak push that keeps the claw open without sweeping the capsule; 0 leaves the
    skill's own finger torques."""
    target_relative: bool = False
    """A moving skill's (a Mover's) target is an offset from the task's own target T in
    :data:`~hrlp.skills.skill.HANDOVER_TARGET`'s box (10 cm each way), instead of a point of the whole workspace: the
    Manager's first targets fall near T. Only on tasks that observe a target (reach-and-move)."""
    initiation: bool = False
    """Each skill starts only from its initiation set (:attr:`Skill.initiation`: the states like those it was trained
    from, e.g. a Mover trained from held starts while the capsule is lifted): a choice outside its skill's set runs the
    nearest skill before it in the Manager's order whose set holds (list skills in the order they chain: a Mover chosen
    before the capsule is held runs the Gripper, or the Reacher while the hand is far), else the first skill whose set
    holds, each with its own parameter block; the choice run is the one reported (``info['macro']``, the decision
    shares). The skill that ran last counts as available wherever it has taken the arm (a Gripper's swing may leave its
    starts' 9 cm), so a Mover chosen while the Gripper is still at work lets it go on; a choice runs as made where no
    skill is available, and the micro-action always does."""

    pregrasp: bool = False
    """A point skill's goal is an offset in :data:`~hrlp.skills.skill.HANDOVER_PREGRASP`'s box (3 cm aside, 0-8 cm above
    the capsule's centre) instead of HANDOVER_POINT's (5 cm, 0-20 cm): the Manager's first goals, the box's centre 4 cm
    above C, leave the palm where a Gripper starts. Only with ``relative``."""

    def __post_init__(self) -> None:
        if self.pregrasp is True and self.relative is False:
            raise ValueError("Handover.pregrasp is a box of capsule-relative goals: it needs relative=True")
        for name in ("relative", "target_relative", "initiation", "pregrasp"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"Handover.{name} must be true or false, got {getattr(self, name)!r}")
        for name in ("open_torque", "approach_height", "approach_radius"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (0 <= v <= 1):
                raise ValueError(f"Handover.{name} must be a number in [0, 1], got {v!r}")
        if self.approach_height > 0 and self.approach_radius <= 0:
            raise ValueError("Handover.approach_radius must be positive when approach_height is")


@dataclass(frozen=True)
class MacroStep:
    """One Manager decision in each of ``N`` environments."""

    obs: np.ndarray  # [N, obs_dim] the observation after the macro-action
    rewards: np.ndarray  # [N] discounted in-macro reward sum_j gamma^j r_j (minus the micro penalty)
    terminated: np.ndarray  # [N] bool
    truncated: np.ndarray  # [N] bool
    discount: np.ndarray  # [N] gamma^tau
    tau: np.ndarray  # [N] int, low-level steps taken
    task_reward: np.ndarray  # [N] undiscounted sum of the task's rewards (what a flat policy's return counts)
    choice: np.ndarray  # [N] int, the macro-action run
    infos: list[dict[str, Any]]  # the last low-level info of each environment


class MacroEnv(gym.Env):
    """A Manager's view of an arm task: choose a skill (or the micro-action) and its parameters.

    Args:
        env: the low-level task (an :class:`ArmEnv`).
        skills: the frozen skills the Manager may choose, in order.
        k: steps per skill call (None: each skill's own default k).
        micro: the micro-action, or None for none. With no skills and a micro-action this is the flat
            baseline through the same code.
        gamma: the low-level discount used inside a macro-action.

    ``on_substep``, if set, is called with the active macro-action's name after every low-level step
    (rendering uses it to record every frame and label it).
    """

    metadata = {"render_modes": ["rgb_array"]}  # noqa: RUF012 (Gymnasium's convention)

    def __init__(self, env: ArmEnv, skills: Sequence[Skill], k: int | None = None, micro: MicroAction | None = None,
                 gamma: float = 0.99, handover: Handover | None = None) -> None:  # fmt: skip
        if not skills and micro is None:
            raise ValueError("MacroEnv needs at least one skill or the micro-action")
        if k is not None and (isinstance(k, bool) or not isinstance(k, int) or k < 1):
            raise ValueError(f"k must be a positive integer, got {k!r}")
        if not (0 < gamma <= 1):
            raise ValueError(f"gamma must be in (0, 1], got {gamma!r}")
        self.env, self.skills, self.micro, self.gamma = env, list(skills), micro, float(gamma)
        self.handover = handover
        self.durations = np.array([k or s.k for s in self.skills] + ([micro.duration] if micro else []), dtype=np.int64)
        self.names = [s.name for s in self.skills] + (["micro"] if micro else [])
        self.points = [s.task in POINT_TASKS for s in self.skills]
        #: How each skill is driven: the hand-over settings for point skills, None for skills run as trained.
        self.drives = [handover if pt else None for pt in self.points]
        #: What the Manager's block of each skill means (:meth:`_spec`).
        self.param_specs = [self._spec(s, pt) for s, pt in zip(self.skills, self.points, strict=True)]
        task = getattr(env.unwrapped, "task", None)
        if any(p.frame == "target" for p in self.param_specs) and not getattr(task, "observes_target", False):
            raise ValueError(f"Handover.target_relative needs a task that observes a target (reach-and-move, the Movers); "
                             f"{type(task).__name__} does not")  # fmt: skip
        low = [np.asarray(p.low, dtype=np.float64) for p in self.param_specs]
        high = [np.asarray(p.high, dtype=np.float64) for p in self.param_specs]
        if micro:
            low.append(np.full(N_JOINTS, -micro.max_torque))
            high.append(np.full(N_JOINTS, micro.max_torque))
        self.param_dims = tuple(len(lo) for lo in low)
        self.offsets = np.concatenate([[0], np.cumsum(self.param_dims)]).astype(np.int64)
        lo_all = np.concatenate(low) if low else np.zeros(0)
        hi_all = np.concatenate(high) if high else np.zeros(0)
        self._centre, self._half = (hi_all + lo_all) / 2, (hi_all - lo_all) / 2
        blocks = [gym.spaces.Box(-1.0, 1.0, shape=(d,), dtype=np.float64) for d in self.param_dims]
        self.action_space = gym.spaces.Tuple((gym.spaces.Discrete(len(blocks)), *blocks))
        self.observation_space = env.observation_space
        self.render_mode = env.render_mode
        self.on_substep: Callable[[str], None] | None = None
        self._obs = np.zeros(env.observation_space.shape)
        self._ran = -1  # the macro-action the last decision of this episode ran (-1: none yet)

    def _spec(self, skill: Skill, point: bool) -> ParamSpec:
        """What the Manager's block of ``skill`` means: its own specification, or with hand-over the capsule-relative
        box for point skills (``relative``) and the target-relative box for moving skills (``target_relative``)."""
        h = self.handover
        if h and h.relative and point:
            return HANDOVER_PREGRASP if h.pregrasp else HANDOVER_POINT
        if h and h.target_relative and skill.task in MOVE_TASKS:
            return HANDOVER_TARGET
        return skill.param

    def parameters(self, choice: int, block: np.ndarray, obs: np.ndarray | None = None) -> np.ndarray:
        """The chosen macro-action's parameters in its own units (metres in the world frame, torques) from its block in
        [-1, 1], in state ``obs`` (default: the current one; it matters for parameters relative to a body)."""
        lo, hi = self.offsets[choice], self.offsets[choice + 1]
        local = self._centre[lo:hi] + self._half[lo:hi] * np.clip(block, -1.0, 1.0)
        return local + self._origin(choice, obs)

    def block(self, choice: int, params: np.ndarray, obs: np.ndarray | None = None) -> np.ndarray:
        """Inverse of :meth:`parameters`: the block in [-1, 1] that passes ``params`` to macro-action ``choice``."""
        lo, hi = self.offsets[choice], self.offsets[choice + 1]
        half = np.where(self._half[lo:hi] > 0, self._half[lo:hi], 1.0)
        return (np.asarray(params, dtype=np.float64) - self._origin(choice, obs) - self._centre[lo:hi]) / half

    def _origin(self, choice: int, obs: np.ndarray | None) -> np.ndarray:
        if choice >= len(self.skills):
            return np.zeros(int(self.param_dims[choice]))
        state = self._obs if obs is None else np.asarray(obs, dtype=np.float64)
        return self.param_specs[choice].origin(state.reshape(1, -1))[0]

    @property
    def ran_last(self) -> int:
        """The macro-action the previous decision of this episode ran (-1 before the episode's first decision)."""
        return self._ran

    def would_run(self, choice: int) -> int:
        """The macro-action that ``choice`` runs from the current state: itself, or under initiation sets
        (:attr:`Handover.initiation`) the one :func:`initiated` picks."""
        if self.handover is None or not self.handover.initiation:
            return int(choice)
        return int(initiated(self.skills, self._obs[None], np.array([choice]), np.array([self._ran]))[0])

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Reset the low-level task."""
        super().reset(seed=seed)
        self._obs, info = self.env.reset(seed=seed, options=options)
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
                "macro": self.names[int(res.choice[0])], "task_reward": float(res.task_reward[0])}  # fmt: skip
        return res.obs[0].copy(), float(res.rewards[0]), bool(res.terminated[0]), bool(res.truncated[0]), info

    @property
    def physics_seconds(self) -> float:
        """CPU seconds the low-level task has spent inside ``mj_step``."""
        return self.env.unwrapped.physics_seconds  # type: ignore[attr-defined]

    def get_state(self) -> dict[str, Any]:
        """The low-level task's exact state (JSON-serialisable); see :meth:`ArmEnv.get_state`."""
        return {"env": self.env.get_state(), "obs": self._obs.tolist(), "ran": self._ran}

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state` (a state saved before ``ran`` was recorded: none yet)."""
        self.env.set_state(state["env"])
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
    in [-1, 1]; clipped). At every low-level step each skill is evaluated once, on ``[M, 24]`` for the ``M``
    environments running it, and an environment whose macro-action has ended (its duration, or its episode)
    waits. Raises ValueError for a wrong shape, NaN/inf, or a choice that is not one of the macro-actions.
    """
    infos: list[dict[str, Any]] = [{} for _ in envs]
    runs: list[int] | None = None  # the macro-actions run, for on_substep's labels

    def step(running: np.ndarray, torques: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        nonlocal runs
        rows = []
        for i, t in zip(running, torques, strict=True):
            env = envs[i]
            rows.append(env.env.step(t))
            infos[i] = rows[-1][4]
            if env.on_substep is not None:
                if runs is None:  # decide() has checked the actions; the envs are still at the decision's start
                    runs = [e.would_run(int(a[0])) for e, a in zip(envs, np.asarray(actions), strict=True)]
                env.on_substep(env.names[runs[i]])
        obs, r, term, trunc, _ = zip(*rows, strict=True)
        return np.stack(obs), np.array(r, dtype=np.float64), np.array(term, dtype=bool), np.array(trunc, dtype=bool)

    def features(name: str, idx: np.ndarray) -> np.ndarray:
        return np.stack([envs[i].env.unwrapped.physics.feature(name) for i in idx])  # type: ignore[attr-defined]

    ran = np.array([e._ran for e in envs], dtype=np.int64)
    _, res = decide(envs[0], np.stack([e._obs for e in envs]), actions, step, features, ran)
    for e, o, c in zip(envs, res.obs, res.choice, strict=True):
        e._obs, e._ran = o.copy(), int(c)
    return dataclasses.replace(res, infos=infos)


def decide(layout: MacroEnv, obs: np.ndarray, actions: np.ndarray,
           step: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
           features: Callable[[str, np.ndarray], np.ndarray] | None = None,
           ran: np.ndarray | None = None) -> tuple[np.ndarray, MacroStep]:  # fmt: skip
    """One Manager decision in ``N`` worlds from ``obs [N, obs_dim]``: the macro-action logic of :func:`step_macros`,
    over any low-level stepper. ``layout`` gives the macro-actions (skills, durations, parameter blocks, hand-over,
    gamma); ``step(running, torques)`` applies ``torques [M, 9]`` to the worlds ``running`` (indices) for one control
    step and returns their ``(obs [M, obs_dim], rewards [M], terminated [M], truncated [M])``; ``features(name, idx)``
    gives the named observation feature of the worlds ``idx`` in their current state, ``[M, width]``, for the skills that
    read features (:attr:`Skill.features`); ``ran [N]`` the macro-action each world's previous decision of its episode
    ran (-1: none), for initiation sets (:attr:`Handover.initiation`). Returns the choices run and the
    :class:`MacroStep` (``infos`` empty: the stepper keeps them)."""
    first = layout
    n, width = len(obs), 1 + int(first.offsets[-1])
    a = np.asarray(actions, dtype=np.float64)
    if a.shape != (n, width):
        raise ValueError(f"Manager actions must have shape ({n}, {width}) (choice + parameter blocks), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("Manager actions contain NaN or inf")
    choice = a[:, 0].astype(np.int64)
    if (choice != a[:, 0]).any() or (choice < 0).any() or (choice >= len(first.names)).any():
        raise ValueError(f"Manager choices must be integers in [0, {len(first.names)}), got {a[:, 0].tolist()}")
    params = first._centre + first._half * np.clip(a[:, 1:], -1.0, 1.0)
    obs = np.array(obs, dtype=np.float64)
    if first.handover is not None and first.handover.initiation:
        choice = initiated(first.skills, obs, choice, ran)
    durations = first.durations[choice]
    for s, spec in enumerate(first.param_specs):  # parameters relative to a body: add its position at the start
        if spec.frame != "world":
            params[:, first.offsets[s] : first.offsets[s + 1]] += spec.origin(obs)
    lifted = np.ones(n, dtype=bool)  # the goal is still raised (until the hand is above it)
    rewards, task_reward = np.zeros(n), np.zeros(n)
    discount, tau = np.ones(n), np.zeros(n, dtype=np.int64)
    terminated, truncated = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    torques = np.zeros((n, N_JOINTS))
    active = np.ones(n, dtype=bool)
    offsets, n_skills = first.offsets, len(first.skills)
    for j in range(int(durations.max())):
        active &= durations > j
        running = np.flatnonzero(active)
        if running.size == 0:
            break
        chosen = choice[running]
        for s in np.unique(chosen):
            idx = running[chosen == s]
            block = params[idx, offsets[s] : offsets[s + 1]]
            if s == n_skills:
                torques[idx] = block
                continue
            h = first.drives[s]
            if h is not None and h.approach_height > 0:
                off = np.linalg.norm(obs[idx, _HAND_XY] - block[:, :2], axis=1)
                lifted[idx] &= off >= h.approach_radius
                block = block + np.outer(lifted[idx], (0.0, 0.0, h.approach_height))
            skill = first.skills[s]
            seen = None
            if skill.features:
                if features is None:
                    raise ValueError(f"skill {skill.name} reads observation features; this stepper gives none")
                seen = np.concatenate([features(f, idx) for f in skill.features], axis=1)
            torques[idx] = skill.act(obs[idx, :BASE_OBS_DIM], block, seen)
            if h is not None and h.open_torque > 0:
                torques[idx, N_JOINTS - 2 :] = (-h.open_torque, h.open_torque)
        obs[running], r, term, trunc = step(running, torques[running])
        rewards[running] += discount[running] * r
        task_reward[running] += r
        discount[running] *= first.gamma
        tau[running] += 1
        ended = term | trunc
        terminated[running], truncated[running] = term, trunc & ~term
        active[running[ended]] = False
    if first.micro is not None and first.micro.penalty:
        rewards[choice == n_skills] -= first.micro.penalty
    return choice, MacroStep(obs, rewards, terminated, truncated, discount, tau, task_reward, choice, [])


def initiated(skills: Sequence[Skill], obs: np.ndarray, choice: np.ndarray, ran: np.ndarray | None = None) -> np.ndarray:
    """The macro-action each of ``N`` states runs under initiation sets (:attr:`Handover.initiation`).

    A skill is available where its set holds in ``obs [N, >=24]`` or where it is the skill ``ran [N]`` ran last (the
    previous decision's, -1 for none: a running skill goes on wherever it took the arm). ``choice [N]`` runs where its
    skill is available, and the micro-action (index ``len(skills)``) always; else the nearest available skill before it
    in the Manager's order (its prerequisite, for skills listed in the order they chain); else the first available
    skill; else ``choice``. -> ``[N]`` int."""
    if not skills:
        return choice
    n, n_skills = len(choice), len(skills)
    available = np.stack([s.initiation.holds(obs) for s in skills], axis=1)  # [N, n_skills]
    if ran is not None:
        going = (ran >= 0) & (ran < n_skills)
        available[np.flatnonzero(going), ran[going]] = True
    outside = (choice < n_skills) & ~available[np.arange(n), np.minimum(choice, n_skills - 1)]
    before = available & (np.arange(n_skills)[None, :] < choice[:, None])  # the skills that come before the choice
    last_before = n_skills - 1 - np.argmax(before[:, ::-1], axis=1)
    fallback = np.where(before.any(axis=1), last_before, np.argmax(available, axis=1))
    replace = outside & available.any(axis=1)
    out = choice.copy()
    out[replace] = fallback[replace]
    return out


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
        """Always: a MacroEnv saves its low-level task's exact state."""
        return True

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
        return VectorStep(
            obs=obs.copy(),
            next_obs=next_obs,
            rewards=res.rewards,
            discount=res.discount,
            tau=res.tau,
            terminated=res.terminated,
            truncated=res.truncated,
            success=np.array([bool(info.get("success", False)) for info in res.infos]),
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


class BatchedMacroVectorEnv:
    """A Manager's ``N`` environments over one :class:`~hrlp.envs.batched.BatchedArmEnv`: the macro-action logic of
    :func:`step_macros` (:func:`decide`, batched skill inference) with the physics of every world stepped in one call
    per low-level step, the worlds whose macro-action has ended waiting (:meth:`BatchedArmEnv.advance`).

    Args:
        worlds: the ``N`` worlds of the low-level task; this object resets and steps them from now on.
        layout: a :class:`MacroEnv` of the same task giving the macro-actions (skills, durations, parameter blocks,
            hand-over, micro-action, gamma); its own environment is not stepped.

    Its steps are :class:`MacroVectorEnv`'s over ``N`` MacroEnvs of the same task and seeds, to within the batched
    physics' agreement with ArmEnv's (about 1e-7, :mod:`hrlp.envs.batched`); :meth:`get_state` has the same format.
    """

    def __init__(self, worlds: BatchedArmEnv, layout: MacroEnv) -> None:
        if not isinstance(layout, MacroEnv):
            raise ValueError(f"BatchedMacroVectorEnv: the layout must be a MacroEnv, got {type(layout).__name__}")
        if type(worlds.task) is not type(layout.env.task):
            raise ValueError(f"BatchedMacroVectorEnv: the worlds run {type(worlds.task).__name__}, the layout's "
                             f"macro-actions {type(layout.env.task).__name__}")  # fmt: skip
        read = dict.fromkeys(f for s in layout.skills for f in s.features)
        if missing := [f for f in read if f not in worlds.measured_features]:
            raise ValueError(f"BatchedMacroVectorEnv: the skills read {', '.join(missing)}, which the worlds do not measure; "
                             f"build them with features={tuple(read)!r}")  # fmt: skip
        self.worlds, self.layout, self.gamma = worlds, layout, layout.gamma
        self._act_dim = 1 + int(layout.offsets[-1])
        self._obs: np.ndarray | None = None
        self._ran = np.full(worlds.num_envs, -1, dtype=np.int64)  # as MacroEnv._ran, per world

    @property
    def num_envs(self) -> int:
        """N."""
        return self.worlds.num_envs

    @property
    def names(self) -> list[str]:
        """The macro-actions' names, in the order of the Manager's choices."""
        return self.layout.names

    @property
    def obs_dim(self) -> int:
        """Length of one observation (the low-level task's)."""
        return self.worlds.obs_dim

    @property
    def act_dim(self) -> int:
        """``1 + S``: the choice, then every parameter block."""
        return self._act_dim

    @property
    def resumable(self) -> bool:
        """Always: every world's state is saved exactly."""
        return True

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Reset every world (``i`` with ``seed + i``); returns ``obs [N, obs_dim]``."""
        self._obs = self.worlds.reset(seed=seed)
        self._ran[:] = -1
        return self._obs.copy()

    def step(self, actions: np.ndarray) -> VectorStep:
        """One decision in every world from flat hierarchical actions ``[N, 1 + S]`` (checked by :func:`decide`);
        restarts the worlds whose episode ended."""
        if self._obs is None:
            raise RuntimeError("BatchedMacroVectorEnv: call reset() before step()")
        n, worlds = self.num_envs, self.worlds
        last: dict[str, np.ndarray] = {}
        success = np.zeros(n, dtype=bool)
        full, mask = np.zeros((n, N_JOINTS)), np.zeros(n, dtype=bool)
        seconds = 0.0

        def step(running: np.ndarray, torques: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
            nonlocal seconds
            full[:], mask[:] = 0.0, False
            full[running], mask[running] = torques, True
            out = worlds.advance(full, mask)
            seconds += out.physics_seconds
            for k, v in out.infos.items():
                if k not in last:
                    last[k] = np.zeros(n, dtype=bool) if v.dtype == bool else np.full(n, np.nan)
                last[k][running] = v[running]
            success[running] = out.success[running]
            return out.next_obs[running], out.rewards[running], out.terminated[running], out.truncated[running]

        def features(name: str, idx: np.ndarray) -> np.ndarray:
            return worlds.features(name)[idx]

        _, res = decide(self.layout, self._obs, actions, step, features, self._ran)
        next_obs = res.obs
        obs = next_obs.copy()
        self._ran[:] = res.choice
        ended = np.flatnonzero(res.terminated | res.truncated)
        if ended.size:
            obs[ended] = worlds.reset_worlds(ended)
            self._ran[ended] = -1
        self._obs = obs
        infos = {**last, "task_reward": res.task_reward, "choice": res.choice}
        return VectorStep(obs=obs.copy(), next_obs=next_obs, rewards=res.rewards, discount=res.discount, tau=res.tau,
                          terminated=res.terminated, truncated=res.truncated, success=success, infos=infos,
                          physics_seconds=seconds)  # fmt: skip

    def get_state(self) -> dict[str, Any]:
        """:class:`MacroVectorEnv`'s format: ``{"envs": [{"env": world state, "obs": ...}], "obs": [N, obs_dim]}``."""
        if self._obs is None:
            raise RuntimeError("BatchedMacroVectorEnv: call reset() before get_state()")
        worlds = self.worlds.get_state()["envs"]
        return {"envs": [{"env": w, "obs": o, "ran": int(r)} for w, o, r in zip(worlds, self._obs.tolist(), self._ran,
                                                                              strict=True)],
                "obs": self._obs.tolist()}  # fmt: skip

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state` (or a :class:`MacroVectorEnv`'s of the same task)."""
        if len(state["envs"]) != self.num_envs:
            raise ValueError(f"BatchedMacroVectorEnv: the saved state has {len(state['envs'])} environments, this one "
                             f"{self.num_envs}")  # fmt: skip
        self.worlds.set_state({"envs": [s["env"] for s in state["envs"]]})
        self._obs = np.asarray(state["obs"], dtype=np.float64).reshape(self.num_envs, self.obs_dim)
        self._ran = np.array([int(s.get("ran", -1)) for s in state["envs"]], dtype=np.int64)

    def close(self) -> None:
        """Close the worlds and the layout's environment."""
        self.worlds.close()
        self.layout.close()


@dataclass(frozen=True)
class MacroSpec:
    """Which skills a Manager commands, for how long, and its micro-action (a field of the training config)."""

    skills: tuple[str, ...] = ()
    """Skill names, looked up in ``library``, then in ``$HRLP_SKILLS`` / ``~/.hrlp/skills``, then among the skills
    shipped with hrlp (``hrlp skills list``)."""
    k: int | None = None
    """Low-level steps per skill call (None: each skill's default)."""
    micro: MicroAction | None = None
    """The micro-action, or None."""
    library: str | None = None
    """A skill library directory searched first."""
    handover: Handover | None = None
    """How point skills hand over (:class:`Handover`); None runs them as the paper does (absolute goals, as trained)."""

    def __post_init__(self) -> None:
        if not self.skills and self.micro is None:
            raise ValueError("a Manager needs at least one skill or the micro-action (--micro)")
        if len(set(self.skills)) != len(self.skills):
            raise ValueError(f"skills are listed twice: {', '.join(self.skills)}")
        if self.k is not None and (isinstance(self.k, bool) or not isinstance(self.k, int) or self.k < 1):
            raise ValueError(f"k must be a positive integer, got {self.k!r}")

    def load_skills(self) -> list[Skill]:
        """The named skills, frozen (a one-line error names a missing or damaged one)."""
        from hrlp.skills.library import load_skill

        return [load_skill(name, self.library) for name in self.skills]

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable form."""
        from dataclasses import asdict

        return asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> MacroSpec:
        """Inverse of :meth:`to_json`."""
        micro, handover = d.get("micro"), d.get("handover")
        return cls(tuple(d["skills"]), d.get("k"), MicroAction(**micro) if micro else None, d.get("library"),
                   Handover(**handover) if handover else None)  # fmt: skip
