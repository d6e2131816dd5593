"""results.csv as the report reads it (every row checked before any is counted), the shape paths an experiment
directory stores, and the launcher's late additions to summary.json: plain code on files of the test's own."""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import pytest

from swarm_ros.app.report_stats import group_stats, time_and_accuracy
from swarm_ros.app.results_file import ExperimentError, read_results, stored_shape_file
from swarm_ros.artifacts.run_dir import OutputError, fill_summary

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
PILOT = ROOT / "docs" / "results" / "head_to_head_pilot" / "results.csv"  # real rows, both algorithms


def _rows() -> list[dict]:
    return list(csv.DictReader(io.StringIO(PILOT.read_text())))


def _write(path: Path, rows: list[dict], end: str = "\n") -> Path:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator=end)
    writer.writeheader()
    writer.writerows(rows)
    path.write_text(buf.getvalue(), newline="")
    return path


def test_the_committed_results_read_whole(tmp_path):
    rows = read_results(PILOT)
    assert len(rows) == 18 and {r["algorithm"] for r in rows} == {"darr-niazi", "rubenstein"}


def test_a_file_saved_with_crlf_line_ends_reads_the_same(tmp_path):
    assert read_results(_write(tmp_path / "results.csv", _rows(), end="\r\n")) == read_results(PILOT)


def test_a_run_listed_twice_is_refused_naming_both_lines(tmp_path):
    rows = _rows()
    path = _write(tmp_path / "results.csv", [*rows, rows[12]])
    with pytest.raises(ExperimentError, match=r"line 20: the run of line 14 again \(rectangle, 442 robots"):
        read_results(path)


def test_a_last_line_cut_short_is_refused_not_dropped(tmp_path):
    path = tmp_path / "results.csv"
    text = PILOT.read_text()
    path.write_text(text + text.splitlines()[1][:40])
    with pytest.raises(ExperimentError, match=r"line 20: cut short .*run the experiment again to resume it"):
        read_results(path)


@pytest.mark.parametrize(
    "edit,message",
    [
        ({"coverage": "7.5"}, "coverage must be a share between 0 and 1, got 7.5"),
        ({"hole_filled": "1.5"}, "hole_filled must be a share between 0 and 1, got 1.5"),
        ({"coverage": "0.1"}, "outcome complete needs the whole shape covered, got coverage 0.1"),
        (
            {"empty_patches": "3"},
            "outcome complete needs the whole shape covered, got coverage 1.0 and empty_patches 3",
        ),
        ({"localized": "400"}, "localized + unlocalized + lost_robots must be the 442 robots, got 400"),
        ({"empty_patches": "500", "outcome": "incomplete"}, "empty_patches must be at most the shape's 442"),
        ({"fill_50_tick": "900"}, "fill_50_tick, fill_90_tick and convergence_tick must come in that order"),
    ],
)
def test_measures_that_contradict_each_other_are_refused_naming_the_line(tmp_path, edit, message):
    rows = _rows()
    assert rows[12]["outcome"] == "complete" and rows[12]["robots"] == "442"  # rectangle, darr-niazi, repetition 0
    rows[12].update(edit)
    with pytest.raises(ExperimentError, match=re.escape(f"line 14: {message}")):
        read_results(_write(tmp_path / "results.csv", rows))


def test_time_and_accuracy_gives_each_mean_its_confidence_interval_and_how_many_runs_reached_a_time(tmp_path):
    rows = _rows()
    square = [r for r in rows if r["shape"] == "square9" and r["algorithm"] == "rubenstein"]
    square[0]["fill_90_tick"] = ""  # one of three runs did not reach 90%
    square[0]["outcome"] = "timeout"
    stats = group_stats(read_results(_write(tmp_path / "results.csv", rows)))
    line = next(x for x in time_and_accuracy(stats) if x.startswith("| square9 | 81 | rubenstein |"))
    cells = [c.strip() for c in line.split("|")[1:-1]]
    t50, t90, filled = cells[5], cells[6], cells[8]
    assert " ± " in t50 and "of" not in t50  # all three reached it
    assert t90.endswith("(2 of 3)") and " ± " in t90
    assert filled.endswith("%") and " ± " in filled


def test_an_experiment_stores_a_shape_files_path_relative_to_the_working_directory_under_it(tmp_path, monkeypatch):
    shape = tmp_path / "config" / "shapes" / "ring9.txt"
    monkeypatch.chdir(tmp_path)
    assert stored_shape_file(str(shape)) == "config/shapes/ring9.txt"  # as from a repository's root
    assert stored_shape_file("star") == "star"  # a built-in by its name
    elsewhere = tmp_path.parent / "other" / "ring9.txt"
    assert stored_shape_file(str(elsewhere)) == str(elsewhere.resolve())  # not under it: absolute


def test_the_launcher_lists_a_restart_the_monitor_did_not_at_the_tick_it_happened(tmp_path):
    """A rubenstein batch restarted at tick 3,094 of a run that ended at 8,032 is listed at 3,094, in tick order
    among the monitor's own (which stay), and processes, null in what the monitor wrote, is filled."""
    summary = {
        "convergence_tick": 8032,
        "restarts": [{"tick": 5000, "node": "monitor"}],
        "processes": None,
        "shutdown_seconds": None,
    }
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    restarted = [(5000, "monitor"), (3094, "robot_batch_1"), (9000, "robot_batch_0")]
    assert fill_summary(tmp_path, restarted, processes=2)
    after = json.loads((tmp_path / "summary.json").read_text())
    assert after["restarts"] == [
        {"tick": 3094, "node": "robot_batch_1"},
        {"tick": 5000, "node": "monitor"},
        {"tick": 8032, "node": "robot_batch_0"},  # after the run's result was whole: at its last tick
    ]
    assert after["processes"] == 2 and after["shutdown_seconds"] is None
    assert not fill_summary(tmp_path, restarted, processes=3), "nothing left to fill"


def test_a_summary_the_launcher_cannot_fill_is_an_error_naming_it_and_left_as_it_was(tmp_path):
    """A fresh clone's suite once found processes null after a run that passed every other check: the launcher's
    fill had failed unsaid. Now it says why (the launcher warns with it)."""
    (tmp_path / "summary.json").write_text('{"processes": null, "restarts": [')
    with pytest.raises(OutputError, match=r"summary.json: could not fill in processes: "):
        fill_summary(tmp_path, [], processes=2)
    assert (tmp_path / "summary.json").read_text() == '{"processes": null, "restarts": ['
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]
