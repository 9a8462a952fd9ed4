"""``hrlp tables`` never replaces a file it did not write unless asked to (docs/reliability.md, item 8)."""

import csv
import json

from typer.testing import CliRunner

from hrlp.cli import app
from hrlp.experiments.presets import PRESETS
from hrlp.experiments.runner import run_dir_name
from hrlp.experiments.tables import MANIFEST, build_tables, read_manifest

PRESET = "reachers"


def write_runs(root):
    """Finished runs of one preset as runner.py lays them out: result.json (full config) and progress.csv."""
    preset = PRESETS[PRESET]
    for run in preset.runs[:2]:
        for seed in (0, 1):
            d = root / PRESET / run_dir_name(run.name) / f"s{seed}"
            d.mkdir(parents=True)
            with (d / "progress.csv").open("w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["iteration", "env_steps", "episodes", "return_mean", "success_rate", "target_dist_sum"])
                for i in range(1, 4):
                    w.writerow([i, i * 1000, 10, -100 + i, 0.1 * i, "nan"])
            result = {"preset": PRESET, "run": run.name, "seed": seed, "config": preset.config(run, seed).to_json(),
                      "env_steps": 3000, "wall_s": 60.0, "episodes": 10, "success": {"mean": 0.5, "low": 0.2, "high": 0.8},
                      "return": {"mean": -50.0, "low": -60.0, "high": -40.0}, "target_dist_sum": None,
                      "macro_usage": None, "paper": run.paper}  # fmt: skip
            (d / "result.json").write_text(json.dumps(result))


def invoke(*args):
    return CliRunner().invoke(app, list(args))


def test_tables_refuse_to_replace_files_they_did_not_write(tmp_path):
    root, out = tmp_path / "runs", tmp_path / "results"
    write_runs(root)
    out.mkdir()
    committed = {f"{PRESET}.md": "# hand-written results\n", "README.md": "# notes\n"}
    for name, text in committed.items():
        (out / name).write_text(text)
    r = invoke("tables", "--root", str(root), "--out", str(out))
    assert r.exit_code == 2
    lines = [line for line in r.output.splitlines() if line.strip()]
    assert lines == [f"error: {out}: would replace {PRESET}.md, which hrlp tables did not write there (or which changed "
                     "since); pass --overwrite to replace them, or choose another --out"]  # fmt: skip
    assert sorted(p.name for p in out.iterdir()) == ["README.md", f"{PRESET}.md"]  # nothing written at all
    assert (out / f"{PRESET}.md").read_text() == committed[f"{PRESET}.md"]
    # Asked to, it replaces them and records what it wrote; from then on it rebuilds its own files without asking.
    r = invoke("tables", "--root", str(root), "--out", str(out), "--overwrite")
    assert r.exit_code == 0, r.output
    assert (out / f"{PRESET}.md").read_text().startswith(f"# {PRESET}")
    assert sorted(read_manifest(out)) == [f"{PRESET}.md", f"{PRESET}.png"]
    assert invoke("tables", "--root", str(root), "--out", str(out)).exit_code == 0
    assert (out / "README.md").read_text() == committed["README.md"]  # never one of its files
    # A file edited by hand since is not its own any more.
    (out / f"{PRESET}.md").write_text((out / f"{PRESET}.md").read_text() + "\nA note added by hand.\n")
    r = invoke("tables", "--root", str(root), "--out", str(out))
    assert r.exit_code == 2 and "would replace reachers.md" in r.output
    assert (out / f"{PRESET}.md").read_text().endswith("A note added by hand.\n")


def test_the_next_step_reproduce_prints_leaves_committed_results_alone(tmp_path, monkeypatch):
    # `hrlp reproduce` ends with "tables: hrlp tables --root OUT"; run where docs/results holds committed files.
    root = tmp_path / "runs" / "reproduce"
    write_runs(root)
    monkeypatch.chdir(tmp_path)
    docs = tmp_path / "docs" / "results"
    docs.mkdir(parents=True)
    (docs / f"{PRESET}.md").write_text("committed\n")
    for _ in range(2):  # and again: it rebuilds its own files
        r = invoke("tables", "--root", "runs/reproduce")
        assert r.exit_code == 0, r.output
        assert f"wrote runs/reproduce/tables/{PRESET}.md" in r.output
    assert (docs / f"{PRESET}.md").read_text() == "committed\n"
    assert (root / "tables" / MANIFEST).is_file()
    # The runs under ROOT are still found with the tables beside them.
    assert [p.name for p in build_tables(root, root / "tables")] == [f"{PRESET}.md", f"{PRESET}.png"]
