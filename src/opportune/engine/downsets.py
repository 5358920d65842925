"""A second, independent exact method: dynamic programming over the lattice of down-sets.

A linear extension of ``S`` is a path ``∅ = D0 ⊂ D1 ⊂ ... ⊂ Dk = S`` in the
lattice of down-sets of ``S`` that adds one element per step.  Counting paths
level by level (down-sets of size 0, 1, 2, ...) gives ``e(S)``; counting them
from both ends gives the position sums.  No decomposition is used, so the cost
is proportional to the number of down-sets (up to ``2^|S|``): use it for tests
and small cases.  :class:`~opportune.engine.count.Counter` is the fast method.
"""

from __future__ import annotations

import time

from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline, recursion_room
from opportune.engine.poset import LazyUnion, Poset, bits
from opportune.engine.tuning import CHUNK_TABLES_UP_TO as _TABLES_UP_TO

__all__ = ["count_by_downsets", "position_sums_by_downsets", "count_downsets"]



def _setup(poset: Poset, mask: int | None, dl: Deadline = Deadline.NEVER):
    if mask is None:
        mask = poset.full
    if mask < 0 or mask & ~poset.full:
        raise ValueError(f"mask {mask!r} is not a subset of 0..{poset.n - 1}")
    below = [b & mask for b in poset.below]
    # Upper covers inside the induced subposet: the only candidates that can
    # become available when an element is added to a down-set.
    ucov = [0] * poset.n
    for x in bits(mask):
        dl.check("the covers of an order")     # O(elements above x) each
        up = poset.above[x] & mask
        cov = up
        for y in bits(up):
            cov &= ~poset.above[y]
        ucov[x] = cov
    return mask, below, ucov


def _levels(poset: Poset, mask: int | None, deadline: Deadline | float | None = None):
    """Yield the levels of the down-set lattice as ``(mask, paths, avail)``: dicts from each down-set
    ``D`` of the level to the number of paths to ``D`` and to its available elements.

    Two dicts of ints, not one of pairs: millions of small containers would make the garbage
    collector walk them all, uninterruptibly.  Past ``deadline``,
    :class:`~opportune.engine.deadline.BudgetExceeded` (read every 256 steps to a new down-set)."""
    dl = as_deadline(deadline)
    mask, below, ucov = _setup(poset, mask, dl)
    avail0 = 0
    for x in bits(mask):
        if not below[x]:
            avail0 |= 1 << x
    paths, avail = {0: 1}, {0: avail0}
    yield mask, paths, avail
    for _ in range(mask.bit_count()):
        npaths: dict[int, int] = {}
        navail: dict[int, int] = {}
        get = npaths.get
        work = 0
        for d, cnt in paths.items():
            av = avail[d]
            m = av
            while m:
                work += 1
                if not work & 255:      # by new down-sets, not old ones: a wide order has hundreds each
                    dl.check("the dynamic programme over down-sets")
                b = m & -m
                m ^= b
                e = d | b
                old = get(e)
                if old is None:
                    x = b.bit_length() - 1
                    nav = av ^ b
                    for y in bits(ucov[x]):
                        if not below[y] & ~e:
                            nav |= 1 << y
                    npaths[e] = cnt
                    navail[e] = nav
                else:
                    npaths[e] = old + cnt
        paths, avail = npaths, navail
        yield mask, paths, avail


def count_by_downsets(poset: Poset, mask: int | None = None, *, deadline: Deadline | float | None = None) -> int:
    """Number of linear extensions of the subposet induced on ``mask``, by DP over its down-sets.

    O(number of down-sets × width) big-int additions, O(largest level) memory; past ``deadline``,
    :class:`~opportune.engine.deadline.BudgetExceeded`.

    >>> count_by_downsets(Poset.from_pairs(4, [(0, 1), (2, 3)]))
    6
    >>> count_by_downsets(Poset.from_pairs(3, [(0, 1), (1, 2)]), 0b101)
    1
    """
    last = None
    for _, paths, _ in _levels(poset, mask, deadline):
        last = paths
    assert last is not None and len(last) == 1
    (cnt,) = last.values()
    return cnt


def count_downsets(poset: Poset, mask: int | None = None, *, deadline: Deadline | float | None = None) -> int:
    """Number of down-sets (order ideals, including ∅ and ``mask``) of the subposet induced on ``mask``.

    Same cost and ``deadline`` as :func:`count_by_downsets`.

    >>> count_downsets(Poset.antichain(3))
    8
    """
    return sum(len(paths) for _, paths, _ in _levels(poset, mask, deadline))


