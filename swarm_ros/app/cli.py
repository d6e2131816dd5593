"""The ``swarm-ros`` command line: its arguments (``simulate``, ``run``, ``experiment``, ``report``, ``replay``,
``topics`` and ``shapes``); what each command does is :mod:`swarm_ros.app.commands`'.

Bad input ends with one line ``swarm-ros: error: ...`` on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path
from typing import Any

from swarm_ros import __version__
from swarm_ros.app import commands
from swarm_ros.app.commands import EXIT_INTERRUPTED, EXIT_USAGE, PROG
from swarm_ros.core.errors import InputError, ParameterError, RunFailed
from swarm_ros.core.grid import World
from swarm_ros.core.inputs import path_too_long, shown
from swarm_ros.core.params import (
    BATCH_LOSS_POLICIES,
    MAX_RESTARTS,
    RUN_PARAMETER,
    RUN_PARAMETERS,
    WORLD_SHARDS,
    Param,
    node_parameter,
)
from swarm_ros.core.signals import InterruptSaid
from swarm_ros.protocol.plan import PROCESSES

#: The command line's own numbers (not run parameters), declared and checked the same way.
_OWN = {
    p.name: p
    for p in (
        PROCESSES,
        Param("jobs", 1, "worker processes", low=1),
        Param("rate", 1.0, "replay speed", low=0.0, low_open=True),
        Param("delay", 1.0, "seconds before replaying", low=0.0),
        Param("wait_for_subscribers", 0, "subscriptions to wait for", low=0),
        Param("start_offset", 0.0, "seconds into the bag", low=0.0),
        Param("count", 1, "messages to print", low=1),
        Param("seconds", 1.0, "seconds to listen", low=0.0, low_open=True),
    )
}
_RECORD_EVERY = node_parameter("monitor", "record_every")
_MAX_RESTARTS = node_parameter("world", "max_restarts")
_REGION_CUTS = node_parameter("robot_batch", "region_cuts")


def _region_cuts(text: str) -> object:
    """``--region-cuts``: as its parameter, but not empty (given empty, it silently meant the default cuts)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty list of cuts; leave the flag out for the default cuts")
    return _checked(_REGION_CUTS)(text)


def _checked(param: Param):
    """An argparse type for a run parameter's flag: the text as the parameter's type, checked by its declaration."""

    def convert(text: str) -> object:
        try:
            value = param.kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"invalid {'integer' if param.kind is int else 'number'} {text!r}"
            ) from None
        try:
            return param.check(value)
        except ParameterError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return convert


