"""The `hrlp` command's listing and its errors."""

from typer.testing import CliRunner

from hrlp.cli import app
from hrlp.envs import TASKS


def test_tasks_lists_every_registered_id():
    result = CliRunner().invoke(app, ["tasks"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    for spec in TASKS.values():
        assert spec.env_id in result.output
