"""The frontier window: near the optimum where the optimum's programme does not fit.

At each state the *window* is the frontier of an open strategy: the buffered parts and the next remaining
parts in its topological order (fewest remaining ancestors there first, then declaration order), each with
its remaining ancestors (in every open strategy where they fit the window, else in that one), up to
:data:`WINDOW_PARTS` parts and 64 units.  The window is closed in that strategy, and its programme keeps
the open strategies it is closed in (:func:`window_strategies`): in another, a window part waits for a
part outside it, which the model installs only after the window.
The plan's other remaining
units are lumped into one count, the *others*: in the bin they dilute the looks as they do on the real
plan (a look is ``visible`` units drawn from the window's bin units and the others).  An other whose
remaining ancestors are all window parts is *ready* once they are installed: seen then, it is installed (the
others' mean move) and credited with what it would cost after the window, a move and
:data:`~opportune.engine.tuning.WINDOW_READY_LOOKS` shakes and looks, so the window values installing first
what unlocks the parts outside it; the programme counts the ready others installed, not which.  The
others left are seen as nothing until the window is complete, the terminal state (value 0).  (The earlier
window, ``others="buffer"``, installed no other and let one seen be buffered: on a long plan it filled its
locations with parts the plan needs last.  It still decides on plans of several strategies, whose option
values were tuned with it.)  The parts are taken into the window in the order of their
remaining ancestors less their remaining descendants
(:data:`~opportune.engine.tuning.WINDOW_DESCENDANTS`), so a part that unlocks many comes in early with what
it waits for.  The window's exact optimum (the compiled ``WindowCore``,
``src/native/window.cpp``: the optimum's recursion, looks as order statistics, the others one more
group) is solved once per state, within :data:`WINDOW_STATES` states (counted, so the decision is the
same on every machine), and the decision is its best action on the look: a visible part outside the
window seen as an other (buffered, the one first in the topological order).  The programme counts the
parts interchangeable at the state (:func:`twin_groups`: in every strategy it keeps the same remaining
ancestors and descendants, and the same move) as one part's units, as the optimum does on the whole plan:
the same values in fewer states, so larger windows fit.  Nor does the decision pass over a move the
optimum never passes over (:func:`install_first`): with one strategy open, an installation for a shake
or for buffering that very part; with an unlimited buffer, a part seen for a shake (each where the
moves' costs make it so); the window, whose parts outside are lumped, shook so on about 6 of KILBRID's
80 looks a run.  On a plan of several strategies the frontier windows of the first
:data:`~opportune.engine.tuning.WINDOW_STRATEGIES` open ones are solved (larger ones there, :data:`~opportune.engine.tuning.WINDOW_PARTS_SEVERAL`), and on a look the
move of least expected cost over the windows, with its window's others a look and a move each after it,
decides: the look chooses the strategy.  A window of one strategy's frontier values a state as if the
others were closed, so the moves that keep several open (a buffering, an installation several allow, the
shake) are worth the option of choosing later, two looks deep (:func:`two_looks`): each at the value of the
state it leads to where each look there takes its best move over the windows (read from their programmes),
the shake at this state's value from those moves.  (One look deep, :func:`option_value` of this state taken
off every such move, for measurement: a buffering that fills a location was credited with the option of an
empty one.)
The sizes tried there grow while the states of the next, predicted from the growth of the two before, stay
within :data:`~opportune.engine.tuning.WINDOW_GROWTH_SEVERAL` times the cap.  A *joint window*
(``joint=True``, for measurement: nearer the optimum on some two-strategy plans, farther on others) is the
union of the strategies' frontier windows (:func:`joint_window`) solved in all of them at once (a unit
waiting there for a part outside is never installed in that strategy), ending in a strategy once that
strategy's own window is installed, at the cost its largest window adds to its own window of that size.
Where one strategy is open, larger windows (:data:`WINDOW_PARTS_MORE`) are tried after :data:`WINDOW_PARTS`
while predicted to fit.  Where the window does not fit in states (a smaller window is tried) or in its time,
the base rule decides.

Measured against the optimum on 16-30-part plans and per decision on the SALBP plans:
``benchmarks/bench_fallback.py`` (docs/decisions.md).
"""

from __future__ import annotations

from collections import OrderedDict
from math import comb
from dataclasses import dataclass

from opportune.engine import compiled_core
from opportune.engine.deadline import Deadline, as_deadline
from opportune.engine.poset import bits
from opportune.engine.tuning import (  # tuning.py says why
    WINDOW_ANCESTORS, WINDOW_CACHE, WINDOW_DESCENDANTS, WINDOW_GROWTH_SEVERAL, WINDOW_OPTION_LOOKS, WINDOW_PARTS,
    WEIGHTED_OPTION_DRAWS, WINDOW_PARTS_MORE, WINDOW_PARTS_SEVERAL, WINDOW_READY_LOOKS, WINDOW_START_FACTOR,
    WINDOW_STATES, WINDOW_STRATEGIES)
from opportune.policies.base import DONE, SHAKE, Action, DecidesOnMasks, Decision
from opportune.policies.interchangeable import interchangeable_groups
from opportune.policies.optimal import shake_loop
from opportune.planning.costs import TimeModel

__all__ = ["FrontierWindow", "Groups", "TwoLooks", "WindowTable", "best_seen_chances", "frontier_window",
           "in_bin", "install_first", "joint_window", "near_parts", "option_value", "outside_rest",
           "start_factor_applies", "twin_groups", "two_looks", "window_available", "window_strategies"]

_native = compiled_core()


def window_available(engine, weights: dict[str, float] | None = None) -> bool:
    """Whether the window serves this plan and bin: the compiled core is built (not switched off with
    ``OPPORTUNE_PURE_PYTHON=1``), the bin is uniform (its looks are order statistics), and the plan has
    at most 64 strategies.  O(parts).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    weights : dict, optional
        Per-part visibility weights (all equal or None: a uniform bin).

    Returns
    -------
    bool
        True where :class:`FrontierWindow` can decide.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> window_available(OrderEngine(make_plan(["a", "b"], {})), {"a": 2.0})
    False
    """
    uniform = len({float((weights or {}).get(p.id, 1.0)) for p in engine.plan.parts}) <= 1
    return _native is not None and hasattr(_native, "WindowCore") and uniform and engine.k <= 64


@dataclass(frozen=True)
class WindowTable:
    """What a decision at one state needs, whatever its look.  Under 1 kB for a window of 12 parts,
    whatever the plan (the parts outside are a count: a look's are ranked when it comes).

    Parameters
    ----------
    parts : tuple of int
        The window's parts (plan indices, declaration order).
    values : tuple of float
        The expected costs after each move (``WindowCore.moves``): three per part of ``parts`` (install
        it from the bin, buffer it, install it from the buffer; ``inf`` where that is no move), then
        buffering a part from outside the window, then the window's expected cost from the state.
    outside : int
        How many remaining parts are outside the window.
    size : int
        The window's size, as tried (:data:`WINDOW_PARTS`).
    states : int
        The states its programme held.
    rest : float, default 0.0
        What the parts outside cost after the window (a look and a move a unit): windows of different
        strategies' frontiers compare by ``values[-1] + rest``.
    ready_install : float, default inf
        The expected cost after installing a ready other (a part outside the window whose remaining
        ancestors are all installed) seen at the state; ``inf``: the window installs none.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(list("abcdefghij"), {"j": list("abcdefghi")}))
    >>> table = FrontierWindow(visible=2, capacity=1, sizes=(3,), more=()).table(engine, 0, 1, ())
    >>> table.parts, table.outside, len(table.values) == 3 * len(table.parts) + 2
    ((0, 1, 2), 7, True)
    """

    parts: tuple[int, ...]
    values: tuple[float, ...]
    outside: int
    size: int
    states: int
    #: What the parts outside cost after the window, a look and a move a unit: windows of different
    #: strategies' frontiers compare by ``values[-1] + rest``.
    rest: float = 0.0
    ready_install: float = float("inf")

    @property
    def value(self) -> float:
        """The window's expected cost from the state (``values[-1]``)."""
        return self.values[-1]


def _ancestors(engine, mask: int, consistent: int, parts=None) -> tuple[dict[int, int], dict[int, int]]:
    """Remaining part -> the remaining units below its last unit (its own excluded) in the open strategy
    where they are fewest (ties: the first): the parts it waits for on its nearest way in, transitive in
    that strategy; and -> those below it in any open strategy.  Of every part, or of ``parts`` (indices).
    O(parts × strategies)."""
    nearest, every = {}, {}
    posets = [p for s, p in enumerate(engine.posets) if consistent >> s & 1]
    for i in range(len(engine.plan.parts)) if parts is None else parts:
        first, q = engine.first[i], engine.plan.parts[i].quantity
        own = ((1 << q) - 1) << first
        if own & ~mask == 0:
            continue
        below = [poset.below[first + q - 1] & ~mask & ~own for poset in posets]
        nearest[i] = min(below, key=int.bit_count)
        every[i] = 0
        for b in below:
            every[i] |= b
    return nearest, every


