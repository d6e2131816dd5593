"""The package as a ROS 2 user drives it, with ROS 2 Jazzy's own tools (test/ros2_tools.py): a colcon build,
then ``ros2 launch`` with its defaults, with a parameter file, an output directory and every run argument,
stopped with Ctrl-C at start-up and mid-run, with a batch, a world shard and the monitor SIGKILLed; the three
terminals of ``ros2 run`` that docs/guides/ros2_tools.md shows; ``ros2 topic``, ``ros2 node``, ``ros2 param`` and
``ros2 pkg`` on a live run; and ``swarm-ros replay`` watched with ``ros2 topic echo``.

Each checks what the user would: the run directory where they asked for it, equal to ``simulate``'s,
exit status 0, and no ``[ERROR]`` line and no traceback in a clean run. The launches share one workspace,
built once, with the kernels' cache setup filled; the rubenstein launch empties its algorithm's first, as an install
without it, and the launch compiles them once.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import tempfile
import time
from pathlib import Path

import pytest
import yaml
from bagcheck import assert_bag_holds_run
from graph_runs import assert_same_run, bag_tick, descendants_of, processes_mentioning, shm_group, shm_left
from ros2_tools import NODES, Ros2, build_workspace, ctrl_c, install_ros2_tools, stop
from waiting import wait_for

from swarm_ros.app import cli
from swarm_ros.core.params import RUBENSTEIN, RUN_PARAMETERS
from swarm_ros.protocol.plan import CentralTopics
from swarm_ros.ros.shm import in_use, shm_locks

pytestmark = pytest.mark.process

STUDY = CentralTopics.of("darr-niazi")  #: the study's model's run's topics
LAUNCH = "ros2 launch swarm_ros swarm.launch.py"
#: The star under the local rule, cut at 1,500 ticks: a few seconds of run, long enough to kill in
SHORT = {"shape": "star", "seed": "5", "rules": "local", "max_ticks": "1500"}
STAMP = "swarm_ros-kernels-rubenstein.compiled"  #: the rubenstein kernels' stamp (swarm_ros/core/kernels.py)
RATE = 40  #: ticks a second of the live run the ros2 tools inspect: paced, it leaves the CPU to them


@pytest.fixture(scope="module")
def ros(tmp_path_factory):
    install_ros2_tools()
    install = build_workspace(tmp_path_factory.mktemp("ws"))
    shell = Ros2(install, tmp_path_factory.mktemp("user"), 200 + os.getpid() % 30)
    yield shell
    shell.run("ros2 daemon stop", timeout=30)


def _arguments(values: dict[str, str]) -> str:
    return " ".join(f"{k}:={v}" for k, v in values.items())


def _clean(output: str) -> None:
    """What a user reads after a run that succeeded: no error line, no traceback, and no process that had to be
    stopped (each ends by itself with the run)."""
    assert "[ERROR]" not in output and "Traceback" not in output, output[-4000:]
    assert "sending signal" not in output and "stopping what is left" not in output, output[-4000:]


def _simulate(out: Path, *flags: str) -> Path:
    assert cli.main(["simulate", *flags, "--out", str(out), "--quiet"]) == 0
    return out


def _launch_dir(ros: Ros2, before: list[Path]) -> Path:
    """The log directory of the launch started after ``before`` was listed."""
    return wait_for(
        lambda: next((p.parent for p in ros.launch_logs() if p not in before), None), 60, "the launch's params.yaml"
    )


def _node_pid(launch_dir: Path, name: str) -> int:
    """The pid of node ``name`` of the launch whose logs are in ``launch_dir`` (its params file names it)."""

    def find():
        for pid in processes_mentioning(f"__node:={name}"):
            try:
                args = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
            except OSError:
                continue
            if f"__node:={name}" in args and "python" in args[0] and any(str(launch_dir) in a for a in args):
                return pid
        return None

    return wait_for(find, 60, f"the process of {name}")


def _summary(run: Path) -> dict:
    return json.loads((run / "summary.json").read_text())


def test_ros2_pkg_lists_the_node_executables(ros):
    done = ros.run("ros2 pkg executables swarm_ros")
    assert done.returncode == 0, done.stderr
    assert sorted(done.stdout.split("\n")[:-1]) == [
        "swarm_ros monitor",
        "swarm_ros robot_batch",
        "swarm_ros swarm-ros",
        "swarm_ros world",
        "swarm_ros world_shard",
    ]


#: what each node logs once ready: the kernels it compiled, by numba's own count (seconds of CPU would not tell on
#: a slower machine)
READY = r"ready, [\d.]+ s after the process started \([\d.]+ s of CPU, (\d+) kernels compiled\)"


def test_ros2_launch_with_its_defaults_writes_the_run_simulate_writes(ros, tmp_path):
    """The install's kernels' cache is filled (the build ships setup's, test_install.py): nothing is compiled, by the
    launch or by a node; the run goes to runs/<time>_star_n1036_v1_s1 under the launch's directory, equal to
    simulate's; the launch ends by itself, cleanly, with exit status 0. (An empty cache: the rubenstein launch.)"""
    before = ros.launch_logs()
    done = ros.run(LAUNCH, cwd=tmp_path, timeout=300)
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-4000:]
    _clean(output)
    assert "compiling" not in output
    assert [int(n) for n in re.findall(READY, output)] == [0, 0, 0, 0], output[-4000:]
    (run,) = (tmp_path / "runs").iterdir()
    assert re.fullmatch(r"\d{8}-\d{6}_star_n1036_v1_s1", run.name)
    assert_same_run(_simulate(tmp_path / "ref"), run, launched=False)
    logs = _launch_dir(ros, before)
    assert not list(logs.glob("world.checkpoint*")), "the world's checkpoint goes with the run"


