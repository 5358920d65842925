"""The code's shape, measured from the source: the limits docs/where-a-change-goes.md promises.

Each test walks the package with :mod:`ast` (nothing is imported), so a change that breaks a limit
fails here with the place named, not in review.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "opportune"

#: Functions allowed past :data:`MAX_LINES`: the pure-Python counter's hot closure and the method that
#: builds it (one call per set counted; splitting it costs a call per set). At most two, by promise.
LONG_ALLOWED = frozenset({"engine/count.py:Counter._make_counter", "engine/count.py:Counter._make_counter.f"})
MAX_LINES = 100   # lines of code: a docstring is not counted (see _length)

#: The paths the old layout had, removed in 0.2.0 (CHANGELOG "What moved").
OLD_PATHS = ("plan.py", "simulate.py", "report.py", "report_html.py", "simulate_products.py", "learn.py",
             "products.py", "engine/relax.py", "worlds/costs.py", "planning/learn.py", "planning/relax.py")


def _functions(tree: ast.AST, prefix: str = ""):
    """(qualified name, node) of every function, methods and closures included."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            name = f"{prefix}{node.name}"
            yield name, node
            yield from _functions(node, name + ".")
        elif isinstance(node, ast.ClassDef):
            yield from _functions(node, f"{prefix}{node.name}.")
        else:
            yield from _functions(node, prefix)


def _length(node) -> int:
    """Lines of a function without its docstring: numpydoc sections are read apart from the code."""
    lines = node.end_lineno - node.lineno + 1
    first = node.body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        lines -= first.end_lineno - first.lineno + 1
    return lines


def _long_functions() -> dict[str, int]:
    found = {}
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        for name, node in _functions(ast.parse(path.read_text(encoding="utf-8"))):
            lines = _length(node)
            if lines > MAX_LINES:
                found[f"{rel}:{name}"] = lines
    return found


def test_no_function_over_the_limit_outside_the_stated_list():
    long = _long_functions()
    assert len(LONG_ALLOWED) <= 2
    unexpected = {k: v for k, v in long.items() if k not in LONG_ALLOWED}
    assert not unexpected, f"functions over {MAX_LINES} lines: {unexpected}"


def test_the_walk_finds_a_long_function(tmp_path):
    """The walk sees closures inside methods: a 102-line closure is reported by its qualified name."""
    body = "\n".join(["            x = 1"] * 100)
    tree = ast.parse(f"class A:\n    def m(self):\n        def g():\n{body}\n            return x\n")
    sizes = {n: _length(node) for n, node in _functions(tree)}
    assert sizes["A.m.g"] == 102 and sizes["A.m"] == 103


def test_a_docstring_is_not_counted():
    tree = ast.parse('def f():\n    """One.\n\n    Two.\n    """\n    return 1\n')
    (node,) = tree.body
    assert _length(node) == 2


def test_the_schedule_module_stays_small():
    lines = (SRC / "engine" / "schedule.py").read_text(encoding="utf-8").count("\n")
    assert lines <= 500, f"engine/schedule.py has {lines} lines (promised: at most 500)"


def test_create_app_is_short():
    tree = ast.parse((SRC / "service" / "app.py").read_text(encoding="utf-8"))
    (node,) = [n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "create_app"]
    assert node.end_lineno - node.lineno + 1 <= 60


@pytest.mark.parametrize("old", OLD_PATHS)
def test_no_old_path_stub(old):
    assert not (SRC / old).exists(), f"{old} came back: the 0.2.0 layout moved it (CHANGELOG)"
