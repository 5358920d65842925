"""The schedule: what has been installed, plus *all* admissible ways to finish.

The paper's schedule is "the sequence of steps that have been completed plus
the set of all possible sequences for completing the remaining steps".  A
:class:`Schedule` represents that set without listing it: every question
(how many completions, which parts can go in now, how many options each keeps,
where each part is expected to come) is answered by counting linear
extensions with the memoised :class:`~opportune.engine.count.Counter`.

How a plan becomes posets:

* **Quantities.**  A part with quantity *q* becomes *q* units chained
  ``u1 < u2 < ... < uq``.  Sequences of part ids correspond one-to-one to
  linear extensions of the chained units (exactly one of the *q!* orders of
  interchangeable units is the chained one), so identical units never
  multiply a count.
* **Several strategies.**  The admissible sequences are the union over the
  strategies still consistent with what was installed.  Its size is
  computed by inclusion–exclusion: the sequences admissible under every
  strategy of a set *T* are the linear extensions of the union of their
  orders (zero if that union has a cycle).  One counter per set *T*, each
  keeping its memo for the life of the plan.
"""

from __future__ import annotations

import math
import time
from _thread import allocate_lock     # threading.Lock without threading's import (a count's start-up)
from contextlib import contextmanager
from dataclasses import dataclass, replace
from functools import lru_cache
from itertools import combinations

from opportune.engine.count import MAX_TOTAL, Counter, entries_within
from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline, no_collection
from opportune.engine.hub import HubPath
from opportune.engine.memory import memory_total
from opportune.engine.poset import CycleError, Poset, bits, byte_unions
from opportune.planning.plan import Plan

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    import random
    from typing import Collection, Iterable, Sequence

    from fractions import Fraction     # loaded where a fraction is made: it loads decimal (5 ms at start-up)

MAX_STRATEGIES_EXACT = 12  # inclusion–exclusion has 2^k terms
STATE_CACHE_LIMIT = 300_000  # entries per per-state cache before it is cleared
#: An engine's default ``memory_limit``: a quarter of the machine's memory (a service sets its plan share).
DEFAULT_MEMORY = memory_total() // 4
#: Between two measurements of an engine's bytes in :meth:`OrderEngine.maintain`, seconds (a measurement
#: samples every memo: a few milliseconds; a decision adds a bounded number of entries meanwhile).
MEASURE_EVERY = 0.5
#: Memos over ``memory_limit`` are shrunk to this share of it (room for hours before the next shrink).
SHRINK_TO = 0.5
#: Share of an engine's ``memory_limit`` that programmes kept beside it (a policy's exact optimum,
#: :meth:`OrderEngine.reserve_programme`) may hold in all; the memos keep the rest.
PROGRAMME_SHARE = 0.5
#: Most seconds one :meth:`OrderEngine.maintain` spends shrinking (the rest waits for the next one).
SHRINK_SECONDS = 0.02
HUB_PROBE = 100_000  # new memo entries a plain count may add before counting through a hub is tried
COUNT_MARGIN = 0.25  # seconds Schedule.count_result may take past its deadline (checks' granularity, the answer)
ESTIMATE_RESERVE = 3e-5  # seconds per element an estimate needs for its bounds and first path (~0.25 s for 10,000)
GRACE = 0.05  # seconds the exact count and the estimate each get in count_result when its deadline has passed
#: Seconds of the first turn of the plain count and of the engine's count in count_result's exact phase
#: (each later round twice as long; see Schedule._exact_turns): small orders are exact within the
#: first, and an order that its hub counts in a tenth of a second is not held up by the plain count.
FIRST_TURN = 0.05
#: The plain count's turn, as a share of the engine's, once the engine found a hub: ARC111's plain
#: count never finishes, its hub count takes about 4 s (a quarter more: 5 s, within the default limit).
PLAIN_SHARE = 0.25
#: Most seconds relaxation Monte Carlo takes in count_result's exact phase, after the second round of
#: turns (one strategy; :func:`~opportune.engine.estimate.relaxation_estimate`): it stops as soon as
#: its interval is within EARLY_ERROR (a tenth of a second to two seconds on sparse orders of 64-100
#: elements), and gives the time back at once where it cannot hit; the exact count has the rest.  A
#: fixed time, not a share of the limit: a longer limit must not make an exact count later.
EARLY_SECONDS = 2.0
#: Share of that first estimate's time for counting its relaxations (their own time): where its draws
#: never hit (ARC111), it is found hopeless after this, so that the exact count (through a hub there)
#: loses little (ARC111 exact in about 6 s of the default 10); a quarter left sparse orders of 100
#: elements with pieces of 40 elements, ±9% within 3 s where pieces of 45 give ±4%.
EARLY_COUNT_SHARE = 0.5
#: The relative error at which that first relaxation estimate stops (the error asked, if looser):
#: ±5% takes a few thousand hits; where the exact count then fails too, the estimate phase runs it
#: again towards the error asked.
EARLY_ERROR = 0.05
#: Share of the estimate phase the first relaxation estimate's draws go on for, when it stated an error
#: wider than asked (one strategy): its draws are the best use of the time (the estimate's own split
#: gave them a third, then sequential Monte Carlo runs that are far wider on such orders); the rest is
#: for the estimate's certain bounds and its own go at the draws.
EARLY_RESUME = 0.85


class NotAdmissible(ValueError):
    """Installing a part would leave no admissible sequence (or the part is unknown / used up)."""

    def __init__(self, message: str, part: str | None = None):
        self.part = part
        super().__init__(message)


@dataclass(frozen=True)
class CountResult:
    """A number of admissible sequences: exact, or an estimate with its stated error.

    ``value`` is an ``int`` when ``exact``; otherwise a float estimate whose
    true value lies within ``value * (1 ± rel_error)`` with probability
    ``confidence``.
    """

    value: int | float
    exact: bool = True
    rel_error: float = 0.0
    confidence: float = 1.0
    method: str = "exact"
    #: ``log10`` of an estimate, kept beside ``value``: an estimate past 1.8e308 (a plan of a few
    #: hundred steps) is ``inf`` as a float
    log10_value: float | None = None
    #: ``log10`` of the ends of an interval holding the count: the stated one within the certain
    #: bounds the orders give (so finite for every estimate :meth:`Schedule.count_result` makes;
    #: None where nobody gave one)
    log10_low: float | None = None
    log10_high: float | None = None

    @property
    def log10(self) -> float:
        if self.log10_value is not None:
            return self.log10_value
        return log10_int(self.value) if isinstance(self.value, int) else (
            math.log10(self.value) if self.value > 0 else float("-inf"))

    @property
    def interval_log10(self) -> tuple[float, float] | None:
        """``(log10 low, log10 high)``: the count itself when exact, else the interval given (None
        if none was)."""
        if self.exact:
            return self.log10, self.log10
        if self.log10_low is None or self.log10_high is None:
            return None
        return self.log10_low, self.log10_high


def interval_unbuilt(plan: Plan) -> CountResult:
    """What is certain of a plan's count without building its orders: at least 1 (a plan is checked to
    have an admissible sequence) and at most the sequences of its units with each part's units in
    order, ``n! / (q1! q2! ...)`` (from the log-gamma function, O(parts)).  An estimate, marked so, at
    the middle of that interval (in logarithms).

    >>> from opportune import make_plan
    >>> r = interval_unbuilt(make_plan(["a", "b", "c"], {}))
    >>> r.exact, round(r.log10_high, 6) == round(math.log10(6), 6), r.log10_low
    (False, True, 0.0)
    """
    q = [p.quantity for p in plan.parts]
    high = max(0.0, (math.lgamma(sum(q) + 1) - sum(math.lgamma(k + 1) for k in q)) / math.log(10))
    mid = high / 2
    return CountResult(10.0 ** mid if mid < 308 else math.inf, exact=False, rel_error=math.inf, confidence=1.0,
                       method="bounds", log10_value=mid, log10_low=0.0, log10_high=high)


def _signed_sum_log10(parts: list[tuple[int, float, float]]) -> tuple[float, float]:
    """``(log10 of the sum, its relative error)`` of terms given as ``(sign, log10 of the value,
    relative error)``, the errors adding up; in log space, since the values may be far past a float
    (nan, with an infinite error, if the sum is not positive or a term is unknown).

    >>> log10, rel = _signed_sum_log10([(1, 400.0, 0.1), (-1, 399.0, 0.1)])
    >>> round(log10, 6), round(rel, 6)      # 10^400 - 10^399 = 9 × 10^399, errors 10^399 + 10^398
    (399.954243, 0.122222)
    """
    if not parts or any(math.isnan(lg) for _, lg, _ in parts):
        return float("nan"), math.inf
    top = max(lg for _, lg, _ in parts)
    if top == -math.inf:
        return float("nan"), math.inf
    total = sum(sign * 10.0 ** (lg - top) for sign, lg, _ in parts)
    # an unbounded error stays unbounded however small its term looks (its size is what is unknown)
    err = sum(rel if math.isinf(rel) else rel * 10.0 ** (lg - top) for _, lg, rel in parts if rel)
    if not total > 0:
        return float("nan"), math.inf
    return top + math.log10(total), err / total


