"""Where the package's data (shapes/, config/) lives, for source, editable and normal installs.

A source checkout or an editable install (``pip install -e .``) reads the folders beside
the package; a normal install (``pip install .`` or colcon) has them under
``<prefix>/share/swarm_ros/`` through setup.py's data_files.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

PACKAGE = "swarm_ros"


def _candidates(kind: str) -> list[Path]:
    here = Path(__file__).resolve().parent.parent.parent  # repository root when run from source
    dirs = [here / kind] if (here / "package.xml").is_file() else []
    dirs.append(Path(sys.prefix) / "share" / PACKAGE / kind)
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / PACKAGE / kind)
    return dirs


def data_dir(kind: str) -> Path:
    """The installed ``shapes`` or ``config`` folder.

    Raises:
        FileNotFoundError: the package's data files are not installed anywhere we look.
    """
    for d in _candidates(kind):
        if d.is_dir():
            return d
    looked = ", ".join(str(d) for d in _candidates(kind))
    raise FileNotFoundError(f"swarm_ros data folder '{kind}' not found (looked in {looked})")
