"""Exact counting of linear extensions by recursive decomposition, with a lifelong memo.

The number ``e(S)`` of linear extensions of the subposet induced on a set ``S``
obeys three rules, applied in this order (Kangas, Hankala, Niinimäki &
Koivisto, "Counting linear extensions of sparse posets", IJCAI 2016, plus the
classical ordinal-sum rule):

1. **Components.**  If the comparability graph of ``S`` falls into connected
   pieces ``C1..Ck``, the pieces interleave freely:
   ``e(S) = |S|! / (|C1|! ... |Ck|!) * e(C1) ... e(Ck)``.
2. **Cut elements.**  If some elements of ``S`` are comparable to every other
   element of ``S`` (they form a chain ``z1 < ... < zk``), ``S`` is the ordinal
   sum ``B0 ⊕ z1 ⊕ B1 ⊕ ... ⊕ zk ⊕ Bk`` and ``e(S) = e(B0) ... e(Bk)``.
3. **First element.**  Otherwise ``e(S) = sum over minimal x of e(S - {x})``.

Every value is memoised on the set, as a Python int, for the whole life of the
:class:`Counter`: the subproblems of a count are exactly the questions a
simulation asks next (the remaining parts after one more installation), so
later calls are mostly dictionary lookups.  Rule 3 only ever removes minimal
elements, so the subproblems of an up-set are up-sets: the memo is keyed on
"what is still to do".

Without rules 1–2 this is the classical dynamic programme over the lattice of
down-sets (:mod:`opportune.engine.downsets`); with them the number of memo
entries is usually far smaller (KILBRID: 626,575 down-sets, ~3,200 entries).
"""

from __future__ import annotations

import sys
import time
from math import factorial
from typing import Callable

from opportune.engine.poset import Poset, bits

__all__ = ["BudgetExceeded", "Counter", "count_linear_extensions"]

_CHECK_EVERY = 512  # new memo entries between clock checks


class BudgetExceeded(Exception):
    """An exact count would need more memo entries or time than allowed.

    The counter's memo stays valid (only finished values are stored): call
    again with a larger budget to continue where it stopped, or fall back to
    :func:`opportune.engine.estimate.estimate_count`.

    Attributes: ``reason`` (``"memo"`` or ``"time"``), ``memo_size``, ``elapsed``.
    """

    def __init__(self, message: str, *, reason: str = "memo", memo_size: int = 0, elapsed: float = 0.0):
        self.reason = reason
        self.memo_size = memo_size
        self.elapsed = elapsed
        super().__init__(message)


