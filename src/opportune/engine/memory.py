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

import sys
from itertools import islice

__all__ = ["SAMPLE", "nbytes", "poset_nbytes"]

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
