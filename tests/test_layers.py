"""Imports run one way: planning → formats → engine → policies → sequencer → worlds/study/derive → service/cli.

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
    # ... and the planning tools that build a plan with the engine's orders and counts and the file
    # readers: they live with the plan but sit on the engine (only the command line imports them)
    "opportune.planning.relax": 2,
    "opportune.planning.learn": 2,
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
    # plans from the product's geometry: meshes read, blocking found, the plan written through formats
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

# Facades: the package's lazy names, and the old module paths users import, each a few lines
# re-exporting from the new place.  They are outside the layers (they may name any layer) and no
# module of the package imports them: internal code uses the new paths.
FACADES = {
    "opportune",
    "opportune.plan",
    "opportune.products",
    "opportune.learn",
    "opportune.simulate",
    "opportune.simulate_products",
    "opportune.report",
    "opportune.report_html",
    "opportune.engine.relax",
    "opportune.worlds.costs",
}

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


def test_every_module_has_a_layer_or_is_a_facade(graph):
    homeless = sorted(m for m in graph if m not in FACADES and layer(m) is None)
    assert not homeless, f"give these modules a layer in tests/test_layers.py's LAYERS: {homeless}"
    for facade in FACADES:
        assert facade in graph, f"{facade} is listed as a facade but is no module"


def test_no_import_goes_up_a_layer(graph):
    upward = sorted(
        f"{source} ({layer(source)}) imports {target} ({layer(target)})"
        for source, targets in graph.items() if source not in FACADES
        for target in targets if target not in FACADES and layer(target) > layer(source)
    )
    assert not upward, f"{len(upward)} imports go up a layer:\n" + "\n".join(upward)


def test_the_package_imports_no_facade(graph):
    """Internal code imports the new paths; the old ones are for users (and the package's lazy names)."""
    inward = sorted(f"{source} imports {target}" for source, targets in graph.items() if source not in FACADES
                    for target in targets if target in FACADES)
    assert not inward, f"{len(inward)} imports of a facade inside the package:\n" + "\n".join(inward)


def test_facades_are_thin(graph):
    """An old module path is a few lines of re-exports: no logic of its own."""
    modules = source_modules()
    for facade in FACADES - {"opportune"}:
        tree = ast.parse(modules[facade].read_text(encoding="utf-8"))
        kinds = {type(node).__name__ for node in tree.body}
        assert kinds <= {"Expr", "ImportFrom", "Import", "Assign"}, (facade, kinds)
        assert len(modules[facade].read_text(encoding="utf-8").splitlines()) <= 40, facade


def test_no_import_circle():
    graph = import_graph(typing=False)
    inner = {m: {t for t in targets if t not in FACADES} for m, targets in graph.items() if m not in FACADES}
    found = cycles(inner)
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
