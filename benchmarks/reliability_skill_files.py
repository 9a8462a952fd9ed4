"""Bad skill files through the real ``hrlp`` command: code executed, hangs, tracebacks (docs/reliability.md, item 10).

Builds every kind of bad skill file of ``tests/reliability/bad_skill_files.py`` (at least 40) in a temporary directory
and gives each to ``hrlp skills show NAME`` and to ``hrlp train-manager ReachAndGrip1 --skills NAME`` (the loading a
Manager does), every command in its own forked process with a deadline and an address-space limit, then counts:
payloads that ran (a pickle that creates a file when unpickled, Python files in an entry), commands killed at the
deadline (hangs), tracebacks, bad files accepted (exit 0) and refusals that were not one ``error:`` line.

    python benchmarks/reliability_skill_files.py [--deadline 10] [--modes show,load] [--parallel 2] [--verbose]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "reliability"))

from bad_skill_files import MODES, build_bad_skill_files, code_executed, run_bad_skill_files, summarise


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--deadline", type=float, default=10.0, help="seconds a command may take before it counts as a hang")
    ap.add_argument("--modes", default=",".join(MODES), help="commands to run each bad file through: show, load")
    ap.add_argument("--parallel", type=int, default=2, help="commands at once")
    ap.add_argument("--verbose", action="store_true", help="print each command's outcome")
    args = ap.parse_args()
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    if unknown := sorted(set(modes) - set(MODES)):
        ap.error(f"unknown modes {', '.join(unknown)} (known: {', '.join(MODES)})")
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        files = build_bad_skill_files(Path(tmp))
        outcomes = run_bad_skill_files(files, dict.fromkeys(modes), deadline=args.deadline, parallel=args.parallel)
        wall = time.perf_counter() - start
        s = summarise(files, outcomes)
        failures = [o for o in outcomes if not o.clean_error]
        for o in outcomes if args.verbose else failures:
            state = "hang" if o.hung else f"exit {o.returncode}"
            last = (o.error_lines or o.stdout.splitlines() or [""])[-1]
            print(f"{'ok ' if o.clean_error else 'BAD'} {o.mode:<5} {o.kind:<24} {state:<7} {o.seconds:6.2f} s  {last[:150]}")
        for name in code_executed(files):
            print(f"BAD code executed: {name}")
    print(f"{s['commands']} commands ({', '.join(modes)}) in {wall:.1f} s; slowest {s['max_seconds']:.2f} s; "
          f"{s['accepted']} accepted, {s['not_one_line']} refused in more than one line")  # fmt: skip
    print(f"bad skill files: {s['kinds']} kinds -> {s['code_executed']} code executed, {s['hangs']} hangs, "
          f"{s['tracebacks']} tracebacks")  # fmt: skip


if __name__ == "__main__":
    main()
