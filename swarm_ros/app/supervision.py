"""What is done when one of a run's node processes ends, as plain decisions: ``swarm-ros run``
(:mod:`swarm_ros.app.launcher`) and ``ros2 launch swarm_ros swarm.launch.py`` both follow them, each
turning a verdict into its own actions (a process started again, the run ended). And what the launch
file starts the graph with (:func:`launch_setup`).

- The monitor exits 0: it has written the run; the launch ends once the others have exited too.
- The world exits 0: the run has ended; the monitor has :data:`MONITOR_GRACE` seconds to write it.
- The world or the monitor killed by a signal: started again, with the next incarnation, up to
  ``max_restarts`` times (the world goes on from its checkpoint, the monitor from its bag); once more,
  the launch ends: the run cannot go on.
- The world or the monitor exits with an error status: the run failed there (a restart would fail the
  same way); the launch ends. So does a batch lost more than ``max_restarts`` times before tick 0.
- A process stopped by the user (Ctrl-C in the launch's terminal signals every process; exit status 130,
  or killed by SIGINT, SIGTERM or SIGHUP): the launch stops, nothing is started again; the monitor, if it
  was stopped after tick 0, has written the run so far (outcome ``interrupted``).
- A robot batch exits non-zero before the world's end: under ``on_batch_loss: restart`` (or before tick 0)
  started again (same robots, next incarnation) up to ``max_restarts`` times; otherwise the world removes
  its robots and the run goes on. A batch that exits 0 has seen the run's end.

Unlike ``respawn`` (which starts a process again whatever its exit status, with the same arguments),
a batch that ends with the run is not started again, and a restarted process is told its incarnation.
"""

from __future__ import annotations

import json
import signal
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from swarm_ros.app.param_file import check_given, check_launcher_sets, params_yaml, read_params_file, record_every
from swarm_ros.app.processes import CHECKPOINT, check_graph, check_graph_shape, death, world_sections
from swarm_ros.artifacts.run_dir import check_out_dir, default_run_dir
from swarm_ros.core.algorithm import DARR_NIAZI, algorithm_of, check_can, check_loss_policy, check_world_shards
from swarm_ros.core.errors import ConfigError, ParameterError, RunFailed
from swarm_ros.core.params import RUN_PARAMETER, Param, node_defaults
from swarm_ros.core.signals import EXIT_INTERRUPTED
from swarm_ros.protocol.plan import MONITOR, PROCESSES, WORLD, is_world, plan_for


class RunEnded(RunFailed):
    """The launch ends because the run failed: ``ros2 launch`` prints it in one line, stops every node, exits 1."""


#: Exit statuses of a process the user stopped: 130 (a node's Ctrl-C or SIGTERM), 129 (its launcher died),
#: killed by SIGINT, SIGTERM or SIGHUP before its handlers were in place.
STOPPED = frozenset({EXIT_INTERRUPTED, EXIT_INTERRUPTED - 1, -signal.SIGINT, -signal.SIGTERM, -signal.SIGHUP})
MONITOR_GRACE = 30.0  #: seconds the monitor has to write the run after the world's end (as ``swarm-ros run``)
END_GRACE = 10.0  #: seconds the others get to end by themselves once the monitor has written the run
LATE_STATUS = 1.0  #: seconds the launcher still listens for the world's outcome once every process is gone


@dataclass(frozen=True)
class Verdict:
    """What to do about a process that ended: start it again (``restart``), end the launch as failed
    (``end``, the reason), stop it as the user asked (``stop``, the reason), and what to say (``note``).
    ``wait_for_monitor``: the run is over, the monitor is writing it."""

    restart: bool = False
    end: str | None = None
    stop: str | None = None
    note: str | None = None
    wait_for_monitor: bool = False