def test_ros2_launch_honours_a_parameter_file_an_output_directory_and_every_run_argument(ros, tmp_path):
    """Each run argument wins over the parameter file, the file's /monitor section is applied, out_dir is where
    the run goes; the run equals simulate's with the same values."""
    params = tmp_path / "mine.yaml"
    params.write_text(
        yaml.safe_dump(
            {
                "/**": {"ros__parameters": {"shape": "tyre", "seed": 4, "rules": "paper"}},
                "/monitor": {"ros__parameters": {"record": False}},
            }
        )
    )
    values = {
        "shape": "rectangle",
        "mesh_scale": "1.0",
        "shape_scale": "2",
        "robots": "300",
        "algorithm": "darr-niazi",
        "vision_radius": "1.5",
        "rules": "local",
        "join": "local",
        "crowding": "disc",
        "steps": "literal",
        "seed": "7",
        "max_ticks": "300",
        "wiggle_deg": "30.0",
        "fail_fraction": "0.05",
        "fail_tick": "100",
        "world_radius": "30",
    }
    # every run argument the graph takes: the rubenstein algorithm's it refuses, so far
    assert set(values) == {p.name for p in RUN_PARAMETERS if p.algorithm != RUBENSTEIN}, "every run argument is given"
    out = tmp_path / "deep" / "run"
    before = ros.launch_logs()
    temporary = set(Path(tempfile.gettempdir()).glob("launch_params_*"))
    done = ros.run(
        f"{LAUNCH} params_file:={params} out_dir:={out} processes:=3 region_cuts:=-5,5 {_arguments(values)}",
        timeout=240,
    )
    assert done.returncode == 0, (done.stdout + done.stderr)[-4000:]
    # each batch told its strip by -p arguments: no launch_params_* file left in /tmp per node and launch
    assert set(Path(tempfile.gettempdir()).glob("launch_params_*")) <= temporary
    _clean(done.stdout + done.stderr)
    typed = {
        k: yaml.safe_load(v) if k not in ("shape", "join", "crowding", "steps", "rules", "algorithm") else v
        for k, v in values.items()
    }
    written = yaml.safe_load((_launch_dir(ros, before) / "params.yaml").read_text())["/**"]["ros__parameters"]
    foreign = {p.name for p in RUN_PARAMETERS if p.algorithm == RUBENSTEIN}
    assert {k: v for k, v in written.items() if k not in foreign} == typed, "what every node reads"
    assert {k: written[k] for k in foreign} == {p.name: p.default for p in RUN_PARAMETERS if p.name in foreign}
    assert len(re.findall(r"\[robot_batch_\d\]: robot_batch_\d: columns ", done.stdout + done.stderr)) == 3
    ref_params = tmp_path / "ref.yaml"
    ref_params.write_text(yaml.safe_dump({"/**": {"ros__parameters": typed}}))
    ref = _simulate(tmp_path / "ref", "--params-file", str(ref_params), "--no-recording")
    for name in ("metrics.csv", "final_state.csv"):
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    got, want = _summary(out), _summary(ref)
    for key in ("engine", "wall_seconds", "startup_seconds", "shutdown_seconds", "rejected_messages"):
        got.pop(key, None), want.pop(key, None)
    assert got.pop("bag_robots_every") == 1  # checked against the bag below
    assert (got.pop("processes"), got.pop("world_shards")) == (None, 1)  # no swarm-ros run to say K
    assert got == want and got["lost_robots"] > 0, got
    assert not (out / "recording.rrd").exists(), "the file's /monitor record: false"
    assert_bag_holds_run(out)


