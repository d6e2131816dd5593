"""launch/swarm.launch.py, without ROS 2's launch packages (they are not installable here).

The file is loaded under small stand-ins for ``launch`` and ``launch_ros`` that record
the actions it declares; the recorded nodes, executables, parameters and remappings must
be those ``swarm-ros run`` starts for the same arguments. What this cannot check is
``ros2 launch`` itself: docs/ros_graph.md says how to run the file on a ROS 2 Jazzy install.
"""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path

import pytest
import yaml

from swarm_ros.app import launcher, processes
from swarm_ros.app.launcher import Launch
from swarm_ros.core import Shape
from swarm_ros.core.params import Settings
from swarm_ros.protocol.runkey import KEY_ENV, run_key

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent
LAUNCH_FILE = ROOT / "launch" / "swarm.launch.py"


class _Action:
    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _LaunchConfiguration:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context.values[self.name]


class _Context:
    def __init__(self, values):
        self.values = values


def _stub_modules(monkeypatch) -> None:
    """Stand-ins for the parts of launch / launch_ros the file uses, recording their arguments."""
    launch = types.ModuleType("launch")
    launch.LaunchDescription = type("LaunchDescription", (_Action,), {})
    actions = types.ModuleType("launch.actions")
    for name in ("DeclareLaunchArgument", "OpaqueFunction", "SetEnvironmentVariable", "EmitEvent",
                 "RegisterEventHandler", "TimerAction"):
        setattr(actions, name, type(name, (_Action,), {}))
    event_handlers = types.ModuleType("launch.event_handlers")
    event_handlers.OnProcessExit = type("OnProcessExit", (_Action,), {})
    events = types.ModuleType("launch.events")
    events.Shutdown = type("Shutdown", (_Action,), {})
    substitutions = types.ModuleType("launch.substitutions")
    substitutions.LaunchConfiguration = _LaunchConfiguration
    launch_ros = types.ModuleType("launch_ros")
    ros_actions = types.ModuleType("launch_ros.actions")
    ros_actions.Node = type("Node", (_Action,), {})
    index = types.ModuleType("ament_index_python.packages")
    index.get_package_share_directory = lambda package: str(ROOT)  # the source tree has config/, shapes/
    for name, module in {"launch": launch, "launch.actions": actions, "launch.substitutions": substitutions,
                         "launch.event_handlers": event_handlers, "launch.events": events,
                         "launch_ros": launch_ros, "launch_ros.actions": ros_actions,
                         "ament_index_python.packages": index}.items():
        monkeypatch.setitem(sys.modules, name, module)


def _launched(monkeypatch, **arguments: str) -> tuple[list, dict[str, str]]:
    """(the Node actions, the environment it sets) of the launch file for these launch arguments."""
    nodes, env, _ = _launch_actions(monkeypatch, **arguments)
    return nodes, env


