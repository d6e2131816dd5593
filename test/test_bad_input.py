"""Every row of docs/bad_input.md that runs the command line, run as written in this process: one line, exit 2,
nothing written, and no process started (the ``unit`` marker refuses one: conftest). The rows that start a node
(``ros2 run swarm_ros ...``) run in test_ros_graph.py, each a process of its own."""

from __future__ import annotations

import re
import shlex

import pytest
from bad_inputs import ROOT, fixtures_for, listing, split_assignments, starts_node, table

from swarm_ros.app import cli

pytestmark = pytest.mark.unit

CLI_ROWS = [row for row in table() if not starts_node(row[1])]


def test_the_table_has_at_least_20_rows_numbered_in_order():
    rows = table()
    assert len(rows) >= 20
    assert [int(n) for n, _, _ in rows] == list(range(1, len(rows) + 1))


def test_the_usage_page_counts_the_rows_of_the_table():
    said = re.search(
        r"\[bad_input\.md\]\(bad_input\.md\)\s+lists\s+(\d+) bad inputs", (ROOT / "docs" / "usage.md").read_text()
    )
    assert said and int(said.group(1)) == len(table())


@pytest.mark.parametrize("number,command,message", CLI_ROWS, ids=[f"row{n}" for n, _, _ in CLI_ROWS])
def test_bad_input_row(tmp_path, bad_input_files, monkeypatch, capsys, number, command, message):
    fixtures_for(command, bad_input_files, tmp_path)
    before = listing(tmp_path)
    words = shlex.split(command)
    for name, value in split_assignments(words).items():
        monkeypatch.setenv(name, value)
    assert words[0] == "swarm-ros", f"row {number}: a row runs swarm-ros or ros2 run swarm_ros"
    monkeypatch.chdir(tmp_path)
    code, err = cli.main(words[1:]), capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("swarm-ros: error: ") and err.count("\n") == 1, err
    assert message in err, err
    assert listing(tmp_path) == before, "bad input wrote something"
