"""What each ``swarm-ros`` command does, given its parsed arguments (:mod:`swarm_ros.app.cli` parses them).

Bad input raises :class:`~swarm_ros.core.errors.InputError` (the command line prints it in one line and exits 2).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from swarm_ros.app.param_file import check_given, check_launcher_sets, read_params_file, record_every
from swarm_ros.app.simulate import note_partial, simulate
from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.core.algorithm import algorithm_of, check_can, check_loss_policy, check_world_shards
from swarm_ros.core.errors import InputError
from swarm_ros.core.grid import World
from swarm_ros.core.params import (
    NODE_PARAMETERS,
    RUN_PARAMETERS,
    RunParams,
    Settings,
    node_defaults,
)
from swarm_ros.core.resources import check_world_memory
from swarm_ros.core.shapes import Shape, builtin_shapes, builtin_shapes_3d
from swarm_ros.core.signals import EXIT_INTERRUPTED

if TYPE_CHECKING:
    pass

PROG = "swarm-ros"
EXIT_USAGE = 2
MAX_DOMAIN_ID = 232  # Fast DDS's ports overflow above this (on Linux, 101 with ephemeral ports in use)
LIST_SECONDS, ECHO_SECONDS = 2.0, 10.0  # topics: listening time, and --echo's wait
EXIT_AT_ONCE = False  # set by a finished 'run': see swarm_ros.app.cli.entry()


def cmd_shapes(args: argparse.Namespace) -> int:
    check_world_memory(args.world_radius, dims=3 if args.solid else 2)
    world = World(args.world_radius)
    if args.solid:
        print(
            f"{'shape':<10} {'voxels':>7} {'tunnels':>7} {'cavities':>8}  bounding box "
            "(xmin, ymin, zmin)-(xmax, ymax, zmax)  file"
        )
        misfits = _list_shapes(builtin_shapes_3d(), world)
        print(
            f"world: {World(args.world_radius, 3).describe()} voxels, walls on the outer shell"
            + (f"; {misfits} shape(s) do not fit in it" if misfits else "")
        )
        return 0
    print(f"{'shape':<10} {'patches':>7} {'holes':>5}  bounding box (xmin, ymin)-(xmax, ymax)  file")
    misfits = _list_shapes(builtin_shapes(), world)
    print(
        f"world: {world.size} x {world.size} patches, walls on the border ring"
        + (f"; {misfits} shape(s) do not fit in it" if misfits else "")
        + "; 3D shapes: swarm-ros shapes --3d"
    )
    return 0


def _list_shapes(shapes: dict[str, Path], world: World) -> int:
    """Print a line per shape (2D or 3D, by the file); return how many do not fit in ``world``."""
    misfits = 0
    for name, path in shapes.items():
        try:
            shape = Shape.load(name, world)
        except InputError as exc:  # e.g. larger than this world: say so and list the others
            misfits += 1
            reason = str(exc).split(": ", 1)[-1].split(" at patch")[0]  # e.g. reaches beyond the walls
            print(f"{name:<10} {'-':>7} {'-':>5}  does not fit: {reason}  {path}")
            continue
        if shape.dims == 3:
            lo, hi = shape.bbox[:3], shape.bbox[3:]
            box = f"({lo[0]:>3}, {lo[1]:>3}, {lo[2]:>3})-({hi[0]:>3}, {hi[1]:>3}, {hi[2]:>3})"
            print(f"{name:<10} {shape.patches:>7} {shape.tunnels:>7} {shape.cavities:>8}  {box}{'':9}{path}")
            continue
        x0, y0, x1, y1 = shape.bbox
        print(f"{name:<10} {shape.patches:>7} {shape.holes:>5}  ({x0:>3}, {y0:>3})-({x1:>3}, {y1:>3}){'':18}{path}")
    return misfits


def _settings(args: argparse.Namespace) -> tuple[Settings, dict[str, dict[str, object]]]:
    """The run settings (parameter file, then flags) and the node parameters the file sets."""
    settings = Settings()
    nodes: dict[str, dict[str, object]] = {kind: {} for kind in NODE_PARAMETERS}
    if args.params_file is not None:
        settings, nodes = read_params_file(args.params_file, settings)
    flags = {p.name: getattr(args, p.name) for p in RUN_PARAMETERS if p.flag != ""}
    if args.fail_robots:
        flags["fail_fraction"], flags["fail_tick"] = args.fail_robots
    settings = settings.updated(**flags)
    check_given(flags, settings.algorithm)
    return settings, nodes


def _flag(value: object, section: dict[str, object], key: str) -> Any:
    """A flag's value if given, else the parameter file's /monitor value, else the monitor's default."""
    return value if value is not None else section.get(key, node_defaults("monitor")[key])


