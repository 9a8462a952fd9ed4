"""Batched sampling: many environments stepped together, one policy call per step for all of them.

Per-observation policy calls, not physics, are what make RL libraries slow on small networks (a torch call on 64
observations costs what one on a single observation does: ``benchmarks/policy_call.py``), so the sampler keeps ``N``
environments in one process and asks the
policy for ``N`` actions at once. It sees them only as a :class:`~hrlp.envs.vector.VectorEnv`
(one step record, same-step autoreset): ordinary Gymnasium environments (:class:`~hrlp.envs.vector.SerialVectorEnv`),
a Manager's macro-action environments (:class:`~hrlp.skills.macro_env.ManagerVectorEnv`, batched skill
inference) or a batched physics backend (:class:`~hrlp.arm.batched.BatchedArmEnv`) go through the same
loop, and every batch carries the per-decision discount (gamma for a flat step, gamma^tau for a
macro-action of tau low-level steps). Time is accounted per phase (environment, inference) so a
training run can report where its wall time goes.
"""

from __future__ import annotations

import dataclasses
import math
import os
import pickle
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from hrlp.envs.faults import EnvError
from hrlp.envs.vector import NO_SUCCESS_TEST, SerialVectorEnv, VectorConstructor, VectorEnv, VectorStep
from hrlp.envs.vector import action_decoder as action_decoder  # re-exported: its home is hrlp.envs.vector
from hrlp.policies.mlp import Policy
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.skills.macro_env import MacroEnv, ManagerVectorEnv, manager_vector_env
from hrlp.stopping import children_ignore_stop_signals, ignore_stop_signals

DEFAULT_GAMMA = 0.99
"""The discount of a flat step when none is given (:class:`hrlp.config.AdvantageConfig`'s default)."""


class NonFiniteError(ValueError):
    """NaN or inf where data enters training (an observation, a reward, an action, a value target), named by the
    environment index, the step and the field, raised before the data reaches the normaliser, the networks or a
    checkpoint."""


FLOAT32_MAX = float(np.finfo(np.float32).max)
"""Batches are float32 tensors: a reward beyond this is finite here but infinite in the batch."""


def first_non_finite(values: np.ndarray | torch.Tensor, bound: float = math.inf) -> tuple[int, ...] | None:
    """The index of the first NaN or inf in ``values`` (C order) -- or, with ``bound``, of the first value whose
    magnitude exceeds it -- or None if there is none."""
    a = values.detach().cpu().numpy() if isinstance(values, torch.Tensor) else np.asarray(values)
    bad = np.argwhere(~(np.abs(a) <= bound)) if bound < math.inf else np.argwhere(~np.isfinite(a))
    return None if bad.size == 0 else tuple(int(i) for i in bad[0])


@dataclass(frozen=True)
class Batch:
    """``T`` steps of ``N`` environments, time-major. Observations are normalised as the policy saw them."""

    obs: torch.Tensor  # [T, N, obs_dim] policy inputs
    next_obs: torch.Tensor  # [T, N, obs_dim] the observation after each step (the real final one at episode ends)
    actions: torch.Tensor  # [T, N, act_dim] actions as sampled (before clipping to the action space)
    rewards: torch.Tensor  # [T, N]
    terminated: torch.Tensor  # [T, N] bool: the MDP ended (no bootstrap)
    truncated: torch.Tensor  # [T, N] bool: cut by a time limit or fault (bootstrap from next_obs)
    discount: torch.Tensor  # [T, N] gamma^tau per decision (gamma for a flat step, tau = 1)
    env_steps: int = 0  # low-level environment steps (T * N for flat policies, the sum of the taus for a Manager)

    @property
    def steps(self) -> int:
        """Decisions in the batch (T * N)."""
        return self.rewards.numel()


@dataclass(frozen=True)
class Episode:
    """One finished episode's summary."""

    ret: float
    """Undiscounted return of the task's rewards."""
    length: int
    """Low-level environment steps."""
    success: bool | None
    """``info['success']`` at the end (Definition 1 on gripping tasks), None if the task has no success test."""
    target_dist_sum: float | None = None
    """TargetDistSum (reach-and-move, Movers), None elsewhere."""


