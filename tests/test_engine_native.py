"""The compiled counter (opportune._native) gives the same exact counts as the pure-Python one.

``make test`` builds the compiled core (``pip install -e .`` runs CMake through
scikit-build-core), so these tests require it: a build that silently fell back to pure
Python would fail here rather than pass unnoticed.  ``OPPORTUNE_PURE_PYTHON=1`` turns the
core off on purpose; then only the fallback is checked.
"""

from __future__ import annotations

import math
import os
import random
from itertools import permutations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opportune.engine import native
from opportune.engine.count import BudgetExceeded, Counter
from opportune.engine.poset import Poset

PURE = os.environ.get("OPPORTUNE_PURE_PYTHON", "") not in ("", "0")
needs_core = pytest.mark.skipif(PURE, reason="OPPORTUNE_PURE_PYTHON is set: the compiled core is off on purpose")


def random_poset(rng: random.Random, n: int, density: float) -> Poset:
    perm = list(range(n))
    rng.shuffle(perm)
    pairs = [(perm[i], perm[j]) for i in range(n) for j in range(i + 1, n) if rng.random() < density]
    return Poset.from_pairs(n, pairs)


def brute_force(p: Poset, mask: int) -> int:
    elems = [i for i in range(p.n) if mask >> i & 1]
    return sum(all(not p.less(b, a) for i, a in enumerate(order) for b in order[i + 1:])
               for order in permutations(elems))


def random_subsets(rng: random.Random, p: Poset, k: int) -> list[int]:
    return [p.full] + [rng.getrandbits(p.n) for _ in range(k)]


@needs_core
def test_the_core_is_built():
    assert native.available(), "opportune._native is missing: `pip install -e .` should have compiled it"
    assert Counter(Poset.chain(3)).compiled
    assert not Counter(Poset.chain(3), native=False).compiled


@needs_core
@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 8), density=st.floats(0.0, 0.6), seed=st.integers(0, 10**6))
def test_compiled_equals_brute_force_on_small_orders(n, density, seed):
    rng = random.Random(seed)
    p = random_poset(rng, n, density)
    core = native.native_counter(p)
    for mask in random_subsets(rng, p, 6):
        expected = brute_force(p, mask)
        for direction in (0, 1):
            status, value, _ = core.count(mask, direction, -1, -1.0)
            assert status == 0 and value == expected


@needs_core
@settings(max_examples=12, deadline=None)
@given(n=st.sampled_from([20, 40, 63, 64, 65, 90, 128, 129, 200]), density=st.floats(0.02, 0.3),
       seed=st.integers(0, 10**6))
def test_compiled_equals_pure_python_on_random_orders(n, density, seed):
    """Every word width (1, 2, 4 words) against the pure-Python counter, on random subsets."""
    rng = random.Random(seed)
    p = random_poset(rng, n, density if n <= 64 else max(density, 3.0 / n))
    compiled = Counter(p, max_memo=None)
    pure = Counter(p, max_memo=None, native=False)
    assert compiled.compiled and not pure.compiled
    # random up-sets (what remains to be done) are what the engine asks; keep them easy enough
    masks = []
    for _ in range(5):
        done = 0
        for _ in range(rng.randrange(p.n + 1)):
            ready = [i for i in range(p.n) if not done >> i & 1 and p.below[i] & ~done == 0]
            done |= 1 << rng.choice(ready)
        masks.append(p.full & ~done)
    for mask in masks:
        try:
            expected = Counter(p, max_memo=20_000, native=False).count(mask)
        except BudgetExceeded:
            continue
        assert compiled.count(mask) == expected
        assert pure.count(mask) == expected


@needs_core
def test_big_counts_and_every_width():
    """Counts far beyond 64 bits, components and cut elements, on 1 to 16 words."""
    for n in (30, 64, 100, 250, 500, 1000):
        anti = Poset.antichain(n)
        core = native.NativeCounter(anti)
        assert core.count(anti.full, 0, -1, -1.0)[1] == math.factorial(n)
        assert Counter(anti).count() == math.factorial(n)
        assert Counter(anti).compiled == (n <= native.MAX_ELEMENTS)
        # two chains joined by a cut element in the middle: C(2k, k) on each side
        k = n // 4
        pairs = [(i, i + 1) for i in range(k - 1)] + [(k + i, k + i + 1) for i in range(k - 1)]
        hub = 2 * k
        pairs += [(k - 1, hub), (2 * k - 1, hub)]
        rest = list(range(hub + 1, hub + 1 + 2 * k))
        pairs += [(hub, rest[0]), (hub, rest[k])]
        pairs += [(rest[i], rest[i + 1]) for i in range(k - 1)] + [(rest[k + i], rest[k + i + 1]) for i in range(k - 1)]
        p = Poset.from_pairs(hub + 1 + 2 * k, pairs)
        assert native.NativeCounter(p).count(p.full, 1, -1, -1.0)[1] == math.comb(2 * k, k) ** 2
        assert Counter(p).count() == math.comb(2 * k, k) ** 2
        assert Counter(p).count() == Counter(p, native=False).count()


