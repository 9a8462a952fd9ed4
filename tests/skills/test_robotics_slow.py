"""A Manager on a real Gymnasium-Robotics environment: PointMaze_Open-v3 (MuJoCo, a Dict observation), with its own
sparse reward (1 while within 0.45 m of the goal) and success test (``info['success']`` at the episode's last step:
the task goes on for 300 steps whatever happens, so the ball must reach the goal and stay there).

The Manager commands three scripted skills of ``tests/robotics_skills.py``: ``push`` (a constant force for 20 steps)
and ``brake`` (stop where it is), neither of which goes to the goal, and ``goto_point`` (PD control to any point of
the maze's floor, its parameters absolute). It must learn to choose ``goto_point`` and to aim it at the goal it
observes: the untrained Manager succeeds in about 6% of episodes. Measured on one core: about two minutes of training,
then greedy success 1.0 over 100 episodes (seed 0)."""

from __future__ import annotations

import pytest

from hrlp.config import MacroSpec, TrainConfig, TRPOConfig, ValueFitConfig
from hrlp.evaluate import evaluate_run
from hrlp.train import train_with_progress

pytestmark = pytest.mark.slow

pytest.importorskip("gymnasium_robotics")

#: gymnasium_robotics registers its ids when imported, which MODULE:ID asks hrlp to do.
TASK = "gymnasium_robotics:PointMaze_Open-v3"
SKILLS = ("robotics_skills:push", "robotics_skills:brake", "robotics_skills:goto_point")


def test_a_manager_learns_to_aim_a_goto_skill_at_the_goal_of_a_gymnasium_robotics_maze(tmp_path):
    # Episodes of about 7 decisions: hrlp's settings for short episodes (small batches, larger steps, the paper's
    # full-batch Fisher products and baseline fit).
    trpo, value = TRPOConfig(max_kl=0.05, fisher_fraction=1.0), ValueFitConfig(max_iter=25, fraction=1.0)
    cfg = TrainConfig(task=TASK, steps=1_500_000, batch_steps=500, num_envs=16, seed=0, macro=MacroSpec(SKILLS),
                      trpo=trpo, value=value)  # fmt: skip
    train_with_progress(cfg, tmp_path / "manager")
    ev = evaluate_run(tmp_path / "manager", episodes=100)
    assert ev.success is not None and ev.success.mean >= 0.9, ev
    assert ev.macro_usage is not None and ev.macro_usage["goto_point"] >= 0.9, ev
