"""Counting the admissible sequences of a plan written as ways: exactly, or estimated with a stated error.

A plan written as ways (:attr:`opportune.planning.plan.Plan.ways`) admits a sequence iff each part, when
it goes in, has a way that admits what is in (:class:`~opportune.planning.ways.WaysTable`).  The number
of completions of an installed set ``S`` obeys

    ``f(full) = 1``,   ``f(S) = sum over the parts p that can go in on S of f(S ∪ {p})``,

a dynamic programme over the installed sets reachable from ``S``; a set from which no completion exists
has ``f = 0`` (it is *dead*: the sequencer never goes there).  :class:`WaysCounter` keeps ``f`` of every
set it met for its whole life, as the order engine's counter does (the next questions of a run are
mostly look-ups), under the engine's conventions: a cap on the new entries of one call and on the memo
as a whole, one :class:`~opportune.engine.deadline.Deadline`, :class:`BudgetExceeded` when a count does
not fit (what was counted stays).  A set some remaining part of which has every way blocked is dead at
once (:meth:`~opportune.planning.ways.WaysTable.shut_out`), without a search.

Where the exact count does not fit, :func:`estimate_completions` estimates it by sequential Monte Carlo:
runs of walks from ``S`` that go forward together a part at a time, each step choosing uniformly among
the parts that can go in without shutting a part out, the walks drawn again in proportion to their
numbers of choices (so a walk at a dead end is replaced by a live one).  Each run's product of the mean
numbers of choices is an unbiased estimate of ``f(S)``; the stated error is the 95% Student-t interval of
the mean over independent runs (in logarithms, the counts of a 300-part plan being far past a float),
which like any interval from a sample holds only approximately when the runs' estimates are
heavy-tailed.  Every draw comes from one seeded generator: the same seed, the same estimate.

Complexity: an exact count is O(reachable live sets × ways) mask operations; a run O(parts × walks ×
the ways naming a part), kept incremental by :class:`_Walk`.
"""

from __future__ import annotations

import math
import time

from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline
from opportune.engine.memory import nbytes
from opportune.engine.poset import bits as _bits
from opportune.engine.result import CountResult
# this module's names for its tuning constants
from opportune.engine.tuning import (
    WAYS_CHECK_EVERY as CHECK_EVERY,
    WAYS_LOCK_EVERY as LOCK_EVERY,
    WAYS_MAX_PARTICLES as MAX_PARTICLES,
    WAYS_MAX_TOTAL as MAX_TOTAL,
    WAYS_MIN_RUNS as MIN_RUNS,
    WAYS_MIXED as MIXED,
    WAYS_PARTICLES as PARTICLES,
    WAYS_RUNS_IN_TIME as RUNS_IN_TIME,
)
from opportune.planning.ways import WaysTable

__all__ = ["WaysChains", "WaysCounter", "estimate_completions", "sample_completions"]


