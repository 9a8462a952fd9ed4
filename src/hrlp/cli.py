"""The ``hrlp`` command."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

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
    steps: Annotated[int, typer.Option(help="Low-level control steps to record (default: one episode).")] = 0,
    seed: Annotated[int, typer.Option(help="Seed of the start state and the actions.")] = 0,
    width: Annotated[int, typer.Option(help="Frame width in pixels.")] = 480,
    height: Annotated[int, typer.Option(help="Frame height in pixels.")] = 360,
    camera: Annotated[str, typer.Option(help="Model camera: front or side.")] = "front",
) -> None:
    """Record a rollout to a video file, off-screen: a task with random actions, or a trained run's policy.

    A Manager's video labels every frame with the active skill.
    """
    from hrlp.checkpoint import CheckpointError
    from hrlp.video import check_video_path, rollout_frames, write_video

    try:
        if steps < 0 or width < 16 or height < 16:
            raise ValueError("--steps must be >= 0 and --width/--height >= 16")
        if camera not in ("front", "side"):
            raise ValueError(f"--camera must be 'front' or 'side', got {camera!r}")
        check_video_path(out)
        frames, fps, name = rollout_frames(source, steps, seed, err_console, width=width, height=height, camera=camera)
    except (ValueError, CheckpointError) as e:
        raise _fail(str(e)) from None
    count = write_video(out, frames, fps=fps)
    console.print(f"wrote {out} ({count} frames, {count / fps:.1f} s) of {name}")


@app.command()
def demo(
    out_dir: Annotated[Path, typer.Option(help="Run directory (run again to continue it).")] = Path("runs/demo"),
    steps: Annotated[int, typer.Option(help="Low-level environment steps of Manager training.")] = 1_000_000,
    seed: Annotated[int, typer.Option(help="Seed of the run.")] = 0,
    episodes: Annotated[int, typer.Option(help="Evaluation episodes for the success rate.")] = 100,
    video_steps: Annotated[int, typer.Option(help="Low-level steps in the video (default: one episode).")] = 0,
    workers: Annotated[int, typer.Option(help="Sampling processes (1: sample in this process).")] = 2,
) -> None:
    """Train a Manager on reach-and-grip with the shipped skills; print its success rate, write a video and a plot."""
    from hrlp.checkpoint import CheckpointError
    from hrlp.experiments.demo import run_demo

    try:
        if steps <= 0 or episodes <= 0 or video_steps < 0 or workers < 1:
            raise ValueError("--steps, --episodes and --workers must be positive, --video-steps at least 0")
        res = run_demo(out_dir, steps, seed, episodes, video_steps, err_console, workers)
    except (ValueError, CheckpointError) as e:
        raise _fail(str(e)) from None
    console.print(f"success rate: {res.success}")
    console.print(f"video: {res.video}\nlearning curve: {res.plot}\nrun: {res.run_dir} (hrlp eval / hrlp render work on it)")


@app.command()
def presets() -> None:
    """List the paper's experiments as presets (runs, seeds, default budget)."""
    from hrlp.experiments.presets import PRESETS

    table = Table(title="presets (hrlp reproduce PRESET)")
    for col in ("preset", "paper", "runs", "seeds", "budget", "metric", "description"):
        table.add_column(col)
    for p in PRESETS.values():
        table.add_row(p.name, p.source, str(len(p.runs)), str(len(p.seeds)), f"{p.budget:,}", p.metric, p.description)
    console.print(table)