def _launch_actions(monkeypatch, user_env: dict[str, str] | None = None,
                    **arguments: str) -> tuple[list, dict[str, str], list]:
    """(the Node actions, the environment, the other actions of the graph) for these launch arguments,
    with only ``user_env`` of the variables the launch file reads set."""
    _stub_modules(monkeypatch)
    for name in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "FASTRTPS_DEFAULT_PROFILES_FILE", KEY_ENV):
        monkeypatch.delenv(name, raising=False)
    for name, value in (user_env or {}).items():
        monkeypatch.setenv(name, value)
    spec = importlib.util.spec_from_file_location("swarm_launch", LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    entities = module.generate_launch_description().args[0]
    kinds = {type(e).__name__ for e in entities}
    assert kinds == {"DeclareLaunchArgument", "SetEnvironmentVariable", "OpaqueFunction"}
    declared = {e.args[0]: e.kwargs["default_value"] for e in entities if type(e).__name__ == "DeclareLaunchArgument"}
    assert set(arguments) <= set(declared), "every argument used here is a declared launch argument"
    env = {e.args[0]: e.args[1] for e in entities if type(e).__name__ == "SetEnvironmentVariable"}
    context = _Context({**declared, **arguments})
    (function,) = [e.kwargs["function"] for e in entities if type(e).__name__ == "OpaqueFunction"]
    graph = function(context)
    nodes = [a for a in graph if type(a).__name__ == "Node"]
    return nodes, env, [a for a in graph if type(a).__name__ != "Node"]


def _effective(parameters: list, node: str) -> dict:
    """A node's parameters as ROS 2 resolves a list of parameter files and dicts (later wins)."""
    values: dict = {}
    for item in parameters:
        if isinstance(item, str):
            doc = yaml.safe_load(Path(item).read_text())
            for key in ("/**", f"/{node}"):
                values.update(doc.get(key, {}).get("ros__parameters", {}))
        else:
            values.update(item)
    return values


@pytest.mark.parametrize("arguments,settings,processes", [
    ({}, {}, 2),
    ({"shape": "k-letter", "processes": "3", "seed": "9", "rules": "local", "vision_radius": "2.0"},
     {"shape": "k-letter", "seed": 9, "rules": "local", "vision_radius": 2.0}, 3),
])
def test_the_launch_file_starts_the_graph_swarm_ros_run_starts(monkeypatch, tmp_path, arguments, settings,
                                                              processes):
    nodes, env = _launched(monkeypatch, **arguments)
    run = Settings(**settings)
    shape, params = run.resolve()
    launch = Launch(settings=run, shape=shape, params=params, processes=processes, out=tmp_path / "run")
    plan = launch.plan()
    # the same processes, in the same order, with the same executables (ros2 run's names) and node names
    assert [(n.kwargs["name"], n.kwargs["executable"]) for n in nodes] == [(name, exe) for name, exe, _ in plan]
    assert {n.kwargs["package"] for n in nodes} == {"swarm_ros"}
    # no remappings either way: swarm-ros run only names the node (-r __node:=<name>), as name= does
    assert all("remappings" not in n.kwargs for n in nodes)
    # batches are respawned, as swarm-ros run restarts them
    assert [n.kwargs.get("respawn", False) for n in nodes] == [name.startswith("robot_batch") for name, _, _ in plan]
    # the run parameters each node reads equal those of swarm-ros run with the package's parameter file
    config = ROOT / "config" / "swarm_ros.yaml"
    expected = {k: v for k, v in yaml.safe_load(config.read_text())["/**"]["ros__parameters"].items()}
    expected.update(settings)
    for node, (name, _, extra) in zip(nodes, plan):
        values = _effective(node.kwargs["parameters"], name)
        assert {k: values[k] for k in expected} == expected, name
        assert {k: values[k] for k in extra} == extra, name
    # the environment swarm-ros run gives its nodes (processes.node_env), with a new run key
    key = env.pop(KEY_ENV)
    assert env == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                   "FASTRTPS_DEFAULT_PROFILES_FILE": str(ROOT / "config" / "fastdds.xml")}
    assert run_key({KEY_ENV: key})[1] and len(key) == 64 and key != _launched(monkeypatch, **arguments)[1][KEY_ENV]
    assert Shape.load(values["shape"]).name == shape.name


def test_the_launch_file_passes_a_parameter_file_and_an_output_directory(monkeypatch, tmp_path):
    params = tmp_path / "mine.yaml"
    params.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"shape": "tyre", "seed": 4}},
                                      "/monitor": {"ros__parameters": {"record": False}}}))
    nodes, _ = _launched(monkeypatch, params_file=str(params), out_dir=str(tmp_path / "out"), seed="5")
    by_name = {n.kwargs["name"]: _effective(n.kwargs["parameters"], n.kwargs["name"]) for n in nodes}
    assert {name: (v["shape"], v["seed"]) for name, v in by_name.items()} == dict.fromkeys(by_name, ("tyre", 5))
    assert by_name["monitor"]["record"] is False and by_name["monitor"]["out_dir"] == str(tmp_path / "out")


