"""The pile's frontier window: near the optimum in the pile bin where the optimum's programme does not fit.

The uniform bin's frontier window (:mod:`~opportune.policies.window`) carried to the pile bin
(:mod:`~opportune.policies.pile`): at each state the window is the same parts
(:func:`~opportune.policies.window.frontier_window`: the buffered parts and the next remaining parts in a
topological order, closed under their remaining ancestors, up to a size), and the plan's other remaining
units are lumped into one count, the *others*.  The window is made a plan of its own
(:func:`window_plan`: its parts with their remaining units, each open strategy's order among them,
ancestors outside it taken as installed), and the pile's exact optimum is solved on it with the others
one more group of units (:class:`PileWindowSolver`; compiled, :class:`CompiledPileWindowSolver`, the
pile's own core ``src/native/pile.cpp`` with the group added, the same doubles): they lie in the pile
and in its visible top as units of a part do, an other seen may be buffered (a free location, the
others' mean move), and none is installed before the window is complete, the terminal state (what the
others cost after it does not depend on the window's policy).

The decision on a look is the window's best action on the look as the window sees it (a visible part
outside the window is an other; buffered, it is the one first in the topological order); an installation
no open strategy of the plan allows is never chosen.  Every look of a state is decided when the state's
window is solved (:class:`PileWindowTable`): the exact evaluation of the policy asks each look of a state
between the looks of its successors, so a state is solved once.  The window's states are counted
(:data:`~opportune.engine.tuning.PILE_WINDOW_STATES` a size tried: the same decision on every machine);
where no window fits, or past the deadline, the base rule decides.

Measured against the pile's optimum on 16-20-part plans (``benchmarks/policy_lab.py --bins pile
--policies fallback``) and per decision on KILBRID (``benchmarks/bench_fallback.py``).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from dataclasses import replace as _replace

from opportune.engine import OrderEngine, compiled_core, tuning
from opportune.engine.deadline import Deadline, as_deadline
from opportune.planning.costs import TimeModel
from opportune.planning.plan import Plan, Strategy
from opportune.policies.base import DONE, SHAKE, Action, DecidesOnMasks, Decision
from opportune.policies.evaluate import OutOfTime
from opportune.policies.optimal import OptimalTooLarge
from opportune.policies.pile import CompiledPileSolver, PileSolver, compiled_pile_available
from opportune.policies.window import frontier_window

__all__ = ["CompiledPileWindowSolver", "PileWindow", "PileWindowSolver", "PileWindowTable", "pile_window_available",
           "pile_window_solver", "window_plan"]

_native = compiled_core()   # None: the Python programme only

#: The id the others' group takes in a window's moves (no plan part has it: part ids are printable).
OTHERS = "\x00others"


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
    >>> pile_window_available(OrderEngine(make_plan(["a"], {}))) in (True, False)
    True
    """
    return _native is not None and hasattr(_native, "PileCore") and engine.k <= 64


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


class PileWindowSolver(PileSolver):
    """The pile's optimum on a window's plan with ``others`` more units lumped as one more group (see the
    module): a part after the plan's parts in the states (the last buffer count) and in the looks, buffered
    at ``other_move`` (infinite: never), never installed.  With no others it is :class:`PileSolver`.
    The optimum only (no policy).  Complexity: as PileSolver's, on the window's plan.
    """

    def __init__(self, engine, *, others: int = 0, other_move: float = float("inf"), **settings):
        super().__init__(engine, **settings)
        self.others, self.other_move = int(others), float(other_move)
        if self.others:
            self.quantity = [*self.quantity, self.others]
            self.move = [*self.move, self.other_move]
            self.weights = [*self.weights, 1.0]
            self.ids = (*self.ids, OTHERS)

    def _part_index(self, part: str) -> int:
        return len(self.plan.parts) if part == OTHERS else self.plan.index(part)

    def _others_args(self) -> tuple:
        return (self.others, self.other_move)

    def _installed_counts(self, mask: int) -> list[int]:
        return super()._installed_counts(mask) + [0] * (self.others > 0)

    def _buffer_installs(self, mask: int, cons: int, buf: tuple[int, ...]):
        """The plan's parts' installations from the buffer (the others are never installed).  O(parts)."""
        n = len(self.plan.parts)
        for i, (m, c, nb) in super()._buffer_installs(mask, cons, buf[:n]):
            yield i, (m, c, nb + buf[n:])

    def _moves(self, key: tuple, look: tuple[int, ...]):
        """The plan's parts' moves, then buffering an other seen (a free location; ``other_move``)."""
        n = len(self.plan.parts)
        yield from super()._moves(key, tuple(i for i in look if i != n))
        mask, cons, buf = key
        if n in look and self.other_move < float("inf") and (self.capacity is None or sum(buf) < self.capacity):
            nb = list(buf)
            nb[n] += 1
            yield self.other_move, (mask, cons, tuple(nb)), Action("buffer", OTHERS)


