"""Parameterised action spaces of any form (flat Tuple, nested Tuple, OneOf), normalised to [-1, 1] per parameter."""

import dataclasses
import math
from typing import ClassVar

import gymnasium as gym
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from hrlp.algos.trpo import TRPOConfig
from hrlp.checkpoint import load_checkpoint
from hrlp.cli import app
from hrlp.envs.actions import NormalisedParameters, parameter_blocks
from hrlp.envs.check import check_spaces, parameterised_dims
from hrlp.evaluate import evaluate_run
from hrlp.policies.mlp import HierarchicalPolicy, policy_for_space
from hrlp.rollout import action_decoder
from hrlp.train import TrainConfig, env_factory, load_trained, train

Box, Discrete, Tuple = gym.spaces.Box, gym.spaces.Discrete, gym.spaces.Tuple
INF = np.inf

#: Per choice: its native bounds and the parameter that pays best (choice 0's range is [0, 720], e.g. an angle).
SPACES = {
    "flat": Tuple((Discrete(2), Box(0.0, 720.0, (1,)), Box(-INF, INF, (1,)))),
    "nested": Tuple((Discrete(2), Tuple((Box(0.0, 720.0, (1,)), Box(-5.0, 5.0, (2,)))))),
    "oneof": gym.spaces.OneOf((Box(0.0, 720.0, (1,)), Box(-5.0, 5.0, (2,)))),
}
TARGETS = {"flat": ([500.0], [3.0]), "nested": ([500.0], [1.0, -2.0]), "oneof": ([500.0], [1.0, -2.0])}
IDS = {kind: f"hrlp_test/ParamBandit{kind.capitalize()}-v0" for kind in SPACES}


