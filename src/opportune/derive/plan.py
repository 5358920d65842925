"""The exact plan of an assembly's blocking relation: every feasible sequence, and no other.

Under the motion model a part ``p`` can go in after the set ``S`` is built iff for some direction
``d`` no part of ``S`` is in ``B_d(p)``, the parts blocking ``p`` along ``d``: iff ``p`` precedes every
part of ``B_d(p)``.  So the feasible sequences are the union, over a choice of one direction per part,
of the sequences of the order ``{p < q : q in B_d(p)}`` (a choice whose order has a cycle admits
none).  That union is the project's plan with several strategies, made minimal:

* per part, only the directions whose blocker sets are minimal (a direction blocked by a superset of
  another's blockers adds only sequences the other admits);
* no strategy whose sequences another's contain (its order's closure a superset of another's);
* each strategy's constraints the transitive reduction of its order (no redundant constraint).

More than :data:`~opportune.limits.MAX_STRATEGIES` strategies left is refused, never approximated;
so is an assembly with no feasible sequence, naming the parts that lock each other.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Sequence

from opportune.derive.blocking import Blocking
from opportune.engine.poset import CycleError, Poset, bits
from opportune.limits import MAX_CHOICES, MAX_STRATEGIES


class DeriveError(ValueError):
    """An assembly whose plan cannot be written: no feasible sequence, or more strategies than a plan holds."""


@dataclass(frozen=True)
class DerivedStrategy:
    """One strategy: a direction for each part, and the order it forces as ``(before, after)`` pairs
    (the transitive reduction)."""

    directions: dict[str, str]
    pairs: tuple[tuple[str, str], ...]


def locked(block: Blocking) -> dict[str, dict[str, frozenset[str]]]:
    """The parts that lock each other: what remains when parts are taken out, last first, while one can be.

    A part can be the last in of a set iff some direction is free of the set's other parts; fewer parts
    block less, so taking out any such part never hurts, and the assembly has a feasible sequence iff
    this takes every part out.  The parts left (with each direction's blockers among them) are the
    largest set none of whose parts can go in last: the lock.

    Parameters
    ----------
    block : Blocking
        The blocking relation.

    Returns
    -------
    dict
        For each locked part, each direction and the locked parts blocking it there; empty if none.

    Examples
    --------
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0)}, {"a": {"+x": frozenset("b")}, "b": {"+x": frozenset("a")}}, 0, 0)
    >>> sorted(locked(b))
    ['a', 'b']
    """
    left = set(block.parts)
    progress = True
    while progress and left:
        progress = False
        for p in sorted(left):
            if any(not (q & left) for q in block.blockers[p].values()):
                left.discard(p)
                progress = True
    return {p: {d: q & left for d, q in block.blockers[p].items()} for p in sorted(left)}


def options(block: Blocking) -> dict[str, list[tuple[str, frozenset[str]]]]:
    """Per part, its directions whose blocker sets are minimal under inclusion (one direction per set).

    Parameters
    ----------
    block : Blocking
        The blocking relation.

    Returns
    -------
    dict
        For each part, ``(direction, blockers)`` pairs in the directions' order: a direction blocked by a
        superset of another's blockers, or by the same set as an earlier one, is left out.

    Examples
    --------
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0), "-x": (-1, 0, 0)},
    ...              {"a": {"+x": frozenset("b"), "-x": frozenset()}, "b": {"+x": frozenset(), "-x": frozenset()}}, 0, 0)
    >>> options(b)["a"]
    [('-x', frozenset())]
    """
    out = {}
    for p in block.parts:
        sets = [(d, q) for d, q in block.blockers[p].items()]
        keep: list[tuple[str, frozenset[str]]] = []
        for d, q in sets:
            if any(other < q for _, other in sets) or any(q == k for _, k in keep):
                continue
            keep.append((d, q))
        out[p] = keep
    return out


def exact_strategies(block: Blocking, before: Sequence[tuple[str, str]] = ()) -> list[DerivedStrategy]:
    """The minimal strategies whose union admits exactly the feasible sequences.

    Parameters
    ----------
    block : Blocking
        The blocking relation.
    before : sequence of (str, str)
        Orders added to every strategy (process constraints: ``(a, b)``, a before b).

    Returns
    -------
    list of DerivedStrategy
        At most :data:`~opportune.limits.MAX_STRATEGIES`, none admitting a subset of another's sequences.

    Raises
    ------
    DeriveError
        No feasible sequence (the locked parts named, with what blocks each; or none that keeps ``before``), more than
        :data:`~opportune.limits.MAX_CHOICES` direction choices × parts to examine, or more than
        :data:`~opportune.limits.MAX_STRATEGIES` strategies in the exact plan.

    Examples
    --------
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0), "-x": (-1, 0, 0)},
    ...              {"a": {"+x": frozenset("b"), "-x": frozenset()}, "b": {"+x": frozenset(), "-x": frozenset("a")}},
    ...              0, 0)
    >>> [s.pairs for s in exact_strategies(b)]
    [()]
    """
    lock = locked(block)
    if lock:
        raise DeriveError(_lock_message(lock))
    opts = options(block)
    ids = block.parts
    index = {p: i for i, p in enumerate(ids)}
    fixed = [p for p in ids if len(opts[p]) == 1]
    free = [p for p in ids if len(opts[p]) > 1]
    combos = 1
    for p in free:
        combos *= len(opts[p])
    # each combination examined keeps its order's closure (a mask per part): bounded before the work
    if combos * len(ids) > MAX_CHOICES:
        raise DeriveError(f"{combos:,} combinations of insertion directions to examine ({len(free)} parts have "
                          f"several), times {len(ids)} parts, is over {MAX_CHOICES:,}: give fewer directions, or "
                          "derive subassemblies; no approximation is written")
    base = _edges({p: opts[p][0][1] for p in fixed}, index) | {(index[a], index[b]) for a, b in before}
    closures: dict[tuple[int, ...], tuple[dict[str, str], tuple[int, ...]]] = {}
    for choice in itertools.product(*(opts[p] for p in free)):
        edges = base | _edges({p: q for p, (_, q) in zip(free, choice)}, index)
        try:
            key = tuple(Poset.from_pairs(len(ids), edges).above)    # the closure: each part's successors
        except CycleError:
            continue
        if key not in closures:
            dirs = {p: opts[p][0][0] for p in fixed} | {p: d for p, (d, _) in zip(free, choice)}
            closures[key] = (dirs, key)
    if not closures:    # every choice of directions is in a cycle with the added orders
        raise DeriveError(f"no feasible sequence keeps the process constraints ({len(before)} order"
                          f"{'' if len(before) == 1 else 's'}, the base and identical parts' included): every choice of insertion directions contradicts them; drop or "
                          "change a constraint")
    kept = _undominated(list(closures.values()), MAX_STRATEGIES)
    if kept is None:
        raise DeriveError(f"the exact plan needs more than {MAX_STRATEGIES} strategies (no one's sequences contain "
                          f"another's); a plan holds at most {MAX_STRATEGIES}: give fewer directions, or derive "
                          "subassemblies; no approximation is written")
    return [DerivedStrategy(dict(sorted(dirs.items(), key=lambda kv: index[kv[0]])), reduction(ids, closure))
            for dirs, closure in kept]


def _edges(chosen: dict[str, frozenset[str]], index: dict[str, int]) -> set[tuple[int, int]]:
    """The order's edges ``p -> q`` (p before q) for each part's chosen blockers."""
    return {(index[p], index[q]) for p, qs in chosen.items() for q in qs}


def _undominated(found: list[tuple[dict[str, str], tuple[int, ...]]], most: int) -> list | None:
    """Drop each strategy whose closure contains another's (its sequences are a subset), or None as soon
    as more than ``most`` are kept.  Fewest constraints first: a strategy kept is never dominated by a
    later one (as many constraints or more, and a different closure), so the kept list only grows and
    the work is O(found × most)."""
    found.sort(key=lambda item: sum(bin(m).count("1") for m in item[1]))
    kept: list = []
    for dirs, closure in found:
        if any(all(k & c == k for k, c in zip(other, closure)) for _, other in kept):
            continue
        kept.append((dirs, closure))
        if len(kept) > most:
            return None
    return kept


def reduction(ids: tuple[str, ...], reach: tuple[int, ...]) -> tuple[tuple[str, str], ...]:
    """The transitive reduction of a closed order: ``a -> b`` kept unless some ``c`` lies between.

    Parameters
    ----------
    ids : tuple of str
        The elements' names.
    reach : tuple of int
        Each element's successors, a bit mask (transitively closed).

    Returns
    -------
    tuple of (str, str)
        The cover pairs ``(before, after)``.

    Examples
    --------
    >>> reduction(("a", "b", "c"), (0b110, 0b100, 0))
    (('a', 'b'), ('b', 'c'))
    """
    pairs = []
    for a, succ in enumerate(reach):
        via = 0
        for c in bits(succ):
            via |= reach[c]
        pairs.extend((ids[a], ids[b]) for b in bits(succ & ~via))
    return tuple(pairs)


def _lock_message(lock: dict[str, dict[str, frozenset[str]]]) -> str:
    """Why no sequence is feasible: each locked part with what blocks it along each direction."""
    shown = list(lock.items())[:12]
    why = "; ".join(f"{p}: " + ", ".join(f"{d} by {'+'.join(sorted(q))}" for d, q in dirs.items() if q)
                    for p, dirs in shown)
    more = f"; … ({len(lock) - 12} more parts)" if len(lock) > 12 else ""
    return (f"no feasible sequence: parts {', '.join(lock)} lock each other (none of them can go in last among "
            f"them along any direction): {why}{more}")
