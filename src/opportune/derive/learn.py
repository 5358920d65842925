"""Learning a plan from observed sequences (the paper's "new style of planning").

Given sequences that assembled the product successfully, :func:`learn_plan` writes the single-strategy
plan with every constraint they agree on: ``a`` before ``b`` is a constraint exactly when every
observed sequence installs (every unit of) ``a`` before (every unit of) ``b``.  Any single partial
order that admits all the observed sequences has only constraints of that kind, so the learned
order, the intersection of the sequences' orders, is the tightest plan that never forbids an
observed sequence.  It is written as its cover relations (the transitive reduction).

**Accident probability.**  A constraint seen in every one of ``n`` sequences may still be an
accident of too few observations.  For a cover ``a -> b`` of the learned order ``P``, let ``P'`` be
``P`` without that one relation (every other relation of ``P`` kept, so still an order): the plan
that does not require it.  If the
observations were ``n`` independent, uniformly random admissible sequences of ``P'``, the chance
that all of them put ``a`` before ``b`` is ``p^n`` with ``p = e(P) / e(P')`` (``e``: the number of
linear extensions, counted exactly by :mod:`opportune.engine`).  That is the accident probability:
small means the constraint is well supported, near 1 means the data cannot tell.  It assumes
independent, uniformly random observations; a workshop that follows one routine makes every
constraint look certain, whatever the number says.

**Failed sequences.**  A failed sequence that violates learned constraints confirms them.  One that
violates none is admitted by the learned plan, and then by *every* single-strategy plan consistent
with the successes: such a plan's constraints are a subset of the learned ones (see above), so it
admits every sequence the learned plan admits.  Such a failure cannot be excluded by one partial
order; :func:`learn_plan` then looks for two strategies that exclude it (the successes split by one
constraint that the failure breaks), or says that it found none.

>>> learned = learn_plan(["a b c", "b a c"], name="tiny")
>>> learned.plan.strategies[0].pairs()
[('a', 'c'), ('b', 'c')]
>>> [(c.before, c.after, c.support, round(c.accident_probability, 4)) for c in learned.constraints]
[('a', 'c', 2, 0.4444), ('b', 'c', 2, 0.4444)]
"""

from __future__ import annotations

import json
import math
import re
import time
from bisect import bisect_left, bisect_right
from dataclasses import dataclass
from typing import Iterable

from opportune.engine.count import Counter
from opportune.engine.deadline import BudgetExceeded
from opportune.engine.poset import Poset
from opportune.formats.problems import Problem
from opportune.formats.sequences import SequenceError, Sequences, sequences_from
from opportune.planning.plan import Plan

__all__ = ["DEFAULT_MAX_ACCIDENT", "FailedSequence", "LearnedConstraint", "LearnedPlan", "MAX_REPAIR_WORK",
           "learn_plan", "learned_order", "read_sequences"]

from opportune.formats.sequences import read_sequences  # noqa: E402  (re-exported: the reader of learn's input)

DEFAULT_MAX_ACCIDENT = 0.05
# The search for a two-strategy repair stops after this many (sequence x part) mask operations, so a
# large input cannot hang it; it then says that it stopped.
MAX_REPAIR_WORK = 20_000_000


