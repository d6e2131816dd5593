"""The shape-formation algorithms swarm_ros runs, and what each one supplies: the one place a command, a node or a
report asks "which algorithm, and what is its own here?". The ``algorithm`` run parameter picks an entry.

An entry is data: numbers the shared code needs (the tick limit, memory a robot, the shape dimensions it forms, the
loss policies its graph supports) and, for what is code, the dotted name of the function or class that supplies it
(``"package.module:attribute"``), imported when first asked for. The shared code (the drivers, the nodes, the launch
file, experiments, the report) calls these hooks and never tests an algorithm's name. Each hook names the layer it
lives in (:data:`HOOK_LAYERS`): a module may ask only for hooks of its own layer or a lower one (test_algorithm).

A third algorithm is a module that calls :func:`register` when imported, named in the environment variable
``SWARM_ROS_ALGORITHMS`` (modules, comma-separated; the graph's node processes inherit it): it is imported when
the algorithms are first listed or one not built in is asked for (docs/adding_an_algorithm.md).
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass, field, fields
from typing import Any

from .errors import ContractError, ParameterError

DARR_NIAZI, RUBENSTEIN = "darr-niazi", "rubenstein"

#: The layer of each hook of an entry (docs/architecture.md, test_layers): who may ask for it.
HOOK_LAYERS = {
    "engine": "core",
    "summary": "core",
    "check_params": "core",
    "check_shape": "core",
    "compile": "core",
    "warm_up": "core",
    "checked_step": "core",
    "plan": "protocol",
    "batch_host": "protocol",
    "wire": "protocol",
    "recording": "artifacts",
    "write_run": "artifacts",
    "world_node": "nodes",
    "world_shard_node": "nodes",
    "robot_batch_node": "nodes",
    "monitor_node": "nodes",
    "check_graph": "app",
    "print_summary": "app",
    "as_study_row": "app",
}


@dataclass(frozen=True)
class Algorithm:
    """One shape-formation algorithm: its numbers, and the dotted names of its hooks (see the module)."""

    name: str
    #: tick limit when ``max_ticks`` is left at 0
    max_ticks: int
    #: memory a run takes per robot, in bytes (peak RSS growth per robot; core.resources checks a run against it)
    bytes_per_robot: int
    #: its kernel modules' package, relative to swarm_ros/core ("" if it has none), for core.kernels' cache stamps
    kernel_dir: str
    #: about how long its kernels take to compile, in seconds (scripts/bench_compile.py, a quiet 2-core machine)
    compile_seconds: int
    #: the directory name's setting part of its default run directory, formatted with the run's parameters
    run_dir_setting: str
    #: what simulate's progress bar counts: the unit of a cell of the shape, and what is done with it
    progress_unit: str
    progress_what: str
    #: what the shape's cells are called in a report ("patches", "pixels")
    cells: str = "patches"
    #: what a report calls the counts in results.csv's localized, unlocalized and empty_patches columns
    count_words: tuple[str, str, str] = ("localized robots", "unlocalized robots", "empty shape patches")
    #: the robots are recorded every this many ticks unless told, or more rarely in a large swarm (params.auto_every)
    record_every: int = 1
    #: the core's kernel modules its kernels call (and so carry compiled in): a change to one leaves its cache stale
    shared_kernels: tuple[str, ...] = ()
    #: whether its graph can remove a lost batch's robots and go on (``on_batch_loss: remove``); if not, why not
    no_removal: str = ""
    #: why its graph refuses world shards ("" if it runs with them)
    no_world_shards: str = ""
    # -- hooks: "module:attribute" (HOOK_LAYERS says each one's layer) --
    #: class ``(shape, params)``: the in-process engine (``run(max_ticks)``, ``tick``, ``done``, ``outcome``,
    #: ``history``, ``progress()``, ``empty_curve()``; ``step()`` for ``checked_step``; a central world's also what
    #: :class:`~swarm_ros.core.strips.CentralRun` says)
    engine: str = ""
    #: ``(run, wall_seconds, stopped=None) -> dict``: the summary.json record of an in-process run
    summary: str = ""
    #: ``(params) -> None``: its own checks of the run parameters (ParameterError), or "" for none
    check_params: str = ""
    #: ``(params, shape) -> None``: refuse a shape it cannot form (ParameterError)
    check_shape: str = ""
    #: ``() -> None``: run a few ticks of each of its code paths, so numba compiles its kernels into their cache
    #: ("": it has no kernels of its own)
    compile: str = ""
    #: ``(shape, params) -> None``: load its run's compiled kernels into this process, or "": the launcher then
    #: starts each node afresh instead of forking it from a process that has them loaded (app/forking.py)
    warm_up: str = ""
    #: ``(processes, region_cuts, world_shards) -> [(name, executable, parameters)]``: its graph's node processes
    plan: str = ""
    #: class ``(shape, params, own, drop)``: what a robot batch of its graph hears and decides (a
    #: :class:`~swarm_ros.protocol.batch_host.BatchHost`), for the one robot-batch node (``robot_batch_node``
    #: ``swarm_ros.nodes.robot_batch:RobotBatchNode``)
    batch_host: str = ""
    #: ``(dims) -> Wire``: in a central world's graph (one world process holding every robot: core.strips), its rows on
    #: the wire in a world of ``dims`` dimensions, their checks and its batch (a
    #: :class:`~swarm_ros.protocol.central_rows.Wire`); "" for none
    wire: str = ""
    #: its graph's node classes, one per role its graph runs, each ``(node, settings, own parameters)``: an rclpy node
    #: made, and its parameters read, by the role's executable (nodes/roles.py); "" for a role its graph has not
    world_node: str = ""
    world_shard_node: str = ""
    robot_batch_node: str = ""
    monitor_node: str = ""
    #: ``(shape, params, processes, region_cuts, flag) -> None``: its own checks of a graph run (ParameterError): that
    #: its world cuts into ``processes`` strips (``flag``: how the user named that count), at ``region_cuts`` (x
    #: positions in its unit) if given
    check_graph: str = ""
    #: ``(run) -> None``: one tick of the engine, with every invariant that must hold over it checked (``--check``)
    checked_step: str = ""
    #: ``(path, run, options) -> recorder | None``: the recording of an in-process run (``every``, ``log(run)`` as
    #: ticks go, ``finish(run, outcome)``); None if the options record nothing
    recording: str = ""
    #: ``(out, run, summary, overwrite, recording, every, bag=None) -> Path``: the run directory of a run (an
    #: in-process one's; a central world's monitor's, with its ``bag``)
    write_run: str = ""
    #: ``(summary, out, dims) -> None``: the summary a command prints at the end of a run
    print_summary: str = ""
    #: ``(summary) -> dict``: its summary in the columns of the study's results.csv, or "" if they are its own
    as_study_row: str = ""
    _loaded: dict = field(default_factory=dict, compare=False, repr=False)

    def hook(self, name: str) -> Any:
        """The hook ``name``, imported on first use; ``None`` if this algorithm has none."""
        if name not in HOOK_LAYERS:
            raise ContractError(f"no hook {name!r}: one of {', '.join(HOOK_LAYERS)}")
        where = getattr(self, name)
        if not where:
            return None
        if name not in self._loaded:
            module, _, attribute = where.partition(":")
            self._loaded[name] = getattr(importlib.import_module(module), attribute)
        return self._loaded[name]

    def setting(self, params: Any) -> str:
        """The setting part of a default run directory's name (``v1``, ``rubenstein``)."""
        return self.run_dir_setting.format(**{f.name: getattr(params, f.name) for f in fields(params)})

    @property
    def removes_lost_robots(self) -> bool:
        """Whether its graph can remove a lost batch's robots and go on (``on_batch_loss: remove``)."""
        return not self.no_removal


