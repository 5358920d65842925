"""A plan's summary: sizes and the minimal constraint set of each strategy."""

from __future__ import annotations

from opportune.planning.orders import strategy_summaries
from opportune.planning.plan import Plan


def summarize(plan: Plan) -> dict:
    """Sizes, declared / minimal / implied constraints per strategy.

    ``minimal`` is the transitive reduction (the Hasse diagram) as ``[before, after]``
    id pairs; ``implied`` is the size of the transitive closure.  Polynomial time (:func:`strategy_summaries`:
    each strategy's constrained parts only); never enumerates sequences.

    >>> from opportune import make_plan
    >>> summarize(make_plan(["a", "b", "c"], {"b": ["a"], "c": ["a", "b"]}))["strategies"][0]["minimal"]
    [['a', 'b'], ['b', 'c']]
    """
    ids = plan.part_ids
    strategies = []
    for strategy, (covers, implied) in zip(plan.strategies, strategy_summaries(plan)):
        strategies.append({
            "name": strategy.name,
            "declared": len(strategy.pairs()),
            "minimal": [[ids[a], ids[b]] for a, b in sorted(covers, key=lambda e: (e[1], e[0]))],
            "implied": implied,
        })
    return {
        "plan": plan.name,
        "parts": len(plan.parts),
        "units": plan.n_units,
        "strategies": strategies,
    }
