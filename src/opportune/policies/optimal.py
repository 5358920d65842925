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
(``src/native/optimal.cpp``) with the same operations in the same order: the same doubles, about 25
times faster (25 to 30 in a weighted bin), at most 64 bytes a state (:func:`optimum_bytes`; and a
bounded look cache in a weighted bin); :func:`optimal_solver` picks it where the core is built (not
with ``OPPORTUNE_PURE_PYTHON=1``), on the plan with its interchangeable parts merged
(:mod:`.interchangeable`: parts no strategy, cost or weight tells apart counted as one part's units).

Bounds: the states stored never exceed ``max_states`` (:class:`OptimalTooLarge`), and a
``deadline`` (:class:`~opportune.engine.deadline.Deadline`) is read between states
(:class:`OutOfTime`; what was finished stays memoised, so a later call goes on from there).  How
many states a plan needs is known before the programme starts: :mod:`.states`.  Memory grows with
the states only: at most about :data:`~opportune.policies.states.BYTES_PER_STATE` bytes per state,
plus the look cache, which is bounded (:data:`LOOK_CACHE_LOOKS` looks in all; it used to keep every
bin's looks, ~20 kB per state on KILBRID).
"""

from __future__ import annotations

import sys
from functools import lru_cache
from math import comb, prod

from opportune.engine import OrderEngine, compiled_core
from opportune.engine.deadline import Deadline, as_deadline
from opportune.policies.base import DONE, SHAKE, Action, Decision
from opportune.policies.interchangeable import merge_interchangeable
from opportune.planning.costs import TimeModel

#: Looks (with their probabilities) the look cache keeps, over all the bin contents it holds: about
#: 150 bytes each, so at most about 30 MB whatever the plan (it used to grow with the states × looks).
LOOK_CACHE_LOOKS = 200_000

_native = compiled_core()   # None: the Python programme only

#: Bytes of an (installed, strategies) pair the compiled optimum interns: the pair in a vector and a
#: node of the hash map that finds it (what ``OptimalCore.bytes`` counts).
COMPILED_PAIR_BYTES = 64

#: The compiled optimum's cache of a weighted bin's looks (by bin content) holds at most this many
#: bytes, and is cleared whole before it would hold more (a bin's looks are enumerated again when needed).
COMPILED_LOOK_CACHE_BYTES = 4 << 20

#: Visible parts the compiled optimum of a weighted bin takes at most: a look is coded in 6 bits a part.
COMPILED_WEIGHTED_VISIBLE = 10

#: The compiled optimum of a weighted bin enumerates a bin's looks at every state (about 7 ns a look,
#: measured on 12 parts, 3 visible): the look-ahead takes it on plans of at most this many looks at the
#: start times states (the start has the most looks), about ten seconds' work like its uniform bin's
#: cap (:attr:`~opportune.policies.lookahead.Lookahead.COMPILED_STATES`).
COMPILED_WEIGHTED_LOOKS = 1_000_000_000

#: Bytes a look of a weighted bin takes in the compiled cache besides its parts (one byte each): its
#: probability (8), and while the bin's looks are enumerated, its sum and its sorted parts by code (128).
COMPILED_LOOK_BYTES = 136

#: Bytes a bin's entry takes in the compiled look cache (its hash node and vectors; ``ENTRY_BYTES``
#: in ``src/native/optimal.cpp``).
COMPILED_LOOK_ENTRY_BYTES = 96


class OptimalTooLarge(RuntimeError):
    """The state space is over the limit: the optimum is not computed."""


class OutOfTime(RuntimeError):
    """The programme passed its ``deadline``; the states it finished stay memoised."""


class OptimalSolver:
    """Exact minimum expected cost of assembling ``engine.plan`` from a Markov bin.

    ``weights`` gives per-part visibility weights (``None``: uniform bin).
    Complexity: O(states × parts) in a uniform bin (the looks as order statistics), else
    O(states × (looks × visible + parts)); states ≤ down-sets × buffer contents.
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
        as it goes: nothing to do here (the compiled programmes size their tables).  O(1)."""

    # ------------------------------------------------------------ states

    def start_key(self) -> tuple:
        return (0, self.engine.all_strategies, (0,) * len(self.ids))

    def key_of(self, state) -> tuple:
        """The solver's key for a sequencer :class:`~opportune.sequencer.State`."""
        return (state.schedule.mask, state.schedule.consistent, self.buffer_counts(state.buffer))

    def policy_key(self, mask: int, consistent: int, buffer) -> tuple:
        """The key a policy's programme keeps for a state: here the optimum's, with the buffer as counts
        (:class:`~opportune.policies.evaluate.PolicyEvaluator` keeps the buffer's order where the policy
        uses it)."""
        return (mask, consistent, self.buffer_counts(buffer))

    def policy_moves(self, key: tuple, look: tuple[int, ...]):
        """The moves of :meth:`_moves` between the keys of :meth:`policy_key` (here the same)."""
        return self._moves(key, look)

    def _buffered(self, key: tuple) -> tuple[str, ...]:
        """The buffer of a :meth:`policy_key` as the policy sees it (here in declaration order)."""
        return tuple(self.ids[i] for i, c in enumerate(key[2]) for _ in range(c))

    def buffer_counts(self, buffer) -> tuple[int, ...]:
        """The buffer as the solver keeps it: units buffered per part, in declaration order."""
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
            after = engine.consistent_after(mask, cons, u)
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
                after = engine.consistent_after(mask, cons, u)
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
        action = policy.choose_at(self.engine, mask, cons, buffer, free, tuple(ids[i] for i in look))
        if action.kind == "shake":
            return None
        for move in self.policy_moves(key, look):
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
        """Minimum expected remaining cost from a state (default: the start)."""
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
        after = self.engine.consistent_after(mask, cons, u)
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
        c_look, c_shake = self.costs.look, self.costs.shake
        acc_pm, acc_p, v = 0.0, 0.0, float("inf")
        for m, p in best_per_look:
            if m == float("inf"):
                break
            acc_pm += p * m
            acc_p += p
            v = min(v, (c_look + acc_pm + (1.0 - acc_p) * c_shake) / acc_p)
        if v == float("inf"):
            raise RuntimeError("no look allows any action: the assembly cannot proceed")
        return v

    @property
    def states(self) -> int:
        return len(self._values)

    def best_action(self, key: tuple, look: tuple[int, ...]) -> tuple[Action, float]:
        """The optimal action for a state and look (ties: install, then buffer, then declaration order)."""
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
    """The optimal online policy: at each look, the action of least expected total cost."""

    name = "optimal"
    deterministic = True

    def __init__(self, solver: OptimalSolver):
        self.solver = solver

    def decide(self, state, visible) -> Decision:
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


def optimum_bytes(states: int, keys: int, *, compiled: bool, weighted_looks: tuple[int, int] | None = None) -> int:
    """The bytes the optimum's programme holds for ``states`` states over ``keys`` (installed,
    strategies) pairs, known before it starts: the compiled table reserved for the count (16-byte
    slots, a power of two at least twice the states, at least 1,024) and the pairs it interns, or
    :data:`~opportune.policies.states.BYTES_PER_STATE` a state in Python (plus the bounded look cache).
    ``weighted_looks``: in a weighted bin, ``(looks at the start, parts a look)``: the compiled
    programme's look cache adds at most :data:`COMPILED_LOOK_CACHE_BYTES` and the start's looks
    (:data:`COMPILED_LOOK_BYTES` each, the most any bin has).  O(log states).

    >>> optimum_bytes(3_000, 100, compiled=True)
    137472
    >>> optimum_bytes(3_000, 100, compiled=True, weighted_looks=(10, 2)) - 137472
    4195780
    """
    if not compiled:
        from opportune.policies.states import BYTES_PER_STATE

        return states * BYTES_PER_STATE
    slots = 1024
    while slots < 2 * states:
        slots *= 2
    looks = 0
    if weighted_looks is not None:
        start, k = weighted_looks
        looks = COMPILED_LOOK_CACHE_BYTES + start * (COMPILED_LOOK_BYTES + k) + COMPILED_LOOK_ENTRY_BYTES
    return 16 * slots + COMPILED_PAIR_BYTES * keys + looks


def optimal_solver(engine: OrderEngine, *, merge: bool = True, **settings) -> OptimalSolver:
    """The optimum's programme: :class:`CompiledOptimalSolver` where the compiled core takes the plan
    and bin (see :func:`compiled_optimal_available`), else :class:`OptimalSolver`; the same values
    either way.  With ``merge`` (the default), on the plan with its interchangeable parts merged
    (:func:`~opportune.policies.interchangeable.merge_interchangeable`; fewer states, the same values
    to rounding), through a :class:`MergedOptimalSolver` whose decisions name the plan's parts.
    O(strategies × parts × units / 64) before the work.

    >>> from opportune import make_plan
    >>> round(optimal_solver(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), visible=1).value(), 4)
    2.5
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
        below = [[int(b) for b in poset.below] for poset in engine.posets]
        return (engine.n_units, list(engine.first), list(self.quantity), below, list(self.move),
                float(self.costs.look), float(self.costs.shake), self.visible, -1 if self.capacity is None else self.capacity)

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
