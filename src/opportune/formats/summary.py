"""A plan's summary: sizes and the minimal constraint set of each strategy."""

from __future__ import annotations

from fractions import Fraction

from opportune.engine.poset import Poset
from opportune.plan import Plan


def strategy_poset(plan: Plan, index: int) -> Poset:
    """The partial order of one strategy over the plan's parts (quantities ignored)."""
    return Poset.from_pairs(len(plan.parts), plan.index_pairs(plan.strategies[index]))


def summarize(plan: Plan) -> dict:
    """Sizes, declared / minimal / implied constraints per strategy.

    ``minimal`` is the transitive reduction (the Hasse diagram) as ``[before, after]``
    id pairs; ``implied`` is the size of the transitive closure.  Polynomial time;
    never enumerates sequences.
    """
    ids = plan.part_ids
    strategies = []
    for k, strategy in enumerate(plan.strategies):
        poset = strategy_poset(plan, k)
        strategies.append({
            "name": strategy.name,
            "declared": len(strategy.pairs()),
            "minimal": [[ids[a], ids[b]] for a, b in sorted(poset.cover_pairs(), key=lambda e: (e[1], e[0]))],
            "implied": sum(bin(m).count("1") for m in poset.below),
        })
    return {
        "plan": plan.name,
        "parts": len(plan.parts),
        "units": plan.n_units,
        "strategies": strategies,
    }



_BIG = 14_000  # bits: fewer than 4,215 decimal digits, which str() writes


class _DecimalFraction(Fraction):
    """A Fraction that writes itself as text however many digits its terms have."""

    def __str__(self):
        from opportune.engine.schedule import decimal

        if self.denominator == 1:
            return decimal(self.numerator)
        return f"{decimal(self.numerator)}/{decimal(self.denominator)}"


def printable_decision(decision):
    """The same decision, its counts and fractions ready to be written as text however many digits they have.

    Python refuses to write an int of more than 4,300 digits with ``str()`` (a guard against
    quadratic-time conversions of untrusted text, kept in force), and a plan of 2,000 unconstrained
    parts already has 2,000! (5,736 digits) sequences.  A decision's ``to_dict()`` and ``explain()``
    write counts with ``str()``: this gives them the large counts as decimal text (written by
    :func:`~opportune.engine.schedule.decimal`), so both work at any size and say exactly what they
    say of small counts.  The decision itself is returned when nothing in it is that large.
    (The lasting fix is for :mod:`opportune.policies.base` to write its counts with ``decimal``.)
    """
    from dataclasses import replace

    from opportune.engine.schedule import decimal

    def large(n) -> bool:
        return isinstance(n, int) and n.bit_length() >= _BIG

    if not any(large(c.options) or large(c.total) for c in decision.candidates) and \
            not any(large(v.numerator) or large(v.denominator) for _, v in decision.positions):
        return decision
    candidates = tuple(replace(c, options=decimal(c.options) if large(c.options) else c.options,
                               total=decimal(c.total) if large(c.total) else c.total) for c in decision.candidates)
    positions = tuple((p, _DecimalFraction(v.numerator, v.denominator)) for p, v in decision.positions)
    return replace(decision, candidates=candidates, positions=positions)
