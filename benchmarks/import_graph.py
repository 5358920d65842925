"""The package's import graph, room by room, drawn from the code (docs/where-a-change-goes.md's figure).

A *room* is one entry of the layer table ``tests/test_layers.py`` checks (``opportune.engine``,
``opportune.derive``, ``opportune.cli``, ...); the figure puts each room on its floor (lowest at the
bottom), lists the modules it holds, and draws an arrow from a room to every room it imports (the
import walk of ``tests/test_layers.py``: every import, at module level or in a function, and the lazy
name tables), the wider the more module-to-module imports stand behind it.  The command line's
modules (the ``cli`` package, ``cli_count``, ``launch``, ``__main__``) are one room.  The package's root (its lazy
names only) and the compiled core (``opportune._native``, which imports nothing) are left out, as is
``opportune._lazy`` (the lazy-name helper every package's ``__init__`` imports, which imports
nothing): arrows to them say nothing about where a change goes.

Usage::

    python benchmarks/import_graph.py            # writes docs/img/import-graph.dot and .svg (graphviz's dot)
    python benchmarks/import_graph.py --check    # exit 1 if the committed .dot differs from the code's

``tests/test_where_a_change_goes.py`` regenerates the DOT text and compares it with the committed file,
so the figure cannot drift from the code.
"""

from __future__ import annotations

import argparse
import math
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from test_layers import LAYERS, ROOT, import_graph  # noqa: E402  (the one layer table and import walk)

DOT = REPO / "docs" / "img" / "import-graph.dot"
SVG = DOT.with_suffix(".svg")
#: Left out of the figure (see the module's text).
LEFT_OUT = {ROOT[0], "opportune._native", "opportune._lazy"}
#: The command line's modules, drawn as one room (its entry, the fast ``count`` and the rest).
COMMAND_LINE = {"opportune.cli_count": "opportune.cli", "opportune.launch": "opportune.cli",
                "opportune.__main__": "opportune.cli"}
#: The floors' names, lowest first (the layers of tests/test_layers.py).
FLOORS = ("plan, limits", "files", "engine", "policies", "sequencer", "worlds, study, derive", "front doors")


def room(module: str) -> str | None:
    """The room (longest prefix in the layer table) a module belongs to; None for one left out."""
    if module in LEFT_OUT:
        return None
    best = max((p for p in LAYERS if module == p or module.startswith(p + ".")), key=len, default=None)
    return None if best in LEFT_OUT else COMMAND_LINE.get(best, best)


def short(name: str) -> str:
    """A room's or module's name without the package's."""
    return name.removeprefix("opportune.")


def room_graph() -> tuple[dict[str, list[str]], Counter]:
    """The rooms with their modules (sorted), and the number of module imports between each two rooms."""
    graph = import_graph()
    rooms: dict[str, list[str]] = {}
    edges: Counter = Counter()
    for module, targets in graph.items():
        here = room(module)
        if here is None:
            continue
        rooms.setdefault(here, []).append(module)
        for target in targets:
            there = room(target)
            if there is not None and there != here:
                edges[here, there] += 1
    return {r: sorted(ms) for r, ms in sorted(rooms.items())}, edges


def _label(name: str, modules: list[str]) -> str:
    """The room's name over its modules (a package's first level: ``routers``, not each router)."""
    inside = sorted({short(m).removeprefix(short(name) + ".").split(".")[0] for m in modules if m != name})
    lines, line = [], ""
    for word in inside:   # a few modules a line, so that a large room stays readable
        if line and len(line) + len(word) > 34:
            lines.append(line)
            line = ""
        line = f"{line} {word}".strip()
    if line:
        lines.append(line)
    return "\\n".join([short(name), *lines]) if lines else short(name)


def dot_text() -> str:
    """The figure's DOT source: deterministic (sorted), so that a test can compare it with the committed one."""
    rooms, edges = room_graph()
    out = ["// The package's import graph by room: made by benchmarks/import_graph.py from the code; do not edit.",
           "digraph imports {",
           '  graph [ranksep=0.5, nodesep=0.25, fontname="Helvetica", newrank=true];',
           '  node [shape=box, style="rounded,filled", fillcolor="#f4f6fa", fontname="Helvetica", fontsize=10];',
           '  edge [color="#8899aa", arrowsize=0.6];',
           "  // the floors, top floor first: a spine of their names on the left, each room on its floor",
           '  node [shape=plaintext, style="", fontsize=10, fontcolor="#556677"];']
    floors = [level for level in range(len(FLOORS) - 1, -1, -1) if any(LAYERS[r] == level for r in rooms)]
    out += [f'  floor{level} [label="floor {level}\\n{FLOORS[level]}"];' for level in floors]
    out.append("  " + " -> ".join(f"floor{level}" for level in floors) + " [style=invis];")
    out.append('  node [shape=box, style="rounded,filled", fontsize=10, fontcolor=black];')
    for level in floors:
        names = [r for r in rooms if LAYERS[r] == level]
        out.append(f"  {{ rank=same; floor{level}; " + " ".join(f'"{short(r)}";' for r in names) + " }")
        out += [f'  "{short(r)}" [label="{_label(r, rooms[r])}"];' for r in names]
    # an arrow's width grows with the number of module imports behind it
    for (a, b), n in sorted(edges.items()):
        out.append(f'  "{short(a)}" -> "{short(b)}"' + (f" [penwidth={1 + math.log2(n) / 2:.2f}];" if n > 1 else ";"))
    out.append("}")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed .dot; write nothing")
    args = parser.parse_args(argv)
    text = dot_text()
    if args.check:
        same = DOT.is_file() and DOT.read_text(encoding="utf-8") == text
        print(f"{DOT.relative_to(REPO)}: " + ("as the code" if same else "differs from the code: run "
                                               "python benchmarks/import_graph.py"))
        return 0 if same else 1
    DOT.write_text(text, encoding="utf-8")
    if shutil.which("dot") is None:
        print("graphviz's `dot` is not on the PATH (apt install graphviz): wrote the .dot only", file=sys.stderr)
        return 1
    subprocess.run(["dot", "-Tsvg", str(DOT), "-o", str(SVG)], check=True)
    rooms, edges = room_graph()
    print(f"{len(rooms)} rooms, {sum(len(m) for m in rooms.values())} modules, {len(edges)} arrows "
          f"({sum(edges.values())} module imports): {DOT.relative_to(REPO)}, {SVG.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
