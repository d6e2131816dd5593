"""Pictures of a run (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from .core.state import RobotState  # noqa: E402

if TYPE_CHECKING:
    from .output import RunRecord

# Patch classes of the picture and their colours (colour-blind safe, Okabe-Ito based).
_CLASSES = (
    ("free", "#ffffff"),
    ("wall", "#4d4d4d"),
    ("empty shape patch", "#f3d9a4"),
    ("localized robot", "#0072b2"),
    ("seed robot", "#d55e00"),
)
_MOVING_COLOUR = "#009e73"
_SEPARATED_COLOUR = "#cc79a7"


def save_final_png(run: RunRecord, path: Path) -> None:
    """The formed shape: walls, shape patches, localized robots, seeds and left-over robots."""
    world, s = run.shape.world, run.state
    r = world.radius
    grid = np.zeros((world.size, world.size), dtype=np.int8)
    grid[world.wall_mask()] = 1
    grid[run.shape.mask] = 2
    occ = s.occupancy.reshape(world.size, world.size)
    grid[occ >= 0] = 3
    grid[np.isin(occ, np.arange(4))] = 4

    fig, ax = plt.subplots(figsize=(6.4, 6.8), dpi=120)
    ax.imshow(grid, origin="lower", cmap=ListedColormap([c for _, c in _CLASSES]), vmin=0, vmax=len(_CLASSES) - 1,
              extent=(-r - 0.5, r + 0.5, -r - 0.5, r + 0.5), interpolation="nearest")
    handles = [Patch(facecolor=c, edgecolor="#999999", label=name) for name, c in _CLASSES[1:]]
    moving = (s.state == RobotState.MOVING_INSIDE) | (s.state == RobotState.MOVING_OUTSIDE)
    for mask, colour, label in ((moving, _MOVING_COLOUR, "moving robot"),
                                (s.state == RobotState.SEPARATED, _SEPARATED_COLOUR, "separated robot")):
        if mask.any():
            ax.scatter(s.x[mask], s.y[mask], s=9, c=colour, linewidths=0, zorder=3)
            handles.append(Patch(facecolor=colour, label=f"{label} ({int(mask.sum())})"))
    m, p = run.final, run.params
    ax.set_title(f"{run.shape.name}: {run.outcome} at tick {m.tick}\n"
                 f"{p.robots} robots, vision {p.vision_radius:g}, seed {p.seed}; "
                 f"{m.localized}/{run.shape.patches} patches filled", fontsize=10)
    ax.set_xlabel("x (patches)")
    ax.set_ylabel("y (patches)")
    ax.set_aspect("equal")
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3, fontsize=8, frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
