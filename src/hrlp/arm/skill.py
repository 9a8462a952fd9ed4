"""A skill: a trained policy frozen for reuse, acting on the arm's base observation and its parameters.

Section 1.1: "the Manager ... selects one of N available macro-actions and passes a vector of
parameters to the selected macro-action". A skill's parameters enter its observation where its
training task put them (the Reacher's goal and the Mover's target at indices 24-26, after the
24 base numbers), so a skill trained on a task can be driven by any Manager that sets them. A skill may also read
named observation features after its parameters (:data:`~hrlp.arm.physics.OBS_FEATURES`, e.g. the capsule's pose for
a Gripper trained with ``observe_capsule``): the environment it acts in computes them from its physics.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from hrlp.arm.physics import BASE_OBS_DIM, CAPSULE_REST_Z, N_JOINTS, OBS_FEATURES, ArmPhysics
from hrlp.policies.mlp import GaussianPolicy, NumpyMLP
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.skills.core import ObsView, ParamBox, Skill

#: Named frames a parameter vector can be expressed in: the slice of the observation that holds the frame's origin
#: (None for the world frame). A parameter in a body's frame is an offset from that body's position. 'hand' and
#: 'capsule' lie in the 24 base numbers; 'target' (the task's target T) in obs[24:27] of the tasks that observe one
#: (:attr:`hrlp.arm.tasks.Task.observes_target`: the moving tasks).
FRAMES: dict[str, slice | None] = {"world": None, "hand": slice(18, 21), "capsule": slice(21, 24), "target": slice(24, 27)}


@dataclass(frozen=True)
class ParamSpec:
    """What a skill's parameter vector is, in which frame, and where it enters the skill's observation."""

    dim: int
    """Number of parameters (0 for a parameterless skill such as the Gripper)."""
    low: tuple[float, ...]
    """Lower bounds, one per parameter, in ``frame``."""
    high: tuple[float, ...]
    """Upper bounds, one per parameter, in ``frame``."""
    meaning: str
    """What the parameters mean, e.g. 'goal position of the hand H (x, y, z), metres'."""
    obs_start: int = BASE_OBS_DIM
    """Index of the skill's observation where the parameters start (they follow the 24 base numbers)."""
    frame: str = "world"
    """The frame of the bounds (a key of :data:`FRAMES`): 'world', or a body ('capsule', 'hand', 'target') whose
    position at the start of the macro-action is added to the parameters before they reach the skill."""

    def __post_init__(self) -> None:
        if self.dim < 0 or len(self.low) != self.dim or len(self.high) != self.dim:
            raise ValueError(f"ParamSpec: dim {self.dim} does not match bounds {self.low}, {self.high}")
        if any(not (lo <= hi) for lo, hi in zip(self.low, self.high, strict=True)):
            raise ValueError(f"ParamSpec: low {self.low} exceeds high {self.high}")
        if self.frame not in FRAMES:
            raise ValueError(f"ParamSpec: unknown frame {self.frame!r} (known: {', '.join(FRAMES)})")
        if self.frame != "world" and self.dim != 3:
            raise ValueError(f"ParamSpec: a parameter in the {self.frame} frame is a 3-d point, got dim {self.dim}")

    def origin(self, base_obs: np.ndarray) -> np.ndarray:
        """The frame's origin in world coordinates for each state: ``[N, >=24] -> [N, dim]`` (zeros for 'world'; the
        'target' frame reads obs[24:27])."""
        base = np.asarray(base_obs, dtype=np.float64)
        where = FRAMES[self.frame]
        return np.zeros((base.shape[0], self.dim)) if where is None else base[:, where].copy()

    def box(self) -> ParamBox:
        """The generic parameter box (:class:`~hrlp.skills.core.ParamBox`): the same bounds, the frame as the part of
        the arm's observation it names (None for 'world')."""
        return ParamBox(self.low, self.high, self.meaning, None if self.frame == "world" else self.frame)

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable form."""
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> ParamSpec:
        """Inverse of :meth:`to_json`."""
        return cls(int(d["dim"]), tuple(d["low"]), tuple(d["high"]), str(d["meaning"]), int(d["obs_start"]),
                   str(d.get("frame", "world")))  # fmt: skip


# The reachable band above the table (docs/environments.md): the skills' own box for 3-d points, in the world frame.
_WORKSPACE_LOW, _WORKSPACE_HIGH = (-0.55, -0.45, 0.0), (0.25, 0.45, 0.45)
_POINT = "position of the hand H to reach (x, y, z), metres"
_TARGET = "target position T of the capsule (x, y, z), metres"
#: Parameter specifications of the skills trained on each task, declared here once (the task decides the observation
#: layout and the meaning; a skill file's manifest records a copy, which loading checks but never uses).
PARAM_SPECS: dict[str, ParamSpec] = {
    "Reacher": ParamSpec(3, _WORKSPACE_LOW, _WORKSPACE_HIGH, _POINT),
    "ReacherStabilised": ParamSpec(3, _WORKSPACE_LOW, _WORKSPACE_HIGH, _POINT),
    "Reacher3D": ParamSpec(3, _WORKSPACE_LOW, _WORKSPACE_HIGH, _POINT),
    "ReacherHandover": ParamSpec(3, _WORKSPACE_LOW, _WORKSPACE_HIGH, _POINT),
    "MoverPlain": ParamSpec(3, _WORKSPACE_LOW, _WORKSPACE_HIGH, _TARGET),
    "MoverNoised": ParamSpec(3, _WORKSPACE_LOW, _WORKSPACE_HIGH, _TARGET),
    "Gripper": ParamSpec(0, (), (), "none: grips the capsule nearest the claw"),
}
#: Tasks whose skills bring the hand to a point (their parameter is the point H must reach).
POINT_TASKS = frozenset({"Reacher", "ReacherStabilised", "Reacher3D", "ReacherHandover"})
#: Tasks whose skills move the capsule to a point (their parameter is the capsule's target).
MOVE_TASKS = frozenset({"MoverPlain", "MoverNoised"})
#: The hand-over parameterisation of a moving skill on a task with a target: the Manager's target is an offset of at
#: most 10 cm each way from the task's own target T (docs/skills.md, "Skills that hand over").
HANDOVER_TARGET = ParamSpec(3, (-0.1, -0.1, -0.1), (0.1, 0.1, 0.1), "offset of the capsule's target from the task's "
                            "target T (x, y, z), metres", frame="target")  # fmt: skip
#: The hand-over parameterisation of a point skill: the Manager's goal is an offset from the capsule, at most 5 cm
#: aside and 0-20 cm above its centre: where a grip starts (docs/skills.md, "Skills that hand over").
HANDOVER_POINT = ParamSpec(3, (-0.05, -0.05, 0.0), (0.05, 0.05, 0.20), "offset of the hand's goal from the capsule's "
                           "centre C (x, y, z), metres", frame="capsule")  # fmt: skip
#: The pre-grasp parameterisation of a point skill (``Handover.pregrasp``): an offset at most 3 cm aside and 0-8 cm above
#: C, centred 4 cm above it (the lowest goal ReacherHandover trains on), so that a Manager's first goals already leave the
#: palm where a Gripper starts (within 9 cm of C), not HANDOVER_POINT's centre 10 cm up.
HANDOVER_PREGRASP = ParamSpec(3, (-0.03, -0.03, 0.0), (0.03, 0.03, 0.08), "offset of the hand's pre-grasp goal from the "
                              "capsule's centre C (x, y, z), metres", frame="capsule")  # fmt: skip


#: Height of the capsule's centre above its resting height, metres, above which it counts as lifted (held): a capsule in
#: the claw of a Gripper that gripped it sits 1.1-3.4 cm up (the recorded held starts), one resting on the table 0 cm.
CAPSULE_LIFTED = 0.01
#: Where a Gripper or a Mover that grips for itself starts when its task does not say (GripperTask's and MoverTask's
#: starts: the palm at most 9 cm from the capsule's centre), metres.
GRIP_START_REACH = 0.09


@dataclass(frozen=True)
class Initiation:
    """A skill's initiation set (an option's, Sutton, Precup & Singh 1999): the states it may start from, those like the
    ones it was trained from, tested on the base observation (H = obs[18:21], C = obs[21:24]).

    ``capsule`` is 'any', 'resting' (C at most :data:`CAPSULE_LIFTED` above its resting height) or 'lifted' (above it);
    ``hand_within``, if set, bounds d(H, C) in metres. :func:`initiation_for` declares each skill's from its training
    task; a Manager's environment with ``Handover.initiation`` runs a choice outside its skill's set as another skill.
    """

    capsule: str = "any"
    """'any', 'resting' or 'lifted'."""
    hand_within: float | None = None
    """Largest d(H, C) the skill starts from, metres (None: anywhere)."""

    def __post_init__(self) -> None:
        if self.capsule not in ("any", "resting", "lifted"):
            raise ValueError(f"Initiation.capsule must be 'any', 'resting' or 'lifted', got {self.capsule!r}")
        h = self.hand_within
        if h is not None and (isinstance(h, bool) or not isinstance(h, int | float) or not (0 < h < np.inf)):
            raise ValueError(f"Initiation.hand_within must be a positive number of metres or None, got {h!r}")

    def holds(self, base_obs: np.ndarray) -> np.ndarray:
        """Whether each state is in the set: ``[N, >=24] -> [N]`` bool."""
        obs = np.asarray(base_obs, dtype=np.float64).reshape(len(base_obs), -1)
        ok = np.ones(len(obs), dtype=bool)
        if self.capsule != "any":
            lifted = obs[:, 23] - CAPSULE_REST_Z > CAPSULE_LIFTED
            ok &= lifted if self.capsule == "lifted" else ~lifted
        if self.hand_within is not None:
            ok &= np.linalg.norm(obs[:, 18:21] - obs[:, 21:24], axis=1) <= self.hand_within
        return ok

    def describe(self) -> str:
        """One phrase, e.g. 'the capsule resting' or 'the hand within 9 cm of the capsule'."""
        parts = [] if self.capsule == "any" else [f"the capsule {self.capsule}"]
        if self.hand_within is not None:
            parts.append(f"the hand within {self.hand_within * 100:g} cm of the capsule")
        return " and ".join(parts) or "anywhere"


def initiation_for(task: str, task_kwargs: dict[str, Any] | None = None) -> Initiation:
    """The initiation set of a skill trained on ``task`` with ``task_kwargs``, declared here once from the task's start
    states: a Reacher (:data:`POINT_TASKS`) starts anywhere with the capsule resting; a Gripper, with the palm within its
    ``start_distance``'s upper end (default 9 cm); a Mover trained from held starts (``starts='held'``), with the
    capsule lifted; any other Mover, with the palm within 9 cm; a skill of any other task, anywhere. Raises a one-line
    ValueError for task settings it cannot read."""
    kw = task_kwargs or {}
    if task in POINT_TASKS:
        return Initiation(capsule="resting")
    if task == "Gripper":
        reach = kw.get("start_distance", (0.05, GRIP_START_REACH))
        if not isinstance(reach, list | tuple) or len(reach) != 2 or not all(_is_number(r) for r in reach):
            raise ValueError(f"a Gripper's start_distance must be two numbers of metres, got {reach!r}")
        return Initiation(hand_within=float(reach[1]))
    if task in MOVE_TASKS:
        return Initiation(capsule="lifted") if kw.get("starts") == "held" else Initiation(hand_within=GRIP_START_REACH)
    return Initiation()


def _is_number(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and bool(np.isfinite(v))


class ArmSkill(Skill):
    """A frozen arm skill: ``torques(base_obs [N, 24], params [N, dim], features [N, F]) -> [N, 9]`` (the policy's mean
    action); as a generic skill (:class:`hrlp.skills.core.Skill`) it reads the parts ``base`` and its features.

    Attributes:
        name: the skill's name in the library.
        task: the task it was trained on.
        param: its parameter specification.
        k: its default duration in low-level steps.
        content_hash: sha256 of its weights file (changes if and only if the weights change).
        features: the named observation features it reads after its parameters (:data:`OBS_FEATURES`; none for the
            paper's skills), ``feature_dim`` numbers in all.
        initiation: the states it may start from (:func:`initiation_for` its training task; default anywhere).
    """

    def __init__(self, name: str, task: str, param: ParamSpec, k: int, policy: GaussianPolicy,
                 normalizer: RunningNormalizer, content_hash: str, features: tuple[str, ...] = (),
                 initiation: Initiation | None = None) -> None:  # fmt: skip
        if k < 1:
            raise ValueError(f"skill {name}: default duration k must be >= 1, got {k}")
        self.features = check_features(features, f"skill {name}")
        self.initiation = initiation or Initiation()
        self.name, self.task, self.param, self.k, self.content_hash = name, task, param, int(k), content_hash
        for p in policy.parameters():
            p.requires_grad_(False)  # frozen: a skill never enters a trust region
        self.policy = policy.eval()
        normalizer.freeze()
        self.normalizer = normalizer
        self._mean = NumpyMLP(policy.mean_net)
        self.feature_dim = features_dim(self.features)
        self.obs_dim = BASE_OBS_DIM + param.dim + self.feature_dim
        self.params = param.box()
        self.reads = ("base", *self.features)

    def observation(self, base_obs: np.ndarray, params: np.ndarray, features: np.ndarray | None = None) -> np.ndarray:
        """The skill's own observation: the 24 base numbers, its parameters, then its features (in the order of
        :attr:`features`). [N, obs_dim]"""
        base = np.asarray(base_obs, dtype=np.float64)
        if base.ndim != 2 or base.shape[1] < BASE_OBS_DIM:
            raise ValueError(f"skill {self.name}: base observations must have shape [N, >=24], got {base.shape}")
        p = np.asarray(params, dtype=np.float64).reshape(base.shape[0], self.param.dim)
        if not self.features:
            return np.concatenate([base[:, :BASE_OBS_DIM], p], axis=1)
        if features is None:
            raise ValueError(f"skill {self.name} reads the observation features {', '.join(self.features)}; pass them "
                             f"([N, {self.feature_dim}])")  # fmt: skip
        f = np.asarray(features, dtype=np.float64)
        if f.shape != (base.shape[0], self.feature_dim):
            raise ValueError(f"skill {self.name}: features ({', '.join(self.features)}) must have shape "
                             f"[{base.shape[0]}, {self.feature_dim}], got {list(f.shape)}")  # fmt: skip
        return np.concatenate([base[:, :BASE_OBS_DIM], p, f], axis=1)

    def features_of(self, physics: Sequence[ArmPhysics]) -> np.ndarray | None:
        """The features this skill reads in each world's current state, ``[N, feature_dim]`` (None if it reads none)."""
        if not self.features:
            return None
        return np.stack([np.concatenate([p.feature(f) for f in self.features]) for p in physics])

    def act(self, obs: ObsView, params: np.ndarray) -> np.ndarray:
        """The generic skill's actions: :meth:`torques` of the part ``base`` and the features read by name."""
        seen = np.concatenate([obs[f] for f in self.features], axis=1) if self.features else None
        return self.torques(obs["base"], params, seen)

    def initiable(self, obs: ObsView) -> np.ndarray:
        """Whether each state is in :attr:`initiation`."""
        return self.initiation.holds(obs["base"])

    def torques(self, base_obs: np.ndarray, params: np.ndarray, features: np.ndarray | None = None) -> np.ndarray:
        """Torques in [-1, 1] for ``N`` states: ``[N, 24] x [N, dim] (x [N, feature_dim]) -> [N, 9]``; rejects NaN/inf
        inputs, and missing or misshapen features for a skill that reads them."""
        obs = self.observation(base_obs, params, features)
        if not np.isfinite(obs).all():
            raise ValueError(f"skill {self.name}: observation, parameters or features contain NaN or inf")
        a = self._mean(self.normalizer.normalize(obs))
        return np.clip(a, -1.0, 1.0).reshape(obs.shape[0], N_JOINTS)


def check_features(features: object, who: str) -> tuple[str, ...]:
    """``features`` as a tuple of distinct known feature names (:data:`OBS_FEATURES`); a one-line ValueError naming
    ``who`` otherwise."""
    if not isinstance(features, list | tuple) or not all(isinstance(f, str) for f in features):
        raise ValueError(f"{who}: features must be a list of feature names, got {features!r}")
    if unknown := [f for f in features if f not in OBS_FEATURES]:
        raise ValueError(f"{who}: unknown observation feature(s) {', '.join(map(repr, unknown))} "
                         f"(known: {', '.join(OBS_FEATURES)})")  # fmt: skip
    if len(set(features)) != len(features):
        raise ValueError(f"{who}: features {list(features)} name one feature twice")
    return tuple(features)


def features_dim(features: tuple[str, ...]) -> int:
    """How many numbers the named features take: the sum of their widths in :data:`OBS_FEATURES`."""
    return sum(OBS_FEATURES[f] for f in features)
