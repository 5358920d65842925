"""The counter's choice of method per hard piece (recursion up or down, down-set DP) and its budgets.

Correctness only: every way of counting gives the same exact numbers as brute force, the
down-set DP and the plain recursion; budgets stop a count instead of letting it run on.
"""

from __future__ import annotations

import math
import random
import time
from unittest.mock import patch

import pytest
from hypothesis import given, settings, strategies as st

from conftest import CpuTime
from opportune.engine import count as count_module
from opportune.engine.count import BudgetExceeded, Counter
from opportune.engine.downsets import count_by_downsets, count_downsets, count_downsets_bounded, upset_counts
from opportune.engine.poset import Poset, bits
from test_engine_count import brute
from test_engine_count_scans import random_poset


def sparse_order(n: int, k: float, seed: int) -> Poset:
    """linext's random sparse orders: a random permutation, each pair joined with probability k / (n - 1)."""
    return random_poset(random.Random(seed), n, k / max(1, n - 1))


def brute_count(p: Poset, mask: int) -> int:
    return brute(p, mask)[0]


@st.composite
def posets(draw, max_n=8):
    n = draw(st.integers(0, max_n))
    perm = draw(st.permutations(range(n)))
    cand = [(perm[i], perm[j]) for i in range(n) for j in range(i + 1, n)]
    pairs = draw(st.lists(st.sampled_from(cand), max_size=3 * n)) if cand else []
    return Poset.from_pairs(n, pairs)


def chosen(p: Poset, *, dp_cost: float | None = None, **budget) -> Counter:
    """A counter that chooses a method for every piece at once (probe of one new entry)."""
    c = Counter(p, **budget)
    c.probe = 0
    return c


METHODS = [None, 0.0, float("inf")]      # _DP_COST: as shipped, the DP whenever it is known, never the DP


@settings(max_examples=250, deadline=None)
@given(posets(), st.integers(0, 255), st.sampled_from(METHODS))
def test_chosen_methods_match_brute_force(p, mask, dp_cost):
    mask &= p.full
    expect = brute_count(p, mask)
    with patch.object(count_module, "_DP_COST", count_module._DP_COST if dp_cost is None else dp_cost):
        c = chosen(p)
        assert c.count(mask) == expect
        assert c.cached(mask) == expect or mask & (mask - 1) == 0
        # then the rest of what a simulation asks, from the same memo
        s = mask
        while s:
            x = p.minimal(s) & -p.minimal(s)
            assert c.count(s ^ x) == brute_count(p, s ^ x)
            s ^= x
    assert Counter(p).count(mask) == expect == count_by_downsets(p, mask)


@settings(max_examples=60, deadline=None)
@given(st.integers(12, 26), st.sampled_from([1.5, 3, 5]), st.integers(0, 10_000), st.sampled_from(METHODS))
def test_chosen_methods_match_plain_counter_on_sparse_orders(n, k, seed, dp_cost):
    p = sparse_order(n, k, seed)
    plain = Counter(p)
    plain.probe = 1 << 60                # never leaves the plain recursion
    expect = plain.count()
    with patch.object(count_module, "_DP_COST", count_module._DP_COST if dp_cost is None else dp_cost):
        c = chosen(p)
        assert c.count() == expect
    hard = len(Counter(p)._hard_pieces(p.full))              # connected pieces without a cut element
    assert sum(c.methods.values()) == hard                   # each finished by one method
    if dp_cost == 0.0:
        assert c.methods.get("downsets", 0) == hard
    if dp_cost == float("inf"):
        assert not c.methods.get("downsets")
    # sets of either direction in one memo: every later question is still exact
    rng = random.Random(seed)
    s = p.full
    while s.bit_count() > 1:
        assert c.count(s) == plain.count(s)
        s ^= 1 << rng.choice(list(bits(p.minimal(s))))
    assert c.position_sums() == plain.position_sums()
    if n <= 18:
        assert expect == count_by_downsets(p)


def test_both_directions_and_the_dp_on_the_hard_family():
    """Orders of the benchmark family small enough to finish in a test: every method agrees."""
    for n, k, seed in [(30, 3, 1), (30, 5, 2), (34, 3, 7)]:
        p = sparse_order(n, k, seed)
        plain = Counter(p, max_memo=None)
        plain.probe = 1 << 60
        expect = plain.count()
        assert Counter(p.dual(), max_memo=None).count() == expect
        assert upset_counts(p)[0] == expect
        assert Counter(p, max_memo=None).count() == expect       # as shipped: probe, then per piece
        for cost in (0.0, float("inf")):
            with patch.object(count_module, "_DP_COST", cost):
                assert chosen(p, max_memo=None).count() == expect


def test_disconnected_mask_chooses_per_piece():
    """Two hard pieces side by side: each is finished by its own method; the whole is their interleavings."""
    a = sparse_order(18, 3, 4)
    b = sparse_order(16, 5, 9)
    n = a.n + b.n
    pairs = a.cover_pairs() + [(x + a.n, y + a.n) for x, y in b.cover_pairs()]
    p = Poset.from_pairs(n, pairs)
    c = chosen(p)
    ea, eb = Counter(a).count(), Counter(b).count()
    from math import comb

    assert c.count() == comb(n, a.n) * ea * eb
    assert sum(c.methods.values()) == 2
    assert c.cached((1 << a.n) - 1) == ea and c.cached(p.full ^ ((1 << a.n) - 1)) == eb


