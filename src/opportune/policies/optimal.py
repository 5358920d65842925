"""The optimum: the least expected cost any online policy can achieve in a Markov bin.

Under the ``uniform`` and ``weighted`` bin models a look depends only on what
is in the bin, so the assembly is a Markov decision process over states
(installed parts, buffered parts).  At a state *s*, a look *L* arrives with
probability *p(L)*; the robot may install a visible or buffered part,
buffer a visible part, or shake (pay and look again).  With *m(L)* the best
non-shake continuation for look *L*, the value satisfies

    V(s) = c_look + Σ_L p(L) · min(m(L), c_shake + V(s))

— the shake is a self-loop.  It is solved exactly: the looks on which the
robot acts form a threshold set (those with *m(L)* ≤ c_shake + V(s)), so V(s)
is the minimum over prefixes *A* of the looks sorted by *m(L)* of
``(c_look + Σ_A p m + (1 − P_A) c_shake) / P_A``.  Every non-shake action
moves to a state with more parts installed or buffered, so the recursion
over states terminates; it is memoised, and refuses above ``max_states``.

In a uniform bin no look is enumerated: *m(L)* is the least of the visible parts' own best moves
and of the buffer's best installation, so with the bin's *n* units ranked by their part's best move
the best visible unit is the *j*-th with probability C(n − j, k − 1) / C(n, k) for *k* visible: the
looks' values are order statistics (:meth:`OptimalSolver._order_statistics`), O(parts) a state.
The weighted bin ranks its parts the same way and sums, per part, the probabilities of the looks
whose best-ranked part it is (its looks enumerated, once per bin content): O(looks) a state, no sort.
:class:`CompiledOptimalSolver` runs the recursion of either bin in the compiled core
(``src/native/optimal.cpp``) with the same operations in the same order: the same doubles, many times
faster (docs/decisions.md gives the measured factors), at most 64 bytes a state (:func:`optimum_bytes`;
and a bounded look cache in a weighted bin); :func:`optimal_solver` picks it where the core is built (not
with ``OPPORTUNE_PURE_PYTHON=1``), on the plan with its interchangeable parts merged
(:mod:`.interchangeable`: parts no strategy, cost or weight tells apart counted as one part's units).

Bounds: the states stored never exceed ``max_states`` (:class:`OptimalTooLarge`), and a
``deadline`` (:class:`~opportune.engine.deadline.Deadline`) is read between states
(:class:`OutOfTime`; what was finished stays memoised, so a later call goes on from there).  How
many states a plan needs is known before the programme starts: :mod:`.states`.  Memory grows with
the states only: at most about :data:`~opportune.policies.states.BYTES_PER_STATE` bytes per state,
plus the look cache, which is bounded (:data:`LOOK_CACHE_LOOKS` looks in all).
"""

from __future__ import annotations

import sys
from functools import lru_cache
from math import comb, prod

from opportune.engine import OrderEngine, compiled_core
from opportune.engine.deadline import Deadline, as_deadline
from opportune.engine.tuning import (  # noqa: F401 (the look cache's and the compiled optimum's bounds, by these names)
    COMPILED_LOOK_BYTES,
    COMPILED_LOOK_CACHE_BYTES,
    COMPILED_LOOK_ENTRY_BYTES,
    COMPILED_PAIR_BYTES,
    COMPILED_WEIGHTED_LOOKS,
    COMPILED_WEIGHTED_VISIBLE,
    LOOK_CACHE_LOOKS,
)
from opportune.policies.base import DONE, SHAKE, Action, Decision
from opportune.policies.interchangeable import merge_interchangeable
from opportune.planning.costs import TimeModel

_native = compiled_core()   # None: the Python programme only


class OptimalTooLarge(RuntimeError):
    """The state space is over the limit: the optimum is not computed.

    Examples
    --------
    >>> from opportune import make_plan
    >>> OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {})), max_states=3).value()
    Traceback (most recent call last):
    ...
    opportune.policies.optimal.OptimalTooLarge: the optimum needs more than 3 states for this plan; ...
    """


class OutOfTime(RuntimeError):
    """The programme passed its ``deadline``; the states it finished stay memoised.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine.deadline import Deadline
    >>> solver = OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {})))
    >>> solver.deadline = Deadline(0.0)         # a moment long past
    >>> solver.value()
    Traceback (most recent call last):
    ...
    opportune.policies.optimal.OutOfTime: the optimum's programme passed its deadline
    >>> solver.deadline = None                  # no deadline: it goes on from where it stopped
    >>> solver.value()
    3.0
    """