def test_bad_launch_arguments_fail_in_one_line_before_any_node_starts(ros, tmp_path):
    for line, said in (
        (f"{LAUNCH} seed:=abc", "launch argument seed:=abc: seed must be an integer"),
        (f"{LAUNCH} processes:=0", "launch argument processes:=0: processes must be an integer >= 1"),
        (f"{LAUNCH} shape:=nope", "nope"),
        (f"{LAUNCH} mesh_scale:=2.0", "mesh_scale applies to mesh shapes"),
        (f"{LAUNCH} processes:=1033", "a world of 65 columns cannot be cut into 1033 strips"),
        (f"{LAUNCH} params_file:={tmp_path / 'missing.yaml'}", "missing.yaml"),
    ):
        done = ros.run(line, cwd=tmp_path, timeout=120)
        output = done.stdout + done.stderr
        assert done.returncode == 1, output
        assert "Traceback" not in output and "process started" not in output, output
        (error,) = [ln for ln in output.splitlines() if "[ERROR]" in ln]
        assert "Caught exception in launch" in error and said in error, error
    assert not (tmp_path / "runs").exists()


def test_ctrl_c_at_start_up_leaves_nothing_and_mid_run_keeps_the_run_so_far(ros, tmp_path):
    runs = tmp_path / "runs"
    out = runs / "early"
    log = tmp_path / "early.log"
    proc = ros.start(f"{LAUNCH} out_dir:={out}", log=log)
    # while the nodes load, before tick 0 (a Ctrl-C in the first tenth of a second of a Python process, while
    # the interpreter itself starts, ends in its own traceback: docs/guides/ros2_tools.md)
    wait_for(lambda: "robot_batch_1: columns" in log.read_text(), 60, "the nodes' start")
    ctrl_c(proc)
    assert "tick 0" not in log.read_text()
    proc.wait(timeout=60)
    assert "Traceback" not in log.read_text(), log.read_text()[-3000:]
    assert not runs.exists() or not list(runs.iterdir()), "nothing of a run before tick 0"
    assert not processes_mentioning(str(out))

    out = runs / "late"
    before = ros.launch_logs()
    proc = ros.start(f"{LAUNCH} out_dir:={out} world_radius:=120 max_ticks:=20000", log=tmp_path / "late.log")
    checkpoint = _launch_dir(ros, before) / "world.checkpoint"
    wait_for(lambda: bag_tick(out) >= 200, 120, "tick 200")
    ctrl_c(proc)
    proc.wait(timeout=60)
    text = (tmp_path / "late.log").read_text()
    assert "Traceback" not in text and "restarted" not in text, text[-3000:]
    summary = _summary(out)
    assert summary["outcome"] == "interrupted" and summary["convergence_tick"] >= 200
    assert len((out / "metrics.csv").read_text().splitlines()) == summary["convergence_tick"] + 2
    assert list(runs.iterdir()) == [out], "nothing beside the run"
    assert not processes_mentioning(str(out)) and not list(checkpoint.parent.glob("world.checkpoint*"))