@dataclass(frozen=True)
class LearnedConstraint:
    """One cover constraint of the learned plan: ``before`` is installed before ``after``.

    Parameters
    ----------
    before, after : str
        The part ids: ``before`` is installed before ``after``.
    support : int
        Observed successful sequences that satisfy it (all of them: that is why it was learned).
    chance : float or None
        The probability ``p`` that one uniformly random admissible sequence of the plan without this
        constraint satisfies it (None when the count was over budget).
    accident_probability : float or None
        ``p ** support``: the chance that the constraint is an accident of too few observations.
    confirmed_by : tuple of str
        Where the failed sequences that violate it came from (``file:line``).

    Examples
    --------
    >>> c = learn_plan(["a b c", "a c b"], failed=["b a c"]).constraints[0]
    >>> c.before, c.after, c.support, round(c.chance, 4), round(c.accident_probability, 4), c.confirmed
    ('a', 'b', 2, 0.6667, 0.4444, True)
    """

    before: str
    after: str
    support: int
    chance: float | None
    accident_probability: float | None
    confirmed_by: tuple[str, ...] = ()

    @property
    def confirmed(self) -> bool:
        return bool(self.confirmed_by)

    def to_dict(self, max_accident: float | None = None) -> dict:
        """The constraint as plain data (an entry of ``learn --json``'s ``constraints``).

        Parameters
        ----------
        max_accident : float, optional
            With it, ``flagged`` says whether the accident probability is above it.

        Returns
        -------
        dict
            ``before``, ``after``, ``support``, ``accident_probability``, ``chance``, ``confirmed``,
            ``confirmed_by`` (and ``flagged``).

        Examples
        --------
        >>> c = learn_plan(["a b", "a b"]).constraints[0]
        >>> doc = c.to_dict(0.05)
        >>> doc["before"], doc["after"], doc["accident_probability"], doc["chance"], doc["flagged"]
        ('a', 'b', 0.25, 0.5, True)
        """
        doc = {"before": self.before, "after": self.after, "support": self.support,
               "accident_probability": self.accident_probability, "chance": self.chance,
               "confirmed": self.confirmed, "confirmed_by": list(self.confirmed_by)}
        if max_accident is not None:
            doc["flagged"] = self.accident_probability is not None and self.accident_probability > max_accident
        return doc


@dataclass(frozen=True)
class FailedSequence:
    """A failed sequence and the learned constraints it violates (``(before, after)`` pairs).

    ``excluded`` is False when it violates none: the learned plan admits it.

    Parameters
    ----------
    sequence : tuple of str
        The failed sequence's part ids, in order.
    where : str
        Where it came from (``file:line``, or ``sequence N`` for one given in Python).
    violates : tuple of (str, str)
        The learned constraints it breaks, as ``(before, after)`` pairs.
    succeeded : bool
        True when the very same sequence was also observed as a success (no plan can exclude it).

    Examples
    --------
    >>> learn_plan(["a b c", "a c b"], failed=["b a c"]).failed[0]
    FailedSequence(sequence=('b', 'a', 'c'), where='sequence 1', violates=(('a', 'b'),), succeeded=False)
    """

    sequence: tuple[str, ...]
    where: str
    violates: tuple[tuple[str, str], ...]
    succeeded: bool = False

    @property
    def excluded(self) -> bool:
        return bool(self.violates)

    def to_dict(self) -> dict:
        """The failed sequence as plain data (an entry of ``learn --json``'s ``failed``).

        Returns
        -------
        dict
            ``where``, ``sequence``, ``excluded``, ``violates`` and ``also_succeeded``.

        Examples
        --------
        >>> learn_plan(["a b c", "a c b"], failed=["a b c"]).failed[0].to_dict()
        {'where': 'sequence 1', 'sequence': ['a', 'b', 'c'], 'excluded': False, 'violates': [], 'also_succeeded': True}
        """
        return {"where": self.where, "sequence": list(self.sequence), "excluded": self.excluded,
                "violates": [list(p) for p in self.violates], "also_succeeded": self.succeeded}


