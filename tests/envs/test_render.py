"""Off-screen rendering (EGL or OSMesa) and the `hrlp render` command."""

import imageio.v2 as imageio
import numpy as np
from typer.testing import CliRunner

from hrlp.arm import make
from hrlp.cli import app


def test_render_returns_an_rgb_frame_that_changes_with_the_state():
    env = make("Gripper", render_mode="rgb_array", width=96, height=64)
    env.reset(seed=0)
    a = env.render()
    assert a.shape == (64, 96, 3) and a.dtype == np.uint8 and a.std() > 5
    for _ in range(30):
        env.step(np.ones(9))
    assert np.abs(env.render().astype(int) - a).sum() > 0
    assert make("Gripper").render() is None  # no render_mode, no frame
    env.close()


def test_render_command_writes_a_playable_video(tmp_path):
    out = tmp_path / "sub" / "g.mp4"
    result = CliRunner().invoke(
        app, ["render", "ReachAndGrip1", "--out", str(out), "--steps", "12", "--width", "64", "--height", "48"]
    )
    assert result.exit_code == 0, result.output
    frames = [f for f in imageio.get_reader(out)]
    assert len(frames) == 13 and frames[0].shape == (48, 64, 3)
    assert [p.name for p in out.parent.iterdir()] == ["g.mp4"]  # no temporary file left behind


def test_render_command_rejects_bad_input_before_rendering(tmp_path):
    runner = CliRunner()
    r = runner.invoke(app, ["render", "NoSuchTask", "--out", str(tmp_path / "a.mp4")])
    assert r.exit_code == 2 and "unknown task" in r.output
    r = runner.invoke(app, ["render", "Gripper", "--out", str(tmp_path / "a.avi")])
    assert r.exit_code == 2 and ".mp4 or .gif" in r.output
    assert not any(tmp_path.iterdir())


def test_rollout_frames_are_an_ordinary_rollouts_frames_across_an_episode_end():
    from hrlp.video import rollout_frames

    frames, fps, name = rollout_frames("Gripper", steps=14, seed=3, width=48, height=32, episode_steps=6)
    frames = list(frames)
    assert len(frames) == 15 and "random actions" in name and fps > 0
    # the same rollout by hand: seed 3, the same random torques, a frame after every step, a reset after 6 steps
    env = make("Gripper", render_mode="rgb_array", width=48, height=32, episode_steps=6)
    rng = np.random.default_rng(3)
    env.reset(seed=3)
    expected = [env.render()]
    for _ in range(14):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, size=(1, 9))[0])
        expected.append(env.render())
        if terminated or truncated:
            env.reset()
    env.close()
    assert all(np.array_equal(a, b) for a, b in zip(frames, expected, strict=True))
    assert not np.array_equal(frames[6], frames[7])  # the episode ended at step 6: frame 7 is a new episode's