class WaysCounter:
    """Exact numbers of completions of installed sets of a plan written as ways, memoised for life.

    Parameters
    ----------
    table : WaysTable
        The plan's ways as masks.
    max_memo : int or None
        Most new memo entries one :meth:`count` may add (None: unlimited); past it
        :class:`BudgetExceeded` (reason ``"memo"``), the entries made so far kept.
    max_total : int or None
        Entries the memo holds at most: a call that starts with more drops the oldest half first.

    Examples
    --------
    >>> c = WaysCounter(WaysTable(3, [[(0b010, ())], [(0, ())], [(0, ())]]))    # a before b
    >>> c.count(0), c.count(0b010)
    (3, 0)
    """

    def __init__(self, table: WaysTable, *, max_memo: int | None = 2_000_000, max_total: int | None = MAX_TOTAL):
        self.table = table
        self.max_memo = max_memo
        self.max_total = max_total
        self.memo: dict[int, int] = {table.full: 1}
        # what the order engine's upkeep reads and sets on each of its counters
        self.deadline: float | None = None
        self.time_limit: float | None = None
        self.hold_upkeep = False

    def count(self, mask: int, deadline: Deadline | float | None = None) -> int:
        """The number of admissible completions of the installed set ``mask`` (0: dead).

        Parameters
        ----------
        mask : int
            The installed parts (bit ``i``: the ``i``-th declared part).
        deadline : Deadline or float, optional
            Past it, :class:`BudgetExceeded` (reason ``"time"``).

        Returns
        -------
        int
            The exact count.

        Raises
        ------
        BudgetExceeded
            Over ``max_memo`` new entries or past ``deadline``; what was counted stays in the memo.

        Examples
        --------
        >>> WaysCounter(WaysTable(2, [[(0, ())], [(0, ())]])).count(0)
        2
        """
        r = self.memo.get(mask)
        if r is not None:
            return r
        if not self.hold_upkeep and self.max_total is not None and len(self.memo) > self.max_total:
            self.shrink(0.5)
        dl = as_deadline(deadline).sooner(self.deadline)
        if self.time_limit is not None:
            dl = dl.within(self.time_limit)
        return self._count(mask, dl)

    def _count(self, mask: int, dl: Deadline) -> int:
        """The memoised recursion, with an explicit stack (a 10,000-part plan is as deep)."""
        table, memo = self.table, self.memo
        get, goes, shutting = memo.get, table.goes, table.shutting
        limit = self.max_memo if self.max_memo is not None else math.inf
        new = pushed = 0
        # a frame: the set, the parts still to try on it, the sum so far, and the parts that would shut
        # another out (WaysTable.shutting: one pass a set instead of one a part tried)
        frames = [[mask, goes(mask), 0, shutting(mask)]]
        while frames:
            frame = frames[-1]
            s, todo = frame[0], frame[1]
            down = False
            while todo:
                b = todo & -todo
                todo ^= b
                t = s | b
                v = get(t)
                if v is None:
                    if frame[3] & b:
                        v = 0
                    else:
                        # the clock at each step down too: on hundreds of parts the first entry is made only at
                        # the full set, hundreds of steps (each O(parts × ways)) down (a reading costs far less)
                        dl.check("counting the completions of a plan of ways")
                        frame[1] = todo
                        pushed += 1     # the clock read by sets entered (a first descent is as deep as the plan)
                        if not pushed % CHECK_EVERY:
                            dl.check("counting the completions of a plan of ways")
                        frames.append([t, goes(t), 0, shutting(t)])
                        down = True
                        break
                frame[2] += v
            if down:
                continue
            memo[s] = frame[2]
            new += 1
            if new > limit:
                raise BudgetExceeded(f"exact count needs more than max_memo={self.max_memo} new memo entries",
                                     reason="memo", memo_size=len(memo))
            frames.pop()
            if frames:
                frames[-1][2] += frame[2]
        return memo[mask]

    def shrink(self, keep: float, deadline: Deadline | float | None = None) -> None:
        """Keep the newest ``keep`` share of the memo (dictionaries keep insertion order); stops past
        ``deadline`` with :class:`BudgetExceeded` (what is left is valid).  O(entries dropped)."""
        dl = as_deadline(deadline)
        drop = len(self.memo) - int(keep * len(self.memo))
        for k, key in enumerate(list(self.memo)[:drop]):
            if key != self.table.full:
                del self.memo[key]
            if not k & 4095:
                dl.check("shrinking a memo")

    def entries(self) -> int:
        """Entries in the memo."""
        return len(self.memo)

    def nbytes(self) -> int:
        """Estimated bytes of the memo (:func:`~opportune.engine.memory.nbytes`)."""
        return nbytes(self.memo)

    def maintain(self) -> bool:
        """Between decisions: drop the oldest half of the memo if it is over ``max_total``; True if so."""
        if self.hold_upkeep or self.max_total is None or len(self.memo) <= self.max_total:
            return False
        self.shrink(0.5)
        return True


