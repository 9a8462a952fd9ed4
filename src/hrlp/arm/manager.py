"""A Manager's worlds on the arm's batched backend: :func:`hrlp.skills.core.decide` over a
:class:`~hrlp.arm.batched.BatchedArmEnv`, every world's physics stepped in one call per low-level step."""

from __future__ import annotations

from typing import Any

import numpy as np

from hrlp.arm.batched import BatchedArmEnv
from hrlp.arm.physics import N_JOINTS
from hrlp.envs.vector import VectorStep
from hrlp.skills.core import decide
from hrlp.skills.macro_env import MacroEnv


class BatchedMacroVectorEnv:
    """A Manager's ``N`` environments over one :class:`~hrlp.arm.batched.BatchedArmEnv`: the macro-action logic of
    :func:`step_macros` (:func:`decide`, batched skill inference) with the physics of every world stepped in one call
    per low-level step, the worlds whose macro-action has ended waiting (:meth:`BatchedArmEnv.advance`).

    Args:
        worlds: the ``N`` worlds of the low-level task; this object resets and steps them from now on.
        layout: a :class:`MacroEnv` of the same task giving the macro-actions (skills, durations, parameter blocks,
            hand-over, micro-action, gamma); its own environment is not stepped.

    Its steps are :class:`MacroVectorEnv`'s over ``N`` MacroEnvs of the same task and seeds, to within the batched
    physics' agreement with ArmEnv's (about 1e-7, :mod:`hrlp.arm.batched`); :meth:`get_state` has the same format.
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

        res = decide(self.layout.hierarchy, self._obs, actions, step, features, self._ran)
        next_obs = res.obs
        obs = next_obs.copy()
        self._ran[:] = res.choice
        ended = np.flatnonzero(res.terminated | res.truncated)
        if ended.size:
            obs[ended] = worlds.reset_worlds(ended)
            self._ran[ended] = -1
        self._obs = obs
        infos = {**last, "task_reward": res.task_reward, "choice": res.choice, "skill_done": res.skill_done}
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
