"""The rows of docs/bad_input.md and the files they name: read by test_bad_input.py (the rows of the command line,
run in-process) and test_ros_graph.py (the rows of a node, each a process of its own)."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import stat
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
ROW = re.compile(r"^\| (\d+) \| (.+?) \| `(.+?)` \| `(.+?)` \|$")
EXPERIMENT = "seed: 1\nrepetitions: 2\nvision_radius: 1\nshapes:\n  {shape}: [{sizes}]\n"


def table() -> list[tuple[str, str, str]]:
    """(number, command, message) of every row."""
    rows = [ROW.match(line) for line in (ROOT / "docs" / "bad_input.md").read_text().splitlines()]
    return [(m.group(1), m.group(3), m.group(4)) for m in rows if m]


def fixtures_for(command: str, source: Path, d: Path) -> None:
    """Copy into ``d`` the entries of ``source`` (a directory :func:`make_fixtures` filled) that a row's ``command``
    names, by name or by the name before its first dot (``--out left``: left.partial.rrd beside it), and the entries
    those files name in turn (an experiment file's reference). A row's directory holds only what it needs (a whole
    set in each, for every row, was most of the files a session left to delete)."""
    words = set(re.findall(r"[\w.-]+", command))
    entries = {p.name: p for p in source.iterdir()}
    wanted = {name for name in entries if name in words or name.split(".")[0] in words}
    for name in list(wanted):
        if entries[name].is_file() and not entries[name].is_symlink():
            text = entries[name].read_bytes().decode("utf-8", "replace")
            wanted |= {other for other in entries if other in text}
    for name in wanted:
        src, dst = entries[name], d / name
        if src.is_symlink():
            dst.symlink_to(os.readlink(src))
        elif stat.S_ISFIFO(src.lstat().st_mode):
            os.mkfifo(dst)
        elif src.is_dir():
            shutil.copytree(src, dst, symlinks=True)
        else:
            shutil.copy2(src, dst)


def make_fixtures(d: Path) -> None:
    """The files docs/bad_input.md names."""
    files = {
        "empty.txt": "",
        "comments.txt": "; only a comment\n",
        "badchar.txt": "....\n.#x.\n....\n",
        "ragged.txt": "....\n.##\n....\n",
        "garbage.png": "this is not a png",
        "empty.png": "",
        "split.txt": "........\n.##..##.\n.##..##.\n........\n",
        "huge.txt": ("#" * 70 + "\n") * 70,
        "thin.txt": ".....\n.###.\n.....\n",
        "bad.yaml": "/**:\n  ros__parameters:\n    robotz: 100\n",
        "typed.yaml": "/**:\n  ros__parameters:\n    robots: many\n",
        "broken.yaml": "/**:\n  ros__parameters: [\n",
        "notadir": "a file\n",
        "badexp.yaml": EXPERIMENT.format(shape="stra", sizes="100"),
        "negexp.yaml": EXPERIMENT.format(shape="star", sizes="1030, -3"),
        "rules.yaml": "/**:\n  ros__parameters:\n    rules: fast\n",
        "rulesexp.yaml": EXPERIMENT.format(shape="star", sizes="1036") + "rules: [paper, fast]\n",
        "refexp.yaml": EXPERIMENT.format(shape="star", sizes="1036") + "reference: notes.csv\n",
        "notes.csv": "a,b\n1,2\n",
        "window.yaml": "/world:\n  ros__parameters:\n    monitor_window: -5\n",
        "split.yaml": "/robot_batch:\n  ros__parameters:\n    batches: 3\n",
        "batchrobots.yaml": "/robot_batch:\n  ros__parameters:\n    robots: 600\n",
        "worldseed.yaml": "/**:\n  ros__parameters:\n    robots: 500\n/world:\n  ros__parameters:\n    seed: 3\n",
        "foo.yaml": "/foo:\n  ros__parameters:\n    robots: 500\n",
        "batch0.yaml": "/robot_batch_0:\n  ros__parameters:\n    seed: 9\n",
        "outdir.yaml": "/**:\n  ros__parameters:\n    out_dir: x\n",
        "worldout.yaml": "/world:\n  ros__parameters:\n    out_dir: x\n",
        "shards.yaml": "/monitor:\n  ros__parameters:\n    world_shards: 3\n",
        "left.partial.rrd": "what an earlier, killed run recorded\n",
        "bigexp.yaml": EXPERIMENT.format(shape="star", sizes="1036") + "world_radius: 100000\n",
        "okexp.yaml": EXPERIMENT.format(shape="star", sizes="1036"),
        "farexp.yaml": EXPERIMENT.format(shape="star", sizes="1036").replace("vision_radius: 1", "vision_radius: 40"),
    }
    files.update(
        {
            "hugeexp.yaml": EXPERIMENT.format(shape="star", sizes="1036") + "max_ticks: 100000000000000000000\n",
            "manyexp.yaml": EXPERIMENT.format(shape="star", sizes="1036").replace(
                "repetitions: 2", "repetitions: 1000000000000"
            ),
            "gridexp.yaml": EXPERIMENT.format(shape="star", sizes="1036")
            .replace("repetitions: 2", "repetitions: 100000")
            .replace("vision_radius: 1", "vision_radius: [1, 2, 3, 4]")
            + "rules: [paper, local, literal]\n",
            "floatexp.yaml": EXPERIMENT.format(shape="star", sizes="442.0"),
            "twice.yaml": "/**:\n  ros__parameters:\n    robots: 500\n    robots: 600\n",
            "torusexp.yaml": EXPERIMENT.format(shape="torus", sizes="100") + "algorithm: [darr-niazi, rubenstein]\n",
            "scaledexp.yaml": EXPERIMENT.format(shape="star", sizes="1036") + "shape_scale: 3\n",
            "scaled.yaml": "/**:\n  ros__parameters:\n    shape_scale: 1.5\n",
            "rbcuts.yaml": "/**:\n  ros__parameters:\n    algorithm: rubenstein\n"
            '/robot_batch:\n  ros__parameters:\n    region_cuts: "500"\n',
        }
    )
    for name, text in files.items():
        (d / name).write_text(text)
    (d / "bomb.png").write_bytes(_png_header(10000, 10000))
    (d / "loop").symlink_to("loop")
    (d / "dangling").symlink_to("missing")
    os.mkfifo(d / "fifo")
    (d / "badrow").mkdir()
    (d / "badrow" / "results.csv").write_text(
        "shape,shape_file,robots,vision_radius,rules,join,crowding,steps,repetition,seed,shape_patches,max_ticks,"
        "wiggle_deg,world_radius,fail_fraction,fail_tick,engine,outcome,convergence_tick,localized,unlocalized,"
        "separated,empty_patches,lost_robots,convergence_rate,wall_seconds\n"
        "star,star.txt,1036,1.0,paper,walk,ahead,one,0,1,1036,100000,45.0,32,0.0,0,inprocess,bogus,405,1036,0,0,0,0,"
        "2.5,0.5\n"
    )
    _make_damaged_results(d)
    (d / "noise").mkdir()
    (d / "noise" / "results.csv").write_bytes(np.random.default_rng(3).bytes(3000))
    Image.new("L", (9, 9), 255).save(d / "white.png")
    (d / "taken").mkdir()
    (d / "taken" / "summary.json").write_text("{}")
    (d / "emptydir").mkdir()
    (d / "brokenbag").mkdir()
    (d / "brokenbag" / "metadata.yaml").write_text("rosbag2_bagfile_information: [\n")
    (d / "oldbag").mkdir()
    (d / "oldbag" / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: 99\n")
    _make_3d_fixtures(d)


def _make_damaged_results(d: Path) -> None:
    """Copies of the pilot's results.csv (18 real rows; line 14 is the rectangle's first run under the study's model),
    each damaged one way, and one beside a regular file named figures."""
    text = (ROOT / "docs" / "results" / "head_to_head_pilot" / "results.csv").read_text()
    lines = text.splitlines(keepends=True)
    complete = lines[13]
    assert complete.startswith("rectangle,rectangle,442,darr-niazi,") and ",complete," in complete
    columns = lines[0].strip().split(",")

    def edited(**values: str) -> str:
        cells = complete.strip().split(",")
        for key, value in values.items():
            cells[columns.index(key)] = value
        return ",".join(cells) + "\n"

    damaged = {
        "dup": text + complete,
        "cut": text + complete[:40],
        "over": "".join([*lines[:13], edited(coverage="7.5"), *lines[14:]]),
        "partial": "".join([*lines[:13], edited(coverage="0.1"), *lines[14:]]),
        "figfile": text,
    }
    for name, content in damaged.items():
        (d / name).mkdir()
        (d / name / "results.csv").write_text(content)
    (d / "figfile" / "figures").write_text("a file of the user's, not the report's\n")


def _png_header(width: int, height: int) -> bytes:
    """The first bytes of a 1-bit greyscale PNG of this size: all an image's size is read from."""
    import struct
    import zlib

    ihdr = b"IHDR" + struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr[4:]) + chunk(b"IDAT", b"") + chunk(b"IEND", b"")