class _Ways:
    """A plan's ways numbered flat (way ``k`` of part ``owner[k]``), with per part ``b`` the ways ``b``
    blocks and the needs ``(way, bit)`` it meets: what a :class:`_Walk` updates when ``b`` goes in."""

    def __init__(self, table: WaysTable):
        self.table = table
        self.owner: list[int] = []
        self.needs: list[int] = []          # per way: how many needs it has
        self.blockers: list[int] = []       # per way: its blockers' mask
        self.of_part: list[list[int]] = [[] for _ in range(table.n)]
        self.blocks: list[list[int]] = [[] for _ in range(table.n)]
        self.meets: list[list[tuple[int, int]]] = [[] for _ in range(table.n)]
        for q, ways in enumerate(table.ways):
            for blockers, needs in ways:
                k = len(self.owner)
                self.owner.append(q)
                self.needs.append(len(needs))
                self.blockers.append(blockers)
                self.of_part[q].append(k)
                for b in _bits(blockers):
                    self.blocks[b].append(k)
                for bit, need in enumerate(needs):
                    for b in _bits(need):
                        self.meets[b].append((k, 1 << bit))


class _Walk:
    """One walk's state, updated as parts go in, in O(ways naming the part) a part: which ways are still
    open (no blocker in), which needs each way has met, how many usable ways (open, every need met) and
    open ways each part has, and the parts ready to go in.  Flat arrays, so a copy (a resampled walk) is
    a few C-level copies."""

    __slots__ = ("ways", "mask", "open", "met", "usable", "left", "ready", "order", "common")

    def __init__(self, ways: _Ways, mask: int):
        self.ways = ways
        self.mask = 0
        self.open = bytearray(b"\x01" * len(ways.owner))
        self.met = [0] * len(ways.owner)
        self.left = [len(k) for k in ways.of_part]          # open ways per part
        self.usable = [sum(1 for k in ks if not ways.needs[k]) for ks in ways.of_part]
        self.ready = {i for i, u in enumerate(self.usable) if u}
        # per part, the blockers its open ways share (-1: none open): a part among them shuts it out
        self.common = [self._common(q) for q in range(len(ways.of_part))]
        for i in _bits(mask):
            self.add(i)
        self.order: list[int] = []          # the parts this walk added, in order

    def copy(self) -> "_Walk":
        w = object.__new__(_Walk)
        w.ways, w.mask, w.open, w.met = self.ways, self.mask, bytearray(self.open), self.met[:]
        w.usable, w.left, w.ready, w.order = self.usable[:], self.left[:], set(self.ready), self.order[:]
        w.common = self.common[:]
        return w

    def _common(self, q: int) -> int:
        """The blockers every open way of part ``q`` shares (-1 if none is open)."""
        out = -1
        for k in self.ways.of_part[q]:
            if self.open[k]:
                out &= self.ways.blockers[k]
        return out

    def add(self, i: int) -> None:
        """Part ``i`` goes in."""
        ways, is_open, usable, met, ready = self.ways, self.open, self.usable, self.met, self.ready
        self.mask |= 1 << i
        ready.discard(i)
        full_needs = ways.needs
        closed = set()
        for k in ways.blocks[i]:
            if is_open[k]:
                is_open[k] = 0
                q = ways.owner[k]
                closed.add(q)
                self.left[q] -= 1
                if met[k].bit_count() == full_needs[k]:
                    usable[q] -= 1
                    if not usable[q]:
                        ready.discard(q)
        for k, bit in ways.meets[i]:
            if not met[k] & bit:
                met[k] |= bit
                if is_open[k] and met[k].bit_count() == full_needs[k]:
                    q = ways.owner[k]
                    usable[q] += 1
                    if usable[q] == 1 and not self.mask >> q & 1:
                        ready.add(q)
        for q in closed:
            self.common[q] = self._common(q)

    def shuts_out(self, i: int) -> bool:
        """Whether installing ``i`` would leave another remaining part with every way blocked."""
        ways, is_open, mask, left = self.ways, self.open, self.mask, self.left
        closing: dict[int, int] = {}
        for k in ways.blocks[i]:
            if is_open[k]:
                q = ways.owner[k]
                if q != i and not mask >> q & 1:
                    n = closing[q] = closing.get(q, 0) + 1
                    if n == left[q]:
                        return True
        return False

    def locked(self) -> bool:
        """Whether the parts left lock each other: taken out last first while one can be (a part can be
        last if some way of it is open and none of its blockers is among the others left), some remain.
        Needs left aside, so a locked set is surely dead (and, in a plan without needs, only a dead set
        is locked).  O(passes × open ways) mask operations."""
        ways, is_open, mask = self.ways, self.open, self.mask
        rest = ways.table.full & ~mask
        left = [(ways.owner[k], ways.blockers[k]) for k in range(len(ways.owner))
                if is_open[k] and not mask >> ways.owner[k] & 1]
        while rest:
            out = 0
            for q, blockers in left:
                if not blockers & rest & ~(1 << q):
                    out |= 1 << q
            if not out:
                return True
            rest &= ~out
            left = [(q, b) for q, b in left if rest >> q & 1]
        return False

    def choices(self) -> list[int]:
        """The parts that can go in now without shutting another out (in increasing order: seeded draws
        do not depend on a set's order): those among no remaining part's shared blockers
        (:meth:`shuts_out`'s answer for all at once, O(parts))."""
        mask, shutting = self.mask, 0
        for q, c in enumerate(self.common):
            if c > 0 and not mask >> q & 1:
                shutting |= c
        return [i for i in sorted(self.ready) if not shutting >> i & 1]


