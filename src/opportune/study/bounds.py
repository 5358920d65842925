"""Certified lower bounds on the expected cost of any online policy: information relaxation with a penalty.

The optimum of :mod:`opportune.policies.optimal` is exact but needs every state of the plan; on plans of
45-111 parts nobody can compute it, so how far a policy is from the best possible is unknown.  This
module bounds the best possible from below, on any plan, by the duality of Brown, Smith & Sun
("Information relaxations and duality in stochastic dynamic programs", Operations Research 2010).

**The bin's randomness as exogenous noise.**  Before a trial, draw for every look index *t* = 0, 1, 2, ...
an independent key per unit of the plan: uniform on (0, 1) in the uniform bin, exponential of rate equal
to the part's visibility weight in the weighted bin.  The look at index *t* shows the ``visible`` units
still in the bin with the smallest keys (copies of a part are interchangeable: the *c* copies of a part
left in the bin are its slots 0 .. *c*-1).  Why any non-anticipative policy's cost has the same
distribution as in the model: the state at look *t* depends only on the keys of looks before *t*, and
the keys of look *t* are independent of them, so given the history the look shows a uniformly random
set of ``visible`` remaining units (uniform keys), or units drawn one after another with chance
proportional to their weights (the smallest of independent exponentials is each one's with chance
proportional to its rate, and the race starts afresh among the rest): exactly the bin's law, a fresh
look after every action, as in :class:`~opportune.worlds.bins.UniformBin` and
:class:`~opportune.worlds.bins.WeightedBin`.

**The bound.**  For any function *f(s, L)* of a state and a look, the penalty
``Σ_t f(s_t, L_t) − E[f(s_t, L) | s_t]`` has mean zero under every non-anticipative policy (each term
has mean zero given the past), so for every such policy ``E[cost] = E[cost − penalty] ≥ E[min over
action sequences of (cost − penalty)]``, the minimum taken with all the keys known (a deterministic
problem per trial).  With a value function *V̂* (zero at the end) and ``f(s, L) = m(s, L)``, the least
over the actions at *s* on look *L* of their cost plus *V̂* after them (a shake: ``c_shake + V̂(s)``),
the inner objective telescopes to ``V̂(s_0) + Σ_t w_t`` with, per look,

    w = [c(a) + V̂(s') − m(s, L)] + [c_look + E_L m(s, L) − V̂(s)]

The first bracket is ≥ 0 by the definition of *m*; the second is the Bellman residual of *V̂*, ≥ 0
exactly when *V̂* is a *subsolution* (``V̂ ≤ T V̂``).  Every penalty offered here is built from a
subsolution, so every step costs ≥ 0 and the inner problem is a shortest path with non-negative
lengths from the start over (look index, state) nodes.  It is solved by best-first search (A*, a node
ranked by its cost so far plus its own residual, which every step out of it pays): the first finished
node it takes off the queue is the exact minimum; if it stops at its node budget first, the least rank
on its queue is a lower bound of the minimum (every path to the end passes a queued node, and costs
only grow along it) — a relaxation of the inner problem, never a heuristic solution of it, so the
bound stays valid.  With the exact optimum's values (``penalty="optimal"``) the residual is
zero and the optimal action costs zero at every look: the bound equals the optimum on every trial.

**Penalties** (``penalty=``):

* ``"none"``: no penalty: the clairvoyant bound (the future of the bin known, nothing charged for it).
* ``"motions"``: *V̂* = the motions still needed (every unit not installed moves at least once).  Then
  ``m(s, L) = V̂(s)`` when a part can go in, and one more motion or a shake when none can, so the
  penalty charges each look the *chance* of being blocked instead of the blocking that happened:
  the inner problem keeps the clairvoyant's foresight of which parts come but loses its luck.
* ``"relaxed"``: *V̂* = the larger of the motions and the exact optimum of a relaxed plan read through a
  projection of the state (:mod:`opportune.study.relaxation`: the most-ordered parts kept with their
  common order, the others merged into free parts): a subsolution that charges the blocking the kept
  parts cause.  Its relaxed plan keeps as many parts as fit :data:`RELAXED_STATES` states
  (``relaxed_states=``); its mean over the looks is order statistics in a uniform bin.  Worth most with
  a limited buffer, where most parts fit.
* ``"optimal"``: the exact optimum's values (:class:`~opportune.policies.optimal.OptimalSolver`; plans
  whose optimum fits ``max_states``): the bound is the optimum, with no Monte Carlo spread (a check
  of the method, and of this implementation).
* ``"auto"`` (default): ``"optimal"`` where the optimum fits, else ``"relaxed"`` with a limited buffer and
  ``"motions"`` with an unlimited one (where the relaxed plan keeps few parts and adds little for its
  cost per node: docs/lower-bounds.md gives both, measured).

The inner search is exact when it finishes within ``node_budget`` expanded nodes; where it does not, the
trial's value is the queue's least cost (lower, still valid).  The result says how many trials were
solved exactly.  The Monte Carlo interval is the normal 95% interval of the trials' mean.

Bounds on hostile input, checked before any work: ``trials`` at most :data:`MAX_TRIALS`,
``node_budget`` at most :data:`MAX_NODE_BUDGET` (memory grows with the nodes: about 0.5 kB each),
the uniform and weighted bins only.  Time: O(trials × node_budget × (units + looks' moves)).

>>> from opportune import make_plan
>>> plan = make_plan(["a", "b", "c"], {"c": ["a", "b"]})
>>> r = lower_bound(plan, visible=1, trials=200, seed=0, penalty="optimal")
>>> round(r.mean, 6) == round(r.optimum, 6), r.half_width
(True, 0.0)
"""

