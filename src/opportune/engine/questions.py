"""The questions an order engine answers about a state: installable parts, options, positions.

The base class :class:`StateQuestions` of :class:`~opportune.engine.schedule.OrderEngine`; every
answer is cached per state (keyed by ``mask | consistent << n_units``) and counted through
:class:`~opportune.engine.exact.ExactCounting`.
"""

from __future__ import annotations

from opportune.engine import tuning
from opportune.engine.deadline import BudgetExceeded
from opportune.engine.poset import bits as _bits
from opportune.engine.poset import byte_unions

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Collection, Iterable

    from opportune.engine.count import Counter

    from fractions import Fraction

__all__ = ["StateQuestions"]


class StateQuestions:
    """Questions about a state for an :class:`~opportune.engine.schedule.OrderEngine` (its base class)."""

    def consistent_after(self, mask: int, consistent: int, unit: int) -> int:
        """Strategies (bitmask) in which ``unit`` can be installed on top of ``mask``.  O(strategies).

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.
        unit : int
            The unit to install next.

        Returns
        -------
        int
            Those of ``consistent`` whose order has every unit before ``unit`` installed (0: none).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], strategies={"x": {"c": ["a"]}, "y": {"c": ["b"]}}))
        >>> c = engine.first[2]                # the unit of part c
        >>> engine.consistent_after(0, 0b11, c), engine.consistent_after(0b001, 0b11, c)
        (0, 1)
        """
        if self.k == 1:  # the common case: no loop
            return consistent if self.posets[0].below[unit] & ~mask == 0 else 0
        out = 0
        for s in range(self.k):
            if consistent >> s & 1 and self.posets[s].below[unit] & ~mask == 0:
                out |= 1 << s
        return out

    def exact_after(self, mask: int, consistent: int, unit: int) -> int:
        """:meth:`consistent_after`, decided exactly: the exact programmes (the optimum, a policy's value)
        step by it.  An order engine's is exact already; a plan written as ways decides here whether the
        set after has a completion without the bound its look-by-look answers keep
        (:meth:`~opportune.engine.waysengine.WaysEngine.exact_after`).  O(strategies) here.

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.
        unit : int
            The unit to install next.

        Returns
        -------
        int
            As :meth:`consistent_after`.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> OrderEngine(make_plan(["a", "b"], {"b": ["a"]})).exact_after(0, 1, 1)
        0
        """
        return self.consistent_after(mask, consistent, unit)

    def waits(self, mask: int, consistent: int, unit: int) -> tuple[int, int]:
        """The installs still needed before ``unit`` can go in, and the steps that wait on it (each under
        the consistent strategy that has the fewest).  O(strategies).

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open (not 0).
        unit : int
            A unit not installed.

        Returns
        -------
        tuple of (int, int)
            The units left below ``unit``, and the units left above it.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"b": ["a"], "c": ["b"]}))
        >>> engine.waits(0, 1, engine.first[1]), engine.waits(0b001, 1, engine.first[2])
        ((1, 1), (1, 0))
        """
        remaining = self.full & ~mask
        posets = [self.posets[s] for s in range(self.k) if consistent >> s & 1]
        return (min((p.below[unit] & remaining).bit_count() for p in posets),
                min((p.above[unit] & remaining).bit_count() for p in posets))

    def steps_waiting(self, unit: int) -> int:
        """The steps that wait on ``unit`` at the start, in the strategy that has the most (a static
        priority).  O(strategies).

        Parameters
        ----------
        unit : int
            A unit.

        Returns
        -------
        int
            The units above it.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], strategies={"x": {"c": ["a"]}, "y": {"c": ["b"], "b": ["a"]}}))
        >>> engine.steps_waiting(engine.first[0])
        2
        """
        return max(p.above[unit].bit_count() for p in self.posets)

    def next_unit(self, mask: int, part: int) -> int | None:
        """The next uninstalled unit of a part, or None if all are installed.  O(quantity).

        Parameters
        ----------
        mask : int
            The installed units.
        part : int
            The part's index in ``plan.parts``.

        Returns
        -------
        int or None
            The unit's number (a part's units go in lowest first).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan([{"id": "s", "quantity": 2}, "a"], {}))
        >>> engine.next_unit(0, 0), engine.next_unit(0b01, 0), engine.next_unit(0b11, 0)
        (0, 1, None)
        """
        first = self.first[part]
        q = self._quantity[part]
        if q == 1:
            return None if mask >> first & 1 else first
        for u in range(first, first + q):
            if not mask >> u & 1:
                return u
        return None

    def options(self, mask: int, consistent: int) -> dict[str, int]:
        """For each part installable now: admissible completions left after installing it.

        Cached per state.  Callers above the engine use :meth:`Schedule.options
        <opportune.engine.schedule.Schedule.options>`.

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.

        Returns
        -------
        dict of str to int
            Part id → completions after it, in declaration order (the caller must not change it:
            it is the cached one).

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))       # a b c, a c b, b a c
        >>> engine.options(0, engine.all_strategies)
        {'a': 2, 'b': 1}
        """
        key = mask | consistent << self.n_units
        cached = self._options_cache.get(key)
        if cached is not None:
            return cached
        out: dict[str, int] = {}
        for i, part in enumerate(self.plan.parts):
            u = self.next_unit(mask, i)
            if u is None:
                continue
            after = self.consistent_after(mask, consistent, u)
            if after:
                out[part.id] = self.count(mask | 1 << u, after)
        self._options_cache[key] = out
        return out

    def installable_set(self, mask: int, consistent: int) -> frozenset[str]:
        """The parts installable in a state, as a set (cached; no counting).

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.

        Returns
        -------
        frozenset of str
            Their ids.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))       # a b c, a c b, b a c
        >>> sorted(engine.installable_set(0, engine.all_strategies))
        ['a', 'b']
        """
        key = mask | consistent << self.n_units
        out = self._installable_cache.get(key)
        if out is None:
            out = frozenset(self.installable(mask, consistent))  # the scan options_for keeps for the state
            self._installable_cache[key] = out
        return out

    def options_for(self, mask: int, consistent: int, parts: Collection[str]) -> dict[str, int]:
        """:meth:`options` restricted to ``parts`` (those installable), counting only what is asked.

        On large plans a decision needs the options of the few visible or buffered
        parts, not of every installable part.  Per state, the installable units are
        found once and each count is cached; the parts asked about are then looked up
        one by one (O(k) big-integer operations for k parts asked about, not O(n) for the
        n installable parts).  Declaration order, like :meth:`options`.

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.
        parts : collection of str
            Part ids (those not installable are left out).

        Returns
        -------
        dict of str to int
            Part id → completions after it, for those of ``parts`` installable now.

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))       # a b c, a c b, b a c
        >>> engine.options_for(0, engine.all_strategies, ["c", "b"])
        {'b': 1}
        """
        key = mask | consistent << self.n_units
        entry = self._option_cache.get(key)
        if entry is None:
            full = self._options_cache.get(key)
            if full is not None:
                return {p: n for p, n in full.items() if p in parts}
            entry = self._option_entry(key, mask, consistent)
        known = entry[2]
        out: dict[str, int] = {}
        for part, unit in self._next_units(entry, mask, parts):
            value = known.get(part)
            if value is None:
                after = self.consistent_after(mask, consistent, unit)
                value = known[part] = self.count(mask | 1 << unit, after)
            out[part] = value
        return out

    def installable(self, mask: int, consistent: int) -> tuple[str, ...]:
        """The parts installable in a state, in declaration order, without counting anything.

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.

        Returns
        -------
        tuple of str
            Their ids.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"a": ["c"]}))
        >>> engine.installable(0, engine.all_strategies)
        ('b', 'c')
        """
        key = mask | consistent << self.n_units
        entry = self._option_cache.get(key)
        if entry is None:
            entry = self._option_entry(key, mask, consistent)
        return tuple(self._entry_parts(entry))

    def installable_among(self, mask: int, consistent: int, parts: Collection[str]) -> list[str]:
        """Those of ``parts`` installable now (declaration order), without counting anything.

        Shares the per-state table of :meth:`options_for`, so asking this first and the
        options next costs one scan of the state.  A decision with a single candidate
        needs no count at all.

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.
        parts : collection of str
            Part ids.

        Returns
        -------
        list of str
            Those installable now.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> engine.installable_among(0, engine.all_strategies, ("c", "b"))
        ['b']
        """
        key = mask | consistent << self.n_units
        entry = self._option_cache.get(key)
        if entry is None:
            entry = self._option_entry(key, mask, consistent)
        return [part for part, _ in self._next_units(entry, mask, parts)]

    def _option_entry(self, key: int, mask: int, consistent: int) -> list:
        """The per-state entry of :meth:`options_for`: ``[installable units (a bitmask), the installable
        parts with their next unit's number (built when first asked for all of them), the options
        counted so far]``."""
        if len(self._option_cache) > tuning.STATE_CACHE_LIMIT:
            self._trim()
        entry = self._option_cache[key] = [self.installable_units(mask, consistent), None, {}]
        return entry

    def _entry_parts(self, entry: list) -> dict[str, int]:
        """Every installable part of a state's entry with its next unit's number (declaration order)."""
        if entry[1] is None:
            ids = self._unit_ids
            # unit numbers, not bits: n bits of n bits each would be O(n²) time and memory (12 MB on 10,000 parts)
            entry[1] = {ids[u]: u for u in _bits(entry[0])}
        return entry[1]

    def _next_units(self, entry: list, mask: int, parts: Collection[str]) -> list[tuple[str, int]]:
        """``(part, its next unit)`` for those of ``parts`` installable in the entry's state (declaration
        order).  O(k log k) big-integer operations for k parts (each O(n / 64) on n units), unless the
        entry already holds every installable part."""
        asked = parts if isinstance(parts, (set, frozenset)) else set(parts)   # a look may name a part twice
        if entry[1] is not None:
            can = entry[1]
            if len(asked) >= len(can):
                return [(p, u) for p, u in can.items() if p in asked]
            return sorted(((p, can[p]) for p in asked if p in can), key=lambda pu: pu[1])
        out = []
        units, installable = self._part_units, entry[0]
        for part in asked:
            left = units.get(part, 0) & ~mask
            if left:
                unit = (left & -left).bit_length() - 1   # a part's units go in in order: the lowest left
                if installable >> unit & 1:
                    out.append((part, unit))
        out.sort(key=lambda pu: pu[1])
        return out

    def installable_units(self, mask: int, consistent: int) -> int:
        """Bitmask of the units that can be installed now: the minimal remaining units under some
        consistent strategy (at most one per part, its next unit: a part's units are chained).

        A unit is minimal unless it is above some remaining unit; the union of what lies above
        the remaining units is gathered a byte of the set at a time from per-strategy tables built
        on first use (:meth:`prepare`).

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.

        Returns
        -------
        int
            The installable units (a bitmask).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))       # a b c, a c b, b a c
        >>> bin(engine.installable_units(0, engine.all_strategies))      # units of a and b
        '0b11'
        """
        remaining = self.full & ~mask
        data = remaining.to_bytes(self._nbytes, "little")
        out = 0
        for s, tables in enumerate(self._above_tables()):
            if consistent >> s & 1:
                up = 0
                if self.n_units <= tuning.WIDE_TABLES:
                    for table, byte in zip(tables, data):
                        if byte:
                            up |= table[byte]
                else:   # tables of four bits (see _above_tables)
                    for low, high, byte in zip(tables[0::2], tables[1::2], data):
                        if byte:
                            up |= low[byte & 15] | high[byte >> 4]
                out |= remaining & ~up
        return out

    def _above_tables(self) -> list[list[list[int]]]:
        """Per strategy and byte ``j`` of a unit set: ``table[v]`` is the union of ``above[u]``
        over the units ``u`` that the byte value ``v`` holds (built on first use)."""
        tables = self._above
        if tables is None:
            # past WIDE_TABLES units, tables of four bits: byte tables hold 32 n sets of up to n bits
            # (390 MB and 0.6 s to build on a 10,000-unit assembly graph), these 4 n
            width = 8 if self.n_units <= tuning.WIDE_TABLES else 4
            tables = self._above = [byte_unions(poset.above, self.n_units, width) for poset in self.posets]
        return tables

    def expected_positions(self, mask: int, consistent: int) -> dict[str, Fraction]:
        """Expected position (1 = next) of each remaining part's next unit (declaration order).

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.

        Returns
        -------
        dict of str to Fraction
            Part id → its exact expected position over the admissible completions.

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))       # a b c, a c b, b a c
        >>> {part: str(f) for part, f in engine.expected_positions(0b001, engine.all_strategies).items()}
        {'b': '3/2', 'c': '3/2'}
        """
        total, sums = self.position_sums_for(mask, consistent, (p.id for p in self.plan.parts))
        from fractions import Fraction

        return {part: Fraction(s, total) for part, s in sums.items()}

    def position_sums_for(self, mask: int, consistent: int, parts: Iterable[str]) -> tuple[int, dict[str, int]]:
        """``(completions, {part: sum of its next unit's positions})`` for those of ``parts`` remaining.

        Each sum over the completions count is an expected position: one denominator for
        all, so comparing sums compares expected positions, without fractions.  Computed
        once per state (a buffer decision compares the two or three visible parts).

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.
        parts : iterable of str
            Part ids (those with no unit left are left out).

        Returns
        -------
        tuple of (int, dict of str to int)
            The completions, and part id → the sum of its next unit's positions over them.

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))       # a b c, a c b, b a c
        >>> engine.position_sums_for(0, engine.all_strategies, ["c", "a"])
        (3, {'c': 8, 'a': 4})
        """
        key = mask | consistent << self.n_units
        table = self._positions_cache.get(key)
        if table is None:
            if len(self._positions_cache) > tuning.STATE_CACHE_LIMIT:
                self._trim()
            total = self.count(mask, consistent)
            if self._hub_state(mask, consistent):   # through a hub: only the units asked for, one by one
                table = self._positions_cache[key] = (total, {})
            else:
                table = self._positions_cache[key] = (total, self.position_sums(mask, consistent))
        total, by_unit = table
        units = self._part_units
        out: dict[str, int] = {}
        for part in parts:
            left = units[part] & ~mask
            if left:  # the next unit is the lowest one left
                unit = (left & -left).bit_length() - 1
                value = by_unit.get(unit)
                if value is None:
                    value = by_unit[unit] = self._unit_position_sum(mask, consistent, unit)
                out[part] = value
        return total, out

    def _hub_state(self, mask: int, consistent: int) -> bool:
        """Whether some counter of the state counts it through a hub (never on plans the plain counter handles)."""
        if not self._hubs:
            return False
        remaining = self.full & ~mask
        return any(self._hub_for(counter, remaining) is not None for _, counter in self._terms(consistent))

    def _unit_position_sum(self, mask: int, consistent: int, unit: int) -> int:
        remaining = self.full & ~mask
        return sum(sign * self._term_position_sums(counter, remaining, (unit,))[unit]
                   for sign, counter in self._terms(consistent))

    def position_sums(self, mask: int, consistent: int) -> dict[int, int]:
        """Sum over all admissible completions of each remaining unit's 1-based position.

        Parameters
        ----------
        mask : int
            The installed units.
        consistent : int
            The strategies still open.

        Returns
        -------
        dict of int to int
            Unit → its position sum (divided by the count: its expected position).

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))       # a b c, a c b, b a c
        >>> sorted(engine.position_sums(0, engine.all_strategies).items())    # units of a, b, c
        [(0, 4), (1, 6), (2, 8)]
        """
        remaining = self.full & ~mask
        terms = self._terms(consistent)
        if len(terms) == 1:  # one strategy: the counter's own (fresh) table
            return self._term_position_sums(terms[0][1], remaining)
        sums: dict[int, int] = {}
        for sign, counter in terms:
            for unit, value in self._term_position_sums(counter, remaining).items():
                sums[unit] = sums.get(unit, 0) + sign * value
        return sums

    def _term_position_sums(self, counter: Counter, s: int, units: Iterable[int] | None = None) -> dict[int, int]:
        """Position sums of ``units`` (default: all of ``s``) over the orders of ``s`` under one counter."""
        self._term_count(counter, s)            # chooses the way (and finds the hub) if not done yet
        if self._until is not None:
            self._check_until()
            counter.deadline = self._until if counter.deadline is None else min(counter.deadline, self._until)
        hub = self._hub_for(counter, s)
        if hub is None:
            sums = counter.position_sums(s)
            return sums if units is None else {u: sums[u] for u in units}
        out = {}
        deadline = self._deadline(counter)
        for u in (_bits(s) if units is None else units):
            v = hub.position_sum(s, u, deadline=deadline)
            if v is None and self._until is not None:
                # the plain vectors have no deadline (a 1,000-task plan took a minute): within a decision's
                # budget, give up instead
                raise BudgetExceeded("the expected positions need the plain vectors", reason="time")
            if v is None:       # not of the hub form after all: the plain vectors (may exceed a time limit)
                sums = counter.position_sums(s)
                return sums if units is None else {u: sums[u] for u in (_bits(s) if units is None else units)}
            out[u] = v
        return out