def test_the_launch_file_passes_sros2_enclaves_as_swarm_ros_run_does(monkeypatch, tmp_path):
    assert all("ros_arguments" not in n.kwargs for n in _launched(monkeypatch)[0])  # none unless asked
    nodes, _ = _launched(monkeypatch, enclaves="/swarm_ros")
    run = Settings()
    shape, params = run.resolve()
    launch = Launch(settings=run, shape=shape, params=params, processes=2, out=tmp_path / "run", enclaves="/swarm_ros")
    commands = {name: processes.node_command(exe, tmp_path / "p.yaml", name, extra, launch.enclaves)
                for name, exe, extra in launch.plan()}
    for node in nodes:
        name = node.kwargs["name"]
        assert node.kwargs["ros_arguments"] == ["--enclave", f"/swarm_ros/{name}"]
        i = commands[name].index("--enclave")
        assert commands[name][i:i + 2] == node.kwargs["ros_arguments"], name


def test_the_launch_file_keeps_a_run_key_the_user_set(monkeypatch):
    _, env, _ = _launch_actions(monkeypatch, user_env={KEY_ENV: "a key for every host of mine"})
    assert env[KEY_ENV] == "a key for every host of mine"


class _Exited:
    """A ProcessExited event, as far as the handlers read it."""

    def __init__(self, returncode: int):
        self.returncode = returncode


def _end_handlers(monkeypatch) -> dict:
    """{node name: the on_exit callable the launch file registers for it}."""
    nodes, _, others = _launch_actions(monkeypatch)
    assert {type(a).__name__ for a in others} == {"RegisterEventHandler"}
    handlers = [a.args[0] for a in others]
    assert {type(h).__name__ for h in handlers} == {"OnProcessExit"}
    by_action = {id(n): n.kwargs["name"] for n in nodes}
    return {by_action[id(h.kwargs["target_action"])]: h.kwargs["on_exit"] for h in handlers}


def _shutdown(actions) -> str | None:
    """The reason of the Shutdown these actions emit at once; None if they emit none."""
    for action in actions or []:
        if type(action).__name__ == "EmitEvent" and type(action.kwargs["event"]).__name__ == "Shutdown":
            return action.kwargs["event"].kwargs["reason"]
    return None


@pytest.mark.parametrize("exits,ends_at", [
    ([("world", 0), ("monitor", 0)], 1),  # the normal end: the monitor writes the run after the world's outcome
    ([("monitor", 0)], 0),  # the monitor is done: the batches' respawns must not keep the launch going
    ([("world", 1)], 0),  # the world failed: nobody will end the run
    ([("monitor", 1), ("world", 0)], 1),  # the monitor died mid-run: the swarm runs to its end without it
    ([("monitor", 1), ("world", 1)], 1),
])
def test_the_launch_ends_with_the_run(monkeypatch, exits, ends_at):
    handlers = _end_handlers(monkeypatch)
    assert set(handlers) == {"world", "monitor"}
    for i, (name, code) in enumerate(exits):
        actions = handlers[name](_Exited(code), None)
        reason = _shutdown(actions)
        assert (reason is not None) == (i == ends_at), (name, code, actions)
        if reason is not None:
            assert f"{name} exited with status {code}" in reason
            return
    raise AssertionError("the launch never ended")


def test_a_monitor_that_never_writes_the_run_is_given_up_on(monkeypatch):
    handlers = _end_handlers(monkeypatch)
    (timer,) = handlers["world"](_Exited(0), None)
    assert type(timer).__name__ == "TimerAction" and timer.kwargs["period"] == 3 * launcher._GRACE  # as swarm-ros run
    assert "did not write the run" in _shutdown(timer.kwargs["actions"])
