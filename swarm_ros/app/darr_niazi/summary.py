"""What ``swarm-ros simulate`` and ``run`` print when a run of the study's model is over (or of another algorithm
that reports on its grid, as the test suite's random walk does)."""

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