def decimal(n: int) -> str:
    """An int as decimal text, however many digits, without lifting Python's guard on int/str
    conversions (4,300 digits: a guard for parsing untrusted text, which stays in force): the number
    is split by a power of ten until the pieces are short enough.

    >>> len(decimal(10 ** 10_000))
    10001
    """
    if n < 0:
        return "-" + decimal(-n)
    if n.bit_length() < 14_000:            # fewer than 4,215 digits
        return str(n)
    half = int(n.bit_length() * 0.30103) // 2
    high, low = divmod(n, 10 ** half)
    return decimal(high) + decimal(low).zfill(half)


#: Plans of more units than this find their installable units with tables of four bits, not eight.
WIDE_TABLES = 2048

#: Counts of more digits than this are written rounded by :func:`count_text`: the same bound as Python's
#: own guard on int-to-text conversion, and for the same reason (exact text is quadratic in the digits:
#: 20 ms for the 35,660 digits of 10,000!, more than a look's budget when an answer holds several).
EXACT_DIGITS = 4_300


def count_text(n: int, exact_digits: int = EXACT_DIGITS) -> str:
    """A count as text: exact decimal when it has at most ``exact_digits`` digits, otherwise its first 17
    significant digits (truncated, not rounded) in scientific notation.  O(d) in the digits d beyond
    the bound (one power of ten and one division), O(d²) within it.

    >>> count_text(336)
    '336'
    >>> count_text(10 ** 5000 + 123, exact_digits=100)
    '1.0000000000000000e+5000'
    >>> count_text(2 ** 20000, exact_digits=100)
    '3.9802768403379665e+6020'
    >>> count_text(12345678901234567, exact_digits=15), count_text(1234567890123456, exact_digits=15)
    ('1.2345678901234567e+16', '1.234567890123456e+15')
    """
    if n < 0:
        return "-" + count_text(-n, exact_digits)
    if n.bit_length() * 0.30103 < exact_digits - 1:     # surely within the bound
        return decimal(n)
    return _count_text(n, exact_digits)