@dataclass
class Timing:
    """Seconds spent per phase of sampling."""

    env: float = 0.0
    """Stepping the environments (physics included)."""
    inference: float = 0.0
    """Normalising observations and sampling actions."""
    physics: float = 0.0
    """CPU time inside ``mj_step``, summed over every environment (and every worker); NaN where an environment does
    not report it (``physics_seconds``: hrlp's tasks and the Manager's view of them do, Gymnasium's do not)."""


def vector_env(envs: Sequence[gym.Env], gamma: float | None = None) -> VectorEnv:
    """The :class:`~hrlp.envs.vector.VectorEnv` that steps ``envs`` together: a
    :class:`~hrlp.skills.macro_env.ManagerVectorEnv` for a Manager's :class:`~hrlp.skills.macro_env.MacroEnv`s (their own
    gamma; a different ``gamma`` is refused, since it would discount the decisions otherwise than inside them), else a
    :class:`~hrlp.envs.vector.SerialVectorEnv` with ``gamma`` per step (default :data:`DEFAULT_GAMMA`)."""
    macro = [isinstance(env, MacroEnv) for env in envs]
    if any(macro):
        if not all(macro):
            raise ValueError("vector_env: the environments mix MacroEnvs and other environments")
        vec = manager_vector_env(envs)  # type: ignore[arg-type]
        if gamma is not None and gamma != vec.gamma:
            raise ValueError(f"vector_env: gamma {gamma} differs from the MacroEnvs' own ({vec.gamma})")
        return vec
    return SerialVectorEnv(envs, DEFAULT_GAMMA if gamma is None else gamma)


def build_vector_env(env_fns: Sequence[Callable[[], gym.Env]], gamma: float | None = None) -> VectorEnv:
    """The :class:`~hrlp.envs.vector.VectorEnv` of ``env_fns``: the constructor's own when every one is the same
    :class:`~hrlp.envs.vector.VectorConstructor` (the batched backend of ``TrainConfig.backend``: a
    :class:`~hrlp.arm.batched.BatchedArmEnv`, or a Manager's :class:`~hrlp.skills.macro_env.ManagerVectorEnv` over one),
    else :func:`vector_env` of the environments they build."""
    first = env_fns[0]
    if isinstance(first, VectorConstructor) and all(fn is first for fn in env_fns):
        return first.vector(len(env_fns), DEFAULT_GAMMA if gamma is None else gamma)
    return vector_env([fn() for fn in env_fns], gamma)