def _make_3d_fixtures(d: Path) -> None:
    """The 3D shape files of docs/bad_input.md: meshes and layered text grids."""
    import trimesh

    trimesh.creation.torus(major_radius=8, minor_radius=3).export(d / "ring.stl")
    open_box = trimesh.creation.box(extents=(10, 8, 6))
    open_box.update_faces(np.arange(1, len(open_box.faces)))  # one triangle removed: a hole
    open_box.export(d / "open.stl")
    (d / "junk.stl").write_text("not a mesh\n")
    (d / "layers.txt").write_text("###\n###\n---\n##\n##\n")
    (d / "flat3d.txt").write_text("##\n##\n---\n##\n#.\n")


def listing(d: Path) -> dict[str, int]:
    return {str(p.relative_to(d)): p.lstat().st_size for p in d.rglob("*")}


#: the first words of a row that starts a node: ros2 run swarm_ros <node> (ros2cli need not be installed: the test runs
#: the node's module)
NODE = ("ros2", "run", "swarm_ros")


def split_assignments(words: list[str]) -> dict[str, str]:
    """Take the VAR=value words before the command off ``words``, as a shell takes them."""
    assigned = {}
    while words and re.fullmatch(r"[A-Z_]+=.*", words[0]):
        name, _, value = words.pop(0).partition("=")
        assigned[name] = value
    return assigned


def starts_node(command: str) -> bool:
    """Whether a row's command runs a node (``ros2 run swarm_ros <node> ...``) rather than swarm-ros."""
    words = shlex.split(command)
    split_assignments(words)
    return tuple(words[:3]) == NODE
