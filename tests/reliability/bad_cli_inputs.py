"""Bad inputs to the ``hrlp`` command, each run as a real ``python -m hrlp`` process: the table that
``test_reliability_cli.py`` checks and ``benchmarks/reliability.py`` counts (docs/reliability.md, "The CLI's promise").

Every input must end with exit code 2 and exactly one line on stderr, ``error: ...``, matching the case's ``expect``,
within the case's time limit, and never a traceback. ``was`` records what the code before issue 16 did with it
(``traceback``, ``silent``: accepted without a word, ``hang``: no output for minutes, ``misleading``: one line that
blames the wrong thing, ``multiline``: click's framed usage error, ``clean``: already one right line), measured by
running the table on that code.

Arguments may hold placeholders, filled in by :func:`fill`: ``{tmp}`` (a directory of the case's own), ``{file}`` (a
regular file), ``{empty}`` (an empty directory), ``{run}`` (a real finished run of ``hrlp train``, 16 steps of Reacher),
``{dead}`` (``127.0.0.1:PORT`` with nothing listening) and ``{too_many}`` (one more worker than the machine allows).
"""

from __future__ import annotations

import ctypes.util
import os
import re
import signal
import socket
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

TINY = ("--steps", "16", "--batch-steps", "16", "--num-envs", "4", "--episode-steps", "20")
"""A flat run that trains in seconds: what a silently accepted input costs before the test sees exit code 0."""
TINY_MANAGER = ("--steps", "16", "--batch-steps", "4", "--num-envs", "4", "--episode-steps", "20")
OSMESA: dict[str, str | None] = {"MUJOCO_GL": "osmesa", "PYOPENGL_PLATFORM": None}
"""MuJoCo's software renderer (its library, libOSMesa, is missing on a machine without the Debian package
libosmesa6); PYOPENGL_PLATFORM is unset as a user's shell has it (MuJoCo sets it in the processes it runs in)."""
NO_DISPLAY: dict[str, str | None] = {"MUJOCO_GL": "glfw", "DISPLAY": None, "WAYLAND_DISPLAY": None, "PYOPENGL_PLATFORM": None}
"""MuJoCo's windowed renderer without a display."""


@dataclass(frozen=True)
class BadInput:
    """One bad command line and the error it must give."""

    name: str
    args: tuple[str, ...]
    expect: str
    """A regular expression the error line (after ``error: ``) must match: the error is the right one."""
    was: str
    """What the code before issue 16 did (see the module docstring)."""
    env: dict[str, str | None] = field(default_factory=dict)
    """Environment variables to set (None: unset)."""
    torch: bool = False
    """True if the error comes after torch is imported (a config check); the others fail while the options are parsed."""
    needs: str = ""
    """A condition of the machine: ``no-osmesa`` (no OSMesa library), ``no-box2d`` (Box2D not installed)."""

    @property
    def limit_s(self) -> float:
        """Seconds the process may take, start-up included: generous for a busy machine, far below a hang."""
        return 60.0 if self.torch else 20.0


def _c(name: str, args: str | tuple[str, ...], expect: str, was: str, **kw: object) -> BadInput:
    return BadInput(name, tuple(args.split()) if isinstance(args, str) else args, expect, was, **kw)  # type: ignore[arg-type]


