"""Rational relaxation of an over-constrained plan: the cheapest set of constraints to drop.

The paper asks that "in problems which are over constrained, the selected times must at least
conform to a rational relaxation of the given constraints".  A plan is over-constrained when it has
no admissible sequence: a strategy's constraints form a cycle, or (given the parts already
installed) no strategy admits the installed prefix.  Each declared constraint ``before -> after``
carries a weight, the price of dropping it (``{part: ID, weight: W}`` in a plan file; default 1), and
the relaxation drops a set of declared constraints of minimum total weight.

For one strategy this is the minimum-weight *feedback arc set* of its constraint graph
(:func:`min_feedback_arc_set`), solved exactly, one strongly connected component at a time (a
constraint between two components lies on no cycle and is never dropped):

* a component of at most :data:`DP_FIRST_PARTS` parts by a dynamic programme over subsets: the
  cheapest order of the component, where dropping means the constraints that point backwards
  (O(2^k · k) for k parts);
* a larger one by branch and bound on a growing family of cycles: the cheapest set of constraints
  that meets every cycle found so far (an exact minimum-weight hitting set, bounded below by
  sharing each cycle's price among its constraints), checked against the whole component; the
  cycles that survive it join the family, until the answer leaves no cycle (then it is minimal) or
  no set meets the family more cheaply than the best complete answer known (then that one is).
  Knots of real plans are sparse and settle quickly; a dense one of at most
  :data:`DP_MAX_PARTS` parts that has not settled within :data:`BB_FIRST_SECONDS` seconds goes to
  the DP.

Limits (refused with a message above them): a component holds at most :data:`MAX_COMPONENT_PARTS`
parts and :data:`MAX_COMPONENT_ARCS` constraints; the search stops after ``time_limit`` seconds
(:data:`DEFAULT_TIME_LIMIT` by default) and then answers the best relaxation found, marked as not
proven minimal (``minimal=False``), never silently.

With parts already installed (``installed``, in order), a constraint ``x -> y`` whose ``y`` is
installed and whose ``x`` is not wholly installed before it is violated by the prefix: it must be
dropped (*forced*) for the strategy to admit the prefix.  The rule over several strategies:

* every cyclic strategy is repaired at its own minimum (a cycle makes the whole plan file invalid,
  whatever the other strategies), and every strategy is kept: least commitment keeps every
  alternative the user wrote;
* if no strategy admits the installed prefix, exactly one strategy is relaxed to admit it: the one
  whose repair costs least beyond its cycle repair (the first declared among equals); the others
  are left as they are (they stay valid alternatives for the next product).  This is the cheapest
  set of constraints whose removal gives the plan an admissible sequence starting with the prefix.

Strategies that end up admitting exactly the same sequences as an earlier one are removed (a plan
may not hold the same strategy twice) and reported.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Hashable, Iterable, Mapping, Sequence

from opportune.engine.deadline import Deadline, as_deadline

if TYPE_CHECKING:
    from opportune.planning.plan import Plan

DP_FIRST_PARTS = 12          # components up to this many parts: the subset DP first (2^12 · 12 steps, ~10 ms)
DP_MAX_PARTS = 20            # ... up to this many: the DP if the branch and bound has not settled it in
BB_FIRST_SECONDS = 0.5       # this long (the DP takes 3 to 8 s at 20 parts on a 2-core machine)
MAX_COMPONENT_PARTS = 200    # parts in one cyclic component
MAX_COMPONENT_ARCS = 2_000   # constraints inside one cyclic component
MAX_CYCLES = 50_000          # cycles kept in the branch and bound's family
DEFAULT_TIME_LIMIT = 10.0    # seconds for the whole relaxation
_EPS = 1e-9                  # weights are floats: "cheaper" means cheaper by more than rounding


class RelaxRefused(ValueError):
    """A plan over the relaxation's limits (the message states the limit and what to do).

    Examples
    --------
    >>> ring = [(i, (i + 1) % 201, 1) for i in range(201)]       # 201 parts in one cycle
    >>> min_feedback_arc_set(range(201), ring)
    Traceback (most recent call last):
    ...
    opportune.derive.relax.RelaxRefused: a knot of 201 mutually dependent parts joined by 201 constraints ...
    """


class RelaxTimeout(Exception):
    """The search ran out of time: ``weight`` and ``arcs`` are the best feedback arc set found,
    feasible (it breaks every cycle) but not proven minimal.

    Parameters
    ----------
    message : str
        What ran out, in words.
    weight : float
        The total weight of ``arcs``.
    arcs : list of tuple
        The best set found, ``(u, v)`` pairs in the order given.

    Examples
    --------
    >>> try:
    ...     min_feedback_arc_set("abc", {("a", "b"): 1, ("b", "c"): 1, ("c", "a"): 3, ("b", "a"): 1}, time_limit=0)
    ... except RelaxTimeout as exc:
    ...     print(exc.weight, exc.arcs)        # breaks every cycle; the minimum is 1.0
    2.0 [('b', 'c'), ('b', 'a')]
    """

    def __init__(self, message: str, weight: float, arcs: list):
        super().__init__(message)
        self.weight, self.arcs = weight, arcs


# ---------------------------------------------------------------- graphs


def strongly_connected_components(n: int, succ: Sequence[Sequence[int]]) -> list[list[int]]:
    """The strongly connected components of a digraph on ``0..n-1`` (Tarjan, iterative), each a list.

    O(n + arcs).

    Parameters
    ----------
    n : int
        The number of vertices.
    succ : sequence of sequences of int
        Each vertex's successors.

    Returns
    -------
    list of list of int
        The components, each a list of vertices; a component comes before the components that reach it
        (reverse topological order).

    Examples
    --------
    >>> strongly_connected_components(3, [[1], [2], []])
    [[2], [1], [0]]
    >>> sorted(map(sorted, strongly_connected_components(4, [[1], [0, 2], [3], []])))
    [[0, 1], [2], [3]]
    """
    index = [-1] * n
    low = [0] * n
    on_stack = [False] * n
    stack: list[int] = []
    out: list[list[int]] = []
    counter = 0
    for root in range(n):
        if index[root] >= 0:
            continue
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack[root] = True
        work = [(root, 0)]
        while work:
            node, i = work[-1]
            nexts = succ[node]
            if i < len(nexts):
                work[-1] = (node, i + 1)
                nxt = nexts[i]
                if index[nxt] < 0:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on_stack[nxt] = True
                    work.append((nxt, 0))
                elif on_stack[nxt]:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    x = stack.pop()
                    on_stack[x] = False
                    comp.append(x)
                    if x == node:
                        break
                out.append(comp)
    return out


def _is_acyclic(n: int, arcs: Iterable[tuple[int, int]]) -> bool:
    """Kahn's algorithm: O(n + arcs)."""
    succ: list[list[int]] = [[] for _ in range(n)]
    indeg = [0] * n
    for u, v in arcs:
        succ[u].append(v)
        indeg[v] += 1
    ready = [v for v in range(n) if not indeg[v]]
    seen = 0
    while ready:
        u = ready.pop()
        seen += 1
        for v in succ[u]:
            indeg[v] -= 1
            if not indeg[v]:
                ready.append(v)
    return seen == n


