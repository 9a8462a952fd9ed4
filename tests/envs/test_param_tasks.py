"""The short-episode parameterised-action tasks (hrlp.envs.param_tasks): spaces, optimal returns, baselines, training."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from scipy.stats import norm

import hrlp.envs  # noqa: F401  (registers the ids)
from hrlp.envs.check import check_spaces
from hrlp.envs.param_tasks import (
    PARAM_TASKS,
    SHORT_EPISODE_SETTINGS,
    ParamBandit,
    ParamMatch,
    ParamReach,
    heuristic_action,
    random_action,
    short_episode_config,
)

NAMES = sorted(PARAM_TASKS)
BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "short_episodes.py"


def mean_return(env: gym.Env, policy: str, episodes: int, seed: int = 0) -> float:
    """Mean undiscounted return of the oracle, heuristic or random policy over ``episodes`` seeded episodes."""
    rng = np.random.default_rng(seed)
    total = 0.0
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        while True:
            if policy == "oracle":
                a = env.unwrapped.oracle_action()
            elif policy == "heuristic":
                a = heuristic_action(env, obs)
            else:
                a = random_action(env, rng)
            obs, r, terminated, truncated, _ = env.step(a)
            total += float(r)
            if terminated or truncated:
                break
    return total / episodes


@pytest.mark.parametrize("name", NAMES)
def test_env_checker_and_hrlp_spaces(name):
    env = gym.make(f"hrlp/{name}-v0")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium recommends [-1, 1] bounds: these are wide on purpose
        check_env(env.unwrapped, skip_render_check=True)
    check_spaces(name, env.observation_space, env.action_space)
    space = env.action_space
    assert isinstance(space, gym.spaces.Tuple) and isinstance(space.spaces[0], gym.spaces.Discrete)
    assert max(float(np.max(b.high - b.low)) for b in space.spaces[1:] if b.shape[0]) >= 100  # wide native bounds


@pytest.mark.parametrize("name", NAMES)
def test_seeded_and_deterministic(name):
    def trajectory(seed):
        env = gym.make(f"hrlp/{name}-v0")
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for _ in range(env.unwrapped.horizon):
            obs, r, terminated, truncated, _ = env.step(heuristic_action(env, obs))
            out.append(np.append(obs, r))
            if terminated or truncated:
                break
        return np.concatenate(out)

    np.testing.assert_array_equal(trajectory(3), trajectory(3))
    assert not np.array_equal(trajectory(3), trajectory(4))


@pytest.mark.parametrize("name", NAMES)
def test_oracle_reaches_the_stated_optimum(name):
    env = gym.make(f"hrlp/{name}-v0")
    optimal = env.unwrapped.optimal_return()
    got = mean_return(env, "oracle", 3000)
    assert abs(got - optimal) <= 0.01 * optimal, (got, optimal)  # bandit: MC standard error about 0.003


def test_stated_optima():
    assert ParamBandit().optimal_return() == ParamBandit.OPTIMAL == 0.75
    assert ParamMatch().optimal_return() == 3.0 and ParamMatch(steps=7).optimal_return() == 7.0
    assert ParamReach().optimal_return() == 1.0


@pytest.mark.parametrize("name", ["ParamBandit", "ParamMatch"])
def test_no_sampled_action_beats_the_oracle_in_its_state(name):
    """Each decision's state is drawn afresh, so the best per-decision reward bounds the return: no sampled action
    (random, or the oracle's own perturbed) earns more than the oracle's action in the same state."""
    env = gym.make(f"hrlp/{name}-v0")
    rng = np.random.default_rng(1)
    for i in range(100):
        env.reset(seed=i)
        best = copy.deepcopy(env.unwrapped).step(env.unwrapped.oracle_action())[1]
        k, *us = env.unwrapped.oracle_action()
        for _ in range(10):
            probe = copy.deepcopy(env.unwrapped)
            if rng.random() < 0.5:
                a = random_action(env, rng)
            else:
                a = (k, *(u + rng.normal(0, 5, size=u.shape).astype(np.float32) for u in us))
            assert probe.step(a)[1] <= best + 1e-12


@pytest.mark.parametrize("name", NAMES)
def test_no_sampled_policy_beats_the_optimum(name):
    env = gym.make(f"hrlp/{name}-v0")
    optimal = env.unwrapped.optimal_return()
    rng = np.random.default_rng(2)
    for _ in range(5):  # an oracle with noisy parameters, and a policy mixing it with random actions
        noise, mix = rng.uniform(0, 10), rng.uniform(0, 0.5)
        total, episodes = 0.0, 300
        for i in range(episodes):
            env.reset(seed=i)
            while True:
                k, *us = env.unwrapped.oracle_action()
                a = (k, *(u + rng.normal(0, noise, size=u.shape).astype(np.float32) for u in us))
                if rng.random() < mix:
                    a = random_action(env, rng)
                _, r, terminated, truncated, _ = env.step(a)
                total += float(r)
                if terminated or truncated:
                    break
        assert total / episodes <= optimal + 1e-9


def _bandit_expectations() -> tuple[float, float]:
    """The bandit's random and heuristic expected returns, in closed form (Gaussian integrals) and by quadrature."""
    ys = np.linspace(-1, 1, 20001)

    def mean_kernel_uniform(lo, hi, target, width):  # E over u ~ U[lo, hi] of K(u - target, width)
        return width * math.sqrt(2 * math.pi) / (hi - lo) * (norm.cdf((hi - target) / width) - norm.cdf((lo - target) / width))

    far = float(np.mean(mean_kernel_uniform(0, 720, 360 + 240 * ys, 72)))
    near = float(np.mean(mean_kernel_uniform(-50, 50, 40 * ys, 10)))
    random = (0.5 * far + 0.5 * near + 0.25) / 3  # E[(1 - x)/2] = E[(1 + x)/2] = 1/2, skip pays 0.25

    def centred(c, width):  # E over y ~ U[-1, 1] of K(c y, width)
        return width / c * math.sqrt(2 * math.pi) * (norm.cdf(c / width) - 0.5)

    heuristic = 0.75 * (0.5 * centred(240, 72) + 0.5 * centred(40, 10))  # the right choice pays (1 + |x|)/2, mean 0.75
    return random, heuristic


def test_bandit_random_and_heuristic_returns_match_their_closed_forms():
    random, heuristic = _bandit_expectations()
    env = gym.make("hrlp/ParamBandit-v0")
    assert abs(mean_return(env, "random", 6000) - random) < 0.01
    assert abs(mean_return(env, "heuristic", 6000) - heuristic) < 0.01
    assert 0.15 < random < heuristic < 0.3 < ParamBandit.OPTIMAL


@pytest.mark.parametrize(
    ("name", "random_range", "heuristic_range"),
    [("ParamMatch", (0.15, 0.3), (1.7, 2.0)), ("ParamReach", (0.01, 0.07), (0.999, 1.0))],
)
def test_random_and_heuristic_returns(name, random_range, heuristic_range):
    """Below the optimum, the random policy far below it (ranges from 20,000-episode simulations with a margin)."""
    env = gym.make(f"hrlp/{name}-v0")
    random, heuristic = mean_return(env, "random", 1000), mean_return(env, "heuristic", 1000)
    assert random_range[0] <= random <= random_range[1]
    assert heuristic_range[0] <= heuristic <= heuristic_range[1] <= env.unwrapped.optimal_return()


def test_reach_success_is_reported_and_the_time_limit_truncates():
    env = gym.make("hrlp/ParamReach-v0")
    env.reset(seed=0)
    for t in range(8):  # standing still: never arrives
        _, r, terminated, truncated, info = env.step((1, np.zeros(2, np.float32), np.zeros(2, np.float32)))
        assert r == 0.0 and not terminated and truncated == (t == 7)
    assert info == {"success": False}
    env.reset(seed=0)
    while True:
        _, r, terminated, truncated, info = env.step(env.unwrapped.oracle_action())
        if terminated or truncated:
            break
    assert terminated and r == 1.0 and info == {"success": True}


@pytest.mark.parametrize(
    ("cls", "kwargs", "match"),
    [
        (ParamBandit, {"skip_reward": 0.9}, "skip_reward must be a number in"),
        (ParamBandit, {"skip_reward": "x"}, "skip_reward must be"),
        (ParamBandit, {"skip_reward": math.nan}, "skip_reward must be"),
        (ParamMatch, {"steps": 0}, "steps must be an integer in"),
        (ParamMatch, {"steps": 2.5}, "steps must be an integer in"),
        (ParamReach, {"max_decisions": 2}, "max_decisions must be an integer in"),
        (ParamReach, {"goal_radius": -1.0}, "goal_radius must be a number in"),
        (ParamReach, {"max_decisions": True}, "max_decisions must be an integer in"),
    ],
)
def test_bad_arguments_are_one_line_value_errors(cls, kwargs, match):
    with pytest.raises(ValueError, match=match) as e:
        cls(**kwargs)
    assert "\n" not in str(e.value)


def test_bad_arguments_through_env_factory_are_one_line():
    from hrlp.train import env_factory

    with pytest.raises(ValueError, match="steps must be an integer") as e:
        env_factory("hrlp/ParamMatch-v0", steps=0)
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="invalid argument") as e:
        env_factory("hrlp/ParamBandit-v0", nonsense=1)
    assert "\n" not in str(e.value)


