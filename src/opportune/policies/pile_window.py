"""The pile's frontier window: near the optimum in the pile bin where the optimum's programme does not fit.

The uniform bin's frontier window (:mod:`~opportune.policies.window`) carried to the pile bin
(:mod:`~opportune.policies.pile`): at each state the window is the same parts
(:func:`~opportune.policies.window.frontier_window`: the buffered parts and the next remaining parts in a
topological order, closed under their remaining ancestors, up to a size), and the plan's other remaining
units are lumped into one count, the *others*.  The window is made a plan of its own
(:func:`~opportune.policies.lumped.window_plan`: its parts with their remaining units, each open strategy's order among them,
ancestors outside it taken as installed), and the pile's exact optimum is solved on it with the others
one more group of units (:class:`PileWindowSolver`; compiled, :class:`CompiledPileWindowSolver`, the
pile's own core ``src/native/pile.cpp`` with the group added, the same doubles): they lie in the pile
and in its visible top as units of a part do, an other seen may be buffered (a free location, the
others' mean move), and none is installed before the window is complete, the terminal state (what the
others cost after it does not depend on the window's policy).

The window takes the parts of the look first (the pile's top stays until a unit is taken from it: a part
seen outside the state's window would otherwise be valued as a lumped other, never installed, and the
window would shake where the optimum buffers or installs it).  The decision on a look is the window's best
action on it (a visible part outside the window is an other; buffered, it is the one first in the
topological order); an installation no open strategy of the plan allows is never chosen.  Every look of
a window is decided when it is solved (:class:`PileWindowTable`; :meth:`PileWindowSolver.actions`, in one
call to the compiled core), and looks whose parts one window holds
share it: the exact evaluation of the policy asks each look of a state between the looks of its
successors.  Where several strategies are open, a window of each one's frontier decides the look by the
least of their moves (:class:`~opportune.policies.lumped.LumpedWindow`): a move that keeps several open
is valued with the one-look option value (or, where a caller sets :attr:`PileWindow.look_deeper_locations`,
a look deeper, by the windows of the state it leads to: :meth:`PileWindow._kept_open`; measured to lose by
default, :data:`~opportune.engine.tuning.PILE_LOOK_DEEPER_LOCATIONS`), and with two locations or more, or two parts a look or more,
each strategy's window takes first only the parts of the look near its frontier (:meth:`PileWindow._forced_in`: a part deep in that
strategy's order is one of its others, not the chain below it), and
the shake less the value of keeping several open, computed over the fresh looks of their parts
(:func:`fresh_look_value`).  The window's size is the
largest predicted to fit
:data:`~opportune.engine.tuning.PILE_WINDOW_STATES` (:class:`~opportune.policies.lumped.LumpedWindow`:
counted states, the same decision on every machine), :data:`~opportune.engine.tuning.PILE_SEVERAL_FACTOR`
times more where several strategies are open and the buffer has two locations or more
(:meth:`PileWindow._cap`: there a window keeps every strategy it is closed in and each buffered combination,
and the moves that close a strategy are decided), :data:`~opportune.engine.tuning.PILE_LOCATIONS_FACTOR`
times more again where there is no deadline and the buffer has a location or more
(:data:`~opportune.engine.tuning.PILE_MORE_LOCATIONS`: each location multiplies the buffered combinations a
window keeps, so the same cap holds fewer parts; within a budget the cap is the usual one), of at most
:data:`~opportune.engine.tuning.PILE_DEEPER_PARTS` parts where a move keeping several open is valued a look
deeper (:meth:`PileWindow._sizes`), and :data:`~opportune.engine.tuning.PILE_START_FACTOR` times more
before a run's first installation, without a deadline (nothing installed: the states every run passes
through, its start again after each shake there; within a budget the cap is the usual one), and with one
location until :data:`~opportune.engine.tuning.PILE_EARLY_UNITS` units are installed; where none
fits, or past the deadline, the base rule decides.

Measured against the pile's optimum on the lab's plans of 16-30 parts (``benchmarks/policy_lab.py --bins pile
--policies fallback``) and per decision on KILBRID (``benchmarks/bench_fallback.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

from opportune.engine import compiled_core, tuning
from opportune.engine.deadline import as_deadline
from opportune.planning.costs import TimeModel
from opportune.policies.base import Action
from opportune.policies.lumped import OTHERS, CompiledOthers, LumpedWindow, OthersGroup
from opportune.policies.optimal import shake_loop
from opportune.policies.pile import CompiledPileSolver, PileSolver, compiled_pile_available
from opportune.policies.window import in_bin, outside_rest

__all__ = ["CompiledPileWindowSolver", "PileWindow", "PileWindowSolver", "PileWindowTable", "fresh_look_value",
           "pile_window_available", "pile_window_solver"]

_native = compiled_core()   # None: the Python programme only


def pile_window_available(engine) -> bool:
    """Whether the pile window serves this plan: the compiled core is built (not switched off with
    ``OPPORTUNE_PURE_PYTHON=1``; the Python programme is the compiled one's reference, too slow to decide
    within a budget) and the plan has at most 64 strategies.  O(1).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.

    Returns
    -------
    bool
        True where :class:`PileWindow` decides by the compiled programme.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> pile_window_available(OrderEngine(make_plan(["a"], {}))) in (True, False)
    True
    """
    return _native is not None and hasattr(_native, "PileCore") and engine.k <= 64


class PileWindowSolver(OthersGroup, PileSolver):
    """The pile's optimum on a window's plan with ``others`` more units lumped as one more group
    (:class:`~opportune.policies.lumped.OthersGroup`); with no others it is :class:`PileSolver`.  The optimum
    only (no policy).  Complexity: as PileSolver's, on the window's plan.
    """

    def _others_args(self) -> tuple:
        return (self.others, self.other_move)

    def _moves(self, key: tuple, look: tuple[int, ...]):
        """The plan's parts' moves, then buffering an other seen (a free location; ``other_move``)."""
        n = len(self.plan.parts)
        yield from super()._moves(key, tuple(i for i in look if i != n))
        nxt = self._buffer_other(key) if n in look else None
        if nxt is not None:
            yield self.other_move, nxt, Action("buffer", OTHERS)


    def actions(self, key: tuple, order: list[int], legal: list[bool]) -> tuple[float, dict]:
        """The value after a shake at ``key``, and the best move on every look of it: ``(kind, group,
        source, expected cost)`` (a group is a window part's index, the others last; the caller weighs it
        against a shake), or None where there is no move.  Ties: install, then buffer, then ``order`` (a
        rank per group), the bin before the buffer, as the optimum's; an installation of a group ``legal``
        refuses is not a move.  O(looks × moves); the compiled programme's in one call.

        Parameters
        ----------
        key : tuple
            The state (:meth:`~opportune.policies.optimal.OptimalSolver.policy_key`).
        order : list of int
            A rank per group (the window's parts, then the others), breaking ties of value and kind.
        legal : list of bool
            Per group, whether installing it is a move (the plan's open strategies allow it).

        Returns
        -------
        (float, dict)
            The value after a shake, and look (sorted groups) -> the best move with its expected cost, or None.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> solver = PileWindowSolver(OrderEngine(make_plan(["a"], {})), visible=1, others=1, other_move=1.0)
        >>> solver.actions(solver.start_key(), [0, 1], [True, False])
        (1.5, {(0,): ('install', 0, 'bin', 1.0), (1,): ('buffer', 1, None, 2.0)})
        """
        after_shake = self._after_shake(key)
        kinds, actions = {"install": 0, "buffer": 1}, {}
        for look, _ in self._looks(self._bin_counts(key)):
            best = None
            for cost, nxt, action in self._moves(key, look):
                j = self._part_index(action.part)
                if action.kind == "install" and not legal[j]:
                    continue
                rank = (cost + self._after(key, look, action, nxt), kinds[action.kind], order[j],
                        action.source == "buffer")
                if best is None or rank < best[0]:
                    best = (rank, (action.kind, j, action.source))
            actions[look] = None if best is None else (*best[1], best[0][0])
        return after_shake, actions


class CompiledPileWindowSolver(CompiledOthers, CompiledPileSolver, PileWindowSolver):
    """:class:`PileWindowSolver` computed by the pile's compiled core (the others its last group): the same
    doubles, and :meth:`actions` in one call to the core.  A ``ValueError`` where the core does not take the
    window's plan.  The core keeps the expectation over the unit replacing one taken, by the state after the
    move and the rest of the look: the same doubles, each computed once however many moves lead there."""

    def __init__(self, engine, **settings):
        super().__init__(engine, **settings)
        self._core.memo_taken(True)

    def actions(self, key: tuple, order: list[int], legal: list[bool]) -> tuple[float, dict]:
        return self._run(self._core.actions, key[0], key[1], list(key[2]), list(order), list(legal))


def pile_window_solver(engine, **settings) -> PileWindowSolver:
    """:class:`CompiledPileWindowSolver` where the compiled core takes the window's plan, else
    :class:`PileWindowSolver`; the same values either way.  O(1) before the work.

    Parameters
    ----------
    engine : OrderEngine
        The window plan's engine.
    **settings
        ``others``, ``other_move`` and :class:`~opportune.policies.pile.PileSolver`'s settings.

    Returns
    -------
    PileWindowSolver
        The programme (nothing computed yet).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> solver = pile_window_solver(OrderEngine(make_plan(["a"], {})), visible=1, others=1, other_move=1.0)
    >>> solver.value()       # the top is a (1 move) or the other (buffered, then a: 2 moves), evenly
    1.5
    """
    if compiled_pile_available(engine):
        try:
            return CompiledPileWindowSolver(engine, **settings)
        except ValueError:          # codes over 64 bits: the Python programme
            pass
    return PileWindowSolver(engine, **settings)


@dataclass(frozen=True)
class PileWindowTable:
    """A state's window solved: its parts (plan indices), the parts outside it (in the window's topological
    order), the window's best action on each look it can see (the window's parts by index, the others last;
    None: shake; else its kind, group, source and expected cost), the window's value after a shake, its
    size, the states its programme held, and what the parts outside cost after it."""

    parts: tuple[int, ...]
    outside: tuple[int, ...]
    actions: dict
    value: float
    size: int
    states: int
    #: What the parts outside cost after the window (:func:`~opportune.policies.window.outside_rest`).
    rest: float = 0.0


class PileWindow(LumpedWindow):
    """The exact optimum of the frontier window in the pile bin at each state, the rest of the plan lumped
    (see the module; :class:`~opportune.policies.lumped.LumpedWindow` for the work counted and the deadline).

    Parameters
    ----------
    base : policy, optional
        What decides where no window fits in ``max_states`` or in time (default
        :class:`~opportune.policies.variants.Slack`).
    visible, capacity, costs :
        The pile's world (as :class:`~opportune.policies.pile.PileSolver`).
    sizes : tuple of int
        The window sizes tried in turn (:data:`~opportune.engine.tuning.PILE_WINDOW_PARTS`).
    max_states : int
        Values a window's programme may hold (:data:`~opportune.engine.tuning.PILE_WINDOW_STATES`).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> PileWindow(visible=1, capacity=1).choose_at(engine, 0, 1, (), 1.0, ("c",))
    Action(kind='buffer', part='c', source=None)
    """

    name = "pile window"
    rule = "the action of least expected cost in the frontier window's exact optimum in the pile (the other parts lumped)"
    cache = tuning.PILE_WINDOW_CACHE
    pile = True

    def __init__(self, base=None, *, visible: int = 2, capacity: int | None = None, costs: TimeModel | None = None,
                 sizes: tuple[int, ...] = tuning.PILE_WINDOW_PARTS, max_states: int = tuning.PILE_WINDOW_STATES):
        super().__init__(base, visible=visible, capacity=capacity, costs=costs, sizes=sizes, max_states=max_states)

    def _solved(self, engine, mask: int, consistent: int, buffer, parts, outside, size: int) -> PileWindowTable:
        """The window of ``size`` parts solved, every look of the state decided.  The work is counted."""
        key, others, other_move, _ = self._window_key(engine, buffer, parts, outside, mask)
        sub = self._window_engine(engine, mask, consistent, parts)
        solver = pile_window_solver(sub, visible=self.visible, capacity=self.capacity, costs=self.costs,
                                    max_states=self._cap(len(parts), consistent, mask), others=others, other_move=other_move)
        solver.deadline = as_deadline(self.deadline)
        key = (0, sub.all_strategies, key)
        try:
            value, actions = solver._deep(lambda k: self._actions(engine, mask, consistent, parts, solver, k), key)
        finally:
            self._count(solver)
        return PileWindowTable(tuple(parts), tuple(outside), actions, value, size, solver.states,
                               outside_rest(engine, mask, outside, self.costs))

    def _actions(self, engine, mask: int, consistent: int, parts: list[int], solver, key: tuple):
        """The value after a shake, and the window's best action on every look of the state
        (:meth:`PileWindowSolver.actions`: ties by the plan's declaration order, the others last); an
        installation no open strategy of the plan allows is not a move.  O(looks × moves)."""
        legal = [engine.consistent_after(mask, consistent, engine.next_unit(mask, i)) != 0 for i in parts]
        order = list(parts)
        if len(solver.quantity) > len(parts):       # the others' group: never installed, ranked last
            legal.append(False)
            order.append(len(engine.plan.parts))
        return solver.actions(key, order, legal)

    def _decide(self, engine, mask: int, consistent: int, table: PileWindowTable, buffer,
                visible) -> tuple[float, Action | None, float]:
        plan = engine.plan
        index = {i: j for j, i in enumerate(table.parts)}
        n = len(table.parts)
        shake = float(self.costs.shake) + table.value
        chosen = table.actions.get(tuple(sorted(index.get(plan.index(p), n) for p in visible)))
        if chosen is None:
            return float("inf"), None, shake
        kind, j, source, value = chosen
        if j < n:
            return value, Action(kind, plan.parts[table.parts[j]].id, source), shake
        # an other: the one seen first in the window's topological order
        ids = set(visible)
        return value, Action("buffer", next(plan.parts[i].id for i in table.outside if plan.parts[i].id in ids)), shake

    #: The look's parts near a strategy's frontier (:meth:`~opportune.policies.lumped.LumpedWindow._forced_in`):
    #: :data:`~opportune.engine.tuning.PILE_NEAR_LOCATIONS`, :data:`~opportune.engine.tuning.PILE_NEAR_VISIBLE`,
    #: :data:`~opportune.engine.tuning.PILE_NEAR_UNITS`.
    near_locations: float = tuning.PILE_NEAR_LOCATIONS
    near_visible: int = tuning.PILE_NEAR_VISIBLE
    near_units: int | None = tuning.PILE_NEAR_UNITS

    #: Where several strategies are open and the buffer has at least this many locations, a window's
    #: programme may hold :attr:`several_factor` times ``max_states``
    #: (:data:`~opportune.engine.tuning.PILE_SEVERAL_LOCATIONS`).
    several_locations: float = tuning.PILE_SEVERAL_LOCATIONS
    #: See :attr:`several_locations` (:data:`~opportune.engine.tuning.PILE_SEVERAL_FACTOR`; 1: no more).
    several_factor: int = tuning.PILE_SEVERAL_FACTOR

    #: Where the buffer has at least this many locations, without a deadline, a window's programme may hold
    #: :attr:`locations_factor` times ``max_states`` (:data:`~opportune.engine.tuning.PILE_MORE_LOCATIONS`).
    more_locations: float = tuning.PILE_MORE_LOCATIONS
    #: See :attr:`more_locations` (:data:`~opportune.engine.tuning.PILE_LOCATIONS_FACTOR`; 1: no more).
    locations_factor: int = tuning.PILE_LOCATIONS_FACTOR

    def _cap(self, parts: int, consistent: int, mask: int) -> int:
        """``max_states``, times :attr:`several_factor` where several strategies are open and the buffer has
        :attr:`several_locations` or more: there a window of one strategy's frontier keeps every strategy
        it is closed in and each buffered combination, so the same cap holds fewer parts, while the
        decisions that close a strategy are the ones the gap comes from (a run meets few such states).
        Times :attr:`locations_factor` where the buffer has :attr:`more_locations` or more and there is no
        deadline (each location multiplies the buffered combinations; within a budget the deadline would cut
        the larger window).  Times :meth:`~opportune.policies.lumped.LumpedWindow._start` (before a run's
        first installation, without a deadline; with one location until :attr:`early_units` are installed).
        O(1)."""
        several = consistent.bit_count() > 1 and self.locations >= self.several_locations
        more = self.locations >= self.more_locations and as_deadline(self.deadline).at == float("inf")
        return (self.max_states * (self.several_factor if several else 1) * (self.locations_factor if more else 1)
                * self._start(mask))

    #: Before a run's first installation (nothing installed), without a deadline, a window's programme may
    #: hold this many times more (:data:`~opportune.engine.tuning.PILE_START_FACTOR`; 1: no more).
    start_factor: int = tuning.PILE_START_FACTOR
    #: With at most :attr:`early_locations` buffer locations, the start factor holds until this many units are
    #: installed (:data:`~opportune.engine.tuning.PILE_EARLY_UNITS`; 0: before the first installation only).
    early_units: int = tuning.PILE_EARLY_UNITS
    #: See :attr:`early_units` (:data:`~opportune.engine.tuning.PILE_EARLY_LOCATIONS`).
    early_locations: float = tuning.PILE_EARLY_LOCATIONS

    def _start_units(self) -> int:
        """:attr:`early_units` with at most :attr:`early_locations` buffer locations (few states, every run
        passes through them, and a part buffered early blocks the one location for long), else 0: the start's
        cap before the first installation only.  O(1)."""
        return self.early_units if self.locations <= self.early_locations else 0

    #: Buffer locations up to which a move keeping several strategies open is valued a look deeper
    #: (:data:`~opportune.engine.tuning.PILE_LOOK_DEEPER_LOCATIONS`; 0: never, the one-look option value).
    look_deeper_locations: float = tuning.PILE_LOOK_DEEPER_LOCATIONS
    #: The largest window where a move keeping several strategies open is valued a look deeper
    #: (:data:`~opportune.engine.tuning.PILE_DEEPER_PARTS`).
    deeper_parts: int = tuning.PILE_DEEPER_PARTS

    def _sizes(self, consistent: int) -> tuple[int, ...]:
        """``sizes``, at most :attr:`deeper_parts` where several strategies are open and a move keeping them
        is valued a look deeper (:meth:`_kept_open`): there the move is valued by the windows of the state it
        leads to and a shake by the state's own, and the larger the windows, the more the two differ (a
        buffering valued by a window of the whole plan, exact, against a shake valued by windows of 18 of
        20 parts whose lumped others wait unused). O(sizes)."""
        if consistent.bit_count() > 1 and self.locations <= self.look_deeper_locations:
            return tuple(s for s in self.sizes if s <= self.deeper_parts)
        return self.sizes

    def _kept_open(self, engine, mask: int, consistent: int, buffer, visible, action, keeps) -> float | None:
        """A move keeping several strategies open valued a look deeper: its motion, then the look after it
        (the top less the unit taken and one drawn from the hidden units; the same top after an
        installation from the buffer), each taking its best move over the windows of the state the move
        leads to, or a shake and a fresh look there (:func:`fresh_look_value`).  None where no window fits
        there (the deadline, or the cap), or past :data:`~opportune.engine.tuning.PILE_LOOK_DEEPER_LOCATIONS`
        buffer locations: the one-look option decides.  O(parts × windows) and the windows
        of that state (cached)."""
        if self.locations > self.look_deeper_locations:
            return None
        plan = engine.plan
        look, after = list(visible), list(buffer)
        mask2 = mask | 1 << engine.next_unit(mask, plan.index(action.part)) if action.kind == "install" else mask
        if action.kind == "buffer":
            after.append(action.part)
        (after if action.source == "buffer" else look).remove(action.part)
        move = float(self.costs.move(action.part))
        if mask2 == engine.full:
            return move
        tables = self.tables(engine, mask2, keeps, tuple(after))
        if not tables:
            return None
        fresh = fresh_look_value(engine, mask2, after, tables, self.visible, self.costs, tuning.PILE_OPTION_LOOKS)
        shake = float(self.costs.shake) + (fresh if fresh < float("inf") else min(t.value + t.rest for t in tables))
        maps, top = _maps(tables), [plan.index(p) for p in look]
        # an installation from the buffer leaves the top as it was; else a hidden unit takes the place taken
        hidden = {} if action.source == "buffer" else in_bin(engine, mask2, after + look)
        total = sum(hidden.values())
        if not total:
            return move + float(self.costs.look) + min(shake, _best_over(tables, maps, top))
        return move + float(self.costs.look) + sum(c / total * min(shake, _best_over(tables, maps, top + [j]))
                                                   for j, c in hidden.items())

    def _option_at(self, engine, mask: int, consistent: int, buffer, tables) -> float:
        """What keeping several strategies open is worth at a state, one look deep: the least of the windows'
        values with their rests less the state's value where each fresh look (a shake's: the bin's units
        drawn evenly) takes its best move over all the windows, the shake loop over them (as the pile's
        optimum's).  0 where the looks are more than :data:`~opportune.engine.tuning.PILE_OPTION_LOOKS`.
        O(looks × windows)."""
        return _pile_option(engine, mask, buffer, tables, self.visible, self.costs)

    def _note(self, table: PileWindowTable) -> str:
        return f"expected cost of the window after a shake {table.value:.4f}"


def _pile_option(engine, mask: int, buffer, tables, visible: int, costs: TimeModel) -> float:
    """:meth:`PileWindow._option` computed: the least of the windows' values with their rests less
    :func:`fresh_look_value`, at least 0; 0 past :data:`~opportune.engine.tuning.PILE_OPTION_LOOKS` looks."""
    value = fresh_look_value(engine, mask, buffer, tables, visible, costs, tuning.PILE_OPTION_LOOKS)
    least = min(t.value + t.rest for t in tables)
    return max(0.0, least - value) if value < float("inf") else 0.0


def fresh_look_value(engine, mask: int, buffer, tables, visible: int, costs: TimeModel,
                     most: int | None = None) -> float:
    """The value of a state after a shake where each fresh look (the bin's units drawn evenly; the units of
    parts outside every window one group) takes its best move over the windows, with their rests, the shake
    loop over the looks (as the pile's optimum's).  With one window, that window's own value after a shake
    and its rest.  O(looks × windows).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask : int
        The installed units.
    buffer : sequence of str
        The buffered parts.
    tables : sequence of PileWindowTable
        The state's windows.
    visible : int
        Parts per look.
    costs : TimeModel
        The costs of a look and a shake.
    most : int, optional
        Looks at most: inf past it (default: no limit).

    Returns
    -------
    float
        The value; inf where no look has a move, or past ``most`` looks.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> window = PileWindow(visible=1, capacity=1)
    >>> (table,) = window.tables(engine, 0, 1, ())
    >>> round(fresh_look_value(engine, 0, (), [table], 1, window.costs), 9) == round(table.value, 9)
    True
    """
    counts = in_bin(engine, mask, buffer)
    groups: list = [i for i in sorted({i for t in tables for i in t.parts}) if i in counts]
    sizes = [counts[i] for i in groups]
    if sum(counts.values()) > sum(sizes):
        groups.append(-1)           # the units of the parts outside every window
        sizes.append(sum(counts.values()) - sum(sizes))
    total = sum(sizes)
    k = min(visible, total)
    if most is not None and k and comb(len(groups) + k - 1, k) > most:     # k = 0: every unit left buffered
        return float("inf")
    maps = _maps(tables)
    pairs = sorted((_best_over(tables, maps, [groups[g] for g in look]), ways / comb(total, k))
                   for look, ways in _looks(sizes, k))
    return shake_loop(pairs, costs.look, costs.shake)


def _maps(tables) -> list[dict[int, int]]:
    """Per window, plan index -> its group (the others, ``len(parts)``, are the missing ones).  O(parts)."""
    return [{i: j for j, i in enumerate(t.parts)} for t in tables]


def _best_over(tables, maps, look) -> float:
    """The least over the windows of their best move on ``look`` (plan indices; a part outside a window is
    one of its others) with their rests; inf where none has a move.  O(windows × visible)."""
    best = float("inf")
    for t, index in zip(tables, maps):
        chosen = t.actions.get(tuple(sorted(index.get(i, len(t.parts)) for i in look)))
        if chosen is not None:
            best = min(best, chosen[3] + t.rest)
    return best


def _looks(sizes: list[int], k: int, start: int = 0):
    """Every multiset of ``k`` units over groups of ``sizes`` units (from group ``start``), as a list of group
    indices with repeats, with its number of ways to be drawn.  O(looks)."""
    if k == 0:
        yield [], 1
        return
    for g in range(start, len(sizes)):
        for c in range(1, min(k, sizes[g]) + 1):
            for rest, ways in _looks(sizes, k - c, g + 1):
                yield [g] * c + rest, comb(sizes[g], c) * ways
