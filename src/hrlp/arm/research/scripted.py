"""A scripted (model-based) grasp controller: an expert for the Gripper skill that can label any state.

The controller reads only the current physics state (joint angles and velocities, the capsule's pose) and the model,
so it can label states it never visited itself (DAgger). Its design, measured in ``benchmarks/scripted_grasp.py``:

- **Grasp pose.** A top-down grasp: the palm's x axis (the fingers' direction) straight down, H at the capsule's
  centre C, the fingers closing across the capsule. With the fingers opened 0.6 rad the tips clear the table
  (about 7 mm), and closing them pinches the capsule below its equator, so it rises into the claw; the tips end
  about 1.6 cm apart around it. Tilting the palm's x away from vertical (an oblique approach in the capsule's
  cross-section) puts the lower finger into the table, so the palm stays vertical. Where the claw cannot point down
  with its closing direction exactly across the capsule's axis (the front of the start circle, x > 0, where the
  shoulder's rotation and the wrist's abduction hit their limits), the palm turns about the vertical by up to
  0.6 rad; the fingers still close around the capsule (measured: success within 20-30 steps of closing).
- **Plan** (:class:`GraspPlan`), cached per capsule pose rounded to a few millimetres and degrees, so a pure function
  of the state: joint angles (inverse kinematics with orientation, from fixed seeds) that put H on the vertical line
  above C at a few heights, from the grasp (height 0) to the approach height.
- **Motion**: computed torque ``tau = M (w^2 (q* - q) - 2 w qdot) + qfrc_bias`` towards a joint target ``q*`` on that
  line, divided by the gears and clipped to [-1, 1]. The height of the target is a funnel: the further H is from the
  line (horizontally) or the palm from the grasp orientation, the higher the target, so the hand comes down only once
  it is over the capsule and aligned. An arm far from the line (in joint space or the palm's orientation) turns into
  it at the top of the line and keeps a larger (transit) clearance, since turning the palm swings the finger tips. Each
  step towards the target is scaled down as a whole (not clipped per joint), so the move keeps its direction, and a
  step that would bring the claw's lowest point (H or an open tip) below the needed clearance while it is near the
  capsule is raised by inverse kinematics. A claw lower than that beside the capsule first rises straight up and a
  little away, its fingers held as they are (opening them could swing a finger into the capsule).
- **Fingers**: held open (computed torque to -0.6 / +0.6 rad) until H is aligned and within ``close_height`` of the
  grasp, then closed with full torque; they stay closed while Definition 1 holds.
- **Escape** (``ScriptedGraspConfig.escape_clearance``, off by default): from starts with a finger or the palm within
  a centimetre of the capsule the grasp succeeded in 0.87 of them against 0.96 from the rest, nearly every failure a
  capsule pushed out of reach as the arm turned towards the line (it has no rolling friction). With the escape, while
  the arm is that close and not closing or descending, the hand first goes straight up with the fingers opening a
  little: 0.96 from both (``benchmarks/scripted_grasp.py --escape-clearance 0.01``, 300 starts).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import mujoco
import numpy as np

from hrlp.arm.physics import ARM_JOINTS, BASE_AXIS_XY, CAPSULE_RADIUS, CAPSULE_REST_Z, N_JOINTS, ArmPhysics
from hrlp.mjcompat import full_inertia

#: Motor gears of the 9 joints (ARM_CLAW facts): torque = gear * control.
GEARS = np.array([100.0, 100.0, 100.0, 70.0, 70.0, 30.0, 30.0, 10.0, 10.0])
_DOWN = np.array([0.0, 0.0, -1.0])
#: Horizontal distance beyond the funnel within which the claw counts as near the capsule (rising, keeping clear), m.
_NEAR = 0.07


@dataclass(frozen=True)
class ScriptedGraspConfig:
    """Constants of :class:`ScriptedGrasp` (the defaults are the measured choice)."""

    keep_clear: bool = True
    """Moves over the capsule keep the claw clear of it (the module's "Motion"; 0.935 of the Gripper's own starts).
    False: the first version's motion, from which ``gripper-imitated`` was imitated (0.895): each joint's step clipped on
    its own, one clearance whether or not the arm is near the plan's line, no raising of a step that dips, the fingers
    opened while rising, no retreat, and the plan's height key on an absolute grid."""
    omega: float = 30.0
    """Bandwidth w of the computed-torque tracking, rad/s (time constant about 1/w... 2/w)."""
    open_angle: float = 0.6
    """Finger opening held before closing, radians (rc = -open, lc = +open)."""
    approach_height: float = 0.06
    """Height of H above C from which the hand comes down, metres."""
    heights: tuple[float, ...] = (0.0, 0.01, 0.02, 0.03, 0.045, 0.06, 0.08)
    """Heights of H above C at which the plan solves the inverse kinematics, metres (the target is interpolated)."""
    align_radius: float = 0.008
    """Horizontal distance of H from the line above C under which the target comes all the way down, metres."""
    funnel_radius: float = 0.03
    """Horizontal distance at (and beyond) which the target stays at the approach height, metres."""
    align_angle: float = 0.15
    """Orientation error (radians) under which the target comes all the way down."""
    funnel_angle: float = 0.5
    """Orientation error (radians) at and beyond which the target stays at the approach height."""
    close_height: float = 0.03
    """Height of H above the grasp point under which the fingers close (when aligned), metres."""
    close_lift: float = 0.01
    """While closing, H follows the capsule's centre up to this height above its resting height, metres."""
    close_radius: float = 0.015
    """Horizontal distance of H from C under which the fingers may close, metres."""
    yaw_offsets: tuple[float, ...] = (0.0, 0.2, -0.2, 0.4, -0.4, 0.6, -0.6)
    """Turns of the palm about the vertical away from 'fingers across the axis', tried in order, radians."""
    position_grid: float = 0.004
    """Rounding of the capsule's position for the plan cache, metres."""
    height_grid: float = 0.01
    """Rounding of the capsule's height for the plan cache, metres (coarser: a pinched capsule rises a little)."""
    max_step: float = 0.4
    """Largest joint-target error per arm joint, radians (limits the speed of long moves)."""
    yaw_grid: float = 0.05
    """Rounding of the capsule's yaw for the plan cache, radians."""
    ik_seeds: int = 8
    """Random joint configurations (fixed seed) the plan's inverse kinematics starts from, besides a default pose."""
    reach: float = 0.36
    """Horizontal distance of the capsule from the arm's base axis beyond which the top-down grasp is out of reach
    (the controller then waits), metres."""
    rolling: float = 0.3
    """Capsule speed across the table above which the controller waits for it to settle, m/s."""
    joint_tolerance: float = 0.35
    """Largest joint-angle distance (radians, any arm joint) from the plan's line at which the hand may come down."""
    clearance: float = 0.015
    """Height the claw's lowest point (H or a finger tip) keeps above the capsule's top while it is not over the
    capsule, metres: a hand lower than that near the capsule first rises."""
    clear_margin: float = 0.01
    """Extra height over the needed clearance to which a move over the capsule raises the claw, metres (so that the
    move does not take turns with rising)."""
    transit_clearance: float = 0.03
    """The clearance kept instead of ``clearance`` while the arm is far from the plan's line (joints or palm
    orientation beyond the funnel), metres."""
    rise_below: float = 0.005
    """Clearance under which the claw rises straight up (and a little away) before any move over the capsule,
    metres; above it, moves over the capsule raise the claw as they go (``clear_margin``)."""
    rise_retreat: float = 0.01
    """Horizontal step away from the capsule taken with each rise, metres."""
    rise_slack: float = 0.008
    """How far below the needed clearance the claw may dip (while a move over the capsule brings it back up) before
    the controller stops and rises, metres."""
    escape_clearance: float = 0.0
    """Outside 'close' and 'descend', an arm whose nearest geom (a finger, the palm, a link) is closer than this to the
    capsule (``mj_geomDistance``) moves its hand straight up first (``escape_step``, the palm's orientation kept, the
    fingers opened by ``escape_opening``): out of a tight start without the sweep that pushes the capsule away, metres
    (0: off, the motion ``gripper-claw`` was imitated from; with 0.01 it grips from 0.96 of the Gripper's own starts
    against 0.92 without, ``benchmarks/scripted_grasp.py --escape-clearance 0.01``)."""
    escape_step: float = 0.03
    """How far above the hand the escape's target is at each control step, metres."""
    escape_opening: float = 0.25
    """How much further each finger opens during the escape, radians."""
    max_lines: int = 4
    """Most distinct arm configurations (lines) a plan keeps."""
    cache_size: int = 512
    """Plans kept in the cache (least recently used dropped first)."""

    def __post_init__(self) -> None:
        for name, top in (("escape_clearance", 0.05), ("escape_step", 0.1), ("escape_opening", 1.05)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (math.isfinite(v) and 0 <= v <= top):
                raise ValueError(f"ScriptedGraspConfig.{name} must be a number in [0, {top}], got {v!r}")


@dataclass(frozen=True)
class GraspLine:
    """Joint targets that put H on the vertical line above a capsule pose, in one grasp orientation."""

    rotation: np.ndarray
    """The palm's grasp orientation (columns: palm x, y, z in the world frame). [3, 3]"""
    heights: np.ndarray
    """Heights of H above the plan's capsule centre, from 0 (the grasp) up. [K]"""
    joints: np.ndarray
    """Joint angles (9; the fingers as the IK left them) putting H at ``capsule + heights[k] * up``. [K, 9]"""
    jac_pinv: np.ndarray
    """Pseudo-inverse of H's Jacobian over the 7 arm joints at each row of ``joints``: a first-order correction from
    the rounded capsule position to the exact one. [K, 7, 3]"""
    yaw_offset: float
    """The palm's turn about the vertical away from 'fingers across the capsule's axis', radians."""


@dataclass(frozen=True)
class GraspPlan:
    """Ways to grasp one (rounded) capsule pose: the lines of the turn closest to 'across the axis' that has any."""

    capsule: np.ndarray
    """The (rounded) capsule centre the plan is for. [3]"""
    lines: tuple[GraspLine, ...]
    """Distinct inverse-kinematics solutions (arm configurations), each a line of targets."""
    feasible: bool
    """Whether some line reaches the configured approach height (False: only lower lines, or a best effort for a
    capsule out of reach)."""


def _rot_err(r: np.ndarray, rg: np.ndarray) -> np.ndarray:
    """Rotation error from ``r`` to ``rg`` (both [3, 3], columns the axes): ``0.5 * sum_i r_i x rg_i``, a vector along
    the axis that turns ``r`` towards ``rg`` of length sin(angle) (for small angles)."""
    s = r @ rg.T
    return 0.5 * np.array([s[1, 2] - s[2, 1], s[2, 0] - s[0, 2], s[0, 1] - s[1, 0]])


def _yaw_rotation(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class ScriptedGrasp:
    """A top-down grasp controller for the arm with a claw; ``act()`` is a function of the current state only.

    The only memory is a cache of plans keyed by the rounded capsule pose, each computed from fixed seeds: a pure
    function of that pose, so the same state always gets the same action.

    Args:
        physics: the arm whose state is read (the controller never changes it).
        config: constants (:class:`ScriptedGraspConfig`).
    """

    def __init__(self, physics: ArmPhysics, config: ScriptedGraspConfig = ScriptedGraspConfig()) -> None:
        self.physics = physics
        self.config = config
        # A private copy of the state, brought up to date (mj_forward) before every decision: after mj_step the
        # positions MuJoCo reports belong to the start of the last substep, so reading them directly would make the
        # action depend on how the state was reached, not only on what it is.
        self._now = ArmPhysics(physics.config)
        m = physics.model
        self._scratch = mujoco.MjData(m)
        self._claw = m.body("claw").id
        self._hand = m.site("hand").id
        self._object_geom = m.geom("object").id
        self._table = m.geom("table").id
        self._arm_geoms = sorted(physics._arm_geoms)
        self._jacp = np.zeros((3, m.nv))
        self._jacr = np.zeros((3, m.nv))
        self._mass = np.zeros((m.nv, m.nv))
        self._lo = physics.joint_range[:ARM_JOINTS, 0].copy()
        self._hi = physics.joint_range[:ARM_JOINTS, 1].copy()
        rng = np.random.default_rng(20240615)
        self._seeds = [np.zeros(N_JOINTS)] + [
            rng.uniform(physics.joint_range[:, 0], physics.joint_range[:, 1]) for _ in range(config.ik_seeds)
        ]
        self._cache: OrderedDict[tuple[int, ...], GraspPlan] = OrderedDict()
        self.plans_made = 0
        """Plans computed so far (cache misses)."""

    def _sync(self) -> None:
        src, dst = self.physics.data, self._now.data
        dst.qpos[:] = src.qpos
        dst.qvel[:] = src.qvel
        dst.mocap_pos[:] = src.mocap_pos
        dst.mocap_quat[:] = src.mocap_quat
        mujoco.mj_forward(self._now.model, dst)

    # --- the capsule's pose and the plan --------------------------------------------------------------------------
    def _capsule_yaw(self) -> float:
        ax = self._now.data.geom_xmat[self._object_geom].reshape(3, 3)[:, 2]
        if math.hypot(ax[0], ax[1]) < 1e-6:  # standing on an end: any yaw
            return 0.0
        return math.atan2(ax[1], ax[0]) % math.pi  # a capsule is symmetric: yaw modulo pi

    def _key(self) -> tuple[int, ...]:
        cfg, c = self.config, self._now.capsule
        g, gz = cfg.position_grid, cfg.height_grid
        n_yaw = max(1, round(math.pi / cfg.yaw_grid))
        yaw = round(self._capsule_yaw() / math.pi * n_yaw) % n_yaw
        # The height relative to the resting height: a capsule lying on the table (z = its radius, a half-way point of
        # an absolute grid) would otherwise flip between two plans with the last digit of its height.
        return (round(c[0] / g), round(c[1] / g), round((c[2] - self._key_rest()) / gz), yaw)

    def _key_rest(self) -> float:
        """The height the plan key's height grid starts from (the first version's grid started at 0)."""
        return CAPSULE_REST_Z if self.config.keep_clear else 0.0

    def plan(self) -> GraspPlan:
        """The plan for the current capsule pose (cached per rounded pose: a pure function of the state)."""
        self._sync()
        key = self._key()
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        cfg = self.config
        n_yaw = max(1, round(math.pi / cfg.yaw_grid))
        capsule = np.array(
            [key[0] * cfg.position_grid, key[1] * cfg.position_grid, self._key_rest() + key[2] * cfg.height_grid]
        )
        plan = self._make_plan(capsule, key[3] * math.pi / n_yaw)
        self.plans_made += 1
        self._cache[key] = plan
        if len(self._cache) > cfg.cache_size:
            self._cache.popitem(last=False)
        return plan

    def _ik(self, goal: np.ndarray, rg: np.ndarray, q0: np.ndarray, iters: int) -> tuple[np.ndarray, float, float]:
        """Damped least squares on H's position and the palm's orientation ``rg`` over the 7 arm joints, in the
        scratch data (whose capsule and fingers are left as they are)."""
        m, d = self._now.model, self._scratch
        q = q0.copy()
        wr = 0.3  # metres per radian: orientation errors weigh like 3 mm per 0.01 rad
        for i in range(iters):
            d.qpos[:N_JOINTS] = q
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            e = goal - d.site_xpos[self._hand]
            er = _rot_err(d.xmat[self._claw].reshape(3, 3), rg)
            if e @ e < 1e-8 and er @ er < 1e-6:
                break
            if i == 40 and e @ e > 0.03**2:
                break  # stuck far from the goal (a joint limit): give up early
            mujoco.mj_jacSite(m, d, self._jacp, self._jacr, self._hand)
            j = np.vstack([self._jacp[:, :ARM_JOINTS], wr * self._jacr[:, :ARM_JOINTS]])
            dq = j.T @ np.linalg.solve(j @ j.T + 1e-4 * np.eye(6), np.concatenate([e, wr * er]))
            q[:ARM_JOINTS] = np.clip(q[:ARM_JOINTS] + np.clip(dq, -0.3, 0.3), self._lo, self._hi)
        d.qpos[:N_JOINTS] = q
        mujoco.mj_kinematics(m, d)
        pe = float(np.linalg.norm(goal - d.site_xpos[self._hand]))
        oe = float(np.linalg.norm(_rot_err(d.xmat[self._claw].reshape(3, 3), rg)))
        return q, pe, oe

    def _table_contact(self, q: np.ndarray) -> bool:
        """Whether the arm touches the table at joint angles ``q`` (the capsule is not checked)."""
        m, d = self._now.model, self._scratch
        d.qpos[:N_JOINTS] = q
        mujoco.mj_kinematics(m, d)
        for g in self._arm_geoms:
            if d.geom_xpos[g, 2] < 0.1 and mujoco.mj_geomDistance(m, d, g, self._table, 0.01, None) < 0:
                return True
        return False

    def _line(self, capsule: np.ndarray, rg: np.ndarray, q: np.ndarray, offset: float) -> GraspLine | None:
        """The line above ``capsule`` from grasp solution ``q`` upwards, until a height is out of reach (None if
        not even the first height above the grasp is reachable)."""
        m, d = self._now.model, self._scratch
        rows: list[np.ndarray] = []
        pinv: list[np.ndarray] = []
        for h in self.config.heights:
            q, pe, oe = self._ik(capsule + np.array([0.0, 0.0, h]), rg, q, iters=40)
            if pe > 0.005 or oe > 0.05:
                break
            rows.append(q.copy())
            mujoco.mj_comPos(m, d)
            mujoco.mj_jacSite(m, d, self._jacp, None, self._hand)
            j = self._jacp[:, :ARM_JOINTS]
            pinv.append(j.T @ np.linalg.inv(j @ j.T + 1e-4 * np.eye(3)))
        if len(rows) < 2:
            return None
        return GraspLine(rg, np.array(self.config.heights[: len(rows)]), np.array(rows), np.array(pinv), offset)

    def _make_plan(self, capsule: np.ndarray, yaw: float) -> GraspPlan:
        cfg = self.config
        self._scratch.qpos[:] = self._now.data.qpos
        self._scratch.qpos[7:9] = (-cfg.open_angle, cfg.open_angle)
        a = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        across = np.cross(a, [0.0, 0.0, 1.0])  # horizontal, across the capsule's axis
        top = cfg.approach_height - 1e-9
        low: list[GraspLine] = []
        for offset in cfg.yaw_offsets:
            lines: list[GraspLine] = []
            nearest = np.inf
            for sign in (1.0, -1.0):
                y = _yaw_rotation(offset) @ (sign * across)
                rg = np.stack([_DOWN, y, np.cross(_DOWN, y)], axis=1)
                for seed in self._seeds:
                    if len(lines) >= cfg.max_lines:
                        break
                    q, pe, oe = self._ik(capsule, rg, seed, iters=100)
                    nearest = min(nearest, pe)
                    if pe > 0.005 or oe > 0.05 or self._table_contact(q):
                        continue
                    if len(low) >= cfg.max_lines or any(
                        np.abs(q[:ARM_JOINTS] - ln.joints[0, :ARM_JOINTS]).max() < 0.2 for ln in lines + low
                    ):
                        continue  # the same arm configuration as one already found
                    line = self._line(capsule, rg, q, offset)
                    if line is not None:
                        (lines if line.heights[-1] >= top else low).append(line)
            if lines:
                return GraspPlan(capsule, tuple(lines), True)
            if nearest > 0.03 and not low:
                break  # far out of reach: turning the palm will not bring it within 5 mm
        if low:
            return GraspPlan(capsule, tuple(low), False)
        # Out of reach: a best effort towards the point, as close as the inverse kinematics gets.
        rg = np.stack([_DOWN, across, np.cross(_DOWN, across)], axis=1)
        q, _, _ = self._ik(capsule, rg, self._seeds[0], iters=100)
        q1, _, _ = self._ik(capsule + np.array([0.0, 0.0, cfg.heights[1]]), rg, q, iters=40)
        line = GraspLine(rg, np.array(cfg.heights[:2]), np.array([q, q1]), np.zeros((2, ARM_JOINTS, 3)), 0.0)
        return GraspPlan(capsule, (line,), False)

    # --- acting ---------------------------------------------------------------------------------------------------
    def line(self, plan: GraspPlan) -> GraspLine:
        """The plan's line nearest the arm's current configuration (joint space, any row)."""
        if len(plan.lines) == 1:
            return plan.lines[0]
        q = self._now.qpos[:ARM_JOINTS]
        return min(plan.lines, key=lambda ln: float(((ln.joints[:, :ARM_JOINTS] - q) ** 2).sum(1).min()))

    def target(self, plan: GraspPlan, line: GraspLine, height: float, lowest: float = np.inf) -> np.ndarray:
        """Joint angles [9] that put H at ``height`` above the exact capsule centre (but no higher than ``lowest``
        above the table), in the line's orientation."""
        k = int(np.clip(np.searchsorted(line.heights, height) - 1, 0, len(line.heights) - 2))
        h0, h1 = line.heights[k], line.heights[k + 1]
        w = float(np.clip((height - h0) / (h1 - h0), 0.0, 1.0))
        q = (1 - w) * line.joints[k] + w * line.joints[k + 1]
        shift = self._now.capsule - plan.capsule
        shift[2] = min(self._now.capsule[2], lowest) - plan.capsule[2]
        pinv = (1 - w) * line.jac_pinv[k] + w * line.jac_pinv[k + 1]
        q[:ARM_JOINTS] = np.clip(q[:ARM_JOINTS] + pinv @ shift, self._lo, self._hi)
        return q

    def approach_height(self, line: GraspLine) -> float:
        """Height of H above C from which the hand comes down: the configured one, or lower where the line above the
        capsule leaves the arm's reach (behind the base)."""
        return min(self.config.approach_height, float(line.heights[-1]))

    def _needed_clearance(self, line: GraspLine, far: bool = False) -> float:
        # No more than the top of the line offers (open tips about 1.8 cm below H), so that rising and moving over it
        # do not take turns. An arm far from the line in joint space turns its palm on the way, which swings the finger
        # tips: it keeps the larger transit clearance.
        wanted = self.config.transit_clearance if far else self.config.clearance
        return min(wanted, float(line.heights[-1]) - 0.018 - CAPSULE_RADIUS - 0.005)

    def _held(self) -> bool:
        """Definition 1 now: finger tips closer than 3 cm and d(H, C) < 5 cm."""
        p = self._now
        return p.finger_gap() < 0.03 and p.hand_to_capsule() < 0.05

    def situation(self) -> dict[str, float | str]:
        """What the controller sees now, a pure function of the state: its phase ('hold': Definition 1 holds; 'wait':
        the capsule is out of reach or rolling faster than ``config.rolling``; 'close', 'descend', 'rise', 'over')
        and, but in 'hold' and 'wait', H's horizontal distance from the line above C (rho), its height above C
        (above) and the palm's orientation error (angle, radians)."""
        self._sync()
        if self._held():
            return {"phase": "hold"}
        cfg, p = self.config, self._now
        c, v = p.capsule, p.data.qvel[N_JOINTS : N_JOINTS + 3]
        if math.hypot(c[0] - BASE_AXIS_XY[0], c[1] - BASE_AXIS_XY[1]) > cfg.reach or math.hypot(v[0], v[1]) > cfg.rolling:
            return {"phase": "wait"}  # out of reach, or still rolling: no plan would hold
        plan = self.plan()
        line = self.line(plan)
        h = p.hand
        rho = math.hypot(h[0] - c[0], h[1] - c[1])
        above = float(h[2] - c[2])
        angle = float(np.linalg.norm(_rot_err(p.data.xmat[self._claw].reshape(3, 3), line.rotation)))
        # How far the arm is from the line in joint space: near the capsule, only a small move is safe.
        joints = float(np.abs(line.joints[:, :ARM_JOINTS] - p.qpos[:ARM_JOINTS]).max(1).min())
        # The claw's lowest point (H or a finger tip) above the capsule's top.
        clearance = float(min(h[2], p.fingertips[0][2], p.fingertips[1][2]) - c[2] - CAPSULE_RADIUS)
        aligned = joints < cfg.joint_tolerance and angle < cfg.funnel_angle
        if aligned and rho < cfg.close_radius and above < cfg.close_height:
            phase = "close"
        elif aligned and rho < cfg.funnel_radius:
            phase = "descend"
        elif (
            clearance
            < (
                min(cfg.rise_below, self._needed_clearance(line, not aligned) - cfg.rise_slack)
                if cfg.keep_clear
                else self._needed_clearance(line)
            )
            and rho < cfg.funnel_radius + _NEAR
        ):
            phase = "rise"  # the claw is low beside the capsule: straight up first, so the move over it sweeps nothing
        else:
            phase = "over"
        return {"phase": phase, "rho": rho, "above": above, "angle": angle, "joints": joints, "clearance": clearance}

    def arm_clearance(self) -> float:
        """The smallest distance between an arm geom and the capsule now, metres (at most 5 cm: farther reads 5 cm)."""
        self._sync()
        return self._now.arm_clearance()

    def act(self) -> np.ndarray:
        """Motor controls [9] in [-1, 1] for the current state."""
        cfg, p = self.config, self._now
        s = self.situation()
        phase = s["phase"]
        # situation() has just synced the private copy of the state.
        if cfg.escape_clearance > 0 and phase in ("over", "rise") and p.arm_clearance() < cfg.escape_clearance:
            return self._escape()
        if phase in ("hold", "wait"):
            q = p.qpos.copy()  # stay where the arm is (velocity damped, gravity compensated)
        else:
            plan = self.plan()
            line = self.line(plan)
            rho, angle = float(s["rho"]), float(s["angle"])
            # Far from the line (joints or palm beyond the funnel): the larger transit clearance and the line's top.
            far = cfg.keep_clear and (float(s["joints"]) >= cfg.joint_tolerance or angle >= cfg.funnel_angle)
            if phase == "close":
                # H at the capsule's centre, at most close_lift above where it lies on the table: a pinched capsule
                # rises into the claw, and a hand that followed it all the way up would keep the tips from closing.
                q = self.target(plan, line, 0.0, lowest=CAPSULE_REST_Z + cfg.close_lift)
            elif phase == "rise":
                # Straight up from where the hand is, keeping the palm's orientation, so the fingers do not sweep.
                goal = p.hand + np.array([0.0, 0.0, self._needed_clearance(line, far) + 0.015 - float(s["clearance"])])
                if cfg.keep_clear:
                    away = p.hand[:2] - p.capsule[:2]
                    goal[:2] += cfg.rise_retreat * away / max(float(np.linalg.norm(away)), 1e-6)
                q = self._hand_to(goal)
            else:
                f_rho = np.clip((rho - cfg.align_radius) / (cfg.funnel_radius - cfg.align_radius), 0.0, 1.0)
                f_ang = np.clip((angle - cfg.align_angle) / (cfg.funnel_angle - cfg.align_angle), 0.0, 1.0)
                # An arm far from the line turns into it at the top of the line, away from the capsule.
                top = float(line.heights[-1]) if far else self.approach_height(line)
                q = self.target(plan, line, top * float(max(f_rho, f_ang)))
            q = q.copy()
            # The whole step scaled down (not each joint clipped), so that the move keeps its direction in joint space.
            dq = q[:ARM_JOINTS] - p.qpos[:ARM_JOINTS]
            if cfg.keep_clear:
                q[:ARM_JOINTS] = p.qpos[:ARM_JOINTS] + dq * min(1.0, cfg.max_step / max(float(np.abs(dq).max()), 1e-9))
            else:
                q[:ARM_JOINTS] = p.qpos[:ARM_JOINTS] + np.clip(dq, -cfg.max_step, cfg.max_step)
            if phase == "over" and cfg.keep_clear:
                q = self._keep_clear(q, line, far)
        # The fingers open, but while rising they stay as they are: a finger low beside the capsule would swing into it.
        q[7:] = p.qpos[7:9] if phase == "rise" and cfg.keep_clear else (-cfg.open_angle, cfg.open_angle)
        u = self._computed_torque(q) / GEARS
        if phase in ("hold", "close"):
            u[7:] = (1.0, -1.0)
        return np.clip(u, -1.0, 1.0)

    def _escape(self) -> np.ndarray:
        """Controls that take the hand straight up (``escape_step`` above it, the palm's orientation kept) and open the
        fingers by ``escape_opening`` more than they are: out of a start too close to the capsule without sweeping it."""
        cfg, p = self.config, self._now
        q = self._hand_to(p.hand + np.array([0.0, 0.0, cfg.escape_step])).copy()
        q[7:] = p.qpos[7:9] + np.array([-cfg.escape_opening, cfg.escape_opening])
        return np.clip(self._computed_torque(q) / GEARS, -1.0, 1.0)

    def _hand_to(self, goal: np.ndarray) -> np.ndarray:
        """Joint angles [9] (inverse kinematics from the current ones) that put H at ``goal`` with the palm's current
        orientation kept."""
        p = self._now
        self._scratch.qpos[:] = p.data.qpos
        q, _, _ = self._ik(goal, p.data.xmat[self._claw].reshape(3, 3).copy(), p.qpos.copy(), 15)
        return q

    def _keep_clear(self, q: np.ndarray, line: GraspLine, far: bool) -> np.ndarray:
        """``q`` [9] raised, if needed, so that the claw's lowest point (H or an open finger tip) keeps the needed
        clearance above the capsule's top wherever H is within ``funnel_radius + _NEAR`` of the capsule horizontally: a
        move in joint space towards a distant line may otherwise dip the claw into the capsule on the way."""
        cfg, p, m, d = self.config, self._now, self._now.model, self._scratch
        d.qpos[:] = p.data.qpos
        d.qpos[:N_JOINTS] = q
        d.qpos[7:9] = (-cfg.open_angle, cfg.open_angle)
        mujoco.mj_kinematics(m, d)
        h, c = d.site_xpos[self._hand].copy(), p.capsule
        if math.hypot(h[0] - c[0], h[1] - c[1]) >= cfg.funnel_radius + _NEAR:
            return q
        lowest = min(h[2], *(d.site_xpos[t][2] for t in self._now._tips)) - c[2] - CAPSULE_RADIUS
        need = max(self._needed_clearance(line, far), 0.0) + cfg.clear_margin
        if lowest >= need:
            return q
        raised, _, _ = self._ik(h + np.array([0.0, 0.0, need - lowest]), d.xmat[self._claw].reshape(3, 3).copy(), q, 15)
        raised[7:] = q[7:]
        return raised

    def _computed_torque(self, q: np.ndarray) -> np.ndarray:
        p, w = self._now, self.config.omega
        full_inertia(p.model, p.data, self._mass)
        acc = w * w * (q - p.qpos) - 2.0 * w * p.qvel
        # qfrc_bias holds gravity and Coriolis forces; the joints' damping (qfrc_passive) is cancelled too.
        return self._mass[:N_JOINTS, :N_JOINTS] @ acc + p.data.qfrc_bias[:N_JOINTS] - p.data.qfrc_passive[:N_JOINTS]
