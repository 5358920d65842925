"""Exact counting through a hub: an element that glues everything below it.

Assembly graphs often have a *hub* ``h``: a sub-assembly step that needs
dozens of earlier steps and that the rest of the product is built on (ARC111:
task 91 needs 56 tasks and 19 come after it).  While ``h`` is not yet done, all
its predecessors stay in one connected piece, so the decomposition of
:class:`~opportune.engine.count.Counter` cannot split them and its memo
explodes.  Yet the count factors neatly around ``h``:

* ``A`` = what must come after ``h``; ``B`` = the rest (``↓h`` and the steps
  unrelated to ``h``).  If every relation between ``B`` and ``A`` goes through
  ``h``, a linear extension is a linear extension of ``B``, then ``h`` and the
  steps of ``A`` merged into the ``b`` steps of ``B`` that follow the last
  predecessor of ``h``:

      e(S) = e(A) · Σ_b D(b) · C(b + 1 + |A|, 1 + |A|)

  where ``D(b)`` is the number of linear extensions of ``B`` with exactly ``b``
  steps after the last element of ``↓h``: the *tail distribution*,
  :func:`TailCounter.tail`.  ``B`` without ``h`` splits freely, so ``D`` is cheap.
* A few relations ``b < a`` from unrelated steps into ``A`` ("coupling") are
  removed and put back by inclusion–exclusion: with ``Q`` the order without
  them, ``e(P) = Σ_F (-1)^|F| e(Q + {a < b for (b, a) in F})``; with the
  relation reversed, ``b`` (and all above it) joins ``A``, so every term has
  the same form.

The tail distribution is computed by the same recursion as the counter
(components, cut elements, minimal elements) on vectors instead of numbers.
Merging two independent pieces is a convolution once each vector is scaled
by binomials (the shuffle count factors into "before the mark" and "after
the mark" parts).
"""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager
from itertools import combinations, islice
from math import comb
from operator import add, mul

from opportune.engine.count import EVICT_CHUNK, Counter
from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline, recursion_room
from opportune.engine.poset import (
    CycleError,
    Poset,
    bits,
    byte_unions,
    components,
    cut_blocks,
)
from opportune.engine.tuning import NATIVE_TAILS, HUB_ENTRY_OVERHEAD as ENTRY_OVERHEAD

__all__ = ["HubPath", "TailCounter", "hub_count", "hub_candidates", "hub_split"]





def entry_bytes(d: tuple[int, ...]) -> int:
    """Bytes one tail-memo entry holds, from its vector ``d``: the tuple, and its length times the size of
    its middle count (the largest counts are near the middle of a tail distribution, so this errs
    high, the safe side of a memory limit).  O(1).

    >>> entry_bytes([1, 10 ** 30, 1]) > entry_bytes([1, 2, 1])
    True
    """
    return ENTRY_OVERHEAD + sys.getsizeof(d) + len(d) * sys.getsizeof(d[len(d) >> 1]) if d else ENTRY_OVERHEAD


