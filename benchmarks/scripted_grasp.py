"""The scripted grasp expert (:class:`hrlp.arm.research.scripted.ScriptedGrasp`) on the Gripper's start sets.

Runs ``--episodes`` episodes of ``--steps`` control steps (environment seeds ``--seed`` + index) from the Gripper's own
starts (``GripperTask(**GRIPPER_START)``: H 0-9 cm from C, each finger opened 0-1 rad) and, with ``--bank`` (default:
``/work/runs/dagger/round1/starts.npz`` when it exists), from a start bank of Manager hand-over states. Prints per
start set: success (Definition 1 at any step) with its 95% Wilson interval, the share of episodes in which the
capsule ended more than 3 cm (across the table) from where it lay at the start ("pushed"), the median and 90th
percentile of the step of first success, the finger gap at first success (under 3 cm, Definition 1's bound: the
capsule is between the tips), and the failures by kind. For the bank, the same split by what the start state allows:
capsule within reach (centre at most 0.36 m from the arm's base axis) and at rest (slower than 0.1 m/s), or not.

``--first-version`` runs the controller's first version (``ScriptedGraspConfig(keep_clear=False)``);
``--escape-clearance M`` turns on its escape from tight starts (``ScriptedGraspConfig.escape_clearance``). Success is
also split by the start clearance, the nearest any arm geom comes to the capsule at the start.

    python benchmarks/scripted_grasp.py --episodes 100 [--bank PATH | --no-bank] [--steps 100] [--first-version] \
        [--escape-clearance 0.01] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from hrlp.arm.env import ArmEnv
from hrlp.arm.physics import BASE_AXIS_XY, N_JOINTS
from hrlp.arm.research.scripted import ScriptedGrasp, ScriptedGraspConfig
from hrlp.arm.tasks import GripperTask
from hrlp.evaluate import wilson_interval
from hrlp.experiments.presets import GRIPPER_START

DEFAULT_BANK = Path("/work/runs/dagger/round1/starts.npz")
PUSHED = 0.03


def run_episodes(
    bank: str | None, episodes: int, steps: int, seed: int, config: ScriptedGraspConfig | None = None
) -> list[dict[str, Any]]:
    """One record per episode: success, first-success step, push distance, start facts, phases."""
    kw: dict[str, Any] = dict(GRIPPER_START)
    if bank:
        kw["starts"] = bank
    env = ArmEnv(GripperTask(**kw), episode_steps=steps)
    p = env.physics
    expert = ScriptedGrasp(p, config or ScriptedGraspConfig())
    out = []
    for ep in range(episodes):
        env.reset(seed=seed + ep)
        c0 = p.capsule.copy()
        v0 = p.data.qvel[N_JOINTS : N_JOINTS + 3]
        rec: dict[str, Any] = {
            "d0": p.hand_to_capsule(),
            "reach0": math.hypot(c0[0] - BASE_AXIS_XY[0], c0[1] - BASE_AXIS_XY[1]),
            "speed0": math.hypot(v0[0], v0[1]),
            "clear0": expert.arm_clearance(),
            "first": -1,
        }
        phases = []
        for t in range(steps):
            phases.append(str(expert.situation()["phase"]))
            _, _, _, trunc, info = env.step(expert.act())
            if info["success"] and rec["first"] < 0:
                rec["first"] = t + 1
                rec["gap"] = p.finger_gap()
            if trunc:
                break
        rec["success"] = rec["first"] > 0
        rec["pushed"] = math.hypot(*(p.capsule[:2] - c0[:2]))
        rec["phases"] = "".join(ph[0] for ph in phases)
        out.append(rec)
    return out


def summary(name: str, recs: list[dict[str, Any]]) -> dict[str, Any]:
    """Print and return the figures of one start set."""
    n = len(recs)
    ok = [r for r in recs if r["success"]]
    firsts = np.array([r["first"] for r in ok])
    pushed = sum(r["pushed"] > PUSHED for r in recs)
    res: dict[str, Any] = {
        "episodes": n,
        "success": wilson_interval(len(ok), n).__dict__,
        "pushed_share": pushed / n,
        "first_success_median": float(np.median(firsts)) if len(ok) else None,
        "first_success_p90": float(np.percentile(firsts, 90)) if len(ok) else None,
        "gap_at_success_median": float(np.median([r["gap"] for r in ok])) if ok else None,
    }
    print(f"{name}: success {wilson_interval(len(ok), n)} over {n} episodes; capsule pushed > 3 cm in {pushed / n:.0%}")
    if ok:
        print(f"  first success at step {np.median(firsts):.0f} (median), {np.percentile(firsts, 90):.0f} (90th pct); "
              f"finger gap then {res['gap_at_success_median'] * 100:.1f} cm (median)")  # fmt: skip
    fails = [r for r in recs if not r["success"]]
    if fails:
        kinds = {
            "pushed > 3 cm": sum(r["pushed"] > PUSHED for r in fails),
            "waited (capsule out of reach or rolling) most of the episode": sum(r["phases"].count("w") > 50 for r in fails),
            "closing at the end": sum(r["phases"].endswith("c") for r in fails),
        }
        res["failures"] = kinds
        print(f"  failures {len(fails)}: " + ", ".join(f"{k} {v}" for k, v in kinds.items()))
    by_clearance = {}
    for name, lo, hi in (("under 1 cm", -1.0, 0.01), ("1 cm or more", 0.01, 1.0)):
        part = [r for r in recs if lo <= r["clear0"] < hi]
        if part:
            by_clearance[name] = {"episodes": len(part), "success": sum(r["success"] for r in part) / len(part)}
    res["by_start_clearance"] = by_clearance
    print("  success by start clearance: " + ", ".join(f"{k} {v['success']:.2f} ({v['episodes']})"
                                                        for k, v in by_clearance.items()))  # fmt: skip
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bank", default=str(DEFAULT_BANK) if DEFAULT_BANK.exists() else None)
    ap.add_argument("--no-bank", action="store_true")
    ap.add_argument("--first-version", action="store_true", help="the controller's first version (keep_clear=False)")
    ap.add_argument("--escape-clearance", type=float, default=0.0,
                    help="ScriptedGraspConfig.escape_clearance, metres (0: off, the default expert)")  # fmt: skip
    ap.add_argument("--out", default=None, help="write the figures as JSON here")
    args = ap.parse_args()
    try:
        config = ScriptedGraspConfig(keep_clear=not args.first_version, escape_clearance=args.escape_clearance)
    except ValueError as e:
        ap.error(str(e))
    report: dict[str, Any] = {}
    t0 = time.perf_counter()
    report["own"] = summary("own starts (GRIPPER_START)", run_episodes(None, args.episodes, args.steps, args.seed, config))
    if args.bank and not args.no_bank:
        recs = run_episodes(args.bank, args.episodes, args.steps, args.seed, config)
        report["bank"] = summary(f"bank {args.bank}", recs)
        feasible = [r for r in recs if r["reach0"] <= 0.36 and r["speed0"] <= 0.1]
        rest = [r for r in recs if not (r["reach0"] <= 0.36 and r["speed0"] <= 0.1)]
        if feasible:
            report["bank_within_reach_at_rest"] = summary("  bank, capsule within reach and at rest", feasible)
        if rest:
            report["bank_out_of_reach_or_rolling"] = summary("  bank, capsule out of reach or rolling", rest)
    print(f"wall time {time.perf_counter() - t0:.0f} s")
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
