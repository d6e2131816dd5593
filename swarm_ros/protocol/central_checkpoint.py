"""A central world's checkpoint: what a restarted world process needs to go on from a tick it saved.

The world saves, every :func:`save_every` ticks (a multiple of ``record_every``, at least :data:`SAVE_TICKS`), and
before that tick's rows leave the process: its tick, the engine's own arrays
(:meth:`~swarm_ros.core.strips.CentralRun.saved`: for the rubenstein algorithm every robot's arrays, the pixels
covered, the running counts and the metrics of every tick so far), and the batches it serves (their node names and
strips). One ``.npz`` file, written whole to a temporary name and renamed, so a kill at any instruction leaves the
last whole checkpoint or the new one, never a part.

A world shard saves the same way, every :data:`SHARD_SAVE_TICKS` ticks or so, with the robots it holds: its peers
wait for it while it decides again the ticks since, from the messages they sent it, which their topics keep for as
many ticks (:func:`shard_kept`).

A restarted world takes the last checkpoint and decides again the ticks after it: the batches keep nothing between
ticks, so they decide them as before, and the run is the same. It sends the monitor the metrics rows from the tick
after the last ``record_every``-th one before the checkpoint (the monitor may never have had them, if the old process
died between saving and sending) and the monitor drops what it already holds, once it has checked those rows equal
its own.

The file holds no key and is not signed: it is the world's own, in the run's log directory, which only the user who
runs it can write.
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from swarm_ros.core.errors import ContractError, RunFailed
from swarm_ros.core.strips import CentralRun

SAVE_TICKS = 1000  #: ticks between checkpoints, at least: a save writes the metrics of every tick so far
#: ticks between a world shard's checkpoints, at least: its peers' topics keep their messages to it for as long
SHARD_SAVE_TICKS = 100
_OWN = ("tick", "cuts", "host_numbers", "host_names")  #: the checkpoint's own arrays, beside the engine's
_KEPT = "kept_"  #: the prefix of the arrays the lockstep keeps beside them (a world shard's robots)


def save_every(record_every: int, ticks: int = SAVE_TICKS) -> int:
    """Ticks between checkpoints: the first multiple of ``record_every`` at or past ``ticks``."""
    return -(-ticks // record_every) * record_every


def shard_kept(record_every: int) -> int:
    """Ticks of messages a world shard's topics keep for a restarted peer: it may be as many ticks behind as there
    are between saves, and its peers one more (deciding the next tick), and one to spare."""
    return save_every(record_every, SHARD_SAVE_TICKS) + 2


@dataclass(frozen=True)
class Saved:
    """A checkpoint read back."""

    tick: int
    hosts: dict[int, str]  #: batch number -> its node name
    cuts: np.ndarray  #: the batches' strips (swarm_ros.core.strips.Strips.cuts)
    kept: dict[str, np.ndarray]  #: what the lockstep saved beside the run (a world shard's robots)


def save(
    path: Path, run: CentralRun, hosts: dict[int, str], cuts: np.ndarray, kept: dict[str, np.ndarray] | None = None
) -> None:
    """Save ``run`` as it stands, the batches it serves and the lockstep's ``kept`` arrays, to ``path`` (whole, or
    not at all)."""
    numbers = sorted(hosts)
    arrays: dict[str, Any] = run.saved()
    arrays.update({_KEPT + name: values for name, values in (kept or {}).items()})
    arrays.update(
        tick=np.array([run.tick]),
        cuts=np.asarray(cuts, dtype=np.int64),
        host_numbers=np.array(numbers, dtype=np.int64),
        host_names=np.array([hosts[k] for k in numbers]),
    )
    part = path.with_name(f"{path.name}.part")  # removed with the checkpoint at the end of the run
    with open(part, "wb") as f:
        np.savez(f, **arrays)
    os.replace(part, path)


def load(path: Path, run: CentralRun) -> Saved:
    """Put ``run`` (a run of the checkpoint's parameters) where the checkpoint at ``path`` left it; the batches
    it served.

    Raises:
        RunFailed: there is none, or it does not read as one of this run.
    """
    try:
        with np.load(path, allow_pickle=False) as f:
            got = {name: f[name] for name in f.files}
        tick = int(got["tick"][0])
        hosts = dict(zip(got["host_numbers"].tolist(), got["host_names"].tolist()))
        kept = {name[len(_KEPT) :]: got[name] for name in got if name.startswith(_KEPT)}
        saved = Saved(tick, hosts, got["cuts"], kept)
    except FileNotFoundError as exc:
        raise RunFailed(f"a restarted world found no checkpoint at {path}") from exc
    except (OSError, KeyError, ValueError, IndexError, zipfile.BadZipFile) as exc:
        raise RunFailed(f"the world's checkpoint {path} does not read: {exc}") from exc
    try:
        run.restore(tick, {name: got[name] for name in got if name not in _OWN and not name.startswith(_KEPT)})
    except (KeyError, ValueError, ContractError) as exc:
        raise RunFailed(f"the world's checkpoint {path} is not of this run ({exc})") from exc
    return saved
