"""Policies and value net: shapes, the Manager's single network, batched acting, the NumPy copy."""

import numpy as np
import pytest
import torch
from torch import nn

from hrlp.policies.distributions import Categorical, DiagGaussian, Hierarchical
from hrlp.policies.mlp import CategoricalPolicy, GaussianPolicy, HierarchicalPolicy, NumpyMLP, ValueNet, mlp


def test_mlp_layout():
    net = mlp(5, 3, hidden=(64, 32), activation=nn.ReLU)
    linears = [m for m in net if isinstance(m, nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(5, 64), (64, 32), (32, 3)]
    assert sum(isinstance(m, nn.ReLU) for m in net) == 2
    assert net(torch.zeros(4, 5)).shape == (4, 3)


def test_gaussian_and_categorical_policies():
    torch.manual_seed(0)
    obs = torch.randn(6, 5)
    g = GaussianPolicy(5, 2, init_log_std=-0.5)
    d = g(obs)
    assert isinstance(d, DiagGaussian) and d.mean.shape == (6, 2)
    torch.testing.assert_close(d.log_std, torch.full((6, 2), -0.5))
    c = CategoricalPolicy(5, 4)(obs)
    assert isinstance(c, Categorical) and c.probs.shape == (6, 4)


def test_manager_is_one_network_with_two_hidden_layers_of_64():
    policy = HierarchicalPolicy(24, 3, (3, 0, 2))
    linears = [m for m in policy.modules() if isinstance(m, nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(24, 64), (64, 64), (64, 3 + 5)]
    assert policy.log_std.shape == (5,)
    d = policy(torch.randn(7, 24))
    assert isinstance(d, Hierarchical) and d.param_dims == (3, 0, 2)
    assert d.categorical.logits.shape == (7, 3) and d.gaussian.mean.shape == (7, 5)
    with pytest.raises(ValueError, match="param_dims"):
        HierarchicalPolicy(24, 2, (3, 0, 2))


def test_act_numpy_batched_single_and_deterministic():
    policy = HierarchicalPolicy(4, 2, (1, 2))
    obs = np.random.default_rng(0).normal(size=(16, 4)).astype(np.float32)
    a = policy.act_numpy(obs, torch.Generator().manual_seed(1))
    assert a.shape == (16, 4) and isinstance(a, np.ndarray)
    np.testing.assert_array_equal(a, policy.act_numpy(obs, torch.Generator().manual_seed(1)))
    mode = policy.act_numpy(obs, deterministic=True)
    with torch.no_grad():
        np.testing.assert_array_equal(mode, policy(torch.as_tensor(obs)).mode().numpy())
    assert policy.act_numpy(obs[0], deterministic=True).shape == (4,)
    tuples = policy.act_tuples(obs, deterministic=True)
    assert len(tuples) == 16 and tuples[0][1].shape == (1,) and tuples[0][2].shape == (2,)
    assert all(t[0] == int(row[0]) for t, row in zip(tuples, mode, strict=True))


def test_value_net_and_numpy_copy():
    v = ValueNet(5)
    obs = np.random.default_rng(1).normal(size=(9, 5))
    out = v.predict_numpy(obs.astype(np.float32))
    assert out.shape == (9,)
    copy = NumpyMLP(v.net)
    np.testing.assert_allclose(copy(obs).squeeze(-1), out, rtol=1e-5, atol=1e-6)
    g = GaussianPolicy(5, 2)
    with torch.no_grad():
        np.testing.assert_allclose(
            NumpyMLP(g.mean_net)(obs[0]), g.mean_net(torch.as_tensor(obs[:1]).float())[0].numpy(), atol=1e-6
        )
    with pytest.raises(TypeError, match="NumpyMLP"):
        NumpyMLP(nn.Sequential(nn.Linear(2, 2), nn.Sigmoid()))


def test_policies_work_in_float64():
    policy = GaussianPolicy(3, 2).double()
    assert policy.act_numpy(np.zeros((2, 3))).dtype == np.float64
    assert policy.numpy_actor()(np.zeros((2, 3)), None).dtype == np.float64


@pytest.mark.parametrize("activation", [nn.Tanh, nn.ReLU, nn.ELU])  # ELU: no NumPy path, torch is used
def test_numpy_actor_samples_what_act_numpy_samples(activation):
    """The sampler's NumPy path draws the same noise from the generator; only float rounding may differ."""
    policy = GaussianPolicy(5, 3, activation=activation, init_log_std=-0.5)
    with torch.no_grad():
        for p in policy.parameters():
            p.add_(torch.randn(p.shape, generator=torch.Generator().manual_seed(2)))
    obs = np.random.default_rng(0).normal(size=(16, 5)).astype(np.float32)
    act = policy.numpy_actor()
    g1, g2 = torch.Generator().manual_seed(1), torch.Generator().manual_seed(1)
    for _ in range(3):  # the generators stay in step
        a = act(obs, g1)
        assert a.shape == (16, 3) and a.dtype == np.float32
        np.testing.assert_allclose(a, policy.act_numpy(obs, g2), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(act(obs[0], g1), policy.act_numpy(obs[0], g2), rtol=1e-5, atol=1e-5)


def test_numpy_actor_of_the_manager_samples_what_act_numpy_samples():
    policy = HierarchicalPolicy(6, 3, (2, 0, 4), init_log_std=-0.5)
    with torch.no_grad():
        for p in policy.parameters():
            p.add_(torch.randn(p.shape, generator=torch.Generator().manual_seed(3)))  # logits far from uniform
    obs = np.random.default_rng(0).normal(size=(32, 6)).astype(np.float32)
    act = policy.numpy_actor()
    g1, g2 = torch.Generator().manual_seed(1), torch.Generator().manual_seed(1)
    for _ in range(3):
        a, b = act(obs, g1), policy.act_numpy(obs, g2)
        assert a.shape == (32, 7) and a.dtype == np.float32
        np.testing.assert_array_equal(a[:, 0], b[:, 0])  # the same choices
        assert len(set(a[:, 0])) > 1
        np.testing.assert_allclose(a[:, 1:], b[:, 1:], rtol=1e-5, atol=1e-5)
    assert act(obs[0], g1).shape == (7,)


def test_numpy_actor_keeps_the_weights_it_was_made_with():
    policy = GaussianPolicy(2, 1, init_log_std=-20.0)  # std ~ 0: the sample is the mean
    act = policy.numpy_actor()
    before = act(np.ones((1, 2), dtype=np.float32), None)
    with torch.no_grad():
        policy.mean_net[-1].bias.add_(1.0)
    np.testing.assert_allclose(act(np.ones((1, 2), dtype=np.float32), None), before, atol=1e-6)
    np.testing.assert_allclose(policy.numpy_actor()(np.ones((1, 2), dtype=np.float32), None), before + 1.0, atol=1e-6)


def test_acting_in_inference_mode_does_not_break_later_training():
    """Cached layout tensors built during a no-grad acting call must still work under autograd."""
    policy = HierarchicalPolicy(3, 2, (2, 1))
    policy.act_numpy(np.zeros((2, 3), dtype=np.float32))
    d = policy(torch.zeros(2, 3))
    d.kl(d.detach()).sum().backward()
    d = policy(torch.zeros(2, 3))
    d.log_prob(d.sample()).sum().backward()
    assert policy.log_std.grad is not None and torch.isfinite(policy.log_std.grad).all()
