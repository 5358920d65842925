"""The order of a plan's strategy on the parts it constrains: its minimal constraints, its closure, a cycle.

Pure Python over plan indices, for checking a plan as it is read (a cycle, redundant constraints,
strategies that admit the same sequences) and for its summary; counting sequences is the engine's
(:mod:`opportune.engine`), which takes :class:`CycleError` from here.
"""

from __future__ import annotations

TYPE_CHECKING = False
if TYPE_CHECKING:       # pragma: no cover
    from typing import Sequence

    from opportune.planning.plan import Plan


class CycleError(ValueError):
    """The given relation has a cycle, so it is not a partial order.

    ``cycle`` lists the elements of one cycle in order, closed: its first and
    last entries are equal, and each entry is directly before the next in the
    given relation.  ``[1, 2, 1]`` means ``1 < 2`` and ``2 < 1`` were both given;
    ``[3, 3]`` means ``3 < 3`` was given.
    """

    def __init__(self, cycle: Sequence[int]):
        self.cycle = list(cycle)
        super().__init__("cycle in the order: " + " -> ".join(map(str, self.cycle)))


class StrategyOrder:
    """The partial order of one strategy on the parts its constraints name (its *support*).

    A plan of 10,000 parts and 64 strategies that each constrain a few hundred parts would cost 64
    closures of 10,000-bit sets over the whole plan (seconds); on the support each is a few hundred
    bits.  Parts outside the support are unordered, so nothing is lost.  The support is numbered
    in a topological order (the earliest declared part first among those ready), and one pass in
    that order gives the closure and the covers together: O(k + pairs) big-int operations of at
    most k bits (k = the support's size, at most twice the pairs), no iteration over set bits.
    Raises :class:`~opportune.engine.poset.CycleError` (plan indices) on a cycle.

    >>> o = StrategyOrder([(0, 5), (5, 9), (0, 9)])
    >>> o.support, o.cover_pairs(), o.less(0, 9), o.less(9, 0), o.implied
    ((0, 5, 9), [(0, 5), (5, 9)], True, False, 3)
    >>> StrategyOrder([(0, 1), (1, 2), (2, 1)])
    Traceback (most recent call last):
    ...
    opportune.planning.orders.CycleError: cycle in the order: 2 -> 1 -> 2
    """

    __slots__ = ("support", "local", "below", "_cover_list", "_covers", "_implied")

    def __init__(self, pairs: list[tuple[int, int]]):
        import heapq

        preds: dict[int, set[int]] = {}
        succ: dict[int, list[int]] = {}
        for b, a in pairs:
            if a not in preds or b not in preds[a]:
                preds.setdefault(a, set()).add(b)
                succ.setdefault(b, []).append(a)
        nodes = set(preds).union(succ)
        waiting = {a: len(ps) for a, ps in preds.items()}
        ready = sorted(x for x in nodes if x not in preds)
        order: list[int] = []
        while ready:
            x = heapq.heappop(ready)
            order.append(x)
            for a in succ.get(x, ()):
                waiting[a] -= 1
                if not waiting[a]:
                    heapq.heappush(ready, a)
        if len(order) < len(nodes):
            raise CycleError(_a_cycle(preds, nodes.difference(order)))
        local = {g: i for i, g in enumerate(order)}
        below = [0] * len(order)
        covers: list[tuple[int, int]] = []
        for i, g in enumerate(order):
            ps = preds.get(g)
            if not ps:
                continue
            m = u = 0
            for b in ps:
                lb = local[b]
                m |= below[lb] | 1 << lb
                u |= below[lb]  # what lies under another predecessor is not a cover
            below[i] = m
            covers.extend((b, g) for b in ps if not u >> local[b] & 1)
        self.support, self.local, self.below = tuple(order), local, below
        covers.sort()
        self._cover_list = covers
        self._covers: frozenset | None = None
        self._implied: int | None = None

    def cover_pairs(self) -> list[tuple[int, int]]:
        """The minimal constraints (transitive reduction) as ``(before, after)`` plan indices, sorted."""
        return list(self._cover_list)

    def covers(self) -> frozenset:
        """:meth:`cover_pairs` as a set: two strategies admit the same sequences iff their covers are equal."""
        if self._covers is None:
            self._covers = frozenset(self._cover_list)
        return self._covers

    @property
    def implied(self) -> int:
        """Constraints of the transitive closure (comparable pairs): O(k) popcounts."""
        if self._implied is None:
            self._implied = sum(m.bit_count() for m in self.below)
        return self._implied

    def less(self, before: int, after: int) -> bool:
        """Whether the strategy puts plan part ``before`` before ``after`` (directly or not).  O(1)."""
        a, b = self.local.get(after), self.local.get(before)
        return a is not None and b is not None and bool(self.below[a] >> b & 1)

    def contains(self, looser: "StrategyOrder") -> bool:
        """Whether every constraint of ``looser`` holds in this order (so its sequences are among looser's).

        O(looser's support) set test (after two O(1) ones: sizes of the supports and of the closures),
        then one bit test per cover of ``looser`` until one fails.
        """
        local, below = self.local, self.below
        if (len(looser.support) > len(self.support) or looser.implied > self.implied
                or not local.keys() >= looser.local.keys()):
            return False
        for b, a in looser._cover_list:  # both in the support: no look-up can fail
            if not below[local[a]] >> local[b] & 1:
                return False
        return True


def _a_cycle(preds: dict[int, set[int]], left: set[int]) -> list[int]:
    """One cycle among ``left``, the elements a topological sort could not place: each of them has a
    predecessor among them, so walking predecessors from any one repeats an element.  O(len(left))."""
    x = min(left)
    seen: dict[int, int] = {}
    path: list[int] = []
    while x not in seen:
        seen[x] = len(path)
        path.append(x)
        x = min(b for b in preds[x] if b in left)
    cycle = path[seen[x]:]
    cycle.reverse()  # walked backwards (after to before): each entry is now before the next
    return cycle + cycle[:1]


def strategy_summaries(plan: Plan) -> tuple[tuple[list[tuple[int, int]], int], ...]:
    """Each strategy's minimal constraints (sorted plan-index pairs) and the size of its closure,
    computed once per plan (checking a plan computes them; :func:`summarize` reuses them).
    O(parts constrained + constraints) big-int operations per strategy (:class:`StrategyOrder`).
    Raises CycleError for a cyclic strategy (a plan read with cycles allowed)."""
    kept = plan.__dict__.get("_strategy_summaries")
    if kept is None:
        kept = tuple(keep_summary(StrategyOrder(plan.index_pairs(s))) for s in plan.strategies)
        object.__setattr__(plan, "_strategy_summaries", kept)
    return kept


def keep_summary(order: StrategyOrder) -> tuple[list[tuple[int, int]], int]:
    """The part of ``order`` that :func:`strategy_summaries` keeps with the plan: its covers and the
    size of its closure (the closure itself can take megabytes; the covers take what the constraints take)."""
    return order.cover_pairs(), order.implied
