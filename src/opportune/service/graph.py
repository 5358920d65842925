"""A layered layout of a strategy's precedence graph, for the dashboard to draw as SVG.

Computed here, once per plan, from the minimal constraints of
:func:`opportune.formats.summary.summarize` (the Hasse diagram, as in the
paper's Figure 2): parts are placed in columns by longest path from the
parts with no requirement, edges spanning several columns pass through
invisible bend points, and the order within columns is improved by a few
barycentre sweeps to reduce crossings.  Plain coordinates; the browser only
draws them, so nothing is fetched and nothing is built.
"""

from __future__ import annotations

from opportune.planning.plan import Plan

DX = 120   # distance between columns
DY = 56    # distance between rows
MARGIN = 40
SWEEPS = 6


def layout(plan: Plan, minimal: list[list[str]], name: str = "") -> dict:
    """Coordinates of the parts and edges of one strategy (``minimal``: ``[before, after]`` pairs)."""
    ids = list(plan.part_ids)
    preds: dict[str, list[str]] = {p: [] for p in ids}
    for b, a in minimal:
        preds[a].append(b)
    layer: dict[str, int] = {}

    def depth(p: str) -> int:  # iterative longest path (plans may be deep)
        stack = [p]
        while stack:
            q = stack[-1]
            todo = [b for b in preds[q] if b not in layer]
            if todo:
                stack.extend(todo)
                continue
            stack.pop()
            layer[q] = 1 + max((layer[b] for b in preds[q]), default=-1)
        return layer[p]

    for p in ids:
        depth(p)
    n_layers = 1 + max(layer.values(), default=0)

    # Columns of real nodes and bend points ("dummies") for long edges.
    columns: list[list[str]] = [[] for _ in range(n_layers)]
    for p in ids:
        columns[layer[p]].append(p)
    up: dict[str, list[str]] = {p: [] for p in ids}      # neighbours one column to the left
    down: dict[str, list[str]] = {p: [] for p in ids}    # neighbours one column to the right
    chains: list[tuple[str, str, list[str]]] = []
    for b, a in minimal:
        chain = [b]
        for k in range(layer[b] + 1, layer[a]):
            d = f"\0{b}\0{a}\0{k}"
            columns[k].append(d)
            up[d], down[d] = [], []
            chain.append(d)
        chain.append(a)
        for x, y in zip(chain, chain[1:]):
            down[x].append(y)
            up[y].append(x)
        chains.append((b, a, chain))

    pos = {v: i for col in columns for i, v in enumerate(col)}
    for sweep in range(SWEEPS):
        order = range(1, n_layers) if sweep % 2 == 0 else range(n_layers - 2, -1, -1)
        for k in order:
            nbrs = up if sweep % 2 == 0 else down
            col = columns[k]

            def bary(v, nbrs=nbrs):
                ns = nbrs[v]
                return sum(pos[n] for n in ns) / len(ns) if ns else pos[v]

            col.sort(key=lambda v: (bary(v), pos[v]))
            for i, v in enumerate(col):
                pos[v] = i

    tallest = max((len(c) for c in columns), default=1)
    coords: dict[str, tuple[float, float]] = {}
    for k, col in enumerate(columns):
        offset = (tallest - len(col)) * DY / 2
        for i, v in enumerate(col):
            coords[v] = (MARGIN + k * DX, MARGIN + offset + i * DY)

    nodes = []
    for p in ids:
        part = plan.part(p)
        x, y = coords[p]
        nodes.append({"id": p, "name": part.name, "quantity": part.quantity, "layer": layer[p], "x": x, "y": y})
    edges = [{"from": b, "to": a, "points": [list(coords[v]) for v in chain]} for b, a, chain in chains]
    return {
        "strategy": name,
        "width": 2 * MARGIN + (n_layers - 1) * DX,
        "height": 2 * MARGIN + (tallest - 1) * DY,
        "nodes": nodes,
        "edges": edges,
    }


def layouts(plan: Plan, summary: dict) -> list[dict]:
    """One layout per strategy, from a plan's summary."""
    return [layout(plan, s["minimal"], s["name"]) for s in summary["strategies"]]
