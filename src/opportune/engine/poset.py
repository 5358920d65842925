"""Strict partial orders on ``0..n-1`` stored as bitmasks.

A :class:`Poset` keeps, for every element ``i``, the bitmask ``below[i]`` of all
elements strictly before it and ``above[i]`` of all elements strictly after it
(the transitive closure, so "is ``a`` before ``b``" is one bit test).  Subsets of
the elements are Python ints used as bitmasks: bit ``i`` set means element
``i`` is in the set.

>>> p = Poset.from_pairs(4, [(0, 1), (1, 2)])
>>> [bin(m) for m in p.below]
['0b0', '0b1', '0b11', '0b0']
>>> p.minimal(p.full)          # elements 0 and 3
9
>>> p.cover_pairs()
[(0, 1), (1, 2)]
"""

from __future__ import annotations

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:       # pragma: no cover
    from typing import Iterable, Iterator, Sequence

    from opportune.engine.deadline import Deadline


from opportune.planning.orders import CycleError  # noqa: E402  (a plan's order can have one too)


def _clock(deadline):
    """``check()``: raises :class:`~opportune.engine.deadline.BudgetExceeded` once ``deadline`` (a
    Deadline, a ``time.perf_counter()`` moment or None) has passed; None when there is none, so that
    the loops below cost nothing without one."""
    if deadline is None:
        return None
    from opportune.engine.deadline import as_deadline

    d = as_deadline(deadline)
    return d.check if d.finite else None

__all__ = ["CycleError", "LazyMeet", "LazyUnion", "Poset", "bits", "byte_unions", "components", "cut_blocks", "cut_chain", "elements",
           "split_components"]


#: The set bits of each byte value, for :func:`bits` on wide masks.
_BYTE_BITS = tuple(tuple(k for k in range(8) if v >> k & 1) for v in range(256))


