"""Exact counting of linear extensions by recursive decomposition, with a lifelong memo.

The number ``e(S)`` of linear extensions of the subposet induced on a set ``S``
obeys three rules, applied in this order (Kangas, Hankala, Niinimäki &
Koivisto, "Counting linear extensions of sparse posets", IJCAI 2016, plus the
classical ordinal-sum rule):

1. **Cut elements.**  If some elements of ``S`` are comparable to every other
   element of ``S`` (they form a chain ``z1 < ... < zk``), ``S`` is the ordinal
   sum ``B0 ⊕ z1 ⊕ B1 ⊕ ... ⊕ zk ⊕ Bk`` and ``e(S) = e(B0) ... e(Bk)``.
2. **Components.**  If the comparability graph of ``S`` falls into connected
   pieces ``C1..Ck``, the pieces interleave freely:
   ``e(S) = |S|! / (|C1|! ... |Ck|!) * e(C1) ... e(Ck)``.
3. **First element.**  Otherwise ``e(S) = sum over minimal x of e(S - {x})``.

(A set with a cut element is connected, so the order of rules 1 and 2 does not
change which sets are visited.)  Both tests are bit-parallel: one pass over
``S``, a table look-up per chunk of its bits, finds the cut elements and the
minimal elements.  The components are the overlap classes of the up-sets
``{m} ∪ (above(m) ∩ S)`` of the minimal elements ``m`` — every comparable pair
lies in one of them — so a connected set costs O(width²) mask operations, not
a search of its comparability graph.  A poset of at most 48 elements, once its
counter has done some work, scans in three look-ups instead (chunks of up to
16 bits), which also give the elements comparable to nothing else in ``S``;
the other components grow from a top element by closure steps of three
look-ups each.  Both ways visit the pieces in the same order.

Every value is memoised on the set, as a Python int, for the whole life of the
:class:`Counter`: the subproblems of a count are exactly the questions a
simulation asks next (the remaining parts after one more installation), so
later calls are mostly dictionary lookups.  Rule 3 only ever removes minimal
elements, so the subproblems of an up-set are up-sets: the memo is keyed on
"what is still to do".

**Position sums** are memoised the same way, one vector per set, computed by a
forward recursion on the same decomposition (each rule has a matching rule for
the vector: see :meth:`Counter.position_sums`).  A new set reuses the vectors
of its components, blocks and one-smaller sets seen before, so a query for a
remaining set that differs from a seen one by one installation costs a few new
vectors, not a pass over its whole decomposition.  A vector is stored as one
Python int with a fixed-width field per element (element ``i`` in bits
``i*W .. i*W+W-1``): adding two vectors or scaling one by an integer is then a
single big-int operation.

Without rules 1–2 this is the classical dynamic programme over the lattice of
down-sets (:mod:`opportune.engine.downsets`); with them the number of memo
entries is usually far smaller (KILBRID: 626,575 down-sets, ~3,200 entries).

**A method per hard piece.**  A count first runs plainly for a probe of
``Counter.probe`` new entries (8,192), which settles everything easy.  If
that is not enough, the set is split by rules 1–2 into its connected pieces
without cut elements, and each piece still unknown gets the cheapest of three
exact methods, found by running them in turns on doubling shares of the
budget (see :meth:`Counter._count_piece`): the recursion above; the same
recursion on the reversed order (removing *last* elements: ``e(S)`` is the
same, the sets visited are not — on random sparse orders either direction
can be 3–35 times cheaper); and the dynamic programme over down-sets when the
piece has few enough of them (a bounded count tells).  All three store exact
values in the one memo, so the memo semantics are unchanged: a value is the
count of its set, whichever way it was found.  ``Counter.methods`` counts the
pieces each method finished.  Pure Python pays for every memo entry in
interpreted big-int operations, so the compiled core
(:mod:`opportune.engine.native`) runs the recursion wherever it is built;
docs/counting.md gives the measured times of both, beside the C++ peers'.
"""

from __future__ import annotations

import sys
import time
from itertools import islice
from math import factorial

from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline, recursion_room  # noqa: F401 (BudgetExceeded: its documented import)
from opportune.engine.poset import LazyMeet as _LazyMeet
from opportune.engine.poset import LazyUnion as _LazyUnion
from opportune.engine.poset import Poset, bits, components, cut_blocks, cut_chain, split_components
from opportune.engine.tuning import (
    OTHER_SHARE, MAX_TOTAL, CHECK_EVERY as _CHECK_EVERY, NARROW_UP_TO as _NARROW, BYTE_TABLES_UP_TO as
    _WIDE, EVICT_CHUNK, PIECE_PROBE as _PROBE, DP_COST as _DP_COST, IDEAL_PROBE as _IDEAL_PROBE, DP_MAX_N
    as _DP_MAX_N)

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Callable

__all__ = ["BudgetExceeded", "Counter", "count_linear_extensions", "entries_within"]



def _check_every(n: int) -> int:
    """New memo entries between clock checks: fewer on large posets, whose entries cost O(n) big-int
    operations each (between two checks at the usual rate, a 1,000-element poset would do 256,000 of them:
    a deadline would be missed by that)."""
    every = _CHECK_EVERY
    while every > 1 and every * n > 16_384:
        every //= 2
    return every

_INF = float("inf")


class _Factorials(dict):
    """``k -> k!``, each computed when first needed (a 10,000-element chain needs none of them)."""

    def __missing__(self, k: int) -> int:
        v = self[k] = factorial(k)
        return v