# ---------------------------------------------------------------- exact methods on one component


def _dp(k: int, arcs: list[tuple[int, int, float]], deadline: float) -> tuple[list[int], bool]:
    """Minimum-weight feedback arc set of a component of ``k`` vertices by DP over vertex subsets.

    ``f[S]`` is the least weight of backward arcs among the vertices of ``S`` placed first, in the best
    order; placing ``v`` right after ``S`` costs the weight of the arcs from ``v`` into ``S`` (they would
    point backwards).  The weight of arcs from ``v`` into ``S`` comes from two tables of 2^(k/2) entries
    per vertex (the low and high halves of ``S``), so each step is O(1): O(2^k · k) time, O(2^k) memory.
    Returns the indices of the arcs dropped and whether the answer is complete (False: out of time).
    """
    h = k // 2
    low_mask = (1 << h) - 1
    lo = [[0.0] * (1 << h) for _ in range(k)]
    hi = [[0.0] * (1 << (k - h)) for _ in range(k)]
    wv = [[0.0] * k for _ in range(k)]
    for u, v, w in arcs:
        wv[u][v] += w
    for v in range(k):
        t_lo, t_hi, row = lo[v], hi[v], wv[v]
        for m in range(1, 1 << h):
            b = (m & -m).bit_length() - 1
            t_lo[m] = t_lo[m & (m - 1)] + row[b]
        for m in range(1, 1 << (k - h)):
            b = (m & -m).bit_length() - 1
            t_hi[m] = t_hi[m & (m - 1)] + row[b + h]
    full = (1 << k) - 1
    inf = math.inf
    f = [inf] * (1 << k)
    f[0] = 0.0
    bits = [(1 << v, v) for v in range(k)]
    for s in range(full):
        if not s & 4095 and time.monotonic() > deadline:
            return [], False
        fs = f[s]
        s_lo, s_hi = s & low_mask, s >> h
        for bit, v in bits:
            if s & bit:
                continue
            c = fs + lo[v][s_lo] + hi[v][s_hi]
            t = s | bit
            if c < f[t]:
                f[t] = c
    # Walk back from the full set: the last vertex of an optimal order, then the one before, ...
    order: list[int] = []
    t = full
    while t:
        for bit, v in bits:
            if t & bit:
                s = t ^ bit
                if f[s] + lo[v][s & low_mask] + hi[v][s >> h] == f[t]:
                    order.append(v)
                    t = s
                    break
    order.reverse()
    pos = {v: i for i, v in enumerate(order)}
    return [i for i, (u, v, _) in enumerate(arcs) if pos[v] < pos[u]], True


