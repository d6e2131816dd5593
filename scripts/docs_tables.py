#!/usr/bin/env python3
"""Write the docs' tables that mirror code, from the code: the run's and each node's parameters
(``swarm_ros.core.params``) in docs/protocol.md. A table sits between ``<!-- table: NAME -->`` and
``<!-- end of table -->``; NAME is ``run`` or a node (``world``, ``robot_batch``, ``monitor``).
test/test_docs.py fails while a table is not what this script writes.

    .venv/bin/python scripts/docs_tables.py [--check]
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
from pathlib import Path

from swarm_ros.core.params import NODE_PARAMETERS, RUN_PARAMETERS, Param

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "docs" / "protocol.md"]
_BLOCK = re.compile(r"(<!-- table: (\w+) -->\n)(.*?)(<!-- end of table -->)", re.S)


def markdown_table(params: tuple[Param, ...]) -> str:
    """The parameters as a Markdown table: name, default, meaning, valid values."""
    rows = ["| parameter | default | meaning | valid values |", "|---|---|---|---|"]
    for p in params:
        default = f'"{p.default}"' if p.kind is str else str(p.default).lower() if p.kind is bool else p.default
        rows.append(f"| `{p.name}` | {default} | {p.help} | {p.describe()} |".replace("\n", " "))
    return "\n".join(rows) + "\n"


def table(name: str) -> str:
    return markdown_table(RUN_PARAMETERS if name == "run" else NODE_PARAMETERS[name])


def render(text: str) -> str:
    """``text`` with every table block rewritten from the code."""
    return _BLOCK.sub(lambda m: m.group(1) + table(m.group(2)) + m.group(4), text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a table is stale")
    args = parser.parse_args(argv)
    stale = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        new = render(text)
        if new == text:
            continue
        stale.append(page.relative_to(ROOT))
        if not args.check:
            fd, tmp = tempfile.mkstemp(dir=page.parent, prefix=f".{page.name}.")
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(new)
            os.replace(tmp, page)
    for page in stale:
        print(f"{page}: {'stale' if args.check else 'rewritten'}", file=sys.stderr)
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    raise SystemExit(main())
