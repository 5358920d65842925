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

    ``problems`` is a list of :class:`opportune.formats.problems.Problem`;
    ``str(error)`` renders all of them, one per line.
    """

    def __init__(self, problems):
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems) or "invalid plan")


@dataclass(frozen=True)
class Part:
    """One kind of part, installed by one operation per unit.

    ``quantity`` identical, interchangeable units (e.g. 4 screws) share every
    constraint on the part.  ``acquire`` and ``install`` are handling costs (or
    durations) used as tie-breaks and in timing.  ``geometry`` is the part's shape in the physical
    bin, ``("box", (x, y, z))`` (edge lengths) or ``("cylinder", (radius, height))`` in metres, its real
    shape ``("convex", bodies)`` (each body a tuple of corners ``(x, y, z)``, the corners of a convex
    body: :mod:`opportune.formats.shapes`), or ``None`` for the bin's default shape.
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

    The mapping holds the constraints as declared (direct, possibly redundant);
    parts with no requirements may be absent from it.  ``weights`` maps a
    constraint ``(before, after)`` to the price of dropping it when the plan is
    over-constrained (:mod:`opportune.derive.relax`); constraints absent from it
    weigh 1, and only weights other than 1 are kept.
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
        """Declared constraints as ``(before, after)`` pairs, in declaration order."""
        return [(b, a) for a, bs in self.requires.items() for b in bs]

    def weight(self, before: str, after: str) -> float:
        """The weight of the constraint ``before -> after`` (1 unless the plan gives another)."""
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
class Plan:
    """Parts (in declaration order) and one or more strategies.

    Declaration order is meaningful: it is the final, deterministic tie-break
    of every decision made over the plan.  Build plans with
    :func:`opportune.formats.load_plan` (files) or :func:`opportune.make_plan` (code);
    both validate.

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

    def __post_init__(self):
        object.__setattr__(self, "simulation", MappingProxyType(dict(self.simulation)))
        object.__setattr__(self, "parts", tuple(self.parts))
        object.__setattr__(self, "strategies", tuple(self.strategies))
        object.__setattr__(self, "_index", {p.id: i for i, p in enumerate(self.parts)})

    def __reduce__(self):
        return (Plan, (self.name, self.parts, self.strategies, self.source, self.description,
                       _plain(self.simulation), self.andor))

    @property
    def part_ids(self) -> tuple[str, ...]:
        return tuple(p.id for p in self.parts)

    def index(self, part_id: str) -> int:
        """Declaration position of a part (0-based); ``KeyError`` if unknown."""
        return self._index[part_id]

    def part(self, part_id: str) -> Part:
        return self.parts[self._index[part_id]]

    def __contains__(self, part_id: object) -> bool:
        return part_id in self._index

    @property
    def n_units(self) -> int:
        """Total number of install operations (sum of quantities)."""
        return sum(p.quantity for p in self.parts)

    def index_pairs(self, strategy: Strategy) -> list[tuple[int, int]]:
        """A strategy's declared constraints as ``(before, after)`` part indices."""
        return [(self._index[b], self._index[a]) for b, a in strategy.pairs()]

    def to_networkx(self, strategy: int = 0):
        """One strategy as a ``networkx.DiGraph``: a node per part (its plan attributes as node data), an
        edge per cover relation (the fewest edges that give the order; O(constraints), computed once per
        plan).  networkx is optional (``pip install networkx``); the way back is
        :func:`opportune.formats.graphfiles.plan_from_networkx`."""
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
        """The plan in the file schema (round-trips through :func:`opportune.formats.plan_from_dict`)."""
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
