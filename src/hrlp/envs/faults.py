"""Faults of a user's environment, reported with their context (docs/reliability.md, "How a run stops").

An environment whose ``step`` or ``reset`` raises, returns something other than Gymnasium's tuples (the old Gym API
included) or an observation that does not fit its declared space is the user's code failing, not hrlp: the run ends
with one line that says which environment (its id and index), when (the step of its episode, the iteration), what
was expected and what came back, the user's own frames of the traceback (not hrlp's, Gymnasium's wrappers' or
multiprocessing's), and where the run stands (its last checkpoint, intact). :func:`step_env` and :func:`reset_env`
make the calls and the checks; each layer above adds what it knows (:class:`EnvFault`'s fields): the vector
environment the index, the sampler the episode step and the worker's offset, the training loop the iteration and
the checkpoint. The record is a plain dataclass, so a sampling worker sends it to the main process as it is.
"""

from __future__ import annotations

import dataclasses
import os
import traceback
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import gymnasium as gym
import numpy as np


@dataclass(frozen=True)
class EnvFault:
    """What went wrong in a user's environment, and where."""

    env_id: str
    """The environment's Gymnasium id (its class name when it has none)."""
    index: int
    """The environment's index among the run's environments (all workers' together)."""
    call: str
    """``step`` or ``reset``."""
    what: str
    """What was expected and what came back, or what the environment raised."""
    frames: str = ""
    """The innermost frames of the user's own code, ``env.py:31 in step <- ...`` (empty when none is outside hrlp)."""
    episode_step: int | None = None
    """The step of the environment's episode that failed (None for a reset, or where unknown)."""
    decision: bool = False
    """Whether ``episode_step`` begins a Manager's decision (one or more low-level steps) rather than one step."""
    iteration: int | None = None
    """The training iteration it happened in (None: not known here, or before the first)."""
    run_state: str = ""
    """Where the run stands, e.g. ``the run's last checkpoint (iteration 1, 64 steps) is intact; --resume continues it``."""

    def line(self) -> str:
        """The one line: ``Faulty-v0, environment 1, step 30 of its episode, iteration 2: step() raised RuntimeError:
        boom (at fault_env.py:31 in step); the run's last checkpoint (iteration 1, 64 steps) is intact; ...``."""
        where = [self.env_id, f"environment {self.index}"]
        if self.call == "reset":
            where.append("at the reset that starts an episode")
        elif self.episode_step is not None:
            step = f"step {self.episode_step} of its episode"
            where.append(f"the decision from {step}" if self.decision else step)
        if self.iteration is not None:
            where.append(f"iteration {self.iteration}")
        out = f"{', '.join(where)}: {self.what}"
        if self.frames:
            out += f" (at {self.frames})"
        return out + (f"; {self.run_state}" if self.run_state else "")


class EnvError(ValueError):
    """A user's environment failed (:class:`EnvFault`); ``str()`` is the fault's one line."""

    def __init__(self, fault: EnvFault) -> None:
        super().__init__(fault)
        self.fault = fault

    def __str__(self) -> str:
        return self.fault.line()

    def adding(self, **fields: Any) -> EnvError:
        """The same fault with ``fields`` set (those already known are kept)."""
        known = {k: v for k, v in fields.items() if getattr(self.fault, k) in (None, "", False)}
        return EnvError(dataclasses.replace(self.fault, **known))


def env_label(env: gym.Env) -> str:
    """The environment's Gymnasium id, or its class name where it was built without one."""
    spec = getattr(env, "spec", None)
    return spec.id if spec is not None and getattr(spec, "id", None) else type(getattr(env, "unwrapped", env)).__name__


_NOT_USER_DIRS = (Path(__file__).parents[1], Path(gym.__file__).parent, Path(np.__file__).parent,
                  Path(os.__file__).parent / "multiprocessing")  # fmt: skip
_NOT_USER = tuple(str(p.resolve()) + os.sep for p in _NOT_USER_DIRS)
"""Directories whose frames are not the user's: hrlp, Gymnasium (its wrappers sit between hrlp and the environment),
NumPy (where a user's array call fails, the user's line is the one to show), multiprocessing."""