def test_a_batch_a_world_shard_and_the_monitor_sigkilled_under_ros2_launch_come_back_and_the_run_is_identical(
    ros, tmp_path
):
    """``world_shards:=2``: two world shard nodes instead of the world. A batch, then a world shard, then the monitor,
    SIGKILLed mid-run, are each started again by the launch file's supervision and go on (the shard from its save, the
    monitor from its bag); the run equals simulate's, and the launch removes the shared-memory files the killed nodes
    held. (A world that is one process is killed under ``swarm-ros run`` in test_node_restarts: the launch file's
    supervision is the same for every node.)"""
    ref = _simulate(tmp_path / "ref", "--shape", "star", "--seed", "5", "--rules", "local", "--max-ticks", "1500")
    out = tmp_path / "run"
    before = ros.launch_logs()
    log = tmp_path / "launch.log"
    proc = ros.start(f"{LAUNCH} out_dir:={out} processes:=2 world_shards:=2 {_arguments(SHORT)}", log=log)
    logs = _launch_dir(ros, before)
    wait_for(lambda: bag_tick(out) >= 150, 120, "tick 150", poll=0.01)
    # the shared-memory files the nodes hold: a SIGKILLed node leaves its own and its peers' ports (before, 10
    # fastrtps_port* and 10 sem.*_mutex files stayed in /dev/shm after a kill); the launch removes them
    nodes = ["monitor", "world_shard_0", "world_shard_1", "robot_batch_0", "robot_batch_1"]
    held = set().union(*(shm_locks(_node_pid(logs, name)) for name in nodes))
    # a port's files are shared by every participant on the host: one that another test's process holds as the
    # launch tidies up is rightly kept then, and may be let go before the check below (CI once saw it)
    ports = {f for el in held if "fastrtps_port" in el for f in shm_group(el)}
    elsewhere: set[str] = set()
    for tick, node in ((150, "robot_batch_1"), (450, "world_shard_1"), (800, "monitor")):
        wait_for(lambda t=tick: bag_tick(out) >= t, 120, f"tick {tick}", poll=0.01)
        os.kill(_node_pid(logs, node), signal.SIGKILL)

    def ended() -> bool:  # meanwhile, note the ports another process holds
        elsewhere.update(in_use(ports, besides=frozenset([proc.pid, *descendants_of(proc.pid)])))
        return proc.poll() is not None

    wait_for(ended, 240, "the launch's end", poll=0.1)
    assert proc.wait(timeout=10) == 0, log.read_text()[-4000:]
    text = log.read_text()
    for node in ("robot_batch_1", "world_shard_1", "monitor"):
        assert f"swarm_ros: {node} was killed by SIGKILL; restarted (1 of 3)" in text, text[-4000:]
    for name in ("metrics.csv", "final_state.csv"):
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    summary = _summary(out)
    assert summary["outcome"] == _summary(ref)["outcome"] and summary["lost_robots"] == 0
    assert {"world_shard_1", "monitor"} <= {r["node"] for r in summary["restarts"]}, summary["restarts"]
    assert_bag_holds_run(out)
    assert not processes_mentioning(str(out)) and not list(logs.glob("world.checkpoint*"))
    files = {f for el in held for f in (el, el.removesuffix("_el"), f"/dev/shm/sem.{Path(el).name[:-3]}_mutex")}
    assert held and shm_left({f for f in files if not shm_group(f) & elsewhere}) == [], (shm_left(files), elsewhere)