# fmt: off
CASES: tuple[BadInput, ...] = (
    # --- train: the task, its arguments and its spaces -----------------------------------------------------------
    _c("train-box2d-missing", "train LunarLander-v3 --run-dir {tmp}/r", r"needs Box2D.*pip install 'gymnasium\[box2d\]'",
       "traceback", needs="no-box2d"),
    _c("train-tuple-observations", "train Blackjack-v1 --run-dir {tmp}/r", r"unsupported observation space Tuple\(",
       "traceback"),
    _c("train-discrete-observations", "train FrozenLake-v1 --run-dir {tmp}/r", r"unsupported observation space Discrete",
       "traceback"),
    _c("train-unknown-task-arg", "train Reacher --task-arg foo=1 --run-dir {tmp}/r",
       r"Reacher: invalid argument 'foo'.*valid arguments: level_coeff, success_tol", "misleading"),
    _c("train-unknown-task-arg-gym", "train Pendulum-v1 --task-arg foo=1 --run-dir {tmp}/r",
       r"Pendulum-v1: invalid argument 'foo'.*valid arguments: .*\bg\b", "traceback"),
    _c("train-task-arg-episode-steps", "train Reacher --task-arg episode_steps=5 --run-dir {tmp}/r", r"--episode-steps",
       "traceback"),
    _c("train-task-arg-physics", "train Reacher --task-arg physics=3 --run-dir {tmp}/r", r"invalid argument 'physics'",
       "traceback"),
    _c("train-task-arg-twice", ("train", "Gripper", "--task-arg", "c1=-1", "--task-arg", "c1=-2", *TINY, "--run-dir",
       "{tmp}/r"), r"--task-arg c1 is given twice", "silent"),
    _c("train-task-arg-no-equals", "train Reacher --task-arg c1 --run-dir {tmp}/r", r"NAME=VALUE", "clean"),
    _c("train-task-arg-bad-value", "train Gripper --task-arg c1=abc --run-dir {tmp}/r", r"c1 must be a finite number",
       "clean"),
    _c("train-gym-constructor-fails", "train HalfCheetah-v5 --task-arg xml_file={tmp}/missing.xml --run-dir {tmp}/r",
       r"HalfCheetah-v5: cannot be built .*does not exist", "traceback"),
    _c("train-init-log-std-discrete", ("train", "CartPole-v1", "--init-log-std", "-1", *TINY[:6], "--run-dir", "{tmp}/r"),
       r"--init-log-std .*Discrete\(2\)", "silent"),
    _c("train-unknown-task", "train NoSuchTask --run-dir {tmp}/r", r"unknown task 'NoSuchTask'", "clean"),
    # --- train: numbers -------------------------------------------------------------------------------------------
    _c("train-seed-negative", "train Reacher --seed -1 --run-dir {tmp}/r", r"--seed must be at least 0, got -1", "traceback"),
    _c("train-seed-beyond-32-bits", "train Reacher --seed 99999999999999999999 --run-dir {tmp}/r",
       r"--seed must be at most 4,294,967,295", "misleading"),
    _c("train-num-envs-huge", "train Reacher --num-envs 20000 --run-dir {tmp}/r", r"--num-envs must be at most 1,024.*MuJoCo",
       "hang"),
    _c("train-num-envs-zero", "train Reacher --num-envs 0 --run-dir {tmp}/r", r"--num-envs must be a positive integer",
       "clean"),
    _c("train-workers-too-many", ("train", "Reacher", "--workers", "{too_many}", *TINY[:4], "--num-envs", "{too_many}",
       "--run-dir", "{tmp}/r"), r"--workers must be at most \d+, got \d+: each worker is a process", "silent"),
    _c("train-batch-huge", "train Reacher --batch-steps 100000000000 --run-dir {tmp}/r",
       r"--batch-steps must be at most 10,000,000.*memory", "traceback"),
    _c("train-steps-huge", ("train", "Reacher", *TINY[2:], "--steps", "10000000000000", "--run-dir", "{tmp}/r"),
       r"--steps must be at most 1,000,000,000,000", "silent"),
    _c("train-steps-zero", "train Reacher --steps 0 --run-dir {tmp}/r", r"--steps must be a positive number", "clean"),
    _c("train-episode-steps-zero", "train Reacher --episode-steps 0 --run-dir {tmp}/r", r"--episode-steps must be a positive",
       "clean"),
    _c("train-fisher-fraction-keeps-nothing", ("train", "Reacher", *TINY, "--fisher-fraction", "0.000001", "--run-dir",
       "{tmp}/r"), r"fisher_fraction 1e-06 keeps .*fewer than one", "silent"),
    _c("train-value-fraction-keeps-nothing", ("train", "Reacher", *TINY, "--value-fraction", "0.000001", "--run-dir",
       "{tmp}/r"), r"value fraction 1e-06 keeps .*fewer than one", "silent"),
    _c("train-steps-not-a-number", "train Reacher --steps abc", r"train: Invalid value for '--steps'", "multiline"),
    _c("train-option-without-value", "train Reacher --steps", r"Option '--steps' requires an argument", "multiline"),
    _c("train-unknown-option", "train Reacher --foo", r"train: No such option: --foo", "multiline"),
    _c("train-missing-task", "train", r"train: Missing argument", "multiline"),
    _c("train-run-dir-is-a-file", ("train", "Reacher", *TINY, "--run-dir", "{file}"), r"--run-dir .* is a file", "clean"),
    _c("train-run-dir-under-a-file", ("train", "Reacher", *TINY, "--run-dir", "{file}/run"),
       r"--run-dir .*/run lies under .*, which is a file", "clean"),
    _c("train-mujoco-gl-invalid", "train Reacher --run-dir {tmp}/r", r"MUJOCO_GL: bogus: use egl", "traceback",
       env={"MUJOCO_GL": "bogus"}),
    _c("train-mujoco-gl-osmesa-missing", "train Reacher --run-dir {tmp}/r", r"MUJOCO_GL=osmesa.*Debian package libosmesa6",
       "traceback", env=OSMESA, needs="no-osmesa"),
    # --- train-manager --------------------------------------------------------------------------------------------
    _c("manager-k-zero", "train-manager ReachAndGrip2 --skills gripper --k 0 --run-dir {tmp}/r",
       r"--k must be a positive integer", "clean"),
    _c("manager-k-beyond-the-episode", ("train-manager", "ReachAndGrip2", "--skills", "gripper", "--k", "1000",
       *TINY_MANAGER, "--run-dir", "{tmp}/r"), r"k \(1,000\) is longer than an episode \(20 steps\)", "silent"),
    _c("manager-micro-options-without-micro", ("train-manager", "ReachAndGrip2", "--skills", "gripper", "--micro-duration",
       "5", *TINY_MANAGER, "--run-dir", "{tmp}/r"), r"--micro-duration sets the micro-action.*add --micro", "silent"),
    _c("manager-k-without-skills", ("train-manager", "ReachAndGrip2", "--micro", "--k", "5", *TINY_MANAGER, "--run-dir",
       "{tmp}/r"), r"--k sets how long each skill runs.*no skills", "silent"),
    _c("manager-library-missing", ("train-manager", "ReachAndGrip2", "--skills", "gripper", "--library", "{tmp}/nolib",
       *TINY_MANAGER, "--run-dir", "{tmp}/r"), r"--library .*nolib: no such directory", "silent"),
    _c("manager-micro-torque-beyond-1", "train-manager ReachAndGrip2 --micro --micro-max-torque 2 --run-dir {tmp}/r",
       r"--micro-max-torque must be in \(0, 1\]", "clean"),
    _c("manager-micro-penalty-nan", "train-manager ReachAndGrip2 --micro --micro-penalty nan --run-dir {tmp}/r",
       r"--micro-penalty must be a finite number", "clean"),
    _c("manager-on-discrete-actions", "train-manager CartPole-v1 --micro --run-dir {tmp}/r", r"skills emit Box actions",
       "clean"),
    _c("manager-num-envs-huge", "train-manager ReachAndGrip2 --micro --num-envs 50000 --batch-steps 100000 --run-dir {tmp}/r",
       r"--num-envs must be at most 1,024", "hang"),
    _c("manager-seed-negative", "train-manager ReachAndGrip2 --micro --seed -5 --run-dir {tmp}/r",
       r"--seed must be at least 0", "traceback"),
    # --- eval -----------------------------------------------------------------------------------------------------
    _c("eval-missing-run", "eval {tmp}/runs/nope", r"RUN_DIR .*nope: no such run directory", "clean"),
    _c("eval-a-file", "eval {file}", r"RUN_DIR .* is a file, not a run directory", "misleading"),
    _c("eval-episodes-zero", "eval {run} --episodes 0", r"--episodes must be a positive integer", "clean"),
    _c("eval-episodes-huge", "eval {run} --episodes 1000000000", r"--episodes must be at most 100,000", "hang"),
    _c("eval-seed-negative", "eval {run} --seed -1 --episodes 1", r"--seed must be at least 0", "traceback"),
    # --- render ---------------------------------------------------------------------------------------------------
    _c("render-missing-run", "render {tmp}/runs/nope", r"runs/nope: no such run directory", "misleading"),
    _c("render-a-file", "render {file}", r"is a file, not a run directory", "misleading"),
    _c("render-width-beyond-framebuffer", "render Reacher --width 5000 --steps 2 --out {tmp}/a.mp4",
       r"--width must be in \[16, 640\], got 5000.*framebuffer", "traceback"),
    _c("render-height-beyond-framebuffer", "render Reacher --height 5000 --steps 2 --out {tmp}/a.mp4",
       r"--height must be in \[16, 480\]", "traceback"),
    _c("render-width-tiny", "render Reacher --width 8 --out {tmp}/a.mp4", r"--width must be in \[16, 640\]", "clean"),
    _c("render-bad-suffix", "render Reacher --out {tmp}/a.avi", r"\.mp4 or \.gif", "clean"),
    _c("render-unknown-camera", "render Reacher --camera top --out {tmp}/a.mp4", r"--camera must be 'front' or 'side'",
       "clean"),
    _c("render-seed-negative", "render Reacher --seed -1 --steps 2 --out {tmp}/a.mp4", r"--seed must be at least 0",
       "misleading"),
    _c("render-steps-huge", "render Reacher --steps 1000000000 --out {tmp}/a.mp4", r"--steps must be at most 1,000,000",
       "hang"),
    _c("render-osmesa-missing", "render Reacher --steps 2 --out {tmp}/a.mp4", r"MUJOCO_GL=osmesa.*libosmesa6", "traceback",
       env=OSMESA, needs="no-osmesa"),
    _c("render-no-display", "render Reacher --steps 2 --out {tmp}/a.mp4",
       r"GLFW, which needs a display.*MUJOCO_GL=egl \(Debian: libegl1\)", "traceback", env=NO_DISPLAY),
    # --- reproduce ------------------------------------------------------------------------------------------------
    _c("reproduce-out-is-a-file", "reproduce reachers --out {file} --budget 16 --seeds 1", r"--out .* is a file",
       "traceback"),
    _c("reproduce-seeds-zero", "reproduce reachers --seeds 0 --out {tmp}/o", r"--seeds must be a positive integer", "clean"),
    _c("reproduce-budget-huge", "reproduce reachers --budget 10000000000000 --out {tmp}/o", r"--budget must be at most",
       "silent"),
    _c("reproduce-unknown-backend", "reproduce reachers --backend dask --out {tmp}/o", r"--backend must be one of", "clean"),
    _c("reproduce-ray-dead-address", "reproduce reachers --backend ray --address {dead} --out {tmp}/o",
       r"cannot reach a Ray cluster at 127\.0\.0\.1:\d+: .*within 5 s", "hang"),
    _c("reproduce-address-without-ray", "reproduce reachers --address {dead} --budget 16 --seeds 1 --out {tmp}/o",
       r"--address .* needs --backend ray", "silent"),
    _c("reproduce-workers-with-ray", "reproduce reachers --backend ray --workers 3 --out {tmp}/o",
       r"--workers sizes the local process pool.*leave --workers out", "silent"),
    _c("reproduce-workers-too-many", "reproduce reachers --workers {too_many} --budget 16 --seeds 1 --out {tmp}/o",
       r"--workers must be at most", "silent"),
    # --- tables ---------------------------------------------------------------------------------------------------
    _c("tables-root-is-a-file", "tables --root {file}", r"--root .* is a file", "misleading"),
    _c("tables-out-is-a-file", "tables --root {empty} --out {file}", r"--out .* is a file", "misleading"),
    _c("tables-threshold-nan", "tables --root {empty} --threshold nan", r"--threshold must be a finite number, got nan",
       "misleading"),
    _c("tables-threshold-beyond-1", "tables --root {empty} --threshold 2", r"--threshold must be in \(0, 1\]", "clean"),
    _c("tables-window-zero", "tables --root {empty} --window 0", r"--window must be a positive integer", "clean"),
    # --- theory ---------------------------------------------------------------------------------------------------
    _c("theory-mdps-zero", "theory --mdps 0 --out {tmp}/t", r"--mdps must be a positive integer", "clean"),
    _c("theory-mdps-huge", "theory --mdps 100000000000 --out {tmp}/t", r"--mdps must be at most 100,000", "hang"),
    _c("theory-seed-negative", "theory --mdps 1 --seed -1 --out {tmp}/t", r"--seed must be at least 0", "traceback"),
    _c("theory-out-is-a-file", "theory --mdps 1 --out {file}", r"--out .* is a file", "traceback"),
    # --- demo -----------------------------------------------------------------------------------------------------
    _c("demo-steps-zero", "demo --steps 0 --out-dir {tmp}/d", r"--steps must be a positive number", "clean"),
    _c("demo-out-dir-is-a-file", "demo --steps 16 --out-dir {file}", r"--out-dir .* is a file", "traceback"),
    _c("demo-seed-negative", "demo --steps 16 --seed -1 --out-dir {tmp}/d", r"--seed must be at least 0", "traceback"),
    _c("demo-workers-too-many", "demo --steps 16 --workers {too_many} --out-dir {tmp}/d", r"--workers must be at most",
       "silent"),
    _c("demo-episodes-huge", "demo --steps 16 --episodes 1000000000 --out-dir {tmp}/d", r"--episodes must be at most",
       "hang"),
    _c("demo-no-display", "demo --steps 16 --out-dir {tmp}/d", r"GLFW, which needs a display", "traceback", env=NO_DISPLAY),
    # --- dagger ---------------------------------------------------------------------------------------------------
    _c("dagger-missing-run", "dagger {tmp}/runs/nope", r"MANAGER_RUN .*nope: no such run directory", "clean"),
    _c("dagger-a-file", "dagger {file}", r"MANAGER_RUN .* is a file, not a run directory", "misleading"),
    _c("dagger-states-zero", "dagger {run} --states 0", r"--states must be a positive integer", "clean"),
    _c("dagger-starts-fraction-beyond-1", "dagger {run} --starts-fraction 2", r"--starts-fraction must be in \(0, 1\]",
       "clean"),
    _c("dagger-max-hand-distance-zero", "dagger {run} --max-hand-distance 0", r"--max-hand-distance must be in \(0, 10\]",
       "clean"),
    _c("dagger-max-capsule-speed-nan", "dagger {run} --max-capsule-speed nan",
       r"--max-capsule-speed must be a finite number", "clean"),
    # --- skills build (its options checked while parsed) and the command itself ----------------------------------------
    _c("skills-build-workers-too-many", "skills build --library {tmp}/lib --out {tmp}/o --only gripper --budget 16 "
       "--workers {too_many}", r"--workers must be at most", "silent"),
    _c("skills-build-library-a-file", "skills build --library {file} --out {tmp}/o --only gripper --budget 16",
       r"--library .* is a file, not a skill library", "misleading"),
    _c("skills-build-out-a-file", "skills build --library {tmp}/lib --out {file} --only gripper --budget 16",
       r"--out .* is a file, not a directory", "clean"),
    _c("skills-show-library-a-file", "skills show reacher --library {file}", r"--library .* is a file, not a skill library",
       "silent"),
    _c("unknown-command", "nosuchcommand", r"No such command 'nosuchcommand'", "multiline"),
    _c("tasks-unknown-option", "tasks --foo", r"tasks: No such option: --foo", "multiline"),
    _c("skills-unknown-subcommand", "skills nosuch", r"skills: No such command 'nosuch'", "multiline"),
)
# fmt: on
"""The bad inputs: every subcommand that takes input, every kind of failure the issue lists."""