@dataclass(frozen=True)
class LearnedPlan:
    """What :func:`learn_plan` learned.

    Parameters
    ----------
    plan : Plan
        The single-strategy :class:`~opportune.planning.plan.Plan` (cover constraints only).
    constraints : tuple of LearnedConstraint
        One per cover, in the plan's order.
    sequences, distinct : int
        How many successful sequences (and different ones) it learned from.
    failed : tuple of FailedSequence
        One per failed sequence given.
    repair : Plan, optional
        A two-strategy plan that admits every success and excludes every failure, when the single plan
        cannot and one was found (else None).
    repair_note : str
        What was found, or why not.
    max_accident : float
        Constraints with a larger accident probability are flagged (:attr:`flagged`).
    complete : bool
        False when some accident probabilities were over the counting budget (they are None).
    source : str, optional
        The sequences' file, if they came from one.

    Examples
    --------
    >>> learned = learn_plan(["a b c", "b a c"], failed=["a b c"])
    >>> learned.sequences, learned.distinct, [f.where for f in learned.unexcluded], learned.repair
    (2, 2, ['sequence 1'], None)
    >>> learned.repair_note
    'no plan can exclude sequence 1: the same sequence is also among the successes'
    """

    plan: Plan
    constraints: tuple[LearnedConstraint, ...]
    sequences: int
    distinct: int
    failed: tuple[FailedSequence, ...] = ()
    repair: Plan | None = None
    repair_note: str = ""
    max_accident: float = DEFAULT_MAX_ACCIDENT
    complete: bool = True
    source: str | None = None

    @property
    def unexcluded(self) -> tuple[FailedSequence, ...]:
        """The failed sequences that no single partial order consistent with the successes excludes."""
        return tuple(f for f in self.failed if not f.excluded)

    @property
    def flagged(self) -> tuple[LearnedConstraint, ...]:
        """The constraints whose accident probability is above ``max_accident``."""
        return tuple(c for c in self.constraints
                     if c.accident_probability is not None and c.accident_probability > self.max_accident)

    def to_json(self) -> dict:
        """The JSON document of ``opportune learn --json``.

        Returns
        -------
        dict
            The plan (as a plan file's dict), the counts of sequences, ``max_accident``, ``complete``, the
            constraints, the failed sequences, those no single plan excludes, and the repair with its note.

        Examples
        --------
        >>> doc = learn_plan(["a b c", "a c b"]).to_json()
        >>> doc["plan"]["strategies"], doc["sequences"], doc["repair"]
        ([{'name': 'default', 'requires': {'b': ['a'], 'c': ['a']}}], 2, None)
        """
        return {"plan": self.plan.to_dict(), "sequences": self.sequences, "distinct": self.distinct,
                "max_accident": self.max_accident, "complete": self.complete,
                "constraints": [c.to_dict(self.max_accident) for c in self.constraints],
                "failed": [f.to_dict() for f in self.failed],
                "unexcluded": [f.where for f in self.unexcluded],
                "repair": self.repair.to_dict() if self.repair is not None else None,
                "repair_note": self.repair_note}

    def to_yaml(self, *, repaired: bool = False) -> str:
        """The learned plan as a YAML plan file, each constraint commented with its support and accident
        probability.  O(parts + constraints).

        Parameters
        ----------
        repaired : bool
            The two-strategy repair instead, when there is one.

        Returns
        -------
        str
            A plan file that :func:`~opportune.formats.loader.read_plan` reads back.

        Examples
        --------
        >>> text = learn_plan(["a b c", "a c b"]).to_yaml()
        >>> print(text[text.index("name:"):])
        name: learned
        parts: [a, b, c]
        requires:            # X: parts that must be installed before X
          b:
            - a  # ! support 2/2, accident 0.444
          c:
            - a  # ! support 2/2, accident 0.444
        <BLANKLINE>
        """
        return _yaml(self, repaired and self.repair is not None)


def learned_order(sequences: Iterable[Iterable[str]], parts: list[str]) -> Poset:
    """The constraints every sequence satisfies, as a :class:`~opportune.engine.poset.Poset` on ``parts``.

    ``a < b`` when every sequence installs the last unit of ``a`` before the first unit of ``b``.
    Each sequence's relation is a (closed) interval order, and an intersection of closed orders is
    closed.  O(total length + sequences × parts) mask operations on masks of ``len(parts)`` bits.

    Parameters
    ----------
    sequences : iterable of sequences of str
        The sequences, each of part ids (every one of ``parts``, a part's id as often as its units).
    parts : list of str
        The part ids: the poset's elements, in this order.

    Returns
    -------
    Poset
        ``a < b`` (indices into ``parts``) exactly when every sequence has ``a`` wholly before ``b``.

    Examples
    --------
    >>> learned_order([["a", "b", "c"], ["b", "a", "c"]], ["a", "b", "c"]).cover_pairs()
    [(0, 2), (1, 2)]
    >>> learned_order([["a", "b", "a"], ["a", "a", "b"]], ["a", "b"]).cover_pairs()    # a's units around b
    []
    """
    index = {p: i for i, p in enumerate(parts)}
    seen = set()
    rels = []
    for seq in sequences:
        seq = tuple(seq)
        if seq not in seen:         # a repeat adds no constraint
            seen.add(seq)
            rels.append(_relation(seq, index))
    return _intersect(rels, len(parts))