class Counter:
    """Linear-extension counter for one Poset; keeps its memo for its whole life.

    Parameters
    ----------
    poset : Poset
        The order whose linear extensions are counted (its subsets by bitmask).
    max_memo : int or None
        Most *new* memo entries (counts plus position-sum vectors) one call of
        :meth:`count` / :meth:`position_sums` may add (None: unlimited).  A call
        that would add more raises :class:`BudgetExceeded`; what it stored so
        far stays, so the same call with a larger budget continues from there.
        Entries stored by earlier calls never count against a call.
    time_limit : float or None
        Most seconds one call of :meth:`count` / :meth:`position_sums` may
        spend computing (None: unlimited).  The attribute ``deadline`` (a
        :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()``
        value, default None) stops every call at that moment as well, and each
        call takes the caller's own ``deadline=``: the soonest of the three
        wins.  Everything a call builds or calls (the reversed view, the
        down-set programme, hub terms) runs under that same moment.
    max_total : int or None
        Memory cap on the memo as a whole (counts plus vectors; None:
        unlimited).  It never makes a call fail: when a call that has to
        compute something starts with more than ``max_total`` entries held, the
        oldest entries are evicted until half remain (later calls recompute
        them if needed).  One call can still add up to ``max_memo`` entries on
        top, so the memo holds at most about ``max_total + max_memo`` entries.
        The default, 2,000,000, bounds memory like the old lifetime
        ``max_memo`` did, without ever failing because of the memo's age.

    native : bool or None
        Run the recursion in the compiled core (:mod:`opportune.engine.native`)
        when it is built and the order has at most 1,024 elements (None, the
        default), or never (False).  Results are the same exact integers; the
        compiled memo holds the counts of every set the recursion visits, the
        Python memo only those asked for.

    Notes
    -----
    All three budgets are plain attributes and may be changed between calls; the memo
    survives a :class:`BudgetExceeded`.

    Complexity: each memo entry costs O(|S|) big-int operations plus one
    addition or multiplication per child.  The number of entries is at most the
    number of connected up-sets of the poset, usually much less; a repeated
    query is a single dictionary lookup.

    Examples
    --------
    >>> p = Poset.from_pairs(4, [(0, 1), (2, 3)])   # two independent chains
    >>> c = Counter(p)
    >>> c.count()                                     # 4! / (2! 2!)
    6
    >>> c.count(0b0111)                               # elements 0, 1, 2
    3
    >>> c.position_sums(0b0111)                       # 0 is at 1,1,2; 1 at 2,3,3; 2 at 3,2,1
    {0: 4, 1: 8, 2: 6}
    """

    def __init__(self, poset: Poset, *, max_memo: int | None = 2_000_000, time_limit: float | None = None,
                 max_total: int | None = MAX_TOTAL, native: bool | None = None):
        self.poset = poset
        self._native = None
        self._direction = 0                     # 1 for the reversed view (see _reverse)
        if native is not False:
            from opportune.engine.native import MAX_BYTES, entry_bytes, native_counter
            self._native = native_counter(poset, max_total)
            if self._native is not None and max_total is not None and max_total > MAX_TOTAL:
                # a counter made to hold more entries than usual holds their bytes too
                self._native.max_bytes = max(MAX_BYTES, max_total * entry_bytes(poset.n))
        self.max_memo = max_memo
        self.time_limit = time_limit
        self.max_total = max_total
        self._memo: dict[int, int] = {0: 1}
        self._vec: dict[int, int] = {}          # set -> packed position-sum vector (field width self._width)
        self._width = 0
        # [new-entry limit, deadline, new entries in this call]
        self._budget: list = [sys.maxsize, float("inf"), 0]
        self._depth = 3 * poset.n + 200          # recursion depth a count may need
        self._room = recursion_room(self._depth)   # given to each top-level count, and put back after
        # Chunk tables (see _narrow_tables) take about as long to build as 2^c / 16 memo entries take
        # to compute with byte tables (KILBRID: ~8 ms): switch to them once the memo is that large, so
        # one-shot counters never pay for them.
        c = max(1, -(-poset.n // _chunks(poset.n)))
        self._narrow_after = 1 << max(0, c - 4) if poset.n <= _NARROW else sys.maxsize
        self._f = self._make_counter()
        self._g: Callable[[int], int] | None = None
        #: New memo entries a count spends plainly before its hard pieces get a method each (see
        #: :meth:`_count_piece`); a plain attribute, like the budgets.
        self.probe = _PROBE
        #: A ``time.perf_counter()`` value past which every call stops too (None: none), whatever
        #: ``time_limit`` says: one deadline for all the counts of a caller.
        self.deadline: float | None = None
        #: How many hard pieces each method has finished so far: ``up`` (the recursion), ``down`` (the
        #: recursion on the reversed order), ``downsets`` (the dynamic programme over down-sets).
        self.methods: dict[str, int] = {}
        self._rev: Counter | None = None
        #: While True (an engine sets it for the span of a decision), a call never evicts or restarts
        #: the memo, however large: :meth:`maintain`, between decisions, does (a call's growth is
        #: bounded by its budget, so the memo overshoots ``max_total`` by at most one decision's work).
        self.hold_upkeep = False
        self._shares: dict[int, int] = {}       # hard piece -> its methods' share of new entries next time
        self._ideals: dict[int, int | None] = {}    # hard piece -> its number of down-sets (None: very many)

    # ------------------------------------------------------------------ public API
    def count(self, mask: int | None = None, *, deadline: Deadline | float | None = None) -> int:
        """Exact number of linear extensions of the subposet induced on ``mask`` (default: all).

        ``mask`` may be any subset; in practice it is usually an up-set (what
        remains to be done).  A mask seen before is answered by one dictionary
        lookup.  Raises :class:`BudgetExceeded` if this call would add more
        than ``max_memo`` memo entries, take more than ``time_limit`` seconds,
        or pass ``deadline`` (a :class:`~opportune.engine.deadline.Deadline`, or a
        ``time.perf_counter()`` moment; the soonest of it, ``time_limit`` and the
        attribute ``deadline`` stops the call).  Every loop of a call whose
        length depends on the order reads the clock, so a call ends within a
        few milliseconds of its deadline on orders of up to 10,000 elements.

        Parameters
        ----------
        mask : int or None
            The set, a bitmask of the order's elements (None: all of them).
        deadline : Deadline, float or None
            When this call must stop, besides ``time_limit`` and the attribute ``deadline``.

        Returns
        -------
        int
            The exact number of linear extensions of the subposet on ``mask``.

        Raises
        ------
        BudgetExceeded
            When the call would add more than ``max_memo`` entries or pass its deadline (what it
            stored stays: the same call with more budget continues from there).
        ValueError
            When ``mask`` is not a subset of the order's elements.

        Examples
        --------
        >>> Counter(Poset.antichain(3)).count()
        6
        >>> Counter(Poset.chain(3)).count(0b101)
        1
        >>> fence = Poset.from_pairs(12, [(i, i + 1) if i % 2 == 0 else (i + 1, i) for i in range(11)])
        >>> c = Counter(fence, max_memo=20)                 # a zigzag of 12: more than 20 sets to count
        >>> try:
        ...     c.count()
        ... except BudgetExceeded as exc:
        ...     print(exc.reason)
        memo
        >>> c.max_memo = None; c.count()                    # goes on from what it stored
        2702765
        """
        r = self._memo.get(mask)
        if r is not None:
            return r
        return self._count_miss(mask, deadline)

    __call__ = count

    def position_sums(self, mask: int | None = None, *, deadline: Deadline | float | None = None) -> dict[int, int]:
        """For every element ``x`` of ``mask``: the sum over all linear extensions of the 1-based position of ``x``.

        ``position_sums(mask)[x] / count(mask)`` is the expected position of
        ``x`` in a uniformly random linear extension.  Exact ints.

        The vector ``P(S)`` of a set is computed from those of its parts by the
        rule :meth:`count` uses for ``S``, and memoised:

        * cut elements ``B0 ⊕ z1 ⊕ B1 ⊕ ...``: an element of block ``Bj`` with
          ``o`` elements before the block has ``P(S)[x] = e(S)/e(Bj) P(Bj)[x] + o e(S)``;
          the cut element after ``o`` elements has ``(o + 1) e(S)``;
        * components: an element of a component ``C`` of ``k`` elements in a
          set of ``n`` has ``P(S)[x] = e(S)/e(C) P(C)[x] (n + 1)/(k + 1)`` (the
          ``j``-th of ``k`` random positions among ``n`` is at ``j (n+1)/(k+1)``
          on average);
        * first element: ``P(S)[y] = e(S) + sum over minimal x != y of P(S - x)[y]``.

        Each new set costs O(children) big-int operations on packed vectors;
        sets seen by earlier calls cost nothing.

        Parameters
        ----------
        mask : int or None
            The set, a bitmask of the order's elements (None: all of them).
        deadline : Deadline, float or None
            When this call must stop, as for :meth:`count`.

        Returns
        -------
        dict of int to int
            Element → the sum of its positions over all linear extensions of ``mask``.

        Raises
        ------
        BudgetExceeded
            Like :meth:`count` (vectors count as memo entries).
        ValueError
            When ``mask`` is not a subset of the order's elements.

        Examples
        --------
        >>> Counter(Poset.from_pairs(3, [(0, 1)])).position_sums()     # 012, 021, 201
        {0: 4, 1: 8, 2: 6}
        >>> Counter(Poset.chain(3)).position_sums(0b110)
        {1: 1, 2: 2}
        """
        if mask is None:
            mask = self.poset.full
        self._check_mask(mask)
        if mask == 0:
            return {}
        width = self._width
        v = self._vec.get(mask)
        if v is None:
            with self._room:
                self._start_budget(deadline)
                es = self._memo.get(mask)
                if es is None:
                    es = self._f(mask) if mask & (mask - 1) else 1
                if self._g is None or self._need_width(es) > width:
                    self._set_width(self._need_width(es))
                    width = self._width
                v = self._g(mask)
        # fields cut from the bytes once (fields are whole bytes): a shift of the whole vector per
        # element is quadratic, a large share of a second on an order of 1,000 elements
        wb = width // 8
        raw = v.to_bytes(max(1, mask.bit_length()) * wb, "little")
        return {i: int.from_bytes(raw[i * wb:(i + 1) * wb], "little") for i in bits(mask)}

    def expected_positions(self, mask: int | None = None, *,
                           deadline: Deadline | float | None = None) -> dict[int, float]:
        """Expected 1-based position of each element of ``mask`` in a uniformly random linear extension.

        ``position_sums(mask)[x] / count(mask)``, as a float.

        Parameters
        ----------
        mask : int or None
            The set, a bitmask of the order's elements (None: all of them).
        deadline : Deadline, float or None
            When this call must stop, as for :meth:`count`.

        Returns
        -------
        dict of int to float
            Element → its expected position (1 = first).

        Raises
        ------
        BudgetExceeded
            Like :meth:`count`.

        Examples
        --------
        >>> Counter(Poset.from_pairs(3, [(0, 1)])).expected_positions()
        {0: 1.3333333333333333, 1: 2.6666666666666665, 2: 2.0}
        """
        if mask is None:
            mask = self.poset.full
        total = self.count(mask, deadline=deadline)
        return {x: _ratio(s, total) for x, s in self.position_sums(mask, deadline=deadline).items()}

    def sample(self, rng, mask: int | None = None, *, deadline: Deadline | float | None = None) -> list[int]:
        """A uniformly random linear extension of ``mask`` (exact; ``rng`` is a :class:`random.Random`).

        Chooses the first element ``x`` with probability ``e(S - x) / e(S)``,
        then recurses.  O(|mask| × width) memo lookups, after :meth:`count`.

        Parameters
        ----------
        rng : random.Random
            The random stream (seeded by the caller).
        mask : int or None
            The set, a bitmask of the order's elements (None: all of them).
        deadline : Deadline, float or None
            Bounds the counts it needs, and is read at every step.

        Returns
        -------
        list of int
            The elements of ``mask`` in the order drawn.

        Raises
        ------
        BudgetExceeded
            Like :meth:`count`, or past ``deadline`` between steps.

        Examples
        --------
        >>> import random
        >>> Counter(Poset.chain(3)).sample(random.Random(1))
        [0, 1, 2]
        >>> c, rng = Counter(Poset.from_pairs(3, [(0, 1)])), random.Random(2)
        >>> draws = [tuple(c.sample(rng)) for _ in range(3000)]         # 012, 021, 201: a third each
        >>> {d: abs(draws.count(d) - 1000) < 120 for d in sorted(set(draws))}
        {(0, 1, 2): True, (0, 2, 1): True, (2, 0, 1): True}
        """
        if mask is None:
            mask = self.poset.full
        below = self.poset.below
        out = []
        s = mask
        dl = as_deadline(deadline)
        while s:
            dl.check("sampling a linear extension")
            total = self.count(s, deadline=dl)
            r = rng.randrange(total)
            m = s
            while m:
                b = m & -m
                m ^= b
                i = b.bit_length() - 1
                if below[i] & s:
                    continue
                v = self.count(s ^ b, deadline=dl)
                if r < v:
                    break
                r -= v
            out.append(i)
            s ^= b
        return out

    def cached(self, mask: int) -> int | None:
        """The count of ``mask`` if it is in the memo, else None (never computes).

        Parameters
        ----------
        mask : int
            The set, a bitmask of the order's elements.

        Returns
        -------
        int or None
            The stored exact count (from the Python memo or the compiled one), or None.

        Examples
        --------
        >>> c = Counter(Poset.antichain(2))
        >>> c.cached(0b11), c.count(0b11), c.cached(0b11)
        (None, 2, 2)
        """
        r = self._memo.get(mask)
        if r is None and self._native is not None and mask.__class__ is int and 0 <= mask <= self.poset.full:
            r = self._native.lookup(mask)
        return r

    @property
    def compiled(self) -> bool:
        """True when this counter runs its recursion in the compiled core."""
        return self._native is not None

    def learn(self, mask: int, value: int) -> None:
        """Store the exact count ``value`` of ``mask`` found by another exact method (see :mod:`.hub`).

        Later counts that meet ``mask`` as a piece use it instead of recursing.

        Parameters
        ----------
        mask : int
            The set, a bitmask of the order's elements.
        value : int
            Its exact number of linear extensions.

        Raises
        ------
        ValueError
            When ``mask`` is not a subset of the order's elements.

        Examples
        --------
        >>> c = Counter(Poset.from_pairs(4, [(0, 1), (2, 3)]))
        >>> c.learn(0b0111, 3); c.cached(0b0111), c.count()
        (3, 6)
        """
        self._check_mask(mask)
        self._memo[mask] = value
        if self._native is not None:
            self._native.put(mask, value)

    def scan(self, mask: int) -> tuple[int, int]:
        """``(minimal elements, cut elements)`` of ``mask``: a cut element is comparable to every other element.

        Bit-parallel (a table look-up per byte of ``mask``); the recursions of
        this package use it to split a set before they recurse.

        Parameters
        ----------
        mask : int
            The set, a bitmask of the order's elements.

        Returns
        -------
        tuple of (int, int)
            The minimal elements of ``mask`` and its cut elements, as bitmasks.

        Examples
        --------
        >>> Counter(Poset.from_pairs(3, [(0, 1), (0, 2)])).scan(0b111)   # 0 is minimal and a cut
        (1, 1)
        """
        nbytes, UP, CAP = self._tables()
        up = 0
        cap = -1
        for tu, tc, byte in zip(UP, CAP, mask.to_bytes(nbytes, "little")):
            if byte:
                up |= tu[byte]
                cap &= tc[byte]
        return mask & ~up, mask & cap

    @property
    def memo_size(self) -> int:
        """Number of entries in the memo (counts plus position-sum vectors)."""
        return len(self._memo) + len(self._vec) + (self._native.size() if self._native is not None else 0)

    def entries(self) -> int:
        """What :meth:`shrink` keeps a share of: :attr:`memo_size`.  O(1).

        Returns
        -------
        int
            Entries held (counts plus position-sum vectors, the compiled memo's included).

        Examples
        --------
        >>> c = Counter(Poset.antichain(3), native=False); _ = c.count(0b011)
        >>> c.entries() == c.memo_size == 2                  # the empty set's count and 0b011's
        True
        """
        return self.memo_size

    def nbytes(self) -> int:
        """Estimated bytes this counter holds: memo, vectors, compiled memo, scan tables, its order and
        the reversed view's (see :mod:`opportune.engine.memory`; O(1) in the memo's size).

        Returns
        -------
        int
            Estimated bytes.

        Examples
        --------
        >>> c = Counter(Poset.from_pairs(3, [(0, 1)])); c.count() == 3 and c.nbytes() > 0
        True
        """
        from opportune.engine.memory import nbytes, poset_nbytes

        total = nbytes(self._memo) + nbytes(self._vec) + poset_nbytes(self.poset)
        if self._native is not None:
            total += self._native.memory()
        for tables in (getattr(self, "_tabs", None), getattr(self, "_ntabs", None)):
            if tables is not None:
                total += nbytes(tables, depth=4)
        if self._rev is not None:           # shares this memo: its own order and tables only
            total += poset_nbytes(self._rev.poset) + nbytes(getattr(self._rev, "_tabs", None), depth=4)
        return total

    def maintain(self, deadline: float = _INF) -> bool:
        """Keep the memo within ``max_total``: evict the oldest half if it is over, restart the compiled
        memo if it is over (entries or bytes).  True if anything was dropped.

        Every call does it at its start unless ``hold_upkeep`` is set (evicting then stops at the call's
        deadline, ``BudgetExceeded``); an engine that holds it during decisions calls this between them
        (no deadline: the upkeep finishes).  Complexity: O(1) when under the caps, else O(entries
        dropped).

        Parameters
        ----------
        deadline : float
            A ``time.perf_counter()`` moment past which evicting stops (default: never).

        Returns
        -------
        bool
            True if anything was dropped.

        Raises
        ------
        BudgetExceeded
            Past ``deadline`` while evicting (what is left is valid; the next upkeep goes on).

        Examples
        --------
        >>> c = Counter(Poset.antichain(3), max_total=1, native=False); _ = c.count(0b011), c.count(0b101)
        >>> c.maintain(), c.memo_size
        (True, 1)
        """
        limit = self.max_total
        dropped = False
        if limit is not None and len(self._memo) + len(self._vec) > limit:
            self._evict(limit // 2, deadline)
            dropped = True
        if self._native is not None and self._native.over(limit):
            self._native.reset()        # the compiled memo starts again (Python's keeps what it holds)
            dropped = True
        elif self._native is not None and self.hold_upkeep is False:
            reserve = getattr(self._native._core, "reserve", None)
            if reserve is not None:     # a table over 40% full doubles now, not at 50% within a decision
                reserve(self._native.size() // 4)
        return dropped

    def clear(self) -> None:
        """Forget every memoised value (frees memory; later calls recompute).

        Examples
        --------
        >>> c = Counter(Poset.antichain(3)); c.count()
        6
        >>> c.clear(); c.cached(0b111) is None, c.count()
        (True, 6)
        """
        if self._native is not None:
            self._native.reset()
        self._memo.clear()
        self._memo[0] = 1
        self._vec.clear()
        self._shares.clear()

    def __repr__(self) -> str:
        return f"<Counter n={self.poset.n} memo={len(self._memo)} vectors={len(self._vec)}>"

    # ------------------------------------------------------------------ internals
    def _check_mask(self, mask) -> None:
        if not isinstance(mask, int) or mask < 0 or mask & ~self.poset.full:
            raise ValueError(f"mask {mask!r} is not a subset of 0..{self.poset.n - 1}")

    def _start_budget(self, deadline: Deadline | float | None = None) -> None:
        """Start the budget of one top-level call (evict if the memo is over ``max_total``;
        switch to chunk-table scans once the memo shows they pay).

        The call stops at the soonest of ``deadline`` (the caller's), ``time_limit`` from now and
        the attribute ``deadline``."""
        b = self._budget
        limit = self.max_memo
        b[0] = limit if limit is not None else sys.maxsize
        limit = self.time_limit
        b[1] = time.perf_counter() + limit if limit is not None else _INF
        for d in (self.deadline, deadline):
            if d is not None:
                at = d.at if d.__class__ is Deadline else as_deadline(d).at
                if at < b[1]:
                    b[1] = at
        b[2] = 0
        if not self.hold_upkeep:
            self.maintain(b[1])
        self._maybe_narrow()

    def _maybe_narrow(self) -> None:
        """Switch to chunk-table scans once the memo is large enough for them to pay."""
        if self._native is None and len(self._memo) >= self._narrow_after:
            self._narrow_after = sys.maxsize
            self._narrow_tables()
            self._f = self._make_counter()
            if self._g is not None:
                self._g = self._make_vectors()

    def shrink(self, keep: float = 0.0, deadline: Deadline | float | None = None) -> None:
        """Between calls: drop all but the newest ``keep`` share (0 to 1) of the memo's entries, vectors
        first, and restart the compiled memo (tail memos included) unless ``keep`` is 1.  What an engine
        over its memory limit does.  Past ``deadline``, :class:`BudgetExceeded` (what is left is
        valid).  O(entries dropped).

        Parameters
        ----------
        keep : float
            The share of entries kept, newest first (0 to 1).
        deadline : Deadline, float or None
            When dropping must stop (None: never).

        Raises
        ------
        ValueError
            When ``keep`` is not from 0 to 1.
        BudgetExceeded
            Past ``deadline`` (what is left is valid).

        Examples
        --------
        >>> c = Counter(Poset.antichain(4), native=False); _ = c.count(0b0111), c.count(0b1110)
        >>> c.shrink(0.0); c.memo_size, c.count(0b0111)
        (1, 6)
        """
        if not 0 <= keep <= 1:
            raise ValueError("keep is a share, from 0 to 1")
        if self._native is not None and keep < 1:
            self._native.reset()
        self._shares.clear()
        self._evict(int(keep * (len(self._memo) + len(self._vec))), as_deadline(deadline).at)

    def _evict(self, keep: int, deadline: float) -> None:
        """Drop the oldest entries (insertion order) until at most ``keep`` remain in all.

        Dropping a million entries takes a large share of a second: it drops them in chunks of
        :data:`EVICT_CHUNK`, reads the call's clock (``deadline``) after each and, past it, raises
        :class:`BudgetExceeded` (what is left is valid; the next call goes on evicting).  Only the
        chunk at hand is listed, so a drop spread over many calls is O(entries dropped) in all."""
        memo, vec = self._memo, self._vec
        drop = len(memo) + len(vec) - keep
        perf = time.perf_counter
        # Vectors are the larger entries: drop them first, then the oldest counts (never the empty set's).
        for table, floor in ((vec, 0), (memo, 1)):
            while drop > 0 and len(table) > floor:
                chunk = list(islice(table, min(drop, EVICT_CHUNK) + floor))
                for key in chunk:
                    if drop <= 0:
                        break
                    if key or table is vec:
                        del table[key]
                        drop -= 1
                if table is memo:
                    memo[0] = 1
                if perf() > deadline:
                    raise BudgetExceeded("evicting old entries exceeded the time limit", reason="time",
                                         memo_size=len(memo) + len(vec))

    def _count_miss(self, mask: int | None, deadline: Deadline | float | None = None) -> int:
        if mask is None:
            mask = self.poset.full
            r = self._memo.get(mask)
            if r is not None:
                return r
        if mask.__class__ is not int or mask < 0 or mask & ~self.poset.full:
            self._check_mask(mask)
        if mask & (mask - 1) == 0:
            return 1
        with self._room:
            return self._count_deep(mask, deadline)

    def _count_deep(self, mask: int, deadline: Deadline | float | None) -> int:
        """:meth:`_count_miss` past its look-ups (within the recursion's room)."""
        self._start_budget(deadline)
        b = self._budget
        limit = b[0]
        if limit - b[2] <= self.probe:
            return self._f(mask)
        b[0] = b[2] + self.probe
        try:
            return self._f(mask)
        except BudgetExceeded as exc:
            if exc.reason != "memo" or b[0] >= limit:
                raise
        finally:
            b[0] = limit
        # Not done within the probe: count each hard piece by the method chosen for it, then the whole
        # from the memo (the decomposition of what the probe finished is all look-ups).
        for piece in self._hard_pieces(mask):
            self._count_piece(piece)
        return self._f(mask)

    def _late(self, what: str = "exact count") -> None:
        """Raise :class:`BudgetExceeded` (reason ``"time"``) once the current call's deadline has passed."""
        if time.perf_counter() > self._budget[1]:
            raise BudgetExceeded(f"{what} exceeded its time limit", reason="time", memo_size=self.memo_size)

    # ------------------------------------------------------------------ choosing a method per piece
    def _hard_pieces(self, mask: int) -> list[int]:
        """The connected pieces without cut elements that ``mask`` splits into by rules 1-2 and that
        are not in the memo (largest first)."""
        known = self._known
        below, above = self.poset.below, self.poset.above
        split = self._make_split()
        out = []
        stack = [mask]
        while stack:
            s = stack.pop()
            if s & (s - 1) == 0 or known(s):
                continue
            self._late()            # each split scans the set: O(n) on a large order
            chain, comps, iso, _ = split(s)
            if chain is not None:
                rest = s
                for z in chain:
                    stack.append(rest & below[z])
                    rest &= above[z]
                stack.append(rest)
            elif iso or len(comps) > 1:
                stack.extend(comps)
            else:
                out.append(s)
        out.sort(key=int.bit_count, reverse=True)
        return out

    def _count_piece(self, s: int) -> None:
        """Put ``e(s)`` in the memo, for a connected piece the plain recursion did not finish within its probe.

        Three exact methods share the call's budget:

        * ``up``: the recursion as everywhere (remove a minimal element);
        * ``down``: the same recursion on the reversed order (remove a maximal
          element), with the same memo — ``e(s)`` does not depend on the
          direction, but the sets visited do, often by a factor of 3-20 on
          sparse orders, and neither direction is reliably the better one;
        * ``downsets``: the dynamic programme over the down-sets of ``s``
          (:func:`~opportune.engine.downsets.upset_counts`), when it has few
          enough of them: no decomposition, but each down-set costs about
          half a memo entry of the recursion.

        The two directions run in turns, each resuming from what it stored
        before, with doubling shares of new entries (the direction with fewer
        extremal elements first, with sixteen times the other's share: the
        transpose heuristic of Kangas et al.'s ``lecount``); the
        down-set count of ``s`` (bounded, cheap) decides when the programme
        is no dearer than the next turn, and then it finishes the piece.  So a
        piece costs about 1.06 times the guessed direction's count when the
        guess is right, and at most about 34 times its cheapest method when it
        is wrong.
        """
        from opportune.engine.downsets import count_downsets_bounded, upset_counts

        memo = self._memo
        b = self._budget
        limit = b[0]
        poset = self.poset
        self._maybe_narrow()
        ups = self._f
        downs = self._reverse()._f
        mins = poset.minimal(s).bit_count()
        maxs = poset.maximal(s).bit_count()
        # the direction with fewer extremal elements first, with sixteen times the other's share (on 24
        # random sparse orders of 40 elements it was the cheaper one 20 times; the costs differed up
        # to 35-fold; on 24 of 48 elements a sixteenth, not a quarter, saved 9% of the entries in all
        # and cost more on none)
        other = 1.0 if mins == maxs else OTHER_SHARE
        order = [("up", ups, 1.0), ("down", downs, other)]
        if mins > maxs:
            order = [("down", downs, 1.0), ("up", ups, other)]
        ideals = self._ideals.get(s, 0)
        if ideals == 0:
            ideals = (count_downsets_bounded(poset, s, limit=_IDEAL_PROBE, deadline=b[1])
                      if s.bit_count() <= _DP_MAX_N else None)
            if ideals is None and time.perf_counter() > b[1]:   # cut by the deadline: not "too many"
                raise BudgetExceeded("exact count exceeded its time limit", reason="time", memo_size=self.memo_size)
            self._ideals[s] = ideals
        share = self._shares.get(s, max(2, self.probe))
        while s not in memo:
            for name, run, part in order:
                if ideals is not None and ideals * _DP_COST <= share and ideals <= limit - b[2]:
                    found = upset_counts(poset, s, keep=1, deadline=b[1], max_sets=ideals)
                    if found is None:
                        raise BudgetExceeded("exact count exceeded its time limit", reason="time",
                                             memo_size=self.memo_size)
                    value, top = found
                    for u, v in top.items():
                        if u not in memo:
                            memo[u] = v
                            if self._native is not None:
                                self._native.put(u, v)
                            b[2] += 1
                    self.methods["downsets"] = self.methods.get("downsets", 0) + 1
                    return
                b[0] = min(limit, b[2] + int(share * part))
                try:
                    run(s)
                except BudgetExceeded as exc:
                    if exc.reason != "memo" or b[0] >= limit:
                        raise
                    continue
                finally:
                    b[0] = limit
                self.methods[name] = self.methods.get(name, 0) + 1
                self._shares.pop(s, None)
                return
            share *= 2
            self._shares[s] = share

    def _known(self, s: int) -> bool:
        """Whether the count of ``s`` is in a memo (never computes)."""
        return s in self._memo or (self._native is not None and self._native.lookup(s) is not None)

    def _reverse(self) -> "Counter":
        """A counter of the reversed order that shares this one's memo and budget (see :meth:`_count_piece`)."""
        r = self._rev
        if r is None:
            r = self._rev = Counter(self.poset.dual(), max_memo=None, time_limit=None, max_total=None, native=False)
            r._memo = self._memo
            r._budget = self._budget
            # the compiled core counts the reversed order by removing maximal elements of this one
            r._native = self._native
            r._direction = 1
            r.probe = sys.maxsize
            r._f = r._make_counter()
        r._maybe_narrow()
        return r

    def _need_width(self, es: int) -> int:
        """Field width that holds every intermediate vector entry of a set with ``es`` extensions.

        Entries are at most ``|S| e(S) <= n e(mask)`` and the component rule
        multiplies by at most ``n + 1`` before dividing; every set of the
        decomposition of ``mask`` has at most ``e(mask)`` extensions.
        """
        n = self.poset.n
        top = self._memo.get(self.poset.full)
        if top is not None and top > es:
            es = top
        return es.bit_length() + 2 * (n + 1).bit_length() + 1

    def _set_width(self, width: int) -> None:
        """(Re)build the vector recursion for a field width of at least ``width`` bits, repacking stored vectors.

        The repack copies bytes (fields are whole bytes), O(total size of the vectors), and looks at the
        current call's clock after every vector: past it, it raises :class:`BudgetExceeded` and changes
        nothing (a 1,000-element poset's vectors are hundreds of kilobytes each).
        """
        old = self._width
        if width > old:
            width = -(-max(width, old + old // 2) // 8) * 8     # whole bytes: see fill() in _make_vectors
            if self._vec:
                ob, pad = old // 8, bytes((width - old) // 8)
                deadline, perf = self._budget[1], time.perf_counter
                repacked = {}
                for s, v in self._vec.items():
                    fields = s.bit_length()
                    b = v.to_bytes(fields * ob, "little")
                    repacked[s] = int.from_bytes(pad.join([b[i * ob:(i + 1) * ob] for i in range(fields)]),
                                                 "little")
                    if perf() > deadline:
                        raise BudgetExceeded("repacking the position sums exceeded their time limit",
                                             reason="time", memo_size=len(self._memo) + len(self._vec))
                self._vec.clear()
                self._vec.update(repacked)
            self._width = width
        self._g = self._make_vectors()

    def _tables(self):
        """Byte tables for bit-parallel scans: for byte ``k`` of a set and its value ``v``,
        ``UP[k][v]`` is the union of ``above[i]`` and ``CAP[k][v]`` the intersection of
        ``{i} | below[i] | above[i]`` over the elements ``i`` of that byte.

        So for any set ``s``: its minimal elements are ``s & ~OR(UP)`` and its cut
        elements (comparable to every other element) ``s & AND(CAP)``, in
        ``ceil(n / 8)`` look-ups instead of a pass over the elements.
        """
        t = getattr(self, "_tabs", None)
        if t is None:
            t = self._tabs = _byte_tables(self.poset)
        return t

    def _narrow_tables(self) -> tuple[int, list[list[int]]]:
        """``(c, T)``: tables that scan a set of a poset of at most ``_NARROW`` elements in three look-ups
        (four above 48 elements: ``T`` then has four tables).

        The set is cut into three chunks of ``c = ceil(n / 3)`` bits (four of ``ceil(n / 4)``).  Each
        element ``i`` has a packed mask of three ``n``-bit fields: the elements
        comparable to ``i`` or ``i`` itself, those not comparable to ``i``, and
        those not above ``i``.  ``T[j][v]`` is the intersection of these over
        the elements of value ``v`` of chunk ``j``, so for ``x = T[0][..] &
        T[1][..] & T[2][..]`` of a set ``s``: ``s & x`` are its cut elements,
        ``s & x >> n`` the elements comparable to no other element of ``s`` and
        ``s & x >> 2n`` its minimal elements (what :meth:`scan` finds a byte at
        a time with :meth:`_tables`).
        """
        t = getattr(self, "_ntabs", None)
        if t is None:
            p = self.poset
            n = p.n
            full = p.full
            c = max(1, -(-n // _chunks(n)))
            packed = [(p.below[i] | p.above[i] | 1 << i) | (full & ~(p.below[i] | p.above[i])) << n
                      | (full & ~p.above[i]) << 2 * n for i in range(n)]
            t = self._ntabs = (c, _chunk_tables(c, packed, _chunks(n)))
        return t

    def _narrow_pieces(self) -> Callable[[int], list[int]]:
        """``pieces(rest)``: the components of a set with no cut element and no element comparable to
        nothing else in it (chunk-table scans: see :meth:`_narrow_tables`), highest first.

        Each piece grows from the highest element left by closure steps of three look-ups: the
        elements of ``rest`` comparable to some element of ``x`` (which include ``x``, as every
        element of ``rest`` is comparable to another), however many minimal elements it has.
        """
        T0, T1, T2, T3, c, c2, c3, cmask, n, nbr = self._narrow_scan()

        def pieces(rest: int) -> list[int]:
            comps = []
            while rest:
                x = nbr[rest.bit_length() - 1] & rest
                while x != rest:
                    y = rest & ~((T0[x & cmask] & T1[(x >> c) & cmask] & T2[(x >> c2) & cmask]
                                  & T3[x >> c3]) >> n)
                    if y == x:
                        break
                    x = y
                comps.append(x)
                rest ^= x
            return comps

        return pieces

    def _narrow_scan(self) -> tuple:
        """What a scan with the chunk tables reads, as locals for the hot loops: ``(T0, T1, T2, T3, c,
        2c, 3c, 2^c - 1, n, nbr)``, ``T3 = [-1]`` with three chunks, ``nbr[i]`` the elements comparable
        to ``i`` and ``i`` itself (see :meth:`_narrow_tables`).  O(n) once the tables are built."""
        c, tables = self._narrow_tables()
        T0, T1, T2, T3 = (tables + [[-1]])[:4]
        p = self.poset
        nbr = [b | a | 1 << i for i, (b, a) in enumerate(zip(p.below, p.above))]
        return T0, T1, T2, T3, c, 2 * c, 3 * c, (1 << c) - 1, p.n, nbr

    def _make_counter(self) -> Callable[[int], int]:
        if self._native is not None:
            return self._make_compiled()
        memo = self._memo
        poset = self.poset
        below = list(poset.below)
        above = list(poset.above)
        # Scan a set with three look-ups in chunk tables once they are built (small posets, after
        # some work: see _start_budget), else a byte at a time.
        narrow = getattr(self, "_ntabs", None) is not None
        if narrow:
            T0, T1, T2, T3, c, c2, c3, cmask, n, nbr = self._narrow_scan()
            n2 = 2 * n
            pieces = self._narrow_pieces()
        else:
            nbytes, UP, CAP = self._tables()
        if poset.n <= _WIDE:
            fact = [1] * (poset.n + 1)
            for i in range(2, poset.n + 1):
                fact[i] = fact[i - 1] * i
        else:
            fact = _Factorials()
        budget = self._budget
        get = memo.get
        vec = self._vec
        check = _check_every(self.poset.n) - 1

        # the clock: every so many entries, sums and products, and inside a long split
        clock = _clock(budget, "exact count exceeded its time limit", memo, vec)

        def f(s: int) -> int:
            r = get(s)
            if r is not None:
                return r
            # Budget: counted when a new set is entered, not when it is stored, so that a deep first
            # descent (a large poset, nothing stored yet) still looks at the clock.  Every entered set
            # is stored once finished, so this counts the same new entries.
            k = budget[2] = budget[2] + 1
            if k > budget[0]:
                raise _over_memo("exact count needs", budget[0], len(memo) + len(vec))
            if not k & check:
                clock()
            # cut elements (Counter.scan, inlined: this is the hot path)
            if narrow:
                sc = T0[s & cmask] & T1[(s >> c) & cmask] & T2[(s >> c2) & cmask] & T3[s >> c3]
                cuts = s & sc
            else:
                up = 0
                cap = -1
                for tu, tc, byte in zip(UP, CAP, s.to_bytes(nbytes, "little")):
                    if byte:
                        up |= tu[byte]
                        cap &= tc[byte]
                cuts = s & cap
            if cuts:
                if cuts == s:
                    r = 1                       # a chain
                elif cuts & (cuts - 1) == 0:    # one cut element: the set below it times the set above it
                    zi = cuts.bit_length() - 1
                    r = 1
                    block = s & below[zi]
                    if block & (block - 1):
                        v = get(block)
                        r = v if v is not None else f(block)
                    block = s & above[zi]
                    if block & (block - 1):
                        v = get(block)
                        r *= v if v is not None else f(block)
                else:
                    lo = cuts & -cuts
                    hi = cuts ^ lo
                    if hi & (hi - 1) == 0:      # two cut elements z1 < z2 (common: no sort needed)
                        z1 = lo.bit_length() - 1
                        z2 = hi.bit_length() - 1
                        if not below[z2] >> z1 & 1:
                            z1, z2 = z2, z1
                        blocks = (s & below[z1], s & above[z1] & below[z2], s & above[z2])
                    else:
                        blocks = cut_blocks(below, above, s, cuts)
                    r = 1
                    for block in blocks:
                        if block & (block - 1):
                            v = get(block)
                            r *= v if v is not None else f(block)
            else:
                # components
                if narrow:
                    # An element comparable to nothing else in s is a component by itself; the rest
                    # falls into closures under comparability.  The first closure (_narrow_pieces'
                    # loop, inlined: the call alone costs about a tenth of the counter's time here)
                    # usually is all of s: then rule 3, with no list made; else the other pieces.
                    iso = s & sc >> n
                    rest = s ^ iso
                    mins = s & sc >> n2
                    comps = ()
                    if rest:
                        x = nbr[rest.bit_length() - 1] & rest
                        while x != rest:
                            y = rest & ~((T0[x & cmask] & T1[(x >> c) & cmask] & T2[(x >> c2) & cmask]
                                  & T3[x >> c3]) >> n)
                            if y == x:
                                break
                            x = y
                        if x != rest or iso:
                            comps = [x, *pieces(rest ^ x)]
                            # recurse in the order of the overlap classes below (by highest minimal
                            # element), so the memo fills in the same order whichever scan is used
                            if len(comps) == 2:
                                if comps[0] & mins > comps[1] & mins:
                                    comps.reverse()
                            elif len(comps) > 2:
                                comps.sort(key=mins.__and__)
                else:
                    # the overlap classes of the up-sets of the minimal elements (poset.components);
                    # a minimal element with nothing above it is a component by itself (iso), which
                    # keeps a wide antichain linear, not quadratic
                    mins = s & ~up
                    comps = []
                    if not up & s:
                        iso = s   # an antichain (nothing above anything): every element a component by itself
                    else:
                        # O(width^2) mask operations in all: a wide set of a large order can take
                        # seconds here, inside one entry (hence the clock)
                        comps, iso = split_components(above, s, mins, clock)
                if iso or len(comps) > 1:
                    # s!/(|C1|!...|Ck|!) e(C1)...e(Ck); every partial quotient is exact
                    r = fact[s.bit_count()]
                    k = 0
                    for comp in comps:
                        if comp & (comp - 1):
                            v = get(comp)
                            r = r // fact[comp.bit_count()] * (v if v is not None else f(comp))
                            # each step is a division of a number of up to n log n bits
                            k += 1
                            if not k & 15:
                                clock()
                else:
                    r = 0
                    m = mins
                    k = 0
                    while m:
                        b = m & -m
                        m ^= b
                        t = s ^ b
                        v = get(t)
                        r += v if v is not None else f(t)
                        k += 1
                        if not k & 63:      # a wide set of known children: big sums
                            clock()
            memo[s] = r
            return r

        return f

    def _make_compiled(self) -> Callable[[int], int]:
        """The recursion of :meth:`_make_counter`, run by the compiled core under the same budget."""
        memo = self._memo
        get = memo.get
        budget = self._budget
        core = self._native
        direction = self._direction
        perf = time.perf_counter

        def f(s: int) -> int:
            r = get(s)
            if r is not None:
                return r
            if s & (s - 1) == 0:
                return 1
            room = budget[0] - budget[2]
            if room <= 0:
                raise _over_memo("exact count needs", budget[0], self.memo_size)
            deadline = budget[1]
            seconds = -1.0 if deadline == _INF else max(0.0, deadline - perf())
            status, r, added = core.count(s, direction, room if room < sys.maxsize else -1, seconds)
            budget[2] += added
            if status == 1:
                raise _over_memo("exact count needs", budget[0], self.memo_size)
            if status == 2:
                raise BudgetExceeded("exact count exceeded its time limit", reason="time",
                                     memo_size=self.memo_size)
            memo[s] = r
            return r

        return f

    def _make_split(self) -> Callable[[int], tuple]:
        """``split(s)`` for a set of at least two elements: how rules 1–2 apply to it, as in the counter.

        Returns ``(chain, comps, iso, mins)``: ``chain`` is the list of cut
        elements in order (None if there are none, and then the rest is not
        computed); otherwise ``comps`` are the components, in the order the
        counter recurses into them, ``iso`` a mask of one-element components
        not listed in ``comps``, and ``mins`` the minimal elements of ``s``.
        """
        poset = self.poset
        below = list(poset.below)
        above = list(poset.above)
        if getattr(self, "_ntabs", None) is not None:
            T0, T1, T2, T3, c, c2, c3, cmask, n, _ = self._narrow_scan()
            pieces = self._narrow_pieces()

            def split(s: int) -> tuple:
                sc = T0[s & cmask] & T1[(s >> c) & cmask] & T2[(s >> c2) & cmask] & T3[s >> c3]
                cuts = s & sc
                if cuts:
                    return cut_chain(below, cuts), None, 0, 0
                iso = s & sc >> n
                comps = pieces(s ^ iso)
                mins = s & sc >> 2 * n
                comps.sort(key=mins.__and__)
                return None, comps, iso, mins
        else:
            budget = self._budget

            def split(s: int) -> tuple:
                mins, cuts = self.scan(s)
                if cuts:
                    return cut_chain(below, cuts), None, 0, 0
                comps = components(above, s, mins, deadline=budget[1])
                iso = 0
                if comps[-1] & (comps[-1] - 1) == 0:      # one-element pieces (listed last): as iso
                    keep = []
                    for c in comps:
                        if c & (c - 1):
                            keep.append(c)
                        else:
                            iso |= c
                    comps = keep
                return None, comps, iso, mins

        return split

    def _make_vectors(self) -> Callable[[int], int]:
        """The memoised forward recursion for packed position-sum vectors (see :meth:`position_sums`)."""
        memo = self._memo
        vec = self._vec
        below = list(self.poset.below)
        above = list(self.poset.above)
        split = self._make_split()
        width = self._width
        budget = self._budget
        get = memo.get
        vget = vec.get
        f = self._f
        # fill(s, t): t in the field of every element of s, joined from little-endian bytes (fields
        # are whole bytes: see _set_width)
        nbytes = max(1, (self.poset.n + 7) // 8)
        wbytes = width // 8
        zero = bytes(wbytes)
        zero8 = bytes(8 * wbytes)

        def fill(s: int, t: int) -> int:
            """``t * ones(s)`` (``0 <= t < 2^width``: no carries), by joining bytes: the product of a
            vector of a large order by a count of thousands of bits takes a large share of a second."""
            tb = t.to_bytes(wbytes, "little")
            parts = []
            for byte in s.to_bytes(nbytes, "little"):
                if not byte:
                    parts.append(zero8)
                else:
                    parts += [tb if byte >> j & 1 else zero for j in range(8)]
            return int.from_bytes(b"".join(parts), "little")

        def cnt(s: int) -> int:
            if s & (s - 1) == 0:
                return 1
            v = get(s)
            return v if v is not None else f(s)

        # the clock, read at every step of the loops below and after every vector: each is O(n)
        # big-int work on packed vectors of a large order
        late = _clock(budget, "position sums exceeded their time limit", memo, vec)

        def vstore(s: int, v: int) -> int:
            k = budget[2] = budget[2] + 1
            if k > budget[0]:
                raise _over_memo("position sums need", budget[0], len(memo) + len(vec))
            vec[s] = v
            late()
            return v

        def g(s: int) -> int:
            v = vget(s)
            if v is not None:
                return v
            if s & (s - 1) == 0:
                return 1 << ((s.bit_length() - 1) * width)
            es = cnt(s)
            late()
            chain, comps, iso, mins = split(s)
            if chain is not None:
                v = 0
                off = 0                 # elements before the current block
                rest = s
                for zi in chain:
                    late()
                    block = rest & below[zi]
                    rest &= above[zi]
                    if block:
                        v += (es // cnt(block)) * g(block)
                        if off:
                            v += fill(block, off * es)
                        off += block.bit_count()
                    v += ((off + 1) * es) << (zi * width)
                    off += 1
                if rest:
                    v += (es // cnt(rest)) * g(rest) + fill(rest, off * es)
                return vstore(s, v)
            if iso or len(comps) > 1:
                n1 = s.bit_count() + 1
                v = 0
                for comp in comps:
                    late()
                    v += (es // cnt(comp)) * n1 * g(comp) // (comp.bit_count() + 1)
                if iso:
                    # a one-element component is at (n + 1) / 2 on average; es (n + 1) is even.  It
                    # fits a field, so it is written into the field of every element of iso at once,
                    # not shifted and added to the whole vector once per element
                    v += fill(iso, es * n1 >> 1)
                return vstore(s, v)
            v = fill(s, es)
            m = mins
            while m:
                b = m & -m
                m ^= b
                v += g(s ^ b)
                late()
            return vstore(s, v)

        return g


def _byte_tables(poset: Poset):
    n = poset.n
    nbytes = max(1, (n + 7) // 8)
    if n > _WIDE:
        # 256 entries of n bits per byte would take O(n^2) memory (800 MB for 10,000 elements): fill
        # only the entries that sets actually meet
        up_t, cap_t = [], []
        for k in range(nbytes):
            idx = range(8 * k, min(n, 8 * k + 8))
            up_t.append(_LazyUnion([poset.above[i] for i in idx]))
            cap_t.append(_LazyMeet([poset.below[i] | poset.above[i] | 1 << i for i in idx]))
        return nbytes, up_t, cap_t
    up_t, cap_t = [], []
    for k in range(nbytes):
        ut = [0] * 256
        ct = [-1] * 256
        for v in range(1, 256):
            low = v & -v
            i = 8 * k + low.bit_length() - 1
            if i < n:
                ut[v] = ut[v ^ low] | poset.above[i]
                ct[v] = ct[v ^ low] & (poset.below[i] | poset.above[i] | 1 << i)
            else:                       # bits past n never occur in a valid set
                ut[v] = ut[v ^ low]
                ct[v] = ct[v ^ low]
        up_t.append(ut)
        cap_t.append(ct)
    return nbytes, up_t, cap_t


def _chunks(n: int) -> int:
    """Chunks of the chunk-table scans of an ``n``-element poset: three up to 48 elements, else four."""
    return 3 if n <= 48 else 4


def _chunk_tables(c: int, values: list[int], k: int = 3) -> list[list[int]]:
    """``k`` tables, one per ``c``-bit chunk of a set: entry ``v`` of table ``j`` is the
    intersection (``&``) of ``values[i]`` over the elements ``i`` of value ``v`` of chunk ``j``.

    Each table is built from the tables of the two halves of its chunk (at most 256
    entries each), a row per distinct value of the upper half, and its entries are
    shared objects (few distinct values): a 16-bit chunk costs 65,536 pointers, not ints.
    """
    def subsets(vals):
        t = [-1] * (1 << len(vals))
        for v in range(1, len(t)):
            low = v & -v
            t[v] = t[v ^ low] & vals[low.bit_length() - 1]
        return t

    out = []
    for j in range(k):
        vals = values[j * c:(j + 1) * c]
        half = len(vals) // 2
        lo, hi = subsets(vals[:half]), subsets(vals[half:])
        shared: dict[int, int] = {}
        rows: dict[int, list[int]] = {}
        table: list[int] = []
        for h in hi:
            row = rows.get(h)
            if row is None:
                row = rows[h] = [shared.setdefault(x, x) for x in [h & x for x in lo]]
            table += row
        out.append(table)
    return out


def _clock(budget: list, message: str, memo: dict, vec: dict) -> Callable[[], None]:
    """``clock()``: raises :class:`BudgetExceeded` (reason ``"time"``, ``message``) once the deadline
    ``budget[1]`` (a ``time.perf_counter()`` value) has passed.  One reading of the clock, O(1)."""
    perf = time.perf_counter

    def clock() -> None:
        if perf() > budget[1]:
            raise BudgetExceeded(message, reason="time", memo_size=len(memo) + len(vec))

    return clock


def _over_memo(what: str, limit: int, size: int) -> BudgetExceeded:
    """The error of a count (``what``: "exact count needs") that would store more than ``limit`` new entries."""
    return BudgetExceeded(f"{what} more than max_memo={limit} new memo entries", reason="memo", memo_size=size)


def _ratio(a: int, b: int) -> float:
    """a / b as a float, exact-ish for huge ints."""
    try:
        return a / b
    except OverflowError:  # pragma: no cover - only for astronomically large counts
        shift = max(a.bit_length(), b.bit_length()) - 900
        return (a >> shift) / (b >> shift)


def entries_within(n: int, nbytes: int) -> int:
    """Memo entries an exact count on an order of ``n`` elements may make within ``nbytes`` bytes of
    memory: by :func:`~opportune.engine.native.entry_bytes` where the compiled core takes the order,
    else by a Python entry's size (a dict slot, a key of ``n`` bits and a count of ``log2(n!)``
    bits, about 100 bytes of objects besides).  At least 1.  O(1).

    Parameters
    ----------
    n : int
        Elements of the order.
    nbytes : int
        Bytes the memo may take.

    Returns
    -------
    int
        Entries that fit (at least 1).

    Examples
    --------
    >>> entries_within(50, 2**30) > 1_000_000
    True
    """
    import math

    from opportune.engine import native

    if native.available() and n <= native.MAX_ELEMENTS:
        per = native.entry_bytes(n)
    else:
        per = 100 + n // 8 + int(math.lgamma(n + 1) / math.log(2)) // 8
    return max(1, nbytes // per)


def count_linear_extensions(poset: Poset, mask: int | None = None, *, max_memo: int | None = None,
                            time_limit: float | None = None, deadline: Deadline | float | None = None) -> int:
    """Number of linear extensions of ``poset`` (or of the subposet induced on ``mask``).

    A one-shot convenience around :class:`Counter`: its memo goes with it, so repeated questions
    about one order are cheaper asked of one :class:`Counter`.

    Parameters
    ----------
    poset : Poset
        The order.
    mask : int or None
        The set, a bitmask of the order's elements (None: all of them).
    max_memo, time_limit : int or None, float or None
        As for :class:`Counter`.
    deadline : Deadline, float or None
        As in :meth:`Counter.count`.

    Returns
    -------
    int
        The exact number of linear extensions.

    Raises
    ------
    BudgetExceeded
        When the count does not fit ``max_memo``, ``time_limit`` or ``deadline``.

    Examples
    --------
    >>> count_linear_extensions(Poset.from_pairs(3, [(0, 2), (1, 2)]))
    2
    """
    return Counter(poset, max_memo=max_memo, time_limit=time_limit).count(mask, deadline=deadline)