from __future__ import annotations

import heapq
import math
import random
import statistics
import time
from dataclasses import dataclass, field
from math import comb

from opportune.engine import OrderEngine
from opportune.policies.optimal import OptimalSolver, OptimalTooLarge
from opportune.planning.costs import TimeModel

__all__ = ["BoundError", "BoundResult", "PENALTIES", "check_request", "describe_gaps", "inner_minimum", "lower_bound",
           "penalty_for", "policy_gaps"]

PENALTIES = ("auto", "none", "motions", "relaxed", "optimal")
BINS = ("uniform", "weighted")
MAX_TRIALS = 1_000_000
MAX_NODE_BUDGET = 5_000_000
#: States of the exact optimum ``penalty="auto"`` tries before it falls back to ``"motions"``.
AUTO_OPTIMAL_STATES = 200_000
#: States of the relaxed plan's optimum (``penalty="relaxed"``) with the compiled programme and with the Python
#: one (docs/lower-bounds.md gives the time and memory each takes at its limit).
RELAXED_STATES = 2_000_000
RELAXED_STATES_PYTHON = 100_000
#: Seconds (wall) one count of a relaxed plan's states may take: a safety, never the measure.  The count's work
#: is bounded by the budget (it stops past it), so a limit this generous is not reached and the parts kept
#: are the same on any machine; a count cut short says "does not fit", which is how a short limit once made
#: the choice depend on the machine's load (fewer of KILBRID's parts kept on a loaded machine).
RELAXED_COUNT_SECONDS = 120.0
#: Values and residuals the relaxed penalty keeps per state met (each memo about 40 MB when full; cleared past it).
PENALTY_MEMO = 200_000
#: The most ``relaxed_states`` accepts (about 1 GB in the compiled programme).
MAX_RELAXED_STATES = 20_000_000
Z95 = 1.959963984540054


class BoundError(ValueError):
    """A bound that cannot be computed as asked (a user mistake: the message says what to change).

    Raised by :func:`lower_bound` (and :func:`check_request`) before any work.

    Examples
    --------
    >>> from opportune import make_plan
    >>> try:
    ...     lower_bound(make_plan(["a", "b"], {"b": ["a"]}), bin="pile")
    ... except BoundError as exc:
    ...     print(exc)
    the bound is defined for the Markov bins (uniform, weighted), not 'pile': use --bin uniform or weighted
    """


@dataclass(frozen=True)
class BoundResult:
    """A certified lower bound on the expected cost of every online policy, with its Monte Carlo error.

    ``mean`` ± ``half_width`` is the 95% interval of the bound; ``values`` each trial's inner minimum
    (or its lower bound where the search stopped at its budget: ``trials - exact_trials`` of them);
    ``start_value`` is *V̂* at the start (itself a lower bound when the penalty's *V̂* is a subsolution);
    ``optimum`` the exact optimum where the penalty computed it (``penalty="optimal"``), else None.
    Made by :func:`lower_bound`; :attr:`low` and :attr:`high` are the interval's ends.

    Parameters
    ----------
    mean : float
        The bound: the mean of the trials' values.
    half_width : float
        Half the normal 95% interval of that mean.
    trials : int
        Trials (bins of keys) drawn.
    method : str
        How the bound was computed, in words (penalty, parts kept, trials solved exactly).
    penalty : str
        The penalty used (``auto`` resolved: ``none``, ``motions``, ``relaxed`` or ``optimal``).
    exact_trials : int
        Trials whose inner problem was solved exactly (the others are bounded below).
    nodes : int
        Nodes the inner searches expanded in all.
    seconds : float
        Wall seconds it took.
    start_value : float
        *V̂* at the start.
    optimum : float or None
        The exact optimum, where the penalty computed it.
    values : tuple of float
        Each trial's value.

    Examples
    --------
    >>> from opportune import make_plan
    >>> r = lower_bound(make_plan(["a", "b", "c"], {"c": ["a", "b"]}), visible=1, trials=20, penalty="motions")
    >>> r.low <= r.mean <= r.high, len(r.values) == r.trials == r.exact_trials == 20, r.penalty
    (True, True, 'motions')
    """

    mean: float
    half_width: float
    trials: int
    method: str
    penalty: str
    exact_trials: int
    nodes: int
    seconds: float
    start_value: float
    optimum: float | None = None
    values: tuple[float, ...] = field(default=(), repr=False)

    @property
    def low(self) -> float:
        return self.mean - self.half_width

    @property
    def high(self) -> float:
        return self.mean + self.half_width

    def to_dict(self) -> dict:
        """The result as plain data (what ``simulate --json`` writes), each trial's values left out.

        Returns
        -------
        dict
            ``mean``, ``half_width``, ``ci95`` (``[low, high]``), ``trials``, ``method``, ``penalty``,
            ``exact_trials``, ``nodes``, ``seconds``, ``start_value`` and ``optimum``.

        Examples
        --------
        >>> d = BoundResult(10.0, 0.5, 200, "m", "motions", 200, 1234, 0.25, 9.0).to_dict()
        >>> d["ci95"], d["optimum"], "values" in d
        ([9.5, 10.5], None, False)
        """
        return {"mean": self.mean, "half_width": self.half_width, "ci95": [self.low, self.high],
                "trials": self.trials, "method": self.method, "penalty": self.penalty,
                "exact_trials": self.exact_trials, "nodes": self.nodes, "seconds": self.seconds,
                "start_value": self.start_value, "optimum": self.optimum}