def position_sums_by_downsets(poset: Poset, mask: int | None = None, *,
                              deadline: Deadline | float | None = None) -> dict[int, int]:
    """For every ``x`` in ``mask``: the sum over all linear extensions of ``mask`` of the 1-based position of ``x``.

    ``x`` is at position ``|D| + 1`` in exactly ``F(D) * B(D ∪ {x})`` extensions,
    where ``F(D)`` counts the ways to reach the down-set ``D`` and ``B(E)`` the
    ways to finish from ``E``.  O(number of down-sets × width) big-int
    operations and memory for the whole lattice; past ``deadline``,
    :class:`~opportune.engine.deadline.BudgetExceeded`.

    >>> position_sums_by_downsets(Poset.from_pairs(3, [(0, 1)]))
    {0: 4, 1: 8, 2: 6}
    """
    dl = as_deadline(deadline)
    levels = []
    m = None
    for m, paths, avail in _levels(poset, mask, dl):
        levels.append((paths, avail))
    assert m is not None
    back: dict[int, int] = {m: 1}
    sums = {x: 0 for x in bits(m)}
    for size in range(len(levels) - 2, -1, -1):
        nb: dict[int, int] = {}
        paths, avail = levels[size]
        work = 0
        for d, cnt in paths.items():
            total = 0
            a = avail[d]
            while a:
                work += 1
                if not work & 255:
                    dl.check("position sums over down-sets")
                b = a & -a
                a ^= b
                v = back[d | b]
                total += v
                sums[b.bit_length() - 1] += cnt * v * (size + 1)
            nb[d] = total
        back = nb
    return sums


# ---------------------------------------------------------------- the fast versions the counter uses


def count_downsets_bounded(poset: Poset, mask: int | None = None, *, limit: int = 20_000,
                           deadline: Deadline | float | None = None) -> int | None:
    """Number of down-sets of the subposet induced on ``mask``, or None if finding it would take
    more than ``limit`` memoised sets (then there are usually very many), or would end after
    ``deadline`` (a :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()``
    value; the caller tells the two apart by the clock).

    Much cheaper than listing them: branch on the element ``x`` with the most
    comparable elements — a down-set either holds ``x`` (and everything below
    it) or not (and nothing above it) — and multiply the counts of pieces
    that fall apart, memoised on what is left.  The counter uses it to tell
    whether the dynamic programme over down-sets is affordable for a piece.

    >>> count_downsets_bounded(Poset.antichain(3)), count_downsets_bounded(Poset.chain(3))
    (8, 4)
    >>> count_downsets_bounded(Poset.antichain(40), limit=10) == 2 ** 40     # found without listing them
    True
    """
    if mask is None:
        mask = poset.full
    below, above = poset.below, poset.above
    nbr = [b | a for b, a in zip(below, above)]
    memo: dict[int, int] = {0: 1}
    calls = [0]
    at = as_deadline(deadline).at
    deadline = at if at != float("inf") else None
    every = 7 if mask.bit_count() <= 256 else 0     # a call on a large set is O(n) big-int operations

    def f(s: int) -> int | None:
        r = memo.get(s)
        if r is not None:
            return r
        calls[0] += 1
        if calls[0] > limit:
            return None
        if deadline is not None and not calls[0] & every and time.perf_counter() > deadline:
            return None
        # elements comparable to nothing else in s double the count; then one connected piece
        # (closure under comparability from the lowest element)
        near = 0
        m = s
        while m:
            b = m & -m
            m ^= b
            near |= nbr[b.bit_length() - 1]
        iso = s & ~near
        if iso:
            r = f(s ^ iso)
            r = r << iso.bit_count() if r is not None else None
            if r is not None:
                memo[s] = r
            return r
        comp = front = s & -s
        while front:
            b = front & -front
            front ^= b
            new = nbr[b.bit_length() - 1] & s & ~comp
            comp |= new
            front |= new
        if comp != s:
            a = f(comp)
            b = f(s ^ comp) if a is not None else None
            r = a * b if b is not None else None
        else:
            x = max(bits(s), key=lambda i: (nbr[i] & s).bit_count())
            a = f(s & ~(below[x] | 1 << x))          # x in the down-set: what is left above/beside it
            b = f(s & ~(above[x] | 1 << x)) if a is not None else None
            r = a + b if b is not None else None
        if r is not None:
            memo[s] = r
        return r

    with recursion_room(3 * mask.bit_count() + 200):
        return f(mask)


