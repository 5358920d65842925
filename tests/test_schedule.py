"""The schedule against brute-force enumeration: counts, installable parts, options, positions, sampling."""

from __future__ import annotations

import itertools
import json
from collections import Counter as Tally
from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import GEARBOX, brute_sequences, multiset_permutations, random_plans, respects
from opportune import load_plan, make_plan
from opportune.engine import NotAdmissible, OrderEngine, Schedule


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 3), max_size=7))
def test_the_brute_force_makes_every_distinct_ordering_once_in_order(items):
    """The references below rest on it: the orderings of a multiset, against every permutation deduplicated."""
    assert list(multiset_permutations(items)) == sorted(set(itertools.permutations(items)))


@settings(max_examples=100, deadline=None)
@given(random_plans(max_parts=5, max_units=6))
def test_brute_sequences_are_the_orderings_that_respect_a_strategy(plan):
    units = [p.id for p in plan.parts for _ in range(p.quantity)]
    every = set(itertools.permutations(units))
    admissible = [s for s in every if any(respects(s, strategy) for strategy in plan.strategies)]
    assert brute_sequences(plan) == sorted(admissible)


@st.composite
def plans_with_prefix(draw):
    plan = draw(random_plans(max_parts=6, max_units=8, max_strategies=3))
    full = brute_sequences(plan)
    seq = full[draw(st.integers(0, len(full) - 1))]
    cut = draw(st.integers(0, len(seq)))
    return plan, seq[:cut]


@settings(max_examples=200, deadline=None)
@given(plans_with_prefix())
def test_schedule_matches_brute_force(case):
    plan, prefix = case
    sched = Schedule(plan, prefix)
    completions = brute_sequences(plan, prefix)
    total = len(completions)
    assert sched.count() == total
    firsts = Tally(c[0] for c in completions if c)
    assert set(sched.installable()) == set(firsts)
    assert sched.options() == {p: firsts[p] for p in sched.installable()}
    assert list(sched.options()) == [p for p in plan.part_ids if p in firsts]  # declaration order
    assert sched.next_probabilities() == {p: Fraction(firsts[p], total) for p in firsts}
    positions = sched.expected_positions()
    assert set(positions) == set(sched.remaining)
    for part, value in positions.items():
        assert value == Fraction(sum(c.index(part) + 1 for c in completions), total)
    # Strategies still consistent: those under which the prefix can still be completed.
    from conftest import respects

    alive = {s.name for s in plan.strategies
             if any(respects(tuple(prefix) + c, s) for c in completions)} if completions else set()
    assert set(sched.consistent_strategies) == alive


@settings(max_examples=100, deadline=None)
@given(random_plans(max_parts=5, max_units=6))
def test_completions_lists_exactly_the_admissible_sequences(plan):
    assert sorted(Schedule(plan).completions()) == sorted(brute_sequences(plan))


def test_gearbox_has_336_sequences():
    assert Schedule(load_plan(GEARBOX)).count() == 336


def test_quantities_do_not_multiply_counts():
    plan = make_plan([{"id": "sc", "quantity": 4}, "co"], {"sc": ["co"]})
    s = Schedule(plan)
    assert s.count() == 1
    assert s.installable() == ("co",)
    s = s.install("co").install("sc")
    assert s.remaining == {"sc": 3}
    plan = make_plan([{"id": "sc", "quantity": 2}, "a"])
    assert Schedule(plan).completions() == [("sc", "sc", "a"), ("sc", "a", "sc"), ("a", "sc", "sc")]


def test_union_counts_shared_sequences_once():
    # a<b and b<a; plus a third strategy with no order: the union is all 2 orders.
    plan = make_plan(["a", "b", "c"], strategies={"x": {"b": ["a"], "c": ["b"]}, "y": {"c": ["a", "b"]}})
    assert Schedule(plan).count() == 2  # x ⊂ y: a b c, b a c
    plan = make_plan(["a", "b"], strategies={"x": {"b": ["a"]}, "y": {"a": ["b"]}})
    s = Schedule(plan)
    assert s.count() == 2
    assert s.install("b").consistent_strategies == ("y",)


def test_install_refuses_with_clear_errors_and_leaves_state():
    s = Schedule(load_plan(GEARBOX))
    with pytest.raises(NotAdmissible, match="'co' cannot be installed yet: it requires"):
        s.install("co")
    with pytest.raises(NotAdmissible, match="unknown part 'zz'"):
        s.install("zz")
    t = s.install("ca")
    with pytest.raises(NotAdmissible, match="already installed"):
        t.install("ca")
    assert s.installed == () and t.installed == ("ca",)


def test_schedules_branch_and_share_the_memo():
    engine = OrderEngine(load_plan(GEARBOX))
    root = Schedule(engine)
    a = root.install("ca").install("ba")
    b = root.install("ca").install("sm")
    assert a.engine is b.engine is root.engine
    assert a.count() + b.count() == root.install("ca").count()


def test_uniform_sampling_chi_square():
    from scipy.stats import chisquare

    plan = make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["b"]})
    s = Schedule(plan)
    seqs = s.completions()
    assert len(seqs) == 6
    import random

    rng = random.Random(12345)
    draws = Tally(tuple(s.sample(rng)) for _ in range(6000))
    assert set(draws) == set(seqs)
    stat, p = chisquare([draws[q] for q in seqs])
    assert p > 0.001, (stat, p, draws)


def test_sampling_is_seeded():
    s = Schedule(load_plan(GEARBOX))
    assert s.sample(7) == s.sample(7)
    assert s.sample(7) != s.sample(8) or s.sample(9) != s.sample(7)


def test_completions_refuse_large_sets():
    with pytest.raises(ValueError, match="limit"):
        Schedule(load_plan(GEARBOX)).completions(limit=100)


def test_count_after_prefix_cli():
    from typer.testing import CliRunner

    from opportune.cli import app

    runner = CliRunner()
    r = runner.invoke(app, ["count", str(GEARBOX), "--after", "ca ba", "--json"])
    doc = json.loads(r.output)
    assert doc["sequences"] == str(Schedule(load_plan(GEARBOX), ["ca", "ba"]).count())
    assert doc["after"] == ["ca", "ba"]
    r = runner.invoke(app, ["count", str(GEARBOX), "--after", "ca,co"])
    assert r.exit_code == 1 and "not admissible" in r.output and "'co' cannot be installed yet" in r.output
    assert "Traceback" not in r.output


@settings(max_examples=100, deadline=None)
@given(plans_with_prefix(), st.data())
def test_options_for_a_few_parts_agree_with_all_options(case, data):
    plan, prefix = case
    engine = OrderEngine(plan)
    ask = data.draw(st.lists(st.sampled_from(plan.part_ids), max_size=4, unique=True))
    few = Schedule(engine, prefix).options_for(ask)  # asked first: computed part by part
    every = Schedule(OrderEngine(plan), prefix).options()
    assert few == {p: every[p] for p in ask if p in every}
