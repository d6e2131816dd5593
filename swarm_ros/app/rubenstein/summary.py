"""What a rubenstein run's summary looks like at the command line: as ``swarm-ros simulate`` and ``run`` print it,
and as a row of the study's results.csv (its ``as_study_row`` hook), so that one report holds both algorithms."""

from __future__ import annotations

from pathlib import Path

from swarm_ros.core.params import RUBENSTEIN, foreign_defaults
from swarm_ros.core.rubenstein.layout import SEEDS


def print_summary(s: dict, out: Path, _dims: int = 2) -> None:
    """A rubenstein run's summary.json, as ``simulate`` and ``run`` print it."""
    rows = [
        ("shape", f"{s['shape']} ({s['shape_pixels']} pixels of {s['pixel_size']:g} d)"),
        ("robots", f"{s['robots']}  (algorithm rubenstein, seed {s['seed']}, engine {s['engine']})"),
        ("outcome", s["outcome"]),
        ("end tick", str(s["convergence_tick"])),
        ("50% / 90% tick", f"{s['fill_50_tick']} / {s['fill_90_tick']}"),
        ("covered", f"{s['coverage']:.1%} of the pixels"),
        ("joined", f"{s['joined']}  (outside the shape {s['joined_outside']})"),
        ("loc. error", f"{s['loc_error']:.3f} d (mean over the joined)"),
        ("wall time", f"{s['wall_seconds']:.2f} s"),
        ("output", str(out)),
    ]
    for key, value in rows:
        print(f"{key:<17} {value}")


def as_study_row(summary: dict) -> dict:
    """A rubenstein run's summary in results.csv's columns: its shape pixels are the shape's patches, its joined
    robots the localized ones (seeds included), its uncovered pixels the empty patches, and the parameters of
    the study's model their defaults."""
    robots, joined, pixels = summary["robots"], summary["joined"], summary["shape_pixels"]
    tick = summary["convergence_tick"]
    return {
        **foreign_defaults(RUBENSTEIN),
        **summary,
        "shape_patches": pixels,
        "localized": joined,
        "unlocalized": robots - joined,
        "separated": 0,
        "empty_patches": pixels - round(summary["coverage"] * pixels),
        "lost_robots": 0,
        "convergence_rate": round((joined - len(SEEDS)) / tick, 6) if tick > 0 else 0.0,
    }
