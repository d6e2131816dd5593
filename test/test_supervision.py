"""What the launch file decides, without ROS 2's launch packages (test_ros2_cli.py runs it with them): the
parameter file its nodes read (swarm_ros.app.supervision.launch_setup) and what it does when a node process
ends (Supervisor), as ``swarm-ros run`` does."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest
import yaml

from swarm_ros.app.param_file import params_yaml
from swarm_ros.app.processes import CHECKPOINT
from swarm_ros.app.supervision import STOPPED, Supervisor, Verdict, argument_value, launch_processes, launch_setup
from swarm_ros.core.errors import ConfigError, InputError
from swarm_ros.core.params import RUN_PARAMETERS, Settings

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "config" / "swarm_ros.yaml"
BLANK = {p.name: "" for p in RUN_PARAMETERS}  # the launch arguments a user did not give


def _setup(tmp_path: Path, params_file: Path = CONFIG, out_dir: str = "", processes: int = 2, **arguments: str):
    return launch_setup(str(params_file), {**BLANK, **arguments}, out_dir, tmp_path / "log", processes)


def _written(setup) -> dict:
    return yaml.safe_load(setup.params.read_text())


def test_the_nodes_read_what_swarm_ros_run_writes_for_the_same_settings(tmp_path):
    setup = _setup(tmp_path, out_dir=str(tmp_path / "run"), shape="rectangle", seed="6")
    written = _written(setup)
    run = Settings(shape="rectangle", seed=6, robots=442)
    assert written["/**"] == yaml.safe_load(params_yaml(run, {}))["/**"]
    assert written["/monitor"]["ros__parameters"] == {"out_dir": str(tmp_path / "run"), "record_every": 0}
    assert written["/world"]["ros__parameters"]["checkpoint"] == str(tmp_path / "log" / CHECKPOINT)
    assert written["/world"]["ros__parameters"]["record_every"] == 0
    assert setup.checkpoint == tmp_path / "log" / CHECKPOINT and setup.out == tmp_path / "run"
    assert (setup.supervisor.max_restarts, setup.supervisor.on_batch_loss) == (3, "restart")


def test_arguments_win_over_the_parameter_file_and_its_node_sections_are_kept(tmp_path):
    params = tmp_path / "mine.yaml"
    params.write_text(
        yaml.safe_dump(
            {
                "/**": {"ros__parameters": {"shape": "tyre", "seed": 4}},
                "/world": {
                    "ros__parameters": {
                        "max_restarts": 1,
                        "on_batch_loss": "remove",
                        "incarnation": 0,
                        "record_every": 3,
                    }
                },
                "/monitor": {"ros__parameters": {"record": False, "out_dir": str(tmp_path / "from-file")}},
            }
        )
    )
    setup = _setup(tmp_path, params, out_dir=str(tmp_path / "from-argument"), seed="5", vision_radius="2")
    written = _written(setup)
    assert (written["/**"]["ros__parameters"]["shape"], written["/**"]["ros__parameters"]["seed"]) == ("tyre", 5)
    assert written["/**"]["ros__parameters"]["vision_radius"] == 2.0
    monitor = written["/monitor"]["ros__parameters"]
    # record_every from the /world section (the monitor's has none), for both: the world and the monitor agree
    assert monitor == {"record": False, "out_dir": str(tmp_path / "from-argument"), "record_every": 3}
    assert written["/world"]["ros__parameters"]["record_every"] == 3
    assert "incarnation" not in written["/world"]["ros__parameters"], "the supervisor's to set"
    assert (setup.supervisor.max_restarts, setup.supervisor.on_batch_loss) == (1, "remove")
    assert _setup(tmp_path, params).out == tmp_path / "from-file", "without the argument, the file's out_dir"


@pytest.mark.parametrize(
    "section,values,message",
    [
        ("/world", {"incarnation": 2}, "/world sets incarnation, which swarm-ros run and the launch file set"),
        ("/monitor", {"world_shards": 2}, "/monitor sets world_shards, which swarm-ros run and the launch file set"),
        ("/robot_batch", {"batch": 1}, "/robot_batch sets batch, which swarm-ros run and the launch file set"),
    ],
)
def test_the_launch_refuses_what_it_sets_for_each_process_itself(tmp_path, section, values, message):
    """A value the launch would replace for each process (rather than silently drop) is refused, as by run."""
    params = tmp_path / "mine.yaml"
    params.write_text(yaml.safe_dump({section: {"ros__parameters": values}}))
    with pytest.raises(InputError, match=message):
        _setup(tmp_path, params)


def test_without_out_dir_the_run_is_named_once_under_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    setup = _setup(tmp_path)
    assert setup.out.parent == tmp_path / "runs" and setup.out.name.endswith("_star_n1036_v1_s1")
    assert _written(setup)["/monitor"]["ros__parameters"]["out_dir"] == str(setup.out)  # a restarted monitor's too


@pytest.mark.parametrize(
    "name,text,value",
    [
        ("seed", "7", 7),
        ("vision_radius", "2", 2.0),
        ("shape", "1", "1"),
        ("wiggle_deg", "30.5", 30.5),
        ("join", "local", "local"),
    ],
)
def test_an_argument_is_read_as_ros_2_reads_a_parameter_value(name, text, value):
    got = argument_value(name, text)
    assert got == value and type(got) is type(value)


@pytest.mark.parametrize(
    "call,said",
    [
        (lambda p: argument_value("seed", "abc"), "launch argument seed:=abc: seed must be an integer"),
        (lambda p: argument_value("rules", "fast"), "rules must be one of paper, local, literal, got 'fast'"),
        (lambda p: argument_value("robots", "[1, 2"), "robots must be an integer"),
        (lambda p: launch_processes("0"), "launch argument processes:=0: processes must be an integer >= 1"),
        (
            lambda p: _setup(p, processes=1033),
            "a world of 65 columns cannot be cut into 1033 strips, one per robot-batch process (processes, default 2)",
        ),
        (lambda p: _setup(p, p / "missing.yaml"), "missing.yaml"),
        (lambda p: _setup(p, shape="nope"), "nope"),
        (lambda p: launch_setup(str(CONFIG), BLANK, "", p / "log", 2, "swarm"), "enclaves must be an enclave path"),
    ],
)
def test_bad_launch_arguments_are_refused_in_one_line(tmp_path, call, said):
    with pytest.raises(InputError) as caught:
        call(tmp_path)
    assert said in str(caught.value) and "\n" not in str(caught.value)
    assert not (tmp_path / "log" / "params.yaml").exists()


def test_a_file_that_sets_a_run_parameter_in_a_node_section_is_refused(tmp_path):
    params = tmp_path / "bad.yaml"
    params.write_text(yaml.safe_dump({"/world": {"ros__parameters": {"seed": 3}}}))
    with pytest.raises(ConfigError, match="run parameters go in '/\\*\\*'"):
        _setup(tmp_path, params)


# -- what happens when a process ends -------------------------------------------------------------

KILLED = -signal.SIGKILL


@pytest.mark.parametrize(
    "exits,verdicts",
    [
        # the normal end: batches and world exit 0 with the run, the monitor once it has written it
        (
            [("robot_batch_0", 0), ("world", 0), ("monitor", 0)],
            [Verdict(), Verdict(wait_for_monitor=True), Verdict(note="the monitor has written the run")],
        ),
        # a batch killed is started again, up to max_restarts times, then its robots are removed
        (
            [("robot_batch_1", KILLED), ("robot_batch_1", KILLED), ("robot_batch_1", 1)],
            [
                Verdict(restart=True, note="robot_batch_1 was killed by SIGKILL; restarted (1 of 2)"),
                Verdict(restart=True, note="robot_batch_1 was killed by SIGKILL; restarted (2 of 2)"),
                Verdict(
                    note="robot_batch_1 exited with status 1; it was restarted 2 times already: the world removes its "
                    "robots and the run goes on"
                ),
            ],
        ),
        # the world and the monitor killed come back; once too often, the run cannot go on
        (
            [("world", KILLED), ("monitor", KILLED), ("world", KILLED), ("world", KILLED)],
            [
                Verdict(restart=True, note="world was killed by SIGKILL; restarted (1 of 2)"),
                Verdict(restart=True, note="monitor was killed by SIGKILL; restarted (1 of 2)"),
                Verdict(restart=True, note="world was killed by SIGKILL; restarted (2 of 2)"),
                Verdict(
                    end="world was killed by SIGKILL; it was restarted 2 times already (max_restarts): the run cannot "
                    "go on"
                ),
            ],
        ),
        # an error status is the run's failure: a restart would fail the same way
        ([("world", 1)], [Verdict(end="world exited with status 1")]),
        (
            [("world", 0), ("monitor", 1)],
            [
                Verdict(wait_for_monitor=True),
                Verdict(
                    end="the monitor exited with status 1; the swarm ran to its end, but no run directory was written"
                ),
            ],
        ),
        # a batch that dies after the run's end is not started again
        ([("world", 0), ("robot_batch_0", KILLED)], [Verdict(wait_for_monitor=True), Verdict()]),
        # Ctrl-C: the terminal signals every process; the first to go stops the launch, nothing comes back
        (
            [("robot_batch_0", 130), ("world", 130), ("monitor", -signal.SIGINT)],
            [Verdict(stop="robot_batch_0 was stopped (exited with status 130): the run stops"), Verdict(), Verdict()],
        ),
    ],
)
def test_a_process_that_ends_is_handled_as_swarm_ros_run_handles_it(exits, verdicts):
    supervisor = Supervisor(max_restarts=2)
    assert [supervisor.exited(name, code) for name, code in exits] == verdicts


def test_under_remove_a_lost_batch_is_not_started_again_and_restarts_count_incarnations():
    supervisor = Supervisor(max_restarts=3, on_batch_loss="remove")
    assert supervisor.exited("robot_batch_0", KILLED) == Verdict(
        note="robot_batch_0 was killed by SIGKILL; the world removes its robots (on_batch_loss: remove) and the run "
        "goes on"
    )
    assert supervisor.incarnation("world") == 0
    supervisor.exited("world", KILLED)
    assert supervisor.incarnation("world") == 1


def test_a_batch_whose_robots_cannot_be_removed_ends_the_run_once_out_of_restarts():
    """The rubenstein algorithm's world cannot remove a lost batch's robots: past the bound the run ends (the
    launcher stops every process and the monitor writes the run so far), where the study's model's goes on."""
    supervisor = Supervisor(max_restarts=1, removes=False, said=("--on-batch-loss remove", "--max-restarts"))
    assert supervisor.exited("robot_batch_0", KILLED).restart
    assert supervisor.exited("robot_batch_0", KILLED) == Verdict(
        end="robot_batch_0 was killed by SIGKILL; it was restarted 1 times already (--max-restarts): the run cannot "
        "go on without its robots"
    )
    assert Supervisor(max_restarts=0).exited("robot_batch_0", KILLED).note.endswith("the run goes on")


def test_stopped_statuses_are_the_nodes_interrupt_statuses():
    from swarm_ros.ros.runtime import EXIT_INTERRUPTED, EXIT_ORPHANED

    assert {EXIT_INTERRUPTED, EXIT_ORPHANED, -signal.SIGINT, -signal.SIGTERM, -signal.SIGHUP} == STOPPED


def test_before_tick_0_a_lost_batch_is_started_again_under_remove_too_and_its_last_error_is_said():
    supervisor = Supervisor(max_restarts=1, on_batch_loss="remove", said=("--on-batch-loss remove", "--max-restarts"))
    assert supervisor.exited("robot_batch_0", 1, why="boom", started=False) == Verdict(
        restart=True, note="robot_batch_0 exited with status 1 (boom); restarted (1 of 1)"
    )
    assert supervisor.exited("robot_batch_0", KILLED, started=False) == Verdict(
        end="robot_batch_0 was killed by SIGKILL before the run started, 2 times"
    )
    assert supervisor.exited("world", KILLED) == Verdict(
        restart=True, note="world was killed by SIGKILL; restarted (1 of 1)"
    )
    assert "(--max-restarts)" in supervisor.exited("world", KILLED).end


def test_under_swarm_ros_run_a_nodes_signal_is_a_fault_not_a_stop():
    """Its nodes have process groups of their own: Ctrl-C reaches the command only, which stops them itself."""
    supervisor = Supervisor(max_restarts=3, stops=frozenset())
    assert supervisor.exited("robot_batch_0", -signal.SIGTERM).restart
    assert supervisor.exited("world", 130) == Verdict(end="world exited with status 130")


def test_the_launch_refuses_an_output_directory_behind_a_symbolic_link_loop_before_any_node(tmp_path):
    """Before, ros2 launch ran the whole swarm into a looping out_dir:= and failed at the end, leaving its partial
    recording and bag beside it."""
    (tmp_path / "L").symlink_to("L")
    with pytest.raises(InputError, match="a symbolic link that leads nowhere \\(a loop\\)"):
        _setup(tmp_path, out_dir=str(tmp_path / "L"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["L"]


def test_the_launch_refuses_a_named_pipe_as_its_shape_without_opening_it(tmp_path):
    """A pipe no one writes to blocked the launch's own read of the shape for ever."""
    import os

    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(InputError, match="not a regular file"):
        _setup(tmp_path, shape=str(tmp_path / "fifo"), out_dir=str(tmp_path / "run"))


