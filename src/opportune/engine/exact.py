"""Exact counts of an order engine's states, and the one deadline of a decision.

The base class :class:`ExactCounting` of :class:`~opportune.engine.schedule.OrderEngine`: the
counters per set of strategies, the inclusion–exclusion terms, counting a term plainly or through
its hub (:class:`~opportune.engine.hub.HubPath`), and the clocks (:meth:`ExactCounting.deadline`, a
decision's one deadline; :meth:`ExactCounting.time_limited`, a limit per count).  What it reads
is set by the engine's ``__init__``.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from itertools import combinations

from opportune.engine import tuning
from opportune.engine.count import MAX_TOTAL, Counter
from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline
from opportune.engine.hub import HubPath
from opportune.engine.poset import CycleError

__all__ = ["ExactCounting"]


class ExactCounting:
    """Exact counting for an :class:`~opportune.engine.schedule.OrderEngine` (its base class)."""

    def counter(self, strategies: int) -> Counter | None:
        """Counter for the sequences admissible under *every* strategy in the bitmask.

        Made once per set of strategies (their orders united) and kept, with its memo, for the
        engine's life.

        Parameters
        ----------
        strategies : int
            A non-empty set of strategies (bit *k* for ``plan.strategies[k]``).

        Returns
        -------
        Counter or None
            The :class:`~opportune.engine.count.Counter` of the united order, or None where the
            strategies contradict each other (no sequence is admissible under all of them).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], strategies={"x": {"c": ["a"]}, "y": {"c": ["b"]}}))
        >>> engine.counter(0b01).count(engine.full), engine.counter(0b11).count(engine.full)
        (3, 2)
        >>> OrderEngine(make_plan(["a", "c"], strategies={"x": {"c": ["a"]}, "y": {"a": ["c"]}})).counter(0b11) is None
        True
        """
        if strategies not in self._counters:
            members = [self.posets[s] for s in range(self.k) if strategies >> s & 1]
            poset = members[0]
            try:
                for other in members[1:]:
                    poset = poset.union(other)
            except CycleError:
                self._counters[strategies] = None
            else:
                # a count allowed more entries than a counter usually holds keeps them between its
                # phases (the memory limit still bounds what stays between decisions)
                self._counters[strategies] = Counter(poset, max_memo=self.max_memo, time_limit=self.time_limit,
                                                     max_total=max(MAX_TOTAL, self.max_memo or 0))
                self._counters[strategies].hold_upkeep = self._deciding > 0
        return self._counters[strategies]

    def _terms(self, consistent: int, deadline=None) -> list:
        """Inclusion–exclusion terms ``(sign, counter)`` over the non-empty subsets of ``consistent`` (cached;
        the single strategies first).  Past ``deadline`` (a :class:`~opportune.engine.deadline.Deadline`,
        read before each union of orders), :class:`BudgetExceeded`; the counters made so far are kept."""
        terms = self._terms_cache.get(consistent)
        if terms is not None:
            return terms
        members = [s for s in range(self.k) if consistent >> s & 1]
        if len(members) > tuning.MAX_STRATEGIES_EXACT:
            raise BudgetExceeded(f"{len(members)} strategies: inclusion–exclusion over 2^{len(members)} sets")
        terms = []
        for size in range(1, len(members) + 1):
            sign = 1 if size % 2 else -1
            for subset in combinations(members, size):
                if deadline is not None and size > 1:
                    deadline.check("the orders of the strategies' intersections")
                counter = self.counter(sum(1 << s for s in subset))
                if counter is not None:
                    terms.append((sign, counter))
        self._terms_cache[consistent] = terms
        return terms

    def terms(self, consistent: int, deadline: Deadline | None = None) -> list:
        """The inclusion–exclusion terms ``(sign, counter)`` of a set of strategies.

        What :mod:`opportune.engine.phases` counts term by term: the admissible sequences under any
        of the strategies are the signed sum of the terms' counts.  Cached per set.

        Parameters
        ----------
        consistent : int
            The strategies (a bitmask).
        deadline : Deadline or None, optional
            Read before each union of orders (None: none).

        Returns
        -------
        list of (int, Counter)
            One term per non-empty subset whose orders agree, the single strategies first; the sign
            ``+1`` for odd subsets, ``-1`` for even ones.

        Raises
        ------
        BudgetExceeded
            Past ``deadline`` (the counters made so far are kept), or more than
            ``MAX_STRATEGIES_EXACT`` strategies (:mod:`opportune.engine.tuning`).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], strategies={"x": {"c": ["a"]}, "y": {"c": ["b"]}}))
        >>> [(sign, c.count(engine.full)) for sign, c in engine.terms(0b11)]     # 3 + 3 - 2
        [(1, 3), (1, 3), (-1, 2)]
        """
        return self._terms(consistent, deadline)

    def hub_found_in(self, terms: list) -> bool:
        """Whether a counter of the terms ``(sign, counter)`` counts through a hub it found.  O(terms).

        Parameters
        ----------
        terms : list of (int, Counter)
            Terms of :meth:`terms`.

        Returns
        -------
        bool
            True if one of them has a hub (never on orders the plain counter handles).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> engine.count(0, engine.all_strategies), engine.hub_found_in(engine.terms(engine.all_strategies))
        (3, False)
        """
        hubs = self._hubs
        return any(hubs.get(c) is not None for _, c in terms)

    def hub_looked_for(self, counter: Counter) -> bool:
        """Whether a hub was looked for on ``counter`` (found, not found, or a search cut short).  O(1).

        Parameters
        ----------
        counter : Counter
            A counter of this engine.

        Returns
        -------
        bool
            True once its plain count ran out of its probe and a hub was searched for.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> engine.hub_looked_for(engine.counter(engine.all_strategies))     # a small order: never
        False
        """
        return counter in self._hubs or counter in self._hub_search

    def end_probe(self, counter: Counter) -> None:
        """End the plain count's probe on ``counter``: its next count looks for a hub at once.  O(1).

        What the exact phases do after a plain turn that did not finish, so that the engine's turn
        goes to the hub.

        Parameters
        ----------
        counter : Counter
            A counter of this engine.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> engine.end_probe(engine.counter(engine.all_strategies))
        >>> engine.count(0, engine.all_strategies)           # exact either way
        3
        """
        self._probe_left[counter] = 0

    def count(self, mask: int, consistent: int) -> int:
        """Exact number of admissible completions after installing ``mask``.

        Inclusion–exclusion over the strategies still consistent, each term counted plainly or
        through its hub; cached per state.  Callers above the engine use :meth:`Schedule.count
        <opportune.engine.schedule.Schedule.count>`.

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.

        Returns
        -------
        int
            The number of admissible completions.

        Raises
        ------
        BudgetExceeded
            The count did not fit the memo or time budget, or the deadline of :meth:`deadline`
            (what was counted stays in the memos: a later call goes on from there).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], strategies={"x": {"c": ["a"]}, "y": {"c": ["b"]}}))
        >>> engine.count(0, 0b11), engine.count(0, 0b01), engine.count(0b001, 0b11)
        (4, 3, 2)
        """
        terms = self._terms_cache.get(consistent)
        if terms is None:
            terms = self._terms(consistent)
        if len(terms) == 1:  # one strategy: no inclusion–exclusion, and the counter's memo is the cache
            remaining = self.full & ~mask
            r = terms[0][1].cached(remaining)
            return r if r is not None else self._term_count(terms[0][1], remaining)
        key = mask | consistent << self.n_units
        cached = self._count_cache.get(key)
        if cached is not None:
            return cached
        if len(self._count_cache) > tuning.STATE_CACHE_LIMIT:
            self._trim()
        remaining = self.full & ~mask
        total = 0
        for sign, counter in terms:
            total += sign * self._term_count(counter, remaining)
        self._count_cache[key] = total
        return total

    def _term_count(self, counter: Counter, s: int) -> int:
        """``counter.count(s)``, through a hub (:class:`~opportune.engine.hub.HubPath`) when the plain count fails.

        The plain count is tried first with at most ``HUB_PROBE`` new memo entries (over all
        calls: a probe cut short by a time limit resumes where it stopped); only if that
        fails is a hub looked for (once per counter; a search cut short by a time limit
        resumes too, its memos kept).  A counter with a hub sends every set holding it
        (with some of what precedes it) to the hub path, whose memos persist: the nested
        sets of a simulation cost milliseconds.  Counts are exact either way; a plan the
        plain counter handles never leaves it.
        """
        r = counter.cached(s)
        if r is not None:
            return r
        if self._until is not None:
            self._check_until()
            counter.deadline = self._until if counter.deadline is None else min(counter.deadline, self._until)
        if counter in self._hubs:
            hub = self._hubs[counter]
            if hub is not None and hub.applies(s):
                v = hub.count(s, deadline=self._deadline(counter))
                if v is not None:
                    counter.learn(s, v)
                    return v
            return counter.count(s)
        hub = self._hub_search.get(counter)
        if hub is None:
            limit = counter.max_memo
            if limit is not None and limit <= tuning.HUB_PROBE:
                return counter.count(s)
            left = self._probe_left.get(counter, tuning.HUB_PROBE)
            counter.max_memo = left
            before = counter.memo_size
            try:
                return counter.count(s)
            except BudgetExceeded as exc:
                if exc.reason != "memo":
                    self._probe_left[counter] = left - max(0, counter.memo_size - before)   # (a memo reset shrinks it)
                    if self._probe_left[counter] > 0:
                        raise
            finally:
                counter.max_memo = limit
            hub = self._hub_search[counter] = HubPath(counter.poset, max_memo=limit, deadline=self._deadline(counter))
            hub.counter.hold_upkeep = self._deciding > 0
        v = hub.count(s, deadline=self._deadline(counter), discover=True)   # a time limit raises: resumed later
        del self._hub_search[counter]
        if v is not None and hub.tails:
            self._hubs[counter] = hub
            counter.learn(s, v)
            return v
        self._hubs[counter] = None
        return counter.count(s)             # plainly, continuing from the probe's memo

    def _check_until(self) -> None:
        """Raise BudgetExceeded once the deadline of :meth:`deadline` has passed: a decision that asks
        for many counts, each quick (memo hits in the compiled core), must still stop on time."""
        now = time.perf_counter()
        if now > self._until:
            raise BudgetExceeded("the deadline has passed", reason="time", elapsed=0.0)

    @property
    def decision_deadline(self) -> Deadline:
        """The deadline :meth:`deadline` set for the decision under way (``Deadline.NEVER`` outside one):
        programmes beside the engine that count nothing through it (a compiled optimum) keep it too.
        O(1).

        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b"], {"b": ["a"]}))
        >>> engine.decision_deadline.finite
        False
        >>> with engine.deadline(0.0):
        ...     engine.decision_deadline.at
        0.0
        """
        return as_deadline(self._until)

    @contextmanager
    def deadline(self, until: float | None):
        """Within the block, every exact count of this engine stops at ``until``.

        One deadline for all the counts of a decision, not a limit per count.  What was counted
        stays in the memos, so a later call continues from there.

        Parameters
        ----------
        until : float or None
            A ``time.perf_counter()`` moment (None: none within the block).

        Yields
        ------
        OrderEngine
            This engine.

        Raises
        ------
        BudgetExceeded
            From a count inside the block, once ``until`` has passed.

        Examples
        --------
        >>> import time
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> with engine.deadline(time.perf_counter() - 1.0):      # already passed
        ...     engine.count(0, engine.all_strategies)
        Traceback (most recent call last):
        ...
        opportune.engine.deadline.BudgetExceeded: the deadline has passed
        >>> engine.count(0, engine.all_strategies)
        3
        """
        # An absolute stop (Counter.deadline), not a time limit from each count's start: work done
        # before a count (a probe, a hub search) must not push the end of the decision later.
        saved = self._until, {key: c.deadline for key, c in self._counters.items() if c is not None}
        self._until = until
        try:
            yield self
        finally:
            self._until = saved[0]
            for key, c in self._counters.items():
                if c is not None:
                    c.deadline = saved[1].get(key)

    @contextmanager
    def time_limited(self, seconds: float | None):
        """Within the block, every exact count of this engine gives up after ``seconds``.

        For a caller that must know early whether exact counting is affordable on a plan,
        without waiting for the memo budget to run out.  The engine's and its counters' own limits
        come back after the block.

        Parameters
        ----------
        seconds : float or None
            Seconds per count (None: no limit within the block).

        Yields
        ------
        OrderEngine
            This engine.

        Raises
        ------
        BudgetExceeded
            From a count inside the block that took longer (what it counted stays in the memo).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> with engine.time_limited(5.0):
        ...     engine.time_limit, engine.count(0, engine.all_strategies)
        (5.0, 3)
        >>> engine.time_limit is None
        True
        """
        saved = self.time_limit, {key: c.time_limit for key, c in self._counters.items() if c is not None}
        self.time_limit = seconds
        for c in self._counters.values():
            if c is not None:
                c.time_limit = seconds
        try:
            yield self
        finally:
            self.time_limit = saved[0]
            for key, c in self._counters.items():
                if c is not None:
                    c.time_limit = saved[1].get(key, saved[0])

    def warm_up(self, time_limit: float | None = None, mask: int = 0, consistent: int | None = None) -> bool:
        """Build what every decision uses (:meth:`prepare`), then count a state exactly.

        This chooses how the plan is counted (finding a hub if it has one) and fills the memos every
        later question uses.  If it does not finish, what it built and counted is kept.  Callers
        above the engine use :meth:`Schedule.warm_up <opportune.engine.schedule.Schedule.warm_up>`.

        Parameters
        ----------
        time_limit : float or None, optional
            Seconds for all of it (None: no limit).
        mask : int, default 0
            The state's installed units (default: the first state).
        consistent : int or None, optional
            The state's open strategies (None: all).

        Returns
        -------
        bool
            True if it finished in time.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> engine.warm_up(1.0), engine.warm_up(1.0, mask=0b001, consistent=engine.all_strategies)
        (True, True)
        """
        until = time.perf_counter() + time_limit if time_limit is not None else None
        try:
            self.prepare(until)
            with self.deadline(until):
                self.count(mask, self.all_strategies if consistent is None else consistent)
        except BudgetExceeded:
            return False
        return True

    def prepare(self, deadline: Deadline | float | None = None) -> None:
        """Build the plan's tables that any decision needs, so that none is built inside one: the tables
        that find installable units, and each strategy's cover pairs (where the chains of an estimate
        move).  O(n / 4 · 16 + covers) big-integer operations per strategy, once per engine; each
        table is kept when finished.

        Parameters
        ----------
        deadline : Deadline or float or None, optional
            When to stop (a :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()``
            moment; None: never).

        Raises
        ------
        BudgetExceeded
            Past ``deadline`` (:class:`~opportune.engine.deadline.BudgetExceeded`); the tables
            finished so far are kept.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> OrderEngine(make_plan(["a", "b"], {"b": ["a"]})).prepare()
        """
        dl = as_deadline(deadline)
        dl.check("preparing the plan's tables")
        self._above_tables()
        for poset in self.posets:
            dl.check("preparing the plan's tables")
            poset.cover_pairs(deadline=dl)

    def _deadline(self, counter: Counter) -> float:
        """When the work on one count must stop: the deadline of :meth:`deadline` if one is set (it
        covers everything a decision counts), else the counter's own time limit from now."""
        if self._until is not None:
            return self._until
        return time.perf_counter() + counter.time_limit if counter.time_limit is not None else float("inf")

    def _hub_for(self, counter: Counter, s: int) -> HubPath | None:
        """The hub path of ``counter`` if it applies to ``s`` (after a count of ``s`` has chosen the way)."""
        hub = self._hubs.get(counter)
        return hub if hub is not None and hub.applies(s) else None
