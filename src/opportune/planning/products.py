"""Several products at once: one joint plan for N fixtures fed from one bin.

A cell may build N products (N copies of one, or different ones) on N fixtures, from
one bin that holds all their parts.  The products are independent, so the admissible
sequences of the whole cell are the *interleavings* of the fixtures' admissible
sequences: the linear extensions of the disjoint union of the per-fixture plans.  If
fixture ``i`` has ``n_i`` steps left and ``e_i`` admissible completions, the cell has

    multinomial(n_1, ..., n_N) * e_1 * ... * e_N

completions, and installing part ``x`` on fixture ``i`` keeps ``n_i * e_i(P_i - x) *
prod_{j != i} e_j`` of them (up to the common multinomial factor): the paper's rule
"keep the most options" generalises unchanged to "keep the most options across all
products in progress".

So a multi-product cell is one ordinary :class:`~opportune.planning.plan.Plan` whose parts are
the *units* ``x@1 … x@N`` (part ``x`` on fixture 1 … N), with one strategy per
combination of the fixtures' strategies; the order engine and every policy work on it
as on any plan.  The one new thing is the bin: it holds part *kinds* (``x``), and a
seen ``x`` can be any unit ``x@i`` still needed (:mod:`opportune.cell`).

Limits (refused with a :class:`ProductsError` naming what to change):
:data:`MAX_PRODUCTS` fixtures; the joint plan within the plan limits of
:mod:`opportune.planning.plan` (parts, units, :data:`~opportune.planning.plan.MAX_STRATEGIES` strategy
combinations, constraints).  Exact decisions count a union of at most
:data:`~opportune.engine.schedule.MAX_STRATEGIES_EXACT` (12) strategies, so a joint plan of
more combinations is decided within a decision budget (estimating what it cannot count):
:func:`opportune.study.simulate_products.check_countable` and the service refuse it otherwise.

>>> from opportune import make_plan
>>> plan = make_plan(["a", "b"], {"b": ["a"]}, name="pair")
>>> joint = several_products(plan, 2)
>>> joint.part_ids
('a@1', 'b@1', 'a@2', 'b@2')
>>> split_unit("b@2")
('b', 2)
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

from opportune.planning.plan import (
    MAX_CONSTRAINTS,
    MAX_PARTS,
    MAX_STRATEGIES,
    MAX_UNITS,
    Part,
    Plan,
    Strategy,
    Way,
    _plain,
)
from opportune.limits import MAX_PRODUCTS  # noqa: F401 (their home: the one table of limits)

__all__ = ["MAX_PRODUCTS", "ProductsError", "check_products", "combine_products", "fixtures_of", "kind_of",
           "kinds_in_bin", "several_products", "split_unit", "unit_id"]

#: Fixtures (products in progress at once) a cell may have.
SEPARATOR = "@"


class ProductsError(ValueError):
    """A multi-product request that cannot be honoured (too many products, too large a joint plan…).

    Examples
    --------
    >>> split_unit("bolt")
    Traceback (most recent call last):
        ...
    opportune.planning.products.ProductsError: 'bolt' is not a part of a multi-product plan (expected KIND@FIXTURE, e.g. 'x@1')
    """


def unit_id(kind: str, fixture: int) -> str:
    """The joint plan's id of part ``kind`` on ``fixture``.

    Parameters
    ----------
    kind : str
        The part's id in its own plan.
    fixture : int
        The fixture, from 1.

    Returns
    -------
    str
        ``"KIND@FIXTURE"``.

    Examples
    --------
    >>> unit_id("co", 3)
    'co@3'
    """
    return f"{kind}{SEPARATOR}{fixture}"


def split_unit(unit: str) -> tuple[str, int]:
    """``(part kind, fixture)`` of a joint plan's part id; the inverse of :func:`unit_id`.

    The fixture is the number after the *last* ``@`` (part ids may contain ``@`` themselves).
    O(len(unit)).

    Parameters
    ----------
    unit : str
        A joint plan's part id.

    Returns
    -------
    tuple of (str, int)
        The part kind and the fixture.

    Raises
    ------
    ProductsError
        For an id without a fixture number.

    Examples
    --------
    >>> split_unit("bolt@home@12")
    ('bolt@home', 12)
    """
    kind, sep, number = unit.rpartition(SEPARATOR)
    if not sep or not kind or not number.isdigit() or number.startswith("0"):
        raise ProductsError(f"'{unit}' is not a part of a multi-product plan (expected KIND@FIXTURE, e.g. 'x@1')")
    return kind, int(number)


def kind_of(unit: str) -> str:
    """The part kind of a joint plan's part id (``"x@2"`` → ``"x"``)."""
    return split_unit(unit)[0]


