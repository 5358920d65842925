"""What ``derive --explain`` and ``--figure`` read of a plan written as ways: found from the ways themselves.

A plan written as ways (:mod:`opportune.derive.ways`) has no strategies to read the explanation from, but
its ways say the same things: a part's way along ``d`` is blocked by exactly the parts of ``B_d(p)``, so

* a direction ``d`` of a part ``p`` is an **insertion direction** iff some feasible sequence puts ``p`` in
  on a set ``S`` (its supports met) with no part of ``B_d(p)`` in ``S``;
* ``a`` goes in before ``b`` in **every** feasible sequence (a forced order) iff no feasible sequence puts
  ``b`` before ``a``.

Both are decided from sampled feasible sequences first (:func:`~opportune.engine.ways.sample_completions`:
each one shows the directions its parts used and refutes every order it breaks), then what they leave
open is decided one question at a time: without needs by peeling the blocking relation (a direction:
:func:`~opportune.derive.explain._usable`'s rule) or with a search for one completion of the plan with the
question's condition added (:meth:`~opportune.planning.ways.WaysTable.completion`); a forced order that
follows from the ways directly (a part blocked by ``b`` along every way it has, or needing ``a`` in every
way) or from two such is proved without a search.  Every search stops at the time given; what it did not
reach is said (``unfinished``), never guessed.

Complexity: the samples are :data:`SAMPLES` walks, O(parts × ways naming a part) each; a search is
O(parts × ways) mask operations per set it visits (parts of them, with no needs).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from opportune.derive.plan import DerivedStrategy
from opportune.planning.ways import Undecided, WaysTable

__all__ = ["WaysFacts", "ways_facts", "sequence_strategy", "SAMPLES", "SEARCH_WORK"]

#: Runs × walks of the sampled feasible sequences: 24 runs of 4 walks (96 sequences, about uniform; more runs
#: than walks, as the walks of a run share ancestors) refute most orders that are not forced in the random
#: blocks measured, leaving few questions to decide one by one.
SAMPLES = (24, 4)
#: Sets one search for a completion may visit beyond ten times the parts (a plan without dead ends needs as many
#: as it has parts; one with many is left undecided rather than searched at length).
SEARCH_WORK = 1_000


@dataclass
class WaysFacts:
    """The explanation's facts of a plan written as ways.

    Parameters
    ----------
    order : dict
        The forced orders' transitive reduction as one order's ``constraints`` (as
        :class:`~opportune.derive.explain.Explanation` holds a strategy's), each with its reason.
    usable : dict
        Part id → its insertion directions (the parts whose every direction was decided).
    forced : list of (str, str)
        Every forced order (closed).
    unfinished : list of str
        What the time did not decide.

    Examples
    --------
    >>> from opportune.derive import derive
    >>> f = ways_facts(derive("geometry:pump", gravity="-z", form="ways"))
    >>> c = f.order["constraints"][0]
    >>> f.usable["shaft"], c["before"], c["after"], c["other_directions"], f.unfinished
    (['-z'], 'bearing', 'shaft', {'+z': ['housing', 'seal']}, [])
    """

    order: dict
    usable: dict[str, list[str]]
    forced: list[tuple[str, str]]
    unfinished: list[str] = field(default_factory=list)


def ways_facts(derivation, *, until: float | None = None, seed: int = 0) -> WaysFacts:
    """The insertion directions and forced orders of a derivation whose plan is written as ways.

    Parameters
    ----------
    derivation : Derivation
        A derivation (its plan written as ways, every part of quantity 1, or identical parts as units).
    until : float, optional
        A moment of ``time.perf_counter()`` past which nothing more is decided.
    seed : int
        Seed of the sampled sequences.

    Returns
    -------
    WaysFacts
        The facts, exact where decided (see the module).

    Examples
    --------
    >>> from opportune.derive import derive
    >>> f = ways_facts(derive("geometry:gearbox", gravity="-z", form="ways"))
    >>> f.usable["gear_a"], [a for a, b in f.forced if b == "gear_a"]
    (['-x'], ['bearing_a2', 'housing', 'shaft_a'])
    """
    from opportune.engine.ways import sample_completions

    block = derivation.blocking
    table, ids = _instance_table(derivation)
    index = {p: i for i, p in enumerate(ids)}
    own = {p: {d: _mask(q, index) for d, q in block.blockers[p].items()} for p in ids}
    runs, walks = SAMPLES
    now = time.perf_counter()
    # the samples a third of the time at most: on 300 parts they are the slowest step, and a question they
    # leave is decided one by one after them
    samples = sample_completions(table, runs=runs, particles=walks, seed=seed,
                                 deadline=None if until is None else now + (until - now) / 3)
    proved = _closed(_direct(table))
    usable, left_dirs = _usable_directions(table, ids, own, samples, proved, until)
    forced, left_pairs = _forced(table, ids, samples, proved, until)
    unfinished = ([f"insertion directions of {left_dirs} parts"] if left_dirs else []) + (
        [f"{left_pairs} orders (not said to be forced)"] if left_pairs else [])
    return WaysFacts(_reasons(derivation, ids, forced), usable, forced, unfinished)


def _instance_table(derivation) -> tuple[WaysTable, list[str]]:
    """The derivation's ways as masks over its instances (the blocking relation's parts), with their ids:
    the plan's table, each unit of a part of several identical instances named by its instance."""
    table = WaysTable.of(derivation.plan)
    return table, list(_table_ids(derivation, table))


