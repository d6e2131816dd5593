"""The package's import graph, as the source says it."""

from __future__ import annotations

from pathlib import Path


def _imports_of(path, module: str, package: str) -> set[str]:
    """The swarm_ros modules that ``module`` (file ``path``) imports, lazy and TYPE_CHECKING imports included."""
    import ast

    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")
            if node.level:
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            found.add(target)
            found |= {f"{target}.{a.name}" for a in node.names}  # `from . import messages`
    return found


def module_graph() -> dict[str, set[str]]:

    root = Path(__file__).resolve().parents[1] / "swarm_ros"
    modules = {}
    for path in root.rglob("*.py"):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        package = ".".join(parts if parts[-1] == "__init__" else parts[:-1]).removesuffix(".__init__")
        name = ".".join(parts).removesuffix(".__init__")
        modules[name] = (path, package)
    return {
        name: {m for m in _imports_of(path, name, package) if m in modules and m != name}
        for name, (path, package) in modules.items()
    }


#: Each subpackage's layer, lowest first. ``swarm_ros`` itself (its ``__main__``) is above them all.
LAYERS = {"core": 0, "protocol": 1, "artifacts": 2, "ros": 3, "nodes": 4, "tools": 4, "app": 5}


def layer_of(module: str) -> tuple[str, int]:
    parts = module.split(".")
    if module == "swarm_ros":
        return "swarm_ros", -1  # the package itself: only its version, which any layer may read
    if len(parts) < 2 or parts[1] not in LAYERS:
        return "swarm_ros", max(LAYERS.values()) + 1
    return parts[1], LAYERS[parts[1]]