WAS = ("traceback", "silent", "hang", "misleading", "multiline", "clean")


@dataclass(frozen=True)
class Context:
    """What the placeholders stand for (made by :func:`prepare`)."""

    root: Path
    file: Path
    empty: Path
    run: Path
    dead: str
    too_many: int


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def prepare(root: Path) -> Context:
    """Make the files the placeholders name under ``root``; ``{run}`` is a real 16-step run of ``hrlp train``."""
    from hrlp.bounds import max_processes
    from hrlp.train import TrainConfig, train

    root.mkdir(parents=True, exist_ok=True)
    (root / "file.txt").write_text("not a directory\n")
    (root / "empty").mkdir(exist_ok=True)
    run = root / "run"
    if not (run / "checkpoint").is_dir():
        list(train(TrainConfig(task="Reacher", steps=16, batch_steps=16, num_envs=4, episode_steps=20), run))
    return Context(root, root / "file.txt", root / "empty", run, f"127.0.0.1:{_free_port()}", max_processes() + 1)


def fill(case: BadInput, ctx: Context) -> tuple[list[str], Path]:
    """The case's arguments with the placeholders filled in, and its own directory (created)."""
    tmp = ctx.root / "cases" / case.name
    tmp.mkdir(parents=True, exist_ok=True)
    values = dict(tmp=tmp, file=ctx.file, empty=ctx.empty, run=ctx.run, dead=ctx.dead, too_many=ctx.too_many)
    return [a.format(**values) for a in case.args], tmp


