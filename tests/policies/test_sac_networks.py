"""SAC's distributions and networks: squashed Gaussian densities against torch.distributions, Lemma 1's KL for the
hybrid one against a Monte Carlo estimate, the actor's encodings and bounds, and the twin critics' two views."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch.distributions import Normal, TanhTransform, TransformedDistribution

from hrlp.policies.distributions import Categorical, HybridSquashed, SquashedGaussian
from hrlp.policies.sac import SACActor, TwinQ, action_kind


def _reference(mean, log_std):
    return TransformedDistribution(Normal(mean, log_std.exp()), [TanhTransform(cache_size=1)])


def test_squashed_gaussian_log_prob_matches_torchs_tanh_transformed_normal():
    g = torch.Generator().manual_seed(0)
    mean, log_std = torch.randn(64, 3, generator=g), 0.5 * torch.randn(64, 3, generator=g)
    d = SquashedGaussian(mean, log_std)
    a, lp = d.rsample(torch.Generator().manual_seed(1))
    expected = _reference(mean, log_std).log_prob(a.clamp(-0.999999, 0.999999)).sum(-1)
    assert torch.allclose(d.log_prob(a), expected, atol=1e-3)
    unsaturated = a.abs().max(-1).values < 0.999
    assert torch.allclose(lp.sum(-1)[unsaturated], d.log_prob(a)[unsaturated], atol=1e-3)
    assert (a.abs() < 1).all() and torch.equal(d.mode(), torch.tanh(mean))


def test_the_reparameterised_sample_carries_gradients_and_a_large_pre_tanh_value_stays_finite():
    mean = torch.tensor([[0.0, 30.0]], requires_grad=True)
    _, lp = SquashedGaussian(mean, torch.zeros(1, 2)).rsample(torch.Generator().manual_seed(0))
    lp.sum().backward()
    assert torch.isfinite(lp).all() and mean.grad is not None and torch.isfinite(mean.grad).all()


def test_hybrid_log_prob_is_the_choice_plus_only_the_chosen_block():
    logits, means, log_std = torch.tensor([[0.0, 1.0, -1.0]]), torch.tensor([[0.1, -0.2, 0.3]]), torch.full((1, 3), -0.5)
    d = HybridSquashed(logits, means, log_std, (1, 2, 0))
    action = torch.tensor([[1.0, float("nan"), 0.4, -0.3]])  # block 0 is not chosen: whatever it holds is ignored
    block = SquashedGaussian(means[:, 1:3], log_std[:, 1:3]).log_prob(action[:, 2:4])
    assert torch.allclose(d.log_prob(action), torch.log_softmax(logits, -1)[:, 1] + block)
    parameterless = torch.tensor([[2.0, 0.5, 0.0, 0.0]])
    assert torch.allclose(d.log_prob(parameterless), torch.log_softmax(logits, -1)[:, 2])


def test_hybrid_kl_is_lemma_1_and_agrees_with_a_monte_carlo_estimate():
    dims = (2, 1)
    p = HybridSquashed(torch.tensor([[0.3, -0.2]]), torch.tensor([[0.2, -0.4, 0.5]]), torch.tensor([[-0.3, 0.1, -0.6]]), dims)
    q = HybridSquashed(torch.tensor([[-0.1, 0.4]]), torch.tensor([[0.0, 0.1, 0.2]]), torch.tensor([[-0.1, -0.2, -0.4]]), dims)
    exact = float(p.kl(q))
    g = torch.Generator().manual_seed(3)
    n = 200_000
    rep = HybridSquashed(p.categorical.log_p.expand(n, -1), p.squashed.mean.expand(n, -1), p.squashed.log_std.expand(n, -1),
                         dims)  # fmt: skip
    other = HybridSquashed(q.categorical.log_p.expand(n, -1), q.squashed.mean.expand(n, -1),
                           q.squashed.log_std.expand(n, -1), dims)  # fmt: skip
    a = rep.sample(g)
    a[:, 1:] = a[:, 1:].clamp(-0.9999, 0.9999)
    estimate = float((rep.log_prob(a) - other.log_prob(a)).mean())
    assert exact == pytest.approx(estimate, abs=0.01)


def test_hybrid_rsample_blocks_gives_each_blocks_log_density():
    d = HybridSquashed(torch.zeros(4, 3), torch.randn(4, 3), torch.zeros(4, 3), (1, 0, 2))
    x, lp = d.rsample_blocks(torch.Generator().manual_seed(0))
    assert x.shape == (4, 3) and lp.shape == (4, 3)
    assert torch.equal(lp[:, 1], torch.zeros(4))
    each = SquashedGaussian(d.squashed.mean, d.squashed.log_std)
    u = torch.atanh(x.clamp(-0.999999, 0.999999))
    per_column = _reference(each.mean, each.log_std).log_prob(torch.tanh(u).clamp(-0.999999, 0.999999))
    assert torch.allclose(lp[:, 0], per_column[:, 0], atol=1e-3) and torch.allclose(
        lp[:, 2], per_column[:, 1:].sum(-1), atol=1e-3
    )


def test_the_actor_acts_in_a_boxs_own_bounds_and_maps_them_back():
    space = gym.spaces.Box(np.array([0.0, -10.0], np.float32), np.array([720.0, 10.0], np.float32))
    actor = SACActor(5, space, (16, 16))
    obs = torch.randn(32, 5)
    a = actor.act(obs, torch.Generator().manual_seed(0))
    assert a.shape == (32, 2) and (a[:, 0] >= 0).all() and (a[:, 0] <= 720).all() and (a[:, 1].abs() <= 10).all()
    rows = actor.to_hybrid(a)
    assert torch.equal(rows[:, 0], torch.zeros(32)) and (rows[:, 1:].abs() <= 1 + 1e-6).all()
    assert torch.allclose(rows[:, 1:] * actor.scale + actor.offset, a, atol=1e-4)
    assert torch.allclose(actor.act(obs, deterministic=True)[:, 0], torch.full((32,), 360.0), atol=10.0)  # near tanh(0)


def test_the_actor_speaks_each_spaces_encoding():
    assert action_kind(gym.spaces.Discrete(4)) == ("discrete", (0, 0, 0, 0))
    discrete = SACActor(3, gym.spaces.Discrete(4), (8,))
    assert isinstance(discrete(torch.zeros(2, 3)), Categorical)
    k = discrete.act(torch.zeros(5, 3), torch.Generator().manual_seed(0))
    assert k.shape == (5,) and torch.equal(discrete.to_hybrid(k)[:, 0], k.float())
    tup = gym.spaces.Tuple((gym.spaces.Discrete(2), gym.spaces.Box(-1, 1, (2,)), gym.spaces.Box(-1, 1, (1,))))
    hybrid = SACActor(3, tup, (8,))
    a = hybrid.act(torch.zeros(5, 3), torch.Generator().manual_seed(0))
    assert a.shape == (5, 4) and set(a[:, 0].tolist()) <= {0.0, 1.0} and torch.equal(hybrid.to_hybrid(a), a)
    with pytest.raises(ValueError):
        SACActor(3, gym.spaces.MultiBinary(3))


def test_twin_critics_every_choice_equals_one_choice_at_a_time():
    q = TwinQ(4, (2, 0, 1), (16,))
    obs, x = torch.randn(6, 4), torch.rand(6, 3) * 2 - 1
    every1, every2 = q.every_choice(obs, x)
    for k in range(3):
        q1, q2 = q(obs, torch.cat([torch.full((6, 1), float(k)), x], dim=1))
        assert torch.allclose(every1[:, k], q1, atol=1e-6) and torch.allclose(every2[:, k], q2, atol=1e-6)
    # The other blocks' parameters do not reach a choice's value.
    changed = x.clone()
    changed[:, 2] = 0.7
    assert torch.allclose(q.every_choice(obs, changed)[0][:, :2], every1[:, :2])