class Counter:
    """Linear-extension counter for one Poset; keeps its memo for its whole life.

    Parameters
    ----------
    poset : Poset
    max_memo : int or None
        Most memo entries the counter may ever hold (None: unlimited).  A call
        that would store more raises :class:`BudgetExceeded`.
    time_limit : float or None
        Most seconds one call of :meth:`count` / :meth:`position_sums` may
        spend computing (None: unlimited).

    Both budgets are plain attributes and may be changed between calls; the
    memo survives a :class:`BudgetExceeded`.

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

    def __init__(self, poset: Poset, *, max_memo: int | None = 2_000_000, time_limit: float | None = None):
        self.poset = poset
        self.max_memo = max_memo
        self.time_limit = time_limit
        self._memo: dict[int, int] = {0: 1}
        self._budget = [0, 0.0, 0]  # [memo limit, deadline, insertions since last clock check]
        self._f = self._make_counter()

    # ------------------------------------------------------------------ public API
    def count(self, mask: int | None = None) -> int:
        """Exact number of linear extensions of the subposet induced on ``mask`` (default: all).

        ``mask`` may be any subset; in practice it is usually an up-set (what
        remains to be done).  A mask seen before is answered by one dictionary
        lookup.  Raises :class:`BudgetExceeded` if the memo would exceed
        ``max_memo`` entries or the call exceeds ``time_limit`` seconds.

        >>> Counter(Poset.antichain(3)).count()
        6
        >>> Counter(Poset.chain(3)).count(0b101)
        1
        """
        r = self._memo.get(mask)
        if r is not None:
            return r
        return self._count_miss(mask)

    __call__ = count

    def position_sums(self, mask: int | None = None) -> dict[int, int]:
        """For every element ``x`` of ``mask``: the sum over all linear extensions of the 1-based position of ``x``.

        ``position_sums(mask)[x] / count(mask)`` is the expected position of
        ``x`` in a uniformly random linear extension.  Exact ints.

        Computed by one backward pass over the decomposition DAG of ``mask``
        (every node's sums are a linear function of its children's, so each
        node's coefficient is propagated top-down, largest sets first):
        O(nodes × |mask|) big-int operations after :meth:`count`, whose memo it
        reuses.  Raises :class:`BudgetExceeded` like :meth:`count`.

        >>> Counter(Poset.from_pairs(3, [(0, 1)])).position_sums()
        {0: 4, 1: 8, 2: 6}
        """
        if mask is None:
            mask = self.poset.full
        self.count(mask)
        if mask == 0:
            return {}
        self._start_budget()
        memo = self._memo
        f = self._f
        k = mask.bit_count()
        scale = factorial(k)          # makes every coefficient an integer (see _propagate)
        coef: dict[int, int] = {mask: scale}
        acc: dict[int, int] = {}      # set -> weight to add to each of its elements
        point = [0] * self.poset.n    # weight for single elements
        # Collect the DAG in order of decreasing size: a child is always smaller.
        nodes = self._reachable(mask)
        nodes.sort(key=int.bit_count, reverse=True)
        below, above = self.poset.below, self.poset.above

        def value(s: int) -> int:
            if s & (s - 1) == 0:
                return 1
            v = memo.get(s)
            return v if v is not None else f(s)

        for s in nodes:
            c = coef.pop(s, 0)
            if not c:
                continue
            kind, parts = self._split(s)
            if kind == "leaf":
                point[s.bit_length() - 1] += c
                continue
            es = value(s)
            if kind == "disc":
                size = s.bit_count()
                for comp in parts:
                    csize = comp.bit_count()
                    coef[comp] = coef.get(comp, 0) + c * (es // value(comp)) * (size + 1) // (csize + 1)
            elif kind == "cut":
                offset = 0
                for block in parts:
                    if isinstance(block, tuple):        # a cut element: ("z", bit)
                        z = block[1]
                        point[z.bit_length() - 1] += c * (offset + 1) * es
                        offset += 1
                        continue
                    if block:
                        coef[block] = coef.get(block, 0) + c * (es // value(block))
                        if offset:
                            w = c * offset * es
                            acc[block] = acc.get(block, 0) + w
                        offset += block.bit_count()
            else:  # "sum": e(S) = sum over minimal x of e(S - x); every element gains e(S)
                for b in parts:
                    t = s ^ b
                    coef[t] = coef.get(t, 0) + c
                acc[s] = acc.get(s, 0) + c * es
        for s, w in acc.items():
            for i in bits(s):
                point[i] += w
        out = {}
        for i in bits(mask):
            q, r = divmod(point[i], scale)
            assert r == 0, "position sums must be integral"
            out[i] = q
        return out

    def expected_positions(self, mask: int | None = None) -> dict[int, float]:
        """Expected 1-based position of each element of ``mask`` in a uniformly random linear extension.

        >>> Counter(Poset.from_pairs(3, [(0, 1)])).expected_positions()
        {0: 1.3333333333333333, 1: 2.6666666666666665, 2: 2.0}
        """
        if mask is None:
            mask = self.poset.full
        total = self.count(mask)
        return {x: _ratio(s, total) for x, s in self.position_sums(mask).items()}

    def sample(self, rng, mask: int | None = None) -> list[int]:
        """A uniformly random linear extension of ``mask`` (exact; ``rng`` is a :class:`random.Random`).

        Chooses the first element ``x`` with probability ``e(S - x) / e(S)``,
        then recurses.  O(|mask| × width) memo lookups, after :meth:`count`.

        >>> import random
        >>> Counter(Poset.chain(3)).sample(random.Random(1))
        [0, 1, 2]
        """
        if mask is None:
            mask = self.poset.full
        below = self.poset.below
        out = []
        s = mask
        while s:
            total = self.count(s)
            r = rng.randrange(total)
            m = s
            while m:
                b = m & -m
                m ^= b
                i = b.bit_length() - 1
                if below[i] & s:
                    continue
                v = self.count(s ^ b)
                if r < v:
                    break
                r -= v
            out.append(i)
            s ^= b
        return out

    @property
    def memo_size(self) -> int:
        """Number of entries in the memo."""
        return len(self._memo)

    def clear(self) -> None:
        """Forget every memoised value (frees memory; later calls recompute)."""
        self._memo.clear()
        self._memo[0] = 1

    def __repr__(self) -> str:
        return f"<Counter n={self.poset.n} memo={len(self._memo)}>"

    # ------------------------------------------------------------------ internals
    def _start_budget(self) -> None:
        b = self._budget
        b[0] = self.max_memo if self.max_memo is not None else sys.maxsize
        b[1] = time.perf_counter() + self.time_limit if self.time_limit is not None else float("inf")
        b[2] = 0
        need = 3 * self.poset.n + 200
        if sys.getrecursionlimit() < need:   # Python 3.11 frames do not use the C stack
            sys.setrecursionlimit(need)

    def _count_miss(self, mask: int | None) -> int:
        if mask is None:
            mask = self.poset.full
            r = self._memo.get(mask)
            if r is not None:
                return r
        if not isinstance(mask, int) or mask < 0 or mask & ~self.poset.full:
            raise ValueError(f"mask {mask!r} is not a subset of 0..{self.poset.n - 1}")
        if mask & (mask - 1) == 0:
            r = 1
        else:
            self._start_budget()
            r = self._f(mask)
        if len(self._memo) < self._budget[0] or mask & (mask - 1) == 0:
            self._memo[mask] = r
        return r

    def _make_counter(self) -> Callable[[int], int]:
        memo = self._memo
        poset = self.poset
        below = list(poset.below)
        above = list(poset.above)
        cmp_ = [b | a for b, a in zip(below, above)]
        fact = [factorial(i) for i in range(poset.n + 1)]
        budget = self._budget
        get = memo.get
        perf = time.perf_counter

        def store(s: int, r: int) -> int:
            if len(memo) >= budget[0]:
                raise BudgetExceeded(
                    f"exact count needs more than max_memo={budget[0]} memo entries",
                    reason="memo", memo_size=len(memo))
            memo[s] = r
            budget[2] += 1
            if budget[2] >= _CHECK_EVERY:
                budget[2] = 0
                if perf() > budget[1]:
                    raise BudgetExceeded("exact count exceeded its time limit", reason="time", memo_size=len(memo))
            return r

        def f(s: int) -> int:
            r = get(s)
            if r is not None:
                return r
            # --- rule 1: connected components of the comparability graph
            low = s & -s
            comp = low
            frontier = low
            while frontier:
                b = frontier & -frontier
                frontier ^= b
                new = cmp_[b.bit_length() - 1] & s & ~comp
                if new:
                    comp |= new
                    frontier |= new
            if comp != s:
                r = fact[s.bit_count()]
                rest = s
                while True:
                    rest ^= comp
                    r //= fact[comp.bit_count()]
                    if comp & (comp - 1):
                        v = get(comp)
                        r *= v if v is not None else f(comp)
                    if not rest:
                        break
                    low = rest & -rest
                    comp = low
                    frontier = low
                    while frontier:
                        b = frontier & -frontier
                        frontier ^= b
                        new = cmp_[b.bit_length() - 1] & rest & ~comp
                        if new:
                            comp |= new
                            frontier |= new
                return store(s, r)
            # --- rules 2 and 3: cut elements, else minimal elements
            cuts = 0
            mins = []
            m = s
            while m:
                b = m & -m
                m ^= b
                i = b.bit_length() - 1
                if (cmp_[i] & s) | b == s:
                    cuts |= b
                elif not below[i] & s:
                    mins.append(b)
            if cuts:
                if cuts == s:
                    return store(s, 1)          # a chain
                r = 1
                for block in _blocks(s, cuts, below, above):
                    if block & (block - 1):
                        v = get(block)
                        r *= v if v is not None else f(block)
                return store(s, r)
            r = 0
            for b in mins:
                t = s ^ b
                v = get(t)
                r += v if v is not None else f(t)
            return store(s, r)

        return f

    def _split(self, s: int):
        """The decomposition rule :meth:`count` applies to ``s`` (same order of rules).

        Returns ``("leaf", s)``, ``("disc", components)``, ``("cut", blocks)``
        where blocks alternate sets and ``("z", bit)`` cut elements in order,
        or ``("sum", minimal bits)``.
        """
        if s & (s - 1) == 0:
            return "leaf", s
        poset = self.poset
        below, above = poset.below, poset.above
        comps = _components(s, below, above)
        if len(comps) > 1:
            return "disc", comps
        cuts = 0
        mins = []
        for i in bits(s):
            b = 1 << i
            if ((below[i] | above[i]) & s) | b == s:
                cuts |= b
            elif not below[i] & s:
                mins.append(b)
        if cuts:
            parts: list = []
            zs = sorted(bits(cuts), key=lambda i: (below[i] & s).bit_count())
            prev = None
            for z in zs:
                lo = s & below[z]
                if prev is not None:
                    lo &= above[prev]
                parts.append(lo)
                parts.append(("z", 1 << z))
                prev = z
            parts.append(s & above[prev])
            return "cut", parts
        return "sum", mins

    def _reachable(self, mask: int) -> list[int]:
        """All sets in the decomposition DAG below ``mask`` (including it)."""
        seen = {mask}
        stack = [mask]
        while stack:
            s = stack.pop()
            kind, parts = self._split(s)
            if kind == "leaf":
                continue
            if kind == "disc":
                children = parts
            elif kind == "cut":
                children = [p for p in parts if not isinstance(p, tuple) and p]
            else:
                children = [s ^ b for b in parts]
            for t in children:
                if t not in seen:
                    seen.add(t)
                    stack.append(t)
        return list(seen)


def _blocks(s: int, cuts: int, below, above):
    """The non-cut blocks of ``s`` between consecutive cut elements (the cuts form a chain)."""
    zs = sorted(bits(cuts), key=lambda i: (below[i] & s).bit_count())
    out = []
    prev = None
    for z in zs:
        lo = s & below[z]
        if prev is not None:
            lo &= above[prev]
        out.append(lo)
        prev = z
    out.append(s & above[prev])
    return out


def _components(s: int, below, above) -> list[int]:
    """Connected components of the comparability graph induced on ``s``."""
    out = []
    rest = s
    while rest:
        low = rest & -rest
        comp = low
        frontier = low
        while frontier:
            b = frontier & -frontier
            frontier ^= b
            i = b.bit_length() - 1
            new = (below[i] | above[i]) & rest & ~comp
            comp |= new
            frontier |= new
        out.append(comp)
        rest ^= comp
    return out


def _ratio(a: int, b: int) -> float:
    """a / b as a float, exact-ish for huge ints."""
    try:
        return a / b
    except OverflowError:  # pragma: no cover - only for astronomically large counts
        shift = max(a.bit_length(), b.bit_length()) - 900
        return (a >> shift) / (b >> shift)


def count_linear_extensions(poset: Poset, mask: int | None = None, *, max_memo: int | None = None,
                            time_limit: float | None = None) -> int:
    """Number of linear extensions of ``poset`` (or of the subposet induced on ``mask``).

    A one-shot convenience around :class:`Counter`.

    >>> count_linear_extensions(Poset.from_pairs(3, [(0, 2), (1, 2)]))
    2
    """
    return Counter(poset, max_memo=max_memo, time_limit=time_limit).count(mask)
