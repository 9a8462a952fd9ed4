"""TRPO update: works unchanged for every distribution, respects the trust region, moves only what it is given."""

import dataclasses

import pytest
import torch
from torch import nn

from hrlp.algos.kernels import get_flat_params
from hrlp.algos.trpo import TRPOConfig, TRPOStats, surrogate_objective, trpo_update
from hrlp.config import AdvantageConfig
from hrlp.policies.distributions import DiagGaussian
from hrlp.policies.mlp import CategoricalPolicy, GaussianPolicy, HierarchicalPolicy, ValueNet

F64 = torch.float64
OBS_DIM, BATCH = 4, 256


def _problem(kind: str, seed: int = 0):
    """A policy, a batch of states, actions drawn from the policy and advantages that favour some of them."""
    torch.manual_seed(seed)
    g = torch.Generator().manual_seed(seed)
    obs = torch.randn(BATCH, OBS_DIM, generator=g, dtype=F64)
    if kind == "gaussian":
        policy = GaussianPolicy(OBS_DIM, 2).double()
    elif kind == "categorical":
        policy = CategoricalPolicy(OBS_DIM, 3).double()
    else:
        policy = HierarchicalPolicy(OBS_DIM, 3, (2, 0, 1)).double()
    old = policy(obs).detach()
    actions = old.sample(g)
    if kind == "gaussian":
        advantages = -(actions - obs[:, :2]).square().sum(-1)
    elif kind == "categorical":
        advantages = (actions == (obs[:, 0] > 0).long()).to(F64)
    else:  # prefer macro-action 2 with a parameter near obs[:, 1], and macro-action 1 a little
        k = actions[:, 0]
        advantages = (k == 2).to(F64) * (1.0 - (actions[:, 3] - obs[:, 1]).square()) + 0.3 * (k == 1).to(F64)
    return policy, obs, old, actions, advantages


@pytest.mark.parametrize("kind", ["gaussian", "categorical", "hierarchical"])
def test_update_improves_surrogate_within_trust_region(kind):
    policy, obs, old, actions, advantages = _problem(kind)
    cfg = TRPOConfig(max_kl=0.01)
    stats = trpo_update(list(policy.parameters()), lambda: policy(obs), old, actions, advantages, cfg)
    assert stats.accepted and stats.line_search_steps >= 1
    assert stats.surrogate_after > stats.surrogate_before and stats.improvement > 0
    assert 0 < stats.kl <= cfg.max_kl * (1 + 1e-9)
    assert stats.kl > 0.2 * cfg.max_kl  # the step actually uses the trust region (quadratic model ~ exact KL)
    with torch.no_grad():
        new = policy(obs)
        assert old.kl(new).mean().item() == pytest.approx(stats.kl, rel=1e-9)
        adv = (advantages - advantages.mean()) / (advantages.std(unbiased=False) + 1e-8)
        surrogate = surrogate_objective(new, actions, old.log_prob(actions), adv).item()
        assert surrogate == pytest.approx(stats.surrogate_after, rel=1e-9)
    assert stats.step_norm > 0 and stats.grad_norm > 0 and stats.beta > 0
    assert stats.cg_relative_residual < 0.5


@pytest.mark.parametrize("kind", ["gaussian", "hierarchical"])
def test_fisher_products_on_a_subsample(kind):
    # The same states passed as the Fisher sample give exactly the full update.
    policy, obs, old, actions, advantages = _problem(kind)
    full = trpo_update(list(policy.parameters()), lambda: policy(obs), old, actions, advantages)
    theta_full = get_flat_params(list(policy.parameters()))
    policy, obs, old, actions, advantages = _problem(kind)
    same = trpo_update(list(policy.parameters()), lambda: policy(obs), old, actions, advantages,
                       fisher_dist_fn=lambda: policy(obs))  # fmt: skip
    assert same == full and torch.equal(get_flat_params(list(policy.parameters())), theta_full)
    # Every 4th state: a different step, still an improvement inside the exact trust region on every state.
    policy, obs, old, actions, advantages = _problem(kind)
    cfg = TRPOConfig(max_kl=0.01, fisher_fraction=0.25)
    sub = trpo_update(list(policy.parameters()), lambda: policy(obs), old, actions, advantages, cfg,
                      fisher_dist_fn=lambda: policy(obs[::4]))  # fmt: skip
    assert sub != full and sub.accepted and sub.surrogate_after > sub.surrogate_before
    assert 0.2 * cfg.max_kl < sub.kl <= cfg.max_kl * (1 + 1e-9)
    with torch.no_grad():
        assert old.kl(policy(obs)).mean().item() == pytest.approx(sub.kl, rel=1e-9)