class OptimalSolver:
    """Exact minimum expected cost of assembling ``engine.plan`` from a Markov bin.

    Complexity: O(states × parts) in a uniform bin (the looks as order statistics), else
    O(states × (looks × visible + parts)); states ≤ down-sets × buffer contents.
    :func:`optimal_solver` gives the compiled programme where it is built (the same values).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    visible : int
        Units seen at a look.
    capacity : int or None
        Buffer locations (None: unlimited).
    costs : TimeModel, optional
        The costs of a look, a shake and each part's move (default :class:`~opportune.planning.costs.TimeModel`).
    weights : dict, optional
        Per-part visibility weights (None, or all equal: the uniform bin).
    max_states : int
        States the programme may store (:class:`OptimalTooLarge` past it).

    Examples
    --------
    >>> from opportune import make_plan
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    >>> [round(OptimalSolver(engine, visible=1, capacity=k).value(), 4) for k in (0, 1)]   # a location helps
    [4.5, 3.6667]
    >>> round(OptimalSolver(engine, visible=1, weights={"c": 3.0}).value(), 4)          # c seen most often
    3.9
    >>> OptimalSolver(engine, visible=1, capacity=1, max_states=2).value()
    Traceback (most recent call last):
    ...
    opportune.policies.optimal.OptimalTooLarge: the optimum needs more than 2 states for this plan; ...
    """

    #: The policy whose value a subclass computes (None: the optimum).
    policy = None

    def __init__(self, engine: OrderEngine, *, visible: int = 2, capacity: int | None = None,
                 costs: TimeModel | None = None, weights: dict[str, float] | None = None,
                 max_states: int = 500_000):
        self.engine = engine
        self.plan = engine.plan
        self.visible = visible
        self.capacity = capacity
        self.costs = costs or TimeModel()
        self.weights = [float((weights or {}).get(p.id, 1.0)) for p in self.plan.parts]
        self.max_states = max_states
        self.quantity = [p.quantity for p in self.plan.parts]
        self.ids = self.plan.part_ids
        self.move = [self.costs.move(p) for p in self.ids]
        #: Every unit in the bin equally likely to be seen: the looks' values are order statistics, not enumerated.
        self.uniform = len(set(self.weights)) <= 1
        self._values: dict[tuple, float] = {}
        # the looks of a bin: cached for the states that share it (most do, nearby in the recursion),
        # within a bound on the looks kept, not on the entries: a large plan has many looks per bin
        looks_at_start = comb(len(self.ids) + visible - 1, visible) if self.ids else 1
        self._looks = lru_cache(maxsize=max(16, LOOK_CACHE_LOOKS // max(1, looks_at_start)))(self._look_distribution)
        self._until = Deadline.NEVER
        self._next_report = 0
        #: Called as ``progress(self)`` every 64 new states (for a progress bar; None: not called).
        self.progress = None

    # ------------------------------------------------------------ bounds

    @property
    def deadline(self) -> Deadline | None:
        """The :class:`~opportune.engine.deadline.Deadline` read between states (None: none).

        Set it to a Deadline, a ``time.perf_counter()`` value or None; past it the programme raises
        :class:`OutOfTime`, and what it finished before stays, so a later call goes on from there."""
        return None if self._until is Deadline.NEVER else self._until

    @deadline.setter
    def deadline(self, value) -> None:
        self._until = as_deadline(value)

    def _tick(self, what: str, stored: int) -> None:
        """On entering every new state: the deadline (a state's children are entered before it is
        stored, so a count of stored states would miss whole descents); the progress report once per
        64 more stored.  O(1)."""
        if self._until.expired():
            raise OutOfTime(f"{what} passed its deadline")
        if self.progress is not None and stored >= self._next_report:
            self._next_report = stored + 64
            self.progress(self)

    def reserve(self, states: int) -> None:
        """Make room for ``states`` values before the work (the count from
        :func:`~opportune.policies.states.estimate_states`).  The Python programme's dictionary grows
        as it goes: nothing to do here (the compiled programmes size their tables).  O(1).

        Parameters
        ----------
        states : int
            The states the programme will store.

        Examples
        --------
        >>> from opportune import make_plan
        >>> solver = OptimalSolver(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})))
        >>> solver.reserve(100)
        >>> solver.states
        0
        """

    # ------------------------------------------------------------ states

    def start_key(self) -> tuple:
        """The key of the start: nothing installed, every strategy open, the buffer empty.

        Returns
        -------
        tuple
            ``(installed units, open strategies, units buffered per part)``.

        Examples
        --------
        >>> from opportune import make_plan
        >>> OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))).start_key()
        (0, 1, (0, 0, 0))
        """
        return (0, self.engine.all_strategies, (0,) * len(self.ids))

    def key_of(self, state) -> tuple:
        """The solver's key for a sequencer :class:`~opportune.sequencer.State`.

        Parameters
        ----------
        state : State
            The sequencer's state.

        Returns
        -------
        tuple
            ``(installed units, open strategies, units buffered per part)``.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.sequencer import Sequencer
        >>> plan = make_plan(["a", "b", "c"], {"c": ["a", "b"]})
        >>> seq = Sequencer(plan, buffer_capacity=1)
        >>> seq.step(["c"]).action.kind
        'buffer'
        >>> OptimalSolver(OrderEngine(plan)).key_of(seq.state)
        (0, 1, (0, 0, 1))
        """
        return (state.schedule.mask, state.schedule.consistent, self.buffer_counts(state.buffer))

    def policy_key(self, mask: int, consistent: int, buffer) -> tuple:
        """The key a policy's programme keeps for a state: here the optimum's, with the buffer as counts
        (:class:`~opportune.policies.evaluate.PolicyEvaluator` keeps the buffer's order where the policy
        uses it).

        Parameters
        ----------
        mask, consistent : int
            The installed units and the open strategies.
        buffer : sequence of str
            The buffered parts.

        Returns
        -------
        tuple
            The key.

        Examples
        --------
        >>> from opportune import make_plan
        >>> OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))).policy_key(0b011, 1, ["c"])
        (3, 1, (0, 0, 1))
        """
        return (mask, consistent, self.buffer_counts(buffer))

    def policy_moves(self, key: tuple, look: tuple[int, ...]):
        """The moves of :meth:`_moves` between the keys of :meth:`policy_key` (here the same): every
        installation and buffering a look allows, and every installation from the buffer.

        Parameters
        ----------
        key : tuple
            The state (:meth:`policy_key`).
        look : tuple of int
            The visible units' parts, as plan indices (sorted).

        Returns
        -------
        iterator of (float, tuple, Action)
            Each move's cost now, the key after it and the action.

        Examples
        --------
        >>> from opportune import make_plan
        >>> solver = OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]})), capacity=1)
        >>> [(str(action), key) for _, key, action in solver.policy_moves(solver.start_key(), (0, 2))]
        [('install a', (1, 1, (0, 0, 0))), ('buffer a', (0, 1, (1, 0, 0))), ('buffer c', (0, 1, (0, 0, 1)))]
        """
        return self._moves(key, look)

    def _buffered(self, key: tuple) -> tuple[str, ...]:
        """The buffer of a :meth:`policy_key` as the policy sees it (here in declaration order)."""
        return tuple(self.ids[i] for i, c in enumerate(key[2]) for _ in range(c))

    def buffer_counts(self, buffer) -> tuple[int, ...]:
        """The buffer as the solver keeps it: units buffered per part, in declaration order.

        Parameters
        ----------
        buffer : iterable of str
            The buffered parts' ids.

        Returns
        -------
        tuple of int
            Units buffered per part.

        Examples
        --------
        >>> from opportune import make_plan
        >>> OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))).buffer_counts(["c"])
        (0, 0, 1)
        """
        buf = [0] * len(self.ids)
        for p in buffer:
            buf[self.plan.index(p)] += 1
        return tuple(buf)

    def _installed_counts(self, mask: int) -> list[int]:
        counts = [0] * len(self.ids)
        for i, first in enumerate(self.engine.first):
            for u in range(first, first + self.quantity[i]):
                if mask >> u & 1:
                    counts[i] += 1
        return counts

    def _look_distribution(self, bin_counts: tuple[int, ...]) -> tuple[tuple[tuple[int, ...], float], ...]:
        """Every possible look (a sorted tuple of part indices) with its probability.

        Units are drawn one after another without replacement, each with chance
        proportional to its part's weight (all 1: uniform)."""
        total_units = sum(bin_counts)
        k = min(self.visible, total_units)
        out: dict[tuple[int, ...], float] = {}
        counts = list(bin_counts)
        w = self.weights

        def draw(depth: int, prob: float, taken: list[int]):
            if depth == k:
                key = tuple(sorted(taken))
                out[key] = out.get(key, 0.0) + prob
                return
            # summed in a loop, not with sum(): the same additions on every Python (3.12's sum()
            # compensates) and in the compiled programme
            mass = 0.0
            for i, c in enumerate(counts):
                mass += c * w[i]
            for i, c in enumerate(counts):
                if c:
                    counts[i] -= 1
                    taken.append(i)
                    draw(depth + 1, prob * c * w[i] / mass, taken)
                    taken.pop()
                    counts[i] += 1

        draw(0, 1.0, [])
        return tuple(sorted(out.items()))

    def _moves(self, key: tuple, look: tuple[int, ...]):
        """Non-shake actions for a look: ``(cost_now, next_key, action)``."""
        mask, cons, buf = key
        engine = self.engine
        used = sum(buf)
        free = self.capacity is None or used < self.capacity
        seen = set()
        for i in look:
            if i in seen:
                continue
            seen.add(i)
            u = engine.next_unit(mask, i)
            after = engine.exact_after(mask, cons, u)
            if after:
                yield self.move[i], (mask | 1 << u, after, buf), Action("install", self.ids[i], "bin")
            if free:
                nb = list(buf)
                nb[i] += 1
                yield self.move[i], (mask, cons, tuple(nb)), Action("buffer", self.ids[i])
        for i, nxt in self._buffer_installs(mask, cons, buf):
            yield self.move[i], nxt, Action("install", self.ids[i], "buffer")

    def _buffer_installs(self, mask: int, cons: int, buf: tuple[int, ...]):
        """``(part, next key)`` of every installation from the buffer that keeps a strategy.  O(parts)."""
        engine = self.engine
        for i, c in enumerate(buf):
            if c:
                u = engine.next_unit(mask, i)
                after = engine.exact_after(mask, cons, u)
                if after:
                    nb = list(buf)
                    nb[i] -= 1
                    yield i, (mask | 1 << u, after, tuple(nb))

    def _policy_move(self, policy, key: tuple, look: tuple[int, ...]):
        """The move ``policy`` makes at ``key`` on ``look``, as ``(cost, next key, action)`` of
        :meth:`_moves`, or None when it shakes; a move that is not legal there is a ``ValueError``.
        The policy decides on the machine form of the state (``choose_at``), its key that of
        :meth:`policy_key`."""
        mask, cons, _ = key
        ids = self.ids
        buffer = self._buffered(key)
        free = float("inf") if self.capacity is None else self.capacity - len(buffer)
        # the moves first: on a plan written as ways they decide exactly which sets after are live, and the
        # engine's look-by-look answers the policy reads take those decisions (never a guess of "live")
        moves = list(self.policy_moves(key, look))
        action = policy.choose_at(self.engine, mask, cons, buffer, free, tuple(ids[i] for i in look))
        if action.kind == "shake":
            return None
        for move in moves:
            if same_action(move[2], action):
                return move
        raise ValueError(f"the policy chose {action} at a state where it is not a legal move")

    def _after(self, key: tuple, look: tuple[int, ...], action: Action, nxt: tuple) -> float:
        """Expected cost to go after ``action`` (a fresh look follows every move in a Markov bin)."""
        return self._value(nxt)

    def _after_shake(self, key: tuple) -> float:
        """Expected cost to go after a shake at ``key`` (plus the shake's own cost)."""
        return self._value(key)

    def _deep(self, solve, key: tuple | None) -> float:
        """``solve(key)`` (default: the start) with room for the recursion: one level per part moved."""
        key = self.start_key() if key is None else key
        limit = sys.getrecursionlimit()
        sys.setrecursionlimit(max(limit, 10_000))
        try:
            return solve(key)
        finally:
            sys.setrecursionlimit(limit)

    def _bin_counts(self, key: tuple) -> tuple[int, ...]:
        mask, _, buf = key
        inst = self._installed_counts(mask)
        return tuple(q - a - b for q, a, b in zip(self.quantity, inst, buf))

    # ------------------------------------------------------------ values

    def value(self, key: tuple | None = None) -> float:
        """Minimum expected remaining cost from a state (default: the start).

        Parameters
        ----------
        key : tuple, optional
            The state (:meth:`policy_key`); default :meth:`start_key`.

        Returns
        -------
        float
            The expected cost, in the time model's units (looks, moves and shakes to the end).

        Raises
        ------
        OptimalTooLarge
            More than ``max_states`` states.
        OutOfTime
            Past the :attr:`deadline` (what was finished stays: a later call goes on from there).

        Examples
        --------
        >>> from opportune import make_plan
        >>> solver = OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]})), visible=1, capacity=1)
        >>> round(solver.value(), 4), round(solver.value((0, 1, (0, 0, 1))), 4), solver.states   # c buffered
        (3.6667, 3.0, 13)
        """
        return self._deep(self._value, key)

    def _value(self, key: tuple) -> float:
        cached = self._values.get(key)
        if cached is not None:
            return cached
        if key[0] == self.engine.full:
            self._values[key] = 0.0
            return 0.0
        stored = len(self._values)
        self._tick("the optimum's programme", stored)
        if stored >= self.max_states:
            raise OptimalTooLarge(
                f"the optimum needs more than {self.max_states:,} states for this plan; "
                "raise --optimal-states, or leave 'optimal' out of the strategies")
        v = self._shake_loop(self._order_statistics(key))
        self._values[key] = v
        return v

    def _order_statistics(self, key: tuple) -> list[tuple[float, float]]:
        """``(m, p)`` in increasing ``m``: the best move's value on a look, and the chance of a look
        with that best move (in a uniform bin with no look enumerated; see the module's docstring).

        The best move on a look is the least of the visible parts' own best moves (install from the bin
        or buffer) and of the buffer's best installation, which every look shares.  With the bin's units
        ranked by their part's best move (ties by declaration order), the part whose ``c`` units hold
        ranks ``r + 1 .. r + c`` of ``n`` is the best visible one with probability
        ``(C(n − r, k) − C(n − r − c, k)) / C(n, k)`` for ``k`` visible (:meth:`_uniform_chances`; in a
        weighted bin :meth:`_weighted_chances`).  The compiled programme (``src/native/optimal.cpp``)
        does the same operations in the same order.  O(parts) values."""
        mask, cons, buf = key
        move, value = self.move, self._value
        free = self.capacity is None or sum(buf) < self.capacity
        inf = float("inf")
        ranked = []         # (best move, part, units in the bin)
        n = 0
        for i, c in enumerate(self._bin_counts(key)):
            if c <= 0:
                continue
            n += c
            ranked.append((self._best_move(key, i, free), i, c))
        from_buffer = inf
        for i, nxt in self._buffer_installs(mask, cons, buf):
            from_buffer = min(from_buffer, move[i] + value(nxt))
        if n == 0:          # every unit left is in the buffer: no part is seen
            return [(from_buffer, 1.0)]
        ranked.sort()
        chances = self._uniform_chances(ranked, n) if self.uniform else self._weighted_chances(ranked, key)
        return [(min(best, from_buffer), p) for (best, _, _), p in zip(ranked, chances)]

    def _best_move(self, key: tuple, i: int, free: bool) -> float:
        """A part's best move on a look that shows it: installing its next unit from the bin or, with a free
        location, buffering one (inf: neither).  O(strategies)."""
        mask, cons, buf = key
        best = float("inf")
        u = self.engine.next_unit(mask, i)
        after = self.engine.exact_after(mask, cons, u)
        if after:
            best = self.move[i] + self._value((mask | 1 << u, after, buf))
        if free:
            nb = list(buf)
            nb[i] += 1
            best = min(best, self.move[i] + self._value((mask, cons, tuple(nb))))
        return best

    def _uniform_chances(self, ranked: list[tuple[float, int, int]], n: int) -> list[float]:
        """Each ranked part's chance of being the best visible one in a uniform bin of ``n`` units:
        ``(C(n − r, k) − C(n − r − c, k)) / C(n, k)``.  O(parts)."""
        k = min(self.visible, n)
        total = float(comb(n, k))
        out, rank = [], 0
        for _, _, c in ranked:
            out.append(float(comb(n - rank, k) - comb(n - rank - c, k)) / total)
            rank += c
        return out

    def _weighted_chances(self, ranked: list[tuple[float, int, int]], key: tuple) -> list[float]:
        """Each ranked part's chance of being the best visible one in a weighted bin: the probabilities
        of the looks (:meth:`_look_distribution`, in its order) whose best-ranked part it is.  A look's
        best move is its best part's (or the buffer's), so the looks are grouped, not sorted one by one:
        the least over the prefixes of the groups is the least over the prefixes of the looks (adding
        looks of one value moves the value monotonically towards it).  O(looks × visible)."""
        rank = {i: r for r, (_, i, _) in enumerate(ranked)}
        out = [0.0] * len(ranked)
        for look, p in self._looks(self._bin_counts(key)):
            out[min(rank[i] for i in look)] += p
        return out

    def _solve_shake_loop(self, best_per_look) -> float:
        """The shake loop over ``(m, p)`` pairs in any order (sorted here)."""
        best_per_look.sort()
        return self._shake_loop(best_per_look)

    def _shake_loop(self, best_per_look) -> float:
        """The least over prefixes of ``(m, p)`` pairs in increasing ``m`` (see the module's docstring)."""
        v = shake_loop(best_per_look, self.costs.look, self.costs.shake)
        if v == float("inf"):
            raise RuntimeError("no look allows any action: the assembly cannot proceed")
        return v

    @property
    def states(self) -> int:
        return len(self._values)

    def best_action(self, key: tuple, look: tuple[int, ...]) -> tuple[Action, float]:
        """The optimal action for a state and look (ties: install, then buffer, then declaration order).

        Parameters
        ----------
        key : tuple
            The state (:meth:`policy_key`).
        look : tuple of int
            The visible units' parts, as plan indices (sorted).

        Returns
        -------
        (Action, float)
            The action (a shake where no move is cheaper than shaking by 1e-12) and its expected cost to
            the end.

        Examples
        --------
        >>> from opportune import make_plan
        >>> solver = OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]})), visible=1, capacity=1)
        >>> solver.best_action(solver.start_key(), (2,))        # c seen first: buffered
        (Action(kind='buffer', part='c', source=None), 4.0)
        >>> solver.best_action((0, 1, (0, 0, 1)), (0,))
        (Action(kind='install', part='a', source='bin'), 3.0)
        """
        v = self._after_shake(key)
        best, best_cost = None, float("inf")
        kind_rank = {"install": 0, "buffer": 1}
        for c, nxt, action in self._moves(key, look):
            total = c + self._after(key, look, action, nxt)
            rank = (total, kind_rank[action.kind], self.plan.index(action.part), action.source != "bin")
            if best is None or rank < best[0]:
                best, best_cost = (rank, action), total
        shake_cost = self.costs.shake + v
        if best is None or best_cost > shake_cost + 1e-12:
            return SHAKE, shake_cost
        return best[1], best_cost

    def action_value(self, key: tuple, look: tuple[int, ...], action: Action) -> tuple[float, tuple | None]:
        """The expected cost to the end of taking ``action`` at a state and look and acting optimally after
        (the value :meth:`best_action` takes the least of), and the state it leads to.

        Parameters
        ----------
        key : tuple
            The state (:meth:`policy_key`).
        look : tuple of int
            The visible units' parts, as plan indices (sorted).
        action : Action
            An installation, a buffering or a shake.

        Returns
        -------
        (float, tuple or None)
            The expected cost (the look's own cost not included, as in :meth:`best_action`) and the key
            after the action (None for a shake: the same state, a fresh look).

        Raises
        ------
        ValueError
            The action is not legal at this state and look.

        Examples
        --------
        >>> from opportune import make_plan
        >>> solver = OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]})), visible=1, capacity=1)
        >>> solver.action_value(solver.start_key(), (2,), Action("buffer", "c"))
        (4.0, (0, 1, (0, 0, 1)))
        >>> value, after = solver.action_value(solver.start_key(), (2,), SHAKE)      # dearer than buffering c
        >>> round(value, 4), after
        (4.6667, None)
        """
        if action.kind == "shake":
            return self.costs.shake + self._after_shake(key), None
        for cost, nxt, move in self._moves(key, look):
            if same_action(move, action):
                return cost + self._after(key, look, move, nxt), nxt
        raise ValueError(f"{action} is not a legal move at this state and look")

    def bin_counts(self, key: tuple) -> tuple[int, ...]:
        """The units of each part still in the bin at a state (not installed, not buffered).

        Parameters
        ----------
        key : tuple
            The state (:meth:`policy_key`).

        Returns
        -------
        tuple of int
            Units per part, in the plan's declaration order.

        Examples
        --------
        >>> from opportune import make_plan
        >>> solver = OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]})), capacity=1)
        >>> solver.bin_counts(solver.policy_key(0b001, 1, ["c"]))     # a installed, c buffered
        (0, 1, 0)
        """
        return self._bin_counts(key)


def shake_loop(best_per_look, look: float, shake: float) -> float:
    """A state's value from its looks: each look of chance ``p`` taking a move of expected cost ``m`` or a
    shake (and a fresh look), the looks acted on those of least ``m``: the least over prefixes of the
    ``(m, p)`` pairs, given in increasing ``m``, of (look + Σ p·m + (1 − Σ p)·shake) / Σ p (see the
    module's docstring); inf where no look has a move.  O(looks).

    Parameters
    ----------
    best_per_look : iterable of (float, float)
        Each look's best move's expected cost (inf: none) and its chance, in increasing cost.
    look, shake : float
        The costs of a look and of a shake.

    Returns
    -------
    float
        The value, or inf.

    Examples
    --------
    >>> shake_loop([(1.0, 0.5), (5.0, 0.5)], 0.0, 1.0)      # act on the first look only: 1 + 1 = 2
    2.0
    >>> shake_loop([(float("inf"), 1.0)], 0.0, 1.0)
    inf
    """
    acc_pm, acc_p, v = 0.0, 0.0, float("inf")
    for m, p in best_per_look:
        if m == float("inf"):
            break
        acc_pm += p * m
        acc_p += p
        v = min(v, (look + acc_pm + (1.0 - acc_p) * shake) / acc_p)
    return v


def same_action(a: Action, b: Action) -> bool:
    """The same move: kind and part, and for an installation the same source (bin by default)."""
    return a.kind == b.kind and a.part == b.part and (a.kind != "install" or (a.source or "bin") == (b.source or "bin"))


def check_evaluable(policy, bin_name: str = "") -> None:
    """Refuse, with a ``ValueError`` that says why, a policy whose exact value is not defined or not
    computable: one that chooses at random, or one that does not decide on the state alone."""
    name = getattr(policy, "name", policy)
    if getattr(policy, "deterministic", True) is False:
        raise ValueError(f"'{name}' chooses at random: its expected cost is not defined by one decision rule; "
                         f"estimate it with `opportune simulate{' --bin ' + bin_name if bin_name else ''}`")
    if getattr(policy, "choose_at", None) is None:
        raise ValueError(f"'{name}' cannot be evaluated exactly: it does not decide on the state alone (no choose_at)")


class Optimal:
    """The optimal online policy: at each look, the action of least expected total cost.

    Parameters
    ----------
    solver : OptimalSolver
        The optimum's programme for the plan and the world the policy acts in (its values are computed
        as the decisions need them, and kept).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.sequencer import Sequencer
    >>> plan = make_plan(["a", "b", "c"], {"c": ["a", "b"]})
    >>> policy = Optimal(OptimalSolver(OrderEngine(plan), visible=1, capacity=1))
    >>> [str(row.action) for row in Sequencer(plan, policy, buffer_capacity=1).run([["c"], ["a"], ["b"], []])]
    ['buffer c', 'install a', 'install b', 'install c (from buffer)', 'done']
    """

    name = "optimal"
    deterministic = True

    def __init__(self, solver: OptimalSolver):
        self.solver = solver

    def decide(self, state, visible) -> Decision:
        """The action of least expected remaining cost at the state on the look.

        Parameters
        ----------
        state : State
            The sequencer's state (in the solver's world: its plan, visible parts and buffer).
        visible : iterable of str
            The look.

        Returns
        -------
        Decision
            The action, with its expected remaining cost in the note.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.sequencer import Sequencer
        >>> plan = make_plan(["a", "b", "c"], {"c": ["a", "b"]})
        >>> state = Sequencer(plan, buffer_capacity=1).state
        >>> d = Optimal(OptimalSolver(OrderEngine(plan), visible=1, capacity=1)).decide(state, ["c"])
        >>> d.action, d.note
        (Action(kind='buffer', part='c', source=None), 'expected remaining cost 4.0000')
        """
        if state.is_complete:
            return Decision(DONE, "the assembly is complete")
        key = self.solver.key_of(state)
        look = tuple(sorted(self.solver.plan.index(p) for p in visible))
        action, cost = self.solver.best_action(key, look)
        return Decision(action, "least expected remaining cost", note=f"expected remaining cost {cost:.4f}")


def compiled_optimal_available(engine, weights: dict[str, float] | None = None, *, visible: int | None = None) -> bool:
    """Whether the compiled optimum takes this plan: the core is built (and not switched off with
    ``OPPORTUNE_PURE_PYTHON=1``), the weights (if any) are positive and finite, the plan has at most
    64 units and 64 strategies, and at most 2^62 buffer contents (the product of the quantities plus
    one: up to 62 parts of one unit), and in a weighted bin (weights that differ) at most
    :data:`COMPILED_WEIGHTED_VISIBLE` visible parts (``visible``; None: not asked).  O(parts).

    >>> from opportune import make_plan
    >>> compiled_optimal_available(OrderEngine(make_plan(["a", "b"], {})), {"a": 0.0})
    False
    """
    values = {float((weights or {}).get(p.id, 1.0)) for p in engine.plan.parts}
    valid = all(0.0 < w < float("inf") for w in values)
    if visible is not None and visible > COMPILED_WEIGHTED_VISIBLE and len(values) > 1:
        valid = False
    # a state's code is (installed, strategies) × buffer contents + contents: at most 2^62 contents
    contents = prod(p.quantity + 1 for p in engine.plan.parts)
    return (_native is not None and hasattr(_native, "OptimalCore") and valid and 1 <= engine.n_units <= 64
            and engine.k <= 64 and contents <= 1 << 62)


def optimum_bytes(states: int, keys: int, *, compiled: bool, weighted_looks: tuple[int, int] | None = None,
                  ways: bool = False) -> int:
    """The bytes the optimum's programme holds for ``states`` states over ``keys`` (installed,
    strategies) pairs, known before it starts: the compiled table reserved for the count (16-byte
    slots, a power of two at least twice the states, at least 1,024) and the pairs it interns, or
    :data:`~opportune.policies.states.BYTES_PER_STATE` a state in Python (plus the bounded look cache).
    ``weighted_looks``: in a weighted bin, ``(looks at the start, parts a look)``: the compiled
    programme's look cache adds at most :data:`COMPILED_LOOK_CACHE_BYTES` and the start's looks
    (:data:`COMPILED_LOOK_BYTES` each, the most any bin has).  ``ways``: on a plan written as ways the
    compiled programme keeps the sets it decided live or dead in a second table of as many slots
    (:func:`ways_table_bytes`).  O(log states).

    >>> optimum_bytes(3_000, 100, compiled=True)
    137472
    >>> optimum_bytes(3_000, 100, compiled=True, ways=True) - 137472
    131072
    >>> optimum_bytes(3_000, 100, compiled=True, weighted_looks=(10, 2)) - 137472
    4195780
    """
    if not compiled:
        from opportune.policies.states import BYTES_PER_STATE

        return states * BYTES_PER_STATE
    looks = 0
    if weighted_looks is not None:
        start, k = weighted_looks
        looks = COMPILED_LOOK_CACHE_BYTES + start * (COMPILED_LOOK_BYTES + k) + COMPILED_LOOK_ENTRY_BYTES
    return (2 if ways else 1) * ways_table_bytes(states) + COMPILED_PAIR_BYTES * keys + looks


def ways_table_bytes(states: int) -> int:
    """The bytes of a compiled table reserved for ``states`` values: 16-byte slots, a power of two at
    least twice the states, at least 1,024 (``src/native/memo_table.hpp``).  On a plan written as ways a
    compiled programme reserved for ``states`` keeps as many sets decided live or dead, in a table of as
    many bytes (forgotten whole when full: decided again).  O(log states).

    >>> ways_table_bytes(3_000)
    131072
    """
    slots = 1024
    while slots < 2 * states:
        slots *= 2
    return 16 * slots


def optimal_solver(engine: OrderEngine, *, merge: bool = True, **settings) -> OptimalSolver:
    """The optimum's programme: :class:`CompiledOptimalSolver` where the compiled core takes the plan
    and bin (see :func:`compiled_optimal_available`), else :class:`OptimalSolver`; the same values
    either way.  With ``merge`` (the default), on the plan with its interchangeable parts merged
    (:func:`~opportune.policies.interchangeable.merge_interchangeable`; fewer states, the same values
    to rounding), through a :class:`MergedOptimalSolver` whose decisions name the plan's parts.
    O(strategies × parts × units / 64) before the work.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    merge : bool
        Solve the plan with its interchangeable parts merged (fewer states).
    **settings
        As :class:`OptimalSolver`'s: ``visible``, ``capacity``, ``costs``, ``weights``, ``max_states``.

    Returns
    -------
    OptimalSolver
        The programme (compiled, merged or both where they apply); its values are computed as asked.

    Examples
    --------
    >>> from opportune import make_plan
    >>> round(optimal_solver(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), visible=1).value(), 4)
    2.5
    >>> screws = OrderEngine(make_plan(["base", "s1", "s2", "s3"], {"s1": ["base"], "s2": ["base"], "s3": ["base"]}))
    >>> merged, whole = optimal_solver(screws, capacity=1), optimal_solver(screws, capacity=1, merge=False)
    >>> round(merged.value(), 6) == round(whole.value(), 6), merged.states < whole.states
    (True, True)
    """
    if merge:
        merged = merge_interchangeable(engine, settings.get("costs"), settings.get("weights"))
        if merged.reduced:
            inner = dict(settings, weights=merged.weights(settings.get("weights")))
            return MergedOptimalSolver(engine, merged, _solver(merged.engine, inner), **settings)
    return _solver(engine, settings)


def optimum_engine(engine: OrderEngine, costs: TimeModel | None = None,
                   weights: dict[str, float] | None = None) -> OrderEngine:
    """The engine whose states :func:`optimal_solver` stores: the plan's with its interchangeable
    parts merged (``engine`` itself where none are), to size the programme before it starts
    (:func:`~opportune.policies.states.estimate_states`).  O(strategies × parts × units / 64) the
    first time, then cached.

    >>> from opportune import make_plan
    >>> optimum_engine(OrderEngine(make_plan(["a", "b"], {}))).plan.parts[0].quantity
    2
    """
    return merge_interchangeable(engine, costs, weights).engine


def _solver(engine: OrderEngine, settings: dict) -> OptimalSolver:
    """The compiled programme where the core takes the plan and bin, else the Python one."""
    if compiled_optimal_available(engine, settings.get("weights")):
        try:
            return CompiledOptimalSolver(engine, **settings)
        except ValueError:          # buffer contents over 64-bit codes, or too many visible: Python
            pass
    return OptimalSolver(engine, **settings)


class MergedOptimalSolver(OptimalSolver):
    """The optimum on a plan's own states and looks, its values those of the plan with interchangeable
    parts merged (``inner``, on ``merged.engine``; see :mod:`~opportune.policies.interchangeable`).

    Its moves, actions and keys are the plan's (a decision names the part seen); every value is the
    inner programme's at :meth:`~opportune.policies.interchangeable.Merged.key` of the state, so
    states that differ only by which of interchangeable parts are installed or buffered share one.
    Its states, bytes, reserve, deadline and state cap are the inner programme's.  O(parts) a value
    on top of the inner programme's work.
    """

    def __init__(self, engine: OrderEngine, merged, inner: OptimalSolver, **settings):
        super().__init__(engine, **settings)
        self.merged = merged
        self.inner = inner
        inner.progress = self._inner_progress

    def _inner_progress(self, _inner) -> None:
        if self.progress is not None:
            self.progress(self)

    @property
    def deadline(self) -> Deadline | None:
        """The inner programme's (see :attr:`OptimalSolver.deadline`)."""
        return self.inner.deadline

    @deadline.setter
    def deadline(self, value) -> None:
        self.inner.deadline = value

    def reserve(self, states: int) -> None:
        """The inner programme's room for ``states`` values (its count: on the merged plan)."""
        self.inner.reserve(states)

    @property
    def states(self) -> int:
        return self.inner.states

    @property
    def bytes(self) -> int | None:
        """The memory the inner compiled programme holds (None: the Python programme's is not measured)."""
        return getattr(self.inner, "bytes", None)

    def _value(self, key: tuple) -> float:
        return self.inner._value(self.merged.key(key))


class CompiledCore:
    """What the compiled optimum programmes share (:class:`CompiledOptimalSolver`, the pile's
    :class:`~opportune.policies.pile.CompiledPileSolver`): the plan in the core's terms, and the core's
    table (``self._core``) sized, counted and measured.  A mixin before an :class:`OptimalSolver`."""

    def _core_args(self) -> tuple:
        """The arguments every core takes first: units, parts' first units and quantities, the units below
        each unit per strategy, move costs, the look's and the shake's costs, visible, capacity (-1: none)."""
        engine = self.engine
        # a plan written as ways has no orders: one strategy with nothing below any unit, its ways given
        # after (:meth:`_give_ways`)
        below = [[int(b) for b in poset.below] for poset in engine.posets] or [[0] * engine.n_units]
        return (engine.n_units, list(engine.first), list(self.quantity), below, list(self.move),
                float(self.costs.look), float(self.costs.shake), self.visible, -1 if self.capacity is None else self.capacity)

    def _give_ways(self) -> None:
        """On a plan written as ways, its table to the core: each part's ways as a blockers mask and need
        masks (the core decides which sets have a completion, exactly, as
        :meth:`~opportune.engine.waysengine.WaysEngine.alive`).  O(ways)."""
        if self.plan.is_ways:
            self._core.set_ways(self.engine.table.ways)

    def reserve(self, states: int) -> None:
        """Make room for ``states`` values at once (the count from
        :func:`~opportune.policies.states.estimate_states`): no table doubling during the work."""
        self._core.reserve(int(states))

    @property
    def states(self) -> int:
        return self._core.states

    @property
    def bytes(self) -> int:
        """The memory the compiled programme holds (its table and interned pairs)."""
        return self._core.bytes

    def _report(self) -> None:
        """The progress report as the Python programme's: once per 64 more states (a call stores many)."""
        if self.progress is not None and self._core.states >= self._next_report:
            self._next_report = self._core.states + 64
            self.progress(self)


class CompiledOptimalSolver(CompiledCore, OptimalSolver):
    """The optimum of a uniform or weighted bin computed by the compiled core (``_native.OptimalCore``,
    ``src/native/optimal.cpp``): the recursion of :meth:`OptimalSolver._value` with the looks as order
    statistics (a weighted bin's looks enumerated once per bin content, as
    :meth:`OptimalSolver._look_distribution` does, in a cache of at most
    :data:`COMPILED_LOOK_CACHE_BYTES`), the same floating-point operations in the same order, so the
    same doubles.

    The same settings and methods; ``max_states`` bounds the stored values (:class:`OptimalTooLarge`),
    the ``deadline`` is read at every new state (:class:`OutOfTime`; what was finished stays).
    Memory: :func:`optimum_bytes` (32-64 bytes a state once :meth:`reserve` d, the pairs, and in a
    weighted bin the look cache).  A ``ValueError`` where the core does not take the plan
    (:func:`compiled_optimal_available`, or more than :data:`COMPILED_WEIGHTED_VISIBLE` visible in a
    weighted bin).  Complexity: O(states × parts × strategies), and O(states × looks × visible) in a
    weighted bin.
    """

    def __init__(self, engine: OrderEngine, **settings):
        super().__init__(engine, **settings)
        weights = None if self.uniform else dict(zip(self.ids, self.weights))
        if not compiled_optimal_available(engine, weights):
            raise ValueError("the compiled optimum needs the compiled core, positive weights and a plan of 1 to "
                             "64 units and at most 64 strategies")
        self._core = _native.OptimalCore(*self._core_args(), **self._core_options())
        self._give_ways()

    def _core_options(self) -> dict:
        """The core's settings after the plan's: the weights (none: a uniform bin) and the look cache's bytes."""
        return {"weights": [] if self.uniform else list(self.weights), "look_cache_bytes": COMPILED_LOOK_CACHE_BYTES}

    def _value(self, key: tuple) -> float:
        try:
            return self._core.value(key[0], key[1], list(key[2]), seconds=self._until.seconds(),
                                    max_states=self.max_states)
        except _native.OptimalCoreTimeout:
            raise OutOfTime("the optimum's programme passed its deadline") from None
        except _native.OptimalCoreTooLarge:
            raise OptimalTooLarge(
                f"the optimum needs more than {self.max_states:,} states for this plan; "
                "raise --optimal-states, or leave 'optimal' out of the strategies") from None
        except _native.OptimalCoreStuck as exc:
            raise RuntimeError(str(exc)) from None
        finally:
            self._report()
