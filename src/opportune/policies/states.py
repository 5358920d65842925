"""How many states the exact programmes need, known before they start.

The programmes of :mod:`.optimal`, :mod:`.evaluate` and :mod:`.pile` memoise one value per state
they reach.  For the optimum every state is reached: a key (installed units, consistent strategies)
for every admissible prefix set, times every buffer content that fits (``capacity``), and in the
pile bin times every window as well.  So the state count is a sum over the order's down-sets,

    states = Σ_keys  Σ_{buffer b ≤ remaining, |b| ≤ capacity}  w(remaining − b)

with ``w = 1`` in a Markov bin and ``w = 1 + windows(bin)`` in the pile (one value after a shake,
one per window).  A policy that ignores the buffer's order reaches a subset of the same states, so
this bounds its programme too; one that keeps the order (:mod:`.evaluate`) at most
:func:`orderings_factor` times as many.

:func:`estimate_states` finds it in three ways, cheapest first, and says which it used:

* **exact** — the keys are listed level by level (one step per key, far cheaper than the
  programme's work per state: no looks, no decisions), each weighed exactly;
* **at least** — the listing stopped early (over the limit, or out of time): what it listed is a
  proven lower bound;
* **estimated** — the order's down-sets counted by size per strategy (a memoised decomposition,
  no listing), each weighed as if every part had one unit.  Exact for one strategy of single-unit
  parts.  Identical units weighed as distinct overcount the buffers (``2^q`` contents for a part of
  quantity *q* instead of ``q + 1``) and the pile's windows; several strategies count the keys they
  share once per strategy but miss the keys that differ only in the strategies still consistent.
  Measured between 0.85 and 7.3 times the true count on random plans of up to 7 units (quantities
  up to 3, up to 3 strategies); tests/test_evaluate_bounds.py checks a factor of 16 either way.

Example
-------
>>> from opportune import make_plan
>>> from opportune.engine import OrderEngine
>>> e = estimate_states(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), visible=1)
>>> e.states, e.exact     # {} with buffer {} {a} {b} {a,b}; {a} with {} {b}; {a,b}
(7, True)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

from opportune.engine.deadline import Deadline, as_deadline, recursion_room
from opportune.engine.poset import bits
from opportune.engine.tuning import BYTES_PER_STATE, PROFILE_MAX_UNITS

__all__ = ["BYTES_PER_STATE", "StateEstimate", "StateListing", "downset_profile", "estimate_from_downsets", "estimate_states",
           "looks_at_start", "orderings_factor", "reachable_keys"]


@dataclass(frozen=True)
class StateEstimate:
    """What :func:`estimate_states` found.

    ``states``: the best figure (exact when ``exact``); ``low``: a proven lower bound; ``how``: the
    method in words (for messages); ``keys``: (installed, strategies) keys listed; ``looks``: the
    distinct looks at the start.
    """

    states: int
    low: int
    exact: bool
    how: str
    keys: int = 0
    #: Looks of the first state (every part in the bin): the programme's work per state grows with them.
    looks: int = 1

    def over(self, limit: int) -> bool:
        """True when the programme would need more than ``limit`` states (by the best figure)."""
        return self.states > limit or self.low > limit

    def describe(self) -> str:
        """``'3,477 (exact)'``, ``'at least 2,000,001'``, ``'about 1.2e+13 (estimated from ...)'``."""
        if self.exact:
            return f"{self.states:,} (exact)"
        if self.states <= self.low:
            return f"at least {big(self.low)}"
        return f"about {big(self.states)} ({self.how}; at least {big(self.low)})"


def big(n: int) -> str:
    """``'12,345'``, or ``'3.5e+13'`` from a billion on (any size: no float conversion).

    >>> big(12345), big(2 ** 45), big(10 ** 5000)
    ('12,345', '3.5e+13', '1e+5000')
    """
    if n < 10 ** 9:
        return f"{n:,}"
    e = math.floor(math.log10(n))
    m = 10 ** (math.log10(n) - e)
    if round(m, 1) >= 10:
        m, e = m / 10, e + 1
    return f"{m:.2g}e+{e}"


def estimate_states(engine, *, visible: int = 2, capacity: int | None = None, pile: bool = False,
                    stop_above: int | None = None, deadline: Deadline | float | None = None,
                    time_limit: float | None = 2.0) -> StateEstimate:
    """The number of states the exact optimum's programme stores for ``engine.plan``.

    ``stop_above``: stop listing once the count passes it (the answer is then "at least");
    ``deadline`` / ``time_limit`` (seconds, default 2; None: none): the sooner ends the work, and the answer is
    then a lower bound or the down-set estimate.  Complexity: O(keys × units) for the listing, at
    most O(stop_above) keys; the estimate O(decomposition pieces × units²) bit operations.

    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> estimate_states(OrderEngine(make_plan(["a", "b", "c"], {})), capacity=0).states   # 2^3 down-sets
    8
    """
    until = as_deadline(deadline).within(time_limit)
    listing = StateListing(engine, visible=visible, capacity=capacity, pile=pile, stop_above=stop_above)
    # the listing gets part of the time: where it cannot finish, the estimate needs the rest
    listed = listing.advance(until.share(0.6))
    if listed is not None and listed.exact:
        return listed
    looks = listing.looks
    # every set of minimal units is a down-set, so a key: a bound where the listing saw little
    minimal = max((sum(1 for b in poset.below if not b) for poset in engine.posets), default=0)
    low = max(listing.total, (1 << minimal) - 1)
    profile = estimate_from_downsets(engine, deadline=until, weigh=listing.weigh)
    if profile is None or profile <= low:
        return StateEstimate(low, low, False, "listed in part", listing.keys, looks)
    return StateEstimate(profile, low, False, "estimated from the order's down-sets", listing.keys, looks)


def looks_at_start(engine, visible: int) -> int:
    """Distinct looks with every unit in the bin (the most any state has): multisets of ``visible`` parts
    within their quantities.  O(parts × visible).

    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> looks_at_start(OrderEngine(make_plan(["a", "b", "c"], {})), 2)     # ab ac bc
    3
    """
    quantity = [p.quantity for p in engine.plan.parts]
    k = min(visible, sum(quantity))
    poly = [1]
    for q in quantity:
        poly = _times_run(poly, q, k)
    return poly[k] if k < len(poly) else 0


# ---------------------------------------------------------------- weights


class _Weigher:
    """States per key, from the units left of each part (cached on the sorted multiset of them)."""

    def __init__(self, engine, visible: int, capacity: int | None, pile: bool):
        self.visible, self.capacity, self.pile = visible, capacity, pile
        self.quantity = [p.quantity for p in engine.plan.parts]
        self.single = all(q == 1 for q in self.quantity)
        self.engine = engine
        # the units of single-unit parts (counted by one bit count), and the parts of several units
        self.singles = sum(1 << engine.first[i] for i, q in enumerate(self.quantity) if q == 1)
        self.multiple = [(engine.first[i], q) for i, q in enumerate(self.quantity) if q > 1]
        self._by_rem = lru_cache(maxsize=65_536)(self._weight)

    def of_remaining(self, r: int) -> int:
        """States of a key whose remaining parts are ``r`` single units."""
        return self._by_rem((1,) * r)

    def of_mask(self, mask: int) -> int:
        engine = self.engine
        if self.single:
            return self._by_rem((1,) * (engine.n_units - mask.bit_count()))
        # the sorted multiset of units left per part: the single parts' ones first, then the others'
        rem = []
        for first, q in self.multiple:
            left = q - ((mask >> first) & ((1 << q) - 1)).bit_count()
            if left:
                rem.append(left)
        ones = (self.singles & ~mask).bit_count()
        return self._by_rem((1,) * ones + tuple(sorted(rem)))

    def _weight(self, rem: tuple[int, ...]) -> int:
        total = sum(rem)
        if total == 0:
            # the finished key: one value in a Markov bin; the pile's programme stores none for it
            return 0 if self.pile else 1
        cap = total if self.capacity is None else min(self.capacity, total)
        v = self.visible
        if len(rem) == total:
            # single units (the common case), in closed form: C(r, k) buffers of k units, each leaving
            # C(r − k, min(v, r − k)) windows in the pile; C(r, k) by recurrence (O(cap) products)
            if not self.pile and cap == total:
                return 1 << total
            out, c = 0, 1
            for k in range(cap + 1):
                out += c * (1 + math.comb(total - k, min(v, total - k)) if self.pile else 1)
                c = c * (total - k) // (k + 1)
            return out
        if not self.pile:
            if cap == total:
                return math.prod(r + 1 for r in rem)
            poly = [1]
            for r in rem:
                poly = _times_run(poly, r, cap)
            return sum(poly)
        # pile: per buffer content b, one value after a shake plus one per window of the bin rem − b;
        # F[j][k]: pairs (b ≤ rem, window w ≤ rem − b) with |b| = k, |w| = j (j ≤ v)
        F = [[1] + [0] * cap] + [[0] * (cap + 1) for _ in range(v)]
        for r in rem:
            G = [[0] * (cap + 1) for _ in range(v + 1)]
            for j in range(v + 1):
                for w in range(min(r, v - j) + 1):
                    # b from 0 to r − w: a run of r − w + 1 ones, by a sliding sum over k
                    row, out = F[j], G[j + w]
                    run = r - w
                    acc = 0
                    for k in range(cap + 1):
                        acc += row[k]
                        if k - run - 1 >= 0:
                            acc -= row[k - run - 1]
                        out[k] += acc
            F = G
        buffers = [1]
        for r in rem:
            buffers = _times_run(buffers, r, cap)
        return sum(buffers[k] + F[min(v, total - k)][k] for k in range(len(buffers)))


def _times_run(poly: list[int], r: int, cap: int) -> list[int]:
    """``poly × (1 + t + ... + t^r)``, truncated above degree ``cap`` (a sliding sum: O(cap))."""
    size = min(len(poly) + r, cap + 1)
    out = [0] * size
    acc = 0
    for k in range(size):
        if k < len(poly):
            acc += poly[k]
        if 0 <= k - r - 1 < len(poly):
            acc -= poly[k - r - 1]
        out[k] = acc
    return out


# ---------------------------------------------------------------- listing the keys


class StateListing:
    """The exact listing of :func:`estimate_states`, done in slices: each :meth:`advance` goes on where the
    last one stopped (the level-by-level walk of :func:`reachable_keys` is kept between calls), so per-plan
    work can list a large plan's states between other work.  The answer is the same as one call's.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine (the one the programme stores states of).
    visible : int, default 2
        Units seen at a look.
    capacity : int or None, optional
        Buffer locations (None: unlimited).
    pile : bool, default False
        The pile bin's states (a window each).
    stop_above : int or None, optional
        Stop once the count passes it: the answer is then "at least".

    Attributes
    ----------
    total, keys : int
        The states and the (installed, strategies) keys listed so far.
    looks : int
        The distinct looks at the start (:func:`looks_at_start`).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> from opportune.engine.deadline import Deadline
    >>> listing = StateListing(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), visible=1)
    >>> listing.advance(Deadline.NEVER).describe()
    '7 (exact)'
    """

    def __init__(self, engine, *, visible: int = 2, capacity: int | None = None, pile: bool = False,
                 stop_above: int | None = None):
        self.weigh = _Weigher(engine, visible, capacity, pile)
        self._keys = reachable_keys(engine)      # never cut inside: the clock is read between keys
        self._limit = float("inf") if stop_above is None else stop_above
        self.looks = looks_at_start(engine, visible)
        self.total = 0
        self.keys = 0
        self.result: StateEstimate | None = None

    def advance(self, until: Deadline) -> StateEstimate | None:
        """List until ``until`` passes (read at every key), the count passes ``stop_above``, or every key is
        listed.  O(keys listed × units).

        Parameters
        ----------
        until : Deadline
            When to stop this slice.

        Returns
        -------
        StateEstimate or None
            The answer once known (exact, or "at least" past ``stop_above``); None: call again.
        """
        if self.result is not None:
            return self.result
        for mask, _ in self._keys:
            self.keys += 1
            self.total += self.weigh.of_mask(mask)
            if self.total > self._limit:
                self.result = StateEstimate(self.total, self.total, False, "listed in part", self.keys, self.looks)
                return self.result
            if until.expired():
                return None
        self.result = StateEstimate(self.total, self.total, True, "listed", self.keys, self.looks)
        return self.result


def reachable_keys(engine, until: Deadline = Deadline.NEVER):
    """Yield every (installed units mask, consistent strategies) key reachable by installations,
    level by level (one more unit per level); the generator ends early once ``until`` has passed
    (the caller reads ``until.expired()`` to tell).  Complexity: O(keys × units).

    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> list(reachable_keys(OrderEngine(make_plan(["a", "b"], {"b": ["a"]}))))
    [(0, 1), (1, 1), (3, 1)]
    """
    n = engine.n_units
    posets = engine.posets
    k = engine.k
    level = [(0, engine.all_strategies)]
    check = until.finite
    for _ in range(n + 1):
        nxt = {}
        for mask, cons in level:
            yield mask, cons
            rest = engine.full ^ mask
            steps = 0
            while rest:
                b = rest & -rest
                rest ^= b
                steps += 1
                if check and not steps & 1023 and until.expired():
                    return
                u = b.bit_length() - 1
                if k == 1 and posets:
                    if not posets[0].below[u] & ~mask:
                        nxt[(mask | b, cons)] = None
                else:       # several strategies, or a plan written as ways (its sets after decided exactly)
                    after = engine.exact_after(mask, cons, u)
                    if after:
                        nxt[(mask | b, after)] = None
            if check and until.expired():
                return
        if not nxt:
            break
        level = list(nxt)


def orderings_factor(engine, capacity: int | None, ties) -> int:
    """At most how many orders of one buffer content a programme that keeps the buffer's order stores:
    the buffer's order matters only between parts of one pair of ``ties`` (part indices; None: every
    pair), so the orders of a content are at most the product, over the connected groups of the tie
    graph, of the factorial of the units of the group it can hold.  Complexity: O(parts + ties).

    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> e = OrderEngine(make_plan(["a", "b", "c"], {}))
    >>> orderings_factor(e, None, None), orderings_factor(e, 2, None), orderings_factor(e, None, {(0, 2)})
    (6, 2, 2)
    """
    quantity = [p.quantity for p in engine.plan.parts]
    group = list(range(len(quantity)))

    def root(i: int) -> int:
        while group[i] != i:
            group[i] = group[group[i]]
            i = group[i]
        return i

    pairs = ((0, i) for i in range(len(quantity))) if ties is None else ties
    for a, b in pairs:
        group[root(a)] = root(b)
    units: dict[int, int] = {}
    for i, q in enumerate(quantity):
        units[root(i)] = units.get(root(i), 0) + q
    cap = float("inf") if capacity is None else capacity
    return math.prod(math.factorial(int(min(u, cap))) for u in units.values())


# ---------------------------------------------------------------- the down-set estimate


def estimate_from_downsets(engine, *, visible: int = 2, capacity: int | None = None, pile: bool = False,
                           deadline: Deadline | float | None = None, weigh: _Weigher | None = None) -> int | None:
    """The state count estimated from the order alone: Σ over strategies and down-sets of the states
    of a key whose remaining units were single parts (None: past ``deadline``, or a plan of more than
    2,000 units, or one written as ways).  Exact for one strategy of single-unit parts; see the module's docstring for the
    factor otherwise.  Complexity: that of :func:`downset_profile` per strategy.

    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> estimate_from_downsets(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), visible=1)
    7
    """
    weigh = weigh or _Weigher(engine, visible, capacity, pile)
    until = as_deadline(deadline)
    n = engine.n_units
    if n > PROFILE_MAX_UNITS or not engine.posets:     # a plan written as ways has no order to decompose
        return None
    weights = [weigh.of_remaining(r) for r in range(n + 1)]
    total = 0
    for poset in engine.posets:
        profile = downset_profile(poset, until)
        if profile is None:
            return None
        total += sum(c * weights[r] for r, c in enumerate(profile))
    return total


def downset_profile(poset, deadline: Deadline | float | None = None, *, limit: int = 200_000) -> list[int] | None:
    """``p[r]``: the number of down-sets of ``poset`` that leave ``r`` elements out (None: more than
    ``limit`` memoised pieces, or past ``deadline``).

    The decomposition of :func:`~opportune.engine.downsets.count_downsets_bounded` (split into
    connected pieces; branch on the most connected element), carrying the polynomial
    ``Σ_D t^|S \\ D|`` packed into one integer (one slot of ``n + 1`` bits per power: no coefficient
    reaches ``2^n``), so products and sums are single big-integer operations.
    Complexity: O(pieces × n²) bit operations at worst.

    >>> from opportune.engine.poset import Poset
    >>> downset_profile(Poset.from_pairs(3, [(0, 1)]))      # {}, {0}, {2}, {0,1}, {0,2}, {0,1,2}
    [1, 2, 2, 1]
    """
    until = as_deadline(deadline)
    n = poset.n
    width = n + 1
    slot_mask = (1 << width) - 1
    below, above = poset.below, poset.above
    nbr = [b | a for b, a in zip(below, above)]
    one_plus_t = 1 | 1 << width
    memo: dict[int, int] = {0: 1}
    calls = [0]
    check = until.finite

    def f(s: int) -> int | None:
        r = memo.get(s)
        if r is not None:
            return r
        calls[0] += 1
        if calls[0] > limit or (check and not calls[0] & 63 and until.expired()):
            return None
        near = 0
        m = s
        while m:
            b = m & -m
            m ^= b
            near |= nbr[b.bit_length() - 1]
        iso = s & ~near
        if iso:
            rest = f(s ^ iso)
            if rest is None:
                return None
            r = rest * one_plus_t ** iso.bit_count()
        else:
            comp = front = s & -s
            while front:
                b = front & -front
                front ^= b
                new = nbr[b.bit_length() - 1] & s & ~comp
                comp |= new
                front |= new
            if comp != s:
                a = f(comp)
                c = f(s ^ comp) if a is not None else None
                if c is None:
                    return None
                r = a * c
            else:
                x = max(bits(s), key=lambda i: (nbr[i] & s).bit_count())
                inside = f(s & ~(below[x] | 1 << x))              # x in the down-set, with all below it
                if inside is None:
                    return None
                out = s & (above[x] | 1 << x)                     # x left out, with all above it
                outside = f(s & ~out)
                if outside is None:
                    return None
                r = inside + (outside << width * out.bit_count())
        memo[s] = r
        return r

    with recursion_room(3 * n + 200):
        packed = f(poset.full)
    if packed is None:
        return None
    return [(packed >> width * r) & slot_mask for r in range(n + 1)]