def unmet(case: BadInput) -> str | None:
    """Why the case cannot be run on this machine (its ``needs``), or None."""
    if case.needs == "no-osmesa" and ctypes.util.find_library("OSMesa"):
        return "an OSMesa library is installed, so MUJOCO_GL=osmesa works here"
    if case.needs == "no-box2d":
        import importlib.util

        if importlib.util.find_spec("Box2D") is not None:
            return "Box2D is installed"
    return None


@dataclass(frozen=True)
class Outcome:
    """What one bad input did."""

    returncode: int | None
    """None: still running at the time limit (then killed, with every process it started)."""
    stdout: str
    stderr: str
    seconds: float

    @property
    def lines(self) -> list[str]:
        """The non-empty lines of stderr."""
        return [line for line in self.stderr.splitlines() if line.strip()]

    def verdict(self, case: BadInput) -> str:
        """``ok`` (exit code 2, one line ``error: ...`` matching ``expect``, in time) or what went wrong:
        ``traceback``, ``hang``, ``silent`` (exit code 0), ``multiline``, ``wrong message``, ``exit code N``."""
        if "Traceback (most recent call last)" in self.stderr + self.stdout:
            return "traceback"
        if self.returncode is None:
            return "hang"
        if self.returncode == 0:
            return "silent"
        if len(self.lines) != 1 or not self.lines[0].startswith("error: "):
            return "multiline"
        if not re.search(case.expect, self.lines[0]):
            return "wrong message"
        if self.returncode != 2:
            return f"exit code {self.returncode}"
        return "ok"


