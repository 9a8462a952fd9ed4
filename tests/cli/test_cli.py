"""The `hrlp` command's listing and its errors."""

from typer.testing import CliRunner

from hrlp.arm import TASKS
from hrlp.cli import app


def test_tasks_lists_every_registered_id():
    result = CliRunner().invoke(app, ["tasks"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    for spec in TASKS.values():
        assert spec.env_id in result.output


def test_theory_command_prints_a_table_per_statement_and_rejects_bad_input(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["theory", "--mdps", "2", "--seed", "1", "--out", str(tmp_path)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "Lemma 1" in result.output and "Theorem 1" in result.output and "Corollary 1" in result.output
    bad = runner.invoke(app, ["theory", "--mdps", "0"])
    assert bad.exit_code == 2 and "--mdps must be a positive integer" in bad.output


def test_presets_and_skills_read_at_80_columns_one_line_each(monkeypatch):
    import io

    from rich.console import Console

    from hrlp import cli
    from hrlp.experiments.presets import PRESETS, RESEARCH_PRESETS

    assert RESEARCH_PRESETS < PRESETS.keys()
    manual = len(PRESETS) - len(RESEARCH_PRESETS)
    for args, entries in ((["presets"], manual + 1), (["presets", "--all"], len(PRESETS)), (["skills", "list"], None)):
        buf = io.StringIO()
        monkeypatch.setattr(cli, "console", Console(file=buf, force_terminal=True, width=80, color_system=None))
        assert CliRunner().invoke(app, args).exit_code == 0
        lines = buf.getvalue().splitlines()
        assert max(map(len, lines)) <= 80, args
        if entries is not None:  # a title, a header and one line per preset (and one naming those not listed)
            assert len(lines) == entries + 2 and lines[2].startswith("shipped-skills ") and lines[2].endswith("…")
            listed = {line.split()[0] for line in lines[2:]}
            assert ("reach-and-grip-2-chained" in listed) == ("--all" in args)
            assert "reach-and-grip-2-chained-recovery-2" in listed
            footer = f"and {len(RESEARCH_PRESETS)} presets of the research record"
            assert lines[-1].startswith(footer) != ("--all" in args)
    monkeypatch.undo()
    research = CliRunner().invoke(app, ["presets", "reach-and-grip-2-tuned"])
    assert research.exit_code == 0 and "kept for the research record" in research.output
    r = CliRunner().invoke(app, ["presets", "reach-and-grip-1"])
    assert r.exit_code == 0 and "gripper+reacher,c2=3,tr=0.03" in r.output and "hrlp reproduce reach-and-grip-1" in r.output
    bad = CliRunner().invoke(app, ["presets", "nope"])
    assert bad.exit_code != 0 and "no preset 'nope'" in bad.output and "Traceback" not in bad.output


def test_skills_build_names_its_recipes_and_refuses_another_preset_in_one_line(tmp_path):
    r = CliRunner().invoke(app, ["skills", "build", "--library", str(tmp_path / "lib"), "--preset", "fetch"])
    assert r.exit_code != 0 and "--preset 'fetch' is not a skill recipe (recipes: shipped-skills, fetch-skills)" in r.output
    r = CliRunner().invoke(app, ["skills", "build", "--library", str(tmp_path / "lib"), "--preset", "fetch-skills",
                                 "--only", "nothing"])  # fmt: skip
    assert r.exit_code != 0 and "--only: no recipe for nothing (recipes: fetch-reach)" in r.output


def test_the_fetch_stack_check_names_what_is_missing_or_too_new(monkeypatch):
    import importlib.metadata

    import pytest

    from hrlp.fetch import check_installed

    real = importlib.metadata.version

    def version(name: str, mujoco: str, robotics: bool) -> str:
        if name == "gymnasium-robotics" and not robotics:
            raise importlib.metadata.PackageNotFoundError(name)
        return mujoco if name == "mujoco" else real(name) if name != "gymnasium-robotics" else "1.4.2"

    for mujoco, robotics, message in (("3.11.0", False, 'Fetch needs Gymnasium-Robotics: pip install "hrlp\\[fetch\\]"'),
                                      ("3.12.0", True, "fails at reset on mujoco 3.12.0 \\(from 3.12 on\\)"),
                                      ("4.0.1", True, "fails at reset on mujoco 4.0.1")):  # fmt: skip
        monkeypatch.setattr(importlib.metadata, "version", lambda n, m=mujoco, r=robotics: version(n, m, r))
        with pytest.raises(ValueError, match=message):
            check_installed()
    monkeypatch.setattr(importlib.metadata, "version", lambda n: version(n, "3.11.0", True))
    check_installed()
