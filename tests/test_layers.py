"""Imports run one way: planning → formats → engine → policies → sequencer → worlds/study/derive → service/cli.

Every module has its floor and no module is an exception: no old module path, no tool that lives on a
lower floor than what it imports.  The package's root is the front door (its lazy names point at every
floor), so it sits on the top one.

The package's import graph is read from its source with :mod:`ast` (every ``import`` and ``from ...
import`` at module level or inside a function, relative ones resolved, ``importlib.import_module``
and ``__import__`` calls on a literal, and string literals naming a module, as the packages' lazy
name tables hold them).  A module may import its own layer or a lower one, never a higher one; and
the modules import one another without a circle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "opportune"

# The layers, lowest first.  A module takes the layer of the longest prefix that names it.
LAYERS = {
    # planning: the plan, several products in one plan, a strategy's order, the cell's costs (no file
    # format, no counting) ...
    "opportune.planning": 0,
    # helpers every layer's package __init__ uses (lazy names) and that import nothing of opportune
    "opportune._lazy": 0,
    # the one table of limits every reader and the service take their bounds from (imports nothing)
    "opportune.limits": 0,
    # files in and out; the shipped data sets are files read through formats (a name → a path)
    "opportune.formats": 1,
    "opportune.datasets": 1,
    # the order engine; the compiled core is its fast path (it imports nothing of opportune)
    "opportune.engine": 2,
    "opportune._native": 2,
    "opportune.policies": 3,
    "opportune.sequencer": 4,
    # the sequencer of a cell fed with several products (one joint plan): a sequencer, used by the
    # service's live runs as much as by studies
    "opportune.multi": 4,
    "opportune.worlds": 5,
    # where plans come from when no one writes them by hand: learnt from observed sequences, relaxed
    # from an over-constrained plan, derived from the product's geometry; all three build a plan with
    # the file readers and the order engine
    "opportune.derive": 5,
    "opportune.study": 5,
    "opportune.service": 6,
    "opportune.cli": 6,
    "opportune.cli_count": 6,
    "opportune.client": 6,
    # the command's entry point (`opportune` and `python -m opportune`)
    "opportune.launch": 6,
    "opportune.__main__": 6,
}

# The package's root: its lazy names (``opportune.Plan``, ``opportune.Sequencer``, ...) point at several
# floors, so it sits on the top one.  Only the root itself takes this floor: a module it does not list
# has no floor (see ``layer``).
ROOT = ("opportune", 6)

# Compiled modules: not in the source tree, importable all the same.
COMPILED = {"opportune._native"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def source_modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imported(name: str, path: Path, known: set[str], typing: bool = True) -> set[str]:
    """The package's modules that module ``name`` (its source at ``path``) imports, anywhere in it.

    ``typing=False`` leaves out the imports under ``if TYPE_CHECKING:`` (for type checkers only: they
    never run, so they make no circle).  A module's own packages are left out (Python loads them
    before the module), and so is ``from opportune import __version__`` (the root's one constant)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    if not typing:
        for node in ast.walk(tree):
            if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
                node.body = []

    def add(target: str, names: tuple[str, ...] = ()) -> None:
        if target == "opportune" and names == ("__version__",):
            return
        # ``from a import b``: the module a.b if there is one, else (a name defined in a) the module a
        subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in known]
        if subs:
            found.update(subs)
            if len(subs) == len(names):
                return
        while target and target not in known:
            target = target.rpartition(".")[0]
        if target:
            found.add(target)

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            add(target, tuple(a.name for a in node.names))
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            func = node.func
            fname = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if fname in ("import_module", "__import__") and isinstance(node.args[0].value, str):
                add(node.args[0].value)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in known:
            found.add(node.value)   # a lazy name table: {"Plan": "opportune.planning.plan", ...}
    ancestors = {name.rsplit(".", k)[0] for k in range(1, name.count(".") + 1)}
    return {m for m in found if m.startswith("opportune") and m != name and m not in ancestors}


def import_graph(typing: bool = True) -> dict[str, set[str]]:
    modules = source_modules()
    known = set(modules) | COMPILED
    graph = {name: imported(name, path, known, typing) for name, path in modules.items()}
    for name in COMPILED:
        graph[name] = set()
    return graph


def layer(module: str) -> int | None:
    if module == ROOT[0]:
        return ROOT[1]
    best = None
    for prefix, level in LAYERS.items():
        if module == prefix or module.startswith(prefix + "."):
            if best is None or len(prefix) > len(best[0]):
                best = (prefix, level)
    return None if best is None else best[1]


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (networkx: the dev extra)."""
    nx = pytest.importorskip("networkx", reason="networkx is in the dev extra that make test installs")
    g = nx.DiGraph((a, b) for a, targets in graph.items() for b in targets if b in graph)
    return sorted(sorted(c) for c in nx.strongly_connected_components(g) if len(c) > 1)


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph()


def test_every_module_has_a_layer(graph):
    homeless = sorted(m for m in graph if layer(m) is None)
    assert not homeless, f"give these modules a layer in tests/test_layers.py's LAYERS: {homeless}"


def test_no_import_goes_up_a_layer(graph):
    upward = sorted(
        f"{source} ({layer(source)}) imports {target} ({layer(target)})"
        for source, targets in graph.items() for target in targets if layer(target) > layer(source)
    )
    assert not upward, f"{len(upward)} imports go up a layer:\n" + "\n".join(upward)


def test_a_layer_is_named_by_its_prefix():
    """A module takes the floor of the longest prefix naming it; the root's floor is its own alone."""
    assert layer("opportune") == 6
    assert layer("opportune.derive.learn") == layer("opportune.derive") == 5
    assert layer("opportune.engine.schedule") == 2
    assert layer("opportune.nothing_listed") is None
    assert layer("opportune_other") is None


def test_no_import_circle():
    found = cycles(import_graph(typing=False))
    assert not found, f"{len(found)} import circles:\n" + "\n".join(" ↔ ".join(c) for c in found)


def test_the_walk_sees_every_kind_of_import(tmp_path):
    """The reader finds imports inside functions, relative ones, ``from a import module``, the
    lazy tables' strings and ``import_module`` literals: a circle through any of them is found."""
    known = {"opportune", "opportune.a", "opportune.b", "opportune.b.c", "opportune.d", "opportune.e"}
    src = tmp_path / "opportune"
    (src / "b").mkdir(parents=True)
    (src / "a.py").write_text("def f():\n    from .b import c\n")
    (src / "b" / "__init__.py").write_text("_LAZY = {'x': 'opportune.d'}\n")
    (src / "b" / "c.py").write_text("import importlib\nimportlib.import_module('opportune.e')\n")
    (src / "d.py").write_text("from opportune import a\n")
    (src / "e.py").write_text("from opportune.a import f\n")
    found = {}
    global PACKAGE
    saved, PACKAGE = PACKAGE, src
    try:
        for path in sorted(src.rglob("*.py")):
            found[module_name(path)] = imported(module_name(path), path, known)
    finally:
        PACKAGE = saved
    assert found == {"opportune.a": {"opportune.b.c"}, "opportune.b": {"opportune.d"},
                     "opportune.b.c": {"opportune.e"}, "opportune.d": {"opportune.a"},
                     "opportune.e": {"opportune.a"}}
    assert cycles(found) == [["opportune.a", "opportune.b.c", "opportune.e"]]