def user_frames(tb: TracebackType | None, limit: int = 3) -> str:
    """The innermost ``limit`` frames of ``tb`` outside hrlp, Gymnasium, NumPy and multiprocessing, innermost first:
    ``my_env.py:31 in step <- my_env.py:12 in _physics``; paths under the working directory are relative."""
    frames = [f for f in traceback.extract_tb(tb) if not str(Path(f.filename).resolve()).startswith(_NOT_USER)]
    shown = []
    for f in reversed(frames[-limit:]):
        path = f.filename
        try:
            rel = os.path.relpath(path)
            path = path if rel.startswith("..") else rel
        except ValueError:  # another drive (Windows)
            pass
        shown.append(f"{path}:{f.lineno} in {f.name}")
    return " <- ".join(shown)


def raised_in(env: gym.Env, index: int, call: str, error: Exception) -> EnvError:
    """The :class:`EnvError` for ``error``, raised by ``env.CALL()`` (the user's frames from its traceback)."""
    message = " ".join(str(error).split())
    return EnvError(EnvFault(env_label(env), index, call, f"{call}() raised {type(error).__name__}" +
                             (f": {message}" if message else ""), user_frames(error.__traceback__)))  # fmt: skip


def _shown(value: Any) -> str:
    """What came back, briefly: ``an array of shape (5,)``, ``a tuple of 4 values``, ``None``."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape}"
    if isinstance(value, tuple | list):
        return f"a {type(value).__name__} of {len(value)} values"
    return "None" if value is None else f"a {type(value).__name__}"


def flat_observation(env: gym.Env, obs: Any, index: int, call: str, obs_dim: int) -> np.ndarray:
    """``obs`` as a float64 row of ``obs_dim`` numbers; :class:`EnvError` when it does not fit the declared space."""
    try:
        row = np.asarray(obs, dtype=np.float64)
    except (TypeError, ValueError):
        row = None
    if row is None or row.size != obs_dim:
        space = env.observation_space
        got = _shown(obs) if row is None else f"an observation of shape {row.shape}"
        raise EnvError(EnvFault(env_label(env), index, call, f"{call}() returned {got}; the observation space is "
                                f"{space} ({obs_dim} numbers)"))  # fmt: skip
    return row.reshape(obs_dim)


def step_env(env: gym.Env, action: Any, index: int, obs_dim: int | None = None) -> tuple[Any, Any, Any, Any, Any]:
    """``env.step(action)`` as Gymnasium's five values; what the environment raises, or a result of another shape
    (the old Gym API's four values), is an :class:`EnvError` naming environment ``index``. With ``obs_dim`` the
    observation comes back as a float64 row of that many numbers (:func:`flat_observation`)."""
    try:
        result = env.step(action)
    except Exception as e:
        raise raised_in(env, index, "step", e) from e
    if not isinstance(result, tuple) or len(result) != 5:
        old = " (the old Gym API's observation, reward, done, info)" if isinstance(result, tuple) and len(result) == 4 else ""
        raise EnvError(EnvFault(env_label(env), index, "step", "step() must return (observation, reward, terminated, "
                                f"truncated, info); it returned {_shown(result)}{old}"))  # fmt: skip
    if obs_dim is None:
        return result
    obs, reward, terminated, truncated, info = result
    return flat_observation(env, obs, index, "step", obs_dim), reward, terminated, truncated, info


def reset_env(env: gym.Env, index: int, obs_dim: int | None = None, **kwargs: Any) -> tuple[Any, dict]:
    """``env.reset(**kwargs)`` as Gymnasium's ``(observation, info)``; what the environment raises, or an observation
    alone (the old Gym API), is an :class:`EnvError` naming environment ``index``. With ``obs_dim``, the observation
    as :func:`step_env` gives it."""
    try:
        result = env.reset(**kwargs)
    except Exception as e:
        raise raised_in(env, index, "reset", e) from e
    if not (isinstance(result, tuple) and len(result) == 2 and isinstance(result[1], dict)):
        old = ", the observation alone, as the old Gym API (before 0.26) returned it" if not isinstance(result, tuple) else ""
        raise EnvError(EnvFault(env_label(env), index, "reset", "reset() must return (observation, info); it returned "
                                f"{_shown(result)}{old}"))  # fmt: skip
    if obs_dim is None:
        return result
    return flat_observation(env, result[0], index, "reset", obs_dim), result[1]


__all__ = ["EnvError", "EnvFault", "env_label", "flat_observation", "raised_in", "reset_env", "step_env", "user_frames"]