def _table_ids(derivation, table: WaysTable) -> list[str]:
    """The instance each bit of the plan's table stands for (a part's ``k``-th unit: its ``k``-th instance)."""
    man = derivation.manifest
    groups = man.quantities if man is not None else {}
    out = []
    for p in derivation.plan.parts:
        out += list(groups.get(p.id, (p.id,)))[:p.quantity] if p.quantity > 1 else [p.id]
    if len(out) != table.n:
        raise ValueError("the plan's units are not the derivation's parts")
    return out


def _mask(parts, index: dict[str, int]) -> int:
    m = 0
    for q in parts:
        m |= 1 << index[q]
    return m


def _needs(table: WaysTable, i: int) -> tuple | None:
    """Part ``i``'s needs (the same in each of its ways but ``first``), or None if it has only ``first``."""
    full = table.full & ~(1 << i)
    for blockers, needs in table.ways[i]:
        if blockers != full or needs:
            return needs
    return None


def _usable_directions(table: WaysTable, ids: list[str], own: dict, samples, proved: list[int],
                       until) -> tuple[dict, int]:
    """Each part's insertion directions, and how many parts the time left undecided (``proved``: the parts
    surely before each part, :func:`_direct`'s closure: a direction one of them blocks is none)."""
    found: dict[str, set[str]] = {p: set() for p in ids}
    for seq in samples:
        s = 0
        for i in seq:
            p = ids[i]
            found[p] |= {d for d, m in own[p].items() if not m & s}
            s |= 1 << i
    undecided: set[str] = set()
    for i, p in enumerate(ids):
        for d, m in own[p].items():
            needs = _needs(table, i)
            # a part surely before it in the way, or every part of a support (unless it may go in first)
            if d in found[p] or m & proved[i] or (not _may_go_first(table, i)
                                                  and any(n & ~m == 0 for n in needs or ())):
                continue
            ways = [(m, needs)] if needs is not None else []
            ways += [(b, n) for b, n in table.ways[i] if b == table.full & ~(1 << i) and not n]   # first
            answer = _admits(table, i, ways, until)
            if answer is None:
                undecided.add(p)
            elif answer:
                found[p].add(d)
    # a part with a direction undecided is left out (its directions not said, nor that it has one only)
    return {p: [d for d in own[p] if d in found[p]] for p in ids if p not in undecided}, len(undecided)


