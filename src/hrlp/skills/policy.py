"""A frozen learned policy as a skill: a goal-conditioned policy whose goal is the Manager's parameter.

A policy trained on a goal-conditioned environment (a Dict observation with ``observation``, ``achieved_goal``,
``desired_goal``, Gymnasium-Robotics' convention) is a parameterised skill whose parameter is its ``desired_goal``,
bound by name: wherever it runs, it reads the same parts of its new environment's observation, with the part its
parameter replaces set to the Manager's parameters. The same class serves a policy trained by hrlp
(:func:`hrlp.training.sources.from_run`) and one trained by Stable-Baselines3 (:func:`from_sb3`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import gymnasium as gym
import numpy as np

from hrlp.skills.core import ObsLayout, ObsView, ParamBox, Skill
from hrlp.skills.sb3 import load_sb3


class PolicySkill(Skill):
    """A frozen policy ``act([M, obs_dim]) -> [M, A]`` over named observation parts.

    Args:
        name: the skill's name.
        parts: the parts of its own observation, in the order its input concatenates them: ``(name, width)`` pairs.
        param_part: the part its parameters replace (e.g. ``desired_goal``); None for a parameterless skill.
        params: its parameter box in the user's units (width of ``param_part``).
        policy: its deterministic action on a batch of its own observations, in the environment's units.
        action_low, action_high: the action bounds it was trained with (its actions are clipped to them).
        k: its default duration.
        done_part, done_within: the skill ends (a success end) once part ``done_part`` (e.g. ``achieved_goal``) is
            within ``done_within`` of its parameters (Euclidean); None: it runs its ``k`` steps.
        bind: where it reads its own parts in the environment it runs in, when they go by other names there: ``own
            part -> the environment's parts``, concatenated in order (e.g. a policy trained on FetchReach, whose
            ``achieved_goal`` is the gripper's position, runs on FetchPickAndPlace with ``{"achieved_goal":
            ("grip_pos",)}``). Unbound parts are read by their own name; the parameter part is never read.
    """

    def __init__(self, name: str, parts: Sequence[tuple[str, int]], param_part: str | None, params: ParamBox,
                 policy: Callable[[np.ndarray], np.ndarray], action_low: np.ndarray, action_high: np.ndarray, *,
                 k: int = 10, done_part: str | None = None, done_within: float | None = None,
                 bind: Mapping[str, Sequence[str]] | None = None) -> None:  # fmt: skip
        self.name, self.k, self.params = str(name), _positive(k, name), params
        self.parts = tuple((str(p), int(w)) for p, w in parts)
        names = [p for p, _ in self.parts]
        if param_part is not None and param_part not in names:
            raise ValueError(f"skill {name}: its parameter part {param_part!r} is not one of its observation parts "
                             f"({', '.join(names)})")  # fmt: skip
        width = dict(self.parts).get(param_part, 0) if param_part else 0
        if params.dim != width:
            raise ValueError(f"skill {name}: its parameter box has {params.dim} numbers, its parameter part "
                             f"{param_part!r} {width}")  # fmt: skip
        if (done_part is None) != (done_within is None):
            raise ValueError(f"skill {name}: give both done_part and done_within, or neither")
        if done_within is not None and not done_within > 0:
            raise ValueError(f"skill {name}: done_within must be a positive distance, got {done_within!r}")
        self.param_part, self._policy = param_part, policy
        self.action_low = np.asarray(action_low, dtype=np.float64).reshape(-1)
        self.action_high = np.asarray(action_high, dtype=np.float64).reshape(-1)
        self.done_part, self.done_within = done_part, done_within
        self.has_done = done_part is not None
        self.bind = check_bind(bind, names, param_part, self.name)
        self.sources = {p: self.bind.get(p, (p,)) for p in names if p != param_part}
        read = [q for p in names if p != param_part for q in self.sources[p]] + ([done_part] if done_part else [])
        self.reads = tuple(dict.fromkeys(read))

    def check(self, layout: ObsLayout, action_space: gym.spaces.Box, measured: Sequence[str] = ()) -> None:
        super().check(layout, action_space, measured)
        widths = dict(zip(layout.names, (layout.width(n) for n in layout.names), strict=True))
        for part, width in self.parts:
            if part == self.param_part:
                continue
            src = self.sources[part]
            if (got := sum(widths.get(q, 0) for q in src)) != width:
                where = f"part {part!r}" if src == (part,) else f"part {part!r} (bound to {'+'.join(src)})"
                raise ValueError(f"skill {self.name} reads {width} numbers of {where}; this environment has {got}")
        if self.done_part and layout.width(self.done_part) != self.params.dim:
            raise ValueError(f"skill {self.name} ends when part {self.done_part!r} reaches its parameters, but that part "
                             f"has {layout.width(self.done_part)} numbers and its parameters {self.params.dim}")  # fmt: skip
        a = int(np.prod(action_space.shape))
        if a != self.action_low.size:
            raise ValueError(f"skill {self.name} emits {self.action_low.size} action numbers; this environment takes {a}")

    def observation(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        """The skill's own input: its parts in order, its parameter part replaced by ``params``. ``[M, obs_dim]``"""
        cols = [np.asarray(params, dtype=np.float64) if p == self.param_part else _read(obs, self.sources[p])
                for p, _ in self.parts]  # fmt: skip
        return np.concatenate(cols, axis=1) if cols else np.zeros((len(obs), 0))

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        x = self.observation(obs, params)
        if not np.isfinite(x).all():
            raise ValueError(f"skill {self.name}: observation or parameters contain NaN or inf")
        a = np.asarray(self._policy(x), dtype=np.float64).reshape(len(x), -1)
        return np.clip(a, self.action_low, self.action_high)

    def done(self, obs: ObsView, params: np.ndarray) -> np.ndarray | None:
        if self.done_part is None:
            return None
        return np.linalg.norm(obs[self.done_part] - params, axis=1) <= self.done_within  # type: ignore[operator]