def _intersect(rels: list[tuple[list[int], list[int]]], n: int) -> Poset:
    """The order of the pairs in every relation of ``rels`` (each ``(above, below)``).  O(len(rels) × n)."""
    full = (1 << n) - 1
    above = [full & ~(1 << i) for i in range(n)]
    below = list(above)
    for up, down in rels:
        for i in range(n):
            above[i] &= up[i]
            below[i] &= down[i]
    return Poset(n, below, above)


def _relation(seq: tuple[str, ...], index: dict[str, int]) -> tuple[list[int], list[int]]:
    """The order of one sequence: ``above[a]``, the parts whose first unit comes after the last unit of
    ``a``, and ``below[b]``, the parts whose last unit comes before the first unit of ``b``.  O(len(seq))
    mask operations."""
    first: dict[int, int] = {}
    last: dict[int, int] = {}
    for pos, p in enumerate(seq):
        i = index[p]
        first.setdefault(i, pos)
        last[i] = pos
    by_first = sorted(first, key=first.__getitem__)
    starts = [first[i] for i in by_first]
    suffix = [0] * (len(by_first) + 1)                  # suffix[k]: the parts by_first[k:]
    for k in range(len(by_first) - 1, -1, -1):
        suffix[k] = suffix[k + 1] | 1 << by_first[k]
    by_last = sorted(last, key=last.__getitem__)
    ends = [last[i] for i in by_last]
    prefix = [0] * (len(by_last) + 1)                   # prefix[k]: the parts by_last[:k]
    for k, i in enumerate(by_last):
        prefix[k + 1] = prefix[k] | 1 << i
    above = [0] * len(index)
    below = [0] * len(index)
    for i in first:
        above[i] = suffix[bisect_right(starts, last[i])]
        below[i] = prefix[bisect_left(ends, first[i])]
    return above, below


def learn_plan(sequences, failed=(), *, name: str = "learned", max_accident: float = DEFAULT_MAX_ACCIDENT,
               time_limit: float | None = 20.0, max_memo: int | None = 2_000_000) -> LearnedPlan:
    """Learn the tightest single-strategy plan that admits every successful sequence (the constraints they
    all satisfy, as its cover relations), with each constraint's support and accident probability.

    Parameters
    ----------
    sequences : Sequences or iterable of sequences
        The successful sequences: a :class:`~opportune.formats.sequences.Sequences` (from
        :func:`read_sequences`), or sequences of part ids (a ``str`` is split on spaces and commas).
        All must install the same parts the same number of times (a repeated id: units of a part).
    failed : Sequences or iterable of sequences
        Failed sequences of the same parts (optional).
    name : str
        The learned plan's name.
    max_accident : float
        Constraints with a larger accident probability are *flagged* (kept in the plan: dropping one
        could admit sequences that failed).
    time_limit, max_memo : float or None, int or None
        Budget of the exact counts behind the accident probabilities: seconds for all of them, and
        new memo entries per count.  A probability over budget is None (``complete`` is False).

    Returns
    -------
    LearnedPlan
        The plan, each constraint's support and accident probability, the failed sequences with what
        they violate, and a two-strategy repair where one plan cannot exclude every failure.

    Raises
    ------
    SequenceError
        Sequences of different parts, an empty input or one over the limits (naming the line;
        :class:`~opportune.formats.sequences.SequenceError`).

    Complexity: the order is O(total length + distinct sequences × parts) mask operations; each
    accident probability is one exact count of linear extensions (per cover constraint: #P-hard in
    general, fast on the orders of real plans, bounded by ``time_limit``).

    Examples
    --------
    >>> learned = learn_plan(["a b c", "a c b"], failed=["b a c"])
    >>> learned.plan.strategies[0].pairs(), learned.constraints[0].confirmed
    ([('a', 'b'), ('a', 'c')], True)
    >>> learn_plan(["a b", "a c"])     # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    opportune.formats.sequences.SequenceError: error: sequence 2: unknown part 'c': ...
    """
    good = _as_sequences(sequences, None, "sequences")
    if not good.sequences:
        raise SequenceError(Problem("no sequences to learn from", "give at least one successful sequence, one per "
                                    "line", file=good.file, code="empty"))
    bad = _as_sequences(failed, good, "failed sequences")
    parts = list(good.quantities)
    index = {p: i for i, p in enumerate(parts)}
    order = learned_order(good.sequences, parts)
    covers = order.cover_pairs()
    n = len(good.sequences)
    plan = _plan(name, good.quantities, {"default": covers}, parts, good.file)

    chances, complete = _chances(order, covers, [good.quantities[p] for p in parts], time_limit, max_memo)
    success = set(good.sequences)
    failures, confirmed = [], {}
    for i, seq in enumerate(bad.sequences):
        rel = _relation(seq, index)[0]
        violates = tuple((parts[b], parts[a]) for b, a in covers if not rel[b] >> a & 1)
        failures.append(FailedSequence(seq, bad.where(i), violates, seq in success))
        for pair in violates:
            confirmed.setdefault(pair, []).append(bad.where(i))
    constraints = tuple(
        LearnedConstraint(parts[b], parts[a], n, chance,
                          None if chance is None else (math.exp(n * math.log(chance)) if chance > 0 else 0.0),
                          tuple(confirmed.get((parts[b], parts[a]), ())))
        for (b, a), chance in zip(covers, chances))
    learned = LearnedPlan(plan, constraints, n, len(success), tuple(failures), max_accident=max_accident,
                          complete=complete, source=good.file)
    open_ = [f for f in failures if not f.excluded]
    if not open_:
        return learned
    repair, note = _repair(good, parts, index, open_, name)
    return LearnedPlan(plan, constraints, n, len(success), tuple(failures), repair, note, max_accident, complete,
                       good.file)