def _smc_run(ways: _Ways, start: int, particles: int, rng, dl: Deadline,
             finished: list | None = None) -> float:
    """``log`` of one sequential Monte Carlo estimate of the completions of ``start`` (``-inf``: all dead).

    ``particles`` walks go forward together a part at a time; at each step the estimate is multiplied by
    the walks' mean number of choices, and the walks are drawn again in proportion to their numbers of
    choices, each then taking one of its choices at random (a walk with none, or found locked every
    :data:`LOCK_EVERY` steps, weighs 0 and is replaced).  The product
    is an unbiased estimate of the number of completions (the normalising constant of sequential
    importance sampling with multinomial resampling).  The walks at the end (appended to ``finished``, if
    given, as their orders) are completions drawn about uniformly.  O(parts × particles × ways naming a
    part)."""
    walks = [_Walk(ways, start)]
    walks += [walks[0].copy() for _ in range(particles - 1)]
    log_z = 0.0
    for step in range(ways.table.n - start.bit_count()):
        options = []
        for w in walks:         # the clock read a walk at a time: a step of 8 walks on 300 parts is milliseconds
            o = w.choices()
            if o and not step % LOCK_EVERY and w.locked():   # parts left that lock each other: no completion
                o = []
            options.append(o)
            dl.check("estimating the completions of a plan of ways")
        weights = [len(o) for o in options]
        total = sum(weights)
        if not total:
            return -math.inf
        log_z += math.log(total / particles)
        picks = rng.choices(range(particles), weights=weights, k=particles)
        nxt = []
        for j in picks:
            w = walks[j].copy()
            part = options[j][rng.randrange(weights[j])]
            w.add(part)
            w.order.append(part)
            nxt.append(w)
        walks = nxt
        dl.check("estimating the completions of a plan of ways")
    if finished is not None:
        finished.extend(w.order for w in walks)
    return log_z


