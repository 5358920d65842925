"""What the frontier windows of the pile and of the weighted bin share: the window made a plan of its own,
the plan's other units lumped as one more group of an exact programme, and the policy that solves a state's
window and decides by it.

The uniform bin's window (:mod:`~opportune.policies.window`) has its own compiled programme, whose looks
are order statistics.  The pile's (:mod:`~opportune.policies.pile_window`) and the weighted bin's
(:mod:`~opportune.policies.weighted_window`) are those bins' exact programmes (:mod:`~opportune.policies.pile`,
:mod:`~opportune.policies.optimal`, Python and compiled) run on :func:`window_plan` with the *others*, the
plan's remaining units outside the window, as one more group after its parts (:class:`OthersGroup`): in
the bin they dilute the looks, an other seen may be buffered (a free location, the others' mean move), and
none is installed before the window is complete, the terminal state (what the others cost after it does
not depend on what was done in the window).  The window takes the parts of the look first (with their
ancestors, where they fit), so that a part seen is valued as the part it is, not as a lumped other.

Where several strategies are open, as in the uniform bin, a window of each open strategy's frontier is
solved (its plan keeps the strategies it is closed in: in another, a window part waits for a part outside
it), and the look chooses among their best moves, each with what the parts outside its window cost after
it (:func:`~opportune.policies.window.outside_rest`), less the value of keeping several strategies open
on the moves that keep them: a window of one strategy's frontier values a state as if the others were
closed.  Taking the first open strategy's frontier alone, the others credited with the parts outside it,
cost up to +6.7% over the optimum in the pile and +34% in a weighted bin on 16-part two-strategy plans
(docs/decisions.md).  Each bin's subclass values that option over its own looks (:meth:`LumpedWindow._option`,
cached by the state and its windows), and may have a strategy's window take first only the parts of the
look near that strategy's frontier (:meth:`LumpedWindow._forced_in`): a part deep in its order would bring
in the chain below it, and the strategy's own frontier would be lumped.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import replace as _replace

from opportune.engine import OrderEngine
from opportune.engine.deadline import Deadline, as_deadline
from opportune.engine.tuning import WINDOW_ENGINES, WINDOW_STRATEGIES
from opportune.engine.tuning import WINDOW_MISSES as MISSES
from opportune.engine.tuning import WINDOW_REFINE as REFINE
from opportune.planning.costs import TimeModel
from opportune.planning.plan import Plan, Strategy
from opportune.policies.base import DONE, SHAKE, Action, DecidesOnMasks, Decision
from opportune.policies.evaluate import OutOfTime
from opportune.policies.optimal import OptimalTooLarge
from opportune.policies.window import (core_strategies, frontier_window, near_parts, start_factor_applies,
                                       window_decision, window_strategies)

__all__ = ["OTHERS", "CompiledOthers", "LumpedWindow", "OthersGroup", "window_plan"]

#: The id the others' group takes in a window programme's moves (no plan part has it: part ids are printable).
OTHERS = "\x00others"


def window_plan(engine, mask: int, consistent: int, parts: list[int]) -> Plan:
    """The window's parts as a plan of their own: each with its remaining units (in declaration order), one
    strategy per open strategy with its order among them (a part before another where the last remaining unit
    of the one is below the first of the other; ancestors outside the window taken as installed).
    O(parts² × strategies).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies.
    parts : list of int
        The window's parts (plan indices, declaration order), each with a unit left.

    Returns
    -------
    Plan
        The window's plan (the parts keep their ids, so a cost model prices them as on the plan).

    Examples
    --------
    >>> from opportune import make_plan
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"b": ["a"], "c": ["b"]}))
    >>> plan = window_plan(engine, 1, 1, [1, 2])
    >>> plan.part_ids, dict(plan.strategies[0].requires)
    (('b', 'c'), {'c': ('b',)})
    """
    plan = engine.plan
    first, last, kept = {}, {}, []
    for i in parts:
        units = [u for u in range(engine.first[i], engine.first[i] + plan.parts[i].quantity) if not mask >> u & 1]
        first[i], last[i] = units[0], units[-1]
        kept.append(_replace(plan.parts[i], quantity=len(units)))
    strategies = []
    for s, poset in enumerate(engine.posets):
        if consistent >> s & 1:
            requires = {plan.parts[a].id: tuple(plan.parts[b].id for b in parts
                                                if b != a and poset.below[first[a]] >> last[b] & 1)
                        for a in parts}
            strategies.append(Strategy(f"s{s}", {a: bs for a, bs in requires.items() if bs}))
    return Plan("window", tuple(kept), tuple(strategies))


class OthersGroup:
    """A mixin before an exact programme (:class:`~opportune.policies.optimal.OptimalSolver` or
    :class:`~opportune.policies.pile.PileSolver`): ``others`` more units lumped as one more group after the
    plan's parts, in the states (the last buffer count) and in the looks (of weight ``other_weight``),
    buffered at ``other_move`` (infinite: never), never installed.  With no others, the programme itself."""

    def __init__(self, engine, *, others: int = 0, other_move: float = float("inf"), other_weight: float = 1.0,
                 **settings):
        super().__init__(engine, **settings)
        self.others, self.other_move = int(others), float(other_move)
        if self.others:
            self.quantity = [*self.quantity, self.others]
            self.move = [*self.move, self.other_move]
            self.weights = [*self.weights, float(other_weight)]
            self.ids = (*self.ids, OTHERS)

    def _part_index(self, part: str) -> int:
        return len(self.plan.parts) if part == OTHERS else self.plan.index(part)

    def _installed_counts(self, mask: int) -> list[int]:
        return super()._installed_counts(mask) + [0] * (self.others > 0)

    def _buffer_installs(self, mask: int, cons: int, buf: tuple[int, ...]):
        """The plan's parts' installations from the buffer (the others are never installed).  O(parts)."""
        n = len(self.plan.parts)
        for i, (m, c, nb) in super()._buffer_installs(mask, cons, buf[:n]):
            yield i, (m, c, nb + buf[n:])

    def _buffer_other(self, key: tuple) -> tuple | None:
        """The key after buffering an other, or None where that is not a move (no free location, or the
        others are never buffered).  O(parts)."""
        n = len(self.plan.parts)
        mask, cons, buf = key
        if self.other_move == float("inf") or (self.capacity is not None and sum(buf) >= self.capacity):
            return None
        nb = list(buf)
        nb[n] += 1
        return (mask, cons, tuple(nb))


class CompiledOthers:
    """A mixin before a compiled programme of an :class:`OthersGroup`: the core gets the plan's parts'
    quantities and moves (the others apart, in its last arguments)."""

    def _core_args(self) -> tuple:
        args = list(super()._core_args())
        n = len(self.plan.parts)
        args[2], args[4] = args[2][:n], args[4][:n]
        return tuple(args)


class LumpedWindow(DecidesOnMasks):
    """A policy deciding by the exact programme of the frontier window at each state, the rest of the plan
    lumped (see the module): the windows tried in increasing size, the largest that fits ``max_states`` (or
    the deadline) deciding, the state's solved window cached; the base rule where none fits.  A subclass
    gives :meth:`_solved` (a state's window solved: a table with ``parts``, ``states``, ``value``, the
    window's expected cost from the state, and ``rest``, what the parts outside it cost after it,
    :func:`~opportune.policies.window.outside_rest`), :meth:`_decide` (a table's best move on a look, or
    None, with its expected cost and that of a shake, the rest aside), :meth:`_note`, and :meth:`_option`
    where it values keeping several strategies open.  Where several strategies are open, a window of each
    one's frontier is solved, and each look takes the least of their moves (:meth:`_over_windows`).

    The attribute ``work`` counts windows solved, the states they held, decisions left to the base, and
    windows predicted to fit that did not (``missed``; :meth:`_largest`).
    The attribute ``deadline``, a :class:`~opportune.engine.deadline.Deadline` or None, stops a window's
    programme; the base decides then.
    """

    deterministic = True
    decision_key = None
    #: States whose solved window is kept.
    cache = 4096
    #: Whether the bin is the pile (its states listed with its windows).
    pile = False

    def __init__(self, base=None, *, visible: int = 2, capacity: int | None = None, costs: TimeModel | None = None,
                 sizes: tuple[int, ...] = (5, 8, 12), max_states: int = 20_000):
        from opportune.policies.variants import Slack

        self.base = base if base is not None else Slack()
        self.visible, self.capacity, self.costs = visible, capacity, costs or TimeModel()
        self.sizes, self.max_states = tuple(sorted(sizes)), max_states
        self.deadline: Deadline | None = None
        self.work = {"windows": 0, "states": 0, "most_states": 0, "by_base": 0, "missed": 0}
        self._tables: OrderedDict = OrderedDict()      # by state and forced parts: the window that decides
        self._windows: OrderedDict = OrderedDict()     # by state and window: the window solved
        # what the search for a state's largest window asks again (across its sizes, its rounds and a state's
        # looks), each a function of its key alone: a decision never depends on what was asked before
        self._frontiers: OrderedDict = OrderedDict()   # by (installed, strategies, parts first, size)
        self._engines: OrderedDict = OrderedDict()     # by (installed, strategies, parts): the window plan's engine
        self._listings: OrderedDict = OrderedDict()    # by (installed, strategies, parts): its states listed, the most asked
        self._options: OrderedDict = OrderedDict()     # by state and windows: the option of several strategies
        self._engine = None
        self.last_table = None

    def table(self, engine, mask: int, consistent: int, buffer, forced: tuple[str, ...] = ()):
        """The state's window solved (cached), or None where no window fits (states, or the deadline): of the
        frontier windows of the open strategies (:meth:`tables`), the one of least value with its rest.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask, consistent : int
            The installed units and the open strategies.
        buffer : sequence of str
            The buffered parts.
        forced : tuple of str
            Parts the window takes first, as it takes the buffered ones (with their ancestors, where they fit).

        Returns
        -------
        table or None
            The largest window's table that fitted, or None where none did.
        """
        tables = self.tables(engine, mask, consistent, buffer, forced)
        return min(tables, key=lambda t: t.value + t.rest) if tables else None

    def tables(self, engine, mask: int, consistent: int, buffer, forced: tuple[str, ...] = ()) -> tuple:
        """The state's windows solved (cached), one a distinct window of the first
        :data:`~opportune.engine.tuning.WINDOW_STRATEGIES` open strategies' frontiers, each the largest that
        fits; empty where none fits.  A look then takes its best move over them (:meth:`choose_at`): each
        window is one strategy's frontier, and on a two-strategy plan the look chooses the strategy, as on the
        real plan.  At most ``len(sizes) × max_states`` states of work a window.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask, consistent : int
            The installed units and the open strategies.
        buffer : sequence of str
            The buffered parts.
        forced : tuple of str
            Parts each window takes first, as it takes the buffered ones.

        Returns
        -------
        tuple of tables
            One a distinct window (one strategy open: at most one), or empty.
        """
        if self._engine is not engine:
            self._engine = engine
            for cache in (self._tables, self._windows, self._frontiers, self._engines, self._listings, self._options):
                cache.clear()
        key = (mask, consistent, tuple(sorted(buffer)), forced)
        got = _cached(self._tables, key)
        if got is None:
            found: dict = {}
            strategies, given = core_strategies(engine, consistent)[:WINDOW_STRATEGIES], self.deadline
            try:
                for n, s in enumerate(strategies):
                    # each strategy's windows their share of the time left (none: no deadline, the same
                    # decisions): a window the deadline cuts leaves its strategy the last size finished, and
                    # the later strategies still get theirs, not the time the first one's larger windows took
                    self.deadline = as_deadline(given).share(1 / (len(strategies) - n))
                    first = tuple(buffer) + self._forced_in(engine, mask, consistent, forced, s)
                    table = self._largest(engine, mask, consistent, buffer, first, s)
                    if table is not None:
                        found.setdefault(table.parts, table)
            finally:
                self.deadline = given
            got = tuple(found.values())
            if got:
                _keep(self._tables, key, got, self.cache)
        return got

    def _largest(self, engine, mask: int, consistent: int, buffer, first: tuple, strategy: int):
        """The largest window predicted to fit, solved: the smallest size is solved, then in turn the largest
        size whose states are predicted within its cap (:meth:`_pick`), up to
        :data:`~opportune.engine.tuning.WINDOW_REFINE` windows solved.  A window predicted to fit that does
        not (its programme passed the cap) is a miss: the prediction's ratio is raised to what the miss proved,
        the next pick is at most halfway from the last window solved to the missed one, and no later pick is
        the missed size or larger, up to :data:`~opportune.engine.tuning.WINDOW_MISSES` misses (a miss no
        longer leaves the smallest window deciding where the largest sizes are far from it); past the
        deadline the last window solved decides.  So a state costs a few windows, not every size.  Each
        window is ``strategy``'s frontier.  None where the smallest does not fit."""
        parts, outside = self._frontier(engine, mask, consistent, first, self.sizes[0], strategy)
        got = self._window(engine, mask, consistent, buffer, parts, outside, self.sizes[0])
        if got is None:
            return None
        solved = missed = 0
        floor, missed_size, below = 0.0, float("inf"), float("inf")     # what the misses proved
        while outside and solved < REFINE and missed < MISSES:
            ratio = max(floor, got.states / max(1, self._listed(engine, mask, consistent, parts,
                                                                 self._cap(len(parts), consistent, mask))))
            pick = self._pick(engine, mask, consistent, first, strategy, got.size, below, parts, ratio)
            if pick is None:
                break
            bigger = self._window(engine, mask, consistent, buffer, pick[1], pick[2], pick[0])
            if bigger is None and as_deadline(self.deadline).expired():
                break               # out of time, not a miss: the last window solved decides
            if bigger is None:
                missed += 1
                self.work["missed"] += 1
                cap = self._cap(len(pick[1]), consistent, mask)
                floor = max(ratio, (cap + 1) / max(1, self._listed(engine, mask, consistent, pick[1], cap)))
                missed_size, below = min(missed_size, pick[0]), (got.size + pick[0]) // 2 + 1
                continue
            solved += 1
            got, (_, parts, outside), below = bigger, pick, missed_size
        return got

    def _pick(self, engine, mask: int, consistent: int, first: tuple, strategy: int, above: int, below: float,
              parts, ratio: float):
        """The largest size over ``above`` and under ``below`` whose window's states are predicted within its
        cap (the states listed for its plan, :func:`~opportune.policies.states.estimate_states` without the
        others, times ``ratio``), the sizes tried in turn until one is predicted over it: ``(size, parts,
        outside)``, or None where no larger window is predicted to fit.  O(sizes) listings, each stopped at
        the cap."""
        pick = None
        for size in (s for s in self._sizes(consistent) if above < s < below):
            more, rest = self._frontier(engine, mask, consistent, first, size, strategy)
            if more == (pick[1] if pick else parts):
                continue
            cap = self._cap(len(more), consistent, mask)
            if ratio * self._listed(engine, mask, consistent, more, int(cap / ratio) + 1) > cap:
                break
            pick = (size, more, rest)
            if not rest:
                break
        return pick

    def _window(self, engine, mask: int, consistent: int, buffer, parts: list[int], outside: list[int], size: int):
        """The window of these parts solved (cached by state and parts: looks that force parts already in it
        share it), or None where it does not fit (states, or the deadline)."""
        key = (mask, consistent, tuple(sorted(buffer)), tuple(parts))
        got = _cached(self._windows, key)
        if got is None:
            try:
                got = _keep(self._windows, key, self._solved(engine, mask, consistent, buffer, parts, outside, size),
                            self.cache)
            except (OptimalTooLarge, OutOfTime):
                return None
        return got

    def _listed(self, engine, mask: int, consistent: int, parts: list[int], most: int) -> int:
        """The states of the window's plan without the others, listed, or ``most + 1`` where they are more
        than ``most`` (a function of the key and ``most`` alone; the callers compare it with ``most``).  The
        listing is cached by state and parts: a count answers every later ask, a listing stopped answers
        those stopping no later, so the search's rounds and a state's looks list a window once, again only
        for a later stop (on KILBRID at 3 visible in the pile, 8-9 listings a decision before).
        O(states listed)."""
        from opportune.policies.states import estimate_states

        key = (mask, consistent, tuple(parts))
        got = _cached(self._listings, key)
        if got is None or not (got[1] or most <= got[2]):
            found = estimate_states(self._window_engine(engine, mask, consistent, parts), visible=self.visible,
                                    capacity=self.capacity, pile=self.pile, stop_above=most, time_limit=None)
            got = _keep(self._listings, key, (found.states, found.exact, most), self.cache)
        states, exact, _ = got
        return states if exact and states <= most else most + 1

    def _frontier(self, engine, mask: int, consistent: int, first: tuple, size: int, strategy: int):
        """:func:`~opportune.policies.window.frontier_window` of ``size`` parts of ``strategy``'s frontier with
        the parts ``first`` taken first, cached (the search asks each size in each of its rounds, and a
        state's looks ask again).  In the order of remaining ancestors alone: these programmes have no ready
        others (the uniform window's order by descendants was measured with them)."""
        key = (mask, consistent, first, size, strategy)
        got = _cached(self._frontiers, key)
        return got if got is not None else _keep(
            self._frontiers, key, frontier_window(engine, mask, consistent, first, size, strategy, descendants=0.0),
            self.cache)

    def _window_engine(self, engine, mask: int, consistent: int, parts: list[int]) -> OrderEngine:
        """:func:`window_engine`, cached (a window listed is then solved, and a state's looks share it)."""
        key = (mask, consistent, tuple(parts))
        got = _cached(self._engines, key)
        if got is None:
            kept = window_strategies(engine, mask, consistent, parts) or consistent
            got = _keep(self._engines, key, window_engine(engine, mask, kept, parts), WINDOW_ENGINES)
        return got

    def _cap(self, parts: int, consistent: int, mask: int) -> int:
        """The states a window of ``parts`` parts may hold at a state of these open strategies and installed
        units: ``max_states``, times :meth:`_start` (a subclass may grant more where several are open)."""
        return self.max_states * self._start(mask)

    #: Before a run's first installation, without a deadline, a window's programme may hold this many times
    #: more (1: no more; the pile's :data:`~opportune.engine.tuning.PILE_START_FACTOR`).
    start_factor: int = 1

    def _start(self, mask: int) -> int:
        """:attr:`start_factor` at a state before a run's first installation (nothing installed: the states
        every run passes through, its start again after each shake there) where there is no deadline, else
        1: within a budget the cap is the usual one.  O(1)."""
        return self.start_factor if start_factor_applies(mask, self.deadline, self._start_units()) else 1

    def _start_units(self) -> int:
        """The installed units up to which :meth:`_start` grants the start factor (0: before the first
        installation only; a subclass may grant it longer).  O(1)."""
        return 0

    def _sizes(self, consistent: int) -> tuple[int, ...]:
        """The window sizes tried at a state of these open strategies (``sizes``; a subclass may try fewer
        where several are open)."""
        return self.sizes

    def _forced(self, engine, visible) -> tuple[str, ...]:
        """The parts of a look the window takes first, with their ancestors where they fit, as it takes the
        buffered ones: a part seen outside the state's window is then valued as the part it is, not as a
        lumped other that is never installed (on a 16-part plan at 1 visible and 1 location, +1.03% over
        the optimum without, +0.28% with, in a weighted bin).  Looks whose parts the state's window holds
        share its table (:meth:`_window` caches by the parts).  O(visible)."""
        return tuple(sorted(set(visible), key=engine.plan.index))

    #: Where several strategies are open, with at least this many buffer locations, or :attr:`near_visible`
    #: parts a look, a strategy's window takes first only the parts of a look within :attr:`near_units` of
    #: its frontier (:meth:`_forced_in`).
    near_locations: float = float("inf")
    #: See :attr:`near_locations`.
    near_visible: int = 2
    #: Remaining units a part of a look may wait for in a strategy and still be taken first by its window
    #: (None: every part of the look is taken first, whatever the settings).
    near_units: int | None = None

    @property
    def locations(self) -> float:
        """The buffer's locations (infinite where unlimited), as the settings' thresholds compare them.  O(1)."""
        return float("inf") if self.capacity is None else self.capacity

    def _forced_in(self, engine, mask: int, consistent: int, forced: tuple[str, ...], strategy: int) -> tuple[str, ...]:
        """The parts of a look ``strategy``'s window takes first (:meth:`_forced`): all of them with one
        strategy open, or with fewer than :attr:`near_locations` locations and :attr:`near_visible` parts a
        look, or without :attr:`near_units`; else those within :attr:`near_units` remaining units of its
        frontier (:func:`~opportune.policies.window.near_parts`), the others seen there lumped as others.
        A part deep in one strategy's order, taken in with the chain below it, makes that strategy's window
        its chain, the strategy's own frontier lumped and never installed: the window then values the
        strategy far over what it costs, and a move closing it wins the look.  O(visible)."""
        if self.near_units is None or consistent.bit_count() < 2 or (
                self.locations < self.near_locations and self.visible < self.near_visible):
            return forced
        return near_parts(engine, mask, strategy, forced, self.near_units)

    def _count(self, solver) -> None:
        """The work of a window's programme, counted."""
        self.work["windows"] += 1
        self.work["states"] += solver.states
        self.work["most_states"] = max(self.work["most_states"], solver.states)

    def _window_key(self, engine, buffer, parts: list[int], outside: list[int], mask: int):
        """The window's buffer counts (the others buffered last, where there are others), the others' count,
        their mean move and their mean weight (``self.weights``, where the subclass has them).  O(units)."""
        plan = engine.plan
        index = {i: j for j, i in enumerate(parts)}
        buf, others_buffered = [0] * len(parts), 0
        for p in buffer:
            j = index.get(plan.index(p))
            if j is None:
                others_buffered += 1
            else:
                buf[j] += 1
        units = [plan.parts[i].id for i in outside
                 for u in range(engine.first[i], engine.first[i] + plan.parts[i].quantity) if not mask >> u & 1]
        weights = getattr(self, "weights", None) or {}
        n = len(units) or 1
        return (tuple(buf) + ((others_buffered,) if units else ()), len(units),
                sum(self.costs.move(p) for p in units) / n if units else float("inf"),
                sum(float(weights.get(p, 1.0)) for p in units) / n)

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]):
        if mask == engine.full:
            return DONE
        tables = self.tables(engine, mask, consistent, buffer, self._forced(engine, visible))
        if not tables:
            self.last_table = None
            self.work["by_base"] += 1
            return self.base.choose_at(engine, mask, consistent, buffer, free, visible)
        decided = [(self._decide(engine, mask, consistent, t, buffer, visible), t) for t in tables]
        if len(decided) == 1:
            (value, action, shake), self.last_table = decided[0]
            return SHAKE if action is None or value > shake + 1e-12 else action
        return self._over_windows(engine, mask, consistent, buffer, decided, visible)

    def _over_windows(self, engine, mask: int, consistent: int, buffer, decided, visible) -> Action:
        """Where several strategies' windows decide (the look chooses the strategy, as on the real plan, where
        its installations close the others): each window's best move on the look with its rest, the value of
        keeping several strategies open (:meth:`_option`) taken off the moves that keep them (a buffering, an
        installation several allow), the least deciding (ties: the first strategy's); a shake where none is
        cheaper than a shake after the least window less that value, by 1e-12.  A window of one strategy's
        frontier values a state as if the others were closed.  O(windows) and :meth:`_option`."""
        plan = engine.plan
        option = self._option(engine, mask, consistent, buffer, tuple(t for _, t in decided))
        least = min(decided, key=lambda d: d[1].value + d[1].rest)[1]
        ranked = []
        for n, ((value, action, _), t) in enumerate(decided):
            if action is None:
                continue
            keeps = consistent
            if action.kind == "install":
                keeps = engine.consistent_after(mask, consistent, engine.next_unit(mask, plan.index(action.part)))
            deeper = self._kept_open(engine, mask, consistent, buffer, visible, action, keeps) \
                if keeps.bit_count() > 1 else None
            ranked.append((value + t.rest - option * (keeps.bit_count() > 1) if deeper is None else deeper,
                           n, action, t))
        best = min(ranked, key=lambda r: r[:2]) if ranked else None
        if best is None or best[0] > float(self.costs.shake) + least.value + least.rest - option + 1e-12:
            self.last_table = least
            return SHAKE
        self.last_table = best[3]
        return best[2]

    def _kept_open(self, engine, mask: int, consistent: int, buffer, visible, action, keeps) -> float | None:
        """A move keeping several strategies open valued a look deeper, by the windows of the state it leads
        to (a subclass's; None here: the option value decides)."""
        return None

    def _option(self, engine, mask: int, consistent: int, buffer, tables) -> float:
        """What keeping several strategies open is worth at a state, one look deep, by its windows
        (:meth:`_option_at`), cached by the state and the windows (a state's looks ask again).  O(1) cached."""
        key = (mask, consistent, tuple(sorted(buffer)), tuple(t.parts for t in tables))
        got = _cached(self._options, key)
        if got is None:
            got = _keep(self._options, key, self._option_at(engine, mask, consistent, buffer, tables), self.cache)
        return got

    def _option_at(self, engine, mask: int, consistent: int, buffer, tables) -> float:
        """:meth:`_option` computed (a subclass's; 0 here: each look takes the least of the windows' moves)."""
        return 0.0

    def decide(self, state, visible: tuple[str, ...], because: str = "") -> Decision:
        """The decision with its reasons; ``because``: why the window decides (a caller's words, first).

        Parameters
        ----------
        state : State
            The sequencer's state.
        visible : tuple of str
            The look.
        because : str
            Why the window decides, said first in the rule (empty: nothing said).

        Returns
        -------
        Decision
            The window's decision, or the base's (saying that no window fitted).
        """
        return window_decision(self, state, visible, because, self._note)


def _cached(cache: OrderedDict, key):
    """``cache[key]`` made the newest, or None."""
    got = cache.get(key)
    if got is not None:
        cache.move_to_end(key)
    return got


def _keep(cache: OrderedDict, key, value, most: int):
    """``value`` kept under ``key``, the oldest dropped past ``most`` entries; the value."""
    cache[key] = value
    if len(cache) > most:
        cache.popitem(last=False)
    return value


def window_engine(engine, mask: int, consistent: int, parts: list[int]) -> OrderEngine:
    """The engine of :func:`window_plan` (no memory upkeep: it lives for one state).  O(units × covers)."""
    return OrderEngine(window_plan(engine, mask, consistent, parts), memory_limit=None)