# ---------------------------------------------------------------- the bin's keys


class Keys:
    """The exogenous noise of one trial: per look index, the plan's unit slots in increasing key order.

    Slot ``(i, j)`` is copy *j* of part *i*; the look at index *t* with ``counts[i]`` copies of part *i*
    in the bin shows the first ``visible`` slots of look *t*'s order with ``j < counts[i]``.  Drawn
    lazily (one look's keys the first time it is asked for), from ``rng``.  O(units log units) per look.
    """

    def __init__(self, quantity: list[int], weights: list[float] | None, visible: int, rng: random.Random):
        self.slots = [(i, j) for i, q in enumerate(quantity) for j in range(q)]
        self.rates = None if weights is None else [weights[i] for i, _ in self.slots]
        self.visible = visible
        self.rng = rng
        self.orders: list[list[tuple[int, int]]] = []

    def order(self, t: int) -> list[tuple[int, int]]:
        orders = self.orders
        while len(orders) <= t:
            rnd = self.rng.random
            if self.rates is None:
                keys = [rnd() for _ in self.slots]
            else:   # exponential of rate w: -log(1 - U) / w (1 - U is never 0)
                keys = [-math.log(1.0 - rnd()) / w for w in self.rates]
            orders.append([s for _, s in sorted(zip(keys, self.slots))])
        return orders[t]

    def look(self, t: int, counts: tuple[int, ...]) -> tuple[int, ...]:
        """The look at index ``t`` from a bin holding ``counts[i]`` copies of part *i*: sorted part indices."""
        out = []
        k = self.visible
        for i, j in self.order(t):
            if j < counts[i]:
                out.append(i)
                if len(out) == k:
                    break
        return tuple(sorted(out))


# ---------------------------------------------------------------- penalties


class _Penalty:
    """A value function *V̂* (a subsolution) and its look term ``m(s, L)`` with its mean.

    ``start`` is *V̂* at the start; :meth:`look_terms` gives, for a state and a look, the moves
    ``(cost, next key)`` with each one's step cost ``w`` (≥ 0) and the shake's."""

    name = ""
    exact_optimum = False

    def __init__(self, solver: OptimalSolver):
        self.solver = solver
        self.costs = solver.costs
        engine = solver.engine
        # each part's units as (first bit, bit mask of its units): counts by popcount, not a loop over units
        self._units = [(first, (1 << q) - 1) for first, q in zip(engine.first, solver.quantity)]

    def installed_counts(self, mask: int) -> list[int]:
        """Units installed per part."""
        return [(mask >> first & ones).bit_count() for first, ones in self._units]

    def bin_counts(self, key) -> tuple[int, ...]:
        """Units in the bin per part (neither installed nor buffered)."""
        mask, _, buf = key
        return tuple(q - (mask >> first & ones).bit_count() - b
                     for q, (first, ones), b in zip(self.solver.quantity, self._units, buf))

    def value(self, key) -> float:
        raise NotImplementedError

    def look_term(self, key, look, moves) -> float:
        """``f(s, L)``: here the least of each move's cost plus *V̂* after it, and the shake's."""
        v = self.value
        best = self.costs.shake + v(key)
        for c, nxt, _ in moves:
            x = c + v(nxt)
            if x < best:
                best = x
        return best

    def mean_look_term(self, key) -> float:
        """``E_L f(s, L)`` in a uniform bin without enumerating the looks: *f* is the least of the visible
        parts' own best moves, of the buffer's best installation and of the shake, so with the bin's units
        ranked by their part's best move, the part whose ``c`` units hold ranks ``r + 1 .. r + c`` of ``n``
        is the best visible one with chance ``(C(n − r, k) − C(n − r − c, k)) / C(n, k)`` (as the optimum's
        programme does).  O(parts) values of *V̂*."""
        s, v, move = self.solver, self.value, self.solver.move
        mask, cons, buf = key
        engine = s.engine
        free = s.capacity is None or sum(buf) < s.capacity
        shared = self.costs.shake + v(key)     # the shake and the buffer's installations: on every look
        for i, nxt in s._buffer_installs(mask, cons, buf):
            shared = min(shared, move[i] + v(nxt))
        ranked, n = [], 0
        for i, c in enumerate(self.bin_counts(key)):
            if c <= 0:
                continue
            n += c
            best = math.inf
            u = engine.next_unit(mask, i)
            after = engine.consistent_after(mask, cons, u)
            if after:
                best = move[i] + v((mask | 1 << u, after, buf))
            if free:
                best = min(best, move[i] + v((mask, cons, buf[:i] + (buf[i] + 1,) + buf[i + 1:])))
            ranked.append((best, c))
        if n == 0:
            return shared
        ranked.sort()
        k = min(s.visible, n)
        total, rank, mean = comb(n, k), 0, 0.0
        for best, c in ranked:
            mean += (comb(n - rank, k) - comb(n - rank - c, k)) / total * min(best, shared)
            rank += c
        return mean

    def residual(self, key) -> float:
        """``c_look + E_L f(s, L) − V̂(s)`` (≥ 0 for a subsolution): by enumerating the looks."""
        s = self.solver
        total = 0.0
        for look, p in s._looks(self.bin_counts(key)):
            total += p * self.look_term(key, look, list(s._moves(key, look)))
        return self.costs.look + total - self.value(key)