def estimate_completions(table: WaysTable, mask: int = 0, *, seed: int = 0, rel_error: float = 0.01,
                         deadline: Deadline | float | None = None, max_runs: int = 10_000,
                         particles: int = PARTICLES) -> CountResult:
    """An estimate of the completions of ``mask`` by sequential Monte Carlo (see :func:`_smc_run`).

    Independent runs of ``particles`` walks each, until the 95% interval of their mean is within
    ``rel_error`` (after :data:`MIN_RUNS` runs), ``max_runs`` runs or ``deadline``: a run cut by the
    deadline is dropped.  With a deadline, the first run's time sets the later runs' size: as many walks
    (doubling, up to :data:`MAX_PARTICLES`) as let :data:`RUNS_IN_TIME` runs fit in the time left.  Each run is unbiased, so their mean is; the interval is Student's t over the
    runs (approximate where the runs' estimates are heavy-tailed).

    Parameters
    ----------
    table : WaysTable
        The plan's ways.
    mask : int
        The installed parts.
    seed : int
        The generator's seed: the same seed, the same estimate (but for a stop on the clock).
    rel_error : float
        The interval's half-width, as a share of the estimate, at which to stop.
    deadline : Deadline or float, optional
        Stop past it.
    max_runs : int
        Most runs.
    particles : int
        Walks in a run.

    Returns
    -------
    CountResult
        ``exact=False``, ``method="ways-smc"``, the estimate (``log10_value`` beside it), its relative
        error at ``confidence`` 0.95 (infinite with fewer than two runs) and the interval's ends in
        ``log10``; ``nan`` if no run finished.

    Examples
    --------
    >>> t = WaysTable(4, [[(0, ())]] * 4)          # 4 free parts: 24 sequences, every run says 24
    >>> r = estimate_completions(t, seed=1)
    >>> round(r.value), r.rel_error, r.exact
    (24, 0.0, False)
    """
    import random       # here: a count's start-up does not load it (an exact count never draws)

    dl = as_deadline(deadline)
    rng = random.Random(seed)
    ways = _Ways(table)
    logs: list[float] = []
    first: list[float] = []         # the first run, when the later ones are larger
    size = particles
    while len(logs) < max_runs and not dl.expired():
        start = time.perf_counter()
        try:
            logs.append(_smc_run(ways, mask, size, rng, dl))
        except BudgetExceeded:
            break
        if len(logs) == 1 and not first and dl.finite:
            # more walks a run where the time allows RUNS_IN_TIME runs of them: the spread of a run's
            # logarithm falls as its walks grow.  The first run is set aside, and counts only if fewer
            # than two larger runs finish (a choice by the number of runs, not their values: unbiased)
            size = _run_size(particles, time.perf_counter() - start, dl.remaining())
            if size > particles:
                first, logs = logs, []
                continue
        if len(logs) >= MIN_RUNS and _interval(logs)[1] <= rel_error:
            break
    return _result(logs if len(logs) >= 2 else first + logs)


def sample_completions(table: WaysTable, mask: int = 0, *, runs: int = 4, particles: int = PARTICLES,
                       seed: int = 0, deadline: Deadline | float | None = None) -> list[list[int]]:
    """Admissible completions of ``mask`` drawn about uniformly: the walks at the end of ``runs``
    sequential Monte Carlo runs of ``particles`` walks each (:func:`_smc_run`; the walks of one run share
    ancestors, so draw several runs where independence matters).

    Parameters
    ----------
    table : WaysTable
        The plan's ways.
    mask : int
        The installed parts.
    runs, particles : int
        Runs, and walks in a run.
    seed : int
        The generator's seed.
    deadline : Deadline or float, optional
        Stop past it (the runs finished kept).

    Returns
    -------
    list of list of int
        Each completion's parts (positions in the plan), in the order they go in; empty if ``mask`` has
        none or no run finished.

    Examples
    --------
    >>> t = WaysTable(3, [[(0b010, ())], [(0, ())], [(0, ())]])     # a before b
    >>> all(s.index(0) < s.index(1) for s in sample_completions(t, seed=2))
    True
    """
    import random

    dl = as_deadline(deadline)
    rng = random.Random(seed)
    ways = _Ways(table)
    out: list[list[int]] = []
    for _ in range(runs):
        finished: list[list[int]] = []
        try:
            _smc_run(ways, mask, particles, rng, dl, finished)      # a run whose walks all died adds none
        except BudgetExceeded:
            break
        out += finished
    return out