def _order_heuristic(k: int, arcs: list[tuple[int, int, float]], deadline: float) -> list[int]:
    """A good (not always optimal) feedback arc set: the backward arcs of an order found by Eades, Lin
    and Smyth's greedy rule, improved by moving one vertex at a time to its best place, then made
    minimal (a dropped arc that closes no cycle is put back, heaviest first).  O(k^2 + k·arcs) a pass."""
    out_w: list[dict[int, float]] = [{} for _ in range(k)]
    in_w: list[dict[int, float]] = [{} for _ in range(k)]
    for u, v, w in arcs:
        out_w[u][v] = out_w[u].get(v, 0.0) + w
        in_w[v][u] = in_w[v].get(u, 0.0) + w
    # Greedy: sinks to the back, sources to the front, else the vertex with most weight out minus in.
    alive = set(range(k))
    front: list[int] = []
    back: list[int] = []
    while alive:
        changed = True
        while changed:
            changed = False
            for v in list(alive):
                if not any(x in alive for x in out_w[v]):
                    back.append(v)
                    alive.discard(v)
                    changed = True
                elif not any(x in alive for x in in_w[v]):
                    front.append(v)
                    alive.discard(v)
                    changed = True
        if alive:
            v = max(sorted(alive), key=lambda x: sum(w for y, w in out_w[x].items() if y in alive)
                    - sum(w for y, w in in_w[x].items() if y in alive))
            front.append(v)
            alive.discard(v)
    order = front + back[::-1]
    # Local search: move each vertex to the place that minimises the weight of backward arcs.
    improved = True
    while improved and time.monotonic() < deadline:
        improved = False
        for v in list(order):
            rest = [x for x in order if x != v]
            here = order.index(v)
            # cost of placing v at position p in rest: arcs x->v with x after p, arcs v->x with x before p
            cost = sum(w for x, w in in_w[v].items())  # p = 0: every arc into v points backwards
            best_cost, best_p, current = cost, 0, None
            for p, x in enumerate(rest, start=1):
                cost += out_w[v].get(x, 0.0) - in_w[v].get(x, 0.0)
                if p == here:
                    current = cost
                if cost < best_cost - _EPS:
                    best_cost, best_p = cost, p
            if here == 0:
                current = sum(w for x, w in in_w[v].items())
            if current is not None and best_cost < current - _EPS:
                rest.insert(best_p, v)
                order = rest
                improved = True
    pos = {v: i for i, v in enumerate(order)}
    dropped = [i for i, (u, v, _) in enumerate(arcs) if pos[v] < pos[u]]
    return _make_minimal(k, arcs, dropped)


def _make_minimal(k: int, arcs: list[tuple[int, int, float]], dropped: list[int]) -> list[int]:
    """Put back each dropped arc (heaviest first) whose return closes no cycle.  O(dropped · arcs)."""
    gone = set(dropped)
    succ: list[set[int]] = [set() for _ in range(k)]
    for i, (u, v, _) in enumerate(arcs):
        if i not in gone:
            succ[u].add(v)
    for i in sorted(dropped, key=lambda i: -arcs[i][2]):
        u, v, _ = arcs[i]
        # u -> v closes a cycle iff v already reaches u
        seen, stack = {v}, [v]
        while stack:
            x = stack.pop()
            for y in succ[x]:
                if y not in seen:
                    seen.add(y)
                    stack.append(y)
        if u not in seen:
            succ[u].add(v)
            gone.discard(i)
    return sorted(gone)


def _cycles_through(k: int, arcs: list[tuple[int, int, float]], alive: list[bool], deadline: float,
                    limit: int) -> list[int]:
    """Cycles of the graph of the ``alive`` arcs, as bitmasks of arc indices: for each alive arc
    ``u -> v`` on a cycle, a shortest path back from ``v`` to ``u`` closes one.  O(arcs · (k + arcs))."""
    succ: list[list[int]] = [[] for _ in range(k)]
    for i, (u, v, _) in enumerate(arcs):
        if alive[i]:
            succ[u].append(i)
    comp_of = [0] * k
    for c, comp in enumerate(strongly_connected_components(k, [[arcs[i][1] for i in succ[u]] for u in range(k)])):
        for v in comp:
            comp_of[v] = c
    found: set[int] = set()
    for i, (u, v, _) in enumerate(arcs):
        if not alive[i] or comp_of[u] != comp_of[v] or u == v:
            continue
        if time.monotonic() > deadline or len(found) >= limit:
            break
        prev: dict[int, int] = {v: -1}
        frontier = [v]
        while frontier and u not in prev:
            nxt = []
            for x in frontier:
                for j in succ[x]:
                    y = arcs[j][1]
                    if y not in prev:
                        prev[y] = j
                        nxt.append(y)
            frontier = nxt
        if u in prev:
            mask = 1 << i
            x = u
            while x != v:
                j = prev[x]
                mask |= 1 << j
                x = arcs[j][0]
            found.add(mask)
    return list(found)


