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

    A plan written as ways has no strategies: ``ways`` counts each part's ways instead (parts not listed
    have one free way), with the parts of more than one.
    """
    if plan.ways is not None:
        several = [p for p, w in plan.ways.items() if len(w) > 1]
        return {"plan": plan.name, "parts": len(plan.parts), "units": plan.n_units, "strategies": [],
                "ways": {"listed": len(plan.ways), "in_all": sum(len(w) for w in plan.ways.values()),
                         "most": max((len(w) for w in plan.ways.values()), default=1),
                         "several": several}}
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


def ways_line(ways: dict) -> str:
    """The ``ways`` of a summary as ``check`` prints it.

    >>> ways_line({"listed": 2, "in_all": 3, "most": 2, "several": ["b"]})
    '3 ways for 2 listed parts (at most 2 a part); several ways: b'
    """
    shown = ", ".join(ways["several"][:20]) + (f", … ({len(ways['several']) - 20} more)"
                                               if len(ways["several"]) > 20 else "")
    return (f"{ways['in_all']} ways for {ways['listed']} listed parts (at most {ways['most']} a part)"
            + (f"; several ways: {shown}" if shown else ""))