class ParamBandit(gym.Env):
    """A one-step user environment with a parameterised action of the form ``kind``: choose a block, set its
    parameters; reward ``-mean |x - target|`` over the chosen block, in units of its width (720 and 10): in [-1, 0].
    It records the (native) actions it receives, and saves its exact state (so that runs on it resume exactly)."""

    received: ClassVar[list[tuple[int, np.ndarray]]] = []

    def __init__(self, kind: str = "nested") -> None:
        self.kind = kind
        self.action_space = SPACES[kind]
        self.observation_space = Box(-1.0, 1.0, (2,), np.float64)
        self._obs = np.zeros(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._obs = self.np_random.uniform(-1, 1, size=2)
        return self._obs.copy(), {}

    def step(self, action):
        assert self.action_space.contains(action), action
        k = int(action[0])
        x = {"flat": lambda: action[1 + k], "nested": lambda: action[1][k], "oneof": lambda: action[1]}[self.kind]()
        x = np.asarray(x, dtype=np.float64)
        ParamBandit.received.append((k, x))
        r = -float(np.mean(np.abs(x - TARGETS[self.kind][k]))) / (720.0 if k == 0 else 10.0)
        self._obs = self.np_random.uniform(-1, 1, size=2)
        return self._obs.copy(), r, True, False, {}

    def get_state(self) -> dict:
        return {"rng": self.np_random.bit_generator.state, "obs": self._obs.tolist()}

    def set_state(self, state: dict) -> None:
        self.np_random.bit_generator.state = state["rng"]
        self._obs = np.asarray(state["obs"])


class BadSpace(gym.Env):
    """An environment whose action space is given (to check the one-line errors)."""

    observation_space = Box(-1.0, 1.0, (1,))

    def __init__(self, space: gym.Space) -> None:
        self.action_space = space

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(1, np.float32), {}

    def step(self, action):
        return np.zeros(1, np.float32), 0.0, True, False, {}


for _kind, _id in IDS.items():
    if _id not in gym.registry:
        gym.register(_id, entry_point=ParamBandit, kwargs={"kind": _kind})
if "hrlp_test/ParamStart1-v0" not in gym.registry:
    gym.register("hrlp_test/ParamStart1-v0", entry_point=BadSpace,
                 kwargs={"space": Tuple((Discrete(1, start=1), Box(0.0, 1.0, (1,))))})  # fmt: skip


def at_bounds(received: list[tuple[int, np.ndarray]], low: float = 0.0, high: float = 720.0) -> tuple[float, float]:
    """Shares of choice-0 parameters (range [low, high]) at exactly ``low`` and at exactly ``high``."""
    xs = np.array([x[0] for k, x in received if k == 0])
    assert xs.size > 100
    return float(np.mean(xs == low)), float(np.mean(xs == high))


def test_the_map_is_affine_onto_finite_bounds_and_passes_infinite_ones_through():
    box = Box(np.array([0.0, -INF, -2.0, 3.0], np.float32), np.array([720.0, INF, INF, 3.0], np.float32))
    env = NormalisedParameters(BadSpace(Tuple((Discrete(1), box))))
    canon = env.action_space.spaces[1]
    assert canon.low.tolist() == [-1, -INF, -2, -1] and canon.high.tolist() == [1, INF, INF, 1]

    def native(u):
        return env.action((0, np.array(u, np.float32)))[1].tolist()

    assert native([-1, 3.7, -5, 0]) == [0.0, pytest.approx(3.7), -2.0, 3.0]  # a half-infinite bound clips only
    assert native([0, -1e6, 7, 1]) == [360.0, -1e6, 7.0, 3.0]  # 0 -> the midpoint; low == high -> that value
    assert native([1, 0, 0, -1]) == [720.0, 0.0, 0.0, 3.0]
    assert native([0.5, 0, 0, 0]) == [540.0, 0.0, 0.0, 3.0]
    assert native([1.5, 0, 0, 0])[0] == 720.0 and native([-3, 0, 0, 0])[0] == 0.0  # out of [-1, 1]: clipped
    assert env.reverse_action((0, np.array([180.0, 2.0, 5.0, 3.0])))[1].tolist() == [-0.5, 2.0, 5.0, 0.0]
    ints = NormalisedParameters(BadSpace(Tuple((Discrete(1), Box(0, 10, (1,), np.int64)))))
    assert ints.action((0, np.array([0.1], np.float32)))[1].tolist() == [6]  # 5.5 rounded, in the Box's dtype


@pytest.mark.parametrize("kind", list(SPACES))
def test_each_form_round_trips_through_the_canonical_space(kind):
    env = NormalisedParameters(BadSpace(SPACES[kind]))
    assert env.kind == kind and parameterised_dims(env.action_space) == ((1, 1) if kind == "flat" else (1, 2))
    native, canon = SPACES[kind], env.action_space
    native.seed(1)
    canon.seed(2)
    for _ in range(50):
        x = native.sample()
        u = env.reverse_action(x)
        assert canon.contains(u)
        back = env.action(u)
        assert native.contains(back) and int(back[0]) == int(x[0])
        got, want = (back[1:], x[1:]) if kind == "flat" else (back[1], x[1])
        if kind == "oneof":
            got, want = [got], [want]
        for g, w in zip(got, want, strict=True):
            np.testing.assert_allclose(g, w, rtol=1e-5, atol=1e-4)
        assert native.contains(env.action(canon.sample()))  # any canonical action is a valid native one


def test_the_first_actions_are_no_longer_clipped_to_a_bound():
    env = NormalisedParameters(gym.make(IDS["flat"]))
    obs = np.zeros((4000, 2), np.float32)
    gen = torch.Generator().manual_seed(0)
    torch.manual_seed(0)
    raw = env.unwrapped.action_space  # before: the policy acted in native units, mean 0 and std 1 on [0, 720]
    native = action_decoder(raw)(policy_for_space(2, raw).act_numpy(obs, gen))
    low_before, _ = at_bounds([(int(a[0]), a[1]) for a in native])
    now = action_decoder(env.action_space)(policy_for_space(2, env.action_space).act_numpy(obs, gen))
    low_now, high_now = at_bounds([(int(a[0]), env.action(a)[1]) for a in now])
    assert low_before > 0.45 and low_now < 0.22 and high_now < 0.22, (low_before, low_now, high_now)  # N(0, 1): 16% each
    narrow = policy_for_space(2, env.action_space, init_log_std=math.log(0.4))  # std 0.4: 1.2% out of [-1, 1]
    low, high = at_bounds(
        [(int(a[0]), env.action(a)[1]) for a in action_decoder(env.action_space)(narrow.act_numpy(obs, gen))]
    )
    assert low + high < 0.05, (low, high)


@pytest.mark.parametrize("kind", list(SPACES))
def test_a_user_environment_of_each_form_trains_and_evaluates_end_to_end(tmp_path, kind):
    cfg = TrainConfig(task=IDS[kind], steps=4_000, batch_steps=800, num_envs=8, trpo=TRPOConfig(max_kl=0.05))
    ParamBandit.received = []
    stats = list(train(cfg, tmp_path / "run"))
    assert len(stats) == 5 and stats[-1]["env_steps"] == 4_000
    first = ParamBandit.received[: cfg.batch_steps]  # the initial policy's: std 1 on [-1, 1], 16% beyond each bound
    assert len(first) == cfg.batch_steps and max(at_bounds(first)) < 0.25  # (before: about half clipped to 0)
    returns = [s["return_mean"] for s in stats]
    assert all(-1.0 <= r <= 0.0 for r in returns) and returns[-1] > returns[0], returns  # native rewards, improving
    trained = load_trained(tmp_path / "run")
    assert isinstance(trained.policy, HierarchicalPolicy) and trained.policy.param_dims == parameterised_dims(
        trained.make_env().action_space
    )
    ev = evaluate_run(tmp_path / "run", episodes=5)
    assert ev.episodes == 5 and -1.0 <= ev.ret.mean <= 0.0
    r = CliRunner().invoke(app, ["eval", str(tmp_path / "run"), "--episodes", "2"])
    assert r.exit_code == 0 and "return" in r.output, r.output


def test_a_run_on_a_nested_space_resumes_exactly(tmp_path):
    cfg = TrainConfig(task=IDS["nested"], steps=600, batch_steps=200, num_envs=4, seed=3)
    full = list(train(cfg, tmp_path / "full"))
    part = list(train(dataclasses.replace(cfg, steps=400), tmp_path / "cut"))
    rest = list(train(cfg, tmp_path / "cut", resume=True))

    def strip(rows):
        return [{k: v for k, v in r.items() if not k.startswith("time/")} for r in rows]

    assert len(part) == 2 and strip(part + rest) == strip(full)
    a, _ = load_checkpoint(tmp_path / "full" / "checkpoint")
    b, _ = load_checkpoint(tmp_path / "cut" / "checkpoint")
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_only_parameterised_gymnasium_spaces_are_wrapped():
    assert isinstance(env_factory(IDS["oneof"])(), NormalisedParameters)
    cartpole = env_factory("CartPole-v1")()
    assert not isinstance(cartpole, NormalisedParameters) and isinstance(cartpole.action_space, Discrete)
    pendulum = env_factory("Pendulum-v1")()
    assert not isinstance(pendulum, NormalisedParameters) and pendulum.action_space.high.tolist() == [2.0]


def _with(box: Box, **arrays) -> Box:
    """``box`` with bounds Box itself refuses (NaN, low > high), as a user's space may still carry them."""
    for name, value in arrays.items():
        getattr(box, name)[:] = value
    return box


@pytest.mark.parametrize(
    ("space", "problem"),
    [
        (Tuple((Discrete(2, start=1), Box(0, 1, (1,)), Box(0, 1, (1,)))), "must start at 0, not 1"),
        (
            Tuple((Discrete(3), Box(0, 1, (1,)), Box(0, 1, (1,)))),
            "Discrete(3) needs 3 parameter blocks (one per choice), got 2",
        ),
        (Tuple((Discrete(2), Tuple((Box(0, 1, (1,)),)))), "needs 2 parameter blocks (one per choice), got 1"),
        (Tuple((Discrete(1), Box(0, 1, (2, 2)))), "parameter block 0 must be a 1-d Box"),
        (gym.spaces.OneOf((Box(0, 1, (1,)), Discrete(3))), "parameter block 1 must be a 1-d Box, got Discrete(3)"),
        (Tuple((Discrete(1), _with(Box(0, 1, (2,)), low=np.nan))), "parameter block 0 has NaN bounds"),
        (Tuple((Discrete(1), Tuple((_with(Box(0, 1, (2,)), high=-1.0),)))), "block 0 has a low bound above its high bound"),
        (
            Tuple((Box(0, 1, (1,)), Box(0, 1, (1,)))),
            "use Box, Discrete, Tuple(Discrete(n), Box(d_1), ..., Box(d_n)), "
            "Tuple(Discrete(n), Tuple(Box(d_1), ..., Box(d_n))) or OneOf((Box(d_1), ..., Box(d_n)))",
        ),
        (gym.spaces.MultiDiscrete([2, 3]), "unsupported action space MultiDiscrete([2 3]): use Box, Discrete, Tuple("),
    ],
)
def test_bad_parameterised_spaces_get_one_line_naming_the_env_and_the_problem(space, problem):
    with pytest.raises(ValueError) as e:
        check_spaces("MyEnv-v0", Box(-1, 1, (1,)), space)
    assert str(e.value).startswith("MyEnv-v0: ") and problem in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(ValueError, match=r"^BadSpace: "):
        NormalisedParameters(BadSpace(space))


def test_a_registered_environment_with_a_bad_space_fails_before_any_compute():
    with pytest.raises(ValueError, match=r"^hrlp_test/ParamStart1-v0: action space .* must start at 0, not 1$"):
        env_factory("hrlp_test/ParamStart1-v0")
    assert parameter_blocks(SPACES["nested"])[0] == "nested"


def test_a_checkpoint_records_its_action_units_and_a_native_units_one_is_refused(tmp_path):
    # A parameterised run saved before parameters were normalised acted in native units: loading it now would read its
    # actions as [-1, 1] ones without a word. Its checkpoint lacks 'action_units', and every reader refuses it.
    import json

    from hrlp.checkpoint import CheckpointError

    run = tmp_path / "r"
    list(train(TrainConfig(task="hrlp_test/PickAndPoint-v0", steps=64, batch_steps=32, num_envs=4), run))
    meta_path = run / "checkpoint" / "meta.json"
    saved = json.loads(meta_path.read_text())  # the checkpoint's meta is not covered by the content hash
    assert saved["meta"]["action_units"] == "normalised"
    evaluate_run(run, episodes=2)  # loads
    del saved["meta"]["action_units"]
    meta_path.write_text(json.dumps(saved))
    cfg = TrainConfig.from_json(saved["meta"]["config"])
    for read in (lambda: load_trained(run), lambda: list(train(cfg, run, resume=True))):
        with pytest.raises(CheckpointError, match=r"acts in native units.*taken in normalised ones.*train the run again"):
            read()
    flat = tmp_path / "flat"  # a Box run: native units, before and now
    list(train(TrainConfig(task="Pendulum-v1", steps=64, batch_steps=32, num_envs=4), flat))
    assert json.loads((flat / "checkpoint" / "meta.json").read_text())["meta"]["action_units"] == "native"
