"""Run settings from YAML parameter files in the ROS 2 form, plus command-line overrides.

A parameter file maps node names to ``ros__parameters``, so the same file serves
``ros2 run swarm_ros <node> --ros-args --params-file FILE`` and
``swarm-ros simulate --params-file FILE``::

    /**:
      ros__parameters:
        shape: star
        robots: 0          # 0 = the shape's patch count
        vision_radius: 1.0

Sections are read in file order; a later section overrides an earlier one. A section
named after a node (``/world``, ``/robot_batch``, ``/monitor``) holds only that node's
own parameters (:data:`NODE_PARAMETERS`), checked like the run's: a run parameter there
is refused, since nodes that read different values would not run the same swarm. The command line
applies them where they mean something: ``/monitor`` (recording and output directory)
in ``simulate`` and ``run``, ``/world`` in ``run``; flags override them. ``run`` refuses
``/robot_batch`` values other than the defaults, since it assigns each of its processes
its robots itself; ``simulate`` has no graph, and checks and ignores ``/world`` and
``/robot_batch``.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

from swarm_ros.core.errors import ParameterError, SwarmError
from swarm_ros.core.params import DEFAULT_MAX_TICKS, DEFAULT_SEED, DEFAULT_VISION, DEFAULT_WIGGLE_DEG, RunParams
from swarm_ros.core.rulesets import DEFAULT_RULES
from swarm_ros.core.shapes import Shape
from swarm_ros.core.grid import DEFAULT_RADIUS, World

if TYPE_CHECKING:
    from swarm_ros.artifacts.rerun_recording import Recorder


class ConfigError(SwarmError):
    """A parameter file is unreadable or holds an unknown or ill-typed key; the message names both."""


#: Memory a run takes per patch of its world, in bytes, in each process that holds the world: peak RSS of
#: ``swarm-ros simulate --world-radius R --max-ticks 3`` grew by 92 bytes per patch from R = 500 to R = 1500
#: (recording on; 84 without), rounded up.
BYTES_PER_PATCH = 100


def available_memory() -> int | None:
    """Bytes of memory available to new allocations now (``MemAvailable``), or None where that cannot be read."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_world_memory(radius: int, copies: int = 1) -> None:
    """Refuse a world too large for this machine's memory, before anything is allocated.

    ``copies``: the processes that each hold the world (1 in-process; for the ROS graph the
    world, the monitor and each robot batch).

    Raises:
        ParameterError: in one line, with the memory needed and the memory available.
    """
    available = available_memory()
    if available is None or not isinstance(radius, int) or radius < 3:
        return  # not Linux, or a bad radius (World says why)
    side = 2 * radius + 1
    needed = side * side * BYTES_PER_PATCH * copies
    if needed > available:
        largest = int(((available / (BYTES_PER_PATCH * copies)) ** 0.5 - 1) // 2)
        gib = 1024 ** 3
        each = f" in each of {copies} processes" if copies > 1 else ""
        raise ParameterError(f"world_radius {radius} needs about {needed / gib:,.1f} GiB ({side} x {side} patches at "
                             f"{BYTES_PER_PATCH} bytes each{each}), more than the {available / gib:.1f} GiB of "
                             f"memory available now; at most {largest} fits")


@dataclass(frozen=True)
class Settings:
    """What a run needs before the shape is loaded. ``robots = 0`` means the shape's patch count;
    ``join``, ``crowding`` and ``steps`` = "" mean the rule set's own value."""

    shape: str = "star"
    robots: int = 0
    vision_radius: float = DEFAULT_VISION
    rules: str = DEFAULT_RULES
    join: str = ""
    crowding: str = ""
    steps: str = ""
    seed: int = DEFAULT_SEED
    max_ticks: int = DEFAULT_MAX_TICKS
    wiggle_deg: float = DEFAULT_WIGGLE_DEG
    fail_fraction: float = 0.0
    fail_tick: int = 0
    world_radius: int = DEFAULT_RADIUS

    def updated(self, **values: object) -> Settings:
        """A copy with the given non-None values."""
        return replace(self, **{k: v for k, v in values.items() if v is not None})

    def resolve(self) -> tuple[Shape, RunParams]:
        """The shape and run parameters these settings stand for (every engine and node derives them so).

        Raises:
            SwarmError: a bad shape, a bad value, or more robots than free patches.
        """
        check_world_memory(self.world_radius)
        shape = Shape.load(self.shape, World(self.world_radius))
        params = RunParams(robots=self.robots or shape.patches, vision_radius=self.vision_radius, seed=self.seed,
                           max_ticks=self.max_ticks, wiggle_deg=self.wiggle_deg, fail_fraction=self.fail_fraction,
                           fail_tick=self.fail_tick, rules=self.rules, join=self.join, crowding=self.crowding,
                           steps=self.steps)
        params.check_vision(shape.world.radius)
        if params.robots > shape.free_patches:
            w = shape.world.size
            raise ParameterError(f"{shape.source}: {params.robots} robots do not fit on the "
                                 f"{shape.free_patches} free patches of the {w} x {w} world")
        return shape, params


_TYPES = {f.name: f.type for f in fields(Settings)}

BATCH_LOSS_POLICIES = ("restart", "remove")  #: what the graph does when a robot-batch process dies
MAX_RESTARTS = 3  #: restarts of one robot batch's process, at most, before its robots are removed

#: Each ROS node's own parameters and their defaults (the type is the default's type).
NODE_PARAMETERS: dict[str, dict[str, object]] = {
    "world": {
        "monitor_window": 128,  # max ticks the world runs ahead of the monitor; 0 = do not wait for one
        "start_timeout": 60.0,  # seconds to wait for robot batches to cover every robot
        "on_batch_loss": "restart",  # restart: wait for a lost batch process to come back; remove: remove its robots
        "max_restarts": MAX_RESTARTS,  # restarts per batch waited for; a batch lost once more has its robots removed
        "restart_timeout": 30.0,  # seconds to wait for a lost batch to come back before removing its robots
    },
    "robot_batch": {
        "batch": 0,  # this process hosts batch `batch` of `batches` (contiguous ids) ...
        "batches": 1,
        "robot_ids": "",  # ... unless robot_ids lists them, e.g. "4-99,150"
        "incarnation": 0,  # 0 for a batch's first process; the launcher counts restarts up from 1
    },
    "monitor": {
        "out_dir": "",  # run directory; "" = runs/<time>_<shape>_n<N>_v<R>_s<seed>
        "overwrite": False,  # replace an existing run directory
        "record": True,  # write recording.rrd (Rerun) into the run directory
        "record_every": 1,  # log the robots every k-th tick (metrics: every tick)
        "bag": True,  # write bag/, a rosbag2 (MCAP) of every message on the swarm's topics
        "viewer_url": "",  # also stream live to this Rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy
    },
}
_NODE_TYPES = {node: {k: type(v).__name__ for k, v in own.items()} for node, own in NODE_PARAMETERS.items()}


def check_node_values(kind: str, values: dict[str, object], where: str = "") -> None:
    """Range checks of a node's own parameters (types are checked where they are read).

    Raises:
        ParameterError: a value out of its range, in one line naming the parameter (and ``where``).
    """
    limits = {
        "monitor_window": (lambda v: v >= 0, "an integer >= 0"),
        "start_timeout": (lambda v: 0 < v < float("inf"), "a number > 0"),
        "max_restarts": (lambda v: v >= 0, "an integer >= 0"),
        "restart_timeout": (lambda v: 0 < v < float("inf"), "a number > 0"),
        "on_batch_loss": (lambda v: v in BATCH_LOSS_POLICIES, f"one of {', '.join(BATCH_LOSS_POLICIES)}"),
        "batches": (lambda v: v >= 1, "an integer >= 1"),
        "batch": (lambda v: v >= 0, "an integer >= 0"),
        "incarnation": (lambda v: v >= 0, "an integer >= 0"),
        "record_every": (lambda v: v >= 1, "an integer >= 1"),
    }
    prefix = f"{where}: " if where else ""
    for key, value in values.items():
        if key in limits and key in NODE_PARAMETERS[kind] and not limits[key][0](value):
            raise ParameterError(f"{prefix}{key} must be {limits[key][1]}, got {value!r}")


_TYPE_WORDS = {"str": "a string", "int": "an integer", "float": "a number", "bool": "a boolean"}


def _check_type(path: Path, key: str, value: object, want: str) -> object:
    if want == "bool":
        ok = isinstance(value, bool)
    elif want == "str":
        ok = isinstance(value, str)
    elif want == "int":
        ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    else:
        ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
        value = float(value) if ok else value
    if not ok:
        raise ConfigError(f"{path}: parameter '{key}' must be {_TYPE_WORDS[want]}, got {value!r}")
    return value


def read_yaml(path: Path, what: str, error: type[SwarmError]) -> object:
    """The YAML document in ``path``, or ``error`` with one line naming the file (unreadable, bad YAML)."""
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise error(f"{path}: not valid YAML ({first})") from None


def load_params_file(path: str | Path, base: Settings | None = None) -> Settings:
    """The run settings of a ROS 2 style parameter file over ``base`` (defaults if None).

    Raises:
        ConfigError: unreadable file, bad YAML, wrong layout, unknown key or wrong type.
    """
    return read_params_file(path, base)[0]


def read_params_file(path: str | Path, base: Settings | None = None) -> tuple[Settings, dict[str, dict[str, object]]]:
    """The run settings of a parameter file over ``base``, and the node parameters its node sections set.

    The second item maps each node kind (``world``, ``robot_batch``, ``monitor``) to the
    parameters of its own that the file sets, types and ranges checked.

    Raises:
        ConfigError: unreadable file, bad YAML, wrong layout, unknown key or wrong type.
        ParameterError: a node parameter out of its range.
    """
    path = Path(path)
    data = read_yaml(path, "parameter file", ConfigError)
    if not isinstance(data, dict) or not data:
        raise ConfigError(f"{path}: expected '/node_name: ros__parameters: {{...}}' sections")
    values: dict[str, object] = {}
    nodes: dict[str, dict[str, object]] = {kind: {} for kind in NODE_PARAMETERS}
    for node, section in data.items():
        if not isinstance(section, dict) or set(section) != {"ros__parameters"} \
                or not isinstance(section["ros__parameters"], dict):
            raise ConfigError(f"{path}: section '{node}' must hold exactly one 'ros__parameters' mapping")
        kind = str(node).lstrip("/")
        own = _NODE_TYPES.get(kind, {})
        known = {**_TYPES, **own}
        for key, value in section["ros__parameters"].items():
            if key not in known:
                raise ConfigError(f"{path}: unknown parameter '{key}' in '{node}' "
                                  f"(known: {', '.join(sorted(known))})")
            checked = _check_type(path, key, value, known[key])
            if key in _TYPES and own:
                raise ConfigError(f"{path}: '{node}' sets the run parameter '{key}'; run parameters go in '/**', "
                                  f"which every node reads, so that all nodes run the same swarm")
            if key in _TYPES:
                values[key] = checked
            else:
                nodes[kind][key] = checked
    for kind, given in nodes.items():
        check_node_values(kind, given, where=f"{path}: /{kind}")
    return (base or Settings()).updated(**values), nodes


_URL_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")


@dataclass(frozen=True)
class RecordingOptions:
    """How a run is recorded; the same for both engines (CLI flags, monitor parameters).

    Attributes:
        enabled: write recording.rrd (default on).
        every: log the robots every ``every``-th tick (>= 1).
        spawn: start a viewer and stream to it live.
        connect: stream live to the viewer at this URL.
    """

    enabled: bool = True
    every: int = 1
    spawn: bool = False
    connect: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.every, int) or isinstance(self.every, bool) or self.every < 1:
            raise ParameterError(f"record_every must be an integer >= 1, got {self.every!r}")
        if self.connect and not self.connect.startswith(_URL_SCHEMES):
            raise ParameterError(f"viewer URL must start with one of {', '.join(_URL_SCHEMES)}, "
                                 f"got {self.connect!r} (e.g. rerun+http://127.0.0.1:9876/proxy)")

    def reachable(self, timeout: float = 1.0) -> RecordingOptions:
        """These options, without ``connect`` if no viewer answers there (said in one line on stderr).

        Rerun would otherwise retry for about ten seconds and print its own errors; the
        recording file does not depend on the viewer, so the run goes on without it.
        """
        if not self.connect:
            return self
        import socket
        import sys
        from urllib.parse import urlsplit

        try:
            url = urlsplit(self.connect)
            host, port = url.hostname or "127.0.0.1", url.port or 9876
        except ValueError as exc:
            raise ParameterError(f"viewer URL {self.connect!r}: {exc}") from None
        try:
            socket.create_connection((host, port), timeout=timeout).close()
            return self
        except OSError as exc:
            print(f"swarm-ros: warning: no Rerun viewer answers at {self.connect} ({exc.strerror or exc}); "
                  f"going on without it", file=sys.stderr, flush=True)
            return replace(self, connect=None)

    @property
    def active(self) -> bool:
        """Whether anything is recorded at all (to a file or a viewer)."""
        return self.enabled or self.spawn or bool(self.connect)

    def open(self, path: Path, shape: Shape, params: RunParams) -> Recorder | None:
        """A :class:`Recorder` streaming to ``path`` (if enabled) and the viewer, or None if nothing is recorded."""
        if not self.active:
            return None
        from swarm_ros.artifacts.rerun_recording import Recorder

        return Recorder(path if self.enabled else None, shape, params, every=self.every, spawn=self.spawn,
                        connect=self.connect)
