"""The exact optimum, and the exact value of a policy, when the bin is a pile.

In the ``pile`` bin (:class:`~opportune.worlds.bins.PileBin`) the robot sees the top ``visible``
units of a randomly stacked pile; taking one uncovers the next, and a shake reshuffles the pile.
What it sees is no longer a fresh draw at every look: the *window* stays until a unit is taken from
it.  The hidden part of the pile is a uniformly random arrangement of the units not in the window
(nothing the robot did depended on it), so the state is (installed, buffered, window) and

    V(s, W) = c_look + min( m(s, W),  c_shake + S(s) ),      S(s) = Σ_W p(W) V(s, W)

where ``m`` is the best move (taking a window unit brings a uniformly drawn hidden unit into the
window; installing from the buffer keeps the window) and ``S`` the value of a freshly shaken pile,
solved exactly like the uniform bin's shake loop (see :mod:`.optimal`).  A policy's value is the
same recursion with its own action in place of the minimum.

Example (the gearbox, 2 visible, unlimited buffer):

>>> from opportune import load_plan                                # doctest: +SKIP
>>> PileSolver(OrderEngine(load_plan("example:gearbox"))).value()  # doctest: +SKIP
14.74...

The optimum alone (no policy) is also compiled: :class:`CompiledPileSolver` runs the same recursion in
C++ (``_native.PileCore``, ``src/native/pile.cpp``) with the same floating-point operations in the same
order, so its values are the same doubles, many times faster (docs/decisions.md gives the measured
factor) and in at most :data:`COMPILED_BYTES_PER_STATE` bytes per stored value.  :func:`pile_solver` picks it where the
compiled core is there (not with ``OPPORTUNE_PURE_PYTHON=1``), else PileSolver.
"""

from __future__ import annotations

import sys

from opportune.engine import compiled_core
from opportune.engine.tuning import PILE_COMPILED_BYTES_PER_STATE as COMPILED_BYTES_PER_STATE
from opportune.policies.evaluate import BufferOrder, OutOfTime
from opportune.policies.optimal import CompiledCore, OptimalSolver, OptimalTooLarge, check_evaluable

_native = compiled_core()   # None: the Python programme only

__all__ = ["COMPILED_BYTES_PER_STATE", "CompiledPileSolver", "PileSolver", "compiled_pile_available", "pile_solver"]



