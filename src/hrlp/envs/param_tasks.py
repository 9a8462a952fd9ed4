"""Short-episode parameterised-action tasks with exactly known optimal returns (no physics, no MuJoCo).

Each task acts in the flat space ``Tuple(Discrete(n), Box(d_1), ..., Box(d_n))`` that hrlp's hierarchical policy
produces: a discrete choice ``k`` and the continuous parameters ``u_k`` of that choice (the others are ignored). Some
parameters have wide native bounds ([0, 720], [-50, 50]), as real parameterised tasks do. Every task states its
optimal expected return (derived in its docstring, :meth:`optimal_return`) and has a hand-written heuristic
(:func:`heuristic_action`); :func:`random_action` is the uniform random policy.

* ``hrlp/ParamBandit-v0`` (:class:`ParamBandit`): a contextual bandit, one decision; the best choice and its
  parameter depend on the context.
* ``hrlp/ParamMatch-v0`` (:class:`ParamMatch`): a few decisions; the parameter must match a (nonlinear) function of
  the state, the reward shaped by the distance.
* ``hrlp/ParamReach-v0`` (:class:`ParamReach`): up to 8 decisions, reward only at the end (1 on reaching the goal):
  choose between a long jump and a short step, and their directions.

:data:`SHORT_EPISODE_SETTINGS` holds training settings (:class:`hrlp.train.TrainConfig` overrides) for such
short-episode problems, measured by ``benchmarks/short_episodes.py`` (docs/benchmarks.md).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from hrlp.envs.check import SHORT_EPISODE_SETTINGS as _CLI_SHORT

__all__ = [
    "PARAM_TASKS",
    "SHORT_EPISODE_SETTINGS",
    "ParamBandit",
    "ParamMatch",
    "ParamReach",
    "heuristic_action",
    "random_action",
    "register_param_tasks",
    "short_episode_config",
]

NAMESPACE = "hrlp"


def _kernel(error: np.ndarray | float, width: float) -> float:
    """``exp(-||error||^2 / (2 width^2))``: 1 on target, falling smoothly with the distance."""
    e = np.asarray(error, dtype=np.float64)
    return float(np.exp(-0.5 * float(np.sum(e * e)) / (width * width)))


def _number(name: str, value: Any, low: float, high: float, what: str) -> float:
    """``value`` as a float in [low, high], else a one-line ValueError."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or not low <= value <= high:
        raise ValueError(f"{name} must be {what}, got {value!r}")
    return float(value)


def _integer(name: str, value: Any, low: int, high: int) -> int:
    """``value`` as an int in [low, high], else a one-line ValueError."""
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    return int(value)


