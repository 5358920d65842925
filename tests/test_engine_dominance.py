"""Comparisons the order alone settles (engine/dominance.py) agree with exact counts, and the compiled
Markov chains make the same moves as the pure-Python ones."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import random_plans
from test_engine_count_scans import random_poset, up_sets
from opportune.engine import OrderEngine, native
from opportune.engine.count import Counter
from opportune.engine.dominance import earliest_by_order, most_options_by_order
from opportune.engine.poset import bits
from opportune.engine.sampling import CompletionChains
from opportune.policies.opportunistic import choose_exact


def _cases(seed: int, n_max: int = 9):
    rng = random.Random(seed)
    poset = random_poset(rng, rng.randint(2, n_max), rng.choice([0.1, 0.25, 0.4]))
    for remaining in up_sets(rng, poset, 3):
        units = list(bits(remaining))
        if len(units) >= 2:
            yield rng, poset, remaining, units


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2**32))
def test_most_options_by_order_names_exactly_the_best_candidates(seed):
    """When the order settles it, the units returned are exactly those that keep the most completions."""
    for rng, poset, remaining, units in _cases(seed):
        counter = Counter(poset)
        minimal = [u for u in units if not poset.below[u] & remaining]
        if len(minimal) < 2:
            continue
        cands = rng.sample(minimal, rng.randint(2, len(minimal)))
        got = most_options_by_order(poset, remaining, cands)
        if got is not None:
            kept = {u: counter.count(remaining & ~(1 << u)) for u in cands}
            assert sorted(got) == sorted(u for u in cands if kept[u] == max(kept.values()))


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2**32))
def test_earliest_by_order_names_exactly_the_least_expected_positions(seed):
    """When the order settles it, the units returned are exactly those with the least expected position."""
    for rng, poset, remaining, units in _cases(seed):
        sums = Counter(poset).position_sums(remaining)
        cands = rng.sample(units, rng.randint(2, min(4, len(units))))
        got = earliest_by_order(poset, remaining, cands)
        if got is not None:
            assert sorted(got) == sorted(u for u in cands if sums[u] == min(sums[v] for v in cands))


def test_the_order_settles_a_good_share_of_comparisons():
    """Not vacuous: on random orders the functions answer often (and the tests above then check them)."""
    answered = asked = 0
    for seed in range(60):
        for rng, poset, remaining, units in _cases(seed):
            asked += 1
            answered += earliest_by_order(poset, remaining, units[:2]) is not None
    assert asked > 100 and answered > 0.3 * asked, (answered, asked)


@settings(max_examples=40, deadline=None)
@given(random_plans(max_parts=7, max_units=8), st.integers(0, 2**16))
def test_the_rule_decides_the_same_with_and_without_the_order_shortcut(plan, seed):
    """choose_exact settles what the order settles without counting; counting everything agrees."""
    rng = random.Random(seed)
    engine = OrderEngine(plan)
    mask, cons = 0, engine.all_strategies
    while mask != engine.full:
        left = [p for p in plan.part_ids if engine.next_unit(mask, plan.index(p)) is not None]
        look = tuple(rng.sample(left, min(len(left), rng.randint(1, 3))))
        buffer = tuple(rng.sample(left, rng.randint(0, min(2, len(left)))))
        for free in (0, 1):
            assert (choose_exact(engine, mask, cons, buffer, free, look)
                    == choose_exact(engine, mask, cons, buffer, free, look, order_first=False))
        units = engine.installable_units(mask, cons)
        u = rng.choice(list(bits(units)))
        mask, cons = mask | 1 << u, engine.consistent_after(mask, cons, u)


@pytest.mark.skipif(not native.available(), reason="the compiled core is not built")
@pytest.mark.parametrize("seed", range(6))
def test_compiled_and_pure_python_chains_make_the_same_moves(seed, monkeypatch):
    """Same seed, same sequences and same estimates, through installations, on both paths."""
    rng = random.Random(seed)
    poset = random_poset(rng, rng.randint(5, 40), rng.choice([0.05, 0.15, 0.3]))

    def follow(core):
        monkeypatch.setattr(native, "_native", core)
        chains = CompletionChains(poset, poset.full, chains=4, seed=seed)
        left, out = poset.full, []
        pick = random.Random(seed + 1)
        while left:
            chains.run(50)
            minimal = [u for u in bits(left) if not poset.below[u] & left]
            est = chains.estimate(first=minimal, positions=list(bits(left))[:3], steps=40, samples=4)
            out.append(([list(o) for o in chains.orders], est.first, est.positions))
            left &= ~(1 << pick.choice(minimal))
            chains.advance(left)
        return out

    core = native._native
    assert follow(core) == follow(None)


@pytest.mark.skipif(not native.available(), reason="the compiled core is not built")
@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32))
def test_chains_start_from_admissible_sequences_alike_compiled_and_not(seed):
    """A population's starting sequences are admissible sequences of the steps left (each step after its
    predecessors, every step once), and the compiled start draws exactly the pure-Python one's."""
    from opportune.engine import sampling

    core = native._native
    for _, poset, remaining, units in _cases(seed, n_max=14):
        starts = []
        for use in (core, None):
            with pytest.MonkeyPatch.context() as mp:
                mp.setattr(native, "_native", use)
                mp.setattr(sampling, "_starts", type(sampling._starts)())   # nothing kept: drawn afresh
                chains = CompletionChains(poset, remaining, chains=3, seed=seed)
                starts.append([list(o) for o in chains.orders])
        assert starts[0] == starts[1]
        for order in starts[0]:
            assert sorted(order) == units
            placed = 0
            for u in order:
                assert not poset.below[u] & remaining & ~placed, "a step before one of its predecessors"
                placed |= 1 << u