def test_upset_counts_and_bounded_downset_count():
    rng = random.Random(3)
    for trial in range(150):
        p = sparse_order(rng.randrange(1, 13), rng.choice([1, 2, 3, 5]), trial)
        mask = rng.getrandbits(p.n)
        assert count_downsets_bounded(p, mask) == count_downsets(p, mask)
        value, top = upset_counts(p, mask, keep=2)
        c = Counter(p)
        assert value == count_by_downsets(p, mask) == c.count(mask)
        sizes = {u.bit_count() for u in top}
        assert not top or max(sizes) == mask.bit_count() and min(sizes) >= mask.bit_count() - 2
        for u, v in top.items():
            assert u & ~mask == 0 and all(p.above[x] & mask & ~u == 0 for x in bits(u))   # an up-set of mask
            assert c.count(u) == v
    # bounded: gives up rather than working long; the deadline and the set budget stop the DP
    wide = sparse_order(60, 2, 1)
    assert count_downsets_bounded(wide, limit=5) is None
    assert upset_counts(wide, deadline=time.perf_counter() - 1) is None
    assert upset_counts(sparse_order(30, 3, 1), max_sets=100) is None


def test_memo_budget_is_kept_across_methods():
    p = sparse_order(34, 3, 7)
    expect = Counter(p, max_memo=None).count()
    # (its count takes about 1,500 entries in the compiled core, 11,000 in Python: 500 a call stops it
    # several times either way)
    c = chosen(p, max_memo=500, max_total=None)
    failures = 0
    while True:
        before = c.memo_size
        try:
            assert c.count() == expect
            break
        except BudgetExceeded as exc:
            assert exc.reason == "memo"
            failures += 1
            assert failures < 500
        assert c.memo_size - before <= 500           # each call adds at most max_memo entries
    assert failures > 0


def test_tiny_time_limit_on_a_hard_order_returns():
    """A count that cannot finish stops at its time limit: BudgetExceeded from the counter, a marked
    estimate from Schedule.count_result; neither runs on."""
    p = sparse_order(64, 3, 11)
    c = Counter(p, time_limit=0.05)
    with CpuTime() as cpu, pytest.raises(BudgetExceeded) as info:
        c.count()
    assert info.value.reason == "time"
    assert cpu.seconds < 5.0                           # far from the minutes an exact count takes
    # the memo stays valid: a small remaining set is still exact
    s = p.full
    while s.bit_count() > 10:
        s ^= p.minimal(s) & -p.minimal(s)
    c.time_limit = None
    assert c.count(s) == count_by_downsets(p, s)

    from opportune import make_plan
    from opportune.engine import OrderEngine, Schedule

    ids = [f"t{i}" for i in range(p.n)]
    requires: dict[str, list[str]] = {}
    for a, b in p.cover_pairs():
        requires.setdefault(ids[b], []).append(ids[a])
    engine = OrderEngine(make_plan(ids, requires), time_limit=0.05)
    with CpuTime() as cpu:
        result = Schedule(engine).count_result(time_limit=0.5)
    assert cpu.seconds < 10.0
    assert not result.exact and result.method != "exact"


def test_an_estimate_past_a_float_keeps_its_logarithm():
    """Past 1.8e308 sequences (here about 10^360) the estimate's float is inf, but its log10 is kept
    (it used to be inf too, and the command said "about inf admissible sequences")."""
    from opportune import make_plan
    from opportune.engine import OrderEngine, Schedule
    from opportune.engine.schedule import COUNT_MARGIN

    p = sparse_order(240, 3, 5)
    ids = [f"t{i}" for i in range(p.n)]
    requires: dict[str, list[str]] = {}
    for a, b in p.cover_pairs():
        requires.setdefault(ids[b], []).append(ids[a])
    plan = make_plan(ids, requires)
    # an estimate always comes back, on time (CPU time of this process: it holds under load)
    with CpuTime() as cpu:
        result = Schedule(OrderEngine(plan, time_limit=0.05)).count_result(time_limit=1.0)
    assert cpu.seconds <= 0.05 + 1.0 + COUNT_MARGIN
    assert not result.exact
    assert math.isfinite(result.log10) and result.log10 > 308
    assert result.value == math.inf
    # and below the 240! sequences of 240 unrelated steps
    assert result.log10 < math.lgamma(241) / math.log(10)


def test_an_estimate_over_several_strategies_states_the_joint_confidence(monkeypatch):
    """With k inclusion-exclusion terms estimated, each term is estimated at confidence 1 - 0.05/k
    and the sum's stated confidence is the union bound 1 - sum of the terms' misses (not the smallest
    term confidence, which would overstate it)."""
    import opportune.engine.estimate as estimate_module
    from opportune import make_plan
    from opportune.engine import OrderEngine, Schedule

    p = sparse_order(64, 3, 11)
    ids = [f"t{i}" for i in range(p.n)]
    base: dict[str, list[str]] = {}
    for a, b in p.cover_pairs():
        base.setdefault(ids[b], []).append(ids[a])
    other = {k: list(v) for k, v in base.items()}
    free = next((a, b) for a in range(p.n) for b in range(p.n) if a != b and not p.comparable(a, b))
    other.setdefault(ids[free[1]], []).append(ids[free[0]])
    plan = make_plan(ids, strategies={"a": base, "b": other})
    asked = []
    real = estimate_module.estimate_count

    def spy(*args, **kwargs):
        asked.append(kwargs["confidence"])
        return real(*args, **kwargs)

    monkeypatch.setattr(estimate_module, "estimate_count", spy)
    result = Schedule(OrderEngine(plan, time_limit=0.05)).count_result(time_limit=1.0)
    assert not result.exact
    assert len(asked) == 3 and all(abs(c - (1 - 0.05 / 3)) < 1e-12 for c in asked)
    assert abs(result.confidence - 0.95) < 1e-9