#: Key of :func:`_ancestors_of`'s memo in the engine's kept store (``engine.kept``: freed with the engine,
#: where the look-ahead keeps its programmes too).  Cleared whole past
#: :data:`~opportune.engine.tuning.WINDOW_ANCESTORS` entries.
_ANCESTORS = "window.ancestors"


def _ancestors_of(engine, mask: int, consistent: int) -> tuple[dict[int, int], dict[int, int]]:
    """:func:`_ancestors` of every part, kept on the engine (a pure function of the state): a state's windows
    of each size and strategy ask the same, and each is O(parts × strategies).  O(1) when kept."""
    memo = engine.kept.setdefault(_ANCESTORS, {})
    got = memo.get((mask, consistent))
    if got is None:
        if len(memo) > WINDOW_ANCESTORS:
            memo.clear()
        got = memo[(mask, consistent)] = _ancestors(engine, mask, consistent)
    return got


def _closure(i: int, every: dict[int, int], part_of, window: set[int], most: int) -> set[int] | None:
    """Part ``i`` and its remaining ancestors in every open strategy not in ``window`` (an ancestor in one
    strategy brings its own in the others), or None past ``most`` parts.  O(parts added × strategies)."""
    new, todo = set(), [i]
    while todo:
        j = todo.pop()
        if j in new or j in window:
            continue
        new.add(j)
        if len(new) > most:
            return None
        todo.extend(part_of[u] for u in bits(every[j]))
    return new


def near_parts(engine, mask: int, strategy: int, parts, most: int) -> tuple[str, ...]:
    """The parts of ``parts`` that wait in ``strategy`` for at most ``most`` remaining units (their remaining
    ancestors there, transitive), in their order: those a window of that strategy's frontier may take first
    without taking in the chain below them.  O(len(parts)) once the state's ancestors are kept.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask : int
        The installed units.
    strategy : int
        The strategy (index).
    parts : sequence of str
        Part ids.
    most : int
        Remaining units a part may wait for.

    Returns
    -------
    tuple of str
        The parts of ``parts`` within ``most`` units of the strategy's frontier.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"b": ["a"], "c": ["b"]}))
    >>> near_parts(engine, 0, 0, ("a", "b", "c"), 1)
    ('a', 'b')
    """
    below, _ = _ancestors_of(engine, mask, 1 << strategy)
    plan = engine.plan
    return tuple(p for p in parts if below.get(plan.index(p), 0).bit_count() <= most)


def frontier_window(engine, mask: int, consistent: int, buffer, size: int, strategy: int | None = None,
                    descendants: float = WINDOW_DESCENDANTS) -> tuple[list[int], list[int]]:
    """The window of ``size`` parts at a state, the frontier of one open strategy: the buffered parts and the
    remaining parts first in its order (fewest remaining ancestor units there less ``descendants`` times their
    remaining descendant units, so a part that unlocks many comes early with what it waits for; then
    declaration order), each with its remaining ancestors in every open strategy where they fit the window, else there
    (so the window is closed in it), at most 64 units; and the remaining parts outside it, in that order.  The last part taken may bring more than ``size`` parts;
    a buffered part whose ancestors would take the window past it is left out (lumped with the others).
    O(parts × strategies).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies.
    buffer : sequence of str
        The buffered parts.
    size : int
        Parts in the window (buffered ones and ancestors counted; more where a buffered part's closure adds
        them).
    strategy : int, optional
        The open strategy whose frontier it is (default: the first open one).  The window is closed in it,
        and in the other strategies :func:`window_strategies` finds.
    descendants : float
        The weight of a part's remaining descendants in the order (:data:`WINDOW_DESCENDANTS`; 0: the
        remaining ancestors alone).

    Returns
    -------
    (list of int, list of int)
        The window's parts in declaration order, the others in topological order.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["b"], "d": ["c"]}))
    >>> frontier_window(engine, 0, 1, ("c",), 2)
    ([1, 2], [0, 3])
    """
    if strategy is None:
        strategy = core_strategies(engine, consistent)[0]
    # one strategy's order: a closure in all at once (their union, transitive) takes in most of a plan whose
    # strategies order the parts differently, and a window closed in none solves a plan that is not there
    anc, _ = _ancestors_of(engine, mask, 1 << strategy)
    _, every = _ancestors_of(engine, mask, consistent)
    order = sorted(anc, key=lambda i: (anc[i].bit_count() - descendants * _descendants(engine, mask, strategy, i), i))
    buffered = sorted({engine.plan.index(p) for p in buffer}, key=order.index)
    window = _closed_window(engine, mask, buffered + order, buffered, anc, every, size)
    return sorted(window), [i for i in order if i not in window]


def start_factor_applies(mask: int, deadline, units: int = 0) -> bool:
    """Whether a window's programme may hold its start factor's states: before a run's first installation
    (nothing installed: the states every run passes through, its start again after each shake there), or
    until ``units`` units are installed, and without a deadline (within a budget the cap is the usual one).
    O(1).

    Parameters
    ----------
    mask : int
        The installed units.
    deadline : Deadline, float or None
        The decision's deadline (None: none).
    units : int
        The installed units up to which it applies (0: before the first installation only).

    Returns
    -------
    bool
        True where the window's cap is its start factor times the usual one.

    Examples
    --------
    >>> from opportune.engine.deadline import Deadline
    >>> start_factor_applies(0, None), start_factor_applies(0b1, None), start_factor_applies(0, Deadline.after(1.0))
    (True, False, False)
    >>> start_factor_applies(0b111, None, units=3), start_factor_applies(0b1111, None, units=3)
    (True, False)
    """
    return mask.bit_count() <= units and as_deadline(deadline).at == float("inf")


@dataclass(frozen=True)
class Groups:
    """A window's parts as its programme counts them: ``members[n]`` the window parts whose remaining units
    are the programme's part ``n``'s (interchangeable at the state: :func:`twin_groups`).

    Parameters
    ----------
    parts : tuple of int
        The window's parts (plan indices, declaration order).
    members : tuple of tuple of int
        The groups, each in declaration order, the groups by their first part.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"b": ["a"]}))
    >>> groups = Groups((0, 1, 2), ((0, 2), (1,)))
    >>> groups.index
    {0: 0, 2: 0, 1: 1}
    >>> groups.expand([1, 2, 3, 4, 5, 6, 7, 8], engine, 0, ("c",))      # c buffered: not in the bin
    (1, 2, inf, 4, 5, inf, inf, inf, 3, 7, 8)
    """

    parts: tuple[int, ...]
    members: tuple[tuple[int, ...], ...]

    @classmethod
    def alone(cls, parts) -> Groups:
        """Every part its own group."""
        return cls(tuple(parts), tuple((i,) for i in parts))

    @property
    def index(self) -> dict[int, int]:
        """Each part's group.  O(parts)."""
        return {i: n for n, members in enumerate(self.members) for i in members}

    def units(self, engine, mask: int) -> tuple[dict[int, int], list[int]]:
        """The window's remaining units as programme bits (group by group, each member's in order) and
        each group's first bit.  O(units)."""
        unit_bit, first = {}, []
        for members in self.members:
            first.append(len(unit_bit))
            for i in members:
                for u in range(engine.first[i], engine.first[i] + engine.plan.parts[i].quantity):
                    if not mask >> u & 1:
                        unit_bit[u] = len(unit_bit)
        return unit_bit, first

    def buffered(self, engine, buffer) -> tuple[list[int], int]:
        """The buffered units of each group, and those of parts outside the window.  O(buffer)."""
        index, out, others = self.index, [0] * len(self.members), 0
        for p in buffer:
            n = index.get(engine.plan.index(p))
            if n is None:
                others += 1
            else:
                out[n] += 1
        return out, others

    def expand(self, values, engine, mask: int, buffer) -> tuple[float, ...]:
        """The programme's move values (three per group, then the other's buffering and the state's value)
        as :attr:`WindowTable.values` at the state of installed units ``mask`` and ``buffer``, three per
        part: its group's, ``inf`` for a move the part has no unit for (none in the bin: neither installed
        from it nor buffered; none buffered: not installed from the buffer), as where each is its own.
        O(parts + buffer)."""
        index, held = self.index, {}
        for p in buffer:
            held[engine.plan.index(p)] = held.get(engine.plan.index(p), 0) + 1
        inf, out = float("inf"), []
        for i in self.parts:
            n, bin_ = index[i], _left(engine, mask, i) > held.get(i, 0)
            out += [values[3 * n] if bin_ else inf, values[3 * n + 1] if bin_ else inf,
                    values[3 * n + 2] if held.get(i) else inf]
        return tuple(out) + tuple(values[-2:])


