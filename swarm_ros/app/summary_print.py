"""What ``swarm-ros simulate`` and ``run`` print when a run is over (the study's model's, or a rubenstein run's)."""

from __future__ import annotations

from pathlib import Path

#: What a summary's wall time holds, by engine: the engine alone is docs/benchmarks.md's
_TIMED = {"ros2": "tick 0 to the outcome", "inprocess": "the kernels' loading and the recording included"}


def print_summary(s: dict, out: Path, dims: int) -> None:
    """A run's summary.json on the study's model's grid, as ``simulate`` and ``run`` print it: the study's model's
    parameters where the summary has them (another algorithm on the same grid has none)."""
    cells = "voxels" if dims == 3 else "patches"
    vision, ruled = (f"vision {s['vision_radius']:g}, " if "vision_radius" in s else ""), "rules" in s
    rate = s["convergence_tick"] / s["wall_seconds"] if s["wall_seconds"] > 0 else float("inf")
    rows = [
        ("shape", f"{s['shape']} ({s['shape_patches']} {cells})"),
        ("robots", f"{s['robots']}  ({vision}seed {s['seed']}, engine {s['engine']})"),
        *(
            [("rules", f"{s['rules']}  (join {s['join']}, crowding {s['crowding']}, steps {s['steps']})")]
            if ruled
            else []
        ),
        ("outcome", s["outcome"]),
        ("convergence tick", f"{s['convergence_tick']}"),
        ("localized", f"{s['localized']} / {s['shape_patches']} {cells}"),
        ("unlocalized", f"{s['unlocalized']}  (separated {s['separated']})"),
        (f"empty {cells}", f"{s['empty_patches']}"),
        *(
            [
                (
                    "lost robots",
                    f"{s['lost_robots']}  ("
                    + ", ".join(f"{x['robots']} at tick {x['tick']}" for x in s["losses"])
                    + ")",
                )
            ]
            if s.get("lost_robots")
            else []
        ),
        ("convergence rate", f"{s['convergence_rate']:.4f} robots/tick"),
        ("wall time", f"{s['wall_seconds']:.2f} s  ({rate:,.0f} ticks/s, {_TIMED[s['engine']]})"),
        ("output", str(out)),
    ]
    for key, value in rows:
        print(f"{key:<17} {value}")


def print_rubenstein_summary(s: dict, out: Path, _dims: int = 2) -> None:
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
