"""The command line's shape: one module per group of commands, registered in one place, no long function.

``opportune.cli`` makes the application and registers the commands; each command is a function of the
module of its group (``opportune.cli.plans``, ``opportune.cli.simulate``, ...), whose checks, work and
printing are helper functions, so no function of the command line reaches 100 lines.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
from pathlib import Path

import typer
import typer.models

import opportune.cli
from opportune.cli import app

SOURCE = Path(opportune.cli.__file__).resolve().parent
# The command line's modules outside the package: its entry and the quick path of `count`.
ALSO = (SOURCE.parent / "cli_count.py", SOURCE.parent / "launch.py")
LONGEST = 100   # lines of a function (its signature and docstring included), at most - 1


def functions(path: Path):
    """Every function and method in a source file (nested ones too), with its length in lines."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield f"{path.name}:{node.lineno} {node.name}", node.end_lineno - node.lineno + 1


def test_no_function_of_the_command_line_reaches_100_lines():
    paths = sorted(SOURCE.glob("*.py")) + list(ALSO)
    found = dict(f for path in paths for f in functions(path))
    assert len(found) > 50      # the walk sees the package (every module's functions, not one file's)
    long = {name: n for name, n in found.items() if n >= LONGEST}
    assert not long, f"functions of {LONGEST} lines or more: {long}; move their checks and printing into helpers"


def test_the_check_sees_a_long_function(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(LONGEST))
    (tmp_path / "long.py").write_text(f"def f():\n{body}\n")
    assert dict(functions(tmp_path / "long.py")) == {"long.py:1 f": LONGEST + 1}


def registered(typer_app: typer.Typer) -> list:
    """The callbacks of every command the application runs, its groups' commands included."""
    found = [c.callback for c in typer_app.registered_commands]
    for group in typer_app.registered_groups:
        found += registered(group.typer_instance)
    return found


def is_command(function) -> bool:
    """A function whose parameters are typer's arguments and options (a command, registered or not)."""
    return any(isinstance(p.default, typer.models.ParameterInfo)
               for p in inspect.signature(function).parameters.values())


def test_every_command_lives_in_its_group_module_and_is_registered():
    modules = [opportune.cli] + [importlib.import_module(f"opportune.cli.{m.name}")
                                 for m in pkgutil.iter_modules([str(SOURCE)]) if m.name != "__main__"]
    written = {f for module in modules for _, f in inspect.getmembers(module, inspect.isfunction)
               if f.__module__ == module.__name__ and is_command(f)}
    written.discard(app.registered_callback.callback)     # the main group's own options (--version)
    callbacks = registered(app)
    assert len(callbacks) == len(set(callbacks)) >= 18      # no command registered twice
    # each from a group's module (the package's own module registers, it defines none) ...
    assert {f.__module__ for f in callbacks} <= {m.__name__ for m in modules} - {"opportune.cli"}
    # ... and every function written as a command is one (`schema` takes no parameter: only registered)
    assert written <= set(callbacks), f"not registered: {sorted(f.__qualname__ for f in written - set(callbacks))}"
    assert {f.__name__ for f in set(callbacks) - written} == {"schema"}