def _hitting_set(cycles: list[list[int]], weights: list[float], bound: float,
                 deadline: float) -> tuple[list[int] | None, bool]:
    """The cheapest set of arcs meeting every cycle (lists of arc indices), if cheaper than ``bound``.

    Branch and bound: take a cycle not yet met with fewest allowed arcs; branch on which of its arcs
    is the first chosen (the arcs before it are excluded in that branch, so no set is visited twice).
    The lower bound shares each unmet cycle's cheapest remaining price among its arcs (a feasible
    dual of the covering LP).  Exponential in the worst case; returns ``(set or None, complete)``.
    """
    best: list = [bound, None]
    timed_out = [False]
    family = [(sum(1 << a for a in cyc), cyc) for cyc in cycles]   # bitmasks make "is it met?" one AND

    def search(chosen: int, banned: int, cost: float) -> None:
        if time.monotonic() > deadline:   # every node: a node costs O(cycles known), far more than the clock
            timed_out[0] = True
        if timed_out[0]:
            return
        # One pass over the unmet cycles: the lower bound, and the cycle to branch on.
        residual: dict[int, float] = {}
        bound_here = cost
        pick: list[int] | None = None
        for mask, cyc in family:
            if mask & chosen:
                continue
            allowed = cyc if not mask & banned else [a for a in cyc if not banned >> a & 1]
            if not allowed:
                return
            if pick is None or len(allowed) < len(pick):
                pick = allowed
            m = min(residual.get(a, weights[a]) for a in allowed)
            if m > 0:
                bound_here += m
                for a in allowed:
                    residual[a] = residual.get(a, weights[a]) - m
        if bound_here >= best[0] - _EPS:
            return
        if pick is None:
            best[0], best[1] = cost, [a for a in range(chosen.bit_length()) if chosen >> a & 1]
            return
        for a in sorted(pick, key=lambda a: (weights[a], a)):
            search(chosen | 1 << a, banned, cost + weights[a])
            banned |= 1 << a

    import sys

    depth = sys.getrecursionlimit()
    sys.setrecursionlimit(max(depth, 10_000))   # one level per arc chosen: at most MAX_COMPONENT_ARCS
    try:
        search(0, 0, 0.0)
    finally:
        sys.setrecursionlimit(depth)
    return best[1], not timed_out[0]


def _branch_and_bound(k: int, arcs: list[tuple[int, int, float]], deadline: float) -> tuple[list[int], bool]:
    """Minimum-weight feedback arc set of one component by a cycle hitting set grown lazily.

    Start from the heuristic's answer (an upper bound) and the shortest cycle through each arc; solve
    the hitting set of the cycles known exactly; if what is left has no cycle, that set is optimal
    (it is no dearer than any feedback arc set, which must meet these cycles too); else add the
    cycles left, complete the set into a feedback arc set (a new upper bound if cheaper), and repeat.
    If no set meets the known cycles more cheaply than the upper bound, the upper bound is optimal.
    Returns the dropped arc indices and whether they are proven minimal.
    """
    weights = [w for _, _, w in arcs]
    best = _order_heuristic(k, arcs, deadline)
    best_w = sum(weights[i] for i in best)
    masks = set(_cycles_through(k, arcs, [True] * len(arcs), deadline, MAX_CYCLES))
    while True:
        if time.monotonic() > deadline or len(masks) > MAX_CYCLES:
            return best, False
        cycles = sorted(([i for i in range(m.bit_length()) if m >> i & 1] for m in masks), key=len)
        chosen, complete = _hitting_set(cycles, weights, best_w, deadline)
        if not complete:
            return best, False
        if chosen is None:
            return best, True   # nothing meets the known cycles more cheaply: the best known is minimal
        alive = [True] * len(arcs)
        for i in chosen:
            alive[i] = False
        new = [m for m in _cycles_through(k, arcs, alive, deadline, MAX_CYCLES) if m not in masks]
        if not new:
            if _is_acyclic(k, ((u, v) for i, (u, v, _) in enumerate(arcs) if alive[i])):
                return chosen, True
            return best, False  # ran out of time while listing the cycles left
        masks.update(new)
        # Complete the set into a feedback arc set: a new upper bound when cheaper.
        rest = [i for i in range(len(arcs)) if alive[i]]
        sub = [arcs[i] for i in rest]
        extra = [rest[j] for j in _order_heuristic(k, sub, deadline)]
        candidate = _make_minimal(k, arcs, sorted(set(chosen) | set(extra)))
        w = sum(weights[i] for i in candidate)
        if w < best_w - _EPS:
            best, best_w = candidate, w


# ---------------------------------------------------------------- the feedback arc set


