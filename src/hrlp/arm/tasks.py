"""The paper's tasks on the arm: start distributions, reward terms and success tests.

Each task is a frozen dataclass of its settings (the paper's constants are constructor
arguments) and implements :class:`Task`. Tasks never step physics; the environment
(``hrlp.arm.env.ArmEnv``) does, and asks the task for rewards after every step.

Start distributions (docs/environments.md, "Start distributions"). The capsule lies on the
table with its centre on a circle of radius :data:`CIRCLE_RADIUS` around the arm's base axis
(the vertical line through the shoulder, x = -0.15, y = 0), which the hand reaches at every angle
(sampled reachability: ``tests/envs/test_reachability.py``). Hand starts are solved by inverse
kinematics from random joint angles and rejected if the arm touches the table or the capsule.
"""

from __future__ import annotations

import abc
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from hrlp.arm.physics import BASE_AXIS_XY, CAPSULE_REST_Z, N_JOINTS, OBS_FEATURES, ArmPhysics
from hrlp.paths import default_library_root

#: Radius (metres) of the circle around the base axis on which capsules and palms start.
#: Sampling 200k random arm poses puts the hand within 2 cm of the table at every angle for radii
#: 0.2-0.4 m; 0.3 m sits in the middle of that band.
CIRCLE_RADIUS = 0.30
#: Height of the palm's (H's) start circle in the reach-and-grip experiments. At 0.15 m the hand cannot
#: reach the angles behind the arm (|angle| > 140 degrees); at 0.08 m it reaches all of them.
PALM_CIRCLE_Z = 0.08
#: Least half-width (radians) of the palm's start angles in reach-and-grip, whatever the curriculum's w.
PALM_MIN_HALF_WIDTH = 0.3


def circle_point(angle: float, z: float = CAPSULE_REST_Z, radius: float = CIRCLE_RADIUS) -> np.ndarray:
    """The point at ``angle`` (radians, 0 = straight ahead along +x) on a circle around the base axis. [3]"""
    return np.array([BASE_AXIS_XY[0] + radius * math.cos(angle), BASE_AXIS_XY[1] + radius * math.sin(angle), z])


@dataclass(frozen=True)
class SparseSuccess:
    """Definition 1 (sparse reward): success if at some step d(H, C) < tr1 and d(FT1, FT2) < tr2.

    Defaults: tr1 = 0.05 m (the hand is on the capsule; the capsule's radius is 0.025 m) and
    tr2 = 0.03 m (the finger tips end about 0.017 m apart around a held capsule, 0.04 m open).
    """

    tr1: float = 0.05
    """Threshold on d(H, C), metres."""
    tr2: float = 0.03
    """Threshold on d(FT1, FT2), metres."""

    def __post_init__(self) -> None:
        _positive(self, "tr1", "tr2")

    def __call__(self, physics: ArmPhysics) -> bool:
        """Whether the current state satisfies both conditions."""
        return physics.finger_gap() < self.tr2 and physics.hand_to_capsule() < self.tr1


