"""Distributions: closed forms against Monte Carlo and quadrature, Lemma 1, encoding helpers, gradients."""

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from scipy import integrate, stats

from hrlp.policies.distributions import (
    Categorical,
    DiagGaussian,
    Hierarchical,
    flat_to_tuple,
    flat_to_tuples,
    tuple_to_flat,
    tuples_to_flat,
)

F64 = torch.float64
N_MC = 20_000


def _gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _repeat(dist, n):
    """The single distribution ``dist`` (batch of 1) repeated ``n`` times."""
    if isinstance(dist, DiagGaussian):
        return DiagGaussian(dist.mean.expand(n, -1), dist.log_std.expand(n, -1))
    if isinstance(dist, Categorical):
        return Categorical(dist.logits.expand(n, -1))
    g = dist.gaussian
    return Hierarchical(dist.categorical.logits.expand(n, -1), g.mean.expand(n, -1), g.log_std.expand(n, -1), dist.param_dims)


def _pair(kind: str):
    """Two different single-state distributions of one kind, float64."""
    if kind == "gaussian":
        p = DiagGaussian(torch.tensor([[0.3, -1.0, 2.0]], dtype=F64), torch.tensor([0.1, -0.5, 0.4], dtype=F64))
        q = DiagGaussian(torch.tensor([[0.0, -0.6, 2.5]], dtype=F64), torch.tensor([0.3, -0.2, 0.1], dtype=F64))
    elif kind == "categorical":
        p = Categorical(torch.tensor([[0.2, -1.0, 1.3, 0.0]], dtype=F64))
        q = Categorical(torch.tensor([[0.0, 0.5, 0.7, -0.4]], dtype=F64))
    else:
        dims = (2, 0, 1)
        p = Hierarchical(
            torch.tensor([[0.5, -0.3, 0.1]], dtype=F64),
            torch.tensor([[0.2, -0.4, 1.0]], dtype=F64),
            torch.tensor([0.0, -0.3, 0.2], dtype=F64),
            dims,
        )
        q = Hierarchical(
            torch.tensor([[0.1, 0.2, -0.4]], dtype=F64),
            torch.tensor([[0.5, -0.1, 0.6]], dtype=F64),
            torch.tensor([0.2, -0.1, -0.1], dtype=F64),
            dims,
        )
    return p, q


KINDS = ["gaussian", "categorical", "hierarchical"]


@pytest.mark.parametrize("kind", KINDS)
def test_entropy_matches_monte_carlo(kind):
    p, _ = _pair(kind)
    big = _repeat(p, N_MC)
    neg_log_p = -big.log_prob(big.sample(_gen(1)))
    estimate, stderr = neg_log_p.mean().item(), neg_log_p.std().item() / math.sqrt(N_MC)
    assert abs(p.entropy().item() - estimate) < 4 * stderr


@pytest.mark.parametrize("kind", KINDS)
def test_kl_matches_monte_carlo(kind):
    p, q = _pair(kind)
    big_p, big_q = _repeat(p, N_MC), _repeat(q, N_MC)
    a = big_p.sample(_gen(2))
    log_ratio = big_p.log_prob(a) - big_q.log_prob(a)
    estimate, stderr = log_ratio.mean().item(), log_ratio.std().item() / math.sqrt(N_MC)
    assert p.kl(q).item() > 0
    assert abs(p.kl(q).item() - estimate) < 4 * stderr


@pytest.mark.parametrize("kind", KINDS)
def test_kl_with_itself_is_zero(kind):
    p, _ = _pair(kind)
    assert p.kl(p).item() == pytest.approx(0.0, abs=1e-12)
    assert p.kl(p.detach()).item() == pytest.approx(0.0, abs=1e-12)


def test_gaussian_closed_forms_against_scipy():
    p, _ = _pair("gaussian")
    x = torch.tensor([[0.1, 0.2, -0.3]], dtype=F64)
    sp = stats.norm(p.mean.numpy()[0], p.std.numpy()[0])
    assert p.log_prob(x).item() == pytest.approx(sp.logpdf(x.numpy()[0]).sum(), rel=1e-12)
    assert p.entropy().item() == pytest.approx(sp.entropy().sum(), rel=1e-12)