def fixtures_of(plan: Plan) -> int:
    """How many fixtures a joint plan has (the largest fixture number of its parts).

    Raises :class:`ProductsError` if a part id is not ``KIND@FIXTURE``.  O(parts).

    >>> from opportune import make_plan
    >>> fixtures_of(several_products(make_plan(["a"]), 3))
    3
    """
    return max(split_unit(p)[1] for p in plan.part_ids)


def check_products(n, *, what: str = "products") -> int:
    """``n`` as a number of products, or a :class:`ProductsError` saying what is allowed.

    >>> check_products(3)
    3
    """
    if isinstance(n, bool) or not isinstance(n, int):
        if isinstance(n, float) and n.is_integer():
            n = int(n)
        else:
            raise ProductsError(f"{what} must be a whole number from 1 to {MAX_PRODUCTS}, not {n!r}")
    if not 1 <= n <= MAX_PRODUCTS:
        raise ProductsError(f"{what} must be from 1 to {MAX_PRODUCTS} (fixtures in one cell), not {n}")
    return n


def several_products(plan: Plan, n: int, *, serial: bool = False) -> Plan:
    """The joint plan of ``n`` copies of ``plan`` built at once on ``n`` fixtures from one bin.

    Each part ``x`` becomes ``x@1 … x@n`` (same name, quantity and costs); each strategy of the joint
    plan is one choice of strategy per fixture (``s^n`` of them for ``s`` strategies).
    O(n * (parts + constraints) * strategy combinations).

    Parameters
    ----------
    plan : Plan
        One product's plan.
    n : int
        The number of products (fixtures), 1 to :data:`MAX_PRODUCTS`.
    serial : bool, default False
        Every product is finished before the next one starts (the "one product after another" cell:
        each fixture's first steps require the previous fixture's last ones).

    Returns
    -------
    Plan
        The joint plan.

    Raises
    ------
    ProductsError
        For ``n`` outside 1..:data:`MAX_PRODUCTS` or a joint plan beyond the plan limits.

    Examples
    --------
    >>> from opportune import make_plan
    >>> joint = several_products(make_plan(["a", "b"], {"b": ["a"]}), 2, serial=True)
    >>> joint.strategies[0].pairs()
    [('a@1', 'b@1'), ('a@2', 'b@2'), ('b@1', 'a@2')]
    """
    n = check_products(n)
    return combine_products([plan] * n, serial=serial, name=f"{plan.name} ×{n}" if n > 1 else plan.name)