def _admits(table: WaysTable, i: int, ways: list, until) -> bool | None:
    """Whether the plan with part ``i``'s ways replaced by ``ways`` admits a sequence (None: undecided)."""
    if not ways:
        return False
    if until is not None and time.perf_counter() > until:
        return None
    if not table.has_needs and not any(n for _, n in ways):
        return _peels([[b for b, _ in w] for w in table.ways[:i]] + [[b for b, _ in ways]]
                      + [[b for b, _ in w] for w in table.ways[i + 1:]])
    changed = WaysTable(table.n, [ways if k == i else w for k, w in enumerate(table.ways)])
    try:
        return changed.completion(0, 10 * table.n + SEARCH_WORK, until) is not None
    except Undecided:
        return None


def _peels(blockers: list[list[int]]) -> bool:
    """Whether parts with these ways (per part, its ways' blocker masks; no needs) admit a sequence: taken out
    last first while one can be (a way none of whose blockers is left), none remains.  Fewer parts block
    less, so the order of taking out does not matter (:func:`~opportune.derive.plan.locked`); each way
    keeps a count of its blockers left: O(the blocker sets' sizes)."""
    left: list[int] = []
    owner: list[int] = []
    waiting: dict[int, list[int]] = {}
    free = []
    for i, ways in enumerate(blockers):
        for b in ways:
            k = len(left)
            left.append(b.bit_count())
            owner.append(i)
            for q in _bits(b & ~(1 << i)):
                waiting.setdefault(q, []).append(k)
            left[k] -= b >> i & 1
            if not left[k]:
                free.append(i)
    out = set()
    while free:
        i = free.pop()
        if i in out:
            continue
        out.add(i)
        for k in waiting.get(i, ()):
            left[k] -= 1
            if not left[k] and owner[k] not in out:
                free.append(owner[k])
    return len(out) == len(blockers)


def _may_go_first(table: WaysTable, i: int) -> bool:
    """Whether part ``i`` has a way ``first``."""
    return any(b == table.full & ~(1 << i) and not n for b, n in table.ways[i])


def _forced(table: WaysTable, ids: list[str], samples, proved: list[int],
            until) -> tuple[list[tuple[str, str]], int]:
    """Every forced order ``(a, b)`` and how many candidates the time left undecided."""
    n = table.n
    before = [table.full & ~(1 << i) for i in range(n)]      # the parts before i in every sample
    for seq in samples:
        s = 0
        for i in seq:
            before[i] &= s
            s |= 1 << i
    proved = list(proved)
    left = 0
    for b in range(n):
        if until is not None and time.perf_counter() > until:     # the rest undecided, counted at once
            left += sum((before[c] & ~proved[c]).bit_count() for c in range(b, n))
            break
        for a in _bits(before[b] & ~proved[b]):
            # b before a possible? without needs: b's ways each blocked by a (a after b); else a's ways each
            # need b in (a way first is then no way of a)
            if table.has_needs:
                ways, who = [(bl, needs + (1 << b,)) for bl, needs in table.ways[a]
                             if bl != table.full & ~(1 << a) or needs], a
            else:
                ways, who = [(bl | 1 << a, ()) for bl, _ in table.ways[b]], b
            answer = _admits(table, who, ways, until)
            if answer is None:
                left += 1
            elif not answer:
                _add(proved, a, b)
    return sorted((ids[a], ids[b]) for b in range(n) for a in _bits(proved[b])), left


def _add(before: list[int], a: int, b: int) -> None:
    """Add ``a`` before ``b`` to a closed order (part → the parts before it), closed again: whatever is before
    ``a`` (and ``a``) goes before ``b`` and before whatever is after ``b``.  O(parts) mask operations."""
    add = before[a] | 1 << a
    if before[b] & add == add:
        return
    for c in range(len(before)):
        if c == b or before[c] >> b & 1:
            before[c] |= add


def _direct(table: WaysTable) -> list[int]:
    """Per part, the parts the ways alone put before it: ``a`` before ``b`` where ``b`` blocks every way of
    ``a``, or every way of ``b`` needs ``a`` alone."""
    out = [0] * table.n
    for a, ways in enumerate(table.ways):
        common = table.full
        for blockers, _ in ways:
            common &= blockers
        for b in _bits(common & ~(1 << a)):
            out[b] |= 1 << a
    for b, ways in enumerate(table.ways):
        common = table.full
        for _, needs in ways:
            common &= sum(n for n in needs if n & (n - 1) == 0)
        out[b] |= common & ~(1 << b)
    return out