def min_feedback_arc_set(nodes: Iterable[Hashable], weighted_arcs, *, time_limit: float | None = DEFAULT_TIME_LIMIT,
                         method: str = "auto", deadline: Deadline | float | None = None) -> tuple[float, list[tuple]]:
    """The cheapest set of arcs whose removal leaves no cycle: ``(total weight, arcs)``.

    Exact: each strongly connected component is solved on its own, by the subset DP (O(2^k · k) for k
    vertices) up to :data:`DP_FIRST_PARTS` vertices, else by the lazy cycle hitting set above
    (exponential in the worst case, quick when cycles are few), falling back to the DP up to
    :data:`DP_MAX_PARTS` vertices if that has not finished in :data:`BB_FIRST_SECONDS`.  Finding the
    components is O(nodes + arcs).

    Parameters
    ----------
    nodes : iterable of hashable
        The vertices (those of the arcs are added).
    weighted_arcs : mapping or iterable
        ``{(u, v): weight}`` or ``(u, v, weight)`` triples (parallel arcs add their weights; a loop
        ``(u, u)`` is always dropped); weights are finite numbers > 0.
    time_limit : float or None
        Seconds for the whole search (:data:`DEFAULT_TIME_LIMIT`; None: no limit).
    method : {"auto", "dp", "bb"}
        ``"dp"`` or ``"bb"`` forces the subset DP (up to 22 vertices) or the branch and bound.
    deadline : Deadline or float, optional
        The caller's deadline (a :class:`~opportune.engine.deadline.Deadline` or a
        ``time.perf_counter()`` moment); the search stops at the sooner of it and ``time_limit``.

    Returns
    -------
    (float, list of tuple)
        The total weight and the arcs dropped, ``(u, v)`` pairs in the order given.

    Raises
    ------
    ValueError
        An unknown ``method``, or a weight that is not a finite number > 0.
    RelaxRefused
        A component over :data:`MAX_COMPONENT_PARTS` vertices or :data:`MAX_COMPONENT_ARCS` arcs, or one
        over 22 vertices for the forced DP.
    RelaxTimeout
        The time ran out first; it carries the best set found (a feedback arc set, not proven minimal).

    Examples
    --------
    >>> min_feedback_arc_set("abc", {("a", "b"): 1, ("b", "c"): 1, ("c", "a"): 3, ("b", "a"): 1})
    (1.0, [('a', 'b')])
    >>> min_feedback_arc_set("ab", [("a", "b", 1)])
    (0.0, [])
    """
    if method not in ("auto", "dp", "bb"):
        raise ValueError(f"unknown method {method!r}: auto, dp or bb")
    time_limit = _sooner(time_limit, deadline)
    deadline = time.monotonic() + (time_limit if time_limit is not None else math.inf)
    ids: dict[Hashable, int] = {}
    for v in nodes:
        ids.setdefault(v, len(ids))
    items = weighted_arcs.items() if isinstance(weighted_arcs, Mapping) else (((u, v), w) for u, v, w in weighted_arcs)
    merged: dict[tuple, float] = {}
    for (u, v), w in items:
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not (0 < w < math.inf):
            raise ValueError(f"the arc {u!r} -> {v!r} has weight {w!r}: weights are finite numbers > 0")
        ids.setdefault(u, len(ids))
        ids.setdefault(v, len(ids))
        merged[(u, v)] = merged.get((u, v), 0.0) + float(w)
    n = len(ids)
    succ: list[list[int]] = [[] for _ in range(n)]
    for u, v in merged:
        if u != v:
            succ[ids[u]].append(ids[v])
    comp_of = [0] * n
    comps = strongly_connected_components(n, succ)
    for c, comp in enumerate(comps):
        for v in comp:
            comp_of[v] = c
    dropped: list[tuple] = [(u, v) for u, v in merged if u == v]
    inside: dict[int, list[tuple]] = {}
    for (u, v), w in merged.items():
        if u != v and comp_of[ids[u]] == comp_of[ids[v]]:
            inside.setdefault(comp_of[ids[u]], []).append((u, v, w))
    proven = True
    for c, comp_arcs in sorted(inside.items()):
        size = len(comps[c])
        if size > MAX_COMPONENT_PARTS or len(comp_arcs) > MAX_COMPONENT_ARCS:
            raise RelaxRefused(
                f"a knot of {size:,} mutually dependent parts joined by {len(comp_arcs):,} constraints (a strongly "
                f"connected component) is over the relaxation's limits of {MAX_COMPONENT_PARTS} parts and "
                f"{MAX_COMPONENT_ARCS:,} constraints in one component")
        local = {v: i for i, v in enumerate(sorted(comps[c]))}
        arcs = [(local[ids[u]], local[ids[v]], w) for u, v, w in comp_arcs]
        chosen, complete = [], False
        if time.monotonic() > deadline:
            chosen = _order_heuristic(size, arcs, deadline)
        elif method == "bb" or (method == "auto" and size > DP_FIRST_PARTS):
            # Knots of real plans are sparse, and the branch and bound settles them in milliseconds;
            # a dense one that it cannot settle quickly goes to the DP if it is small enough.
            quick = method == "auto" and size <= DP_MAX_PARTS
            chosen, complete = _branch_and_bound(size, arcs, min(deadline, time.monotonic() + BB_FIRST_SECONDS)
                                                 if quick else deadline)
        if not complete and method != "bb" and (method == "dp" or size <= DP_MAX_PARTS) and time.monotonic() < deadline:
            if size > 22:
                raise RelaxRefused(f"the subset DP takes components of at most 22 parts, not {size}")
            chosen, complete = _dp(size, arcs, deadline)
            if not complete:
                chosen = _order_heuristic(size, arcs, math.inf)
        proven &= complete
        dropped += [comp_arcs[i][:2] for i in chosen]
    order = {a: i for i, a in enumerate(merged)}
    dropped.sort(key=order.__getitem__)
    weight = math.fsum(merged[a] for a in dropped)
    if not proven:
        raise RelaxTimeout(f"the search for the cheapest relaxation ran out of its {time_limit:g} s; the best "
                           "relaxation found is not proven minimal", weight, dropped)
    return weight, dropped


