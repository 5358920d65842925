"""The weighted bin's frontier window: near the optimum in a weighted bin where the optimum's programme does
not fit.

The uniform bin's frontier window (:mod:`~opportune.policies.window`) carried to the weighted bin, whose
looks are not order statistics: at each state the window is the same parts
(:func:`~opportune.policies.window.frontier_window`), made a plan of its own
(:func:`~opportune.policies.lumped.window_plan`), and the weighted bin's exact optimum
(:class:`~opportune.policies.optimal.OptimalSolver`; compiled, the weighted ``OptimalCore`` of
``src/native/optimal.cpp`` with the others' group added, the same doubles) is solved on it with the plan's
other remaining units one more group (:class:`~opportune.policies.lumped.OthersGroup`) of their mean weight
(their share of the bin's weight, so of the looks, is the plan's) and their mean move.  From it come the
expected costs after each move of the state (:class:`~opportune.policies.window.WindowTable`), and the
decision on a look is the uniform window's rule over them
(:func:`~opportune.policies.window.best_move`: the best of :func:`~opportune.policies.window.moves_on_look`, or a shake).  Its states are counted
(:data:`~opportune.engine.tuning.WEIGHTED_WINDOW_STATES` a size tried); where no window fits, or past the
deadline, the base rule decides.  Where several strategies are open, a window of each one's frontier
decides the look by the least of their moves (:class:`~opportune.policies.lumped.LumpedWindow`), less the
value of keeping several open on the moves that keep them (:meth:`WeightedWindow._option_at`: the uniform
bin's :func:`~opportune.policies.window.option_value` with the state's looks drawn by the weights, as the
weighted bin draws them; drawn evenly it made the window worse), and with two buffer locations or more, or
two parts a look or more, each strategy's window takes first only the parts of the look near its frontier
(the pile's rule, :meth:`~opportune.policies.lumped.LumpedWindow._forced_in`).  Measured in docs/decisions.md.
"""

from __future__ import annotations

from math import comb

from opportune.engine import compiled_core, tuning
from opportune.engine.deadline import as_deadline
from opportune.planning.costs import TimeModel
from opportune.policies.base import Action
from opportune.policies.lumped import CompiledOthers, LumpedWindow, OthersGroup
from opportune.policies.optimal import (
    COMPILED_LOOK_CACHE_BYTES,
    COMPILED_WEIGHTED_VISIBLE,
    CompiledOptimalSolver,
    OptimalSolver,
    compiled_optimal_available,
)
from opportune.policies.window import WindowTable, moves_on_look, option_value, outside_rest

__all__ = ["CompiledWeightedWindowSolver", "WeightedWindow", "WeightedWindowSolver", "weighted_window_available",
           "weighted_window_solver"]

_native = compiled_core()   # None: the Python programme only


def weighted_window_available(engine, visible: int) -> bool:
    """Whether the weighted window serves this plan: the compiled core is built (not switched off with
    ``OPPORTUNE_PURE_PYTHON=1``; the Python programme is its reference, too slow to decide within a budget),
    at most :data:`~opportune.policies.optimal.COMPILED_WEIGHTED_VISIBLE` visible, and at most 64 strategies.
    O(1).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    visible : int
        Parts visible per look.

    Returns
    -------
    bool
        True where :class:`WeightedWindow` decides by the compiled programme.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> weighted_window_available(OrderEngine(make_plan(["a"], {})), 11)
    False
    """
    return (_native is not None and hasattr(_native, "OptimalCore") and visible <= COMPILED_WEIGHTED_VISIBLE
            and engine.k <= 64)


class WeightedWindowSolver(OthersGroup, OptimalSolver):
    """The weighted bin's optimum on a window's plan with ``others`` more units lumped as one more group of
    weight ``other_weight`` (:class:`~opportune.policies.lumped.OthersGroup`).  Its looks' chances are the
    weighted bin's whatever the weights (exact for equal ones too: the compiled core lumps others there only).
    Complexity: as OptimalSolver's in a weighted bin, on the window's plan.
    """

    def __init__(self, engine, **settings):
        super().__init__(engine, **settings)
        self.uniform = False

    def _best_move(self, key: tuple, i: int, free: bool) -> float:
        if i < len(self.plan.parts):
            return super()._best_move(key, i, free)
        nxt = self._buffer_other(key) if free else None
        return float("inf") if nxt is None else self.other_move + self._value(nxt)