def upset_counts(poset: Poset, mask: int | None = None, *, keep: int = 1,
                 deadline: Deadline | float | None = float("inf"),
                 max_sets: int | None = None) -> tuple[int, dict[int, int]] | None:
    """``(e(mask), top)`` by the dynamic programme over the up-sets of ``mask``, smallest first.

    ``e(U) = sum over minimal m of e(U - m)``: every up-set ``U`` of ``mask``
    is reached from the up-sets one smaller, level by level, so the cost is
    the number of down-sets (as :func:`count_by_downsets`) at a few
    bytecodes each, with no decomposition and no memo; the levels are
    forgotten as it goes.  ``top`` holds ``e(U)`` of the up-sets with at
    least ``|mask| - keep`` elements (``mask`` itself and what remains after
    removing up to ``keep`` first elements: the questions a simulation asks
    next).  None if ``time.perf_counter()`` passes ``deadline`` (a
    :class:`~opportune.engine.deadline.Deadline` or a ``perf_counter`` moment) or the sets
    visited exceed ``max_sets``.

    Elements are renumbered to the piece, and "minimal in what is left" is a
    table look-up per chunk of up to 14 bits.

    >>> upset_counts(Poset.from_pairs(3, [(0, 1)]))
    (3, {3: 1, 6: 2, 7: 3})
    """
    if mask is None:
        mask = poset.full
    dl = as_deadline(deadline)
    if mask == poset.full:
        sub, old = poset, list(range(poset.n))
    else:
        try:
            sub, old = poset.restrict(mask, deadline=dl)
        except BudgetExceeded:
            return None
    if sub.n <= 1:
        return 1, {mask: 1}
    chunks = _chunk_tables(sub.below, sub.n, dl)
    if chunks is None:
        return None
    found = _upset_levels(sub, *chunks, keep, dl.at, max_sets if max_sets is not None else float("inf"))
    if found is None:
        return None
    value, top_local = found
    top = {}
    for u, v in top_local.items():
        g = 0
        for i in bits(u):
            g |= 1 << old[i]
        top[g] = v
    return value, top


def _chunk_tables(below: list[int], k: int, dl: Deadline) -> tuple[list, int, int] | None:
    """``(tables, chunk width c, chunks)``: ``tables[j][v]`` is the union of what lies below the
    elements of chunk ``j`` that the bits ``v`` hold (None past ``dl``)."""
    if k <= _TABLES_UP_TO:
        nch = -(-k // 14)
        c = -(-k // nch)
        tables = []
        for j in range(nch):
            vals = below[j * c:(j + 1) * c]
            t = [0] * (1 << len(vals))
            for v in range(1, len(t)):
                low = v & -v
                t[v] = t[v ^ low] | vals[low.bit_length() - 1]
            tables.append(t)
            if dl.expired():
                return None
    else:
        # 2^14 entries of k bits per 14 elements would take gigabytes on a large order: byte
        # tables filled on demand (none of this finishes in time there, but it stops in time)
        c = 8
        nch = -(-k // c)
        tables = [LazyUnion(below[j * c:(j + 1) * c]) for j in range(nch)]
    return tables, c, nch


def _upset_levels(sub: Poset, tables: list, c: int, nch: int, keep: int, deadline: float,
                  limit: float) -> tuple[int, dict[int, int]] | None:
    """The levels of :func:`upset_counts` on the renumbered piece ``sub``: ``(e(sub), the counts of
    its up-sets of at least |sub| - keep elements)``, or None past ``deadline`` (a ``perf_counter``
    moment) or ``limit`` sets.  The hot loop: its names are locals."""
    import time

    k = sub.n
    cm = (1 << c) - 1
    # sets between two readings of the clock: each costs a look-up per chunk
    every = 1023 if nch <= 4 else 63 if nch <= 32 else 0
    unrolled = nch <= 4
    T0, T1, T2, T3 = (tables + [[0], [0], [0]])[:4]
    c2, c3 = 2 * c, 3 * c
    full = sub.full
    perf = time.perf_counter
    seen = 1
    level: dict[int, int] = {0: 1}
    top_local: dict[int, int] = {}
    for size in range(k):
        nxt: dict[int, int] = {}
        get = nxt.get
        done = 0
        for u, v in level.items():
            r = full ^ u                        # not yet in U: its maximal elements may join
            if unrolled:
                d = T0[r & cm] | T1[r >> c & cm] | T2[r >> c2 & cm] | T3[r >> c3]
            else:
                d = 0
                x = r
                for t in tables:
                    d |= t[x & cm]
                    x >>= c
            m = r & ~d
            done += 1
            if m & (m - 1) and k > 64:
                # many elements may join one set of a wide order: read the clock as they do
                while m:
                    b = m & -m
                    m ^= b
                    w = u | b
                    nxt[w] = get(w, 0) + v
                    done += 1
                    if not done & 255 and perf() > deadline:
                        return None
            else:
                while m:
                    b = m & -m
                    m ^= b
                    w = u | b
                    nxt[w] = get(w, 0) + v
            if not done & every and perf() > deadline:
                return None
        level = nxt
        seen += len(level)
        if seen > limit or perf() > deadline:
            return None
        if size + 1 >= k - keep:
            top_local.update(level)
    (value,) = level.values()
    return value, top_local
