"""The Gymnasium environment that joins the arm's physics to one task.

Observation (float64): the paper's 24 base numbers, then the task's extra numbers.

    ======  ==========================================  =====
    index   meaning                                      unit
    ======  ==========================================  =====
    0-8     joint angles (s_abduction ... lc_close)      rad
    9-17    joint velocities                             rad/s
    18-20   hand H (capsule centre if gripped)           m
    21-23   capsule centre C                             m
    24-26   task extra: Reacher goal / Mover & reach-    m
            and-move target T (absent for gripping)
    ======  ==========================================  =====

Action: 9 torques in [-1, 1] (scaled by each motor's gear: 100, 100, 100, 70, 70, 30, 30, 10, 10).
Reward: the sum of the task's terms, each reported in ``info`` as ``reward_<term>``.
Episodes end by truncation after ``episode_steps`` steps (the paper: 300-500); tasks never
terminate early. A physics instability also truncates the episode (``info['physics_unstable']``).
"""

from __future__ import annotations

import functools
import logging
import math
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from hrlp import bounds
from hrlp.arm.physics import BASE_OBS_DIM, BASE_PARTS, N_JOINTS, OBS_FEATURES, TARGET_PART, ArmPhysics, PhysicsConfig
from hrlp.arm.tasks import Task

log = logging.getLogger(__name__)


@functools.cache
def _reward_key(term: str) -> str:
    # Built once per term name instead of formatting a string per term per step.
    return f"reward_{term}"