class CompiledWeightedWindowSolver(CompiledOthers, CompiledOptimalSolver, WeightedWindowSolver):
    """:class:`WeightedWindowSolver` computed by the weighted bin's compiled core (the others its last group):
    the same doubles.  A ``ValueError`` where the core does not take the window's plan."""

    def _core_options(self) -> dict:
        n = len(self.plan.parts)
        return {"weights": list(self.weights[:n]), "look_cache_bytes": COMPILED_LOOK_CACHE_BYTES,
                "others": self.others, "other_move": self.other_move,
                "other_weight": self.weights[n] if self.others else 1.0}


def weighted_window_solver(engine, **settings) -> WeightedWindowSolver:
    """:class:`CompiledWeightedWindowSolver` where the compiled core takes the window's plan, else
    :class:`WeightedWindowSolver`; the same values either way.  O(parts) before the work.

    Parameters
    ----------
    engine : OrderEngine
        The window plan's engine.
    **settings
        ``others``, ``other_move``, ``other_weight`` and :class:`~opportune.policies.optimal.OptimalSolver`'s
        settings (``weights`` by part id).

    Returns
    -------
    WeightedWindowSolver
        The programme (nothing computed yet).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> solver = weighted_window_solver(OrderEngine(make_plan(["a"], {})), visible=1, weights={"a": 2.0},
    ...                                 others=1, other_move=1.0, other_weight=1.0)
    >>> round(solver.value(), 4)     # a seen first with chance 2/3 (1 move), else the other buffered first
    1.3333
    """
    if compiled_optimal_available(engine, settings.get("weights"), visible=settings.get("visible")):
        try:
            return CompiledWeightedWindowSolver(engine, **settings)
        except ValueError:          # codes over 64 bits: the Python programme
            pass
    return WeightedWindowSolver(engine, **settings)