def twin_groups(engine, mask: int, consistent: int, parts, costs: TimeModel) -> Groups:
    """A window's parts grouped by interchangeability at a state: in every strategy of ``consistent`` the
    same remaining ancestors and the same remaining descendants (so neither is before the other), and the
    same move.  Swapping two of a group maps the window's programme (its orders, its ready others, its
    costs, the chances of a look) onto itself, so its values depend only on how many of a group's units
    are installed and buffered: the programme counts them as one part's, in fewer states.  As
    :mod:`~opportune.policies.interchangeable` does for the whole plan, here at the state: parts told apart
    only by installed ones are merged too (:func:`~opportune.policies.interchangeable.interchangeable_groups`
    at the state).  O(parts × strategies).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the strategies the window's programme keeps.
    parts : sequence of int
        The window's parts (declaration order).
    costs : TimeModel
        The moves' costs.

    Returns
    -------
    Groups
        The groups.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["b", "c"]}))
    >>> twin_groups(engine, 0, 1, [0, 1, 2], TimeModel()).members          # b is a root, a is not c's twin
    ((0,), (1,), (2,))
    >>> twin_groups(engine, 0b0001, 1, [1, 2], TimeModel()).members        # a installed: b and c alike
    ((1, 2),)
    """
    groups = interchangeable_groups(engine, costs, mask=mask, parts=parts,
                                    strategies=core_strategies(engine, consistent))
    return Groups(tuple(parts), tuple(tuple(g) for g in groups))


def _descendants(engine, mask: int, strategy: int, i: int) -> int:
    """Part ``i``'s remaining descendant units in ``strategy`` (its own units left out).  O(1)."""
    own = ((1 << engine.plan.parts[i].quantity) - 1) << engine.first[i]
    return (engine.posets[strategy].above[engine.first[i]] & ~mask & ~own).bit_count()


def _closed_window(engine, mask: int, order: list[int], buffered: list[int], anc: dict[int, int],
                   every: dict[int, int], size: int) -> set[int]:
    """The parts of ``order`` taken in turn, each with its remaining ancestors in ``every`` (every open
    strategy) where they fit ``size`` parts, else in ``anc`` (one strategy: the window is closed there),
    until ``size`` parts (the last may bring more) or 64 units; a buffered part whose ancestors would take
    it past ``size`` is left out (lumped with the others, an occupied location).  O(parts × strategies)."""
    plan, part_of = engine.plan, engine.unit_part
    window: set[int] = set()
    units = 0
    for i in order:
        if i in window or (len(window) >= size and i not in buffered):
            continue
        # closed in every open strategy where that fits (more strategies kept), else in this one
        new = (_closure(i, every, part_of, window, max(0, size - len(window)))
               or ({i} | {part_of[u] for u in bits(anc[i])}) - window)
        more = sum((((1 << plan.parts[j].quantity) - 1) << engine.first[j] & ~mask).bit_count() for j in new)
        if units + more > 64 or (i in buffered and len(window) + len(new) > size):
            if i in buffered:
                continue        # far from the frontier: lumped with the others, an occupied location
            break
        window |= new
        units += more
    return window


def window_strategies(engine, mask: int, consistent: int, parts) -> int:
    """The open strategies in which the window is closed: every remaining unit below a window part there is
    a window part's.  Only these are the window programme's (in another, a window part waits for a part
    outside, installed only after the window in its model, so the window could not be completed there:
    taking it as installed would credit the window with a strategy its installations close).  O(units ×
    strategies).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies.
    parts : iterable of int
        The window's parts (plan indices).

    Returns
    -------
    int
        The strategies' bits (a subset of ``consistent``).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b"], strategies={"s": {"b": ["a"]}, "t": {}}))
    >>> window_strategies(engine, 0, 0b11, [1]), window_strategies(engine, 0, 0b11, [0, 1])
    (2, 3)
    """
    units = 0
    for i in parts:
        units |= ((1 << engine.plan.parts[i].quantity) - 1) << engine.first[i]
    out = 0
    for s in range(engine.k):
        below = engine.posets[s].below
        if consistent >> s & 1 and all(below[u] & ~mask & ~units == 0 for u in bits(units & ~mask)):
            out |= 1 << s
    return out