class Task(abc.ABC):
    """What a task owns: its start distribution, reward terms, success test and extra observations."""

    #: Numbers appended after the 24 base observations (e.g. the Reacher's goal).
    extra_obs_dim: int = 0
    #: Whether the observation holds the task's target T at obs[24:27] (a Manager's parameter may then be relative to it).
    observes_target: bool = False
    #: Named observation features (:data:`hrlp.arm.physics.OBS_FEATURES`) that end the extra observations, in order: a
    #: skill trained on the task is given them wherever it acts (a Manager's environment computes them from its physics).
    observed_features: tuple[str, ...] = ()
    #: Names of per-step quantities the environment sums over the episode and reports in ``info``.
    tracked: tuple[str, ...] = ()
    #: Names of per-step quantities whose largest value over the episode (from its start state on) the environment
    #: reports in ``info`` as ``NAME_max``.
    tracked_max: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        """Short task name used in messages."""
        return type(self).__name__.removesuffix("Task")

    @abc.abstractmethod
    def reset(self, physics: ArmPhysics, rng: np.random.Generator, episode: int) -> None:
        """Set the start state; ``episode`` counts the environment's earlier episodes (for curricula)."""

    @abc.abstractmethod
    def reward_terms(self, physics: ArmPhysics) -> dict[str, float]:
        """The reward's terms; the reward is their sum."""

    @abc.abstractmethod
    def success(self, physics: ArmPhysics) -> bool:
        """Whether the current state counts as success (an episode succeeds if any step does)."""

    def extra_observation(self, physics: ArmPhysics, out: np.ndarray) -> None:
        """Write the task's extra observations into ``out`` [extra_obs_dim] (none by default)."""
        return None

    def track(self, physics: ArmPhysics) -> tuple[float, ...]:
        """Per-step values of :attr:`tracked`."""
        return ()

    def track_max(self, physics: ArmPhysics) -> tuple[float, ...]:
        """Per-step values of :attr:`tracked_max`."""
        return ()

    def episode_state(self) -> dict[str, np.ndarray]:
        """The task's own per-episode state (e.g. the Reacher's goal), for exact save and restore."""
        return {}

    def set_episode_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore :meth:`episode_state`."""
        return None


# --- start-state helpers ----------------------------------------------------------------------


class StartError(RuntimeError):
    """A start distribution could not produce a valid state (the arm cannot reach the requested point)."""


def random_arm(physics: ArmPhysics, rng: np.random.Generator, *, min_hand_z: float = 0.08, tries: int = 200) -> None:
    """Random joint angles (uniform over the ranges, fingers open) with the arm clear of table and capsule."""
    lo, hi = physics.joint_range[:, 0], physics.joint_range[:, 1]
    for _ in range(tries):
        q = rng.uniform(lo, hi)
        q[7:] = 0.0
        physics.set_arm(q)
        physics.forward()
        if physics.hand[2] >= min_hand_z and physics.arm_contacts() == 0:
            return
    raise StartError(f"no collision-free random arm pose with the hand above {min_hand_z} m in {tries} tries")


def arm_with_hand_at(
    physics: ArmPhysics,
    rng: np.random.Generator,
    goal: np.ndarray | Callable[[], np.ndarray],
    *,
    tol: float = 0.01,
    tries: int = 40,
    fingers: float | Callable[[], float] = 0.0,
) -> np.ndarray:
    """Put H at ``goal`` (within ``tol``) by inverse kinematics from random joint angles, arm clear of contacts.

    ``goal`` may be a callable that draws a new goal for each try (a start region rather than a
    point); so may ``fingers``, the opening of each finger in radians (0: the model's rest, tips
    4 cm apart; about 0.8 lets the capsule between them). Returns the goal reached. Raises
    :class:`StartError` if no try succeeds.
    """
    lo, hi = physics.joint_range[:, 0], physics.joint_range[:, 1]
    best = np.inf
    for _ in range(tries):
        g = goal() if callable(goal) else goal
        opening = float(fingers() if callable(fingers) else fingers)
        q0 = rng.uniform(lo, hi)
        q0[7:] = (-opening, opening)  # rc_close < 0 and lc_close > 0 open the claw
        q, err = physics.solve_hand_ik(g, q0, tol=tol / 2)
        best = min(best, err)
        if err > tol:
            continue
        physics.set_arm(q)
        physics.forward()
        if physics.arm_contacts() == 0:
            return g
    raise StartError(f"the hand cannot reach {np.round(g, 3).tolist()} without contact (best error {best:.3f} m)")


def is_reachable(
    physics: ArmPhysics, point: np.ndarray, rng: np.random.Generator, *, tol: float = 0.01, tries: int = 20
) -> bool:
    """Whether some joint configuration puts H within ``tol`` of ``point`` (IK from random starts, contacts ignored)."""
    lo, hi = physics.joint_range[:, 0], physics.joint_range[:, 1]
    return any(physics.solve_hand_ik(point, rng.uniform(lo, hi), tol=tol / 2)[1] < tol for _ in range(tries))


def _upper_offset(rng: np.random.Generator, r_min: float, r_max: float, lift: float = 0.5) -> np.ndarray:
    """A random offset of length U(r_min, r_max) pointing into the upper half-space."""
    direction = rng.normal(size=3)
    direction[2] = abs(direction[2]) + lift  # away from the table
    return rng.uniform(r_min, r_max) * direction / np.linalg.norm(direction)


def _angle(rng: np.random.Generator, half_width: float) -> float:
    return float(rng.uniform(-half_width, half_width)) if half_width > 0 else 0.0


def _place_capsule(physics: ArmPhysics, angle: float) -> np.ndarray:
    c = circle_point(angle)
    physics.set_capsule(c, yaw=angle + math.pi / 2)  # axis tangent to the circle
    return c


def _hide_target(physics: ArmPhysics) -> None:
    # Tasks without a target park the shadow capsule out of view (it never collides).
    physics.set_target(np.array([0.0, 0.0, -1.0]))


def _positive(obj: object, *names: str) -> None:
    for n in names:
        v = getattr(obj, n)
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ValueError(f"{type(obj).__name__}.{n} must be a positive number, got {v!r}")


def _nonneg(obj: object, *names: str) -> None:
    for n in names:
        v = getattr(obj, n)
        if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
            raise ValueError(f"{type(obj).__name__}.{n} must be a non-negative number, got {v!r}")


# --- Reacher ----------------------------------------------------------------------------------

REACHER_VARIANTS = ("normal", "stabilised", "3d", "handover")


#: The handover Reacher's goals: the capsule's centre plus an offset in this box (metres; never inside the capsule).
HANDOVER_GOAL_LOW, HANDOVER_GOAL_HIGH = np.array([-0.05, -0.05, 0.04]), np.array([0.05, 0.05, 0.20])


def claw_closure(physics: ArmPhysics) -> float:
    """How far the claw is from open and symmetric, radians: the closing part of each finger joint (rc_close > 0,
    lc_close < 0) plus their asymmetry |rc_close + lc_close|; 0 for any symmetric opening."""
    rc, lc = float(physics.qpos[N_JOINTS - 2]), float(physics.qpos[N_JOINTS - 1])
    return max(rc, 0.0) + max(-lc, 0.0) + abs(rc + lc)


@dataclass
class ReacherTask(Task):
    """Reacher (Section 4.1, Experiment 3; Section 4.2.2): bring the hand H to a 3-d goal.

    Reward: -d(H, goal), plus for the Stabilised variant -level_coeff * |z-component of the
    forearm's axis| (zero when the forearm is parallel to the table). The goal is appended to the
    observation (obs[24:27]); as a skill, this goal is the parameter the Manager passes.

    Variants (start distributions):
      - normal: the capsule lies on the table at a random angle on the circle; the goal is a
        point 0-6 cm above its centre (the paper: "moving hand to the location of the capsule").
      - stabilised: as normal, with the forearm-level reward term.
      - 3d: the goal is the hand position of a random collision-free arm pose with the hand
        at least 5 cm above the table, so it is reachable by construction; the capsule lies on
        the circle at a random angle.
      - handover: a Reacher that leaves a state the Gripper can take over. The goal is a pre-grasp
        point, never inside the capsule: its centre plus an offset in the hand-over box (x, y within
        5 cm, z 4-20 cm above, :data:`HANDOVER_GOAL_LOW`/``HIGH``), redrawn where the hand cannot reach
        it (high points behind the arm). Two more reward terms:
        -capsule_coeff * d(C, C_0) (moving the capsule from where it lay costs) and -claw_coeff *
        (closure + asymmetry of the two finger joints) (the claw arrives open and symmetric). Success
        also needs the capsule within 1 cm of where it lay.
    The arm starts in a random collision-free pose. Success: d(H, goal) < success_tol.
    """

    variant: str = "normal"
    """One of 'normal', 'stabilised', '3d'."""
    level_coeff: float = 0.5
    """Weight of the forearm-level term (stabilised variant only)."""
    success_tol: float = 0.03
    """A step succeeds when d(H, goal) is below this, metres."""
    capsule_coeff: float = 5.0
    """Weight of d(C, C_0), the capsule's displacement from where it lay (handover variant only)."""
    claw_coeff: float = 0.1
    """Weight of the claw's closure and asymmetry, radians (handover variant only)."""
    goal: np.ndarray = field(default_factory=lambda: np.zeros(3), init=False, compare=False, repr=False)
    """The current episode's goal (episode state, set by ``reset``). [3]"""
    start_capsule: np.ndarray = field(default_factory=lambda: np.zeros(3), init=False, compare=False, repr=False)
    """Where the capsule lay at the episode's start (episode state). [3]"""
    extra_obs_dim = 3

    def __post_init__(self) -> None:
        if self.variant not in REACHER_VARIANTS:
            raise ValueError(f"ReacherTask.variant must be one of {REACHER_VARIANTS}, got {self.variant!r}")
        _nonneg(self, "level_coeff", "capsule_coeff", "claw_coeff")
        _positive(self, "success_tol")

    @property
    def name(self) -> str:
        return {"normal": "Reacher", "stabilised": "ReacherStabilised", "3d": "Reacher3D", "handover": "ReacherHandover"}[
            self.variant
        ]

    def reset(self, physics: ArmPhysics, rng: np.random.Generator, episode: int) -> None:
        _hide_target(physics)
        c = _place_capsule(physics, _angle(rng, math.pi))
        if self.variant == "3d":
            random_arm(physics, rng, min_hand_z=0.05)
            self.goal[:] = physics.hand
        elif self.variant == "handover":
            for _ in range(50):  # goals the hand cannot reach (high ones behind the arm) are redrawn
                self.goal[:] = c + rng.uniform(HANDOVER_GOAL_LOW, HANDOVER_GOAL_HIGH)
                if is_reachable(physics, self.goal, rng, tries=8):
                    break
            else:
                raise StartError(f"no reachable pre-grasp goal above the capsule at {np.round(c, 3).tolist()}")
        else:
            self.goal[:] = c + np.array([0.0, 0.0, rng.uniform(0.0, 0.06)])
        random_arm(physics, rng)
        self.start_capsule[:] = physics.capsule

    def reward_terms(self, physics: ArmPhysics) -> dict[str, float]:
        h, g = physics.hand, self.goal
        terms = {"distance": -math.dist(h, g)}
        if self.variant == "stabilised":
            terms["level"] = -self.level_coeff * abs(float(physics.forearm_axis[2]))
        elif self.variant == "handover":
            terms["capsule"] = -self.capsule_coeff * math.dist(physics.capsule, self.start_capsule)
            terms["claw"] = -self.claw_coeff * claw_closure(physics)
        return terms

    def success(self, physics: ArmPhysics) -> bool:
        reached = math.dist(physics.hand, self.goal) < self.success_tol
        return reached and (self.variant != "handover" or math.dist(physics.capsule, self.start_capsule) < 0.01)

    def extra_observation(self, physics: ArmPhysics, out: np.ndarray) -> None:
        out[:] = self.goal

    def episode_state(self) -> dict[str, np.ndarray]:
        return {"goal": self.goal.copy(), "start_capsule": self.start_capsule.copy()}

    def set_episode_state(self, state: dict[str, np.ndarray]) -> None:
        self.goal[:] = state["goal"]
        if "start_capsule" in state:  # states saved before the handover variant lack it
            self.start_capsule[:] = state["start_capsule"]