def test_gaussian_log_std_broadcasts():
    mean = torch.zeros(4, 2)
    d1 = DiagGaussian(mean, torch.tensor([0.1, 0.2]))
    d2 = DiagGaussian(mean, torch.tensor([[0.1, 0.2]] * 4))
    a = torch.ones(4, 2)
    torch.testing.assert_close(d1.log_prob(a), d2.log_prob(a))
    assert d1.entropy().shape == (4,)


def test_categorical_known_answers():
    d = Categorical(torch.log(torch.tensor([[0.5, 0.25, 0.25]], dtype=F64)))
    assert d.entropy().item() == pytest.approx(1.5 * math.log(2))
    assert d.log_prob(torch.tensor([1])).item() == pytest.approx(math.log(0.25))
    assert d.log_prob(torch.tensor([1.0])).item() == pytest.approx(math.log(0.25))  # float-encoded index
    assert d.mode().tolist() == [0]
    u = Categorical(torch.zeros(1, 3, dtype=F64))
    assert d.kl(u).item() == pytest.approx(math.log(3) - 1.5 * math.log(2))


def test_categorical_sample_frequencies():
    probs = torch.tensor([0.1, 0.6, 0.3], dtype=F64)
    d = Categorical(torch.log(probs).expand(N_MC, -1))
    a = d.sample(_gen(3))
    assert a.dtype == torch.long and a.shape == (N_MC,)
    freq = torch.bincount(a, minlength=3).double() / N_MC
    stderr = torch.sqrt(probs * (1 - probs) / N_MC)
    assert torch.all((freq - probs).abs() < 4 * stderr)


def _hier_1d(logits, means, log_std):
    """Three macro-actions with 1-d parameters each."""
    return Hierarchical(
        torch.tensor([logits], dtype=F64), torch.tensor([means], dtype=F64), torch.tensor(log_std, dtype=F64), (1, 1, 1)
    )


def test_hierarchical_kl_matches_quadrature():
    """Lemma 1 against KL(mu, mu~) = sum_k int mu(k, u) log(mu(k, u) / mu~(k, u)) du computed numerically."""
    mu = _hier_1d([0.4, -0.2, 0.9], [0.0, 1.0, -0.5], [0.0, -0.4, 0.3])
    nu = _hier_1d([-0.1, 0.3, 0.2], [0.3, 0.6, -1.0], [0.2, -0.1, 0.0])
    p, p_tilde = mu.categorical.probs[0].numpy(), nu.categorical.probs[0].numpy()
    total = 0.0
    for k in range(3):
        m, s = mu.gaussian.mean[0, k].item(), mu.gaussian.std[0, k].item()
        mt, st = nu.gaussian.mean[0, k].item(), nu.gaussian.std[0, k].item()

        def integrand(u, k=k, m=m, s=s, mt=mt, st=st):
            dens, dens_t = p[k] * stats.norm.pdf(u, m, s), p_tilde[k] * stats.norm.pdf(u, mt, st)
            return dens * (np.log(dens) - np.log(dens_t))

        total += integrate.quad(integrand, m - 12 * s, m + 12 * s, epsabs=1e-12)[0]
    assert mu.kl(nu).item() == pytest.approx(total, rel=1e-8)


def test_hierarchical_kl_is_lemma_1_decomposition():
    mu, nu = _pair("hierarchical")
    p = mu.categorical.probs[0]
    block_kl = [
        DiagGaussian(mu.gaussian.mean[:, 0:2], mu.gaussian.log_std[0, 0:2]).kl(
            DiagGaussian(nu.gaussian.mean[:, 0:2], nu.gaussian.log_std[0, 0:2])
        ),
        torch.zeros(1, dtype=F64),
        DiagGaussian(mu.gaussian.mean[:, 2:3], mu.gaussian.log_std[0, 2:3]).kl(
            DiagGaussian(nu.gaussian.mean[:, 2:3], nu.gaussian.log_std[0, 2:3])
        ),
    ]
    expected = mu.categorical.kl(nu.categorical) + sum(p[k] * block_kl[k] for k in range(3))
    torch.testing.assert_close(mu.kl(nu), expected)
    torch.testing.assert_close(mu.block_kl(nu)[0], torch.cat(block_kl))