@needs_core
@pytest.mark.parametrize("seed", range(6))
def test_the_core_takes_orders_past_256_and_agrees_with_python(seed):
    """Orders of 257 to 1,024 elements go to the core, components of very unequal sizes included
    (the multinomial of a set is built from the smaller components' sizes), and every count equals
    the pure-Python one, on the whole order and on random subsets."""
    rng = random.Random(seed)      # a plain loop: the Python counter raises the recursion limit
    n = rng.randint(257, native.MAX_ELEMENTS)
    perm = list(range(n))
    rng.shuffle(perm)
    pairs, at = [], 0
    while at < n:           # components: narrow strips (two or three chains with random links)
        size = min(n - at, rng.choice((1, 2, 5, 20, n // 2)))
        block = perm[at:at + size]
        width = rng.choice((1, 2, 3))
        for i in range(size - width):
            pairs.append((block[i], block[i + width]))
            if rng.random() < 0.2 and i + width + 1 < size:
                pairs.append((block[i], block[i + width + 1]))
        at += size
    p = Poset.from_pairs(n, pairs)
    fast, slow = Counter(p, max_memo=None), Counter(p, native=False, max_memo=None)
    assert fast.compiled and not slow.compiled
    for mask in random_subsets(rng, p, 3):
        assert fast.count(mask) == slow.count(mask)


def test_entries_within_a_memory_budget_scale_with_the_entry_size():
    """A count's entry budget from bytes: more entries for small orders than for large ones, never
    none, and within the bytes by the stated size of an entry."""
    from opportune.engine.count import entries_within

    for n in (2, 50, 300, 1024, 5000):
        per = native.entry_bytes(n) if native.available() and n <= native.MAX_ELEMENTS else None
        got = entries_within(n, 2**30)
        assert got >= 1
        if per is not None:
            assert got * per <= 2**30 < (got + 1) * per
    assert entries_within(50, 2**30) > entries_within(300, 2**30) > entries_within(1024, 2**30)
    assert entries_within(1000, 10) == 1


def test_an_engine_with_max_memo_0_budgets_its_counts_by_its_memory_limit():
    """``max_memo=0`` (what ``opportune count`` passes): entries from the engine's own memory limit and
    the order's size in units (a part of quantity 3 is 3 units), so the limit decides, not the part count."""
    from opportune import make_plan
    from opportune.engine import OrderEngine
    from opportune.engine.count import entries_within

    plan = make_plan(["a", {"id": "b", "quantity": 300}, "c"], {"c": ["a"]})
    assert entries_within(302, 2**30) != entries_within(3, 2**30)
    for limit in (2**20, 2**30):
        engine = OrderEngine(plan, max_memo=0, memory_limit=limit)
        assert engine.max_memo == entries_within(engine.n_units, limit)
    assert OrderEngine(plan, max_memo=0, memory_limit=2**30).max_memo > OrderEngine(plan, max_memo=0, memory_limit=2**20).max_memo
    assert OrderEngine(plan, max_memo=1234).max_memo == 1234


@needs_core
def test_budgets_stop_the_core_and_its_memo_survives():
    rng = random.Random(3)
    p = random_poset(rng, 36, 0.08)
    exact = Counter(p, max_memo=None, native=False).count()
    c = Counter(p, max_memo=500)
    with pytest.raises(BudgetExceeded) as info:
        c.count()
    assert info.value.reason == "memo"
    kept = c.memo_size
    assert kept > 0                          # what it stored stays, and the next call goes on from it
    c.max_memo = None
    assert c.count() == exact
    assert c.memo_size > kept
    # a time limit of zero stops at once (the core looks at the clock every 64 new entries)
    t = Counter(p, max_memo=None)
    t.time_limit = 0.0
    with pytest.raises(BudgetExceeded) as info:
        t.count()
    assert info.value.reason == "time"


@needs_core
def test_learn_and_cached_reach_the_compiled_memo():
    p = Poset.from_pairs(4, [(0, 2), (1, 2), (1, 3)])
    c = Counter(p)
    assert c.cached(0b1110) is None
    assert c.count() == brute_force(p, p.full)
    # the recursion stored the sets it visited in the core (removing 0 leaves {1, 2, 3}, two orders):
    # cached() finds them although Python's memo holds only the set asked for
    assert 0b1110 not in c._memo and c.cached(0b1110) == 2
    p = Poset.from_pairs(5, [(0, 1), (2, 3)])
    core = native.native_counter(p)
    core.put(0b00111, 3)
    assert core.lookup(0b00111) == 3
    assert core.count(0b00111, 0, -1, -1.0) == (0, 3, 0)     # answered from the stored value


@needs_core
def test_compiled_counter_agrees_through_the_whole_engine(monkeypatch):
    """Options, expected positions and installable parts on a real graph, compiled against pure."""
    from opportune.datasets import salbp
    from opportune.engine.schedule import OrderEngine, Schedule

    plan = salbp("KILBRID")
    compiled = Schedule(OrderEngine(plan))
    compiled.count()                                   # its counter is made now, compiled
    monkeypatch.setattr(native, "_native", None)      # counters made from here on are pure Python
    pure = Schedule(OrderEngine(plan))
    rng = random.Random(5)
    for _ in range(15):
        assert compiled.count() == pure.count()
        assert compiled.options() == pure.options()
        assert compiled.expected_positions() == pure.expected_positions()
        if compiled.is_complete:
            break
        part = rng.choice(sorted(compiled.installable()))
        compiled, pure = compiled.install(part), pure.install(part)
    assert compiled.engine.counter(compiled.engine.all_strategies).compiled
    assert not pure.engine.counter(pure.engine.all_strategies).compiled


def test_pure_python_fallback_when_the_core_is_off():
    """With OPPORTUNE_PURE_PYTHON=1 the package runs without the core and counts the same."""
    import subprocess
    import sys

    code = ("from opportune.engine import native; from opportune.engine.count import Counter; "
            "from opportune.datasets import salbp_path; from opportune.formats.loader import load_plan; "
            "from opportune.engine.schedule import Schedule; "
            "print(native.available(), Schedule(load_plan(salbp_path('KILBRID'))).count())")
    env = dict(os.environ, OPPORTUNE_PURE_PYTHON="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    available, value = out.stdout.split()
    assert available == "False"
    from opportune.datasets import salbp_path
    from opportune.engine.schedule import Schedule
    from opportune.formats.loader import load_plan

    assert int(value) == Schedule(load_plan(salbp_path("KILBRID"))).count()


@needs_core
@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 40), density=st.floats(0.0, 0.4), seed=st.integers(0, 10**6))
def test_compiled_tail_distributions_equal_the_pure_python_ones(n, density, seed):
    """The hub's tail distributions (engine/hub.py): compiled recursion against the Python one."""
    from opportune.engine.hub import TailCounter

    rng = random.Random(seed)
    p = random_poset(rng, n, density if n <= 16 else min(density, 4.0 / n))
    marks = rng.getrandbits(n) or 1
    compiled = TailCounter(Counter(p), marks)
    pure = TailCounter(Counter(p, native=False), marks)
    assert compiled._core is not None and pure._core is None
    for _ in range(4):
        s = rng.getrandbits(n) | (1 << rng.choice([i for i in range(n) if marks >> i & 1]))
        d = compiled.tail(s)
        assert d == pure.tail(s)
        assert sum(d) == Counter(p, native=False).count(s)     # every order has its mark somewhere


@needs_core
def test_the_compiled_memo_starts_again_only_between_calls():
    """Over its cap the compiled memo is reset at the start of a top-level call, never within one: the
    recursions above it (position sums, the hub) make many calls into the core per top-level call, and
    a reset within one would make them recompute everything again and again."""
    rng = random.Random(9)
    p = random_poset(rng, 30, 0.1)
    pure = Counter(p, native=False)
    c = Counter(p, max_total=50)
    assert c.count() == pure.count()
    held = c._native.size()
    assert held > 50                                   # kept through the call that filled it
    resets = []

    class Spy(type(c._native)):      # NativeCounter has __slots__: count the resets in a subclass
        __slots__ = ()

        def reset(self):
            resets.append(1)
            super().reset()

    c._native.__class__ = Spy
    assert c.position_sums() == pure.position_sums()   # one call: many core calls, no reset among them
    assert len(resets) == 1                            # once, at its start (the memo was over its cap)
    c.clear()
    assert c._native.size() == 0


def zigzag_numbers(n: int) -> list[int]:
    """Euler's zigzag numbers E_0..E_n (the boustrophedon: no counting of orders), the number of linear
    extensions of the fence a1 < a2 > a3 < a4 ... on n elements."""
    out, row = [1], [1]
    for _ in range(n):
        new = [0]
        for x in reversed(row):
            new.append(new[-1] + x)
        row = new
        out.append(row[-1])
    return out


def spread(n_total: int, k: int, offset: int = 0) -> list[int]:
    """``k`` distinct elements of ``0..n_total-1`` spread over every word of the set (stride ~ n/k)."""
    step = max(1, n_total // k)
    return [(offset + i * step) % n_total for i in range(k)]


@needs_core
@pytest.mark.parametrize("n_total", [64, 100, 200, 300])
def test_fence_counts_cross_every_inline_boundary_on_every_width(n_total):
    """Fences have Euler's zigzag numbers as counts: those of fences up to 60 elements run through 2^63,
    2^64, 2^127, 2^128 and 2^192, so the memo's counts (and the sums of a set's children) cross each
    boundary of the slots' inline counts, on keys of 1, 2, 4 and 8 words (the fence spread over the
    words of a larger order).  Both directions, the pure-Python counter and brute force (small
    fences) agree."""
    k = 60
    zig = zigzag_numbers(k)
    assert zig[:8] == [1, 1, 1, 2, 5, 16, 61, 272]          # A000111
    elems = spread(n_total, k, offset=3)
    pairs = [(elems[i], elems[i + 1]) if i % 2 == 0 else (elems[i + 1], elems[i]) for i in range(k - 1)]
    p = Poset.from_pairs(n_total, pairs)
    core = native.NativeCounter(p)
    for m in list(range(1, 9)) + [22, 23, 24, 25, 38, 39, 40, 51, 52, 53, k]:
        mask = sum(1 << e for e in elems[:m])
        for direction in (0, 1):
            assert core.count(mask, direction, -1, -1.0)[1] == zig[m], (m, direction)
        if m <= 8 and n_total == 64:
            assert brute_force(p, mask) == zig[m]
    assert Counter(p, native=False).count(sum(1 << e for e in elems)) == zig[k]


@needs_core
@settings(max_examples=40, deadline=None)
@given(x=st.sampled_from([1, 2**63 - 1, 2**63, 2**64 - 1, 2**64, 2**127 - 1, 2**127, 2**128 - 1, 2**128,
                          2**191, 2**192 - 1, 2**300 + 7]),
       dx=st.integers(0, 3), y=st.integers(1, 2**200), n_total=st.sampled_from([4, 100, 200, 300]))
def test_counts_at_the_inline_boundaries_are_stored_and_summed_exactly(x, dx, y, n_total):
    """A count put in the memo comes back exact on both sides of every inline boundary (2^63 and 2^127:
    a count below 2^127 sits in its slot, a larger one in the arena), and a set's count is the exact
    sum of its children's (added in three words, carries past 2^128 and 2^192 included)."""
    a, b, c, d = spread(n_total, 4, offset=1)
    p = Poset.from_pairs(n_total, [(a, c), (b, c), (b, d)])     # N: connected, no cut element
    core = native.NativeCounter(p)
    x += dx
    without_a, without_b = (1 << b) | (1 << c) | (1 << d), (1 << a) | (1 << c) | (1 << d)
    core.put(without_a, x)
    core.put(without_b, y)
    assert core.lookup(without_a) == x and core.lookup(without_b) == y
    whole = (1 << a) | (1 << b) | (1 << c) | (1 << d)
    assert core.count(whole, 0, -1, -1.0)[1] == x + y     # the minimal elements a, b removed: the two sets
    assert core.lookup(whole) == x + y


@needs_core
@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 7), density=st.floats(0.0, 0.7), seed=st.integers(0, 10**6),
       n_total=st.sampled_from([7, 70, 150, 300]))
def test_convex_sets_found_from_their_parents_equal_brute_force(n, density, seed, n_total):
    """On a convex set (what remains of an order, or any interval of it) the core finds each child's
    minimal (maximal) elements from its parent's and the covers of the removed element, instead of
    scanning: the counts equal brute force and the scanned direction (2) on convex sets and on others,
    on keys of 1 to 8 words (the order's elements spread over the words of a larger one)."""
    rng = random.Random(seed)
    small = random_poset(rng, n, density)
    elems = spread(n_total, n, offset=rng.randrange(n_total))
    p = Poset.from_pairs(n_total, [(elems[a], elems[b]) for a in range(n) for b in range(n) if small.less(a, b)])
    done = 0                     # a random down-set: what remains is an up-set (convex)
    for _ in range(rng.randrange(n + 1)):
        ready = [i for i in range(n) if not done >> i & 1 and small.below[i] & ~done == 0]
        done |= 1 << rng.choice(ready)
    masks = [small.full, small.full & ~done]
    lo, hi = rng.randrange(n), rng.randrange(n)     # an interval [lo, hi] (convex) and a random set
    masks.append((small.above[lo] | 1 << lo) & (small.below[hi] | 1 << hi))
    masks.append(rng.getrandbits(n))
    for m in masks:
        mask = sum(1 << elems[i] for i in range(n) if m >> i & 1)
        expected = brute_force(small, m)
        for direction in (0, 1, 2):
            assert native.NativeCounter(p).count(mask, direction, -1, -1.0)[1] == expected, (m, direction)