def _as_sequences(items, like: Sequences | None, what: str) -> Sequences:
    """Checked :class:`Sequences` from a :class:`Sequences` or plain sequences (re-checked against ``like``)."""
    if isinstance(items, Sequences):
        if like is None:
            return items
        return sequences_from(zip(items.lines, items.sequences), file=items.file, like=like, what=what)
    listed = []
    for i, seq in enumerate(items, start=1):
        if isinstance(seq, str):
            seq = re.split(r"[\s,]+", seq.strip()) if seq.strip() else []
        listed.append((i, tuple(str(p) for p in seq)))
        if i > 100_000 + 1:     # let sequences_from refuse it with its message, without reading the rest
            break
    return sequences_from(listed, like=like, what=what)


def _unit_poset(quantities: list[int], pairs: Iterable[tuple[int, int]]) -> Poset:
    """The order on units (as the engine builds it): a part's units in a chain, and each constraint
    ``(b, a)`` from the last unit of ``b`` to the first unit of ``a``."""
    first, n = [], 0
    for q in quantities:
        first.append(n)
        n += q
    unit_pairs = [(first[i] + k, first[i] + k + 1) for i, q in enumerate(quantities) for k in range(q - 1)]
    unit_pairs += [(first[b] + quantities[b] - 1, first[a]) for b, a in pairs]
    return Poset.from_pairs(n, unit_pairs)


def _chances(order: Poset, covers: list[tuple[int, int]], quantities: list[int], time_limit: float | None,
             max_memo: int | None) -> tuple[list[float | None], bool]:
    """For each cover ``(b, a)``: ``e(P) / e(P - cover)``, the probability that a uniformly random
    admissible sequence of the order without that cover keeps ``b`` before ``a``.  One exact count per
    cover (plus one for ``P``); None for those past the budget."""
    deadline = None if time_limit is None else time.perf_counter() + time_limit
    out: list[float | None] = [None] * len(covers)

    def count(pairs) -> int | None:
        left = None if deadline is None else deadline - time.perf_counter()
        if left is not None and left <= 0:
            return None
        counter = Counter(_unit_poset(quantities, pairs), max_memo=max_memo, time_limit=left)
        try:
            return counter.count()
        except BudgetExceeded:
            return None

    whole = count(covers)
    if whole is None:
        return out, False
    log_whole = math.log(whole)
    lower: dict[int, list[int]] = {}
    upper: dict[int, list[int]] = {}
    for b, a in covers:
        upper.setdefault(b, []).append(a)
        lower.setdefault(a, []).append(b)
    for k, (b, a) in enumerate(covers):
        # P minus the one pair (b, a), every other relation kept: generated by the other covers plus
        # x -> a for each lower cover x of b, and b -> y for each upper cover y of a (a chain through
        # b -> a of two or more covers keeps a way round it; b -> a itself has none).
        pairs = covers[:k] + covers[k + 1:] + [(x, a) for x in lower.get(b, ())] + [(b, y) for y in upper.get(a, ())]
        e = count(pairs)
        if e is not None:
            out[k] = min(1.0, math.exp(log_whole - math.log(e)))
    return out, all(c is not None for c in out)


