"""hrlp.skills.sb3: SB3 PPO/SAC/TD3 actors read without unpickling, equal to ``model.predict(deterministic=True)``."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import gymnasium as gym
import torch
from gymnasium import spaces
from stable_baselines3 import A2C, DDPG, DQN, PPO, SAC, TD3
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from hrlp.skills import sb3
from hrlp.skills.sb3 import SB3Policy, load_sb3

ATOL = 1e-5


class GoalEnv(gym.Env):
    """A tiny goal-style env: Dict observation (sorted keys in SB3's order), Box(2) actions."""

    def __init__(self) -> None:
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(-1.0, 1.0, (4,), np.float32),
                "achieved_goal": spaces.Box(-1.0, 1.0, (2,), np.float32),
                "desired_goal": spaces.Box(-1.0, 1.0, (2,), np.float32),
            }
        )
        self.action_space = spaces.Box(np.array([-1.0, 0.0], np.float32), np.array([2.0, 0.5], np.float32))

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, False, False, {}


class LinearExtractor(BaseFeaturesExtractor):
    """A custom features extractor with weights (refused)."""

    def __init__(self, observation_space: spaces.Box) -> None:
        super().__init__(observation_space, 8)
        self.linear = nn.Linear(int(np.prod(observation_space.shape)), 8)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.linear(obs)


def _touch(path: str) -> None:
    Path(path).write_text("the pickle ran")


