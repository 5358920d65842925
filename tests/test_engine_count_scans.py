"""Counter: the chunk-table scan of small posets and the byte-table scan of large ones agree exactly."""

from __future__ import annotations

import random
import sys

import pytest

from opportune.engine.count import Counter
from opportune.engine.poset import Poset


def random_poset(rng: random.Random, n: int, density: float) -> Poset:
    perm = list(range(n))
    rng.shuffle(perm)
    pairs = [(perm[i], perm[j]) for i in range(n) for j in range(i + 1, n) if rng.random() < density]
    return Poset.from_pairs(n, pairs)


def up_sets(rng: random.Random, p: Poset, k: int) -> list[int]:
    """``k`` random remaining sets: the full set minus a random down-set each."""
    out = []
    for _ in range(k):
        done = 0
        for _ in range(rng.randrange(p.n + 1)):
            ready = [i for i in range(p.n) if not done >> i & 1 and p.below[i] & ~done == 0]
            if not ready:
                break
            done |= 1 << rng.choice(ready)
        out.append(p.full & ~done)
    return out


@pytest.mark.parametrize("n,density", [(1, 0.5), (5, 0.3), (12, 0.15), (20, 0.1), (31, 0.1), (47, 0.2), (48, 0.2)])
def test_narrow_and_wide_scans_agree(n, density):
    rng = random.Random(n)
    for _ in range(3):
        p = random_poset(rng, n, density)
        masks = up_sets(rng, p, 40) + [rng.getrandbits(n) if n else 0 for _ in range(20 if n <= 20 else 0)]
        narrow = Counter(p, max_memo=None, native=False)
        narrow._narrow_after = 0                   # chunk tables from the first call
        wide = Counter(p, max_memo=None, native=False)
        wide._narrow_after = sys.maxsize           # byte tables only
        default = Counter(p, max_memo=None, native=False)  # switches when its memo is large enough
        compiled = Counter(p, max_memo=None)       # the compiled core where it is built
        for m in masks:
            assert narrow.count(m) == wide.count(m) == default.count(m) == compiled.count(m)
            assert (narrow.position_sums(m) == wide.position_sums(m) == default.position_sums(m)
                    == compiled.position_sums(m))
        # same sets visited in the same order: eviction and budgets behave alike
        assert list(narrow._memo) == list(wide._memo) == list(default._memo)
        assert list(narrow._vec) == list(wide._vec) == list(default._vec)
        assert hasattr(narrow, "_ntabs") and not hasattr(wide, "_ntabs")


def test_chunk_tables_match_byte_tables():
    rng = random.Random(7)
    for n in (0, 1, 2, 3, 16, 17, 45, 48):
        p = random_poset(rng, n, 0.1)
        counter = Counter(p)
        c, (t0, t1, t2) = counter._narrow_tables()
        cmask = (1 << c) - 1
        for _ in range(200):
            s = rng.getrandbits(n) if n else 0
            x = t0[s & cmask] & t1[(s >> c) & cmask] & t2[s >> 2 * c]
            mins, cuts = counter.scan(s)
            assert s & x == cuts
            assert s & x >> 2 * n == mins
            alone = [i for i in range(n) if s >> i & 1 and not (p.below[i] | p.above[i]) & s]
            assert s & x >> n == sum(1 << i for i in alone)