def _read(obs: ObsView, names: tuple[str, ...]) -> np.ndarray:
    return obs[names[0]] if len(names) == 1 else np.concatenate([obs[n] for n in names], axis=1)


def check_bind(bind: Mapping[str, Sequence[str]] | None, parts: Sequence[str], param_part: str | None,
               who: str) -> dict[str, tuple[str, ...]]:  # fmt: skip
    """``bind`` (own part -> the environment's parts) checked against a policy's own ``parts``: every key one of its
    parts other than ``param_part``, every value a non-empty list of part names; a one-line ValueError naming ``who``."""
    out: dict[str, tuple[str, ...]] = {}
    for own, src in (bind or {}).items():
        if own not in parts or own == param_part:
            raise ValueError(f"skill {who}: bind names {own!r}, which is not one of the parts it reads "
                             f"({', '.join(p for p in parts if p != param_part)})")  # fmt: skip
        names = (src,) if isinstance(src, str) else tuple(src) if isinstance(src, Sequence) else ()
        if not names or not all(isinstance(n, str) and n for n in names):
            raise ValueError(f"skill {who}: bind's {own!r} must name one or more observation parts, got {src!r}")
        out[str(own)] = names
    return out


def parse_bind(items: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """``["achieved_goal=grip_pos", "observation=grip_pos,gripper_state"]`` -> a ``bind`` mapping; a one-line
    ValueError for an item without ``=``."""
    out: dict[str, tuple[str, ...]] = {}
    for item in items:
        own, eq, src = item.partition("=")
        if not eq or not own.strip() or not src.strip():
            raise ValueError(f"--bind {item!r}: write OWN_PART=PART[,PART...], e.g. achieved_goal=grip_pos")
        out[own.strip()] = tuple(n.strip() for n in src.split(","))
    return out


def from_sb3(path: str | Path, name: str | None = None, *, param: str | None = "desired_goal", low: object = None,
             high: object = None, k: int = 10, done_part: str | None = None, done_within: float | None = None,
             bind: Mapping[str, Sequence[str]] | None = None) -> PolicySkill:  # fmt: skip
    """A skill from a Stable-Baselines3 PPO, SAC or TD3 ``.zip`` (read without unpickling, :mod:`hrlp.skills.sb3`).

    ``param`` names the observation part its parameters replace (for a policy trained on a Dict observation; default
    ``desired_goal``, None for none); ``low``/``high`` bound the parameters in the user's units (required for a
    parameter part); ``bind`` reads its parts under the names they have where it runs (:class:`PolicySkill`). A policy
    trained on a Box observation reads the part ``observation`` of its new environment."""
    p = load_sb3(path)
    skill_name = name or Path(path).stem
    parts = p.obs_parts
    if param is not None and param not in dict(parts):
        if p.obs_is_dict:
            raise ValueError(f"{path}: no observation part {param!r} to take the parameters (its parts: "
                             f"{', '.join(n for n, _ in parts)}); name one with param=")  # fmt: skip
        param = None
    width = dict(parts).get(param, 0) if param else 0
    box = param_box(low, high, width, None, f"{path}")  # an SB3 file records a Dict's bounds only as text: not read
    return PolicySkill(skill_name, parts, param, box, p.act, p.action_low, p.action_high, k=k, done_part=done_part,
                       done_within=done_within, bind=bind)  # fmt: skip


def param_box(low: object, high: object, width: int, recorded: tuple[np.ndarray, np.ndarray] | None, who: str) -> ParamBox:
    """A parameter box of ``width`` numbers from the user's ``low``/``high`` (numbers or lists), else the ``recorded``
    bounds if finite; a one-line ValueError naming ``who`` otherwise."""
    if width == 0:
        return ParamBox((), ())
    if low is None or high is None:
        if recorded is None or not (np.isfinite(recorded[0]).all() and np.isfinite(recorded[1]).all()):
            raise ValueError(f"{who}: its parameter part has no finite bounds on record; give low= and high= (the "
                             "parameters' box in your units)")  # fmt: skip
        low, high = recorded if low is None and high is None else (low if low is not None else recorded[0],
                                                                   high if high is not None else recorded[1])  # fmt: skip
    bounds = []
    for what, v in (("low", low), ("high", high)):
        a = np.asarray(v, dtype=np.float64).reshape(-1)
        if a.size not in (1, width):
            raise ValueError(f"{who}: {what} must be one number or {width} (its parameter part's width), got {a.size}")
        bounds.append(np.broadcast_to(a, (width,)))
    return ParamBox.of(*bounds)


def _positive(k: object, name: str) -> int:
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
        raise ValueError(f"skill {name}: k must be a positive integer, got {k!r}")
    return int(k)