def test_hierarchical_log_prob_counts_only_the_chosen_block():
    mu, _ = _pair("hierarchical")  # blocks: k=0 -> cols 1:3, k=1 -> none, k=2 -> col 3
    a = torch.tensor([[0.0, 0.1, 0.2, 0.3]], dtype=F64)
    changed_other = a.clone()
    changed_other[0, 3] = 55.0
    assert mu.log_prob(a).item() == mu.log_prob(changed_other).item()
    changed_other[0, 3] = float("nan")  # not even a nan leaks from another block
    assert mu.log_prob(a).item() == mu.log_prob(changed_other).item()
    changed_own = a.clone()
    changed_own[0, 1] = 3.0
    assert mu.log_prob(a).item() != mu.log_prob(changed_own).item()
    expected = mu.categorical.log_prob(torch.tensor([0])) + DiagGaussian(
        mu.gaussian.mean[:, 0:2], mu.gaussian.log_std[0, 0:2]
    ).log_prob(a[:, 1:3])
    torch.testing.assert_close(mu.log_prob(a), expected)
    # A parameterless macro-action contributes log p_k only.
    b = torch.tensor([[1.0, 9.0, 9.0, 9.0]], dtype=F64)
    torch.testing.assert_close(mu.log_prob(b), mu.categorical.log_prob(torch.tensor([1])))


def test_hierarchical_reduces_to_categorical_and_gaussian():
    logits = torch.tensor([[0.3, -0.2]], dtype=F64)
    parameterless = Hierarchical(logits, torch.zeros(1, 0, dtype=F64), torch.zeros(0, dtype=F64), (0, 0))
    other = Hierarchical(logits.flip(-1), torch.zeros(1, 0, dtype=F64), torch.zeros(0, dtype=F64), (0, 0))
    torch.testing.assert_close(parameterless.kl(other), Categorical(logits).kl(Categorical(logits.flip(-1))))
    torch.testing.assert_close(parameterless.entropy(), Categorical(logits).entropy())
    mean, log_std = torch.tensor([[0.5, -1.0]], dtype=F64), torch.tensor([0.1, 0.2], dtype=F64)
    single = Hierarchical(torch.zeros(1, 1, dtype=F64), mean, log_std, (2,))
    a = torch.tensor([[0.0, 0.4, -0.8]], dtype=F64)
    torch.testing.assert_close(single.log_prob(a), DiagGaussian(mean, log_std).log_prob(a[:, 1:]))
    torch.testing.assert_close(single.entropy(), DiagGaussian(mean, log_std).entropy())


def test_hierarchical_sample_and_mode_encoding():
    mu, _ = _pair("hierarchical")
    big = _repeat(mu, 8)
    a = big.sample(_gen(4))
    assert a.shape == (8, 4) and a.dtype == F64
    assert set(a[:, 0].tolist()) <= {0.0, 1.0, 2.0}
    torch.testing.assert_close(a, big.sample(_gen(4)))  # same generator seed, same sample
    m = mu.mode()
    assert m[0, 0].item() == mu.categorical.probs.argmax().item()
    torch.testing.assert_close(m[:, 1:], mu.gaussian.mean)


def test_hierarchical_rejects_bad_shapes():
    with pytest.raises(ValueError, match="means"):
        Hierarchical(torch.zeros(2, 2), torch.zeros(2, 3), torch.zeros(3), (1, 1))
    with pytest.raises(ValueError, match="logits"):
        Hierarchical(torch.zeros(2, 3), torch.zeros(2, 2), torch.zeros(2), (1, 1))
    with pytest.raises(ValueError, match="param_dims"):
        Hierarchical(torch.zeros(2, 0), torch.zeros(2, 0), torch.zeros(0), ())