def run_case(case: BadInput, ctx: Context, limit_s: float | None = None, python: tuple[str, ...] = ()) -> Outcome:
    """Run the case as ``python -m hrlp ARGS`` in its own directory and session (killed with every process it started
    once ``limit_s``, default the case's own, has passed). ``python`` replaces ``sys.executable`` (e.g. with
    ``-X importtime`` added)."""
    args, tmp = fill(case, ctx)
    env = {**os.environ, "COLUMNS": "200", "HRLP_SKILLS": str(ctx.root / "no-library")}
    for key, value in case.env.items():
        if value is None:
            env.pop(key, None)
        else:
            env[key] = value
    start = time.perf_counter()
    proc = subprocess.Popen([*(python or (sys.executable,)), "-m", "hrlp", *args], cwd=tmp, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)  # fmt: skip
    try:
        out, err = proc.communicate(timeout=case.limit_s if limit_s is None else limit_s)
        code: int | None = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the command and any worker processes it started
        out, err = proc.communicate()
        code = None
    return Outcome(code, out, err, time.perf_counter() - start)


def run_all(cases: tuple[BadInput, ...], ctx: Context, workers: int = 4, **kw: object) -> dict[str, Outcome]:
    """Every case's :class:`Outcome`, ``workers`` processes at a time."""
    with ThreadPoolExecutor(workers) as pool:
        outcomes = pool.map(lambda c: run_case(c, ctx, **kw), cases)  # type: ignore[arg-type]
        return {c.name: o for c, o in zip(cases, outcomes, strict=True)}