class Sampler:
    """Steps ``N`` environments with batched policy inference, through one :class:`~hrlp.envs.vector.VectorEnv`.

    Args:
        env_fns: one constructor per environment (stepped by :func:`build_vector_env`), or a ready VectorEnv (e.g. a
            :class:`~hrlp.arm.batched.BatchedArmEnv`), which the sampler then owns.
        policy: the policy; called once per step on ``[N, obs_dim]``.
        normalizer: observation normaliser. Its statistics stay fixed during a batch, so the policy and the value
            baseline see every observation of the batch normalised alike; they are updated with the batch's raw
            observations at its end (unless frozen).
        seed: environment ``i`` is reset first with ``seed + i``; actions use a torch generator seeded with ``seed``.
        first_index: the index of the first environment in error messages (a sampling worker's share starts there).
        gamma: the discount of a flat step (``Batch.discount``); None: :data:`DEFAULT_GAMMA`. MacroEnvs and a ready
            VectorEnv discount with their own.

    One loop for every kind of environment: a step's rewards, discounts (gamma^tau), flags and observations come
    from :class:`~hrlp.envs.vector.VectorStep`; episode returns count the task's undiscounted rewards
    (``infos['task_reward']`` where the environment reports it, as a Manager's does, else the rewards), lengths the
    low-level steps (the sum of the taus), and ``Batch.env_steps`` the taus of the batch.

    Every observation (at reset and after each step), reward and action is checked for NaN and inf as it enters;
    the first non-finite one raises :class:`NonFiniteError` naming the environment, the step and the field, before
    the batch reaches the normaliser.
    """

    def __init__(
        self,
        env_fns: Sequence[Callable[[], gym.Env]] | VectorEnv,
        policy: Policy,
        normalizer: RunningNormalizer,
        seed: int = 0,
        first_index: int = 0,
        gamma: float | None = None,
    ) -> None:
        if isinstance(env_fns, VectorEnv):
            self.vector_env: VectorEnv = env_fns
        elif not env_fns:
            raise ValueError("Sampler needs at least one environment")
        else:
            self.vector_env = build_vector_env(env_fns, gamma)
        self.policy = policy
        self.normalizer = normalizer
        self.generator = torch.Generator().manual_seed(seed)
        self.first_index = first_index
        n = self.num_envs
        self._ret = np.zeros(n)
        self._len = np.zeros(n, dtype=np.int64)
        try:
            self._obs = np.asarray(self.vector_env.reset(seed=seed), dtype=np.float64).copy()
        except EnvError as e:
            raise self._located(e) from None
        self.timing = Timing()
        self.last_raw_obs: np.ndarray | None = None  # [T, N, obs_dim] raw observations of the last batch
        self.last_raw_next_obs: np.ndarray | None = None  # [T, N, obs_dim] raw observations each step produced
        self.last_tau: np.ndarray | None = None  # [T, N] low-level steps of each decision
        self.last_path: np.ndarray | None = None  # [T, N, K, obs_dim] a Manager's observations inside each decision
        self._requested: int | None = None

    @property
    def num_envs(self) -> int:
        """N, the number of environments."""
        return self.vector_env.num_envs

    @property
    def keep_paths(self) -> bool:
        """Whether :meth:`collect` keeps a Manager's observations inside each decision in :attr:`last_path` (off-policy goal
        relabelling reads them; off by default: a large on-policy batch need not compute nor hold them)."""
        return bool(getattr(self.vector_env, "record_paths", False))

    @keep_paths.setter
    def keep_paths(self, value: bool) -> None:
        if hasattr(self.vector_env, "record_paths"):
            self.vector_env.record_paths = bool(value)

    def request(self, steps_per_env: int) -> None:
        """Ask for a batch of ``steps_per_env`` steps per environment; :meth:`receive` samples and returns it.

        The same two-call protocol as :class:`ParallelSampler`, whose workers sample in between."""
        self._requested = steps_per_env

    def receive(self) -> tuple[Batch, list[Episode]]:
        """The batch asked for by :meth:`request`, sampled now."""
        steps, self._requested = self._requested, None
        if steps is None:
            raise RuntimeError("receive() without a request()")
        return self.collect(steps)

    def collect(self, steps_per_env: int) -> tuple[Batch, list[Episode]]:
        """Run ``steps_per_env`` steps in every environment; returns the batch and the episodes that finished."""
        n, dim = self.num_envs, self._obs.shape[1]
        obs_buf = np.empty((steps_per_env, n, dim))
        next_buf = np.empty((steps_per_env, n, dim))
        rewards = np.empty((steps_per_env, n))
        discount = np.empty((steps_per_env, n))
        terminated = np.zeros((steps_per_env, n), dtype=bool)
        truncated = np.zeros((steps_per_env, n), dtype=bool)
        actions_buf: np.ndarray | None = None
        episodes: list[Episode] = []
        raw_buf = np.empty((steps_per_env, n, dim))
        raw_next = np.empty((steps_per_env, n, dim))
        tau_buf = np.empty((steps_per_env, n), dtype=np.int64)
        path_buf: np.ndarray | None = None
        env_steps = 0
        physics = 0.0
        act = self.policy.numpy_actor()  # the weights stay fixed during a batch
        if not np.isfinite(self._obs).all():  # a reset's (or a restored state's) observation
            self._non_finite(-1, {"observation": self._obs}, None)
        for t in range(steps_per_env):
            t0 = time.perf_counter()
            raw_buf[t] = self._obs
            obs_buf[t] = self.normalizer.normalize(self._obs)
            actions = act(obs_buf[t].astype(np.float32), self.generator)
            rows = actions.reshape(n, -1)  # flat rows (a Discrete action is one number)
            if not np.isfinite(actions).all():
                self._non_finite(t, {"action": rows}, self._len + 1)
            if actions_buf is None:
                actions_buf = np.empty((steps_per_env, *actions.shape))
            actions_buf[t] = actions
            t1 = time.perf_counter()
            try:
                step = self.vector_env.step(rows)
            except EnvError as e:  # the user's environment failed: name it by its run-wide index and its episode step
                raise self._located(e) from None
            t2 = time.perf_counter()
            episode_steps = self._len + step.tau  # per environment, the step of its episode taken last
            rewards[t], discount[t] = step.rewards, step.discount
            terminated[t], truncated[t] = step.terminated, step.truncated
            self._ret += step.infos.get("task_reward", step.rewards)
            self._len += step.tau
            env_steps += int(step.tau.sum())
            physics += step.physics_seconds
            for i in np.flatnonzero(step.done):
                episodes.append(self._finish(int(i), step))
            self._obs[:] = step.obs
            # A few microseconds per step for all environments: every number that enters training is finite.
            # (A reward beyond float32's range is finite here but infinite in the float32 batch: it counts as non-finite.)
            ok_rewards = np.abs(rewards[t]).max() <= FLOAT32_MAX  # False for NaN too
            if not (ok_rewards and np.isfinite(step.next_obs).all() and np.isfinite(self._obs).all()):
                self._non_finite(t, {"reward": rewards[t], "observation": step.next_obs, "reset observation": self._obs},
                                 episode_steps)  # fmt: skip
            next_buf[t] = self.normalizer.normalize(step.next_obs)
            raw_next[t], tau_buf[t] = step.next_obs, step.tau
            if step.path is not None:
                if path_buf is None:
                    path_buf = np.empty((steps_per_env, *step.path.shape))
                path_buf[t] = step.path
            self.timing.inference += t1 - t0
            self.timing.env += t2 - t1
        assert actions_buf is not None
        self.timing.physics += physics
        self.last_raw_obs, self.last_raw_next_obs, self.last_tau, self.last_path = raw_buf, raw_next, tau_buf, path_buf
        if not self.normalizer.frozen:
            self.normalizer.update(raw_buf.reshape(-1, dim))
        f32 = torch.float32
        batch = Batch(
            obs=torch.as_tensor(obs_buf, dtype=f32),
            next_obs=torch.as_tensor(next_buf, dtype=f32),
            actions=torch.as_tensor(actions_buf, dtype=f32),
            rewards=torch.as_tensor(rewards, dtype=f32),
            terminated=torch.as_tensor(terminated),
            truncated=torch.as_tensor(truncated),
            discount=torch.as_tensor(discount, dtype=f32),
            env_steps=env_steps,
        )
        return batch, episodes

    @property
    def resumable(self) -> bool:
        """Whether every environment can save and restore its exact state (hrlp tasks can; most Gymnasium ids not)."""
        return self.vector_env.resumable

    def get_state(self) -> dict:
        """The sampler's progress (JSON): current observations, running returns, and each environment's exact state."""
        return {
            "obs": self._obs.tolist(),
            "ret": self._ret.tolist(),
            "len": self._len.tolist(),
            "envs": self.vector_env.get_state()["envs"] if self.resumable else None,
        }

    def set_state(self, state: dict) -> None:
        """Restore :meth:`get_state`. Environments that cannot be restored keep their fresh episodes."""
        if state["envs"] is None or not self.resumable:
            return
        if len(state["envs"]) != self.num_envs:
            raise ValueError(f"saved sampler has {len(state['envs'])} environments, this one {self.num_envs}")
        self.vector_env.set_state({"envs": state["envs"], "obs": state["obs"]})
        self._obs[:] = state["obs"]
        self._ret[:] = state["ret"]
        self._len[:] = state["len"]

    def _non_finite(self, t: int, fields: dict[str, np.ndarray], steps: np.ndarray | None) -> None:
        """Raise :class:`NonFiniteError` for the first non-finite value of ``fields`` (each ``[N]`` or ``[N, D]``).

        ``t``: the decision of the batch (-1: before the first); ``steps``: per environment, the step of its episode the
        values belong to (None: they come from a reset). A field named ``reset observation`` always comes from a reset.
        """
        for name, values in fields.items():
            where = first_non_finite(values, FLOAT32_MAX if name == "reward" else math.inf)
            if where is None:
                continue
            i = where[0]
            field = name if len(where) == 1 else f"{name}[{where[1]}]"
            if steps is None or name == "reset observation":
                when = "at the reset that starts an episode"
            else:
                when = f"at step {int(steps[i])} of its episode"
            if t >= 0:
                when += f" (decision {t + 1} of this batch)"
            value = float(values[where])
            shown = f"{value}, beyond float32's range" if math.isfinite(value) else str(value)
            raise NonFiniteError(f"non-finite {field} ({shown}) from environment {self.first_index + i} {when}; "
                                 "stopped before it entered the normaliser, the networks or a checkpoint")  # fmt: skip
        raise AssertionError("_non_finite called with finite values")  # pragma: no cover

    def _located(self, error: EnvError) -> EnvError:
        """``error`` (raised by environment ``i`` of this sampler's vector environment) with the environment's index
        among all the run's and, for a step, the step of its episode that failed."""
        fault = error.fault
        i = fault.index
        step = None if fault.call == "reset" or not 0 <= i < self.num_envs else int(self._len[i]) + 1
        return EnvError(dataclasses.replace(fault, index=self.first_index + i, episode_step=step,
                                            decision=isinstance(self.vector_env, ManagerVectorEnv)))  # fmt: skip

    def _finish(self, i: int, step: VectorStep) -> Episode:
        """Environment ``i``'s episode, ended at ``step``; its running return and length start again."""
        no_test = step.infos.get(NO_SUCCESS_TEST)
        tds = step.infos.get("target_dist_sum")
        ep = Episode(
            ret=float(self._ret[i]),
            length=int(self._len[i]),
            success=None if no_test is not None and no_test[i] else bool(step.success[i]),
            target_dist_sum=None if tds is None or math.isnan(tds[i]) else float(tds[i]),
        )
        self._ret[i] = 0.0
        self._len[i] = 0
        return ep

    def close(self) -> None:
        """Close every environment."""
        self.vector_env.close()