class CompiledPileWindowSolver(CompiledPileSolver, PileWindowSolver):
    """:class:`PileWindowSolver` computed by the pile's compiled core (the others its last group): the same
    doubles.  A ``ValueError`` where the core does not take the window's plan."""

    def _core_args(self) -> tuple:
        args = list(super()._core_args())
        n = len(self.plan.parts)
        args[2], args[4] = args[2][:n], args[4][:n]     # the plan's parts' quantities and moves: the others apart
        return tuple(args)


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
    >>> solver = pile_window_solver(OrderEngine(make_plan(["a"], {})), visible=1, others=1, other_move=1.0)
    >>> round(solver.value(), 4)
    2.5
    """
    if compiled_pile_available(engine):
        try:
            return CompiledPileWindowSolver(engine, **settings)
        except ValueError:          # codes over 64 bits: the Python programme
            pass
    return PileWindowSolver(engine, **settings)


@dataclass(frozen=True)
class PileWindowTable:
    """A state's window solved: its parts (plan indices), the others' units, the window's best action on
    each look it can see (by the window's parts' indices, the others last; None: shake), the window's value
    after a shake, its size and the states its programme held."""

    parts: tuple[int, ...]
    outside: tuple[int, ...]
    actions: dict
    value: float
    size: int
    states: int


class PileWindow(DecidesOnMasks):
    """The exact optimum of the frontier window in the pile bin at each state, the rest of the plan lumped
    (see the module).

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

    Notes
    -----
    The attribute ``work`` counts what it did: windows solved, the states they held, and decisions left
    to the base.  The attribute ``deadline``, a :class:`~opportune.engine.deadline.Deadline` or None,
    stops a window's programme; the base decides then.

    Examples
    --------
    >>> from opportune import make_plan
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> PileWindow(visible=1, capacity=1).choose_at(engine, 0, 1, (), 1.0, ("c",))
    Action(kind='buffer', part='c', source=None)
    """

    name = "pile window"
    rule = "the action of least expected cost in the frontier window's exact optimum in the pile (the other parts lumped)"
    deterministic = True
    decision_key = None

    def __init__(self, base=None, *, visible: int = 2, capacity: int | None = None, costs: TimeModel | None = None,
                 sizes: tuple[int, ...] = tuning.PILE_WINDOW_PARTS, max_states: int = tuning.PILE_WINDOW_STATES):
        from opportune.policies.variants import Slack

        self.base = base if base is not None else Slack()
        self.visible, self.capacity, self.costs = visible, capacity, costs or TimeModel()
        self.sizes, self.max_states = tuple(sorted(sizes)), max_states
        self.deadline: Deadline | None = None
        self.work = {"windows": 0, "states": 0, "most_states": 0, "by_base": 0}
        self._tables: OrderedDict = OrderedDict()
        self._engine = None
        self.last_table: PileWindowTable | None = None

    def table(self, engine, mask: int, consistent: int, buffer) -> PileWindowTable | None:
        """The state's window solved (cached), or None where no window fits (states, or the deadline).
        At most ``len(sizes) × max_states`` values of work.

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
        PileWindowTable or None
            The largest window's table that fitted, or None where none did.
        """
        if self._engine is not engine:
            self._engine, self._tables = engine, OrderedDict()
        key = (mask, consistent, tuple(sorted(buffer)))
        got = self._tables.get(key)
        if got is not None:
            self._tables.move_to_end(key)
            return got
        for size in self.sizes:
            # the smaller windows first: past the deadline or the cap, the largest finished one decides
            try:
                got = self._solve(engine, mask, consistent, buffer, size)
            except (OptimalTooLarge, OutOfTime):
                break
            if not got.outside:
                break           # the window holds every part left: a larger one is the same
        if got is not None:
            self._tables[key] = got
            if len(self._tables) > tuning.PILE_WINDOW_CACHE:
                self._tables.popitem(last=False)
        return got

    def _solve(self, engine, mask: int, consistent: int, buffer, size: int) -> PileWindowTable:
        """The window of ``size`` parts solved, every look of the state decided.  The work is counted."""
        parts, outside = frontier_window(engine, mask, consistent, buffer, size)
        solver, key = self._solver(engine, mask, consistent, buffer, parts, outside)
        solver.deadline = as_deadline(self.deadline)
        try:
            value, actions = solver._deep(lambda k: self._actions(engine, mask, consistent, parts, solver, k), key)
        finally:
            self.work["windows"] += 1
            self.work["states"] += solver.states
            self.work["most_states"] = max(self.work["most_states"], solver.states)
        return PileWindowTable(tuple(parts), tuple(outside), actions, value, size, solver.states)

    def _solver(self, engine, mask: int, consistent: int, buffer, parts: list[int], outside: list[int]):
        """The window's programme (nothing computed yet) and the state's key in it."""
        plan = engine.plan
        index = {i: j for j, i in enumerate(parts)}
        buf, others_buffered = [0] * len(parts), 0
        for p in buffer:
            j = index.get(plan.index(p))
            if j is None:
                others_buffered += 1
            else:
                buf[j] += 1
        moves = [self.costs.move(plan.parts[i].id) for i in outside
                 for u in range(engine.first[i], engine.first[i] + plan.parts[i].quantity) if not mask >> u & 1]
        sub = OrderEngine(window_plan(engine, mask, consistent, parts), memory_limit=None)
        solver = pile_window_solver(sub, visible=self.visible, capacity=self.capacity, costs=self.costs,
                                    max_states=self.max_states, others=len(moves),
                                    other_move=sum(moves) / len(moves) if moves else float("inf"))
        return solver, (0, sub.all_strategies, tuple(buf) + ((others_buffered,) if moves else ()))

    def _actions(self, engine, mask: int, consistent: int, parts: list[int], solver, key: tuple):
        """The value after a shake, and the window's best action on every look of the state (ties: install,
        then buffer, then declaration order, the others last, the bin before the buffer, as the optimum's);
        an installation no open strategy of the plan allows is not a move.  O(looks × moves)."""
        after_shake = solver._after_shake(key)
        shake = solver.costs.shake + after_shake
        legal = {j for j, i in enumerate(parts)
                 if engine.consistent_after(mask, consistent, engine.next_unit(mask, i)) != 0}
        n, kinds, actions = len(parts), {"install": 0, "buffer": 1}, {}
        for look, _ in solver._looks(solver._bin_counts(key)):
            best = None
            for cost, nxt, action in solver._moves(key, look):
                j = solver._part_index(action.part)
                if action.kind == "install" and j not in legal:
                    continue
                rank = (cost + solver._after(key, look, action, nxt), kinds[action.kind],
                        parts[j] if j < n else len(engine.plan.parts), action.source == "buffer")
                if best is None or rank < best[0]:
                    best = (rank, (action.kind, j, action.source))
            actions[look] = None if best is None or best[0][0] > shake + 1e-12 else best[1]
        return after_shake, actions

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        if mask == engine.full:
            return DONE
        table = self.table(engine, mask, consistent, buffer)
        self.last_table = table
        if table is None:
            self.work["by_base"] += 1
            return self.base.choose_at(engine, mask, consistent, buffer, free, visible)
        plan = engine.plan
        index = {i: j for j, i in enumerate(table.parts)}
        n = len(table.parts)
        seen = [index.get(plan.index(p), n) for p in visible]
        chosen = table.actions.get(tuple(sorted(seen)))
        if chosen is None:
            return SHAKE
        kind, j, source = chosen
        if j < n:
            return Action(kind, plan.parts[table.parts[j]].id, source)
        # an other: the one seen first in the window's topological order
        ids = set(visible)
        return Action("buffer", next(plan.parts[i].id for i in table.outside if plan.parts[i].id in ids))

    def decide(self, state, visible: tuple[str, ...], because: str = "") -> Decision:
        """The decision with its reasons; ``because``: why the window decides (a caller's words, first).

        Parameters
        ----------
        state : State
            The sequencer's state.
        visible : tuple of str
            The look (the pile's visible top).
        because : str
            Why the window decides, said first in the rule (empty: nothing said).

        Returns
        -------
        Decision
            The window's decision, or the base's (saying that no window fitted).
        """
        sched = state.schedule
        if sched.mask == sched.engine.full:
            return Decision(DONE, "the assembly is complete")
        action = self.choose_at(sched.engine, sched.mask, sched.consistent, state.buffer, state.buffer_free, visible)
        table = self.last_table
        if table is None:
            base = self.base.decide(state, visible)
            return Decision(base.action, f"as the base rule ({self.base.name}), because {because + ' and ' * bool(because)}"
                            f"no frontier window fitted its state cap ({self.max_states:,}) or its time: {base.rule}",
                            note=base.note)
        rule = f"by its frontier window, because {because}: {self.rule}" if because else self.rule
        return Decision(action, rule, note=f"a window of {len(table.parts)} parts, {table.states:,} states; "
                        f"expected cost of the window after a shake {table.value:.4f}")
