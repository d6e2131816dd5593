"""swarm-ros experiment and report: the grid, seeds, parallel runs, resume, statistics, figures, bad configs."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from graph_runs import children_of
from runs import small_config
from waiting import wait_for

from swarm_ros.app import cli
from swarm_ros.app.experiment_file import load_experiment, run_seed
from swarm_ros.app.published import ReferenceFileError, load_reference
from swarm_ros.app.report_stats import group_stats
from swarm_ros.app.results_file import RESULT_COLUMNS, ExperimentError, read_results
from swarm_ros.core.rubenstein.run import RubensteinRun

pytestmark = pytest.mark.process

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable


def experiment(config: Path, out: Path, *extra: str) -> int:
    return cli.main(["experiment", str(config), "--out", str(out), "--quiet", *extra])


def rows_without_timing(out: Path) -> list[dict]:
    rows = read_results(out / "results.csv")
    for r in rows:
        r.pop("wall_seconds")
    return sorted(rows, key=lambda r: (r["shape"], r["robots"], r["vision_radius"], r["rules"], r["repetition"]))


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> tuple[Path, Path]:
    """(config, experiment directory) of the small grid, run with 2 jobs."""
    base = tmp_path_factory.mktemp("exp")
    config = small_config(base)
    out = base / "out"
    assert experiment(config, out, "--jobs", "2") == 0
    return config, out


# -- the grid and its seeds --------------------------------------------------------


def test_paper_protocol_file_is_the_studys_grid():
    exp = load_experiment(ROOT / "config/experiments/paper.yaml")
    runs = exp.runs()
    assert len(runs) == 6 * 6 * 10 and exp.vision_radius == (1.0,) and exp.repetitions == 10
    assert exp.rules == ("paper",) and exp.reference == "study_reference.csv"
    sizes = {name: sizes for name, _, _, sizes in exp.shapes}
    assert sizes["star"] == (1025, 1030, 1035, 1036, 1040, 1045)
    assert sizes["wrench"] == (500, 525, 550, 565, 575, 600)
    assert all(patches in sizes[name] for name, _, patches, _ in exp.shapes)
    assert len({r.seed for r in runs}) == len(runs)


def test_the_experiments_name_survives_a_list_of_rule_sets(tmp_path, monkeypatch):
    """The name (not the last rule set) names experiment.json and the default directory experiments/<name>."""
    assert load_experiment(ROOT / "config/experiments/rules.yaml").name == "rules"
    config = small_config(
        tmp_path, name="tiny", rules=["paper", "literal"], vision_radius=1, repetitions=1, shapes={"disc.txt": [50]}
    )
    assert load_experiment(config).name == "tiny"
    monkeypatch.chdir(tmp_path)
    assert cli.main(["experiment", str(config), "--quiet"]) == 0
    assert json.loads((tmp_path / "experiments/tiny/experiment.json").read_text())["experiment"]["name"] == "tiny"
    assert sorted(p.name for p in (tmp_path / "experiments").iterdir()) == ["tiny"]


def test_rules_study_file_crosses_every_rule_set_with_three_radii_at_the_patch_counts():
    exp = load_experiment(ROOT / "config/experiments/rules.yaml")
    runs = exp.runs()
    assert exp.rules == ("paper", "local", "literal") and exp.vision_radius == (1.0, 2.0, 3.0)
    assert len(runs) == 6 * 3 * 3 * 10
    assert all(sizes == (patches,) for _, _, patches, sizes in exp.shapes)
    # common random numbers: the rule sets of one coordinate share its seed
    seeds = {}
    for r in runs:
        seeds.setdefault((r.shape, r.robots, r.vision_radius, r.repetition), set()).add(r.seed)
    assert all(len(v) == 1 for v in seeds.values()) and len(seeds) == len(runs) // 3


def test_the_shipped_reference_holds_the_published_numbers():
    ref = load_reference(ROOT / "config/experiments/study_reference.csv")
    assert list(ref) == ["star", "wrench", "k-letter", "rectangle", "tyre", "spinner"]
    star, k = ref["star"], ref["k-letter"]
    assert (star.study_robots, star.mean, star.ci95_low, star.ci95_high) == (1036, 861.8, 599.1, 1124.49)
    assert (k.study_robots, k.sizes_mean_min, k.sizes_mean_max) == (1352, 14.6, 702.7)
    assert [r.study_robots for r in ref.values()] == [1036, 566, 1352, 438, 1282, 1040]


def test_a_runs_seed_depends_only_on_the_experiment_seed_and_its_coordinates(tmp_path):
    a = {r.key: r.seed for r in load_experiment(small_config(tmp_path)).runs()}
    b = {r.key: r.seed for r in load_experiment(small_config(tmp_path, vision_radius=[1.5], repetitions=5)).runs()}
    shared = a.keys() & b.keys()
    assert len(shared) == 9 and all(a[k] == b[k] for k in shared)
    c = load_experiment(small_config(tmp_path, seed=12)).runs()
    assert all(a[r.key] != r.seed for r in c)
    assert run_seed(11, "disc", 50, 1.0, 0) == a[("disc", 50, "darr-niazi", 1.0, "paper", 0)]


# -- running -----------------------------------------------------------------------


def test_experiment_writes_results_stats_and_figures(small):
    config, out = small
    rows = read_results(out / "results.csv")
    assert len(rows) == 3 * 2 * 3 and list(next(csv.reader((out / "results.csv").open()))) == list(RESULT_COLUMNS)
    patches = rows[0]["shape_patches"]
    assert patches == 69 and {r["robots"] for r in rows} == {50, 69, 80}
    assert {r["engine"] for r in rows} == {"inprocess"}
    for r in (r for r in rows if r["vision_radius"] == 1):  # what the study found, on a small disc
        if r["robots"] < patches:
            assert r["outcome"] == "incomplete" and r["empty_patches"] == patches - r["robots"]
        elif r["robots"] > patches:
            assert r["outcome"] == "complete_with_extras" and r["separated"] == r["robots"] - patches
    stats = list(csv.DictReader((out / "stats.csv").open()))
    assert len(stats) == 6 and all(s["runs"] == "3" for s in stats)
    md = (out / "stats.md").read_text()
    assert "| shape | patches | robots | runs | mean time (ticks) | 95% CI |" in md
    assert md.count("| disc | 69 |") == 8 and "### Rules `paper`, vision radius 1.5" in md
    assert "Against the published numbers" not in md  # no reference file
    figures = sorted(p.name for p in (out / "figures").iterdir())
    assert figures == [
        "all_shapes_paper_v1.5.png",
        "all_shapes_paper_v1.png",
        "disc_paper_v1.5.png",
        "disc_paper_v1.png",
        "vision.png",
    ]
    assert all((out / "figures" / f).read_bytes()[:4] == b"\x89PNG" for f in figures)


def test_results_do_not_depend_on_the_number_of_jobs(small, tmp_path):
    config, out = small
    one = tmp_path / "one"
    assert experiment(config, one, "--jobs", "1") == 0
    assert rows_without_timing(one) == rows_without_timing(out)


def test_report_rebuilds_tables_and_figures_from_the_results_file_alone(small, tmp_path, capsys):
    _, out = small
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "results.csv").write_bytes((out / "results.csv").read_bytes())
    assert cli.main(["report", str(copy)]) == 0
    assert (copy / "stats.csv").read_bytes() == (out / "stats.csv").read_bytes()
    assert (copy / "stats.md").read_bytes() == (out / "stats.md").read_bytes()
    assert sorted(p.name for p in (copy / "figures").iterdir()) == sorted(p.name for p in (out / "figures").iterdir())
    assert str(copy / "stats.md") in capsys.readouterr().out


def test_rerunning_a_finished_experiment_runs_nothing_again(small, capsys):
    config, out = small
    before = (out / "results.csv").read_bytes()
    assert cli.main(["experiment", str(config), "--out", str(out)]) == 0
    assert (out / "results.csv").read_bytes() == before
    assert "resuming: 18 of 18 runs already" in capsys.readouterr().err


def test_an_experiment_written_before_the_algorithm_axis_resumes_and_its_results_are_upgraded(small, tmp_path, capsys):
    """A directory of the previous version (results.csv without the algorithm and the comparison's columns,
    experiment.json without the axis) resumes with nothing to run; its results.csv is rewritten with the new
    columns, the study's model's rows completed (share filled from their counts, no fill ticks)."""
    from swarm_ros.app.results_file import PREVIOUS_COLUMNS

    config, out = small
    copy = tmp_path / "old"
    copy.mkdir()
    record = json.loads((out / "experiment.json").read_text())
    del record["experiment"]["algorithm"]
    (copy / "experiment.json").write_text(json.dumps(record))
    rows = list(csv.DictReader((out / "results.csv").open()))
    old = [",".join(PREVIOUS_COLUMNS)] + [",".join(r[c] for c in PREVIOUS_COLUMNS) for r in rows]
    (copy / "results.csv").write_text("\n".join(old) + "\n")
    assert experiment(config, copy) == 0
    assert (copy / "results.csv").read_text().split("\n", 1)[0] == ",".join(RESULT_COLUMNS)
    upgraded = read_results(copy / "results.csv")
    assert len(upgraded) == len(rows) and all(r["algorithm"] == "darr-niazi" for r in upgraded)
    assert all(r["fill_50_tick"] is None and r["coverage"] == r["localized"] / r["shape_patches"] for r in upgraded)
    assert [r["convergence_tick"] for r in upgraded] == [int(r["convergence_tick"]) for r in rows]


def test_a_line_cut_short_by_a_crash_is_dropped_and_its_run_redone(small, tmp_path):
    config, out = small
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("results.csv", "experiment.json"):
        (copy / name).write_bytes((out / name).read_bytes())
    lines = (out / "results.csv").read_text().splitlines(keepends=True)
    (copy / "results.csv").write_text("".join(lines[:-2]) + lines[-2][:25])  # 2 runs lost, one half-written
    assert experiment(config, copy) == 0
    assert rows_without_timing(copy) == rows_without_timing(out)


def test_ctrl_c_keeps_finished_runs_and_the_same_command_resumes(small, tmp_path):
    config, out = small
    big = small_config(tmp_path, repetitions=40)  # 240 runs, the first 3 repetitions are the small grid
    run_dir = tmp_path / "run"
    cmd = [PY, "-m", "swarm_ros", "experiment", str(big), "--out", str(run_dir), "--jobs", "2"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    results = run_dir / "results.csv"
    wait_for(lambda: results.exists() and len(results.read_text().splitlines()) > 4, 120, "three finished runs")
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "run the same command again to resume" in err and "Traceback" not in err
    kept = read_results(results)
    assert 3 <= len(kept) < 240
    assert not children_of(proc.pid), "a worker outlived the interrupted experiment"
    done = subprocess.run(cmd + ["--quiet"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    full = read_results(results)
    assert len(full) == 240 and len({(r["robots"], r["vision_radius"], r["repetition"]) for r in full}) == 240
    assert full[: len(kept)] == kept  # the finished runs were kept, not redone
    # the first three repetitions are the small experiment's runs: same coordinates, same seeds, same results
    head = [r for r in rows_without_timing(run_dir) if r["repetition"] < 3]
    small_rows = rows_without_timing(out)
    for r in head + small_rows:
        r.pop("shape_file")  # the same shape, copied into another directory
    assert head == small_rows


# -- rule sets and the published numbers -------------------------------------------


def test_one_experiment_compares_rule_sets_from_the_same_starts_against_a_reference(tmp_path):
    (tmp_path / "ref.csv").write_text(
        "# a made-up published number for the small disc\n"
        "shape,study_robots,mean_ticks,ci95_low,ci95_high,group_sizes,sizes_mean_min,sizes_mean_max\n"
        "disc,70,150.0,100.0,200.0,50-80,20.5,300\n"
    )
    config = small_config(tmp_path, vision_radius=[1], rules=["paper", "literal"], reference="ref.csv")
    out = tmp_path / "out"
    assert experiment(config, out) == 0
    rows = read_results(out / "results.csv")
    assert {(r["rules"], r["join"], r["steps"]) for r in rows} == {
        ("paper", "walk", "one"),
        ("literal", "local", "literal"),
    }
    by_rules = {}
    for r in rows:
        by_rules.setdefault(r["rules"], {})[(r["robots"], r["repetition"])] = r["seed"]
    assert by_rules["paper"] == by_rules["literal"]  # the same starts for both rule sets
    assert (out / "reference.csv").read_bytes() == (tmp_path / "ref.csv").read_bytes()
    stats = {(s["rules"], s["robots"]): s for s in group_stats(rows)}
    md = (out / "stats.md").read_text()
    assert "### Rules `paper`, vision radius 1" in md and "### Rules `literal`, vision radius 1" in md
    section = md[md.index("## Against the published numbers") :]
    for rules in ("paper", "literal"):
        s = stats[(rules, 69)]
        others = [stats[(rules, n)]["mean_convergence_tick"] for n in (50, 80)]
        line = next(ln for ln in section[section.index(f"Rules `{rules}`") :].splitlines() if ln.startswith("| disc"))
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[0] == "disc (70)" and cells[1] == "150 [100, 200]" and cells[2] == "69"
        assert cells[4] == f"{s['mean_convergence_tick'] / 150:.2f}"
        assert cells[5] == ("yes" if 100 <= s["mean_convergence_tick"] <= 200 else "no")
        assert cells[6] == "20.5–300" and cells[7] == f"{min(others):.0f}–{max(others):.0f}"
    figures = sorted(p.name for p in (out / "figures").iterdir())
    assert figures == [
        "all_shapes_literal_v1.png",
        "all_shapes_paper_v1.png",
        "disc_literal_v1.png",
        "disc_paper_v1.png",
        "study.png",
    ]


BAD_REFERENCES = [
    ("shape,mean\nstar,1\n", "expected the columns"),
    (
        "shape,study_robots,mean_ticks,ci95_low,ci95_high,group_sizes,sizes_mean_min,sizes_mean_max\n"
        "star,1036,861.8,900,1124.49,x,1,2\n",
        "the CI must hold the mean",
    ),
    (
        "shape,study_robots,mean_ticks,ci95_low,ci95_high,group_sizes,sizes_mean_min,sizes_mean_max\n"
        "star,1036,lots,1,2,x,1,2\n",
        "not a number",
    ),
    (
        "shape,study_robots,mean_ticks,ci95_low,ci95_high,group_sizes,sizes_mean_min,sizes_mean_max\n"
        "star,1036,5,1,9,x,1,2\nstar,1036,5,1,9,x,1,2\n",
        "listed twice",
    ),
]


@pytest.mark.parametrize("text,message", BAD_REFERENCES, ids=[m for _, m in BAD_REFERENCES])
def test_bad_reference_files_are_refused_with_the_line(tmp_path, capsys, text, message):
    (tmp_path / "ref.csv").write_text(text)
    with pytest.raises(ReferenceFileError, match=message):
        load_reference(tmp_path / "ref.csv")
    config = small_config(tmp_path, reference="ref.csv")
    assert experiment(config, tmp_path / "out") == 2
    err = capsys.readouterr().err
    assert "reference: " in err and message in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


# -- statistics --------------------------------------------------------------------


def test_statistics_match_a_hand_computed_t_interval():
    rows = [
        {
            "shape": "s",
            "shape_patches": 10,
            "robots": 10,
            "vision_radius": 1.0,
            "rules": "paper",
            "join": "walk",
            "crowding": "ahead",
            "steps": "one",
            "convergence_tick": t,
            "outcome": o,
            "localized": 10,
            "unlocalized": 0,
            "separated": 0,
            "empty_patches": 0,
            "lost_robots": 0,
            "convergence_rate": 0.5,
        }
        for t, o in ((10, "complete"), (12, "complete"), (14, "timeout"))
    ]
    (s,) = group_stats(rows)
    # mean 12, sd 2, t(0.975, 2 d.f.) = 4.303 from a printed table: half width 4.303 * 2 / sqrt(3) = 4.969
    assert s["mean_convergence_tick"] == 12 and s["sd_convergence_tick"] == pytest.approx(2.0)
    assert s["ci95_low"] == pytest.approx(12 - 4.969, abs=1e-3) and s["ci95_high"] == pytest.approx(16.969, abs=1e-3)
    assert (s["complete"], s["timeout"], s["incomplete"]) == (2, 1, 0)
    assert s["completed_fraction"] == pytest.approx(2 / 3)
    (one,) = group_stats(rows[:1])
    assert math.isnan(one["sd_convergence_tick"]) and math.isnan(one["ci95_low"])


# -- bad input ---------------------------------------------------------------------

BAD = [
    ({"shapes": {"nope": [10]}}, "shapes.nope: nope: no such shape file or built-in shape"),
    ({"repetitons": 3}, "repetitons: unknown key"),
    ({"shapes": {"disc.txt": [50, -3]}}, "shapes.disc.txt[1]: robots must be an integer >= 5, got -3"),
    ({"shapes": {"disc.txt": [0]}}, "shapes.disc.txt[0]: robots must be an integer >= 5, got 0"),
    ({"shapes": {"disc.txt": []}}, "shapes.disc.txt: must be a non-empty list of group sizes"),
    ({"shapes": {}}, "shapes: must map at least one shape to its group sizes"),
    ({"vision_radius": []}, "vision_radius: no vision_radius given"),
    ({"vision_radius": [1, -2]}, "vision_radius[1]: vision_radius must be a number >= 1 and <= 100, got -2"),
    ({"vision_radius": [1, 0.5]}, "vision_radius[1]: vision_radius must be a number >= 1 and <= 100, got 0.5"),
    ({"vision_radius": 40}, "vision_radius[0]: vision_radius must be <= the world radius 10"),
    ({"fail_fraction": 0.1, "fail_tick": 500, "max_ticks": 400}, "fail_tick must be before max_ticks (400)"),
    ({"repetitions": 0}, "repetitions: repetitions must be an integer >= 1 and <= 1000000, got 0"),
    ({"max_ticks": "many"}, "max_ticks: max_ticks must be an integer >= 1 and <= 1000000000 (0 = 100000 under"),
    ({"shapes": {"disc.txt": [500]}}, "shapes.disc.txt[0]: 500 robots do not fit on the 361 free patches"),
    ({"seed": None}, "seed: seed must be an integer >= 0 and <= 9223372036854775807, got None"),
    ({"rules": ["paper", "fast"]}, "rules[1]: rules must be one of paper, local, literal, got 'fast'"),
    ({"rules": []}, "rules: no rules given"),
    ({"rules": ["local", "local"]}, "rules: lists a value twice"),
    ({"crowding": "ring"}, "crowding: crowding must be one of ahead, disc ('' = the rule set's own), got 'ring'"),
    ({"reference": "absent.csv"}, "reference: "),
]


@pytest.mark.parametrize("over,message", BAD, ids=[m.split(":")[0] for _, m in BAD])
def test_bad_configs_fail_before_any_run_naming_file_and_key(tmp_path, capsys, over, message):
    config = small_config(tmp_path, **over)
    out = tmp_path / "out"
    assert experiment(config, out) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"swarm-ros: error: {config}: ") and message in err and err.count("\n") == 1
    assert not out.exists()


def test_missing_keys_unreadable_files_and_foreign_directories_are_refused(tmp_path, capsys):
    config = small_config(tmp_path)
    data = yaml.safe_load(config.read_text())
    del data["repetitions"]
    (tmp_path / "missing.yaml").write_text(yaml.safe_dump(data))
    (tmp_path / "broken.yaml").write_text("shapes: [\n")
    for path, message in (
        (tmp_path / "missing.yaml", "repetitions: missing"),
        (tmp_path / "broken.yaml", "not valid YAML"),
        (tmp_path / "absent.yaml", "no such experiment file"),
    ):
        assert experiment(path, tmp_path / "out") == 2
        assert message in capsys.readouterr().err
    (tmp_path / "foreign" / "sub").mkdir(parents=True)
    (tmp_path / "foreign" / "notes.txt").write_text("mine")
    (tmp_path / "foreign" / "sub" / "more.txt").write_text("also mine")
    (tmp_path / "foreign" / "results.csv").write_text("a results file of another tool\n")
    before = {p: p.read_bytes() for p in (tmp_path / "foreign").rglob("*") if p.is_file()}
    assert experiment(config, tmp_path / "foreign") == 2
    assert "holds no experiment.json" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in (tmp_path / "foreign").rglob("*") if p.is_file()} == before
    assert experiment(config, Path("/sys/x")) == 2  # unwritable: one line
    assert capsys.readouterr().err.count("\n") == 1
    assert cli.main(["report", str(tmp_path / "foreign")]) == 2
    assert "results.csv: not a swarm-ros results file" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in (tmp_path / "foreign").rglob("*") if p.is_file()} == before


def test_another_experiment_in_the_same_directory_is_refused(small, tmp_path, capsys):
    _, out = small
    other = small_config(tmp_path, seed=99)
    assert experiment(other, out) == 2
    assert "holds the results of a different experiment" in capsys.readouterr().err


def test_read_results_rejects_a_file_that_is_not_a_results_file(tmp_path):
    path = tmp_path / "results.csv"
    path.write_text("a,b\n1,2\n")
    with pytest.raises(ExperimentError, match="not a swarm-ros results file"):
        read_results(path)


def _edited_results(done: Path, out: Path, edit) -> int:
    """A copy of ``done``'s results.csv in a new directory ``out``, its rows (dicts of text) passed through
    ``edit`` first; return how many rows it holds."""
    import csv
    import io

    out.mkdir()
    rows = list(csv.DictReader(io.StringIO((done / "results.csv").read_text())))
    edit(rows)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    (out / "results.csv").write_text(buf.getvalue())
    return len(rows)


@pytest.mark.parametrize(
    "column,value,message",
    [
        ("outcome", "bogus", "outcome must be one of complete, complete_with_extras, incomplete, timeout"),
        ("engine", "gpu", "engine must be one of inprocess, ros2, got 'gpu'"),
        ("robots", "2", "robots must be an integer >= 4"),
        ("rules", "fast", "rules must be one of paper, local, literal, got 'fast'"),
        ("convergence_tick", "-3", "convergence_tick must be a number >= 0, got '-3'"),
        ("wall_seconds", "nan", "wall_seconds must be a number >= 0, got 'nan'"),
        ("localized", "many", "localized must be a number, got 'many'"),
    ],
)
def test_report_checks_every_field_of_every_row_before_it_writes_anything(
    small, tmp_path, capsys, column, value, message
):
    """One field out of its set, in the last row (which the figures' re-run check does not pick), is refused in
    one line naming the line and the field, and the directory is left exactly as it was."""
    out = tmp_path / "copy"
    rows = _edited_results(small[1], out, lambda rows: rows[-1].update({column: value}))
    assert cli.main(["report", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"results.csv: line {rows + 1}: {message}" in err and err.count("\n") == 1, err
    assert sorted(p.name for p in out.iterdir()) == ["results.csv"]


def test_a_row_the_rerun_check_refuses_leaves_the_report_as_it_was(small, tmp_path, capsys):
    """The figures re-run one run per curve and compare it with its row: a row that disagrees (here a valid
    outcome, but not the run's) fails the report before stats.csv or stats.md is written."""

    def swap_outcomes(rows):
        for r in rows:
            r["outcome"] = "timeout" if r["outcome"] != "timeout" else "incomplete"

    out = tmp_path / "copy"
    _edited_results(small[1], out, swap_outcomes)
    assert cli.main(["report", str(out)]) == 2
    assert "re-running" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["results.csv"]


# -- the ROS 2 engine --------------------------------------------------------------


def test_ros2_engine_gives_the_in_process_results(small, tmp_path):
    config = small_config(tmp_path, repetitions=1, vision_radius=[1], shapes={"disc.txt": [50, 80]})
    ros, ref = tmp_path / "ros", tmp_path / "ref"
    env = {**os.environ}
    env.pop("ROS_DOMAIN_ID", None)
    done = subprocess.run(
        [PY, "-m", "swarm_ros", "experiment", str(config), "--out", str(ros), "--engine", "ros2", "--quiet"],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr == "", done.stderr  # no worker's traceback, no leaked semaphore on the way out
    assert experiment(config, ref) == 0
    a, b = rows_without_timing(ros), rows_without_timing(ref)
    assert {r.pop("engine") for r in a} == {"ros2"} and {r.pop("engine") for r in b} == {"inprocess"}
    assert a == b


def test_experiments_can_damage_the_swarm_with_failing_robots(tmp_path):
    config = small_config(tmp_path, repetitions=2, vision_radius=[1], fail_fraction=0.2, fail_tick=20)
    out = tmp_path / "out"
    assert experiment(config, out) == 0
    rows = read_results(out / "results.csv")
    assert {(r["fail_fraction"], r["fail_tick"]) for r in rows} == {(0.2, 20)}
    for r in rows:
        lost = round(0.2 * r["robots"])
        assert r["lost_robots"] == lost
        assert r["localized"] == min(r["robots"] - lost, r["shape_patches"])  # the shape repaired itself
    stats = list(csv.DictReader((out / "stats.csv").open()))
    assert {s["mean_lost_robots"] for s in stats} == {str(round(0.2 * n)) for n in (50, 69, 80)}


def test_tick_labels_too_close_to_read_are_left_out_but_the_patch_count_keeps_its_own():
    from swarm_ros.app.report import tick_labels

    sizes = np.array([1025, 1030, 1035, 1036, 1040, 1045])
    assert tick_labels(sizes, keep=1036) == ["1025", "1030", "", "1036", "1040", "1045"]
    assert tick_labels(sizes) == ["1025", "1030", "1035", "", "1040", "1045"]
    assert tick_labels(np.array([100, 200, 300])) == ["100", "200", "300"]
    assert tick_labels(np.array([1036]), keep=1036) == ["1036"]


def test_a_report_interrupted_while_it_draws_keeps_the_figures_it_had(small, tmp_path, monkeypatch):
    """figures/ is swapped in whole: stopped halfway, the directory holds the old set, and nothing half-made."""
    import shutil

    from swarm_ros.app import report

    _, done = small
    out = tmp_path / "copy"
    shutil.copytree(done, out)
    before = sorted(p.name for p in (out / "figures").iterdir())
    calls = []

    def stop_on_the_second(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    real = report.shape_figure
    monkeypatch.setattr(report, "shape_figure", stop_on_the_second)
    with pytest.raises(KeyboardInterrupt):
        report.build_report(out)
    assert sorted(p.name for p in (out / "figures").iterdir()) == before
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []
    shutil.rmtree(out / "figures")
    with pytest.raises(KeyboardInterrupt):
        calls.clear()
        report.build_report(out)
    assert not (out / "figures").exists()  # none rather than a few


def test_the_vision_figure_keeps_a_ci_reaching_below_zero_on_its_log_axis(monkeypatch, tmp_path):
    from swarm_ros.app import report

    stats = [
        {
            "shape": "disc",
            "shape_patches": 69,
            "robots": 69,
            "vision_radius": v,
            "rules": "paper",
            "mean_convergence_tick": m,
            "ci95_low": lo,
            "ci95_high": hi,
            "mean_localized": 69.0,
        }
        for v, m, lo, hi in ((1.0, 40.0, -25.0, 105.0), (2.0, 30.0, 20.0, 40.0))
    ]
    figs = []
    monkeypatch.setattr(report, "_save", lambda fig, path: figs.append(fig))
    report.vision_figure(stats, tmp_path / "vision.png")
    ax = figs[0].axes[0]
    assert ax.get_yscale() == "log"
    bars = [seg for coll in ax.collections for seg in coll.get_segments()]
    lows = [min(seg[:, 1]) for seg in bars]
    assert bars and min(lows) == 1.0  # the CI below one tick is drawn to 1, not off the axis


def test_jobs_beyond_the_experiments_runs_are_not_started_nor_claimed(tmp_path, capsys):
    """--jobs 1000000 for a one-run experiment said '1000000 jobs' (and a LocalCluster was asked for as many)."""
    config = small_config(tmp_path, repetitions=1, vision_radius=[1], shapes={"disc.txt": [50]})
    assert cli.main(["experiment", str(config), "--out", str(tmp_path / "e"), "--jobs", "1000000"]) == 0
    assert "(1 job, engine inprocess)" in capsys.readouterr().out


def test_an_experiment_runs_both_algorithms_on_the_same_grid_and_reports_them_side_by_side(tmp_path, monkeypatch):
    import yaml

    from swarm_ros.app import cli, report

    labels: dict[str, set[str]] = {}
    save = report._save

    def keep_labels(fig, path):
        labels[path.name] = {ax.get_ylabel() for ax in fig.axes}
        save(fig, path)

    monkeypatch.setattr(report, "_save", keep_labels)
    from swarm_ros.app.experiment_file import load_experiment
    from swarm_ros.app.results_file import read_results

    (tmp_path / "square.txt").write_text("######\n" * 6)
    config = tmp_path / "h2h.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "name": "h2h",
                "seed": 5,
                "repetitions": 2,
                "vision_radius": [1, 2],
                "algorithm": ["darr-niazi", "rubenstein"],
                "max_ticks": 30000,
                "shapes": {"square.txt": [36, 40]},
            }
        )
    )
    exp = load_experiment(config)
    algorithms = [s.algorithm for s in exp.runs()]
    assert (
        algorithms.count("darr-niazi") == 2 * 2 * 2 and algorithms.count("rubenstein") == 2 * 2
    )  # once, not per radius
    out = tmp_path / "out"
    assert cli.main(["experiment", str(config), "--out", str(out), "--quiet", "--jobs", "2"]) == 0
    rows = read_results(out / "results.csv")
    theirs = [r for r in rows if r["algorithm"] == "rubenstein"]
    assert len(theirs) == 4 and all(r["vision_radius"] == 1.0 and r["rules"] == "paper" for r in theirs)
    assert all(r["shape_patches"] == 36 and 0 < r["coverage"] <= 1 for r in theirs)
    assert all(r["coverage"] > 0.9 and r["fill_50_tick"] <= r["fill_90_tick"] for r in theirs)
    studied = [r for r in rows if r["algorithm"] == "darr-niazi"]
    assert all(
        r["joined_outside"] == r["hole_filled"] == 0
        and r["loc_error"] == 0.0
        and r["fill_50_tick"] <= r["fill_90_tick"]
        for r in studied
    )
    stats = (out / "stats.md").read_text()
    table = stats[stats.index("## Time and accuracy") :]
    assert "| square | 40 | rubenstein | – | 2 |" in table and "| square | 40 | paper | 2 | 2 |" in table
    assert (out / "figures" / "square_rubenstein.png").stat().st_size > 0  # no vision radius in its name
    assert (out / "figures" / "algorithms.png").stat().st_size > 0  # both algorithms on shared axes
    assert "### The rubenstein algorithm" in stats and "| joined | not joined | uncovered pixels |" in stats
    # each algorithm's counts in its own words: rubenstein's robots join and cover pixels
    assert {"joined robots", "uncovered pixels"} <= labels["square_rubenstein.png"]
    assert {"localized robots", "empty shape patches"} <= labels["square_paper_v1.png"]
    # each grid point's repetition 0 left its step curve, which the report draws without running anything again
    from swarm_ros.app.curves import curve_name, read_curve
    from swarm_ros.core.darr_niazi.engine import Simulation

    firsts = [r for r in rows if r["repetition"] == 0]
    assert sorted(p.name for p in (out / "curves").iterdir()) == sorted(curve_name(r) for r in firsts)
    for r in firsts:
        curve = read_curve(out, r)
        assert curve[0, 0] == 0 and curve[-1, 0] == r["convergence_tick"] and curve[-1, 1] == r["empty_patches"]
        assert np.all(np.diff(curve[:, 0]) > 0) and np.all(np.diff(curve[:-1, 1]) != 0)  # the changes only

    gone = out / "curves" / curve_name(firsts[-1])
    kept = gone.read_text()
    gone.unlink()
    report.build_report(out)  # runs that run again, checks it against its row, and keeps its curve again
    assert gone.read_text() == kept

    def no_runs(*args, **kwargs):
        raise AssertionError("the report ran a run")

    monkeypatch.setattr(RubensteinRun, "run", no_runs)
    monkeypatch.setattr(Simulation, "run", no_runs)
    report.build_report(out)