class ArmEnv(gym.Env[np.ndarray, np.ndarray]):
    """One of the paper's tasks on the arm with a claw.

    Args:
        task: the task (start distribution, reward terms, success test).
        episode_steps: steps before truncation (the paper: 300-500).
        physics: timestep, substeps and gravity.
        render_mode: None or 'rgb_array'.
        width, height, camera: the rendered image's size and the model camera ('front', 'side').
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 100}  # noqa: RUF012 (Gymnasium's convention)

    def __init__(
        self,
        task: Task,
        *,
        episode_steps: int = bounds.DEFAULT_EPISODE_STEPS,
        physics: PhysicsConfig | None = None,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 360,
        camera: str = "front",
    ) -> None:
        if isinstance(episode_steps, bool) or not isinstance(episode_steps, int) or episode_steps < 1:
            raise ValueError(f"{task.name}: episode_steps must be a positive integer, got {episode_steps!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"{task.name}: render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.task = task
        self.episode_steps = episode_steps
        self.physics = ArmPhysics(physics or PhysicsConfig())
        self.render_mode = render_mode
        self._render_args = (width, height, camera)
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.physics.config.control_period)}
        self.obs_dim = BASE_OBS_DIM + task.extra_obs_dim
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(self.obs_dim,), dtype=np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(N_JOINTS,), dtype=np.float64)
        self._obs = np.zeros(self.obs_dim)
        self._rng = np.random.default_rng()
        self._episodes = 0
        self._t = 0
        self._success = False
        self._sums = [0.0] * len(task.tracked)
        self._maxes = [0.0] * len(task.tracked_max)
        self._needs_reset = True

    # --- Gymnasium API ------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Start an episode from the task's start distribution."""
        super().reset(seed=seed)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        p = self.physics
        p.reset()
        self.task.reset(p, self._rng, self._episodes)
        p.forward()
        self._episodes += 1
        self._t = 0
        self._success = self.task.success(p)
        self._sums = [0.0] * len(self.task.tracked)
        self._maxes = [float(v) for v in self.task.track_max(p)]
        self._needs_reset = False
        return self._observe().copy(), {"success": self._success}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Apply 9 torques for one control period (``substeps`` physics steps)."""
        if self._needs_reset:
            raise RuntimeError(f"{self.task.name}: call reset() before step() (the episode has ended or not begun)")
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (N_JOINTS,):
            raise ValueError(f"{self.task.name}: action must have shape ({N_JOINTS},), got {a.shape}")
        if not math.isfinite(a.sum()) and not np.isfinite(a).all():  # the sum is the cheap check on the hot path
            raise ValueError(f"{self.task.name}: action contains NaN or inf: {a.tolist()}")
        p = self.physics
        self._t += 1
        if not p.step(a):
            return self._unstable()
        terms = self.task.reward_terms(p)
        if not self._success and self.task.success(p):
            self._success = True
        truncated = self._t >= self.episode_steps
        info: dict[str, Any] = {_reward_key(k): v for k, v in terms.items()}
        info["success"] = self._success
        if self._sums:
            for i, v in enumerate(self.task.track(p)):
                self._sums[i] += v
            for name, v in zip(self.task.tracked, self._sums, strict=True):
                info[f"{name}_sum"] = v
        if self._maxes:
            for i, v in enumerate(self.task.track_max(p)):
                self._maxes[i] = max(self._maxes[i], float(v))
            for name, v in zip(self.task.tracked_max, self._maxes, strict=True):
                info[f"{name}_max"] = v
        self._needs_reset = truncated
        return self._observe().copy(), sum(terms.values()), False, truncated, info

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """An RGB frame [height, width, 3] when ``render_mode == 'rgb_array'``."""
        if self.render_mode != "rgb_array":
            return None
        return self.physics.render(*self._render_args)

    def close(self) -> None:
        """Release the renderer."""
        self.physics.close()

    @property
    def physics_seconds(self) -> float:
        """CPU seconds this environment has spent inside ``mj_step`` (see :attr:`ArmPhysics.physics_seconds`)."""
        return self.physics.physics_seconds

    # --- exact save and restore (for resuming training mid-episode) ----------------------------
    def get_state(self) -> dict[str, Any]:
        """Everything needed to continue this environment exactly: physics, episode progress, task state, RNG.

        Arrays are returned as lists so the result is JSON-serialisable.
        """
        p = self.physics
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        phys = np.empty(mujoco.mj_stateSize(p.model, spec))
        mujoco.mj_getState(p.model, p.data, phys, spec)
        return {
            "physics": phys.tolist(),
            "obs": self._obs.tolist(),
            "t": self._t,
            "episodes": self._episodes,
            "success": self._success,
            "sums": list(self._sums),
            "maxes": list(self._maxes),
            "needs_reset": self._needs_reset,
            "rng": self._rng.bit_generator.state,  # PCG64: a dict of ints, JSON as it is
            "task": {k: np.asarray(v).tolist() for k, v in self.task.episode_state().items()},
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state from :meth:`get_state`."""
        p = self.physics
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        phys = np.asarray(state["physics"], dtype=np.float64)
        if phys.shape != (mujoco.mj_stateSize(p.model, spec),):
            raise ValueError(f"{self.task.name}: saved physics state has {phys.size} numbers, this model needs "
                             f"{mujoco.mj_stateSize(p.model, spec)}")  # fmt: skip
        mujoco.mj_setState(p.model, p.data, phys, spec)
        mujoco.mj_forward(p.model, p.data)
        self._obs[:] = state["obs"]
        self._t, self._episodes = int(state["t"]), int(state["episodes"])
        self._success, self._needs_reset = bool(state["success"]), bool(state["needs_reset"])
        self._sums = [float(v) for v in state["sums"]]
        # A state saved before the maxima were tracked restarts them from the current step.
        self._maxes = [float(v) for v in state.get("maxes", self.task.track_max(p))]
        self._rng = np.random.default_rng()
        self._rng.bit_generator.state = state["rng"]
        self.task.set_episode_state({k: np.asarray(v) for k, v in state["task"].items()})

    # --- named parts, for skills (hrlp.skills.core) ----------------------------------------------
    @property
    def observation_parts(self) -> dict[str, slice]:
        """The observation's named parts: :data:`~hrlp.arm.physics.BASE_PARTS`, and ``target`` for a task that
        observes one."""
        return {**BASE_PARTS, "target": TARGET_PART} if self.task.observes_target else dict(BASE_PARTS)

    #: Parts measured outside the observation (:meth:`measure`): the named features a skill may read.
    measurable: tuple[str, ...] = tuple(OBS_FEATURES)

    def measure(self, name: str) -> np.ndarray:
        """The named feature (:data:`~hrlp.arm.physics.OBS_FEATURES`) of the current state."""
        return self.physics.feature(name)

    # --- internals ----------------------------------------------------------------------------
    def _observe(self) -> np.ndarray:
        obs = self._obs
        self.physics.base_observation(obs)
        if self.task.extra_obs_dim:
            self.task.extra_observation(self.physics, obs[BASE_OBS_DIM:])
        return obs

    def _unstable(self) -> tuple[np.ndarray, float, bool, bool, dict]:
        # MuJoCo reset the state to keep going; continuing from there would silently teleport the
        # arm, so the episode is cut here and the last good observation is returned.
        warnings = self.physics.instability_warnings()
        log.warning("%s: physics became unstable at step %d %s; episode truncated", self.task.name, self._t, warnings)
        self._needs_reset = True
        info: dict[str, Any] = {f"reward_{k}": 0.0 for k in self._zero_terms()}
        info.update(success=self._success, physics_unstable=True, physics_warnings=warnings)
        return self._obs.copy(), 0.0, False, True, info

    def _zero_terms(self) -> list[str]:
        return list(self.task.reward_terms(self.physics))

    @property
    def episodes_started(self) -> int:
        """How many episodes this environment has started (the curriculum's k)."""
        return self._episodes

    @property
    def elapsed_steps(self) -> int:
        """Steps taken in the current episode."""
        return self._t