class FrontierWindow(DecidesOnMasks):
    """The exact optimum of the frontier window at each state, the rest of the plan lumped (see the module).

    Parameters
    ----------
    base : policy, optional
        What decides where no window fits in :data:`WINDOW_STATES` or in time (default
        :class:`~opportune.policies.variants.Slack`).
    visible, capacity, costs :
        The uniform bin's world (as :class:`~opportune.policies.optimal.OptimalSolver`).
    sizes : tuple of int
        The window sizes tried in turn (:data:`WINDOW_PARTS`).
    several : tuple of int
        The sizes tried where several strategies are open, a size predicted past ``max_states`` skipped
        (:data:`WINDOW_PARTS_SEVERAL`).
    more : tuple of int
        Where one strategy is open, the sizes tried after ``sizes``, each unless predicted past the cap
        (:data:`WINDOW_PARTS_MORE`).
    option : bool
        Whether the look values keeping several strategies open (:func:`option_value`; the default) where
        several windows decide, or takes the least window's best move alone.
    option_looks : {2, 1}
        How deep the option is valued (:data:`~opportune.engine.tuning.WINDOW_OPTION_LOOKS`): 2, each move
        that keeps several strategies open at its own state's option (:func:`two_looks`); 1, the state's
        option taken off every such move (for measurement).
    joint : bool
        Whether the joint window of the open strategies decides where several are open and it fits (see
        the module; False, the default: the strategies' own windows with the option value decide).
    growth : float
        Where several strategies are open, a size is tried while its states, predicted from the growth of
        the two before, are within this many times ``max_states`` (:data:`WINDOW_GROWTH_SEVERAL`).
    max_states : int
        States a window's programme may hold (:data:`WINDOW_STATES`; :attr:`start_factor` times that before a
        run's first installation, without a deadline).
    others : {"ready", "buffer", "ignore"}
        How the window's programme sees the parts outside it: ``"ready"`` (the default), an other whose
        remaining ancestors are all window parts is installed when seen once they are, credited with a move
        and ``ready_looks`` shakes and looks (what it would cost after the window), the rest seen as nothing;
        ``"buffer"``, an other seen may be buffered (a free location), never installed (the earlier window);
        ``"ignore"``, every other seen as nothing (for measurement).
    ready_looks : float
        The ready others' credit beyond their move, in shakes and looks (:data:`WINDOW_READY_LOOKS`).
    descendants : float
        The window takes the parts in the order of their remaining ancestors less this many times their
        remaining descendants (:data:`WINDOW_DESCENDANTS`; 0: ancestors alone, the earlier order).
    merge : bool
        Whether the programme counts the window's interchangeable parts at the state (:func:`twin_groups`)
        as one part's units (the default: the same values in fewer states, so larger windows fit); False
        gives each its own (for measurement).

    Notes
    -----
    The attribute ``work`` counts what it did: windows solved, the states they held, and decisions left
    to the base (no window fitted, or out of time).  The attribute ``deadline``, a
    :class:`~opportune.engine.deadline.Deadline` or None, stops a window's programme; the base decides then.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> FrontierWindow(visible=1, capacity=1).choose_at(engine, 0, 1, (), 1.0, ("c",))
    Action(kind='buffer', part='c', source=None)
    """

    name = "window"
    rule = "the action of least expected cost in the frontier window's exact optimum (the other parts lumped)"
    deterministic = True
    decision_key = None

    def __init__(self, base=None, *, visible: int = 2, capacity: int | None = None, costs: TimeModel | None = None,
                 sizes: tuple[int, ...] = WINDOW_PARTS, max_states: int = WINDOW_STATES, others: str = "ready",
                 several: tuple[int, ...] = WINDOW_PARTS_SEVERAL, more: tuple[int, ...] = WINDOW_PARTS_MORE,
                 option: bool = True, joint: bool = False,
                 growth: float = WINDOW_GROWTH_SEVERAL, option_looks: int = WINDOW_OPTION_LOOKS,
                 ready_looks: float = WINDOW_READY_LOOKS, descendants: float = WINDOW_DESCENDANTS,
                 merge: bool = True):
        from opportune.policies.variants import Slack

        self.base = base if base is not None else Slack()
        self.visible, self.capacity, self.costs = visible, capacity, costs or TimeModel()
        self.sizes, self.max_states, self.more = tuple(sizes), max_states, tuple(more)
        self.several, self.option, self.joint, self.growth = tuple(several), option, joint, growth
        if option_looks not in (1, 2):
            raise ValueError(f"option_looks: 1 or 2 looks deep, not {option_looks!r}")
        self.option_looks = option_looks
        if others not in ("ready", "buffer", "ignore"):
            raise ValueError(f"others: 'ready', 'buffer' or 'ignore', not {others!r}")
        self.others, self.ready_looks, self.descendants = others, float(ready_looks), float(descendants)
        self.merge = merge
        self._plain = False         # set while the earlier window is tried where no window with ready others fits
        self.deadline: Deadline | None = None
        self.work = {"windows": 0, "states": 0, "most_states": 0, "by_base": 0}
        self._tables: OrderedDict = OrderedDict()
        self._engine = None
        self.last_table: WindowTable | None = None

    def table(self, engine, mask: int, consistent: int, buffer) -> WindowTable | None:
        """The window's decision table at a state (cached), or None where no window fits (states, or the
        deadline): of the frontier windows of the open strategies (:meth:`tables`), the one of least expected
        cost with its rest.  At most ``len(sizes) × max_states`` states of work a window.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask, consistent : int
            The installed units and the open strategies.
        buffer : sequence of str
            The buffered parts.

        Returns
        -------
        WindowTable or None
            The largest window's table that fitted, or None where none did.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> window = FrontierWindow(visible=1, capacity=1)
        >>> table = window.table(engine, 0, 1, ())
        >>> table.parts, table.outside, round(table.values[-1], 4), window.work["windows"]
        ((0, 1, 2), 0, 3.6667, 1)
        >>> FrontierWindow(visible=1, capacity=1, max_states=0).table(engine, 0, 1, ()) is None
        True
        """
        tables = self.tables(engine, mask, consistent, buffer)
        return min(tables, key=lambda t: t.values[-1] + t.rest) if tables else None

    def tables(self, engine, mask: int, consistent: int, buffer) -> tuple[WindowTable, ...]:
        """The decision tables of the frontier windows of the first :data:`WINDOW_STRATEGIES` open strategies
        at a state, each of the largest size at which they all fit (cached; none where none fits).

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask, consistent : int
            The installed units and the open strategies.
        buffer : sequence of str
            The buffered parts.

        Returns
        -------
        tuple of WindowTable
            One a distinct window, or empty.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(list("abcdef"), {"f": ["a", "b"]}))
        >>> (t,) = FrontierWindow(visible=2, capacity=1, sizes=(3,), more=()).tables(engine, 0, 1, ())
        >>> t.parts, t.outside, t.rest      # three parts left outside: a look and a move each
        ((0, 1, 2), 3, 3.0)
        """
        return self._kept(engine, mask, consistent, buffer)[0]

    def _kept(self, engine, mask: int, consistent: int, buffer) -> tuple[tuple[WindowTable, ...], TwoLooks | None]:
        """:meth:`tables` at a state with its moves two looks deep (:func:`two_looks`, where several windows
        decide with the option two looks deep; else None), kept together."""
        if self._engine is not engine:
            self._engine, self._tables = engine, OrderedDict()
        key = (mask, consistent, tuple(sorted(buffer)))
        got = self._tables.get(key)
        if got is not None:
            self._tables.move_to_end(key)
            return got
        several = consistent.bit_count() > 1
        programmes: dict[tuple[int, ...], _Programme] = {}
        grown = self._grown(engine, mask, consistent, buffer, programmes)
        if not grown and self._ready(engine) and not as_deadline(self.deadline).expired():
            # no window with the ready others fits (their count is part of the state): the earlier window
            self._plain = True
            try:
                grown = self._grown(engine, mask, consistent, buffer, programmes)
            finally:
                self._plain = False
        tables, deep = (), None
        if grown:
            tables = tuple({t.parts: t for t in grown[-1][1]}.values())
            joint = self._joint(engine, mask, consistent, buffer, grown) if several and self.joint else None
            tables = tables if joint is None else (joint,)
        if len(tables) > 1 and self.option and self.option_looks == 2:
            deep = two_looks(engine, mask, consistent, buffer, tables, [programmes[t.parts] for t in tables],
                             self.visible, self.costs, as_deadline(self.deadline))
        got = (tables, deep)
        if tables:
            self._tables[key] = got
            if len(self._tables) > WINDOW_CACHE:
                self._tables.popitem(last=False)
        return got

    def _grown(self, engine, mask: int, consistent: int, buffer,
               programmes: dict | None = None) -> list[tuple[int, tuple[WindowTable, ...]]]:
        """Each size that fits (the smaller first: past the deadline or the cap, the largest finished ones
        decide) with the tables of the frontier windows of the first :data:`WINDOW_STRATEGIES` open
        strategies, one a strategy in order (a window two share solved once); empty where none fits.
        ``programmes``, a dict: filled with the largest size's programmes by their parts."""
        out, grown = [], []
        several = consistent.bit_count() > 1
        for size in sorted(self.several if several else self.sizes + self.more):
            if (several or size in self.more) and _past_cap(grown, self.growth * self._cap(mask)):
                break           # predicted past the cap by the growth of the last two: not tried
            windows = self._windows(engine, mask, consistent, buffer, size)
            solved: dict[tuple, WindowTable] = {}
            solving: dict[tuple, _Programme] = {}
            try:
                for parts, outside in windows:
                    if tuple(parts) not in solved:
                        solved[tuple(parts)] = self._solve(engine, mask, consistent, buffer, parts, outside, size,
                                                           programmes=solving)
            except (_native.WindowCoreTooLarge, _native.WindowCoreTimeout):
                break
            if programmes is not None:
                programmes.clear()
                programmes.update(solving)
            out.append((size, tuple(solved[tuple(parts)] for parts, _ in windows)))
            grown.append(max(t.states for t in solved.values()))
            if not all(t.outside for t in solved.values()):
                break           # a window holds every part left: a larger one is the same
        return out

    def _joint(self, engine, mask: int, consistent: int, buffer, grown) -> WindowTable | None:
        """The joint window of the open strategies' frontier windows of the largest size that fits after
        them (:func:`joint_window`: smaller ones first, a size predicted past the cap not tried), its end in
        each strategy costing what that strategy's largest window adds to its own window of the joint
        window's size (so a strategy, decided alone, is worth what its largest window says); None where
        none fits."""
        largest = grown[-1][1]
        got, states = None, []
        for size, own in grown:
            if _past_cap(states, self._cap(mask)):
                break
            parts, outside = joint_window(engine, mask, consistent, own)
            if sum(_left(engine, mask, i) for i in parts) > 64:
                break           # the union past the core's 64 units
            costs = [(big.values[-1] + big.rest) - (t.values[-1] + t.rest) for big, t in zip(largest, own)]
            try:
                got = self._solve(engine, mask, consistent, buffer, parts, outside, size,
                                  ([t.parts for t in own], costs))
            except (_native.WindowCoreTooLarge, _native.WindowCoreTimeout):
                break
            states.append(got.states)
            if not got.outside:
                break
        return got

    def _windows(self, engine, mask: int, consistent: int, buffer, size: int) -> list[tuple[list[int], list[int]]]:
        """The frontier windows of ``size`` parts of the first :data:`WINDOW_STRATEGIES` open strategies,
        one a strategy in order.  O(parts × strategies²)."""
        descendants = self.descendants if self._ready(engine) else 0.0
        return [frontier_window(engine, mask, consistent, buffer, size, strategy=s, descendants=descendants)
                for s in core_strategies(engine, consistent)[:WINDOW_STRATEGIES]]

    def _solve(self, engine, mask: int, consistent: int, buffer, parts: list[int], outside: list[int],
               size: int, joint=None, programmes: dict | None = None) -> WindowTable:
        """The window of ``parts`` solved by the compiled core, in the open strategies it is closed in (the
        others' moves are not its own: inf, never chosen), or with ``joint`` (its ends and their costs,
        :meth:`_joint`) in the first :data:`WINDOW_STRATEGIES` open ones: its table.  The work is counted.
        ``programmes``, a dict: its programme put there by its parts (read after a move: :func:`two_looks`)."""
        kept = (_first_bits(consistent, WINDOW_STRATEGIES) if joint
                else window_strategies(engine, mask, consistent, parts))
        groups = (twin_groups(engine, mask, kept, parts, self.costs) if self.merge and joint is None
                  else Groups.alone(parts))
        core, buf, others_buffered = self._core(engine, mask, kept, buffer, groups, outside, joint,
                                                self._ready(engine))
        if programmes is not None:
            programmes[tuple(parts)] = _Programme(core, mask, kept, groups, self._cap(mask))
        seconds = as_deadline(self.deadline).seconds()
        try:
            values = groups.expand(core.moves(0, (1 << kept.bit_count()) - 1, buf, others_buffered,
                                              seconds=seconds, max_states=self._cap(mask)), engine, mask, buffer)
        finally:
            self.work["windows"] += 1
            self.work["states"] += core.states
            self.work["most_states"] = max(self.work["most_states"], core.states)
        rest = outside_rest(engine, mask, outside, self.costs)
        ready = float("inf")
        if self._ready(engine) and not joint:
            ready = core.install_other(0, (1 << kept.bit_count()) - 1, buf, others_buffered, seconds=seconds,
                                       max_states=self._cap(mask))
        return WindowTable(tuple(parts), tuple(values), len(outside), size, core.states, rest, ready)

    def _core(self, engine, mask: int, consistent: int, buffer, groups: Groups, outside: list[int],
              joint=None, ready: bool = False):
        """The compiled window programme for ``groups``' parts (the remaining units of each group one
        part's, the open strategies' orders among them), the window's buffer counts (a group's), and the
        others buffered.  ``joint``: None, or a joint window's ends (each strategy's parts) and their costs
        (:meth:`_joint`).  O(units² × strategies)."""
        plan = engine.plan
        unit_bit, first = groups.units(engine, mask)
        quantity = [end - start for start, end in zip(first, first[1:] + [len(unit_bit)])]
        move = [float(self.costs.move(plan.parts[members[0]].id)) for members in groups.members]
        below, units = [], sum(1 << u for u in unit_bit)
        for s in core_strategies(engine, consistent):
            # the window is closed in these strategies (window_strategies): its units' remaining ancestors
            # are all its own; in a joint window, a unit waiting for one outside it there is below itself
            # (never installed in the window in that strategy)
            below.append([_window_bits(engine.posets[s].below[u] & ~mask, unit_bit)
                          | (engine.posets[s].below[u] & ~mask & ~units != 0) << n for n, u in enumerate(unit_bit)])
        ends = [] if joint is None else [_window_bits(sum(((1 << plan.parts[i].quantity) - 1) << engine.first[i]
                                                          for i in own), unit_bit) for own in joint[0]]
        buf, others_buffered = groups.buffered(engine, buffer)
        other_units = [u for i in outside for u in range(engine.first[i], engine.first[i] + plan.parts[i].quantity)
                       if not mask >> u & 1]
        other_move = (float("inf") if self.others == "ignore" else       # an infinite move: never buffered
                      sum(self.costs.move(plan.parts[engine.unit_part[u]].id) for u in other_units) / len(other_units)
                      if other_units else float(self.costs.motion))
        ready = _ready_others(engine, mask, consistent, units, unit_bit, other_units) if ready and joint is None else []
        core = _native.WindowCore(len(unit_bit), first, quantity, below, move, float(self.costs.look),
                                  float(self.costs.shake), self.visible, -1 if self.capacity is None else self.capacity,
                                  len(other_units), float(other_move), ends, [] if joint is None else list(joint[1]),
                                  ready, float(other_move + self.ready_looks * (self.costs.shake + self.costs.look))
                                  if ready else 0.0)
        return core, buf, others_buffered

    #: Before a run's first installation, without a deadline, a window's programme may hold this many times
    #: ``max_states`` (:data:`~opportune.engine.tuning.WINDOW_START_FACTOR`; :meth:`_cap`).
    start_factor: int = WINDOW_START_FACTOR

    def _cap(self, mask: int) -> int:
        """The states a window's programme may hold at a state of installed units ``mask``: ``max_states``,
        times :attr:`start_factor` where :func:`start_factor_applies`.  O(1)."""
        return self.max_states * (self.start_factor if start_factor_applies(mask, self.deadline) else 1)

    def _ready(self, engine) -> bool:
        """Whether the ready others and the order by descendants serve: with ``others="ready"`` on a plan of
        one strategy.  On a plan of several the earlier window decides (the others buffered as one, the
        order of remaining ancestors): its option values were tuned with it, and on the policy lab's
        16-part two-strategy plans the ready others gave +0.87% over the optimum against +0.08% (r2-16x2, 1
        visible, 2 locations, where several strategies were open) and +0.27% against +0.01% (r5-16x2, 2
        visible, 1 location, where one was left).  Nor where no window with them fits (with an
        unlimited buffer, the others buffered and the ready ones installed both counted in the state)."""
        return self.others == "ready" and engine.k == 1 and not self._plain

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        """The action at a state, on its machine form: the window's best (:func:`best_in_window`), or the
        base's where no window fits.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask, consistent : int
            The installed units and the open strategies.
        buffer : tuple of str
            The buffered parts.
        free : float
            Free buffer locations (``inf``: unlimited), as the base rule reads them.
        visible : tuple of str
            The look.

        Returns
        -------
        Action
            The action (``DONE`` once every unit is installed).

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> FrontierWindow(visible=1, capacity=1).choose_at(engine, 0, 1, (), 1.0, ("a",))
        Action(kind='install', part='a', source='bin')
        """
        if mask == engine.full:
            return DONE
        tables, deep = self._kept(engine, mask, consistent, buffer)
        if not tables:
            self.last_table = None
            self.work["by_base"] += 1
            return self.base.choose_at(engine, mask, consistent, buffer, free, visible)
        # each strategy's window's best move on this look, with its rest: the least decides (the look
        # chooses the strategy, as on the real plan, where its installations close the others)
        best = min(((value + t.rest, n), action, t) for n, t in enumerate(tables)
                   for value, action in [best_move(engine, mask, consistent, t, buffer, visible, self.costs.shake)])
        self.last_table = best[2]
        if deep is not None:
            action = deep.choose(engine, buffer, visible, float(self.costs.shake))
        elif len(tables) > 1 and self.option:
            action = self._with_option(engine, mask, consistent, buffer, visible, tables)
        else:
            action = best[1]
        return install_first(engine, mask, consistent, best[2], buffer, visible, action, self.costs,
                             self.capacity is None)

    def _with_option(self, engine, mask: int, consistent: int, buffer, visible, tables) -> Action:
        """Where several strategies' windows decide: each move's least value over the windows, with the
        value of keeping several strategies open (:func:`option_value`) taken off the moves that keep them
        (a buffering, an installation several allow, the shake): a window of one strategy's frontier values
        a state as if the others were closed.  Ties as :func:`best_move`'s, then the windows' order."""
        option = option_value(engine, mask, consistent, buffer, tables, self.visible, self.costs)
        plan, shake = engine.plan, float(self.costs.shake)
        least = min(t.values[-1] + t.rest for t in tables)
        ranked = []
        for n, t in enumerate(tables):
            for value, order, action in moves_on_look(engine, mask, consistent, t, buffer, visible):
                keeps = consistent
                if action.kind == "install":
                    keeps = engine.consistent_after(mask, consistent, engine.next_unit(mask, plan.index(action.part)))
                ranked.append((value + t.rest - option * (keeps.bit_count() > 1), order, n, action))
        if not ranked:
            return SHAKE
        best = min(ranked, key=lambda r: r[:3])
        return SHAKE if best[0] > shake + least - option + 1e-12 else best[3]

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

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.sequencer import Sequencer
        >>> plan = make_plan(["a", "b", "c"], {"c": ["a", "b"]})
        >>> d = FrontierWindow(visible=1, capacity=1).decide(Sequencer(plan, buffer_capacity=1).state, ("c",))
        >>> d.action, d.note
        (Action(kind='buffer', part='c', source=None), 'a window of 3 parts, 9 states; expected cost of the window 3.6667')
        >>> tiny = FrontierWindow(visible=1, capacity=1, max_states=0)     # no window fits: the base decides
        >>> tiny.decide(Sequencer(plan, buffer_capacity=1).state, ("c",)).rule
        'as the base rule (slack), because no frontier window fitted its state cap (0) or its time: ...'
        """
        return window_decision(self, state, visible, because,
                               lambda table: f"expected cost of the window {table.values[-1]:.4f}")


def window_decision(window, state, visible: tuple[str, ...], because: str, describe) -> Decision:
    """A window policy's decision with its reasons (the uniform, pile and weighted windows share it): its
    action at the state, said as the window's, or the base's where no window fitted; ``describe`` says what
    the window's table tells (after its parts and states, in the note)."""
    sched = state.schedule
    if sched.mask == sched.engine.full:
        return Decision(DONE, "the assembly is complete")
    action = window.choose_at(sched.engine, sched.mask, sched.consistent, state.buffer, state.buffer_free, visible)
    table = window.last_table
    if table is None:
        base = window.base.decide(state, visible)
        return Decision(base.action, f"as the base rule ({window.base.name}), because {because + ' and ' * bool(because)}"
                        f"no frontier window fitted its state cap ({window.max_states:,}) or its time: {base.rule}",
                        note=base.note)
    rule = f"by its frontier window, because {because}: {window.rule}" if because else window.rule
    return Decision(action, rule, note=f"a window of {len(table.parts)} parts, {table.states:,} states; "
                    + describe(table))