def _run_size(particles: int, seconds: float, left: float) -> int:
    """Walks a run may take so that :data:`RUNS_IN_TIME` runs fit in ``left`` seconds, a first run of
    ``particles`` walks having taken ``seconds`` (at most :data:`MAX_PARTICLES`, a power of two)."""
    size = particles
    while size < MAX_PARTICLES and 2 * size / particles * seconds * RUNS_IN_TIME <= left:
        size *= 2
    return size


def _interval(logs: list[float]) -> tuple[float, float]:
    """``(log of the mean weight, relative half-width of its 95% interval)``."""
    from opportune.engine.stats import t_quantile   # here: it loads statistics and random (a count's start-up)

    top = max(logs)
    if top == -math.inf:
        return -math.inf, math.inf
    w = [math.exp(x - top) for x in logs]
    k = len(w)
    mean = sum(w) / k
    if k < 2:
        return top + math.log(mean), math.inf
    var = sum((x - mean) ** 2 for x in w) / (k - 1)
    return top + math.log(mean), t_quantile(0.975, k - 1) * math.sqrt(var / k) / mean


def _result(logs: list[float]) -> CountResult:
    if not logs:
        return CountResult(math.nan, exact=False, rel_error=math.inf, confidence=0.95, method="ways-smc",
                           log10_value=math.nan)
    log_mean, rel = _interval(logs)
    if log_mean == -math.inf:
        return CountResult(0.0, exact=False, rel_error=math.inf, confidence=0.95, method="ways-smc",
                           log10_value=-math.inf)
    l10 = log_mean / math.log(10)
    low = l10 + math.log10(max(1e-300, 1 - rel)) if rel < 1 else 0.0
    high = l10 + math.log10(1 + rel) if math.isfinite(rel) else math.inf
    return CountResult(10.0 ** l10 if l10 < 308 else math.inf, exact=False, rel_error=rel, confidence=0.95,
                       method="ways-smc", log10_value=l10, log10_low=max(0.0, low), log10_high=high)


