"""The compiled core of the counter, when it is there.

``pip install`` builds :mod:`opportune._native` (C++, ``src/native/counter.cpp``) with the
machine's compiler.  It runs the same memoised recursion as the pure-Python
:class:`~opportune.engine.count.Counter` (cut elements, components, removing a minimal or a
maximal element), faster per memo entry (docs/counting.md gives both ways' measured times), for
orders of up to :data:`MAX_ELEMENTS` elements.  Where the module is missing (a build without a compiler, or
``OPPORTUNE_PURE_PYTHON=1`` in the environment) every count runs in pure Python and gives the
same exact numbers; a test compares the two on random orders.

Examples
--------
>>> from opportune.engine.poset import Poset
>>> core = native_counter(Poset.from_pairs(4, [(0, 1), (2, 3)]))
>>> core is None or core.count(0b1111, 0, -1, -1.0)[1] == 6
True
"""

from __future__ import annotations

import os

from opportune.engine.deadline import Deadline
from opportune.engine.poset import Poset
from opportune.engine.tuning import CORE_MAX_ELEMENTS  # noqa: F401 (what the core itself can take)
from opportune.engine.tuning import NATIVE_MAX_ELEMENTS as MAX_ELEMENTS, NATIVE_MAX_BYTES as MAX_BYTES


try:
    if os.environ.get("OPPORTUNE_PURE_PYTHON", "") not in ("", "0"):
        raise ImportError("OPPORTUNE_PURE_PYTHON is set")
    from opportune import _native
except ImportError:     # pragma: no cover - depends on the build
    _native = None


