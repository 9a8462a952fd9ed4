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
