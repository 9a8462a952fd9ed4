"""The figures of issue 16's "Done when" (docs/reliability.md, "Figures"), each measured, nothing simulated:

* **bad CLI inputs** -- every input of ``tests/reliability/bad_cli_inputs.py`` run as a real ``python -m hrlp`` process
  (with ``-X importtime``, so the torch import can be set aside): tracebacks, silent acceptances (exit code 0), hangs
  (no answer within the case's limit), errors that are not one ``error:`` line, and the most seconds from start-up to
  the error with the torch import set aside;
* **kills during training** -- a real training process (``hrlp.train.train`` on Reacher, a checkpoint per iteration)
  killed with SIGKILL at random moments and just before every step of the checkpoint save protocol (creating the
  temporary directory, each file written -- and each half-written --, each fsync, each rename, deleting the old copy,
  and after the save), at the first save and at a save that replaces a checkpoint
  (``tests/reliability/save_protocol.py``); each killed run is checked (a checkpoint that exists must load, its hash
  verified, every tensor finite), resumed to the end, and compared with an uninterrupted run tensor by tensor, its
  ``progress.csv`` listing every iteration once;
* **forced physics blow-ups** -- NaN positions, huge velocities and huge forces written into real MuJoCo states of
  several tasks at random steps of an episode (the first step included): the share flagged, and false alarms on the
  ordinary steps before them;
* **bad skill files** -- the line of ``benchmarks/reliability_skill_files.py``, run as it is.

    python benchmarks/reliability.py [--random-kills 40] [--parallel 2] [--blow-ups 5] [--skip-skill-files] [--verbose]
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "reliability"))

ITERATIONS = 8
"""Iterations (and checkpoint saves) of a killed run."""
KILL_SAVES = (1, 3)
"""Saves killed before every one of their steps: the first (no checkpoint yet) and one that replaces a checkpoint."""


def kills(scratch: Path, random_kills: int, parallel: int, verbose: bool) -> str:
    """The kill figure: ``random_kills`` kills at random moments of iterations 2 to ``ITERATIONS`` (their times measured
    on an uninterrupted run), plus one kill before every step of saves ``KILL_SAVES`` (tests/reliability/save_protocol.py);
    each killed run checked and resumed."""
    import torch
    from save_protocol import check_and_resume, kill_config, protocol_steps, run_child

    from hrlp.checkpoint import load_checkpoint
    from hrlp.train import train

    torch.set_num_threads(1)
    steps = protocol_steps(scratch, KILL_SAVES, ITERATIONS)
    for _ in train(kill_config(ITERATIONS), scratch / "reference"):
        pass
    reference = load_checkpoint(scratch / "reference" / "checkpoint")[0]
    ends = run_child(scratch / "calibration", ITERATIONS).iteration_ends  # seconds after ready
    window = (ends[0], ends[-1])  # from the end of the first iteration (setup, imports) to the end of the last
    plan = [(f"save {s}: before '{label}'", s, i + 1) for s in KILL_SAVES for i, label in enumerate(steps[s])]
    rng = random.Random(16)

    def one(n: int) -> tuple[str, bool]:
        run_dir = scratch / f"kill-{n:03d}"
        if n < len(plan):
            what, save, step = plan[n]
            return what, run_child(run_dir, ITERATIONS, save, step).killed
        while True:  # a random moment of the training; a kill that comes after the end does not count: again
            shutil.rmtree(run_dir, ignore_errors=True)
            delay = rng.uniform(*window)
            if run_child(run_dir, ITERATIONS, kill_after_s=delay).killed:
                return f"random, {delay:.2f} s in (iterations 2-{ITERATIONS}: {window[0]:.2f}-{window[1]:.2f} s)", True

    jobs = range(len(plan) + random_kills)
    with ThreadPoolExecutor(parallel) as pool:  # the training processes; checks and resumes below, one at a time
        done = list(pool.map(one, jobs))
    tally: Counter[str] = Counter()
    for n, (what, killed) in zip(jobs, done, strict=True):
        r = check_and_resume(scratch / f"kill-{n:03d}", ITERATIONS, reference) if killed else {"problem": "not killed"}
        tally.update(k for k in ("corrupt", "failed_resume", "bit_exact", "log_ok") if r.get(k))
        tally["killed"] += killed
        if verbose or r.get("problem"):
            print(f"  {'BAD' if r.get('problem') else 'ok '} {what}: checkpoint of iteration {r.get('iteration_at_kill', '-')}"
                  f" there; {r.get('problem') or 'resumed bit-exactly, every iteration logged once'}")  # fmt: skip
    k = tally["killed"]
    return (f"kills during training: {k} ({random_kills} at random moments of iterations 2-{ITERATIONS}, {len(plan)} before "
            f"every step of the save protocol: {len(steps[1])} steps of the first save, {len(steps[3])} of a save that "
            "replaces a checkpoint) -> "
            f"{tally['corrupt']} corrupt checkpoints, {tally['failed_resume']} failed resumes; {tally['bit_exact']} of {k} "
            f"resumed bit-exactly, {tally['log_ok']} of {k} with every iteration logged once")  # fmt: skip


# --- bad CLI inputs -------------------------------------------------------------------------------------------------


def bad_cli_inputs(scratch: Path, parallel: int, verbose: bool) -> str:
    """The CLI figure, from the table of ``tests/reliability/bad_cli_inputs.py``."""
    from bad_cli_inputs import CASES, Outcome, prepare, run_all, unmet

    ctx = prepare(scratch / "cli")
    runnable = tuple(c for c in CASES if unmet(c) is None)
    load = os.getloadavg()[0]
    outcomes = run_all(runnable, ctx, workers=parallel, python=(sys.executable, "-X", "importtime"))
    load = max(load, os.getloadavg()[0])
    verdicts: Counter[str] = Counter()
    aside: dict[str, float] = {}  # seconds from start-up to the error, the torch import set aside
    wall: dict[str, float] = {}
    for case in runnable:
        o = outcomes[case.name]
        lines = o.stderr.splitlines()
        torch_us = next((int(line.split("|")[1]) for line in lines if line.startswith("import time:")
                         and line.rsplit("|", 1)[-1].strip() == "torch"), 0)  # fmt: skip
        plain = Outcome(o.returncode, o.stdout, "\n".join(x for x in lines if not x.startswith("import time:")), o.seconds)
        verdict = plain.verdict(case)
        verdicts[verdict] += 1
        aside[case.name], wall[case.name] = o.seconds - torch_us / 1e6, o.seconds
        if verbose or verdict != "ok":
            mark = "ok " if verdict == "ok" else "BAD"
            print(f"  {mark} {case.name}: {verdict}, {o.seconds:.2f} s ({aside[case.name]:.2f} s without the torch import): "
                  f"{(plain.lines or ['-'])[-1][:160]}")  # fmt: skip
    skipped = len(CASES) - len(runnable)
    bad = sum(v for k, v in verdicts.items() if k not in ("ok", "traceback", "silent", "hang"))
    slow, slowest = max(aside, key=aside.__getitem__), max(wall, key=wall.__getitem__)
    return (f"bad CLI inputs: {len(CASES)}" + (f" ({skipped} not possible on this machine)" if skipped else "")
            + f" -> {verdicts['traceback']} tracebacks, {verdicts['silent']} silent acceptances, {verdicts['hang']} hangs, "
            f"{bad} errors that are not one right line; each error within {aside[slow]:.2f} s of start-up, torch import "
            f"aside (median {statistics.median(aside.values()):.2f} s, {sum(v > 2 for v in aside.values())} over 2 s; "
            f"slowest {slow}), {wall[slowest]:.2f} s with it "
            f"({slowest}); {parallel} at a time on {os.cpu_count()} cores, load average up to {load:.1f}")  # fmt: skip


# --- physics blow-ups -----------------------------------------------------------------------------------------------


def blow_ups(per_kind: int, verbose: bool) -> str:
    """Forced blow-ups (``BLOW_UPS`` of tests/reliability/test_reliability_physics.py) at the first step and at random
    steps of episodes of several tasks."""
    import logging

    import mujoco
    import numpy as np
    from test_reliability_physics import BLOW_UPS

    from hrlp.arm import make

    logging.getLogger("hrlp.arm.env").setLevel(logging.ERROR)  # each blow-up is logged as a warning: counted here
    mujoco.set_mju_user_warning(lambda message: None)  # and printed by MuJoCo (its warning counters stay as they are)
    rng = np.random.default_rng(2)
    forced = flagged = false_alarms = ordinary = 0
    for task in ("Reacher", "Gripper", "ReachAndGrip2", "MoverNoised"):
        env = make(task, episode_steps=200)
        for kind, force in BLOW_UPS.items():
            for at in [1, *rng.integers(2, 150, size=per_kind - 1)]:
                env.reset(seed=int(rng.integers(1 << 30)))
                early_end = False
                for _ in range(int(at) - 1):
                    *_, terminated, truncated, info = env.step(rng.uniform(-1, 1, 9))
                    ordinary += 1
                    false_alarms += bool(info.get("physics_unstable"))
                    if terminated or truncated:
                        early_end = True
                        break
                if early_end:
                    continue
                force(env.physics.data)
                *_, terminated, truncated, info = env.step(np.zeros(9))
                forced += 1
                ok = truncated and info.get("physics_unstable") and info["physics_warnings"][kind] >= 1
                flagged += bool(ok)
                if verbose or not ok:
                    print(f"  {'ok ' if ok else 'BAD'} {task} {kind} at step {at}")
        env.close()
    share = 100 * flagged / max(forced, 1)
    return (f"forced physics blow-ups: {forced} (3 kinds x {per_kind} steps x 4 tasks, step 1 included) -> {share:.0f}% "
            f"flagged; {false_alarms} false alarms in {ordinary:,} ordinary steps")  # fmt: skip


def skill_files() -> str:
    """The last line of ``benchmarks/reliability_skill_files.py`` (the bad skill files), run as it is."""
    script = ROOT / "benchmarks" / "reliability_skill_files.py"
    if not script.is_file():
        return "bad skill files: benchmarks/reliability_skill_files.py is not there"
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=900)
    lines = [line for line in r.stdout.splitlines() if line.startswith("bad skill files")]
    return lines[-1] if r.returncode == 0 and lines else f"bad skill files: the script failed ({r.stderr[-500:]})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--random-kills", type=int, default=40, help="kills at random times (beside those at each save step)")
    ap.add_argument("--parallel", type=int, default=2, help="training processes at once")
    ap.add_argument("--cli-parallel", type=int, default=1, help="bad inputs at once (1: each timed on its own)")
    ap.add_argument("--blow-ups", type=int, default=10, help="forced blow-ups per kind and task (the first step included)")
    ap.add_argument("--skip-skill-files", action="store_true", help="leave out benchmarks/reliability_skill_files.py")
    ap.add_argument("--only", default="cli,kills,physics,skills", help="figures to measure: cli, kills, physics, skills")
    ap.add_argument("--verbose", action="store_true", help="print every input, kill and blow-up")
    args = ap.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    only = {s.strip() for s in args.only.split(",")}
    lines = []
    with tempfile.TemporaryDirectory(prefix="hrlp-reliability-") as tmp:
        for name, figure in (("cli", lambda: bad_cli_inputs(Path(tmp), args.cli_parallel, args.verbose)),
                             ("kills", lambda: kills(Path(tmp), args.random_kills, args.parallel, args.verbose)),
                             ("physics", lambda: blow_ups(args.blow_ups, args.verbose)),
                             ("skills", skill_files)):  # fmt: skip
            if name not in only or (name == "skills" and args.skip_skill_files):
                continue
            start = time.perf_counter()
            line = figure()
            print(f"{line}  [{time.perf_counter() - start:.0f} s]", flush=True)
            lines.append(line)
    print("\n".join(["", "figures:", *lines]))


if __name__ == "__main__":
    main()