class _NoPenalty(_Penalty):
    """The clairvoyant bound: *V̂* = 0, f = 0 (each step costs its look and its action)."""

    name = "none"

    def value(self, key) -> float:
        return 0.0

    def look_term(self, key, look, moves) -> float:
        return 0.0

    def residual(self, key) -> float:
        return self.costs.look


class _Motions(_Penalty):
    """*V̂* = the motions the units not yet installed still need (the bin's and the buffer's).

    A subsolution: an install keeps ``c + V̂`` at *V̂(s)*; a buffer or a shake adds its cost.  So
    ``m(s, L) = V̂(s) + extra(L)``, extra 0 when a visible or buffered part can go in, else the cheaper
    of a shake and buffering a visible part (when a location is free).  Its mean over the looks is
    closed-form in the uniform bin with equal motions (the chance no visible unit is installable,
    hypergeometric); else the looks are enumerated."""

    name = "motions"

    def __init__(self, solver: OptimalSolver):
        super().__init__(solver)
        self.uniform_costs = not self.costs.parts and all(w == 1.0 for w in solver.weights)
        self.n_units = solver.engine.n_units
        self._installable: dict = {}

    def value(self, key) -> float:
        if self.uniform_costs:
            return self.costs.motion * (self.n_units - key[0].bit_count())
        s = self.solver
        return sum((q - c) * m for q, c, m in zip(s.quantity, self.installed_counts(key[0]), s.move))

    def _can_install(self, key) -> list[bool]:
        """Per part: whether its next unit can go in now."""
        got = self._installable.get(key[:2])
        if got is None:
            mask, cons, _ = key
            e = self.solver.engine
            got = []
            for i in range(len(self.solver.ids)):
                u = e.next_unit(mask, i)
                got.append(u is not None and e.consistent_after(mask, cons, u) != 0)
            if len(self._installable) > 200_000:
                self._installable.clear()
            self._installable[key[:2]] = got
        return got

    def _extra(self, key, look) -> float:
        ok = self._can_install(key)
        if any(ok[i] for i in look) or any(c and ok[i] for i, c in enumerate(key[2])):
            return 0.0
        s = self.solver
        extra = self.costs.shake
        if look and (s.capacity is None or sum(key[2]) < s.capacity):
            extra = min(extra, min(s.move[i] for i in look))
        return extra

    def look_term(self, key, look, moves) -> float:
        return self.value(key) + self._extra(key, look)

    def residual(self, key) -> float:
        if not self.uniform_costs:
            return super().residual(key)
        ok = self._can_install(key)
        if any(c and ok[i] for i, c in enumerate(key[2])):
            return self.costs.look
        s = self.solver
        counts = self.bin_counts(key)
        b = sum(counts)
        k = min(s.visible, b)
        a = sum(c for c, good in zip(counts, ok) if good)
        blocked = comb(b - a, k) / comb(b, k)
        extra = self.costs.shake
        if k and (s.capacity is None or sum(key[2]) < s.capacity):
            extra = min(extra, self.costs.motion)
        return self.costs.look + blocked * extra


class _Relaxed(_Penalty):
    """*V̂* = the larger of the motions still needed and the exact optimum of a relaxed plan read through
    its projection (:mod:`opportune.study.relaxation`): a subsolution, and one that knows the plan's
    order, so it charges the blocking the kept parts cause.  Its mean over the looks: order statistics
    in a uniform bin (O(parts) values a state), else the looks enumerated."""

    name = "relaxed"

    def __init__(self, solver: OptimalSolver, relaxation, relaxed_solver: OptimalSolver):
        super().__init__(solver)
        self.motions = _Motions(solver)
        self.relaxation = relaxation
        self.relaxed = relaxed_solver
        self._cache: dict = {}
        self._residuals: dict = {}

    def value(self, key) -> float:
        got = self._cache.get(key)
        if got is None:
            got = max(self.motions.value(key), self.relaxed.value(self.relaxation.project(key)))
            if len(self._cache) > PENALTY_MEMO:     # a bounded memo: the values are recomputed, never wrong
                self._cache.clear()
            self._cache[key] = got
        return got

    def residual(self, key) -> float:
        got = self._residuals.get(key)
        if got is None:     # the trials' searches meet the same states near the start: each solved once
            if self.solver.uniform:
                got = self.costs.look + self.mean_look_term(key) - self.value(key)
            else:
                got = super().residual(key)
            if len(self._residuals) > PENALTY_MEMO:
                self._residuals.clear()
            self._residuals[key] = got
        return got


class _Optimal(_Penalty):
    """*V̂* = the exact optimum's values: a solution of the Bellman equation, so the residual is zero."""

    name = "optimal"
    exact_optimum = True

    def value(self, key) -> float:
        return self.solver.value(key)

    def residual(self, key) -> float:
        return 0.0


# ---------------------------------------------------------------- the inner problem