class Payload:
    """Unpickling this runs :func:`_touch` (what a tampered policy.pth could do)."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (_touch, (self.marker,))


def _perturb_and_save(model, path: Path) -> Path:
    """Shake the weights (so that clipping and tanh saturation both occur), then ``model.save``."""
    generator = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for parameter in model.policy.parameters():
            parameter.add_(0.3 * torch.randn(parameter.shape, generator=generator))
    model.save(path)
    return path.with_suffix(".zip")


def _observations(policy: SB3Policy, n: int = 256) -> np.ndarray:
    return np.random.default_rng(1).uniform(-3.0, 3.0, (n, policy.obs_dim))


def _as_dict(policy: SB3Policy, obs: np.ndarray) -> dict[str, np.ndarray]:
    split = np.cumsum([width for _, width in policy.obs_parts])[:-1]
    return {key: part for (key, _), part in zip(policy.obs_parts, np.split(obs, split, axis=1), strict=True)}


def _rewrite(source: Path, target: Path, replace: dict[str, bytes | None]) -> Path:
    """Copy an SB3 zip, replacing (bytes) or dropping (None) members."""
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(target, "w") as dst:
        for info in src.infolist():
            if info.filename not in replace:
                dst.writestr(info.filename, src.read(info.filename))
        for name, content in replace.items():
            if content is not None:
                dst.writestr(name, content)
    return target


def _state_dict(path: Path) -> dict[str, torch.Tensor]:
    with zipfile.ZipFile(path) as archive:
        return torch.load(io.BytesIO(archive.read("policy.pth")), weights_only=True, map_location="cpu")


def _torch_bytes(obj) -> bytes:
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


def _refused(path: Path, match: str) -> str:
    with pytest.raises(ValueError, match=match) as caught:
        load_sb3(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: ")
    assert "\n" not in message
    return message


PPO_SMALL = {"n_steps": 64, "batch_size": 32, "n_epochs": 2}
MODELS = {
    "PPO": lambda: PPO("MlpPolicy", "Pendulum-v1", **PPO_SMALL, policy_kwargs={"net_arch": [16, 16]}),
    "PPO-ReLU": lambda: PPO(
        "MlpPolicy", "Pendulum-v1", **PPO_SMALL, policy_kwargs={"net_arch": [16, 16], "activation_fn": nn.ReLU}
    ),
    "PPO-gSDE-squashed": lambda: PPO(
        "MlpPolicy",
        "Pendulum-v1",
        **PPO_SMALL,
        use_sde=True,
        policy_kwargs={"net_arch": {"pi": [16], "vf": [8]}, "squash_output": True},
    ),
    "SAC": lambda: SAC("MlpPolicy", "Pendulum-v1", learning_starts=10, policy_kwargs={"net_arch": [16, 16]}),
    "TD3": lambda: TD3("MlpPolicy", "Pendulum-v1", learning_starts=10, policy_kwargs={"net_arch": [16, 16]}),
}
EXPECTED = {
    "PPO": ("PPO", "Tanh"),
    "PPO-ReLU": ("PPO", "ReLU"),
    "PPO-gSDE-squashed": ("PPO", "Tanh"),
    "SAC": ("SAC", "ReLU"),
    "TD3": ("TD3", "ReLU"),
}


@pytest.mark.parametrize("name", list(MODELS))
def test_actions_equal_predict(name: str, tmp_path: Path) -> None:
    model = MODELS[name]()
    model.learn(64 if name.startswith("PPO") else 50)
    path = _perturb_and_save(model, tmp_path / name)

    policy = load_sb3(path)
    assert (policy.algo, policy.activation) == EXPECTED[name]
    assert policy.obs_parts == (("observation", 3),) and not policy.obs_is_dict
    assert (policy.obs_dim, policy.act_dim) == (3, 1)
    np.testing.assert_array_equal(policy.action_low, [-2.0])
    np.testing.assert_array_equal(policy.action_high, [2.0])

    obs = _observations(policy)
    actions = policy.act(obs)
    expected = model.predict(obs.astype(np.float32), deterministic=True)[0]
    assert actions.shape == (len(obs), 1) and actions.dtype == np.float64
    np.testing.assert_allclose(actions, expected, atol=ATOL, rtol=0)
    assert np.all(actions >= -2.0 - ATOL) and np.all(actions <= 2.0 + ATOL)
    np.testing.assert_allclose(policy.act(obs[0]), expected[0], atol=ATOL, rtol=0)  # one observation -> [A]
    with pytest.raises(ValueError, match="shape"):
        policy.act(obs[:, :2])


@pytest.mark.parametrize("algo", ["PPO", "TD3"])
def test_dict_observation(algo: str, tmp_path: Path) -> None:
    if algo == "PPO":
        model = PPO("MultiInputPolicy", GoalEnv(), **PPO_SMALL, policy_kwargs={"net_arch": [16]})
    else:
        model = TD3("MultiInputPolicy", GoalEnv(), learning_starts=10, policy_kwargs={"net_arch": [16, 16]})
    model.learn(64 if algo == "PPO" else 30)
    path = _perturb_and_save(model, tmp_path / "goal")

    policy = load_sb3(path)
    assert policy.algo == algo and policy.obs_is_dict
    assert policy.obs_parts == (("achieved_goal", 2), ("desired_goal", 2), ("observation", 4))
    np.testing.assert_array_equal(policy.action_low, [-1.0, 0.0])
    np.testing.assert_array_equal(policy.action_high, [2.0, 0.5])
    obs = _observations(policy)
    expected = model.predict(_as_dict(policy, obs.astype(np.float32)), deterministic=True)[0]
    np.testing.assert_allclose(policy.act(obs), expected, atol=ATOL, rtol=0)


@pytest.mark.parametrize(
    "make",
    [
        lambda: A2C("MlpPolicy", "Pendulum-v1"),
        lambda: DQN("MlpPolicy", "CartPole-v1"),
        lambda: DDPG("MlpPolicy", "Pendulum-v1", policy_kwargs={"net_arch": [8]}),
    ],
    ids=["A2C", "DQN", "DDPG"],
)
def test_unsupported_algorithm(make, tmp_path: Path) -> None:
    path = tmp_path / "other.zip"
    make().save(path)
    message = _refused(path, "unsupported algorithm")
    assert "supported: PPO, SAC, TD3" in message


def test_unsupported_policy_kwargs(tmp_path: Path) -> None:
    softplus = PPO("MlpPolicy", "Pendulum-v1", policy_kwargs={"net_arch": [8], "activation_fn": nn.Softplus})
    softplus.save(tmp_path / "softplus")
    _refused(tmp_path / "softplus.zip", "unsupported activation_fn .*Softplus")
    custom = SAC("MlpPolicy", "Pendulum-v1", policy_kwargs={"net_arch": [8], "features_extractor_class": LinearExtractor})
    custom.save(tmp_path / "custom")
    _refused(tmp_path / "custom.zip", "unsupported features_extractor_class")


@pytest.fixture(scope="module")
def ppo_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("ppo") / "ppo.zip"
    PPO("MlpPolicy", "Pendulum-v1", policy_kwargs={"net_arch": [8, 8]}).save(path)
    return path


def test_not_a_zip(tmp_path: Path) -> None:
    path = tmp_path / "model.zip"
    path.write_text("not a zip")
    _refused(path, "not a readable zip")
    _refused(tmp_path / "missing.zip", "no such file")


def test_missing_members(ppo_zip: Path, tmp_path: Path) -> None:
    _refused(_rewrite(ppo_zip, tmp_path / "no_policy.zip", {"policy.pth": None}), "no 'policy.pth'")
    _refused(_rewrite(ppo_zip, tmp_path / "no_data.zip", {"data": None}), "no 'data'")


def test_tampered_policy_never_runs(ppo_zip: Path, tmp_path: Path) -> None:
    marker = tmp_path / "marker.txt"
    state = dict(_state_dict(ppo_zip), payload=Payload(marker))
    path = _rewrite(ppo_zip, tmp_path / "tampered.zip", {"policy.pth": _torch_bytes(state)})

    _refused(path, "weights-only loader refused")
    assert not marker.exists()
    # The file is really dangerous: an ordinary (unsafe) load runs the payload.
    with zipfile.ZipFile(path) as archive:
        torch.load(io.BytesIO(archive.read("policy.pth")), weights_only=False)
    assert marker.exists()


def test_wrong_shapes_and_values(ppo_zip: Path, tmp_path: Path) -> None:
    state = _state_dict(ppo_zip)
    wrong = dict(state)
    wrong["action_net.weight"] = torch.zeros(1, 5)
    _refused(_rewrite(ppo_zip, tmp_path / "shape.zip", {"policy.pth": _torch_bytes(wrong)}), "shapes do not match")
    wide = dict(state)
    wide["mlp_extractor.policy_net.0.weight"] = torch.zeros(8, 4)
    _refused(_rewrite(ppo_zip, tmp_path / "wide.zip", {"policy.pth": _torch_bytes(wide)}), "observation space has 3")
    bad = dict(state)
    bad["mlp_extractor.policy_net.2.bias"] = torch.full((8,), float("nan"))
    _refused(_rewrite(ppo_zip, tmp_path / "nan.zip", {"policy.pth": _torch_bytes(bad)}), "non-finite")


def test_member_size_bound(ppo_zip: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sb3, "MAX_MEMBER_BYTES", 1000)
    _refused(ppo_zip, "over the 1000 limit")