def entry_bytes(n: int) -> int:
    """Bytes one entry of the compiled memo may take on an order of ``n`` elements, for budgets.

    Up to 256 elements (keys of 1, 2 or 4 words) a table slot holds the key and a count of up to 127
    bits (8 bytes a key word plus 16): twice over (the table is at most three quarters full, and
    doubling holds both tables for a moment); a count of ``log2(n!)`` bits past 127 bits goes to
    the arena, once and a half (the arena doubles too).  Past 256 elements a slot of 16 bytes three
    times over (at most half full) and in the arena the key (8 or 16 words) and the count.  Counts
    are smaller on most sets (most sit in their slot), so real entries take less: about 50-60 bytes
    on sparse orders of 50-64 elements.  O(1).

    Parameters
    ----------
    n : int
        Elements of the order.

    Returns
    -------
    int
        Bytes an entry may take, at most.

    Examples
    --------
    >>> entry_bytes(50), entry_bytes(300)
    (96, 528)
    """
    import math

    words = 1
    while 64 * words < n:
        words *= 2
    limbs = max(1, -(-int(math.lgamma(n + 1) / math.log(2) + 1) // 64))
    if words <= 4:
        return 2 * (8 * words + 16) + (12 * limbs if limbs > 2 else 0)
    return 3 * 16 + 12 * (words + limbs)


def available() -> bool:
    """Whether the compiled counter can be used in this process.

    False where ``opportune._native`` was not built (no compiler at install time) or is switched
    off with ``OPPORTUNE_PURE_PYTHON=1``; every count then runs in pure Python with the same exact
    results.  O(1).

    Returns
    -------
    bool
        True when the compiled core is loaded.

    Examples
    --------
    >>> from opportune.engine import compiled_core
    >>> available() == (compiled_core() is not None)
    True
    """
    return _native is not None


class NativeCounter:
    """A compiled memo of linear-extension counts for one :class:`Poset` (both directions share it).

    ``count(mask, direction, max_new, seconds)`` returns ``(status, value, added)``: status 0 with
    the exact count of the set ``mask``, 1 when it would add more than ``max_new`` entries (-1: no
    limit), 2 when it ran out of its ``seconds`` (negative: no limit; or the caller's
    :class:`~opportune.engine.deadline.Deadline`); ``added`` entries were stored either way and
    stay, and a stop never leaves a half-stored entry.  ``direction`` 0 removes minimal elements,
    1 maximal ones.  The core reads its clock every 1,024 word operations of work, table and arena
    growth included.  Most callers want :func:`native_counter`, which gives None where the core is
    missing or the order is outside what it takes.

    Parameters
    ----------
    poset : Poset
        The order; at most :data:`CORE_MAX_ELEMENTS` elements.
    max_total : int or None
        Entries past which :meth:`over` says to start again (None: only :attr:`max_bytes` bounds it).

    Raises
    ------
    ValueError
        When ``poset`` has more than :data:`CORE_MAX_ELEMENTS` elements.

    Examples
    --------
    Built only where the core is (:func:`available`); it counts what the pure-Python
    :class:`~opportune.engine.count.Counter` counts:

    >>> from opportune.engine.count import Counter
    >>> p = Poset.from_pairs(4, [(0, 1), (2, 3)])       # two chains of two: 4! / (2! 2!) = 6
    >>> not available() or NativeCounter(p).count(p.full, 0, -1, -1.0)[:2] == (0, Counter(p, native=False).count())
    True
    """

    __slots__ = ("_core", "_nbytes", "max_total", "max_bytes")

    def __init__(self, poset: Poset, max_total: int | None = None):
        if poset.n > CORE_MAX_ELEMENTS:
            raise ValueError(f"the compiled core takes orders of at most {CORE_MAX_ELEMENTS} elements")
        words = 1
        while 64 * words < poset.n:
            words *= 2
        self._nbytes = 8 * words
        nb = self._nbytes
        cls = getattr(_native, f"Counter{words}")
        self._core = cls(poset.n, [m.to_bytes(nb, "little") for m in poset.below],
                         [m.to_bytes(nb, "little") for m in poset.above])
        self.max_total = max_total
        #: Bytes past which :meth:`over` says to start again (:data:`MAX_BYTES`, or more for a counter
        #: made for a larger count: see :class:`~opportune.engine.count.Counter`).
        self.max_bytes = MAX_BYTES

    def count(self, mask: int, direction: int, max_new: int,
              seconds: float | Deadline) -> tuple[int, int | None, int]:
        """Count the linear extensions of the set ``mask``, within a budget of new entries and time.

        Parameters
        ----------
        mask : int
            The set, a bitmask of the order's elements.
        direction : int
            0: the recursion removes minimal elements; 1: maximal ones (the same count, other sets visited).
        max_new : int
            Most new memo entries this call may add (-1: no limit).
        seconds : float or Deadline
            Most seconds this call may take (negative: no limit), or the caller's deadline.

        Returns
        -------
        tuple of (int, int or None, int)
            ``(status, count, added)``: status 0 with the exact count, 1 (over ``max_new``) or 2 (out of
            time) with None; ``added`` entries were stored either way and stay.

        Examples
        --------
        >>> p = Poset.antichain(3)
        >>> core = native_counter(p)
        >>> core is None or [core.count(p.full, d, -1, -1.0)[:2] for d in (0, 1)] == [(0, 6), (0, 6)]
        True
        """
        if isinstance(seconds, Deadline):
            seconds = seconds.seconds()
        status, value, added = self._core.count(mask.to_bytes(self._nbytes, "little"), direction, max_new, seconds)
        return status, (int.from_bytes(value, "little") if value is not None else None), added

    def over(self, max_total: int | None = None) -> bool:
        """Whether the memo holds more than ``max_total`` entries or :attr:`max_bytes` bytes.

        The caller then resets it, at the start of a top-level call: never within one, where the
        recursions above the core rely on what it has stored.  O(1).

        Parameters
        ----------
        max_total : int or None
            Entries allowed (None: the counter's own ``max_total``).

        Returns
        -------
        bool
            True when the memo is over either cap.

        Examples
        --------
        >>> p = Poset.antichain(4)
        >>> core = native_counter(p)
        >>> core is None or (core.count(p.full, 0, -1, -1.0)[0] == 0 and core.over(0) and not core.over(10**6))
        True
        """
        if max_total is None:
            max_total = self.max_total
        return (max_total is not None and self._core.size() > max_total) or self._core.memory() > self.max_bytes

    def lookup(self, mask: int) -> int | None:
        """The count of ``mask`` if the memo holds it, else None (never computes).  O(1).

        Parameters
        ----------
        mask : int
            The set, a bitmask of the order's elements.

        Returns
        -------
        int or None
            The stored exact count, or None.

        Examples
        --------
        >>> core = native_counter(Poset.antichain(3))
        >>> core is None or (core.lookup(0b111) is None and core.count(0b111, 0, -1, -1.0)[1] == core.lookup(0b111) == 6)
        True
        """
        value = self._core.lookup(mask.to_bytes(self._nbytes, "little"))
        return None if value is None else int.from_bytes(value, "little")

    def put(self, mask: int, value: int) -> None:
        """Store the exact count ``value`` of ``mask`` found by another method.

        Later counts that meet ``mask`` read it instead of recursing.  O(1).

        Parameters
        ----------
        mask : int
            The set, a bitmask of the order's elements.
        value : int
            Its exact number of linear extensions (any size: counts past 2^127 go to the arena).

        Examples
        --------
        >>> core = native_counter(Poset.antichain(30))
        >>> core is None or (core.put(0b111, 6), core.lookup(0b111))[1] == 6
        True
        """
        self._core.put(mask.to_bytes(self._nbytes, "little"), value.to_bytes(max(8, -(-value.bit_length() // 64) * 8), "little"))

    def tails_new(self, marks: int) -> int:
        """A new compiled memo of tail distributions for ``marks`` (see :class:`~opportune.engine.hub.TailCounter`).

        Parameters
        ----------
        marks : int
            The marked elements, a bitmask.

        Returns
        -------
        int
            A handle for :meth:`tail` and :meth:`tails_drop`.

        Examples
        --------
        >>> core = native_counter(Poset.from_pairs(3, [(0, 1)]))
        >>> core is None or isinstance(core.tails_new(0b001), int)
        True
        """
        return self._core.tails_new(marks.to_bytes(self._nbytes, "little"))

    def tails_drop(self, handle: int) -> None:
        """Free the tail memo ``handle`` (what :class:`~opportune.engine.hub.TailCounter` does when it goes).

        Parameters
        ----------
        handle : int
            A handle from :meth:`tails_new`.

        Examples
        --------
        >>> core = native_counter(Poset.from_pairs(3, [(0, 1)]))
        >>> core is None or core.tails_drop(core.tails_new(0b001)) is None
        True
        """
        self._core.tails_drop(handle)

    def tail(self, handle: int, mask: int, max_new: int,
             seconds: float | Deadline) -> tuple[int, list[int] | None, int]:
        """The tail distribution of ``mask`` for the marks of ``handle``, within a budget.

        Entry ``b`` of the distribution counts the linear extensions of ``mask`` with ``b`` elements
        after the last marked one, as :meth:`~opportune.engine.hub.TailCounter.tail` counts them.

        Parameters
        ----------
        handle : int
            A handle from :meth:`tails_new`.
        mask : int
            The set, a bitmask of the order's elements.
        max_new : int
            Most new count entries this call may add (-1: no limit).
        seconds : float or Deadline
            Most seconds this call may take (negative: no limit), or the caller's deadline.

        Returns
        -------
        tuple of (int, list of int or None, int)
            ``(status, distribution or None, new count entries)``, statuses as for :meth:`count`.

        Examples
        --------
        >>> core = native_counter(Poset.from_pairs(3, [(0, 1)]))     # 0 < 1, 2 free; 0 marked
        >>> core is None or core.tail(core.tails_new(0b001), 0b111, -1, -1.0)[:2] == (0, [0, 1, 2])
        True
        """
        if isinstance(seconds, Deadline):
            seconds = seconds.seconds()
        status, values, added = self._core.tail(handle, mask.to_bytes(self._nbytes, "little"), max_new, seconds)
        if values is None:
            return status, None, added
        return status, [int.from_bytes(v, "little") for v in values], added

    def work(self) -> int:
        """Word operations of work done by the last :meth:`count` or :meth:`tail`.

        The core reads its clock every 1,024 of them; tests count work with it instead of time.

        Returns
        -------
        int
            Word operations of the last call.

        Examples
        --------
        >>> core = native_counter(Poset.antichain(8))
        >>> core is None or (core.count(0xFF, 0, -1, -1.0)[1] == 40320 and core.work() > 0)
        True
        """
        return self._core.work()

    def size(self) -> int:
        """Entries in the compiled memo.  O(1).

        Returns
        -------
        int
            Counts stored.

        Examples
        --------
        >>> core = native_counter(Poset.chain(3))
        >>> core is None or (core.put(0b011, 1), core.size())[1] >= 1
        True
        """
        return self._core.size()

    def memory(self) -> int:
        """Bytes the compiled memo holds (table and arena).  O(1).

        Returns
        -------
        int
            Bytes held.

        Examples
        --------
        >>> core = native_counter(Poset.chain(3))
        >>> core is None or core.memory() > 0
        True
        """
        return self._core.memory()

    def reset(self) -> None:
        """Forget every entry (the memo starts again, as :meth:`over` asks).

        Examples
        --------
        >>> core = native_counter(Poset.antichain(3))
        >>> core is None or (core.count(0b111, 0, -1, -1.0), core.reset(), core.lookup(0b111))[2] is None
        True
        """
        self._core.reset()


def native_counter(poset: Poset, max_total: int | None = None) -> NativeCounter | None:
    """A :class:`NativeCounter` for ``poset``, or None where the compiled core cannot take it.

    None where the core is missing (:func:`available` is False) or the order has fewer than 2 or
    more than :data:`MAX_ELEMENTS` elements; the caller then counts in pure Python.

    Parameters
    ----------
    poset : Poset
        The order.
    max_total : int or None
        As for :class:`NativeCounter`.

    Returns
    -------
    NativeCounter or None
        The compiled memo, or None.

    Examples
    --------
    >>> native_counter(Poset.chain(1)) is None                  # nothing to count
    True
    >>> (native_counter(Poset.chain(3)) is not None) == available()
    True
    """
    if _native is None or poset.n > MAX_ELEMENTS or poset.n < 2:
        return None
    return NativeCounter(poset, max_total)
