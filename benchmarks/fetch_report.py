"""Write ``docs/results/fetch.md`` from the JSON files ``benchmarks/fetch_her.py`` wrote: per task and method, the final
greedy success pooled over seeds (Wilson 95% interval over all final evaluation episodes), each seed's figure, the
environment steps to a greedy success of 0.9 (the Manager's with its skills' own training added), wall time, and the
rl-baselines3-zoo's published figures beside them, a section per task and budget; every target of the Fetch issue is said
met or not met.

    python benchmarks/fetch_report.py docs/results/fetch-*.json --out docs/results/fetch.md [--overwrite]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from hrlp.evaluate import wilson_interval

#: rl-baselines3-zoo's logged evaluations (TQC + HER; success rate, environment steps), and one SAC + HER report.
ZOO = {
    "PickAndPlace": "TQC + HER 0.991 after 1M steps (rl-baselines3-zoo, FetchPickAndPlace-v1); SAC + HER 1.00 after 1.5M "
    "(FetchPickAndPlace-v4)",
    "Push": "TQC + HER 0.999 after 1M steps (rl-baselines3-zoo, FetchPush-v1)",
    "Slide": "TQC + HER 0.868 after 3M steps (rl-baselines3-zoo, FetchSlide-v1)",
}
#: The issue's success targets per task (3 seeds, 100+ greedy episodes each).
TARGETS = {"PickAndPlace": 0.95, "Push": 0.95, "Slide": 0.90}
NAMES = {"manager": "hrlp Manager (SAC + HER over skills)", "sac": "hrlp SAC + HER, flat", "trpo": "hrlp TRPO, flat",
         "ppo": "hrlp PPO, flat", "sb3": "Stable-Baselines3 SAC + HER, flat"}  # fmt: skip


def _targets(res: dict[str, Any]) -> list[str]:
    """The Fetch issue's targets for this task, each said met or not met, from the runs at hand."""
    task, n = res["task"], res["eval_episodes"]
    runs = {m: [r for r in res["runs"].values() if r["method"] == m] for m in ("manager", "sb3", "sac")}
    out = []
    if mgr := runs["manager"]:
        finals = [r["curve"][-1][1] for r in mgr]
        pooled = wilson_interval(round(sum(finals) * n), n * len(finals))
        met = "met" if pooled.mean >= TARGETS[task] and len(mgr) >= 3 else "not met"
        out.append(f"- Manager greedy success >= {TARGETS[task]} over 3 seeds: **{met}** ({pooled.mean:.3f} over {len(mgr)} "
                   f"seed(s)).")  # fmt: skip
        her = [r for m in ("sb3", "sac") for r in runs[m]]
        reached = [r["steps_to_0.9"] for r in mgr]
        if all(r["curve"] and r["steps_to_0.9"] == r["curve"][0][0] for r in mgr):
            out.append("- Every Manager reached 0.9 at its first evaluation, before it had learned much: its skill, given "
                       "parameters about zero, does the task, so the steps to 0.9 measure the skill, not the Manager's "
                       "learning.")  # fmt: skip
        if all(s is not None for s in reached) and her:
            worst = max(s for s in reached if s is not None)
            if any(r["steps_to_0.9"] is not None for r in her):
                first = min(r["steps_to_0.9"] for r in her if r["steps_to_0.9"] is not None)
                out.append(f"- 10x fewer steps to 0.9 than HER: {'**met**' if first >= 10 * worst else '**not met**'} "
                           f"({worst:,} against {first:,}).")  # fmt: skip
            else:
                out.append(f"- 10x fewer steps to 0.9 than HER, and 2x with the skills' training: **not established**: HER "
                           f"did not reach 0.9 within these {res['steps']:,} steps (the Manager needed at most {worst:,}; "
                           f"{worst + res['skill_steps']:,} with its skills), and was not run here to 1M steps.")  # fmt: skip
        else:
            out.append("- Steps to 0.9 against HER: **not established** (the Manager or HER did not reach 0.9 here).")
    return out


def _method_rows(res: dict[str, Any]) -> list[str]:
    by: dict[str, list[dict[str, Any]]] = {}
    for r in res["runs"].values():
        by.setdefault(r["method"], []).append(r)
    rows = []
    for method, runs in by.items():
        runs.sort(key=lambda r: r["seed"])
        n = res["eval_episodes"]
        finals = [r["curve"][-1][1] for r in runs if r["curve"]]
        pooled = wilson_interval(round(sum(finals) * n), n * len(finals))
        reached = [r["steps_to_0.9"] for r in runs]
        to = ", ".join(f"{s:,}" if s is not None else "not within" for s in reached)
        extra = res["skill_steps"] if method == "manager" else 0
        total = ", ".join(f"{s + extra:,}" if s is not None else "-" for s in reached)
        wall = sum(r["wall_s"] for r in runs) / 3600
        first = ", ".join(f"{r['curve'][0][1]:.2f}" for r in runs if r["curve"])
        per_seed = ", ".join(f"{f:.2f}" for f in finals)
        rows.append(f"| {NAMES[method]} | {len(runs)} | {pooled.mean:.3f} [{pooled.low:.3f}, {pooled.high:.3f}] | "
                    f"{per_seed} | {first} | {to} | {total if extra else '-'} | {wall:.2f} |")  # fmt: skip
    return rows


def report(results: list[dict[str, Any]]) -> str:
    out = ["# Fetch: the Manager over skills against flat learners and HER", "",
           "Written by `python benchmarks/fetch_report.py` from the JSON files of `benchmarks/fetch_her.py` beside this page "
           "(`docs/fetch.md` describes the skills and the Manager). Greedy success: the policy's mode, on the evaluation "
           "episodes' seeds 10,000 + i; the interval pools every seed's final evaluation (Wilson, 95%). Steps to 0.9: the "
           "first greedy evaluation (every `eval_every` steps) at or above 0.9; for the Manager, plus its skills' own "
           "training steps. First evaluation: the greedy success of each seed's first evaluation. Core-hours: wall hours "
           "on one core of a two-core machine (both cores shared with other work).", ""]  # fmt: skip
    for res in results:
        task = res["task"]
        out += [f"## Fetch{task}-v4, {res['steps']:,} steps", "",
                f"Budget {res['steps']:,} environment steps per run, greedy evaluation every "
                f"{res['eval_every']:,} steps on {res['eval_episodes']} episodes. The Manager's learned skills took "
                f"{res['skill_steps']:,} steps of their own. Published: {ZOO[task]}.", "",
                "| method | seeds | final greedy success [95%] | per seed | first evaluation | steps to 0.9 | with skills | "
                "core-hours |",
                "|---|---|---|---|---|---|---|---|", *_method_rows(res), "", "Targets:", "", *_targets(res), ""]  # fmt: skip
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--overwrite", action="store_true")
    args = ap.parse_args(argv)
    if args.out.exists() and not args.overwrite:
        print(f"{args.out} exists; give --overwrite to replace it", file=sys.stderr)
        return 2
    merged: dict[tuple, dict[str, Any]] = {}  # one task's methods may come from several files of the same budget
    for path in args.results:
        res = json.loads(path.read_text())
        key = (res["task"], res["steps"], res["eval_every"], res["eval_episodes"])
        if key in merged:
            merged[key]["runs"].update(res["runs"])
        else:
            merged[key] = res
    order = sorted(merged, key=lambda k: (("PickAndPlace", "Push", "Slide").index(k[0]), k[1]))
    args.out.write_text(report([merged[k] for k in order]))
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