_REGISTRY: dict[str, Algorithm] = {}
PLUGINS_VARIABLE = "SWARM_ROS_ALGORITHMS"  #: modules that register an algorithm, comma-separated
_plugged: set[str] = set()  #: the plug-in modules imported so far


def _load_plugins() -> None:
    """Import the plug-in modules ``SWARM_ROS_ALGORITHMS`` names (each registers its algorithm), once each.

    Raises:
        ParameterError: a module named cannot be imported, in one line.
    """
    for module in (m.strip() for m in os.environ.get(PLUGINS_VARIABLE, "").split(",")):
        if not module or module in _plugged:
            continue
        _plugged.add(module)
        try:
            importlib.import_module(module)
        except Exception as exc:  # whatever a plug-in raises as it loads: said in one line, as bad input
            raise ParameterError(f"{PLUGINS_VARIABLE}: cannot import {module}: {exc}") from None


def register(algorithm: Algorithm) -> Algorithm:
    """Add ``algorithm`` (a name not yet taken): the ``algorithm`` parameter then accepts its name."""
    if algorithm.name in _REGISTRY:
        raise ContractError(f"an algorithm named {algorithm.name!r} is registered already")
    _REGISTRY[algorithm.name] = algorithm
    return algorithm


def names() -> tuple[str, ...]:
    """Every registered algorithm's name, in the order registered (the study's model first: the default), plug-ins
    included."""
    _load_plugins()
    return tuple(_REGISTRY)