def inner_minimum(solver: OptimalSolver, penalty: _Penalty, keys: Keys, node_budget: int,
                  max_looks: int) -> tuple[float, bool, int]:
    """The least penalised cost of finishing the assembly on one trial's keys, or a lower bound of it.

    Best-first search (A*) over (look index, state) nodes from the start, every step's cost ``w`` ≥ 0 (see
    the module's docstring), each node ranked by its cost so far plus its own Bellman residual (a part of
    every step out of it: an estimate of the rest that never exceeds it); ties go to the deeper node.
    Returns ``(value, exact, nodes expanded)``: exact when a finished node came off the queue within
    ``node_budget`` expansions, else the least rank on the queue (a lower bound: every way to the end
    passes a queued node, and its cost from there is at least the node's residual).  Looks past ``max_looks`` are not
    expanded (their nodes stay on the queue, so the value stays a lower bound).  O(node_budget × (units +
    moves per look) × log nodes) time, O(nodes) memory.

    Parameters
    ----------
    solver : OptimalSolver
        The world: plan, visible parts, buffer, costs and weights.
    penalty : penalty
        What :func:`penalty_for` gives for ``solver``.
    keys : Keys
        The trial's keys (its looks).
    node_budget : int
        Most nodes expanded.
    max_looks : int
        Looks past which no node is expanded (a guard against a search that never ends).

    Returns
    -------
    tuple of (float, bool, int)
        ``(value, exact, nodes expanded)``.

    Raises
    ------
    AssertionError
        When a step costs less than nothing: the penalty's value is not a subsolution (a defect).
    RuntimeError
        When no way finishes the assembly (unreachable: every state has a move on some look).

    Examples
    --------
    With the optimum's values every trial's minimum is the optimum; cut short, the value is lower:

    >>> import random
    >>> from opportune import make_plan
    >>> solver = OptimalSolver(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]})), visible=1)
    >>> keys = Keys(list(solver.quantity), None, 1, random.Random(0))
    >>> value, exact, _ = inner_minimum(solver, penalty_for("optimal", solver), keys, 1000, 100)
    >>> round(value, 9) == round(solver.value(), 9), exact
    (True, True)
    >>> cut = inner_minimum(solver, penalty_for("none", solver), keys, 1, 100)
    >>> cut[0] <= inner_minimum(solver, penalty_for("none", solver), keys, 1000, 100)[0], cut[1]
    (True, False)
    """
    engine = solver.engine
    full = engine.full
    start = solver.start_key()
    base = penalty.value(start)
    shake = solver.costs.shake
    resid = penalty.residual
    # the queue holds (g + h, -t, order, g, key): h = the node's own residual, a part of every step out of it
    heap = [(resid(start), 0, 0, 0.0, start)]
    best_g: dict = {(0, start): 0.0}
    expanded = 0
    v = penalty.value
    while heap:
        priority, negt, _, g, key = heapq.heappop(heap)
        t = -negt
        if best_g.get((t, key), math.inf) < g:
            continue
        if key[0] == full:
            return base + g, True, expanded
        if expanded >= node_budget or t >= max_looks:
            heapq.heappush(heap, (priority, negt, 0, g, key))
            return base + min(h[0] for h in heap), False, expanded
        expanded += 1
        look = keys.look(t, penalty.bin_counts(key))
        moves = list(solver._moves(key, look))
        f = penalty.look_term(key, look, moves)
        own = priority - g
        steps = [(c + v(nxt), nxt) for c, nxt, _ in moves]
        steps.append((shake + v(key), key))
        for after, nxt in steps:
            step = after - f + own
            if step < -1e-9:
                raise AssertionError(f"a step of cost {step} < 0: the penalty's value is not a subsolution")
            ng = g + max(0.0, step)
            node = (t + 1, nxt)
            if ng < best_g.get(node, math.inf):
                best_g[node] = ng
                heapq.heappush(heap, (ng + (0.0 if nxt[0] == full else resid(nxt)), -(t + 1), expanded, ng, nxt))
    raise RuntimeError("no way to finish the assembly")  # every state has a move on some look: unreachable


# ---------------------------------------------------------------- the bound


