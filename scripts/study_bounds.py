#!/usr/bin/env python3
"""Lower bounds on a shape's convergence time, set beside the study's smallest published means.

The study's smallest mean convergence times over its group sizes (e.g. k-letter 14.6 ticks
with 1400 robots) are far below anything this project's readings produce. This script
computes, for each built-in shape, two lower bounds that hold for the model, and prints
them beside the published minimum as a Markdown table:

* **growth bound**: a robot may join only a frontier patch, next to a robot localized by
  the end of the previous tick, so the filled region grows by at most one 8-connected step
  through the shape per tick. A shape patch at graph distance d from the seed block cannot
  be filled before tick d, and the shape cannot complete before its farthest patch is
  filled. This holds under every rule set and for any number of robots.
* **travel bound**: every shape patch but the seeds' needs its own robot, so at least
  P - 4 different robots must join, each travelling at least its straight-line distance to
  the nearest shape patch; the (P - 4)-th smallest of those distances is the distance the
  farthest needed robot must travel. At one patch per tick (``steps: one`` and ``walk``;
  up to three under ``steps: literal``) that many ticks is a lower bound. It is computed
  from the actual start positions of the paper experiment's runs at the study's largest
  group size (the size with the smallest times).

    .venv/bin/python scripts/study_bounds.py [--reference FILE] [--results DIR] [--out FILE]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]


def growth_bound(shape) -> int:
    """Largest 8-connected graph distance, through shape patches, from the seed block to a shape patch."""
    w = shape.world.size
    mask = shape.mask.ravel()
    cells = np.flatnonzero(mask)
    index = -np.ones(mask.size, dtype=np.int64)
    index[cells] = np.arange(cells.size)
    rows, cols = [], []
    for dy in (-w, 0, w):
        for dx in (-1, 0, 1):
            if dx == 0 and dy == 0:
                continue
            nb = cells + dy + dx
            ok = mask[nb]
            rows.append(index[cells[ok]])
            cols.append(index[nb[ok]])
    source = cells.size  # one extra node joined to the four seed patches
    seeds = index[shape.world.flat_index(shape.seed_patches[:, 0], shape.seed_patches[:, 1])]
    r = np.concatenate(rows + [np.full(4, source), seeds])
    c = np.concatenate(cols + [seeds, np.full(4, source)])
    graph = csr_matrix((np.ones(r.size), (r, c)), shape=(source + 1, source + 1))
    order, pred = breadth_first_order(graph, source, directed=False, return_predecessors=True)
    depth = np.zeros(source + 1, dtype=np.int64)
    for node in order[1:]:
        depth[node] = depth[pred[node]] + 1
    return int(depth[:source].max() - 1)  # the seeds themselves are at depth 1


def travel_bound(shape, x: np.ndarray, y: np.ndarray) -> float:
    """The straight-line distance (patches) the farthest needed robot must travel.

    Every shape patch but the seeds' needs its own robot, so at least P - 4 different
    robots join, and each travels at least its distance to the nearest shape patch. The
    (P - 4)-th smallest of those distances is therefore a lower bound on the longest trip.
    """
    cells = np.flatnonzero(shape.mask.ravel())
    px, py = shape.world.patch_xy(cells)
    nearest, _ = cKDTree(np.column_stack([px, py])).query(np.column_stack([x, y]))
    return float(np.sort(nearest)[shape.patches - 4 - 1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--reference", type=Path, default=ROOT / "config/experiments/study_reference.csv")
    ap.add_argument(
        "--results",
        type=Path,
        default=ROOT / "docs/results/paper",
        help="the paper experiment's directory (its seeds and our times)",
    )
    ap.add_argument("--out", type=Path, help="also write the table to this file (via a temporary name)")
    args = ap.parse_args()
    from swarm_ros.app.published import load_reference
    from swarm_ros.app.results_file import read_results
    from swarm_ros.core import Shape
    from swarm_ros.core.darr_niazi.state import RobotState, initial_state

    reference = load_reference(args.reference)
    rows = read_results(args.results / "results.csv")
    lines = [
        "| shape | study's smallest mean (its range over 5 sizes) | growth bound | "
        "travel bound at the largest size (mean, min-max over 10 starts) | our smallest mean (`paper`) |",
        "|---|---|---:|---|---:|",
    ]
    for name, ref in reference.items():
        shape = Shape.load(name)
        growth = growth_bound(shape)
        mine = [r for r in rows if r["shape"] == name]
        largest = max(r["robots"] for r in mine)
        starts = sorted((r for r in mine if r["robots"] == largest), key=lambda r: r["repetition"])
        bounds = []
        for r in starts:
            s = initial_state(shape, largest, r["seed"])
            moving = s.state != RobotState.SEED
            bounds.append(travel_bound(shape, s.x[moving], s.y[moving]))
        by_size = {}
        for r in mine:
            by_size.setdefault(r["robots"], []).append(r["convergence_tick"])
        fastest_n, fastest = min(((n, float(np.mean(v))) for n, v in by_size.items()), key=lambda t: t[1])
        lines.append(
            f"| {name} | {ref.sizes_mean_min:g} ({ref.sizes_mean_min:g}–{ref.sizes_mean_max:g}) | "
            f"{growth} | {np.mean(bounds):.1f} ({min(bounds):.1f}–{max(bounds):.1f}) at N = {largest} | "
            f"{fastest:.0f} at N = {fastest_n} |"
        )
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if args.out:
        part = args.out.with_name(f".{args.out.name}.tmp")
        part.write_text(text, encoding="utf-8")
        os.replace(part, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