def _plan(name: str, quantities: dict, strategies: dict, parts: list[str], source: str | None) -> Plan:
    """A validated plan from part-index cover pairs per strategy."""
    from opportune.formats.loader import plan_from_dict

    doc: dict = {"name": name,
                 "parts": [p if quantities[p] == 1 else {"id": p, "quantity": quantities[p]} for p in parts]}
    if len(strategies) == 1:      # as written in the YAML: one strategy, under a top-level `requires`
        doc["requires"] = _requires(next(iter(strategies.values())), parts)
    else:
        doc["strategies"] = [{"name": s, "requires": _requires(pairs, parts)} for s, pairs in strategies.items()]
    plan = plan_from_dict(doc)
    return Plan(plan.name, plan.parts, plan.strategies, source, plan.description)


def _requires(pairs, parts: list[str]) -> dict[str, list[str]]:
    req: dict[int, list[int]] = {}
    for b, a in pairs:
        req.setdefault(a, []).append(b)
    return {parts[a]: [parts[b] for b in sorted(bs)] for a, bs in sorted(req.items())}


def _repair(good: Sequences, parts: list[str], index: dict[str, int], open_: list[FailedSequence],
            name: str) -> tuple[Plan | None, str]:
    """Two strategies that admit every success and exclude the failures ``open_`` (which the single learned
    order admits): the successes split by one constraint ``x -> y`` (those that satisfy it, and the rest),
    each group learned on its own.  Each group's order contains the single one, so failures it already
    excluded stay excluded; the split works when every one of ``open_`` breaks both groups' orders.

    Tries the constraints the first open failure breaks, most balanced split first; stops after
    ``MAX_REPAIR_WORK`` mask operations.  Returns ``(plan or None, note)``.
    """
    blocked = [f for f in open_ if f.succeeded]
    if blocked:
        return None, (f"no plan can exclude {blocked[0].where}: the same sequence is also among the successes")
    times: dict[tuple[str, ...], int] = {}
    for seq in good.sequences:
        times[seq] = times.get(seq, 0) + 1
    distinct = list(times)
    rels = [_relation(s, index) for s in distinct]
    frels = [_relation(f.sequence, index)[0] for f in open_]
    n, m = len(parts), len(distinct)
    stopped = (f"the search for two strategies stopped after {MAX_REPAIR_WORK:,} mask operations without finding "
               "a split by one constraint that excludes every failure")
    candidates, work = [], 0
    for x in range(n):
        for y in range(n):
            if x == y or frels[0][x] >> y & 1:       # the first open failure must break x -> y
                continue
            work += m
            if work > MAX_REPAIR_WORK:
                return None, stopped
            size = sum(r[0][x] >> y & 1 for r in rels)
            if 0 < size < m:
                candidates.append((-min(size, m - size), x, y))
    candidates.sort()
    for _, x, y in candidates:
        work += 2 * m * n
        if work > MAX_REPAIR_WORK:
            return None, stopped
        groups: tuple[list[int], list[int]] = ([], [])
        for k, r in enumerate(rels):
            groups[0 if r[0][x] >> y & 1 else 1].append(k)
        orders = [_intersect([rels[k] for k in g], n) for g in groups]
        if all(any(o.above[i] & ~fr[i] for i in range(n)) for o in orders for fr in frels):
            strategies = {f"{parts[x]}-before-{parts[y]}": orders[0].cover_pairs(),
                          f"not-{parts[x]}-before-{parts[y]}": orders[1].cover_pairs()}
            plan = _plan(name, good.quantities, strategies, parts, good.file)
            sizes = (sum(times[distinct[k]] for k in groups[0]),)
            sizes += (len(good.sequences) - sizes[0],)
            note = (f"two strategies exclude every failure: the {sizes[0]} successes with {parts[x]} before "
                    f"{parts[y]}, and the {sizes[1]} others, each learned on its own")
            return plan, note
    return None, ("no split of the successes by one constraint gives two strategies that exclude every failure "
                  "(more strategies, or more data, are needed)")


