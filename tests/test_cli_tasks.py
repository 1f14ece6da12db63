"""`grail-bench tasks`."""

from __future__ import annotations

from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app


def test_tasks_lists_every_id():
    result = CliRunner().invoke(app, ["tasks"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    for task_id in grail_bench.task_ids():
        assert task_id in result.output
    assert "suboptimal" in result.output and "(5,7)" in result.output
