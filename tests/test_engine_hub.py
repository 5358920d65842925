"""Counting through a hub: tail distributions and the hub formula against brute force and the plain counter."""

from __future__ import annotations

import math
import random
import time
from itertools import permutations

import pytest
from hypothesis import given, settings, strategies as st

from opportune.engine.count import BudgetExceeded, Counter
from opportune.engine.estimate import estimate_count
from opportune.engine.hub import TailCounter, hub_candidates, hub_count, hub_split
from opportune.engine.poset import Poset, bits
from conftest import CpuTime, salbp_poset


def brute_tail(poset: Poset, s: int, marks: int) -> list[int]:
    """Linear extensions of ``s`` by the number of elements after the last marked one, by enumeration."""
    members = list(bits(s))
    out = [0] * len(members)
    for perm in permutations(members):
        seen = 0
        for x in perm:
            if poset.below[x] & s & ~seen:
                break
            seen |= 1 << x
        else:
            last = max(i for i, x in enumerate(perm) if marks >> x & 1)
            out[len(members) - 1 - last] += 1
    return out


@st.composite
def marked_posets(draw, max_n=7):
    n = draw(st.integers(1, max_n))
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if draw(st.booleans()) and draw(st.booleans())]
    perm = draw(st.permutations(range(n)))          # labels in any order, not only topological
    poset = Poset.from_pairs(n, [(perm[a], perm[b]) for a, b in pairs])
    s = draw(st.integers(1, poset.full)) | 1 << perm[0]
    marks = draw(st.integers(1, poset.full)) & s or 1 << perm[0]
    return poset, s, marks


@settings(max_examples=250, deadline=None)
@given(marked_posets())
def test_tail_distribution_equals_enumeration(case):
    poset, s, marks = case
    tail = TailCounter(Counter(poset), marks).tail(s)
    assert tail == brute_tail(poset, s, marks)
    assert sum(tail) == Counter(poset).count(s)


@settings(max_examples=150, deadline=None)
@given(st.integers(3, 22), st.sampled_from([0.1, 0.2, 0.4]), st.sampled_from([0, 2, 4]), st.integers(1, 5),
       st.randoms(use_true_random=False))
def test_the_first_hub_candidates_are_the_head_of_the_whole_list(n, density, max_coupling, limit, rng):
    """Asking for the first few candidates (as a decision does, to stop early) gives the head of the list."""
    poset = Poset.from_pairs(n, [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < density])
    whole = hub_candidates(poset, poset.full, max_coupling=max_coupling)
    assert hub_candidates(poset, poset.full, max_coupling=max_coupling, limit=limit) == whole[:limit]


def test_a_hub_search_past_its_deadline_stops():
    poset = salbp_poset("ARC111")
    with pytest.raises(BudgetExceeded):
        hub_candidates(poset, poset.full, deadline=time.perf_counter() - 1)


def test_tails_on_a_large_order_start_at_once():
    """The Python tails of a large order (past the compiled core's 256 elements) build only the rows of
    Pascal's triangle they merge with: the whole triangle of 2,400 elements (a hub path of a 1,200-step
    plan) took about a minute, with no deadline, inside one budgeted decision."""
    n = 1_200
    pairs = [(i, i + 1) for i in range(0, n - 1, 2)]           # 600 independent pairs
    poset = Poset.from_pairs(n, pairs)
    s = (1 << 9) - 1                                          # 0<1, 2<3, 4<5, 6<7 and 8
    marks = 0b000000110                                       # 1 and 2
    with CpuTime() as cpu:
        tails = TailCounter(Counter(poset), marks, deadline=time.perf_counter() + 60.0)
        assert tails.tail(s) == brute_tail(poset, s, marks)
    assert cpu.seconds < 5.0


def hub_shaped(rng: random.Random, below_n: int, free_n: int, above_n: int, coupling: int) -> tuple[Poset, int]:
    """A random order built around a hub: parts below it, parts unrelated to it, parts above it, and a few
    relations from unrelated parts into the part above (the coupling the inclusion–exclusion removes)."""
    n = below_n + free_n + above_n + 1
    h = below_n
    low = list(range(below_n))
    free = list(range(below_n + 1, below_n + 1 + free_n))
    high = list(range(below_n + 1 + free_n, n))
    pairs = [(a, b) for i, a in enumerate(low) for b in low[i + 1:] if rng.random() < 0.25]
    pairs += [(a, h) for a in low if rng.random() < 0.7] or [(low[-1], h)]
    pairs += [(h, b) for b in high if rng.random() < 0.6] or [(h, high[0])]
    pairs += [(a, b) for i, a in enumerate(high) for b in high[i + 1:] if rng.random() < 0.3]
    pairs += [(a, b) for a in low for b in free if rng.random() < 0.2]
    pairs += [(a, b) for i, a in enumerate(free) for b in free[i + 1:] if rng.random() < 0.2]
    for _ in range(coupling if free else 0):
        pairs.append((rng.choice(free), rng.choice(high)))
    poset = Poset.from_pairs(n, pairs)
    return poset, h