@dataclass
class Supervisor:
    """The rules above, for one launch (the launch file's, or ``swarm-ros run``'s: :mod:`swarm_ros.app.launcher`).
    ``exited`` is told each process's end; it counts restarts per node. ``said``: how the user set the batch
    policy and the restart bound, for the messages (``--on-batch-loss remove``, ``--max-restarts`` for the
    command line). ``removes``: whether the world can remove a lost batch's robots and go on (the rubenstein
    algorithm's cannot: a batch lost past the bound ends its run, as the world or the monitor would)."""

    max_restarts: int
    on_batch_loss: str = "restart"
    removes: bool = True
    said: tuple[str, str] = ("on_batch_loss: remove", "max_restarts")
    #: exit statuses that mean the user stopped the run: under ``ros2 launch`` a terminal's Ctrl-C signals every
    #: node; ``swarm-ros run`` gives each node a process group of its own, so there a signal is a fault
    stops: frozenset[int] = STOPPED
    restarts: dict[str, int] = field(default_factory=dict)
    world_ended: bool = False
    monitor_done: bool = False
    stopped: bool = False

    def exited(self, name: str, code: int, why: str = "", started: bool = True) -> Verdict:
        """What to do now that node ``name``'s process ended with ``code`` (negative: killed by that signal).
        ``why``: its last error line, if known; ``started``: whether tick 0 went out (under ``remove``, a batch
        lost before it is started again: none of its robots has moved yet)."""
        how = f"{name} {death(code)}" + (f" ({why})" if why and code > 0 else "")
        done = self.restarts.get(name, 0)
        if self.stopped:
            return Verdict()
        if code in self.stops:  # Ctrl-C (the terminal signals every process of the launch) or a user's kill
            self.stopped = True
            return Verdict(stop=f"{name} was stopped ({death(code)}): the run stops")
        if is_world(name) or name == MONITOR:
            if code == 0:
                if name == MONITOR:
                    self.monitor_done = True
                    return Verdict(note="the monitor has written the run")
                self.world_ended = True
                return Verdict(wait_for_monitor=not self.monitor_done)
            if code > 0:
                if name == MONITOR and self.world_ended:
                    return Verdict(
                        end=f"the monitor {death(code)}; the swarm ran to its end, but no run directory was written"
                    )
                return Verdict(end=how)
            if done >= self.max_restarts:
                return Verdict(
                    end=f"{how}; it was restarted {self.max_restarts} times already ({self.said[1]}): "
                    f"the run cannot go on"
                )
            return self._restart(name, how)
        if code == 0 or self.world_ended or self.monitor_done:
            return Verdict()
        if self.on_batch_loss == "restart" or not started:
            if done < self.max_restarts:
                return self._restart(name, how)
            if not started:
                return Verdict(end=f"{how} before the run started, {self.max_restarts + 1} times")
            if not self.removes:
                return Verdict(
                    end=f"{how}; it was restarted {self.max_restarts} times already ({self.said[1]}): "
                    f"the run cannot go on without its robots"
                )
        then = (
            f"the world removes its robots ({self.said[0]})"
            if self.on_batch_loss != "restart"
            else f"it was restarted {self.max_restarts} times already: the world removes its robots"
        )
        return Verdict(note=f"{how}; {then} and the run goes on")

    def _restart(self, name: str, how: str) -> Verdict:
        self.restarts[name] = self.restarts.get(name, 0) + 1
        return Verdict(restart=True, note=f"{how}; restarted ({self.restarts[name]} of {self.max_restarts})")

    def incarnation(self, name: str) -> int:
        """The incarnation of ``name``'s current process: 0 for its first, then one more per restart."""
        return self.restarts.get(name, 0)


@dataclass(frozen=True)
class LaunchSetup:
    """What the launch file starts the graph with: the parameter file every node reads (``params``, the run
    and each node's own section, as ``swarm-ros run`` writes it), the run directory, and the supervisor."""

    params: Path
    out: Path
    checkpoint: Path
    supervisor: Supervisor
    region_cuts: str = ""  #: where the batches' strips start (the launch argument, else the file's /robot_batch)
    plan: tuple[tuple[str, str, dict[str, int | str]], ...] = ()  #: the node processes (protocol.plan.plan_for)
    algorithm: str = DARR_NIAZI  #: whose kernels the nodes load


