"""A plan written as ways, as bit masks: which parts can go in on top of an installed set.

A plan written as ways (:attr:`opportune.planning.plan.Plan.ways`) admits a sequence iff each part,
when it goes in, has a way none of whose blockers is in yet and each of whose needs has a part in.
:class:`WaysTable` holds those ways as bit masks over the parts' declaration positions, and answers the
questions every layer above asks of a state (what can go in now; whether some part can never go in any
more; one completion, if there is one) without counting: the order engine counts
(:mod:`opportune.engine.ways`), the file checker uses :meth:`WaysTable.completion` to refuse a plan
with no admissible sequence.

Complexity: :meth:`WaysTable.can_go` is O(ways of the part × needs) mask operations; :meth:`goes` and
:meth:`shut_out` O(all ways).
"""

from __future__ import annotations

import time

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.planning.plan import Plan

__all__ = ["WaysTable", "Undecided", "UNIT", "unit_id"]

#: What joins a part's id and a unit's number in a plan written as ways (``screw#2``: the second screw to
#: go in); part ids cannot hold it.
UNIT = "#"


def unit_id(part: str, k: int) -> str:
    """The ``k``-th unit (from 1) of a part of several, as a plan written as ways names it.

    Parameters
    ----------
    part : str
        The part's id.
    k : int
        The unit's number, from 1.

    Returns
    -------
    str
        ``part#k``.

    Examples
    --------
    >>> unit_id("screw", 2)
    'screw#2'
    """
    return f"{part}{UNIT}{k}"


class Undecided(Exception):
    """A search for a completion stopped at its work bound before it found one or proved there is none."""