def _ready_now(engine, mask: int, consistent: int, i: int) -> bool:
    """Whether part ``i``'s next unit has no remaining ancestor in any open strategy (outside a window: a
    ready other now).  O(strategies)."""
    u = engine.next_unit(mask, i)
    return all(engine.posets[s].below[u] & ~mask == 0 for s in core_strategies(engine, consistent))


def _ready_others(engine, mask: int, consistent: int, units: int, unit_bit: dict[int, int], other_units) -> list[int]:
    """The others that become installable within the window: each one's remaining ancestors in the open
    strategies ``consistent`` as window bits, where they are all window units (``units``; one waiting for
    another other is left out: the window does not know when that one is installed).  O(others ×
    strategies)."""
    out = []
    for u in other_units:
        need = 0
        for s in core_strategies(engine, consistent):
            need |= engine.posets[s].below[u] & ~mask
        if need & ~units == 0:
            out.append(_window_bits(need, unit_bit))
    return out


def _window_bits(units: int, unit_bit: dict[int, int]) -> int:
    """The plan's ``units`` in the window as window bits (the others left out).  O(popcount)."""
    out = 0
    for u in bits(units):
        if u in unit_bit:
            out |= 1 << unit_bit[u]
    return out


def _left(engine, mask: int, i: int) -> int:
    """Part ``i``'s units not installed.  O(1)."""
    return (((1 << engine.plan.parts[i].quantity) - 1) << engine.first[i] & ~mask).bit_count()


def _first_bits(bits_: int, most: int) -> int:
    """The lowest ``most`` bits of ``bits_``.  O(most)."""
    out = 0
    for _ in range(most):
        if not bits_:
            break
        low = bits_ & -bits_
        out, bits_ = out | low, bits_ & ~low
    return out


