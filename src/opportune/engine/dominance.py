"""Decisions the order alone settles: comparisons of options and expected positions without counting.

The paper's rule compares two kinds of numbers, and both can often be compared from the
partial order of what remains, in time linear in the candidates, where counting them may
take milliseconds to seconds on a large plan:

* **Options** (install rule).  For two minimal steps ``c`` and ``d``, if every step that
  must follow ``d`` must also follow ``c`` (``up(d) ⊆ up(c)``), then installing ``c``
  keeps at least as many completions as installing ``d``: swapping ``c`` and ``d`` maps
  every completion that starts with ``d`` to a distinct one that starts with ``c``.  If the
  inclusion is strict, some completion starting with ``c`` is not such an image, so
  ``c`` keeps strictly more.
* **Expected positions** (buffer rule).  If ``down(a) ⊆ down(b)`` and ``up(a) ⊇ up(b)``,
  swapping ``a`` and ``b`` maps every completion with ``b`` before ``a`` to one with ``a``
  before ``b`` (the pairs cancel in the difference of positions), so
  ``E[pos a] ≤ E[pos b]``, strictly unless the two have the same predecessors and
  successors (then they are interchangeable and equal).  Separately, every completion
  puts ``a`` at a position in ``[|down(a)| + 1, n - |up(a)|]``; disjoint ranges settle
  the comparison too.

Equal signatures (the same predecessors and successors among what remains) mean equal
values, so the exact tie-breaks decide between them, as they would after counting.
These results hold for one partial order; with several consistent strategies the
counts are of a union, and the functions here are not used.

>>> from opportune.engine.poset import Poset
>>> p = Poset.from_pairs(4, [(0, 2), (0, 3), (1, 3)])   # 0 < 2, 0 < 3, 1 < 3
>>> most_options_by_order(p, 0b1111, [0, 1])             # up(1) = {3} ⊂ up(0) = {2, 3}
[0]
>>> earliest_by_order(p, 0b1111, [2, 3])                 # down(2) = {0} ⊂ down(3), up equal
[2]
"""

from __future__ import annotations

from typing import Sequence

from opportune.engine.deadline import Deadline, as_deadline
from opportune.engine.poset import Poset

__all__ = ["most_options_by_order", "earliest_by_order"]


def most_options_by_order(poset: Poset, remaining: int, units: Sequence[int], *,
                          deadline: Deadline | float | None = None) -> list[int] | None:
    """The minimal ``units`` that provably keep the most completions, or None if the order does not settle it.

    Returns the units whose successors among ``remaining`` include every other
    candidate's (they all keep the same, largest number of completions; every other
    candidate keeps strictly fewer).  None when no candidate's successors include all the
    others'.  O(k) set operations on bitmasks for k candidates; past ``deadline`` (read
    every 256 candidates), :class:`~opportune.engine.deadline.BudgetExceeded`.

    >>> from opportune.engine.poset import Poset
    >>> most_options_by_order(Poset.from_pairs(3, [(0, 2)]), 0b111, [0, 1])
    [0]
    >>> most_options_by_order(Poset.from_pairs(4, [(0, 2), (1, 3)]), 0b1111, [0, 1]) is None
    True
    """
    dl = as_deadline(deadline)
    above = poset.above
    ups = [above[u] & remaining for u in units]
    dl.check("comparing options by the order")
    union = 0
    for k, up in enumerate(ups):
        union |= up
        if not k & 255:
            dl.check("comparing options by the order")
    best = [u for u, up in zip(units, ups) if up == union]
    return best or None


def earliest_by_order(poset: Poset, remaining: int, units: Sequence[int], *,
                      deadline: Deadline | float | None = None) -> list[int] | None:
    """The ``units`` provably needed earliest (least expected position in a uniformly random completion
    of ``remaining``), or None if the order does not settle it.

    A unit wins if, against every other candidate, it has the same predecessors and
    successors (equal expected positions), or dominates it (fewer predecessors and more
    successors, by inclusion), or its latest possible position comes before the other's
    earliest.  Returns the winner with every candidate interchangeable with it.  O(k²)
    bitmask operations for k candidates; past ``deadline`` (read for every candidate),
    :class:`~opportune.engine.deadline.BudgetExceeded`.

    >>> from opportune.engine.poset import Poset
    >>> earliest_by_order(Poset.from_pairs(3, [(0, 1)]), 0b111, [1, 0])
    [0]
    >>> earliest_by_order(Poset.from_pairs(4, [(0, 1), (2, 3)]), 0b1111, [1, 3]) is None   # symmetric: not settled
    True
    """
    dl = as_deadline(deadline)
    below, above = poset.below, poset.above
    n = remaining.bit_count()
    sig = [(below[u] & remaining, above[u] & remaining) for u in units]
    for i, (down_a, up_a) in enumerate(sig):
        dl.check("comparing expected positions by the order")
        latest = n - up_a.bit_count()
        for j, (down_b, up_b) in enumerate(sig):
            if not j & 1023:
                dl.check("comparing expected positions by the order")
            if i == j or (down_a == down_b and up_a == up_b):
                continue
            if down_a & ~down_b == 0 and up_b & ~up_a == 0:
                continue        # a dominates b: strictly earlier (the signatures differ)
            if latest < down_b.bit_count() + 1:
                continue        # a's latest position comes before b's earliest
            break
        else:
            return [u for u, s in zip(units, sig) if s == (down_a, up_a)]
    return None
