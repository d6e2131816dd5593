"""The algorithm registry (swarm_ros.core.algorithm): every entry's hooks import and live in the layer they are
declared for, and the checks the shared code makes through it refuse in one line, with the algorithm's reason."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pytest
from layering import LAYERS, layer_of, module_graph

from swarm_ros.core import algorithm as registry
from swarm_ros.core.algorithm import (
    DARR_NIAZI,
    HOOK_LAYERS,
    RUBENSTEIN,
    algorithm_of,
    check_engine,
    check_loss_policy,
    check_world_shards,
    names,
    node_of,
)
from swarm_ros.core.errors import ContractError, ParameterError
from swarm_ros.core.params import RunParams

pytestmark = pytest.mark.unit

PACKAGE = Path(registry.__file__).resolve().parents[1]


@pytest.mark.parametrize("name", names())
def test_each_hook_imports_and_lives_in_the_layer_it_is_declared_for(name):
    entry = algorithm_of(name)
    for hook, layer in HOOK_LAYERS.items():
        where = getattr(entry, hook)
        if not where:
            continue
        module = where.partition(":")[0]
        assert layer_of(module)[1] == LAYERS[layer], f"{name}'s {hook} ({where}) is not in the {layer} layer"
        assert callable(entry.hook(hook)), f"{name}'s {hook} ({where})"


def test_a_hook_is_asked_for_only_from_its_own_layer_or_a_higher_one():
    """A module's ``.hook("x")`` call: x's layer is at or below the module's (a core module never runs a driver)."""
    graph = module_graph()
    asked = re.compile(r"""\.hook\(\s*["'](\w+)["']\s*\)""")
    seen = 0
    for module in graph:
        path = PACKAGE.parent / (module.replace(".", "/") + ".py")
        if not path.exists():
            continue
        for hook in asked.findall(path.read_text("utf-8")):
            seen += 1
            assert LAYERS[HOOK_LAYERS[hook]] <= layer_of(module)[1], f"{module} asks for {hook}"
    assert seen >= 8  # the drivers, the plan, the checks: the shared code does ask


def test_the_shared_code_never_tests_an_algorithms_name():
    """Where the shared code differs by algorithm, it asks the registry: no ``algorithm ==`` outside it."""
    branch = re.compile(r"algorithm\s*(==|!=)|(==|!=)\s*(RUBENSTEIN|DARR_NIAZI)\b")
    found = [
        f"{path.relative_to(PACKAGE.parent)}:{n}"
        for path in sorted(PACKAGE.rglob("*.py"))
        if path.name != "algorithm.py"
        for n, line in enumerate(path.read_text("utf-8").splitlines(), 1)
        if branch.search(line)
    ]
    assert found == []


def test_an_unknown_algorithm_or_a_second_of_a_name_is_refused_in_one_line():
    with pytest.raises(ParameterError, match=r"^algorithm must be one of darr-niazi, rubenstein, got 'kilo'$"):
        algorithm_of("kilo")
    with pytest.raises(ContractError, match="registered already"):
        registry.register(replace(algorithm_of(RUBENSTEIN)))
    with pytest.raises(ContractError, match="no hook"):
        algorithm_of(RUBENSTEIN).hook("decide")
    assert names()[0] == DARR_NIAZI  # the default first


def test_what_a_graph_cannot_do_is_refused_with_the_algorithms_reason_and_allowed_elsewhere(monkeypatch):
    for check, given in ((check_world_shards, True), (check_loss_policy, "remove")):
        check(DARR_NIAZI, given, "--flag")  # the study's model's graph does both
    check_world_shards(RUBENSTEIN, True, "--world-shards")  # a central world's graph has world shards
    check_loss_policy(RUBENSTEIN, "restart", "--flag")  # nothing asked: no refusal
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    registry.register(replace(algorithm_of(RUBENSTEIN), name="one-world", no_world_shards="it settles in one place"))
    with pytest.raises(
        ParameterError, match=r"^--world-shards is not for the one-world algorithm's graph \(it settles"
    ):
        check_world_shards("one-world", True, "--world-shards")
    with pytest.raises(ParameterError, match=r"^x: remove is not for the rubenstein .* has no robot failure\)$"):
        check_loss_policy(RUBENSTEIN, "remove", "x:")
    assert algorithm_of(DARR_NIAZI).removes_lost_robots and not algorithm_of(RUBENSTEIN).removes_lost_robots