def joint_window(engine, mask: int, consistent: int, own) -> tuple[list[int], list[int]]:
    """The joint window of the open strategies' frontier windows at a state: their parts (in declaration
    order), each strategy's window its end there, and the remaining parts outside them.  O(parts ×
    strategies).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies.
    own : sequence of WindowTable
        The first :data:`WINDOW_STRATEGIES` open strategies' frontier windows, one a strategy.

    Returns
    -------
    (list of int, list of int)
        The joint window's parts, and the remaining parts outside it (declaration order).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(list("abcd"), strategies={"s": {"b": ["a"]}, "t": {"a": ["c"]}}))
    >>> own = FrontierWindow(visible=1, capacity=1, several=(2,), joint=False).tables(engine, 0, 0b11, ())
    >>> [t.parts for t in own], joint_window(engine, 0, 0b11, own)
    ([(0, 2), (1, 2)], ([0, 1, 2], [3]))
    """
    parts = sorted({i for t in own for i in t.parts})
    _, every = _ancestors_of(engine, mask, consistent)
    taken = set(parts)
    return parts, [i for i in sorted(every) if i not in taken]


def outside_rest(engine, mask: int, outside, costs: TimeModel) -> float:
    """What the remaining units of the parts ``outside`` a window cost after it, a look and a move a unit:
    windows of different strategies' frontiers compare by their value and this.  O(parts outside).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask : int
        The installed units.
    outside : iterable of int
        The parts outside the window (plan indices).
    costs : TimeModel
        The costs of a look and of each part's move.

    Returns
    -------
    float
        The cost, 0 where no unit is outside.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> from opportune.planning.costs import TimeModel
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> outside_rest(engine, 0b001, [0, 2], TimeModel(look=0.5))    # a is installed: c's unit is left
    1.5
    """
    plan = engine.plan
    return sum((float(costs.look) + costs.move(plan.parts[i].id))
               * (((1 << plan.parts[i].quantity) - 1) << engine.first[i] & ~mask).bit_count() for i in outside)


def _past_cap(states: list[int], cap: float) -> bool:
    """Whether the next size's states, predicted from the growth of the last two sizes' ``states``, pass
    ``cap``.  O(1)."""
    return len(states) > 1 and states[-1] * states[-1] > cap * max(1, states[-2])


def core_strategies(engine, consistent: int) -> list[int]:
    """The open strategies, in order (the window's strategy bits).  O(strategies)."""
    return [s for s in range(engine.k) if consistent >> s & 1]


def install_first(engine, mask: int, consistent: int, table: WindowTable, buffer, visible, action: Action,
                  costs: TimeModel, unlimited: bool = False) -> Action:
    """``action``, unless it passes over a move the exact optimum never passes over.  With one strategy open
    (an installation then closes nothing): a shake while a part seen or buffered can go in now, the
    installation the window values least taken instead (a shake costs what it costs and puts nothing in);
    the buffering of a part seen that can go in, installed instead where its move costs a shake or more
    (buffered, it costs a move more, which can save at most a shake later: a cheap part is worth keeping
    for a look that shows nothing).  With an ``unlimited`` buffer, in any strategies: a shake while a part
    whose move costs a shake or less is seen, the buffering of one the window values least taken instead
    (it costs no more than the shake and leaves a part fewer in the bin).  Either way a part outside the
    window is valued as the window values it (a ready other, an other buffered) or, where it does not,
    taken last; ties as :func:`best_move`'s.  With moves and shakes of one cost the optimum did neither
    on the policy lab's 8-12-part plans (30 runs each of 9 plans of one strategy in 6 settings, some 16,000
    looks with a part that could go in; 9 plans of two strategies with an unlimited buffer, 1-3 visible,
    some 860 looks with a part seen and none that could go in), and applied to its own actions on small
    random plans with costs per part this changes none (the tests).  The window, whose parts outside are
    lumped, shook on about 6 of KILBRID's 80 looks a run where a part that could go in, or could be
    buffered, was seen (1 visible, an unlimited buffer).  O(visible + buffer) and the outside parts'
    ancestors.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies.
    table : WindowTable
        The state's window.
    buffer, visible : tuple of str
        The buffered parts and the look.
    action : Action
        The window's action.
    costs : TimeModel
        What moves and shakes cost.
    unlimited : bool
        Whether the buffer is unlimited.

    Returns
    -------
    Action
        The action.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> table = FrontierWindow(visible=1, capacity=1).table(engine, 0, 1, ())
    >>> costs = TimeModel()
    >>> install_first(engine, 0, 1, table, (), ("a",), SHAKE, costs)
    Action(kind='install', part='a', source='bin')
    >>> [install_first(engine, 0, 1, table, (), ("c",), SHAKE, costs, unlimited) for unlimited in (False, True)]
    [Action(kind='shake', part=None, source=None), Action(kind='buffer', part='c', source=None)]
    """
    plan, one = engine.plan, not consistent & (consistent - 1)

    def goes(i: int) -> bool:
        return engine.consistent_after(mask, consistent, engine.next_unit(mask, i)) != 0

    if one and action.kind == "buffer" and goes(plan.index(action.part)) and costs.move(action.part) >= costs.shake:
        return Action("install", action.part, "bin")
    if action.kind != "shake":
        return action
    cheap = [p for p in visible if costs.move(p) <= costs.shake] if unlimited else []
    valued = sorted(m for m in moves_on_look(engine, mask, consistent, table, buffer, visible)
                    if m[2].kind == "install" and one or m[2].kind == "buffer" and m[2].part in cheap)
    if valued:
        return valued[0][2]
    for source, parts in (("bin", visible), ("buffer", buffer)) if one else ():
        for i in sorted({plan.index(p) for p in parts}):
            if goes(i):
                return Action("install", plan.parts[i].id, source)
    return Action("buffer", plan.parts[min(plan.index(p) for p in cheap)].id) if cheap else action


def best_in_window(engine, mask: int, consistent: int, table: WindowTable, buffer, visible, shake: float) -> Action:
    """The window's best action on a look: :func:`best_move`'s action.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies.
    table : WindowTable
        The state's window.
    buffer, visible : tuple of str
        The buffered parts and the look.
    shake : float
        The shake's cost.

    Returns
    -------
    Action
        The action.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> table = FrontierWindow(visible=1, capacity=1).table(engine, 0, 1, ())
    >>> best_in_window(engine, 0, 1, table, (), ("c",), 1.0), best_in_window(engine, 0, 1, table, (), ("a",), 1.0)
    (Action(kind='buffer', part='c', source=None), Action(kind='install', part='a', source='bin'))
    """
    return best_move(engine, mask, consistent, table, buffer, visible, shake)[1]


def best_move(engine, mask: int, consistent: int, table: WindowTable, buffer, visible,
              shake: float) -> tuple[float, Action]:
    """The window's best action on a look (ties: install, then buffer, then declaration order, the bin
    before the buffer, as the optimum's), or a shake where no move is cheaper than shaking by 1e-12.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies (an installation no open strategy allows is not a move).
    table : WindowTable
        The state's window (:meth:`FrontierWindow.table`).
    buffer, visible : tuple of str
        The buffered parts and the look.
    shake : float
        The shake's cost.

    Returns
    -------
    (float, Action)
        The window's expected cost from the look on, and the action.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> table = FrontierWindow(visible=1, capacity=1).table(engine, 0, 1, ())
    >>> best_move(engine, 0, 1, table, (), ("a",), 1.0)[1]
    Action(kind='install', part='a', source='bin')
    """
    ranked = moves_on_look(engine, mask, consistent, table, buffer, visible)
    values = table.values
    if not ranked:
        return shake + values[-1], SHAKE
    best = min(ranked, key=lambda r: r[:2])
    return (shake + values[-1], SHAKE) if best[0] > shake + values[-1] + 1e-12 else (best[0], best[2])