class PileSolver(BufferOrder, OptimalSolver):
    """Exact least expected cost in the pile bin, and (with ``policy``) the exact cost of a policy.

    A policy that uses the buffer's order is scored on states that keep it
    (:class:`~opportune.policies.evaluate.BufferOrder`).  Complexity: O(states × windows × moves).
    :func:`pile_solver` gives the compiled programme for the optimum where it is built.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    policy : Policy, optional
        A deterministic policy that decides on the state alone (``choose_at``): its exact expected cost
        instead of the optimum.
    **settings
        As :class:`~opportune.policies.optimal.OptimalSolver`'s: ``visible`` (the units on top of the
        pile the robot sees), ``capacity``, ``costs`` and ``max_states`` (which bounds the (state,
        window) pairs); ``weights`` is ignored (a pile has none).

    Raises
    ------
    ValueError
        A policy whose exact value is not defined (it chooses at random) or not computable (no
        ``choose_at``).

    Examples
    --------
    On a chain of four parts, with two visible and one buffer location, the pile costs more than the
    uniform bin (its window stays until a unit is taken); the paper's rule reaches the pile's optimum here:

    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> from opportune.policies.opportunistic import Opportunistic
    >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"b": ["a"], "c": ["b"], "d": ["c"]}))
    >>> round(OptimalSolver(engine, visible=2, capacity=1).value(), 4)
    4.9167
    >>> round(PileSolver(engine, visible=2, capacity=1).value(), 4)
    5.0417
    >>> round(PileSolver(engine, Opportunistic(), visible=2, capacity=1).value(), 4)
    5.0417
    """

    def __init__(self, engine, policy=None, **settings):
        settings.pop("weights", None)
        super().__init__(engine, **settings)
        if policy is not None:
            check_evaluable(policy, "pile")
        self.policy = policy
        self._keep_order(policy)
        # one memo (OptimalSolver._values, which a study hands from its parent to its workers): window
        # values under (key, window), values of a freshly shaken pile under ("shaken", key)
        self._window_values = self._values
        self._shaken = _Prefixed(self._values)

    # ------------------------------------------------------------ public

    def value(self, key: tuple | None = None) -> float:
        """Expected cost from a freshly shaken pile at ``key`` (default: the start): the optimum, or
        the policy's if one was given.

        Parameters
        ----------
        key : tuple, optional
            A state as the programme keys it (:meth:`~opportune.policies.optimal.OptimalSolver.policy_key`:
            installed units, open strategies, the buffer); default: the start.

        Returns
        -------
        float
            The expected cost, in the time model's units (the looks, moves and shakes to the end).

        Raises
        ------
        OptimalTooLarge
            More than ``max_states`` (state, window) pairs.
        OutOfTime
            Past the ``deadline`` (what was finished stays: a later call goes on from there).

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> solver = PileSolver(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), visible=1)
        >>> round(solver.value(), 4), round(solver.value(solver.policy_key(1, 1, ())), 4)   # a installed
        (2.5, 1.0)
        """
        return self._deep(self._shake_value, self.policy_start() if key is None else key)

    def _bin_counts(self, key: tuple) -> tuple[int, ...]:
        return super()._bin_counts(self._counts_key(key))

    @property
    def states(self) -> int:
        return len(self._values)

    def _after_shake(self, key: tuple) -> float:
        return self._shake_value(key)      # a shake restacks the pile: a fresh window

    # ------------------------------------------------------------ the recursion

    def _shake_value(self, key: tuple) -> float:
        """S(key): the value of a freshly drawn window (the start, or after a shake)."""
        cached = self._shaken.get(key)
        if cached is not None:
            return cached
        if key[0] == self.engine.full:
            self._shaken[key] = 0.0
            return 0.0
        c_look, c_shake = self.costs.look, self.costs.shake
        moves = []        # (m(W), p(W)): the move's value, or None where the policy shakes
        for window, p in self._looks(self._bin_counts(key)):
            moves.append((self._move_value(key, window), p))
        if self.policy is None:
            s = self._solve_shake_loop([(float("inf") if m is None else m, p) for m, p in moves])
        else:
            acted = sum(p for m, p in moves if m is not None)
            if acted <= 1e-15:
                raise RuntimeError("the policy shakes at every window of a state it reaches: it never finishes")
            s = (c_look + sum(p * m for m, p in moves if m is not None) + (1 - acted) * c_shake) / acted
        self._shaken[key] = s
        # the windows' own values, now that S is known
        for (window, _), (m, _) in zip(self._looks(self._bin_counts(key)), moves):
            shake = c_shake + s
            self._window_values[(key, window)] = c_look + (shake if m is None else min(m, shake) if
                                                           self.policy is None else m)
        return s

    def _window_value(self, key: tuple, window: tuple[int, ...]) -> float:
        """V(key, W): a look at window W (the cost of the look included)."""
        cached = self._window_values.get((key, window))
        if cached is not None:
            return cached
        if key[0] == self.engine.full:
            return 0.0
        stored = len(self._values)
        self._tick("the pile's programme", stored)
        if stored >= self.max_states:
            raise OptimalTooLarge(f"the pile bin needs more than {self.max_states:,} states for this plan; raise the "
                                  "state limit, or estimate with `opportune simulate --bin pile`")
        m = self._move_value(key, window)
        shake = self.costs.shake + self._shake_value(key)
        if self.policy is None:
            v = self.costs.look + (shake if m is None else min(m, shake))
        else:
            v = self.costs.look + (shake if m is None else m)
        self._window_values[(key, window)] = v
        return v

    def _move_value(self, key: tuple, window: tuple[int, ...]) -> float | None:
        """The best move's cost to go (or the policy's move's; None: no move, or the policy shakes)."""
        if self.policy is not None:
            chosen = self._policy_move(self.policy, key, window)
            return None if chosen is None else chosen[0] + self._after(key, window, chosen[2], chosen[1])
        best = None
        for cost, nxt, move in self._moves(key, window):
            v = cost + self._after(key, window, move, nxt)
            if best is None or v < best:
                best = v
        return best

    def _part_index(self, part: str) -> int:
        """A move's part as the programme indexes it (the plan's declaration order).  O(1)."""
        return self.plan.index(part)

    def _others_args(self) -> tuple:
        """The compiled core's last arguments: no units lumped (see :mod:`.pile_window`)."""
        return (0, float("inf"))

    def _after(self, key: tuple, window: tuple[int, ...], move, nxt: tuple) -> float:
        """Expected value after a move: a unit taken from the window is replaced by a hidden one."""
        if move.kind == "install" and move.source == "buffer":
            return self._window_value(nxt, window)
        i = self._part_index(move.part)
        rest = list(window)
        rest.remove(i)
        # the units of the bin before the move that are not in the window
        hidden = [c - window.count(j) for j, c in enumerate(self._bin_counts(key))]
        total = sum(hidden)
        if total == 0:
            return self._window_value(nxt, tuple(sorted(rest)))
        return sum(c / total * self._window_value(nxt, tuple(sorted(rest + [j])))
                   for j, c in enumerate(hidden) if c)


