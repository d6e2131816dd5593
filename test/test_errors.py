"""One error vocabulary: every error the package raises on purpose is a SwarmError, one class per meaning
(swarm_ros/core/errors.py says which); no built-in exception stands in for a condition the package checks."""

import ast
import builtins
import importlib
import inspect
import pkgutil
from pathlib import Path

import pytest

import swarm_ros
from swarm_ros.core import errors

pytestmark = pytest.mark.unit

PACKAGE = Path(swarm_ros.__file__).parent
#: Built-in exceptions the package may raise: protocols of Python or of a library it plugs into, and the
#: file system's own errors (the command line reports an OSError in one line too).
ALLOWED = {
    "AttributeError",  # a module's __getattr__ (PEP 562) must raise it
    "NotImplementedError",  # an abstract method
    "SystemExit",
    "KeyboardInterrupt",  # a node's exit status; SIGTERM ending a command as Ctrl-C does
    "OSError",
    "FileNotFoundError",
    "FileExistsError",  # the file system's answer, passed on
}
BUILTIN = {name for name, obj in vars(builtins).items() if isinstance(obj, type) and issubclass(obj, BaseException)}
#: Modules that need ROS (or a launch tree) to import; their classes are found by reading the source instead.
_SKIP_IMPORT = ("swarm_ros.nodes", "swarm_ros.ros", "swarm_ros.tools")


def _sources() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def test_no_builtin_exception_is_raised_for_a_checked_condition():
    found = []
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Raise) and node.exc is not None:
                call = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                name = call.id if isinstance(call, ast.Name) else None
                if name in BUILTIN and name not in ALLOWED:
                    found.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}: raise {name}")
    assert not found, "raise the class of swarm_ros.core.errors that says what went wrong:\n" + "\n".join(found)


def test_every_exception_class_of_the_package_is_a_swarm_error():
    """Read from the source (some modules need ROS to import): each class deriving from an exception derives,
    through the package's own classes, from SwarmError."""
    bases: dict[str, list[str]] = {}
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef):
                bases[node.name] = [b.id if isinstance(b, ast.Name) else ast.unparse(b) for b in node.bases]

    exceptions = {name for name in bases if _chain(name, bases) & (BUILTIN | {"SwarmError"})}
    family = {"SwarmError", "KeyboardInterrupt"}  # or a Ctrl-C said once (signals.InterruptSaid)
    strays = sorted(n for n in exceptions if n != "SwarmError" and not family & _chain(n, bases))
    assert not strays, f"exception classes outside the SwarmError family: {strays}"
    assert {"InputError", "ContractError", "Rejected", "RunFailed", "InvariantError"} <= exceptions


def _chain(name: str, bases: dict[str, list[str]]) -> set[str]:
    out, todo = set(), [name]
    while todo:
        n = todo.pop()
        for b in bases.get(n, []):
            if b not in out:
                out.add(b)
                todo.append(b)
    return out


def test_the_families_do_not_catch_one_another():
    """A handler for one meaning never takes another's: none is a ValueError (a bare ``except ValueError``
    around int() cannot swallow them), and the five meanings are disjoint."""
    meanings = [errors.InputError, errors.ContractError, errors.Rejected, errors.RunFailed, errors.InvariantError]
    assert not issubclass(errors.SwarmError, ValueError | AssertionError | RuntimeError)
    for a in meanings:
        assert issubclass(a, errors.SwarmError)
        assert [b for b in meanings if b is not a and issubclass(a, b)] == []


def test_the_importable_modules_define_no_exception_outside_the_family():
    """The same check on the live classes of every module that imports without ROS."""
    for info in pkgutil.walk_packages(swarm_ros.__path__, "swarm_ros."):
        if info.name.startswith(_SKIP_IMPORT) or info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__ == info.name and issubclass(cls, BaseException):
                assert issubclass(cls, errors.SwarmError | KeyboardInterrupt), f"{info.name}.{cls.__name__}"


@pytest.mark.parametrize("cls", [errors.InputError, errors.ContractError, errors.RunFailed, errors.InvariantError])
def test_an_error_reads_as_one_line(cls):
    assert str(cls("a key 'x\ny' is unknown")) == "a key 'x\\ny' is unknown"
    assert str(errors.Rejected("size", "3\nbytes")) == "size: 3\\nbytes"