def test_hub_count_equals_plain_counter_on_hub_shaped_orders():
    """Every candidate the hub formula accepts gives the plain counter's count, coupling or not."""
    rng = random.Random(11)
    solved = coupled = 0
    for trial in range(150):
        poset, _ = hub_shaped(rng, rng.randint(2, 7), rng.randint(0, 6), rng.randint(1, 5), rng.randint(0, 3))
        exact = Counter(poset).count()
        for h, coupling in hub_candidates(poset, poset.full)[:4]:
            value = hub_count(Counter(poset), poset.full, h, coupling)
            if value is not None:
                assert value == exact, (trial, h, coupling)
                solved += 1
                coupled += bool(coupling)
        assert hub_split(Counter(poset), poset.full, time_limit=10) in (None, exact)
    assert solved > 150 and coupled > 40          # the test exercised the formula and the inclusion–exclusion


@settings(max_examples=120, deadline=None)
@given(marked_posets(max_n=8))
def test_hub_count_on_arbitrary_orders(case):
    poset = case[0]
    exact = Counter(poset).count()
    for h, coupling in hub_candidates(poset, poset.full):
        assert hub_count(Counter(poset), poset.full, h, coupling) in (None, exact)


def test_twin_couplings_are_counted_once_and_right():
    """Two interchangeable parts both needed by a part above the hub (ARC111's tasks 88 and 89)."""
    # 0, 1 < hub 2 < 3 < 4;  0 < 5, 6 (twins);  5, 6 < 4
    poset = Poset.from_pairs(7, [(0, 2), (1, 2), (2, 3), (3, 4), (0, 5), (0, 6), (5, 4), (6, 4)])
    (h, coupling), *_ = [c for c in hub_candidates(poset, poset.full) if c[0] == 2]
    assert sorted(coupling) == [(5, 4), (6, 4)]
    assert hub_count(Counter(poset), poset.full, 2, coupling) == Counter(poset).count()


def test_arc111_exact_through_its_hub():
    """ARC111 (111 tasks) is exact through task 91 (index 90); the plain counter cannot finish it, and the
    independent Monte Carlo estimator (no hub) agrees within its own stated error."""
    p = salbp_poset("ARC111")
    exact = estimate_count(p, time_limit=120)
    assert exact.method == "exact" and exact.exact is not None
    assert abs(math.log10(exact.exact) - 103.0294) < 1e-3
    smc = estimate_count(p, exact_memo=0, hub=0, time_limit=0.0, seed=5)
    assert smc.method == "smc" and smc.samples == 2
    assert abs(smc.value / exact.exact - 1) <= max(smc.rel_error, 0.5)


def test_schedule_count_result_is_exact_through_a_hub_when_the_plain_budget_is_too_small(monkeypatch):
    """The path `opportune count` takes: a plain count over budget, then the hub split gives an exact int."""
    from opportune.engine import OrderEngine, Schedule
    from opportune.engine import estimate

    splits = []

    def recording_split(*args, **kwargs):
        splits.append(hub_split(*args, **kwargs))
        return splits[-1]

    monkeypatch.setattr(estimate, "hub_split", recording_split)
    from opportune import make_plan

    rng = random.Random(3)
    poset, h = hub_shaped(rng, 8, 6, 5, 2)
    ids = [f"t{i}" for i in range(poset.n)]
    requires = {ids[b]: [ids[a] for a in bits(poset.below[b])] for b in range(poset.n)}
    plan = make_plan(ids, requires)
    exact = Counter(poset).count()
    sched = Schedule(OrderEngine(plan, max_memo=5))
    result = sched.count_result(time_limit=30)
    assert result.exact and result.value == exact and isinstance(result.value, int)
    assert splits and all(v is not None for v in splits)      # it was the hub split that made it exact


def test_count_result_gives_the_plain_count_turns_of_a_fixed_length_whatever_the_limit(monkeypatch):
    """The plain count's first turn is FIRST_TURN seconds, with any time limit and any time limit of the
    engine (it used to be a tenth of the limit: a plan that its hub counts at once waited for it, longer
    the longer the limit), and no count's time limit is left changed."""
    from opportune import make_plan
    from opportune.engine import OrderEngine, Schedule, phases
    from opportune.engine.schedule import FIRST_TURN

    plan = make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["b", "c"]})
    turns = []
    real = phases._exact_by

    def recording(schedule, terms, remaining, until, plain_only):
        turns.append((plain_only, until - time.perf_counter()))
        return real(schedule, terms, remaining, until, plain_only)

    monkeypatch.setattr(phases, "_exact_by", recording)
    for limit, engine_limit in ((10, None), (100, None), (10, 4.0)):
        engine = OrderEngine(plan, time_limit=engine_limit)
        turns.clear()
        assert Schedule(engine).count_result(time_limit=limit).value == 3
        assert len(turns) == 1 and turns[0][0] and FIRST_TURN - 0.01 <= turns[0][1] <= FIRST_TURN
        assert engine.time_limit == engine_limit
        assert engine.counter(engine.all_strategies).time_limit == engine_limit