def check_request(plan, *, visible: int = 2, capacity: int | None = None, bin: str = "uniform", trials: int = 200,
                  penalty: str = "auto", node_budget: int = 5_000, weights: dict[str, float] | None = None,
                  relaxed_states: int | None = None, max_states: int = AUTO_OPTIMAL_STATES,
                  engine: OrderEngine | None = None) -> dict[str, float] | None:
    """Refuse, before any work, a bound :func:`lower_bound` cannot compute as asked: a :class:`BoundError`
    saying what to change.  Also ``penalty="optimal"`` on a plan whose optimum needs more than ``max_states``
    states (counted, within 2 s, never solved), so a command refuses it before its study.

    Parameters
    ----------
    plan : Plan
        The plan.
    visible, capacity, bin, trials, penalty, node_budget, weights, relaxed_states, max_states, engine
        As for :func:`lower_bound`.

    Returns
    -------
    dict of str to float or None
        The weighted bin's weights (default: the plan's visibilities), None for the uniform bin.

    Raises
    ------
    BoundError
        What to change, for the first thing that cannot be served.

    Examples
    --------
    >>> from opportune import make_plan
    >>> plan = make_plan(["a", "b"], {"b": ["a"]})
    >>> check_request(plan), check_request(plan, bin="weighted")
    (None, {'a': 1.0, 'b': 1.0})
    >>> from opportune import load_plan
    >>> try:
    ...     check_request(load_plan("salbp:KILBRID"), penalty="optimal")
    ... except BoundError as exc:
    ...     print(exc)
    the optimum's values need more than 200,000 states on this plan: use penalty 'relaxed' or 'motions' (or 'auto'), or, in the library, a larger max_states
    """
    if visible is None or isinstance(visible, bool) or not isinstance(visible, int) or visible < 1:
        raise BoundError(f"visible must be a whole number ≥ 1, not {visible!r}")
    if capacity is not None and (isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 0):
        raise BoundError(f"capacity must be a whole number ≥ 0 or None (unlimited), not {capacity!r}")
    if bin not in BINS:
        raise BoundError(f"the bound is defined for the Markov bins ({', '.join(BINS)}), not '{bin}': "
                         "use --bin uniform or weighted")
    if isinstance(trials, bool) or not isinstance(trials, int) or not 2 <= trials <= MAX_TRIALS:
        raise BoundError(f"trials must be a whole number from 2 to {MAX_TRIALS:,} (for an interval), not {trials!r}")
    if isinstance(node_budget, bool) or not isinstance(node_budget, int) or not 1 <= node_budget <= MAX_NODE_BUDGET:
        raise BoundError(f"node_budget must be a whole number from 1 to {MAX_NODE_BUDGET:,}, not {node_budget!r}")
    if penalty not in PENALTIES:
        raise BoundError(f"unknown penalty '{penalty}': choose from {', '.join(PENALTIES)}")
    if relaxed_states is not None and (isinstance(relaxed_states, bool) or not isinstance(relaxed_states, int)
                                       or not 1 <= relaxed_states <= MAX_RELAXED_STATES):
        raise BoundError(f"relaxed_states must be a whole number from 1 to {MAX_RELAXED_STATES:,}, "
                         f"not {relaxed_states!r}")
    if bin == "weighted":
        weights = weights if weights is not None else {p.id: p.visibility for p in plan.parts}
        bad = [p for p, w in weights.items() if not (isinstance(w, (int, float)) and w > 0 and math.isfinite(w))]
        if bad:
            raise BoundError(f"the weighted bin needs a positive visibility for every part ('{bad[0]}' has "
                             f"{weights[bad[0]]!r})")
    else:
        weights = None
    if penalty == "optimal" and not _optimum_fits(engine or OrderEngine(plan), visible, capacity, max_states):
        raise BoundError(f"the optimum's values need more than {max_states:,} states on this plan: "
                         "use penalty 'relaxed' or 'motions' (or 'auto'), or, in the library, a larger max_states")
    return weights


def _optimum_fits(engine: OrderEngine, visible: int, capacity: int | None, max_states: int) -> bool:
    """Whether the optimum's states are counted, within 2 s, to at most ``max_states``."""
    from opportune.policies.states import estimate_states

    est = estimate_states(engine, visible=visible, capacity=capacity, stop_above=max_states, time_limit=2.0)
    return est.exact and est.states <= max_states


def lower_bound(plan, *, visible: int = 2, capacity: int | None = None, bin: str = "uniform", trials: int = 200,
                seed: int = 0, penalty: str = "auto", costs: TimeModel | None = None,
                weights: dict[str, float] | None = None, node_budget: int = 5_000,
                max_states: int = AUTO_OPTIMAL_STATES, engine: OrderEngine | None = None,
                relaxed_states: int | None = None) -> BoundResult:
    """A lower bound on the expected cost of every online policy on ``plan``, with its 95% interval.

    ``visible``, ``capacity``, ``bin`` and ``costs`` are the world's, as in ``opportune simulate``.
    Trial *i* draws its keys from its own stream of ``seed``: the same seed gives the same numbers.
    Time: O(trials × node_budget × (units + moves per look)); memory O(node_budget) nodes at a time
    (plus the optimum's states with ``penalty="optimal"``).

    Parameters
    ----------
    plan : Plan
        The plan (its ``simulation.costs`` and parts' visibilities are the defaults below).
    visible : int
        Parts the camera sees in a look (at least 1).
    capacity : int or None
        Buffer locations (None: unlimited).
    bin : str
        ``"uniform"`` or ``"weighted"`` (the Markov bins, where the bound is defined).
    trials : int
        Bins of keys drawn, 2 to :data:`MAX_TRIALS`.
    seed : int
        Seed of the trials' keys.
    penalty : str
        One of :data:`PENALTIES` (see the module's docstring).
    costs : TimeModel or None
        The costs of a look, a motion and a shake (None: the plan's ``simulation.costs``).
    weights : dict of str to float or None
        Part id → visibility in the weighted bin (None: the plan's).
    node_budget : int
        Nodes the inner search of one trial expands at most, 1 to :data:`MAX_NODE_BUDGET` (past it the
        trial's value is a lower bound of its inner minimum).
    max_states : int
        States of the exact optimum the ``optimal`` penalty may use.
    engine : OrderEngine or None
        The plan's order engine, to share its counts (None: a new one).
    relaxed_states : int or None
        States of the relaxed plan's optimum the ``relaxed`` penalty may use (None:
        :data:`RELAXED_STATES`, or :data:`RELAXED_STATES_PYTHON` where the compiled programme does
        not take the plan).

    Returns
    -------
    BoundResult
        The bound, its interval, and how it was computed.

    Raises
    ------
    BoundError
        A request that cannot be served, before any work, with what to change.

    Examples
    --------
    >>> from opportune import load_plan
    >>> r = lower_bound(load_plan("example:gearbox"), visible=2, trials=50, penalty="motions")
    >>> 10.0 <= r.mean <= 13.5725 and r.exact_trials == 50          # below the optimum, 13.5711
    True
    >>> lower_bound(load_plan("example:gearbox"), visible=0)
    Traceback (most recent call last):
    ...
    opportune.study.bounds.BoundError: visible must be a whole number ≥ 1, not 0
    """
    weights = check_request(plan, visible=visible, capacity=capacity, bin=bin, trials=trials, penalty=penalty,
                            node_budget=node_budget, weights=weights, relaxed_states=relaxed_states,
                            max_states=max_states, engine=engine)
    began = time.perf_counter()
    costs = costs if costs is not None else TimeModel.from_plan(plan)
    engine = engine or OrderEngine(plan)
    solver = OptimalSolver(engine, visible=visible, capacity=capacity, costs=costs, weights=weights,
                           max_states=max_states)
    pen = penalty_for(penalty, solver, relaxed_states)
    optimum = None
    if pen.exact_optimum:
        optimum = solver.value()
    quantity = list(solver.quantity)
    wlist = None if weights is None else list(solver.weights)
    max_looks = 1000 + 200 * engine.n_units * engine.n_units   # simulate's step limit: a hang guard
    values, exact, nodes = [], 0, 0
    for trial in range(trials):
        keys = Keys(quantity, wlist, visible, random.Random(f"bound:{seed}:{trial}"))
        value, done, n = inner_minimum(solver, pen, keys, node_budget, max_looks)
        values.append(value)
        exact += done
        nodes += n
    mean = statistics.fmean(values)
    half = Z95 * statistics.stdev(values) / math.sqrt(trials)
    solved = ("each inner problem solved exactly" if exact == trials else
              f"{exact} inner problems solved exactly, {trials - exact} bounded at {node_budget:,} nodes")
    detail = {"none": " (the clairvoyant bound)"}.get(pen.name, "")
    if isinstance(pen, _Relaxed):
        detail = (f" ({len(pen.relaxation.kept)} of {len(solver.ids)} parts kept, {pen.relaxed.states:,} states, "
                  f"{pen.value(solver.start_key()):.4g} at the start)")
    method = (f"information relaxation (Brown, Smith & Sun 2010), {pen.name!r} penalty{detail}, {trials} trials, "
              f"{solved}")
    return BoundResult(mean, half, trials, method, pen.name, exact, nodes, time.perf_counter() - began,
                       pen.value(solver.start_key()), optimum, tuple(values))


