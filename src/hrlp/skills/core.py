"""The generic hierarchy: what a skill is, how it reads any environment's observation, and one Manager decision.

A skill (the paper's macro-action, Section 1.1) is batched and closed-loop: given the observations of ``M`` worlds and a
parameter block ``[M, d]`` in its own units, it returns the environment's low-level actions ``[M, A]``. It declares,
once:

* its parameter box in the user's units (:class:`ParamBox`); the Manager always learns in [-1, 1], mapped onto the box
  here, in one place (:meth:`ParamBox.to_user`), optionally as an offset from a named observed point (``frame``);
* the named observation parts it reads (:attr:`Skill.reads`), looked up in the environment's :class:`ObsLayout` (the
  keys of a Dict observation, or the parts a domain declares for a flat one) or among the parts the domain measures
  outside the observation;
* when it may start (:meth:`Skill.initiable`) and when it ends early (:meth:`Skill.done`); it runs for at most ``k``
  low-level steps, and :meth:`Skill.begin` resets its per-world state on entry.

The Manager's direct control of the environment (the paper's micro-action) is a skill like any other:
:class:`DirectControl`, whose parameters are the environment's own action. :func:`decide` runs one Manager decision in
``N`` worlds over any low-level stepper; the Manager environments (:mod:`hrlp.skills.macro_env`) and every backend use
it. This module knows spaces and arrays only: no domain, no file format.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from hrlp.domains import load_domains

#: The part name of a whole flat (Box) observation whose environment declares no parts.
WHOLE = "observation"


@dataclass(frozen=True)
class ObsLayout:
    """Named parts of a flat observation row: ``name -> (start, stop)``; parts may overlap (a domain may name a span
    and its pieces). ``dim`` is the row's length."""

    parts: tuple[tuple[str, int, int], ...]
    dim: int

    def __post_init__(self) -> None:
        spans: dict[str, slice] = {}
        for name, lo, hi in self.parts:
            if name in spans:
                raise ValueError(f"observation layout names part {name!r} twice")
            if not 0 <= lo <= hi <= self.dim:
                raise ValueError(f"observation part {name!r} spans [{lo}, {hi}), outside a row of {self.dim} numbers")
            spans[name] = slice(lo, hi)
        object.__setattr__(self, "_spans", spans)  # looked up at every skill step

    @classmethod
    def of_space(cls, space: gym.Space, named: Mapping[str, Any] | None = None) -> ObsLayout:
        """The layout of ``space`` flattened as :func:`gymnasium.spaces.flatten` does: a Dict's keys in the space's
        order (each a Box, flattened), or for a Box the parts ``named`` declares (the domain's, e.g. the arm's hand and
        capsule) or one part :data:`WHOLE`. For a Dict, ``named`` adds parts inside its keys: ``name -> (key, start,
        stop)`` (e.g. Fetch's ``grip_pos``, numbers 0 to 3 of its ``observation``). Raises a one-line ValueError for
        other spaces."""
        if isinstance(space, gym.spaces.Dict):
            parts, at, starts = [], 0, {}
            for key, sub in space.spaces.items():
                if not isinstance(sub, gym.spaces.Box):
                    raise ValueError(f"observation part {key!r} is a {type(sub).__name__}; hrlp reads Box parts only")
                width = int(np.prod(sub.shape))
                parts.append((str(key), at, at + width))
                starts[str(key)] = (at, width)
                at += width
            for name, where in (named or {}).items():
                try:
                    key, lo, hi = where
                    start, width = starts[key]
                except (KeyError, TypeError, ValueError):
                    raise ValueError(f"observation part {name!r} must be (key, start, stop) inside one of the keys "
                                     f"{', '.join(starts)}, got {where!r}") from None  # fmt: skip
                if not 0 <= lo <= hi <= width:
                    raise ValueError(f"observation part {name!r} spans [{lo}, {hi}) of {key!r}, which has {width} numbers")
                parts.append((str(name), start + lo, start + hi))
            return cls(tuple(parts), at)
        if not isinstance(space, gym.spaces.Box):
            raise ValueError(f"observation space {space} is neither a Box nor a Dict of Boxes")
        dim = int(np.prod(space.shape))
        if not named:
            return cls(((WHOLE, 0, dim),), dim)
        return cls(tuple((str(k), *_bounds(s, dim)) for k, s in named.items()), dim)

    @classmethod
    def of_env(cls, env: gym.Env) -> ObsLayout:
        """The layout of ``env``'s own observation (:func:`own_observation_space`) with the parts it names
        (:func:`observation_parts`)."""
        return cls.of_space(own_observation_space(env), observation_parts(env))

    @property
    def names(self) -> tuple[str, ...]:
        """The parts' names, in order."""
        return tuple(p[0] for p in self.parts)

    def span(self, name: str) -> slice:
        """The slice of a row holding part ``name``; KeyError if there is none."""
        return self._spans[name]  # type: ignore[attr-defined]

    def width(self, name: str) -> int:
        """How many numbers part ``name`` takes."""
        s = self.span(name)
        return s.stop - s.start