def _sooner(time_limit: float | None, deadline: Deadline | float | None) -> float | None:
    """Seconds from now to the sooner of ``time_limit`` and ``deadline`` (None: neither); the search
    keeps its own ``time.monotonic()`` clock."""
    d = as_deadline(deadline)
    if not d.finite:
        return time_limit
    left = max(0.0, d.remaining())
    return left if time_limit is None else min(time_limit, left)


# ---------------------------------------------------------------- relaxing a plan


@dataclass(frozen=True)
class Dropped:
    """One declared constraint dropped.

    Parameters
    ----------
    strategy : str
        The strategy's name.
    before, after : str
        The constraint ``before -> after``.
    weight : float
        Its weight: the price of dropping it.
    forced : bool
        True if the installed prefix violates it (it had to go).
    line : int, optional
        Its line in the plan file, when known (:func:`constraint_lines`).

    Examples
    --------
    >>> from opportune.formats.loader import check_text
    >>> plan = check_text("parts: [a, b, c]\\nrequires: {b: [a]}").plan
    >>> relax(plan, ["b"]).dropped
    (Dropped(strategy='default', before='a', after='b', weight=1.0, forced=True, line=None),)
    """

    strategy: str
    before: str
    after: str
    weight: float
    forced: bool = False
    line: int | None = None

    def to_dict(self) -> dict:
        """The dropped constraint as plain data (an entry of ``relax --json``'s ``dropped``).

        Returns
        -------
        dict
            ``strategy``, ``before``, ``after``, ``weight`` (an integer where it is one), ``forced``, ``line``.

        Examples
        --------
        >>> Dropped("default", "a", "b", 1.0).to_dict()
        {'strategy': 'default', 'before': 'a', 'after': 'b', 'weight': 1, 'forced': False, 'line': None}
        """
        return {"strategy": self.strategy, "before": self.before, "after": self.after,
                "weight": _number(self.weight), "forced": self.forced, "line": self.line}


@dataclass(frozen=True)
class Relaxation:
    """The relaxed plan, the constraints dropped and their total weight, and whether it is proven minimal.

    Parameters
    ----------
    plan : Plan
        The relaxed plan: valid (``opportune check`` passes) and admitting the installed prefix.
    dropped : tuple of Dropped
        The declared constraints dropped, strategy by strategy.
    weight : float
        Their total weight.
    minimal : bool
        False when the time ran out before the minimum was proven (the relaxation is still valid).
    removed : tuple of (str, str)
        ``(strategy, same_as)`` for strategies dropped because, relaxed, they admit exactly the
        sequences of an earlier one.
    repaired : str, optional
        The strategy relaxed to admit the installed prefix (None when none needed it).
    notes : tuple of str
        Remarks for the user.

    Examples
    --------
    >>> from opportune.formats.loader import check_text
    >>> cyclic = check_text("parts: [a, b]\\nrequires: {b: [a], a: [{part: b, weight: 2}]}", allow_cycles=True).plan
    >>> r = relax(cyclic)
    >>> r.weight, r.minimal, r.changed, r.plan.strategies[0].pairs()
    (1.0, True, True, [('b', 'a')])
    """

    plan: Plan
    dropped: tuple[Dropped, ...]
    weight: float
    minimal: bool
    removed: tuple[tuple[str, str], ...] = ()
    repaired: str | None = None
    notes: tuple[str, ...] = field(default=())

    @property
    def changed(self) -> bool:
        return bool(self.dropped or self.removed)

    def to_dict(self) -> dict:
        """The relaxation as plain data (``relax --json``).

        Returns
        -------
        dict
            The relaxed plan (a plan file's dict), the constraints dropped, their weight, ``minimal``,
            the strategies removed and the strategy repaired.

        Examples
        --------
        >>> from opportune.formats.loader import check_text
        >>> cyclic = check_text("parts: [a, b]\\nrequires: {b: [a], a: [b]}", allow_cycles=True).plan
        >>> doc = relax(cyclic).to_dict()
        >>> doc["plan"]["strategies"], doc["weight"], doc["minimal"]
        ([{'name': 'default', 'requires': {'a': ['b']}}], 1, True)
        """
        return {"plan": self.plan.to_dict(), "dropped": [d.to_dict() for d in self.dropped],
                "weight": _number(self.weight), "minimal": self.minimal,
                "removed": [{"strategy": a, "same_as": b} for a, b in self.removed], "repaired": self.repaired}


def _number(x: float) -> int | float:
    return int(x) if float(x).is_integer() and abs(x) < 2**53 else x


