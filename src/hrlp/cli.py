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
err_console = Console(stderr=True, soft_wrap=True)  # one-line errors, never wrapped


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
    source: Annotated[str, typer.Argument(help="A task (random policy), e.g. Gripper, or a run directory (trained policy).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Video file to write (.mp4 or .gif).")] = Path("rollout.mp4"),
    steps: Annotated[int, typer.Option(help="Control steps to record (default: one episode).")] = 0,
    seed: Annotated[int, typer.Option(help="Seed of the start state and the actions.")] = 0,
    width: Annotated[int, typer.Option(help="Frame width in pixels.")] = 480,
    height: Annotated[int, typer.Option(help="Frame height in pixels.")] = 360,
    camera: Annotated[str, typer.Option(help="Model camera: front or side.")] = "front",
) -> None:
    """Record a rollout to a video file, off-screen: a task with random actions, or a trained run's policy."""
    import numpy as np
    import torch
    from rich.progress import track

    from hrlp.envs import TASKS, make
    from hrlp.video import check_video_path, write_video

    rng = np.random.default_rng(seed)
    act = lambda obs: rng.uniform(-1.0, 1.0, size=9)  # noqa: E731
    try:
        if Path(source).is_dir():
            from hrlp.train import TrainConfig, load_policy

            policy, normalizer, meta = load_policy(Path(source) / "checkpoint")
            cfg = TrainConfig.from_json(meta["config"])
            source = cfg.task
            gen = torch.Generator().manual_seed(seed)
            act = lambda obs: policy.act_numpy(normalizer(obs, update=False).astype(np.float32), gen, True)  # noqa: E731
        name = source.removeprefix("hrlp/").removesuffix("-v0")
        if name not in TASKS:
            raise ValueError(f"unknown task {source!r}; run 'hrlp tasks' to list them (only hrlp tasks render)")
        if steps < 0 or width < 16 or height < 16:
            raise ValueError("--steps must be >= 0 and --width/--height >= 16")
        if camera not in ("front", "side"):
            raise ValueError(f"--camera must be 'front' or 'side', got {camera!r}")
        check_video_path(out)
    except ValueError as e:
        raise _fail(str(e)) from None
    env = make(name, render_mode="rgb_array", width=width, height=height, camera=camera)
    n = steps or env.episode_steps
    obs, _ = env.reset(seed=seed)

    def frames():
        nonlocal obs
        yield env.render()
        for _ in track(range(n), description=f"rendering {name}", console=err_console, transient=True):
            obs, _, terminated, truncated, _ = env.step(np.clip(act(obs), -1.0, 1.0))
            yield env.render()
            if terminated or truncated:
                obs, _ = env.reset()

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


@app.command()
def train(
    task: Annotated[str, typer.Argument(help="hrlp task (see 'hrlp tasks') or a Gymnasium id with a Box action space.")],
    steps: Annotated[int | None, typer.Option(help="Environment steps in total (default 1,000,000).")] = None,
    seed: Annotated[int, typer.Option(help="Seed of environments, network and action noise.")] = 0,
    run_dir: Annotated[Path | None, typer.Option(help="Where logs and checkpoints go (default runs/TASK-sSEED).")] = None,
    batch_steps: Annotated[int, typer.Option(help="Environment steps per TRPO iteration (paper: 50,000).")] = 50_000,
    num_envs: Annotated[int, typer.Option(help="Environments stepped together with batched inference.")] = 16,
    max_kl: Annotated[float, typer.Option(help="TRPO's trust region, the maximal mean KL per step.")] = 0.01,
    gamma: Annotated[float, typer.Option(help="Discount factor.")] = 0.99,
    episode_steps: Annotated[int | None, typer.Option(help="Episode length of hrlp tasks (default 300).")] = None,
    resume: Annotated[
        bool,
        typer.Option(help="Continue the run in --run-dir from its last checkpoint, with its own settings (--steps may grow)."),
    ] = False,
) -> None:
    """Train a flat TRPO policy; logs to progress.csv and TensorBoard, checkpoints after every iteration."""
    import dataclasses
    import math

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from hrlp.algos.trpo import TRPOConfig
    from hrlp.train import TrainConfig, env_factory
    from hrlp.train import train as run_training

    out = run_dir or Path("runs") / f"{task.replace('/', '_')}-s{seed}"
    try:
        if resume:
            from hrlp.checkpoint import CheckpointError, load_checkpoint

            if not (out / "checkpoint").exists():
                raise ValueError(f"--resume: {out} has no checkpoint to continue from")
            try:
                saved = TrainConfig.from_json(load_checkpoint(out / "checkpoint")[1]["config"])
            except CheckpointError as e:
                raise ValueError(str(e)) from None
            cfg = dataclasses.replace(saved, steps=steps or saved.steps)
        else:
            if (out / "checkpoint").exists():
                raise ValueError(f"{out} already holds a run; pass --resume to continue it or choose another --run-dir")
            cfg = TrainConfig(task=task, steps=steps or 1_000_000, seed=seed, batch_steps=batch_steps, num_envs=num_envs,
                              episode_steps=episode_steps,
                              trpo=dataclasses.replace(TRPOConfig(), max_kl=max_kl, gamma=gamma))  # fmt: skip
        env_factory(cfg.task, cfg.episode_steps)
    except ValueError as e:
        raise _fail(str(e)) from None
    columns = [TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
               TextColumn("{task.fields[status]}")]  # fmt: skip
    with Progress(*columns, console=err_console) as progress:
        bar = progress.add_task(f"train {cfg.task}", total=cfg.iterations * cfg.steps_per_env * cfg.num_envs, status="")
        for st in run_training(cfg, out, resume=resume):
            status = f"return {st['return_mean']:.1f}"
            if not math.isnan(st["success_rate"]):
                status += f"  success {st['success_rate']:.2f}"
            status += f"  kl {st['trpo/kl']:.4f}  {st['time/steps_per_s']:.0f} steps/s"
            progress.update(bar, completed=st["env_steps"], status=status)
    console.print(f"run written to {out} (checkpoint: {out / 'checkpoint'}, logs: progress.csv, tb/)")