#: Named parts of environments that do not name their own, by environment id (:func:`register_observation_parts`).
_DECLARED: dict[str, Mapping[str, Any]] = {}


def register_observation_parts(env_id: str, parts: Mapping[str, Any]) -> None:
    """Name parts of the observation of the environments registered as ``env_id`` (a domain's declaration for an
    environment it did not write, e.g. :mod:`hrlp.fetch` for Gymnasium-Robotics' Fetch tasks): ``name -> slice`` for a
    Box observation, ``name -> (key, start, stop)`` inside a Dict's key (:meth:`ObsLayout.of_space`)."""
    _DECLARED[env_id] = dict(parts)


def observation_parts(env: gym.Env) -> Mapping[str, Any] | None:
    """The parts ``env`` names: its own ``observation_parts`` attribute (the arm's), else those a domain declared for
    its id (domains registered under the ``hrlp.domains`` entry point are imported first); None if neither."""
    own = getattr(env.unwrapped, "observation_parts", None)
    if own is not None:
        return own
    spec = env.spec or env.unwrapped.spec
    if spec is None:
        return None
    load_domains()
    return _DECLARED.get(spec.id)


def own_observation_space(env: gym.Env) -> gym.Space:
    """The environment's observation space before a wrapper flattened a Dict one (the first Dict space down its
    wrappers), else its observation space."""
    e: Any = env
    while e is not None:
        if isinstance(e.observation_space, gym.spaces.Dict):
            return e.observation_space
        e = getattr(e, "env", None)
    return env.observation_space


def _bounds(s: slice, dim: int) -> tuple[int, int]:
    lo, hi, step = s.indices(dim)
    if step != 1:
        raise ValueError(f"an observation part must be a contiguous slice, got {s}")
    return lo, hi


#: Parts a domain measures outside the observation: ``extra(name, idx) -> [M, width]`` for the worlds ``idx``.
Extra = Callable[[str, np.ndarray], np.ndarray]


class ObsView:
    """The observations of some worlds, read by part name: ``view["desired_goal"] -> [M, width]``.

    ``flat`` holds the rows ``[M, dim]``; ``idx`` the worlds' indices among the ``N`` a decision runs in (what
    ``extra`` and a skill's per-world state are indexed by)."""

    def __init__(self, flat: np.ndarray, layout: ObsLayout, idx: np.ndarray, extra: Extra | None = None) -> None:
        self.flat, self.layout, self.idx, self._extra = flat, layout, idx, extra

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.flat[:, self.layout.span(name)]
        except KeyError:
            if self._extra is None:
                raise KeyError(f"no observation part {name!r} (parts: {', '.join(self.layout.names)})") from None
            return np.asarray(self._extra(name, self.idx), dtype=np.float64).reshape(len(self.idx), -1)

    def __len__(self) -> int:
        return len(self.flat)

    def rows(self, which: np.ndarray) -> ObsView:
        """The view of the rows ``which`` (positions in this view)."""
        return ObsView(self.flat[which], self.layout, self.idx[which], self._extra)


