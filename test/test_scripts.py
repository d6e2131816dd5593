"""The scripts still run and print what their docs quote: the bench that issue targets are measured with, the
shape generators' check mode, the study's bounds, the README's screenshot."""

from __future__ import annotations

import re
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image
from runs import small_config

from swarm_ros.app import cli

pytestmark = pytest.mark.process

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"


def test_bench_scale_before_alternates_two_trees_each_run_from_inside_itself(tmp_path):
    """--before DIR: an A/B, each round both trees in turn (the order alternating), then the medians and the
    summed CPU ratio per round; a DIR whose `python -m swarm_ros` would import another tree's package is refused
    (a tree with no package: the import falls through to this checkout's install)."""
    base = [sys.executable, str(SCRIPTS / "bench_scale.py"), "--robots", "300", "--ticks", "5", "--bare"]
    empty = tmp_path / "empty"
    empty.mkdir()
    refused = subprocess.run([*base, "--before", str(empty)], capture_output=True, text=True, timeout=120)
    assert refused.returncode != 0 and "imports swarm_ros from" in refused.stderr, refused.stderr
    done = subprocess.run(
        [*base, "--processes", "2", "--repeats", "2", "--before", str(SCRIPTS.parent)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    rounds = re.findall(r"^  round (\d) (this tree|before)\s+run [\d.]+ s\s+monitor", done.stdout, re.M)
    assert rounds == [("1", "this tree"), ("1", "before"), ("2", "before"), ("2", "this tree")], done.stdout
    assert re.search(r"^the graph's summed CPU a tick, .* per round: [\d.]+, [\d.]+$", done.stdout, re.M), done.stdout


def test_bench_scale_prints_each_engine_and_the_projection_on_k_hosts():
    """A tiny disc, K = 1 and 2 with up to 2 world shards, no recording: the table, the K ratios and a
    projection row per K whose projected tick is what it is built from: the slowest world shard's CPU plus
    the slowest batch's plus the transport's, or the monitor's if longer."""
    done = subprocess.run(
        [
            sys.executable,
            str(SCRIPTS / "bench_scale.py"),
            "--robots",
            "300",
            "--ticks",
            "5",
            "--processes",
            "1",
            "2",
            "--bare",
            "--projection",
            "--world-shards",
            "2",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout
    assert re.search(r"^in-process\s+\d", out, re.M), out
    for k in (1, 2):
        assert re.search(rf"^ROS 2 graph, K = {k}, S = {k}\s+\d.*world", out, re.M), out
    assert re.search(
        r"^K = 2 against K = 1: run time \d+\.\d\dx, .* largest CPU per tick of a process \d", out, re.M
    ), out
    rows = re.findall(
        r"^\s+300\s+(\d)\s+(\d)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+"
        r"([\d.]+)x$",
        out,
        re.M,
    )
    assert [(int(r[0]), int(r[1])) for r in rows] == [(1, 1), (2, 2)], out
    sharded = re.search(r"^ROS 2 graph, K = 2, S = 2 .*$", out, re.M).group(0)
    shard_cpu = [float(ms) for ms in re.findall(r"world_shard_\d ([\d.]+)", sharded)]
    assert len(shard_cpu) == 2, sharded
    assert abs(float(rows[1][2]) - max(shard_cpu)) <= 0.1, (rows[1], sharded)  # the world is the slowest shard
    for _, _, world, batch, monitor, transport, tick, sim_tick, ratio in rows:
        assert float(transport) > 0 and float(sim_tick) > 0
        # the printed figures are rounded to 0.1 ms
        assert float(tick) >= max(float(world) + float(batch) + float(transport), float(monitor)) - 0.2
        assert abs(float(ratio) - float(tick) / float(sim_tick)) <= 0.05 * float(ratio) + 0.1


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("script,dims", [("make_shapes.py", 2), ("make_shapes_3d.py", 3)])
def test_the_shape_generators_check_mode_reports_the_built_in_shapes_and_writes_nothing(script, dims):
    """``--check`` regenerates every built-in shape in memory: its counts are the shipped files'."""
    from swarm_ros.core import Shape

    shapes = SCRIPTS.parent / "shapes"
    before = _tree(shapes)
    done = subprocess.run(
        [sys.executable, str(SCRIPTS / script), "--check"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert _tree(shapes) == before, "--check wrote to shapes/"
    counts = dict(re.findall(r"^(\S+)\s+(?:scale\s+[\d.]+\s+patches\s+)?(\d+)", done.stdout, re.M))
    files = sorted((shapes / "3d" if dims == 3 else shapes).glob("*.txt"))
    assert sorted(counts) == sorted(f.stem for f in files), done.stdout
    for f in files:
        assert int(counts[f.stem]) == Shape.load(str(f)).patches, f.stem


def test_study_bounds_writes_its_table_of_every_shape(tmp_path):
    out = tmp_path / "bounds.md"
    done = subprocess.run(
        [sys.executable, str(SCRIPTS / "study_bounds.py"), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    rows = [ln for ln in out.read_text().splitlines() if re.match(r"\| [a-z-]+ \| [\d.]+ \(", ln)]
    assert [r.split("|")[1].strip() for r in rows] == ["star", "wrench", "k-letter", "rectangle", "tyre", "spinner"]
    for row in rows:  # no run of ours completes faster than the shape can grow (the growth bound, in ticks)
        bound, ours = int(row.split("|")[3]), float(row.split("|")[5].split()[0])
        assert 0 < bound <= ours, row
    assert out.read_text() in done.stdout  # what it writes is what it prints


def _smoke(script: str) -> str:
    done = subprocess.run(
        [sys.executable, str(SCRIPTS / script), "--smoke"], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def _rates(out: str) -> list[float]:
    """Every 'M robot-steps/s' figure the bench printed; each must be a measured, positive rate."""
    return [float(r) for r in re.findall(r"robot-steps +[\d.]+ s +([\d.]+) M robot-steps/s", out)]


def test_bench_engine_smoke_prints_each_rule_set_its_cases_and_the_tick_cost_fit():
    out = _smoke("bench_engine.py")
    assert [m for m in re.findall(r"^rules (\w+):", out, re.M)] == ["paper", "local", "literal"]
    assert len(rates := _rates(out)) == 3 * 3 and min(rates) > 0, out  # star first ticks, star whole, a disc
    # the fit's intercept may come out negative from a smoke run's few, noisy ticks (CI once saw -187.92 us)
    assert re.search(r"least squares: cost = -?[\d.]+ us \+ -?[\d.]+ ns x moving", out), out
    assert "numbers that mean nothing" in out


def test_bench_engine_before_measures_both_trees_alternating_and_refuses_another_tree_in_their_place(tmp_path):
    """--before DIR: each round measures both trees in a fresh process started inside each (the order alternating),
    then prints each case's rates and ratio, and each tree's cost at the largest size against the star's."""
    base = [sys.executable, str(SCRIPTS / "bench_engine.py"), "--smoke", "--rules", "paper", "--rounds", "2"]
    done = subprocess.run([*base, "--before", str(SCRIPTS.parent)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    rounds = re.findall(r"round (\d) of 2: (this tree|before) measured", done.stderr)
    assert rounds == [("1", "this tree"), ("1", "before"), ("2", "before"), ("2", "this tree")], done.stderr
    cases = re.findall(r"^  (paper, [^\n]+?) +([\d.]+) +([\d.]+) +([\d.]+)  [\d.]+-[\d.]+$", done.stdout, re.M)
    assert len(cases) == 3 and all(float(a) > 0 and float(b) > 0 for _, a, b, _ in cases), done.stdout
    assert re.search(r"this tree +paper +[\d.]+x", done.stdout) and re.search(r"before +paper +[\d.]+x", done.stdout)
    empty = tmp_path / "not-a-checkout"  # no swarm_ros in it: the child imports another, which is refused
    empty.mkdir()
    refused = subprocess.run([*base, "--before", str(empty)], capture_output=True, text=True, timeout=300)
    assert refused.returncode != 0 and "not the tree" in refused.stderr + refused.stdout, refused.stderr


def test_bench_algorithms_smoke_prints_both_algorithms_rates():
    out = _smoke("bench_algorithms.py")
    rows = {line.split()[0]: line.split() for line in out.splitlines() if line.strip().startswith(("darr", "rub"))}
    assert set(rows) == {"darr-niazi", "rubenstein"}, out
    assert "ticks 1-300 (300 ticks)" in out and float(rows["rubenstein"][-2]) > 0, out


def test_bench_algorithms_before_measures_both_algorithms_in_both_trees():
    """--before DIR (this tree against itself here): each algorithm's rate in both trees and their ratio."""
    command = [sys.executable, str(SCRIPTS / "bench_algorithms.py"), "--smoke", "--before", str(SCRIPTS.parent)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    row = r"^  (darr-niazi|rubenstein)[^\n]*? +([\d.]+) +([\d.]+) +([\d.]+)  [\d.]+-[\d.]+$"
    cases = re.findall(row, done.stdout, re.M)
    assert [c[0] for c in cases] == ["darr-niazi", "rubenstein"], done.stdout
    assert all(float(a) > 0 and float(b) > 0 for _, a, b, _ in cases), done.stdout


def test_bench_rubenstein_graph_smoke_prints_each_process_cpu_per_tick_against_the_in_process_tick():
    out = _smoke("bench_rubenstein_graph.py")
    nodes = re.findall(r"^  (\w+) +CPU +([\d.]+) ms/tick .* ([\d.]+)x the in-process tick$", out, re.M)
    assert {n for n, _, _ in nodes} == {"world", "monitor", "robot_batch_0", "robot_batch_1"}, out
    assert all(float(ms) > 0 for _, ms, _ in nodes) and "in-process tick:" in out, out


def test_bench_3d_smoke_prints_the_torus_and_a_ball_world():
    out = _smoke("bench_3d.py")
    assert re.findall(r"^rules (\w+):", out, re.M) == ["paper"]
    assert "torus 1348, first 2000 ticks" in out and "ball 1,000" in out
    assert len(rates := _rates(out)) == 2 and min(rates) > 0, out


def test_study_3d_density_smoke_prints_its_table_row():
    out = _smoke("study_3d_density.py")
    rows = [ln for ln in out.splitlines() if ln.startswith("| torus |")]
    assert len(rows) == 1, out
    mean = float(rows[0].split("|")[4])
    assert mean > 0, rows[0]


def _bench(script: str, *args: str, timeout: float = 300) -> str:
    done = subprocess.run(
        [sys.executable, str(SCRIPTS / script), *args], capture_output=True, text=True, timeout=timeout
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def test_bench_ros_speed_with_one_process_prints_the_graph_beside_the_engine_and_the_bare_lockstep():
    """The smallest case of bench_ros (it runs bench_bare's lockstep too): one graph run, K = 1."""
    out = _bench("bench_ros.py", "--only", "speed", "--repeats", "1", "--processes", "1")
    (engine,) = re.findall(r"^in-process, run\(\) +([\d,]+)", out, re.M)
    (graph,) = re.findall(r"^ROS 2 graph, K = 1 +([\d,]+)", out, re.M)
    (bare,) = re.findall(r"^bare rclpy lockstep, K = 1 +([\d,]+)", out, re.M)
    rates = [int(x.replace(",", "")) for x in (engine, graph, bare)]
    assert min(rates) > 0 and rates[0] > rates[1], out  # the in-process engine outruns the graph
    cpu = dict(re.findall(r"(\w+) ([\d.]+)(?:,|$)", out.split("CPU per tick")[1].split("):")[1].splitlines()[0]))
    assert set(cpu) == {"world", "monitor", "robot_batch_0"} and min(map(float, cpu.values())) > 0, out


def test_bench_ros_rosstart_prints_what_a_process_pays_to_be_a_ros_node():
    """Each step's CPU and wall seconds, measured in fresh processes, and their sum."""
    out = _bench("bench_ros.py", "--only", "rosstart", "--repeats", "1")
    steps = re.findall(r"^  (.+?) +CPU ([\d.]+) +wall ([\d.]+)$", out, re.M)
    assert [s[0] for s in steps] == [
        "import rclpy and a message package",
        "the first node (its DDS participant)",
        "12 endpoints",
        "in all",
    ], out
    cpu = [float(s[1]) for s in steps]
    assert min(cpu) > 0 and abs(sum(cpu[:3]) - cpu[3]) < 0.002, out


def test_bench_experiment_times_a_small_experiment_with_the_local_executor(tmp_path):
    out = _bench("bench_experiment.py", "--config", str(small_config(tmp_path)), "--executors", "local", "--jobs", "1")
    assert re.search(r"small\.yaml, executor local: 18 runs \(1 shapes, 3 repetitions, vision 1, 1\.5", out), out
    assert re.search(r"whole command .*: median [\d.]+ s .*, [\d.]+ runs/s", out), out


def test_bench_faults_smoke_kills_a_batch_and_the_run_equals_the_unfaulted_one():
    out = _smoke("bench_faults.py")
    assert re.search(r"per tick: the world's checkpoint [\d.]+ us; the monitor's bag [\d.]+ us", out), out
    rows = dict(re.findall(r"^ +(robot_batch_1|world|monitor) +[\d.]+ \([\d.]+-[\d.]+\) +[\d.]+x .* (\w+)$", out, re.M))
    assert rows == {"robot_batch_1": "yes"}, out
    assert re.search(r"node exit after the launcher's SIGKILL: [\d.]+", out), out


def test_bench_flood_smoke_prints_the_run_alone_and_flooded_both_identical_to_simulate():
    out = _smoke("bench_flood.py")
    rows = {int(m[0]): m[1:] for m in re.findall(r"^ +(\d+) +([\d,]+) +(\d+) +[\d,]+ +(-?\d+) +(\w+)", out, re.M)}
    assert sorted(rows) == [0, 200], out
    for rate, (reached, topics, code, same) in rows.items():
        assert (code, same) == ("0", "yes"), out
        if rate:  # the flood reached every topic of the run
            assert int(reached.replace(",", "")) > 0 and int(topics) >= 10, out
    assert "slowdown: run" in out and "A WRONG RESULT" not in out


def test_screenshot_writes_its_png_or_says_in_one_line_why_it_cannot(tmp_path):
    """With a Vulkan driver the headless viewer paints the recording and the PNG is written; without one (this
    machine's CI: the viewer panics for want of a render context) the script says so in one line, exit 1, and
    writes nothing. A recording that is not there is one line too, exit 2."""
    assert (
        cli.main(
            [
                "simulate",
                "--shape",
                "rectangle",
                "--robots",
                "100",
                "--max-ticks",
                "30",
                "--out",
                str(tmp_path / "r"),
                "--quiet",
            ]
        )
        == 0
    )
    script, out = str(SCRIPTS / "screenshot.py"), tmp_path / "shot.png"
    missing = subprocess.run(
        [sys.executable, script, str(tmp_path / "none.rrd"), str(out)], capture_output=True, text=True
    )
    assert missing.returncode == 2 and missing.stderr.strip().count("\n") == 0 and "no such file" in missing.stderr
    with socket.socket() as s:  # a free port for the viewer: another test may run one beside this
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    done = subprocess.run(
        [sys.executable, script, str(tmp_path / "r" / "recording.rrd"), str(out), "--settle", "1", "--port", str(port)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    if done.returncode == 0:
        assert Image.open(out).width == 1440, done.stdout
    else:
        assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr[-3000:]
        assert done.stderr.strip().splitlines()[-1].startswith("screenshot: error: "), done.stderr[-3000:]
        assert sorted(p.name for p in tmp_path.iterdir()) == ["r"], "nothing written"


def test_bench_run_times_the_readme_command_against_a_base_tree_and_checks_both_runs_agree(tmp_path):
    base = [sys.executable, str(SCRIPTS / "bench_run.py")]
    refused = subprocess.run([*base, "--before", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "no swarm_ros package there" in refused.stderr, refused.stderr
    flags = ["--", "--shape", "rectangle", "--robots", "60", "--processes", "1"]
    done = subprocess.run(
        [*base, "--before", str(SCRIPTS.parent), "--pairs", "1", "--warm", "0", *flags],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert re.search(r"^this/base\s+[\d.]+ \(", done.stdout, re.M) and "identical in every pair" in done.stdout


def test_bench_suite_prints_pytests_own_count_and_seconds_and_keeps_the_log_of_a_run_that_failed():
    """Two repeats of a small module, in this tree: pytest's count and seconds each, then the median. A run with
    no test to run fails (pytest exits 5): exit 1, and its log kept where the script says. Bad input: one line."""
    base = [sys.executable, str(SCRIPTS / "bench_suite.py")]
    done = subprocess.run([*base, "--repeats", "2", "--", "test/test_errors.py", "-n", "0"], capture_output=True,
                          text=True, timeout=300, cwd=SCRIPTS.parent)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    runs = re.findall(r"^run (\d): (\d+) passed, 0 failed, (\d+) s", done.stdout, re.M)
    assert [r[0] for r in runs] == ["1", "2"] and all(int(r[1]) > 0 for r in runs), done.stdout
    assert re.search(r"^median \d+ s \(\d+-\d+\)$", done.stdout, re.M), done.stdout
    none = subprocess.run([*base, "--tier", "unit", "--", "test/test_scripts.py", "-n", "0"], capture_output=True,
                          text=True, timeout=300, cwd=SCRIPTS.parent)  # fmt: skip
    assert none.returncode == 1 and "run 1: 0 passed" in none.stdout, none.stdout + none.stderr
    (kept,) = re.findall(r"the logs are in (\S+)", none.stderr)
    assert "deselected" in (Path(kept) / "pytest-1.log").read_text()
    shutil.rmtree(kept)  # the script's own temporary directory, kept for this check
    bad = subprocess.run([*base, "--repeats", "0"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and bad.stderr.strip().splitlines()[-1].endswith("--repeats 0: at least 1"), bad.stderr