def test_the_three_terminals_of_ros2_run_the_docs_show(ros, tmp_path):
    """docs/guides/ros2_tools.md's commands, each node in its own process as in its own terminal, after the exports it
    shows; the run equals simulate's."""
    out = tmp_path / "star"
    exports = (
        "export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST "
        "FASTRTPS_DEFAULT_PROFILES_FILE=$(ros2 pkg prefix swarm_ros)/share/swarm_ros/config/fastdds.xml "
        "SWARM_ROS_RUN_KEY=0123456789abcdef0123456789abcdef && "
    )
    config = "$(ros2 pkg prefix swarm_ros)/share/swarm_ros/config/swarm_ros.yaml"
    lines = [
        f"ros2 run swarm_ros monitor --ros-args --params-file {config} -p out_dir:={out}",
        *[
            f"ros2 run swarm_ros robot_batch --ros-args --params-file {config} -r __node:=robot_batch_{k} "
            f"-p batch:={k} -p batches:=2"
            for k in (0, 1)
        ],
        f"ros2 run swarm_ros world --ros-args --params-file {config}",
    ]
    terminals = [
        subprocess.Popen(
            ["bash", "-c", ros.prelude + exports + "exec " + line],
            cwd=ros.home,
            env=ros.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        for line in lines
    ]
    try:
        outputs = [p.communicate(timeout=180)[0] for p in terminals]
    finally:
        for p in terminals:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
    assert [p.returncode for p in terminals] == [0, 0, 0, 0], outputs
    for text in outputs:
        _clean(text)
    assert_same_run(_simulate(tmp_path / "ref"), out, launched=False)


def _ask_until(ros, line: str, needle: str, what: str) -> str:
    """Run a ros2 command until its output holds ``needle``; return that output. A fresh ros2 process may list a
    node before it has discovered all of that node's endpoints: CI once saw ``ros2 node info /world`` without
    its Publishers section, 50 ticks into a run."""

    def asked():
        text = ros.run(line).stdout
        return text if needle in text else ""

    return wait_for(asked, 30, what, poll=0.5)


def test_ros2_topic_node_and_param_on_a_live_run(ros, tmp_path):
    """A run paced for watching (the world's tick_rate, from a parameter file) inspected with ros2 node, topic
    and param; ``ros2 topic hz`` sees about the rate asked for."""
    out = tmp_path / "live"
    paced = tmp_path / "paced.yaml"
    paced.write_text(yaml.safe_dump({"/world": {"ros__parameters": {"tick_rate": float(RATE)}}}))
    before = ros.launch_logs()
    proc = ros.start(
        f"{LAUNCH} out_dir:={out} world_radius:=120 max_ticks:=100000 params_file:={paced}", log=tmp_path / "live.log"
    )
    try:
        logs = _launch_dir(ros, before)
        wait_for(lambda: bag_tick(out) >= 50, 120, "tick 50")

        def listed():
            done = ros.run("ros2 node list")
            return done.returncode == 0 and tuple(done.stdout.split()) == NODES

        wait_for(listed, 30, "all four nodes in ros2 node list", poll=0.5)

        robots, metrics = STUDY.robots, STUDY.metrics
        info = _ask_until(ros, "ros2 node info /world", f"{robots}: sensor_msgs", "/world's writers in ros2 node info")
        assert f"{robots}: sensor_msgs/msg/PointCloud2" in info.split("Publishers:")[1].split("Service")[0]
        assert f"{STUDY.decisions('robot_batch_0')}: sensor_msgs/msg/PointCloud2" in info.split("Subscribers:")[1]

        topics = _ask_until(ros, "ros2 topic list -t", "/swarm/status [", "every topic in ros2 topic list")
        for line in (
            f"{robots} [sensor_msgs/msg/PointCloud2]",
            f"{metrics} [sensor_msgs/msg/PointCloud2]",
            "/swarm/held [std_msgs/msg/Int64MultiArray]",
            "/swarm/shape [nav_msgs/msg/OccupancyGrid]",
            "/clock [rosgraph_msgs/msg/Clock]",
            "/swarm/status [diagnostic_msgs/msg/DiagnosticArray]",
        ):
            assert line in topics.splitlines(), topics
        verbose = _ask_until(ros, f"ros2 topic info -v {robots}", "Node name: world", f"{robots}' writer")
        assert "Publisher count: 1" in verbose
        assert "Reliability: RELIABLE" in verbose and "Durability: TRANSIENT_LOCAL" in verbose

        echo = ros.run(f"ros2 topic echo --once --no-lost-messages {metrics}").stdout
        cloud = yaml.safe_load(echo.split("---")[0])  # the metrics rows, a field each column
        names = [f["name"] for f in cloud["fields"]][:7]  # (then the tag's field)
        assert names == ["tick", "stationary", "localized", "inside", "moving", "empty_patches", "walking"], names
        assert cloud["header"]["stamp"]["sec"] >= 50
        clock = yaml.safe_load(ros.run("ros2 topic echo --once --no-lost-messages /clock").stdout.split("---")[0])
        assert clock["clock"]["sec"] >= 50
        hz_log = tmp_path / "hz.log"

        def rates_said() -> list[float]:  # hz prints a rate a second once it hears the topic: three, over 3 s or more
            rates = [float(r) for r in re.findall(r"average rate: ([\d.]+)", hz_log.read_text())]
            return rates if len(rates) >= 3 else []

        hz_proc = ros.start(f"env PYTHONUNBUFFERED=1 ros2 topic hz {robots}", log=hz_log)
        try:
            rates = wait_for(rates_said, 120, "three rates from ros2 topic hz", poll=0.5)
        finally:
            stop(hz_proc, 10)
        hz = hz_log.read_text()
        # paced: about RATE, where the run unpaced goes at hundreds a second. hz times its own receipt of each
        # message, and a reader that falls behind takes a few at once (CI's first window once said 44 at 40)
        assert rates and RATE / 2 < rates[-1] < RATE * 1.5, hz

        written = yaml.safe_load((logs / "params.yaml").read_text())
        listed_names = ros.run("ros2 param list /monitor").stdout.split()  # docs/guides/ros2_tools.md's command
        assert {p.name for p in RUN_PARAMETERS} <= set(listed_names), listed_names
        dumped = {}
        for node in ("/world", "/monitor", "/robot_batch_0"):  # (robot_batch_1 runs robot_batch_0's executable)
            dumped[node] = yaml.safe_load(ros.run(f"ros2 param dump {node}").stdout)[node]["ros__parameters"]
            assert {p.name for p in RUN_PARAMETERS} <= set(dumped[node]), (node, dumped[node])
            run_values = written["/**"]["ros__parameters"]
            assert {k: dumped[node][k] for k in run_values} == run_values
        assert dumped["/world"]["tick_rate"] == float(RATE) and dumped["/robot_batch_0"]["batch"] == 0
        assert dumped["/monitor"]["out_dir"] == str(out)
        assert ros.run("ros2 param get /world max_restarts").stdout.strip() == "Integer value is: 3"  # as the docs say
        described = ros.run("ros2 param describe /world wiggle_deg").stdout
        for line in (
            "Type: double",
            "Description: max turn per tick, degrees",
            "Read only: true",
            "Min value: 0.0",
            "Max value: 180.0",
            "Additional constraints: a number >= 0 and <= 180",
        ):
            assert line in described, described
        refused = ros.run("ros2 param set /world seed 3").stderr
        assert "Setting parameter failed: Trying to set a read-only parameter: seed." in refused, refused
    finally:
        stop(proc, 60)
    assert _summary(out)["outcome"] == "interrupted"


def test_swarm_ros_replay_is_watched_with_ros2_topic_echo(ros, tmp_path):
    """A run's bag replayed from an offset, looping, at a rate: ``ros2 topic echo`` sees its metrics."""
    graph = tmp_path / "graph"
    done = ros.run(f"{LAUNCH} out_dir:={graph} shape:=rectangle seed:=6", timeout=240)
    assert done.returncode == 0, done.stdout[-3000:]
    domain = int(ros.env["ROS_DOMAIN_ID"])
    started = time.monotonic()
    replay = ros.start(
        f"swarm-ros replay {graph} --domain-id {domain} --loop --start-offset 0.5 --rate 2 --delay 0.5 --quiet",
        log=tmp_path / "replay.log",
    )
    try:
        echo = ros.run(
            f"ros2 topic echo --once --no-lost-messages {STUDY.metrics} sensor_msgs/msg/PointCloud2",
            timeout=60,
        )  # with its type, echo waits for the replay's publisher
        metrics = yaml.safe_load(echo.stdout.split("---")[0])
        assert isinstance(metrics, dict) and "header" in metrics, echo.stdout + echo.stderr
        assert metrics["header"]["stamp"]["sec"] > 0, "from the offset on, not the first tick"
        # without --loop the replay would have ended by now: its delay, one pass over the bag at rate 2, and
        # its wait for acknowledgements; with it, it is still going
        from rosbags.rosbag2 import Reader

        from swarm_ros.tools.replay import _ACK_WAIT_S

        with Reader(graph / "bag") as bag:
            one_pass = 0.5 + (bag.end_time - bag.start_time) / 1e9 / 2 + _ACK_WAIT_S
        wait_for(
            lambda: replay.poll() is not None or time.monotonic() - started > one_pass + 1.0,
            one_pass + 60,
            "a single pass's end",
        )
        assert replay.poll() is None, "--loop goes on until stopped"
    finally:
        stop(replay, 30)
    assert replay.returncode == 130 and "Traceback" not in (tmp_path / "replay.log").read_text()


def test_ros2_launch_runs_the_rubenstein_algorithm_as_simulate_does_compiling_its_kernels_once(ros, tmp_path):
    """`algorithm:=rubenstein`: the launch file starts the algorithm's world, batches and monitor under the usual
    names, and the run directory holds simulate's run. Its kernels' cache emptied first, as an install without it:
    the launch compiles the run's algorithm's kernels once, before the nodes start, and no node compiles one."""
    site = next(ros.install.glob("swarm_ros/lib/python3*/site-packages/swarm_ros"))
    emptied = [*site.glob("core/rubenstein/__pycache__/*.nb[ic]"), site / "core/__pycache__/" / STAMP]
    for path in emptied:  # its own kernels, and the stamp that says they are compiled (the core's it shares stay)
        path.unlink()
    (tmp_path / "square6.txt").write_text("######\n" * 6)
    flags = "--algorithm rubenstein --robots 40 --seed 5"
    shape = tmp_path / "square6.txt"
    ref = tmp_path / "ref"
    assert cli.main(["simulate", "--shape", str(shape), *flags.split(), "--out", str(ref), "--quiet"]) == 0
    out = tmp_path / "run"
    done = ros.run(
        f"{LAUNCH} algorithm:=rubenstein shape:={shape} robots:=40 seed:=5 out_dir:={out}", cwd=tmp_path, timeout=300
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-4000:]
    assert "compiling the rubenstein algorithm's numba kernels first" in output
    assert "darr-niazi algorithm's numba kernels" not in output, "only the run's algorithm's are compiled"
    assert [int(n) for n in re.findall(READY, output)] == [0, 0, 0, 0], output[-4000:]
    assert emptied[-1].exists() and list(site.glob("core/rubenstein/__pycache__/*.nbi")), "into the install's cache"
    for name in ("metrics.csv", "final_state.csv"):
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    assert json.loads((out / "summary.json").read_text())["engine"] == "ros2"
