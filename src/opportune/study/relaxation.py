"""A smaller plan whose exact optimum is a lower bound on the plan's, state by state: a *relaxation*.

The information-relaxation bound of :mod:`opportune.study.bounds` needs a value function *V̂* that is a
*subsolution* of the plan's Bellman equation (``V̂ ≤ T V̂``): then every step of its inner problem costs
≥ 0, the inner problem is a shortest path, and *V̂* at the start is itself a lower bound.  This module
builds one that knows the plan's precedence: the exact optimum of a **relaxed plan** *R*, read through a
projection of the plan's states.

**The relaxed plan.**  Keep a set *S* of the plan's parts with every order between them that holds in
every strategy (the intersection of the strategies' orders: an order some strategy drops is not kept);
merge all other parts into a few *free* parts, one per (visibility weight, motion cost), with their
units as its quantity and no order at all.  The projection ``π`` maps a state of the plan (installed
units, buffer) to *R*'s: each kept part's units installed and buffered as they are, each free part's
as the sums over its members (units of one part go in in a fixed order, so a count says which).

**Why ``V*_R ∘ π`` is a subsolution of the plan's equation.**  The bin holds the same units in the
plan and in *R* (the free parts' units are the members' units), so a look has the same law, and its
projection is *R*'s look.  Every action the plan allows at a state *R* allows at its projection, with
the same cost and the projected next state: an installation the plan allows has every predecessor in
some strategy installed, so every predecessor *R* kept is installed; a free unit has none; the buffer
has the same capacity.  So the least over the plan's actions of cost plus ``V*_R ∘ π`` after it is at
least the least over *R*'s actions, look by look, and ``T (V*_R ∘ π) ≥ (T_R V*_R) ∘ π = V*_R ∘ π``.
The maximum of two subsolutions is one too (``T`` is monotone), so the bound's ``relaxed`` penalty
takes the larger of this and the motions still needed.

**Choosing S.**  The parts with the most order relations (most likely to block a look), as many as
keep *R*'s states within a budget, counted before *R*'s programme starts
(:func:`~opportune.policies.states.estimate_states`).  The programme is the compiled one where the
core takes *R* (a uniform bin, at most 64 units), else the Python one: the budget is set by which.

>>> from opportune import make_plan
>>> plan = make_plan(["a", "b", "c", "d"], {"b": ["a"], "c": ["b"]})
>>> r = relax_plan(plan, [0, 1, 2])
>>> [(p.id, p.quantity) for p in r.plan.parts], r.project((0b0011, 1, (0, 0, 0, 1)))
([('a', 1), ('b', 1), ('c', 1), ('free0', 1)], (3, 1, (0, 0, 0, 1)))
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from opportune.engine import OrderEngine
from opportune.formats.loader import make_plan
from opportune.planning.costs import TimeModel

__all__ = ["Relaxation", "common_order", "relax_plan", "ranked_parts"]


def common_order(engine: OrderEngine) -> list[int]:
    """Per part, the bit mask of the parts before it in **every** strategy (part indices).  O(parts² × strategies).

    >>> from opportune import make_plan
    >>> common_order(OrderEngine(make_plan(["a", "b", "c"], {"b": ["a"], "c": ["b"]})))
    [0, 1, 3]
    """
    plan = engine.plan
    n = len(plan.parts)
    firsts = engine.first
    lasts = [f + p.quantity - 1 for f, p in zip(firsts, plan.parts)]
    out = []
    for b in range(n):
        mask = 0
        for a in range(n):
            if a != b and all(poset.below[firsts[b]] >> lasts[a] & 1 for poset in engine.posets):
                mask |= 1 << a
        out.append(mask)
    return out


def ranked_parts(engine: OrderEngine) -> list[int]:
    """The plan's parts, most order relations (in every strategy) first; ties by declaration.  O(parts²).

    >>> from opportune import make_plan
    >>> ranked_parts(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]})))
    [2, 0, 1]
    """
    before = common_order(engine)
    n = len(before)
    after = [sum(1 for b in range(n) if before[b] >> a & 1) for a in range(n)]
    return sorted(range(n), key=lambda i: (-(before[i].bit_count() + after[i]), i))


@dataclass(frozen=True)
class Relaxation:
    """A relaxed plan and the projection of the plan's states onto it (see the module's docstring).

    ``kept[j]``: the plan's part that is *R*'s part *j*, for the kept parts; ``groups[g]``: the plan's
    parts merged into *R*'s free part ``len(kept) + g``; ``first``: *R*'s parts' first units;
    ``units``: the plan's parts' (first unit, bit mask of its units); ``weights``/``costs``: *R*'s bin
    weights and time model (the members' own)."""

    plan: object
    kept: tuple[int, ...]
    groups: tuple[tuple[int, ...], ...]
    first: tuple[int, ...]
    units: tuple[tuple[int, int], ...]
    weights: dict
    costs: TimeModel

    def project(self, key: tuple) -> tuple:
        """The relaxed plan's state key for the plan's ``(installed units, strategies, buffer)`` key.  O(parts)."""
        mask, _, buf = key
        units, first = self.units, self.first
        out, rbuf = 0, []
        for j, i in enumerate(self.kept):
            got = (mask >> units[i][0] & units[i][1]).bit_count()
            out |= ((1 << got) - 1) << first[j]
            rbuf.append(buf[i])
        for g, (members, group_units) in enumerate(zip(self.groups, self._group_units), len(self.kept)):
            out |= ((1 << (mask & group_units).bit_count()) - 1) << first[g]
            rbuf.append(sum(buf[i] for i in members))
        return out, 1, tuple(rbuf)

    @cached_property
    def _group_units(self) -> tuple[int, ...]:
        """Per free part, the bit mask of its members' units in the plan."""
        return tuple(sum(self.units[i][1] << self.units[i][0] for i in members) for members in self.groups)


def relax_plan(plan, kept, costs: TimeModel | None = None, weights: dict | None = None,
               engine: OrderEngine | None = None) -> Relaxation:
    """The relaxed plan keeping the parts ``kept`` (indices) and their common order; the other parts merged
    into free parts by (weight, motion cost).  ``costs``/``weights``: the plan's (default: the plan's
    time model, every weight 1).  O(parts²).

    >>> from opportune import make_plan
    >>> r = relax_plan(make_plan(["a", "b", "c"], {"c": ["a", "b"]}), [2])
    >>> [(p.id, p.quantity) for p in r.plan.parts], r.groups
    ([('c', 1), ('free0', 2)], ((0, 1),))
    """
    engine = engine or OrderEngine(plan)
    costs = costs or TimeModel.from_plan(plan)
    weights = weights or {}
    kept = tuple(sorted(set(kept)))
    before = common_order(engine)
    parts = plan.parts
    ids = [p.id for p in parts]
    groups: dict[tuple, list[int]] = {}
    for i, p in enumerate(parts):
        if i not in kept:
            groups.setdefault((float(weights.get(p.id, 1.0)), costs.move(p.id)), []).append(i)
    taken = set(ids)
    free_ids = []
    for g in range(len(groups)):
        name = f"free{g}"
        while name in taken:
            name += "_"
        free_ids.append(name)
    r_parts = [{"id": ids[i], "quantity": parts[i].quantity} for i in kept]
    r_parts += [{"id": fid, "quantity": sum(parts[i].quantity for i in members)}
                for fid, members in zip(free_ids, groups.values())]
    requires = {ids[b]: [ids[a] for a in kept if before[b] >> a & 1] for b in kept}
    relaxed = make_plan(r_parts, {b: a for b, a in requires.items() if a}, name=f"{plan.name} (relaxed)")
    r_weights = {ids[i]: float(weights.get(ids[i], 1.0)) for i in kept}
    r_weights.update({fid: w for fid, (w, _) in zip(free_ids, groups)})
    r_costs = TimeModel(motion=costs.motion, shake=costs.shake, look=costs.look,
                        parts={**{ids[i]: costs.move(ids[i]) for i in kept},
                               **{fid: m for fid, (_, m) in zip(free_ids, groups)}})
    r_first, at = [], 0
    for p in relaxed.parts:
        r_first.append(at)
        at += p.quantity
    units = tuple((f, (1 << p.quantity) - 1) for f, p in zip(engine.first, parts))
    return Relaxation(relaxed, kept, tuple(tuple(m) for m in groups.values()), tuple(r_first), units,
                      r_weights, r_costs)