def penalty_for(name: str, solver: OptimalSolver, relaxed_states: int | None = None) -> _Penalty:
    """The penalty named ``name`` (one of :data:`PENALTIES`) for the world of ``solver``; ``auto``: the optimum's
    where it fits within ``solver.max_states``, else the relaxed plan's with a limited buffer and the motions
    with an unlimited one (see the module's docstring).  A penalty gives *V̂* (``value(key)``), the look
    term *f* (``look_term(key, look, moves)``) and the Bellman residual ``c_look + E_L f − V̂`` (``residual(key)``)
    for the solver's state keys.

    Parameters
    ----------
    name : str
        One of :data:`PENALTIES`.
    solver : OptimalSolver
        The world: plan, visible parts, buffer, costs and weights.
    relaxed_states : int or None
        As for :func:`lower_bound`.

    Returns
    -------
    penalty
        The value function, its look term and its residual.

    Raises
    ------
    BoundError
        When the penalty cannot be built as asked (the optimum or the relaxed plan does not fit).

    Examples
    --------
    >>> from opportune import load_plan
    >>> solver = OptimalSolver(OrderEngine(load_plan("example:gearbox")), visible=2)
    >>> pen = penalty_for("relaxed", solver)
    >>> round(pen.value(solver.start_key()), 4), abs(pen.residual(solver.start_key())) < 1e-9
    (13.5711, True)
    """
    if name == "none":
        return _NoPenalty(solver)
    if name == "motions":
        return _Motions(solver)
    if name == "relaxed":
        return _relaxed_penalty(solver, relaxed_states)
    fits = _optimum_fits(solver.engine, solver.visible, solver.capacity, solver.max_states)
    if name == "auto":
        if fits:
            return _Optimal(solver)
        return _Motions(solver) if solver.capacity is None else _relaxed_penalty(solver, relaxed_states)
    if not fits:
        raise BoundError(f"the optimum's values need more than {solver.max_states:,} states on this plan: "
                         "use penalty 'relaxed' or 'motions' (or 'auto'), or, in the library, a larger max_states")
    try:
        solver.value()
    except OptimalTooLarge as exc:
        raise BoundError(f"{exc}") from None
    return _Optimal(solver)


def _relaxed_penalty(solver: OptimalSolver, budget: int | None = None) -> _Relaxed:
    """The ``relaxed`` penalty: the most-ordered parts kept, as many as keep the relaxed plan's states within
    :data:`RELAXED_STATES` (:data:`RELAXED_STATES_PYTHON` where the compiled programme does not take it),
    found by bisection on the states counted before any is solved; then the relaxed optimum solved whole.
    O(log parts) counts, then the relaxed programme's states."""
    from opportune.policies.optimal import compiled_optimal_available, optimal_solver
    from opportune.policies.states import estimate_states
    from opportune.study.relaxation import ranked_parts, relax_plan

    engine = solver.engine
    weights = {p: w for p, w in zip(solver.ids, solver.weights)}
    if budget is None:
        budget = RELAXED_STATES if compiled_optimal_available(engine, weights) else RELAXED_STATES_PYTHON
    ranked = ranked_parts(engine)

    def relaxed(k: int):
        r = relax_plan(engine.plan, ranked[:k], solver.costs, weights, engine)
        r_engine = OrderEngine(r.plan)
        est = estimate_states(r_engine, visible=solver.visible, capacity=solver.capacity, stop_above=budget,
                              time_limit=RELAXED_COUNT_SECONDS)
        return r, r_engine, est.exact and est.states <= budget

    best = relaxed(0)
    if not best[2]:
        raise BoundError(f"the relaxed plan needs more than {budget:,} states even with no order kept: allow more "
                         "relaxed states, or use penalty 'motions'")
    low, high = 0, len(ranked)          # low: a count that fits
    while low < high:
        mid = (low + high + 1) // 2
        got = relaxed(mid)
        if got[2]:
            low, best = mid, got
        else:
            high = mid - 1
    r, r_engine, _ = best
    r_solver = optimal_solver(r_engine, visible=solver.visible, capacity=solver.capacity, costs=r.costs,
                              weights=r.weights, max_states=budget)
    r_solver.value()
    return _Relaxed(solver, r, r_solver)


