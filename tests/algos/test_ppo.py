"""PPO beside TRPO: the clipped surrogate's known answers, the update's KL early stop (Lemma 1's KL for a Manager), the
update seam in the training loop, exact resume with Adam's state, and configs saved before the advantage record."""

import dataclasses
import json
import math

import pytest
import torch

from hrlp.algos.ppo import PPOConfig, clipped_surrogate, ppo_update
from hrlp.checkpoint import load_checkpoint
from hrlp.config import OFF_POLICY, AdvantageConfig, TrainConfig, TRPOConfig
from hrlp.experiments.runner import _same_config
from hrlp.policies.distributions import Categorical, DiagGaussian, Hierarchical
from hrlp.train import train


def test_clipped_surrogate_known_answers():
    # Two states; log-ratios ln 1.5 and ln 0.5 with advantages +1 and -1, clip 0.2:
    # state 0: min(1.5 * 1, 1.2 * 1) = 1.2; state 1: min(0.5 * -1, 0.8 * -1) = -0.8; mean 0.2.
    mean = torch.zeros(2, 1)
    dist = DiagGaussian(mean, torch.zeros(2, 1))
    actions = torch.zeros(2, 1)
    logp = dist.log_prob(actions)
    old_log_prob = logp - torch.log(torch.tensor([1.5, 0.5]))
    got = clipped_surrogate(dist, actions, old_log_prob, torch.tensor([1.0, -1.0]), clip=0.2)
    assert float(got) == pytest.approx(0.2)
    # Inside the clip range the objective is the plain importance-sampled surrogate: ratio 1.1 and 0.9 -> (1.1 - 0.9) / 2.
    inside = logp - torch.log(torch.tensor([1.1, 0.9]))
    assert float(clipped_surrogate(dist, actions, inside, torch.tensor([1.0, -1.0]), clip=0.2)) == pytest.approx(0.1)


def _bandit(n: int = 512, seed: int = 0):
    """A one-step problem with a known best action: reward -(a - 2)^2 on a 1-d Gaussian policy (state-free)."""
    g = torch.Generator().manual_seed(seed)
    mean = torch.zeros(1, requires_grad=True)
    log_std = torch.zeros(1, requires_grad=True)

    def dist_fn(index=None):
        k = n if index is None else len(index)
        return DiagGaussian(mean.expand(k, 1), log_std.expand(k, 1))

    actions = dist_fn().sample(g).detach()
    advantages = -((actions[:, 0] - 2.0) ** 2)
    return [mean, log_std], dist_fn, actions, advantages


def test_ppo_update_moves_towards_the_better_actions_and_reports_the_exact_kl():
    params, dist_fn, actions, advantages = _bandit()
    old = dist_fn().detach()  # a copy: the parameters move in place
    opt = torch.optim.Adam(params, lr=0.05)
    stats = ppo_update(params, dist_fn, old, actions, advantages, opt, PPOConfig(target_kl=0.0, epochs=4, minibatches=8),
                       torch.Generator().manual_seed(1))  # fmt: skip
    assert float(params[0].detach()) > 0.1  # the mean moves towards a = 2
    assert stats.surrogate_after > stats.surrogate_before and stats.epochs == 4 and not stats.early_stopped
    assert stats.kl == pytest.approx(float(old.kl(dist_fn().detach()).mean()), rel=1e-6)
    assert 0.0 <= stats.clip_fraction <= 1.0 and math.isfinite(stats.grad_norm)


def test_ppo_stops_after_the_epoch_whose_kl_exceeds_the_target():
    params, dist_fn, actions, advantages = _bandit()
    stats = ppo_update(params, dist_fn, dist_fn(), actions, advantages, torch.optim.Adam(params, lr=0.5),
                       PPOConfig(target_kl=1e-4, epochs=10, minibatches=4))  # fmt: skip
    assert stats.early_stopped and stats.epochs == 1 and stats.kl > 1e-4