def _path(text: str) -> Path:
    """An argparse type for a path argument: refused in one line if empty (Path('') is '.', which no user means)
    or if Linux cannot take it."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path names no file")
    why = path_too_long(text)
    if why:
        raise argparse.ArgumentTypeError(f"{shown(text)}: {why}")
    return Path(text)


def _failure(text: str) -> tuple[float, int]:
    """``P@T``: ``fail_fraction`` P (above 0) and ``fail_tick`` T (1 or later), each checked by its declaration."""
    fraction, at, tick = text.partition("@")
    try:
        p, t = float(fraction), int(tick)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected P@T, e.g. 0.1@500, got {text!r}") from None
    if not at or p == 0 or t == 0:
        raise argparse.ArgumentTypeError(f"P must be above 0 and T at least 1, got {text!r}")
    try:
        return RUN_PARAMETER["fail_fraction"].check(p), RUN_PARAMETER["fail_tick"].check(t)
    except ParameterError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (in {text!r})") from None


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors, and no abbreviated flags (``--shap`` is an error, not ``--shape``: a typo
    must not quietly mean another flag)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Self-organized shape formation in large robot swarms.")
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    sim = sub.add_parser(
        "simulate",
        help="run the in-process engine once and write a run directory",
        description="Run one simulation with the fast in-process engine.",
    )
    _add_run_options(sim)
    sim.add_argument("--check", action="store_true", help="check the Z-spec invariants after every tick (slow)")
    sim.set_defaults(func=commands.cmd_simulate)

    run = sub.add_parser(
        "run",
        help="run once over the ROS 2 graph (world, robot batches, monitor)",
        description="Run one simulation as a ROS 2 graph: a world, K robot-batch processes "
        "and a monitor, each its own process. Same results as 'simulate'.",
    )
    _add_run_options(run)
    run.add_argument(
        "--processes",
        type=_checked(_OWN["processes"]),
        default=PROCESSES.default,
        help=f"robot-batch processes K (default: {PROCESSES.default})",
    )
    run.add_argument(
        "--world-shards",
        type=_checked(WORLD_SHARDS),
        default=WORLD_SHARDS.default,
        metavar="S",
        help="world processes: 1 (default) the world node; S > 1 world shards, each owning the strips of "
        "consecutive robot batches, S <= K (docs/protocol.md, World shards)",
    )
    run.add_argument(
        "--region-cuts",
        type=_region_cuts,
        metavar="X,...",
        help="x positions (patches) where the batches' strips 1..K-1 start, e.g. --region-cuts=-10,10 "
        "for K = 3 (default: the parameter file's /robot_batch region_cuts, else cuts that give "
        "each strip as many robots at tick 0); docs/protocol.md, Regions",
    )
    run.add_argument("--domain-id", type=int, help="ROS domain id (default: $ROS_DOMAIN_ID, else a free one)")
    run.add_argument(
        "--on-batch-loss",
        choices=BATCH_LOSS_POLICIES,
        help="a robot-batch process that dies: restart it, nothing lost (default; up to "
        f"{MAX_RESTARTS} times per batch), or remove its robots, as robots lost for good",
    )
    run.add_argument(
        "--max-restarts",
        type=_checked(_MAX_RESTARTS),
        metavar="N",
        help=f"restarts of each node process, at most: each robot batch, the world, the monitor (default: "
        f"{MAX_RESTARTS}); the world goes on from its checkpoint, the monitor from its bag",
    )
    run.add_argument(
        "--no-bag",
        action="store_false",
        dest="bag",
        default=None,
        help="do not write bag/, the rosbag2 (MCAP) of every message on the swarm's topics",
    )
    run.add_argument(
        "--enclaves",
        metavar="PREFIX",
        help="SROS2: start each node with --enclave PREFIX/<node>, and this command's own node with "
        "PREFIX/swarm_ros_launcher (for a ROS install with DDS security; untested here: "
        "docs/security.md)",
    )
    run.set_defaults(func=commands.cmd_run)

    replay = sub.add_parser(
        "replay",
        help="publish a run's bag again, so ROS tools can watch a past run",
        description="Publish every message of a run's rosbag2 (<run>/bag) again on its topic, "
        "with its type and QoS, paced as recorded.",
    )
    replay.add_argument("bag", type=_path, metavar="BAG", help="a run's bag directory (or the run directory)")
    replay.add_argument("--domain-id", type=int, help="ROS domain id to publish on (default: $ROS_DOMAIN_ID or 0)")
    replay.add_argument(
        "--rate", type=_checked(_OWN["rate"]), default=1.0, help="speed factor against the recorded pace (default: 1)"
    )
    replay.add_argument(
        "--delay",
        type=_checked(_OWN["delay"]),
        default=1.0,
        help="seconds between creating the publishers and the first message (default: 1), "
        "for subscribers to be matched",
    )
    replay.add_argument(
        "--wait-for-subscribers",
        type=_checked(_OWN["wait_for_subscribers"]),
        default=0,
        metavar="N",
        help="first wait until N subscriptions are matched, over all its topics (a reader of two topics counts "
        "two; default: 0), then --delay",
    )
    replay.add_argument(
        "--start-offset",
        type=_checked(_OWN["start_offset"]),
        default=0.0,
        metavar="S",
        help="start S seconds into the bag (as ros2 bag play); the latched topics' last messages "
        "before it are published first",
    )
    replay.add_argument("--loop", action="store_true", help="play the bag again and again, until Ctrl-C")
    replay.add_argument("--quiet", action="store_true", help="no progress bar")
    replay.set_defaults(func=commands.cmd_replay)

    topics = sub.add_parser(
        "topics",
        help="list or echo the topics of a running swarm",
        description="List the live topics of a run (types, publishers, rates), or print the messages of one (--echo).",
    )
    topics.add_argument("--domain-id", type=int, help="ROS domain id of the run (default: $ROS_DOMAIN_ID or 0)")
    topics.add_argument("--echo", metavar="TOPIC", help="print this topic's messages instead of the list")
    topics.add_argument(
        "--count", type=_checked(_OWN["count"]), default=1, help="with --echo: messages to print (default: 1)"
    )
    topics.add_argument(
        "--seconds",
        type=_checked(_OWN["seconds"]),
        help="listen this long to measure rates (default: 2), or with --echo wait at most this "
        "long in all for the topic and its messages (default: 10)",
    )
    topics.add_argument("--full", action="store_true", help="with --echo: print whole arrays, not the first items")
    topics.set_defaults(func=commands.cmd_topics)

    exp = sub.add_parser(
        "experiment",
        help="run a grid of runs (shapes x sizes x radii x repetitions) with statistics",
        description="Run an experiment file's grid of runs in parallel, append each finished run "
        "to DIR/results.csv, then write statistics, tables and figures. Running the "
        "same command again resumes an interrupted experiment.",
    )
    exp.add_argument(
        "config", type=_path, metavar="CONFIG.yaml", help="experiment file, e.g. config/experiments/paper.yaml"
    )
    exp.add_argument("--out", type=_path, help="experiment directory (default: experiments/<name>)")
    exp.add_argument("--jobs", type=_checked(_OWN["jobs"]), help="worker processes (default: the machine's cores)")
    exp.add_argument(
        "--engine",
        choices=("inprocess", "ros2"),
        default="inprocess",
        help="engine of each run (default: inprocess; ros2 gives the same results, slower)",
    )
    exp.add_argument(
        "--processes",
        type=_checked(_OWN["processes"]),
        default=PROCESSES.default,
        help=f"with --engine ros2: robot-batch processes per run (default: {PROCESSES.default})",
    )
    exp.add_argument(
        "--executor",
        choices=("local", "dask"),
        default="local",
        help="where the runs go: local worker processes (default), or a Dask cluster",
    )
    exp.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="with --executor dask: a running scheduler, e.g. tcp://host:8786 (default: start a "
        "LocalCluster of --jobs workers)",
    )
    exp.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    exp.set_defaults(func=commands.cmd_experiment)

    rep = sub.add_parser(
        "report",
        help="(re)build an experiment's statistics, tables and figures",
        description="Rebuild stats.csv, stats.md and figures/ of an experiment directory from its results.csv alone.",
    )
    rep.add_argument("dir", type=_path, metavar="DIR", help="experiment directory holding results.csv")
    rep.set_defaults(func=commands.cmd_report)

    shapes = sub.add_parser("shapes", help="list the built-in shapes", description="List the built-in shapes.")
    shapes.add_argument("--world-radius", type=int, default=World().radius, help="world spans [-R, R] (default: 32)")
    shapes.add_argument("--3d", dest="solid", action="store_true", help="list the built-in 3D shapes instead")
    shapes.set_defaults(func=commands.cmd_shapes)
    return parser


def _add_run_options(p: argparse.ArgumentParser) -> None:
    for param in RUN_PARAMETERS:  # one flag per run parameter, from its declaration
        if param.flag == "":
            continue  # fail_fraction and fail_tick: together, as --fail-robots
        default = param.blank or ("none" if param.default == "" else param.default)
        kwargs: dict[str, Any] = {"choices": param.options} if param.options else {"type": _checked(param)}
        p.add_argument(param.cli_flag, dest=param.name, help=f"{param.help} (default: {default})", **kwargs)
    p.add_argument(
        "--fail-robots",
        type=_failure,
        metavar="P@T",
        help="a fraction P of the robots fails at the end of tick T and is removed, e.g. 0.1@500",
    )
    p.add_argument("--params-file", type=_path, help="ROS 2 style YAML parameter file; flags override it")
    p.add_argument("--out", type=_path, help="output directory (default: runs/<time>_<shape>_n<N>_v<R>_s<seed>)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        default=None,
        help="replace an existing run directory (only one this tool wrote)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    rec = p.add_argument_group(
        "recording",
        "Every run writes a Rerun recording, recording.rrd, into its "
        "output directory; open it with 'rerun <run>/recording.rrd'.",
    )
    rec.add_argument(
        "--no-recording", action="store_false", dest="record", default=None, help="do not write recording.rrd"
    )
    rec.add_argument(
        "--record-every",
        type=_checked(_RECORD_EVERY),
        metavar="K",
        help="log the robots every K-th tick only (default: from the swarm's size: every tick up to "
        "10,000 robots, then every ceil(N/10,000)-th; the metrics every tick)",
    )
    rec.add_argument("--spawn", action="store_true", help="also stream live to a new Rerun viewer (needs a display)")
    rec.add_argument(
        "--connect",
        metavar="URL",
        help="also stream live to a running Rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy",
    )


def main(argv: list[str] | None = None) -> int:
    try:  # from the first line: a Ctrl-C while the command still loads (run_dir, below) is one line too
        from swarm_ros.artifacts import run_dir  # noqa: F401 - loaded in the try: a Ctrl-C meanwhile is one line

        argv = list(sys.argv[1:] if argv is None else argv)
        for i, word in enumerate(argv[:-1]):  # "--fail-robots -0.1@10": argparse takes -0.1@10 for a flag
            if word == "--fail-robots" and re.match(r"-[\d.]", argv[i + 1]):
                argv[i : i + 2] = [f"--fail-robots={argv[i + 1]}"]
                break
        args = build_parser().parse_args(argv)
        return args.func(args)
    except InputError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except RunFailed as exc:  # the run could not go on (a node process failed): one line, exit 1, not a usage error
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        if not isinstance(exc, InterruptSaid):
            print(f"{PROG}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as exc:  # the file system refused what no check foresaw (a disk that filled): one line
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"{PROG}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    finally:
        loaded = sys.modules.get("swarm_ros.artifacts.run_dir")  # not there if its import was interrupted
        if loaded is not None:
            loaded.release_out_dirs()


def entry() -> None:
    """The ``swarm-ros`` console script (and ``python -m swarm_ros.app.cli``).

    After ``run`` the process ends at once (:func:`os._exit`): its files are closed, its
    node processes are gone and the output is flushed here, while the interpreter's own
    teardown (rclpy, numba) would add a fifth of a second to every run.
    """
    code = main()
    if commands.EXIT_AT_ONCE:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    entry()
