"""matplotlib, headless, with a configuration directory it can write.

matplotlib keeps its font cache in ``$MPLCONFIGDIR``, else ``~/.config/matplotlib``. Where neither can be
written (a read-only or missing ``HOME``: a service account, a container), it warns twice and makes a new
``/tmp/matplotlib-*`` in every process, which a node leaves behind (it ends with ``os._exit``). Then this module
points it, before its import, at one directory of this user's that every later process reuses.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _writable(path: Path) -> bool:
    """Whether matplotlib could use ``path``: made if missing (as matplotlib would make it), a directory, and
    writable."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return path.is_dir() and os.access(path, os.W_OK)


def _config_dir() -> None:
    """Set ``MPLCONFIGDIR`` to a directory of this user's under the temporary directory if matplotlib's own
    choice cannot be written (and the user set none)."""
    if os.environ.get("MPLCONFIGDIR"):
        return
    home = Path(os.environ.get("XDG_CONFIG_HOME") or Path(os.path.expanduser("~")) / ".config") / "matplotlib"
    if _writable(home):
        return
    own = Path(tempfile.gettempdir()) / f"swarm_ros-matplotlib-{os.getuid()}"
    try:
        own.mkdir(mode=0o700, exist_ok=True)
    except OSError:
        return  # matplotlib's own fallback, with its warning
    if own.is_dir() and not own.is_symlink() and own.stat().st_uid == os.getuid():
        os.environ["MPLCONFIGDIR"] = str(own)


_config_dir()

import matplotlib  # noqa: E402  (after the configuration directory is chosen)

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

__all__ = ["ListedColormap", "Patch", "matplotlib", "plt"]