@dataclass(frozen=True)
class ParamBox:
    """A skill's parameters in the user's units: ``low <= x <= high`` per parameter, optionally as an offset from the
    observed point ``frame`` (a part name: the Manager's parameters are then added to that part's value at the
    decision's start). The Manager's block ``u`` in [-1, 1] maps onto the box affinely (:meth:`to_user`)."""

    low: tuple[float, ...]
    high: tuple[float, ...]
    meaning: str = ""
    """What the parameters mean, e.g. 'goal position of the gripper (x, y, z), metres'."""
    frame: str | None = None
    """The observation part the parameters are offsets from (None: absolute)."""

    def __post_init__(self) -> None:
        if len(self.low) != len(self.high):
            raise ValueError(f"a parameter box needs as many lower as upper bounds, got {len(self.low)} and {len(self.high)}")
        lo, hi = np.asarray(self.low, dtype=np.float64), np.asarray(self.high, dtype=np.float64)
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
            raise ValueError(f"a parameter box must be finite, got low {list(self.low)}, high {list(self.high)}")
        if (lo > hi).any():
            raise ValueError(f"a parameter box's low {list(self.low)} exceeds its high {list(self.high)}")

    @classmethod
    def of(cls, low: Any, high: Any, meaning: str = "", frame: str | None = None) -> ParamBox:
        """A box from array-likes (or a Gymnasium Box's bounds)."""
        lo = np.asarray(low, dtype=np.float64).reshape(-1)
        hi = np.broadcast_to(np.asarray(high, dtype=np.float64), lo.shape).reshape(-1)
        return cls(tuple(float(v) for v in lo), tuple(float(v) for v in hi), meaning, frame)

    @property
    def dim(self) -> int:
        """Number of parameters."""
        return len(self.low)

    @property
    def centre(self) -> np.ndarray:
        """``(high + low) / 2``, ``[dim]``."""
        return (np.asarray(self.high, dtype=np.float64) + np.asarray(self.low, dtype=np.float64)) / 2

    @property
    def half(self) -> np.ndarray:
        """``(high - low) / 2``, ``[dim]``."""
        return (np.asarray(self.high, dtype=np.float64) - np.asarray(self.low, dtype=np.float64)) / 2

    def to_user(self, u: np.ndarray) -> np.ndarray:
        """``centre + half * clip(u, -1, 1)``: the Manager's block ``[M, dim]`` in the box's units (before ``frame``)."""
        return self.centre + self.half * np.clip(u, -1.0, 1.0)

    def to_unit(self, x: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_user` (unclipped; a flat side maps to 0)."""
        half = self.half
        return (np.asarray(x, dtype=np.float64) - self.centre) / np.where(half > 0, half, 1.0)

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable form."""
        return {"dim": self.dim, "low": list(self.low), "high": list(self.high), "meaning": self.meaning, "frame": self.frame}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ParamBox:
        """Inverse of :meth:`to_json`; a one-line ValueError for a malformed record."""
        try:
            return cls.of(d["low"], d["high"], str(d.get("meaning", "")), d.get("frame"))
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"malformed parameter box {dict(d)!r:.80}: {e}") from None


class Skill:
    """Base of a frozen parameterised skill (override :meth:`act`; the rest has defaults).

    Attributes:
        name: the skill's name (what the Manager's decision shares and videos call it).
        params: its parameter box (:class:`ParamBox`; ``dim`` 0 for a parameterless skill).
        k: its default duration, in low-level steps (at most; :meth:`done` may end it sooner).
        reads: the observation parts it reads (checked against the environment's before any compute).
        chains: whether it takes part in initiation fall-backs (:func:`initiated`); the direct control does not.
        cost: subtracted from the Manager's reward each time it is chosen (the paper's micro-action penalty).
    """

    name: str = "skill"
    params: ParamBox = ParamBox((), ())
    k: int = 10
    reads: tuple[str, ...] = ()
    chains: bool = True
    cost: float = 0.0

    def check(self, layout: ObsLayout, action_space: gym.spaces.Box, measured: Sequence[str] = ()) -> None:
        """Raise a one-line ValueError if this skill cannot run in an environment with ``layout`` and ``action_space``
        (``measured``: the parts the domain measures outside the observation). The default checks :attr:`reads` and
        the frame's part."""
        known = set(layout.names) | set(measured)
        wanted = list(self.reads) + ([self.params.frame] if self.params.frame else [])
        if missing := [p for p in wanted if p not in known]:
            raise ValueError(f"skill {self.name} reads the observation part(s) {', '.join(missing)}, which this environment "
                             f"lacks (its parts: {', '.join(layout.names)})")  # fmt: skip

    def begin(self, obs: ObsView, params: np.ndarray) -> None:
        """Called when the worlds ``obs.idx`` start this skill with ``params [M, dim]`` (world units, frame applied):
        reset per-world state here."""

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        """The low-level actions ``[M, A]`` in the worlds ``obs.idx`` given ``params [M, dim]``."""
        raise NotImplementedError

    def initiable(self, obs: ObsView) -> np.ndarray | None:
        """Whether the skill may start in each world, ``[M]`` bool; None: anywhere."""
        return None

    def done(self, obs: ObsView, params: np.ndarray) -> np.ndarray | None:
        """Whether the skill has finished in each world after a low-level step, ``[M]`` bool (a success end, told
        apart from running out of ``k`` steps); None: it runs its ``k`` steps."""
        return None


class ScriptedSkill(Skill):
    """A skill from plain functions (a scripted controller): ``policy(obs: ObsView, params [M, d]) -> [M, A]``, and
    optional ``initiable(obs) -> [M]``, ``done(obs, params) -> [M]`` and ``begin(obs, params)`` (called as worlds
    ``obs.idx`` start the skill: keep per-world state by ``obs.idx``, e.g. where each started).

    >>> reach = ScriptedSkill("reach", ParamBox.of([-1, -1], [1, 1]), lambda o, p: 5 * (p - o["achieved_goal"]),
    ...                       reads=("achieved_goal",), k=10)
    """

    def __init__(self, name: str, params: ParamBox, policy: Callable[[ObsView, np.ndarray], np.ndarray], *,
                 reads: Sequence[str] = (), k: int = 10,
                 initiable: Callable[[ObsView], np.ndarray] | None = None,
                 done: Callable[[ObsView, np.ndarray], np.ndarray] | None = None,
                 begin: Callable[[ObsView, np.ndarray], object] | None = None) -> None:  # fmt: skip
        if isinstance(k, bool) or not isinstance(k, int) or k < 1:
            raise ValueError(f"skill {name}: k must be a positive integer, got {k!r}")
        self.name, self.params, self.k, self.reads = str(name), params, k, tuple(reads)
        self._policy, self._initiable, self._done, self._begin = policy, initiable, done, begin
        self.has_done = done is not None  # decide() skips the done test of a skill that has none

    def begin(self, obs: ObsView, params: np.ndarray) -> None:
        if self._begin is not None:
            self._begin(obs, params)

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        return np.asarray(self._policy(obs, params), dtype=np.float64).reshape(len(obs), -1)

    def initiable(self, obs: ObsView) -> np.ndarray | None:
        return None if self._initiable is None else np.asarray(self._initiable(obs), dtype=bool).reshape(len(obs))

    def done(self, obs: ObsView, params: np.ndarray) -> np.ndarray | None:
        return None if self._done is None else np.asarray(self._done(obs, params), dtype=bool).reshape(len(obs))


class Wrapped(Skill):
    """``skill`` under another name or parameter box (same width): what the Manager's block means changes, not what it
    runs. The base of skills that change what a skill sees (:meth:`view`) or does (:class:`Holding`, :class:`Seeing`);
    everything not overridden (parts, duration, initiation, end, cost) is ``skill``'s."""

    def __init__(self, skill: Skill, name: str | None = None, params: ParamBox | None = None) -> None:
        if params is not None and params.dim != skill.params.dim:
            raise ValueError(f"skill {skill.name}: a parameter box of {params.dim} numbers for {skill.params.dim} parameters")
        self.skill, self.name = skill, str(name or skill.name)
        self.params = skill.params if params is None else params
        self.k, self.reads, self.chains, self.cost = skill.k, skill.reads, skill.chains, skill.cost
        self.has_done = bool(getattr(skill, "has_done", type(skill).done is not Skill.done))

    def view(self, obs: ObsView) -> ObsView:
        """What the wrapped skill sees of ``obs`` (the same view here)."""
        return obs

    def check(self, layout: ObsLayout, action_space: gym.spaces.Box, measured: Sequence[str] = ()) -> None:
        self.skill.check(layout, action_space, measured)

    def begin(self, obs: ObsView, params: np.ndarray) -> None:
        self.skill.begin(self.view(obs), params)

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        return self.skill.act(self.view(obs), params)

    def initiable(self, obs: ObsView) -> np.ndarray | None:
        return self.skill.initiable(self.view(obs))

    def done(self, obs: ObsView, params: np.ndarray) -> np.ndarray | None:
        return self.skill.done(self.view(obs), params)


class Holding(Wrapped):
    """``skill`` with some entries of its action held at fixed values, e.g. a reaching policy trained where the gripper
    was blocked, run with the gripper held open: ``Holding(reach, {3: 1.0}, "reach_open")``. Everything else (its
    parameters, parts, duration, initiation and end) is ``skill``'s."""

    def __init__(self, skill: Skill, held: Mapping[int, float], name: str | None = None) -> None:
        if not held:
            raise ValueError(f"skill {skill.name}: Holding needs at least one action entry to hold")
        super().__init__(skill, name)
        self.held = {int(i): float(v) for i, v in held.items()}

    def check(self, layout: ObsLayout, action_space: gym.spaces.Box, measured: Sequence[str] = ()) -> None:
        super().check(layout, action_space, measured)
        a = int(np.prod(action_space.shape))
        if bad := [i for i in self.held if not 0 <= i < a]:
            raise ValueError(f"skill {self.name} holds action entries {bad}; this environment's action has {a} numbers")

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        out = np.array(self.skill.act(obs, params), dtype=np.float64)
        for i, v in self.held.items():
            out[:, i] = v
        return out


class _Shown(ObsView):
    """An :class:`ObsView` in which some parts read as constants (:class:`Seeing`)."""

    def __init__(self, view: ObsView, shown: Mapping[str, np.ndarray]) -> None:
        super().__init__(view.flat, view.layout, view.idx, view._extra)
        self._shown = shown

    def __getitem__(self, name: str) -> np.ndarray:
        if name in self._shown:
            return np.broadcast_to(self._shown[name], (len(self.flat), self._shown[name].size))
        return super().__getitem__(name)

    def rows(self, which: np.ndarray) -> ObsView:
        return _Shown(super().rows(which), self._shown)


class Seeing(Wrapped):
    """``skill`` shown some observation parts as constants: a policy trained where a part never changed (FetchReach's
    blocked fingers, ``gripper_state`` always 0) sees it as it was in training wherever it runs,
    ``Seeing(reach, {"gripper_state": [0, 0]})``. The parts must exist in the environment (their width is checked)."""

    def __init__(self, skill: Skill, shown: Mapping[str, Any], name: str | None = None) -> None:
        super().__init__(skill, name)
        self.shown = {str(p): np.asarray(v, dtype=np.float64).reshape(-1) for p, v in shown.items()}

    def view(self, obs: ObsView) -> ObsView:
        return _Shown(obs, self.shown)

    def check(self, layout: ObsLayout, action_space: gym.spaces.Box, measured: Sequence[str] = ()) -> None:
        super().check(layout, action_space, measured)
        for part, value in self.shown.items():
            if part in layout.names and layout.width(part) != value.size:
                raise ValueError(f"skill {self.name} is shown {value.size} numbers as part {part!r}, which has "
                                 f"{layout.width(part)}")  # fmt: skip


class DirectControl(Skill):
    """The Manager's direct control (the paper's micro-action): the environment's own action as the parameters, held
    for ``duration`` steps; its box is the action space's, shrunk about its centre by ``scale`` (Appendix C: bounds on
    micro-actions); ``cost`` is subtracted from the Manager's reward each time it is chosen."""

    chains = False

    def __init__(self, action_space: gym.spaces.Box, duration: int = 1, cost: float = 0.0, scale: float = 1.0,
                 name: str = "micro") -> None:  # fmt: skip
        lo, hi = _finite_box(action_space, "direct control")
        c, h = (hi + lo) / 2, (hi - lo) / 2
        self.name, self.k, self.cost = name, int(duration), float(cost)
        self.params = ParamBox.of(c - scale * h, c + scale * h, "the environment's own action")

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        return params


def _finite_box(space: gym.Space, who: str) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(space, gym.spaces.Box):
        raise ValueError(f"{who} needs a Box action space, got {space}")
    lo, hi = np.asarray(space.low, np.float64).reshape(-1), np.asarray(space.high, np.float64).reshape(-1)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ValueError(f"{who} needs a bounded action space, got {space}")
    return lo, hi


@dataclass(frozen=True)
class MacroStep:
    """One Manager decision in each of ``N`` environments."""

    obs: np.ndarray  # [N, obs_dim] the observation after the macro-action
    rewards: np.ndarray  # [N] discounted in-macro reward sum_j gamma^j r_j (minus the chosen skill's cost)
    terminated: np.ndarray  # [N] bool
    truncated: np.ndarray  # [N] bool
    discount: np.ndarray  # [N] gamma^tau
    tau: np.ndarray  # [N] int, low-level steps taken
    task_reward: np.ndarray  # [N] undiscounted sum of the task's rewards (what a flat policy's return counts)
    choice: np.ndarray  # [N] int, the macro-action run
    infos: list[dict[str, Any]]  # the last low-level info of each environment
    skill_done: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))  # [N] bool: ended by its done test
    path: np.ndarray | None = None
    """``[N, T, obs_dim]``: the observation after each low-level step, ``T`` the hierarchy's longest duration; a world's
    rows past its ``tau`` repeat its last observation (goal relabelling scores every step of a macro-action). None
    unless asked for (:func:`decide`'s ``path``)."""


#: ``step(running, actions) -> (obs [M, obs_dim], rewards [M], terminated [M], truncated [M])`` for the worlds
#: ``running`` (indices): one low-level step of those worlds, the others waiting.
Stepper = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Hierarchy:
    """What a Manager commands: its skills in order (the direct control among them, if any), each one's duration, the
    parameter blocks' layout, and the discount inside a macro-action. Shared by every environment of one Manager."""

    skills: tuple[Skill, ...]
    durations: np.ndarray  # [S] int: low-level steps per call of each skill (at most)
    layout: ObsLayout
    gamma: float
    action_dim: int
    """Length of the environment's own (flat) action."""
    chain: bool = False
    """Initiation sets are enforced (:func:`initiated`)."""

    @property
    def names(self) -> list[str]:
        """The skills' names, in the order of the Manager's choices."""
        return [s.name for s in self.skills]

    @property
    def param_dims(self) -> tuple[int, ...]:
        """Each skill's block width."""
        return tuple(s.params.dim for s in self.skills)

    @property
    def offsets(self) -> np.ndarray:
        """Where each block starts among the ``S`` parameter numbers, ``[S + 1]``."""
        return np.concatenate([[0], np.cumsum(self.param_dims)]).astype(np.int64)

    @property
    def act_dim(self) -> int:
        """``1 + S``: the choice, then every parameter block."""
        return 1 + int(sum(self.param_dims))

    @property
    def ending(self) -> tuple[bool, ...]:
        """Whether each skill has a done test of its own (the others run their ``k`` steps, untested): its
        ``has_done`` where it says, else whether it overrides :meth:`Skill.done`."""
        return tuple(bool(getattr(s, "has_done", type(s).done is not Skill.done)) for s in self.skills)


def initiated(skills: Sequence[Skill], obs: ObsView, choice: np.ndarray, ran: np.ndarray | None = None) -> np.ndarray:
    """The skill each of ``N`` worlds runs under initiation sets.

    A skill that chains (:attr:`Skill.chains`) is available where :meth:`Skill.initiable` holds (or it declares none)
    or where it is the skill ``ran [N]`` ran last (the previous decision's, -1 for none: a running skill goes on wherever
    it took the world). ``choice [N]`` runs where its skill is available, and a skill that does not chain always; else
    the nearest available skill before it in the Manager's order (its prerequisite, for skills listed in the order they
    chain); else the first available skill; else ``choice``. -> ``[N]`` int."""
    chains = np.array([s.chains for s in skills], dtype=bool)
    if not chains.any():
        return choice
    n, n_skills = len(choice), len(skills)
    available = np.zeros((n, n_skills), dtype=bool)
    for i, s in enumerate(skills):
        if s.chains:
            holds = s.initiable(obs)
            available[:, i] = True if holds is None else holds
    if ran is not None:
        going = (ran >= 0) & (ran < n_skills)
        going[going] &= chains[ran[going]]
        available[np.flatnonzero(going), ran[going]] = True
    mine = np.minimum(choice, n_skills - 1)  # a choice past the skills given (a caller's direct control) runs as made
    outside = (choice < n_skills) & chains[mine] & ~available[np.arange(n), mine]
    before = available & (np.arange(n_skills)[None, :] < choice[:, None])  # the skills that come before the choice
    last_before = n_skills - 1 - np.argmax(before[:, ::-1], axis=1)
    fallback = np.where(before.any(axis=1), last_before, np.argmax(available, axis=1))
    replace = outside & available.any(axis=1)
    out = choice.copy()
    out[replace] = fallback[replace]
    return out


def decide(h: Hierarchy, obs: np.ndarray, actions: np.ndarray, step: Stepper, extra: Extra | None = None,
           ran: np.ndarray | None = None, path: bool = False) -> MacroStep:  # fmt: skip
    """One Manager decision in ``N`` worlds from ``obs [N, obs_dim]`` over any low-level stepper.

    ``actions [N, 1 + S]`` are flat hierarchical actions: the choice, then every skill's block in [-1, 1] (clipped and
    mapped onto its :class:`ParamBox`, plus its frame's part at the decision's start). At each low-level step every
    skill acts once on the worlds running it (batched inference) and ``step`` advances those worlds; a world whose
    skill has ended (its duration, its :meth:`Skill.done`, or its episode) waits. ``extra`` gives the parts a domain
    measures outside the observation; ``ran [N]`` the skill each world's previous decision ran (-1: none), for
    initiation sets; ``path``: also the observation after each low-level step (:attr:`MacroStep.path`). Returns the
    :class:`MacroStep` (``infos`` empty: the stepper keeps them). Raises a one-line
    ValueError for a wrong shape, NaN/inf, a choice that is not a skill, or a skill's actions of the wrong shape."""
    n, width = len(obs), h.act_dim
    a = np.asarray(actions, dtype=np.float64)
    if a.shape != (n, width):
        raise ValueError(f"Manager actions must have shape ({n}, {width}) (choice + parameter blocks), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("Manager actions contain NaN or inf")
    choice = a[:, 0].astype(np.int64)
    n_skills = len(h.skills)
    if (choice != a[:, 0]).any() or (choice < 0).any() or (choice >= n_skills).any():
        raise ValueError(f"Manager choices must be integers in [0, {n_skills}), got {a[:, 0].tolist()}")
    obs = np.array(obs, dtype=np.float64)
    everyone = np.arange(n)
    if h.chain:
        choice = initiated(h.skills, ObsView(obs, h.layout, everyone, extra), choice, ran)
    offsets, ending = h.offsets, h.ending
    params = np.empty((n, int(offsets[-1])))
    for s in np.unique(choice):  # each chosen skill's parameters in its own units, then its entry hook
        skill, idx = h.skills[s], np.flatnonzero(choice == s)
        block = skill.params.to_user(a[idx, 1 + offsets[s] : 1 + offsets[s + 1]])
        view = ObsView(obs[idx], h.layout, idx, extra)
        if skill.params.frame is not None:
            block = block + view[skill.params.frame]
        params[idx, offsets[s] : offsets[s + 1]] = block
        skill.begin(view, block)
    durations = h.durations[choice]
    rewards, task_reward = np.zeros(n), np.zeros(n)
    discount, tau = np.ones(n), np.zeros(n, dtype=np.int64)
    terminated, truncated, finished = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    lows = np.zeros((n, h.action_dim))
    active = np.ones(n, dtype=bool)
    steps = np.empty((n, int(h.durations.max()), obs.shape[1])) if path else None
    last = -1
    for j in range(int(durations.max())):
        active &= durations > j
        running = np.flatnonzero(active)
        if running.size == 0:
            break
        chosen = choice[running]
        groups = [(s, running[chosen == s]) for s in np.unique(chosen)]
        for s, idx in groups:
            skill = h.skills[s]
            out = np.asarray(skill.act(ObsView(obs[idx], h.layout, idx, extra), params[idx, offsets[s] : offsets[s + 1]]))
            if out.shape != (len(idx), h.action_dim):
                raise ValueError(f"skill {skill.name} returned actions of shape {out.shape}, expected "
                                 f"({len(idx)}, {h.action_dim}): the environment's action")  # fmt: skip
            lows[idx] = out
        obs[running], r, term, trunc = step(running, lows[running])
        if steps is not None:
            steps[:, j], last = obs, j
        rewards[running] += discount[running] * r
        task_reward[running] += r
        discount[running] *= h.gamma
        tau[running] += 1
        ended = term | trunc
        terminated[running], truncated[running] = term, trunc & ~term
        active[running[ended]] = False
        for s, idx in groups:  # a skill that says it is done stops its worlds (a success end, not a time-out)
            if not ending[s]:
                continue
            going = idx[active[idx]]
            if going.size and (d := h.skills[s].done(ObsView(obs[going], h.layout, going, extra),
                                                       params[going, offsets[s] : offsets[s + 1]])) is not None:  # fmt: skip
                stop = going[np.asarray(d, dtype=bool).reshape(len(going))]
                finished[stop] = True
                active[stop] = False
    if steps is not None:
        steps[:, last + 1 :] = obs[:, None]
    for s, skill in enumerate(h.skills):
        if skill.cost:
            rewards[choice == s] -= skill.cost
    return MacroStep(obs, rewards, terminated, truncated, discount, tau, task_reward, choice, [], finished, steps)


__all__ = [
    "WHOLE",
    "DirectControl",
    "Hierarchy",
    "Holding",
    "MacroStep",
    "ObsLayout",
    "ObsView",
    "ParamBox",
    "ScriptedSkill",
    "Seeing",
    "Skill",
    "Wrapped",
    "decide",
    "initiated",
    "observation_parts",
    "own_observation_space",
    "register_observation_parts",
]