def moves_on_look(engine, mask: int, consistent: int, table: WindowTable, buffer,
                  visible) -> list[tuple[float, tuple, Action]]:
    """The window's moves on a look (the shake aside), each with its expected cost and its rank among equals
    (install, then buffer, then declaration order, the bin before the buffer, as the optimum's): a visible
    part outside the window is buffered as the window's other, the one first in the topological order.
    O(visible + buffer) and the outside parts' ancestors.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies (an installation no open strategy allows is not a move).
    table : WindowTable
        The state's window.
    buffer, visible : tuple of str
        The buffered parts and the look.

    Returns
    -------
    list of (float, tuple, Action)
        The moves of finite cost, unordered.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> table = FrontierWindow(visible=1, capacity=1).table(engine, 0, 1, ())
    >>> [str(action) for _, _, action in sorted(moves_on_look(engine, 0, 1, table, (), ("a",)))]
    ['install a', 'buffer a']
    """
    plan = engine.plan
    values = table.values
    index = {i: j for j, i in enumerate(table.parts)}
    ranked = []
    seen = {plan.index(p) for p in visible}

    def fits(i: int) -> bool:
        return engine.consistent_after(mask, consistent, engine.next_unit(mask, i)) != 0

    for i in seen:
        j = index.get(i)
        if j is not None:
            if fits(i):
                ranked.append((values[3 * j], (0, i, 0), Action("install", plan.parts[i].id, "bin")))
            ranked.append((values[3 * j + 1], (1, i, 0), Action("buffer", plan.parts[i].id)))
    for i in {plan.index(p) for p in buffer}:
        j = index.get(i)
        if j is not None and fits(i):
            ranked.append((values[3 * j + 2], (0, i, 1), Action("install", plan.parts[i].id, "buffer")))
    outside = [i for i in seen if i not in index]
    if outside:
        # the one nearest the frontier, as the window's order ranks them
        anc, _ = _ancestors(engine, mask, consistent, outside)
        i = min(outside, key=lambda i: (anc[i].bit_count(), i))
        ranked.append((values[-2], (1, i, 0), Action("buffer", plan.parts[i].id)))
        for i in outside:           # one installable now: installed as a ready other
            if table.ready_install < float("inf") and _ready_now(engine, mask, consistent, i) and fits(i):
                ranked.append((table.ready_install, (0, i, 0), Action("install", plan.parts[i].id, "bin")))
    return [r for r in ranked if r[0] != float("inf")]


def option_value(engine, mask: int, consistent: int, buffer, tables, visible: int, costs: TimeModel,
                 weights: list[float] | None = None) -> float:
    """What keeping several strategies open is worth at a state, one look deep: the least of the windows'
    values (each window one strategy's frontier, valued as if the others were closed) less the state's
    value where each look takes its best move over all the windows (the look chooses the strategy; looks as
    order statistics, or drawn by ``weights`` in a weighted bin, the shake loop over them, as the optimum's).
    0 with one window, and in a weighted bin past :data:`~opportune.engine.tuning.WEIGHTED_OPTION_DRAWS`.
    O(parts × windows), and O(parts × weights^visible) in a weighted bin.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies.
    buffer : tuple of str
        The buffered parts.
    tables : sequence of WindowTable
        The state's windows (:meth:`FrontierWindow.tables`).
    visible : int
        Parts per look.
    costs : TimeModel
        The costs of a look and a shake.
    weights : list of float, optional
        Per part (plan index), its weight in a weighted bin (None, or all equal: the uniform bin).

    Returns
    -------
    float
        The value, at least 0.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> from opportune.planning.costs import TimeModel
    >>> engine = OrderEngine(make_plan(list("abcd"), strategies={"s": {"b": ["a"], "c": ["b"]},
    ...                                                           "t": {"b": ["c"], "a": ["b"]}}))
    >>> window = FrontierWindow(visible=1, capacity=1, several=(2,), others="buffer")
    >>> tables = window.tables(engine, 0, 0b11, ())
    >>> len(tables), option_value(engine, 0, 0b11, (), tables[:1], 1, TimeModel())
    (2, 0.0)
    >>> option_value(engine, 0, 0b11, (), tables, 1, TimeModel()) > 0
    True
    """
    value = _looks_over(engine, mask, buffer, tables, visible, costs, weights)
    least = min(t.values[-1] + t.rest for t in tables)
    return max(0.0, least - value) if value < float("inf") else 0.0


def _looks_over(engine, mask: int, buffer, tables, visible: int, costs: TimeModel,
                weights: list[float] | None = None) -> float:
    """The state's value where each look takes its best move over the windows ``tables`` (their values at
    this state), the shake loop over the looks (drawn by ``weights``, where given).  O(parts × windows)."""
    plan, inf = engine.plan, float("inf")
    best = {i: inf for i in in_bin(engine, mask, buffer)}
    from_buffer = inf
    for t in tables:
        index = {i: j for j, i in enumerate(t.parts)}
        v = t.values
        for i in best:
            j = index.get(i)
            best[i] = min(best[i], t.rest + (v[-2] if j is None else min(v[3 * j], v[3 * j + 1])))
        for p in set(buffer):
            j = index.get(plan.index(p))
            if j is not None:
                from_buffer = min(from_buffer, t.rest + v[3 * j + 2])
    return _shake_loop(engine, mask, buffer, best, from_buffer, visible, costs, weights)


def in_bin(engine, mask: int, buffer) -> dict[int, int]:
    """Each part's units in the bin (not installed, not in ``buffer``), of the parts that have some.
    O(parts).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask : int
        The installed units.
    buffer : iterable of str
        The parts out of the bin (buffered, or on a pile's top), a unit each, repeats counted.

    Returns
    -------
    dict of int to int
        Part index -> its units in the bin.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> in_bin(engine, 0b001, ("b",))       # a installed, b buffered
    {2: 1}
    """
    plan = engine.plan
    counts = {i: (((1 << p.quantity) - 1) << engine.first[i] & ~mask).bit_count() for i, p in enumerate(plan.parts)}
    for p in buffer:
        counts[plan.index(p)] -= 1
    return {i: c for i, c in counts.items() if c > 0}


def _shake_loop(engine, mask: int, buffer, best: dict[int, float], from_buffer: float, visible: int,
                costs: TimeModel, weights: list[float] | None = None) -> float:
    """A state's value where a look showing part ``i`` (of those in the bin) takes a move of expected cost
    ``best[i]`` and one from the buffer ``from_buffer`` (inf: none): looks as order statistics of the
    parts' units (drawn by ``weights``, per plan index, where they differ: :func:`best_seen_chances`), the
    shake loop over them, as the optimum's; inf where no look allows a move, or past
    :data:`~opportune.engine.tuning.WEIGHTED_OPTION_DRAWS`.  With every unit left buffered, a look and ``from_buffer``.
    O(parts log parts), and O(parts × weights^visible) in a weighted bin."""
    inf = float("inf")
    counts = in_bin(engine, mask, buffer)
    n = sum(counts.values())
    if n == 0:          # every unit left is buffered: no part is seen, the look taken as the optimum's
        return shake_loop([(from_buffer, 1.0)], costs.look, costs.shake)
    ranked = sorted((best.get(i, inf), i) for i in counts)
    k = min(visible, n)
    if weights is not None and len({weights[i] for i in counts}) > 1:
        chances = best_seen_chances([counts[i] for _, i in ranked], [weights[i] for _, i in ranked], k,
                                    WEIGHTED_OPTION_DRAWS)
        if chances is None:
            return inf
    else:           # the chance that a part is the best one seen: order statistics of the units
        chances, rank, total = [], 0, float(comb(n, k))
        for _, i in ranked:
            chances.append(float(comb(n - rank, k) - comb(n - rank - counts[i], k)) / total)
            rank += counts[i]
    return shake_loop([(min(b, from_buffer), p) for (b, _), p in zip(ranked, chances)], costs.look, costs.shake)


def best_seen_chances(sizes: list[int], weights: list[float], k: int, most: int | None = None) -> list[float] | None:
    """Each group's chance of being the first seen in its order, where ``k`` units are drawn without
    replacement, a unit of group ``g`` (of ``sizes[g]`` units) with chance proportional to ``weights[g]``
    (a weighted bin's look, as the optimum's): the chance that every unit drawn is of group ``g`` or later,
    less that of ``g + 1`` or later.  A draw depends on a unit's weight alone, so the draws are enumerated
    over the distinct weights, not the groups.  O(groups × weights^k).

    Parameters
    ----------
    sizes : list of int
        Units per group, in the order of preference.
    weights : list of float
        Each group's weight (positive).
    k : int
        Units drawn (at most ``sum(sizes)``).
    most : int, optional
        Draws enumerated at most (groups × distinct weights^k): None past it (default: no limit).

    Returns
    -------
    list of float or None
        Per group, the chance that it is the first group seen; None past ``most``.

    Examples
    --------
    >>> best_seen_chances([1, 1], [1.0, 3.0], 1)         # the second seen 3 times in 4
    [0.25, 0.75]
    >>> [round(p, 4) for p in best_seen_chances([1, 1, 1], [1.0, 1.0, 2.0], 2)]    # two of three units seen
    [0.5833, 0.4167, 0.0]
    """
    classes = sorted(set(weights))
    if most is not None and len(sizes) * len(classes) ** k > most:
        return None
    index = {w: c for c, w in enumerate(classes)}
    left = [0] * len(classes)
    for size, w in zip(sizes, weights):
        left[index[w]] += size
    inside = list(left)
    all_in = []         # the chance that every unit drawn is of group g or later
    for size, w in zip(sizes, weights):
        all_in.append(_drawn_within(inside, list(left), classes, k))
        inside[index[w]] -= size
    all_in.append(0.0 if k else 1.0)
    return [a - b for a, b in zip(all_in, all_in[1:])]


def _drawn_within(inside: list[int], left: list[int], classes: list[float], k: int) -> float:
    """The chance that ``k`` units drawn from ``left`` (units per weight class) are all of ``inside`` (units
    per class, within ``left``), a unit drawn with chance proportional to its class's weight.  O(classes^k)."""
    if k == 0:
        return 1.0
    mass = 0.0
    for n, w in zip(left, classes):
        mass += n * w
    got = 0.0
    for c, w in enumerate(classes):
        n = inside[c]
        if n:
            inside[c], left[c] = n - 1, left[c] - 1
            got += n * w / mass * _drawn_within(inside, left, classes, k - 1)
            inside[c], left[c] = n, left[c] + 1
    return got


