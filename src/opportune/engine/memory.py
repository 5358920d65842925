"""Bytes held by the order engine's memos and tables, estimated cheaply enough to ask between requests.

A memo of millions of entries cannot be walked on every request, so a container's bytes are its
own table (``sys.getsizeof``) plus its length times the mean size of a few sampled entries (the
first and the last ones: memos fill from small sets to large, so both ends are seen).  Objects
shared between entries (small ints, interned strings) are counted once per entry: the estimate
errs high, which is the safe side of a memory cap.

Complexity: O(``SAMPLE``) per container, whatever its length.

>>> d = {i: 10 ** 40 + i for i in range(10_000)}
>>> exact = sys.getsizeof(d) + sum(sys.getsizeof(k) + sys.getsizeof(v) for k, v in d.items())
>>> 0.8 < nbytes(d) / exact < 1.25
True
"""

from __future__ import annotations

import os
import sys
import time
from _thread import allocate_lock     # threading.Lock without threading's import (a count's start-up)
from contextlib import contextmanager
from itertools import islice

from opportune.engine import tuning
from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline
from opportune.engine.tuning import MEMORY_SAMPLE as SAMPLE

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.engine.count import Counter

__all__ = ["SAMPLE", "MemoryUpkeep", "memory_total", "nbytes", "poset_nbytes", "resident", "trim"]



def _ends(items, n: int) -> list:
    """Up to ``SAMPLE`` items from each end of a sized, reversible container of length ``n``."""
    if n <= 2 * SAMPLE:
        return list(items)
    head = list(islice(iter(items), SAMPLE))
    try:
        tail = list(islice(reversed(items), SAMPLE))
    except TypeError:                       # not reversible (a set): the head alone
        tail = []
    return head + tail


def nbytes(obj, depth: int = 3) -> int:
    """Estimated bytes of ``obj`` and what it holds (containers sampled, ``depth`` levels down)."""
    size = sys.getsizeof(obj)
    if depth <= 0 or isinstance(obj, (int, float, str, bytes, bool)) or obj is None:
        return size
    if isinstance(obj, dict):
        n = len(obj)
        if not n:
            return size
        keys = _ends(obj, n)
        per = sum(nbytes(k, depth - 1) + nbytes(obj[k], depth - 1) for k in keys) / len(keys)
        return size + int(per * n)
    if isinstance(obj, (list, tuple, set, frozenset)):
        n = len(obj)
        if not n:
            return size
        sample = _ends(obj, n)
        return size + int(sum(nbytes(x, depth - 1) for x in sample) / len(sample) * n)
    below = getattr(obj, "below", None)
    if isinstance(below, list):             # a Poset
        return poset_nbytes(obj)
    return size


