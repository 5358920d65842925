"""A plan's summary: sizes and the minimal constraint set of each strategy."""

from __future__ import annotations

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