@app.command()
def reproduce(
    preset: Annotated[str, typer.Argument(help="A preset (see 'hrlp presets'), e.g. reach-and-grip-2.")],
    seeds: Annotated[int | None, typer.Option(help="Seeds 0..N-1 per run (default: the preset's).")] = None,
    budget: Annotated[int | None, typer.Option(help="Environment steps per run (default: the preset's).")] = None,
    out: Annotated[Path, typer.Option(help="Root of the runs (OUT/PRESET/RUN/sSEED).")] = Path("runs/reproduce"),
    backend: Annotated[str, typer.Option(help="process (a local process pool) or ray (a Ray cluster).")] = "process",
    workers: Annotated[int, typer.Option(help="Runs at once on the process pool.")] = 2,
    address: Annotated[str | None, typer.Option(help="Ray cluster address (default: start a local Ray).")] = None,
    reuse: Annotated[
        bool, typer.Option(help="Copy a run whose config matches a finished run of another preset under OUT.")
    ] = True,
) -> None:
    """Run a preset's runs x seeds grid; finished runs are skipped, interrupted ones resume, runs another preset
    already finished with the same config are copied."""
    from hrlp.checkpoint import CheckpointError
    from hrlp.experiments.runner import reproduce as run_grid

    def report(r: dict) -> None:
        s = r.get("success")
        what = f"success {s['mean']:.2f} [{s['low']:.2f}, {s['high']:.2f}]" if s else f"return {r['return']['mean']:.1f}"
        note = (
            " (already done)"
            if r.get("skipped")
            else f" (copied from {r['copied_from']})"
            if r.get("copied_from")
            else f" in {r['wall_s'] / 60:.1f} min"
        )
        err_console.print(f"{r['preset']} / {r['run']} / seed {r['seed']}: {what}, {r['env_steps']:,} steps{note}")

    try:
        results = run_grid(preset, out, seeds, budget, backend, workers, address, on_result=report, reuse=reuse)
    except (ValueError, CheckpointError, ImportError) as e:
        raise _fail(str(e)) from None
    console.print(f"{len(results)} runs of {preset} in {out / preset}; tables: hrlp tables --root {out}")


@app.command()
def tables(
    root: Annotated[Path, typer.Option(help="Root of the runs written by 'hrlp reproduce'.")] = Path("runs/reproduce"),
    out: Annotated[Path, typer.Option(help="Directory for the markdown tables and PNG plots.")] = Path("docs/results"),
    threshold: Annotated[
        list[float] | None,
        typer.Option(help="Training success rate for the sample-efficiency table; repeatable (default 0.05, 0.1, 0.2)."),
    ] = None,
    window: Annotated[int, typer.Option(help="Iterations in the moving average of the training success rate.")] = 3,
) -> None:
    """Rebuild the paper's tables (ours beside the paper's numbers), learning curves, sweep scatter plots and
    sample-efficiency tables from run directories."""
    from hrlp.experiments.tables import DEFAULT_THRESHOLDS, build_tables

    try:
        files = build_tables(root, out, thresholds=tuple(threshold) if threshold else DEFAULT_THRESHOLDS, window=window)
    except ValueError as e:
        raise _fail(str(e)) from None
    for f in files:
        console.print(f"wrote {f}")


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


_STEPS = Annotated[int | None, typer.Option(help="Low-level environment steps in total (default 1,000,000).")]
_SEED = Annotated[int, typer.Option(help="Seed of environments, network and action noise.")]
_RUN_DIR = Annotated[Path | None, typer.Option(help="Where logs and checkpoints go (default runs/TASK-sSEED).")]
_NUM_ENVS = Annotated[int, typer.Option(help="Environments stepped together with batched inference.")]
_MAX_KL = Annotated[float, typer.Option(help="TRPO's trust region, the maximal mean KL per step.")]
_GAMMA = Annotated[float, typer.Option(help="Discount factor (per low-level step).")]
_EPISODE_STEPS = Annotated[int | None, typer.Option(help="Episode length of hrlp tasks (default 300).")]
_TASK_ARG = Annotated[
    list[str] | None,
    typer.Option("--task-arg", help="A task argument NAME=VALUE, repeatable, e.g. --task-arg c1=-10 --task-arg tr=0.06."),
]
_WORKERS = Annotated[int, typer.Option(help="Processes sampling at the same time (e.g. one per core); 1: in this process.")]
_INIT_LOG_STD = Annotated[float, typer.Option(help="Initial log std of the Gaussian action noise.")]
_VALUE_ITERS = Annotated[int, typer.Option(help="L-BFGS iterations of the baseline fit per iteration (modular_rl: 25).")]
_VALUE_FRACTION = Annotated[
    float, typer.Option(help="Share of the batch's time steps the baseline is fitted on (1: every one, the default).")
]
_FISHER_FRACTION = Annotated[
    float, typer.Option(help="Share of the batch the Fisher-vector products use (TRPO paper: 0.1; 1: exact, the default).")
]
_RESUME = Annotated[
    bool, typer.Option(help="Continue the run in --run-dir from its last checkpoint with its own settings (--steps may grow).")
]


