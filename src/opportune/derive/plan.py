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
from opportune.engine.poset import bits
from opportune.limits import MAX_STRATEGIES, MAX_WORKING


class DeriveError(ValueError):
    """An assembly whose plan cannot be written: no feasible sequence, or more strategies than a plan holds.

    Its message names the parts that lock each other (with what blocks each along each direction), or
    says how large the plan would be and what to give instead; no plan is written.

    Examples
    --------
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0)}, {"a": {"+x": frozenset("b")}, "b": {"+x": frozenset("a")}}, 0, 0)
    >>> exact_strategies(b)
    Traceback (most recent call last):
    ...
    opportune.derive.plan.DeriveError: no feasible sequence: parts a, b lock each other (none of them can go in last among them along any direction): a: +x by b; b: +x by a
    """


class TooManyStrategies(DeriveError):
    """The exact union of partial orders needs more than a plan holds: :func:`opportune.derive.derive`
    writes the plan as ways instead (:mod:`opportune.derive.ways`), unless asked for strategies only."""


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


@dataclass(frozen=True)
class Conditions:
    """What each part needs besides a free direction: ``needs[p]`` lists ``p``'s requirements, each a
    kind (``"gravity"``, ``"connected"``) and the set of parts any one of which must be in before ``p``
    (a requirement the fixture meets is left out).  The ``base``, if given, goes first and needs
    nothing; without a base, a part whose requirements are all of kinds in ``waived_first``
    (``connected``: the first part touches nothing built) may go first instead of meeting them."""

    needs: dict[str, tuple[tuple[str, frozenset[str]], ...]]
    base: str | None = None
    waived_first: frozenset[str] = frozenset()

    def may_go_first(self, p: str) -> bool:
        """Whether ``p`` can be the first part (its requirements waived there).

        Parameters
        ----------
        p : str
            A part.

        Returns
        -------
        bool
            True for the base; without a base, for a part whose requirements the first part is spared.

        Examples
        --------
        >>> Conditions({"b": (("gravity", frozenset("a")),)}).may_go_first("b")
        False
        """
        if self.base is not None:
            return p == self.base
        return all(kind in self.waived_first for kind, _ in self.needs.get(p, ()))


@dataclass(frozen=True)
class _Alternative:
    """One way a part can go in: its name (a direction, with its supports) and the parts it must come
    before and after."""

    name: str
    after: frozenset[str]
    before: frozenset[str]


def alternatives(block: Blocking, conditions: Conditions | None = None) -> dict[str, list[_Alternative]]:
    """Per part, the minimal ways it can go in: a direction of :func:`options` and, for each requirement,
    one part in before it (or, where :meth:`Conditions.may_go_first`, the part first of all); a way that
    asks a superset of another's orders is left out.

    Parameters
    ----------
    block : Blocking
        The blocking relation.
    conditions : Conditions, optional
        The supports each part needs, and the base.

    Returns
    -------
    dict
        For each part, its ways: a name (``"+x on b"``, ``"first"``), the parts it must come before and after.

    Examples
    --------
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0)}, {"a": {"+x": frozenset("b")}, "b": {"+x": frozenset()}}, 0, 0)
    >>> [(w.name, sorted(w.after), sorted(w.before)) for w in alternatives(b, Conditions({"b": (("gravity", frozenset("a")),)}))["b"]]
    [('+x on a', [], ['a'])]
    """
    conditions = conditions or Conditions({})
    opts = options(block)
    out = {}
    for p in block.parts:
        needs = () if p == conditions.base else conditions.needs.get(p, ())
        ways = []
        for d, blockers in opts[p]:
            for chosen in itertools.product(*(sorted(n) for _, n in needs)):
                name = d + "".join(f" on {q}" for q in dict.fromkeys(chosen))
                ways.append(_Alternative(name, blockers, frozenset(chosen)))
        if needs and conditions.may_go_first(p):
            ways.append(_Alternative("first", frozenset(block.parts) - {p}, frozenset()))
        keep: list[_Alternative] = []
        for w in ways:
            if any(o.after <= w.after and o.before <= w.before and (o.after, o.before) != (w.after, w.before)
                   for o in ways) or any((o.after, o.before) == (w.after, w.before) for o in keep):
                continue
            keep.append(w)
        out[p] = keep
    return out