def prefix_violations(plan: Plan, strategy, installed: Sequence[str]) -> list[tuple[str, str]]:
    """The declared constraints ``(before, after)`` of ``strategy`` that the installed prefix breaks: ``after``
    has a unit installed and ``before`` has not every unit installed before the first of them.  O(prefix + pairs).
    """
    first: dict[str, int] = {}
    last: dict[str, int] = {}
    count: dict[str, int] = {}
    for i, p in enumerate(installed):
        first.setdefault(p, i)
        last[p] = i
        count[p] = count.get(p, 0) + 1
    return [(b, a) for b, a in strategy.pairs()
            if a in first and (count.get(b, 0) < plan.part(b).quantity or last[b] > first[a])]


def check_installed(plan: Plan, installed: Sequence[str]) -> None:
    """Raise ``ValueError`` naming the first unknown part, or a part installed more often than its quantity."""
    seen: dict[str, int] = {}
    for i, p in enumerate(installed):
        if p not in plan:
            from opportune.formats.problems import unknown_part_hint

            raise ValueError(f"--installed: unknown part '{p}' (position {i + 1}); "
                             + unknown_part_hint(p, plan.part_ids))
        seen[p] = seen.get(p, 0) + 1
        if seen[p] > plan.part(p).quantity:
            raise ValueError(f"--installed: part '{p}' is installed {seen[p]} times (position {i + 1}) but the plan "
                             f"has {plan.part(p).quantity} unit{'s' if plan.part(p).quantity != 1 else ''} of it")


def relax(plan: Plan, installed: Sequence[str] = (), *, time_limit: float | None = DEFAULT_TIME_LIMIT,
          lines: Mapping[tuple[str, str, str], int] | None = None,
          deadline: Deadline | float | None = None) -> Relaxation:
    """The cheapest rational relaxation of ``plan`` (see the module's docstring for the rule).

    Cost: one :func:`min_feedback_arc_set` per cyclic strategy (two for a strategy that contradicts the
    prefix), within ``time_limit`` seconds in all.

    Parameters
    ----------
    plan : Plan
        The plan; it may hold cyclic strategies (read it with ``read_plan(path, allow_cycles=True)``).
    installed : sequence of str
        The prefix of part ids already installed, in order.
    time_limit : float or None
        Seconds for the whole relaxation (:data:`DEFAULT_TIME_LIMIT`; None: no limit); past it the best
        relaxation found is answered with ``minimal`` False.
    lines : mapping, optional
        ``(strategy, before, after)`` → the constraint's line in its file (:func:`constraint_lines`),
        carried into :class:`Dropped`.
    deadline : Deadline or float, optional
        The caller's deadline, as in :func:`min_feedback_arc_set`.

    Returns
    -------
    Relaxation
        Its plan is valid (``opportune check`` passes) and admits ``installed``.

    Raises
    ------
    ValueError
        A prefix with an unknown part, or a part installed more often than its quantity.
    RelaxRefused
        A knot of constraints over the limits (:data:`MAX_COMPONENT_PARTS`, :data:`MAX_COMPONENT_ARCS`).

    Examples
    --------
    >>> from opportune.formats.loader import check_text
    >>> cyclic = check_text("parts: [a, b, c]\\nrequires: {b: [a], c: [b], a: [{part: c, weight: 3}]}",
    ...                     allow_cycles=True).plan
    >>> r = relax(cyclic)
    >>> [(d.before, d.after, d.weight) for d in r.dropped], r.weight, r.minimal
    ([('a', 'b', 1.0)], 1.0, True)

    With ``b`` already installed, a plan that asks ``a`` first is relaxed to admit that prefix:

    >>> r = relax(check_text("parts: [a, b, c]\\nrequires: {b: [a]}").plan, ["b"])
    >>> [(d.before, d.after, d.forced) for d in r.dropped], r.repaired
    ([('a', 'b', True)], 'default')
    >>> relax(r.plan, ["d"])
    Traceback (most recent call last):
    ...
    ValueError: --installed: unknown part 'd' (position 1); the plan's parts are a, b, c
    """
    from opportune.planning.plan import Plan, Strategy

    installed = list(installed)
    check_installed(plan, installed)
    time_limit = _sooner(time_limit, deadline)
    deadline = time.monotonic() + (time_limit if time_limit is not None else math.inf)
    lines = lines or {}
    proven = True

    def fas(pairs: list[tuple[str, str]], strategy) -> tuple[float, list[tuple[str, str]]]:
        nonlocal proven
        left = None if time_limit is None else max(deadline - time.monotonic(), 0.0)
        try:
            return min_feedback_arc_set(plan.part_ids, [(b, a, strategy.weight(b, a)) for b, a in pairs],
                                        time_limit=left)
        except RelaxTimeout as exc:
            proven = False
            return exc.weight, exc.arcs

    cycle_cut: list[tuple[float, list]] = []
    for s in plan.strategies:
        cycle_cut.append(fas(s.pairs(), s))
    # The prefix: forced drops, then the cheapest strategy to repair (only if no strategy admits it).
    repaired, forced_cut = None, None
    if installed:
        violated = [prefix_violations(plan, s, installed) for s in plan.strategies]
        if all(violated):
            best_extra = math.inf
            for i, s in enumerate(plan.strategies):
                forced = set(violated[i])
                w, cut = fas([p for p in s.pairs() if p not in forced], s)
                total = w + math.fsum(s.weight(b, a) for b, a in forced)
                if total - cycle_cut[i][0] < best_extra - _EPS:
                    best_extra, repaired, forced_cut = total - cycle_cut[i][0], i, (forced, cut)
    dropped: list[Dropped] = []
    strategies: list[Strategy] = []
    for i, s in enumerate(plan.strategies):
        forced, cut = (forced_cut if i == repaired else (set(), cycle_cut[i][1]))
        gone = set(cut) | forced
        for b, a in s.pairs():
            if (b, a) in gone:
                dropped.append(Dropped(s.name, b, a, s.weight(b, a), (b, a) in forced, lines.get((s.name, b, a))))
        requires = {a: tuple(b for b in bs if (b, a) not in gone) for a, bs in s.requires.items()}
        requires = {a: bs for a, bs in requires.items() if bs}
        strategies.append(Strategy(s.name, requires, {k: w for k, w in s.weights.items() if k not in gone}))
    # Relaxed strategies may coincide: a plan may not hold two that admit the same sequences.
    removed: list[tuple[str, str]] = []
    if len(strategies) > 1 and dropped:
        from opportune.engine.poset import Poset

        index = {p: k for k, p in enumerate(plan.part_ids)}
        kept: list[tuple[Strategy, Poset]] = []
        for s in strategies:
            poset = Poset.from_pairs(len(index), [(index[b], index[a]) for b, a in s.pairs()])
            same = next((k for k, q in kept if q == poset), None)
            if same is not None:
                removed.append((s.name, same.name))
            else:
                kept.append((s, poset))
        strategies = [s for s, _ in kept]
    relaxed = Plan(plan.name, plan.parts, tuple(strategies), plan.source, plan.description, plan.simulation)
    return Relaxation(relaxed, tuple(dropped), math.fsum(d.weight for d in dropped), proven, tuple(removed),
                      plan.strategies[repaired].name if repaired is not None else None)