@app.command("eval")
def eval_(
    run_dir: Annotated[Path, typer.Argument(help="A run directory written by 'hrlp train'.")],
    episodes: Annotated[int, typer.Option(help="Evaluation episodes.")] = 20,
    seed: Annotated[int, typer.Option(help="Seed of the evaluation episodes.")] = 10_000,
    stochastic: Annotated[bool, typer.Option(help="Sample actions instead of taking the mean.")] = False,
) -> None:
    """Mean return and success rate of a trained policy, with 95% confidence intervals."""
    from hrlp.checkpoint import CheckpointError
    from hrlp.evaluate import evaluate_run

    try:
        ev = evaluate_run(run_dir, episodes=episodes, seed=seed, deterministic=not stochastic)
    except (ValueError, CheckpointError, FileNotFoundError) as e:
        raise _fail(str(e)) from None
    console.print(f"episodes: {ev.episodes}")
    console.print(f"return (mean, 95% CI): {ev.ret}")
    if ev.success is not None:
        console.print(f"success rate (95% Wilson CI): {ev.success}")
    if ev.target_dist_sum is not None:
        console.print(f"TargetDistSum (mean, 95% CI): {ev.target_dist_sum}")


skills_app = typer.Typer(help="The skill library: frozen, parameterised skills for the Manager.", no_args_is_help=True)
app.add_typer(skills_app, name="skills")
_LIBRARY = Annotated[
    Path | None, typer.Option("--library", help="Library directory (default $HRLP_SKILLS or ~/.hrlp/skills).")
]


@skills_app.command("list")
def skills_list(library: _LIBRARY = None) -> None:
    """List the skills in the library."""
    from hrlp.skills import SkillLibrary

    lib = SkillLibrary(library)
    table = Table(title=f"skills in {lib.root}")
    for col in ("name", "task", "params", "k", "trained steps", "sha256"):
        table.add_column(col)
    for name in lib.names():
        m = lib.manifest(name)
        table.add_row(name, m["task"], str(m["param"]["dim"]), str(m["k"]), f"{m['trained']['env_steps']:,}", m["sha256"][:12])
    console.print(table)


@skills_app.command("show")
def skills_show(name: Annotated[str, typer.Argument(help="Skill name.")], library: _LIBRARY = None) -> None:
    """Show a skill's manifest: task, parameters and their meaning, default k, training config, content hash."""
    import json

    from hrlp.skills import SkillLibrary

    try:
        m = SkillLibrary(library).manifest(name)
    except ValueError as e:
        raise _fail(str(e)) from None
    console.print_json(json.dumps(m))


@skills_app.command("add")
def skills_add(
    run_dir: Annotated[Path, typer.Argument(help="A finished run of 'hrlp train' on a skill task.")],
    name: Annotated[str, typer.Option(help="Name of the new skill.")],
    k: Annotated[int, typer.Option(help="Default duration in low-level steps (the paper: 8, 10, 15).")] = 15,
    overwrite: Annotated[bool, typer.Option(help="Replace a skill of the same name.")] = False,
    library: _LIBRARY = None,
) -> None:
    """Turn a finished training run into a named, frozen skill in the library."""
    from hrlp.checkpoint import CheckpointError
    from hrlp.skills import SkillLibrary

    try:
        path = SkillLibrary(library).add(run_dir, name, k=k, overwrite=overwrite)
    except (ValueError, CheckpointError) as e:
        raise _fail(str(e)) from None
    console.print(f"skill {name!r} written to {path}")


def main() -> None:
    """Entry point for ``python -m hrlp``."""
    app()