class ParallelSampler:
    """A :class:`Sampler` whose environments are split over ``workers`` processes that sample at the same time.

    Each worker steps its share of the environments with its own copy of the policy (batched inference over its
    share), receives the current weights and normaliser statistics before every batch, and returns its part of
    the batch, which is joined along the environment axis in environment order; the normaliser is then updated
    in this process with every raw observation, as :class:`Sampler` does. Worker ``w`` seeds its environments
    like :class:`Sampler` would (``seed + i`` for environment ``i``) and its action noise with ``seed + 7919 w``,
    so a run is reproducible for a given number of workers, and :meth:`get_state`/:meth:`set_state` make it
    exactly resumable. Environment constructors must be picklable (``hrlp.train.env_factory``'s are); ``gamma`` is
    :class:`Sampler`'s.
    """

    generator = None  # the action-noise generators live in the workers (their states are in get_state())

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], policy: Policy, normalizer: RunningNormalizer,
                 seed: int = 0, workers: int = 2, gamma: float | None = None) -> None:  # fmt: skip
        import multiprocessing as mp
        from multiprocessing import util as mp_util

        if workers < 2 or workers > len(env_fns):
            raise ValueError(f"ParallelSampler needs 2 <= workers <= environments ({len(env_fns)}), got {workers}")
        self.policy, self.normalizer = policy, normalizer
        self.timing = Timing()
        self.last_raw_obs: np.ndarray | None = None
        bounds = np.linspace(0, len(env_fns), workers + 1).astype(int)
        ctx = mp.get_context("spawn")  # no fork: torch and MuJoCo state must not be shared with children
        self._conns: list[Any] = []
        self._procs: list[Any] = []
        self.num_envs = len(env_fns)
        self._pending = False
        # Workers left running by a run that ends in an exception (a stop signal mid-start-up included) are killed when
        # this object goes or the interpreter exits: they ignore SIGTERM, which multiprocessing's exit would send them
        # before waiting for them (its finalizers with an exit priority run first).
        self._finalizer = mp_util.Finalize(self, _kill_workers, args=(self._procs, self._conns), exitpriority=10)
        try:
            for w in range(workers):
                parent, child = ctx.Pipe()
                self._conns.append(parent)
                chunk = list(env_fns[bounds[w] : bounds[w + 1]])
                # The policy goes as bytes and batches come back as arrays: torch's own pickling would share their
                # memory through a server thread of the sender, which prints a traceback when the other side is killed
                # mid-handshake (as a stop kills the workers).
                args = (child, chunk, pickle.dumps(policy), normalizer.config(), seed + int(bounds[w]), seed + 7919 * w,
                        int(bounds[w]), os.getpid(), gamma)  # fmt: skip
                proc = ctx.Process(target=_sampler_worker, args=args, daemon=True)
                self._procs.append(proc)  # before it starts: a stop as it starts (acted on right after) must find it
                with children_ignore_stop_signals():  # a Ctrl-C while the worker imports torch is this process's
                    proc.start()
                child.close()
            for conn in self._conns:
                _receive(conn)  # each worker reports ready (or the error that stopped it)
        except BaseException:
            self._finalizer()
            raise

    def collect(self, steps_per_env: int) -> tuple[Batch, list[Episode]]:
        """Every worker samples ``steps_per_env`` steps of its environments at once; returns the joined batch."""
        self.request(steps_per_env)
        return self.receive()

    def request(self, steps_per_env: int) -> None:
        """Send the current weights and normaliser statistics and start every worker on its share of a batch.

        Returns at once: this process is free (e.g. to fit the value function) until :meth:`receive`."""
        if self._pending:
            raise RuntimeError("request() while a batch is still being sampled; receive() it first")
        weights = {k: v.detach().cpu().numpy() for k, v in self.policy.state_dict().items()}
        stats = {k: v.numpy() for k, v in self.normalizer.state_dict().items()}
        self._pending = True  # from the first message on: close() then kills the workers instead of waiting for them
        for conn in self._conns:
            conn.send(("collect", (weights, stats, steps_per_env)))

    def receive(self) -> tuple[Batch, list[Episode]]:
        """Wait for the batch started by :meth:`request`; returns it joined in environment order."""
        if not self._pending:
            raise RuntimeError("receive() without a request()")
        parts = [_receive(conn) for conn in self._conns]
        self._pending = False
        fields = ("obs", "next_obs", "actions", "rewards", "terminated", "truncated", "discount")
        joined = {f: torch.cat([torch.from_numpy(p["batch"][f]) for p in parts], dim=1) for f in fields}
        raw = np.concatenate([p["raw"] for p in parts], axis=1)
        self.last_raw_obs = raw
        if not self.normalizer.frozen:
            self.normalizer.update(raw.reshape(-1, raw.shape[-1]))
        self.timing.env += max(p["env"] for p in parts)
        self.timing.inference += max(p["inference"] for p in parts)
        self.timing.physics += sum(p["physics"] for p in parts)
        batch = Batch(**joined, env_steps=sum(p["batch"]["env_steps"] for p in parts))
        return batch, [e for p in parts for e in p["episodes"]]

    def get_state(self) -> dict:
        """Each worker's sampler state and action-noise generator state (JSON)."""
        for conn in self._conns:
            conn.send(("get_state", None))
        return {"workers": [_receive(conn) for conn in self._conns]}

    def set_state(self, state: dict) -> None:
        """Restore :meth:`get_state` (the number of workers must match)."""
        if len(state.get("workers", [])) != len(self._conns):
            raise ValueError(f"saved sampler state has {len(state.get('workers', []))} workers, this run {len(self._conns)}")
        for conn, part in zip(self._conns, state["workers"], strict=True):
            conn.send(("set_state", part))
        for conn in self._conns:
            _receive(conn)

    def close(self) -> None:
        """Stop the workers: between batches they close their environments and end; in the middle of one (a run
        stopped or failed while they sample, whose batch nobody will read) they are killed at once."""
        if self._pending:
            self._finalizer()
            return
        for conn in self._conns:
            try:
                conn.send(("close", None))
            except (BrokenPipeError, OSError):
                pass
        for proc in self._procs:
            proc.join(timeout=10)
        self._finalizer()  # any worker still alive


