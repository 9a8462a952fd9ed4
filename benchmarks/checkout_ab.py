"""hrlp's defaults on an arm task with several checkouts of hrlp, alternating in one command: a before/after ratio.

Each checkout (a directory holding hrlp's ``src`` and ``benchmarks``, e.g. a ``git worktree`` of an older commit) runs
``hrlp_run(TASK, STEPS, 0, {})`` of its own ``benchmarks/trpo_speed.py`` in a subprocess, one after another, for
``--rounds`` rounds, so that every checkout sees the same machine and hour. Prints, per run: env steps/s, the cores'
share of the wall inside ``mj_step`` as the run measured it, and the TRPO step's, the baseline fit's, the slowest
worker's environment and inference shares of the wall.

    git worktree add /tmp/before COMMIT
    python benchmarks/checkout_ab.py /tmp/before . --steps 600000 --rounds 2
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from runlog import add_argument, record


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("checkouts", nargs="+", type=Path, help="hrlp checkouts (each with src/ and benchmarks/trpo_speed.py)")
    ap.add_argument("--task", default="ReachAndGrip2")
    ap.add_argument("--steps", type=int, default=600_000, help="env steps per run")
    ap.add_argument("--rounds", type=int, default=2)
    add_argument(ap)
    args = ap.parse_args()
    for c in args.checkouts:
        if not (c / "benchmarks" / "trpo_speed.py").is_file() or not (c / "src" / "hrlp").is_dir():
            raise SystemExit(f"{c}: not an hrlp checkout (no benchmarks/trpo_speed.py or src/hrlp)")
    if args.steps < 1 or args.rounds < 1:
        raise SystemExit("--steps and --rounds must be positive")
    code = ("import json, sys; sys.path.insert(0, 'benchmarks'); from trpo_speed import hrlp_run; "
            f"print(json.dumps(hrlp_run({args.task!r}, {args.steps}, 0, {{}})))")  # fmt: skip
    rounds: list[dict[str, dict]] = []
    for r in range(args.rounds):
        rounds.append({})
        for c in args.checkouts:
            env = {**os.environ, "PYTHONPATH": str(c.resolve() / "src")}
            out = subprocess.run([sys.executable, "-c", code], cwd=c, env=env, capture_output=True, text=True)
            if out.returncode:  # one line: the error the run ended with (e.g. an unknown --task)
                last = next((line for line in reversed(out.stderr.splitlines()) if line.strip()), "no error output")
                raise SystemExit(f"{c}: the run failed: {last.strip()}")
            d = json.loads(out.stdout.strip().splitlines()[-1])
            rounds[-1][str(c)] = d
            print(f"round {r + 1}, {c}: {d['steps_per_s']:.0f} env steps/s, mj_step {d['physics']:.1%} of the cores, "
                  f"TRPO step {d['update']:.1%}, baseline fit {d['value_fit']:.1%}, env {d['env']:.1%}, "
                  f"inference {d['inference']:.1%}", flush=True)  # fmt: skip

    record(__file__, {"task": args.task, "steps": args.steps, "rounds": rounds}, args.runs_dir)


if __name__ == "__main__":
    main()