def poset_nbytes(poset) -> int:
    """Bytes of a :class:`~opportune.engine.poset.Poset`: its ``below`` and ``above`` bitsets."""
    return 2 * (sys.getsizeof([]) + 8 * poset.n + poset.n * (28 + 4 * (-(-poset.n // 30))))


def memory_total() -> int:
    """Bytes of memory of this machine (``MemTotal``; 4 GiB where it cannot be read)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 4 << 30


def resident() -> int | None:
    """Resident bytes of this process now (``/proc/self/statm``; None where it cannot be read).
    O(1): one small read, about 20 microseconds."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError, AttributeError):
        return None


_libc = None


def trim() -> None:
    """Give freed memory back to the operating system (glibc's ``malloc_trim``; nothing elsewhere):
    after memos are dropped, the allocator keeps their pages unless asked."""
    global _libc
    if _libc is None:
        try:
            import ctypes

            _libc = ctypes.CDLL("libc.so.6")
            _libc.malloc_trim.argtypes = [ctypes.c_size_t]
        except (OSError, AttributeError):
            _libc = False
    if _libc:
        _libc.malloc_trim(0)


class MemoryUpkeep:
    """The memory upkeep of an :class:`~opportune.engine.schedule.OrderEngine` (its base class): what
    it holds in bytes, the programmes granted room beside it, and the work between decisions that keeps
    it within ``memory_limit`` (caches cleared, memos shrunk in slices).  During a decision
    (:meth:`deciding`) nothing is dropped; :meth:`maintain` does it after.  The engine's ``__init__``
    calls :meth:`_start_upkeep`; the caches and counters dropped here are the engine's."""

    def _start_upkeep(self, memory_limit: int | None) -> None:
        """The upkeep's state, set by the engine's ``__init__`` (``memory_limit``: bytes, or None)."""
        if memory_limit is not None and memory_limit <= 0:
            raise ValueError("memory_limit must be a positive number of bytes, or None")
        self.memory_limit = memory_limit
        self.shrunk = 0                 # times maintain() shrank the memos to keep within memory_limit
        self.measure_every = tuning.MEASURE_EVERY
        self._measured = (float("-inf"), 0)     # (time.monotonic(), bytes) of the last measurement
        self._pass = None   # a shrink under way: (keep share, [(memo, entries to keep)]) left to do
        #: Bytes granted to programmes kept beside the engine, by name (:meth:`reserve_programme`).
        self.programmes: dict[object, int] = {}
        #: The programmes themselves, kept here by the policies that share them (freed with the engine:
        #: a programme holds its engine, so a table keyed weakly by the engine would keep both forever).
        self.kept: dict[object, object] = {}
        # Decisions under way (see :meth:`deciding`): while any is, caches and memos may grow but are
        # never trimmed or evicted; :meth:`maintain` does that between decisions.
        self._deciding = 0
        self._upkeep_lock = allocate_lock()
        self.upkeep_due = False     # a cache or memo went over its cap during a decision
        self.maintained = 0         # maintain() calls that dropped something

    def _trim(self) -> None:
        """Bound the per-state caches (not the counters' memos): a long simulation of a large plan
        visits millions of states that never recur; start afresh rather than grow without end.
        During a decision (:meth:`deciding`) only noted: :meth:`maintain` clears them after it."""
        if self._deciding:
            self.upkeep_due = True
            return
        for cache in (self._count_cache, self._option_cache, self._options_cache, self._positions_cache,
                      self._installable_cache):
            if len(cache) > tuning.STATE_CACHE_LIMIT:
                cache.clear()

    def nbytes(self) -> int:
        """Estimated bytes this engine holds: the strategies' orders, every counter's memos and tables,
        hub paths and the per-state caches (sampled, so O(counters + caches), not O(entries); see
        :mod:`opportune.engine.memory`).  What a service accounts per plan.

        Returns
        -------
        int
            The estimated bytes, the programmes' grants (:meth:`reserve_programme`) included.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
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

        Parameters
        ----------
        name : hashable
            The programme's name.
        nbytes : int
            The bytes it needs.

        Returns
        -------
        bool
            True if granted.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> e = OrderEngine(make_plan(["a"], {}), memory_limit=1000)
        >>> e.reserve_programme("optimum", 400), e.reserve_programme("other", 400), e.nbytes() > 400
        (True, False, True)
        """
        others = sum(b for n, b in self.programmes.items() if n != name)
        if self.memory_limit is not None and others + nbytes > tuning.PROGRAMME_SHARE * self.memory_limit:
            return False
        self.programmes[name] = int(nbytes)
        return True

    def clear_state_caches(self) -> None:
        """Forget the per-state caches (options, positions, installable sets; not the counters' memos):
        what a service does to a plan over its memory share between requests.  Later questions about
        those states are counted again (from the memos).  O(1) per cache.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> e = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> e.options(0, e.all_strategies)
        {'a': 2, 'b': 1}
        >>> e.clear_state_caches()
        >>> e.options(0, e.all_strategies)       # counted again, from the memo
        {'a': 2, 'b': 1}
        """
        for cache in (self._count_cache, self._option_cache, self._options_cache, self._positions_cache,
                      self._installable_cache):
            cache.clear()

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
        of a long-running cell past its budget.  :meth:`maintain`, called between looks (the
        sequencer does it after each outcome), does that work.  What piles up meanwhile is bounded by
        the decision's budget.  Blocks may nest and overlap (threads sharing the engine).

        Yields
        ------
        OrderEngine
            This engine.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
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
        way (another thread's).  With a ``memory_limit``, also shrinks the memos when the engine's
        bytes are over it (measured at most every ``measure_every`` seconds; a shrink works in slices
        of ``SHRINK_SECONDS`` and goes on at the next call).  Complexity: O(counters + caches) when
        all are under their caps, else O(entries dropped).

        Returns
        -------
        bool
            True if anything was dropped.

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> e = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> e.count(0, e.all_strategies), e.maintain()     # all under their caps: nothing to drop
        (3, False)
        """
        with self._upkeep_lock:
            if self._deciding:
                return False
            self.upkeep_due = False
            dropped = False
            for cache in (self._count_cache, self._option_cache, self._options_cache, self._positions_cache,
                          self._installable_cache):
                if len(cache) > tuning.STATE_CACHE_LIMIT:
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
            self._drop(self._pass[0], Deadline.after(tuning.SHRINK_SECONDS))
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
        self._drop(tuning.SHRINK_TO * max(0, limit - kept) / max(1, used - kept),
                   Deadline.after(tuning.SHRINK_SECONDS), fresh=True)
        if self._pass is None:
            self._measured = (now, self.nbytes())
        return True

    def shrink(self, keep: float = 0.0, deadline: Deadline | float | None = None) -> bool:
        """Drop all but the newest ``keep`` share of every memo and clear the per-state caches, now
        (between decisions): what a service does when the whole process is over its memory cap.
        Later questions are counted again.  Stops at ``deadline`` (what is left is valid; the next
        call with the same ``keep`` goes on where it stopped).  Does nothing during a decision
        (:meth:`deciding`).  O(entries dropped).

        Parameters
        ----------
        keep : float, default 0.0
            The share of each memo's entries to keep (the newest).
        deadline : Deadline or float or None, optional
            When to stop (a :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()``
            moment; None: never).

        Returns
        -------
        bool
            True if it finished (False too when a decision is under way).

        Examples
        --------
        >>> from opportune import OrderEngine, make_plan
        >>> e = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> e.count(0, e.all_strategies), e.shrink(), e.count(0, e.all_strategies)   # counted again
        (3, True, 3)
        >>> with e.deciding():
        ...     e.shrink()
        False
        """
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