# --- Gripper and reach-and-grip -----------------------------------------------------------------


#: What :class:`GripReward` may measure as d(H, C): the capsule's centre (the paper) or its axis segment.
GRIP_DISTANCES = ("centre", "axis")


@dataclass(frozen=True)
class GripReward:
    """The Gripper's reward (Section 4.1, Experiment 1): c1 d(H,C) + c2 1[d(H,C) < tr] + c3 d(FT1,FT2).

    Requires c1, c3 < 0 < c2 and tr > 0. Defaults: c2 = 3, tr = 0.03, the cell of the paper's grid
    (Figures 6 and 7) where three of Figure 7's four Managers score highest, with the flat runs' c1 = -1
    and c3 = -4 (Section 4.3.2).
    An optional fourth term, ``c4 1[Definition 1 holds now]`` (c4 >= 0, default 0: the paper's
    reward), pays for the gripped state itself; the shipped Gripper skill trains with it.

    ``distance`` chooses what d(H, C) measures in the first two terms: ``"centre"`` (the paper: the
    distance to the capsule's centre of mass) or ``"axis"`` (the distance to the capsule's axis segment,
    :meth:`~hrlp.arm.physics.ArmPhysics.hand_to_capsule_axis`). A claw holds the 12 cm capsule wherever
    it closes along it: with the shipped Gripper, H is a median 3.2 cm from C but 1.1 cm from the axis
    while gripped, so under ``"centre"`` at tr = 0.03 a grip rarely earns the bonus and hovering over the
    centre with an open claw pays more; under ``"axis"`` gripping pays most. Definition 1 (the success
    test) is unchanged.
    """

    c1: float = -1.0
    """Weight of d(H, C) (negative)."""
    c2: float = 3.0
    """Bonus while d(H, C) < tr (positive)."""
    c3: float = -4.0
    """Weight of d(FT1, FT2) (negative: closing the claw is rewarded)."""
    tr: float = 0.03
    """Distance threshold of the bonus, metres."""
    c4: float = 0.0
    """Bonus while the sparse-success condition holds (0: the paper's three-term reward)."""
    distance: str = "centre"
    """What d(H, C) measures: ``"centre"`` (the capsule's centre, the paper) or ``"axis"`` (its axis segment)."""

    def __post_init__(self) -> None:
        for n in ("c1", "c2", "c3", "tr", "c4"):
            v = getattr(self, n)
            if not (isinstance(v, int | float) and math.isfinite(v)):
                raise ValueError(f"grip reward {n} must be a finite number, got {v!r}")
        if not (self.c1 < 0 and self.c3 < 0 < self.c2):
            raise ValueError(f"grip reward needs c1, c3 < 0 < c2, got c1={self.c1}, c2={self.c2}, c3={self.c3}")
        _positive(self, "tr")
        _nonneg(self, "c4")
        if self.distance not in GRIP_DISTANCES:
            raise ValueError(f"grip reward distance must be one of {', '.join(GRIP_DISTANCES)}, got {self.distance!r}")

    def terms(self, physics: ArmPhysics) -> dict[str, float]:
        """The three terms for the current state."""
        d = physics.hand_to_capsule() if self.distance == "centre" else physics.hand_to_capsule_axis()
        return {
            "distance": self.c1 * d,
            "bonus": self.c2 if d < self.tr else 0.0,
            "fingers": self.c3 * physics.finger_gap(),
        }