def test_the_launch_file_starts_the_rubenstein_algorithms_nodes_from_the_same_executables(tmp_path):
    setup = _setup(tmp_path, out_dir=str(tmp_path / "run"), shape="rectangle", algorithm="rubenstein")
    assert [(name, executable) for name, executable, _ in setup.plan] == [
        ("monitor", "monitor"),
        ("robot_batch_0", "robot_batch"),
        ("robot_batch_1", "robot_batch"),
        ("world", "world"),
    ]
    assert _written(setup)["/**"]["ros__parameters"]["algorithm"] == "rubenstein"
    sharded = launch_setup(str(CONFIG), {**BLANK, "algorithm": "rubenstein"}, "", tmp_path / "log2", 2, "", "", 2)
    assert [name for name, _, _ in sharded.plan][-2:] == ["world_shard_0", "world_shard_1"]
    removing = tmp_path / "remove.yaml"
    removing.write_text(CONFIG.read_text() + "\n/world:\n  ros__parameters:\n    on_batch_loss: remove\n")
    with pytest.raises(InputError, match="on_batch_loss: remove is not for the rubenstein algorithm's graph"):
        _setup(tmp_path, removing, shape="rectangle", algorithm="rubenstein")
    cutting = tmp_path / "cuts.yaml"  # the file's cuts, as the argument's: checked in the algorithm's unit (d)
    cutting.write_text(CONFIG.read_text() + '\n/robot_batch:\n  ros__parameters:\n    region_cuts: "500"\n')
    with pytest.raises(InputError, match=r"^region_cuts \[500\] leave a strip with no cell column \(the grid's"):
        _setup(tmp_path, cutting, shape="rectangle", algorithm="rubenstein")
    cut = launch_setup(
        str(CONFIG), {**BLANK, "algorithm": "rubenstein", "shape": "rectangle"}, "", tmp_path / "l3", 2, "", "0"
    )
    assert [own.get("region_cuts") for _, _, own in cut.plan] == [None, "0", "0", None]  # to the batches
    with pytest.raises(InputError, match=r"launch argument vision_radius:=1: vision_radius is a parameter of the "):
        _setup(tmp_path, shape="rectangle", algorithm="rubenstein", vision_radius="1")  # even at its default


def test_a_domain_id_another_runs_lock_holds_is_passed_over(monkeypatch, tmp_path):
    """Two runs on one machine, whose random first pick is the same id: the second takes the next one."""
    import random
    import tempfile

    from swarm_ros.app.processes import DOMAIN_IDS, DomainLock

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # the lock files: swarm_ros-domains/<id>.lock
    monkeypatch.setattr(random, "randrange", lambda n: 0)
    first = DomainLock()
    try:
        second = DomainLock()
        assert (first.domain_id, second.domain_id) == (DOMAIN_IDS[0], DOMAIN_IDS[1])
        second.close()
    finally:
        first.close()
    assert DomainLock().domain_id == DOMAIN_IDS[0], "a closed lock is free again"