def _yaml_value(text: str) -> object:
    """``text`` read as ROS 2 reads ``-p name:=text`` (YAML), or the text itself if it is not YAML."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def launch_processes(text: str, param: Param = PROCESSES) -> int:
    """The ``processes`` launch argument (or ``param``'s: ``world_shards``) as a number.

    Raises:
        ConfigError: not an integer >= 1, in one line.
    """
    try:
        return param.check(_yaml_value(text))
    except ParameterError as exc:
        raise ConfigError(f"launch argument {param.name}:={text}: {exc}") from None


def argument_value(name: str, text: str) -> object:
    """A launch argument's text as the run parameter ``name``'s type, as ``-p name:=text`` reads it (YAML).

    Raises:
        ConfigError: not a value of that parameter, in one line.
    """
    param = RUN_PARAMETER[name]
    try:
        return param.check(text if param.kind is str else _yaml_value(text))
    except ParameterError as exc:
        raise ConfigError(f"launch argument {name}:={text}: {exc}") from None


def parameter_arguments(values: dict[str, object]) -> list[str]:
    """``-p name:=value`` ROS arguments for ``values``, each value written as JSON, which ROS 2 reads back as YAML
    of the same type (a string such as ``"10"`` stays a string)."""
    return [arg for name, value in values.items() for arg in ("-p", f"{name}:={json.dumps(value)}")]


def launch_setup(
    params_file: str,
    arguments: dict[str, str],
    out_dir: str,
    log_dir: Path,
    processes: int,
    enclaves: str = "",
    region_cuts: str = "",
    world_shards: int = 1,
) -> LaunchSetup:
    """Resolve a launch's arguments as ``swarm-ros run`` resolves its flags, and write the nodes' parameter
    file into ``log_dir``. A launch argument wins over the parameter file (run parameters and ``out_dir``);
    ``record_every`` goes to the world (or its shards) and the monitor alike;
    the world's checkpoint is ``<log_dir>/world.checkpoint``; an empty ``out_dir`` is named here
    (``runs/<time>_<shape>_...``), once, so that a restarted monitor writes to the same place.

    Raises:
        InputError: a bad parameter file, argument, shape or output directory, in one line.
    """
    settings, nodes = read_params_file(params_file)
    check_launcher_sets(params_file, nodes)
    given = {name: argument_value(name, text) for name, text in arguments.items() if text}
    settings = settings.updated(**given)
    for name, value in given.items():  # an argument given is refused for the other algorithm, as a flag is
        check_given({name: value}, settings.algorithm, f"launch argument {name}:={arguments[name]}")
    check_graph_shape(settings.shape)
    shape, params = settings.resolve()
    region_cuts = region_cuts or str(nodes["robot_batch"].get("region_cuts", ""))  # the argument, else the file's
    check_can(params.algorithm, "graph")
    check_world_shards(params.algorithm, world_shards > 1, "world_shards")
    check_loss_policy(params.algorithm, nodes["world"].get("on_batch_loss"), "on_batch_loss:")
    check_graph(
        shape,
        params,
        processes,
        enclaves or None,
        flags=("processes", "enclaves"),
        region_cuts=region_cuts,
        world_shards=world_shards,
    )
    if Path(settings.shape).suffix.lower() in (".txt", ".png"):
        settings = settings.updated(shape=str(Path(settings.shape).absolute()))
    settings = settings.updated(robots=params.robots)
    out = Path(out_dir or str(nodes["monitor"].get("out_dir") or "") or default_run_dir(shape.label, params)).absolute()
    check_out_dir(out, bool(nodes["monitor"].get("overwrite", False)))
    every = record_every(nodes)  # as swarm-ros run sets it, for both
    world = {**node_defaults(WORLD), **nodes["world"], "record_every": every}
    monitor = {**nodes["monitor"], "out_dir": str(out), "record_every": every}
    sections = {**world_sections(world, world_shards, log_dir), MONITOR: monitor}
    for section in sections.values():
        section.pop("incarnation", None)  # the supervisor's to set
    path = log_dir / "params.yaml"
    log_dir.mkdir(parents=True, exist_ok=True)
    part = path.with_name(path.name + ".part")
    part.write_text(params_yaml(settings, sections), encoding="utf-8")
    part.replace(path)
    return LaunchSetup(
        path,
        out,
        log_dir / CHECKPOINT,
        Supervisor(
            int(world["max_restarts"]), str(world["on_batch_loss"]), algorithm_of(params.algorithm).removes_lost_robots
        ),
        region_cuts,
        tuple(plan_for(params.algorithm, processes, region_cuts, world_shards)),
        params.algorithm,
    )