@pytest.mark.parametrize("kind", KINDS)
def test_gradients_flow_and_detach_cuts_them(kind):
    p, q = _pair(kind)
    leaves = []

    def leafify(t):
        t = t.detach().clone().requires_grad_(True)
        leaves.append(t)
        return t

    if kind == "gaussian":
        r = DiagGaussian(leafify(p.mean), leafify(p.log_std[0]))
    elif kind == "categorical":
        r = Categorical(leafify(p.logits))
    else:
        r = Hierarchical(leafify(p.categorical.logits), leafify(p.gaussian.mean), leafify(p.gaussian.log_std[0]), p.param_dims)
    a = p.sample(_gen(5))
    (r.log_prob(a).sum() + r.kl(q).sum() + r.entropy().sum()).backward()
    for t in leaves:
        assert t.grad is not None and torch.isfinite(t.grad).all() and t.grad.abs().sum() > 0
    assert not r.detach().kl(q).requires_grad


def test_hierarchical_log_prob_gradient_skips_other_blocks():
    means = torch.tensor([[0.2, -0.4, 1.0]], dtype=F64, requires_grad=True)
    mu = Hierarchical(torch.zeros(1, 3, dtype=F64), means, torch.zeros(3, dtype=F64), (2, 0, 1))
    mu.log_prob(torch.tensor([[2.0, 0.0, 0.0, 0.0]], dtype=F64)).sum().backward()
    assert means.grad[0, :2].abs().sum() == 0 and means.grad[0, 2] != 0


def test_float32_works():
    mu = Hierarchical(torch.zeros(5, 2), torch.zeros(5, 3), torch.zeros(3), (1, 2))
    a = mu.sample(_gen(6))
    assert a.dtype == torch.float32 and mu.log_prob(a).dtype == torch.float32 and mu.kl(mu).dtype == torch.float32


def test_tuple_encoding_round_trip_with_gymnasium_space():
    dims = (2, 0, 1)
    space = gym.spaces.Tuple((gym.spaces.Discrete(3), *(gym.spaces.Box(-1.0, 1.0, (d,)) for d in dims)))
    space.seed(0)
    samples = [space.sample() for _ in range(5)]
    flat = tuples_to_flat(samples, dims)
    assert flat.shape == (5, 4) and flat.dtype == np.float32
    back = flat_to_tuples(flat, dims)
    for s, b in zip(samples, back, strict=True):
        assert space.contains(b)
        assert b[0] == s[0]
        for u, v in zip(s[1:], b[1:], strict=True):
            np.testing.assert_array_equal(u, v)
    torch_flat = torch.as_tensor(flat[0], dtype=F64)
    assert flat_to_tuple(torch_flat, dims)[0] == int(samples[0][0])
    np.testing.assert_array_equal(tuple_to_flat(samples[0], dims), flat[0])


def test_tuple_encoding_matches_distribution_layout():
    dims = (2, 0, 1)
    mu, _ = _pair("hierarchical")
    a = mu.sample(_gen(7))[0]
    k, u0, u1, u2 = flat_to_tuple(a, dims)
    assert k == int(a[0]) and u0.shape == (2,) and u1.shape == (0,) and u2.shape == (1,)
    np.testing.assert_allclose(u2, a[3:4].numpy(), rtol=1e-6)
    with pytest.raises(ValueError, match="block 0"):
        tuple_to_flat((0, np.zeros(3), np.zeros(0), np.zeros(1)), dims)


@pytest.mark.parametrize("kind", KINDS)
def test_detach_is_a_snapshot_of_in_place_parameters(kind):
    """A state-independent log_std is a view of a parameter; the "old" policy must not follow in-place updates."""
    log_std = torch.nn.Parameter(torch.zeros(3, dtype=F64))
    logits = torch.zeros(2, 3, dtype=F64)
    if kind == "gaussian":
        d = DiagGaussian(torch.zeros(2, 3, dtype=F64), log_std)
    elif kind == "categorical":
        d = Categorical(logits + log_std)
    else:
        d = Hierarchical(logits, torch.zeros(2, 3, dtype=F64), log_std, (1, 2, 0))
    old = d.detach()
    entropy = old.entropy().clone()
    with torch.no_grad():
        log_std.add_(1.0)
    torch.testing.assert_close(old.entropy(), entropy)
