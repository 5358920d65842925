"""The plan: parts and the strategies that order them.

A *plan* (section 3 of the paper) is a set of steps — here, installing parts —
with the minimum set of ordering constraints, possibly as several alternative
*strategies*.  Each strategy is a partial order, written as "for each part, the
parts that must be installed before it".  The admissible sequences of a plan are
the union, over its strategies, of the sequences that respect that strategy.

This module holds only the data model.  Reading files lives in
:mod:`opportune.formats`, checking in :mod:`opportune.formats.validate`, and
every question about admissible sequences in :mod:`opportune.engine`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from opportune.limits import (MAX_CONSTRAINTS, MAX_PARTS, MAX_QUANTITY, MAX_STRATEGIES, MAX_UNITS,  # noqa: F401
                              MAX_WEIGHT)


# Limits on every plan, whatever its format (YAML, JSON, .IN2, .alb), enforced by
# :func:`opportune.formats.validate.check_document` before anything is counted, so that the command
# line and the service refuse the same plans with the same message.  The engine's tables grow with
# the square of the number of units: 10,000 units (a 10,000-step chain) take about 0.5 GB.  The values
# are in the one table of limits, :mod:`opportune.limits` (imported above).
# A part's shape in the physical bin (``geometry``), in metres: every dimension within these bounds,
# so that a MuJoCo model built from any valid plan is neither degenerate nor larger than a cell.
MIN_DIMENSION = 0.005
MAX_DIMENSION = 0.5
#: Shapes a part may have, with the number of dimensions each takes: edge lengths, radius and height.
SHAPES = {"box": 3, "cylinder": 2}


class PlanError(ValueError):
    """A plan that cannot be used, with every problem found.

    ``problems`` is a list of :class:`opportune.formats.problems.Problem`; ``str(error)`` renders all
    of them, one per line.  Raised by :func:`~opportune.formats.loader.load_plan`,
    :func:`~opportune.formats.loader.make_plan` and the other plan builders.

    Parameters
    ----------
    problems : iterable of Problem
        Every problem found.

    Examples
    --------
    >>> from opportune import make_plan
    >>> try:
    ...     make_plan(["a", "a"])
    ... except PlanError as error:
    ...     print(len(error.problems), error.problems[0].message)
    1 duplicate part id 'a'
    """

    def __init__(self, problems):
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems) or "invalid plan")


@dataclass(frozen=True)
class Part:
    """One kind of part, installed by one operation per unit.

    Parameters
    ----------
    id : str
        The part's id, unique in its plan.
    name : str, optional
        A name for people.
    quantity : int, default 1
        Identical, interchangeable units (e.g. 4 screws); they share every constraint on the part.
    acquire, install : float, default 1.0
        Handling costs (or durations), used as tie-breaks and in timing.
    visibility : float, default 1.0
        The part's relative chance of being seen in a look of a weighted bin.
    geometry : tuple, optional
        The part's shape in the physical bin, ``("box", (x, y, z))`` (edge lengths) or
        ``("cylinder", (radius, height))`` in metres, its real shape ``("convex", bodies)`` (each body a
        tuple of corners ``(x, y, z)``, the corners of a convex body: :mod:`opportune.formats.shapes`), or
        ``None`` for the bin's default shape.

    Examples
    --------
    >>> screw = Part("s", name="screw", quantity=4)
    >>> screw.label, screw.cost
    ('s (screw)', 2.0)
    """

    id: str
    name: str | None = None
    quantity: int = 1
    acquire: float = 1.0
    install: float = 1.0
    visibility: float = 1.0
    geometry: tuple | None = None

    @property
    def label(self) -> str:
        return f"{self.id} ({self.name})" if self.name else self.id

    @property
    def cost(self) -> float:
        """Handling cost of one unit: acquire + install."""
        return self.acquire + self.install


@dataclass(frozen=True)
class Strategy:
    """One partial order over the parts: ``requires[x]`` must precede ``x``.

    Parameters
    ----------
    name : str
        The strategy's name, unique in its plan.
    requires : mapping of str to tuple of str, optional
        The constraints as declared (direct, possibly redundant): part → the parts installed before
        it.  Parts with no requirements may be absent.
    weights : mapping of (str, str) to float, optional
        A constraint ``(before, after)`` → the price of dropping it when the plan is
        over-constrained (:mod:`opportune.derive.relax`); absent constraints weigh 1, and only
        weights other than 1 are kept.

    Examples
    --------
    >>> s = Strategy("default", {"c": ("a", "b")}, weights={("a", "c"): 5})
    >>> s.pairs(), s.weight("a", "c"), s.weight("b", "c")
    ([('a', 'c'), ('b', 'c')], 5.0, 1.0)
    """

    name: str
    requires: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    weights: Mapping[tuple[str, str], float] = field(default_factory=dict)

    def __post_init__(self):
        frozen = {k: tuple(v) for k, v in self.requires.items()}
        object.__setattr__(self, "requires", MappingProxyType(frozen))
        weights = {(str(b), str(a)): float(w) for (b, a), w in dict(self.weights).items() if w != 1}
        object.__setattr__(self, "weights", MappingProxyType(weights))

    def __reduce__(self):  # read-only mappings do not pickle; rebuild from plain values
        return (Strategy, (self.name, dict(self.requires), dict(self.weights)))

    def pairs(self) -> list[tuple[str, str]]:
        """The declared constraints as ``(before, after)`` pairs, in declaration order.

        Returns
        -------
        list of (str, str)
            One pair per declared constraint.

        Examples
        --------
        >>> Strategy("s", {"c": ("a", "b")}).pairs()
        [('a', 'c'), ('b', 'c')]
        """
        return [(b, a) for a, bs in self.requires.items() for b in bs]

    def weight(self, before: str, after: str) -> float:
        """The weight of the constraint ``before -> after`` (1 unless the plan gives another).

        Parameters
        ----------
        before, after : str
            The constraint's parts.

        Returns
        -------
        float
            The price of dropping the constraint.

        Examples
        --------
        >>> Strategy("s", {"c": ("a",)}, weights={("a", "c"): 3}).weight("a", "c")
        3.0
        """
        return self.weights.get((before, after), 1.0)

    def __hash__(self):
        return hash((self.name, tuple(sorted(self.requires.items())), tuple(sorted(self.weights.items()))))

    def __eq__(self, other):
        return (
            isinstance(other, Strategy)
            and self.name == other.name
            and dict(self.requires) == dict(other.requires)
            and dict(self.weights) == dict(other.weights)
        )


@dataclass(frozen=True)
class Way:
    """One way a part can go in, in a plan written as ways (``ways:`` in a file, :attr:`Plan.ways`).

    The part may go in by this way when none of its ``blockers`` is installed yet and, for each set of
    ``needs``, at least one part of that set is already installed.  A plain precedence ``a before b`` is
    ``b``'s need ``{a}``; a support (``--gravity``: one of the parts ``b`` rests on) is one need of
    several parts.

    Parameters
    ----------
    blockers : frozenset of str
        Parts that must not be installed yet when the part goes in this way (it goes in before them).
    needs : tuple of frozenset of str
        Sets of parts, each of which must already have at least one part installed.
    name : str, optional
        What the way is, for people (a direction such as ``"-z"``).
    first : bool, default False
        The way admits the part only as the first part of all (every other part a blocker; written
        ``first: true``, not as a list of every other part).

    Examples
    --------
    >>> w = Way(frozenset({"c"}), (frozenset({"a", "b"}),), name="-z")
    >>> w.admits({"a"}), w.admits({"a", "c"}), w.admits(set())
    (True, False, False)
    """

    blockers: frozenset = frozenset()
    needs: tuple = ()
    name: str | None = None
    first: bool = False

    def __post_init__(self):
        object.__setattr__(self, "blockers", frozenset(self.blockers))
        object.__setattr__(self, "needs", tuple(frozenset(n) for n in self.needs))

    def admits(self, installed) -> bool:
        """Whether the part can go in this way with ``installed`` in (a set of part ids).

        Parameters
        ----------
        installed : set of str
            The parts installed so far.

        Returns
        -------
        bool
            No blocker installed, and every need met by an installed part.

        Examples
        --------
        >>> Way(frozenset(), (frozenset({"a"}),)).admits({"a"})
        True
        """
        if self.first and installed:
            return False
        return not (self.blockers & installed) and all(n & installed for n in self.needs)

    def to_dict(self) -> dict:
        """The way as a file writes it: ``name``, ``blockers``, ``after`` (needs of one part), ``needs``.

        Returns
        -------
        dict
            Ids sorted; empty fields left out.

        Examples
        --------
        >>> Way(frozenset({"c"}), (frozenset({"a"}), frozenset({"b", "d"}))).to_dict()
        {'blockers': ['c'], 'after': ['a'], 'needs': [['b', 'd']]}
        """
        doc: dict = {"name": self.name} if self.name else {}
        if self.first:
            doc["first"] = True
        if self.blockers:
            doc["blockers"] = sorted(self.blockers)
        after = sorted(next(iter(n)) for n in self.needs if len(n) == 1)
        several = [sorted(n) for n in self.needs if len(n) > 1]
        if after:
            doc["after"] = after
        if several:
            doc["needs"] = several
        return doc


@dataclass(frozen=True)
class Plan:
    """Parts (in declaration order) and one or more strategies.

    Declaration order is meaningful: it is the final, deterministic tie-break of every decision made
    over the plan.  Build plans with :func:`opportune.formats.loader.load_plan` (files) or
    :func:`opportune.formats.loader.make_plan` (code): both validate; this constructor does not.

    Parameters
    ----------
    name : str
        The plan's name.
    parts : tuple of Part
        The parts, in declaration order.
    strategies : tuple of Strategy
        The alternative partial orders; an admissible sequence respects at least one.
    source : str, optional
        The file the plan was read from.
    description : str, optional
        Text for people.
    simulation : mapping, optional
        The file's ``simulation`` settings (the cell's geometry and times).
    andor : AndOrGraph, optional
        The AND/OR graph the strategies were expanded from, kept for drawing.
    ways : mapping of str to tuple of Way, optional
        A plan written as ways (no strategies): each part's ways in (a part not listed has one way with
        no blockers and no needs).  A sequence is admissible iff each part, when installed, has a way
        that admits what is in (:meth:`Way.admits`).  A plan of one strategy is the special case where
        each part has one way whose needs are its required parts, one each
        (:func:`opportune.formats.ways.ways_of_strategy`).

    Examples
    --------
    >>> from opportune import make_plan
    >>> plan = make_plan(["a", "b", "c"], {"c": ["a", "b"]}, name="tiny")
    >>> plan.part_ids
    ('a', 'b', 'c')
    >>> plan.strategies[0].pairs()
    [('a', 'c'), ('b', 'c')]
    """

    name: str
    parts: tuple[Part, ...]
    strategies: tuple[Strategy, ...]
    source: str | None = None
    description: str | None = None
    simulation: Mapping = field(default_factory=dict, compare=False)
    # The AND/OR graph the strategies were expanded from (:mod:`opportune.formats.andor`), if any:
    # kept for drawing; every question about sequences uses the strategies, and to_dict writes them.
    andor: object | None = field(default=None, compare=False)
    ways: Mapping | None = None

    def __post_init__(self):
        object.__setattr__(self, "simulation", MappingProxyType(dict(self.simulation)))
        object.__setattr__(self, "parts", tuple(self.parts))
        object.__setattr__(self, "strategies", tuple(self.strategies))
        object.__setattr__(self, "_index", {p.id: i for i, p in enumerate(self.parts)})
        if self.ways is not None:
            object.__setattr__(self, "ways", MappingProxyType({k: tuple(v) for k, v in self.ways.items()}))

    def __reduce__(self):
        return (Plan, (self.name, self.parts, self.strategies, self.source, self.description,
                       _plain(self.simulation), self.andor, None if self.ways is None else dict(self.ways)))

    def __hash__(self):
        return hash((self.name, self.parts, self.strategies, self.source, self.description))

    @property
    def is_ways(self) -> bool:
        """Whether the plan is written as ways (:attr:`ways`), not as strategies."""
        return self.ways is not None

    @property
    def part_ids(self) -> tuple[str, ...]:
        return tuple(p.id for p in self.parts)

    def index(self, part_id: str) -> int:
        """The declaration position of a part (0-based).

        Parameters
        ----------
        part_id : str
            The part's id.

        Returns
        -------
        int
            Its position in :attr:`parts`.

        Raises
        ------
        KeyError
            If the plan has no such part.

        Examples
        --------
        >>> from opportune import make_plan
        >>> make_plan(["a", "b"]).index("b")
        1
        """
        return self._index[part_id]

    def part(self, part_id: str) -> Part:
        """The part of an id.

        Parameters
        ----------
        part_id : str
            The part's id.

        Returns
        -------
        Part
            The part.

        Raises
        ------
        KeyError
            If the plan has no such part.

        Examples
        --------
        >>> from opportune import make_plan
        >>> make_plan([{"id": "s", "quantity": 4}]).part("s").quantity
        4
        """
        return self.parts[self._index[part_id]]

    def __contains__(self, part_id: object) -> bool:
        return part_id in self._index

    @property
    def n_units(self) -> int:
        """Total number of install operations (sum of quantities)."""
        return sum(p.quantity for p in self.parts)

    def index_pairs(self, strategy: Strategy) -> list[tuple[int, int]]:
        """A strategy's declared constraints as ``(before, after)`` part indices.

        Parameters
        ----------
        strategy : Strategy
            One of the plan's strategies.

        Returns
        -------
        list of (int, int)
            One pair of declaration positions per declared constraint.

        Examples
        --------
        >>> from opportune import make_plan
        >>> plan = make_plan(["a", "b", "c"], {"c": ["a", "b"]})
        >>> plan.index_pairs(plan.strategies[0])
        [(0, 2), (1, 2)]
        """
        return [(self._index[b], self._index[a]) for b, a in strategy.pairs()]

    def to_networkx(self, strategy: int = 0):
        """One strategy as a ``networkx.DiGraph``.

        A node per part (its plan attributes as node data), an edge per cover relation (the fewest
        edges that give the order; O(constraints), computed once per plan).  The way back is
        :func:`opportune.formats.graphfiles.plan_from_networkx`.

        Parameters
        ----------
        strategy : int, default 0
            The strategy's position in :attr:`strategies`.

        Returns
        -------
        networkx.DiGraph
            The strategy's order, named after the plan.

        Raises
        ------
        ImportError
            If networkx is not installed (``pip install networkx``).

        Examples
        --------
        >>> from opportune import make_plan
        >>> graph = make_plan(["a", "b", "c"], {"b": ["a"], "c": ["a", "b"]}).to_networkx()
        >>> sorted(graph.edges())
        [('a', 'b'), ('b', 'c')]
        """
        try:
            import networkx as nx
        except ImportError:
            raise ImportError("Plan.to_networkx needs networkx: pip install networkx") from None
        from opportune.planning.orders import strategy_summaries

        g = nx.DiGraph(name=self.name)
        for part in self.parts:
            data = {k: getattr(part, k) for k in ("name", "quantity", "install", "acquire") if getattr(part, k) is not None}
            g.add_node(part.id, **data)
        ids = self.part_ids
        g.add_edges_from((ids[a], ids[b]) for a, b in strategy_summaries(self)[strategy][0])
        return g

    def to_dict(self) -> dict:
        """The plan in the file schema.

        Returns
        -------
        dict
            A document that round-trips through :func:`opportune.formats.loader.plan_from_dict`
            (every strategy written out, default values left out).

        Examples
        --------
        >>> from opportune import make_plan
        >>> make_plan(["a", "b"], {"b": ["a"]}, name="two").to_dict()
        {'name': 'two', 'parts': ['a', 'b'], 'strategies': [{'name': 'default', 'requires': {'b': ['a']}}]}
        """
        parts: list = []
        for p in self.parts:
            extra = {
                k: v
                for k, v in (("name", p.name), ("quantity", p.quantity), ("acquire", p.acquire), ("install", p.install),
                             ("visibility", p.visibility))
                if v is not None and v != Part.__dataclass_fields__[k].default
            }
            if p.geometry is not None:
                extra["geometry"] = geometry_dict(p.geometry)
            parts.append({"id": p.id, **extra} if extra else p.id)
        doc: dict = {"name": self.name}
        if self.description:
            doc["description"] = self.description
        doc["parts"] = parts
        if self.simulation:
            doc["simulation"] = _plain(self.simulation)
        if self.ways is not None:
            doc["ways"] = {pid: [w.to_dict() for w in ways] for pid, ways in self.ways.items()}
            return doc
        doc["strategies"] = [
            {"name": s.name, "requires": {k: [b if s.weight(b, k) == 1 else {"part": b, "weight": _number(s.weight(b, k))}
                                              for b in v] for k, v in s.requires.items()}}
            for s in self.strategies
        ]
        return doc


def geometry_dict(geometry: tuple) -> dict:
    """A part's geometry as written in a file: ``{"box": [x, y, z]}``."""
    shape, dims = geometry
    if shape == "convex":   # bodies of corners
        return {shape: [[[_number(c) for c in p] for p in body] for body in dims]}
    return {shape: [_number(d) for d in dims]}


def _number(value: float) -> int | float:
    """A weight as written in a file: 5, not 5.0."""
    return int(value) if float(value).is_integer() and abs(value) < 2**53 else value


def _plain(value):
    """Mappings (including read-only proxies) as plain dicts, for serialising."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value
