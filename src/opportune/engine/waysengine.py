"""The order engine of a plan written as ways: the same questions about a state, answered by counting
the completions over installed sets (:mod:`opportune.engine.ways`) instead of linear extensions.

``OrderEngine(plan)`` of a plan written as ways makes a :class:`WaysEngine` (an ``OrderEngine`` by
``isinstance``: registered as its virtual subclass; it shares the order engine's bases, the deadline,
the questions and the memory upkeep, not its orders), so a
:class:`~opportune.engine.schedule.Schedule`, the :class:`~opportune.sequencer.Sequencer` and
``opportune count`` take either plan alike.  A state is an installed set (a bit a unit, as the order
engine's: a part of quantity ``q`` has ``q`` units, in a row, going in lowest first) and one "strategy" (``consistent`` is 1 while the state is live,
0 for none): a part *can be installed* when it has a way that admits what is in and the set with it
still has a completion (:meth:`WaysEngine.live`: never a dead end).

Liveness is decided from the memo where it knows the set; else a set is dead where some part is shut
out or the parts left lock each other (:meth:`~opportune.planning.ways.WaysTable.locked`), which in a
plan without needs decides it exactly; with needs, a live-looking set is searched for one completion
within :data:`LIVE_WORK` sets, and one that search cannot decide is taken as live (a count of 0 says
otherwise).  Questions that need the order's shape (the policies' dominance rules, completion chains)
are the order engine's alone.
"""

from __future__ import annotations

import time

from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline
from opportune.engine.exact import ExactCounting
from opportune.engine.memory import MemoryUpkeep, memory_total, nbytes
from opportune.engine.poset import bits as _bits
from opportune.engine.questions import StateQuestions
from opportune.engine.result import CountResult
from opportune.engine.ways import WaysCounter, estimate_completions
from opportune.planning.ways import Undecided, WaysTable

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from fractions import Fraction
    from typing import Collection, Iterable

    from opportune.planning.plan import Plan

__all__ = ["LIVE_WORK", "WaysEngine"]

#: The engine's default ``memory_limit``, as the order engine's: a quarter of the machine's memory.
DEFAULT_MEMORY = memory_total() // 4
#: Share of a count's time the exact count may take at most before the estimate gets the rest: the
#: reachable sets of a plan whose parts have several ways each grow so fast that an exact count either
#: fits quickly or not at all (a plan of 30 random blocks: never in minutes), so the estimate gets most.
EXACT_SHARE = 0.3
#: Most sets one liveness search visits (plans with needs only) before it takes the set as live.
LIVE_WORK = 200


