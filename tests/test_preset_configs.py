"""Every preset keeps the settings its runs ran with: each run's config (its first seed's, with the run's budget) equals
the snapshot in ``tests/data/preset_configs.json``, whatever TrainConfig's own defaults are (the presets pin the paper's
settings, ``hrlp.experiments.presets.PAPER_SETTINGS``, and a finished run is found again by its config).

The snapshot was written before the defaults changed (issue 17). A preset whose settings change on purpose is written
again with ``python tests/test_preset_configs.py --write`` (runs whose saved configs still read back as they are now keep
their saved lines), and the diff of the JSON file shows what changed.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

SNAPSHOT = Path(__file__).parent / "data" / "preset_configs.json"


def preset_configs() -> dict[str, Any]:
    """``{preset: {"seeds": [...], "runs": {run: config}}}``: each run's config as its first seed runs it, through JSON."""
    from hrlp.experiments.presets import PRESETS

    out = {
        name: {"seeds": list(p.seeds), "runs": {r.name: p.config(r, p.seeds[0]).to_json() for r in p.runs}}
        for name, p in PRESETS.items()
    }
    return json.loads(json.dumps(out))


def _dump(configs: dict[str, Any]) -> str:
    """The snapshot's text: one line per run's config, so that a diff names the run whose settings changed."""
    lines = ["{"]
    for i, (name, p) in enumerate(configs.items()):
        lines.append(f"  {json.dumps(name)}: {{")
        lines.append(f'    "seeds": {json.dumps(p["seeds"])},')
        lines.append('    "runs": {')
        runs = list(p["runs"].items())
        lines += [f"      {json.dumps(r)}: {json.dumps(c, sort_keys=True)}{',' if j < len(runs) - 1 else ''}"
                  for j, (r, c) in enumerate(runs)]  # fmt: skip
        lines.append("    }")
        lines.append("  }" + ("," if i < len(configs) - 1 else ""))
    lines.append("}")
    return "\n".join(lines) + "\n"


def test_every_presets_configs_equal_the_snapshot():
    saved = json.loads(SNAPSHOT.read_text())
    now = preset_configs()
    assert list(now) == list(saved), "presets added or removed: write the snapshot again (see the module's docstring)"
    for name, preset in saved.items():
        assert now[name]["seeds"] == preset["seeds"], name
        assert list(now[name]["runs"]) == list(preset["runs"]), name
        for run, config in preset["runs"].items():
            # Read back as the runner finds a finished run's config: a setting added since the snapshot takes the value
            # the runs were made with (TrainConfig.from_json), e.g. backend "serial".
            assert now[name]["runs"][run] == _read_back(config), f"{name} / {run}"


def _read_back(config: dict[str, Any]) -> dict[str, Any]:
    from hrlp.config import TrainConfig

    return json.loads(json.dumps(TrainConfig.from_json(config).to_json()))


def test_a_setting_added_after_the_snapshot_reads_back_as_the_runs_ran():
    saved = json.loads(SNAPSHOT.read_text())
    config = saved["shipped-skills"]["runs"]["reacher"]
    assert "backend" not in config  # the snapshot predates the batched backend
    assert _read_back(config)["backend"] == "serial"


#: Runs added after the defaults became the fast ones, and trained with them (in one process): the snapshot pins those.
FAST_DEFAULT_RUNS = (
    {
        ("shipped-skills", r)
        for r in ("reacher-handover", "gripper-claw", "gripper-clearance", "gripper-recovery", "gripper-recovery-2")
    }
    | {("reach-and-move-chained", f"reacher-handover+gripper-imitated+mover-held,target_coeff={c},chained") for c in (1, 10)}
    | {("reach-and-move-samples", "manager:reacher-handover+gripper-imitated+mover-held,chained")}
)


def test_the_snapshot_pins_one_process_and_the_papers_update():
    # What the presets ran with before the defaults became the fast ones: one process, exact Fisher products, the
    # baseline by modular_rl's 25 L-BFGS iterations on the whole batch.
    for name, preset in json.loads(SNAPSHOT.read_text()).items():
        if name in OFF_POLICY_PRESETS:  # SAC: its own settings, pinned below
            continue
        for run, config in preset["runs"].items():
            fast = (name, run) in FAST_DEFAULT_RUNS
            assert config["workers"] == 1 and config["num_envs"] == (64 if fast else 16)
            assert config["trpo"]["fisher_fraction"] == (0.1 if fast else 1.0)
            assert (config["value"]["max_iter"], config["value"]["fraction"]) == ((10, 0.25) if fast else (25, 1.0))


#: Presets of SAC runs (the Fetch domain): no TRPO settings to pin, four environments, one process.
OFF_POLICY_PRESETS = ("fetch-skills", "fetch")


def test_the_off_policy_presets_pin_sac_in_one_process():
    saved = json.loads(SNAPSHOT.read_text())
    for name in OFF_POLICY_PRESETS:
        for config in saved[name]["runs"].values():
            assert config["algo"] == "sac" and config["workers"] == 1 and config["num_envs"] == 4


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit(f"usage: python {sys.argv[0]} --write  (rewrites {SNAPSHOT} from the presets as they are now)")
    saved = json.loads(SNAPSHOT.read_text())
    now = preset_configs()
    for name, preset in now.items():  # a run whose saved config still reads back as it is now keeps its saved line
        old = saved.get(name, {}).get("runs", {})
        for run, config in preset["runs"].items():
            if run in old and _read_back(old[run]) == config:
                preset["runs"][run] = old[run]
    SNAPSHOT.write_text(_dump(now))
    print(f"wrote {SNAPSHOT}")