def test_short_episode_config_applies_the_settings():
    cfg = short_episode_config("hrlp/ParamBandit-v0", steps=1000, seed=3, **{"advantage.gamma": 0.9})
    assert cfg.batch_steps == SHORT_EPISODE_SETTINGS["batch_steps"] and cfg.seed == 3 and cfg.steps == 1000
    assert cfg.trpo.max_kl == SHORT_EPISODE_SETTINGS["trpo.max_kl"] and cfg.advantage.gamma == 0.9
    with pytest.raises(ValueError, match="unknown settings"):
        short_episode_config("hrlp/ParamBandit-v0", steps=1000, **{"policy.x": 1})


def _train_greedy(name: str, episodes: int, eval_episodes: int, tmp_path: Path, seed: int = 0) -> tuple[float, int]:
    """Train ``name`` with the short-episode settings for ``episodes`` episodes; the greedy mean return and episodes."""
    from hrlp.evaluate import evaluate_run
    from hrlp.train import train

    cfg = short_episode_config(f"hrlp/{name}-v0", steps=10**7, seed=seed)
    done = 0
    for stats in train(cfg, tmp_path / name, on_warning=lambda message: None):
        done += int(stats["episodes"])
        if done >= episodes:
            break
    return evaluate_run(tmp_path / name, episodes=eval_episodes).ret.mean, done