class _ParamTask(gym.Env):
    """Common parts: the parameterised action space, clipping of actions to it, reading the chosen block."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}
    horizon: int
    """Decisions per episode at most (the episode length)."""

    def _space(self, blocks: list[tuple[float, float, int]]) -> gym.spaces.Tuple:
        boxes = [gym.spaces.Box(lo, hi, shape=(d,), dtype=np.float32) for lo, hi, d in blocks]
        return gym.spaces.Tuple((gym.spaces.Discrete(len(boxes)), *boxes))

    def _parse(self, action: Any) -> tuple[int, np.ndarray]:
        """``(k, u_k)`` of an action ``(k, u_1, ..., u_n)``, ``u_k`` clipped to its bounds (float64)."""
        k = int(np.asarray(action[0]).reshape(-1)[0])
        if not 0 <= k < len(self.action_space.spaces) - 1:
            raise ValueError(f"choice {k} is not one of 0..{len(self.action_space.spaces) - 2}")
        box = self.action_space.spaces[1 + k]
        u = np.asarray(action[1 + k], dtype=np.float64).reshape(box.shape)
        return k, np.clip(u, box.low, box.high)

    def optimal_return(self) -> float:
        """The optimal expected (undiscounted) return of an episode."""
        raise NotImplementedError


class ParamBandit(_ParamTask):
    """A contextual bandit: one decision per episode.

    Observation: the context ``(x, y)``, uniform on [-1, 1]^2. Choices:

    * 0 "far": parameter ``a`` in [0, 720]; pays ``(1 - x)/2 * K(a - (360 + 240 y), 72)``;
    * 1 "near": parameter ``b`` in [-50, 50]; pays ``(1 + x)/2 * K(b - 40 y, 10)``;
    * 2 "skip": no parameter; pays ``skip_reward`` (0.25).

    ``K(e, w) = exp(-e^2 / (2 w^2))`` (1 on target). The best choice depends on ``x`` (far for x < 0, near for
    x > 0) and its parameter on ``y``. Optimal return: the best choice with its parameter on target pays
    ``max((1 - x)/2, (1 + x)/2, skip) = (1 + |x|)/2`` (skip_reward <= 0.5), whose mean over x uniform on [-1, 1] is
    exactly **0.75** (:data:`OPTIMAL`). The heuristic takes the right choice with its parameter at the middle of the
    target's range (360, 0), ignoring ``y``.
    """

    OPTIMAL = 0.75
    horizon = 1

    def __init__(self, skip_reward: float = 0.25) -> None:
        self.skip_reward = _number("skip_reward", skip_reward, 0.0, 0.5, "a number in [0, 0.5]")
        self.observation_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.action_space = self._space([(0.0, 720.0, 1), (-50.0, 50.0, 1), (0.0, 1.0, 0)])
        self._ctx = np.zeros(2)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self._ctx = self.np_random.uniform(-1.0, 1.0, size=2)
        return self._ctx.astype(np.float32), {}

    def targets(self) -> tuple[float, float]:
        """The on-target parameters of choices 0 and 1 in the current context."""
        y = float(self._ctx[1])
        return 360.0 + 240.0 * y, 40.0 * y

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        k, u = self._parse(action)
        x = float(self._ctx[0])
        far, near = self.targets()
        if k == 0:
            r = (1 - x) / 2 * _kernel(u[0] - far, 72.0)
        elif k == 1:
            r = (1 + x) / 2 * _kernel(u[0] - near, 10.0)
        else:
            r = self.skip_reward
        return self._ctx.astype(np.float32), float(r), True, False, {}

    def optimal_return(self) -> float:
        return self.OPTIMAL

    def oracle_action(self) -> tuple:
        """The optimal action in the current state (needs the environment's state)."""
        far, near = self.targets()
        k = 0 if self._ctx[0] < 0 else 1
        return _action(self.action_space, k, far if k == 0 else near)


class ParamMatch(_ParamTask):
    """Match a parameter to the state, with a distance-shaped reward, over ``steps`` decisions (3).

    Each decision observes ``(s1, s2, m, t)``: ``s`` uniform on [-1, 1]^2, a mode ``m`` of -1 or +1 (equally likely)
    and the share of the episode done ``t``; each decision's state is drawn afresh. Choices:

    * 0 "angle": parameter ``a`` in [0, 720], target ``360 + 300 sin(pi s1 / 2) * cos(pi s2 / 2)``, width 72;
    * 1 "offset": parameter ``(u, v)`` in [-50, 50]^2, target ``(40 s1, 40 s2^2 - 20)``, width 10.

    The choice the mode asks for (0 for m = +1, 1 for m = -1) pays ``K(error, width) = exp(-|error|^2 / (2 width^2))``,
    the other pays 0. Optimal return: 1 per decision, exactly **steps** (3.0). The heuristic takes the right choice
    with the targets' first-order approximations (``360 + 300 s1`` and ``(40 s1, 0)``).
    """

    horizon = 3

    def __init__(self, steps: int = 3) -> None:
        self.horizon = _integer("steps", steps, 1, 50)
        self.observation_space = gym.spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self.action_space = self._space([(0.0, 720.0, 1), (-50.0, 50.0, 2)])
        self._s, self._m, self._t = np.zeros(2), 1.0, 0

    def _draw(self) -> None:
        self._s = self.np_random.uniform(-1.0, 1.0, size=2)
        self._m = 1.0 if self.np_random.random() < 0.5 else -1.0

    def _obs(self) -> np.ndarray:
        return np.array([*self._s, self._m, self._t / self.horizon], dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self._t = 0
        self._draw()
        return self._obs(), {}

    def targets(self) -> tuple[float, np.ndarray]:
        """The on-target parameters of choices 0 and 1 in the current state."""
        s1, s2 = (float(v) for v in self._s)
        angle = 360.0 + 300.0 * math.sin(math.pi * s1 / 2) * math.cos(math.pi * s2 / 2)
        return angle, np.array([40.0 * s1, 40.0 * s2 * s2 - 20.0])

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        k, u = self._parse(action)
        angle, offset = self.targets()
        wanted = 0 if self._m > 0 else 1
        r = 0.0 if k != wanted else _kernel(u[0] - angle, 72.0) if k == 0 else _kernel(u - offset, 10.0)
        self._t += 1
        done = self._t >= self.horizon
        if not done:
            self._draw()
        return self._obs(), float(r), done, False, {}

    def optimal_return(self) -> float:
        return float(self.horizon)

    def oracle_action(self) -> tuple:
        """The optimal action in the current state."""
        angle, offset = self.targets()
        return _action(self.action_space, 0, angle) if self._m > 0 else _action(self.action_space, 1, offset)


class ParamReach(_ParamTask):
    """Reach a goal in the plane within ``max_decisions`` decisions (8); reward 1 on arrival, else 0 (sparse).

    The agent starts at the origin; the goal is at a distance uniform in [20, 60], in a uniform direction. It
    observes ``(gx - px, gy - py, t)``: the goal relative to itself (native units) and the share of the decisions
    used. Choices:

    * 0 "jump": parameter a direction ``(dx, dy)`` in [-50, 50]^2; moves exactly 20 along it (not at all for 0);
    * 1 "step": parameter ``(dx, dy)`` in [-50, 50]^2; moves by it, shortened to length 5 if longer.

    The episode ends with reward 1 as soon as the agent is within ``goal_radius`` (5) of the goal (terminated), and
    with 0 after ``max_decisions`` decisions (truncated). Optimal return: exactly **1.0**. Two jumps of 20 reach
    any point within 40 of the start (their sum covers the disc of radius 40), so three reach any point within 60,
    in 3 <= max_decisions decisions; no return exceeds 1. The heuristic jumps straight at the goal while it is more
    than 20 away and steps straight at it otherwise (it too always arrives, using up to 6 decisions).
    """

    JUMP, STEP = 20.0, 5.0
    horizon = 8

    def __init__(self, max_decisions: int = 8, goal_radius: float = 5.0) -> None:
        self.horizon = _integer("max_decisions", max_decisions, 3, 100)
        self.goal_radius = _number("goal_radius", goal_radius, 0.5, 20.0, "a number in [0.5, 20]")
        far = 60.0 + self.JUMP * self.horizon  # no goal is farther than this, wherever the agent has gone
        self.observation_space = gym.spaces.Box(
            np.array([-far, -far, 0.0], dtype=np.float32), np.array([far, far, 1.0], dtype=np.float32), dtype=np.float32
        )
        self.action_space = self._space([(-50.0, 50.0, 2), (-50.0, 50.0, 2)])
        self._pos, self._goal, self._t = np.zeros(2), np.zeros(2), 0

    def _obs(self) -> np.ndarray:
        return np.array([*(self._goal - self._pos), self._t / self.horizon], dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        dist = self.np_random.uniform(20.0, 60.0)
        angle = self.np_random.uniform(-math.pi, math.pi)
        self._pos, self._goal, self._t = np.zeros(2), dist * np.array([math.cos(angle), math.sin(angle)]), 0
        return self._obs(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        k, u = self._parse(action)
        norm = float(np.linalg.norm(u))
        if k == 0:
            move = u * (self.JUMP / norm) if norm > 0 else np.zeros(2)
        else:
            move = u * (self.STEP / norm) if norm > self.STEP else u
        self._pos = self._pos + move
        self._t += 1
        arrived = bool(np.linalg.norm(self._goal - self._pos) <= self.goal_radius)
        truncated = not arrived and self._t >= self.horizon
        info = {"success": arrived} if arrived or truncated else {}
        return self._obs(), 1.0 if arrived else 0.0, arrived, truncated, info

    def optimal_return(self) -> float:
        return 1.0

    def oracle_action(self) -> tuple:
        """An optimal action: jump at the goal while more than 40 away, then two jumps that meet at it (one bent at
        the angle whose two 20-long legs span the distance), or the last straight jump or step."""
        rel = self._goal - self._pos
        d = float(np.linalg.norm(rel))
        if d <= self.goal_radius:
            return _action(self.action_space, 1, np.zeros(2))
        if d > 2 * self.JUMP or abs(d - self.JUMP) <= self.goal_radius:
            return _action(self.action_space, 0, rel)
        if d <= self.STEP + self.goal_radius:
            return _action(self.action_space, 1, rel)
        bend = math.acos(min(1.0, d / (2 * self.JUMP)))  # the first leg of an isosceles triangle with base d
        c, s = math.cos(bend), math.sin(bend)
        return _action(self.action_space, 0, np.array([c * rel[0] - s * rel[1], s * rel[0] + c * rel[1]]))


def _action(space: gym.spaces.Tuple, k: int, u: Any) -> tuple:
    """The action ``(k, u_1, ..., u_n)`` of ``space`` with ``u_k = u`` and the other blocks at their lows."""
    blocks = [np.asarray(b.low, dtype=np.float32).copy() for b in space.spaces[1:]]
    box = space.spaces[1 + k]
    blocks[k] = np.clip(np.asarray(u, dtype=np.float32).reshape(box.shape), box.low, box.high)
    return (int(k), *blocks)


def heuristic_action(env: gym.Env, obs: np.ndarray) -> tuple:
    """The hand-written heuristic of ``env``'s task (see each class) for observation ``obs``."""
    task = env.unwrapped
    space = task.action_space
    o = np.asarray(obs, dtype=np.float64)
    if isinstance(task, ParamBandit):
        return _action(space, 0, 360.0) if o[0] < 0 else _action(space, 1, 0.0)
    if isinstance(task, ParamMatch):
        if o[2] > 0:
            return _action(space, 0, 360.0 + 300.0 * o[0])
        return _action(space, 1, np.array([40.0 * o[0], 0.0]))
    if isinstance(task, ParamReach):
        rel = o[:2]
        return _action(space, 0, rel) if np.linalg.norm(rel) > ParamReach.JUMP else _action(space, 1, rel)
    raise ValueError(f"no heuristic for {type(task).__name__}")


def random_action(env: gym.Env, rng: np.random.Generator) -> tuple:
    """A uniformly random action of ``env``: the choice uniform, every parameter uniform within its bounds."""
    space = env.unwrapped.action_space
    k = int(rng.integers(len(space.spaces) - 1))
    return (k, *(rng.uniform(b.low, b.high).astype(np.float32) for b in space.spaces[1:]))


#: The tasks by name; their Gymnasium ids are ``hrlp/<name>-v0``.
PARAM_TASKS: dict[str, type[_ParamTask]] = {"ParamBandit": ParamBandit, "ParamMatch": ParamMatch, "ParamReach": ParamReach}

#: Training settings for short episodes (1-10 decisions): :class:`hrlp.train.TrainConfig` overrides, the dotted names
#: ``trpo.*`` / ``value.*`` for the nested settings; everything else stays at its default (hidden (64, 64), init_log_std
#: 0, gamma 0.99, GAE lambda 0.97, the baseline fit). Found and measured with ``benchmarks/short_episodes.py``: with
#: them every task of :data:`PARAM_TASKS` reaches >= 95% of its optimal greedy return within 20,000 episodes.
#: The values are those ``hrlp train`` uses for short episodes (:data:`hrlp.envs.check.SHORT_EPISODE_SETTINGS`, declared
#: there): 500 decisions per batch (the default 50,000 is a whole 20,000-episode budget of 1-10-decision episodes) and
#: max KL 0.05 (5x the default 0.01: about 40-150 updates in 20,000 episodes must reach the optimum).
SHORT_EPISODE_SETTINGS: dict[str, Any] = {
    "batch_steps": _CLI_SHORT["batch_steps"],
    "num_envs": _CLI_SHORT["num_envs"],
    "trpo.max_kl": _CLI_SHORT["max_kl"],
    "trpo.fisher_fraction": _CLI_SHORT["fisher_fraction"],
    "value.max_iter": _CLI_SHORT["value_iters"],
    "value.fraction": _CLI_SHORT["value_fraction"],
}


def short_episode_config(task: str, steps: int, seed: int = 0, **overrides: Any) -> Any:
    """A :class:`hrlp.train.TrainConfig` for ``task`` with :data:`SHORT_EPISODE_SETTINGS` (and ``overrides``, same
    names) applied; ``steps`` is the budget in decisions."""
    import dataclasses

    from hrlp.config import TrainConfig

    settings = {**SHORT_EPISODE_SETTINGS, **overrides}
    nested = {f.name: f.default_factory() for f in dataclasses.fields(TrainConfig) if f.name in _NESTED}  # type: ignore[misc]
    top = {k: v for k, v in settings.items() if "." not in k}
    unknown = [k for k in settings if "." in k and k.split(".")[0] not in nested]
    if unknown:
        raise ValueError(f"unknown settings {unknown}: use TrainConfig fields or {', '.join(f'{n}.<field>' for n in nested)}")
    for name, default in nested.items():
        given = {k.removeprefix(f"{name}."): v for k, v in settings.items() if k.startswith(f"{name}.")}
        top[name] = dataclasses.replace(default, **given)
    return TrainConfig(task=task, steps=steps, seed=seed, **top)


_NESTED = ("advantage", "trpo", "ppo", "value")
"""TrainConfig's nested settings that :func:`short_episode_config` takes as ``<name>.<field>``."""


MAX_DECISIONS = {"ParamMatch": 50}
"""Registered time limits that differ from a task's default ``horizon``: ParamMatch's ``steps`` may be up to 50."""


def register_param_tasks() -> None:
    """Register the tasks as ``hrlp/<name>-v0`` Gymnasium ids (idempotent)."""
    for name, cls in PARAM_TASKS.items():
        env_id = f"{NAMESPACE}/{name}-v0"
        if env_id not in gym.registry:  # the declared time limit makes 'hrlp train' pick its short-episode settings
            gym.register(id=env_id, entry_point=cls, max_episode_steps=MAX_DECISIONS.get(name, cls.horizon))