def _closed(before: list[int]) -> list[int]:
    """The transitive closure of ``before`` (part → the parts before it, as masks)."""
    out = list(before)
    changed = True
    while changed:
        changed = False
        for b in range(len(out)):
            m = out[b]
            for a in _bits(out[b]):
                m |= out[a]
            if m != out[b]:
                out[b], changed = m, True
    return out


def _reasons(derivation, ids: list[str], forced: list[tuple[str, str]]) -> dict:
    """The forced orders' transitive reduction, each with its reason: the directions along which the later
    part is in the earlier one's way (with the other directions' blockers), a support, or the ways together."""
    block, conditions = derivation.blocking, derivation.conditions
    pairs = set(forced)
    after: dict[str, set[str]] = {}
    for a, b in forced:
        after.setdefault(a, set()).add(b)
    reduced = [(a, b) for a, b in forced if not any((c, b) in pairs for c in after.get(a, ()) if c != b)]
    out = []
    for a, b in reduced:
        dirs = block.blockers[a]
        along = [d for d, q in dirs.items() if b in q]
        kinds = {k for k, n in conditions.needs.get(b, ()) if a in n}
        if along:
            out.append({"before": a, "after": b, "direction": ", ".join(along),
                        "other_directions": {d: sorted(q) for d, q in dirs.items() if b not in q}})
        elif kinds:
            verb = {frozenset({"gravity"}): "resting on", frozenset({"connected"}): "touching"}.get(
                frozenset(kinds), "resting on or touching")
            out.append({"before": a, "after": b, "direction": None, "support": verb, "other_directions": {}})
        else:
            out.append({"before": a, "after": b, "direction": None, "support": None, "other_directions": {},
                        "why": "in every feasible sequence (the ways together)"})
    return {"directions": {}, "constraints": out}


def sequence_strategy(derivation) -> DerivedStrategy:
    """One feasible sequence of a plan written as ways as a strategy the figure can draw: each part's direction
    (the first free one on the parts before it, ``-z`` where free) and the orders that keep it feasible (the
    part before the parts in its way along that direction; a support before the parts it holds).

    Parameters
    ----------
    derivation : Derivation
        A derivation whose plan is written as ways (the sequence: the first a depth-first search finds).

    Returns
    -------
    DerivedStrategy
        Directions and ``(before, after)`` pairs over the derivation's parts.

    Raises
    ------
    ValueError
        A plan whose sequence the search did not find within its work.

    Examples
    --------
    >>> from opportune.derive import derive
    >>> s = sequence_strategy(derive("geometry:gearbox", gravity="-z", form="ways"))
    >>> s.directions["gear_a"], s.directions["cover"], len(s.directions)
    ('-x', '-z', 14)
    """
    block = derivation.blocking
    table, ids = _instance_table(derivation)
    try:
        seq = table.completion(0, 50 * table.n + SEARCH_WORK)
    except Undecided:
        seq = None
    if seq is None:
        raise ValueError("no feasible sequence found to draw; derive the plan as strategies for the figure")
    placed: set[str] = set()
    mask, directions, pairs = 0, {}, set()
    for i in seq:
        p = ids[i]
        free = [d for d, q in block.blockers[p].items() if not q & placed]
        d = "-z" if "-z" in free else free[0] if free else next(iter(block.blockers[p]))
        directions[p] = d
        pairs |= {(p, q) for q in block.blockers[p].get(d, ())}
        # each need (a support, the base, a process constraint, the unit before) met by a part already in
        pairs |= {(ids[next(_bits(n & mask))], p) for n in (_needs(table, i) or ()) if n & mask}
        placed.add(p)
        mask |= 1 << i
    return DerivedStrategy({p: directions[p] for p in ids}, tuple(sorted(pairs)))


def _bits(mask: int):
    while mask:
        b = mask & -mask
        yield b.bit_length() - 1
        mask ^= b