@app.command()
def train(
    task: Annotated[str, typer.Argument(help="hrlp task (see 'hrlp tasks') or a Gymnasium id.")],
    steps: _STEPS = None,
    seed: _SEED = 0,
    run_dir: _RUN_DIR = None,
    batch_steps: Annotated[int, typer.Option(help="Environment steps per TRPO iteration (paper: 50,000).")] = 50_000,
    num_envs: _NUM_ENVS = 16,
    max_kl: _MAX_KL = 0.01,
    gamma: _GAMMA = 0.99,
    episode_steps: _EPISODE_STEPS = None,
    task_arg: _TASK_ARG = None,
    init_log_std: _INIT_LOG_STD = 0.0,
    fisher_fraction: _FISHER_FRACTION = 1.0,
    value_iters: _VALUE_ITERS = 25,
    value_fraction: _VALUE_FRACTION = 1.0,
    workers: _WORKERS = 1,
    resume: _RESUME = False,
) -> None:
    """Train a flat TRPO policy (Box, Discrete or parameterised Tuple actions); logs and checkpoints every iteration."""
    settings = dict(task=task, steps=steps or 1_000_000, seed=seed, batch_steps=batch_steps, num_envs=num_envs,
                    episode_steps=episode_steps, init_log_std=init_log_std, workers=workers,
                    value_iters=value_iters, value_fraction=value_fraction)  # fmt: skip
    _train(settings, task_arg, dict(max_kl=max_kl, gamma=gamma, fisher_fraction=fisher_fraction), run_dir, resume, steps)


@app.command("train-manager")
def train_manager(
    task: Annotated[str, typer.Argument(help="hrlp task the Manager solves, e.g. ReachAndGrip2.")],
    skills: Annotated[
        str, typer.Option(help="Comma-separated skill names (see 'hrlp skills list'), e.g. gripper,reacher.")
    ] = "",
    micro: Annotated[bool, typer.Option(help="Add the micro-action: direct torque control.")] = False,
    micro_duration: Annotated[int, typer.Option(help="Low-level steps a micro-action lasts.")] = 1,
    micro_penalty: Annotated[float, typer.Option(help="Penalty per use of the micro-action.")] = 0.0,
    micro_max_torque: Annotated[float, typer.Option(help="Torque bound of the micro-action, in (0, 1].")] = 1.0,
    k: Annotated[int | None, typer.Option(help="Low-level steps per skill call (default: each skill's own k).")] = None,
    library: Annotated[Path | None, typer.Option(help="Skill library searched first.")] = None,
    steps: _STEPS = None,
    seed: _SEED = 0,
    run_dir: _RUN_DIR = None,
    batch_steps: Annotated[int, typer.Option(help="Manager decisions per TRPO iteration (paper: 5,000).")] = 5_000,
    num_envs: _NUM_ENVS = 16,
    max_kl: _MAX_KL = 0.01,
    gamma: _GAMMA = 0.99,
    episode_steps: _EPISODE_STEPS = None,
    task_arg: _TASK_ARG = None,
    init_log_std: _INIT_LOG_STD = 0.0,
    fisher_fraction: _FISHER_FRACTION = 1.0,
    value_iters: _VALUE_ITERS = 25,
    value_fraction: _VALUE_FRACTION = 1.0,
    workers: _WORKERS = 1,
    resume: _RESUME = False,
) -> None:
    """Train a Manager over frozen skills with hierarchical TRPO (Lemma 1's KL); logs and checkpoints every iteration."""
    from hrlp.skills.macro_env import MacroSpec, MicroAction

    try:
        names = tuple(s.strip() for s in skills.split(",") if s.strip())
        m = MicroAction(micro_duration, micro_penalty, micro_max_torque) if micro else None
        spec = MacroSpec(names, k, m, None if library is None else str(library))
    except ValueError as e:
        raise _fail(str(e)) from None
    settings = dict(task=task, steps=steps or 1_000_000, seed=seed, batch_steps=batch_steps, num_envs=num_envs,
                    episode_steps=episode_steps, init_log_std=init_log_std, workers=workers, macro=spec,
                    value_iters=value_iters, value_fraction=value_fraction)  # fmt: skip
    _train(settings, task_arg, dict(max_kl=max_kl, gamma=gamma, fisher_fraction=fisher_fraction), run_dir, resume, steps)