def _grip_terms(reward: GripReward, sparse: SparseSuccess, physics: ArmPhysics, held: bool | None = None) -> dict[str, float]:
    """GripReward's terms, with ``c4`` paid while Definition 1 holds (``held``, evaluated here if not given)."""
    terms = reward.terms(physics)
    if reward.c4:
        terms["gripped"] = reward.c4 if (sparse(physics) if held is None else held) else 0.0
    return terms


#: The bank name under which ``hrlp dagger`` stores hand-over states.
HANDOVER_BANK = "handover"


@functools.cache
def start_bank(path: str, name: str = HANDOVER_BANK) -> tuple[np.ndarray, np.ndarray]:
    """The ``(qpos [S, nq], qvel [S, nv])`` start states stored under ``name`` in the ``.npz`` at ``path`` (no pickle).

    Raises ValueError naming the file for a missing file, a file that is not such a bank, or non-finite states."""
    try:
        with np.load(path, allow_pickle=False) as z:
            qpos, qvel = z[f"{name}_qpos"].astype(np.float64), z[f"{name}_qvel"].astype(np.float64)
    except (OSError, KeyError, ValueError) as e:
        raise ValueError(f"start bank {path}: cannot read its {name!r} states ({e})") from None
    if qpos.ndim != 2 or qvel.ndim != 2 or len(qpos) != len(qvel) or len(qpos) == 0:
        raise ValueError(f"start bank {path}: {name!r} states must be [S, nq] and [S, nv] with S > 0, got "
                         f"{qpos.shape} and {qvel.shape}")  # fmt: skip
    if not (np.isfinite(qpos).all() and np.isfinite(qvel).all()):
        raise ValueError(f"start bank {path}: {name!r} states contain NaN or inf")
    return qpos, qvel


#: Where ``GripperTask(starts="recovery")`` draws its bank from: states just after ``gripper-clearance``'s own greedy
#: episodes pushed the capsule more than 3 cm (``python benchmarks/gripper_recovery.py`` writes it).
GRIPPER_RECOVERY_STARTS_FILE = "assets/gripper_recovery_starts.npz"
#: Where ``GripperTask(starts="recovery-2")`` draws its bank from: the same for ``gripper-recovery``'s own episodes (the
#: second round; ``python benchmarks/gripper_recovery.py --skill gripper-recovery --first-seed 1000000`` writes it).
GRIPPER_RECOVERY_2_STARTS_FILE = "assets/gripper_recovery_2_starts.npz"
#: The start banks shipped with hrlp, by the name ``GripperTask.starts`` takes for them.
GRIPPER_BANKS = {"recovery": GRIPPER_RECOVERY_STARTS_FILE, "recovery-2": GRIPPER_RECOVERY_2_STARTS_FILE}


#: The folder of a skill library that holds the start banks ``hrlp skills build`` records (a skill's name cannot start
#: with a dot, so it is never taken for a skill).
BANKS_DIR = ".banks"