class TailCounter:
    """Tail distributions for one poset and one set of marked elements, with a memo.

    ``tail(s)[b]`` is the number of linear extensions of the subposet on ``s``
    in which exactly ``b`` elements come after the last marked element of
    ``s`` (``s`` must contain a marked element).  Unmarked pieces are counted
    by ``counter`` (whose memo is shared).

    Complexity: one vector of at most ``|s|`` ints per set visited; the sets
    visited are those the counter would visit for ``s`` with the marks
    present.  A merge of two pieces of sizes ``n1``, ``n2`` costs
    ``O(n1 · n2)`` big-int products.

    ``deadline`` (a :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()``
    moment) stops every :meth:`tail` with :class:`BudgetExceeded`; the attribute may be changed
    between calls, and :meth:`tail` takes a sooner one per call.

    >>> p = Poset.from_pairs(3, [(0, 1)])          # 0 < 1, 2 free
    >>> TailCounter(Counter(p), marks=0b001).tail(0b111)   # 012, 021: two after 0; 201: one
    [0, 1, 2]
    """

    def __init__(self, counter: Counter, marks: int, *, deadline: Deadline | float | None = float("inf")):
        self.counter = counter
        self.poset = counter.poset
        self.marks = marks
        self.deadline = deadline
        self._memo: dict[int, tuple[int, ...]] = {}
        self._held = [0]        # bytes of the memo's entries (see entry_bytes), kept as they come and go
        n = self.poset.n
        self._binom = _BinomialRows()          # rows of Pascal's triangle, as the Python recursion asks
        self._rec = None
        # the compiled core runs this recursion too (its counts from the counter's compiled memo)
        self._core = counter._native if counter.compiled and counter._direction == 0 and n <= NATIVE_TAILS else None
        self._handle = self._core.tails_new(marks) if self._core is not None else -1

    @property
    def deadline(self) -> float:
        """The ``time.perf_counter()`` moment past which :meth:`tail` stops (``inf``: never)."""
        return self._deadline

    @deadline.setter
    def deadline(self, value: Deadline | float | None) -> None:
        self._deadline = as_deadline(value).at

    def __del__(self):
        core = getattr(self, "_core", None)
        if core is not None:
            core.tails_drop(self._handle)

    def entries(self) -> int:
        """Entries in the memo (what :meth:`shrink` keeps a share of).  O(1)."""
        return len(self._memo)

    def nbytes(self) -> int:
        """Bytes of the memo: its table plus every entry's :func:`entry_bytes`, added as entries are stored
        and taken off as they are dropped (sampling both ends of the memo missed the long vectors of the
        middle by a third).  O(1)."""
        return sys.getsizeof(self._memo) + self._held[0]

    def shrink(self, keep: float = 0.0, deadline: Deadline | float | None = None) -> None:
        """Drop all but the newest ``keep`` share (0 to 1) of the memo (insertion order); past ``deadline``
        (read every 4,096 entries), :class:`BudgetExceeded`, the rest kept.  O(entries dropped)."""
        memo, until, held = self._memo, as_deadline(deadline), self._held
        drop = len(memo) - int(keep * len(memo))
        while drop > 0:                 # in chunks, each listed when it is dropped: O(entries dropped) in all
            chunk = list(islice(memo, min(drop, EVICT_CHUNK)))
            for key in chunk:
                held[0] -= entry_bytes(memo.pop(key))
            drop -= len(chunk)
            if until.expired():
                raise BudgetExceeded("shrinking a tail memo passed its deadline", reason="time")

    def tail(self, s: int, *, deadline: Deadline | float | None = None) -> list[int]:
        if not s & self.marks:
            raise ValueError("the set holds no marked element")
        if deadline is None:
            d = self._tail(s)
        else:
            saved = self._deadline
            self._deadline = min(saved, as_deadline(deadline).at)
            try:
                d = self._tail(s)
            finally:
                self._deadline = saved
        return [*d, *[0] * (s.bit_count() - len(d))]

    # -------------------------------------------------------------- recursion
    def _tail(self, s: int) -> tuple[int, ...]:
        r = self._memo.get(s)
        if r is not None:
            return r
        if self._core is not None:
            return self._compiled(s)
        if self._rec is None:
            self._rec = self._make_recursion()
        with recursion_room(3 * s.bit_count() + 200):
            return self._rec(s)

    def _compiled(self, s: int) -> list[int]:
        """The recursion in the compiled core, under this counter's deadline and the counter's budget."""
        c = self.counter
        c._start_budget(self._deadline)
        b = c._budget
        deadline = b[1]
        seconds = -1.0 if deadline == float("inf") else max(0.0, deadline - time.perf_counter())
        room = b[0] - b[2]
        status, r, added = self._core.tail(self._handle, s, room if room < 1 << 62 else -1, seconds)
        if status == 2:
            raise BudgetExceeded("hub count exceeded its time limit", reason="time", memo_size=c.memo_size)
        if status == 1:
            raise BudgetExceeded(f"hub count needs more than max_memo={b[0]} new memo entries",
                                 reason="memo", memo_size=c.memo_size)
        r = tuple(r)
        self._memo[s] = r
        self._held[0] += entry_bytes(r)
        return r

    def _make_recursion(self):
        """The memoised recursion as a closure over local names (it is the hot path)."""
        memo = self._memo
        get = memo.get
        held = self._held
        below, above = self.poset.below, self.poset.above
        marks = self.marks
        counter = self.counter

        def count(t: int) -> int:       # the plain counts of unmarked pieces, under this call's deadline
            return counter.count(t, deadline=self._deadline)

        scan = self.counter.scan
        binom = self._binom
        merge, merge_plain = self._merge, self._merge_plain
        perf = time.perf_counter

        def f(s: int) -> list[int]:
            # every call: one may convolve long vectors of big counts (far more than the clock costs)
            if perf() > self._deadline:
                raise BudgetExceeded("hub count exceeded its time limit", reason="time", memo_size=len(memo))
            n = s.bit_count()
            mins, cuts = scan(s)
            comps = components(above, s, mins, deadline=self._deadline) if not cuts else ()
            if len(comps) > 1:
                # marked pieces merge pairwise; the unmarked ones form one block (multinomial × counts)
                r = None
                size = 0
                plain_n, plain_e = 0, 1
                for c in comps:
                    k = c.bit_count()
                    if c & marks:
                        d = get(c) or f(c)
                        r = d if r is None else merge(r, size, d, k)
                        size += k
                    else:
                        plain_e *= (count(c) if k > 1 else 1) * binom[plain_n + k][k]
                        plain_n += k
                if plain_n:
                    r = merge_plain(r, size, plain_e, plain_n)
            elif cuts and n > 1:
                cut = cuts.bit_length() - 1     # any cut element splits s into below and above it
                lo, hi = s & below[cut], s & above[cut]
                nh = hi.bit_count()
                if hi & marks:
                    e = count(lo) if lo else 1
                    r = [v * e for v in (get(hi) or f(hi))]
                elif marks >> cut & 1:
                    r = [0] * (nh + 1)
                    r[nh] = (count(lo) if lo else 1) * (count(hi) if hi else 1)
                else:
                    e = count(hi) if hi else 1
                    r = [0] * (nh + 1) + [v * e for v in (get(lo) or f(lo))]
            else:
                r = None
                last = 0
                m = mins
                while m:
                    b = m & -m
                    m ^= b
                    rest = s ^ b
                    if rest & marks:
                        d = get(rest) or f(rest)
                        if r is None:
                            r = d
                        elif len(r) >= len(d):
                            r = [*map(add, r, d), *r[len(d):]]
                        else:
                            r = [*map(add, d, r), *d[len(r):]]
                    else:                       # b is the last marked element
                        last += count(rest) if rest else 1
                if last:
                    r = [*(r or ()), *[0] * (n - len(r or ()))]
                    r[n - 1] += last
            end = len(r)
            while not r[end - 1]:
                end -= 1                        # no orders with that many elements after the last mark
            # a tuple of ints: the collector stops tracking it, so a full collection does not walk
            # every count of every vector (0.4 s on a 300-task plan's memo, inside whichever request)
            r = tuple(r[:end]) if end < len(r) else tuple(r)
            memo[s] = r
            held[0] += entry_bytes(r)
            return r

        return f

    def _merge_plain(self, d: list[int], n1: int, e: int, m: int) -> list[int]:
        """Shuffle a marked piece (vector ``d``, ``n1`` elements) with an unmarked one (``m`` elements, ``e`` orders)."""
        row = self._binom[n1 - 1]
        u = [v * row[i] for i, v in enumerate(d)]
        w = [e * c for c in self._binom[m]]
        return self._unscale(_convolve(u, w), n1, m)

    def _merge(self, d1: list[int], n1: int, d2: list[int], n2: int) -> list[int]:
        """Shuffle two marked pieces: the later of the two marks is the last mark of the union."""
        out = None
        for da, na, db, nb in ((d1, n1, d2, n2), (d2, n2, d1, n1)):
            # the mark of piece a comes last: j <= b_b elements of piece b follow it
            tails = [0] * len(db)
            acc = 0
            for j in range(len(db) - 1, -1, -1):
                acc += db[j]
                tails[j] = acc
            row_a, row_b = self._binom[na - 1], self._binom[nb]
            u = [v * row_a[i] for i, v in enumerate(da)]
            w = [t * row_b[j] for j, t in enumerate(tails)]
            part = self._unscale(_convolve(u, w), na, nb)
            out = part if out is None else _add(out, part)
        return out

    def _unscale(self, w: list[int], na: int, nb: int) -> list[int]:
        """Undo the binomial scaling of a merge of pieces of ``na`` (marked) and ``nb`` elements.

        Entry ``c`` of the merged vector is ``w[c] (N-1-c)! c! / ((na-1)! nb!)``
        with ``N = na + nb``, i.e. ``w[c] C(N-1, nb) / C(N-1, c)`` (exact).
        """
        row = self._binom[na + nb - 1]
        k = row[nb]
        total = na + nb
        return [w[c] * k // row[c] for c in range(min(len(w), total))]


class _BinomialRows:
    """Rows of Pascal's triangle, each computed when first asked for: ``rows[i][k] == comb(i, k)``.

    The whole triangle of a hub path's order (twice the plan's steps: 2,000 on a 1,000-step plan)
    is two million big integers: building it took about a minute, with no deadline, inside one
    decision.  A recursion asks only for the rows of the sizes it merges; each costs O(i) products of
    a big integer by a small one.
    """

    __slots__ = ("_rows",)

    def __init__(self):
        self._rows: dict[int, list[int]] = {}

    def __getitem__(self, i: int) -> list[int]:
        row = self._rows.get(i)
        if row is None:
            row = [1] * (i + 1)
            c = 1
            for k in range(1, i // 2 + 1):
                c = c * (i - k + 1) // k
                row[k] = row[i - k] = c
            self._rows[i] = row
        return row


def _add(u: list[int], w: list[int]) -> list[int]:
    """Elementwise sum of two coefficient lists of any lengths."""
    if len(u) < len(w):
        u, w = w, u
    return [x + y for x, y in zip(u, w)] + u[len(w):]


def _convolve(u: list[int], w: list[int]) -> list[int]:
    """Coefficients of the product of two polynomials with non-negative int coefficients.

    Long ones go through one big-int product (Kronecker substitution: pack
    each list into an int with fields wide enough for any coefficient).
    """
    nu, nw = len(u), len(w)
    if nu < 6 or nw < 6:
        out = [0] * (nu + nw - 1)
        for i, a in enumerate(u):
            if a:
                for j, b in enumerate(w):
                    out[i + j] += a * b
        return out
    width = (max(u).bit_length() + max(w).bit_length() + min(nu, nw).bit_length() + 8) // 8
    pu = int.from_bytes(b"".join(x.to_bytes(width, "little") for x in u), "little")
    pw = int.from_bytes(b"".join(x.to_bytes(width, "little") for x in w), "little")
    k = nu + nw - 1
    raw = (pu * pw).to_bytes(width * k, "little")
    return [int.from_bytes(raw[i * width:(i + 1) * width], "little") for i in range(k)]


def hub_candidates(poset: Poset, s: int, *, max_coupling: int = 4, limit: int | None = None,
                   deadline: Deadline | float | None = None) -> list[tuple[int, list[tuple[int, int]]]]:
    """Elements of ``s`` worth splitting at, best first, with their coupling relations.

    A candidate ``h`` has elements both below and above it in ``s``; its
    coupling relations are the cover pairs ``(b, a)`` with ``a`` above ``h`` and
    ``b`` neither below nor above ``h``.  Candidates with more than
    ``max_coupling`` of them are left out (inclusion–exclusion doubles the work
    per relation).  Order: most cover predecessors first (the branches ``h``
    joins are the glue the split removes), then most elements below, then
    fewest coupling relations.

    ``limit``: only the first ``limit`` candidates are wanted, so the coupling relations are
    found in that order and only until they are known (the same first ``limit`` as the whole
    list).  O(covers) per element looked at: on an order of 2,000 elements every element takes
    about 0.3 s, past a decision's budget.  Past ``deadline`` (a
    :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()`` value) it raises
    :class:`BudgetExceeded`.

    >>> p = Poset.from_pairs(5, [(0, 2), (1, 2), (2, 3), (2, 4)])
    >>> hub_candidates(p, p.full)
    [(2, [])]
    """
    below, above = poset.below, poset.above
    dl = as_deadline(deadline)
    covers = [(a, b) for a, b in poset.cover_pairs(deadline=dl) if s >> a & 1 and s >> b & 1]
    dl.check("the search for a hub")
    indegree = [0] * poset.n
    for _, b in covers:
        indegree[b] += 1
    ranked = sorted((-indegree[h], -(below[h] & s).bit_count(), h) for h in bits(s)
                    if above[h] & s and (below[h] & s).bit_count() >= 2)
    out = []
    for i, (deg, down, h) in enumerate(ranked):
        if limit is not None and len(out) >= limit and (deg, down) != ranked[i - 1][:2]:
            break       # the first `limit` are known: later elements rank below them whatever their coupling
        if dl.expired():
            raise BudgetExceeded("the search for a hub exceeded its time limit", reason="time")
        up = above[h] & s
        related = up | below[h] & s | 1 << h
        coupling = [(b, a) for b, a in covers if up >> a & 1 and not related >> b & 1]
        if len(coupling) <= max_coupling:
            out.append((deg, down, len(coupling), h, coupling))
    out.sort()
    return [(h, coupling) for *_, h, coupling in out[:limit]]


def hub_split(counter: Counter, s: int, *, time_limit: float | None = None, tries: int = 3, probe_memo: int = 100_000,
              deadline: Deadline | float | None = None) -> int | None:
    """Exact count of ``s`` by the first hub split that works within ``time_limit`` seconds and before
    ``deadline`` (the sooner of the two; neither: no limit), else None.

    Takes up to ``tries`` candidates of :func:`hub_candidates`; a candidate is
    used only if the part left without the hub and what follows it is cheap
    for the plain counter (at most ``probe_memo`` new memo entries) — that is
    the sign that the hub was the glue.  On success the count is stored in
    ``counter``'s memo, so later counts that contain ``s`` as a piece are exact.

    >>> p = Poset.from_pairs(6, [(0, 2), (1, 2), (2, 3), (4, 3), (2, 5)])
    >>> hub_split(Counter(p), p.full, time_limit=5) == Counter(p).count()
    True
    """
    dl = as_deadline(deadline).within(time_limit)
    above = counter.poset.above
    saved = counter.max_memo, counter.time_limit
    try:
        try:
            candidates = hub_candidates(counter.poset, s, limit=tries, deadline=dl)
        except BudgetExceeded:
            return None
        for h, coupling in candidates:
            if dl.expired():
                return None
            counter.max_memo, counter.time_limit = probe_memo, None
            try:
                counter.count(s & ~above[h] & ~(1 << h), deadline=dl)
            except BudgetExceeded:
                continue
            counter.max_memo, counter.time_limit = None, None
            try:
                value = hub_count(counter, s, h, coupling, deadline=dl)
            except BudgetExceeded:
                return None
            if value is not None:
                counter.learn(s, value)
                return value
        return None
    finally:
        counter.max_memo, counter.time_limit = saved


def hub_count(counter: Counter, s: int, h: int, coupling: list[tuple[int, int]], *,
              time_limit: float | None = None, deadline: Deadline | float | None = None) -> int | None:
    """Exact number of linear extensions of ``s`` by splitting at hub ``h`` (see the module doc).

    ``coupling`` is the list from :func:`hub_candidates`.  Returns None when a
    term of the inclusion–exclusion does not have the hub form (a reversed
    relation brings new coupling); raises :class:`BudgetExceeded` after
    ``time_limit`` seconds or past ``deadline``, whichever comes first.  Cost: ``2^len(coupling)`` tail distributions
    (sharing one memo) plus small counts of the parts above ``h``.

    >>> p = Poset.from_pairs(6, [(0, 2), (1, 2), (2, 3), (4, 3), (2, 5)])
    >>> hub_count(Counter(p), p.full, 2, [(4, 3)]) == Counter(p).count()
    True
    """
    poset = counter.poset
    dl = as_deadline(deadline).within(time_limit)
    below = poset.below
    down = below[h] & s
    tails = TailCounter(counter, down, deadline=dl)
    dropped = set(coupling)
    base = [pair for pair in poset.cover_pairs(deadline=dl)
            if pair not in dropped and s >> pair[0] & 1 and s >> pair[1] & 1]
    return _over_couplings(poset, s, coupling,
                           lambda flipped: _hub_term(counter, tails, s, h, down, base, flipped, dl), deadline=dl)


def _over_couplings(poset: Poset, s: int, coupling: list[tuple[int, int]], term,
                    deadline: Deadline = Deadline.NEVER) -> int | None:
    """``Σ_F (-1)^|F| term(F)`` over the subsets ``F`` of the coupling relations (the module doc's
    inclusion–exclusion); None as soon as a term is None (still coupled: not of the hub form).

    Twins (same elements below and above within ``s``) are interchangeable, so flipping the
    relation of one twin or of the other gives the same term: it is computed once.  Only twins
    among the coupled elements matter, so only they are compared (O(k^2), not a pass over ``s``).
    """
    below, above = poset.below, poset.above
    twin = {}
    for b, _ in coupling:
        if b not in twin:
            sig = (below[b] & s, above[b] & s)
            for x in twin:
                if twin[x] == x and (below[x] & s, above[x] & s) == sig:
                    twin[b] = x
                    break
            else:
                twin[b] = b
    seen: dict[tuple, int] = {}
    total = 0
    for k in range(len(coupling) + 1):
        for flipped in combinations(coupling, k):
            deadline.check("a hub count")
            key = tuple(sorted((twin[b], a) for b, a in flipped))
            value = seen.get(key)
            if value is None:
                value = seen[key] = term(flipped)
                if value is None:
                    return None
            total += -value if k % 2 else value
    return total


def _hub_term(counter, tails, s, h, down, base, flipped, deadline: Deadline = Deadline.NEVER) -> int | None:
    """e(Q + reversed ``flipped``) on ``s`` by the hub formula (0 if the reversals form a cycle),
    every part of it under the caller's ``deadline``."""
    poset = counter.poset
    try:
        q = Poset.from_pairs(poset.n, base + [(a, b) for b, a in flipped], deadline=deadline)
    except CycleError:
        return 0                                # the reversed relations contradict each other: no orders
    up = q.above[h] & s
    rest = s & ~up & ~(1 << h)
    if any(q.above[b] & up for b in bits(rest & ~down)):
        return None
    # relations inside `rest` are those of the original order (only relations into A changed)
    size_a = up.bit_count()
    e_a = Counter(q, max_memo=None).count(up, deadline=deadline) if up else 1
    d = tails.tail(rest, deadline=deadline)
    return e_a * sum(v * comb(b + 1 + size_a, 1 + size_a) for b, v in enumerate(d))


class _Unavailable(Exception):
    """A piece :class:`HubPath` cannot count (no known hub): the caller counts plainly."""


class HubPath:
    """Exact counts through hubs with memos that persist across calls (one per poset).

    :func:`hub_split` counts one set; a simulation asks for thousands of
    nested sets (what remains, minus one more step each time).  This keeps,
    per hub, one :class:`TailCounter` whose marks are all of ``↓h``: the tail
    distribution of a set depends only on the set, so the vectors of one
    state serve every later state, every inclusion–exclusion term and every
    call, exactly as the plain counter's memo does.  The orders ``Q`` of the
    terms and the counts of the parts above the hub are cached too.

    It works on the poset extended by a *probe* ``z_x = n + x`` above each
    element ``x`` and nothing else: sets without probes are counted as in the
    original poset, and ``e(S + z_x) = Σ over the orders of S of
    (|S| + 1 - position of x)``, so :meth:`position_sum` is two counts (the
    probe is maximal and unrelated to the hub unless ``x`` is above it, so the
    hub form is kept).

    Sets must be up-sets of the original poset (plus probes): then the
    relations inside a set do not depend on the elements outside it, which the
    caches rely on.  :meth:`count` returns None when it cannot help.

    >>> p = Poset.from_pairs(6, [(0, 2), (1, 2), (2, 3), (4, 3), (2, 5)])
    >>> hp = HubPath(p)
    >>> hp.count(p.full, discover=True) == Counter(p).count()
    True
    >>> hp.position_sum(p.full, 4) == Counter(p).position_sums()[4]
    True
    """

    def __init__(self, poset: Poset, *, max_coupling: int = 4, min_down: int = 2, probe_memo: int = 100_000,
                 max_memo: int | None = 2_000_000, deadline: Deadline | float | None = None):
        # ``deadline`` bounds building the extended order (O(n + covers) big-int operations on 2n
        # elements); every count takes its own
        n = self.n = poset.n
        self.base = poset
        self.poset = Poset.from_pairs(2 * n, poset.cover_pairs(deadline=deadline) + [(x, n + x) for x in range(n)],
                                      deadline=deadline)
        self.counter = Counter(self.poset, max_memo=max_memo, max_total=None)
        self.max_coupling = max_coupling
        self.min_down = min_down
        self.probe_memo = probe_memo
        self.tails: dict[int, TailCounter] = {}
        self._covers = self.poset.cover_pairs()
        self._cover_below = [0] * (2 * n)
        for a, b in self._covers:
            self._cover_below[b] |= 1 << a
        self._q: dict[tuple, Poset | None] = {}
        self._up: dict[tuple, int] = {}
        self._up_tables = byte_unions(poset.above, n)
        self._weights: dict[int, list[int]] = {}    # |A| -> the binomials of the hub formula

    def nbytes(self) -> int:
        """Estimated bytes of this path's memos and tables: its counter, every tail memo, the terms'
        orders (O(number of hubs + sampled entries), see :mod:`opportune.engine.memory`)."""
        from opportune.engine.memory import nbytes

        total = self.counter.nbytes() + nbytes(self._q, depth=2) + nbytes(self._up) + nbytes(self._weights)
        total += nbytes(self._up_tables, depth=4) + nbytes(self._covers)
        for tails in list(self.tails.values()):
            total += tails.nbytes() + nbytes(getattr(tails._binom, "_rows", {}))
        return total

    def shrink(self, keep: float = 0.0, deadline: Deadline | float | None = None) -> None:
        """Between calls: keep the newest ``keep`` share of its counter's memo and of every tail memo
        (the compiled ones restart); past ``deadline``, :class:`BudgetExceeded`.  O(entries dropped)."""
        self.counter.shrink(keep, deadline)
        for tails in list(self.tails.values()):
            tails.shrink(keep, deadline)

    # ------------------------------------------------------------ public
    def applies(self, s: int) -> bool:
        """Whether ``s`` (a set of the original poset) holds a known hub with at least ``min_down`` below it."""
        below = self.base.below
        return any(s >> h & 1 and (below[h] & s).bit_count() >= self.min_down for h in self.tails)

    def count(self, s: int, *, deadline: Deadline | float | None = float("inf"), discover: bool = False) -> int | None:
        """Exact count of ``s``: hard pieces through their hub, the rest by the plain counter.

        With ``discover``, a hard piece without a known hub is tried at the
        candidates of :func:`hub_candidates` (as :func:`hub_split` does);
        without, such a piece makes the answer None (the caller counts plainly).
        ``deadline`` (a :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()``
        moment) reaches every count, tail and search of the call: past it, :class:`BudgetExceeded`.
        """
        c = self.counter
        v = c.cached(s)
        if v is not None:
            return v
        if not self._is_upset(s):
            return None
        deadline = as_deadline(deadline).at
        with self._until(deadline):
            return self._count(s, deadline, discover)

    @contextmanager
    def _until(self, deadline: float):
        """Every count of this path's counter (the tails' included) stops at ``deadline``."""
        c = self.counter
        saved = c.deadline
        at = min(deadline, as_deadline(saved).at)       # never later than one the caller set on the counter
        c.deadline = at if at != float("inf") else None
        try:
            yield
        finally:
            c.deadline = saved

    def position_sum(self, s: int, x: int, *, deadline: Deadline | float | None = float("inf")) -> int | None:
        """Sum over the orders of ``s`` of the 1-based position of ``x`` (None when :meth:`count` cannot help).

        Splits ``s`` as the counter does (cut elements, components) down to the
        piece holding ``x``; on that piece, ``(|piece| + 1) e(piece) - e(piece + z_x)``.
        """
        if not self._is_upset(s) or not s >> x & 1:
            return None
        deadline = as_deadline(deadline).at
        try:
            with self._until(deadline):
                return self._pos(s, x, deadline)
        except _Unavailable:
            return None

    def _pos(self, t: int, x: int, deadline: float) -> int:
        if t == 1 << x:
            return 1
        below, above = self.poset.below, self.poset.above
        e = self._count(t, deadline, False)
        if e is None:
            raise _Unavailable
        mins, cuts = self.counter.scan(t)
        if cuts:
            if cuts >> x & 1:
                return ((below[x] & t).bit_count() + 1) * e
            block = t & ~cuts
            offset = 0
            for z in bits(cuts):
                if below[x] >> z & 1:
                    block &= above[z]
                    offset = max(offset, (below[z] & t).bit_count() + 1)
                else:
                    block &= below[z]
            eb = self._count(block, deadline, False) if block & (block - 1) else 1
            if eb is None:
                raise _Unavailable
            return e // eb * self._pos(block, x, deadline) + offset * e
        comps = components(above, t, mins)
        if len(comps) > 1:
            piece = next(c for c in comps if c >> x & 1)
            ec = self._count(piece, deadline, False) if piece & (piece - 1) else 1
            if ec is None:
                raise _Unavailable
            n, k = t.bit_count(), piece.bit_count()
            return e // ec * (n + 1) // (k + 1) * self._pos(piece, x, deadline)
        plus = self._count(t | 1 << (self.n + x), deadline, False)
        if plus is None:
            raise _Unavailable
        return (t.bit_count() + 1) * e - plus

    def _count(self, s: int, deadline: float, discover: bool) -> int | None:
        c = self.counter
        v = c.cached(s)
        if v is not None:
            return v
        for piece in self._hard_pieces(s):
            v = self._piece(piece, deadline, discover)
            if v is None:
                return None
            c.learn(piece, v)
        return self._plain(s, deadline)

    # ------------------------------------------------------------ internals
    def _is_upset(self, s: int) -> bool:
        """Whether the original elements of ``s`` hold everything above them: the union of their
        successors, by one table look-up per byte of the set (see :func:`~opportune.engine.poset.byte_unions`)."""
        core = s & ((1 << self.n) - 1)
        union = 0
        for table, byte in zip(self._up_tables, core.to_bytes(len(self._up_tables), "little")):
            if byte:
                union |= table[byte]
        return not union & ~core

    def _hard_pieces(self, s: int) -> list[int]:
        """The pieces of ``s`` the plain counter cannot split (connected, no cut element) and has not counted."""
        c = self.counter
        below, above = self.poset.below, self.poset.above
        deadline = as_deadline(c.deadline).at       # set by _until for the whole call
        out = []
        stack = [s]
        while stack:
            t = stack.pop()
            if t & (t - 1) == 0 or c.cached(t) is not None:
                continue
            if time.perf_counter() > deadline:     # each split is O(n) or more
                raise BudgetExceeded("hub count exceeded its time limit", reason="time", memo_size=c.memo_size)
            mins, cuts = c.scan(t)
            if cuts:
                stack.extend(cut_blocks(below, above, t, cuts))
                continue
            comps = components(above, t, mins, deadline=deadline)
            if len(comps) > 1:
                stack.extend(comps)
                continue
            out.append(t)
        return out

    def _piece(self, s: int, deadline: float, discover: bool) -> int | None:
        below = self.poset.below
        best = None
        for h in self.tails:
            if s >> h & 1:
                k = (below[h] & s).bit_count()
                if k >= self.min_down and (best is None or k > best[0]):
                    best = (k, h)
        if best is not None:
            v = self._hub_count(s, best[1], deadline)
            if v is not None:
                return v
        if s.bit_count() < 24:
            return self._plain(s, deadline)     # small pieces: nothing to gain
        if not discover:
            return None                         # the caller counts it plainly, under its own budget
        above = self.poset.above
        c = self.counter
        for h, _ in hub_candidates(self.poset, s, max_coupling=self.max_coupling, limit=3, deadline=deadline):
            if h in self.tails or (below[h] & s).bit_count() < self.min_down:
                continue
            saved = c.max_memo, c.time_limit
            c.max_memo, c.time_limit = self.probe_memo, max(deadline - time.perf_counter(), 0.0) if deadline != float("inf") else None
            try:
                c.count(s & ~above[h] & ~(1 << h))     # the hub is the glue only if the rest is cheap
            except BudgetExceeded as exc:
                if exc.reason == "time":
                    raise
                continue
            finally:
                c.max_memo, c.time_limit = saved
            self.tails[h] = TailCounter(c, below[h], deadline=deadline)
            v = self._hub_count(s, h, deadline)
            if v is not None:
                return v
            del self.tails[h]
        return None

    def _plain(self, s: int, deadline: float) -> int:
        """The plain counter's count of ``s`` (its hard pieces already learnt), within ``deadline``."""
        c = self.counter
        saved = c.time_limit
        c.time_limit = max(deadline - time.perf_counter(), 0.0) if deadline != float("inf") else None
        try:
            return c.count(s)
        finally:
            c.time_limit = saved

    def _hub_count(self, s: int, h: int, deadline: float) -> int | None:
        """:func:`hub_count` with the persistent tail memo of ``h`` and cached orders ``Q``."""
        below, above = self.poset.below, self.poset.above
        down = below[h] & s
        up0 = above[h] & s
        related = up0 | down | 1 << h
        cb = self._cover_below
        coupling = [(b, a) for a in bits(up0) for b in bits(cb[a] & s & ~related)]
        if len(coupling) > self.max_coupling:
            return None
        tails = self.tails[h]
        tails.deadline = deadline
        ckey = tuple(sorted(coupling))
        return _over_couplings(self.poset, s, coupling,
                               lambda flipped: self._term(s, h, down, ckey, tuple(flipped), tails),
                               deadline=as_deadline(deadline))

    def _term(self, s, h, down, ckey, flipped, tails) -> int | None:
        qkey = (h, ckey, flipped)
        if qkey in self._q:
            q = self._q[qkey]
        else:
            dropped = set(ckey)
            try:
                q = Poset.from_pairs(self.poset.n, [p for p in self._covers if p not in dropped]
                                     + [(a, b) for b, a in flipped], deadline=tails.deadline)
            except CycleError:
                q = None
            self._q[qkey] = q
        if q is None:
            return 0
        up = q.above[h] & s
        rest = s & ~up & ~(1 << h)
        # still coupled if an unrelated step lies below a step of A (A is the smaller side to scan)
        qb = q.below
        loose = rest & ~down
        for a in bits(up):
            if qb[a] & loose:
                return None
        size_a = up.bit_count()
        ukey = (qkey, up)
        e_a = self._up.get(ukey)
        if e_a is None:
            # what follows the hub can be large too (a big plan): bounded by the same deadline
            e_a = self._up[ukey] = (Counter(q, max_memo=None).count(up, deadline=tails.deadline) if up else 1)
        d = tails.tail(rest)
        weights = self._weights.get(size_a)
        if weights is None or len(weights) < len(d):
            weights = self._weights[size_a] = [comb(b + 1 + size_a, 1 + size_a) for b in range(self.n + 1)]
        return e_a * sum(map(mul, d, weights))
