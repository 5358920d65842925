"""The exact plan of an assembly written as ways: each part's ways in, exact however many alternatives.

Under the motion model a part can go in on the set ``S`` built iff for some direction ``d`` no part of
``S`` is among its blockers ``B_d(p)`` and, for each support it needs (``--gravity``: a part it rests on;
``--connected``: a part it touches), some part of that support's set is in ``S`` (or, where the first
part is spared, ``S`` is empty).  That is a plan written as ways (:mod:`opportune.formats.ways`), word
for word: a way per minimal direction (:func:`~opportune.derive.plan.options`) with the part's supports
as its needs, and a way ``first`` (``first: true``: only as the first part of all) where the part may go in first.  The base
and the process constraints are needs of every way (``a`` before ``b``: each way of ``b`` needs ``a``).

Identical instances (the manifest's ``quantities``) are kept in the manifest's order (each after the one
before) and written as their part's units, ``bolt#1``, ``bolt#2`` (:func:`as_units`), each with its own
ways: the count is of distinct sequences of part ids, and a look names the part.

``opportune derive`` writes this form where the union of partial orders
(:func:`~opportune.derive.plan.exact_strategies`) needs more than a plan holds; it is as exact, and its
size is the blocking relation's (parts × directions), not the number of direction choices.
"""

from __future__ import annotations

from typing import Sequence

from opportune.derive.blocking import Blocking
from opportune.derive.plan import Conditions, DeriveError, _lock_message, _no_sequence_message, alternatives, locked
from opportune.derive.plan import options as minimal_directions
from opportune.formats.ways import SEARCH_WORK
from opportune.planning.plan import Part, Way
from opportune.planning.ways import Undecided, WaysTable, unit_id

__all__ = ["exact_ways", "as_units"]


def exact_ways(block: Blocking, conditions: Conditions | None = None,
               before: Sequence[tuple[str, str]] = ()) -> dict[str, tuple[Way, ...]]:
    """Each part's ways in, admitting exactly the feasible sequences (see the module).

    Parameters
    ----------
    block : Blocking
        The blocking relation.
    conditions : Conditions, optional
        The supports each part needs and the base.
    before : sequence of (str, str)
        Orders every sequence keeps (the base's, the process constraints, identical parts').

    Returns
    -------
    dict of str to tuple of Way
        Every part's ways (named by direction, or ``first``).

    Raises
    ------
    DeriveError
        No feasible sequence (the parts that lock each other named, or the supports no order meets).

    Examples
    --------
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0), "-x": (-1, 0, 0)},
    ...              {"a": {"+x": frozenset("b"), "-x": frozenset("b")}, "b": {"+x": frozenset(), "-x": frozenset()}},
    ...              0, 0)
    >>> [(w.name, sorted(w.blockers)) for w in exact_ways(b)["a"]]
    [('+x', ['b'])]
    """
    lock = locked(block)
    if lock:
        raise DeriveError(_lock_message(lock))
    conditions = conditions or Conditions({})
    after: dict[str, list[frozenset[str]]] = {}
    for a, b in before:
        after.setdefault(b, []).append(frozenset([a]))
    opts = minimal_directions(block)
    out = {}
    for p in block.parts:
        needs = () if p == conditions.base else tuple(n for _, n in conditions.needs.get(p, ()))
        fixed = tuple(after.get(p, ()))
        # a direction whose blockers hold every part of a need (a support below that is in the way, the base,
        # a process constraint) admits the part never: no way
        ways = [Way(blockers, needs + fixed, name=d) for d, blockers in opts[p]
                if not any(n <= blockers for n in needs + fixed)]
        if needs and conditions.may_go_first(p) and not fixed:
            ways.append(Way(frozenset(), fixed, name="first", first=True))
        if not ways:
            raise DeriveError(f"no feasible sequence: every direction of {p} is blocked by all the parts of one of "
                              "its needs (the parts it could rest on or touch, the base, a process constraint), "
                              "which must go in before it")
        out[p] = tuple(ways)
    _check_feasible(block, out, conditions)
    return out


def _check_feasible(block: Blocking, ways: dict[str, tuple[Way, ...]], conditions: Conditions) -> None:
    """Refuse ways that admit no sequence, as the union of orders would (the same messages)."""
    from opportune.formats.ways import ways_plan

    table = WaysTable.of(ways_plan("derived", [Part(p) for p in block.parts], ways))
    try:
        found = table.completion(0, SEARCH_WORK)
    except Undecided:
        return              # the plan's own check warns of it
    if found is None:
        raise DeriveError(_no_sequence_message(alternatives(block, conditions)) if conditions.needs else
                          "no feasible sequence keeps the process constraints (the base and identical parts' "
                          "included): every choice of insertion directions contradicts them; drop or change a "
                          "constraint")


def as_units(ways: dict[str, tuple[Way, ...]], quantities: dict) -> dict[str, tuple[Way, ...]]:
    """Ways over instances as the plan writes them: the ``k``-th instance of a part of several (the
    manifest's ``quantities``, in its order: the order :func:`exact_ways` keeps them in) is the part's
    ``k``-th unit, ``part#k`` (:mod:`opportune.formats.ways`), with the instance's own ways.

    Parameters
    ----------
    ways : dict
        Each instance's ways (:func:`exact_ways`, the instances of a part in sequence).
    quantities : dict
        Part id → its instances.

    Returns
    -------
    dict
        The same ways keyed and naming units (``bolt#2``); the order of a unit after the one before it is
        left out (a plan's units go in in order).

    Examples
    --------
    >>> w = {"b1": (Way(frozenset({"c"})),), "b2": (Way(frozenset({"c"}), (frozenset({"b1"}),)),),
    ...      "c": (Way(frozenset(), (frozenset({"b1", "b2"}),)),)}
    >>> {k: [(sorted(x.blockers), [sorted(n) for n in x.needs]) for x in v] for k, v in as_units(w, {"b": ["b1", "b2"]}).items()}
    {'b#1': [(['c'], [])], 'b#2': [(['c'], [])], 'c': [([], [['b#1', 'b#2']])]}
    """
    unit = {inst: unit_id(part, k) for part, group in quantities.items() if len(group) > 1
            for k, inst in enumerate(group, 1)}
    if not unit:
        return ways
    before = {unit[b]: unit[a] for group in quantities.values() if len(group) > 1 for a, b in zip(group, group[1:])}

    def named(ids) -> frozenset[str]:
        return frozenset(unit.get(q, q) for q in ids)

    out = {}
    for p, ws in ways.items():
        key = unit.get(p, p)
        chain = frozenset([before[key]]) if key in before else None
        out[key] = tuple(Way(named(w.blockers), tuple(named(n) for n in w.needs if named(n) != chain), name=w.name,
                             first=w.first) for w in ws)
    return out
