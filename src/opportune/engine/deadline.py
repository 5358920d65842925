"""One deadline for all the work of a caller: counts, hub terms, position sums, estimates, chains.

A :class:`Deadline` is a moment on ``time.perf_counter()``'s clock after which work must stop.
Every engine entry point takes one (``deadline=``), passes it down unchanged to everything it
calls, and every loop whose length depends on the input reads it (:meth:`Deadline.check` raises
:class:`BudgetExceeded`; :meth:`Deadline.expired` only tells).  The compiled core gets
:meth:`Deadline.seconds` and reads its own steady clock.

Why one object and not a time limit per call: work done before a count (a probe, a hub search,
the first of several strategies' terms) must not push the end of a decision later.  A caller that
wants to give part of its time to a sub-task makes a *sooner* deadline with :meth:`Deadline.share`
or :meth:`Deadline.within`, never a later one.

Examples
--------
>>> d = Deadline.after(60.0)
>>> d.expired(), 0 < d.remaining() <= 60
(False, True)
>>> Deadline.NEVER.remaining()
inf
>>> Deadline.after(0.0).within(10.0).expired()      # a sub-task never outlives its caller
True
>>> try:
...     Deadline.after(-1.0).check("counting")
... except BudgetExceeded as exc:
...     print(exc, exc.reason)
the deadline has passed: counting time
"""

from __future__ import annotations

import gc
import math
import sys
import time
from _thread import allocate_lock     # threading.Lock without threading's import
from contextlib import contextmanager

__all__ = ["BudgetExceeded", "Deadline", "as_deadline", "no_collection", "recursion_room"]

_perf = time.perf_counter
_INF = math.inf


class BudgetExceeded(Exception):
    """An exact count would need more new memo entries or more time than one call may use.

    The counter's memo stays valid (only finished values are stored): call
    again with a larger budget to continue where it stopped, or fall back to
    :func:`opportune.engine.estimate.estimate_count`.

    Parameters
    ----------
    message : str
        What ran out, in words (the exception's text).
    reason : str
        ``"memo"`` (more new entries than a call may add) or ``"time"`` (the deadline passed).
    memo_size : int
        Entries the memo holds when it stopped.
    elapsed : float
        Seconds the call had run, where the raiser measured them (else 0).

    Examples
    --------
    A count over its budget of new entries stops, and the same count with more budget goes on
    from what the first one stored:

    >>> from opportune.engine.count import Counter
    >>> from opportune.engine.poset import Poset
    >>> fence = Poset.from_pairs(12, [(i, i + 1) if i % 2 == 0 else (i + 1, i) for i in range(11)])
    >>> c = Counter(fence, max_memo=20)
    >>> try:
    ...     c.count()
    ... except BudgetExceeded as exc:
    ...     print(exc.reason, exc.memo_size > 0)
    memo True
    >>> c.max_memo = None; c.count()                    # the zigzag numbers: 2,702,765 orders up and down
    2702765
    >>> str(BudgetExceeded("counting ran out of time", reason="time"))
    'counting ran out of time'
    """

    def __init__(self, message: str, *, reason: str = "memo", memo_size: int = 0, elapsed: float = 0.0):
        self.reason = reason
        self.memo_size = memo_size
        self.elapsed = elapsed
        super().__init__(message)