class WaysEngine(ExactCounting, StateQuestions, MemoryUpkeep):
    """The engine of a plan written as ways (made by ``OrderEngine(plan)`` for such a plan).

    Parameters
    ----------
    plan : Plan
        A plan with :attr:`~opportune.planning.plan.Plan.ways`.
    max_memo, time_limit, deadline, memory_limit
        As :class:`~opportune.engine.schedule.OrderEngine`'s: new memo entries and seconds per exact
        count, the deadline of building (nothing to build here), bytes between decisions.

    Examples
    --------
    >>> from opportune.engine.schedule import OrderEngine
    >>> from opportune.formats.ways import ways_plan
    >>> from opportune.planning.plan import Part, Way
    >>> plan = ways_plan("p", [Part("a"), Part("b")], {"a": [Way(frozenset({"b"}))]})
    >>> engine = OrderEngine(plan)
    >>> type(engine).__name__, engine.count(0, 1), engine.installable(0, 1), engine.options(0, 1)
    ('WaysEngine', 1, ('a',), {'a': 1})
    >>> isinstance(engine, OrderEngine)
    True
    """

    def __init__(self, plan: Plan, *, max_memo: int | None = 2_000_000, time_limit: float | None = None,
                 deadline: Deadline | float | None = None, memory_limit: int | None = DEFAULT_MEMORY):
        self.plan = plan
        self.time_limit = time_limit
        self._start_upkeep(memory_limit)
        self.table = WaysTable.of(plan)
        n = self.table.n
        # units as the order engine has them: a part's units in a row, going in lowest first
        self.first, self.unit_part = [], []
        for i, p in enumerate(plan.parts):
            self.first.append(len(self.unit_part))
            self.unit_part += [i] * p.quantity
        self._quantity = [p.quantity for p in plan.parts]
        self.n_units, self.full = n, self.table.full
        if max_memo == 0:       # as many entries as the memory holds (as the order engine's 0)
            from opportune.engine.count import entries_within

            max_memo = entries_within(n, memory_limit or DEFAULT_MEMORY)
        self.max_memo = max_memo
        self.posets = ()                    # no orders: what asks for one fails loudly
        self.k, self.all_strategies = 1, 1
        self.counter = WaysCounter(self.table, max_memo=self.max_memo)
        self.counter.time_limit = time_limit
        self._counters = {1: self.counter}
        self._hubs, self._hub_search, self._probe_left = {}, {}, {}
        self._count_cache, self._options_cache, self._positions_cache = {}, {}, {}
        self._option_cache, self._installable_cache, self._terms_cache = {}, {}, {}
        self._above = None
        self._unit_ids = [plan.parts[i].id for i in self.unit_part]
        self._part_units = {p.id: ((1 << p.quantity) - 1) << self.first[i] for i, p in enumerate(plan.parts)}
        self._until: float | None = None
        self._live: dict[int, bool] = {}
        self._alive: dict[int, bool] = {}   # liveness decided exactly (exact_after), never a guess

    # ---------------------------------------------------------------- states

    def live(self, mask: int) -> bool:
        """Whether the installed set ``mask`` has a completion (see the module for how it is decided).

        Parameters
        ----------
        mask : int
            The installed parts.

        Returns
        -------
        bool
            False only for a set proved dead.

        Examples
        --------
        >>> from opportune.formats.ways import ways_plan
        >>> from opportune.planning.plan import Part, Way
        >>> e = WaysEngine(ways_plan("p", [Part("a"), Part("b")], {"a": [Way(frozenset({"b"}))]}))
        >>> e.live(0b01), e.live(0b10)
        (True, False)
        """
        known = self.counter.memo.get(mask)
        if known is not None:
            return known > 0
        seen = self._alive.get(mask)
        if seen is None:
            seen = self._live.get(mask)
        if seen is not None:
            return seen
        if self.table.shut_out(mask) or self.table.locked(mask):
            found = False
        elif not self.table.has_needs:      # not locked: live, exactly (WaysTable.locked)
            found = True
        else:
            try:
                found = self.table.completion(mask, LIVE_WORK) is not None
            except Undecided:
                found = True
        if len(self._live) > 100_000:
            self._live.clear()
        self._live[mask] = found
        return found

    def consistent_after(self, mask: int, consistent: int, unit: int) -> int:
        """1 if part ``unit`` can go in on ``mask`` and leaves a live set, else 0."""
        if not consistent or mask >> unit & 1 or not self.table.can_go(mask, unit):
            return 0
        return 1 if self.live(mask | 1 << unit) else 0

    def exact_after(self, mask: int, consistent: int, unit: int) -> int:
        """:meth:`consistent_after` with the set after decided exactly (:meth:`alive`): what the exact
        programmes step by, whose states bound the search's work.

        Examples
        --------
        >>> from opportune.formats.ways import ways_plan
        >>> from opportune.planning.plan import Part, Way
        >>> e = WaysEngine(ways_plan("p", [Part("a"), Part("b")], {"a": [Way(frozenset({"b"}))]}))
        >>> e.exact_after(0, 1, 0), e.exact_after(0, 1, 1)
        (1, 0)
        """
        if not consistent or mask >> unit & 1 or not self.table.can_go(mask, unit):
            return 0
        return 1 if self.alive(mask | 1 << unit) else 0

    def alive(self, mask: int) -> bool:
        """Whether the installed set ``mask`` has a completion, decided exactly: a set with a part shut out,
        or whose parts left lock each other, has none; else in a plan without needs it has one; else some
        set one part larger must have one (a depth-first search, every set decided kept).  The compiled
        programmes decide it alike (``src/native/memo_table.hpp``).  O(sets reachable from ``mask`` ×
        ways) the first time.

        Examples
        --------
        >>> from opportune.formats.ways import ways_plan
        >>> from opportune.planning.plan import Part, Way
        >>> e = WaysEngine(ways_plan("p", [Part("a"), Part("b"), Part("c")],
        ...                          {"c": [Way(frozenset(), (frozenset({"a"}),))], "a": [Way(frozenset({"b"}))]}))
        >>> e.alive(0), e.alive(0b010)      # b in first: a never goes in, so c neither
        (True, False)
        """
        memo, table = self._alive, self.table
        stack = [[mask, None]]      # per set entered: its children not tried yet (None: none listed)
        while stack:
            top = stack[-1]
            s, todo = top
            if todo is None:
                found = memo.get(s)
                if found is None:
                    if s == table.full:
                        found = True
                    elif table.shut_out(s) or table.locked(s):
                        found = False
                    elif not table.has_needs:
                        found = True
                if found is None:
                    top[1] = table.goes(s)
                    continue
                memo[s] = found
            elif memo.get(s) is None and todo:
                b = todo & -todo
                top[1] = todo ^ b
                stack.append([s | b, None])
                continue
            elif memo.get(s) is None:
                memo[s] = False         # no child live
            stack.pop()
            if stack and memo[s]:
                memo[stack[-1][0]] = True       # a child is live: so is its parent
        return memo[mask]

    def installable(self, mask: int, consistent: int) -> tuple[str, ...]:
        """The parts that can go in now without a dead end, in declaration order (nothing counted)."""
        key = mask | consistent << self.n_units
        out = self._installable_cache.get(key)
        if out is None:
            if len(self._installable_cache) > 100_000:
                self._installable_cache.clear()
            out = self._installable_cache[key] = tuple(
                self._unit_ids[i] for i in _bits(self.table.goes(mask)) if consistent and self.live(mask | 1 << i))
        return out

    def installable_set(self, mask: int, consistent: int) -> frozenset[str]:
        """:meth:`installable` as a set."""
        return frozenset(self.installable(mask, consistent))

    def installable_among(self, mask: int, consistent: int, parts: Collection[str]) -> list[str]:
        """Those of ``parts`` installable now (declaration order): the liveness of those alone is decided
        (a look asks of two or three parts, and each liveness costs O(passes × ways))."""
        key = mask | consistent << self.n_units
        known = self._installable_cache.get(key)
        index = self.plan.index
        asked = sorted({u for p in parts if (u := self.next_unit(mask, index(p))) is not None}) if consistent else []
        if known is not None:
            return [self._unit_ids[i] for i in asked if self._unit_ids[i] in known]
        return [self._unit_ids[i] for i in asked
                if not mask >> i & 1 and self.table.can_go(mask, i) and self.live(mask | 1 << i)]

    def installable_units(self, mask: int, consistent: int) -> int:
        """The installable parts' next units as a mask."""
        out = 0
        for i in _bits(self.table.goes(mask)):
            if consistent and self.live(mask | 1 << i):
                out |= 1 << i
        return out

    def _next(self, mask: int, part: str) -> int | None:
        """The part's next unit on ``mask`` (None: all its units in)."""
        return self.next_unit(mask, self.plan.index(part))

    def missing_before(self, mask: int, part: str) -> list[str]:
        """Parts to install before ``part``'s next unit (declaration order): for its way that asks the fewest, each
        unmet need met by the part that itself asks the fewest, with what that part asks
        (:meth:`~opportune.planning.ways.WaysTable.before`); [] if it can go in now or every way of it is
        blocked by a part already in.

        Examples
        --------
        >>> from opportune.formats.ways import ways_plan
        >>> from opportune.planning.plan import Part, Way
        >>> ways = {"b": [Way(frozenset(), (frozenset({"a"}),))], "c": [Way(frozenset(), (frozenset({"b"}),))]}
        >>> WaysEngine(ways_plan("p", [Part("a"), Part("b"), Part("c")], ways)).missing_before(0, "c")
        ['a', 'b']
        """
        i = self._next(mask, part)
        return [] if i is None else [self._unit_ids[u] for u in _bits(self.table.before(mask, i))]

    def waits(self, mask: int, consistent: int, unit: int) -> tuple[int, int]:
        """The installs still needed before part ``unit`` can go in (:meth:`missing_before`'s), and the
        parts that must follow it as far as the ways show
        (:meth:`~opportune.planning.ways.WaysTable.waiting_on`): on a plan of one strategy written as ways,
        the order engine's answers.

        Examples
        --------
        >>> from opportune.formats.ways import ways_plan
        >>> from opportune.planning.plan import Part, Way
        >>> ways = {"b": [Way(frozenset(), (frozenset({"a"}),))], "c": [Way(frozenset(), (frozenset({"b"}),))]}
        >>> WaysEngine(ways_plan("p", [Part("a"), Part("b"), Part("c")], ways)).waits(0, 1, 1)
        (1, 1)
        """
        return self.table.before(mask, unit).bit_count(), self.table.waiting_on(mask, unit).bit_count()

    def steps_waiting(self, unit: int) -> int:
        """The parts that must follow part ``unit`` at the start (:meth:`waits`'s second, on nothing
        installed): the rollout's static priority."""
        return self.table.waiting_on(0, unit).bit_count()

    # ---------------------------------------------------------------- counts

    def count(self, mask: int, consistent: int) -> int:
        """The exact number of admissible completions of ``mask`` (0 if ``consistent`` is 0)."""
        if not consistent:
            return 0
        return self.counter.count(mask, self._until)

    def options(self, mask: int, consistent: int) -> dict[str, int]:
        """For each installable part: the completions left after installing it (declaration order)."""
        key = mask | consistent << self.n_units
        cached = self._options_cache.get(key)
        if cached is None:
            cached = self.options_for(mask, consistent, self.installable(mask, consistent))
            self._options_cache[key] = cached
        return dict(cached)

    def options_for(self, mask: int, consistent: int, parts: Collection[str]) -> dict[str, int]:
        """:meth:`options` for those of ``parts`` installable now."""
        return {p: self.count(mask | 1 << self._next(mask, p), 1) for p in self.installable_among(mask, consistent, parts)}

    def prepare(self, deadline: Deadline | float | None = None) -> None:
        """Nothing to build: the ways are the tables."""

    def nbytes(self) -> int:
        """Estimated bytes held: the memo, the liveness and per-state caches, the programmes' grants."""
        return (self.counter.nbytes() + nbytes(self._live) + nbytes(self._alive) + nbytes(self._installable_cache)
                + nbytes(self._options_cache) + nbytes(self._positions_cache) + sum(self.programmes.values()))

    def clear_state_caches(self) -> None:
        """Forget the per-state caches and the liveness found (not the memo)."""
        super().clear_state_caches()
        self._live.clear()
        self._alive.clear()

    def position_sums_for(self, mask: int, consistent: int, parts: Iterable[str]) -> tuple[int, dict[str, int]]:
        """``(completions, position sums)`` of these parts: the sum over all completions of each part's
        1-based position after ``mask`` (a forward pass over the live sets reachable from it).

        Examples
        --------
        >>> from opportune.formats.ways import ways_plan
        >>> from opportune.planning.plan import Part, Way
        >>> e = WaysEngine(ways_plan("p", [Part("a"), Part("b")], {"a": [Way(frozenset({"b"}))]}))
        >>> e.position_sums_for(0, 1, ["a", "b"])
        (1, {'a': 1, 'b': 2})
        """
        total = self.count(mask, consistent)
        sums = self._position_sums(mask) if total else {}
        nxt = {p: self._next(mask, p) for p in parts}
        return total, {p: sums.get(u, 0) for p, u in nxt.items() if u is not None}

    def _position_sums(self, mask: int) -> dict[int, int]:
        key = mask
        cached = self._positions_cache.get(key)
        if cached is not None:
            return cached
        memo, table = self.counter.memo, self.table
        dl = as_deadline(self._until)
        sums: dict[int, int] = {}
        level, depth = {mask: 1}, 1
        while level:
            nxt: dict[int, int] = {}
            for s, paths in level.items():
                shutting = table.shutting(s)        # s is live: t is shut out iff i is among these
                for i in _bits(table.goes(s)):
                    t = s | 1 << i
                    f = memo.get(t)
                    if f is None:
                        f = 0 if shutting >> i & 1 else self.counter.count(t, dl)
                    if f:
                        sums[i] = sums.get(i, 0) + paths * f * depth
                        nxt[t] = nxt.get(t, 0) + paths
                dl.check("position sums of a plan of ways")
            level, depth = nxt, depth + 1
        self._positions_cache[key] = sums
        return sums

    def expected_positions(self, mask: int, consistent: int) -> dict[str, Fraction]:
        """Expected position (1 = next) of each remaining part in a uniformly random completion."""
        from fractions import Fraction      # here: it loads decimal (5 ms at start-up)

        total, sums = self.position_sums_for(mask, consistent, [p.id for p in self.plan.parts])
        return {p: Fraction(v, total) for p, v in sums.items()} if total else {}

    def count_result(self, mask: int, *, rel_error: float = 0.01, time_limit: float = 10.0, seed: int = 0,
                     exact_share: float = 0.65, deadline=None, estimate: bool = True) -> CountResult:
        """The completions of ``mask``: exact within ``exact_share`` of the time (at most
        :data:`EXACT_SHARE`), else estimated by :func:`~opportune.engine.ways.estimate_completions` within
        the rest (``seed``, ``rel_error``);
        ``estimate=False``: the exact count alone, within ``deadline`` (or the engine's), else
        :class:`BudgetExceeded`.

        Examples
        --------
        >>> from opportune.formats.ways import ways_plan
        >>> from opportune.planning.plan import Part
        >>> WaysEngine(ways_plan("p", [Part("a"), Part("b"), Part("c")], {})).count_result(0).value
        6
        """
        if not estimate:
            return CountResult(self.counter.count(mask, self._until if deadline is None else deadline))
        dl = as_deadline(deadline).within(time_limit)
        start = time.perf_counter()
        share = min(exact_share, EXACT_SHARE)
        try:
            return CountResult(self.counter.count(mask, dl.within(share * max(0.0, dl.at - start))))
        except BudgetExceeded:
            pass
        return estimate_completions(self.table, mask, seed=seed, rel_error=rel_error, deadline=dl)
