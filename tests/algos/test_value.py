"""Value-function fit by L-BFGS."""

import pytest
import torch

from hrlp.algos.value import ValueFitConfig, fit_value
from hrlp.policies.mlp import ValueNet


def _regression(seed=0, n=512):
    g = torch.Generator().manual_seed(seed)
    obs = torch.randn(n, 3, generator=g, dtype=torch.float64)
    targets = 2.0 * torch.sin(obs[:, 0]) + obs[:, 1] ** 2 - 0.5 * obs[:, 2] + 3.0
    return obs, targets


def test_fit_raises_explained_variance():
    torch.manual_seed(0)
    net = ValueNet(3).double()
    obs, targets = _regression()
    cfg = ValueFitConfig(max_iter=25)  # modular_rl's iterations (the default, 10, trades fit for time in a run)
    stats = fit_value(net, obs, targets, cfg)
    assert stats.explained_variance_after > 0.9 > stats.explained_variance_before
    assert stats.mse_after < 0.1 * stats.mse_before
    assert 1 <= stats.loss_evaluations <= 2 * cfg.max_iter
    with torch.no_grad():
        mse = (net(obs) - targets).square().mean().item()
    assert mse == pytest.approx(stats.mse_after)
    assert all(p.grad is None for p in net.parameters())


def test_fit_works_in_float32_and_more_iterations_help():
    obs, targets = _regression(1)
    evs = []
    for iters in (2, 40):
        torch.manual_seed(0)
        net = ValueNet(3)
        evs.append(fit_value(net, obs.float(), targets.float(), ValueFitConfig(max_iter=iters)).explained_variance_after)
    assert evs[1] > evs[0]


@pytest.mark.parametrize(
    ("field", "value"), [("max_iter", 0), ("l2_coef", -1.0), ("history_size", 0), ("fraction", 0.0), ("fraction", 1.5)]
)
def test_config_validation(field, value):
    with pytest.raises(ValueError, match=field):
        ValueFitConfig(**{field: value})