# ---------------------------------------------------------------- policies against the bound


#: Standard errors of a mean below the bound beyond which it is called a defect, not noise (one study in
#: about 30,000 goes that far by chance); within the 95% intervals (1.96) it is plain noise.
DEFECT_SE = 4.0


def policy_gaps(bound: BoundResult, times: dict[str, dict]) -> dict[str, dict]:
    """Each policy's mean time against the bound: the signed gap and, for a mean below it, why.

    ``times`` maps a policy's name to its time's statistics (``mean`` and ``ci95``, the normal 95%
    interval, as in ``simulate --json``).  ``gap`` is ``mean / bound − 1``: positive above the bound,
    negative below.  No online policy's *expected* time is below the bound, so a *mean* below it is
    sampling noise or a defect: ``z`` is how many standard errors (the mean's and the bound's, combined)
    it lies below, and ``below`` says ``"noise"`` (z ≤ 1.96: the 95% intervals overlap), ``"rare"`` (up to
    :data:`DEFECT_SE`: noise a 95% interval shows about once in 40 studies) or ``"defect"`` (beyond).
    Policies without a mean are left out.

    Parameters
    ----------
    bound : BoundResult
        The bound.
    times : dict of str to dict
        Policy name → its time's statistics (``mean``, ``ci95``).

    Returns
    -------
    dict of str to dict
        Policy name → ``mean``, ``gap``, ``below`` (None above the bound) and ``z``.

    Examples
    --------
    >>> r = BoundResult(10.0, 0.1, 200, "m", "motions", 200, 0, 0.0, 9.0)
    >>> gaps = policy_gaps(r, {"a": {"mean": 11.0, "ci95": [10.9, 11.1]}, "b": {"mean": 9.95, "ci95": [9.8, 10.1]},
    ...                        "c": {"mean": 9.5, "ci95": [9.45, 9.55]}})
    >>> [(name, round(g["gap"], 3), g["below"]) for name, g in gaps.items()]
    [('a', 0.1, None), ('b', -0.005, 'noise'), ('c', -0.05, 'defect')]
    """
    out = {}
    for name, t in times.items():
        mean = t.get("mean")
        if mean is None or not bound.mean > 0:
            continue
        gap = mean / bound.mean - 1
        below = z = None
        if mean < bound.mean:
            low, high = t.get("ci95") or [mean, mean]
            se = math.hypot((high - low) / 2, bound.half_width) / Z95
            z = math.inf if se == 0 else (bound.mean - mean) / se
            below = "noise" if z <= Z95 else "rare" if z <= DEFECT_SE else "defect"
        out[name] = {"mean": mean, "gap": gap, "below": below, "z": z}
    return out


def describe_gaps(gaps: dict[str, dict]) -> str:
    """:func:`policy_gaps` in words: ``lookahead 0.2% below; paper 1.0% above``, then what each mean below
    the bound means (one sentence per kind).

    Parameters
    ----------
    gaps : dict of str to dict
        What :func:`policy_gaps` gives.

    Returns
    -------
    str
        The sentences.

    Examples
    --------
    >>> print(describe_gaps({"a": {"gap": 0.1, "below": None, "z": None},
    ...                      "b": {"gap": -0.002, "below": "noise", "z": 0.5}}))
    a 10.0% above; b 0.2% below. b below the bound is sampling noise: no online policy's expected time is below it, and b's 95% interval reaches the bound's
    """
    words = "; ".join(f"{name} {abs(100 * g['gap']):.1f}% {'below' if g['gap'] < 0 else 'above'}"
                      for name, g in gaps.items())
    kinds = {kind: [name for name, g in gaps.items() if g["below"] == kind] for kind in ("noise", "rare", "defect")}
    if kinds["noise"]:
        owners = _names([name + "'s" for name in kinds["noise"]])
        words += (f". {_names(kinds['noise'])} below the bound is sampling noise: no online policy's expected time "
                  f"is below it, and {owners} 95% interval reaches the bound's")
    if kinds["rare"]:
        z = max(gaps[n]["z"] for n in kinds["rare"])
        by = f"{'up to ' if len(kinds['rare']) > 1 else ''}{z:.1f}"
        words += (f". {_names(kinds['rare'])} below the bound by {by} standard errors: sampling noise of a "
                  "kind a 95% interval shows about once in 40 studies (more --trials or another --seed tells; beyond "
                  f"{DEFECT_SE:g} it would be a defect)")
    if kinds["defect"]:
        words += (f". {_names(kinds['defect'])} below the bound by more than {DEFECT_SE:g} standard errors: not "
                  "noise but a defect of the bound or of the simulation; please report it with this command line")
    return words


def _names(names: list[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