def way_direction(block: Blocking, part: str, way: str) -> str:
    """The direction of a way in (:func:`alternatives`' names: ``"+x"``, ``"+x on b"``); for ``"first"``
    (nothing is in yet, every direction is free) the part's first direction.

    Parameters
    ----------
    block : Blocking
        The blocking relation.
    part : str
        The part.
    way : str
        Its way in, as a strategy names it.

    Returns
    -------
    str
        A direction of ``block``.

    Examples
    --------
    >>> b = Blocking(("a",), {"+x": (1, 0, 0), "-z": (0, 0, -1)}, {"a": {"+x": frozenset(), "-z": frozenset()}}, 0, 0)
    >>> way_direction(b, "a", "-z on f"), way_direction(b, "a", "first")
    ('-z', '+x')
    """
    if way == "first":
        return next(iter(block.blockers[part]))
    return way.split(" on ")[0]


def way_supports(way: str) -> frozenset[str]:
    """The parts a way in rests on or touches (``"+x on b on c"``: b and c).

    Parameters
    ----------
    way : str
        A way in, as a strategy names it.

    Returns
    -------
    frozenset of str
        The supporting parts (empty for a bare direction or ``"first"``).

    Examples
    --------
    >>> sorted(way_supports("+x on b on c"))
    ['b', 'c']
    """
    return frozenset(way.split(" on ")[1:])


def exact_strategies(block: Blocking, conditions: Conditions | None = None,
                     before: Sequence[tuple[str, str]] = ()) -> list[DerivedStrategy]:
    """The minimal strategies whose union admits exactly the feasible sequences.

    A sequence is feasible iff each part has a way (:func:`alternatives`) whose orders it keeps, so the
    feasible sequences are the union over a way per part of one partial order each.  The union is built
    part by part (parts with one way first, in one order): after each part, an order whose closure
    contains another's is dropped (whatever the later parts add, it stays the larger, admitting fewer
    sequences) and so is one with a cycle; what remains at the end is the minimal union, exactly.

    Parameters
    ----------
    block : Blocking
        The blocking relation.
    conditions : Conditions, optional
        Supports each part needs (``--gravity``, ``--connected``) and the base part.
    before : sequence of (str, str)
        Orders added to every strategy (process constraints: ``(a, b)``, a before b).

    Returns
    -------
    list of DerivedStrategy
        At most :data:`~opportune.limits.MAX_STRATEGIES`, none admitting a subset of another's sequences.

    Raises
    ------
    DeriveError
        No feasible sequence (the locked parts named, with what blocks each), more than
        :data:`~opportune.limits.MAX_WORKING` incomparable partial orders while building, or more than
        :data:`~opportune.limits.MAX_STRATEGIES` strategies in the exact plan.

    Examples
    --------
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0), "-x": (-1, 0, 0)},
    ...              {"a": {"+x": frozenset("b"), "-x": frozenset()}, "b": {"+x": frozenset(), "-x": frozenset("a")}},
    ...              0, 0)
    >>> [s.pairs for s in exact_strategies(b)]
    [()]
    >>> [s.pairs for s in exact_strategies(b, Conditions({"b": (("gravity", frozenset("a")),)}))]    # b rests on a
    [(('a', 'b'),)]
    >>> touch = Conditions({"a": (("connected", frozenset("b")),), "b": (("connected", frozenset("a")),)},
    ...                    waived_first=frozenset({"connected"}))
    >>> sorted(s.pairs for s in exact_strategies(b, touch))      # either first, the other touching it
    [(('a', 'b'),), (('b', 'a'),)]
    """
    lock = locked(block)
    if lock:
        raise DeriveError(_lock_message(lock))
    ways = alternatives(block, conditions)
    ids = block.parts
    index = {p: i for i, p in enumerate(ids)}
    base = conditions.base if conditions else None
    start = _Order.empty(len(ids))
    if base is not None:
        start = start.adding([(index[base], index[q]) for q in ids if q != base])
    if start is not None and before:
        start = start.adding([(index[a], index[b]) for a, b in before])
        if start is None:
            raise DeriveError(_contradiction_message(before))
    order = sorted(ids, key=lambda p: (len(ways[p]), index[p]))
    working = [(start, {})] if start is not None else []
    for step, p in enumerate(order):
        grown = {}
        for closure, names in working:
            for w in ways[p]:
                more = closure.adding([(index[p], index[q]) for q in w.after]
                                      + [(index[q], index[p]) for q in w.before])
                if more is not None and more.key not in grown:
                    grown[more.key] = (more, {**names, p: w.name})
        working = _undominated(list(grown.values()), MAX_WORKING)
        if working is None:
            raise TooManyStrategies(_wall_message(ways, order[:step + 1], len(ids)))
        if not working:
            raise DeriveError(_contradiction_message(before, ways, conditions) if before else _no_sequence_message(ways, conditions))
    if len(working) > MAX_STRATEGIES:
        raise TooManyStrategies(f"the exact plan needs {len(working)} strategies (none of whose sequences contain "
                          f"another's); a plan holds at most {MAX_STRATEGIES}: give fewer directions, or derive "
                          "subassemblies; no approximation is written")
    return [DerivedStrategy(dict(sorted(names.items(), key=lambda kv: index[kv[0]])), reduction(ids, closure.above))
            for closure, names in working]


