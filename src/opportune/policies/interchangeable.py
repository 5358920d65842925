"""Interchangeable parts merged: the optimum's state with parts that no strategy tells apart counted
as one part's units.

Two parts are *interchangeable* when, in every strategy, the parts before each are the same and the
parts after each are the same (so neither is before the other), and they cost the same to move and
are seen with the same weight.  Swapping them then maps every strategy's order, every cost and every
chance of a look onto itself, so the optimum's value at a state depends only on how many units of
such a group are installed and how many buffered, not on which: exactly what a part's ``quantity``
says of its own identical units.  :func:`merge_interchangeable` finds the groups (in every strategy:
a pair that one strategy tells apart is not merged) and builds the *merged* plan, one part per group
(named after its first part in declaration order, its quantity the group's units), whose programme
has fewer states; :meth:`Merged.key` maps a state of the plan onto it.  The decisions are still
taken on the plan's own states and looks, so they name the parts seen
(:class:`~opportune.policies.optimal.MergedOptimalSolver`).

Example: four screws declared as four parts, each before the cover, are one part of four units.

>>> from opportune import make_plan
>>> from opportune.engine import OrderEngine
>>> plan = make_plan(["s1", "s2", "s3", "s4", "cover"], {"cover": ["s1", "s2", "s3", "s4"]})
>>> merged = merge_interchangeable(OrderEngine(plan))
>>> [(p.id, p.quantity) for p in merged.engine.plan.parts]
[('s1', 4), ('cover', 1)]
>>> merged.key((0b0110, 1, (0, 0, 0, 1, 0)))      # s2, s3 installed, s4 buffered
(3, 1, (1, 0))
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, replace

from opportune.engine import OrderEngine
from opportune.planning.costs import TimeModel
from opportune.planning.plan import Plan, Strategy

__all__ = ["Merged", "interchangeable_groups", "merge_interchangeable"]

# The merged plan of an engine, per costs and weights (dropped with the engine): the look-ahead sizes
# the optimum on it before the programme builds it again.
_MERGED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def interchangeable_groups(engine: OrderEngine, costs: TimeModel | None = None,
                           weights: dict[str, float] | None = None, *, mask: int = 0, parts=None,
                           strategies=None) -> list[list[int]]:
    """The plan's parts (indices) grouped by interchangeability (see the module's docstring), each
    group in declaration order, the groups by their first part.  At a state: ``mask`` the installed
    units, left out of both sides (so parts told apart only by installed ones are grouped too),
    ``parts`` those with a unit left to group (default every part), ``strategies`` the strategies
    (indices) that must not tell them apart (default every one), as the frontier window's programme
    groups its parts (:func:`~opportune.policies.window.twin_groups`).  O(strategies × parts × units / 64).

    >>> from opportune import make_plan
    >>> interchangeable_groups(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]})))
    [[0, 1], [2]]
    >>> from opportune.formats.ways import ways_of_strategy
    >>> interchangeable_groups(OrderEngine(ways_of_strategy(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))))
    [[0], [1], [2]]
    """
    costs = costs or TimeModel()
    plan = engine.plan
    parts = range(len(plan.parts)) if parts is None else parts
    if plan.is_ways:    # no orders to compare: each part its own group (a part of a plan of ways is one unit)
        return [[i] for i in parts]
    posets = engine.posets if strategies is None else [engine.posets[s] for s in strategies]
    groups: dict[tuple, list[int]] = {}
    for i in parts:
        part = plan.parts[i]
        # the units before the part's next unit and after its last are whole parts' units (a part's
        # units are chained), so equal masks are equal sets of parts, and neither part is in the other's
        first, last = engine.next_unit(mask, i), engine.first[i] + part.quantity - 1
        sides = tuple((poset.below[first] & ~mask, poset.above[last] & ~mask) for poset in posets)
        weight = float((weights or {}).get(part.id, 1.0))
        groups.setdefault((sides, float(costs.move(part.id)), weight), []).append(i)
    return sorted(groups.values())


@dataclass(frozen=True)
class Merged:
    """A plan with its interchangeable parts merged: ``engine`` is the merged plan's, ``groups`` the
    plan's parts (indices) of each of its parts, ``original`` the plan's engine."""

    original: OrderEngine
    engine: OrderEngine
    groups: tuple[tuple[int, ...], ...]

    @property
    def reduced(self) -> bool:
        """Whether any parts were merged (else the merged plan is the plan)."""
        return len(self.groups) < len(self.original.plan.parts)

    def key(self, key: tuple) -> tuple:
        """The merged programme's key of the plan's ``(installed units, strategies, buffer counts)``:
        per group, its installed units as the merged part's first units, and its buffered units
        summed; the strategies the same.  O(parts)."""
        mask, cons, buf = key
        orig, merged = self.original, self.engine
        out, counts = 0, []
        for g, members in enumerate(self.groups):
            installed = 0
            buffered = 0
            for i in members:
                q = orig.plan.parts[i].quantity
                installed += ((mask >> orig.first[i]) & ((1 << q) - 1)).bit_count()
                buffered += buf[i]
            out |= ((1 << installed) - 1) << merged.first[g]
            counts.append(buffered)
        return out, cons, tuple(counts)

    def weights(self, weights: dict[str, float] | None) -> dict[str, float] | None:
        """The weights by the merged plan's parts (a group's parts weigh the same)."""
        if weights is None:
            return None
        plan = self.original.plan
        return {plan.parts[g[0]].id: weights[plan.parts[g[0]].id] for g in self.groups if plan.parts[g[0]].id in weights}


def merge_interchangeable(engine: OrderEngine, costs: TimeModel | None = None,
                          weights: dict[str, float] | None = None) -> Merged:
    """The plan of ``engine`` with its interchangeable parts merged (:class:`Merged`; its ``engine`` is
    ``engine`` itself where no two parts are interchangeable), cached per engine, costs and weights.
    O(strategies × parts × units / 64) the first time.

    >>> from opportune import make_plan
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"b": ["a"], "c": ["a"]}))
    >>> merge_interchangeable(engine).groups
    ((0,), (1, 2))
    """
    costs = costs or TimeModel()
    setting = (repr(sorted((weights or {}).items())), repr(costs))
    # the cache holds the groups and the merged plan's engine, never ``engine`` itself (a weak key
    # its own value refers to would never be dropped)
    cached = _MERGED.setdefault(engine, {})
    if setting not in cached:
        groups = tuple(tuple(g) for g in interchangeable_groups(engine, costs, weights))
        reduced = len(groups) < len(engine.plan.parts)
        cached[setting] = (groups, OrderEngine(_merged_plan(engine.plan, groups), memory_limit=None) if reduced else None)
    groups, merged = cached[setting]
    return Merged(engine, merged or engine, groups)


def _merged_plan(plan: Plan, groups: tuple[tuple[int, ...], ...]) -> Plan:
    """One part per group (its first part's, with the group's units), each strategy's constraints
    between the groups."""
    group_of = {i: g for g, members in enumerate(groups) for i in members}
    parts = tuple(replace(plan.parts[m[0]], quantity=sum(plan.parts[i].quantity for i in m)) for m in groups)
    strategies = []
    for strategy in plan.strategies:
        requires: dict[str, list[str]] = {}
        for b, a in plan.index_pairs(strategy):
            before, after = parts[group_of[b]].id, parts[group_of[a]].id
            if before not in requires.setdefault(after, []):
                requires[after].append(before)
        strategies.append(Strategy(strategy.name, {k: tuple(v) for k, v in requires.items()}))
    return Plan(plan.name, parts, tuple(strategies), source=plan.source)