def test_smoke_training_and_greedy_evaluation(tmp_path):
    """Two iterations on the bandit: the run trains, saves and evaluates greedily in a few seconds."""
    ret, done = _train_greedy("ParamBandit", 600, 50, tmp_path)
    assert done >= 600 and math.isfinite(ret) and 0.0 <= ret <= ParamBandit.OPTIMAL


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_short_episode_settings_learn_each_task(name, tmp_path):
    """The goal of the benchmark: >= 95% of the optimal greedy return within 20,000 training episodes (seed 0)."""
    ret, done = _train_greedy(name, 20_000, 1000, tmp_path)
    optimal = PARAM_TASKS[name]().optimal_return()
    assert ret >= 0.95 * optimal, (ret, optimal, done)


def test_benchmark_script_runs_and_keeps_its_output(tmp_path):
    out = tmp_path / "r.json"
    args = [sys.executable, str(BENCH), "--seeds", "1", "--episodes", "200", "--eval-episodes", "20", "--tasks",
            "ParamBandit", "--out", str(out)]  # fmt: skip
    run = subprocess.run(args, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "ParamBandit seed 0: greedy return" in run.stdout and "% opt" in run.stdout
    assert json.loads(out.read_text())["tasks"]["ParamBandit"]["optimal"] == 0.75
    again = subprocess.run(args, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert again.returncode != 0 and "--overwrite" in again.stderr