@dataclass(frozen=True)
class _Order:
    """A partial order of parts ``0..n-1``, transitively closed: ``above[x]`` and ``below[x]`` are the
    masks of the parts after and before ``x``; ``key`` packs ``above`` into one integer (a closure is
    inside another iff its key's bits are)."""

    above: tuple[int, ...]
    below: tuple[int, ...]
    key: int

    @staticmethod
    def empty(n: int) -> "_Order":
        return _Order((0,) * n, (0,) * n, 0)

    def adding(self, edges) -> "_Order | None":
        """The closure with the edges ``a -> b`` added, or None if that makes a cycle."""
        above, below = list(self.above), list(self.below)
        for a, b in edges:
            if a == b or above[b] >> a & 1:
                return None
            if above[a] >> b & 1:
                continue
            preds, succs = below[a] | 1 << a, above[b] | 1 << b
            for x in bits(preds):
                above[x] |= succs
            for y in bits(succs):
                below[y] |= preds
        n = len(above)
        return _Order(tuple(above), tuple(below), sum(m << (x * n) for x, m in enumerate(above)))


def _undominated(found: list, most: int) -> list | None:
    """Drop each order whose closure contains another's (its sequences are a subset), or None as soon as
    more than ``most`` are kept.  Fewest pairs first: an order kept is never dominated by a later one (as
    many pairs or more, and a different closure), so the kept list only grows and the work is
    O(found × most) comparisons of packed closures."""
    found.sort(key=lambda item: item[0].key.bit_count())
    kept: list = []
    for item in found:
        key = item[0].key
        if any(other.key & ~key == 0 for other, _ in kept):
            continue
        kept.append(item)
        if len(kept) > most:
            return None
    return kept


def _wall_message(ways: dict[str, list[_Alternative]], done: list[str], n: int) -> str:
    """Why the exact plan is refused: how many parts have several ways, and where the union outgrew the limit."""
    several = sorted((p for p in ways if len(ways[p]) > 1), key=lambda p: -len(ways[p]))
    shown = ", ".join(f"{p} ({len(ways[p])})" for p in several[:8]) + (", …" if len(several) > 8 else "")
    return (f"the exact plan is a union of more than {MAX_WORKING} incomparable partial orders after {len(done)} of "
            f"{n} parts ({len(several)} {'part' if len(several) == 1 else 'parts'} with several ways in: {shown}); a plan "
            f"holds at most "
            f"{MAX_STRATEGIES} strategies, and the engine counts and runs unions of partial orders only: give fewer "
            "directions, a base part, or derive subassemblies; no approximation is written")


def _contradiction_message(before: Sequence[tuple[str, str]], ways: dict[str, list[_Alternative]] | None = None,
                           conditions: Conditions | None = None) -> str:
    """No sequence keeps the orders added to every strategy (process constraints, base, identical parts): the
    parts named, with the orders that contradict (:func:`~opportune.derive.refusals.why_none`)."""
    from opportune.derive.refusals import why_none

    why = why_none(ways or {}, conditions, before)
    return (f"no feasible sequence keeps the process constraints ({len(before)} order"
            f"{'' if len(before) == 1 else 's'}, the base and identical parts' included)"
            + (f": {why}" if why else ": every choice of insertion directions contradicts them")
            + "; drop or change a constraint, or change the parts named")


def _no_sequence_message(ways: dict[str, list[_Alternative]], conditions: Conditions | None = None) -> str:
    """No sequence meets the supports: the parts named with why (the orders that contradict, or a part
    nothing can hold), else the parts that can only go in first."""
    from opportune.derive.refusals import why_none

    why = why_none(ways, conditions)
    if why is None:
        alone = [p for p, w in ways.items() if [x.name for x in w] == ["first"]]
        why = (f"parts {', '.join(alone[:12])} rest on nothing and touch nothing that could be in before them, so "
               "each of them could only go in first" if len(alone) > 1 else "")
    asked = sorted({f"--{kind}" for needs in conditions.needs.values() for kind, _ in needs}) if conditions else []
    asked += ["--base"] if conditions is not None and conditions.base else []
    return (f"no feasible sequence meets the supports asked ({', '.join(asked) or '--gravity, --connected, --base'})"
            + (f": {why}" if why else "")
            + "; give a part to rest on or a base part, change the parts named, or derive without the option")


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
