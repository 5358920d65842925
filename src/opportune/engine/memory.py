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
from itertools import islice

__all__ = ["SAMPLE", "memory_total", "nbytes", "poset_nbytes", "resident", "trim"]

SAMPLE = 8  # entries sampled at each end of a container


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
