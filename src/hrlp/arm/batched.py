"""``N`` worlds of one arm task stepped together, with observations, rewards and success tests as arrays over worlds.

:class:`BatchedArmEnv` implements :class:`~hrlp.envs.vector.VectorEnv` (same-step autoreset, see
:mod:`hrlp.envs.vector`) for hrlp's own arm tasks. Per step it hands the ``N`` worlds' torques to a physics backend
in one call, then computes every world's observation (the paper's 24 numbers and the task's extras), reward terms,
success test and tracked values with NumPy over worlds; only resets (one per episode) run per world, through the
task's own ``reset`` on a scratch :class:`~hrlp.arm.physics.ArmPhysics`.

Backends (``backend=``), both on one ``MjModel`` of the arm with eight 3-number sensors added (hand H, finger tips
FT1/FT2, capsule C, the capsule's and the forearm's axes, the claw's x and y axes), so that a world's measurements come
out of MuJoCo as one ``sensordata`` row instead of eight reads:

- ``"rollout"`` (the default): MuJoCo's ``mujoco.rollout`` module steps every world ``substeps`` physics steps in C
  in one call, on ``threads`` threads (1: the calling thread). ``rollout`` starts each call from the worlds'
  ``mjSTATE_FULLPHYSICS`` states and zeroes the constraint solver's warm start (``qacc_warmstart``) at the first
  substep of every control step, where :class:`~hrlp.arm.env.ArmEnv` carries it over from the last substep;
  the solver then converges to the same answer within its tolerance (1e-8) rather than to the same bits. Episodes
  agree with ArmEnv's to within 1e-7 in observations and rewards, not bit for bit (measured: at most 9e-8 over 4
  worlds x 400-600 steps of every registered arm task, random torques); truncation and success flags agreed exactly.
- ``"loop"``: one ``MjData`` per world, each stepped by ``mj_step`` from a Python loop (the baseline). It keeps
  every world's full integration state, so its episodes are bit-identical to ArmEnv's.

The measurements read after a step are those ArmEnv reads: joint angles and velocities after the last substep,
points (H, C, finger tips, axes) as MuJoCo computed them at the start of the last substep (``mj_step`` updates
positions before it integrates; the sensors record the same values). Rewards use the tasks' own formulas in the same
floating-point order, ``math.dist``/``math.hypot`` per world where the task uses them (CPython's correctly rounded
norm differs from the plain formula in the last bit for about one distance in five).

A physics instability (MuJoCo's bad position, velocity or acceleration reset) truncates the world's episode as in
ArmEnv: reward 0, the last good observation, ``infos['physics_unstable']``. The rollout backend detects it from the
world's clock (MuJoCo's reset sets it back to 0); with ``substeps=1`` an instability on an episode's first step
leaves the clock where a good step would and goes unseen.

This is also where a GPU backend (MuJoCo Warp, MJX) plugs in: it replaces the backend's ``step``; the task
arithmetic below is array code over worlds.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import mujoco
import mujoco.rollout
import numpy as np

from hrlp.arm.physics import (
    BASE_OBS_DIM,
    CAPSULE_REST_Z,
    CLEARANCE_BODIES,
    CLEARANCE_CUTOFF,
    N_JOINTS,
    OBS_FEATURES,
    ArmPhysics,
    PhysicsConfig,
    configure_model,
    model_xml,
)
from hrlp.arm.registry import TASKS, ArmEnvFactory
from hrlp.arm.tasks import (
    GripperTask,
    GripReward,
    MoverTask,
    ReachAndGripTask,
    ReachAndMoveTask,
    ReacherTask,
    SparseSuccess,
    Task,
)
from hrlp.envs.vector import VectorConstructor, VectorStep, check_actions, check_gamma, check_num_envs

#: Physics backends of :class:`BatchedArmEnv`; the first is the default (measured faster: docs/benchmarks.md).
BACKENDS = ("rollout", "loop")
DEFAULT_BACKEND = BACKENDS[0]

_S, _O, _ST = mujoco.mjtSensor, mujoco.mjtObj, mujoco.mjtState
#: The sensors added to the arm's model: name, sensor type, object type, object name. Each gives 3 numbers.
SENSORS: tuple[tuple[str, int, int, str], ...] = (
    ("hrlp_hand", _S.mjSENS_FRAMEPOS, _O.mjOBJ_SITE, "hand"),  # H: site_xpos[hand]
    ("hrlp_tip_right", _S.mjSENS_FRAMEPOS, _O.mjOBJ_SITE, "tip_right"),  # FT1
    ("hrlp_tip_left", _S.mjSENS_FRAMEPOS, _O.mjOBJ_SITE, "tip_left"),  # FT2
    ("hrlp_capsule", _S.mjSENS_FRAMEPOS, _O.mjOBJ_XBODY, "object"),  # C: xpos[object] (the body frame, as ArmPhysics)
    ("hrlp_capsule_axis", _S.mjSENS_FRAMEZAXIS, _O.mjOBJ_GEOM, "object"),  # column 2 of geom_xmat[object]
    ("hrlp_forearm_axis", _S.mjSENS_FRAMEXAXIS, _O.mjOBJ_XBODY, "forearm"),  # column 0 of xmat[forearm]
    ("hrlp_claw_x", _S.mjSENS_FRAMEXAXIS, _O.mjOBJ_XBODY, "claw"),  # column 0 of xmat[claw]: the fingers' direction
    ("hrlp_claw_y", _S.mjSENS_FRAMEYAXIS, _O.mjOBJ_XBODY, "claw"),  # column 1 of xmat[claw]: the closing direction
)
#: Distance sensors added for the ``arm_clearance`` feature only (MuJoCo computes them at every substep): for each
#: body of :data:`~hrlp.arm.physics.CLEARANCE_BODIES`, the smallest distance of its geoms to the capsule, cut off at
#: :data:`~hrlp.arm.physics.CLEARANCE_CUTOFF` (one number each; what :meth:`ArmPhysics.arm_clearance_features` computes).
CLEARANCE_SENSORS: tuple[tuple[str, str], ...] = tuple((f"hrlp_clearance_{b}", b) for b in CLEARANCE_BODIES)
_FULL, _INTEGRATION = _ST.mjSTATE_FULLPHYSICS, _ST.mjSTATE_INTEGRATION
_MOCAP = _ST.mjSTATE_MOCAP_POS | _ST.mjSTATE_MOCAP_QUAT
_BAD = (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL, mujoco.mjtWarning.mjWARN_BADQACC)


def measured_model(config: PhysicsConfig, clearance: bool = False) -> mujoco.MjModel:
    """The arm's model (as :func:`hrlp.arm.physics.load_model` builds it) with :data:`SENSORS` added, and with
    ``clearance`` the :data:`CLEARANCE_SENSORS` too.

    Position sensors change nothing in the dynamics: stepping it gives the same bits as the plain model
    (``tests/envs/test_batched.py`` checks it)."""
    spec = mujoco.MjSpec.from_string(model_xml())
    for name, sensor, objtype, obj in SENSORS:
        spec.add_sensor(name=name, type=sensor, objtype=objtype, objname=obj)
    for name, body in CLEARANCE_SENSORS if clearance else ():
        spec.add_sensor(name=name, type=_S.mjSENS_GEOMDIST, objtype=_O.mjOBJ_BODY, objname=body, reftype=_O.mjOBJ_GEOM,
                        refname="object", cutoff=CLEARANCE_CUTOFF)  # fmt: skip
    return configure_model(spec.compile(), config)  # what load_model applies


# --- measurements of N worlds and the tasks' formulas over them --------------------------------------------------


@dataclass(frozen=True)
class Measurements:
    """What the tasks measure, for ``N`` worlds (views into the backend's buffers: read, do not keep)."""

    qpos: np.ndarray  # [N, 9] joint angles, rad
    qvel: np.ndarray  # [N, 9] joint velocities, rad/s
    capsule_vel: np.ndarray  # [N, 3] the capsule's linear velocity (free joint), m/s
    hand: np.ndarray  # [N, 3] H, m
    tip_right: np.ndarray  # [N, 3] FT1, m
    tip_left: np.ndarray  # [N, 3] FT2, m
    capsule: np.ndarray  # [N, 3] C, m
    capsule_axis: np.ndarray  # [N, 3] unit vector along the capsule
    forearm_axis: np.ndarray  # [N, 3] unit vector along the forearm
    claw_x: np.ndarray  # [N, 3] the palm's x axis (the fingers' direction)
    claw_y: np.ndarray  # [N, 3] the palm's y axis (the direction the fingers close along)
    target: np.ndarray  # [N, 3] T (the shadow capsule), m
    capsule_half_length: float  # half-length of the capsule's axis segment, m
    clearance: np.ndarray | None = None  # [N, 5] each CLEARANCE_BODIES body's distance to the capsule, m (if measured)


def dist_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise Euclidean distance ``[N]`` of ``a, b [N, 3]``, as ``ArmPhysics``'s distances compute it (bit for bit)."""
    dx, dy, dz = a[:, 0] - b[:, 0], a[:, 1] - b[:, 1], a[:, 2] - b[:, 2]
    return np.sqrt(dx * dx + dy * dy + dz * dz)


def math_dist_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``math.dist`` ``[N]`` of ``a, b [N, 3]``: the tasks that call ``math.dist`` get its exact bits."""
    return np.array([math.dist(x, y) for x, y in zip(a.tolist(), b.tolist(), strict=True)], dtype=np.float64)


def math_hypot_xy_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``math.hypot`` of the horizontal offset ``a - b`` (``a, b [N, 3]``), ``[N]``."""
    d = (a[:, :2] - b[:, :2]).tolist()
    return np.array([math.hypot(x, y) for x, y in d], dtype=np.float64)


def hand_to_capsule_axis_rows(m: Measurements) -> np.ndarray:
    """d(H, capsule axis segment) ``[N]``, as :meth:`ArmPhysics.hand_to_capsule_axis` computes it."""
    h, c, ax, half = m.hand, m.capsule, m.capsule_axis, m.capsule_half_length
    hx, hy, hz = h[:, 0] - c[:, 0], h[:, 1] - c[:, 1], h[:, 2] - c[:, 2]
    s = hx * ax[:, 0] + hy * ax[:, 1] + hz * ax[:, 2]
    s = np.minimum(np.maximum(s, -half), half)
    x, y, z = hx - s * ax[:, 0], hy - s * ax[:, 1], hz - s * ax[:, 2]
    return np.sqrt(x * x + y * y + z * z)


def claw_closure_rows(qpos: np.ndarray) -> np.ndarray:
    """:func:`hrlp.arm.tasks.claw_closure` for ``qpos [N, 9]``: closing part of each finger plus their asymmetry, ``[N]``."""
    rc, lc = qpos[:, N_JOINTS - 2], qpos[:, N_JOINTS - 1]
    return np.maximum(rc, 0.0) + np.maximum(-lc, 0.0) + np.abs(rc + lc)


def capsule_pose_rows(m: Measurements) -> np.ndarray:
    """:meth:`ArmPhysics.capsule_pose_features` for ``N`` worlds: ``(a_x^2 - a_y^2, 2 a_x a_y, a_z^2, v_C)``, ``[N, 6]``."""
    x, y, z = m.capsule_axis[:, 0], m.capsule_axis[:, 1], m.capsule_axis[:, 2]
    return np.column_stack([x * x - y * y, 2.0 * x * y, z * z, m.capsule_vel])


def claw_pose_rows(m: Measurements) -> np.ndarray:
    """:meth:`ArmPhysics.claw_pose_features` for ``N`` worlds: ``(H - C, FT1 - C, FT2 - C, palm x, palm y)``, ``[N, 15]``."""
    c = m.capsule
    return np.column_stack([m.hand - c, m.tip_right - c, m.tip_left - c, m.claw_x, m.claw_y])


def feature_rows(name: str, m: Measurements) -> np.ndarray:
    """:meth:`ArmPhysics.feature` for ``N`` worlds: the named observation feature, ``[N, width]``."""
    if name == "capsule_pose":
        return capsule_pose_rows(m)
    if name == "claw_pose":
        return claw_pose_rows(m)
    if name == "arm_clearance":
        if m.clearance is None:
            raise ValueError("the arm_clearance feature needs the worlds' distance sensors: build them with "
                             "features=('arm_clearance',)")  # fmt: skip
        return m.clearance
    raise ValueError(f"unknown observation feature {name!r} (known: {', '.join(OBS_FEATURES)})")


def grip_terms_rows(reward: GripReward, sparse: SparseSuccess, m: Measurements) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """:class:`GripReward`'s terms (with ``c4`` while Definition 1 holds) and Definition 1 itself, ``[N]`` each."""
    d_centre = dist_rows(m.hand, m.capsule)
    d = d_centre if reward.distance == "centre" else hand_to_capsule_axis_rows(m)
    gap = dist_rows(m.tip_right, m.tip_left)
    terms = {
        "distance": reward.c1 * d,
        "bonus": np.where(d < reward.tr, float(reward.c2), 0.0),
        "fingers": reward.c3 * gap,
    }
    held = (gap < sparse.tr2) & (d_centre < sparse.tr1)  # Definition 1, in SparseSuccess's order
    if reward.c4:
        terms["gripped"] = np.where(held, float(reward.c4), 0.0)
    return terms, held


EpisodeState = Mapping[str, np.ndarray]
"""The tasks' per-episode state for ``N`` worlds, by :meth:`Task.episode_state`'s keys (e.g. ``goal [N, 3]``)."""


class VectorisedTask(Protocol):
    """A task's per-step arithmetic over ``N`` worlds (the same numbers as the task's scalar methods)."""

    def evaluate(self, m: Measurements, ep: EpisodeState) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """The reward terms (``[N]`` each, in the task's order) and the success test ``[N]`` bool of this step."""
        ...

    def extra_obs(self, m: Measurements, ep: EpisodeState) -> np.ndarray | None:
        """The task's extra observations ``[N, extra_obs_dim]``, or None if it has none."""
        ...

    def track(self, m: Measurements) -> tuple[np.ndarray, ...]:
        """Per-step values of :attr:`Task.tracked`, ``[N]`` each."""
        ...

    def track_max(self, m: Measurements) -> tuple[np.ndarray, ...]:
        """Per-step values of :attr:`Task.tracked_max`, ``[N]`` each."""
        ...


class _Reacher:
    def __init__(self, task: ReacherTask) -> None:
        self.t = task

    def evaluate(self, m: Measurements, ep: EpisodeState) -> tuple[dict[str, np.ndarray], np.ndarray]:
        t = self.t
        d = math_dist_rows(m.hand, ep["goal"])
        terms = {"distance": -d}
        ok = d < t.success_tol
        if t.variant == "stabilised":
            terms["level"] = -t.level_coeff * np.abs(m.forearm_axis[:, 2])
        elif t.variant == "handover":
            moved = math_dist_rows(m.capsule, ep["start_capsule"])
            terms["capsule"] = -t.capsule_coeff * moved
            terms["claw"] = -t.claw_coeff * claw_closure_rows(m.qpos)
            ok &= moved < 0.01
        return terms, ok

    def extra_obs(self, m: Measurements, ep: EpisodeState) -> np.ndarray | None:
        return ep["goal"]

    def track(self, m: Measurements) -> tuple[np.ndarray, ...]:
        return ()

    def track_max(self, m: Measurements) -> tuple[np.ndarray, ...]:
        return ()


class _Gripper:
    def __init__(self, task: GripperTask) -> None:
        self.t = task

    def evaluate(self, m: Measurements, ep: EpisodeState) -> tuple[dict[str, np.ndarray], np.ndarray]:
        t = self.t
        terms, held = grip_terms_rows(t.reward, t.sparse, m)
        if t.push_coeff:
            terms["push"] = np.where(held, 0.0, -t.push_coeff * math_hypot_xy_rows(m.capsule, ep["start_capsule"]))
        return terms, held

    def extra_obs(self, m: Measurements, ep: EpisodeState) -> np.ndarray | None:
        parts = [feature_rows(name, m) for name in self.t.observed_features]
        return np.column_stack(parts) if parts else None

    def track(self, m: Measurements) -> tuple[np.ndarray, ...]:
        return ()

    def track_max(self, m: Measurements) -> tuple[np.ndarray, ...]:
        return ()


class _ReachAndGrip:
    def __init__(self, task: ReachAndGripTask) -> None:
        self.t = task

    def evaluate(self, m: Measurements, ep: EpisodeState) -> tuple[dict[str, np.ndarray], np.ndarray]:
        return grip_terms_rows(self.t.reward, self.t.sparse, m)

    def extra_obs(self, m: Measurements, ep: EpisodeState) -> np.ndarray | None:
        return None

    def track(self, m: Measurements) -> tuple[np.ndarray, ...]:
        return ()

    def track_max(self, m: Measurements) -> tuple[np.ndarray, ...]:
        return ()


class _Mover:
    """MoverTask and ReachAndMoveTask: reach the capsule, move it to T; TargetDistSum and the episode's extremes."""

    def __init__(self, task: MoverTask | ReachAndMoveTask) -> None:
        self.t = task
        self.hand_coeff = task.hand_coeff if isinstance(task, MoverTask) else None

    def evaluate(self, m: Measurements, ep: EpisodeState) -> tuple[dict[str, np.ndarray], np.ndarray]:
        reach, move = dist_rows(m.hand, m.capsule), dist_rows(m.capsule, m.target)
        terms = {
            "reach": -reach if self.hand_coeff is None else -self.hand_coeff * reach,
            "move": -self.t.target_coeff * move,
        }
        return terms, move < self.t.success_tol

    def extra_obs(self, m: Measurements, ep: EpisodeState) -> np.ndarray | None:
        return m.target

    def track(self, m: Measurements) -> tuple[np.ndarray, ...]:
        return (-dist_rows(m.capsule, m.target),)

    def track_max(self, m: Measurements) -> tuple[np.ndarray, ...]:
        return -dist_rows(m.capsule, m.target), m.capsule[:, 2] - CAPSULE_REST_Z


#: The tasks with a vectorised version, by exact type (a subclass may change the formulas).
VECTORISED: dict[type, Callable[[Any], VectorisedTask]] = {
    ReacherTask: _Reacher,
    GripperTask: _Gripper,
    ReachAndGripTask: _ReachAndGrip,
    MoverTask: _Mover,
    ReachAndMoveTask: _Mover,
}


def vectorise(task: Task) -> VectorisedTask:
    """The vectorised version of ``task``; a one-line ValueError for a task type that has none."""
    build = VECTORISED.get(type(task))
    if build is None:
        known = ", ".join(sorted(t.__name__ for t in VECTORISED))
        raise ValueError(f"BatchedArmEnv: no vectorised version of {type(task).__name__}; supported: {known}")
    return build(task)


# --- physics backends ---------------------------------------------------------------------------------------------


class _Backend(Protocol):
    """Steps ``N`` worlds; the environment owns the ``state [N, nfull]`` (FULLPHYSICS), ``sens [N, 18]`` and
    ``mocap [N, 7]`` buffers and hands a world's full state over through a scratch ``MjData``."""

    def step(self, ctrl: np.ndarray, state: np.ndarray, sens: np.ndarray, idx: np.ndarray | None = None
             ) -> tuple[np.ndarray, float]:  # fmt: skip
        """Apply ``ctrl [N, nu]`` for ``substeps`` physics steps in every world, or in the worlds ``idx`` only (the
        others keep their state); write ``state``, ``sens``; return ``(unstable [N] bool, seconds inside MuJoCo)``."""
        ...

    def load(self, i: int, src: mujoco.MjData) -> None:
        """Make world ``i`` continue from ``src``'s integration state (``state[i]``, ``mocap[i]`` already hold it)."""
        ...

    def save(self, i: int, dst: mujoco.MjData) -> None:
        """Write world ``i``'s integration state into ``dst``."""
        ...

    def close(self) -> None:
        """Release threads."""
        ...


class _LoopBackend:
    """One ``MjData`` per world, stepped by ``mj_step`` from a Python loop; bit-identical to ArmEnv."""

    def __init__(self, model: mujoco.MjModel, n: int, substeps: int) -> None:
        self.model, self.substeps = model, substeps
        self.datas = [mujoco.MjData(model) for _ in range(n)]
        self._counters = [tuple(d.warning[int(k)] for k in _BAD) for d in self.datas]
        self._buf = np.empty(mujoco.mj_stateSize(model, _INTEGRATION))

    def step(self, ctrl: np.ndarray, state: np.ndarray, sens: np.ndarray, idx: np.ndarray | None = None
             ) -> tuple[np.ndarray, float]:  # fmt: skip
        m, nsub, clock = self.model, self.substeps, time.thread_time  # CPU time, as ArmPhysics counts it
        unstable = np.zeros(len(self.datas), dtype=bool)
        seconds = 0.0
        for i in range(len(self.datas)) if idx is None else idx:
            d = self.datas[i]
            d.ctrl[:] = ctrl[i]
            t0 = clock()
            mujoco.mj_step(m, d, nsub)
            seconds += clock() - t0
            mujoco.mj_getState(m, d, state[i], _FULL)
            sens[i] = d.sensordata
            q, v, a = self._counters[i]
            if q.number or v.number or a.number:  # MuJoCo reset the world (as ArmPhysics.step reads it)
                unstable[i] = True
                q.number = v.number = a.number = 0
        return unstable, seconds

    def load(self, i: int, src: mujoco.MjData) -> None:
        mujoco.mj_getState(self.model, src, self._buf, _INTEGRATION)
        mujoco.mj_setState(self.model, self.datas[i], self._buf, _INTEGRATION)

    def save(self, i: int, dst: mujoco.MjData) -> None:
        mujoco.mj_getState(self.model, self.datas[i], self._buf, _INTEGRATION)
        mujoco.mj_setState(self.model, dst, self._buf, _INTEGRATION)

    def close(self) -> None:
        return None


class _RolloutBackend:
    """``mujoco.rollout`` over every world in one call, on ``threads`` threads (see the module docstring on exactness)."""

    def __init__(
        self, model: mujoco.MjModel, n: int, substeps: int, threads: int, state: np.ndarray, mocap: np.ndarray
    ) -> None:
        self.model, self.substeps = model, substeps
        self._state, self._mocap = state, mocap  # the environment's buffers, read by save()
        self._pool = mujoco.rollout.Rollout(nthread=threads if threads > 1 else 0)
        self._datas = [mujoco.MjData(model) for _ in range(threads)]
        self._models = [model] * n
        nfull = mujoco.mj_stateSize(model, _FULL)
        self._ctrl_steps = np.zeros((n, substeps, model.nu))  # the control of every substep (rollout's layout)
        self._ctrl = np.zeros((n, model.nu))
        self._warm = np.zeros((n, model.nv))
        self._out_state = np.empty((n, substeps, nfull))
        self._out_sens = np.empty((n, substeps, model.nsensordata))
        # A few chunks per thread balance worlds that cost more (contacts) against the pool's overhead.
        self._chunk = max(1, n // (4 * threads)) if threads > 1 else None
        self._threads = threads
        # On the calling thread, CPU time (as ArmPhysics counts it); on a pool, the wall time of the call.
        self._clock = time.thread_time if threads == 1 else time.perf_counter

    def step(self, ctrl: np.ndarray, state: np.ndarray, sens: np.ndarray, idx: np.ndarray | None = None
             ) -> tuple[np.ndarray, float]:  # fmt: skip
        if idx is None or len(idx) == len(self._models):
            self._ctrl[:] = ctrl
            self._ctrl_steps[:] = ctrl[:, None, :]
            unstable, seconds = self._run(self._models, state, self._ctrl_steps, self._warm, self._out_state,
                                          self._out_sens, self._chunk)  # fmt: skip
            state[:] = self._out_state[:, -1]
            sens[:] = self._out_sens[:, -1]
            self._warm[:] = 0.0  # the solver's warm start is not among rollout's outputs: the next call starts from zero
            return unstable, seconds
        # Some worlds only (a Manager's macro-actions of different lengths): the same call on their rows.
        m, k = len(idx), self._threads
        self._ctrl[idx] = ctrl[idx]
        out_state = np.empty((m, self.substeps, self._out_state.shape[2]))
        out_sens = np.empty((m, self.substeps, self._out_sens.shape[2]))
        some, seconds = self._run(self._models[:m], state[idx], np.repeat(ctrl[idx, None, :], self.substeps, axis=1),
                                  self._warm[idx], out_state, out_sens, max(1, m // (4 * k)) if k > 1 else None)  # fmt: skip
        state[idx] = out_state[:, -1]
        sens[idx] = out_sens[:, -1]
        self._warm[idx] = 0.0
        unstable = np.zeros(len(self._models), dtype=bool)
        unstable[idx] = some
        return unstable, seconds

    def _run(self, models: list, state: np.ndarray, ctrl: np.ndarray, warm: np.ndarray, out_state: np.ndarray,
             out_sens: np.ndarray, chunk: int | None) -> tuple[np.ndarray, float]:  # fmt: skip
        """One ``rollout`` call from ``state [M, nfull]``; ``(unstable [M], seconds)``."""
        before = state[:, 0].copy() if self.substeps == 1 else None
        t0 = self._clock()
        self._pool.rollout(models, self._datas, state, ctrl, skip_checks=True, nstep=self.substeps,
                           initial_warmstart=warm, state=out_state, sensordata=out_sens, chunk_size=chunk)  # fmt: skip
        seconds = self._clock() - t0
        # A good last substep adds one timestep to the clock (mj_step's own addition, so the same bits). MuJoCo's
        # reset after a bad state sets the clock to 0, and rollout then repeats that state for the remaining substeps.
        last = out_state[:, -1, 0]
        unstable = last != (before if before is not None else out_state[:, -2, 0]) + self.model.opt.timestep
        return unstable, seconds

    def load(self, i: int, src: mujoco.MjData) -> None:
        self._ctrl[i] = src.ctrl
        self._warm[i] = src.qacc_warmstart

    def save(self, i: int, dst: mujoco.MjData) -> None:
        m = self.model
        mujoco.mj_resetData(m, dst)
        mujoco.mj_setState(m, dst, self._state[i], _FULL)
        mujoco.mj_setState(m, dst, self._mocap[i], _MOCAP)
        dst.ctrl[:] = self._ctrl[i]
        dst.qacc_warmstart[:] = self._warm[i]

    def close(self) -> None:
        self._pool.close()


# --- the environment ----------------------------------------------------------------------------------------------


class BatchedArmEnv:
    """``n`` worlds of one arm task stepped together: a :class:`~hrlp.envs.vector.VectorEnv`.

        Args:
            task: the task (one of :data:`VECTORISED`'s types); copied, so the caller's object keeps its own episode state.
            n: the number of worlds N.
            episode_steps: steps before truncation, as :class:`~hrlp.arm.env.ArmEnv`'s.
            physics: timestep, substeps and gravity.
            gamma: the discount per step (``VectorStep.discount``).
            backend: ``"rollout"`` (MuJoCo's rollout module) or ``"loop"`` (``mj_step`` per world from Python).
            threads: threads of the rollout backend (1: the calling thread); the loop backend takes 1 only.
            features: named observation features (:data:`~hrlp.arm.physics.OBS_FEATURES`) that :meth:`features` must
                give beyond the task's own (those the skills acting in these worlds read).

        World ``i`` behaves as an ArmEnv of the same task reset with ``seed + i`` and stepped with row ``i`` of the
        actions, reset on truncation (bit for bit with ``backend="loop"``). ``infos`` carries ``reward_<term>``,
        ``<tracked>_sum``, ``<tracked>_max`` (NaN on an unstable step, which ArmEnv does not report them on) and
        ``physics_unstable``; ``physics_seconds`` is the CPU time of the backend's C calls on the calling thread (as ArmEnv
    counts its ``mj_step``), or with ``threads`` > 1 their wall time. :meth:`get_state` gives
        a list of ArmEnv states (``ArmEnv.set_state`` and :class:`~hrlp.envs.vector.SerialVectorEnv` take them, and
        this class takes theirs).
    """

    def __init__(
        self,
        task: Task,
        n: int,
        *,
        episode_steps: int = 300,
        physics: PhysicsConfig | None = None,
        gamma: float = 0.99,
        backend: str = DEFAULT_BACKEND,
        threads: int = 1,
        features: Sequence[str] = (),
    ) -> None:
        who = f"BatchedArmEnv({getattr(task, 'name', type(task).__name__)})"
        n = check_num_envs(n, who)
        if isinstance(episode_steps, bool) or not isinstance(episode_steps, int) or episode_steps < 1:
            raise ValueError(f"{who}: episode_steps must be a positive integer, got {episode_steps!r}")
        if backend not in BACKENDS:
            raise ValueError(f"{who}: backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
            raise ValueError(f"{who}: threads must be a positive integer, got {threads!r}")
        if backend == "loop" and threads != 1:
            raise ValueError(f"{who}: the loop backend steps on the calling thread only; threads must be 1, got {threads}")
        self._who = who
        self.task = copy.deepcopy(task)
        self._vec = vectorise(self.task)
        self.gamma = check_gamma(gamma, who)
        self.episode_steps = episode_steps
        self.backend = backend
        self.threads = threads
        self._scratch = ArmPhysics(physics or PhysicsConfig())  # resets run here, through the task's own code
        config = self._scratch.config
        if unknown := [f for f in features if f not in OBS_FEATURES]:
            raise ValueError(f"{who}: unknown observation feature(s) {', '.join(map(repr, unknown))} (known: "
                             f"{', '.join(OBS_FEATURES)})")  # fmt: skip
        self._clearance = "arm_clearance" in (*self.task.observed_features, *features)  # with its distance sensors
        self.model = model = measured_model(config, self._clearance)
        nint = mujoco.mj_stateSize(model, _INTEGRATION)
        if nint != mujoco.mj_stateSize(self._scratch.model, _INTEGRATION):  # pragma: no cover - sensors hold no state
            raise AssertionError("the measured model's integration state differs from the arm's")
        self._n, self._obs_dim = n, BASE_OBS_DIM + self.task.extra_obs_dim
        self._state = np.zeros((n, mujoco.mj_stateSize(model, _FULL)))
        self._sens = np.zeros((n, model.nsensordata))
        self._mocap = np.zeros((n, mujoco.mj_stateSize(model, _MOCAP)))
        self._int = np.empty(nint)
        self._io = mujoco.MjData(model)  # hands whole states between resets, backends and get/set_state
        self._backend: _Backend = (
            _LoopBackend(model, n, config.substeps)
            if backend == "loop"
            else _RolloutBackend(model, n, config.substeps, threads, self._state, self._mocap)
        )
        self._measure = self._measurement_views()
        self._obs = np.zeros((n, self._obs_dim))
        self._t = np.zeros(n, dtype=np.int64)
        self._ended = np.zeros(n, dtype=bool)  # episode over, waiting for reset_worlds (advance only)
        self._episodes = np.zeros(n, dtype=np.int64)
        self._success = np.zeros(n, dtype=bool)
        self._sums = np.zeros((n, len(self.task.tracked)))
        self._maxes = np.zeros((n, len(self.task.tracked_max)))
        self._ep = {k: np.zeros((n, *np.shape(v))) for k, v in self.task.episode_state().items()}
        self._rngs = [np.random.default_rng() for _ in range(n)]
        self._ready = False

    # --- VectorEnv ----------------------------------------------------------------------------------------------
    @property
    def num_envs(self) -> int:
        """N, the number of worlds."""
        return self._n

    @property
    def obs_dim(self) -> int:
        """24 plus the task's extra observations."""
        return self._obs_dim

    @property
    def act_dim(self) -> int:
        """9 torques."""
        return N_JOINTS

    @property
    def resumable(self) -> bool:
        """Always: every world's state is saved exactly (:meth:`get_state`)."""
        return True

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Start an episode in every world (world ``i``'s stream seeded with ``seed + i``); returns ``obs [N, obs_dim]``."""
        for i in range(self._n):
            if seed is not None:
                self._rngs[i] = np.random.default_rng(seed + i)
            self._reset_world(i)
        self._ready = True
        return self._obs.copy()

    def step(self, actions: np.ndarray) -> VectorStep:
        """Apply ``actions [N, 9]`` (torques in [-1, 1], clipped by MuJoCo) for one control period in every world."""
        step = self.advance(actions)
        for i in np.flatnonzero(step.truncated):
            self._reset_world(i)
        step.obs[:] = self._obs
        return step

    def advance(self, actions: np.ndarray, active: np.ndarray | None = None) -> VectorStep:
        """:meth:`step` without its resets, in the worlds where ``active [N]`` (bool; None: every world): a world
        whose episode ends here waits, ``obs`` its last observation, until :meth:`reset_worlds` starts its next one
        (stepping it before raises RuntimeError). Rows of worlds not active hold their current observation, reward 0
        and no flags; their ``infos`` are not meaningful. A Manager's macro-actions of different lengths step this way
        (:class:`~hrlp.skills.macro_env.ManagerVectorEnv`)."""
        if not self._ready:
            raise RuntimeError(f"{self._who}: call reset() before step()")
        a = check_actions(actions, self._n, N_JOINTS, self._who)
        idx = None if active is None else np.flatnonzero(active)
        if (self._ended if idx is None else self._ended[idx]).any():
            ended = np.flatnonzero(self._ended)
            raise RuntimeError(f"{self._who}: world(s) {ended.tolist()} ended their episode; reset_worlds() them first")
        unstable, seconds = self._backend.step(a, self._state, self._sens, idx)
        m = self._measure()
        terms, ok = self._vec.evaluate(m, self._ep)
        rewards = np.zeros(self._n)
        for v in terms.values():  # the order of ArmEnv's sum(terms.values())
            rewards = rewards + v
        next_obs = np.empty_like(self._obs)
        self._observe(m, next_obs)
        success = self._success | ok
        sums = self._sums + np.column_stack(self._vec.track(m)) if self._sums.size else self._sums
        if self._maxes.size:
            now = np.column_stack(self._vec.track_max(m))
            maxes = np.where(now > self._maxes, now, self._maxes)  # Python's max(old, new) keeps old on ties and NaN
        else:
            maxes = self._maxes
        t = self._t + 1 if idx is None else self._t + np.asarray(active, dtype=np.int64)
        truncated = t >= self.episode_steps
        tracked = {f"{k}_sum": sums[:, j] for j, k in enumerate(self.task.tracked)}
        tracked |= {f"{k}_max": maxes[:, j] for j, k in enumerate(self.task.tracked_max)}
        if unstable.any():  # as ArmEnv._unstable: the last good observation, reward 0, nothing else counted
            u = unstable
            next_obs[u], rewards[u], success[u] = self._obs[u], 0.0, self._success[u]
            terms = {k: np.where(u, 0.0, v) for k, v in terms.items()}
            sums, maxes = np.where(u[:, None], self._sums, sums), np.where(u[:, None], self._maxes, maxes)
            tracked = {k: np.where(u, np.nan, v) for k, v in tracked.items()}
            truncated |= u
        if idx is not None:  # the worlds left out keep everything
            rest = ~np.asarray(active, dtype=bool)
            next_obs[rest], rewards[rest], success[rest], truncated[rest] = self._obs[rest], 0.0, self._success[rest], False
            sums[rest], maxes[rest] = self._sums[rest], self._maxes[rest]
        self._t, self._ended = t, truncated.copy()
        self._success, self._sums, self._maxes = success, sums, maxes
        infos: dict[str, np.ndarray] = {f"reward_{k}": np.array(v, dtype=np.float64) for k, v in terms.items()}
        infos |= {k: v.copy() for k, v in tracked.items()}
        infos["physics_unstable"] = unstable
        self._obs = next_obs.copy()
        return VectorStep(
            obs=next_obs.copy(),
            next_obs=next_obs,
            rewards=rewards,
            discount=np.full(self._n, self.gamma),
            tau=np.ones(self._n, dtype=np.int64),
            terminated=np.zeros(self._n, dtype=bool),
            truncated=truncated,
            success=success.copy(),
            infos=infos,
            physics_seconds=seconds,
        )

    @property
    def measured_features(self) -> tuple[str, ...]:
        """The named observation features :meth:`features` gives (``arm_clearance`` only where these worlds were built
        with its distance sensors: the task observes it, or ``features`` named it)."""
        return tuple(f for f in OBS_FEATURES if f != "arm_clearance" or self._clearance)

    @property
    def measurable(self) -> tuple[str, ...]:
        """Parts measured outside the observation (:meth:`measure`): :attr:`measured_features`."""
        return self.measured_features

    def measure(self, name: str, worlds: np.ndarray) -> np.ndarray:
        """The named feature of the worlds ``worlds``."""
        return self.features(name)[worlds]

    def features(self, name: str) -> np.ndarray:
        """The named observation feature (:data:`~hrlp.arm.physics.OBS_FEATURES`) of every world's current state,
        ``[N, width]`` (what a skill that reads it is given; :meth:`ArmPhysics.feature` for one world)."""
        return np.array(feature_rows(name, self._measure()), dtype=np.float64)

    def reset_worlds(self, worlds: np.ndarray) -> np.ndarray:
        """Start the next episode of each world in ``worlds`` (indices), continuing its own random stream, as
        :meth:`step` does when an episode ends; returns their observations ``[len(worlds), obs_dim]``."""
        if not self._ready:
            raise RuntimeError(f"{self._who}: call reset() before reset_worlds()")
        rows = np.asarray(worlds, dtype=np.int64).reshape(-1)
        for i in rows:
            self._reset_world(int(i))
        return self._obs[rows].copy()

    def get_state(self) -> dict[str, Any]:
        """``{"envs": [one ArmEnv.get_state() per world], "obs": [N, obs_dim]}`` (JSON-serialisable)."""
        if not self._ready:
            raise RuntimeError(f"{self._who}: call reset() before get_state()")
        return {"envs": [self._world_state(i) for i in range(self._n)], "obs": self._obs.tolist()}

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state` (or a :class:`~hrlp.envs.vector.SerialVectorEnv`'s of the same task)."""
        worlds = state["envs"]
        if len(worlds) != self._n:
            raise ValueError(f"{self._who}: the saved state has {len(worlds)} environments, this one {self._n}")
        for i, s in enumerate(worlds):
            self._load_world(i, s)
        self._ready = True

    def close(self) -> None:
        """Stop the rollout threads and the scratch physics' renderer."""
        self._backend.close()
        self._scratch.close()

    # --- internals ----------------------------------------------------------------------------------------------
    def _measurement_views(self) -> Callable[[], Measurements]:
        m, s, sens = self.model, self._state, self._sens
        qpos = mujoco.mj_stateSize(m, _ST.mjSTATE_TIME)
        qvel = qpos + m.nq
        obj_dof = int(m.jnt_dofadr[m.joint("object").id])
        adr = {name: int(m.sensor(name).adr[0]) for name, *_ in SENSORS}
        target = 3 * int(m.body_mocapid[m.body("target").id])
        half = float(m.geom_size[m.geom("object").id, 1])
        clearance = None
        if self._clearance:  # the clearance sensors, one number each, added last in order: a view
            first = int(m.sensor(CLEARANCE_SENSORS[0][0]).adr[0])
            clearance = sens[:, first : first + len(CLEARANCE_SENSORS)]

        def col(name: str) -> np.ndarray:
            return sens[:, adr[name] : adr[name] + 3]

        views = Measurements(
            qpos=s[:, qpos : qpos + N_JOINTS],
            qvel=s[:, qvel : qvel + N_JOINTS],
            capsule_vel=s[:, qvel + obj_dof : qvel + obj_dof + 3],
            hand=col("hrlp_hand"),
            tip_right=col("hrlp_tip_right"),
            tip_left=col("hrlp_tip_left"),
            capsule=col("hrlp_capsule"),
            capsule_axis=col("hrlp_capsule_axis"),
            forearm_axis=col("hrlp_forearm_axis"),
            claw_x=col("hrlp_claw_x"),
            claw_y=col("hrlp_claw_y"),
            target=self._mocap[:, target : target + 3],
            capsule_half_length=half,
            clearance=clearance,
        )
        return lambda: views  # the buffers are written in place, so the views stay current

    def _observe(self, m: Measurements, out: np.ndarray) -> None:
        out[:, 0:9], out[:, 9:18], out[:, 18:21], out[:, 21:24] = m.qpos, m.qvel, m.hand, m.capsule
        extra = self._vec.extra_obs(m, self._ep)
        if extra is not None:
            out[:, BASE_OBS_DIM:] = extra

    def _reset_world(self, i: int) -> None:
        """ArmEnv.reset for world ``i``: the task's own start distribution on the scratch physics, then copied in."""
        p, task = self._scratch, self.task
        p.reset()
        task.reset(p, self._rngs[i], int(self._episodes[i]))
        p.forward()
        self._episodes[i] += 1
        self._t[i] = 0
        self._ended[i] = False
        self._success[i] = task.success(p)
        self._sums[i] = 0.0
        self._maxes[i] = [float(v) for v in task.track_max(p)]
        for k, v in task.episode_state().items():
            self._ep[k][i] = v
        p.base_observation(self._obs[i])
        if task.extra_obs_dim:
            task.extra_observation(p, self._obs[i, BASE_OBS_DIM:])
        mujoco.mj_getState(p.model, p.data, self._int, _INTEGRATION)
        self._load_physics(i, self._int)

    def _load_physics(self, i: int, integration: np.ndarray) -> None:
        m, io = self.model, self._io
        mujoco.mj_resetData(m, io)
        mujoco.mj_setState(m, io, integration, _INTEGRATION)
        mujoco.mj_getState(m, io, self._state[i], _FULL)
        mujoco.mj_getState(m, io, self._mocap[i], _MOCAP)
        self._backend.load(i, io)
        mujoco.mj_forward(m, io)  # the sensors of the new state, so that measurements (features()) are current
        self._sens[i] = io.sensordata

    def _world_state(self, i: int) -> dict[str, Any]:
        self._backend.save(i, self._io)
        mujoco.mj_getState(self.model, self._io, self._int, _INTEGRATION)
        return {
            "physics": self._int.tolist(),
            "obs": self._obs[i].tolist(),
            "t": int(self._t[i]),
            "episodes": int(self._episodes[i]),
            "success": bool(self._success[i]),
            "sums": self._sums[i].tolist(),
            "maxes": self._maxes[i].tolist(),
            "needs_reset": bool(self._ended[i]),
            "rng": self._rngs[i].bit_generator.state,
            "task": {k: v[i].tolist() for k, v in self._ep.items()},
        }

    def _load_world(self, i: int, s: Mapping[str, Any]) -> None:
        phys = np.asarray(s["physics"], dtype=np.float64)
        if phys.shape != self._int.shape:
            raise ValueError(f"{self._who}: saved physics state of world {i} has {phys.size} numbers, this model needs "
                             f"{self._int.size}")  # fmt: skip
        self._load_physics(i, phys)
        self._obs[i] = s["obs"]
        self._t[i], self._episodes[i], self._success[i] = int(s["t"]), int(s["episodes"]), bool(s["success"])
        self._ended[i] = False
        self._sums[i] = s["sums"]
        if "maxes" in s:
            self._maxes[i] = s["maxes"]
        else:  # a state saved before the maxima were tracked restarts them from the current step (as ArmEnv)
            p = self._scratch
            mujoco.mj_setState(p.model, p.data, phys, _INTEGRATION)
            p.forward()
            self._maxes[i] = [float(v) for v in self.task.track_max(p)]
        rng = np.random.default_rng()
        rng.bit_generator.state = s["rng"]
        self._rngs[i] = rng
        for k, v in s["task"].items():
            if k in self._ep:
                self._ep[k][i] = v
        if s.get("needs_reset"):  # saved between an episode's end and its reset: start the next one, as autoreset would
            self._reset_world(i)


def make_batched(name: str, n: int, **kwargs: Any) -> BatchedArmEnv:
    """:class:`BatchedArmEnv` of the registered task ``name`` (``hrlp.arm.TASKS``), as ``hrlp.arm.make`` builds
    an ArmEnv: keyword arguments go to the environment (``episode_steps``, ``physics``, ``gamma``, ``backend``,
    ``threads``, ``features``) or, the rest, to the task. A one-line ValueError for an unknown task or argument."""
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; known tasks: {', '.join(TASKS)}")
    env_keys = ("episode_steps", "physics", "gamma", "backend", "threads", "features")
    env_kw = {k: kwargs.pop(k) for k in env_keys if k in kwargs}
    valid = TASKS[name].arguments
    if unknown := [k for k in kwargs if valid and k not in valid]:
        raise ValueError(f"{name}: unknown argument(s) {', '.join(unknown)}; valid: {', '.join(valid)}")
    return BatchedArmEnv(TASKS[name].build(**kwargs), n, **env_kw)


@dataclass(frozen=True, eq=False)
class BatchedFactory(ArmEnvFactory, VectorConstructor):
    """An :class:`~hrlp.arm.registry.ArmEnvFactory` that can also build ``n`` worlds of its task as one
    :class:`BatchedArmEnv` (:meth:`vector`). A sampler given ``n`` copies of one such factory steps them as one
    BatchedArmEnv (:func:`hrlp.rollout.build_vector_env`): the batched backend of ``TrainConfig.backend``."""

    def vector(self, n: int, gamma: float) -> BatchedArmEnv:
        """``n`` worlds (world ``i`` as the ``i``-th of ``n`` environments this factory builds), discounting by ``gamma``."""
        return make_batched(self.name, n, gamma=gamma, **self.kwargs)


__all__ = [
    "BACKENDS",
    "DEFAULT_BACKEND",
    "SENSORS",
    "VECTORISED",
    "BatchedArmEnv",
    "BatchedFactory",
    "Measurements",
    "VectorisedTask",
    "capsule_pose_rows",
    "claw_closure_rows",
    "claw_pose_rows",
    "dist_rows",
    "feature_rows",
    "grip_terms_rows",
    "hand_to_capsule_axis_rows",
    "make_batched",
    "math_dist_rows",
    "math_hypot_xy_rows",
    "measured_model",
    "vectorise",
]
