"""reach-and-move beyond TargetDistSum: closest approach, lift, and TargetDistSum against an untouched capsule."""

import math

import numpy as np
import pytest

from hrlp.arm import make
from hrlp.arm.physics import CAPSULE_REST_Z
from hrlp.evaluate import evaluate_run
from hrlp.experiments.tables import move_cell
from hrlp.train import TrainConfig, train


@pytest.mark.parametrize("task", ["ReachAndMove", "MoverNoised"])
def test_the_environment_reports_the_closest_approach_and_the_highest_lift(task):
    env = make(task, episode_steps=40)
    env.reset(seed=0)
    p = env.unwrapped.physics
    closest, lift = -p.capsule_to_target(), p.capsule[2] - CAPSULE_REST_Z
    rng = np.random.default_rng(0)
    for _ in range(40):
        _, _, _, _, info = env.step(rng.uniform(-1, 1, 9))
        closest, lift = max(closest, -p.capsule_to_target()), max(lift, p.capsule[2] - CAPSULE_REST_Z)
        assert info["closest_max"] == pytest.approx(closest) and info["lift_max"] == pytest.approx(lift)
    assert "closest_max" not in make("ReachAndGrip1").reset(seed=0)[1]


def test_the_maxima_survive_a_saved_state():
    env, twin = make("ReachAndMove", episode_steps=30), make("ReachAndMove", episode_steps=30)
    env.reset(seed=1)
    for _ in range(10):
        env.step(np.full(9, 0.3))
    twin.set_state(env.get_state())
    a, b = env.step(np.zeros(9))[4], twin.step(np.zeros(9))[4]
    assert (a["closest_max"], a["lift_max"]) == (b["closest_max"], b["lift_max"])


def test_evaluation_reports_lift_closest_approach_and_target_dist_sum_against_an_untouched_capsule(tmp_path):
    run = tmp_path / "m"
    list(train(TrainConfig(task="ReachAndMove", steps=200, batch_steps=200, num_envs=2, episode_steps=50), run))
    ev = evaluate_run(run, episodes=3)
    env = make("ReachAndMove", episode_steps=50)
    obs, _ = env.reset(seed=10_000)
    assert ev.move is not None
    # The capsule at rest, 15 cm under its target: untouched, 50 steps score -50 * 0.15.
    assert ev.move.untouched_target_dist_sum.mean == pytest.approx(-50 * np.linalg.norm(obs[21:24] - obs[24:27]), rel=1e-6)
    assert ev.move.relative_target_dist_sum.mean == pytest.approx(
        ev.target_dist_sum.mean - ev.move.untouched_target_dist_sum.mean
    )
    assert 0 < ev.move.min_target_dist.mean <= 0.16 and 0 <= ev.move.lift_rate.mean <= 1
    assert math.isfinite(ev.move.relative_target_dist_sum.mean)


def test_tables_show_what_a_moving_run_did():
    result = {
        "success": {"mean": 0.25},
        "move": {"lift_rate": {"mean": 0.5}, "min_target_dist": {"mean": 0.0412}, "relative_target_dist_sum": {"mean": 3.25},
                 "untouched_target_dist_sum": {"mean": -44.4}},
    }  # fmt: skip
    assert move_cell([result, result]) == "0.25 / 0.5 / 0.041 m / +3.2 (untouched -44.4)"
    assert move_cell([{"success": {"mean": 0.0}, "move": None}]) == "-"
