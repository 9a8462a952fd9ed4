"""The ``hrlp`` command."""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from typer.core import TyperGroup

from hrlp import bounds
from hrlp import cli_params as check
from hrlp.config import (
    ALGOS,
    OFF_POLICY,
    PAPER_SETTINGS,
    AdvantageConfig,
    PPOConfig,
    SACConfig,
    TrainConfig,
    TRPOConfig,
    ValueFitConfig,
    auto_workers,
    field_docs,
)
from hrlp.stopping import Stopped, as_stop, describing, raise_if_stopping

console = Console()
err_console = Console(stderr=True, soft_wrap=True)  # one-line errors, never wrapped


def _fail(message: str) -> typer.Exit:
    err_console.print(f"[bold red]error:[/] {message}")
    return typer.Exit(code=2)


def _error_exit(message: str, code: int = 2) -> int:
    """Print ``message`` as one line (``error: ...``, whitespace collapsed, never read as markup) on stderr."""
    err_console.print(f"[bold red]error:[/] {escape(' '.join(message.split()))}", highlight=False)
    return code


#: Installable extras for optional packages a command imports.
_EXTRAS = {
    "ray": "pip install 'hrlp[ray]'",
    "sb3_contrib": "pip install 'hrlp[bench]'",
    "tianshou": "pip install 'hrlp[bench]'",
}


def _known_error_line(error: BaseException) -> str | None:
    """The one line for an error a user's input or machine can cause (a bad value, a file, a missing package or
    driver), or None for anything else (a bug in hrlp: its traceback is shown)."""
    import sys

    if isinstance(error, OSError):  # StorageError names its path in its own words
        plain = type(error).__str__ is OSError.__str__ and error.filename and error.strerror
        return f"{error.filename}: {error.strerror}" if plain else str(error)
    if isinstance(error, ValueError):  # CheckpointError, NonFiniteError, every config check
        return str(error)
    if isinstance(error, ImportError):
        hint = _EXTRAS.get((error.name or "").split(".")[0])
        return f"{error}" + (f": {hint}" if hint else "")
    gym_error = sys.modules.get("gymnasium.error")
    if gym_error is not None and isinstance(error, gym_error.Error):
        return str(error)
    if isinstance(error, RuntimeError) and "MUJOCO_GL" in str(error):  # MuJoCo refuses the value at import
        return f"{error}: use egl (a GPU or Mesa's EGL), osmesa (software) or glfw (a display), or leave MUJOCO_GL unset"
    if "mujoco" in sys.modules or "OpenGL" in sys.modules:  # MuJoCo's OpenGL backend failed (e.g. at import)
        from hrlp.video import gl_failure_line

        return gl_failure_line(error)
    return None


def _stopped_exit(stop: Stopped) -> int:
    """Print a stop's one line on stderr; its exit code (128 + the signal)."""
    default = "" if _COMMAND_STARTED else "during start-up; nothing was written"
    err_console.print(escape(" ".join(stop.line(default).split())), highlight=False)
    return stop.exit_code


class _OneLineErrors(TyperGroup):
    """The ``hrlp`` group: every error a user can cause ends the command with one line ``error: ...`` on stderr and
    exit code 2, never a traceback. Parse errors (click's usage errors, :class:`hrlp.cli_params.BoundError`) and the
    known error types of :func:`_known_error_line` raised by any command are turned into that line here, once. A stop
    signal (:class:`hrlp.stopping.Stopped`) ends it with the one line :meth:`~hrlp.stopping.Stopped.line` and exit code
    128 + the signal."""

    def main(self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
             standalone_mode: bool = True, **extra: Any) -> Any:  # fmt: skip
        from typer._click import exceptions as click_errors

        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
            code = rv if isinstance(rv, int) else 0  # typer.Exit(code) comes back as its code here
            raise_if_stopping()  # a stop signal whose exception went astray (hrlp.stopping) still ends in its line
        except click_errors.NoArgsIsHelpError as e:  # the help was printed
            code = e.exit_code
        except click_errors.UsageError as e:
            if isinstance(e, check.BoundError):
                message = e.message
            else:
                where = f"{e.ctx.command_path}: " if e.ctx is not None else ""
                see = f" (see '{e.ctx.command_path} --help')" if e.ctx is not None else ""
                message = f"{where}{e.format_message()}{see}"
            code = _error_exit(message, e.exit_code)
        except typer.Abort:
            code = _error_exit("aborted", 1)
        except Stopped as e:  # SIGINT, SIGTERM or SIGHUP (hrlp.stopping): one line, and 128 + the signal
            code = _stopped_exit(e)
        except Exception as e:
            if (stop := as_stop(e)) is not None:  # an error the stop caused (it came while the stop unwound the command)
                code = _stopped_exit(stop)
            elif (line := _known_error_line(e)) is None:
                raise
            else:
                code = _error_exit(line)
        if not standalone_mode:
            return code
        raise SystemExit(code)


app = typer.Typer(
    name="hrlp",
    help="Hierarchical Reinforcement Learning with Parameters: tasks, skills, Managers and the paper's experiments.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    cls=_OneLineErrors,
)


def _print_version(value: bool) -> None:
    if value:
        from hrlp import __version__

        console.print(f"hrlp {__version__}", highlight=False)
        raise typer.Exit()


@app.callback()
def _hrlp(
    version: Annotated[
        bool, typer.Option("--version", help="Print hrlp's version and exit.", callback=_print_version, is_eager=True)
    ] = False,
) -> None:
    """Hierarchical Reinforcement Learning with Parameters: tasks, skills, Managers and the paper's experiments."""


_COMMAND_STARTED = False
"""Whether a command's body has begun (its options parsed and checked): a stop signal before that has written nothing."""


def _marking_start(command: Callable[..., Any]) -> Callable[..., Any]:
    """``command`` that first records that a command's body has begun (:data:`_COMMAND_STARTED`)."""

    @functools.wraps(command)
    def run(*args: Any, **kwargs: Any) -> Any:
        global _COMMAND_STARTED
        _COMMAND_STARTED = True
        return command(*args, **kwargs)

    return run


def _given(ctx: typer.Context, name: str) -> bool:
    """Whether the option ``name`` was given on the command line (not left at its default)."""
    source = ctx.get_parameter_source(name)  # by the enum's name: Typer carries its own copy of click's ParameterSource
    return source is not None and source.name not in ("DEFAULT", "DEFAULT_MAP")


_STEPS_CHECK = check.count(1, bounds.MAX_STEPS, bounds.WHY_STEPS, "number of environment steps")
_EPISODES_CHECK = check.count(1, bounds.MAX_EPISODES, bounds.WHY_EPISODES)
_VIDEO_STEPS_CHECK = check.count(0, bounds.MAX_VIDEO_STEPS, bounds.WHY_VIDEO_STEPS)
_BATCH_CHECK = check.count(None, bounds.MAX_BATCH_STEPS, bounds.WHY_BATCH_STEPS)  # 0 or less: TrainConfig says so


@app.command()
def tasks() -> None:
    """List the registered tasks (Gymnasium ids) with their observation and action sizes."""
    from hrlp.arm import TASKS

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
    steps: Annotated[
        int, typer.Option(help="Low-level control steps to record (default: one episode).", callback=_VIDEO_STEPS_CHECK)
    ] = 0,
    seed: Annotated[int, typer.Option(help="Seed of the start state and the actions.", callback=check.seed())] = 0,
    width: Annotated[int, typer.Option(help="Frame width in pixels (16 to the model's 640).")] = 480,
    height: Annotated[int, typer.Option(help="Frame height in pixels (16 to the model's 480).")] = 360,
    camera: Annotated[str, typer.Option(help="Model camera: front or side.")] = "front",
) -> None:
    """Record a rollout to a video file, off-screen: a task with random actions, or a trained run's policy.

    A Manager's video labels every frame with the active skill.
    """
    from hrlp.video import check_rendering, check_video_path, rollout_frames, write_video

    if camera not in ("front", "side"):
        raise ValueError(f"--camera must be 'front' or 'side', got {camera!r}")
    _check_render_source(source)
    check_video_path(out)
    check_rendering(width, height)  # a missing OpenGL driver or an oversized frame fails now, in one line
    frames, fps, name = rollout_frames(source, steps, seed, err_console, width=width, height=height, camera=camera)
    count = write_video(out, frames, fps=fps)
    console.print(f"wrote {out} ({count} frames, {count / fps:.1f} s) of {name}")


def _check_render_source(source: str) -> None:
    """Raise ValueError unless ``source`` is an hrlp task or an existing run directory, saying which it was taken for."""
    from hrlp.arm import TASKS

    if source.removeprefix("hrlp/").removesuffix("-v0") in TASKS:
        return
    path = Path(source)
    if path.is_dir():
        return
    if path.exists():
        raise ValueError(f"{source} is a file, not a run directory (nor a task: run 'hrlp tasks' to list them)")
    if "/" in source or source.startswith((".", "~")) or Path(source).parent != Path("."):
        raise ValueError(f"{source}: no such run directory (and not a task: run 'hrlp tasks' to list them)")
    raise ValueError(f"unknown task {source!r} and no run directory of that name; run 'hrlp tasks' to list the tasks "
                     "(only hrlp tasks render)")  # fmt: skip