def bank_file(asset: str) -> Path:
    """Where the start bank shipped as ``asset`` (a path under the package, ``assets/NAME.npz``) is read from: the skill
    library's ``.banks/NAME.npz`` (``$HRLP_SKILLS``), which ``hrlp skills build`` writes from the skills it built, where
    there is one; else the package's own."""
    own = default_library_root() / BANKS_DIR / Path(asset).name
    return own if own.is_file() else Path(str(resources.files("hrlp.arm").joinpath(asset)))


def gripper_start_bank(starts: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`start_bank` of ``starts``: a shipped bank's name (:data:`GRIPPER_BANKS`, read from :func:`bank_file`) or
    the path of a bank."""
    return start_bank(str(bank_file(GRIPPER_BANKS[starts])) if starts in GRIPPER_BANKS else starts)


@dataclass(frozen=True)
class GripperTask(Task):
    """Gripper (Section 4.1, Experiment 1): grip the capsule with the palm starting close to it.

    Start: the capsule lies on the circle at a random angle in [-angle_range, angle_range]; H
    starts at a random point ``start_distance`` (default 5-9 cm) from the capsule's centre in the
    upper half-space, each finger opened by a random angle in ``finger_opening`` (default 0: at
    rest, tips 4 cm apart), the claw clear of the capsule. The capsule (5 cm across) only fits
    between fingers opened by about 0.8 rad, so starts closer than 5 cm need an opening; the
    shipped Gripper skill trains on ``start_distance=(0, 0.09)``, ``finger_opening=(0, 1)``: the
    paper's "many close positions" (Section 4.1).
    With ``starts``, a share ``starts_fraction`` of the episodes begins instead from a physics state of a start
    bank (an ``.npz`` written by :func:`hrlp.arm.research.starts.write_start_bank`, read without pickle): the states at
    which a Manager handed over to the Gripper (``hrlp dagger``, the paper's Appendix C), or a shipped bank:
    ``"recovery"`` (``"recovery-2"``), states just after ``gripper-clearance`` (``gripper-recovery``) pushed the capsule
    away, from which it must still grip.
    Reward: :class:`GripReward`. Success: :class:`SparseSuccess` (Definition 1).
    """

    reward: GripReward = GripReward()
    """Reward constants c1, c2, c3, tr."""
    sparse: SparseSuccess = SparseSuccess()
    """Definition 1 thresholds."""
    starts: str | None = None
    """Path of a start bank (its ``handover_qpos``/``handover_qvel`` arrays), a shipped bank's name (``"recovery"``,
    ``"recovery-2"``: :data:`GRIPPER_BANKS`), or None for the task's own starts only."""
    starts_fraction: float = 1.0
    """With ``starts``, the share of episodes that begin from the bank (the rest from the task's own start set)."""
    angle_range: float = math.pi
    """Half-width of the capsule's start angle, radians (pi: the full circle)."""
    start_distance: tuple[float, float] = (0.05, 0.09)
    """Range of the start distance d(H, C), metres."""
    finger_opening: tuple[float, float] = (0.0, 0.0)
    """Range of each finger's start opening, radians (at most 1.05, the joint limit)."""
    push_coeff: float = 0.0
    """Weight of a fourth reward term, -push_coeff * the capsule's horizontal displacement from where it lay at the
    episode's start, paid while Definition 1 does not hold: knocking the capsule away costs, lifting it in the claw
    does not (0: the paper's reward)."""
    distance_curriculum: int = 0
    """Episodes (of each environment) over which the upper end of ``start_distance`` grows linearly from
    ``curriculum_from`` to its own value: a curriculum on the start distance, close starts first (0: none, the paper)."""
    curriculum_from: float = 0.03
    """With ``distance_curriculum``, the upper end of the start distance at the first episode, metres (clipped to
    ``start_distance``)."""
    observe_capsule: bool = False
    """Append the capsule's pose to the observation (:meth:`ArmPhysics.capsule_pose_features`: its axis and velocity,
    6 numbers) for a Gripper that sees how a pushed capsule lies (False: the paper's 24 numbers, as the shipped skills)."""
    observe_claw: bool = False
    """Append the claw's pose relative to the capsule after that (:meth:`ArmPhysics.claw_pose_features`: H, FT1 and FT2
    less C, the palm's x and y axes, 15 numbers): what a grip depends on at the scale of millimetres (False: not)."""
    observe_clearance: bool = False
    """Append each arm body's distance to the capsule after that (:meth:`ArmPhysics.arm_clearance_features`: upper arm,
    forearm, palm, the two fingers, 5 numbers, cut off at 5 cm): how close a start is to pushing the capsule away
    (False: not)."""
    start_capsule: np.ndarray = field(default_factory=lambda: np.zeros(3), init=False, compare=False, repr=False)
    """Where the capsule lay at the episode's start (episode state). [3]"""

    @property
    def extra_obs_dim(self) -> int:  # type: ignore[override]
        """The widths of :attr:`observed_features` (6 with :attr:`observe_capsule`, 15 more with :attr:`observe_claw`, 5
        more with :attr:`observe_clearance`)."""
        return sum(OBS_FEATURES[f] for f in self.observed_features)

    @property
    def observed_features(self) -> tuple[str, ...]:  # type: ignore[override]
        """``capsule_pose`` with :attr:`observe_capsule`, then ``claw_pose`` with :attr:`observe_claw`, then
        ``arm_clearance`` with :attr:`observe_clearance`."""
        return (
            ("capsule_pose",) * self.observe_capsule
            + ("claw_pose",) * self.observe_claw
            + ("arm_clearance",) * self.observe_clearance
        )

    def extra_observation(self, physics: ArmPhysics, out: np.ndarray) -> None:
        at = 0
        for name in self.observed_features:
            physics.write_feature(name, out[at:])
            at += OBS_FEATURES[name]

    def __post_init__(self) -> None:
        for flag in ("observe_capsule", "observe_claw", "observe_clearance"):
            if not isinstance(getattr(self, flag), bool):
                raise ValueError(f"GripperTask.{flag} must be true or false, got {getattr(self, flag)!r}")
        _nonneg(self, "angle_range", "push_coeff")
        for name, top in (("start_distance", 0.3), ("finger_opening", 1.05)):
            v = tuple(getattr(self, name))
            if (
                len(v) != 2
                or not all(isinstance(x, int | float) and math.isfinite(x) for x in v)
                or not 0 <= v[0] <= v[1] <= top
            ):
                raise ValueError(f"GripperTask.{name} must be a range (low, high) with 0 <= low <= high <= {top}, got {v!r}")
            object.__setattr__(self, name, (float(v[0]), float(v[1])))
        n = self.distance_curriculum
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise ValueError(f"GripperTask.distance_curriculum must be a whole number of episodes >= 0, got "
                             f"{self.distance_curriculum!r}")  # fmt: skip
        _positive(self, "curriculum_from")
        if not (isinstance(self.starts_fraction, int | float) and 0 <= self.starts_fraction <= 1):
            raise ValueError(f"GripperTask.starts_fraction must be in [0, 1], got {self.starts_fraction!r}")
        if self.starts is not None:
            gripper_start_bank(str(self.starts))  # a missing or malformed bank fails here, when the task is made

    def reset(self, physics: ArmPhysics, rng: np.random.Generator, episode: int) -> None:
        _hide_target(physics)
        if self.starts is not None and rng.uniform() < self.starts_fraction:
            qpos, qvel = gripper_start_bank(str(self.starts))
            i = int(rng.integers(len(qpos)))
            physics.set_state_vectors(qpos[i], qvel[i])
            physics.forward()
        else:
            c = _place_capsule(physics, _angle(rng, self.angle_range))
            (d0, d1), (f0, f1) = self.start_distance, self.finger_opening
            d1 = self.start_distance_high(episode)
            arm_with_hand_at(physics, rng, lambda: c + _upper_offset(rng, d0, d1), fingers=lambda: rng.uniform(f0, f1),
                             tries=200)  # fmt: skip
        self.start_capsule[:] = physics.capsule

    def start_distance_high(self, episode: int) -> float:
        """The upper end of the start distance at the ``episode``-th episode (0-based): ``start_distance[1]``, or on
        the curriculum the linear ramp from ``curriculum_from`` (clipped to ``start_distance``) to it."""
        d0, d1 = self.start_distance
        if not self.distance_curriculum or episode >= self.distance_curriculum:
            return d1
        first = min(max(self.curriculum_from, d0), d1)
        return first + (d1 - first) * episode / self.distance_curriculum

    def reward_terms(self, physics: ArmPhysics) -> dict[str, float]:
        if not self.push_coeff:
            return _grip_terms(self.reward, self.sparse, physics)
        held = self.sparse(physics)  # Definition 1, once per step for both terms that need it
        terms = _grip_terms(self.reward, self.sparse, physics, held)
        c, c0 = physics.capsule, self.start_capsule
        terms["push"] = 0.0 if held else -self.push_coeff * math.hypot(c[0] - c0[0], c[1] - c0[1])
        return terms

    def episode_state(self) -> dict[str, np.ndarray]:
        return {"start_capsule": self.start_capsule.copy()}

    def set_episode_state(self, state: dict[str, np.ndarray]) -> None:
        if "start_capsule" in state:  # states saved before the push term lack it
            self.start_capsule[:] = state["start_capsule"]

    def success(self, physics: ArmPhysics) -> bool:
        return self.sparse(physics)


@dataclass(frozen=True)
class ReachAndGripTask(Task):
    """reach-and-grip (Section 4.3): reach the capsule from afar and grip it.

    Experiment 1: the capsule is fixed (angle 0 on the circle); H starts on the palm circle (same
    radius, 8 cm above the table) at a random angle. Experiment 2: the capsule's angle and the
    palm's angle are drawn independently. Angles are uniform in [-w, w] with w = pi (the full
    circle), or, with the flat-baseline curriculum of Section 4.3.2, w = min(pi, k * alpha) after
    the k-th episode of this environment; the palm's range never narrows below
    [-PALM_MIN_HALF_WIDTH, PALM_MIN_HALF_WIDTH] (0.3 rad), as the palm right above the capsule has
    few contact-free poses. Reward: :class:`GripReward`. Success: Definition 1.
    """

    experiment: int = 1
    """1 (capsule fixed) or 2 (capsule and palm independent)."""
    reward: GripReward = GripReward()
    """Reward constants c1, c2, c3, tr."""
    sparse: SparseSuccess = SparseSuccess()
    """Definition 1 thresholds."""
    curriculum_alpha: float | None = None
    """Curriculum step alpha (radians per episode); None draws from the full circle from the start."""

    def __post_init__(self) -> None:
        if self.experiment not in (1, 2):
            raise ValueError(f"ReachAndGripTask.experiment must be 1 or 2, got {self.experiment!r}")
        if self.curriculum_alpha is not None:
            _positive(self, "curriculum_alpha")

    @property
    def name(self) -> str:
        return f"ReachAndGrip{self.experiment}"

    def angle_half_width(self, episode: int) -> float:
        """w = min(pi, k * alpha) after the k-th episode (pi without a curriculum)."""
        if self.curriculum_alpha is None:
            return math.pi
        return min(math.pi, episode * self.curriculum_alpha)

    def reset(self, physics: ArmPhysics, rng: np.random.Generator, episode: int) -> None:
        _hide_target(physics)
        w = self.angle_half_width(episode)
        _place_capsule(physics, _angle(rng, w) if self.experiment == 2 else 0.0)
        # A palm angle next to the capsule's can leave no contact-free pose; such angles are redrawn. Right above
        # the capsule only ~7% of IK poses are clear, so early in a curriculum (w ~ 0) the palm's range stays
        # at least PALM_MIN_HALF_WIDTH wide.
        palm_w = max(w, PALM_MIN_HALF_WIDTH)
        arm_with_hand_at(physics, rng, lambda: circle_point(_angle(rng, palm_w), z=PALM_CIRCLE_Z))

    def reward_terms(self, physics: ArmPhysics) -> dict[str, float]:
        return _grip_terms(self.reward, self.sparse, physics)

    def success(self, physics: ArmPhysics) -> bool:
        return self.sparse(physics)


# --- Mover and reach-and-move -------------------------------------------------------------------

MOVER_VARIANTS = ("plain", "noised")


#: What moving tasks report beyond TargetDistSum: ``closest_max`` = -min_t d(C, T) and ``lift_max`` = the capsule's
#: greatest height above its resting height (metres) over the episode.
MOVE_EXTREMES = ("closest", "lift")


def _move_extremes(physics: ArmPhysics) -> tuple[float, float]:
    return -physics.capsule_to_target(), float(physics.capsule[2]) - CAPSULE_REST_Z


#: Where ``MoverTask(starts="grip")`` draws its starts from (:data:`hrlp.arm.banks.BANKS`: ``grip``).
MOVER_STARTS_FILE = "assets/mover_starts.npz"
#: Where ``MoverTask(starts="held")`` draws its starts from (:data:`hrlp.arm.banks.BANKS`: ``held``).
MOVER_HELD_STARTS_FILE = "assets/mover_held_starts.npz"
MOVER_STARTS = ("grip", "placed", "held")


def grip_starts(variant: str, held: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The recorded ``(qpos [S, nq], qvel [S, nv])`` start states of the Mover ``variant`` (read without pickle):
    along a Gripper skill's successful episodes, or with ``held`` only those with the capsule in the claw."""
    return start_bank(str(bank_file(MOVER_HELD_STARTS_FILE if held else MOVER_STARTS_FILE)), variant)


@dataclass(frozen=True)
class MoverTask(Task):
    """Mover (Section 4.1, Experiment 2): move the capsule to the target T, palm starting close to it.

    Reward: -hand_coeff d(H, C) - target_coeff d(C, T). The target is appended to the
    observation (obs[24:27]); as a skill, it is the parameter the Manager passes.
    Start sets (``variant``): plain (small) has the capsule's angle within 0.2 rad of straight
    ahead and the target 10 cm above the capsule, jittered by up to 2 cm per axis; noised (large)
    has the capsule anywhere on the circle and the target 5-20 cm above it (5-8 cm behind the arm,
    |angle| > 2.2 rad, where the hand reaches only low points), shifted up to 8 cm horizontally;
    targets the hand cannot reach are redrawn. Where the palm starts (``starts``):
      - grip (default): a physics state recorded along an episode in which the shipped Gripper
        skill gripped the capsule (:mod:`hrlp.arm.research.starts`): the palm 0-9 cm from the capsule
        with the claw opening, closing, or closed around it.
      - placed: H 5.5-6.5 cm above the capsule's centre (plain; within 1 cm horizontally) or 5-10 cm
        from it in the upper half-space (noised), the claw at rest. Closer hand starts put a finger
        inside the capsule. From these starts a Mover never learned to grip (docs/research/skills-lineage.md).
      - held: a state recorded along an episode of the ``gripper-imitated`` skill in which the capsule is in the claw
        (Definition 1 holds): a Mover that only carries, after a Gripper has gripped.
    Success: d(C, T) < success_tol. Tracks d(C, T) so the episode's TargetDistSum is reported.
    """

    variant: str = "plain"
    """'plain' or 'noised'."""
    hand_coeff: float = 1.0
    """Weight of d(H, C)."""
    target_coeff: float = 1.0
    """Weight of d(C, T)."""
    success_tol: float = 0.03
    """A step succeeds when d(C, T) is below this, metres."""
    starts: str = "grip"
    """'grip' (states along the Gripper skill's successful episodes), 'placed' (hand placed by IK, claw at rest) or
    'held' (states with the capsule in the claw of the ``gripper-imitated`` skill)."""
    extra_obs_dim = 3
    observes_target = True
    tracked = ("target_dist",)
    tracked_max = MOVE_EXTREMES

    def __post_init__(self) -> None:
        if self.variant not in MOVER_VARIANTS:
            raise ValueError(f"MoverTask.variant must be one of {MOVER_VARIANTS}, got {self.variant!r}")
        if self.starts not in MOVER_STARTS:
            raise ValueError(f"MoverTask.starts must be one of {MOVER_STARTS}, got {self.starts!r}")
        _nonneg(self, "hand_coeff", "target_coeff")
        _positive(self, "success_tol")

    @property
    def name(self) -> str:
        return {"plain": "MoverPlain", "noised": "MoverNoised"}[self.variant]

    def reset(self, physics: ArmPhysics, rng: np.random.Generator, episode: int) -> None:
        if self.starts in ("grip", "held"):
            qpos, qvel = grip_starts(self.variant, held=self.starts == "held")
            i = int(rng.integers(len(qpos)))
            physics.set_state_vectors(qpos[i], qvel[i])
            physics.forward()
            c = physics.capsule.copy()
            angle = math.atan2(c[1] - BASE_AXIS_XY[1], c[0] - BASE_AXIS_XY[0])
        elif self.variant == "plain":
            c = _place_capsule(physics, _angle(rng, 0.2))
            above = lambda: c + np.array([*rng.uniform(-0.01, 0.01, size=2), rng.uniform(0.055, 0.065)])  # noqa: E731
            arm_with_hand_at(physics, rng, above)
        else:
            angle = _angle(rng, math.pi)
            c = _place_capsule(physics, angle)
            arm_with_hand_at(physics, rng, lambda: c + _upper_offset(rng, 0.05, 0.10, lift=0.3))
        if self.variant == "plain":
            physics.set_target(c + np.array([0.0, 0.0, 0.10]) + rng.uniform(-0.02, 0.02, size=3))
            return
        start = physics.qpos.copy()
        # Behind the arm (|angle| > 2.2 rad) the hand reaches only low points (docs/environments.md).
        top = 0.08 if abs(angle) > 2.2 else 0.20
        for _ in range(50):  # targets the hand cannot reach are redrawn
            target = c + np.array([*rng.uniform(-0.08, 0.08, size=2), rng.uniform(0.05, top)])
            # IK warm-started from the hand's start pose (the target is near it) settles most draws at once.
            if physics.solve_hand_ik(target, start, tol=0.005)[1] < 0.01 or is_reachable(physics, target, rng, tries=4):
                break
        else:
            raise StartError(f"no reachable target above the capsule at {np.round(c, 3).tolist()}")
        physics.set_target(target)

    def reward_terms(self, physics: ArmPhysics) -> dict[str, float]:
        return {
            "reach": -self.hand_coeff * physics.hand_to_capsule(),
            "move": -self.target_coeff * physics.capsule_to_target(),
        }

    def success(self, physics: ArmPhysics) -> bool:
        return physics.capsule_to_target() < self.success_tol

    def extra_observation(self, physics: ArmPhysics, out: np.ndarray) -> None:
        out[:] = physics.target

    def track(self, physics: ArmPhysics) -> tuple[float, ...]:
        return (-physics.capsule_to_target(),)

    def track_max(self, physics: ArmPhysics) -> tuple[float, ...]:
        return _move_extremes(physics)


@dataclass(frozen=True)
class ReachAndMoveTask(Task):
    """reach-and-move (Section 4.2): reach the capsule and move it to the fixed target above it.

    Start: the capsule is fixed (angle 0 on the circle), the target fixed ``target_height`` above
    it, the arm in a random collision-free pose. Reward: -d(H, C) - TargetCoeff d(C, T). The
    episode's TargetDistSum = sum_t -d(C, T) is reported in ``info['target_dist_sum']``. The
    target is appended to the observation (obs[24:27]) so a Manager can pass it to a Mover.
    Success: d(C, T) < success_tol.
    """

    target_coeff: float = 1.0
    """TargetCoeff, the weight of d(C, T)."""
    target_height: float = 0.15
    """Height of the target above the capsule's centre, metres."""
    success_tol: float = 0.03
    """A step succeeds when d(C, T) is below this, metres."""
    extra_obs_dim = 3
    observes_target = True
    tracked = ("target_dist",)
    tracked_max = MOVE_EXTREMES

    def __post_init__(self) -> None:
        _nonneg(self, "target_coeff")
        _positive(self, "target_height", "success_tol")

    def reset(self, physics: ArmPhysics, rng: np.random.Generator, episode: int) -> None:
        c = _place_capsule(physics, 0.0)
        physics.set_target(c + np.array([0.0, 0.0, self.target_height]))
        random_arm(physics, rng)

    def reward_terms(self, physics: ArmPhysics) -> dict[str, float]:
        return {"reach": -physics.hand_to_capsule(), "move": -self.target_coeff * physics.capsule_to_target()}

    def success(self, physics: ArmPhysics) -> bool:
        return physics.capsule_to_target() < self.success_tol

    def extra_observation(self, physics: ArmPhysics, out: np.ndarray) -> None:
        out[:] = physics.target

    def track(self, physics: ArmPhysics) -> tuple[float, ...]:
        return (-physics.capsule_to_target(),)

    def track_max(self, physics: ArmPhysics) -> tuple[float, ...]:
        return _move_extremes(physics)


__all__ = [
    "CIRCLE_RADIUS",
    "N_JOINTS",
    "PALM_CIRCLE_Z",
    "GripReward",
    "GripperTask",
    "MoverTask",
    "ReachAndGripTask",
    "ReachAndMoveTask",
    "ReacherTask",
    "SparseSuccess",
    "StartError",
    "Task",
    "arm_with_hand_at",
    "circle_point",
    "is_reachable",
    "random_arm",
]