def test_each_role_runs_its_algorithms_node_and_a_role_its_graph_has_not_is_refused(monkeypatch):
    """One set of executables: every algorithm's world role is the central world's node (a world shard, the world
    with peers), its monitor the central monitor, the robot batch one node over the central batch host; a role an
    entry names no node for is refused, and an engine of one algorithm refuses another's run."""
    assert node_of(RUBENSTEIN, "world").__name__ == "CentralWorldNode"
    assert node_of(RUBENSTEIN, "world") is node_of(RUBENSTEIN, "world_shard")  # a shard is the world, with peers
    for role in ("world", "world_shard", "monitor", "robot_batch"):
        assert node_of(DARR_NIAZI, role) is node_of(RUBENSTEIN, role)
    hosts = {algorithm_of(a).hook("batch_host").__name__ for a in (DARR_NIAZI, RUBENSTEIN)}
    assert hosts == {"CentralBatch"}
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    registry.register(replace(algorithm_of(RUBENSTEIN), name="one-world", world_shard_node=""))
    with pytest.raises(ParameterError, match="^the world_shard node is not a node of the one-world algorithm's graph$"):
        node_of("one-world", "world_shard")
    engine = algorithm_of(DARR_NIAZI).hook("engine")
    check_engine(DARR_NIAZI, engine)
    with pytest.raises(ParameterError, match="^Simulation does not run the rubenstein algorithm$"):
        check_engine(RUBENSTEIN, engine)


def test_the_default_run_directorys_setting_and_tick_limit_are_each_algorithms_own():
    assert algorithm_of(DARR_NIAZI).setting(RunParams(robots=10, vision_radius=2.5)) == "v2.5"
    assert algorithm_of(RUBENSTEIN).setting(RunParams(robots=10, algorithm=RUBENSTEIN)) == "rubenstein"
    assert RunParams(robots=10).max_ticks == algorithm_of(DARR_NIAZI).max_ticks == 100_000
    assert RunParams(robots=10, algorithm=RUBENSTEIN).max_ticks == algorithm_of(RUBENSTEIN).max_ticks


def test_a_plug_in_that_does_not_import_is_refused_in_one_line(monkeypatch):
    monkeypatch.setenv(registry.PLUGINS_VARIABLE, " , swarm_ros_no_such_plug_in")
    with pytest.raises(ParameterError, match=r"^SWARM_ROS_ALGORITHMS: cannot import swarm_ros_no_such_plug_in: No"):
        names()
    assert algorithm_of(DARR_NIAZI).name == DARR_NIAZI  # a built-in name is found without looking for plug-ins


def test_one_rule_says_how_often_the_robots_are_recorded_for_every_algorithm():
    """The algorithm's own cadence (the entry's record_every), or rarer by the swarm's size: the same rule for both."""
    from swarm_ros.core.params import POSES_PER_TICK, auto_every

    assert auto_every(RunParams(1024)) == 1 and auto_every(RunParams(1024, algorithm=RUBENSTEIN)) == 20
    assert auto_every(RunParams(5 * POSES_PER_TICK)) == 5
    assert auto_every(RunParams(20 * POSES_PER_TICK, algorithm=RUBENSTEIN)) == 20
    assert (
        auto_every(RunParams(25 * POSES_PER_TICK, algorithm=RUBENSTEIN))
        == 25
        == auto_every(RunParams(25 * POSES_PER_TICK))
    )
