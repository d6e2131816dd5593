"""Rerun recordings read back, and rerun's own verification of a file."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np


class Recording:
    """What an .rrd file holds, read back with rerun's own reader (not with swarm_ros code).

    Attributes:
        series: metric name -> {tick: value} (entities ``metrics/<name>``).
        robots: tick -> (positions (n, 2) float32, class ids (n,)) of ``world/robots`` ((n, 3) in 3D).
        occupancy: tick -> flat uint8 class image of ``world/occupancy`` (3D: the filled voxels' centres, flat).
        events: (tick, text) of ``events``, in tick order.
        static: entity paths that hold static data.
        blueprints: how many blueprints the file holds.
    """

    def __init__(self, path) -> None:
        import warnings

        from rerun.chunk import RrdReader

        self.series: dict[str, dict[int, float]] = {}
        self.robots: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.occupancy: dict[int, np.ndarray] = {}
        self.events: list[tuple[int, str]] = []
        self.static: set[str] = set()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a file without footer (killed writer) warns, and reads
            reader = RrdReader(str(path))
            self.blueprints = len(reader.blueprints())
            chunks = reader.stream().to_chunks()
        for chunk in chunks:
            entity, batch = chunk.entity_path, chunk.to_record_batch()
            if chunk.is_static:
                self.static.add(entity)
                continue
            names = batch.schema.names
            ticks = batch.column("tick").to_numpy().tolist()
            if "Scalars:scalars" in names:
                values = batch.column("Scalars:scalars").flatten().to_numpy()
                self.series.setdefault(entity.rsplit("/", 1)[1], {}).update(zip(ticks, values.tolist()))
            for kind, dims in (("Points2D", 2), ("Points3D", 3)):  # a 3D run's robots are Points3D
                if f"{kind}:positions" in names:
                    pos, cls = batch.column(f"{kind}:positions"), batch.column(f"{kind}:class_ids")
                    for k, tick in enumerate(ticks):
                        p = pos[k].values.flatten().to_numpy(zero_copy_only=False).reshape(-1, dims)
                        self.robots[tick] = (p, cls[k].values.to_numpy(zero_copy_only=False))
            if "SegmentationImage:buffer" in names:
                buf = batch.column("SegmentationImage:buffer")
                for k, tick in enumerate(ticks):
                    self.occupancy[tick] = buf[k].values[0].values.to_numpy(zero_copy_only=False)
            if "Boxes3D:centers" in names:  # a 3D run's filled voxels: their centres, (n, 3) flattened
                centres = batch.column("Boxes3D:centers")
                for k, tick in enumerate(ticks):
                    self.occupancy[tick] = centres[k].values.flatten().to_numpy(zero_copy_only=False)
            if "TextLog:text" in names:
                texts = batch.column("TextLog:text").flatten().to_pylist()
                self.events += list(zip(ticks, texts))
        self.events.sort()

    def same_data(self, other: Recording) -> bool:
        """Whether two recordings hold the same logged data (not the same bytes: ids and times differ)."""
        return (
            self.series == other.series
            and self.events == other.events
            and self.static == other.static
            and self.robots.keys() == other.robots.keys()
            and all(np.array_equal(a, b) for t in self.robots for a, b in zip(self.robots[t], other.robots[t]))
            and self.occupancy.keys() == other.occupancy.keys()
            and all(np.array_equal(self.occupancy[t], other.occupancy[t]) for t in self.occupancy)
        )


def rrd_verify(path) -> subprocess.CompletedProcess:
    """``rerun rrd verify PATH`` with the rerun CLI installed beside this Python."""
    import sys

    exe = Path(sys.executable).with_name("rerun")
    return subprocess.run([str(exe), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