def _prepare(
    args: argparse.Namespace, graph: bool = False
) -> tuple[Settings, Shape, RunParams, Path, RecordingOptions, dict]:
    """Settings, shape, parameters, a usable output directory, the recording options and the node
    parameters of the parameter file, or a InputError before anything runs."""
    from swarm_ros.artifacts.run_dir import check_leftovers, check_out_dir, claim_out_dir, default_run_dir

    settings, nodes = _settings(args)
    if graph:
        from swarm_ros.app.processes import check_graph_shape

        check_graph_shape(settings.shape)
    shape, params = settings.resolve()
    check_can(params.algorithm, "graph" if graph else "check" if getattr(args, "check", False) else "")
    if graph:
        check_world_shards(params.algorithm, args.world_shards > 1, "--world-shards")
    monitor = nodes["monitor"]
    recording = RecordingOptions(
        enabled=bool(_flag(args.record, monitor, "record")),
        every=int(args.record_every if args.record_every is not None else record_every(nodes)),
        spawn=args.spawn,
        connect=args.connect or str(monitor.get("viewer_url", "")) or None,
    )
    out = args.out or (
        Path(str(monitor["out_dir"])) if monitor.get("out_dir") else default_run_dir(shape.label, params)
    )
    args.overwrite = bool(_flag(args.overwrite, monitor, "overwrite"))
    check_out_dir(out, args.overwrite)
    if not graph:  # numba and the engine loaded first: from the claim to the driver's StopFlag is then a moment
        algorithm_of(params.algorithm).hook("engine")  # (a SIGTERM there ends the command with nothing written)
    claim_out_dir(out)  # a second command for the same directory is refused now, not after its run
    if graph:  # what a SIGKILLed 'run' of the same directory left (no live command holds it: claimed just now)
        from swarm_ros.app.processes import recover_killed

        recover_killed(out)
    check_leftovers(out)
    every = recording.every_for(params)
    if recording.active and not recording.every and every > algorithm_of(params.algorithm).record_every:  # by size
        print(
            f"{PROG}: the recording logs the robots every {every} ticks "
            f"({params.robots:,} robots; --record-every 1 logs every tick)",
            file=sys.stderr,
        )
    return settings, shape, params, out, recording.reachable(), nodes


def cmd_simulate(args: argparse.Namespace) -> int:
    """``simulate``: the run's algorithm in this process (app/simulate.py, one driver for every algorithm)."""
    _, shape, params, out, options, _ = _prepare(args)
    note_compiling(args.quiet, params.algorithm)
    return simulate(args, shape, params, out, options, PROG)


def cmd_run(args: argparse.Namespace) -> int:
    import json

    from swarm_ros.app.launcher import Launch, plural
    from swarm_ros.app.processes import check_graph
    from swarm_ros.artifacts.run_dir import partial_recording

    settings, shape, params, out, options, nodes = _prepare(args, graph=True)
    check_launcher_sets(args.params_file, nodes)
    cuts = args.region_cuts if args.region_cuts is not None else str(nodes["robot_batch"].get("region_cuts", ""))
    world = {
        **nodes["world"],
        **({"on_batch_loss": args.on_batch_loss} if args.on_batch_loss else {}),
        **({"max_restarts": args.max_restarts} if args.max_restarts is not None else {}),
    }
    said = "--on-batch-loss" if args.on_batch_loss else f"{args.params_file}: /world: on_batch_loss:"
    check_loss_policy(params.algorithm, world.get("on_batch_loss"), said)
    check_graph(shape, params, args.processes, args.enclaves, region_cuts=cuts, world_shards=args.world_shards)
    domain = _domain_id(args.domain_id)
    launch = Launch(
        settings=settings,
        shape=shape,
        params=params,
        processes=args.processes,
        region_cuts=cuts,
        world_shards=args.world_shards,
        out=out,
        overwrite=args.overwrite,
        quiet=args.quiet,
        domain_id=domain,
        recording=options,
        world=world,
        bag=bool(_flag(args.bag, nodes["monitor"], "bag")),
        enclaves=args.enclaves,
    )
    _interrupt_on_sigterm()
    try:
        out = launch.run()
    except KeyboardInterrupt:
        stopped = launch.result()
        if stopped is not None and stopped["outcome"] == "interrupted":
            print(
                f"{PROG}: interrupted at tick {stopped['convergence_tick']}; the run so far is in {out}",
                file=sys.stderr,
            )
        elif stopped is not None:  # the Ctrl-C came while the nodes were shutting down
            print(
                f"{PROG}: interrupted after the run had ended ({stopped['outcome']} at tick "
                f"{stopped['convergence_tick']}); it is whole in {out}",
                file=sys.stderr,
            )
        elif not launch.started:  # the launcher removed what the run had made (launcher.discard_unstarted)
            print(f"{PROG}: interrupted before tick 0; nothing was written", file=sys.stderr)
        else:
            print(
                f"{PROG}: interrupted, but the monitor wrote no run directory (logs: {launch.logs_kept})",
                file=sys.stderr,
            )
            note_partial(partial_recording(out), options, PROG)
        return EXIT_INTERRUPTED
    except BaseException:
        note_partial(partial_recording(out), options, PROG)
        raise
    if not args.quiet:
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        algorithm_of(params.algorithm).hook("print_summary")(summary, out, shape.dims)
        print(
            f"{'ROS graph':<17} domain {launch.domain}, {plural(args.processes, 'robot-batch process')}; "
            f"logs in {out / 'logs'}"
        )
    global EXIT_AT_ONCE
    EXIT_AT_ONCE = True
    return 0