def algorithm_of(name: str) -> Algorithm:
    """The registered algorithm ``name``.

    Raises:
        ParameterError: no algorithm of that name, in one line with the names there are.
    """
    if name not in _REGISTRY:
        _load_plugins()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ParameterError(f"algorithm must be one of {', '.join(_REGISTRY)}, got {name!r}") from None


def node_of(name: str, role: str) -> Any:
    """The node class of algorithm ``name`` for ``role`` (world, world_shard, robot_batch, monitor): what that
    role's executable runs.

    Raises:
        ParameterError: in one line, if the algorithm's graph has no node of that role.
    """
    node = algorithm_of(name).hook(f"{role}_node")
    if node is None:
        raise ParameterError(f"the {role} node is not a node of the {name} algorithm's graph")
    return node


#: What a command needs of an algorithm beyond its engine: its hook, and what the refusal says is missing
_NEEDS = {"graph": ("plan", "no ROS 2 graph yet (swarm-ros simulate runs it)"), "check": ("checked_step", "no --check")}


def check_can(name: str, need: str) -> None:
    """Refuse, in one line, a command that needs what algorithm ``name`` does not supply: ``"graph"`` (``run``, the
    launch file, an experiment over the graph) or ``"check"`` (``simulate --check``); ``""`` asks nothing.

    Raises:
        ParameterError: the algorithm has no such hook.
    """
    if need and not getattr(algorithm_of(name), _NEEDS[need][0]):
        raise ParameterError(f"the {name} algorithm has {_NEEDS[need][1]}")


def check_world_shards(name: str, given: object, said: str) -> None:
    """Refuse world shards (``given`` true), which ``said`` set, for a graph that has none.

    Raises:
        ParameterError: in one line, with the reason.
    """
    reason = algorithm_of(name).no_world_shards
    if given and reason:
        raise ParameterError(f"{said} is not for the {name} algorithm's graph ({reason})")


def check_loss_policy(name: str, policy: object, said: str) -> None:
    """Refuse ``on_batch_loss: remove`` (``policy``, which ``said`` set) for a graph that cannot remove robots.

    Raises:
        ParameterError: in one line, with the reason.
    """
    reason = algorithm_of(name).no_removal
    if policy == "remove" and reason:
        raise ParameterError(f"{said} remove is not for the {name} algorithm's graph ({reason})")


def check_engine(name: str, engine: type) -> None:
    """Refuse to run ``engine`` (an in-process engine class) for algorithm ``name`` if it is not that one's.

    Raises:
        ParameterError: in one line.
    """
    if algorithm_of(name).engine != f"{engine.__module__}:{engine.__qualname__}":
        raise ParameterError(f"{engine.__qualname__} does not run the {name} algorithm")


