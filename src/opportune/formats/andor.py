"""AND/OR assembly plans: every way to build a product from subassemblies (Homem de Mello & Sanderson).

A plan file may describe its product as an AND/OR graph instead of partial orders::

    parts: [housing, seal, bearing, shaft, key, impeller, cover, {id: bolt, quantity: 4}]
    assemblies:                 # the first one listed is the product (or give `product: NAME`)
      pump:                     # OR: each list item is one alternative *way* to make `pump`
        - name: rotor-first
          join: [casing, rotor] # AND: the components this way joins (parts or assemblies)
          then: [cover, bolt]   # steps (parts) that follow all of the components
          before: [[cover, bolt]]
        - name: in-place
          join: [block]
          then: [shaft, key, impeller, seal, cover, bolt]
          before: [[shaft, key], [key, impeller], [impeller, cover], [seal, cover], [cover, bolt]]
      rotor: ...                # (the whole of it: example:pump, examples/pump.yaml)

Semantics, precisely.  Each name is a part (a leaf: one installation step, or ``quantity``
identical ones) or an assembly (a key of ``assemblies``).  A *way* of an assembly has

* ``join``: its components, parts or assemblies.  Each component assembly is built by one of its
  own ways; the steps of different components are unordered relative to each other: a sequence of
  the way interleaves the components' sequences freely;
* ``before`` (optional): pairs ``[X, Y]``, both components or both ``then`` steps of this way:
  every step of ``X`` precedes every step of ``Y``;
* ``then`` (optional): parts installed after *every* step of the components (a fastening step, a
  cover), unordered among themselves unless ``before`` orders them.

A part named in a way of a subassembly is installed as that subassembly is built (there is no
separate "join" operation: the plan's steps are the parts' installations).  Every way of an
assembly makes the same set of parts, and a way uses each part once (directly or through its
components).  The product makes every declared part.

A *strategy* is one choice of way for every assembly reachable from the product through the
chosen ways; its partial order is the union of the constraints above over the chosen ways.  The
plan's admissible sequences are the union over the strategies (as for any plan), so every
command works unchanged.  Identical partial orders are kept once, and a strategy whose
sequences are all admitted by another one is dropped (the union is unchanged).  Strategies are
named by the choices made where there was a choice, e.g. ``pump=rotor-first,rotor=bearing-first``
(``default`` if there was none).

Limits: the choices multiply, so the number of *combinations* (one way per reachable assembly)
is counted first, in time linear in the graph's size and without listing them, and a graph with
more than :data:`MAX_COMBINATIONS` combinations, or whose combinations times parts exceed
:data:`MAX_EXPANSION`, is refused with the counts; after expansion at most
:data:`~opportune.planning.plan.MAX_STRATEGIES` distinct partial orders are accepted.  The engine counts
exactly up to 12 strategies (inclusion–exclusion), and estimates beyond.

>>> from opportune.formats import plan_from_andor
>>> plan = plan_from_andor(["a", "b", "c"], {"p": [{"join": ["a", "b"], "then": ["c"]},
...                                                  {"join": ["a"], "then": ["b", "c"], "before": [["c", "b"]]}]})
>>> [s.name for s in plan.strategies]
['p=1', 'p=2']
>>> sorted(sequences(plan.andor))
[('a', 'b', 'c'), ('a', 'c', 'b'), ('b', 'a', 'c')]
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from itertools import permutations
from typing import TYPE_CHECKING, Any

from opportune.formats.problems import Problem, did_you_mean
from opportune.planning.plan import MAX_STRATEGIES, PlanError, Strategy

if TYPE_CHECKING:
    from opportune.formats.documents import Document

MAX_COMBINATIONS = 4_096      # combinations of ways expanded (one way per reachable assembly)
MAX_EXPANSION = 500_000       # combinations × parts: the work of the expansion (about 1 s)
MAX_SEQUENCES = 200_000       # sequences the brute-force enumerator lists (tests, tiny graphs)


@dataclass(frozen=True)
class Way:
    """One way to make an assembly: ``join`` its components, then the ``then`` steps.

    Parameters
    ----------
    name : str
        The way's name, unique among its assembly's ways.
    join : tuple of str
        The components joined: parts or other assemblies.
    then : tuple of str, default ()
        Parts installed after the join.
    before : tuple of (str, str), default ()
        Extra ``(X, Y)`` pairs: every step of X precedes every step of Y (both components, or both
        ``then`` parts, of this way).

    Examples
    --------
    >>> way = Way("x", ("a", "b"), ("c",))
    >>> expand(AndOrGraph("p", ("a", "b", "c"), (("p", (way,)),)))[0].pairs()
    [('a', 'c'), ('b', 'c')]
    """

    name: str
    join: tuple[str, ...]
    then: tuple[str, ...] = ()
    before: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class AndOrGraph:
    """An AND/OR graph: the product, the parts (declaration order) and each assembly's ways.

    Build one from a plan file (``plan.andor``) or with
    :func:`~opportune.formats.loader.plan_from_andor`; this constructor does not check it
    (:func:`check_assemblies` does).

    Parameters
    ----------
    product : str
        The assembly that is the product.
    parts : tuple of str
        The parts, in declaration order.
    assemblies : tuple of (str, tuple of Way)
        ``(name, ways)`` in declaration order (plain tuples: the graph pickles and hashes).

    Examples
    --------
    >>> g = AndOrGraph("p", ("a", "b", "c"), (("p", (Way("1", ("q", "c")), Way("2", ("a", "r")))),
    ...     ("q", (Way("1", ("a", "b")), Way("2", ("b", "a")))), ("r", (Way("1", ("b", "c")),))))
    >>> g.reachable(), g.combinations()
    (['p', 'q', 'r'], 3)
    """

    product: str
    parts: tuple[str, ...]
    assemblies: tuple[tuple[str, tuple[Way, ...]], ...]

    def ways(self, name: str) -> tuple[Way, ...]:
        """The ways of an assembly.

        Parameters
        ----------
        name : str
            The assembly.

        Returns
        -------
        tuple of Way
            Its ways, in declaration order.

        Raises
        ------
        KeyError
            If ``name`` is not an assembly.

        Examples
        --------
        >>> AndOrGraph("p", ("a", "b"), (("p", (Way("1", ("a", "b")),)),)).ways("p")
        (Way(name='1', join=('a', 'b'), then=(), before=()),)
        """
        return self._table()[name]

    def is_assembly(self, name: str) -> bool:
        """Whether ``name`` is one of the graph's assemblies (not a part).

        Parameters
        ----------
        name : str
            A part or assembly name.

        Returns
        -------
        bool
            True for an assembly.

        Examples
        --------
        >>> g = AndOrGraph("p", ("a", "b"), (("p", (Way("1", ("a", "b")),)),))
        >>> g.is_assembly("p"), g.is_assembly("a")
        (True, False)
        """
        return name in self._table()

    def _table(self) -> dict[str, tuple[Way, ...]]:
        table = self.__dict__.get("_ways")
        if table is None:
            table = dict(self.assemblies)
            object.__setattr__(self, "_ways", table)
        return table

    def reachable(self) -> list[str]:
        """Assemblies reachable from the product through any way, product first (depth-first).  O(graph).

        Returns
        -------
        list of str
            The assemblies' names.

        Examples
        --------
        >>> g = AndOrGraph("p", ("a", "b", "c"), (("p", (Way("1", ("q", "c")),)), ("q", (Way("1", ("a", "b")),)),
        ...     ("unused", (Way("1", ("a", "c")),))))
        >>> g.reachable()
        ['p', 'q']
        """
        seen, order, stack = {self.product}, [], [self.product]
        while stack:
            a = stack.pop()
            order.append(a)
            for way in reversed(self.ways(a)):
                for c in reversed(way.join):
                    if self.is_assembly(c) and c not in seen:
                        seen.add(c)
                        stack.append(c)
        return order

    def combinations(self) -> int:
        """The number of strategies before deduplication: one way for each reachable assembly.

        ``n(a) = Σ over the ways of a of Π over its component assemblies c of n(c)``, computed
        bottom-up without listing anything: O(size of the graph) big-integer operations.

        Returns
        -------
        int
            The combinations of ways.

        Examples
        --------
        >>> g = AndOrGraph("p", ("a", "b", "c"), (("p", (Way("1", ("q", "c")), Way("2", ("a", "r")))),
        ...     ("q", (Way("1", ("a", "b")), Way("2", ("b", "a")))), ("r", (Way("1", ("b", "c")),))))
        >>> g.combinations()
        3
        """
        return _combination_counts(self)[self.product]

    def to_dict(self) -> dict:
        """The graph in the file schema.

        Returns
        -------
        dict
            ``product`` and ``assemblies`` (name → list of ways), as a plan file writes them.

        Examples
        --------
        >>> AndOrGraph("p", ("a", "b"), (("p", (Way("1", ("a", "b")),)),)).to_dict()
        {'product': 'p', 'assemblies': {'p': [{'name': '1', 'join': ['a', 'b']}]}}
        """
        out: dict = {}
        for name, ways in self.assemblies:
            items = []
            for w in ways:
                item: dict = {"name": w.name, "join": list(w.join)}
                if w.then:
                    item["then"] = list(w.then)
                if w.before:
                    item["before"] = [list(p) for p in w.before]
                items.append(item)
            out[name] = items
        return {"product": self.product, "assemblies": out}


# ---------------------------------------------------------------- reading and checking


def check_assemblies(data: dict, doc: Document, part_ids: list[str]) -> tuple[list[Strategy], AndOrGraph | None,
                                                                                 list[Problem]]:
    """Read and check the ``assemblies`` of a schema-valid document; expand them into strategies.

    Polynomial before the expansion (O(ways × components × parts / 64)); the expansion is refused
    above :data:`MAX_COMBINATIONS` combinations (or :data:`MAX_EXPANSION` combinations × parts).
    :func:`opportune.formats.validate.check_document` calls it for a document with ``assemblies``.

    Parameters
    ----------
    data : dict
        The plan document.
    doc : Document
        The document it was read from (for the problems' lines).
    part_ids : list of str
        The plan's part ids.

    Returns
    -------
    tuple of (list of Strategy, AndOrGraph or None, list of Problem)
        The strategies (empty if there is any error), the graph, and every problem found.

    Examples
    --------
    >>> from opportune.formats.documents import Document
    >>> data = {"parts": ["a", "b", "c"], "assemblies": {"p": [{"join": ["a", "b", "b"]}]}}
    >>> strategies, graph, problems = check_assemblies(data, Document(data, {}, "f.yaml"), ["a", "b", "c"])
    >>> [str(p) for p in problems]  # doctest: +NORMALIZE_WHITESPACE
    ["f.yaml: error: way '1' of 'p' uses part 'b' twice (through b and b) — a way uses each part once: remove it
      from one of its components", "f.yaml: error: part 'c' is not used by the product 'p' — add it to a way of an
      assembly, or remove it from `parts`"]
    """
    file = doc.file

    def at(*path) -> int | None:
        return doc.line(("assemblies",) + path)

    problems: list[Problem] = []
    if "requires" in data or "strategies" in data:
        key = "requires" if "requires" in data else "strategies"
        problems.append(Problem(f"the plan has both `{key}` and `assemblies`",
                                "give the order either as partial orders (`requires` or `strategies`) or as an "
                                "AND/OR graph (`assemblies`), not both", file=file, line=doc.line((key,)),
                                code="conflict"))
        return [], None, problems
    parts = set(part_ids)
    raw = data["assemblies"]
    names = [str(k) for k in raw]
    for key in raw:
        if str(key) in parts:
            problems.append(Problem(f"'{key}' is both a part and an assembly", "give the assembly another name",
                                    file=file, line=at(key), parts=(str(key),), code="andor-name"))
    known = parts | set(names)
    choices = sorted(known)

    def unknown(name: str, what: str, line) -> Problem:
        return Problem(f"unknown name '{name}' {what}",
                       did_you_mean(name, choices)
                       + "declare it under `parts` or as an assembly under `assemblies`",
                       file=file, line=line, parts=(name,), code="unknown-part")

    product = data.get("product")
    if product is None:
        product = names[0]
    product = str(product)
    if product not in names:
        problems.append(Problem(f"the product '{product}' is not an assembly",
                                f"name one of the assemblies ({', '.join(names[:5])}) as `product`, or remove "
                                "`product` (the first assembly listed is the product)", file=file,
                                line=doc.line(("product",)), code="andor-product"))
    table: list[tuple[str, tuple[Way, ...]]] = []
    for key, items in raw.items():
        a = str(key)
        ways, seen = [], {}
        for i, item in enumerate(items):
            wname = str(item.get("name", i + 1))
            line = at(key, i)
            if wname in seen:
                problems.append(Problem(f"assembly '{a}' has two ways named '{wname}'", "give each way its own name",
                                        file=file, line=line, code="andor-way"))
            seen[wname] = i
            ways.append(_read_way(item, wname, a, parts, known, lambda *path: at(key, i, *path), unknown, file,
                                  problems))
        table.append((a, tuple(ways)))
    if problems:
        return [], None, problems
    graph = AndOrGraph(product, tuple(part_ids), tuple(table))
    cycle_problems = _assembly_cycles(graph, doc)
    if cycle_problems:
        return [], None, cycle_problems
    problems += _content_problems(graph, doc)
    if any(p.severity == "error" for p in problems):
        return [], None, problems
    try:
        strategies = expand(graph)
    except PlanError as exc:
        for p in exc.problems:
            problems.append(Problem(p.message, p.hint, file=file, line=at(product), code=p.code))
        return [], None, problems
    return strategies, graph, problems


def _read_way(item: dict, wname: str, a: str, parts: set[str], known: set[str], at_way, unknown, file: str | None,
              problems: list[Problem]) -> Way:
    """Way ``wname`` of assembly ``a`` as a :class:`Way` (:func:`check_assemblies`); what is wrong with it is
    appended to ``problems``.  ``at_way(*path)``: the line of a path inside the way; ``unknown(name, what,
    line)``: the problem of a name that is neither a part nor an assembly."""
    join = tuple(str(c) for c in item["join"])
    then = tuple(str(t) for t in item.get("then") or ())
    before = tuple((str(x), str(y)) for x, y in item.get("before") or ())
    where = f"in way '{wname}' of '{a}'"
    for j, c in enumerate(join):
        if c not in known:
            problems.append(unknown(c, where, at_way("join", j)))
    for j, t in enumerate(then):
        if t not in known:
            problems.append(unknown(t, where, at_way("then", j)))
        elif t not in parts:
            problems.append(Problem(f"`then` of way '{wname}' of '{a}' names the assembly '{t}'; `then` "
                                    "lists parts", f"put '{t}' under `join`", file=file,
                                    line=at_way("then", j), parts=(t,), code="andor-then"))
    if len(join) + len(then) < 2:
        problems.append(Problem(f"way '{wname}' of '{a}' makes it from a single "
                                f"{'component' if join else 'step'}: a way joins two or more components, "
                                "or adds a `then` step", "add the other components, or use the component "
                                "itself instead of this assembly", file=file, line=at_way(), code="andor-way"))
    members = set(join)
    for k, (x, y) in enumerate(before):
        bline = at_way("before", k)
        if x == y:
            problems.append(Problem(f"way '{wname}' of '{a}': `before` pair [{x}, {y}] orders '{x}' before "
                                    "itself", "remove the pair", file=file, line=bline, code="andor-before"))
        elif not ({x, y} <= members or {x, y} <= set(then)):
            problems.append(Problem(
                f"way '{wname}' of '{a}': `before` pair [{x}, {y}] must name two components (`join`) or "
                "two `then` steps of this way",
                "`then` steps already follow every component; order parts inside a component in that "
                "component's own ways", file=file, line=bline, parts=(x, y), code="andor-before"))
    cycle = _cycle(before)
    if cycle:
        problems.append(Problem(f"way '{wname}' of '{a}': its `before` pairs make a cycle: "
                                + " -> ".join(cycle), "remove one of the pairs", file=file,
                                line=at_way("before"), parts=tuple(cycle[:-1]), code="cycle"))
    return Way(wname, join, then, before)


_WAY_KEYS = frozenset({"name", "description", "join", "then", "before"})


def fits_schema(name: Any, ways: Any, is_part_id) -> bool:
    """True only if one entry of ``assemblies`` certainly satisfies the plan schema (a linear walk):
    the validator, far slower a value, then judges only the others.  ``is_part_id``: the id test.

    >>> fits_schema("p", [{"join": ["a", "b"], "then": ["c"]}], str.isidentifier)
    True
    >>> fits_schema("p", [{"join": ["a", "b"], "bfore": []}], str.isidentifier)
    False
    """
    if not (is_part_id(name) and isinstance(ways, list) and ways):
        return False
    for w in ways:
        if not (isinstance(w, dict) and _WAY_KEYS.issuperset(w) and isinstance(w.get("join"), list) and w["join"]):
            return False
        if "name" in w and not (isinstance(w["name"], str) and w["name"]):
            return False
        if "description" in w and not isinstance(w["description"], str):
            return False
        if not all(is_part_id(c) for c in w["join"]):
            return False
        if "then" in w and not (isinstance(w["then"], list) and all(is_part_id(t) for t in w["then"])):
            return False
        if "before" in w and not (isinstance(w["before"], list) and all(
                isinstance(pair, list) and len(pair) == 2 and all(is_part_id(x) for x in pair)
                for pair in w["before"])):
            return False
    return True


def _cycle(pairs: Iterable[tuple[str, str]]) -> list[str] | None:
    """A cycle of a small directed graph given as pairs (``[x, …, x]``), or None.  O(pairs) per node."""
    succ: dict[str, list[str]] = {}
    for x, y in pairs:
        if x != y:
            succ.setdefault(x, []).append(y)
    state: dict[str, int] = {}
    for root in list(succ):
        if root in state:
            continue
        path, stack = [], [(root, iter(succ.get(root, ())))]
        state[root] = 1
        path.append(root)
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                stack.pop()
                path.pop()
                state[node] = 2
            elif state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            elif nxt not in state:
                state[nxt] = 1
                path.append(nxt)
                stack.append((nxt, iter(succ.get(nxt, ()))))
    return None


def _assembly_cycles(graph: AndOrGraph, doc: Document) -> list[Problem]:
    """An assembly that contains itself (through the components of any of its ways), one problem per cycle."""
    pairs = [(a, c) for a, ways in graph.assemblies for w in ways for c in w.join if graph.is_assembly(c)]
    out, found = [], set()
    for a, c in pairs:
        if a == c and a not in found:  # joins itself directly
            found.add(a)
            i = next(i for i, w in enumerate(graph.ways(a)) if a in w.join)
            out.append(Problem(f"an assembly contains itself: way '{graph.ways(a)[i].name}' of '{a}' joins '{a}'",
                               f"remove '{a}' from the way's `join`", file=doc.file,
                               line=doc.line(("assemblies", a, i)), parts=(a,), code="cycle"))
    while len(out) < 10:  # the first ten cycles; each search is O(pairs)
        cycle = _cycle([p for p in pairs if not ({p[0], p[1]} & found)])
        if not cycle:
            return out
        found |= set(cycle)
        a, c = cycle[0], cycle[1]
        i = next(i for i, w in enumerate(graph.ways(a)) if c in w.join)
        out.append(Problem("an assembly contains itself: " + " -> ".join(cycle)
                           + " (each arrow: the assembly on the left has a way that joins the one on the right)",
                           f"remove '{c}' from way '{graph.ways(a)[i].name}' of '{a}', or break the cycle elsewhere",
                           file=doc.file, line=doc.line(("assemblies", a, i)), parts=tuple(cycle[:-1]),
                           code="cycle"))
    return out


def _topological(graph: AndOrGraph) -> list[str]:
    """Every assembly, components before the assemblies that join them (the graph has no cycle).  O(graph)."""
    order, state = [], {}
    for root, _ in graph.assemblies:
        if root in state:
            continue
        stack = [(root, iter([c for w in graph.ways(root) for c in w.join if graph.is_assembly(c)]))]
        state[root] = 1
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                stack.pop()
                state[node] = 2
                order.append(node)
            elif nxt not in state:
                state[nxt] = 1
                stack.append((nxt, iter([c for w in graph.ways(nxt) for c in w.join if graph.is_assembly(c)])))
    return order


def _content_problems(graph: AndOrGraph, doc: Document) -> list[Problem]:
    """Parts used twice in a way, ways of one assembly that make different parts, unreachable names.

    Part sets are bitmasks over the parts: O(ways × components × parts / 64).
    """
    file = doc.file
    bit = {p: 1 << i for i, p in enumerate(graph.parts)}
    content: dict[str, int] = dict(bit)
    out: list[Problem] = []

    def names(mask: int) -> list[str]:
        return [p for p in graph.parts if mask & bit[p]]

    def shown(mask: int) -> str:
        ids = names(mask)
        return ", ".join(ids[:8]) + (f", … ({len(ids) - 8} more)" if len(ids) > 8 else "")

    for a in _topological(graph):
        first = None
        for i, w in enumerate(graph.ways(a)):
            line = doc.line(("assemblies", a, i))
            used, twice, via = 0, 0, {}
            for c in w.join + w.then:
                m = content.get(c, 0)
                overlap = used & m
                if overlap:
                    twice |= overlap
                    for p in names(overlap):
                        via.setdefault(p, [x for x in w.join + w.then if content.get(x, 0) & bit[p]])
                used |= m
            if twice:
                for p in names(twice)[:5]:
                    out.append(Problem(f"way '{w.name}' of '{a}' uses part '{p}' twice (through "
                                       f"{' and '.join(via[p])})",
                                       "a way uses each part once: remove it from one of its components",
                                       file=file, line=line, parts=(p,), code="andor-twice"))
            if first is None:
                first = (w, used)
                content[a] = used
            elif used != first[1]:
                more, fewer = used & ~first[1], first[1] & ~used
                diff = "; ".join(s for s in (f"it adds {shown(more)}" if more else "",
                                             f"it lacks {shown(fewer)}" if fewer else "") if s)
                out.append(Problem(f"way '{w.name}' of '{a}' makes other parts than way '{first[0].name}': {diff}",
                                   "every way of an assembly makes the same parts", file=file, line=line,
                                   parts=tuple(names(more | fewer)[:8]), code="andor-parts"))
    product = content.get(graph.product, 0)
    all_parts = (1 << len(graph.parts)) - 1
    for p in names(all_parts & ~product):
        i = graph.parts.index(p)
        out.append(Problem(f"part '{p}' is not used by the product '{graph.product}'",
                           "add it to a way of an assembly, or remove it from `parts`", file=file,
                           line=doc.line(("parts", i)), parts=(p,), code="andor-unreachable"))
    reachable = set(graph.reachable())
    for a, _ in graph.assemblies:
        if a not in reachable:
            out.append(Problem(f"assembly '{a}' is not used by the product '{graph.product}'",
                               "join it in a way of the product (or of one of its subassemblies), or remove it",
                               file=file, line=doc.line(("assemblies", a)), severity="warning",
                               code="andor-unreachable"))
    return out


# ---------------------------------------------------------------- expansion


def _combination_counts(graph: AndOrGraph, cap: int | None = None) -> dict[str, int]:
    """Combinations per assembly (bottom-up); each capped at ``cap + 1`` so the numbers stay small."""
    n: dict[str, int] = {}
    for a in _topological(graph):
        total = 0
        for w in graph.ways(a):
            prod = 1
            for c in w.join:
                if graph.is_assembly(c):
                    prod *= n[c]
                    if cap is not None:
                        prod = min(prod, cap + 1)
            total += prod
        n[a] = min(total, cap + 1) if cap is not None else total
    return n


def expand(graph: AndOrGraph) -> list[Strategy]:
    """The strategies of an AND/OR graph: one partial order per combination of ways, deduplicated.

    Each strategy's ``requires`` holds its minimal constraints (the transitive reduction).  Identical
    partial orders are kept once (the first combination's name), then a strategy whose sequences
    another admits too is dropped.  Time O(combinations × (steps + constraints) × parts / 64).

    Parameters
    ----------
    graph : AndOrGraph
        A checked graph.

    Returns
    -------
    list of Strategy
        The distinct strategies.

    Raises
    ------
    PlanError
        Above :data:`MAX_COMBINATIONS` combinations (counted first, without listing them),
        :data:`MAX_EXPANSION` combinations × parts, or
        :data:`~opportune.planning.plan.MAX_STRATEGIES` distinct partial orders.

    Examples
    --------
    >>> g = AndOrGraph("p", ("a", "b", "c"), (("p", (Way("x", ("a", "b"), ("c",)),)),))
    >>> [(s.name, dict(s.requires)) for s in expand(g)]
    [('default', {'c': ('a', 'b')})]
    """
    counts = _combination_counts(graph, cap=MAX_COMBINATIONS)
    total = counts[graph.product]
    n_parts = len(graph.parts)
    if total > MAX_COMBINATIONS or total * n_parts > MAX_EXPANSION:
        reach = set(graph.reachable())
        several = [(a, len(ws)) for a, ws in graph.assemblies if a in reach and len(ws) > 1]
        listed = ", ".join(f"{a}: {k} ways" for a, k in several[:6]) + (f", … ({len(several) - 6} more assemblies "
                                                                          "with a choice)" if len(several) > 6 else "")
        exact = _combination_counts(graph, cap=10**12)[graph.product]  # capped: the message stays cheap
        size = f"{exact:,}" if exact <= 10**12 else "more than 10^12"
        limit = (f"at most {MAX_COMBINATIONS:,} are expanded" if total > MAX_COMBINATIONS else
                 f"with {n_parts:,} parts at most {MAX_EXPANSION // max(1, n_parts):,} are expanded "
                 f"({MAX_EXPANSION:,} combinations × parts)")
        raise PlanError([Problem(f"the AND/OR graph has {size} combinations of ways ({listed}); {limit}",
                                 "remove ways that add nothing, or split the product into plans for its "
                                 "subassemblies", code="limit")])
    part_index = {p: i for i, p in enumerate(graph.parts)}
    topo = _topological(graph)
    kept: dict[tuple, tuple[str, list[list[int]]]] = {}
    for chosen in _choices(graph):
        below, preds = _closure(graph, chosen, topo, part_index)
        key = tuple(below)
        if key not in kept:
            kept[key] = (_strategy_name(graph, chosen), preds)
            if len(kept) > MAX_STRATEGIES:
                raise PlanError([Problem(
                    f"the AND/OR graph's {total:,} combinations of ways make more than {MAX_STRATEGIES} different "
                    f"partial orders; at most {MAX_STRATEGIES} strategies are accepted",
                    "remove ways that add little, or split the product into plans for its subassemblies",
                    code="limit")])
    closures = list(kept)
    covers = [_covers(c, kept[c][1]) for c in closures]
    strategies = []
    for i, ci in enumerate(closures):
        # i admits a subset of j's sequences if j's minimal constraints all hold in i
        if any(j != i and all(ci[a] >> b & 1 for b, a in covers[j]) for j in range(len(closures))):
            continue
        req: dict[str, list[str]] = {}
        for b, a in sorted(covers[i], key=lambda pair: (pair[1], pair[0])):
            req.setdefault(graph.parts[a], []).append(graph.parts[b])
        strategies.append(Strategy(kept[ci][0], req))
    return strategies


def _choices(graph: AndOrGraph) -> Iterator[dict[str, int]]:
    """Every combination: a way index for each assembly reachable through the ways chosen.  Iterative."""
    work: list[tuple[dict[str, int], list[str]]] = [({}, [graph.product])]
    while work:
        chosen, pending = work.pop()
        while pending and (pending[-1] in chosen or len(graph.ways(pending[-1])) == 1):
            a = pending.pop()
            if a not in chosen:  # one way: no branching, no copy
                chosen[a] = 0
                pending.extend(c for c in graph.ways(a)[0].join if graph.is_assembly(c))
        if not pending:
            yield chosen
            continue
        a = pending.pop()
        ways = graph.ways(a)
        for i in reversed(range(len(ways))):
            work.append(({**chosen, a: i}, pending + [c for c in ways[i].join if graph.is_assembly(c)]))


def _strategy_name(graph: AndOrGraph, chosen: Mapping[str, int]) -> str:
    made = [f"{a}={ways[chosen[a]].name}" for a, ways in graph.assemblies if a in chosen and len(ways) > 1]
    return ",".join(made) or "default"


def _edges(graph: AndOrGraph, chosen: Mapping[str, int], topo: list[str], index: dict[str, int]) -> dict[int, int]:
    """The constraints of one combination: for each part (by index), the bitmask of its direct predecessors.

    Built through the first and last steps of each component (its sources and sinks, as bitmasks),
    not every pair of steps: O(ways × components × parts / 64) operations.
    """
    sources: dict[str, int] = {}
    sinks: dict[str, int] = {}
    preds: dict[int, int] = {}
    for a in topo:
        if a not in chosen:
            continue
        w = graph.ways(a)[chosen[a]]

        def src(c):
            return sources[c] if c in sources else 1 << index[c]

        def snk(c):
            return sinks[c] if c in sinks else 1 << index[c]

        after_some = {y for _, y in w.before}
        before_some = {x for x, _ in w.before}
        for x, y in w.before:
            m = snk(x)
            rest = src(y)
            while rest:
                low = rest & -rest
                t = low.bit_length() - 1
                preds[t] = preds.get(t, 0) | m
                rest ^= low
        last = 0  # the components' maximal steps
        first = 0
        for c in w.join:
            if c not in before_some:
                last |= snk(c)
            if c not in after_some:
                first |= src(c)
        for t in w.then:
            preds[index[t]] = preds.get(index[t], 0) | last
        sources[a] = first
        if w.then:
            sinks[a] = sum(1 << index[t] for t in w.then if t not in before_some)
        else:
            sinks[a] = last
    return preds


def _closure(graph: AndOrGraph, chosen: Mapping[str, int], topo: list[str],
             index: dict[str, int]) -> tuple[list[int], dict[int, int]]:
    """For each part (by index), the bitmask of the parts that precede it in this combination, and the
    bitmasks of the direct predecessors.  An iterative depth-first walk: O(constraints) mask operations."""
    preds = _edges(graph, chosen, topo, index)
    n = len(graph.parts)
    below: list[int | None] = [None] * n
    for root in range(n):
        if below[root] is not None:
            continue
        stack = [root]
        while stack:
            i = stack[-1]
            todo = []
            rest = preds.get(i, 0)
            m = rest
            while rest:
                low = rest & -rest
                b = low.bit_length() - 1
                if below[b] is None:
                    todo.append(b)
                else:
                    m |= below[b]
                rest ^= low
            if todo:  # acyclic (checked): each part is entered once its predecessors are done
                stack.extend(todo)
                continue
            stack.pop()
            below[i] = m
    return below, preds  # type: ignore[return-value]


def _covers(below: tuple[int, ...], preds: dict[int, int]) -> list[tuple[int, int]]:
    """Minimal constraints ``(before, after)`` by index: the maximal elements of each part's down-set.

    Those are the down-set less everything below a direct predecessor: O(constraints) mask operations.
    """
    out = []
    for a, m in enumerate(below):
        lower = 0
        rest = preds.get(a, 0)
        while rest:
            low = rest & -rest
            lower |= below[low.bit_length() - 1]
            rest ^= low
        cover = m & ~lower
        while cover:
            low = cover & -cover
            out.append((low.bit_length() - 1, a))
            cover ^= low
    return out


# ---------------------------------------------------------------- Python API


def sequences(graph: AndOrGraph, limit: int = MAX_SEQUENCES) -> set[tuple[str, ...]]:
    """Every sequence of parts the AND/OR graph admits, by brute force (a reference for tests).

    Recursive, straight from the definition: an assembly's sequences are the union over its ways;
    a way's are the interleavings of one sequence of each component that respect ``before``, each
    followed by an order of the ``then`` steps that respects ``before``.  Exponential.

    Parameters
    ----------
    graph : AndOrGraph
        The graph.
    limit : int, default MAX_SEQUENCES
        The most sequences listed for one assembly.

    Returns
    -------
    set of tuple of str
        The admissible sequences.

    Raises
    ------
    ValueError
        Past ``limit`` sequences for one assembly.

    Examples
    --------
    >>> g = AndOrGraph("p", ("a", "b", "c"), (("p", (Way("x", ("a", "b"), ("c",)),)),))
    >>> sorted(sequences(g))
    [('a', 'b', 'c'), ('b', 'a', 'c')]
    >>> sequences(g, limit=1)
    Traceback (most recent call last):
        ...
    ValueError: more than 1 sequences for 'p'
    """
    from itertools import product as cartesian

    memo: dict[str, set[tuple[str, ...]]] = {}

    def of(name: str) -> set[tuple[str, ...]]:
        if not graph.is_assembly(name):
            return {(name,)}
        if name not in memo:
            out: set[tuple[str, ...]] = set()
            for w in graph.ways(name):
                tails = [t for t in permutations(w.then) if _respects(t, w.then, w.before, lambda s: {s})]
                for parts in cartesian(*[sorted(of(c)) for c in w.join]):
                    owner = {p: c for c, seq in zip(w.join, parts) for p in seq}
                    for merged in _interleavings(list(parts)):
                        if not _respects(merged, w.join, w.before, lambda c, owner=owner: set(_of_owner(owner, c))):
                            continue
                        for t in tails:
                            out.add(merged + t)
                            if len(out) > limit:
                                raise ValueError(f"more than {limit:,} sequences for '{name}'")
            memo[name] = out
        return memo[name]

    return of(graph.product)


def _of_owner(owner: dict[str, str], component: str) -> list[str]:
    return [p for p, c in owner.items() if c == component]


def _respects(seq: tuple[str, ...], members, pairs, steps_of) -> bool:
    """True if, for each pair (x, y) of ``members``, every step of x comes before every step of y in ``seq``."""
    pos = {p: k for k, p in enumerate(seq)}
    for x, y in pairs:
        if x in members and y in members:
            xs = [pos[s] for s in steps_of(x) if s in pos]
            ys = [pos[s] for s in steps_of(y) if s in pos]
            if xs and ys and max(xs) > min(ys):
                return False
    return True


def _interleavings(seqs: list[tuple[str, ...]]) -> Iterator[tuple[str, ...]]:
    """Every merge of the sequences keeping each one's order."""
    seqs = [s for s in seqs if s]
    if not seqs:
        yield ()
        return
    for i, s in enumerate(seqs):
        rest = seqs[:i] + [s[1:]] + seqs[i + 1:]
        for tail in _interleavings(rest):
            yield (s[0],) + tail