def cmd_experiment(args: argparse.Namespace) -> int:
    from swarm_ros.app.executors import default_jobs
    from swarm_ros.app.experiment import run_experiment

    if args.scheduler and args.executor != "dask":
        raise InputError("--scheduler needs --executor dask")
    _interrupt_on_sigterm()
    start = time.perf_counter()
    jobs = args.jobs or (1 if args.engine == "ros2" else default_jobs())
    out, jobs = run_experiment(
        args.config,
        args.out,
        jobs=jobs,
        engine=args.engine,
        processes=args.processes,
        quiet=args.quiet,
        executor=args.executor,
        scheduler=args.scheduler,
    )
    if not args.quiet:
        where = (
            f"Dask at {args.scheduler}"
            if args.scheduler
            else f"{jobs} job{'s' if jobs != 1 else ''}"
            + (" on a Dask LocalCluster" if args.executor == "dask" else "")
        )
        print(f"experiment done in {time.perf_counter() - start:.1f} s ({where}, engine {args.engine})")
        print(
            f"results  {out / 'results.csv'}\nstats    {out / 'stats.csv'}, {out / 'stats.md'}\n"
            f"figures  {out / 'figures'}"
        )
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from swarm_ros.app.report import build_report

    for path in build_report(args.dir):
        print(path)
    return 0


def note_compiling(quiet: bool, algorithm: str) -> None:
    """Say in one line (unless ``quiet``) that ``algorithm``'s numba kernels must be compiled first, if they must."""
    from swarm_ros.core.kernels import compiling_note, kernels_cached

    if not quiet and not kernels_cached(algorithm):
        print(f"{PROG}: {compiling_note(algorithm)}", file=sys.stderr, flush=True)


def _interrupt_on_sigterm() -> None:
    """SIGTERM ends the command like Ctrl-C does, so its child processes are stopped, not orphaned."""
    import signal

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)


def _domain_id(flag: int | None) -> int | None:
    """The ROS domain id of ``--domain-id``, else of $ROS_DOMAIN_ID, else None; checked against [0, 232]."""
    domain = flag
    if domain is None and os.environ.get("ROS_DOMAIN_ID", "").strip():
        try:
            domain = int(os.environ["ROS_DOMAIN_ID"])
        except ValueError:
            raise InputError(f"ROS_DOMAIN_ID must be an integer, got {os.environ['ROS_DOMAIN_ID']!r}") from None
    if domain is not None and not 0 <= domain <= MAX_DOMAIN_ID:
        raise InputError(f"ROS domain id must be in [0, {MAX_DOMAIN_ID}], got {domain}")
    return domain


def cmd_replay(args: argparse.Namespace) -> int:
    from swarm_ros.tools.replay import replay

    bag = args.bag / "bag" if (args.bag / "bag" / "metadata.yaml").is_file() else args.bag
    domain = _domain_id(args.domain_id)
    _interrupt_on_sigterm()  # its ROS participant is then closed (no Fast DDS files left in /dev/shm)
    code = replay(
        bag,
        0 if domain is None else domain,
        rate=args.rate,
        delay=args.delay,
        subscribers=args.wait_for_subscribers,
        quiet=args.quiet,
        start_offset=args.start_offset,
        loop=args.loop,
    )
    if code == EXIT_INTERRUPTED:
        print(f"{PROG}: interrupted", file=sys.stderr)
    return code


def cmd_topics(args: argparse.Namespace) -> int:
    from swarm_ros.tools.topics import run_topics

    domain = _domain_id(args.domain_id)
    _interrupt_on_sigterm()
    seconds = args.seconds or (ECHO_SECONDS if args.echo else LIST_SECONDS)
    return run_topics(
        0 if domain is None else domain, echo=args.echo, count=args.count, seconds=seconds, full=args.full
    )
