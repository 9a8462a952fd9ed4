"""The ``hrlp`` command."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

app = typer.Typer(
    name="hrlp",
    help="Hierarchical Reinforcement Learning with Parameters: tasks, skills, Managers and the paper's experiments.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)


def _fail(message: str) -> typer.Exit:
    err_console.print(f"[bold red]error:[/] {message}")
    return typer.Exit(code=2)


@app.command()
def tasks() -> None:
    """List the registered tasks (Gymnasium ids) with their observation and action sizes."""
    from hrlp.envs import TASKS

    table = Table(title="hrlp tasks")
    for col in ("id", "obs", "act", "description"):
        table.add_column(col)
    for spec in TASKS.values():
        task = spec.build()
        table.add_row(spec.env_id, str(24 + task.extra_obs_dim), "9", spec.description)
    console.print(table)


@app.command()
def render(
    task: Annotated[str, typer.Argument(help="Task name or id, e.g. Gripper or hrlp/Gripper-v0.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Video file to write (.mp4 or .gif).")] = Path("rollout.mp4"),
    steps: Annotated[int, typer.Option(help="Control steps to record (default: one episode).")] = 0,
    seed: Annotated[int, typer.Option(help="Seed of the start state and the random actions.")] = 0,
    width: Annotated[int, typer.Option(help="Frame width in pixels.")] = 480,
    height: Annotated[int, typer.Option(help="Frame height in pixels.")] = 360,
    camera: Annotated[str, typer.Option(help="Model camera: front or side.")] = "front",
) -> None:
    """Record a rollout of a task with a random policy to a video file, off-screen."""
    import numpy as np
    from rich.progress import track

    from hrlp.envs import TASKS, make
    from hrlp.video import check_video_path, write_video

    name = task.removeprefix("hrlp/").removesuffix("-v0")
    try:
        if name not in TASKS:
            raise ValueError(f"unknown task {task!r}; run 'hrlp tasks' to list them")
        if steps < 0 or width < 16 or height < 16:
            raise ValueError("--steps must be >= 0 and --width/--height >= 16")
        if camera not in ("front", "side"):
            raise ValueError(f"--camera must be 'front' or 'side', got {camera!r}")
        check_video_path(out)
    except ValueError as e:
        raise _fail(str(e)) from None
    env = make(name, render_mode="rgb_array", width=width, height=height, camera=camera)
    n = steps or env.episode_steps
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)

    def frames():
        yield env.render()
        for _ in track(range(n), description=f"rendering {name}", console=err_console, transient=True):
            _, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, size=9))
            yield env.render()
            if terminated or truncated:
                env.reset()

    count = write_video(out, frames(), fps=env.metadata["render_fps"])
    env.close()
    console.print(f"wrote {out} ({count} frames, {count / env.metadata['render_fps']:.1f} s)")


@app.command()
def theory(
    mdps: Annotated[int, typer.Option(help="Random MDPs to search (each with several policy pairs).")] = 200,
    seed: Annotated[int, typer.Option(help="Seed of the search.")] = 0,
    out: Annotated[Path, typer.Option(help="Directory for counterexample files.")] = Path("theory_counterexamples"),
) -> None:
    """Check Lemma 1, Theorem 1, Lemma 2 and Corollary 1 numerically on random finite MDPs."""
    from hrlp.theory import run_theory

    if mdps <= 0:
        raise _fail(f"--mdps must be a positive integer, got {mdps}")
    run_theory(mdps=mdps, seed=seed, out_dir=out, console=console)


def main() -> None:
    """Entry point for ``python -m hrlp``."""
    app()