def parse_task_args(items: list[str] | None) -> dict[str, Any]:
    """``["c1=-10", "tr=0.06"]`` -> ``{"c1": -10, "tr": 0.06}`` (values read as JSON, else kept as strings)."""
    import json

    out: dict[str, Any] = {}
    for item in items or []:
        name, sep, raw = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--task-arg must look like NAME=VALUE, got {item!r}")
        try:
            out[name.strip()] = json.loads(raw)
        except json.JSONDecodeError:
            out[name.strip()] = raw
    return out


def _train(settings: dict[str, Any], task_arg: list[str] | None, trpo_settings: dict[str, float], run_dir: Path | None,
           resume: bool, steps: int | None) -> Path:  # fmt: skip
    """Shared body of ``train`` and ``train-manager``: build and check the config, then train with a progress bar."""
    import dataclasses

    from hrlp.algos.trpo import TRPOConfig
    from hrlp.algos.value import ValueFitConfig
    from hrlp.checkpoint import CheckpointError
    from hrlp.train import TrainConfig, env_factory, train_with_progress

    task = settings["task"]
    out = run_dir or Path("runs") / f"{task.replace('/', '_')}-s{settings['seed']}"
    try:
        if resume:
            from hrlp.checkpoint import load_checkpoint

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
            trpo = TRPOConfig(**trpo_settings)
            value = ValueFitConfig(max_iter=settings.pop("value_iters"), fraction=settings.pop("value_fraction"))
            cfg = TrainConfig(**settings, trpo=trpo, value=value, task_kwargs=parse_task_args(task_arg))
        env_factory(cfg.task, cfg.episode_steps, cfg.macro, cfg.trpo.gamma, **cfg.task_kwargs)
    except (ValueError, CheckpointError) as e:
        raise _fail(str(e)) from None
    kind = "train-manager" if cfg.macro is not None else "train"
    try:
        train_with_progress(cfg, out, resume, err_console, f"{kind} {cfg.task}")
    except (ValueError, CheckpointError) as e:
        raise _fail(str(e)) from None
    console.print(f"run written to {out} (checkpoint: {out / 'checkpoint'}, logs: progress.csv, tb/)")
    return out


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
    if ev.macro_usage is not None:
        console.print("decisions per macro-action: " + ", ".join(f"{k} {v:.0%}" for k, v in ev.macro_usage.items()))


skills_app = typer.Typer(help="The skill library: frozen, parameterised skills for the Manager.", no_args_is_help=True)
app.add_typer(skills_app, name="skills")
_LIBRARY = Annotated[
    Path | None, typer.Option("--library", help="Library directory (default $HRLP_SKILLS or ~/.hrlp/skills).")
]


@skills_app.command("list")
def skills_list(library: _LIBRARY = None) -> None:
    """List the skills in the library and those shipped with hrlp (a library skill hides a shipped one of its name)."""
    from hrlp.skills import SkillLibrary, shipped_library_root

    lib, shipped = SkillLibrary(library), SkillLibrary(shipped_library_root())
    table = Table(title=f"skills in {lib.root} and shipped with hrlp")
    for col in ("name", "task", "params", "k", "trained steps", "sha256", "from"):
        table.add_column(col)
    seen: set[str] = set()
    for source, where in ((lib, "library"), (shipped, "shipped")):
        for name in source.names():
            if name in seen:
                continue
            seen.add(name)
            m = source.manifest(name)
            table.add_row(name, m["task"], str(m["param"]["dim"]), str(m["k"]), f"{m['trained']['env_steps']:,}",
                          m["sha256"][:12], where)  # fmt: skip
    console.print(table)


@skills_app.command("show")
def skills_show(name: Annotated[str, typer.Argument(help="Skill name.")], library: _LIBRARY = None) -> None:
    """Show a skill's manifest: task, parameters and their meaning, default k, training config, content hash."""
    import json

    from hrlp.skills import SkillLibrary, shipped_library_root

    lib, shipped = SkillLibrary(library), SkillLibrary(shipped_library_root())
    try:
        m = (lib if name in lib.names() or name not in shipped.names() else shipped).manifest(name)
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
