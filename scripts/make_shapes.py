#!/usr/bin/env python3
"""Regenerate the six built-in shapes in shapes/ from geometric descriptions.

Each shape is a predicate over continuous points with a scale factor; the script
rasterises it on patch centres of a 61 x 61 grid (x, y in [-30, 30], one free patch
inside the walls of the default 65 x 65 world) and picks the scale whose patch count is
nearest the robot count that completes the shape in the original study. The files are
data: edit them by hand if you like; this script only documents how they were made.

    python scripts/make_shapes.py            # rewrite shapes/*.txt
    python scripts/make_shapes.py --check    # only report counts
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from swarm_ros.core.grid import World  # noqa: E402
from swarm_ros.core.shapes import Shape, write_text_grid  # noqa: E402

HALF = 30  # grid covers [-HALF, HALF]


def _rot(x, y, deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return c * x + s * y, -s * x + c * y


def _segment_dist(x, y, ax, ay, bx, by):
    """Distance from points to the segment a-b."""
    dx, dy = bx - ax, by - ay
    t = np.clip(((x - ax) * dx + (y - ay) * dy) / (dx * dx + dy * dy), 0.0, 1.0)
    return np.hypot(x - (ax + t * dx), y - (ay + t * dy))


def star(x, y, s):
    """Five-armed starfish: r(theta) = s (1 + 0.55 cos 5(theta - 90 deg)), one arm up."""
    r = np.hypot(x, y)
    th = np.arctan2(y, x)
    return r <= s * (1.0 + 0.55 * np.cos(5.0 * (th - math.pi / 2)))


def wrench(x, y, s):
    """Open-end wrench, tilted 40 degrees: a handle, a round head with a jaw, a ring end."""
    u, v = _rot(x / s, y / s, 40.0)
    handle = (np.abs(u) <= 2.6) & (v >= -20.0) & (v <= 12.0)
    head = np.hypot(u, v - 15.0) <= 7.0
    jaw = (np.abs(u) <= 2.8) & (v >= 14.0)
    ring = np.hypot(u, v + 21.0) <= 5.0
    return handle | (head & ~jaw) | ring


def k_letter(x, y, s):
    """Capital K: a vertical stem and two diagonal strokes meeting it at mid-height."""
    u, v = x / s, y / s
    stem = (u >= -22.0) & (u <= -11.0) & (np.abs(v) <= 27.0)
    upper = _segment_dist(u, v, -11.0, 0.0, 18.0, 24.0) <= 5.5
    lower = _segment_dist(u, v, -11.0, 0.0, 18.0, -24.0) <= 5.5
    box = (np.abs(u) <= 30.0) & (np.abs(v) <= 27.0)
    return (stem | upper | lower) & box


def rectangle(x, y, s):
    """Upright rectangle 17 patches wide; the scale sets its height (2s, an even number)."""
    return (np.abs(x) <= 8.0) & (y >= -s) & (y <= s - 1.0)


def tyre(x, y, s):
    """A ring (annulus) with the hole at the origin; inner radius 0.55 of the outer."""
    r = np.hypot(x, y)
    return (r <= s) & (r >= 0.55 * s)


def spinner(x, y, s):
    """Fidget spinner: a hub with a bearing hole and three lobes, each with a hole."""
    u, v = x / s, y / s
    hub = np.hypot(u, v) <= 7.0
    hole = np.hypot(u, v) <= 2.5
    body = hub & ~hole
    for k in range(3):
        a = math.radians(90.0 + 120.0 * k)
        cx, cy = 13.0 * math.cos(a), 13.0 * math.sin(a)
        lobe = np.hypot(u - cx, v - cy) <= 7.0
        lobe_hole = np.hypot(u - cx, v - cy) <= 3.5
        arm = _segment_dist(u, v, 0.0, 0.0, cx, cy) <= 4.0
        body = (body | ((lobe | arm) & ~lobe_hole)) & ~hole
    return body


# name -> (predicate, target patches from the original study, scale search range)
SHAPES = {
    "star": (star, 1036, (5.0, 25.0)),
    "wrench": (wrench, 566, (0.3, 1.4)),
    "k-letter": (k_letter, 1352, (0.3, 1.1)),
    "rectangle": (rectangle, 438, (5.0, 20.0)),
    "tyre": (tyre, 1282, (5.0, 30.0)),
    "spinner": (spinner, 1040, (0.3, 1.5)),
}


def rasterise(pred, s: float) -> np.ndarray:
    """Boolean grid, top row first (file orientation), of patch centres inside the shape."""
    coords = np.arange(-HALF, HALF + 1, dtype=float)
    x, y = np.meshgrid(coords, coords[::-1])
    return pred(x, y, s)


def best_scale(pred, target: int, lo: float, hi: float) -> tuple[float, np.ndarray]:
    best = None
    for s in np.linspace(lo, hi, 4001):
        grid = rasterise(pred, float(s))
        err = abs(int(grid.sum()) - target)
        if best is None or err < best[0]:
            best = (err, float(s), grid)
    return best[1], best[2]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="report counts, write nothing")
    args = ap.parse_args()
    world = World()
    for name, (pred, target, (lo, hi)) in SHAPES.items():
        s, grid = best_scale(pred, target, lo, hi)
        shape = Shape.from_grid(grid, world, name=name, source=f"generated {name}")
        err = 100.0 * (shape.patches - target) / target
        print(
            f"{name:10s} scale {s:7.4f}  patches {shape.patches:5d}  target {target:5d}  "
            f"({err:+.2f}%)  holes {shape.holes}  bbox {shape.bbox}"
        )
        if not args.check:
            write_text_grid(
                grid,
                ROOT / "shapes" / f"{name}.txt",
                comments=[
                    f"{name}: {shape.patches} patches (original study: {target} robots complete it).",
                    "Made by scripts/make_shapes.py; '#' = shape patch, '.' = free, grid centre = origin.",
                ],
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