@app.command()
def demo(
    out_dir: Annotated[Path, typer.Option(help="Run directory (run again to continue it).", callback=check.out_dir)] = Path(
        "runs/demo"
    ),
    steps: Annotated[
        int | None,
        typer.Option(
            help="Low-level environment steps of Manager training (default: arm 1,000,000; fetch 60,000).",
            callback=_STEPS_CHECK,
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the run.", callback=check.seed())] = 0,
    episodes: Annotated[int, typer.Option(help="Evaluation episodes for the success rate.", callback=_EPISODES_CHECK)] = 100,
    video_steps: Annotated[
        int, typer.Option(help="Low-level steps in the video (default: one episode).", callback=_VIDEO_STEPS_CHECK)
    ] = 0,
    workers: Annotated[
        int,
        typer.Option(help="Sampling processes (1: sample in this process; the arm's demo only).", callback=check.workers()),
    ] = 2,
    robot: Annotated[
        str,
        typer.Option(
            help="arm: reach-and-grip on hrlp's arm; fetch: FetchPickAndPlace (needs hrlp\\[fetch]).",
            callback=check.choice(("arm", "fetch")),
        ),
    ] = "arm",
) -> None:
    """Train a Manager with shipped skills (reach-and-grip on the arm, or pick-and-place on Fetch); print its success
    rate, write a video labelled with the active skill and a learning-curve plot."""
    from hrlp.video import check_rendering

    check_rendering(480, 360)  # the video comes after minutes of training: a missing OpenGL driver fails now
    from hrlp.experiments.demo import run_demo

    with describing(lambda: f"; the same command continues the run in {out_dir} from its last checkpoint"):
        res = run_demo(out_dir, steps, seed, episodes, video_steps, err_console, workers, robot)
    console.print(f"success rate: {res.success}")
    console.print(f"video: {res.video}\nlearning curve: {res.plot}\nrun: {res.run_dir} (hrlp eval / hrlp render work on it)")


@app.command()
def presets(
    name: Annotated[str | None, typer.Argument(help="A preset to show whole: its description and its runs.")] = None,
    all_: Annotated[
        bool, typer.Option("--all", help="Also list the research record's presets (explorations, superseded settings).")
    ] = False,
) -> None:
    """List the paper's experiments and hrlp's own as presets (runs, seeds, default budget), a line each; with NAME, one
    preset whole."""
    from hrlp.experiments.presets import PRESETS, RESEARCH

    if name is not None:
        if name not in PRESETS:
            raise ValueError(f"no preset {name!r}; the presets: {', '.join(PRESETS)}")
        p = PRESETS[name]
        own = any(run.steps for run in p.runs)  # runs with budgets of their own
        console.print(f"[bold]{p.name}[/] ({p.source}): {len(p.runs)} runs x {len(p.seeds)} seeds, "
                      f"{'steps per run as listed' if own else f'{p.budget:,} steps each'}, metric {p.metric}",
                      soft_wrap=False, highlight=False)  # fmt: skip
        console.print(p.description, highlight=False)
        if RESEARCH in p.tags:
            console.print("kept for the research record (docs/research/presets.md): an exploration or a superseded setting",
                          highlight=False)  # fmt: skip
        for run in p.runs:
            console.print(f"  {run.name}" + (f" ({run.steps or p.budget:,} steps)" if own else ""), highlight=False)
        console.print(f"run it: hrlp reproduce {p.name}", highlight=False)
        return
    shown = [p for p in PRESETS.values() if all_ or RESEARCH not in p.tags]
    rows = [(p.name, str(len(p.runs)), str(len(p.seeds)), f"{p.budget:,}", f"{p.source}: {p.description}") for p in shown]
    _one_line_table("presets: hrlp reproduce PRESET runs one, hrlp presets PRESET shows it whole",
                    ("preset", "runs", "seeds", "budget", "paper: description"), rows)  # fmt: skip
    if hidden := len(PRESETS) - len(shown):
        console.print(f"and {hidden} presets of the research record: hrlp presets --all",
                      highlight=False)  # fmt: skip


def _one_line_table(title: str, columns: tuple[str, ...], rows: list[tuple[str, ...]]) -> None:
    """A table of one line per row at any terminal width: every column as wide as its longest entry, but the last, which
    takes what is left and ends in an ellipsis where it does not fit (shown whole when written to a file or a pipe)."""
    from rich.cells import cell_len, set_cell_size
    from rich.text import Text

    widths = [max(cell_len(Text.from_markup(r[i]).plain) for r in [columns, *rows]) for i in range(len(columns) - 1)]
    room = console.width - sum(widths) - 2 * len(widths) if console.is_terminal else 10**6

    def line(cells: tuple[str, ...]) -> Text:
        out = Text()
        for cell, w in zip(cells, widths, strict=False):
            text = Text.from_markup(cell)
            out.append_text(text)
            out.append(" " * (w - cell_len(text.plain) + 2))
        last = cells[-1]
        out.append(last if cell_len(last) <= room else set_cell_size(last, max(room - 1, 0)) + "…")
        return out

    console.print(title, highlight=False)
    console.print(line(columns), style="bold", soft_wrap=True)
    for r in rows:
        console.print(line(r), soft_wrap=True, highlight=False)


@app.command()
def reproduce(
    ctx: typer.Context,
    preset: Annotated[str, typer.Argument(help="A preset (see 'hrlp presets'), e.g. reach-and-grip-2.")],
    seeds: Annotated[
        int | None,
        typer.Option(help="Seeds 0..N-1 per run (default: the preset's).", callback=check.count(1, bounds.MAX_SEED)),
    ] = None,
    budget: Annotated[
        int | None, typer.Option(help="Environment steps per run (default: the preset's).", callback=_STEPS_CHECK)
    ] = None,
    out: Annotated[Path, typer.Option(help="Root of the runs (OUT/PRESET/RUN/sSEED).", callback=check.out_dir)] = Path(
        "runs/reproduce"
    ),
    backend: Annotated[str, typer.Option(help="process (a local process pool) or ray (a Ray cluster).")] = "process",
    workers: Annotated[int, typer.Option(help="Runs at once on the process pool.", callback=check.workers())] = 2,
    address: Annotated[
        str | None, typer.Option(help="Ray cluster address, HOST:PORT (default: start a local Ray); needs --backend ray.")
    ] = None,
    reuse: Annotated[
        bool, typer.Option(help="Copy a run whose config matches a finished run of another preset under OUT.")
    ] = True,
    only: Annotated[
        list[str] | None,
        typer.Option(help="Run only the runs whose name matches this shell pattern, e.g. '*,c2=3,tr=0.03'; repeatable."),
    ] = None,
) -> None:
    """Run a preset's runs x seeds grid; finished runs are skipped, interrupted ones resume, runs another preset
    already finished with the same config are copied."""
    if backend not in ("process", "ray"):
        raise ValueError(f"--backend must be one of process, ray, got {backend!r}")
    if address is not None and backend != "ray":
        raise ValueError(f"--address {address} is a Ray cluster's; it needs --backend ray (the {backend} backend ignores it)")
    if backend == "ray" and _given(ctx, "workers"):
        raise ValueError("--workers sizes the local process pool; with --backend ray the cluster's CPUs decide how many "
                         "runs go at once (leave --workers out)")  # fmt: skip
    if address is not None and (problem := bounds.ray_address_problem(address)) is not None:
        raise ValueError(problem)  # a dead address fails here, within seconds, not after Ray's minutes of retries
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

    stopped = "; finished runs are kept, and the same command continues the others from their last checkpoints"
    with describing(lambda: stopped):
        results = run_grid(preset, out, seeds, budget, backend, workers, address, on_result=report, reuse=reuse,
                           only=tuple(only or ()))  # fmt: skip
    console.print(f"{len(results)} runs of {preset} in {out / preset}; tables: hrlp tables --root {out}")


@app.command()
def tables(
    root: Annotated[Path, typer.Option(help="Root of the runs written by 'hrlp reproduce'.", callback=check.out_dir)] = Path(
        "runs/reproduce"
    ),
    out: Annotated[
        Path | None,
        typer.Option(help="Directory for the markdown tables and PNG plots (default ROOT/tables).", callback=check.out_dir),
    ] = None,
    threshold: Annotated[
        list[float] | None,
        typer.Option(
            help="Training success rate for the sample-efficiency table; repeatable (default: the preset's own, else "
            "0.05, 0.1, 0.2).",
            callback=check.real(0.0, 1.0, low_open=True),
        ),
    ] = None,
    window: Annotated[
        int, typer.Option(help="Iterations in the moving average of the training success rate.", callback=check.count(1))
    ] = 3,
    overwrite: Annotated[
        bool, typer.Option(help="Replace files in --out that 'hrlp tables' did not write there (e.g. committed results).")
    ] = False,
) -> None:
    """Rebuild the paper's tables (ours beside the paper's numbers), learning curves, sweep scatter plots and
    sample-efficiency tables from run directories.

    Files it wrote before (recorded in OUT/.hrlp-tables.json) are replaced; any other file is replaced only with
    --overwrite."""
    from hrlp.atomic import StorageError
    from hrlp.experiments.tables import build_tables, default_out

    out = default_out(root) if out is None else out
    try:
        files = build_tables(root, out, thresholds=tuple(threshold) if threshold else None, window=window,
                             overwrite=overwrite)  # fmt: skip
    except StorageError:
        raise
    except OSError as e:
        raise OSError(_os_error_line(e, out)) from None
    for f in files:
        console.print(f"wrote {f}")


@app.command()
def theory(
    mdps: Annotated[
        int,
        typer.Option(
            help="Random MDPs to search (each with several policy pairs).",
            callback=check.count(1, bounds.MAX_MDPS, bounds.WHY_MDPS),
        ),
    ] = 200,
    seed: Annotated[int, typer.Option(help="Seed of the search.", callback=check.seed())] = 0,
    out: Annotated[Path, typer.Option(help="Directory for counterexample files.", callback=check.out_dir)] = Path(
        "theory_counterexamples"
    ),
) -> None:
    """Check Lemma 1, Theorem 1, Lemma 2 and Corollary 1 numerically on random finite MDPs."""
    from hrlp.theory import run_theory

    run_theory(mdps=mdps, seed=seed, out_dir=out, console=console)


# --- train and train-manager: their options generated from the config dataclasses ------------------------------------
#
# Every field of TrainConfig, TRPOConfig and ValueFitConfig is an option of both commands, named after the field
# (``--max-kl``; the value fit's fields prefixed ``--value-``), typed by its annotation, defaulting to the dataclass's
# default, its help the field's docstring (hrlp.config.field_docs), so that the help and the config cannot drift
# apart. hrlp.config imports neither torch nor gymnasium: ``hrlp --help`` and ``hrlp train --help`` stay fast.


@dataclass(frozen=True)
class _Setting:
    """A field of a run's config that is an option of ``train`` and ``train-manager``."""

    config: type
    """The dataclass the field belongs to: ``TrainConfig``, ``TRPOConfig`` or ``ValueFitConfig``."""
    field: str
    """The field's name."""
    option: str
    """The option's parameter name: ``--option-name`` on the command line, ``ctx.params[option]``."""


_LEFT_OUT: dict[type, dict[str, str]] = {
    TrainConfig: {
        "task": "the commands' TASK argument, whose help says what each command takes",
        "advantage": "nested: each AdvantageConfig field is an option of its own",
        "trpo": "nested: each TRPOConfig field is an option of its own",
        "ppo": "nested: each PPOConfig field is an option of its own (--ppo-...)",
        "sac": "nested: each SACConfig field is an option of its own (--sac-...)",
        "value": "nested: each ValueFitConfig field is an option of its own (--value-...)",
        "macro": "a MacroSpec that train-manager's own options build (--skills, --k, --library, --micro..., --handover...); "
        "a flat run has none",
        "task_kwargs": "given as --task-arg NAME=VALUE, repeatable (a dict has no one-token form), below",
    },
}
"""The config fields that are deliberately not generated options, and why."""

_OPTION_NAMES = {(ValueFitConfig, "max_iter"): "value_iters", (ValueFitConfig, "fraction"): "value_fraction"}
"""Options named otherwise than their field: the value fit's first two options predate the generated ones."""

_NESTED: dict[type, str] = {
    AdvantageConfig: "advantage",
    TRPOConfig: "trpo",
    PPOConfig: "ppo",
    SACConfig: "sac",
    ValueFitConfig: "value",
}
"""TrainConfig's nested records, by the field that holds each."""

_PREFIXES = {ValueFitConfig: "value_", PPOConfig: "ppo_", SACConfig: "sac_"}
"""Option-name prefixes of the records whose field names would clash with another's (``--ppo-entropy-coef``)."""

_SETTINGS: tuple[_Setting, ...] = tuple(
    _Setting(config, f.name, _OPTION_NAMES.get((config, f.name), _PREFIXES.get(config, "") + f.name))
    for config in (TrainConfig, *_NESTED)
    for f in dataclasses.fields(config)
    if f.name not in _LEFT_OUT.get(config, {})
)
"""The generated options of ``train`` and ``train-manager``, in the fields' order."""

_PANELS = {TrainConfig: "Run (TrainConfig)", AdvantageConfig: "Advantages (AdvantageConfig)", TRPOConfig: "TRPO (TRPOConfig)",
           PPOConfig: "PPO (PPOConfig, with --algo ppo)", SACConfig: "SAC (SACConfig, with --algo sac)",
           ValueFitConfig: "Value fit (ValueFitConfig)"}  # fmt: skip
"""The help's section for each dataclass's options."""

_OPTION_TYPES: dict[str, Any] = {"int": int, "float": float, "bool": bool, "str": str, "int | None": int | None,
                                 "str | None": str | None, "tuple[int, ...]": str}  # fmt: skip
"""The option's type for a field's annotation; a tuple of integers is given as ``64,64`` (:func:`check.widths`)."""

_CHECKS: dict[str, check.Check] = {  # the bounds checked while the options are parsed, in hrlp.bounds' words
    "steps": _STEPS_CHECK,
    "batch_steps": _BATCH_CHECK,
    "num_envs": check.count(1, bounds.MAX_NUM_ENVS, bounds.WHY_NUM_ENVS),
    "workers": check.workers(0),  # 0: one per core (hrlp.training.environments.resolve_config)
    "seed": check.seed(),
    "episode_steps": check.count(1),
    "hidden": check.widths,
    "init_log_std": check.real(),
    "episodes": check.count(1, bounds.MAX_STEPS, bounds.WHY_STEPS, "number of episodes"),
    "reward_scale": check.real(0.0, low_open=True),
    "init_from": check.skill_ref,
    "max_kl": check.real(0.0, low_open=True),
    "cg_iters": check.count(1, 1000, "each iteration is a Fisher-vector product over the batch"),
    "cg_damping": check.real(0.0),
    "cg_residual_tol": check.real(0.0),
    "line_search_backtracks": check.count(1),
    "line_search_shrink": check.real(0.0, 1.0, low_open=True, high_open=True),
    "gamma": check.real(0.0, 1.0),
    "gae_lambda": check.real(0.0, 1.0),
    "entropy_coef": check.real(0.0),
    "fisher_fraction": check.real(0.0, 1.0, low_open=True),
    "algo": check.choice(ALGOS),
    "ppo_clip": check.real(0.0, low_open=True),
    "ppo_epochs": check.count(1, 1000, "each epoch is a pass over the batch"),
    "ppo_minibatches": check.count(1),
    "ppo_lr": check.real(0.0, low_open=True),
    "ppo_max_grad_norm": check.real(0.0),
    "ppo_target_kl": check.real(0.0),
    "ppo_entropy_coef": check.real(0.0),
    "sac_lr": check.real(0.0, low_open=True),
    "sac_batch_size": check.count(1, 1_000_000, "a minibatch is drawn per gradient step"),
    "sac_buffer_size": check.count(1, bounds.MAX_STEPS, bounds.WHY_STEPS, "number of transitions"),
    "sac_learning_starts": check.count(0, bounds.MAX_STEPS, bounds.WHY_STEPS),
    "sac_updates_per_step": check.real(0.0, 1000.0),
    "sac_tau": check.real(0.0, 1.0, low_open=True),
    "sac_hidden": check.widths,
    "sac_init_alpha": check.real(0.0, low_open=True),
    "sac_choice_entropy": check.real(0.0, 1.0),
    "sac_her_future": check.count(0, 1000, "each relabelled goal replaces a real one in the minibatch"),
    "value_iters": check.count(1),
    "value_l2_coef": check.real(0.0),
    "value_history_size": check.count(1),
    "value_fraction": check.real(0.0, 1.0, low_open=True),
}
"""Each generated option's check while parsed; TRPOConfig's and ValueFitConfig's own checks follow
(:func:`check.config_field`). TrainConfig's checks that combine fields run before torch is imported
(:func:`_check_numbers`) and when the config is built."""


def _parameter(setting: _Setting, default: Any) -> inspect.Parameter:
    """The command parameter of a generated option: ``Annotated[type, typer.Option(...)] = default``."""
    field = next(f for f in dataclasses.fields(setting.config) if f.name == setting.field)
    kind = _OPTION_TYPES[str(field.type)]  # a field of another type needs an entry there, or a place in _LEFT_OUT
    first = _CHECKS.get(setting.option)
    callback = first if setting.config is TrainConfig else check.config_field(setting.config, setting.field, first)
    option = typer.Option(
        help=field_docs(setting.config).get(setting.field, ""),
        callback=callback,
        rich_help_panel=_PANELS[setting.config],
        metavar="W,W,..." if kind is str else None,
    )
    if isinstance(default, tuple):  # hidden layer widths: shown and given as 64,64
        default = ",".join(map(str, default))
    return inspect.Parameter(setting.option, inspect.Parameter.KEYWORD_ONLY, default=default,
                             annotation=Annotated[kind, option])  # fmt: skip


def _settings_options(**defaults: Any) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Give a command (``def command(ctx, ..., **settings)``) the generated options of :data:`_SETTINGS` after its own:
    one keyword parameter per setting, default the dataclass's unless ``defaults`` names another for this command
    (``train-manager``'s batch of 5,000 decisions)."""
    if unknown := set(defaults) - {s.option for s in _SETTINGS}:
        raise TypeError(f"no generated options {sorted(unknown)}")

    def add(command: Callable[..., None]) -> Callable[..., None]:
        own = inspect.signature(command, eval_str=True)
        params = [p for p in own.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD]
        if clash := {p.name for p in params} & {s.option for s in _SETTINGS}:
            raise TypeError(f"{command.__name__}: options {sorted(clash)} are generated from the config")
        for s in _SETTINGS:
            field = next(f for f in dataclasses.fields(s.config) if f.name == s.field)
            params.append(_parameter(s, defaults.get(s.option, field.default)))

        @functools.wraps(command)
        def run(**kwargs: Any) -> None:
            command(**kwargs)

        run.__signature__ = own.replace(parameters=params)  # type: ignore[attr-defined]
        run.__annotations__ = {p.name: p.annotation for p in params}
        return run

    return add


def _config_kwargs(params: dict[str, Any], config: type) -> dict[str, Any]:
    """The fields of ``config`` given by the generated options in ``params`` (a command's ``ctx.params``)."""
    return {s.field: params[s.option] for s in _SETTINGS if s.config is config}


_SEED = Annotated[int, typer.Option(help="Seed of environments, network and action noise.", callback=check.seed())]
_WORKERS = Annotated[
    int,
    typer.Option(
        help="Processes sampling at the same time (e.g. one per core); 1: in this process.", callback=check.workers()
    ),
]
_RUN_DIR = Annotated[
    Path | None, typer.Option(help="Where logs and checkpoints go (default runs/TASK-sSEED).", callback=check.out_dir)
]
_TASK_ARG = Annotated[
    list[str] | None,
    typer.Option("--task-arg", help="A task argument NAME=VALUE, repeatable, e.g. --task-arg c1=-10 --task-arg tr=0.06."),
]
_RESUME = Annotated[
    bool, typer.Option(help="Continue the run in --run-dir from its last checkpoint with its own settings (--steps may grow).")
]


def _paper_options() -> dict[str, Any]:
    """:data:`hrlp.config.PAPER_SETTINGS` by option name (``value.max_iter`` is ``value_iters``)."""
    records = {name: config for config, name in _NESTED.items()}
    out = {}
    for name, value in PAPER_SETTINGS.items():
        record, _, field = name.rpartition(".")
        config = records[record] if record else TrainConfig
        out[next(s.option for s in _SETTINGS if s.config is config and s.field == field)] = value
    return out


_PAPER_OPTIONS = _paper_options()
"""The options ``--paper-settings`` sets, with their values."""

_PAPER = Annotated[
    bool,
    typer.Option(
        help="The paper's settings, as every preset runs them, for the options among these left out: "
        + " ".join(
            f"--{n.replace('_', '-')} {v:g}" if isinstance(v, float) else f"--{n.replace('_', '-')} {v}"
            for n, v in _PAPER_OPTIONS.items()
        )
        + " (one process; the defaults sample on every core, with faster updates that learn as well: docs/benchmarks.md)."
    ),
]


def _apply_paper_settings(ctx: typer.Context) -> set[str]:
    """With ``--paper-settings``, put the paper's value into ``ctx.params`` for each of :data:`_PAPER_OPTIONS` left out;
    the names of the options set."""
    if not ctx.params.get("paper_settings"):
        return set()
    left_out = {name for name in _PAPER_OPTIONS if not _given(ctx, name)}
    ctx.params.update({name: _PAPER_OPTIONS[name] for name in left_out})
    return left_out


def _stops_as_a_run(command: Callable[..., None]) -> Callable[..., None]:
    """A training command whose stop by a signal names the run's last saved iteration and the command that continues
    it (:func:`_run_stop_detail`)."""

    @functools.wraps(command)
    def run(**kwargs: Any) -> None:
        ctx = kwargs["ctx"]
        with describing(lambda: _run_stop_detail(ctx)):
            command(**kwargs)

    return run


def _run_stop_detail(ctx: typer.Context) -> str:
    """Where a training run stopped by a signal stands on disk, and what continues it: ``at iteration 41 (2,050,000
    steps); hrlp train Reacher --run-dir runs/x --resume continues it``."""
    import shlex

    p = ctx.params
    out = _run_dir(p)
    saved = _saved_progress(out / "checkpoint")
    if saved is None:
        return "before its first iteration was saved: there is nothing to resume, and the same command starts the run again"
    iteration, steps = saved
    budgets = "".join(f" --{n} {p[n]}" for n in ("steps", "episodes") if p.get("resume") and _given(ctx, n))
    return (f"at iteration {iteration} ({steps:,} steps); hrlp {ctx.info_name} {shlex.quote(p['task'])} --run-dir "
            f"{shlex.quote(str(out))} --resume{budgets} continues it")  # fmt: skip


def _run_dir(p: dict[str, Any]) -> Path:
    """The run directory of a training command's options ``p`` (``--run-dir``, or ``runs/TASK-sSEED``)."""
    return p.get("run_dir") or Path("runs") / f"{p['task'].replace('/', '_').replace(':', '_')}-s{p['seed']}"


def _saved_progress(checkpoint: Path) -> tuple[int, int] | None:
    """``(iteration, env_steps)`` of the training checkpoint at ``checkpoint`` (or of the whole ``.old`` copy a kill
    between a save's renames leaves), None if there is none or it cannot be read. Reads only ``meta.json``."""
    import json
    import sys

    path = checkpoint / "meta.json"
    if not path.is_file() and "hrlp.checkpoint" in sys.modules:  # (no torch import here, at a stop during start-up)
        from hrlp.checkpoint import CheckpointError, resolve_checkpoint

        try:
            path = resolve_checkpoint(checkpoint) / "meta.json"
        except CheckpointError:
            return None
    try:
        meta = json.loads(path.read_text())["meta"]
        return int(meta["iteration"]), int(meta["env_steps"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


@app.command()
@_settings_options()
@_stops_as_a_run
def train(
    ctx: typer.Context,
    task: Annotated[
        str,
        typer.Argument(help="hrlp task (see 'hrlp tasks'), a Gymnasium id, or MODULE:ID (the module registers the id)."),
    ],
    run_dir: _RUN_DIR = None,
    task_arg: _TASK_ARG = None,
    resume: _RESUME = False,
    paper_settings: _PAPER = False,
    **settings: Any,
) -> None:
    """Train a flat TRPO policy (Box, Discrete or parameterised Tuple actions); logs and checkpoints every iteration.

    The options of the run, TRPO and the value baseline are the fields of TrainConfig, TRPOConfig and ValueFitConfig
    (hrlp.config), with their defaults (--paper-settings: the paper's, where the defaults are faster)."""
    _apply_paper_settings(ctx)
    if not resume:  # before torch is imported: the task, its arguments and spaces (a resume uses the run's own)
        notes = [_off_policy_defaults(ctx)] if settings["algo"] in OFF_POLICY else [_episode_length_defaults(ctx, task)]
        notes.append(_small_batch_defaults(ctx))
        _check_numbers(ctx)
        ctx.meta["start_notes"] = [_few_updates_note(ctx, task)]  # printed once the run is set up (an error stays one line)
        _check_task(task, settings["episode_steps"], task_arg, ctx)
        for note in filter(None, notes):  # after the checks: an error stays the one line
            err_console.print(note, soft_wrap=True, highlight=False)
    _train(ctx, None, run_dir, resume, task_arg)  # short-episode settings, where chosen, are in ctx.params


@app.command("train-manager")
@_settings_options(batch_steps=5_000)  # the paper's Manager batch (TrainConfig's default is the flat runs' 50,000)
@_stops_as_a_run
def train_manager(
    ctx: typer.Context,
    task: Annotated[
        str,
        typer.Argument(help="Task the Manager solves: an hrlp task (e.g. ReachAndGrip2), a Gymnasium id or MODULE:ID."),
    ],
    skills: Annotated[
        str,
        typer.Option(
            help="Comma-separated skills: library names (see 'hrlp skills list'), e.g. gripper,reacher, or MODULE:NAME "
            "Python references (a Skill, or a function returning one; docs/skills.md)."
        ),
    ] = "",
    micro: Annotated[bool, typer.Option(help="Add the micro-action: direct torque control.")] = False,
    micro_duration: Annotated[
        int, typer.Option(help="Low-level steps a micro-action lasts (needs --micro).", callback=check.count(1))
    ] = 1,
    micro_penalty: Annotated[
        float, typer.Option(help="Penalty per use of the micro-action (needs --micro).", callback=check.real(0.0))
    ] = 0.0,
    micro_max_torque: Annotated[
        float,
        typer.Option(
            help="Torque bound of the micro-action, in (0, 1] (needs --micro).", callback=check.real(0.0, 1.0, low_open=True)
        ),
    ] = 1.0,
    k: Annotated[
        int | None, typer.Option(help="Low-level steps per skill call (default: each skill's own k).", callback=check.count(1))
    ] = None,
    library: Annotated[
        Path | None, typer.Option(help="Skill library searched first (an existing directory).", callback=check.existing_dir)
    ] = None,
    handover: Annotated[
        bool,
        typer.Option(
            help="Drive Reachers for hand-over: goals relative to the capsule, approach from above, claw held "
            "open (docs/skills.md); --no-handover: the paper's absolute goals, skills run as trained."
        ),
    ] = True,
    handover_approach_height: Annotated[
        float,
        typer.Option(
            help="Metres a Reacher's goal is raised until the hand is above it, in [0, 1] (0: straight to the goal; "
            "needs --handover).",
            callback=check.real(0.0, 1.0),
        ),
    ] = 0.11,
    handover_open_torque: Annotated[
        float,
        typer.Option(
            help="Torque holding the claw open while a Reacher runs, in place of its own finger torques, in [0, 1] "
            "(0: the skill's own, for a Reacher trained to keep the claw open; needs --handover).",
            callback=check.real(0.0, 1.0),
        ),
    ] = 0.2,
    handover_target_relative: Annotated[
        bool,
        typer.Option(
            help="Pass a Mover's target as an offset of at most 10 cm from the task's own target (reach-and-move; "
            "docs/skills.md) instead of a point of the workspace; needs --handover.",
        ),
    ] = False,
    handover_initiation: Annotated[
        bool,
        typer.Option(
            help="Start each skill only from its initiation set (the states like those it was trained from, e.g. a "
            "Mover from held starts only while the capsule is lifted): a choice outside it runs the first skill whose "
            "set holds (docs/skills.md); needs --handover.",
        ),
    ] = False,
    handover_pregrasp: Annotated[
        bool,
        typer.Option(
            help="Give a Reacher goals in the pre-grasp box (3 cm aside, 0-8 cm above the capsule's centre, centred 4 cm "
            "above it) instead of 5 cm aside and 0-20 cm above (docs/skills.md); needs --handover.",
        ),
    ] = False,
    chain: Annotated[
        bool,
        typer.Option(
            help="Enforce the skills' initiation tests: a choice outside its skill's set runs the nearest skill before "
            "it whose set holds (docs/skills.md)."
        ),
    ] = False,
    run_dir: _RUN_DIR = None,
    task_arg: _TASK_ARG = None,
    resume: _RESUME = False,
    paper_settings: _PAPER = False,
    **settings: Any,
) -> None:
    """Train a Manager over frozen skills with hierarchical TRPO (Lemma 1's KL); logs and checkpoints every iteration.

    The options of the run, TRPO and the value baseline are the fields of TrainConfig, TRPOConfig and ValueFitConfig
    (hrlp.config), with their defaults (but 5,000 decisions per batch; --paper-settings: the paper's, where the
    defaults are faster)."""
    _apply_paper_settings(ctx)
    if not resume:  # options the Manager would silently ignore (with --resume they are compared with the run's)
        if ignored := [f"--{n.replace('_', '-')}" for n in ("micro_duration", "micro_penalty", "micro_max_torque")
                       if not micro and _given(ctx, n)]:  # fmt: skip
            one = len(ignored) == 1
            raise ValueError(f"{', '.join(ignored)} set{'s' if one else ''} the micro-action, which this Manager does not "
                             f"have: add --micro, or leave {'it' if one else 'them'} out")  # fmt: skip
        if ignored := [f"--{n.replace('_', '-')}" for n in _HANDOVER_OPTIONS if not handover and _given(ctx, n)]:
            one = len(ignored) == 1
            them = "it" if one else "them"
            raise ValueError(f"{', '.join(ignored)} set{'s' if one else ''} how Reachers are driven for hand-over, "
                             f"which --no-handover turns off: drop --no-handover, or leave {them} out")  # fmt: skip
        if k is not None and not skills.strip():
            raise ValueError("--k sets how long each skill runs, and this Manager has no skills (--skills)")
        notes = [_off_policy_defaults(ctx), _small_batch_defaults(ctx)]
        _check_numbers(ctx)  # before torch is imported
        _check_task(task, settings["episode_steps"], task_arg, ctx)
        for note in filter(None, notes):
            err_console.print(note, soft_wrap=True, highlight=False)
    from hrlp.config import Handover, MacroSpec, MicroAction

    try:
        names = tuple(s.strip() for s in skills.split(",") if s.strip())
        m = MicroAction(micro_duration, micro_penalty, micro_max_torque) if micro else None
        drive = Handover(approach_height=handover_approach_height, open_torque=handover_open_torque,
                         target_relative=handover_target_relative,
                         initiation=handover_initiation, pregrasp=handover_pregrasp) if handover else None  # fmt: skip
        if not _is_arm_task(task) and not any(_given(ctx, n) for n in ("handover", *_HANDOVER_OPTIONS)):
            drive = None  # hand-over drives the arm's Reachers and Movers; elsewhere skills run as they are
        spec = MacroSpec(names, k, m, None if library is None else str(library), drive, chain)
    except ValueError:
        if not resume:  # with --resume the run's own macro-actions are used (options given are compared with them)
            raise
        spec = None
    _train(ctx, spec, run_dir, resume, task_arg)


_HANDOVER_OPTIONS = ("handover_approach_height", "handover_open_torque", "handover_target_relative",
                     "handover_initiation", "handover_pregrasp")  # fmt: skip


def _is_arm_task(task: str) -> bool:
    """Whether ``task`` names one of hrlp's arm tasks (whose Reachers and Movers hand-over drives)."""
    from hrlp.arm.registry import TASKS

    return task.removeprefix("hrlp/").removesuffix("-v0") in TASKS


def parse_task_args(items: list[str] | None) -> dict[str, Any]:
    """``["c1=-10", "tr=0.06"]`` -> ``{"c1": -10, "tr": 0.06}`` (values read as JSON, else kept as strings)."""
    import json

    out: dict[str, Any] = {}
    for item in items or []:
        name, sep, raw = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--task-arg must look like NAME=VALUE, got {item!r}")
        if name.strip() in out:
            raise ValueError(f"--task-arg {name.strip()} is given twice ({out[name.strip()]!r} and {raw!r}); give it once")
        try:
            out[name.strip()] = json.loads(raw)
        except json.JSONDecodeError:
            out[name.strip()] = raw
    return out


def _train(ctx: typer.Context, macro: Any, run_dir: Path | None, resume: bool, task_arg: list[str] | None) -> Path:
    """Shared body of ``train`` and ``train-manager``: build and check the config from the options in ``ctx.params``
    (and a Manager's ``macro``, a MacroSpec), then train with a progress bar.

    With ``--resume`` the run continues with its own settings: options left out take the run's values, and an option
    given on the command line that differs from the run's is refused with one line naming it (only ``--steps`` and
    ``--episodes`` may change); ``train`` refuses a Manager run and ``train-manager`` a flat one."""
    from hrlp.atomic import StorageError
    from hrlp.checkpoint import CheckpointError, checkpoint_exists
    from hrlp.train import env_factory, train_with_progress

    p = ctx.params
    task = p["task"]
    out = _run_dir(p)
    manager_command = macro is not None or ctx.info_name == "train-manager"
    try:
        if resume:
            from hrlp.checkpoint import load_checkpoint

            if not checkpoint_exists(out / "checkpoint"):
                raise ValueError(f"--resume: {out} has no checkpoint to continue from")
            try:
                saved = TrainConfig.from_json(load_checkpoint(out / "checkpoint")[1]["config"])
            except CheckpointError as e:
                raise ValueError(str(e)) from None
            except (KeyError, TypeError) as e:
                raise ValueError(f"--resume: {out / 'checkpoint'}: its config is malformed ({e})") from None
            if (saved.macro is not None) != manager_command:
                kind, command = ("a Manager", "train-manager") if saved.macro is not None else ("a flat", "train")
                raise ValueError(f"--resume: {out} holds {kind} run; continue it with 'hrlp {command} {saved.task} "
                                 f"--run-dir {out} --resume'")  # fmt: skip
            differences = _resume_differences(saved, ctx)
            if differences:
                raise ValueError(f"--resume: {out} was trained with other settings: {', '.join(differences)}; only --steps "
                                 "and --episodes may change (leave the other options out to continue with the run's "
                                 "own)")  # fmt: skip
            budgets = {name: p[name] for name in ("steps", "episodes") if _given(ctx, name)}  # else the run's own
            cfg = dataclasses.replace(saved, **budgets)
        else:
            if checkpoint_exists(out / "checkpoint"):
                raise ValueError(f"{out} already holds a run; pass --resume to continue it or choose another --run-dir")
            if manager_command and p["init_from"] is not None:
                raise ValueError("--init-from starts a flat run from a skill's weights; a Manager starts from a fresh "
                                 "network (its skills are given by --skills)")  # fmt: skip
            nested = {name: config(**_config_kwargs(p, config)) for config, name in _NESTED.items()}
            cfg = TrainConfig(task=task, **_config_kwargs(p, TrainConfig), **nested, macro=macro,
                              task_kwargs=parse_task_args(task_arg))  # fmt: skip
        env_factory(cfg.task, cfg.episode_steps, cfg.macro, cfg.advantage.gamma, **cfg.task_kwargs)
    except CheckpointError as e:
        raise ValueError(str(e)) from None
    kind = "train-manager" if cfg.macro is not None else "train"
    try:  # errors end as one line from the top-level handler (_OneLineErrors)
        summary = train_with_progress(cfg, out, resume, err_console, f"{kind} {cfg.task}",
                                      notes=[n for n in ctx.meta.get("start_notes", []) if n])  # fmt: skip
    except StorageError:
        raise
    except OSError as e:  # a file system error not already named by hrlp's writers
        raise OSError(_os_error_line(e, out)) from None
    console.print(summary.line(), soft_wrap=True)
    console.print(f"run written to {out} (checkpoint: {out / 'checkpoint'}, logs: progress.csv, tb/)")
    return out


def _episode_length_defaults(ctx: typer.Context, task: str) -> str:
    """For a Gymnasium environment whose registration declares episodes of at most
    :data:`~hrlp.envs.check.SHORT_EPISODE_STEPS` decisions (``max_episode_steps``), put the short-episode settings into
    ``ctx.params`` for the options left out and return the note that says so ("" when nothing changes). The defaults
    suit 300-step episodes: on 1-10-decision episodes a 50,000-decision batch is a whole 20,000-episode budget. hrlp's
    own arm tasks keep the paper's settings whatever ``--episode-steps``."""
    from hrlp.arm import TASKS
    from hrlp.arm.registry import declared_episode_steps
    from hrlp.envs.check import SHORT_EPISODE_SETTINGS, SHORT_EPISODE_STEPS

    left_out = [name for name in SHORT_EPISODE_SETTINGS if not _given(ctx, name)]
    if not left_out or task.removeprefix("hrlp/").removesuffix("-v0") in TASKS:
        return ""
    try:
        length = declared_episode_steps(task)  # the environment's own declaration, not a --episode-steps cut
        measured = length is None
        if measured:  # nothing declares it: a few episodes under random actions measure it
            length = _measured_episode_steps(task, ctx)
    except ValueError:
        return ""  # an unknown task or bad arguments: _check_task says so
    if length is None or length > SHORT_EPISODE_STEPS:
        return ""
    ctx.params.update({name: SHORT_EPISODE_SETTINGS[name] for name in left_out})
    shown = " ".join(f"--{name.replace('_', '-')} {SHORT_EPISODE_SETTINGS[name]:g}" for name in left_out)
    plural = "s" if length != 1 else ""
    how = f"lasted at most {length:,} decision{plural} under random actions" if measured else (
        f"last at most {length:,} decision{plural}")  # fmt: skip
    return (f"note: {task}'s episodes {how}: short-episode settings {shown} (give the options to choose others; "
            "docs/training.md)")  # fmt: skip


def _measured_episode_steps(task: str, ctx: typer.Context) -> int | None:
    """:func:`hrlp.envs.check.measured_episode_steps` of the task with the command's task arguments (None if it cannot
    be built: _check_task then says why in one line)."""
    import gymnasium as gym

    from hrlp.envs.check import measured_episode_steps, registered_gym_id

    if "measured_episode_steps" in ctx.meta:  # measured once per command
        return ctx.meta["measured_episode_steps"]
    length = None
    try:
        env = gym.make(registered_gym_id(task), **parse_task_args(ctx.params.get("task_arg")))
    except Exception:  # _check_task names the problem
        return None
    try:
        length = measured_episode_steps(env, ctx.params["seed"])
    except Exception:  # the environment's own fault: the run itself reports it with its context
        pass
    finally:
        env.close()
    ctx.meta["measured_episode_steps"] = length
    return length


def _few_updates_note(ctx: typer.Context, task: str) -> str:
    """One line when a fresh on-policy run's budget allows fewer than :data:`~hrlp.envs.check.FEW_UPDATES` policy
    updates ("" otherwise): the updates its --steps (or its --episodes, at the longest episode length declared or
    measured) allow at its batch size, and the --batch-steps that would give that many."""
    from hrlp.arm import TASKS
    from hrlp.arm.registry import declared_episode_steps
    from hrlp.envs.check import FEW_UPDATES

    p = ctx.params
    if p["algo"] in OFF_POLICY or p["batch_steps"] < p["num_envs"]:
        return ""
    batch = -(-p["batch_steps"] // p["num_envs"]) * p["num_envs"]
    decisions, why = p["steps"], f"--steps {p['steps']:,}"
    if p["episodes"] is not None:
        try:
            length = declared_episode_steps(task, p["episode_steps"])
        except ValueError:
            length = None
        if length is None and task.removeprefix("hrlp/").removesuffix("-v0") not in TASKS:
            length = _measured_episode_steps(task, ctx)
        if length is not None and p["episodes"] * length < decisions:
            decisions, why = p["episodes"] * length, f"--episodes {p['episodes']:,} of at most {length:,} decisions"
    updates = max(1, decisions // batch)
    if updates >= FEW_UPDATES:
        return ""
    better = max(p["num_envs"], decisions // FEW_UPDATES // p["num_envs"] * p["num_envs"])
    plural = "s" if updates != 1 else ""
    return (f"note: {why} allows about {updates} policy update{plural} of --batch-steps {p['batch_steps']:,}; fewer than "
            f"{FEW_UPDATES} rarely learn: --batch-steps {better:,} gives {FEW_UPDATES}")  # fmt: skip


OFF_POLICY_SETTINGS: dict[str, Any] = {"num_envs": 4, "batch_steps": 10_000}
"""``--algo sac``'s run settings where they are left out: 4 environments (a gradient step per decision collected, as
Stable-Baselines3's SAC, whatever their number), and a log row and checkpoint (the replay buffer with it) every 10,000
decisions instead of the on-policy batch."""


def _off_policy_defaults(ctx: typer.Context) -> str:
    """For an off-policy ``--algo``, :data:`OFF_POLICY_SETTINGS` into ``ctx.params`` for the options left out; the note
    that says so ("" when nothing changes or the algorithm is on-policy)."""
    p = ctx.params
    left_out = [name for name in OFF_POLICY_SETTINGS if not _given(ctx, name)]
    if p["algo"] not in OFF_POLICY or not left_out:
        return ""
    p.update({name: OFF_POLICY_SETTINGS[name] for name in left_out})
    shown = " ".join(f"--{name.replace('_', '-')} {OFF_POLICY_SETTINGS[name]:,}" for name in left_out)
    return f"note: --algo {p['algo']} runs with {shown} (give the options to choose others)"


def _small_batch_defaults(ctx: typer.Context) -> str:
    """For a batch too small for the default ``--fisher-fraction`` or ``--value-fraction`` (fewer than one state in
    each stride: a few decisions per environment), left out, put 1 (every state) into ``ctx.params`` and return the
    note that says so ("" when nothing changes). A fraction given on the command line is checked as given."""
    p = ctx.params
    if p["batch_steps"] < p["num_envs"] or p["algo"] in OFF_POLICY:
        return ""  # TrainConfig says so in its own words; an off-policy run has no Fisher matrix nor baseline fit
    steps_per_env = -(-p["batch_steps"] // p["num_envs"])
    sizes = {"fisher_fraction": (steps_per_env * p["num_envs"], "decisions"), "value_fraction": (steps_per_env, "time steps")}
    changed = [name for name, (size, unit) in sizes.items()
               if not _given(ctx, name) and bounds.fraction_problem(name, p[name], size, unit) is not None]  # fmt: skip
    if not changed:
        return ""
    was = " and ".join(f"--{name.replace('_', '-')} {p[name]:g}" for name in changed)
    p.update({name: 1.0 for name in changed})
    now = " ".join(f"--{name.replace('_', '-')} 1" for name in changed)
    return (f"note: a batch of {steps_per_env * p['num_envs']:,} decisions ({steps_per_env:,} per environment) is too small "
            f"for the default {was}: every state is used ({now})")  # fmt: skip


def _check_numbers(ctx: typer.Context) -> None:
    """The checks of a fresh run's config that combine options (:mod:`hrlp.bounds`, as ``TrainConfig`` makes them), made
    before torch is imported; a single option's bounds were checked while parsing."""
    from hrlp.envs.check import default_episode_steps

    p = ctx.params
    if p["workers"] == 0:
        auto_workers(p["num_envs"])  # a bad $HRLP_WORKERS fails here, in one line naming it
    if p["batch_steps"] < p["num_envs"]:
        return  # TrainConfig says so in its own words
    steps_per_env = -(-p["batch_steps"] // p["num_envs"])
    problems = []
    if p["algo"] not in OFF_POLICY:  # the Fisher matrix and the baseline fit are on-policy
        problems += [
            bounds.fraction_problem("fisher_fraction", p["fisher_fraction"], steps_per_env * p["num_envs"], "decisions"),
            bounds.fraction_problem("value fraction", p["value_fraction"], steps_per_env, "time steps"),
        ]
    if ctx.info_name == "train-manager":
        episode = p["episode_steps"] or default_episode_steps()
        problems += [
            bounds.duration_problem("k", p["k"], episode),
            bounds.duration_problem("the micro-action's duration", p["micro_duration"] if p["micro"] else None, episode),
        ]
    if problem := next((x for x in problems if x is not None), None):
        raise ValueError(problem)


def _check_task(task: str, episode_steps: int | None, task_arg: list[str] | None, ctx: typer.Context | None) -> None:
    """The checks of a fresh run that need no torch: the task, its arguments (:func:`hrlp.envs.check.probe_task`),
    and options given on the command line that the task would silently ignore."""
    import gymnasium as gym

    from hrlp.arm import TASKS
    from hrlp.arm.registry import probe_task
    from hrlp.envs.check import invalid_arguments_line

    kwargs = parse_task_args(task_arg)
    name = task.removeprefix("hrlp/").removesuffix("-v0")
    valid = TASKS[name].arguments if name in TASKS else ()
    if unknown := [k for k in kwargs if valid and k not in valid and k != "episode_steps"]:  # physics, render_mode, ...
        raise ValueError(invalid_arguments_line(name, unknown, valid))
    _, action_space = probe_task(task, episode_steps, **kwargs)
    if ctx is not None and ctx.info_name == "train-manager" and not isinstance(action_space, gym.spaces.Box):
        raise ValueError(f"{task}: a Manager's skills emit Box actions; this environment's action space is {action_space}")
    if ctx is not None and _given(ctx, "init_log_std") and isinstance(action_space, gym.spaces.Discrete):
        raise ValueError(f"--init-log-std sets the Gaussian noise of continuous actions; {task}'s actions are "
                         f"{action_space}, drawn from a categorical policy (leave --init-log-std out)")  # fmt: skip


def _os_error_line(error: OSError, where: Path) -> str:
    """One line for an OSError: the path it names (else ``where``) and why."""
    return f"{error.filename or where}: {error.strerror or error}"


#: Options of ``train``/``train-manager`` that locate or drive the run rather than define it (not compared on --resume).
_RUN_OPTIONS = frozenset({"ctx", "run_dir", "resume", "steps", "episodes", "paper_settings"})
"""Options a resume may give freely: where the run is, and its budgets (``--paper-settings`` stands for the options it
sets, compared one by one)."""


def _resume_differences(saved: Any, ctx: typer.Context | None) -> list[str]:
    """``--OPTION VALUE (the run: VALUE)`` for every option given on the command line whose value differs from the
    saved run's config ``saved``; options left out (their defaults) are the run's own and never differ."""
    import dataclasses

    if ctx is None:
        return []

    def given_here(name: str) -> bool:  # by the enum's name: Typer may carry its own copy of click's ParameterSource
        source = ctx.get_parameter_source(name)
        return source is not None and source.name not in ("DEFAULT", "DEFAULT_MAP")

    from_paper = {name for name in _PAPER_OPTIONS if ctx.params.get("paper_settings") and not given_here(name)}
    given = [name for name in ctx.params if name not in _RUN_OPTIONS and (given_here(name) or name in from_paper)]
    out = []
    for name in given:
        flag = f"--{name.replace('_', '-')}" if name != "task" else "TASK"
        value = ctx.params[name]
        accessor = _RESUME_ACCESSORS.get(name)
        if accessor is None and name in {f.name for f in dataclasses.fields(saved)}:  # an option named as its setting
            accessor = _replace_top(name)
        if accessor is None:
            out.append(f"{flag} (cannot be checked against the run; leave it out)")
            continue
        get, put = accessor
        try:
            changed = put(saved, value, ctx.params) != saved
        except (ValueError, TypeError):  # a value the run could not have had
            changed = True
        if changed:
            shown = "TASK " + str(value) if name == "task" else f"{flag} {_show(value)}"
            out.append(f"{shown} (the run: {_show(get(saved))}{'; from --paper-settings' if name in from_paper else ''})")
    return out


def _show(value: Any) -> str:
    if isinstance(value, list | tuple):
        return ",".join(map(str, value)) if value else "(none)"
    if value is None:
        return "(default)"
    return str(value)


def _replace_nested(record: str, name: str) -> tuple[Any, Any]:
    import dataclasses

    def put(c: Any, v: Any, p: dict[str, Any]) -> Any:
        return dataclasses.replace(c, **{record: dataclasses.replace(getattr(c, record), **{name: v})})

    return lambda c: getattr(getattr(c, record), name), put


def _replace_top(name: str) -> tuple[Any, Any]:
    import dataclasses

    return lambda c: getattr(c, name), lambda c, v, p: dataclasses.replace(c, **{name: v})


def _replace_macro(field: str, convert: Any = lambda v: v) -> tuple[Any, Any]:
    import dataclasses

    return (lambda c: getattr(c.macro, field),
            lambda c, v, p: dataclasses.replace(c, macro=dataclasses.replace(c.macro, **{field: convert(v)})))  # fmt: skip


def _micro_flag() -> tuple[Any, Any]:
    import dataclasses

    def put(c: Any, v: bool, p: dict[str, Any]) -> Any:
        from hrlp.config import MicroAction

        if not v:
            micro = None
        else:
            micro = c.macro.micro or MicroAction(p["micro_duration"], p["micro_penalty"], p["micro_max_torque"])
        return dataclasses.replace(c, macro=dataclasses.replace(c.macro, micro=micro))

    return (lambda c: "on" if c.macro.micro is not None else "off"), put


def _handover_flag() -> tuple[Any, Any]:
    import dataclasses

    def put(c: Any, v: bool, p: dict[str, Any]) -> Any:
        from hrlp.config import Handover

        fresh = Handover(approach_height=p["handover_approach_height"], open_torque=p["handover_open_torque"],
                         target_relative=p["handover_target_relative"], initiation=p["handover_initiation"],
                         pregrasp=p["handover_pregrasp"])  # fmt: skip
        handover = (c.macro.handover or fresh) if v else None
        return dataclasses.replace(c, macro=dataclasses.replace(c.macro, handover=handover))

    return (lambda c: "on" if c.macro.handover is not None else "off"), put


def _handover_field(field: str) -> tuple[Any, Any]:
    import dataclasses

    def put(c: Any, v: Any, p: dict[str, Any]) -> Any:
        if c.macro.handover is None:  # the run drives no Reacher for hand-over: as with --no-handover, the option is unused
            return c
        handover = dataclasses.replace(c.macro.handover, **{field: v})
        return dataclasses.replace(c, macro=dataclasses.replace(c.macro, handover=handover))

    return (lambda c: "off" if c.macro.handover is None else getattr(c.macro.handover, field)), put


def _micro_field(field: str) -> tuple[Any, Any]:
    import dataclasses

    def put(c: Any, v: Any, p: dict[str, Any]) -> Any:
        if c.macro.micro is None:  # the run has no micro-action: as in a fresh run without --micro, the option is unused
            return c
        micro = dataclasses.replace(c.macro.micro, **{field: v})
        return dataclasses.replace(c, macro=dataclasses.replace(c.macro, micro=micro))

    return (lambda c: "off" if c.macro.micro is None else getattr(c.macro.micro, field)), put


def _task_accessor() -> tuple[Any, Any]:
    import dataclasses

    def name(task: str) -> str:
        return task.removeprefix("hrlp/").removesuffix("-v0")

    def put(c: Any, v: str, p: dict[str, Any]) -> Any:
        return c if name(v) == name(c.task) else dataclasses.replace(c, task=v)

    return lambda c: c.task, put


def _task_args_accessor() -> tuple[Any, Any]:
    import dataclasses

    def show(c: Any) -> str:
        return ",".join(f"{k}={v}" for k, v in c.task_kwargs.items()) or "(none)"

    return show, lambda c, v, p: dataclasses.replace(c, task_kwargs=parse_task_args(v))


def _resolve_config(cfg: TrainConfig) -> TrainConfig:
    """:func:`hrlp.training.environments.resolve_config`, imported when a resume compares settings (not for --help)."""
    from hrlp.training.environments import resolve_config

    return resolve_config(cfg)


def _setting_accessor(setting: _Setting) -> tuple[Any, Any]:
    if (setting.config, setting.field) == (TrainConfig, "workers"):  # 0: the count this machine gives, compared as such
        return lambda c: c.workers, lambda c, v, p: _resolve_config(dataclasses.replace(c, workers=v))
    if (setting.config, setting.field) == (TrainConfig, "backend"):  # auto: the run's choice for its task
        return lambda c: c.backend, lambda c, v, p: _resolve_config(dataclasses.replace(c, backend=v))
    if setting.config is TrainConfig:
        return _replace_top(setting.field)
    return _replace_nested(_NESTED[setting.config], setting.field)


#: How each defining option of ``train``/``train-manager`` reads (for the message) and sets (to compare) a saved config.
_RESUME_ACCESSORS: dict[str, tuple[Any, Any]] = {
    "task": _task_accessor(),
    **{s.option: _setting_accessor(s) for s in _SETTINGS},
    "task_arg": _task_args_accessor(),
    "skills": _replace_macro("skills", lambda v: tuple(s.strip() for s in v.split(",") if s.strip())),
    "k": _replace_macro("k"),
    "library": _replace_macro("library", lambda v: None if v is None else str(v)),
    "micro": _micro_flag(),
    "handover": _handover_flag(),
    "handover_approach_height": _handover_field("approach_height"),
    "handover_open_torque": _handover_field("open_torque"),
    "handover_target_relative": _handover_field("target_relative"),
    "handover_initiation": _handover_field("initiation"),
    "handover_pregrasp": _handover_field("pregrasp"),
    "micro_duration": _micro_field("duration"),
    "micro_penalty": _micro_field("penalty"),
    "micro_max_torque": _micro_field("max_torque"),
}


@app.command("eval")
def eval_(
    run_dir: Annotated[Path, typer.Argument(help="A run directory written by 'hrlp train'.", callback=check.run_dir)],
    episodes: Annotated[int, typer.Option(help="Evaluation episodes.", callback=_EPISODES_CHECK)] = 20,
    seed: Annotated[int, typer.Option(help="Seed of the evaluation episodes.", callback=check.seed())] = 10_000,
    stochastic: Annotated[bool, typer.Option(help="Sample actions instead of taking the mean.")] = False,
) -> None:
    """Mean return and success rate of a trained policy, with 95% confidence intervals.

    Progress goes to stderr: a bar in a terminal; written to a file or a pipe, a line every tenth of the episodes (at
    least every 10 s) with the running return and success rate."""
    from hrlp.atomic import StorageError
    from hrlp.evaluate import evaluate_with_progress

    try:  # errors end as one line from the top-level handler (_OneLineErrors)
        with describing(lambda: "during the evaluation; nothing was written"):
            ev = evaluate_with_progress(run_dir, episodes=episodes, seed=seed, deterministic=not stochastic,
                                        console=err_console, description=f"eval {run_dir}")  # fmt: skip
    except StorageError:
        raise
    except OSError as e:
        raise OSError(_os_error_line(e, run_dir)) from None
    console.print(f"episodes: {ev.episodes}")
    console.print(f"return (mean, 95% CI): {ev.ret}")
    if ev.success is not None:
        console.print(f"success rate (95% Wilson CI): {ev.success}")
    if ev.target_dist_sum is not None:
        console.print(f"TargetDistSum (mean, 95% CI): {ev.target_dist_sum}")
    if ev.move is not None:
        m = ev.move
        console.print(f"TargetDistSum of the capsule left untouched: {m.untouched_target_dist_sum}; ours minus it: "
                      f"{m.relative_target_dist_sum}")  # fmt: skip
        console.print(f"min d(C, T) (m): {m.min_target_dist}; capsule lifted > 3 cm (Wilson CI): {m.lift_rate}")
    if ev.macro_usage is not None:
        console.print("decisions per macro-action: " + ", ".join(f"{k} {v:.0%}" for k, v in ev.macro_usage.items()))


skills_app = typer.Typer(help="The skill library: frozen, parameterised skills for the Manager.", no_args_is_help=True)
app.add_typer(skills_app, name="skills")
_LIBRARY = Annotated[
    Path | None,
    typer.Option("--library", help="Library directory (default $HRLP_SKILLS or ~/.hrlp/skills).", callback=check.library),
]


@skills_app.command("list")
def skills_list(library: _LIBRARY = None) -> None:
    """List the skills in the library and those shipped with hrlp (a library skill hides a shipped one of its name).

    A broken entry is listed too, marked 'broken', with its one-line reason on stderr; the others are listed as usual."""
    from rich.markup import escape

    from hrlp.skills import SkillLibrary, shipped_roots

    lib = SkillLibrary(library)
    if not lib.root.is_dir():
        err_console.print(f"note: no library at {escape(str(lib.root))} yet ('hrlp skills add' makes it): shipped skills only")
    rows: list[tuple[str, ...]] = []
    seen: set[str] = set()
    broken: list[str] = []
    for source, where in ((lib, "library"), *((SkillLibrary(root), "shipped") for root in shipped_roots())):
        for name in source.names():
            if name in seen:
                continue
            seen.add(name)
            try:
                m = source.manifest(name)
            except ValueError as e:  # CheckpointError included: one entry's problem, not the listing's
                rows.append((escape(name), "[red]broken[/]", "", "", "", where, ""))
                broken.append(str(e))
                continue
            task = str(m["task"]).rpartition(":")[2]  # a module's environment by its id: the row fits 80 columns
            rows.append((name, task, str(m["param"]["dim"]), str(m["k"]), f"{m['trained']['env_steps']:,}", where,
                         ", ".join(m.get("features", [])) or "-"))  # fmt: skip
    _one_line_table(escape(f"skills in {lib.root} and shipped with hrlp (hrlp skills show NAME: one whole)"),
                    ("name", "task", "params", "k", "steps", "from", "features"), rows)  # fmt: skip
    for reason in broken:
        err_console.print(f"[yellow]broken:[/] {escape(reason)}")


@skills_app.command("show")
def skills_show(name: Annotated[str, typer.Argument(help="Skill name.")], library: _LIBRARY = None) -> None:
    """Show a skill's manifest: task, parameters and their meaning, default k, training config, content hash."""
    import json

    from rich.markup import escape

    from hrlp.skills import SkillLibrary, locate_skill, shipped_roots

    try:  # the library first, then the shipped skills; a name with a path in it is refused, never followed
        m = locate_skill(name, [SkillLibrary(library).root, *shipped_roots()]).manifest(name)
    except ValueError as e:
        raise _fail(escape(str(e))) from None
    console.print_json(json.dumps(m))


@skills_app.command("add")
def skills_add(
    run_dir: Annotated[Path, typer.Argument(help="A finished flat run of 'hrlp train' (an arm skill task or any env).")],
    name: Annotated[str, typer.Option(help="Name of the new skill.")],
    k: Annotated[
        int | None,
        typer.Option(help="Default duration in low-level steps (default: 15 on the arm, 10 else).", callback=check.count(1)),
    ] = None,
    param: Annotated[
        str | None,
        typer.Option(
            help="Observation part the Manager's parameters replace, for a run on a Dict observation "
            "(default: desired_goal; 'none' for none). Not for the arm's tasks, whose skills declare theirs."
        ),
    ] = None,
    low: Annotated[
        str | None,
        typer.Option(
            help="Lower bounds of the parameters, comma-separated (or one number for "
            "all; default: the part's own, when finite)."
        ),
    ] = None,
    high: Annotated[str | None, typer.Option(help="Upper bounds of the parameters, as --low.")] = None,
    done_part: Annotated[
        str | None,
        typer.Option(
            help="End the skill early when this part (e.g. achieved_goal) is within --done-within of its parameters."
        ),
    ] = None,
    done_within: Annotated[float | None, typer.Option(help="Distance for --done-part.", callback=check.real(0.0))] = None,
    bind: Annotated[
        list[str] | None,
        typer.Option(
            help="OWN_PART=PART[,PART...]: read one of the run's observation parts from the parts of that name (joined "
            "in order) wherever the skill runs, e.g. achieved_goal=grip_pos; repeatable."
        ),
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace a skill of the same name.")] = False,
    library: _LIBRARY = None,
) -> None:
    """Turn a finished training run into a named, frozen skill in the library (docs/skills.md)."""
    from hrlp.arm.skill import PARAM_SPECS
    from hrlp.arm.skill_files import add_run
    from hrlp.checkpoint import CheckpointError, read_run_checkpoint
    from hrlp.skills import SkillLibrary

    try:
        task = read_run_checkpoint(run_dir / "checkpoint")[2].task
        lib = SkillLibrary(library)
        if task.removeprefix("hrlp/").removesuffix("-v0") in PARAM_SPECS:
            if given := [f"--{o.replace('_', '-')}" for o, v in (("param", param), ("low", low), ("high", high),
                                                                 ("done_part", done_part), ("done_within", done_within),
                                                                 ("bind", bind or None))
                         if v is not None]:  # fmt: skip
                raise ValueError(f"{', '.join(given)}: an arm skill's parameters are its task's ({task}); leave them out")
            path = add_run(lib, run_dir, name, k=15 if k is None else k, overwrite=overwrite)
        else:
            from hrlp.skills.policy import parse_bind
            from hrlp.training.loading import policy_skill_files

            part = "desired_goal" if param is None else (None if param == "none" else param)
            tensors, manifest = policy_skill_files(run_dir, param=part, low=_numbers(low, "--low"),
                                                   high=_numbers(high, "--high"), k=10 if k is None else k,
                                                   done_part=done_part, done_within=done_within,
                                                   bind=parse_bind(bind or ()))  # fmt: skip
            path = lib.save(name, tensors, manifest, overwrite=overwrite)
    except (ValueError, CheckpointError) as e:
        raise _fail(str(e)) from None
    console.print(f"skill {name!r} written to {path}")


def _numbers(text: str | None, option: str) -> list[float] | None:
    """``"0,-1.5"`` -> ``[0.0, -1.5]``; a one-line ValueError naming ``option`` for anything else."""
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"{option} must be numbers separated by commas, got {text!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{option} must be finite numbers, got {text!r}")
    return values


@skills_app.command("build")
def skills_build(
    library: Annotated[Path, typer.Option(help="Library the skills are added to.", callback=check.library)],
    out: Annotated[
        Path, typer.Option(help="Root of the training runs (as 'hrlp reproduce --out').", callback=check.out_dir)
    ] = Path("runs/reproduce"),
    only: Annotated[str, typer.Option(help="Comma-separated skills to build (default: all of them).")] = "",
    budget: Annotated[
        int | None, typer.Option(help="Environment steps per skill (default: each recipe's own).", callback=_STEPS_CHECK)
    ] = None,
    workers: Annotated[int, typer.Option(help="Runs at once.", callback=check.workers())] = 2,
    overwrite: Annotated[
        bool, typer.Option(help="Replace skills of the same names, and their start banks, in the library.")
    ] = False,
    preset: Annotated[
        str, typer.Option(help="The recipes: shipped-skills (the arm's) or fetch-skills (Fetch's; needs hrlp\\[fetch]).")
    ] = "shipped-skills",
    bank_scale: Annotated[
        float,
        typer.Option(
            help="Start banks recorded at this share of their recipes' size.", callback=check.real(0.0, 1.0, low_open=True)
        ),
    ] = 1.0,
) -> None:
    """Train shipped skills from their recipes (--preset; default the arm's, 'shipped-skills') and add them to LIBRARY:
    in stages, each after the skills it starts from, recording the start banks a stage reads from the skills built
    before it (into LIBRARY/.banks)."""
    from dataclasses import replace

    from hrlp.checkpoint import CheckpointError
    from hrlp.experiments.presets import PRESETS
    from hrlp.experiments.skill_build import build_skills

    recipes = [name for name, p in PRESETS.items() if all(r.skill for r in p.runs)]
    if preset not in recipes:
        raise _fail(f"--preset {preset!r} is not a skill recipe (recipes: {', '.join(recipes)})")
    chosen = PRESETS[preset]
    names = [s.strip() for s in only.split(",") if s.strip()]
    known = [r.name for r in chosen.runs]
    try:
        if unknown := sorted(set(names) - set(known)):
            raise ValueError(f"--only: no recipe for {', '.join(unknown)} (recipes: {', '.join(known)})")
        chosen = replace(chosen, runs=tuple(r for r in chosen.runs if not names or r.name in names))
        build_skills(chosen, library, out, budget, workers, overwrite, bank_scale,
                     lambda line: console.print(line, highlight=False, soft_wrap=True))  # fmt: skip
    except (ValueError, CheckpointError) as e:
        raise _fail(str(e)) from None


@app.command()
def dagger(
    manager_run: Annotated[Path, typer.Argument(help="Run directory of a trained Manager.", callback=check.run_dir)],
    skill: Annotated[str, typer.Option(help="The Manager's skill to retrain from its hand-over states.")] = "gripper",
    name: Annotated[str | None, typer.Option(help="Name of the retrained skill (default: SKILL-dagger).")] = None,
    out: Annotated[
        Path | None, typer.Option(help="Directory of the round (default: MANAGER_RUN-dagger).", callback=check.out_dir)
    ] = None,
    library: _LIBRARY = None,
    states: Annotated[
        int, typer.Option(help="Hand-over states to collect.", callback=check.count(1, bounds.MAX_STATES, bounds.WHY_STATES))
    ] = 2_000,
    skill_steps: Annotated[
        int, typer.Option(help="Environment steps of the skill's retraining.", callback=_STEPS_CHECK)
    ] = 2_000_000,
    starts_fraction: Annotated[
        float,
        typer.Option(help="Share of retraining episodes from hand-over states.", callback=check.real(0.0, 1.0, low_open=True)),
    ] = 0.5,
    manager_steps: Annotated[
        int | None, typer.Option(help="Steps of the new Manager (default: the old one's).", callback=_STEPS_CHECK)
    ] = None,
    workers: _WORKERS = 2,
    episodes: Annotated[int, typer.Option(help="Evaluation episodes per success rate.", callback=_EPISODES_CHECK)] = 100,
    seed: _SEED = 0,
    max_hand_distance: Annotated[
        float | None,
        typer.Option(
            help="Keep only hand-overs with d(H, C) at most this, metres (a grip can start there).",
            callback=check.real(0.0, 10.0, low_open=True),
        ),
    ] = None,
    max_capsule_speed: Annotated[
        float | None,
        typer.Option(
            help="Keep only hand-overs with the capsule slower than this across the table, m/s.",
            callback=check.real(0.0, 100.0, low_open=True),
        ),
    ] = None,
    switches_only: Annotated[
        bool,
        typer.Option(
            "--switches-only",
            help="Keep only the decisions at which control passes to SKILL, not those continuing its own run.",
        ),
    ] = False,
) -> None:
    """One DAgger round (Appendix C): collect the states where MANAGER_RUN calls SKILL, retrain the skill from them
    (warm-started), freeze it under a new name with its lineage, retrain the Manager with it, compare old and new."""
    from hrlp.arm.research.dagger import DaggerConfig, run_round

    cfg = DaggerConfig(str(manager_run), skill, name or f"{skill}-dagger", None if library is None else str(library),
                       states, skill_steps, starts_fraction, manager_steps, workers, episodes, seed, max_hand_distance,
                       max_capsule_speed, switches_only)  # fmt: skip
    res = run_round(cfg, out or manager_run.with_name(manager_run.name + "-dagger"), err_console)  # errors: one line

    def cell(d: dict[str, Any]) -> str:
        return f"{d['mean']:.2f} [{d['low']:.2f}, {d['high']:.2f}]"

    for what, key in (("skill from hand-over states", "skill_from_handover"), ("skill from its own starts",
                      "skill_from_own_starts"), ("Manager", "manager")):  # fmt: skip
        console.print(f"{what}: {cell(res[key]['old'])} -> {cell(res[key]['new'])}")
    console.print(f"round written to {res['round_dir']}/round.json; new skill {res['new_skill']}")


@app.command("runs")
def runs_command(
    root: Annotated[Path, typer.Argument(help="Directory searched for run directories (default runs).")] = Path("runs"),
) -> None:
    """List the run directories under ROOT: task and skills, steps done and asked for, training and evaluation
    success, and whether a trainer holds the run now (read from their files alone; nothing is loaded or written)."""
    from rich.markup import escape

    from hrlp.runs import find_runs

    try:
        found = find_runs(root)
    except ValueError as e:
        raise _fail(escape(str(e))) from None
    if not found:
        console.print(f"no runs under {escape(str(root))} (a run directory holds config.json and progress.csv)")
        return

    def rate(v: float | None) -> str:
        return "-" if v is None else f"{v:.2f}"

    rows = [("run", "task", "steps", "train success", "eval success", "state")]
    for r in found:
        where = r.path.relative_to(root).as_posix() if r.path != Path(root) else "."
        state = r.state if r.problem is None else f"{r.state}; unreadable: {r.problem}"
        rows.append((where, r.task, f"{r.steps:,}/{r.budget:,}", rate(r.train_success), rate(r.eval_success), state))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]) - 1)]
    for row in rows:  # plain aligned columns, never cut to the terminal's width (a file or a pipe gets them whole)
        print("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=False)) + "  " + row[-1])
    print(f"{len(found)} run{'s' if len(found) != 1 else ''} under {root}")


for _commands in (app, skills_app):  # every command records when its body begins (a stop's line says what was written)
    for _info in _commands.registered_commands:
        _info.callback = _marking_start(_info.callback)  # type: ignore[arg-type]


def main() -> None:
    """Entry point for ``python -m hrlp``."""
    app()