class WeightedWindow(LumpedWindow):
    """The exact optimum of the frontier window in a weighted bin at each state, the rest of the plan lumped
    (see the module; :class:`~opportune.policies.lumped.LumpedWindow` for the work counted and the deadline).

    Parameters
    ----------
    base : policy, optional
        What decides where no window fits in ``max_states`` or in time (default
        :class:`~opportune.policies.variants.Slack`).
    visible, capacity, costs, weights :
        The weighted bin's world (as :class:`~opportune.policies.optimal.OptimalSolver`; ``weights`` by part id).
    sizes : tuple of int
        The window sizes tried in turn (:data:`~opportune.engine.tuning.WEIGHTED_WINDOW_PARTS`).
    max_states : int
        States a window's programme may hold (:data:`~opportune.engine.tuning.WEIGHTED_WINDOW_STATES`).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> WeightedWindow(visible=1, capacity=1, weights={"c": 3.0}).choose_at(engine, 0, 1, (), 1.0, ("c",))
    Action(kind='buffer', part='c', source=None)
    """

    name = "weighted window"
    rule = ("the action of least expected cost in the frontier window's exact optimum in the weighted bin "
            "(the other parts lumped)")

    def __init__(self, base=None, *, visible: int = 2, capacity: int | None = None, costs: TimeModel | None = None,
                 weights: dict[str, float] | None = None, sizes: tuple[int, ...] = tuning.WEIGHTED_WINDOW_PARTS,
                 max_states: int = tuning.WEIGHTED_WINDOW_STATES):
        super().__init__(base, visible=visible, capacity=capacity, costs=costs, sizes=sizes, max_states=max_states)
        self.weights = dict(weights or {})

    def _solved(self, engine, mask: int, consistent: int, buffer, parts, outside, size: int) -> WindowTable:
        """The window of ``size`` parts solved: the expected costs after each move.  The work is counted."""
        buf, others, other_move, other_weight = self._window_key(engine, buffer, parts, outside, mask)
        sub = self._window_engine(engine, mask, consistent, parts)
        solver = weighted_window_solver(sub, visible=self.visible, capacity=self.capacity, costs=self.costs,
                                        weights={p.id: self.weights.get(p.id, 1.0) for p in sub.plan.parts},
                                        max_states=self._cap(len(parts), consistent, mask), others=others, other_move=other_move,
                                        other_weight=other_weight)
        solver.deadline = as_deadline(self.deadline)
        try:
            values = solver._deep(lambda key: _after_moves(solver, key), (0, sub.all_strategies, buf))
        finally:
            self._count(solver)
        return WindowTable(tuple(parts), tuple(values), len(outside), size, solver.states,
                           outside_rest(engine, mask, outside, self.costs))

    def _cap(self, parts: int, consistent: int, mask: int) -> int:
        """``max_states`` (times :meth:`~opportune.policies.lumped.LumpedWindow._start`), and at most
        :data:`~opportune.engine.tuning.WEIGHTED_WINDOW_LOOKS` looks over the states (each state enumerates its
        bin's looks: at most those of the window's parts and the others)."""
        return min(self.max_states * self._start(mask),
                   tuning.WEIGHTED_WINDOW_LOOKS // comb(parts + self.visible, self.visible))

    def _decide(self, engine, mask: int, consistent: int, table: WindowTable, buffer,
                visible) -> tuple[float, Action | None, float]:
        ranked = moves_on_look(engine, mask, consistent, table, buffer, visible)
        shake = self.costs.shake + table.values[-1]
        if not ranked:
            return float("inf"), None, shake
        value, _, action = min(ranked, key=lambda r: r[:2])
        return value, action, shake

    #: Whether the looks value keeping several strategies open (:meth:`_option_at`; False: each look takes
    #: the least of the windows' moves, for measurement).
    option: bool = True
    #: The look's parts near a strategy's frontier (:meth:`~opportune.policies.lumped.LumpedWindow._forced_in`):
    #: :data:`~opportune.engine.tuning.WEIGHTED_NEAR_LOCATIONS`,
    #: :data:`~opportune.engine.tuning.WEIGHTED_NEAR_VISIBLE`, :data:`~opportune.engine.tuning.WEIGHTED_NEAR_UNITS`.
    near_locations: float = tuning.WEIGHTED_NEAR_LOCATIONS
    near_visible: int = tuning.WEIGHTED_NEAR_VISIBLE
    near_units: int | None = tuning.WEIGHTED_NEAR_UNITS

    def _option_at(self, engine, mask: int, consistent: int, buffer, tables) -> float:
        """What keeping several strategies open is worth at a state, one look deep: the least of the windows'
        values with their rests less the state's value where each look, drawn by the parts' weights as the
        weighted bin's, takes its best move over all the windows (:func:`~opportune.policies.window.option_value`
        with the weights; 0 past :data:`~opportune.engine.tuning.WEIGHTED_OPTION_DRAWS`).
        O(parts × windows + parts × weights^visible)."""
        if not self.option:
            return 0.0
        weights = [float(self.weights.get(p.id, 1.0)) for p in engine.plan.parts]
        return option_value(engine, mask, consistent, buffer, tables, self.visible, self.costs, weights)

    def _note(self, table: WindowTable) -> str:
        return f"expected cost of the window {table.values[-1]:.4f}"


def _after_moves(solver: WeightedWindowSolver, key: tuple) -> list[float]:
    """What ``WindowCore.moves`` gives, by the weighted programme: per window part the expected cost after
    installing its next unit from the bin, after buffering one, after installing one from the buffer (inf
    where not a move); then after buffering an other, and the state's own value.  O(parts) values."""
    mask, cons, buf = key
    engine, n, inf = solver.engine, len(solver.plan.parts), float("inf")
    free = solver.capacity is None or sum(buf) < solver.capacity
    in_bin = solver._bin_counts(key)
    out = [inf] * (3 * n + 2)
    for j in range(n):
        u = engine.next_unit(mask, j)
        after = 0 if u is None else engine.consistent_after(mask, cons, u)
        if in_bin[j] > 0:
            if after:
                out[3 * j] = solver.move[j] + solver._value((mask | 1 << u, after, buf))
            if free:
                out[3 * j + 1] = solver.move[j] + solver._value((mask, cons, buf[:j] + (buf[j] + 1,) + buf[j + 1:]))
        if buf[j] and after:
            out[3 * j + 2] = solver.move[j] + solver._value((mask | 1 << u, after, buf[:j] + (buf[j] - 1,) + buf[j + 1:]))
    nxt = solver._buffer_other(key) if solver.others > buf[-1] and len(buf) > n else None
    if nxt is not None:
        out[3 * n] = solver.other_move + solver._value(nxt)
    out[3 * n + 1] = solver._value(key)
    return out