def test_only_the_given_parameters_move():
    """A frozen feature layer and the value net stay bit-identical; no .grad is left on anything."""
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(0)
    frozen = nn.Linear(OBS_DIM, 8).double().requires_grad_(False)
    head = nn.Linear(8, 2).double()
    log_std = nn.Parameter(torch.zeros(2, dtype=F64))
    value = ValueNet(OBS_DIM).double()
    obs = torch.randn(BATCH, OBS_DIM, generator=g, dtype=F64)

    def dist_fn():
        return DiagGaussian(head(torch.tanh(frozen(obs))), log_std)

    old = dist_fn().detach()
    actions = old.sample(g)
    before = {
        name: p.clone() for name, p in [*frozen.named_parameters(), *(("v." + n, p) for n, p in value.named_parameters())]
    }
    head_before = get_flat_params(list(head.parameters()))
    stats = trpo_update([*head.parameters(), log_std], dist_fn, old, actions, actions[:, 0] - actions[:, 1])
    assert stats.accepted
    after = dict([*frozen.named_parameters(), *(("v." + n, p) for n, p in value.named_parameters())])
    for name, p in before.items():
        assert torch.equal(p, after[name]), name
    assert not torch.equal(head_before, get_flat_params(list(head.parameters())))
    assert all(p.grad is None for p in [*frozen.parameters(), *head.parameters(), log_std, *value.parameters()])


def test_zero_advantages_take_no_step():
    policy, obs, old, actions, advantages = _problem("hierarchical")
    theta = get_flat_params(list(policy.parameters()))
    stats = trpo_update(list(policy.parameters()), lambda: policy(obs), old, actions, torch.zeros_like(advantages))
    assert not stats.accepted and stats.line_search_steps == 0 and stats.step_norm == 0.0
    assert torch.equal(theta, get_flat_params(list(policy.parameters())))


def test_entropy_bonus_alone_raises_entropy():
    policy, obs, old, actions, advantages = _problem("hierarchical")
    cfg = TRPOConfig(entropy_coef=1.0, normalize_advantages=False)
    stats = trpo_update(list(policy.parameters()), lambda: policy(obs), old, actions, torch.zeros_like(advantages), cfg)
    assert stats.accepted and stats.entropy > stats.entropy_before and stats.kl <= cfg.max_kl


def test_deterministic_given_seed():
    results = []
    for _ in range(2):
        policy, obs, old, actions, advantages = _problem("gaussian", seed=3)
        results.append(trpo_update(list(policy.parameters()), lambda p=policy, o=obs: p(o), old, actions, advantages))
    assert results[0] == results[1]


def test_float32_policy():
    policy, obs, _, actions, advantages = _problem("hierarchical")
    policy = policy.float()
    obs32, actions32, adv32 = obs.float(), actions.float(), advantages.float()
    old32 = policy(obs32).detach()
    stats = trpo_update(list(policy.parameters()), lambda: policy(obs32), old32, actions32, adv32)
    assert stats.accepted and stats.kl <= 0.01 * (1 + 1e-6)


def test_stats_are_plain_numbers():
    policy, obs, old, actions, advantages = _problem("categorical")
    stats = trpo_update(list(policy.parameters()), lambda: policy(obs), old, actions, advantages)
    row = stats.to_dict()
    assert set(row) == {f.name for f in dataclasses.fields(TRPOStats)}
    assert all(isinstance(v, int | float | bool) for v in row.values())


def test_rejects_params_without_grad():
    policy, obs, old, actions, advantages = _problem("gaussian")
    with pytest.raises(ValueError, match="require grad"):
        trpo_update([p.detach() for p in policy.parameters()], lambda: policy(obs), old, actions, advantages)


def test_config_defaults_follow_the_paper():
    cfg, adv = TRPOConfig(), AdvantageConfig()
    assert (cfg.max_kl, adv.gamma) == (0.01, 0.99)  # Appendix D
    assert (cfg.cg_iters, cfg.cg_damping, adv.gae_lambda, cfg.entropy_coef) == (10, 0.1, 0.97, 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.max_kl = 0.1  # type: ignore[misc]


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("max_kl", 0.0),
        ("max_kl", -0.01),
        ("max_kl", float("inf")),
        ("cg_iters", 0),
        ("cg_damping", -1.0),
        ("cg_residual_tol", -1.0),
        ("line_search_backtracks", 0),
        ("line_search_shrink", 1.0),
        ("line_search_shrink", 0.0),
        ("entropy_coef", -0.01),
        ("fisher_fraction", 0.0),
        ("fisher_fraction", 1.5),
    ],
)
def test_config_validation(field, value):
    with pytest.raises(ValueError, match=field):
        TRPOConfig(**{field: value})


@pytest.mark.parametrize(("field", "value"), [("gamma", 1.5), ("gae_lambda", -0.1)])
def test_advantage_config_validation(field, value):
    with pytest.raises(ValueError, match=field):
        AdvantageConfig(**{field: value})


@pytest.mark.parametrize("kind", ["gaussian", "hierarchical"])
def test_old_dist_none_is_the_policy_itself_with_one_forward_pass_per_candidate(kind):
    """``old_dist=None`` takes the old policy from the gradient's own forward pass: the same step, bit for bit, as
    passing it; the batch's policy is computed once at the start and once per line-search candidate, no more."""
    policy, obs, old, actions, advantages = _problem(kind)
    given = trpo_update(list(policy.parameters()), lambda: policy(obs), old, actions, advantages)
    theta_given = get_flat_params(list(policy.parameters()))
    policy, obs, _, actions, advantages = _problem(kind)
    calls = []

    def dist_fn():
        calls.append(1)
        return policy(obs)

    own = trpo_update(list(policy.parameters()), dist_fn, None, actions, advantages)
    assert own == given and torch.equal(get_flat_params(list(policy.parameters())), theta_given)
    assert own.accepted and len(calls) == 1 + own.line_search_steps
