"""The arm with a claw: the MuJoCo model and every measurement the tasks use.

Physics is kept apart from tasks (as in dm_control): this module owns the model, the simulation
state and the named points of the paper (Section 4: "H is the location of the hand (precisely a
point where the center of the mass of the capsule would be if the capsule were properly gripped
by the hand) and C is the location of the center of mass of the capsule"), plus finger tips
FT1/FT2 and the target T. Tasks (``hrlp.arm.tasks``) only read these measurements and place
the capsule, the target and the arm through the methods below.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass
from importlib import resources

import mujoco
import numpy as np

from hrlp.mjcompat import open_renderer, sum_contact_margins

#: Joint names in actuator order (ARM_CLAW facts, joints 1..9).
JOINTS: tuple[str, ...] = (
    "s_abduction",
    "s_flexion",
    "s_rotation",
    "e_flexion",
    "e_pronation",
    "w_abduction",
    "w_flexion",
    "rc_close",
    "lc_close",
)
N_JOINTS = len(JOINTS)
#: The 7 joints that move the palm; the last two open and close the fingers.
ARM_JOINTS = 7
#: Base observation size (paper, Appendix B.1): 9 angles, 9 velocities, hand H, capsule C.
BASE_OBS_DIM = 2 * N_JOINTS + 3 + 3
#: Named parts of the base observation (what a skill reads by name, :class:`hrlp.skills.core.ObsLayout`): ``base`` is
#: all 24 numbers, the others its pieces.
BASE_PARTS: dict[str, slice] = {
    "base": slice(0, BASE_OBS_DIM),
    "joint_angles": slice(0, N_JOINTS),
    "joint_velocities": slice(N_JOINTS, 2 * N_JOINTS),
    "hand": slice(2 * N_JOINTS, 2 * N_JOINTS + 3),
    "capsule": slice(2 * N_JOINTS + 3, BASE_OBS_DIM),
}
#: Where a task that observes a target T (:attr:`hrlp.arm.tasks.Task.observes_target`) puts it.
TARGET_PART = slice(BASE_OBS_DIM, BASE_OBS_DIM + 3)
#: Named observation features beyond the 24 base numbers, by name: their width. A task may append them to its
#: observation (``GripperTask.observe_capsule``) and a skill trained on it reads them wherever it acts, computed from
#: the physics by :meth:`ArmPhysics.feature` (one world) or :func:`hrlp.arm.batched.feature_rows` (N worlds).
#: ``capsule_pose``: :meth:`ArmPhysics.capsule_pose_features`; ``claw_pose``: :meth:`ArmPhysics.claw_pose_features`;
#: ``arm_clearance``: :meth:`ArmPhysics.arm_clearance_features`.
OBS_FEATURES: dict[str, int] = {"capsule_pose": 6, "claw_pose": 15, "arm_clearance": 5}
#: The arm's bodies whose geoms can touch the capsule, in the order of the ``arm_clearance`` feature.
CLEARANCE_BODIES = ("upperarm", "forearm", "claw", "rightclaw", "leftclaw")
#: The ``arm_clearance`` feature reads this distance (metres) for any body farther from the capsule.
CLEARANCE_CUTOFF = 0.05
#: The arm's base axis is the vertical line through the shoulder; start circles are centred on it.
BASE_AXIS_XY = np.array([-0.15, 0.0])
#: Height of the capsule's centre when it lies on the table (its radius).
CAPSULE_RADIUS = 0.025
CAPSULE_REST_Z = CAPSULE_RADIUS


@dataclass(frozen=True)
class PhysicsConfig:
    """Simulation settings shared by every task.

    The defaults are measured choices (docs/environments.md, "Timestep and control period"):
    a 0.002 s timestep with 5 substeps and the ``implicitfast`` integrator gives the paper's
    0.01 s control period at about 1.4x the speed of the original 0.001 s Euler timestep, with no
    instability in random-torque rollouts (Euler at 0.002 s had one).
    """

    timestep: float = 0.002
    """Physics timestep in seconds (the original model used 0.001)."""
    substeps: int = 5
    """Physics steps per control step; control period = timestep * substeps."""
    gravity: bool = True
    """Gravity 0 0 -9.81 (the original shipped with and without it)."""

    def __post_init__(self) -> None:
        if not (self.timestep > 0 and math.isfinite(self.timestep)):
            raise ValueError(f"PhysicsConfig.timestep must be a positive number, got {self.timestep!r}")
        if int(self.substeps) != self.substeps or self.substeps < 1:
            raise ValueError(f"PhysicsConfig.substeps must be a positive integer, got {self.substeps!r}")

    @property
    def control_period(self) -> float:
        """Seconds of simulated time per control step."""
        return self.timestep * self.substeps


@functools.cache
def model_xml() -> str:
    """The MJCF text of the arm (shipped inside the package)."""
    return resources.files("hrlp.arm").joinpath("assets/arm_claw.xml").read_text()


def load_model(config: PhysicsConfig = PhysicsConfig()) -> mujoco.MjModel:
    """A fresh ``MjModel`` of the arm with the timestep and gravity of ``config``."""
    return configure_model(mujoco.MjModel.from_xml_string(model_xml()), config)


def configure_model(model: mujoco.MjModel, config: PhysicsConfig) -> mujoco.MjModel:
    """Set, in place, what every compiled arm model gets: the timestep and gravity of ``config``, and contact margins
    that are the sum of the two geoms' on every MuJoCo (:func:`hrlp.mjcompat.sum_contact_margins`; the shipped skills
    were trained under that rule)."""
    model.opt.timestep = config.timestep
    model.opt.gravity[:] = (0.0, 0.0, -9.81) if config.gravity else (0.0, 0.0, 0.0)
    return sum_contact_margins(model)


class PhysicsError(RuntimeError):
    """Raised when the simulation cannot continue (for example a NaN state was set by hand)."""


class ArmPhysics:
    """The arm's MuJoCo model and data, with the paper's named measurements.

    Measurements are returned as read-only-by-convention views into ``MjData``; copy them if
    they must outlive the next step.
    """

    def __init__(self, config: PhysicsConfig = PhysicsConfig()) -> None:
        self.config = config
        self.model = load_model(config)
        self.data = mujoco.MjData(self.model)
        self.physics_seconds = 0.0
        """CPU seconds spent inside ``mj_step`` so far (training reports its share of the cores' time)."""
        m = self.model
        self._joint_qpos = np.array([m.jnt_qposadr[m.joint(j).id] for j in JOINTS])
        self._joint_dof = np.array([m.jnt_dofadr[m.joint(j).id] for j in JOINTS])
        # The hinges come first in the model, so contiguous slices avoid fancy-indexing copies.
        assert (self._joint_qpos == np.arange(N_JOINTS)).all() and (self._joint_dof == np.arange(N_JOINTS)).all()
        self.joint_range = m.jnt_range[:N_JOINTS].copy()  # [9, 2]
        obj = m.joint("object")
        self._obj_qpos = int(m.jnt_qposadr[obj.id])
        self._obj_dof = int(m.jnt_dofadr[obj.id])
        self._target_mocap = int(m.body_mocapid[m.body("target").id])
        self._hand = m.site("hand").id
        self._tips = (m.site("tip_right").id, m.site("tip_left").id)
        self._obj_body = m.body("object").id
        self._forearm_body = m.body("forearm").id
        self._claw_body = m.body("claw").id
        self._table = m.geom("table").id
        self._object_geom = m.geom("object").id
        self._arm_geoms = frozenset(
            g for g in range(m.ngeom) if g not in (self._table, self._object_geom, m.geom("target").id)
        )
        self._nearest_points = np.zeros(6)  # mj_geomDistance's output (arm_clearance)
        by_body = {b: tuple(sorted(g for g in self._arm_geoms if m.body(int(m.geom_bodyid[g])).name == b))
                   for b in CLEARANCE_BODIES}  # fmt: skip
        if sum(map(len, by_body.values())) != len(self._arm_geoms) or not all(by_body.values()):  # pragma: no cover
            raise AssertionError("CLEARANCE_BODIES must hold every arm geom")
        self._clearance_geoms = tuple(by_body.values())
        self._renderer: mujoco.Renderer | None = None
        # MuJoCo's instability warning counters, as views into MjData (read after every step, see step()).
        w, kinds = self.data.warning, mujoco.mjtWarning
        bad = (kinds.mjWARN_BADQPOS, kinds.mjWARN_BADQVEL, kinds.mjWARN_BADQACC)
        self._instability_counters = tuple(w[int(k)] for k in bad)
        self._last_warnings = {"bad_qpos": 0, "bad_qvel": 0, "bad_qacc": 0}
        # Views into MjData (its arrays are never reallocated): reading a measurement costs no indexing.
        d = self.data
        self._hand_v = d.site_xpos[self._hand]
        self._tip_v = (d.site_xpos[self._tips[0]], d.site_xpos[self._tips[1]])
        self._capsule_v = d.xpos[self._obj_body]
        self._capsule_axis_v = d.geom_xmat[self._object_geom]  # row-major 3 x 3: the axis is entries 2, 5, 8
        self._capsule_half_length = float(m.geom_size[self._object_geom, 1])
        self._claw_axes_v = d.xmat[self._claw_body]  # row-major 3 x 3: the palm's x axis is entries 0, 3, 6, y 1, 4, 7
        self._target_v = d.mocap_pos[self._target_mocap]
        mujoco.mj_forward(m, self.data)

    # --- measurements -------------------------------------------------------------------------
    @property
    def qpos(self) -> np.ndarray:
        """Joint angles of the 9 hinges, radians. [9]"""
        return self.data.qpos[:N_JOINTS]

    @property
    def qvel(self) -> np.ndarray:
        """Joint velocities of the 9 hinges, radians/s. [9]"""
        return self.data.qvel[:N_JOINTS]

    @property
    def hand(self) -> np.ndarray:
        """H: where the capsule's centre would be if properly gripped. [3]"""
        return self._hand_v

    @property
    def fingertips(self) -> tuple[np.ndarray, np.ndarray]:
        """FT1, FT2: the far ends of the two fingers. ([3], [3])"""
        return self._tip_v

    @property
    def capsule(self) -> np.ndarray:
        """C: the capsule's centre of mass. [3]"""
        return self._capsule_v

    def capsule_pose_features(self, out: np.ndarray) -> np.ndarray:
        """Write 6 numbers into ``out[:6]``: the capsule's axis a as ``(a_x^2 - a_y^2, 2 a_x a_y, a_z^2)`` (continuous, and
        the same for a and -a, as a capsule is symmetric: for a capsule lying at yaw theta, ``(cos 2 theta, sin 2 theta,
        0)``) and the capsule's linear velocity, m/s (what the paper's 24 numbers leave out)."""
        ax = self._capsule_axis_v
        x, y, z = ax[2], ax[5], ax[8]
        out[0], out[1], out[2] = x * x - y * y, 2.0 * x * y, z * z
        out[3:6] = self.data.qvel[N_JOINTS : N_JOINTS + 3]  # the free joint's linear velocity, world frame
        return out

    def claw_pose_features(self, out: np.ndarray) -> np.ndarray:
        """Write 15 numbers into ``out[:15]``: H - C, FT1 - C and FT2 - C (metres), then the palm's x axis (the fingers'
        direction) and y axis (the direction they close along), world frame.

        The 24 base numbers hold H and C, but a normaliser scales each coordinate by its spread over the workspace (tens
        of centimetres), so the millimetres between the claw and the capsule that a grip depends on are lost in it; the
        finger tips and the palm's orientation are functions of the joint angles that a small network learns poorly.
        A Gripper imitating the scripted grasp fits it with a third less error given these numbers
        (docs/research/skills-lineage.md)."""
        c, ax = self._capsule_v, self._claw_axes_v
        out[0:3] = self._hand_v - c
        out[3:6] = self._tip_v[0] - c
        out[6:9] = self._tip_v[1] - c
        out[9:12] = ax[0::3]
        out[12:15] = ax[1::3]
        return out

    def arm_clearance_features(self, out: np.ndarray) -> np.ndarray:
        """Write 5 numbers into ``out[:5]``: for each body of :data:`CLEARANCE_BODIES` (upper arm, forearm, palm, right
        and left finger), the smallest distance between its geoms and the capsule, metres (``mj_geomDistance``; negative
        while they overlap; :data:`CLEARANCE_CUTOFF` when farther), with the geoms where MuJoCo last placed them (the
        start of the last substep, as the other measurements).

        A start with the forearm or a finger within millimetres of the capsule is where a move of the claw pushes it
        away; the joint angles determine these distances, but through a function a small network learns poorly. The
        batched backend reads the same numbers from distance sensors (:data:`hrlp.arm.batched.CLEARANCE_SENSORS`)."""
        m, d, cap, pts = self.model, self.data, self._object_geom, self._nearest_points
        for i, geoms in enumerate(self._clearance_geoms):
            out[i] = min(mujoco.mj_geomDistance(m, d, g, cap, CLEARANCE_CUTOFF, pts) for g in geoms)
        return out

    def write_feature(self, name: str, out: np.ndarray) -> np.ndarray:
        """Write the named observation feature (:data:`OBS_FEATURES`) of the current state into ``out[:width]``;
        ValueError for an unknown name."""
        if name == "capsule_pose":
            return self.capsule_pose_features(out)
        if name == "claw_pose":
            return self.claw_pose_features(out)
        if name == "arm_clearance":
            return self.arm_clearance_features(out)
        raise ValueError(f"unknown observation feature {name!r} (known: {', '.join(OBS_FEATURES)})")

    def feature(self, name: str) -> np.ndarray:
        """The named observation feature (:data:`OBS_FEATURES`) of the current state, ``[width]``; ValueError for an
        unknown name."""
        return self.write_feature(name, np.empty(OBS_FEATURES.get(name, 0)))

    @property
    def target(self) -> np.ndarray:
        """T: the centre of the shadow capsule, where the capsule should be moved. [3]"""
        return self._target_v

    @property
    def forearm_axis(self) -> np.ndarray:
        """Unit vector along the forearm, world frame. [3]"""
        return self.data.xmat[self._forearm_body].reshape(3, 3)[:, 0]

    def finger_gap(self) -> float:
        """d(FT1, FT2): distance between the finger tips, metres."""
        a, b = self.fingertips
        return _dist(a, b)

    def hand_to_capsule(self) -> float:
        """d(H, C), metres."""
        return _dist(self.hand, self.capsule)

    def hand_to_capsule_axis(self) -> float:
        """d(H, capsule axis): distance from H to the nearest point of the capsule's axis segment, metres.

        The axis is the capsule's core segment (half-length ``model.geom_size[object, 1]``, 3.5 cm either side of C);
        a claw that holds the capsule off its centre, which centred grips rarely avoid on a 12 cm capsule, has H
        near the axis but up to 4 cm from C."""
        c, h = self._capsule_v, self._hand_v
        ax = self._capsule_axis_v  # unit vector: column 2 of the capsule geom's rotation (MuJoCo capsules lie along z)
        s = (h[0] - c[0]) * ax[2] + (h[1] - c[1]) * ax[5] + (h[2] - c[2]) * ax[8]
        s = min(max(s, -self._capsule_half_length), self._capsule_half_length)
        x, y, z = h[0] - c[0] - s * ax[2], h[1] - c[1] - s * ax[5], h[2] - c[2] - s * ax[8]
        return math.sqrt(x * x + y * y + z * z)

    def capsule_to_target(self) -> float:
        """d(C, T), metres."""
        return _dist(self.capsule, self.target)

    def base_observation(self, out: np.ndarray) -> np.ndarray:
        """Write the paper's 24 numbers into ``out[:24]``: angles, velocities, H, C."""
        d = self.data
        out[0:9] = d.qpos[0:9]
        out[9:18] = d.qvel[0:9]
        out[18:21] = self._hand_v
        out[21:24] = self._capsule_v
        return out

    # --- state setting ------------------------------------------------------------------------
    def reset(self) -> None:
        """Reset to the model's reference state (arm hanging, capsule at its spawn point)."""
        mujoco.mj_resetData(self.model, self.data)

    def set_arm(self, qpos: np.ndarray, qvel: np.ndarray | None = None) -> None:
        """Set the 9 joint angles (clipped to their ranges) and velocities (default zero)."""
        self.data.qpos[:N_JOINTS] = np.clip(qpos, self.joint_range[:, 0], self.joint_range[:, 1])
        self.data.qvel[:N_JOINTS] = 0.0 if qvel is None else qvel

    def set_state_vectors(self, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """Set every generalised position [nq] and velocity [nv]: the 9 hinges and the capsule's free joint."""
        m = self.model
        if np.shape(qpos) != (m.nq,) or np.shape(qvel) != (m.nv,):
            raise ValueError(f"state vectors must have shapes ({m.nq},), ({m.nv},); got {np.shape(qpos)}, {np.shape(qvel)}")
        self.data.qpos[:] = qpos
        self.data.qvel[:] = qvel

    def set_capsule(self, pos: np.ndarray, yaw: float = 0.0) -> None:
        """Place the capsule lying on its side at ``pos`` with its axis at angle ``yaw`` in the xy-plane."""
        a = self._obj_qpos
        self.data.qpos[a : a + 3] = pos
        # Lying capsule: rotate its z-axis onto the horizontal direction (cos yaw, sin yaw, 0).
        quat = np.empty(4)
        half = np.array([0.0, math.pi / 2, 0.0])  # pitch 90 degrees about y puts z along x
        mujoco.mju_euler2Quat(quat, half, "xyz")
        yaw_q = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
        out = np.empty(4)
        mujoco.mju_mulQuat(out, yaw_q, quat)
        self.data.qpos[a + 3 : a + 7] = out
        self.data.qvel[self._obj_dof : self._obj_dof + 6] = 0.0

    def set_target(self, pos: np.ndarray, yaw: float = 0.0) -> None:
        """Place the shadow capsule (target T)."""
        self.data.mocap_pos[self._target_mocap] = pos
        quat = np.empty(4)
        mujoco.mju_euler2Quat(quat, np.array([0.0, math.pi / 2, yaw]), "XYZ")
        self.data.mocap_quat[self._target_mocap] = quat

    def forward(self) -> None:
        """Recompute positions (``mj_forward``) after the state was set by hand."""
        mujoco.mj_forward(self.model, self.data)

    def arm_contacts(self) -> int:
        """Number of contacts between arm geoms and the table or the capsule (after ``forward``)."""
        d = self.data
        n = 0
        for i in range(d.ncon):
            c = d.contact[i]
            if c.dist < 0 and (c.geom1 in self._arm_geoms or c.geom2 in self._arm_geoms):
                n += 1
        return n

    def arm_clearance(self, distmax: float = 0.05) -> float:
        """The smallest distance between an arm geom (a link, the palm, a finger) and the capsule, metres, after
        ``forward`` (``mj_geomDistance``; negative while they overlap; ``distmax`` when every geom is farther)."""
        m, d, cap = self.model, self.data, self._object_geom
        return min(mujoco.mj_geomDistance(m, d, g, cap, distmax, self._nearest_points) for g in self._arm_geoms)

    # --- stepping -----------------------------------------------------------------------------
    def step(self, ctrl: np.ndarray) -> bool:
        """Advance one control period with torques ``ctrl`` in [-1, 1]^9.

        Returns False if MuJoCo hit an instability during the step (a NaN, inf or huge position, velocity or
        acceleration). MuJoCo then resets the state itself (mj_checkPos/Vel/Acc) and raises one of its warning
        counters (``data.warning[mjWARN_BADQPOS/BADQVEL/BADQACC]``); those counters are what is read here, so a
        blow-up is flagged at any step and substep, the first of an episode included (the simulated clock, which the
        reset sets back to 0, cannot tell a reset from a start at 0). Reading them costs well under a microsecond;
        they are set back to 0 once read, so every flagged step is a new one (:meth:`instability_warnings` keeps the
        counts of the last flagged step).
        """
        d = self.data
        d.ctrl[:] = ctrl  # MuJoCo clamps to ctrlrange because the motors are ctrllimited.
        start = time.thread_time()  # CPU time: a process preempted mid-step is not counted as physics
        mujoco.mj_step(self.model, d, self.config.substeps)
        self.physics_seconds += time.thread_time() - start
        qpos_w, qvel_w, qacc_w = self._instability_counters
        if qpos_w.number or qvel_w.number or qacc_w.number:
            self._last_warnings = {
                "bad_qpos": int(qpos_w.number),
                "bad_qvel": int(qvel_w.number),
                "bad_qacc": int(qacc_w.number),
            }
            qpos_w.number = qvel_w.number = qacc_w.number = 0
            return False
        return True

    def instability_warnings(self) -> dict[str, int]:
        """Counts of MuJoCo's instability warnings (bad qpos, qvel, qacc) raised during the last step that
        reported an instability (all 0 if none has)."""
        return dict(self._last_warnings)

    # --- kinematics helpers -------------------------------------------------------------------
    def hand_at(self, qpos: np.ndarray) -> np.ndarray:
        """H for joint angles ``qpos`` (does not change the current state). [3]"""
        saved = self.data.qpos.copy()
        self.data.qpos[:N_JOINTS] = qpos
        mujoco.mj_kinematics(self.model, self.data)
        h = self.data.site_xpos[self._hand].copy()
        self.data.qpos[:] = saved
        mujoco.mj_kinematics(self.model, self.data)
        return h

    def solve_hand_ik(
        self,
        goal: np.ndarray,
        q_init: np.ndarray,
        *,
        iters: int = 60,
        tol: float = 0.005,
        damping: float = 1e-2,
    ) -> tuple[np.ndarray, float]:
        """Joint angles that put H at ``goal``: damped least squares over the 7 arm joints.

        Starts from ``q_init`` [9], keeps every joint inside its range, leaves the fingers as
        given. Returns (qpos [9], final error in metres). Leaves the simulation state unchanged.
        """
        m, d = self.model, self.data
        saved = d.qpos.copy()
        q = np.clip(np.asarray(q_init, dtype=float), self.joint_range[:, 0], self.joint_range[:, 1])
        jac = np.zeros((3, m.nv))
        err = np.inf
        lo, hi = self.joint_range[:ARM_JOINTS, 0], self.joint_range[:ARM_JOINTS, 1]
        for _ in range(iters):
            d.qpos[:N_JOINTS] = q
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            e = goal - d.site_xpos[self._hand]
            err = float(np.sqrt(e @ e))
            if err < tol:
                break
            mujoco.mj_jacSite(m, d, jac, None, self._hand)
            j = jac[:, :ARM_JOINTS]
            dq = j.T @ np.linalg.solve(j @ j.T + damping**2 * np.eye(3), e)
            q[:ARM_JOINTS] = np.clip(q[:ARM_JOINTS] + dq, lo, hi)
        d.qpos[:] = saved
        mujoco.mj_kinematics(m, d)
        return q, err

    # --- rendering ----------------------------------------------------------------------------
    def render(self, width: int = 480, height: int = 360, camera: str = "front") -> np.ndarray:
        """An RGB image [height, width, 3] (uint8) of the current state, rendered off-screen."""
        if self._renderer is None or (self._renderer.width, self._renderer.height) != (width, height):
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = open_renderer(self.model, height, width)
        self._renderer.update_scene(self.data, camera=camera)
        return self._renderer.render()

    def close(self) -> None:
        """Release the off-screen renderer, if any."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def _dist(a: np.ndarray, b: np.ndarray) -> float:
    # Faster than np.linalg.norm for 3-vectors; this runs several times per control step.
    dx = a[0] - b[0]
    dy = a[1] - b[1]
    dz = a[2] - b[2]
    return math.sqrt(dx * dx + dy * dy + dz * dz)
