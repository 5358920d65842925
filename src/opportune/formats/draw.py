"""Drawing plans as layered precedence diagrams (Graphviz), like the paper's Figure 2.

Only the minimal constraints (the transitive reduction) are drawn: an arc
``a -> b`` means *a* must be installed before *b*.
"""

from __future__ import annotations

from pathlib import Path

import graphviz

from opportune.planning.orders import strategy_summaries
from opportune.planning.plan import Plan


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
        prefix = f"s{k}_" if several else ""
        target = graphviz.Digraph(name=f"cluster_{k}", graph_attr={"label": strategy.name, "style": "rounded"}) \
            if several else g
        for part in plan.parts:
            label = part.id + (f"\n{part.name}" if names and part.name and part.name != part.id else "") \
                + (f"\n×{part.quantity}" if part.quantity > 1 else "")
            tooltip = part.name or part.id
            target.node(prefix + part.id, label=label, tooltip=tooltip)
        for a, b in strategy_summaries(plan)[k][0]:  # the cover relations, computed once per plan
            target.edge(prefix + plan.parts[a].id, prefix + plan.parts[b].id)
        if several:
            g.subgraph(target)
    return g


def to_andor_graph(plan: Plan, *, names: bool = False, dpi: int | None = None) -> graphviz.Digraph:
    """The AND/OR graph of a plan read from ``assemblies`` (:mod:`opportune.formats.andor`), top down.

    Assemblies are boxes, parts circles; each way is a small grey node under its assembly (the OR:
    one of them is chosen), with solid arcs to the components it joins (the AND), dashed arcs to
    its ``then`` steps, and its ``before`` pairs written in its label.  O(size of the graph).
    Raises ``ValueError`` if the plan has no AND/OR graph.
    """
    graph = plan.andor
    if graph is None:
        raise ValueError(f"plan '{plan.name}' has no AND/OR graph (no `assemblies`)")
    graph_attr = {"rankdir": "TB", "label": plan.name, "labelloc": "t", "fontname": "Helvetica",
                  "nodesep": "0.25", "ranksep": "0.4"}
    if dpi is not None:
        graph_attr["dpi"] = str(dpi)
    g = graphviz.Digraph(plan.name, graph_attr=graph_attr,
                         node_attr={"fontname": "Helvetica", "fontsize": "11", "margin": "0.04"},
                         edge_attr={"arrowsize": "0.6"})
    node: dict[str, str] = {}
    for i, part in enumerate(plan.parts):
        node[part.id] = f"p{i}"
        label = part.id + (f"\n{part.name}" if names and part.name and part.name != part.id else "") \
            + (f"\n×{part.quantity}" if part.quantity > 1 else "")
        g.node(f"p{i}", label=label, shape="circle", tooltip=part.name or part.id)
    for i, (name, _) in enumerate(graph.assemblies):
        node[name] = f"a{i}"
        g.node(f"a{i}", label=name, shape="box", style="bold" if name == graph.product else "",
               tooltip=("product" if name == graph.product else "subassembly"))
    for i, (name, ways) in enumerate(graph.assemblies):
        for j, way in enumerate(ways):
            w = f"w{i}_{j}"
            label = way.name + "".join(f"\n{x} → {y}" for x, y in way.before)
            g.node(w, label=label, shape="box", style="rounded,filled", fillcolor="#e8e8e8", fontsize="9",
                   height="0.2", tooltip=f"way '{way.name}' of {name}")
            g.edge(node[name], w, arrowhead="none" if len(ways) == 1 else "normal")
            for c in way.join:
                g.edge(w, node[c])
            for t in way.then:
                g.edge(w, node[t], style="dashed")
    return g


def _drawing(plan: Plan, names: bool, dpi: int | None, andor: bool) -> graphviz.Digraph:
    return to_andor_graph(plan, names=names, dpi=dpi) if andor else to_graph(plan, names=names, dpi=dpi)


def to_dot(plan: Plan, *, names: bool = False, andor: bool = False) -> str:
    """The diagram as Graphviz ``dot`` source (``andor``: the AND/OR graph, :func:`to_andor_graph`)."""
    return _drawing(plan, names, None, andor).source


def render(plan: Plan, path: str | Path, fmt: str | None = None, *, names: bool = False,
           dpi: int | None = None, andor: bool = False) -> Path:
    """Render the diagram to ``path`` (svg, png or pdf); raises :class:`DotMissing` without Graphviz."""
    path = Path(path)
    fmt = fmt or path.suffix.lstrip(".").lower()
    try:
        data = _drawing(plan, names, dpi, andor).pipe(format=fmt)
    except graphviz.ExecutableNotFound:
        raise DotMissing("Graphviz's `dot` program is missing: install it (apt-get install graphviz, "
                         "or run `make setup`), or write dot source with --format dot") from None
    path.write_bytes(data)
    return path