def test_ppo_early_stop_uses_lemma_1s_hierarchical_kl():
    """With a Manager's distribution, the KL the update stops on is KL(categorical) + sum_k p_k KL(Gaussian_k)."""
    torch.manual_seed(0)
    n = 256
    logits = torch.zeros(2, requires_grad=True)
    means = torch.zeros(3, requires_grad=True)  # skill 0 has 1 parameter, skill 1 has 2
    log_std = torch.zeros(3, requires_grad=True)

    def dist_fn(index=None):
        k = n if index is None else len(index)
        return Hierarchical(logits.expand(k, 2), means.expand(k, 3), log_std.expand(k, 3), (1, 2))

    old = dist_fn().detach()
    actions = old.sample(torch.Generator().manual_seed(0))
    advantages = torch.where(actions[:, 0] == 1, 1.0, -1.0) + actions[:, 1]
    stats = ppo_update([logits, means, log_std], dist_fn, old, actions, advantages,
                       torch.optim.Adam([logits, means, log_std], lr=0.05), PPOConfig(epochs=3, minibatches=4))  # fmt: skip
    new = dist_fn().detach()
    p = torch.softmax(logits.detach(), 0)  # the old probabilities are uniform
    cat = float(Categorical(torch.zeros(1, 2)).kl(Categorical(logits.detach()[None])))
    g0 = float(DiagGaussian(torch.zeros(1, 1), torch.zeros(1, 1)).kl(DiagGaussian(means.detach()[None, :1],
                                                                                   log_std.detach()[None, :1])))  # fmt: skip
    g1 = float(DiagGaussian(torch.zeros(1, 2), torch.zeros(1, 2)).kl(DiagGaussian(means.detach()[None, 1:],
                                                                                   log_std.detach()[None, 1:])))  # fmt: skip
    lemma_1 = cat + 0.5 * g0 + 0.5 * g1  # weights: the old policy's probabilities
    assert stats.kl == pytest.approx(lemma_1, rel=1e-5) and float(old.kl(new).mean()) == pytest.approx(lemma_1, rel=1e-5)
    assert float(p[1]) > 0.5  # skill 1 (advantage +1) became likelier


def test_ppo_config_is_checked():
    for bad in ({"clip": 0.0}, {"epochs": 0}, {"minibatches": 1.5}, {"lr": -1.0}, {"target_kl": math.nan}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            PPOConfig(**bad)
    with pytest.raises(ValueError, match="algo must be one of trpo, ppo"):
        TrainConfig(task="Pendulum-v1", algo="sgd")
    with pytest.raises(ValueError, match="minibatches"):
        TrainConfig(task="Pendulum-v1", algo="ppo", batch_steps=16, num_envs=16)


def test_a_ppo_run_trains_logs_ppo_statistics_and_resumes_exactly(tmp_path):
    cfg = TrainConfig(task="ReacherStabilised", steps=600, batch_steps=200, num_envs=4, episode_steps=70, seed=5,
                      algo="ppo", ppo=PPOConfig(epochs=2, minibatches=4))  # fmt: skip
    full = list(train(cfg, tmp_path / "full"))
    assert "ppo/kl" in full[0] and "trpo/kl" not in full[0] and full[0]["ppo/epochs"] >= 1
    part = list(train(dataclasses.replace(cfg, steps=400), tmp_path / "cut"))
    rest = list(train(cfg, tmp_path / "cut", resume=True))

    def strip(rows):
        return [{k: v for k, v in r.items() if not k.startswith("time/")} for r in rows]

    assert strip(part + rest) == strip(full)  # Adam's moments and the shuffle's generator were saved and restored
    a, _ = load_checkpoint(tmp_path / "full" / "checkpoint")
    b, _ = load_checkpoint(tmp_path / "cut" / "checkpoint")
    assert any(k.startswith("ppo.adam.") for k in a) and all(torch.equal(a[k], b[k]) for k in a)


def test_configs_saved_with_gamma_in_trpos_record_read_as_the_advantage_record(tmp_path):
    cfg = TrainConfig(task="Reacher", advantage=AdvantageConfig(gamma=0.95, gae_lambda=0.9), trpo=TRPOConfig(max_kl=0.02))
    old = cfg.to_json()
    old["trpo"] = {**old.pop("advantage"), **old["trpo"]}  # the layout before AdvantageConfig
    del old["ppo"], old["algo"]
    assert TrainConfig.from_json(old) == cfg
    assert _same_config(old, json.loads(json.dumps(cfg.to_json())))  # a preset's finished run is still found


def test_every_presets_runs_made_before_the_advantage_record_are_still_found_and_keep_trpo():
    """Every preset keeps the settings it ran with: TRPO, gamma 0.99 and GAE lambda 0.97 (Appendix D and modular_rl, as
    before), and a finished run saved in the layout before AdvantageConfig (gamma and lambda in TRPO's record, no PPO
    record) is the preset's run for the runner (:func:`_same_config`), so no preset retrains."""
    from hrlp.experiments.presets import PRESETS

    for preset in PRESETS.values():
        for run in preset.runs:
            cfg = run.config
            where = (preset.name, run.name)
            if cfg.algo in OFF_POLICY:  # the Fetch presets: SAC from the start, no record before the advantage's
                continue
            assert cfg.algo == "trpo" and cfg.advantage == AdvantageConfig(gamma=0.99, gae_lambda=0.97), where
            old = cfg.to_json()
            old["trpo"] = {**old["trpo"], **old.pop("advantage")}
            del old["ppo"], old["algo"]
            assert _same_config(old, json.loads(json.dumps(cfg.to_json()))), where