class WaysTable:
    """The ways of a plan's parts as bit masks (part ``i`` is bit ``i``, declaration order).

    Parameters
    ----------
    n : int
        Number of parts.
    ways : list of list of (int, tuple of int)
        Per part, its ways: ``(blockers mask, needs masks)``.

    Examples
    --------
    >>> t = WaysTable(3, [[(0b010, ())], [(0, (0b001,))], [(0, ())]])    # a before b (both ways)
    >>> bin(t.goes(0)), bin(t.goes(0b001))
    ('0b101', '0b110')
    >>> t.completion(0)
    [0, 1, 2]
    """

    __slots__ = ("n", "full", "ways", "_free", "has_needs", "_open")

    def __init__(self, n: int, ways: list):
        self.n = n
        self.full = (1 << n) - 1
        self.ways = [[(int(b), tuple(int(x) for x in needs)) for b, needs in w] for w in ways]
        # parts with a way that asks nothing: they can go in whenever they are not in yet
        self._free = 0
        for i, w in enumerate(self.ways):
            if any(b == 0 and not needs for b, needs in w):
                self._free |= 1 << i
        #: whether any way has needs (without, :meth:`locked` decides liveness exactly)
        self.has_needs = any(needs for w in self.ways for _, needs in w)
        self._open = None       # (mask, what _open_ways found on it): the last set asked

    @classmethod
    def of(cls, plan: Plan) -> "WaysTable":
        """The table of a plan written as ways, a bit per unit: a part of quantity ``q`` has ``q`` units,
        in declaration order, each after the one before (its units go in in order, as the order engine's
        do), with the ways its key ``id#k`` lists (else those of ``id``); a part the plan lists no way for
        has one free way.  A reference ``id#k`` in a way is the part's ``k``-th unit, ``id`` its only unit.

        Parameters
        ----------
        plan : Plan
            A plan with :attr:`~opportune.planning.plan.Plan.ways`.

        Returns
        -------
        WaysTable
            Its ways as masks.

        Examples
        --------
        >>> from opportune.planning.plan import Part, Plan, Way
        >>> plan = Plan("p", (Part("a"), Part("b")), (), ways={"b": (Way(frozenset({"a"})),)})
        >>> WaysTable.of(plan).ways
        [[(0, ())], [(1, ())]]
        >>> plan = Plan("p", (Part("s", quantity=2), Part("c")), (), ways={"c": (Way(frozenset({"s#2"})),)})
        >>> WaysTable.of(plan).ways          # the second screw after the first; c before the second
        [[(0, ())], [(0, (1,))], [(2, ())]]
        """
        first, n = {}, 0
        for p in plan.parts:
            first[p.id] = n
            n += p.quantity

        def mask(ids) -> int:
            m = 0
            for q in ids:
                pid, _, k = (q, "", "1") if q in first else q.rpartition(UNIT)
                m |= 1 << (first[pid] + int(k) - 1)
            return m

        given = plan.ways or {}
        table = []
        full = (1 << n) - 1
        for p in plan.parts:
            for k in range(p.quantity):
                unit = first[p.id] + k
                ways = given.get(unit_id(p.id, k + 1) if p.quantity > 1 else p.id) or given.get(p.id, ())
                rows = [(full & ~(1 << unit) if w.first else mask(w.blockers), tuple(mask(x) for x in w.needs))
                        for w in ways] or [(0, ())]
                # a later unit after the one before it: interchangeable units, counted once in one order
                table.append([(b, needs + (1 << unit - 1,)) for b, needs in rows] if k else rows)
        return cls(n, table)

    def can_go(self, mask: int, i: int) -> bool:
        """Whether part ``i`` (not in ``mask``) has a way that admits the installed set ``mask``."""
        if self._free >> i & 1:
            return True
        for blockers, needs in self.ways[i]:
            if not blockers & mask and all(n & mask for n in needs):
                return True
        return False

    def goes(self, mask: int) -> int:
        """The parts not in ``mask`` that can go in on top of it, as a mask."""
        out = self._free & ~mask
        rest = self.full & ~mask & ~out
        while rest:
            b = rest & -rest
            rest ^= b
            if self.can_go(mask, b.bit_length() - 1):
                out |= b
        return out

    def shut_out(self, mask: int) -> bool:
        """Whether some part not in ``mask`` has every way blocked by a part in it: it can never go in,
        so ``mask`` has no completion.  (A necessary sign of a dead end, not a sufficient one.)"""
        rest = self.full & ~mask & ~self._free
        while rest:
            b = rest & -rest
            rest ^= b
            if all(blockers & mask for blockers, _ in self.ways[b.bit_length() - 1]):
                return True
        return False

    def shutting(self, mask: int) -> int:
        """The parts whose going in on ``mask`` would shut another part out: for each part left, the
        blockers every way of it still open shares.  On a set not shut out itself, ``t = mask | 1 << b``
        is shut out exactly when ``b`` is among them, so one pass answers :meth:`shut_out` for every part
        that can go next.  O(ways) mask operations.

        Examples
        --------
        >>> t = WaysTable(3, [[(0b010, ())], [(0, ())], [(0b011, ()), (0b010, ())]])  # b shuts a and c out
        >>> bin(t.shutting(0)), t.shut_out(0b010)
        ('0b10', True)
        """
        out = 0
        rest = self.full & ~mask & ~self._free
        while rest:
            b = rest & -rest
            rest ^= b
            common = -1
            for blockers, _ in self.ways[b.bit_length() - 1]:
                if not blockers & mask:
                    common &= blockers
                    if not common:
                        break
            if common > 0:
                out |= common
        return out

    def locked(self, mask: int) -> bool:
        """Whether the parts not in ``mask`` lock each other: taken out last first while one can be (a
        part can go in last if a way of it has no blocker in ``mask`` nor among the others left), some
        remain.  Needs left aside: a locked set has no completion, and in a plan without needs only a
        locked set has none (fewer parts in block less, so the order of taking out does not matter).
        O(passes × ways) mask operations.

        Examples
        --------
        >>> t = WaysTable(3, [[(0b010, ())], [(0b001, ())], [(0, ())]])     # a and b block each other
        >>> t.locked(0), t.locked(0b100)
        (True, True)
        """
        rest = self.full & ~mask
        left = [(i, blockers) for i in _bits(rest) for blockers, _ in self.ways[i] if not blockers & mask]
        while rest:
            out = 0
            for i, blockers in left:
                if not blockers & rest & ~(1 << i):
                    out |= 1 << i
            if not out:
                return True
            rest &= ~out
            left = [(i, b) for i, b in left if rest >> i & 1]
        return False

    def before(self, mask: int, i: int) -> int:
        """The parts to install before part ``i`` can go in on ``mask``: for its way that asks the
        fewest, each unmet need met by the member that itself asks the fewest (with what that member
        asks, recursively), none of them a blocker of the way.  Exact for a plan of one way per part
        whose needs are single parts (a strategy, where it is every predecessor left); in general one
        set of installs that lets ``i`` in, not always the smallest (that is a set cover).  0 if ``i``
        can go in now, or no way of it is open.  O(parts × ways) mask operations.

        Examples
        --------
        >>> t = WaysTable(3, [[(0, ())], [(0, (0b001,))], [(0, (0b010,))]])    # a, then b, then c
        >>> bin(t.before(0, 2)), bin(t.before(0b001, 2)), t.before(0b011, 2)
        ('0b11', '0b10', 0)
        """
        memo: dict[int, int | None] = {}
        found = self._before(mask, i, memo)
        return found or 0

    def _before(self, mask: int, i: int, memo: dict) -> int | None:
        """:meth:`before` of ``i`` (None: no open way; a part in the middle of its own search counts as
        unable, so a cycle of needs is not followed)."""
        if i in memo:
            return memo[i]
        memo[i] = None
        best = None
        for blockers, needs in self.ways[i]:
            if blockers & mask:
                continue
            got = 0
            for need in needs:
                if need & mask:
                    continue
                pick = None
                for g in _bits(need):
                    sub = self._before(mask, g, memo)
                    if sub is None or (sub | 1 << g) & blockers:
                        continue
                    sub |= 1 << g
                    if pick is None or sub.bit_count() < pick.bit_count():
                        pick = sub
                if pick is None:
                    break
                got |= pick
            else:
                if best is None or got.bit_count() < best.bit_count():
                    best = got
        memo[i] = best
        return best

    def waiting_on(self, mask: int, i: int) -> int:
        """The parts left that must go in after part ``i`` in every completion of ``mask``, as far as the
        ways show it: a part every open way of which has an unmet need all of whose members are ``i``
        or wait on it, or a part that blocks every open way of ``i`` or of one waiting on it (taken to a
        fixpoint).  Exact for a plan of one way per part whose needs are single parts (every successor
        left); else a lower bound.  O(passes × ways) mask operations.

        Examples
        --------
        >>> t = WaysTable(3, [[(0, ())], [(0, (0b001,))], [(0, (0b010,))]])    # a, then b, then c
        >>> bin(t.waiting_on(0, 0)), bin(t.waiting_on(0, 1)), t.waiting_on(0, 2)
        ('0b110', '0b100', 0)
        """
        rest = self.full & ~mask & ~(1 << i)
        open_ways, common, needy = self._open_ways(mask)
        after, grew = 1 << i, True
        while grew:
            grew = False
            for q in needy:
                if rest >> q & 1 and not after >> q & 1 and all(
                        any(not n & ~after for n in needs) for _, needs in open_ways[q]):
                    after |= 1 << q
                    grew = True
            for x in _bits(after):
                blocks = rest & ~after & common.get(x, 0)
                if blocks:
                    after |= blocks
                    grew = True
        return after & ~(1 << i)

    def _open_ways(self, mask: int) -> tuple[dict, dict, list]:
        """On ``mask`` (the last one asked kept): each part left's open ways with their unmet needs, the
        blockers they share (0 if none is open), and the parts every open way of which has a need."""
        if self._open is None or self._open[0] != mask:
            self._open = (mask, self._open_ways_of(mask))
        return self._open[1]

    def _open_ways_of(self, mask: int) -> tuple[dict, dict, list]:
        """:meth:`_open_ways`, found.  O(ways) mask operations."""
        open_ways = {q: [(b, tuple(n for n in needs if not n & mask)) for b, needs in self.ways[q] if not b & mask]
                     for q in _bits(self.full & ~mask)}
        common = {}
        for q, ways in open_ways.items():
            c = -1
            for b, _ in ways:
                c &= b
            common[q] = c if ways else 0
        needy = [q for q, ways in open_ways.items() if ways and all(needs for _, needs in ways)]
        return open_ways, common, needy

    def completion(self, mask: int = 0, work: int = 1_000_000, until: float | None = None) -> list[int] | None:
        """One admissible completion of ``mask`` (the parts' positions in the order they go in), or None
        if it has none: a depth-first search that remembers the sets found to have no completion.

        Parameters
        ----------
        mask : int
            The installed parts.
        work : int
            Most sets the search may visit.
        until : float, optional
            A moment of ``time.perf_counter()`` past which the search stops, undecided.

        Returns
        -------
        list of int or None
            The parts left, in an admissible order; None if there is none.

        Raises
        ------
        Undecided
            The search visited ``work`` sets, or passed ``until``, without deciding.

        Examples
        --------
        >>> WaysTable(2, [[(0b10, ())], [(0b01, ())]]).completion() is None     # each blocks the other
        True
        """
        dead: set[int] = set()
        path: list[int] = []
        stack = [(mask, self.goes(mask))]
        visited = 0
        while stack:
            s, todo = stack[-1]
            if s == self.full:
                return path
            if not todo:
                dead.add(s)
                stack.pop()
                if path:
                    path.pop()
                continue
            b = todo & -todo
            stack[-1] = (s, todo ^ b)
            t = s | b
            if t in dead or self.shut_out(t) or self.locked(t):
                continue
            visited += 1
            if visited > work or (until is not None and time.perf_counter() > until):
                raise Undecided(f"no completion found after {visited - 1:,} sets")
            path.append(b.bit_length() - 1)
            stack.append((t, self.goes(t)))
        return None


def _bits(mask: int):
    while mask:
        b = mask & -mask
        yield b.bit_length() - 1
        mask ^= b