class Deadline:
    """A moment (``time.perf_counter()`` value, ``inf`` for none) after which work stops.

    Immutable; cheap to make and to read (``at`` is a plain float, for hot loops that compare it
    with ``time.perf_counter()`` themselves).  Complexity: every method is O(1).
    """

    __slots__ = ("at",)
    NEVER: "Deadline"

    def __init__(self, at: float = _INF):
        if at != at:            # nan: no moment at all is a caller's mistake, not "never"
            raise ValueError("a deadline must be a number of seconds on time.perf_counter()'s clock, not nan")
        object.__setattr__(self, "at", float(at))

    def __setattr__(self, name, value):
        raise AttributeError("a Deadline is immutable: make a sooner one with within() or share()")

    @classmethod
    def after(cls, seconds: float | None) -> "Deadline":
        """The deadline ``seconds`` from now (None: never)."""
        return cls.NEVER if seconds is None else cls(_perf() + seconds)

    # ---------------------------------------------------------------- reading it

    def remaining(self) -> float:
        """Seconds left (negative once passed; ``inf`` for never)."""
        return self.at - _perf() if self.at != _INF else _INF

    def expired(self) -> bool:
        """True once the moment has passed."""
        return self.at != _INF and _perf() > self.at

    def check(self, what: str = "") -> None:
        """Raise :class:`BudgetExceeded` (reason ``"time"``) once the moment has passed."""
        if self.at != _INF and _perf() > self.at:
            raise BudgetExceeded(f"the deadline has passed{': ' + what if what else ''}", reason="time")

    def seconds(self) -> float:
        """Seconds left for the compiled core: ``-1.0`` for never, else at least 0."""
        return -1.0 if self.at == _INF else max(0.0, self.at - _perf())

    @property
    def finite(self) -> bool:
        return self.at != _INF

    # ---------------------------------------------------------------- sooner deadlines for sub-tasks

    def within(self, seconds: float | None) -> "Deadline":
        """The sooner of this deadline and ``seconds`` from now (None: this one)."""
        if seconds is None:
            return self
        at = _perf() + seconds
        return self if at >= self.at else Deadline(at)

    def share(self, fraction: float) -> "Deadline":
        """A deadline ``fraction`` of the remaining time from now (this one if it is never)."""
        if self.at == _INF:
            return self
        now = _perf()
        return Deadline(now + max(0.0, self.at - now) * fraction)

    def sooner(self, other: "Deadline | float | None") -> "Deadline":
        """The sooner of two deadlines (a float is a ``perf_counter`` moment, None never)."""
        o = as_deadline(other)
        return self if self.at <= o.at else o

    # ---------------------------------------------------------------- plumbing

    def __repr__(self) -> str:
        return "Deadline.NEVER" if self.at == _INF else f"Deadline(in {self.remaining():.6f} s)"

    def __eq__(self, other) -> bool:
        return isinstance(other, Deadline) and other.at == self.at

    def __hash__(self) -> int:
        return hash(self.at)

    def __reduce__(self):
        # a moment on one process's clock means nothing in another: a deadline sent to a worker
        # process keeps its remaining time
        return (Deadline.after, (None if self.at == _INF else self.remaining(),))


Deadline.NEVER = Deadline()


def as_deadline(value: "Deadline | float | None") -> Deadline:
    """A :class:`Deadline` from what older callers pass: a Deadline, a ``perf_counter`` moment
    (float), or None (never)."""
    if value is None:
        return Deadline.NEVER
    if isinstance(value, Deadline):
        return value
    return Deadline(value)


_held = [0, False]              # blocks of no_collection() open in any thread; whether the first switched it off
_held_lock = allocate_lock()


@contextmanager
def no_collection():
    """Within the block, no automatic collection of reference cycles.

    A full collection walks every container object of the whole process, not only what the block
    made: 0.3 s for three million objects, a cost no deadline check inside the block can bound.  A
    timed call holds it off (the engine's memos are tuples, ints and dicts without cycles, which
    reference counting frees); the caller's next collection does that work, outside the call's time.
    Blocks may nest and overlap in threads (a service counting for several requests): collection is
    back on, if it was on before the first, once the last block ends.  O(1).

    >>> with no_collection():
    ...     gc.isenabled()
    False
    """
    with _held_lock:
        if _held[0] == 0:
            _held[1] = gc.isenabled()
            gc.disable()
        _held[0] += 1
    try:
        yield
    finally:
        with _held_lock:
            _held[0] -= 1
            if _held[0] == 0 and _held[1]:
                gc.enable()


class recursion_room:
    """Within the block, room for ``depth`` nested Python calls: the interpreter's recursion limit is
    raised for the block where it is lower, and put back after.  A deep recursion (a count over
    thousands of elements) must not leave the process's limit changed for good: the caller did not
    ask for it, and a test runner that manages the limit (Hypothesis) warns of it.  Re-entrant.

    >>> import sys
    >>> before = sys.getrecursionlimit()
    >>> with recursion_room(before + 5_000):
    ...     sys.getrecursionlimit() == before + 5_000
    True
    >>> sys.getrecursionlimit() == before
    True
    """

    __slots__ = ("depth", "_old")

    def __init__(self, depth: int):
        self.depth = depth
        self._old: list[int] = []

    def __enter__(self) -> "recursion_room":
        old = sys.getrecursionlimit()
        self._old.append(old)
        if old < self.depth:
            sys.setrecursionlimit(self.depth)
        return self

    def __exit__(self, *exc) -> bool:
        old = self._old.pop()
        if sys.getrecursionlimit() != old:
            sys.setrecursionlimit(old)
        return False
