"""Learning-curve plots and the demo (real training, video and plot at a tiny budget)."""

import pytest
from typer.testing import CliRunner

from hrlp.cli import app
from hrlp.plots import LEGEND_INSIDE_MAX, learning_curves_figure, plot_learning_curves, read_progress
from hrlp.train import TrainConfig, train


def test_learning_curves_of_several_seeds(tmp_path):
    runs = []
    for seed in (0, 1):
        list(train(TrainConfig(task="Reacher", steps=200, batch_steps=100, num_envs=2, episode_steps=20, seed=seed),
                   tmp_path / f"s{seed}"))  # fmt: skip
        runs.append(tmp_path / f"s{seed}")
    log = read_progress(runs[0])
    assert list(log["env_steps"]) == [100, 200]
    out = plot_learning_curves({"Reacher": runs}, tmp_path / "plots" / "curve.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="must end in"):
        plot_learning_curves({"Reacher": runs}, tmp_path / "curve.txt")
    with pytest.raises(ValueError, match=r"no progress\.csv"):
        read_progress(tmp_path / "nowhere")


def test_many_learning_curves_get_one_legend_below_the_axes(tmp_path):
    import matplotlib.pyplot as plt

    run = tmp_path / "s0"
    list(train(TrainConfig(task="Reacher", steps=200, batch_steps=100, num_envs=2, episode_steps=20), run))
    few = learning_curves_figure({f"cell {i}": [run] for i in range(LEGEND_INSIDE_MAX)})
    assert all(ax.get_legend() is not None for ax in few.axes) and not few.legends
    many = learning_curves_figure({f"a long run label, cell {i}": [run] for i in range(16)})
    assert all(ax.get_legend() is None for ax in many.axes) and len(many.legends) == 1
    renderer = many.canvas.get_renderer()
    legend = many.legends[0].get_window_extent(renderer)
    for ax in many.axes:  # the legend lies wholly below every axes (their tick labels included), so it hides no curve
        assert legend.y1 < ax.get_tightbbox(renderer).y0
    assert legend.y0 >= 0  # and inside the figure, not cut off at its bottom edge
    assert len(many.legends[0].get_texts()) == 16
    assert len({tuple(line.get_color()) for line in many.axes[0].get_lines()}) == 16  # 16 colours for 16 lines
    plt.close(few)
    plt.close(many)


def test_demo_trains_evaluates_and_writes_video_and_plot(tmp_path):
    out = tmp_path / "demo"
    r = CliRunner().invoke(app, ["demo", "--out-dir", str(out), "--steps", "100", "--episodes", "2", "--video-steps", "30"])
    assert r.exit_code == 0, r.output
    assert "success rate:" in r.output
    assert (out / "demo.mp4").stat().st_size > 1_000 and (out / "learning_curve.png").exists()
    assert read_progress(out)["env_steps"][-1] >= 100
    # Running it again continues the same run instead of failing or starting over.
    r = CliRunner().invoke(app, ["demo", "--out-dir", str(out), "--steps", "100", "--episodes", "1", "--video-steps", "5"])
    assert r.exit_code == 0, r.output
    assert len(read_progress(out)["env_steps"]) == 1


def test_demo_cli_defaults_are_the_demos_own():
    """The CLI keeps its defaults literal (so that ``hrlp --help`` need not import torch); they must match the demo's."""
    import inspect
    import typing

    from hrlp.cli import demo
    from hrlp.experiments.demo import DEMO_STEPS, FETCH_DEMO_STEPS, demo_config

    params = inspect.signature(demo).parameters
    said = typing.get_type_hints(demo, include_extras=True)["steps"].__metadata__[0].help  # each robot's default budget
    assert f"arm {DEMO_STEPS:,}" in said and f"fetch {FETCH_DEMO_STEPS:,}" in said
    config_defaults = inspect.signature(demo_config).parameters
    assert params["seed"].default == config_defaults["seed"].default
    assert params["workers"].default == config_defaults["workers"].default