class _Programme:
    """A window's solved programme, read at the states one move on (:func:`two_looks`): the state it was
    solved at, its parts (as its programme counts them) and the plan's strategies its programme keeps (its
    strategy bits in order)."""

    def __init__(self, core, mask: int, kept: int, groups: Groups, max_states: int):
        self.core, self.mask, self.kept, self.groups, self.max_states = core, mask, kept, groups, max_states

    def moves_at(self, engine, mask: int, consistent: int, buffer, seconds: float) -> tuple[float, ...] | None:
        """The window's move values (as :attr:`WindowTable.values`) at a state its programme holds: more
        units installed, all of them its own, some of its strategies open; None where it holds no such
        state, or it passes the cap or the deadline.  O(window units) and the states it adds."""
        groups = self.groups
        unit_bit, first = groups.units(engine, self.mask)
        index, installed = groups.index, [0] * len(groups.members)
        for u in bits(mask & ~self.mask):
            if u not in unit_bit:
                return None         # an installation outside the window: not in its programme
            installed[index[engine.unit_part[u]]] += 1
        # a group's units are installed lowest bit first, whichever member's the unit was
        units = sum(((1 << c) - 1) << first[n] for n, c in enumerate(installed))
        strategies = sum(1 << n for n, s in enumerate(core_strategies(engine, self.kept)) if consistent >> s & 1)
        if not strategies:
            return None
        buf, others_buffered = groups.buffered(engine, buffer)
        try:
            return groups.expand(self.core.moves(units, strategies, buf, others_buffered, seconds=seconds,
                                                 max_states=self.max_states), engine, mask, buffer)
        except (_native.WindowCoreTooLarge, _native.WindowCoreTimeout):
            return None


@dataclass(frozen=True)
class TwoLooks:
    """A state's moves valued two looks deep (:func:`two_looks`): what a decision there needs, whatever its
    look.

    Parameters
    ----------
    moves : dict
        ``(kind, part index, source)`` -> the expected cost after that move (``("install", i, "bin")``,
        ``("buffer", i, None)``, ``("install", i, "buffer")``), of the moves some window allows.
    value : float
        The state's expected cost where each look takes its best move of ``moves`` (the shake's
        continuation).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(list("abcd"), strategies={"s": {"b": ["a"], "c": ["b"]},
    ...                                                           "t": {"b": ["c"], "a": ["b"]}}))
    >>> deep = FrontierWindow(visible=1, capacity=1, several=(2,))._kept(engine, 0, 0b11, ())[1]
    >>> deep.choose(engine, (), ("d",), 1.0), deep.moves[("install", 3, "bin")] < deep.value + 1.0
    (Action(kind='install', part='d', source='bin'), True)
    """

    moves: dict
    value: float

    def choose(self, engine, buffer, visible, shake: float) -> Action:
        """The move of least expected cost on a look (ties: install, then buffer, then declaration order,
        the bin before the buffer, as the optimum's), or a shake where none is cheaper than shaking by
        1e-12.  O(visible + buffer).

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        buffer, visible : tuple of str
            The buffered parts and the look.
        shake : float
            The shake's cost.

        Returns
        -------
        Action
            The action.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b"], {}))
        >>> looks = TwoLooks({("install", 0, "bin"): 1.0, ("buffer", 0, None): 2.0}, 1.5)
        >>> looks.choose(engine, (), ("a",), 1.0), looks.choose(engine, (), ("b",), 1.0)
        (Action(kind='install', part='a', source='bin'), Action(kind='shake', part=None, source=None))
        """
        plan, ranked = engine.plan, []
        for i in {plan.index(p) for p in visible}:
            for kind, source, order in (("install", "bin", 0), ("buffer", None, 1)):
                if (kind, i, source) in self.moves:
                    ranked.append((self.moves[kind, i, source], (order, i, 0), Action(kind, plan.parts[i].id, source)))
        for i in {plan.index(p) for p in buffer}:
            if ("install", i, "buffer") in self.moves:
                ranked.append((self.moves["install", i, "buffer"], (0, i, 1),
                               Action("install", plan.parts[i].id, "buffer")))
        if not ranked:
            return SHAKE
        best = min(ranked, key=lambda r: r[:2])
        return SHAKE if best[0] > shake + self.value + 1e-12 else best[2]


def two_looks(engine, mask: int, consistent: int, buffer, tables, programmes, visible: int, costs: TimeModel,
              deadline: Deadline | None = None) -> TwoLooks:
    """A state's moves where several strategies' windows decide, two looks deep: a move that closes all but
    one strategy at its window's value (the least over the windows, with the parts outside a look and a
    move each after it); one that keeps several open (a buffering, an installation several allow) at its
    motion and the value of the state it leads to where each look there takes its best move over the
    windows, read from their programmes at that state (the option of choosing later at that state, not at
    this one: a buffering that fills a location keeps less of it).  The state's own value, the shake's
    continuation, takes each look's best of these.  O(moves × (window parts + parts × windows)).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask, consistent : int
        The installed units and the open strategies (several).
    buffer : tuple of str
        The buffered parts.
    tables : sequence of WindowTable
        The state's windows (:meth:`FrontierWindow.tables`).
    programmes : sequence
        Their programmes, in the same order (kept by :class:`FrontierWindow` while it solves them).
    visible : int
        Parts per look.
    costs : TimeModel
        The costs of a motion, a look and a shake.
    deadline : Deadline, optional
        Stops a programme that must add states; a window that cannot answer is left out there.

    Returns
    -------
    TwoLooks
        The moves' values and the state's.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(list("abcd"), strategies={"s": {"b": ["a"], "c": ["b"]},
    ...                                                           "t": {"b": ["c"], "a": ["b"]}}))
    >>> tables, deep = FrontierWindow(visible=1, capacity=1, several=(2,))._kept(engine, 0, 0b11, ())
    >>> len(tables), sorted(deep.moves)[:2]
    (2, [('buffer', 0, None), ('buffer', 1, None)])
    """
    plan, inf = engine.plan, float("inf")
    seconds = as_deadline(deadline).seconds()
    moves: dict[tuple, float] = {}
    after: dict[tuple, float] = {}          # a state one move on -> its value over the windows there
    for t in tables:
        for (kind, i, source), value in _window_moves(engine, mask, consistent, buffer, t):
            mask2, buffer2 = mask, tuple(buffer)
            keeps = consistent
            if kind == "install":
                u = engine.next_unit(mask, i)
                keeps, mask2 = engine.consistent_after(mask, consistent, u), mask | 1 << u
                if source == "buffer":
                    rest = list(buffer)
                    rest.remove(plan.parts[i].id)
                    buffer2 = tuple(rest)
            else:
                buffer2 = (*buffer, plan.parts[i].id)
            if keeps.bit_count() > 1:
                state = (mask2, keeps, tuple(sorted(buffer2)))
                if state not in after:
                    read = [(t2, prog.moves_at(engine, mask2, keeps, buffer2, seconds))
                            for t2, prog in zip(tables, programmes)]
                    there = [WindowTable(t2.parts, v, t2.outside, t2.size, t2.states, t2.rest) for t2, v in read if v]
                    after[state] = _looks_over(engine, mask2, buffer2, there, visible, costs) if there else inf
                value = float(costs.move(plan.parts[i].id)) + after[state] if after[state] < inf else value + t.rest
            elif keeps:
                value += t.rest
            else:
                continue
            moves[kind, i, source] = min(moves.get((kind, i, source), inf), value)
    best = {i: min(moves.get(("install", i, "bin"), inf), moves.get(("buffer", i, None), inf))
            for i in in_bin(engine, mask, buffer)}
    from_buffer = min((v for (kind, _, source), v in moves.items() if source == "buffer"), default=inf)
    return TwoLooks(moves, _shake_loop(engine, mask, buffer, best, from_buffer, visible, costs))


def _window_moves(engine, mask: int, consistent: int, buffer, table: WindowTable):
    """A window's moves at its state, of finite value: ``((kind, part index, source), value)``, for every part
    with a unit in the bin (installed or buffered; one outside the window buffered as an other, or installed
    as a ready other where it can be) and every buffered window part (installed from the buffer).
    O(parts × strategies)."""
    plan, inf = engine.plan, float("inf")
    index = {i: j for j, i in enumerate(table.parts)}
    v = table.values
    out = []
    for i in in_bin(engine, mask, buffer):
        j = index.get(i)
        ready = table.ready_install if j is None and _ready_now(engine, mask, consistent, i) else inf
        out += [(("install", i, "bin"), ready if j is None else v[3 * j]),
                (("buffer", i, None), v[-2] if j is None else v[3 * j + 1])]
    for i in {plan.index(p) for p in buffer}:
        j = index.get(i)
        if j is not None:
            out.append((("install", i, "buffer"), v[3 * j + 2]))
    return [(key, value) for key, value in out if value < inf]