# ---------------------------------------------------------------- YAML with comments

_PLAIN = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")
_KEYWORDS = {"y", "n", "yes", "no", "on", "off", "true", "false", "null"}


def _scalar(text: str) -> str:
    """A YAML scalar for ``text``: plain when safe, else double-quoted with every other character escaped."""
    if _PLAIN.fullmatch(text) and text.lower() not in _KEYWORDS:
        return text
    out = []
    for c in text:
        o = ord(c)
        if c in '"\\':
            out.append("\\" + c)
        elif 0x20 <= o < 0x7F:
            out.append(c)
        else:
            out.append(f"\\u{o:04x}" if o <= 0xFFFF else f"\\U{o:08x}")
    return '"' + "".join(out) + '"'


def _number(p: float | None) -> str:
    if p is None:
        return "not computed (over the counting budget)"
    return f"{p:.3g}" if p >= 1e-3 or p == 0 else f"{p:.2e}"


def _yaml(learned: LearnedPlan, repaired: bool) -> str:
    plan = learned.repair if repaired else learned.plan
    src = f" from {learned.source}" if learned.source else ""
    lines = [f"# Learned by `opportune learn`{src}: {learned.sequences} successful sequence(s), "
             f"{learned.distinct} different.",
             "# Each constraint holds in every observed sequence; the comment beside it gives its support and its",
             "# accident probability: the chance that that many uniformly random admissible sequences of the plan",
             "# without this constraint would all satisfy it anyway (small: well supported).",
             f"# Flagged (!): accident probability above {learned.max_accident:g}; kept, since dropping a constraint",
             "# can admit sequences that fail."]
    if learned.failed:
        lines.append(f"# {len(learned.failed)} failed sequence(s) given; 'confirmed' constraints are broken by one.")
    if repaired:
        lines.append(f"# Repair: {learned.repair_note}.")
    lines.append(f"name: {_scalar(plan.name)}")
    parts = [(_scalar(p.id) if p.quantity == 1 else f"{{id: {_scalar(p.id)}, quantity: {p.quantity}}}")
             for p in plan.parts]
    lines.append(f"parts: [{', '.join(parts)}]")
    info = {(c.before, c.after): c for c in learned.constraints}

    def requires(strategy, indent: str) -> list[str]:
        out = []
        for after, befores in strategy.requires.items():
            out.append(f"{indent}{_scalar(after)}:")
            for before in befores:
                c = info.get((before, after))
                note = ""
                if c is not None and not repaired:
                    flag = (c.accident_probability is not None and c.accident_probability > learned.max_accident)
                    note = (f"  # {'! ' if flag else ''}support {c.support}/{learned.sequences}, accident "
                            f"{_number(c.accident_probability)}" + ("; confirmed by a failure" if c.confirmed else ""))
                out.append(f"{indent}  - {_scalar(before)}{note}")
        return out or [f"{indent[:-2]}  {{}}"]

    if len(plan.strategies) == 1:
        body = requires(plan.strategies[0], "  ")
        if body[0].strip() == "{}":
            lines.append("requires: {}            # no constraint holds in every sequence: any order")
        else:
            lines.append("requires:            # X: parts that must be installed before X")
            lines += body
    else:
        lines.append("strategies:")
        for s in plan.strategies:
            lines.append(f"  - name: {_scalar(s.name)}")
            body = requires(s, "      ")
            if body[0].strip() == "{}":
                lines.append("    requires: {}")
            else:
                lines.append("    requires:")
                lines += body
    return "\n".join(lines) + "\n"


def dumps(learned: LearnedPlan) -> str:
    """``learned.to_json()`` as indented JSON text."""
    return json.dumps(learned.to_json(), indent=2, ensure_ascii=False)