@lru_cache(maxsize=64)   # an answer repeats its counts (a decision's, its row's, the run's): written once
def _count_text(n: int, exact_digits: int) -> str:
    e = int(log10_int(n))              # the exponent, up to the float's last-place error: checked
    p = 10 ** e
    if n < p:
        e, p = e - 1, p // 10
    elif n >= 10 * p:
        e, p = e + 1, 10 * p
    if e < exact_digits:
        return decimal(n)
    head = str(n // (p // 10 ** 16)) if e >= 16 else str(n)   # the first 17 digits (all, if fewer)
    return f"{head[0]}.{head[1:]}e+{e}"


def log10_int(n: int) -> float:
    """``log10(n)`` for an int of any size, without its decimal digits (Python refuses to write ints of
    more than 4,300 digits as text by default, and writing them is quadratic).

    >>> round(log10_int(10 ** 5000), 9)
    5000.0
    """
    if n <= 0:
        return float("-inf")
    shift = max(0, n.bit_length() - 64)
    return math.log10(n >> shift) + shift * math.log10(2)


class OrderEngine:
    """The order engine of one plan: its unit posets and their counters.

    Create one per plan and share it between all schedules, sequencers and
    simulations of that plan: the memo (and the per-state caches below) is
    what makes repeated questions cheap.

    ``max_memo`` and ``time_limit`` bound each exact count; beyond them
    :meth:`Schedule.count_result` falls back to an estimate and says so.  ``max_memo=0``: as many
    entries as ``memory_limit`` (or :data:`DEFAULT_MEMORY`) holds at the order's entry size
    (:func:`~opportune.engine.count.entries_within`), what ``opportune count`` uses.
    """

    def __init__(self, plan: Plan, *, max_memo: int | None = 2_000_000, time_limit: float | None = None,
                 deadline: Deadline | float | None = None, memory_limit: int | None = DEFAULT_MEMORY):
        """``deadline``: building the strategies' orders (a closure per strategy: O(units × covers)
        big-integer operations each, seconds for 64 strategies over 10,000 parts) stops past it with
        ``BudgetExceeded``.  ``memory_limit``: bytes the memos and caches may hold between decisions
        (see :meth:`maintain`; None: only each memo's entry cap)."""
        dl = as_deadline(deadline)
        self.plan = plan
        self.time_limit = time_limit
        if memory_limit is not None and memory_limit <= 0:
            raise ValueError("memory_limit must be a positive number of bytes, or None")
        self.memory_limit = memory_limit
        self.shrunk = 0                 # times maintain() shrank the memos to keep within memory_limit
        self.measure_every = MEASURE_EVERY
        self._measured = (float("-inf"), 0)     # (time.monotonic(), bytes) of the last measurement
        self._pass = None   # a shrink under way: (keep share, [(memo, entries to keep)]) left to do
        #: Bytes granted to programmes kept beside the engine, by name (:meth:`reserve_programme`).
        self.programmes: dict[object, int] = {}
        #: The programmes themselves, kept here by the policies that share them (freed with the engine:
        #: a programme holds its engine, so a table keyed weakly by the engine would keep both forever).
        self.kept: dict[object, object] = {}
        # Units: part i owns units first[i] .. first[i] + quantity - 1, installed in that order.
        self.first: list[int] = []
        self.unit_part: list[int] = []
        for i, part in enumerate(plan.parts):
            self.first.append(len(self.unit_part))
            self.unit_part.extend([i] * part.quantity)
        self.n_units = len(self.unit_part)
        self.full = (1 << self.n_units) - 1
        if max_memo == 0:
            # bytes, not entries: an entry on 1,000 units takes 20 times one on 50
            max_memo = entries_within(self.n_units, memory_limit or DEFAULT_MEMORY)
        self.max_memo = max_memo
        chain = [(u, u + 1) for u in range(self.n_units - 1) if self.unit_part[u] == self.unit_part[u + 1]]
        self.posets: list[Poset] = []
        for strategy in plan.strategies:
            pairs = list(chain)
            for b, a in plan.index_pairs(strategy):
                # Every constraint applies to every unit: last unit of b before first unit of a.
                pairs.append((self.first[b] + plan.parts[b].quantity - 1, self.first[a]))
            self.posets.append(Poset.from_pairs(self.n_units, pairs, deadline=dl))
        self.k = len(self.posets)
        self.all_strategies = (1 << self.k) - 1
        self._counters: dict[int, Counter | None] = {}
        # Per-state caches, keyed by mask | consistent << n_units: one int, no tuple to build and hash.
        self._count_cache: dict[int, int] = {}
        self._options_cache: dict[int, dict[str, int]] = {}
        self._positions_cache: dict[int, tuple[int, dict[int, int]]] = {}  # (count, unit sums)
        self._option_cache: dict[int, tuple[dict, dict[str, int]]] = {}  # (installable, options)
        self._installable_cache: dict[int, frozenset[str]] = {}
        self._terms_cache: dict[int, list] = {}
        self._quantity = [p.quantity for p in plan.parts]
        self._nbytes = max(1, (self.n_units + 7) // 8)
        self._above: list | None = None
        self._unit_ids = [plan.parts[i].id for i in self.unit_part]
        self._part_units = {p.id: ((1 << p.quantity) - 1) << self.first[i] for i, p in enumerate(plan.parts)}
        # Per counter whose plain count failed on a hub: its persistent hub path (None: no hub found).
        self._hubs: dict[Counter, HubPath | None] = {}
        self._hub_search: dict[Counter, HubPath] = {}   # a hub search cut short by a deadline, to resume
        self._probe_left: dict[Counter, int] = {}       # new memo entries the plain probe may still add
        self._until: float | None = None                # the deadline of :meth:`deadline`, if any
        # Decisions under way (see :meth:`deciding`): while any is, caches and memos may grow but are
        # never trimmed or evicted; :meth:`maintain` does that between decisions.
        self._deciding = 0
        self._upkeep_lock = allocate_lock()
        self.upkeep_due = False     # a cache or memo went over its cap during a decision
        self.maintained = 0         # maintain() calls that dropped something

    # ------------------------------------------------------------ posets per strategy set

    def counter(self, strategies: int) -> Counter | None:
        """Counter for the sequences admissible under *every* strategy in the bitmask (None: none are)."""
        if strategies not in self._counters:
            members = [self.posets[s] for s in range(self.k) if strategies >> s & 1]
            poset = members[0]
            try:
                for other in members[1:]:
                    poset = poset.union(other)
            except CycleError:
                self._counters[strategies] = None
            else:
                # a count allowed more entries than a counter usually holds keeps them between its
                # phases (the memory limit still bounds what stays between decisions)
                self._counters[strategies] = Counter(poset, max_memo=self.max_memo, time_limit=self.time_limit,
                                                     max_total=max(MAX_TOTAL, self.max_memo or 0))
                self._counters[strategies].hold_upkeep = self._deciding > 0
        return self._counters[strategies]

    def _terms(self, consistent: int, deadline=None) -> list:
        """Inclusion–exclusion terms ``(sign, counter)`` over the non-empty subsets of ``consistent`` (cached;
        the single strategies first).  Past ``deadline`` (a :class:`~opportune.engine.deadline.Deadline`,
        read before each union of orders), :class:`BudgetExceeded`; the counters made so far are kept."""
        terms = self._terms_cache.get(consistent)
        if terms is not None:
            return terms
        members = [s for s in range(self.k) if consistent >> s & 1]
        if len(members) > MAX_STRATEGIES_EXACT:
            raise BudgetExceeded(f"{len(members)} strategies: inclusion–exclusion over 2^{len(members)} sets")
        terms = []
        for size in range(1, len(members) + 1):
            sign = 1 if size % 2 else -1
            for subset in combinations(members, size):
                if deadline is not None and size > 1:
                    deadline.check("the orders of the strategies' intersections")
                counter = self.counter(sum(1 << s for s in subset))
                if counter is not None:
                    terms.append((sign, counter))
        self._terms_cache[consistent] = terms
        return terms

    # ------------------------------------------------------------ state questions

    def consistent_after(self, mask: int, consistent: int, unit: int) -> int:
        """Strategies (bitmask) in which ``unit`` can be installed on top of ``mask``."""
        if self.k == 1:  # the common case: no loop
            return consistent if self.posets[0].below[unit] & ~mask == 0 else 0
        out = 0
        for s in range(self.k):
            if consistent >> s & 1 and self.posets[s].below[unit] & ~mask == 0:
                out |= 1 << s
        return out

    def next_unit(self, mask: int, part: int) -> int | None:
        """The next uninstalled unit of a part, or None if all are installed."""
        first = self.first[part]
        q = self._quantity[part]
        if q == 1:
            return None if mask >> first & 1 else first
        for u in range(first, first + q):
            if not mask >> u & 1:
                return u
        return None

    def _trim(self) -> None:
        """Bound the per-state caches (not the counters' memos): a long simulation of a large plan
        visits millions of states that never recur; start afresh rather than grow without end.
        During a decision (:meth:`deciding`) only noted: :meth:`maintain` clears them after it."""
        if self._deciding:
            self.upkeep_due = True
            return
        for cache in (self._count_cache, self._option_cache, self._options_cache, self._positions_cache,
                      self._installable_cache):
            if len(cache) > STATE_CACHE_LIMIT:
                cache.clear()

    def nbytes(self) -> int:
        """Estimated bytes this engine holds: the strategies' orders, every counter's memos and tables,
        hub paths and the per-state caches (sampled, so O(counters + caches), not O(entries); see
        :mod:`opportune.engine.memory`).  What a service accounts per plan.

        >>> from opportune import make_plan
        >>> OrderEngine(make_plan(["a", "b"], {"b": ["a"]})).nbytes() > 0
        True
        """
        from opportune.engine.memory import nbytes, poset_nbytes

        total = sum(poset_nbytes(p) for p in self.posets)
        for counter in list(self._counters.values()):
            if counter is not None:
                total += counter.nbytes() - (poset_nbytes(counter.poset) if counter.poset in self.posets else 0)
        for hub in list(self._hubs.values()) + list(self._hub_search.values()):
            if hub is not None:
                total += hub.nbytes()
        for cache in (self._count_cache, self._options_cache, self._positions_cache, self._option_cache,
                      self._installable_cache):
            total += nbytes(cache)
        return total + nbytes(self._above, depth=3) + sum(self.programmes.values())

    def reserve_programme(self, name, nbytes: int) -> bool:
        """Grant ``nbytes`` to a programme kept beside this engine (a policy's exact optimum, sized
        before it starts), under ``name`` (a second grant under a name replaces the first): True
        where the programmes' bytes stay within :data:`PROGRAMME_SHARE` of ``memory_limit`` (always
        without a limit), else False and nothing is granted.  Granted bytes count in :meth:`nbytes`
        (what a service accounts per plan) and are not shrunk: :meth:`maintain` keeps the memos within
        the rest of the limit.  O(programmes).

        >>> from opportune import make_plan
        >>> e = OrderEngine(make_plan(["a"], {}), memory_limit=1000)
        >>> e.reserve_programme("optimum", 400), e.reserve_programme("other", 400), e.nbytes() > 400
        (True, False, True)
        """
        others = sum(b for n, b in self.programmes.items() if n != name)
        if self.memory_limit is not None and others + nbytes > PROGRAMME_SHARE * self.memory_limit:
            return False
        self.programmes[name] = int(nbytes)
        return True

    def clear_state_caches(self) -> None:
        """Forget the per-state caches (options, positions, installable sets; not the counters' memos):
        what a service does to a plan over its memory share between requests.  Later questions about
        those states are counted again (from the memos).  O(1) per cache."""
        for cache in (self._count_cache, self._option_cache, self._options_cache, self._positions_cache,
                      self._installable_cache):
            cache.clear()

    def count(self, mask: int, consistent: int) -> int:
        """Exact number of admissible completions after installing ``mask`` (raises BudgetExceeded)."""
        terms = self._terms_cache.get(consistent)
        if terms is None:
            terms = self._terms(consistent)
        if len(terms) == 1:  # one strategy: no inclusion–exclusion, and the counter's memo is the cache
            remaining = self.full & ~mask
            r = terms[0][1].cached(remaining)
            return r if r is not None else self._term_count(terms[0][1], remaining)
        key = mask | consistent << self.n_units
        cached = self._count_cache.get(key)
        if cached is not None:
            return cached
        if len(self._count_cache) > STATE_CACHE_LIMIT:
            self._trim()
        remaining = self.full & ~mask
        total = 0
        for sign, counter in terms:
            total += sign * self._term_count(counter, remaining)
        self._count_cache[key] = total
        return total

    # ------------------------------------------------------------ counting through a hub

    def _term_count(self, counter: Counter, s: int) -> int:
        """``counter.count(s)``, through a hub (:class:`~opportune.engine.hub.HubPath`) when the plain count fails.

        The plain count is tried first with at most ``HUB_PROBE`` new memo entries (over all
        calls: a probe cut short by a time limit resumes where it stopped); only if that
        fails is a hub looked for (once per counter; a search cut short by a time limit
        resumes too, its memos kept).  A counter with a hub sends every set holding it
        (with some of what precedes it) to the hub path, whose memos persist: the nested
        sets of a simulation cost milliseconds.  Counts are exact either way; a plan the
        plain counter handles never leaves it.
        """
        r = counter.cached(s)
        if r is not None:
            return r
        if self._until is not None:
            self._check_until()
            counter.deadline = self._until if counter.deadline is None else min(counter.deadline, self._until)
        if counter in self._hubs:
            hub = self._hubs[counter]
            if hub is not None and hub.applies(s):
                v = hub.count(s, deadline=self._deadline(counter))
                if v is not None:
                    counter.learn(s, v)
                    return v
            return counter.count(s)
        hub = self._hub_search.get(counter)
        if hub is None:
            limit = counter.max_memo
            if limit is not None and limit <= HUB_PROBE:
                return counter.count(s)
            left = self._probe_left.get(counter, HUB_PROBE)
            counter.max_memo = left
            before = counter.memo_size
            try:
                return counter.count(s)
            except BudgetExceeded as exc:
                if exc.reason != "memo":
                    self._probe_left[counter] = left - max(0, counter.memo_size - before)   # (a memo reset shrinks it)
                    if self._probe_left[counter] > 0:
                        raise
            finally:
                counter.max_memo = limit
            hub = self._hub_search[counter] = HubPath(counter.poset, max_memo=limit, deadline=self._deadline(counter))
            hub.counter.hold_upkeep = self._deciding > 0
        v = hub.count(s, deadline=self._deadline(counter), discover=True)   # a time limit raises: resumed later
        del self._hub_search[counter]
        if v is not None and hub.tails:
            self._hubs[counter] = hub
            counter.learn(s, v)
            return v
        self._hubs[counter] = None
        return counter.count(s)             # plainly, continuing from the probe's memo

    def _check_until(self) -> None:
        """Raise BudgetExceeded once the deadline of :meth:`deadline` has passed: a decision that asks
        for many counts, each quick (memo hits in the compiled core), must still stop on time."""
        now = time.perf_counter()
        if now > self._until:
            raise BudgetExceeded("the deadline has passed", reason="time", elapsed=0.0)

    @property
    def decision_deadline(self) -> Deadline:
        """The deadline :meth:`deadline` set for the decision under way (``Deadline.NEVER`` outside one):
        programmes beside the engine that count nothing through it (a compiled optimum) keep it too.
        O(1).

        >>> from opportune import make_plan
        >>> engine = OrderEngine(make_plan(["a", "b"], {"b": ["a"]}))
        >>> engine.decision_deadline.finite
        False
        >>> with engine.deadline(0.0):
        ...     engine.decision_deadline.at
        0.0
        """
        return as_deadline(self._until)

    @contextmanager
    def deadline(self, until: float | None):
        """Within the block, every exact count of this engine stops at ``until`` (a
        ``time.perf_counter()`` value), raising :class:`BudgetExceeded`: one deadline for
        all the counts of a decision, not a limit per count.  What was counted stays in
        the memos, so a later call continues from there.
        """
        # An absolute stop (Counter.deadline), not a time limit from each count's start: work done
        # before a count (a probe, a hub search) must not push the end of the decision later.
        saved = self._until, {key: c.deadline for key, c in self._counters.items() if c is not None}
        self._until = until
        try:
            yield self
        finally:
            self._until = saved[0]
            for key, c in self._counters.items():
                if c is not None:
                    c.deadline = saved[1].get(key)

    # ------------------------------------------------------------ upkeep between decisions

    def _all_counters(self) -> list[Counter]:
        out = [c for c in list(self._counters.values()) if c is not None]
        for hub in list(self._hubs.values()) + list(self._hub_search.values()):
            if hub is not None:
                out.append(hub.counter)
        return out

    @contextmanager
    def deciding(self):
        """Within the block (a decision), memos and per-state caches may grow past their caps but are
        never evicted, trimmed or restarted: dropping hundreds of thousands of entries took a decision
        of a long-running cell past its budget (207 ms against 50).  :meth:`maintain`, called between
        looks (the sequencer does it after each outcome), does that work.  What piles up meanwhile is
        bounded by the decision's budget.  Blocks may nest and overlap (threads sharing the engine).

        >>> from opportune import make_plan
        >>> e = OrderEngine(make_plan(["a", "b"], {"b": ["a"]}))
        >>> with e.deciding():
        ...     e.count(0, e.all_strategies)
        1
        >>> e.maintain()
        False
        """
        with self._upkeep_lock:
            self._deciding += 1
            for c in self._all_counters():
                c.hold_upkeep = True
        try:
            yield self
        finally:
            with self._upkeep_lock:
                self._deciding -= 1
                if not self._deciding:
                    for c in self._all_counters():
                        c.hold_upkeep = False

    def maintain(self) -> bool:
        """Between decisions: clear the per-state caches over their cap and evict or restart every
        counter's memo over its own (:meth:`Counter.maintain`).  Does nothing while a decision is under
        way (another thread's); True if anything was dropped.  Complexity: O(counters + caches) when
        all are under their caps, else O(entries dropped)."""
        with self._upkeep_lock:
            if self._deciding:
                return False
            self.upkeep_due = False
            dropped = False
            for cache in (self._count_cache, self._option_cache, self._options_cache, self._positions_cache,
                          self._installable_cache):
                if len(cache) > STATE_CACHE_LIMIT:
                    cache.clear()
                    dropped = True
            for c in self._all_counters():
                dropped |= c.maintain()
            if self.memory_limit is not None:
                dropped |= self._keep_within(self.memory_limit)
            self.maintained += dropped
            return dropped

    def _keep_within(self, limit: int, *, now: float | None = None) -> bool:
        """Measure the engine's bytes (at most every ``measure_every`` seconds) and, if they are
        over ``limit``, clear the per-state caches and drop the oldest entries of every memo (counts,
        vectors, tail distributions; the compiled memos restart) in proportion, until about
        :data:`SHRINK_TO` of ``limit`` is held.  A shrink stops after :data:`SHRINK_SECONDS` and goes on
        at the next call, without waiting for a measurement: memos that grow faster than one slice
        per measurement drops were kept over their limit before.  Caller holds ``_upkeep_lock``
        between decisions.  True if anything was dropped.  O(memos) to measure, O(entries dropped) to
        shrink."""
        now = time.monotonic() if now is None else now
        if self._pass is not None:
            self._drop(self._pass[0], Deadline.after(SHRINK_SECONDS))
            self._measured = (now, self.nbytes()) if self._pass is None else (now, self._measured[1])
            return True
        if now < self._measured[0] + self.measure_every:
            return False
        used = self.nbytes()
        self._measured = (now, used)
        if used <= limit:
            return False
        self.shrunk += 1
        # the programmes' grants are not shrunk: the memos keep within the rest
        kept = sum(self.programmes.values())
        self._drop(SHRINK_TO * max(0, limit - kept) / max(1, used - kept), Deadline.after(SHRINK_SECONDS), fresh=True)
        if self._pass is None:
            self._measured = (now, self.nbytes())
        return True

    def shrink(self, keep: float = 0.0, deadline: Deadline | float | None = None) -> bool:
        """Drop all but the newest ``keep`` share of every memo and clear the per-state caches, now
        (between decisions): what a service does when the whole process is over its memory cap.
        Later questions are counted again.  Stops at ``deadline`` (what is left is valid; the next
        call with the same ``keep`` goes on where it stopped); True if it finished.  O(entries dropped)."""
        with self._upkeep_lock:
            if self._deciding:
                return False
            self._measured = (float("-inf"), 0)
            return self._drop(keep, as_deadline(deadline), fresh=self._pass is None or self._pass[0] != keep)

    def _shrinkables(self) -> list:
        """Every memo :meth:`_drop` shrinks: the counters (their own and the hubs') and the hubs' tail memos."""
        out: list = list(self._all_counters())
        for hub in list(self._hubs.values()) + list(self._hub_search.values()):
            if hub is not None:
                out.extend(hub.tails.values())
        return out

    def _drop(self, keep: float, deadline: Deadline, *, fresh: bool = False) -> bool:
        """Shrink every memo to its newest ``keep`` share, within ``deadline``: dropping a million entries
        takes a large share of a second, and a plan's other runs wait meanwhile.  Each memo's target is
        a number of entries fixed when the pass starts (``fresh``), so a pass resumed by a later call
        drops what is left of it, no more.  True if the pass is done (else it stays in ``_pass``)."""
        if fresh or self._pass is None:
            self.clear_state_caches()
            self._pass = (keep, [(m, int(keep * m.entries())) for m in self._shrinkables()])
        todo = self._pass[1]
        try:
            while todo:
                memo, target = todo[-1]
                n = memo.entries()
                if n > target:
                    memo.shrink(target / n, deadline)
                todo.pop()
        except BudgetExceeded:
            return False
        self._pass = None
        return True

    def warm_up(self, time_limit: float | None = None, mask: int = 0, consistent: int | None = None) -> bool:
        """Build what every decision uses (:meth:`prepare`), then count a state exactly (default: the
        first), within ``time_limit`` seconds in all: this chooses how the plan is counted (finding a
        hub if it has one) and fills the memos every later question uses.  True if it finished; if
        not, what it built and counted is kept.  Callers above the engine use :meth:`Schedule.warm_up`.
        """
        until = time.perf_counter() + time_limit if time_limit is not None else None
        try:
            self.prepare(until)
            with self.deadline(until):
                self.count(mask, self.all_strategies if consistent is None else consistent)
        except BudgetExceeded:
            return False
        return True

    def prepare(self, deadline: Deadline | float | None = None) -> None:
        """Build the plan's tables that any decision needs, so that none is built inside one: the tables
        that find installable units, and each strategy's cover pairs (where the chains of an estimate
        move).  O(n / 4 · 16 + covers) big-integer operations per strategy, once per engine; each
        table is kept when finished, the rest raises ``BudgetExceeded`` past ``deadline``.

        >>> from opportune import make_plan
        >>> OrderEngine(make_plan(["a", "b"], {"b": ["a"]})).prepare()
        """
        dl = as_deadline(deadline)
        dl.check("preparing the plan's tables")
        self._above_tables()
        for poset in self.posets:
            dl.check("preparing the plan's tables")
            poset.cover_pairs(deadline=dl)

    def _deadline(self, counter: Counter) -> float:
        """When the work on one count must stop: the deadline of :meth:`deadline` if one is set (it
        covers everything a decision counts), else the counter's own time limit from now."""
        if self._until is not None:
            return self._until
        return time.perf_counter() + counter.time_limit if counter.time_limit is not None else float("inf")

    def _hub_for(self, counter: Counter, s: int) -> HubPath | None:
        """The hub path of ``counter`` if it applies to ``s`` (after a count of ``s`` has chosen the way)."""
        hub = self._hubs.get(counter)
        return hub if hub is not None and hub.applies(s) else None

    def _term_position_sums(self, counter: Counter, s: int, units: Iterable[int] | None = None) -> dict[int, int]:
        """Position sums of ``units`` (default: all of ``s``) over the orders of ``s`` under one counter."""
        self._term_count(counter, s)            # chooses the way (and finds the hub) if not done yet
        if self._until is not None:
            self._check_until()
            counter.deadline = self._until if counter.deadline is None else min(counter.deadline, self._until)
        hub = self._hub_for(counter, s)
        if hub is None:
            sums = counter.position_sums(s)
            return sums if units is None else {u: sums[u] for u in units}
        out = {}
        deadline = self._deadline(counter)
        for u in (_bits(s) if units is None else units):
            v = hub.position_sum(s, u, deadline=deadline)
            if v is None and self._until is not None:
                # the plain vectors have no deadline (a 1,000-task plan took a minute): within a decision's
                # budget, give up instead
                raise BudgetExceeded("the expected positions need the plain vectors", reason="time")
            if v is None:       # not of the hub form after all: the plain vectors (may exceed a time limit)
                sums = counter.position_sums(s)
                return sums if units is None else {u: sums[u] for u in (_bits(s) if units is None else units)}
            out[u] = v
        return out

    def options(self, mask: int, consistent: int) -> dict[str, int]:
        """For each part installable now: admissible completions left after installing it (declaration order)."""
        key = mask | consistent << self.n_units
        cached = self._options_cache.get(key)
        if cached is not None:
            return cached
        out: dict[str, int] = {}
        for i, part in enumerate(self.plan.parts):
            u = self.next_unit(mask, i)
            if u is None:
                continue
            after = self.consistent_after(mask, consistent, u)
            if after:
                out[part.id] = self.count(mask | 1 << u, after)
        self._options_cache[key] = out
        return out

    def installable_set(self, mask: int, consistent: int) -> frozenset[str]:
        """The parts installable in a state, as a set (cached; no counting)."""
        key = mask | consistent << self.n_units
        out = self._installable_cache.get(key)
        if out is None:
            out = frozenset(self.installable(mask, consistent))  # the scan options_for keeps for the state
            self._installable_cache[key] = out
        return out

    def options_for(self, mask: int, consistent: int, parts: Collection[str]) -> dict[str, int]:
        """:meth:`options` restricted to ``parts`` (those installable), counting only what is asked.

        On large plans a decision needs the options of the few visible or buffered
        parts, not of every installable part.  Per state, the installable units are
        found once and each count is cached; the parts asked about are then looked up
        one by one (O(k) big-integer operations for k parts asked about, not O(n) for the
        n installable parts).  Declaration order, like :meth:`options`.
        """
        key = mask | consistent << self.n_units
        entry = self._option_cache.get(key)
        if entry is None:
            full = self._options_cache.get(key)
            if full is not None:
                return {p: n for p, n in full.items() if p in parts}
            entry = self._option_entry(key, mask, consistent)
        known = entry[2]
        out: dict[str, int] = {}
        for part, unit in self._next_units(entry, mask, parts):
            value = known.get(part)
            if value is None:
                after = self.consistent_after(mask, consistent, unit)
                value = known[part] = self.count(mask | 1 << unit, after)
            out[part] = value
        return out

    def installable(self, mask: int, consistent: int) -> tuple[str, ...]:
        """The parts installable in a state, in declaration order, without counting anything.

        >>> from opportune import make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"a": ["c"]}))
        >>> engine.installable(0, engine.all_strategies)
        ('b', 'c')
        """
        key = mask | consistent << self.n_units
        entry = self._option_cache.get(key)
        if entry is None:
            entry = self._option_entry(key, mask, consistent)
        return tuple(self._entry_parts(entry))

    @contextmanager
    def time_limited(self, seconds: float | None):
        """Within the block, every exact count of this engine gives up after ``seconds``
        (raising :class:`BudgetExceeded`; what it counted stays in the memo).

        For a caller that must know early whether exact counting is affordable on a plan,
        without waiting for the memo budget to run out.
        """
        saved = self.time_limit, {key: c.time_limit for key, c in self._counters.items() if c is not None}
        self.time_limit = seconds
        for c in self._counters.values():
            if c is not None:
                c.time_limit = seconds
        try:
            yield self
        finally:
            self.time_limit = saved[0]
            for key, c in self._counters.items():
                if c is not None:
                    c.time_limit = saved[1].get(key, saved[0])

    def installable_among(self, mask: int, consistent: int, parts: Collection[str]) -> list[str]:
        """Those of ``parts`` installable now (declaration order), without counting anything.

        Shares the per-state table of :meth:`options_for`, so asking this first and the
        options next costs one scan of the state.  A decision with a single candidate
        needs no count at all.

        >>> from opportune import make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> engine.installable_among(0, engine.all_strategies, ("c", "b"))
        ['b']
        """
        key = mask | consistent << self.n_units
        entry = self._option_cache.get(key)
        if entry is None:
            entry = self._option_entry(key, mask, consistent)
        return [part for part, _ in self._next_units(entry, mask, parts)]

    def _option_entry(self, key: int, mask: int, consistent: int) -> list:
        """The per-state entry of :meth:`options_for`: ``[installable units (a bitmask), the installable
        parts with their next unit's number (built when first asked for all of them), the options
        counted so far]``."""
        if len(self._option_cache) > STATE_CACHE_LIMIT:
            self._trim()
        entry = self._option_cache[key] = [self.installable_units(mask, consistent), None, {}]
        return entry

    def _entry_parts(self, entry: list) -> dict[str, int]:
        """Every installable part of a state's entry with its next unit's number (declaration order)."""
        if entry[1] is None:
            ids = self._unit_ids
            # unit numbers, not bits: n bits of n bits each would be O(n²) time and memory (12 MB on 10,000 parts)
            entry[1] = {ids[u]: u for u in _bits(entry[0])}
        return entry[1]

    def _next_units(self, entry: list, mask: int, parts: Collection[str]) -> list[tuple[str, int]]:
        """``(part, its next unit)`` for those of ``parts`` installable in the entry's state (declaration
        order).  O(k log k) big-integer operations for k parts (each O(n / 64) on n units), unless the
        entry already holds every installable part."""
        asked = parts if isinstance(parts, (set, frozenset)) else set(parts)   # a look may name a part twice
        if entry[1] is not None:
            can = entry[1]
            if len(asked) >= len(can):
                return [(p, u) for p, u in can.items() if p in asked]
            return sorted(((p, can[p]) for p in asked if p in can), key=lambda pu: pu[1])
        out = []
        units, installable = self._part_units, entry[0]
        for part in asked:
            left = units.get(part, 0) & ~mask
            if left:
                unit = (left & -left).bit_length() - 1   # a part's units go in in order: the lowest left
                if installable >> unit & 1:
                    out.append((part, unit))
        out.sort(key=lambda pu: pu[1])
        return out

    def installable_units(self, mask: int, consistent: int) -> int:
        """Bitmask of the units that can be installed now: the minimal remaining units under some
        consistent strategy (at most one per part, its next unit: a part's units are chained).

        A unit is minimal unless it is above some remaining unit; the union of what lies above
        the remaining units is gathered a byte of the set at a time from :meth:`_above_tables`.
        """
        remaining = self.full & ~mask
        data = remaining.to_bytes(self._nbytes, "little")
        out = 0
        for s, tables in enumerate(self._above_tables()):
            if consistent >> s & 1:
                up = 0
                if self.n_units <= WIDE_TABLES:
                    for table, byte in zip(tables, data):
                        if byte:
                            up |= table[byte]
                else:   # tables of four bits (see _above_tables)
                    for low, high, byte in zip(tables[0::2], tables[1::2], data):
                        if byte:
                            up |= low[byte & 15] | high[byte >> 4]
                out |= remaining & ~up
        return out

    def _above_tables(self) -> list[list[list[int]]]:
        """Per strategy and byte ``j`` of a unit set: ``table[v]`` is the union of ``above[u]``
        over the units ``u`` that the byte value ``v`` holds (built on first use)."""
        tables = self._above
        if tables is None:
            # past WIDE_TABLES units, tables of four bits: byte tables hold 32 n sets of up to n bits
            # (390 MB and 0.6 s to build on a 10,000-unit assembly graph), these 4 n
            width = 8 if self.n_units <= WIDE_TABLES else 4
            tables = self._above = [byte_unions(poset.above, self.n_units, width) for poset in self.posets]
        return tables

    def expected_positions(self, mask: int, consistent: int) -> dict[str, Fraction]:
        """Expected position (1 = next) of each remaining part's next unit (declaration order)."""
        total, sums = self.position_sums_for(mask, consistent, (p.id for p in self.plan.parts))
        from fractions import Fraction

        return {part: Fraction(s, total) for part, s in sums.items()}

    def position_sums_for(self, mask: int, consistent: int, parts: Iterable[str]) -> tuple[int, dict[str, int]]:
        """``(completions, {part: sum of its next unit's positions})`` for those of ``parts`` remaining.

        Each sum over the completions count is an expected position: one denominator for
        all, so comparing sums compares expected positions, without fractions.  Computed
        once per state (a buffer decision compares the two or three visible parts).
        """
        key = mask | consistent << self.n_units
        table = self._positions_cache.get(key)
        if table is None:
            if len(self._positions_cache) > STATE_CACHE_LIMIT:
                self._trim()
            total = self.count(mask, consistent)
            if self._hub_state(mask, consistent):   # through a hub: only the units asked for, one by one
                table = self._positions_cache[key] = (total, {})
            else:
                table = self._positions_cache[key] = (total, self.position_sums(mask, consistent))
        total, by_unit = table
        units = self._part_units
        out: dict[str, int] = {}
        for part in parts:
            left = units[part] & ~mask
            if left:  # the next unit is the lowest one left
                unit = (left & -left).bit_length() - 1
                value = by_unit.get(unit)
                if value is None:
                    value = by_unit[unit] = self._unit_position_sum(mask, consistent, unit)
                out[part] = value
        return total, out

    def _hub_state(self, mask: int, consistent: int) -> bool:
        """Whether some counter of the state counts it through a hub (never on plans the plain counter handles)."""
        if not self._hubs:
            return False
        remaining = self.full & ~mask
        return any(self._hub_for(counter, remaining) is not None for _, counter in self._terms(consistent))

    def _unit_position_sum(self, mask: int, consistent: int, unit: int) -> int:
        remaining = self.full & ~mask
        return sum(sign * self._term_position_sums(counter, remaining, (unit,))[unit]
                   for sign, counter in self._terms(consistent))

    def position_sums(self, mask: int, consistent: int) -> dict[int, int]:
        """Sum over all admissible completions of each remaining unit's 1-based position."""
        remaining = self.full & ~mask
        terms = self._terms(consistent)
        if len(terms) == 1:  # one strategy: the counter's own (fresh) table
            return self._term_position_sums(terms[0][1], remaining)
        sums: dict[int, int] = {}
        for sign, counter in terms:
            for unit, value in self._term_position_sums(counter, remaining).items():
                sums[unit] = sums.get(unit, 0) + sign * value
        return sums


#: Passes over every unit of a plan made to answer ``remaining`` or ``in_bin``, by name: a test
#: reads them to check that a service look makes a bounded number of them, whatever the plan's size.
PASSES: dict[str, int] = {}


def count_pass(name: str) -> None:
    """Count one pass over every unit (see :data:`PASSES`)."""
    PASSES[name] = PASSES.get(name, 0) + 1


class Schedule:
    """A schedule: the parts installed so far (in order) plus all admissible completions.

    Immutable: :meth:`install` returns a new schedule sharing the plan's
    :class:`OrderEngine` (and so its memo), which makes branching cheap.

    >>> from opportune import make_plan
    >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
    >>> s.count(), s.installable()
    (3, ('a', 'b'))
    >>> s.options()
    {'a': 2, 'b': 1}
    >>> s.install("b").count()
    1
    """

    __slots__ = ("engine", "plan", "installed", "mask", "consistent", "_left")

    def __init__(self, plan_or_engine: Plan | OrderEngine, installed: Iterable[str] = ()):
        engine = plan_or_engine if isinstance(plan_or_engine, OrderEngine) else OrderEngine(plan_or_engine)
        self.engine = engine
        self.plan = engine.plan
        self.installed: tuple[str, ...] = ()
        self.mask = 0
        self.consistent = engine.all_strategies
        self._left: dict[str, int] | None = None   # ``remaining``, once asked (see there)
        for part in installed:
            self._install_in_place(part)

    @classmethod
    def _make(cls, engine, installed, mask, consistent) -> "Schedule":
        s = object.__new__(cls)
        s.engine, s.plan, s.installed, s.mask, s.consistent = engine, engine.plan, installed, mask, consistent
        s._left = None
        return s

    @classmethod
    def at(cls, engine: OrderEngine, mask: int, consistent: int, installed: tuple[str, ...] = ()) -> "Schedule":
        """The schedule of ``engine`` at a state given as bitmasks: ``mask`` the installed units,
        ``consistent`` the strategies still open (``installed`` the sequence, if the caller keeps it).
        What a policy deciding on masks asks its counting questions through, so that every count goes
        through this class.  O(1): no check that the state is reachable (the caller's states are).

        >>> from opportune import make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> Schedule.at(engine, 0b001, engine.all_strategies).options()
        {'b': 1, 'c': 1}
        """
        return cls._make(engine, installed, mask, consistent)

    # ------------------------------------------------------------ state

    def _locate(self, part: str) -> tuple[int, int, int]:
        if part not in self.plan:
            raise NotAdmissible(f"unknown part '{part}'", part)
        i = self.plan.index(part)
        u = self.engine.next_unit(self.mask, i)
        if u is None:
            q = self.plan.parts[i].quantity
            raise NotAdmissible(
                f"part '{part}' is already installed" + (f" ({q} of {q} units)" if q > 1 else ""), part)
        after = self.engine.consistent_after(self.mask, self.consistent, u)
        if not after:
            missing = self.missing_before(part)
            raise NotAdmissible(
                f"part '{part}' cannot be installed yet: it requires {', '.join(missing)} first"
                if missing else f"installing '{part}' now leaves no admissible sequence", part)
        return i, u, after

    def _install_in_place(self, part: str) -> None:
        _, u, after = self._locate(part)
        self.installed += (part,)
        self.mask |= 1 << u
        self.consistent = after
        self._left = None

    def install(self, part: str) -> "Schedule":
        """The schedule after installing one unit of ``part``; raises :class:`NotAdmissible`."""
        _, u, after = self._locate(part)
        s = Schedule._make(self.engine, self.installed + (part,), self.mask | 1 << u, after)
        left = self._left
        if left is not None:   # one part fewer: a C-level copy, not another pass over the units
            left = dict(left)
            if left[part] == 1:
                del left[part]
            else:
                left[part] -= 1
            s._left = left
        return s

    def can_install(self, part: str) -> bool:
        try:
            self._locate(part)
        except NotAdmissible:
            return False
        return True

    def missing_before(self, part: str) -> list[str]:
        """Parts still to install before ``part`` in the consistent strategy that misses the fewest."""
        i = self.plan.index(part)
        u = self.engine.next_unit(self.mask, i)
        if u is None:
            return []
        best = None
        for s in range(self.engine.k):
            if self.consistent >> s & 1:
                lacking = self.engine.posets[s].below[u] & ~self.mask
                parts = sorted({self.engine.unit_part[v] for v in _bits(lacking)} - {i})
                if best is None or len(parts) < len(best):
                    best = parts
        return [self.plan.parts[j].id for j in best or []]

    @property
    def remaining(self) -> dict[str, int]:
        """Units still to install, per part (declaration order; parts with none left omitted).

        Found once per schedule, by one pass over the units left (O(units)), and carried to the
        schedules :meth:`install` makes (a dictionary copy): a service look asks for it several times.
        A new dictionary each time (the caller may change it).

        >>> from opportune import make_plan
        >>> Schedule(make_plan(["a", "b"], {})).install("b").remaining
        {'a': 1}
        """
        left = self._left
        if left is None:
            count_pass("remaining")
            left = {}
            for u in _bits(self.engine.full & ~self.mask):
                pid = self.plan.parts[self.engine.unit_part[u]].id
                left[pid] = left.get(pid, 0) + 1
            self._left = left
        return dict(left)

    @property
    def is_complete(self) -> bool:
        return self.mask == self.engine.full

    @property
    def consistent_strategies(self) -> tuple[str, ...]:
        """Names of the strategies the installed sequence still respects."""
        return tuple(s.name for k, s in enumerate(self.plan.strategies) if self.consistent >> k & 1)

    # ------------------------------------------------------------ questions

    def installable(self) -> tuple[str, ...]:
        """Parts that can be installed now (all their required parts installed in some consistent strategy)."""
        return self.engine.installable(self.mask, self.consistent)

    def count(self) -> int:
        """Exact number of admissible completions (raises BudgetExceeded if over budget): the value of
        ``count_result(estimate=False)``."""
        return self.engine.count(self.mask, self.consistent)

    def warm_up(self, time_limit: float | None = None) -> bool:
        """Prepare the engine's tables and count this state exactly within ``time_limit`` seconds
        (:meth:`OrderEngine.warm_up`): how the plan is counted (a hub or not) is chosen here, once,
        and the memos every later question uses are filled.  True if it finished in time; what was
        built and counted is kept either way.  O(one exact count).

        >>> from opportune import make_plan
        >>> Schedule(make_plan(["a", "b"], {"b": ["a"]})).warm_up(1.0)
        True
        """
        return self.engine.warm_up(time_limit, self.mask, self.consistent)

    def chains(self, strategy: int, *, chains: int = 8, seed: int = 0):
        """A population of Markov chains on this state's completions under one strategy (its index),
        for estimates when the exact counts do not fit a decision's budget
        (:class:`~opportune.engine.sampling.CompletionChains`).  O(steps left × chains) to start.

        >>> from opportune import make_plan
        >>> pop = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]})).chains(0, seed=1)
        >>> est = pop.estimate(first=[0, 1], steps=20_000)
        >>> abs(est.first[0][0] - 2 / 3) < 0.05
        True
        """
        from opportune.engine.sampling import CompletionChains    # here: a count never draws

        return CompletionChains(self.engine.posets[strategy], self.engine.full & ~self.mask, chains=chains, seed=seed)

    def count_result(self, *, rel_error: float = 0.01, time_limit: float = 10.0, seed: int = 0,
                     exact_share: float = 0.65, deadline=None, threads: int = 1, estimate: bool = True) -> CountResult:
        """Number of completions: exact within the engine's budget, else a clearly marked estimate
        with an interval.  The one way to count a state: the exact methods, the hub split and the
        estimates are chosen here (and in :meth:`OrderEngine.count` for the exact part), never by
        the caller.

        ``estimate=False``: the exact count alone, the same way, within ``deadline`` (a
        :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()`` moment), or with
        ``deadline=None`` within whatever :meth:`OrderEngine.deadline` the caller holds, else the
        engine's time limit per count; :class:`~opportune.engine.deadline.BudgetExceeded` if it does
        not fit (what was counted stays in the memos).  ``time_limit`` and the estimate's settings
        are then unused.  :meth:`count` is the same, as a plain ``int``.

        Everything stops at one :class:`~opportune.engine.deadline.Deadline`: ``plain + time_limit``
        seconds from the call, or ``deadline`` if sooner, where ``plain`` is the engine's own time
        limit, or a tenth of ``time_limit`` if it has none.  The call returns within that plus
        ``COUNT_MARGIN`` (0.25 s of CPU time, measured at most 0.1 s past it on orders of up to
        10,000 elements: the granularity of the deadline checks and assembling the answer; no automatic
        cycle collection runs inside it, see :func:`~opportune.engine.deadline.no_collection`).  Phases:

        (The phases' times below are scaled down if ``deadline`` leaves less than ``plain +
        time_limit``, and the exact phases end early enough to leave the estimate its pass over
        each order, ``ESTIMATE_RESERVE`` seconds per element.  A deadline already passed still
        gives the first turn and the estimate ``GRACE`` seconds each: a small plan is exact.)

        1. the exact count until ``plain + exact_share * time_limit`` seconds (the memos and each
           piece's progress kept from turn to turn): the plain count (each counter by itself, choosing a
           method per hard piece: see :class:`~opportune.engine.count.Counter`) and the engine's count
           (which looks for a hub and counts through it: :mod:`opportune.engine.hub`) in turns of
           ``FIRST_TURN`` seconds, doubling every round, with relaxation Monte Carlo's go (at most
           ``EARLY_SECONDS``) after the second round.  No turn's length depends on ``time_limit``, which
           only cuts the turns short: an exact count that fits one limit comes at the same moment with
           any longer one;
        2. if still not exact, the estimate (:func:`~opportune.engine.estimate.estimate_count`)
           gets the rest, shared between the inclusion–exclusion terms (without its own hub split
           if the exact phases looked for a hub already): certain bounds from each order and
           Knuth's estimator from its first path on, then sequential Monte Carlo runs where they
           fit (fewer particles, down to 64, when time is short), stopping early once the 95%
           interval is within ``rel_error``.

        The answer always has a value, and an estimate always has a finite interval
        (``log10_low``/``log10_high``: the stated interval within the order's certain bounds,
        ``1 <= count <= n!`` at the very least); ``rel_error`` is infinite when no error could be
        stated from the runs.  Building the inclusion–exclusion terms is inside the budget (a
        deadline between unions); building the engine's orders is the caller's (O(units + pairs)
        big-int operations, ~0.1 s for 10,000 units).  ``threads``: threads that count and draw in
        relaxation Monte Carlo (its counts, draws and answer are the same for any number, but for a
        stop on the clock; the exact phases use one).

        >>> from opportune import make_plan
        >>> r = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]})).count_result(time_limit=1.0)
        >>> r.value, r.exact, r.interval_log10 == (r.log10, r.log10)
        (3, True, True)
        >>> Schedule(make_plan(["a", "b", "c"], {"c": ["a"]})).count_result(estimate=False).value
        3
        """

        if not estimate:
            if deadline is None:
                return CountResult(self.engine.count(self.mask, self.consistent))
            with self.engine.deadline(as_deadline(deadline).at):
                return CountResult(self.engine.count(self.mask, self.consistent))
        with no_collection():       # a full collection of the caller's heap is no part of this call's time
            return self._count_timed(rel_error, time_limit, seed, exact_share, as_deadline(deadline), threads)

    def _count_timed(self, rel_error: float, time_limit: float, seed: int, exact_share: float, deadline: Deadline,
                     threads: int) -> CountResult:
        """:meth:`count_result` with an estimate (see there)."""
        start = time.perf_counter()
        plain = self.engine.time_limit if self.engine.time_limit is not None else time_limit / 10
        end = deadline.within(plain + time_limit)
        try:
            terms = list(self.engine._terms(self.consistent, end))
        except BudgetExceeded:
            terms = None

        remaining = self.engine.full & ~self.mask
        n = remaining.bit_count()
        early = None
        if terms is not None:
            # the phases share what is left of the time (a caller's deadline may have taken some),
            # and the exact ones leave the estimate at least its one pass over each order
            # (ESTIMATE_RESERVE seconds per element: its bounds and first path)
            avail = max(0.0, end.remaining())
            scale = min(1.0, avail / (plain + time_limit)) if plain + time_limit > 0 else 0.0
            last = end.at - min(avail / 2, ESTIMATE_RESERVE * n * len(terms))
            exact_end = min(start + (plain + exact_share * time_limit) * scale, last)
            found, early = self._exact_turns(terms, start, exact_end, rel_error, seed, threads)
            if found is not None:
                return found
        from opportune.engine.estimate import estimate_count

        if end.remaining() < GRACE:         # and the estimate its pass over the orders, if they are small
            end = Deadline.after(GRACE)

        if terms is None:
            # too many strategies for inclusion–exclusion, or no time to build its terms: the union
            # lies between its largest strategy and the sum of them
            terms = [(1, self.engine.counter(1 << s)) for s in range(self.engine.k) if self.consistent >> s & 1]
            union_only = True
        else:
            union_only = False
        if early is not None and early.resume is not None and early.rel_error > rel_error and len(terms) == 1:
            from opportune.engine.estimate import relaxation_estimate

            early = relaxation_estimate(terms[0][1].poset, remaining, rel_error=rel_error, seed=seed, resume=early,
                                        threads=threads,
                                        deadline=Deadline.after(EARLY_RESUME * max(0.0, end.remaining()))) or early
        singles = self.consistent.bit_count()
        missed, methods, parts, ests = 0.0, set(), [], []
        exact: int | None = 0
        for i, (sign, counter) in enumerate(terms):
            share = end.share(1 / (len(terms) - i))
            seconds = max(0.0, share.remaining())
            # the hub split again only if the exact phases did not already look for a hub (found one,
            # found none, or were cut short in the search: a new split would start over with less time)
            hub = {"hub": 0.0} if counter in self.engine._hubs or counter in self.engine._hub_search else {}
            # fewer particles when time is short, so that two runs fit (a run of p particles on n
            # elements took about 2e-7 p n^2 seconds here: ARC111 with 1,024 particles ~3 s)
            particles = 1024
            while particles > 64 and 2e-7 * particles * n * n > seconds / 4:
                particles //= 2
            # each of k terms at confidence 1 - 0.05/k, so that all k intervals hold together with
            # probability at least 95% (a union bound); one term keeps the plain 95%
            est = estimate_count(counter.poset, remaining, rel_error=rel_error / max(1, len(terms)),
                                 time_limit=seconds / 2, overrun=math.inf, deadline=share, seed=seed,
                                 counter=counter, exact_memo=0, particles=particles,
                                 confidence=1 - 0.05 / len(terms), relaxation=early is not None
                                 and early.rel_error > rel_error, resume=early, threads=threads, **hub)
            if early is not None and est.exact is None and early.rel_error < est.rel_error:
                # the narrower stated interval, within the order's certain bounds
                est = replace(early, log10_low=max(early.log10_low, est.log10_low),
                              log10_high=min(early.log10_high, est.log10_high))
            ests.append(est)
            exact = None if exact is None or est.exact is None else exact + sign * est.exact
            parts.append((sign, est.log10_value, est.rel_error))
            if est.rel_error > 0 and est.exact is None:
                missed += 1 - est.confidence
            methods.add(est.method)
        if exact is not None and not union_only:    # every term was counted exactly after all (through a hub)
            return CountResult(exact)
        # certain bounds on the union: at least its largest strategy's count, at most the sum of them
        # (and, with every term, the inclusion–exclusion sum of the terms' bounds)
        low = max(e.log10_low for e in ests[:singles])
        high = _signed_sum_log10([(1, e.log10_high, 0.0) for e in ests[:singles]])[0]
        if union_only:
            log10, rel = max(e.log10_value for e in ests[:singles]), math.inf
        else:
            both = _signed_sum_log10([(sign, e.log10_high if sign > 0 else e.log10_low, 0.0)
                                      for (sign, _), e in zip(terms, ests)])[0]
            if not math.isnan(both):
                high = min(high, both)
            # the intervals of the terms add up; they all hold at once with probability >= 1 - sum(misses)
            log10, rel = _signed_sum_log10(parts)
        high = max(low, min(high, math.lgamma(n + 1) / math.log(10)))     # and at most n! whatever the orders
        if math.isnan(log10):
            log10, rel = (low + high) / 2, math.inf
        log10 = min(max(log10, low), high)
        lo, hi = low, high
        if rel < 1:
            lo = max(low, min(high, log10 + math.log10(1 - rel)))
        if math.isfinite(rel):
            hi = min(high, max(low, log10 + math.log10(1 + rel)))
        return CountResult(10.0 ** log10 if log10 < 308 else math.inf, exact=False, rel_error=rel,
                           confidence=max(0.0, 1 - missed),
                           method=("union:" if union_only else "") + "+".join(sorted(methods)), log10_value=log10,
                           log10_low=lo, log10_high=hi)

    def _exact_turns(self, terms: list, start: float, exact_end: float, rel_error: float, seed: int,
                     threads: int) -> tuple[CountResult | None, object]:
        """The exact phases of :meth:`count_result`, until ``exact_end`` (a ``time.perf_counter()`` moment):
        ``(the exact count or None, the first relaxation estimate or None)``.

        The plain count (each term's counter by itself, its own method per hard piece) and the engine's
        count (which looks for a hub and counts through it: :meth:`OrderEngine.count`) take turns, each
        resuming from its memos: ``FIRST_TURN`` seconds each, then twice as long at every round, the
        plain count a ``PLAIN_SHARE`` of the engine's turn once a hub is found.  After the second round
        (or when the memo budget ends the exact count), relaxation Monte Carlo (one strategy) takes up to
        ``EARLY_SECONDS``.  The turns end on the clock: an exact count that needs about as long as a
        round may come in that round or the next, whatever the limit.  No turn's length depends
        on the time limit, which only cuts the sequence short: a count that finishes within a limit
        finishes at the same moment within any longer one (a plain phase of a tenth of the limit made
        an order that its hub counts in 0.05 s exact in 1.4 s with 3 s and in 3.2 s with 20 s).
        """
        remaining = self.engine.full & ~self.mask
        early = None
        tried = over_memo = False
        turn = FIRST_TURN
        plain_only = True
        while True:
            now = time.perf_counter()
            hub = any(self.engine._hubs.get(c) is not None for _, c in terms)
            seconds = turn * (PLAIN_SHARE if plain_only and hub else 1.0)
            # a deadline spent before the call (reading the plan) still leaves a small plan its exact
            # count: GRACE seconds, within COUNT_MARGIN
            until = min(now + seconds, exact_end)
            if turn == FIRST_TURN and plain_only:
                until = max(until, start + GRACE)
            stop = False
            if not (plain_only and over_memo):
                try:
                    return self._exact_by(terms, remaining, until, plain_only), early
                except BudgetExceeded as exc:
                    if exc.reason != "time":        # each call may add max_memo entries: not one turn after another
                        stop, over_memo = not plain_only, True
                if plain_only:
                    # the plain turn was the engine's probe of the plain count: its turn looks for a hub at once
                    for _, c in terms:
                        self.engine._probe_left[c] = 0
            if time.perf_counter() >= exact_end:
                return None, early
            if not plain_only and (turn > FIRST_TURN or stop) and not tried and len(terms) == 1:
                # relaxation Monte Carlo gets its go now, while a narrow interval is still possible, to a
                # looser error than asked (the estimate phase may narrow it, going on with its draws: its
                # memos, at most relaxmc.MAX_BYTES, stay until count_result returns), for a fixed time
                from opportune.engine.estimate import relaxation_estimate

                tried = True
                early = relaxation_estimate(terms[0][1].poset, remaining, rel_error=max(rel_error, EARLY_ERROR),
                                            seed=seed, whole=False, count_share=EARLY_COUNT_SHARE,
                                            threads=threads, deadline=Deadline(min(exact_end, time.perf_counter()
                                                                                   + EARLY_SECONDS)))
            if stop:
                return None, early
            if not plain_only:
                turn *= 2
            plain_only = not plain_only

    def _exact_by(self, terms: list, remaining: int, until: float, plain_only: bool) -> CountResult:
        """One turn of :meth:`_exact_turns`: every count of the engine stops at ``until``."""
        # the engine's deadline sets each count's time limit when it starts, and the counters' own
        # deadline holds whatever runs after that
        saved = [(c, c.deadline) for _, c in terms]
        for c, _ in saved:
            c.deadline = until
        try:
            with self.engine.time_limited(None), self.engine.deadline(until):
                if plain_only:      # each term's counter by itself (its own choice of method per piece)
                    for _, c in terms:
                        c.count(remaining)
                return CountResult(self.count())
        finally:
            for c, d in saved:
                c.deadline = d

    def options(self) -> dict[str, int]:
        """For each installable part, how many admissible completions remain after installing it.

        These are the paper's "future sequencing options" that the opportunistic
        policy maximises.  Cached per state, so repeated questions are dict look-ups.
        """
        return self.engine.options(self.mask, self.consistent)

    def options_for(self, parts: Collection[str]) -> dict[str, int]:
        """:meth:`options` for just these parts (those of them installable now; declaration order)."""
        return self.engine.options_for(self.mask, self.consistent, parts)

    def next_probabilities(self) -> dict[str, Fraction]:
        """Probability that each installable part comes next in a uniformly random admissible completion."""
        total = self.count()
        from fractions import Fraction

        return {p: Fraction(c, total) for p, c in self.options().items()}

    def expected_positions(self) -> dict[str, Fraction]:
        """Expected position (1 = next) of each remaining part in a uniformly random admissible completion.

        For a part with several units left, the position of its next unit: when it is first needed.
        """
        return self.engine.expected_positions(self.mask, self.consistent)

    def position_sums_for(self, parts: Iterable[str]) -> tuple[int, dict[str, int]]:
        """``(completions, position sums)`` of these parts (those remaining): each sum divided by
        the completions is the part's expected position (see :meth:`expected_positions`)."""
        return self.engine.position_sums_for(self.mask, self.consistent, parts)

    def sample(self, seed: int | random.Random | None = 0) -> list[str]:
        """One admissible completion drawn uniformly at random (exactly, from the counts)."""
        import random     # here: a count never draws

        rng = seed if isinstance(seed, random.Random) else random.Random(seed)
        s, out = self, []
        while not s.is_complete:
            opts = s.options()
            r = rng.randrange(sum(opts.values()))
            for part, c in opts.items():
                if r < c:
                    break
                r -= c
            out.append(part)
            s = s.install(part)
        return out

    def completions(self, limit: int = 100_000) -> list[tuple[str, ...]]:
        """Every admissible completion, in lexicographic order of declaration; refuses above ``limit``."""
        total = self.count()
        if total > limit:
            raise ValueError(f"{total} completions is more than the limit of {limit}: count or sample them instead")
        out: list[tuple[str, ...]] = []

        def walk(s: Schedule, prefix: tuple[str, ...]):
            if s.is_complete:
                out.append(prefix)
                return
            for part in s.options():
                walk(s.install(part), prefix + (part,))

        walk(self, ())
        return out

    def __repr__(self) -> str:
        return f"Schedule({self.plan.name!r}, installed={list(self.installed)!r})"

    def __eq__(self, other) -> bool:
        return isinstance(other, Schedule) and other.engine is self.engine and other.installed == self.installed

    def __hash__(self) -> int:
        return hash((id(self.engine), self.installed))


_bits = bits   # (the name this module's callers and tests use)


def schedule(plan: Plan, installed: Sequence[str] = ()) -> Schedule:
    """Shorthand for ``Schedule(plan, installed)``."""
    return Schedule(plan, installed)
