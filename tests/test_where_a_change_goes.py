"""The page "Where a change goes": its figure is the code's import graph, and it names every room.

The figure's DOT source is regenerated from the code (``benchmarks/import_graph.py``, the import walk
of ``tests/test_layers.py``) and must equal the committed ``docs/img/import-graph.dot``; the committed
SVG must be drawn from that DOT (the same rooms and arrows); the page must name every room.
"""

from __future__ import annotations

import html
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import import_graph  # noqa: E402

PAGE = ROOT / "docs" / "where-a-change-goes.md"
REDRAW = "the figure differs from the code: run `python benchmarks/import_graph.py` and commit docs/img/import-graph.*"


def _dot_rooms_and_arrows(text: str) -> tuple[set[str], set[tuple[str, str]]]:
    rooms = set(re.findall(r'^\s*"([^"]+)" \[label=', text, re.M))
    arrows = set(re.findall(r'^\s*"([^"]+)" -> "([^"]+)"', text, re.M))
    return rooms, arrows


def test_the_committed_figure_is_the_code_s_import_graph():
    assert import_graph.DOT.read_text(encoding="utf-8") == import_graph.dot_text(), REDRAW


def test_the_svg_is_drawn_from_the_committed_dot():
    """Graphviz writes each node's and each edge's name as an SVG ``<title>``: the same rooms, the same arrows."""
    rooms, arrows = _dot_rooms_and_arrows(import_graph.DOT.read_text(encoding="utf-8"))
    svg = import_graph.SVG.read_text(encoding="utf-8")
    titles = {html.unescape(t) for t in re.findall(r"<title>(.*?)</title>", svg)}
    drawn_arrows = {tuple(t.split("->")) for t in titles if "->" in t}
    drawn_rooms = {t for t in titles if "->" not in t and not t.startswith("floor") and t != "imports"}
    assert (drawn_rooms, drawn_arrows) == (rooms, arrows), REDRAW


def test_the_graph_holds_every_module_and_import_between_rooms():
    """A second reading: every module of the source tree is in one room (but those left out, stated), and
    an arrow joins two rooms exactly when some module of one imports some module of the other."""
    graph = import_graph.import_graph()
    rooms, edges = import_graph.room_graph()
    placed = {m for ms in rooms.values() for m in ms}
    assert placed | (import_graph.LEFT_OUT & set(graph)) == set(graph)
    expected = {(import_graph.room(a), import_graph.room(b)) for a, targets in graph.items() for b in targets}
    expected = {(a, b) for a, b in expected if a and b and a != b}
    assert set(edges) == expected
    assert sum(edges.values()) == sum(1 for a, targets in graph.items() for b in targets
                                      if import_graph.room(a) and import_graph.room(b)
                                      and import_graph.room(a) != import_graph.room(b))


def test_the_page_names_every_room_and_shows_the_figure():
    text = PAGE.read_text(encoding="utf-8")
    rooms, _ = import_graph.room_graph()
    missing = sorted(import_graph.short(r) for r in rooms if f"`{import_graph.short(r)}`" not in text)
    assert not missing, f"docs/where-a-change-goes.md names no room {missing}: say what each one is for"
    assert "](img/import-graph.svg)" in text


def test_the_drawing_follows_the_floors():
    """Each room sits on its floor (``rank=same`` with the floor's name), the floors in order, top first."""
    text = import_graph.dot_text()
    spine = re.search(r"^\s*(floor\d+(?: -> floor\d+)*) \[style=invis\];", text, re.M).group(1)
    floors = [int(f.removeprefix("floor")) for f in spine.split(" -> ")]
    assert floors == sorted(floors, reverse=True)
    rooms, _ = import_graph.room_graph()
    for level in floors:
        row = re.search(rf"^\s*\{{ rank=same; floor{level}; (.*) \}}$", text, re.M).group(1)
        assert set(re.findall(r'"([^"]+)"', row)) == {import_graph.short(r) for r in rooms
                                                      if import_graph.LAYERS[r] == level}