def bits(mask: int) -> Iterator[int]:
    """Yield the indices of the set bits of ``mask`` in increasing order.

    O(n / 8 + popcount) for an n-bit mask: above a few machine words, a byte of its little-endian
    bytes at a time, or by searching its binary text when few bits are set (each step of the
    lowest-bit loop copies the whole integer, which is O(popcount × n / 64) on a wide mask).

    >>> list(bits(0b10110)), list(bits(1 << 999 | 5))
    ([1, 2, 4], [0, 2, 999])
    """
    if mask.bit_length() <= 256:
        while mask:
            low = mask & -mask
            yield low.bit_length() - 1
            mask ^= low
        return
    if mask.bit_count() * 32 < mask.bit_length():   # sparse: find the ones in its binary text
        text = bin(mask)
        top = len(text) - 1
        at = text.rfind("1", 2)
        while at != -1:
            yield top - at
            at = text.rfind("1", 2, at)
        return
    table = _BYTE_BITS
    for j, byte in enumerate(mask.to_bytes((mask.bit_length() + 7) // 8, "little")):
        if byte:
            base = 8 * j
            for k in table[byte]:
                yield base + k


def elements(mask: int) -> list[int]:
    """The indices of the set bits of ``mask`` as a sorted list.

    >>> elements(0b1001)
    [0, 3]
    """
    return list(bits(mask))


def _apart(related: Sequence[int], mask: int) -> int:
    """The members ``x`` of ``mask`` with nothing of ``mask`` in ``related[x]`` (the minimal elements
    with ``below``, the maximal ones with ``above``).  O(popcount(mask))."""
    out = 0
    m = mask
    while m:
        low = m & -m
        m ^= low
        if not related[low.bit_length() - 1] & mask:
            out |= low
    return out


class LazyUnion(dict):
    """A byte table built on demand: entry ``v`` is the union (``|``) of ``vals[j]`` over the bits ``j`` of ``v``."""

    def __init__(self, vals: list[int]):
        super().__init__()
        self.vals = vals

    def __missing__(self, v: int) -> int:
        vals = self.vals
        r = 0
        for j in bits(v):
            if j < len(vals):
                r |= vals[j]
        self[v] = r
        return r


class LazyMeet(LazyUnion):
    """As :class:`LazyUnion`, with the intersection (``&``; ``-1`` for no bits)."""

    def __missing__(self, v: int) -> int:
        vals = self.vals
        r = -1
        for j in bits(v):
            if j < len(vals):
                r &= vals[j]
        self[v] = r
        return r


def byte_unions(sets: Sequence[int], n: int, width: int = 8) -> list[list[int]]:
    """For each byte ``j`` of an ``n``-bit set: the union of ``sets[8 j + i]`` over the bits ``i`` of
    every byte value (index 0..255).  With them, the union of ``sets[x]`` over the elements ``x`` of a
    set takes one look-up per byte of the set instead of one step per element.  O(n / 8 · 256) to build.

    ``width=4``: tables of 16 entries per four bits instead (chunk ``j`` is bits ``4 j`` to ``4 j + 3``):
    two look-ups per byte, an eighth of the memory and the time to build.

    >>> byte_unions([0b10, 0b100], 2)[0][0b11]     # elements 0 and 1: sets[0] | sets[1]
    6
    >>> byte_unions([0b10, 0b100, 0, 0, 0b1], 5, width=4)[1][0b1]   # element 4
    1
    """
    size = 1 << width
    out = []
    for j in range((n + width - 1) // width or 1):
        table = [0] * size
        for v in range(1, size):
            low = v & -v
            i = width * j + low.bit_length() - 1
            table[v] = table[v ^ low] | (sets[i] if i < n else 0)
        out.append(table)
    return out


def split_components(above: Sequence[int], s: int, mins: int, check=None) -> tuple[list[int], int]:
    """``(pieces, lone)``: the connected pieces of ``s`` under comparability that have two elements or
    more, and the set of its elements comparable to nothing else in ``s``, given its minimal
    elements ``mins``.

    Every element lies above a minimal one, so the pieces are the overlap classes of the sets
    ``{m} | above[m] & s``.  O(|mins| · pieces) mask operations, the lone elements gathered in
    O(n / 8) (or-ing each into a mask would copy it every time: quadratic on a wide antichain);
    ``check()``, if given, is called every 2,048 merges (it raises to stop).

    >>> split_components([0b010, 0, 0], 0b111, 0b101)     # 0 < 1; 2 alone
    ([3], 4)
    """
    comps: list[int] = []
    lone: list[int] = []
    work = 0
    for i in bits(mins):
        u = above[i] & s
        if not u:
            # comparable to nothing in s (it is minimal): no later up-set meets it, so it skips the
            # quadratic merge (a wide antichain stays linear)
            lone.append(i)
            continue
        u |= 1 << i
        keep = []
        for c in comps:
            if c & u:
                u |= c
            else:
                keep.append(c)
        keep.append(u)
        comps = keep
        work += len(keep)
        if check is not None and work > 2048:
            work = 0
            check()
    if not lone:
        return comps, 0
    buf = bytearray((max(lone) >> 3) + 1)
    for i in lone:
        buf[i >> 3] |= 1 << (i & 7)
    return comps, int.from_bytes(buf, "little")


def components(above: Sequence[int], s: int, mins: int, *, deadline: Deadline | float | None = None) -> list[int]:
    """The connected pieces of ``s`` under comparability, given its minimal elements ``mins``
    (:func:`split_components`, each lone element a piece of its own, last).  Past ``deadline`` it
    raises :class:`~opportune.engine.deadline.BudgetExceeded`.

    >>> components([0b010, 0, 0], 0b111, 0b101)     # 0 < 1; 2 alone
    [3, 4]
    """
    check = _clock(deadline)
    comps, lone = split_components(above, s, mins,
                                   None if check is None else lambda: check("splitting a set into components"))
    return comps + [1 << i for i in bits(lone)] if lone else comps


def cut_chain(below: Sequence[int], cuts: int) -> list[int]:
    """The cut elements of a set (each comparable to every other element of it) in order, lowest first.

    They form a chain, so an element's rank is the number of cut elements below it.  O(k log k).

    >>> cut_chain([0, 0b001, 0b011], 0b101)    # 0 < 1 < 2; cuts 0 and 2
    [0, 2]
    """
    return sorted(bits(cuts), key=lambda i: (below[i] & cuts).bit_count())


def cut_blocks(below: Sequence[int], above: Sequence[int], s: int, cuts: int) -> list[int]:
    """The parts of ``s`` between its cut elements: before the first, between each two, after the last.

    ``s`` is their ordinal sum with the cuts in between, so ``e(s)`` is the product of their counts.
    ``k + 1`` sets for ``k`` cuts, some maybe empty.

    >>> cut_blocks([0, 0b001, 0b011, 0b011], [0b1110, 0b1100, 0, 0], 0b1111, 0b0010)   # 0 < 1 < {2, 3}
    [1, 12]
    """
    out = []
    rest = s
    for z in cut_chain(below, cuts):
        out.append(rest & below[z])
        rest &= above[z]
    out.append(rest)
    return out




def _find_cycle(n: int, succ: Sequence[int], nodes: int) -> list[int]:
    """One directed cycle among ``nodes`` (a mask), where every node of ``nodes``
    has a predecessor in ``nodes`` (what is left after Kahn's algorithm)."""
    pred = [0] * n
    for a in bits(nodes):
        for b in bits(succ[a] & nodes):
            pred[b] |= 1 << a
    # Walk backwards until a node repeats: the walk then closes a cycle.
    v = (nodes & -nodes).bit_length() - 1
    seen: dict[int, int] = {}
    walk: list[int] = []
    while v not in seen:
        seen[v] = len(walk)
        walk.append(v)
        p = pred[v]
        v = (p & -p).bit_length() - 1
    back = walk[seen[v]:]           # v <- ... (each entry's successor is the previous one)
    cycle = back[::-1]              # forward order
    k = cycle.index(min(cycle))     # start at the smallest element, for a stable message
    cycle = cycle[k:] + cycle[:k]
    return cycle + [cycle[0]]


class Poset:
    """Strict partial order on elements ``0..n-1`` stored as bitmasks (transitively closed).

    Attributes
    ----------
    n : int
        Number of elements.
    below : tuple[int, ...]
        ``below[i]`` is the bitmask of all ``j`` with ``j < i``.
    above : tuple[int, ...]
        ``above[i]`` is the bitmask of all ``j`` with ``i < j``.
    full : int
        ``(1 << n) - 1``, the set of all elements.

    Instances are immutable, hashable and compare by value (two posets are
    equal iff they have the same ``n`` and the same relation).  Build them with
    :meth:`from_pairs` or :meth:`from_predecessors`, which compute the
    transitive closure and reject cycles.

    Parameters
    ----------
    n : int
        Number of elements.
    below, above : sequence of int
        The closed relation both ways, as above.  The constructor trusts them (closed, acyclic, each
        the other's mirror) and checks nothing: use the class methods unless they are already so
        (:meth:`dual` passes its own swapped).

    Examples
    --------
    >>> p = Poset.from_pairs(3, [(0, 2), (1, 2)])
    >>> p.less(0, 2), p.less(0, 1), p.comparable(1, 2)
    (True, False, True)
    >>> p == Poset.from_predecessors([0, 0, 0b011])
    True
    """

    __slots__ = ("n", "below", "above", "full", "_hash", "_covers")

    def __init__(self, n: int, below: Sequence[int], above: Sequence[int]):
        # Trusted constructor: ``below``/``above`` must already be a closed,
        # acyclic, mutually consistent relation.  Use the classmethods.
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "below", tuple(below))
        object.__setattr__(self, "above", tuple(above))
        object.__setattr__(self, "full", (1 << n) - 1)
        object.__setattr__(self, "_hash", hash((n, self.below)))
        object.__setattr__(self, "_covers", None)   # the cover pairs, once found (asked for at every hub search)

    def __setattr__(self, name, value):
        raise AttributeError("Poset is immutable")

    def __delattr__(self, name):
        raise AttributeError("Poset is immutable")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Poset):
            return NotImplemented
        return self.n == other.n and self.below == other.below

    def __hash__(self) -> int:
        return self._hash

    def __repr__(self) -> str:
        return f"Poset.from_pairs({self.n}, {self.cover_pairs()!r})"

    def __reduce__(self):
        return (Poset, (self.n, self.below, self.above))

    def __len__(self) -> int:
        return self.n

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_successors(cls, succ: Sequence[int], *, deadline: Deadline | float | None = None) -> "Poset":
        """Poset generated by ``succ[i]`` = bitmask of elements directly after ``i``.

        Computes the transitive closure by one pass in reverse topological
        order: O(n + number of given pairs) big-int ORs.

        Parameters
        ----------
        succ : sequence of int
            For each element, the bitmask of elements after it (need not be closed or reduced).
        deadline : Deadline or float or None, optional
            When to stop (a :class:`~opportune.engine.deadline.Deadline` or a
            ``time.perf_counter()`` moment; None: never).

        Returns
        -------
        Poset
            The order on ``len(succ)`` elements.

        Raises
        ------
        ValueError
            A mask names an element outside ``0..n-1`` (or is negative).
        CycleError
            The relation has a cycle (including ``i < i``); the error names one.
        BudgetExceeded
            Past ``deadline`` (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> Poset.from_successors([0b10, 0b100, 0]).above
        (6, 4, 0)
        >>> Poset.from_successors([0b10, 0b1])
        Traceback (most recent call last):
        ...
        opportune.planning.orders.CycleError: cycle in the order: 0 -> 1 -> 0
        """
        n = len(succ)
        full = (1 << n) - 1
        succ = [int(s) for s in succ]
        for i, s in enumerate(succ):
            if s < 0 or s & ~full:
                raise ValueError(f"successor mask of {i} names elements outside 0..{n - 1}")
            if s >> i & 1:
                raise CycleError([i, i])
        check = _clock(deadline)
        indeg = [0] * n
        for k, s in enumerate(succ):
            for j in bits(s):
                indeg[j] += 1
            if check is not None and not k & 255:
                check("ordering a partial order")
        stack = [i for i in range(n) if indeg[i] == 0]
        order: list[int] = []
        while stack:
            i = stack.pop()
            if check is not None and not len(order) & 255:
                check("ordering a partial order")
            order.append(i)
            for j in bits(succ[i]):
                indeg[j] -= 1
                if indeg[j] == 0:
                    stack.append(j)
        if len(order) < n:
            placed = 0
            for i in order:
                placed |= 1 << i
            raise CycleError(_find_cycle(n, succ, full & ~placed))
        above = [0] * n
        for k, i in enumerate(reversed(order)):
            m = 0
            for j in bits(succ[i]):
                m |= (1 << j) | above[j]
            above[i] = m
            if check is not None and not k & 63:
                check("closing a partial order")
        below = [0] * n
        for k, i in enumerate(order):  # the same pass forwards: O(given pairs), not O(comparable pairs)
            m = below[i] | 1 << i
            for j in bits(succ[i]):
                below[j] |= m
            if check is not None and not k & 63:
                check("closing a partial order")
        return cls(n, below, above)

    @classmethod
    def from_pairs(cls, n: int, pairs: Iterable[tuple[int, int]], *,
                   deadline: Deadline | float | None = None) -> "Poset":
        """Poset on ``0..n-1`` generated by ``pairs``: ``(a, b)`` means ``a`` before ``b``.

        The pairs need not be transitively closed or reduced; duplicates are
        fine.  O(n + len(pairs)) big-int operations.

        Parameters
        ----------
        n : int
            Number of elements.
        pairs : iterable of (int, int)
            The relations ``(before, after)``.
        deadline : Deadline or float or None, optional
            When to stop (a :class:`~opportune.engine.deadline.Deadline` or a
            ``time.perf_counter()`` moment; None: never).

        Returns
        -------
        Poset
            The transitive closure of the pairs.

        Raises
        ------
        ValueError
            ``n`` is negative, or a pair names an element outside ``0..n-1``.
        CycleError
            The pairs contain a cycle, including ``(a, a)``; the error names one real cycle.
        BudgetExceeded
            Past ``deadline`` (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> Poset.from_pairs(3, [(0, 1), (1, 2)]).below[2]
        3
        >>> Poset.from_pairs(2, [(0, 1), (1, 0)])
        Traceback (most recent call last):
        ...
        opportune.planning.orders.CycleError: cycle in the order: 0 -> 1 -> 0
        """
        if n < 0:
            raise ValueError("n must be >= 0")
        succ = [0] * n
        check = _clock(deadline)
        for k, (a, b) in enumerate(pairs):
            if check is not None and not k & 1023:
                check("reading the pairs of a partial order")
            if not (0 <= a < n and 0 <= b < n):
                raise ValueError(f"pair ({a}, {b}) names an element outside 0..{n - 1}")
            if a == b:
                raise CycleError([a, a])
            succ[a] |= 1 << b
        return cls.from_successors(succ, deadline=deadline)

    @classmethod
    def from_predecessors(cls, preds: Sequence[int]) -> "Poset":
        """Poset generated by ``preds[i]`` = bitmask of elements directly before ``i``.

        Same closure and checks as :meth:`from_pairs`.

        Parameters
        ----------
        preds : sequence of int
            For each element, the bitmask of elements before it (need not be closed or reduced).

        Returns
        -------
        Poset
            The order on ``len(preds)`` elements.

        Raises
        ------
        ValueError
            A mask names an element outside ``0..n-1`` (or is negative).
        CycleError
            The relation has a cycle (including ``i < i``); the error names one.

        Examples
        --------
        >>> Poset.from_predecessors([0, 0b1, 0b1]).above[0]
        6
        """
        n = len(preds)
        full = (1 << n) - 1
        succ = [0] * n
        for i, p in enumerate(preds):
            p = int(p)
            if p < 0 or p & ~full:
                raise ValueError(f"predecessor mask of {i} names elements outside 0..{n - 1}")
            if p >> i & 1:
                raise CycleError([i, i])
            bit = 1 << i
            for j in bits(p):
                succ[j] |= bit
        return cls.from_successors(succ)

    @classmethod
    def antichain(cls, n: int) -> "Poset":
        """The empty order on ``n`` elements: every sequence of them is a linear extension.

        Parameters
        ----------
        n : int
            Number of elements.

        Returns
        -------
        Poset
            No two elements related.

        Examples
        --------
        >>> Poset.antichain(2).cover_pairs()
        []
        """
        return cls(n, [0] * n, [0] * n)

    @classmethod
    def chain(cls, n: int) -> "Poset":
        """The total order ``0 < 1 < ... < n-1``: one linear extension.

        Parameters
        ----------
        n : int
            Number of elements.

        Returns
        -------
        Poset
            Every two elements related, in index order.

        Examples
        --------
        >>> Poset.chain(3).cover_pairs()
        [(0, 1), (1, 2)]
        """
        full = (1 << n) - 1
        return cls(n, [(1 << i) - 1 for i in range(n)], [full & ~((2 << i) - 1) for i in range(n)])

    # ------------------------------------------------------------------ combination
    def union(self, other: "Poset") -> "Poset":
        """Transitive closure of both relations on the same ``n`` elements.

        Its linear extensions are those common to ``self`` and ``other``.  O(n + pairs).

        Parameters
        ----------
        other : Poset
            An order on as many elements.

        Returns
        -------
        Poset
            The smallest order containing both.

        Raises
        ------
        ValueError
            The sizes differ.
        CycleError
            The two orders contradict each other (no common linear extension).

        Examples
        --------
        >>> a = Poset.from_pairs(3, [(0, 1)]); b = Poset.from_pairs(3, [(1, 2)])
        >>> a.union(b).less(0, 2)
        True
        """
        if self.n != other.n:
            raise ValueError(f"cannot unite posets on {self.n} and {other.n} elements")
        return Poset.from_successors([a | b for a, b in zip(self._cover_succ(), other._cover_succ())])

    def with_pairs(self, pairs: Iterable[tuple[int, int]]) -> "Poset":
        """This order with extra ``(a, b)`` pairs added (closed).

        Parameters
        ----------
        pairs : iterable of (int, int)
            The relations to add, ``(before, after)``.

        Returns
        -------
        Poset
            A new order (this one is unchanged).

        Raises
        ------
        ValueError
            A pair names an element outside ``0..n-1``.
        CycleError
            A pair contradicts the order (or is ``(a, a)``).

        Examples
        --------
        >>> Poset.antichain(2).with_pairs([(1, 0)]).less(1, 0)
        True
        """
        succ = list(self._cover_succ())
        for a, b in pairs:
            if not (0 <= a < self.n and 0 <= b < self.n):
                raise ValueError(f"pair ({a}, {b}) names an element outside 0..{self.n - 1}")
            if a == b:
                raise CycleError([a, a])
            succ[a] |= 1 << b
        return Poset.from_successors(succ)

    def dual(self) -> "Poset":
        """The reversed order (``a < b`` iff ``b < a`` here); same number of linear extensions.

        O(1): the two relations swap.

        Returns
        -------
        Poset
            The dual order.

        Examples
        --------
        >>> Poset.from_pairs(2, [(0, 1)]).dual().less(1, 0)
        True
        """
        return Poset(self.n, self.above, self.below)

    # ------------------------------------------------------------------ queries
    def less(self, a: int, b: int) -> bool:
        """Whether ``a < b`` (strictly). O(1).

        Parameters
        ----------
        a, b : int
            Two elements.

        Returns
        -------
        bool
            True if ``a`` comes before ``b`` in every linear extension.

        Examples
        --------
        >>> p = Poset.from_pairs(3, [(0, 1), (1, 2)])
        >>> p.less(0, 2), p.less(2, 0), p.less(1, 1)
        (True, False, False)
        """
        return bool(self.above[a] >> b & 1)

    def comparable(self, a: int, b: int) -> bool:
        """Whether ``a < b`` or ``b < a``. O(1).

        Parameters
        ----------
        a, b : int
            Two elements.

        Returns
        -------
        bool
            True if their order is the same in every linear extension.

        Examples
        --------
        >>> p = Poset.from_pairs(3, [(0, 1)])
        >>> p.comparable(1, 0), p.comparable(0, 2)
        (True, False)
        """
        return bool((self.above[a] | self.below[a]) >> b & 1)

    def minimal(self, mask: int) -> int:
        """Bitmask of the minimal elements of the subposet induced on ``mask``.

        An element of ``mask`` is minimal if nothing else in ``mask`` is
        before it.  O(popcount(mask)).

        Parameters
        ----------
        mask : int
            A set of elements (bit ``i`` for element ``i``).

        Returns
        -------
        int
            The bitmask of its minimal elements (those that can come first).

        Examples
        --------
        >>> Poset.from_pairs(3, [(0, 1)]).minimal(0b111)
        5
        >>> Poset.from_pairs(3, [(0, 1)]).minimal(0b110)
        6
        """
        return _apart(self.below, mask)

    def maximal(self, mask: int) -> int:
        """Bitmask of the maximal elements of the subposet induced on ``mask``. O(popcount(mask)).

        Parameters
        ----------
        mask : int
            A set of elements (bit ``i`` for element ``i``).

        Returns
        -------
        int
            The bitmask of its maximal elements (those that can come last).

        Examples
        --------
        >>> Poset.from_pairs(3, [(0, 1)]).maximal(0b111)
        6
        """
        return _apart(self.above, mask)

    def is_downset(self, mask: int) -> bool:
        """Whether ``mask`` is closed downwards (everything before a member is a member).

        O(popcount(mask)).  The down-sets are the states a sequence can reach: what is installed.

        Parameters
        ----------
        mask : int
            A set of elements (bit ``i`` for element ``i``).

        Returns
        -------
        bool
            True if it is a down-set.

        Examples
        --------
        >>> p = Poset.from_pairs(3, [(0, 1)])
        >>> p.is_downset(0b001), p.is_downset(0b010), p.is_downset(0b100)
        (True, False, True)
        """
        below = self.below
        m = mask
        while m:
            low = m & -m
            m ^= low
            if below[low.bit_length() - 1] & ~mask:
                return False
        return True

    def is_upset(self, mask: int) -> bool:
        """Whether ``mask`` is closed upwards (everything after a member is a member). O(popcount(mask)).

        Parameters
        ----------
        mask : int
            A set of elements (bit ``i`` for element ``i``).

        Returns
        -------
        bool
            True if it is an up-set (what is left to install, at a reachable state).

        Examples
        --------
        >>> Poset.from_pairs(2, [(0, 1)]).is_upset(0b10)
        True
        """
        above = self.above
        m = mask
        while m:
            low = m & -m
            m ^= low
            if above[low.bit_length() - 1] & ~mask:
                return False
        return True

    def down_closure(self, mask: int) -> int:
        """Smallest down-set containing ``mask``. O(popcount(mask)).

        Parameters
        ----------
        mask : int
            A set of elements (bit ``i`` for element ``i``).

        Returns
        -------
        int
            ``mask`` with everything before its members.

        Examples
        --------
        >>> Poset.from_pairs(3, [(0, 1), (1, 2)]).down_closure(0b100)
        7
        """
        out = mask
        for i in bits(mask):
            out |= self.below[i]
        return out

    def up_closure(self, mask: int) -> int:
        """Smallest up-set containing ``mask``. O(popcount(mask)).

        Parameters
        ----------
        mask : int
            A set of elements (bit ``i`` for element ``i``).

        Returns
        -------
        int
            ``mask`` with everything after its members.

        Examples
        --------
        >>> Poset.from_pairs(3, [(0, 1), (1, 2)]).up_closure(0b001)
        7
        """
        out = mask
        for i in bits(mask):
            out |= self.above[i]
        return out

    def _cover_succ(self, deadline: Deadline | float | None = None) -> list[int]:
        """For each element, the bitmask of the elements that cover it.

        The covers of ``i`` are the minimal elements of ``above[i]``: take a minimal element
        of what is left (descend from its lowest bit), keep it, drop it with everything above
        it, repeat.  One round per cover, and the descent is one step when the elements are
        numbered in a topological order (as plans usually are), so a long chain costs O(n)
        big-int operations, not O(n^2).
        """
        above, below = self.above, self.below
        check = _clock(deadline)
        succ = []
        for i in range(self.n):
            if check is not None and not i & 31:
                check("finding the covers of a partial order")
            rest = above[i]
            direct = 0
            while rest:
                low = rest & -rest
                j = low.bit_length() - 1
                under = below[j] & rest
                while under:  # j is not minimal in rest: go down
                    low = under & -under
                    j = low.bit_length() - 1
                    under = below[j] & rest
                direct |= low
                rest &= ~(above[j] | low)
            succ.append(direct)
        return succ

    def cover_pairs(self, *, deadline: Deadline | float | None = None) -> list[tuple[int, int]]:
        """The transitive reduction (Hasse diagram): pairs ``(a, b)`` with ``a < b`` and nothing between.

        O(n + covers) big-int operations (more when the elements are not numbered in a topological
        order), found once and kept.

        Parameters
        ----------
        deadline : Deadline or float or None, optional
            When to stop (a :class:`~opportune.engine.deadline.Deadline` or a
            ``time.perf_counter()`` moment; None: never).

        Returns
        -------
        list of (int, int)
            The cover pairs, sorted (a new list each time).

        Raises
        ------
        BudgetExceeded
            Past ``deadline`` (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> Poset.from_pairs(3, [(0, 1), (1, 2), (0, 2)]).cover_pairs()
        [(0, 1), (1, 2)]
        """
        covers = self._covers
        if covers is None:
            covers = [(a, b) for a, s in enumerate(self._cover_succ(deadline)) for b in bits(s)]
            object.__setattr__(self, "_covers", covers)
        return list(covers)

    def restrict(self, mask: int, *, deadline: Deadline | float | None = None) -> tuple["Poset", list[int]]:
        """The subposet induced on ``mask``, renumbered ``0..k-1``, and the old index of each new one.

        O(comparable pairs within ``mask``) operations.

        Parameters
        ----------
        mask : int
            The elements to keep (bit ``i`` for element ``i``).
        deadline : Deadline or float or None, optional
            When to stop (a :class:`~opportune.engine.deadline.Deadline` or a
            ``time.perf_counter()`` moment; None: never).

        Returns
        -------
        tuple of (Poset, list of int)
            The subposet on ``popcount(mask)`` elements, and for each new element its old index
            (increasing).

        Raises
        ------
        BudgetExceeded
            Past ``deadline`` (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> q, old = Poset.from_pairs(3, [(0, 2)]).restrict(0b101)
        >>> q.cover_pairs(), old
        ([(0, 1)], [0, 2])
        """
        check = _clock(deadline)
        old = elements(mask)
        new = {o: i for i, o in enumerate(old)}
        below, above = [], []
        for k, o in enumerate(old):
            if check is not None and not k & 15:
                check("restricting a partial order")
            below.append(sum(1 << new[j] for j in bits(self.below[o] & mask)))
            above.append(sum(1 << new[j] for j in bits(self.above[o] & mask)))
        return Poset(len(old), below, above), old
