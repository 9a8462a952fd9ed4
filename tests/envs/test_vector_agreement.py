"""Every VectorEnv gives the same episodes for the same seed, and the sampler the same batch over each of them.

(a) SerialVectorEnv against its environments stepped by hand (Box, Discrete and parameterised actions); (b)
BatchedArmEnv's loop backend against SerialVectorEnv bit for bit, its rollout backend within 1e-6 (it restarts the
constraint solver's warm start every control step, tests/envs/test_batched.py); (c) the serial ManagerVectorEnv against each
MacroEnv stepped alone with ``env.step``, and the batched one (the Manager over a BatchedArmEnv) against
the serial one, bit for bit over the loop backend; (d) the Sampler over each of them, and against a per-environment loop
(``env.step`` one environment at a time, as the sampler did before it stepped a VectorEnv), for a fixed policy and
seed. Batched skill inference evaluates a skill on ``[M, 24]`` rows where a lone MacroEnv evaluates it on one, and a
matrix product may round differently: with skills the numbers agree to 1e-7, the flags and taus exactly; the
micro-action alone involves no network and agrees bit for bit.
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Callable, Sequence

import gymnasium as gym
import numpy as np
import pytest
import torch

from hrlp.algos.kernels import discounted_returns, gae
from hrlp.arm import make
from hrlp.arm.batched import make_batched
from hrlp.arm.manager import batched_manager
from hrlp.config import MicroAction
from hrlp.envs.vector import NO_SUCCESS_TEST, SerialVectorEnv, VectorEnv, VectorStep, action_decoder
from hrlp.policies.mlp import policy_for_space
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.rollout import Batch, Episode, Sampler, vector_env
from hrlp.skills.library import load_skill
from hrlp.skills.macro_env import MacroEnv, ManagerVectorEnv, manager_vector_env

TASK, N, EPISODE = "ReachAndGrip2", 3, 12
LOOSE = {"tr1": 0.3, "tr2": 0.06}  # success within reach of random torques, so the success flags are compared both ways
ROLLOUT_ATOL = 1e-6
SKILLS_RTOL = 1e-7
FIELDS = ("obs", "next_obs", "rewards", "discount", "tau", "terminated", "truncated", "success")
BATCH_FIELDS = ("obs", "next_obs", "actions", "rewards", "discount", "terminated", "truncated")


def _arm() -> Callable[[], gym.Env]:
    return functools.partial(make, TASK, episode_steps=EPISODE, **LOOSE)


def _torques(steps: int, n: int = N, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.2, 1.2, size=(steps, n, 9))  # beyond the bounds too: clipped


def _run(env: VectorEnv, actions: np.ndarray, seed: int = 11) -> tuple[np.ndarray, list[VectorStep]]:
    return env.reset(seed=seed), [env.step(a) for a in actions]


def _same_steps(ref: list[VectorStep], got: list[VectorStep], atol: float = 0.0) -> None:
    for t, (r, g) in enumerate(zip(ref, got, strict=True)):
        assert set(g.infos) == set(r.infos), f"info keys at step {t}"
        pairs = [(f, getattr(r, f), getattr(g, f)) for f in FIELDS]
        pairs += [(f"infos[{k}]", v, g.infos[k]) for k, v in r.infos.items()]
        for name, x, y in pairs:
            if atol == 0 or x.dtype == bool:
                np.testing.assert_array_equal(y, x, err_msg=f"{name} at step {t}")
            else:
                np.testing.assert_allclose(y, x, rtol=0, atol=atol, err_msg=f"{name} at step {t}")


# --- (a) SerialVectorEnv against its environments stepped by hand ---------------------------------------------------


def test_serial_vector_env_steps_arm_envs_as_they_step_by_hand():
    steps = 30
    actions = _torques(steps)
    vec = SerialVectorEnv([_arm()() for _ in range(N)], gamma=0.9)
    hand = [_arm()() for _ in range(N)]
    obs = vec.reset(seed=5)
    np.testing.assert_array_equal(obs, [env.reset(seed=5 + i)[0] for i, env in enumerate(hand)])
    ended = 0
    for t in range(steps):
        step = vec.step(actions[t])
        assert step.discount.tolist() == [0.9] * N and step.tau.tolist() == [1] * N and NO_SUCCESS_TEST not in step.infos
        for i, env in enumerate(hand):
            o, r, term, trunc, info = env.step(np.clip(actions[t, i], -1.0, 1.0))
            np.testing.assert_array_equal(step.next_obs[i], o)
            assert (step.rewards[i], step.terminated[i], step.truncated[i]) == (r, term, trunc)
            assert step.success[i] == info["success"] and step.infos["reward_distance"][i] == info["reward_distance"]
            if term or trunc:
                o, _ = env.reset()
                ended += 1
            np.testing.assert_array_equal(step.obs[i], o)
    assert ended == N * (steps // EPISODE)


@pytest.mark.parametrize(
    ("env_id", "rows", "decoded"),
    [
        ("CartPole-v1", [[1.0], [0.0]], [1, 0]),
        ("hrlp_test/PickAndPoint-v0", [[0.0, 3.0], [1.0, -0.5]], [(0, [2.0], []), (1, [-0.5], [])]),
    ],
    ids=["discrete", "parameterised"],
)
def test_serial_vector_env_decodes_discrete_and_parameterised_rows(env_id, rows, decoded):
    envs, hand = [gym.make(env_id) for _ in range(2)], [gym.make(env_id) for _ in range(2)]
    vec = SerialVectorEnv(envs, gamma=0.5)
    assert vec.act_dim == len(rows[0]) and not vec.resumable  # Gymnasium's environments cannot save their state
    decode = action_decoder(envs[0].action_space)
    got = decode(np.array(rows))
    for a, b in zip(got, decoded, strict=True):  # the parameter block is clipped to its Box(-2, 2)
        assert a == b if isinstance(b, int) else (a[0] == b[0] and [x.tolist() for x in a[1:]] == list(b[1:]))
    obs = vec.reset(seed=3)
    np.testing.assert_array_equal(obs, [np.ravel(env.reset(seed=3 + i)[0]) for i, env in enumerate(hand)])
    for _ in range(3):
        step = vec.step(np.array(rows))
        for i, env in enumerate(hand):
            o, r, *_ = env.step(got[i])
            np.testing.assert_array_equal(step.next_obs[i], np.ravel(o))
            assert step.rewards[i] == r
        assert step.infos[NO_SUCCESS_TEST].tolist() == [True, True]  # these tasks have no success test


# --- (b) BatchedArmEnv against SerialVectorEnv ------------------------------------------------------------------------


@pytest.mark.parametrize("backend", ["loop", "rollout"])
def test_batched_arm_env_gives_the_serial_reference_episodes(backend):
    actions = _torques(30, seed=2)
    ref_obs, ref = _run(SerialVectorEnv([_arm()() for _ in range(N)]), actions)
    obs, got = _run(make_batched(TASK, N, episode_steps=EPISODE, backend=backend, **LOOSE), actions)
    np.testing.assert_array_equal(obs, ref_obs)
    assert sum(int(s.done.sum()) for s in ref) == N * 2
    success = np.array([s.success for s in ref])
    assert success.any() and not success.all()
    _same_steps(ref, got, 0.0 if backend == "loop" else ROLLOUT_ATOL)


# --- (c) the serial ManagerVectorEnv against each MacroEnv stepped alone ------------------------------------------------


@pytest.fixture(scope="module")
def skills():
    """The shipped Gripper and Reacher (no training here)."""
    return [load_skill("gripper"), load_skill("reacher")]


class _Managers:
    """Constructor of a Manager's environment: the shipped skills with k = 3 and a 2-step micro-action, or the
    micro-action alone (5 steps: the 12-step episodes end inside a decision)."""

    def __init__(self, skills: Sequence | None) -> None:
        self.skills = skills

    def __call__(self) -> MacroEnv:
        if self.skills is None:
            return MacroEnv(make(TASK, episode_steps=EPISODE, **LOOSE), [], micro=MicroAction(5), gamma=0.95)
        return MacroEnv(make(TASK, episode_steps=EPISODE, **LOOSE), self.skills, k=3, micro=MicroAction(2), gamma=0.95)


def _manager_actions(env: MacroEnv, decisions: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    choice = rng.integers(0, len(env.names), (decisions, N, 1))
    return np.concatenate([choice, rng.uniform(-1.2, 1.2, (decisions, N, int(env.offsets[-1])))], axis=2)


def _blocks(env: MacroEnv, row: np.ndarray) -> tuple:
    return (int(row[0]), *(row[1 + lo : 1 + hi] for lo, hi in zip(env.offsets[:-1], env.offsets[1:], strict=True)))


@pytest.mark.parametrize("kind", ["skills", "micro"])
def test_macro_vector_env_gives_each_macro_envs_own_episodes(skills, kind):
    build = _Managers(skills if kind == "skills" else None)
    vec, alone = manager_vector_env([build() for _ in range(N)]), [build() for _ in range(N)]
    rtol = SKILLS_RTOL if kind == "skills" else 0.0
    actions = _manager_actions(alone[0], 14)
    obs = vec.reset(seed=7)
    np.testing.assert_array_equal(obs, [env.reset(seed=7 + i)[0] for i, env in enumerate(alone)])
    ended, taus = 0, set()
    for a in actions:
        step = vec.step(a)
        for i, env in enumerate(alone):
            o, r, term, trunc, info = env.step(_blocks(env, a[i]))
            np.testing.assert_allclose(step.next_obs[i], o, rtol=rtol, atol=rtol * 1e-2)
            np.testing.assert_allclose([step.rewards[i], step.infos["task_reward"][i]], [r, info["task_reward"]], rtol=rtol)
            assert (step.discount[i], step.tau[i]) == (info["discount"], info["tau"])
            assert (step.terminated[i], step.truncated[i], step.success[i]) == (term, trunc, info["success"])
            assert env.names[int(step.infos["choice"][i])] == info["macro"]
            if term or trunc:
                o, _ = env.reset()
                ended += 1
            np.testing.assert_allclose(step.obs[i], o, rtol=rtol, atol=rtol * 1e-2)
            taus.add(int(step.tau[i]))
    assert ended >= N and len(taus) > 1  # episodes end inside the run; decisions last different numbers of steps


def test_macro_vector_env_refuses_environments_of_different_managers(skills):
    with pytest.raises(ValueError, match="environment 1 has other macro-actions"):
        manager_vector_env([_Managers(skills)(), _Managers(None)()])
    with pytest.raises(ValueError, match=r"gamma 0\.9 differs from the MacroEnvs' own"):
        vector_env([_Managers(None)()], gamma=0.9)
    with pytest.raises(ValueError, match="mix MacroEnvs and other environments"):
        vector_env([_Managers(None)(), _arm()()])
    assert isinstance(manager_vector_env([_Managers(None)()]), VectorEnv)


def _batched_managers(build: _Managers, backend: str) -> ManagerVectorEnv:
    return batched_manager(make_batched(TASK, N, episode_steps=EPISODE, backend=backend, **LOOSE), build())


@pytest.mark.parametrize("backend", ["loop", "rollout"])
@pytest.mark.parametrize("kind", ["skills", "micro"])
def test_batched_macro_vector_env_gives_the_macro_vector_envs_episodes(skills, kind, backend):
    # The same skills on the same rows [M, 24] at every low-level step, the physics of all worlds in one call: with the
    # loop backend the same bits; with rollout within its agreement with ArmEnv.
    build = _Managers(skills if kind == "skills" else None)
    actions = _manager_actions(build(), 14)
    ref_obs, ref = _run(manager_vector_env([build() for _ in range(N)]), actions)
    obs, got = _run(_batched_managers(build, backend), actions)
    np.testing.assert_array_equal(obs, ref_obs)
    _same_steps(ref, got, 0.0 if backend == "loop" else ROLLOUT_ATOL)
    assert sum(int(s.truncated.sum()) for s in ref) >= N and len({int(t) for s in ref for t in s.tau}) > 1


def test_a_managers_state_continues_from_one_vector_env_in_the_other(skills):
    build = _Managers(skills)
    actions = _manager_actions(build(), 10)
    serial, batched = manager_vector_env([build() for _ in range(N)]), _batched_managers(build, "loop")
    _run(serial, actions[:5])
    _run(batched, actions[:5], seed=99)  # elsewhere, until it takes the serial one's state
    batched.set_state(json.loads(json.dumps(serial.get_state())))
    _same_steps([serial.step(a) for a in actions[5:]], [batched.step(a) for a in actions[5:]])
    assert json.loads(json.dumps(batched.get_state())) == json.loads(json.dumps(serial.get_state()))


def test_a_batched_manager_refuses_worlds_of_another_task(skills):
    worlds = make_batched("Reacher", N, episode_steps=EPISODE)
    with pytest.raises(ValueError, match="the worlds run ReacherTask, the layout's macro-actions ReachAndGripTask"):
        batched_manager(worlds, _Managers(skills)())
    assert isinstance(_batched_managers(_Managers(None), "loop"), VectorEnv)


# --- (d) the sampler over each ----------------------------------------------------------------------------------------


def _per_env_batch(env_fns: Sequence[Callable[[], gym.Env]], policy, seed: int, steps: int,
                   gamma: float) -> tuple[Batch, list[Episode]]:  # fmt: skip
    """The batch as a loop over single environments gives it: ``env.step`` one environment at a time, a discount and
    tau from ``info`` where a MacroEnv reports them, returns counting ``info['task_reward']``."""
    envs = [fn() for fn in env_fns]
    n, decode, act = len(envs), action_decoder(envs[0].action_space), policy.numpy_actor()
    norm = RunningNormalizer(int(np.prod(envs[0].observation_space.shape)))
    gen = torch.Generator().manual_seed(seed)
    raw = np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(envs)]).astype(np.float64)
    cols: dict[str, list] = {f: [] for f in BATCH_FIELDS}
    ret, length, episodes, env_steps = np.zeros(n), np.zeros(n, dtype=np.int64), [], 0
    for _ in range(steps):
        obs = norm.normalize(raw)
        a = act(obs.astype(np.float32), gen)
        row = {f: np.zeros(n, dtype=bool if f in ("terminated", "truncated") else np.float64) for f in BATCH_FIELDS[3:]}
        next_raw = np.empty_like(raw)
        for i, (env, action) in enumerate(zip(envs, decode(a), strict=True)):
            o, r, term, trunc, info = env.step(action)
            tau = int(info.get("tau", 1))
            row["rewards"][i], row["discount"][i] = r, info.get("discount", gamma)
            row["terminated"][i], row["truncated"][i] = term, trunc and not term
            next_raw[i], ret[i], length[i] = o, ret[i] + info.get("task_reward", r), length[i] + tau
            env_steps += tau
            if term or trunc:
                s, tds = info.get("success"), info.get("target_dist_sum")
                episodes.append(Episode(float(ret[i]), int(length[i]), None if s is None else bool(s), tds))
                ret[i], length[i] = 0.0, 0
                o, _ = env.reset()
            raw[i] = o
        for f, v in (("obs", obs), ("next_obs", norm.normalize(next_raw)), ("actions", a), *row.items()):
            cols[f].append(v)
    tensors = {f: torch.as_tensor(np.stack(v), dtype=None if f in ("terminated", "truncated") else torch.float32)
               for f, v in cols.items()}  # fmt: skip
    return Batch(**tensors, env_steps=env_steps), episodes


def _same_batches(a: Batch, b: Batch, atol: float = 0.0) -> None:
    assert a.env_steps == b.env_steps
    for f in BATCH_FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        if atol == 0 or x.dtype == torch.bool:
            assert torch.equal(x, y), f
        else:
            torch.testing.assert_close(y, x, rtol=0, atol=atol, msg=f)


def _same_episodes(a: list[Episode], b: list[Episode], rel: float = 0.0) -> None:
    assert [(e.length, e.success, e.target_dist_sum) for e in a] == [(e.length, e.success, e.target_dist_sum) for e in b]
    assert [e.ret for e in a] == pytest.approx([e.ret for e in b], rel=rel, abs=0)


def _policy(probe: gym.Env):
    torch.manual_seed(0)
    return policy_for_space(int(np.prod(probe.observation_space.shape)), probe.action_space, (8,))


def test_the_sampler_gives_the_same_flat_batch_over_every_arm_vector_env():
    steps, seed, gamma = 20, 4, 0.9
    fns = [_arm()] * N
    policy = _policy(fns[0]())
    ref, ref_eps = _per_env_batch(fns, policy, seed, steps, gamma)
    batched = {b: make_batched(TASK, N, episode_steps=EPISODE, gamma=gamma, backend=b, **LOOSE) for b in ("loop", "rollout")}
    runs = {"serial": Sampler(fns, policy, RunningNormalizer(24), seed=seed, gamma=gamma)}
    runs |= {b: Sampler(env, policy, RunningNormalizer(24), seed=seed) for b, env in batched.items()}
    for name, sampler in runs.items():
        batch, eps = sampler.collect(steps)
        # The rollout backend's observations differ by up to 1e-7; the policy's actions follow them smoothly.
        _same_batches(ref, batch, 0.0 if name != "rollout" else 1e-5)
        _same_episodes(ref_eps, eps, 0.0 if name != "rollout" else 1e-6)
        assert batch.env_steps == steps * N and len(eps) == N
        sampler.close()
    assert torch.equal(ref.discount, torch.full((steps, N), gamma, dtype=torch.float32))


def test_a_flat_batchs_discount_gives_gae_bit_for_bit_what_the_scalar_gamma_gives():
    gamma, lam = 0.99, 0.97
    sampler = Sampler([_arm()] * N, _policy(_arm()()), RunningNormalizer(24), seed=1, gamma=gamma)
    batch, _ = sampler.collect(2 * EPISODE + 5)  # truncations inside the batch and a bootstrap at its end
    gen = torch.Generator().manual_seed(0)
    values, next_values = (torch.randn(batch.rewards.shape, generator=gen) for _ in range(2))
    args = (batch.rewards, values, next_values, batch.terminated, batch.truncated, gamma, lam)
    scalar, per_step = gae(*args), gae(*args, discount=batch.discount)
    assert batch.truncated.any()
    assert torch.equal(scalar.advantages, per_step.advantages) and torch.equal(scalar.returns, per_step.returns)
    ret_args = (batch.rewards, batch.terminated, batch.truncated, next_values, gamma)
    assert torch.equal(discounted_returns(*ret_args), discounted_returns(*ret_args, discount=batch.discount))


@pytest.mark.parametrize("kind", ["skills", "micro"])
def test_the_sampler_gives_a_managers_batch_as_its_environments_step_alone(skills, kind):
    steps, seed = 10, 6
    fns = [_Managers(skills if kind == "skills" else None)] * N
    policy = _policy(fns[0]())
    ref, ref_eps = _per_env_batch(fns, policy, seed, steps, gamma=math.nan)
    from_fns = Sampler(fns, policy, RunningNormalizer(24), seed=seed, gamma=0.95)
    ready = Sampler(manager_vector_env([fn() for fn in fns]), policy, RunningNormalizer(24), seed=seed)
    for sampler in (from_fns, ready):
        batch, eps = sampler.collect(steps)
        if kind == "micro":  # no network between the decision and the torques: bit for bit
            _same_batches(ref, batch)
            _same_episodes(ref_eps, eps)
        else:
            _same_batches(ref, batch, 1e-5)
            _same_episodes(ref_eps, eps, 1e-6)
        assert torch.equal(batch.discount, ref.discount) and batch.env_steps == ref.env_steps > steps * N
        assert eps and all(e.length == EPISODE for e in eps)  # episodes count low-level steps
        sampler.close()


def test_a_sampler_state_continues_in_another_vector_env():
    # The checkpoint's sampler state {"obs", "ret", "len", "envs": [ArmEnv states]} is one format for every arm VectorEnv.
    steps, seed = 8, 2
    policy = _policy(_arm()())
    first = Sampler([_arm()] * N, policy, RunningNormalizer(24), seed=seed)
    first.collect(steps)
    saved = json.loads(json.dumps(first.get_state()))
    gen, stats = first.generator.get_state(), first.normalizer.state_dict()
    assert set(saved) == {"obs", "ret", "len", "envs"} and len(saved["envs"]) == N
    cont, cont_eps = first.collect(steps)
    other = Sampler(make_batched(TASK, N, episode_steps=EPISODE, backend="loop", **LOOSE), policy, RunningNormalizer(24))
    other.set_state(saved)
    other.generator.set_state(gen)
    other.normalizer.load_state_dict(stats)
    batch, eps = other.collect(steps)
    _same_batches(cont, batch)
    _same_episodes(cont_eps, eps)
