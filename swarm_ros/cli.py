"""The ``swarm-ros`` command line: ``simulate`` and ``shapes``.

Bad input ends with one line ``swarm-ros: error: ...`` on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from . import __version__
from .config import Settings, load_params_file
from .core.engine import Simulation
from .core.errors import SwarmError
from .core.params import RunParams
from .core.shapes import Shape, builtin_shapes
from .core.world import World

PROG = "swarm-ros"
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
_PROGRESS_TICKS = 200  # ticks between progress-bar updates


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid integer {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid number {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise SwarmError(message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Self-organized shape formation in large robot swarms.")
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    sim = sub.add_parser("simulate", help="run the in-process engine once and write a run directory",
                         description="Run one simulation with the fast in-process engine.")
    sim.add_argument("--shape", help="built-in shape name or a .txt/.png shape file (default: star)")
    sim.add_argument("--robots", type=_positive_int, help="robots N, seeds included (default: the shape's patch count)")
    sim.add_argument("--vision", type=_positive_float, dest="vision_radius", help="vision radius in patches (default: 1)")
    sim.add_argument("--seed", type=int, help="run seed (default: 1)")
    sim.add_argument("--max-ticks", type=_positive_int, dest="max_ticks", help="tick limit (default: 100000)")
    sim.add_argument("--wiggle", type=float, dest="wiggle_deg", help="max turn per tick, degrees (default: 45)")
    sim.add_argument("--world-radius", type=int, dest="world_radius", help="world spans [-R, R] (default: 32)")
    sim.add_argument("--params-file", type=Path, help="ROS 2 style YAML parameter file; flags override it")
    sim.add_argument("--out", type=Path, help="output directory (default: runs/<time>_<shape>_n<N>_v<R>_s<seed>)")
    sim.add_argument("--overwrite", action="store_true", help="replace an existing output directory")
    sim.add_argument("--check", action="store_true", help="check the Z-spec invariants after every tick (slow)")
    sim.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    sim.set_defaults(func=cmd_simulate)

    shapes = sub.add_parser("shapes", help="list the built-in shapes", description="List the built-in shapes.")
    shapes.add_argument("--world-radius", type=int, default=World().radius, help="world spans [-R, R] (default: 32)")
    shapes.set_defaults(func=cmd_shapes)
    return parser


def cmd_shapes(args: argparse.Namespace) -> int:
    world = World(args.world_radius)
    print(f"{'shape':<10} {'patches':>7} {'holes':>5}  bounding box (xmin, ymin)-(xmax, ymax)  file")
    for name, path in builtin_shapes().items():
        shape = Shape.load(name, world)
        x0, y0, x1, y1 = shape.bbox
        print(f"{name:<10} {shape.patches:>7} {shape.holes:>5}  ({x0:>3}, {y0:>3})-({x1:>3}, {y1:>3})"
              f"{'':18}{path}")
    print(f"world: {world.size} x {world.size} patches, walls on the border ring")
    return 0


def _settings(args: argparse.Namespace) -> Settings:
    settings = Settings()
    if args.params_file is not None:
        settings = load_params_file(args.params_file, settings)
    return settings.updated(shape=args.shape, robots=args.robots, vision_radius=args.vision_radius,
                            seed=args.seed, max_ticks=args.max_ticks, wiggle_deg=args.wiggle_deg,
                            world_radius=args.world_radius)


def cmd_simulate(args: argparse.Namespace) -> int:
    from .output import RunRecord, check_out_dir, default_run_dir, write_run

    settings = _settings(args)
    shape = Shape.load(settings.shape, World(settings.world_radius))
    params = RunParams(robots=settings.robots or shape.patches, vision_radius=settings.vision_radius,
                       seed=settings.seed, max_ticks=settings.max_ticks, wiggle_deg=settings.wiggle_deg)
    out = args.out or default_run_dir(shape.name, params.robots, params.vision_radius, params.seed)
    check_out_dir(out, args.overwrite)

    start = time.perf_counter()
    sim = Simulation(shape, params)
    _run_with_progress(sim, check=args.check, quiet=args.quiet)
    record = RunRecord.of(sim, wall_seconds=time.perf_counter() - start)
    out = write_run(out, record, overwrite=args.overwrite)
    if not args.quiet:
        _print_summary(record.summary, out)
    return 0


def _run_with_progress(sim: Simulation, check: bool, quiet: bool) -> None:
    from tqdm import tqdm

    if check:
        from .core.invariants import check_state, check_tick

        check_state(sim)
    with tqdm(total=sim.shape.patches, initial=sim.metrics.localized, unit="patch", desc="localized",
              disable=True if quiet else None, file=sys.stderr, dynamic_ncols=True) as bar:
        while not sim.done:
            if check:
                prev = sim.state.copy()
                sim.step()
                check_tick(prev, sim)
            else:
                sim.run(max_ticks=_PROGRESS_TICKS)
            m = sim.metrics
            bar.update(m.localized - bar.n)
            bar.set_postfix(tick=str(m.tick), moving=str(m.moving), refresh=False)


def _print_summary(s: dict, out: Path) -> None:
    rate = s["convergence_tick"] / s["wall_seconds"] if s["wall_seconds"] > 0 else float("inf")
    rows = [
        ("shape", f"{s['shape']} ({s['shape_patches']} patches)"),
        ("robots", f"{s['robots']}  (vision {s['vision_radius']:g}, seed {s['seed']}, engine {s['engine']})"),
        ("outcome", s["outcome"]),
        ("convergence tick", f"{s['convergence_tick']}"),
        ("localized", f"{s['localized']} / {s['shape_patches']} patches"),
        ("unlocalized", f"{s['unlocalized']}  (separated {s['separated']})"),
        ("empty patches", f"{s['empty_patches']}"),
        ("convergence rate", f"{s['convergence_rate']:.4f} robots/tick"),
        ("wall time", f"{s['wall_seconds']:.2f} s  ({rate:,.0f} ticks/s)"),
        ("output", str(out)),
    ]
    for key, value in rows:
        print(f"{key:<17} {value}")


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return args.func(args)
    except SwarmError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1


if __name__ == "__main__":
    sys.exit(main())
