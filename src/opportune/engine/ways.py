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

Where the exact count does not fit, :func:`estimate_completions` estimates it by sequential importance
sampling (Knuth's estimator): independent random walks from ``S``, each step choosing uniformly among
the parts that can go in without shutting a part out, a walk's weight the product of its numbers of
choices (0 if it ends dead; a set whose count the memo holds ends the walk with that count).  The mean
weight is an unbiased estimate of ``f(S)``; the stated error is the 95% Student-t interval of the mean
over the walks (in logarithms, the weights of a 300-part plan being far past a float), which like any
interval from a sample holds only approximately when the weights are heavy-tailed.  Every walk is drawn
from one seeded generator: the same seed, the same estimate.

Complexity: an exact count is O(reachable live sets × ways) mask operations; a walk O(parts × the ways
naming each part), kept incremental by :class:`_Walk`.
"""

from __future__ import annotations

import math
import random
import time
from contextlib import contextmanager

from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline
from opportune.engine.memory import nbytes
from opportune.engine.result import CountResult
from opportune.engine.stats import t_quantile
from opportune.planning.ways import WaysTable

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.planning.plan import Plan

__all__ = ["WaysCounter", "WaysEngine", "estimate_completions"]

#: New memo entries between two readings of the clock (each entry is O(parts × ways) mask work).
CHECK_EVERY = 64
#: Entries the memo of a :class:`WaysCounter` holds at most before its oldest half is dropped (about
#: 150 bytes an entry on 300 parts: 300 MB).
MAX_TOTAL = 2_000_000
#: Walks an estimate draws at least before it may stop on its stated error (fewer say nothing of the spread).
MIN_WALKS = 32


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
        table, memo, full = self.table, self.memo, self.table.full
        get, goes, shut_out = memo.get, table.goes, table.shut_out
        limit = self.max_memo if self.max_memo is not None else math.inf
        new = 0
        frames = [[mask, goes(mask), 0]]
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
                    if shut_out(t):
                        v = 0
                    else:
                        frame[1] = todo
                        frames.append([t, goes(t), 0])
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
            if not new % CHECK_EVERY:
                dl.check("counting the completions of a plan of ways")
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


class _Walk:
    """One random walk's state, updated as parts go in: which ways are still open (no blocker in),
    how many needs each way still misses, and so which parts can go in now, in O(ways naming a part)
    per part installed."""

    def __init__(self, table: WaysTable, blocked_by: list, needed_by: list, mask: int):
        self.table = table
        self.blocked_by, self.needed_by = blocked_by, needed_by
        self.mask = 0
        self.open = [[True] * len(w) for w in table.ways]
        self.open_count = [len(w) for w in table.ways]
        self.missing = [[len(needs) for _, needs in w] for w in table.ways]
        self.met = [[0] * len(w) for w in table.ways]      # per way: its needs met, as bits
        self.usable = [len(w) - sum(1 for _, needs in w if needs) for w in table.ways]
        for i in _bits(mask):
            self.add(i)

    def add(self, i: int) -> None:
        """Part ``i`` goes in."""
        self.mask |= 1 << i
        for q, w in self.blocked_by[i]:
            if self.open[q][w]:
                self.open[q][w] = False
                self.open_count[q] -= 1
                if not self.missing[q][w]:
                    self.usable[q] -= 1
        for q, w, k in self.needed_by[i]:
            if not self.met[q][w] >> k & 1:
                self.met[q][w] |= 1 << k
                self.missing[q][w] -= 1
                if not self.missing[q][w] and self.open[q][w]:
                    self.usable[q] += 1

    def shuts_out(self, i: int) -> bool:
        """Whether installing ``i`` would leave some other remaining part with every way blocked."""
        closing: dict[int, int] = {}
        mask, is_open, left = self.mask, self.open, self.open_count
        for q, w in self.blocked_by[i]:
            if is_open[q][w] and q != i and not mask >> q & 1:
                n = closing[q] = closing.get(q, 0) + 1
                if n == left[q]:
                    return True
        return False

    def choices(self) -> list[int]:
        """The parts that can go in now without shutting another out."""
        mask = self.mask
        return [i for i, u in enumerate(self.usable) if u > 0 and not mask >> i & 1 and not self.shuts_out(i)]


def _bits(mask: int):
    while mask:
        b = mask & -mask
        yield b.bit_length() - 1
        mask ^= b


def _indexes(table: WaysTable) -> tuple[list, list]:
    """Per part ``b``: the ways ``(q, w)`` that ``b`` blocks, and the needs ``(q, w, k)`` it meets."""
    blocked_by: list = [[] for _ in range(table.n)]
    needed_by: list = [[] for _ in range(table.n)]
    for q, ways in enumerate(table.ways):
        for w, (blockers, needs) in enumerate(ways):
            for b in _bits(blockers):
                blocked_by[b].append((q, w))
            for k, need in enumerate(needs):
                for b in _bits(need):
                    needed_by[b].append((q, w, k))
    return blocked_by, needed_by


def _log_walk(table: WaysTable, memo: dict, start: int, rng: random.Random, indexes: tuple,
              dl: Deadline) -> float:
    """``log`` of one walk's weight from ``start`` (``-inf`` if it ends dead)."""
    walk = _Walk(table, *indexes, start)
    log_w = 0.0
    while walk.mask != table.full:
        known = memo.get(walk.mask)
        if known is not None:
            return log_w + math.log(known) if known else -math.inf
        options = walk.choices()
        if not options:
            return -math.inf
        log_w += math.log(len(options))
        walk.add(options[rng.randrange(len(options))])
        dl.check("estimating the completions of a plan of ways")
    return log_w


def estimate_completions(table: WaysTable, mask: int = 0, *, seed: int = 0, rel_error: float = 0.01,
                         deadline: Deadline | float | None = None, max_walks: int = 1_000_000,
                         memo: dict | None = None) -> CountResult:
    """An estimate of the completions of ``mask`` by sequential importance sampling (see the module).

    Parameters
    ----------
    table : WaysTable
        The plan's ways.
    mask : int
        The installed parts.
    seed : int
        The walks' generator's seed.
    rel_error : float
        Stop once the 95% interval's half-width is within this share of the estimate (after
        :data:`MIN_WALKS` walks).
    deadline : Deadline or float, optional
        Stop drawing past it (at least two walks are drawn).
    max_walks : int
        Most walks drawn.
    memo : dict, optional
        Exact counts of sets known already (a :class:`WaysCounter`'s): a walk reaching one ends with it.

    Returns
    -------
    CountResult
        ``exact=False``, ``method="ways-sis"``, the estimate (``log10_value`` beside it), its relative
        error at ``confidence`` 0.95 and the interval's ends in ``log10``.

    Examples
    --------
    >>> t = WaysTable(4, [[(0, ())]] * 4)          # 4 free parts: 24 sequences, every walk weighs 24
    >>> r = estimate_completions(t, seed=1)
    >>> round(r.value), r.rel_error, r.exact
    (24, 0.0, False)
    """
    dl = as_deadline(deadline)
    rng = random.Random(seed)
    memo = memo if memo is not None else {table.full: 1}
    indexes = _indexes(table)
    logs: list[float] = []
    grace = Deadline.NEVER
    while len(logs) < max_walks:
        try:
            logs.append(_log_walk(table, memo, mask, rng, indexes, grace if len(logs) < 2 else dl))
        except BudgetExceeded:
            break
        # the interval is O(walks) to find: looked at every MIN_WALKS walks
        if not len(logs) % MIN_WALKS and _interval(logs)[1] <= rel_error or (len(logs) >= 2 and dl.expired()):
            break
    return _result(logs)


def _interval(logs: list[float]) -> tuple[float, float]:
    """``(log of the mean weight, relative half-width of its 95% interval)``."""
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
    log_mean, rel = _interval(logs)
    if log_mean == -math.inf:
        return CountResult(0.0, exact=False, rel_error=math.inf, confidence=0.95, method="ways-sis",
                           log10_value=-math.inf)
    l10 = log_mean / math.log(10)
    low = l10 + math.log10(max(1e-300, 1 - rel)) if rel < 1 else 0.0
    high = l10 + math.log10(1 + rel) if math.isfinite(rel) else math.inf
    return CountResult(10.0 ** l10 if l10 < 308 else math.inf, exact=False, rel_error=rel, confidence=0.95,
                       method="ways-sis", log10_value=l10, log10_low=max(0.0, low), log10_high=high)