class WaysChains:
    """Completions of a state of a plan of ways drawn for the policies' estimates, in the shape of
    :class:`~opportune.engine.sampling.CompletionChains` (what :meth:`Schedule.chains` gives for such
    a plan): ``chains`` groups, each reading one completion a round, the completions the walks of one
    sequential Monte Carlo run of ``chains`` walks end with (about uniform: exactly so as the walks grow;
    the readings of a round are not independent across groups, so the stated errors are too small by the
    walks' shared ancestry).  ``below[u]`` is the other parts left for a part that cannot go in now and
    0 for one that can; ``above[u]`` the part alone: no two parts look interchangeable.

    Examples
    --------
    >>> t = WaysTable(3, [[(0b010, ())], [(0, ())], [(0, ())]])     # a before b
    >>> c = WaysChains(t, 0, chains=4, seed=1)
    >>> e = c.estimate(first=[0, 2], positions=[1], samples=8, steps=8)
    >>> round(e.first[0][0] + e.first[2][0], 6), e.positions[1][0] > 1
    (1.0, True)
    """

    def __init__(self, table: WaysTable, mask: int, *, chains: int = 8, seed: int = 0):
        import random

        self.table = table
        self.ways = _Ways(table)
        self.rng = random.Random(seed)
        self.chains = max(2, chains)
        self.remaining = table.full & ~mask
        self._kept: tuple[dict, dict] = ({}, {})
        self.steps = 0
        self._tables()

    def _tables(self) -> None:
        """``below`` and ``above`` for the state (see the class)."""
        mask = self.table.full & ~self.remaining
        now = _Walk(self.ways, mask)
        can = set(now.choices())
        self.below = [0 if u in can else self.remaining & ~(1 << u) for u in range(self.table.n)]
        self.above = [1 << u for u in range(self.table.n)]

    def advance(self, remaining: int) -> None:
        """The state moved on: ``remaining`` parts are left (readings of the earlier state dropped)."""
        if remaining != self.remaining:
            self.remaining = remaining
            self._kept = ({}, {})
            self._tables()

    def estimate(self, first=(), positions=(), *, steps: int = 0, samples: int = 32, deadline=None, clock=None,
                 settled=None, min_rounds: int = 8, keep: bool = False):
        """As :meth:`CompletionChains.estimate <opportune.engine.sampling.CompletionChains.estimate>`: for each
        unit of ``first`` the share of completions it begins, for each of ``positions`` its mean position
        (1 = next), a round (one run) at a time until ``samples`` rounds (with ``steps``) or ``deadline``, or
        ``settled``.  Every round, the first too, stops at ``deadline`` (of ``time.perf_counter``): a round
        cut is dropped, and with no round, none kept from before (``keep``) and none finished in time,
        the answer is None (a run over a 300-part plan takes longer than a decision's budget)."""
        if isinstance(deadline, Deadline):
            deadline, clock = (deadline.at if deadline.finite else None), time.perf_counter
        k, start = self.chains, self.table.full & ~self.remaining
        kept = self._kept if keep else ({}, {})
        acc_first = {u: kept[0].get(u) or [[0.0] * k, 0] for u in first}
        acc_pos = {u: kept[1].get(u) or [[0.0] * k, 0] for u in positions}
        if keep:
            kept[0].update(acc_first)
            kept[1].update(acc_pos)
        rounds = 0
        summary = None
        stop = Deadline(deadline) if deadline is not None and clock is time.perf_counter else Deadline.NEVER
        while True:
            ends: list = []
            try:            # every round within the deadline: the budget is the caller's promise
                _smc_run(self.ways, start, k, self.rng, stop, ends)
            except BudgetExceeded:
                break
            self.steps += max(1, self.remaining.bit_count()) * MIXED
            for c, order in enumerate(ends):
                where = {u: i + 1 for i, u in enumerate(order)}
                for u, acc in acc_first.items():
                    acc[0][c] += 1.0 if order and order[0] == u else 0.0
                for u, acc in acc_pos.items():
                    acc[0][c] += where.get(u, 0)
            for acc in (*acc_first.values(), *acc_pos.values()):
                acc[1] += 1
            rounds += 1
            summary = self._summary(acc_first, acc_pos)
            if steps and rounds >= samples:
                break
            if rounds >= 2 and deadline is not None and clock is not None and clock() >= deadline:
                break
            if rounds >= 2 and deadline is None and not steps:
                break
            if settled is not None and rounds >= min_rounds and settled(summary):
                break
        if summary is None:
            summary = self._summary(acc_first, acc_pos)     # the readings kept from before, if any
        return summary

    def _summary(self, acc_first: dict, acc_pos: dict):
        """The estimate from the readings so far (``unit → [per-group sums, rounds]``), or None without one."""
        from opportune.engine.sampling import ChainEstimate, _mean_se

        accs = (*acc_first.values(), *acc_pos.values())
        if not accs or not all(n for _, n in accs):
            return None
        return ChainEstimate(
            first={u: _mean_se([x / n for x in xs]) for u, (xs, n) in acc_first.items()},
            positions={u: _mean_se([x / n for x in xs]) for u, (xs, n) in acc_pos.items()},
            per_chain={"first": {u: [x / n for x in xs] for u, (xs, n) in acc_first.items()},
                       "positions": {u: [x / n for x in xs] for u, (xs, n) in acc_pos.items()}},
            samples=max(n for _, n in accs) * self.chains, steps=self.steps)
