"""Drawing plans as layered precedence diagrams (Graphviz), like the paper's Figure 2.

Only the minimal constraints (the transitive reduction) are drawn: an arc
``a -> b`` means *a* must be installed before *b*.
"""

from __future__ import annotations

from pathlib import Path

import graphviz

from opportune.formats.summary import strategy_poset
from opportune.plan import Plan


class DotMissing(RuntimeError):
    """Graphviz's ``dot`` program is not installed."""


def to_graph(plan: Plan, *, names: bool = False, dpi: int | None = None) -> graphviz.Digraph:
    """A Graphviz digraph with one cluster per strategy (a single strategy is drawn bare).

    ``names``: label each node with the part's name under its id (when it has one); ``dpi``: the
    resolution of raster output (PNG).
    """
    graph_attr = {"rankdir": "LR", "label": plan.name, "labelloc": "t",
                  "fontname": "Helvetica", "nodesep": "0.25", "ranksep": "0.45"}
    if dpi is not None:
        graph_attr["dpi"] = str(dpi)
    g = graphviz.Digraph(plan.name, graph_attr=graph_attr,
                         node_attr={"shape": "circle", "fontname": "Helvetica", "fontsize": "11",
                                    "width": "0.45", "fixedsize": "false", "margin": "0.02"},
                         edge_attr={"arrowsize": "0.6"})
    several = len(plan.strategies) > 1
    for k, strategy in enumerate(plan.strategies):
        poset = strategy_poset(plan, k)
        prefix = f"s{k}_" if several else ""
        target = graphviz.Digraph(name=f"cluster_{k}", graph_attr={"label": strategy.name, "style": "rounded"}) \
            if several else g
        for part in plan.parts:
            label = part.id + (f"\n{part.name}" if names and part.name and part.name != part.id else "") \
                + (f"\n×{part.quantity}" if part.quantity > 1 else "")
            tooltip = part.name or part.id
            target.node(prefix + part.id, label=label, tooltip=tooltip)
        for a, b in poset.cover_pairs():
            target.edge(prefix + plan.parts[a].id, prefix + plan.parts[b].id)
        if several:
            g.subgraph(target)
    return g


def to_dot(plan: Plan, *, names: bool = False) -> str:
    """The diagram as Graphviz ``dot`` source."""
    return to_graph(plan, names=names).source


def render(plan: Plan, path: str | Path, fmt: str | None = None, *, names: bool = False,
           dpi: int | None = None) -> Path:
    """Render the diagram to ``path`` (svg, png or pdf); raises :class:`DotMissing` without Graphviz."""
    path = Path(path)
    fmt = fmt or path.suffix.lstrip(".").lower()
    try:
        data = to_graph(plan, names=names, dpi=dpi).pipe(format=fmt)
    except graphviz.ExecutableNotFound:
        raise DotMissing("Graphviz's `dot` program is missing: install it (apt-get install graphviz, "
                         "or run `make setup`), or write dot source with --format dot") from None
    path.write_bytes(data)
    return path