def combine_products(plans: Sequence[Plan], *, serial: bool = False, name: str | None = None) -> Plan:
    """The joint plan of different products, ``plans[i]`` on fixture ``i + 1``, fed from one bin.

    Parts with the same id in two plans are the same *kind*: one unit in the bin can go to either
    fixture.  A kind's visibility in the bin is its first plan's.  O(total parts and constraints
    times strategy combinations).

    Parameters
    ----------
    plans : sequence of Plan
        The products, one per fixture.
    serial : bool, default False
        As in :func:`several_products`.
    name : str, optional
        The joint plan's name.

    Returns
    -------
    Plan
        The joint plan.

    Raises
    ------
    ProductsError
        For no product, more than :data:`MAX_PRODUCTS`, a value that is not a plan, or a joint plan
        beyond the plan limits (strategy combinations, parts, units).

    Examples
    --------
    >>> from opportune import make_plan
    >>> joint = combine_products([make_plan(["a", "b"]), make_plan(["b", "c"])])
    >>> joint.part_ids
    ('a@1', 'b@1', 'b@2', 'c@2')
    """
    plans = list(plans)
    if not plans:
        raise ProductsError("give at least one product")
    check_products(len(plans), what="the number of products")
    if not all(isinstance(p, Plan) for p in plans):
        raise ProductsError("every product must be a Plan (load it with opportune.load_plan)")
    combos = math.prod(len(p.strategies) for p in plans)
    if combos > MAX_STRATEGIES:
        raise ProductsError(
            f"{len(plans)} products give {combos:,} combinations of their strategies (one per fixture), beyond the "
            f"limit of {MAX_STRATEGIES}: use fewer products, or plans with fewer strategies")
    n_parts = sum(len(p.parts) for p in plans)
    n_units = sum(p.n_units for p in plans)
    if n_parts > MAX_PARTS or n_units > MAX_UNITS:
        raise ProductsError(f"{len(plans)} products have {n_units:,} units in all, beyond the plan limit of "
                            f"{MAX_UNITS:,} (parts: {MAX_PARTS:,}): use fewer products")
    per_combo = sum(len(s.pairs()) for p in plans for s in p.strategies)
    if combos * per_combo > MAX_CONSTRAINTS:
        raise ProductsError(f"the joint plan would declare about {combos * per_combo:,} constraints, beyond the "
                            f"limit of {MAX_CONSTRAINTS:,}: use fewer products")
    ways = _joint_ways(plans, serial)
    visibility: dict[str, float] = {}
    parts: list[Part] = []
    for i, plan in enumerate(plans, 1):
        for p in plan.parts:
            v = visibility.setdefault(p.id, p.visibility)
            parts.append(Part(unit_id(p.id, i), p.name, p.quantity, p.acquire, p.install, v))
    strategies = []
    for choice in itertools.product(*(p.strategies for p in plans)):
        requires: dict[str, list[str]] = {}
        weights: dict[tuple[str, str], float] = {}
        for i, s in enumerate(choice, 1):
            for after, befores in s.requires.items():
                requires.setdefault(unit_id(after, i), []).extend(unit_id(b, i) for b in befores)
            for (b, a), w in s.weights.items():
                weights[(unit_id(b, i), unit_id(a, i))] = w
        if serial:
            for i in range(1, len(plans)):
                last = _ends(plans[i - 1], choice[i - 1], last=True)
                for first in _ends(plans[i], choice[i], last=False):
                    requires.setdefault(unit_id(first, i + 1), []).extend(unit_id(b, i) for b in last)
        label = (choice[0].name if len(plans) == 1 else
                 " + ".join(unit_id(s.name, i) for i, s in enumerate(choice, 1)))
        strategies.append(Strategy(label, requires, weights))
    kinds = list(dict.fromkeys(p.id for plan in plans for p in plan.parts))
    desc = (f"{len(plans)} products on {len(plans)} fixtures from one bin"
            + (", one after another" if serial else "") + f" (part kinds: {', '.join(kinds[:12])}"
            + ("…" if len(kinds) > 12 else "") + ")")
    if name is None:
        same = len(plans) > 1 and all(p is plans[0] for p in plans)
        name = f"{plans[0].name} ×{len(plans)}" if same else " + ".join(p.name for p in plans)
    simulation = _plain(plans[0].simulation)
    costs = dict(simulation.get("costs") or {})
    if costs.get("parts"):   # per-part motion costs apply to every unit of the kind
        costs["parts"] = {unit_id(k, i): v for i in range(1, len(plans) + 1) for k, v in costs["parts"].items()}
        simulation["costs"] = costs
    return Plan(name, tuple(parts), () if ways is not None else tuple(strategies), source=plans[0].source,
                description=desc, simulation=simulation, ways=ways)


def _joint_ways(plans: list[Plan], serial: bool) -> dict | None:
    """The joint plan's ways where the products are written as ways (each unit's ways, renamed to its
    product's units: a product's parts block and need only its own), else None."""
    written = [p.ways is not None for p in plans]
    if not any(written):
        return None
    if not all(written) or serial:
        raise ProductsError("products written as ways are combined only with others written as ways, side by "
                            "side (not one after another)")
    named = sum(len(w.blockers) + sum(len(n) for n in w.needs) for p in plans for ws in p.ways.values() for w in ws)
    if named > MAX_CONSTRAINTS:
        raise ProductsError(f"the joint plan's ways would name {named:,} parts in all, beyond the limit of "
                            f"{MAX_CONSTRAINTS:,}: use fewer products")
    ways: dict = {}
    for i, plan in enumerate(plans, 1):
        for pid, listed in plan.ways.items():
            # a way in first: before every other part of its own product (its blockers, written out); one
            # first with needs admits nothing (its needs are never met first) and is left out
            ways[unit_id(pid, i)] = tuple(
                Way(frozenset(unit_id(b, i) for b in (set(plan.part_ids) - {pid} if w.first else w.blockers)),
                    tuple(frozenset(unit_id(q, i) for q in need) for need in w.needs), name=w.name)
                for w in listed if not (w.first and w.needs))
    return ways


def _ends(plan: Plan, strategy: Strategy, *, last: bool) -> list[str]:
    """The minimal (``last=False``) or maximal (``last=True``) parts of one strategy, in declaration order."""
    if last:
        required = {b for bs in strategy.requires.values() for b in bs}
        return [p for p in plan.part_ids if p not in required]
    return [p for p in plan.part_ids if not strategy.requires.get(p)]


def kinds_in_bin(plan: Plan) -> list[str]:
    """The bin of a joint plan at the start: one entry per unit, by part kind (repeats for quantities
    and for fixtures sharing a kind).  O(units).

    >>> from opportune import make_plan
    >>> kinds_in_bin(several_products(make_plan(["a", "b"]), 2))
    ['a', 'b', 'a', 'b']
    """
    return [kind_of(p.id) for p in plan.parts for _ in range(p.quantity)]