def _kill_workers(procs: list[Any], conns: list[Any]) -> None:
    """Kill every worker process still alive and wait for it (SIGKILL: workers ignore the stop signals)."""
    started = [proc for proc in procs if proc.pid is not None]
    for proc in started:
        if proc.is_alive():
            proc.kill()
    for proc in started:
        proc.join(timeout=10)
    for conn in conns:
        conn.close()


def _receive(conn: Any) -> Any:
    """A worker's reply; a worker's exception is raised here with its message."""
    try:
        kind, payload = conn.recv()
    except EOFError:
        raise RuntimeError("a sampler worker process died") from None
    if kind == "non-finite":
        raise NonFiniteError(payload)
    if kind == "env-error":  # the user's environment failed in the worker: the fault, as the worker's sampler named it
        raise EnvError(payload)
    if kind == "error":
        raise RuntimeError(f"sampler worker failed: {payload}")
    return payload


def die_with_parent(parent_pid: int) -> None:
    """Have the kernel kill this process when its parent dies (Linux ``PR_SET_PDEATHSIG``), so that a trainer killed
    with SIGKILL leaves no sampling workers behind; elsewhere a worker ends at its next message (EOF on the pipe)."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1: PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:  # the parent died before the request took effect
        os._exit(0)


def _sampler_worker(conn: Any, env_fns: list, policy_bytes: bytes, norm_config: dict, env_seed: int, noise_seed: int,
                    first_index: int = 0, parent_pid: int | None = None, gamma: float | None = None) -> None:  # fmt: skip
    """Worker loop: own environments, a policy copy and a frozen normaliser copy; answer collect/state requests.

    It ignores the stop signals (the parent stops it: :mod:`hrlp.stopping`), dies with its parent
    (:func:`die_with_parent`) and ends quietly when the parent's end of the pipe closes."""
    ignore_stop_signals()
    if parent_pid is not None:
        die_with_parent(parent_pid)
    torch.set_num_threads(1)
    try:
        policy: Policy = pickle.loads(policy_bytes)
        normalizer = RunningNormalizer.from_config({**norm_config, "frozen": True})
        sampler = Sampler(env_fns, policy, normalizer, seed=env_seed, first_index=first_index, gamma=gamma)
        sampler.generator.manual_seed(noise_seed)
        conn.send(("ok", None))
    except EnvError as e:  # the first reset of a user's environment failed
        conn.send(("env-error", e.fault))
        return
    except Exception as e:  # reported to the parent, which raises it
        conn.send(("error", f"{type(e).__name__}: {e}"))
        return
    while True:
        try:
            cmd, arg = conn.recv()
        except (EOFError, OSError):  # the parent is gone
            sampler.close()
            return
        try:
            if cmd == "close":
                sampler.close()
                return
            if cmd == "collect":
                weights, stats, steps = arg
                policy.load_state_dict({k: torch.from_numpy(v) for k, v in weights.items()})
                normalizer.load_state_dict(stats)
                env0, inf0, phys0 = sampler.timing.env, sampler.timing.inference, sampler.timing.physics
                batch, episodes = sampler.collect(steps)
                fields = {f.name: getattr(batch, f.name) for f in dataclasses.fields(batch)}
                reply = {
                    "batch": {k: v.numpy() if isinstance(v, torch.Tensor) else v for k, v in fields.items()},
                    "episodes": episodes,
                    "raw": sampler.last_raw_obs,
                    "env": sampler.timing.env - env0,
                    "inference": sampler.timing.inference - inf0,
                    "physics": sampler.timing.physics - phys0,
                }
            elif cmd == "get_state":
                reply = {"sampler": sampler.get_state(), "generator": sampler.generator.get_state().tolist()}
            elif cmd == "set_state":
                sampler.set_state(arg["sampler"])
                sampler.generator.set_state(torch.tensor(arg["generator"], dtype=torch.uint8))
                reply = None
            else:
                raise ValueError(f"unknown command {cmd!r}")
            conn.send(("ok", reply))
        except NonFiniteError as e:  # the parent raises it as it is (it names the environment by its global index)
            conn.send(("non-finite", str(e)))
        except EnvError as e:  # likewise: the fault record, sent as it is
            conn.send(("env-error", e.fault))
        except Exception as e:  # reported to the parent, which raises it
            conn.send(("error", f"{type(e).__name__}: {e}"))


def mean_or_nan(values: Sequence[float | None]) -> float:
    """Mean of the non-None values, NaN if there are none."""
    xs = [float(v) for v in values if v is not None]
    return sum(xs) / len(xs) if xs else math.nan
