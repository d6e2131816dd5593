#!/usr/bin/env python3
"""Screenshot of the Rerun viewer showing a recording, taken headless (the README's picture).

Needs a Vulkan driver; on a machine with no GPU, Mesa's software one does:
``apt-get install mesa-vulkan-drivers``. Without one the viewer cannot start and this
script says so.

    .venv/bin/python scripts/screenshot.py runs/<run>/recording.rrd docs/images/rerun_viewer.png --tick 300
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from PIL import Image


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("recording", type=Path, help="an .rrd file")
    parser.add_argument("out", type=Path, help="the PNG to write")
    parser.add_argument("--tick", type=int, help="show this tick (default: the last)")
    parser.add_argument("--width", type=int, default=1440, help="scale the 1920-wide screenshot to this width")
    parser.add_argument("--port", type=int, default=9877, help="port of the headless viewer")
    parser.add_argument("--settle", type=float, default=4.0, help="seconds to let the viewer load and paint")
    args = parser.parse_args()
    if not args.recording.is_file():
        print(f"screenshot: error: {args.recording}: no such file", file=sys.stderr)
        return 2

    from rerun.experimental import ViewerClient

    exe = Path(sys.executable).with_name("rerun")
    try:
        viewer = ViewerClient.spawn(
            headless=True, port=args.port, hide_welcome_screen=True, executable_path=str(exe) if exe.exists() else None
        )
    except Exception as exc:  # no Vulkan adapter, no viewer binary
        print(
            f"screenshot: error: cannot start a headless Rerun viewer ({exc}); "
            f"try 'apt-get install mesa-vulkan-drivers'",
            file=sys.stderr,
        )
        return 1
    try:
        return _shoot(viewer, args)
    except (ConnectionError, RuntimeError) as exc:  # the viewer died after it started: no render context
        print(
            f"screenshot: error: the headless Rerun viewer stopped ({exc}); it needs a Vulkan driver: "
            f"try 'apt-get install mesa-vulkan-drivers'",
            file=sys.stderr,
        )
        return 1
    except OSError as exc:  # the PNG could not be written (a full disk, a folder that is not there)
        print(f"screenshot: error: cannot write {args.out}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    finally:
        try:
            viewer.quit()
        except (ConnectionError, OSError, RuntimeError):
            pass  # already gone


def _shoot(viewer, args: argparse.Namespace) -> int:
    """Open the recording in ``viewer``, go to the tick, and write the screenshot to ``args.out``."""
    viewer.open(str(args.recording.absolute()))
    time.sleep(args.settle)
    if args.tick is not None:
        viewer.set_time("tick", sequence=args.tick, play_state="paused")
    else:
        viewer.set_time(play_state="paused")
    time.sleep(1.0)
    with tempfile.TemporaryDirectory() as tmp:
        shot = Path(tmp) / "shot.png"
        viewer.save_screenshot(str(shot))
        image = Image.open(shot)
        if args.width and image.width > args.width:
            image = image.resize((args.width, round(image.height * args.width / image.width)), Image.LANCZOS)
        part = args.out.with_name(f".{args.out.name}.tmp")
        try:
            image.save(part, format="PNG", optimize=True)
            part.replace(args.out)
        finally:
            part.unlink(missing_ok=True)  # only if it was not renamed: nothing half-written is left
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