def constraint_lines(path) -> dict[tuple[str, str, str], int]:
    """The line of each declared constraint of a YAML or JSON plan file: ``(strategy, before, after) -> line``.

    Best effort (empty for other formats, standard input or an unreadable file); O(size of the file).

    Parameters
    ----------
    path : str or Path
        The plan file (``example:NAME`` and ``salbp:NAME`` too; ``-`` gives nothing).

    Returns
    -------
    dict
        ``(strategy, before, after)`` → line, from 1.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> path = Path(tempfile.mkdtemp()) / "plan.yaml"
    >>> _ = path.write_text("parts: [a, b, c]\\nrequires:\\n  b: [a]\\n  c: [b, a]\\n")
    >>> constraint_lines(path)
    {('default', 'a', 'b'): 3, ('default', 'b', 'c'): 4, ('default', 'a', 'c'): 4}
    >>> constraint_lines("no-such-file.yaml")
    {}
    """
    from pathlib import Path

    from opportune.formats import shipped
    from opportune.formats.loader import MAX_FILE_BYTES, detect_format, parse_json, parse_yaml
    from opportune.formats.validate import DEFAULT_STRATEGY

    try:
        path = shipped.resolve(path)
        if str(path) == "-":
            return {}
        with Path(path).open("rb") as f:  # at most the bound: /dev/zero is a file too
            raw = f.read(MAX_FILE_BYTES + 1)
        if len(raw) > MAX_FILE_BYTES:
            return {}
        text = raw.decode("utf-8-sig")
    except (KeyError, OSError, UnicodeDecodeError):
        return {}
    fmt = detect_format(path, text[:200])
    if fmt not in ("yaml", "json"):
        return {}
    doc = parse_json(text, str(path)) if fmt == "json" else parse_yaml(text, str(path))
    data = doc.data
    if doc.problems or not isinstance(data, dict):
        return {}
    if isinstance(data.get("strategies"), list):
        entries = [(("strategies", i), s.get("name") or f"strategy {i + 1}", s.get("requires"))
                   for i, s in enumerate(data["strategies"]) if isinstance(s, dict)]
    else:
        entries = [((), DEFAULT_STRATEGY, data.get("requires"))]
    out: dict[tuple[str, str, str], int] = {}
    for base, name, req in entries:
        if not isinstance(req, dict):
            continue
        for after, befores in req.items():
            items = list(enumerate(befores)) if isinstance(befores, list) else [(None, befores)]
            for j, b in items:
                b = b.get("part") if isinstance(b, dict) else b
                if b is None or isinstance(b, (list, dict)):
                    continue
                where = base + ("requires", after) + ((j,) if j is not None else ())
                line = doc.line(where)
                if line:
                    out.setdefault((str(name), str(b), str(after)), line)
    return out