#: The hooks of an algorithm whose world holds every robot (a central world: core.strips), all
#: but its own (``engine``, ``summary``, ``wire``): ``Algorithm(**CENTRAL, ...)`` takes the graph's nodes, plan and
#: checks, and a plain recording and run directory, which an entry may replace with its own.
CENTRAL: dict[str, Any] = {
    "plan": "swarm_ros.protocol.plan:graph_plan",
    "check_graph": "swarm_ros.app.processes:check_central_graph",
    "world_node": "swarm_ros.nodes.central.world:CentralWorldNode",
    "world_shard_node": "swarm_ros.nodes.central.world:CentralWorldNode",
    "robot_batch_node": "swarm_ros.nodes.robot_batch:RobotBatchNode",
    "batch_host": "swarm_ros.protocol.central_batch:CentralBatch",
    "monitor_node": "swarm_ros.nodes.central.monitor:CentralMonitorNode",
    "recording": "swarm_ros.artifacts.central_recording:open_recording",
    "write_run": "swarm_ros.artifacts.central_run_dir:write_simulation",
}

register(
    Algorithm(
        name=DARR_NIAZI,
        max_ticks=100_000,  # the study's
        # peak RSS of `swarm-ros simulate --world-radius 300 --max-ticks 1` (recording on) grew by 210 bytes per robot
        # from 20,000 to 200,000 robots, rounded up
        bytes_per_robot=250,
        kernel_dir="darr_niazi",
        compile_seconds=40,
        run_dir_setting="v{vision_radius:g}",
        progress_unit="patch",
        progress_what="localized",
        engine="swarm_ros.core.darr_niazi.engine:Simulation",
        summary="swarm_ros.core.darr_niazi.run_result:summary_of",
        wire="swarm_ros.protocol.darr_niazi.wire:StudyWire",
        check_shape="swarm_ros.core.params:check_vision_fits",
        compile="swarm_ros.core.darr_niazi.warmup:compile_kernels",
        warm_up="swarm_ros.core.darr_niazi.warmup:warm_up",
        shared_kernels=("rng.py",),
        **{
            **CENTRAL,  # its own recording, run directory and printed summary:
            "recording": "swarm_ros.artifacts.darr_niazi.recording:open_recording",
            "write_run": "swarm_ros.artifacts.darr_niazi.run_dir:write_simulation",
            "print_summary": "swarm_ros.app.darr_niazi.summary:print_summary",
        },
        checked_step="swarm_ros.core.darr_niazi.invariants:checked_step",
    )
)
register(
    Algorithm(
        name=RUBENSTEIN,
        # room for a 1,024-robot run, in which one robot leaves the pack every hundred-odd ticks (the star: about
        # 180,000 ticks)
        max_ticks=400_000,
        # peak RSS grew by 480 bytes per robot from 20,000 to 80,000 robots (as above), rounded up
        bytes_per_robot=600,
        kernel_dir="rubenstein",
        compile_seconds=17,
        run_dir_setting="rubenstein",
        progress_unit="pixel",
        progress_what="covered",
        cells="pixels",
        count_words=("joined robots", "robots not joined", "uncovered pixels"),
        record_every=20,  # a robot steps 0.05 d a tick by default, and a run lasts tens of thousands of ticks
        shared_kernels=("rng.py",),
        **{
            **CENTRAL,  # its own recording, run directory and printed summary:
            "recording": "swarm_ros.artifacts.rubenstein.recording:open_recording",
            "write_run": "swarm_ros.artifacts.rubenstein.run_dir:write_simulation",
            "print_summary": "swarm_ros.app.rubenstein.summary:print_summary",
        },
        no_removal="a lost batch is restarted: the algorithm has no robot failure",
        engine="swarm_ros.core.rubenstein.run:RubensteinRun",
        summary="swarm_ros.core.rubenstein.run:summary_of",
        check_params="swarm_ros.core.rubenstein.layout:check_params",
        check_shape="swarm_ros.core.rubenstein.layout:check_shape_of",
        compile="swarm_ros.core.rubenstein.run:compile_kernels",
        wire="swarm_ros.protocol.rubenstein.rows:RubensteinWire",
        checked_step="swarm_ros.core.rubenstein.tick_checks:checked_step",
        as_study_row="swarm_ros.app.rubenstein.summary:as_study_row",
    )
)
