"""A second, independent exact method: dynamic programming over the lattice of down-sets.

A linear extension of ``S`` is a path ``∅ = D0 ⊂ D1 ⊂ ... ⊂ Dk = S`` in the
lattice of down-sets of ``S`` that adds one element per step.  Counting paths
level by level (down-sets of size 0, 1, 2, ...) gives ``e(S)``; counting them
from both ends gives the position sums.  No decomposition is used, so the cost
is proportional to the number of down-sets (up to ``2^|S|``): use it for tests
and small cases.  :class:`~opportune.engine.count.Counter` is the fast method.
"""

from __future__ import annotations

from opportune.engine.poset import Poset, bits

__all__ = ["count_by_downsets", "position_sums_by_downsets", "count_downsets"]


def _setup(poset: Poset, mask: int | None):
    if mask is None:
        mask = poset.full
    if mask < 0 or mask & ~poset.full:
        raise ValueError(f"mask {mask!r} is not a subset of 0..{poset.n - 1}")
    below = [b & mask for b in poset.below]
    # Upper covers inside the induced subposet: the only candidates that can
    # become available when an element is added to a down-set.
    ucov = [0] * poset.n
    for x in bits(mask):
        up = poset.above[x] & mask
        cov = up
        for y in bits(up):
            cov &= ~poset.above[y]
        ucov[x] = cov
    return mask, below, ucov


def _levels(poset: Poset, mask: int | None):
    """Yield the levels of the down-set lattice as dicts ``D -> (paths to D, available elements)``."""
    mask, below, ucov = _setup(poset, mask)
    avail0 = 0
    for x in bits(mask):
        if not below[x]:
            avail0 |= 1 << x
    level = {0: [1, avail0]}
    yield mask, level
    for _ in range(mask.bit_count()):
        nxt: dict[int, list] = {}
        for d, (cnt, av) in level.items():
            m = av
            while m:
                b = m & -m
                m ^= b
                e = d | b
                slot = nxt.get(e)
                if slot is None:
                    x = b.bit_length() - 1
                    nav = av ^ b
                    for y in bits(ucov[x]):
                        if not below[y] & ~e:
                            nav |= 1 << y
                    nxt[e] = [cnt, nav]
                else:
                    slot[0] += cnt
        level = nxt
        yield mask, level


def count_by_downsets(poset: Poset, mask: int | None = None) -> int:
    """Number of linear extensions of the subposet induced on ``mask``, by DP over its down-sets.

    O(number of down-sets × width) big-int additions, O(largest level) memory.

    >>> count_by_downsets(Poset.from_pairs(4, [(0, 1), (2, 3)]))
    6
    >>> count_by_downsets(Poset.from_pairs(3, [(0, 1), (1, 2)]), 0b101)
    1
    """
    last = None
    for _, level in _levels(poset, mask):
        last = level
    assert last is not None and len(last) == 1
    (cnt, _), = last.values()
    return cnt


def count_downsets(poset: Poset, mask: int | None = None) -> int:
    """Number of down-sets (order ideals, including ∅ and ``mask``) of the subposet induced on ``mask``.

    Same cost as :func:`count_by_downsets`.

    >>> count_downsets(Poset.antichain(3))
    8
    """
    return sum(len(level) for _, level in _levels(poset, mask))


def position_sums_by_downsets(poset: Poset, mask: int | None = None) -> dict[int, int]:
    """For every ``x`` in ``mask``: the sum over all linear extensions of ``mask`` of the 1-based position of ``x``.

    ``x`` is at position ``|D| + 1`` in exactly ``F(D) * B(D ∪ {x})`` extensions,
    where ``F(D)`` counts the ways to reach the down-set ``D`` and ``B(E)`` the
    ways to finish from ``E``.  O(number of down-sets × width) big-int
    operations and memory for the whole lattice.

    >>> position_sums_by_downsets(Poset.from_pairs(3, [(0, 1)]))
    {0: 4, 1: 8, 2: 6}
    """
    levels = []
    m = None
    for m, level in _levels(poset, mask):
        levels.append(level)
    assert m is not None
    back: dict[int, int] = {m: 1}
    sums = {x: 0 for x in bits(m)}
    for size in range(len(levels) - 2, -1, -1):
        nb: dict[int, int] = {}
        for d, (cnt, av) in levels[size].items():
            total = 0
            a = av
            while a:
                b = a & -a
                a ^= b
                v = back[d | b]
                total += v
                sums[b.bit_length() - 1] += cnt * v * (size + 1)
            nb[d] = total
        back = nb
    return sums