def compiled_pile_available(engine) -> bool:
    """Whether the compiled optimum takes this plan: the core is built (and not switched off with
    ``OPPORTUNE_PURE_PYTHON=1``), the plan has at most 64 units and 64 strategies.  O(1)."""
    return _native is not None and hasattr(_native, "PileCore") and engine.n_units <= 64 and engine.k <= 64


def pile_solver(engine, policy=None, **settings) -> PileSolver:
    """The pile's programme: :class:`CompiledPileSolver` for the optimum where the compiled core takes
    the plan, else :class:`PileSolver` (a policy's value, or no compiled core); the same values either
    way.  O(1) before the work.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    policy : Policy, optional
        A policy whose exact value to compute (then always :class:`PileSolver`); None: the optimum.
    **settings
        As :class:`PileSolver`'s: ``visible``, ``capacity``, ``costs``, ``max_states``.

    Returns
    -------
    PileSolver
        The programme; its values are computed as asked.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> round(pile_solver(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), visible=1).value(), 4)
    2.5
    """
    if policy is None and compiled_pile_available(engine):
        try:
            return CompiledPileSolver(engine, **settings)
        except ValueError:          # codes over 64 bits (a huge plan): the Python programme refuses it too
            pass
    return PileSolver(engine, policy, **settings)


class CompiledPileSolver(CompiledCore, PileSolver):
    """The pile's optimum (:class:`PileSolver` with no policy), computed by the compiled core.

    The same settings, methods and values (the same doubles); ``max_states`` bounds the stored values
    (:class:`OptimalTooLarge`), the ``deadline`` is read at every new state (:class:`OutOfTime`; what
    was finished stays).  Memory: :data:`COMPILED_BYTES_PER_STATE` bytes per value.  A ``ValueError``
    where the core does not take the plan (see :func:`compiled_pile_available`).
    Complexity: O(states × windows × moves), as PileSolver (how much faster: docs/decisions.md).
    """

    def __init__(self, engine, policy=None, **settings):
        if policy is not None:
            raise ValueError("the compiled pile programme computes the optimum only: evaluate a policy with PileSolver")
        if not compiled_pile_available(engine):
            raise ValueError("the compiled pile optimum needs the compiled core and a plan of at most 64 units "
                             "and 64 strategies")
        super().__init__(engine, **settings)
        self._core = _native.PileCore(*self._core_args(),
                                      sys.version_info >= (3, 12),   # sum() of floats is compensated from Python 3.12 on
                                      *self._others_args())
        self._give_ways()

    def _shake_value(self, key: tuple) -> float:
        return self._run(self._core.shake_value, key[0], key[1], list(key[2]))

    def _window_value(self, key: tuple, window: tuple[int, ...]) -> float:
        return self._run(self._core.window_value, key[0], key[1], list(key[2]), list(window))

    def _after(self, key: tuple, window: tuple[int, ...], move, nxt: tuple) -> float:
        """As :meth:`PileSolver._after`, the expectation over the hidden unit in one call to the core."""
        if move.kind == "install" and move.source == "buffer":
            return self._window_value(nxt, window)
        return self._run(self._core.taken_value, key[0], key[1], list(key[2]), list(window), self._part_index(move.part),
                         nxt[0], nxt[1], list(nxt[2]))

    def _run(self, solve, *args) -> float:
        try:
            return solve(*args, seconds=self._until.seconds(), max_states=self.max_states)
        except _native.PileTimeout:
            raise OutOfTime("the pile's programme passed its deadline") from None
        except _native.PileTooLarge:
            raise OptimalTooLarge(f"the pile bin needs more than {self.max_states:,} states for this plan; raise the "
                                  "state limit, or estimate with `opportune simulate --bin pile`") from None
        except _native.PileStuck as exc:
            raise RuntimeError(str(exc)) from None
        finally:
            self._report()


class _Prefixed:
    """A view of a dict under keys ``("shaken", key)``."""

    __slots__ = ("_d",)

    def __init__(self, d: dict):
        self._d = d

    def get(self, key):
        return self._d.get(("shaken", key))

    def __setitem__(self, key, value) -> None:
        self._d[("shaken", key)] = value
