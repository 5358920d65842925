"""The weighted bin's frontier window (policies/weighted_window.py, the others' group in src/native/optimal.cpp),
the default policy's fallback in a weighted bin where its optimum does not fit: the compiled programme against
the Python one (the same doubles, others or not), the window over the whole plan against the weighted optimum
(the same doubles and decisions), the lumped others against a plan with an explicit part in their place, and
the default's decisions by it with its work counted and bounded."""

from __future__ import annotations

import random

import pytest
from conftest import random_plans
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from opportune import Sequencer, load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.planning.costs import TimeModel
from opportune.policies.lookahead import Lookahead
from opportune.policies.optimal import optimal_solver
from opportune.policies.weighted_window import (
    CompiledWeightedWindowSolver,
    WeightedWindow,
    WeightedWindowSolver,
    weighted_window_available,
)

pytestmark = pytest.mark.skipif(not weighted_window_available(OrderEngine(make_plan(["a"], {})), 2),
                                reason="the compiled core is not built")
SETTINGS = ((1, 1), (2, 2), (3, 1), (2, None))      # (visible, buffer locations)


def _world(plan, rng: random.Random):
    costs = TimeModel(shake=rng.choice([0.5, 1.0, 2.7]), look=rng.choice([0.0, 0.3]),
                      parts={p.id: rng.choice([1.0, 1.7, 0.35]) for p in plan.parts})
    return costs, {p.id: rng.choice([0.5, 1.0, 2.0, 3.5]) for p in plan.parts}


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=4, max_units=6, max_strategies=2), seed=st.integers(0, 1000),
       others=st.integers(0, 4))
def test_the_compiled_window_gives_the_same_doubles_as_python(plan, seed, others):
    """Every setting, with and without others (bufferable or not, of their own weight): the value at the
    start and after every move there, bit for bit, and the same number of stored values."""
    rng = random.Random(seed)
    engine, (costs, weights) = OrderEngine(plan), _world(plan, rng)
    other_move, other_weight = rng.choice([0.8, 1.0, float("inf")]), rng.choice([0.7, 1.0, 2.5])
    for visible, capacity in SETTINGS:
        kw = dict(visible=visible, capacity=capacity, costs=costs, weights=weights, others=others,
                  other_move=other_move, other_weight=other_weight)
        py, cc = WeightedWindowSolver(engine, **kw), CompiledWeightedWindowSolver(engine, **kw)
        start = py.start_key()
        assert cc.value(start) == py.value(start), (visible, capacity)
        assert cc.states == py.states
        for look, _ in py._looks(py._bin_counts(start)):
            for _, nxt, _ in py._moves(start, tuple(i for i in look if i < len(plan.parts))):
                assert cc._value(nxt) == py._value(nxt)


def _walk(engine, rng: random.Random, moves: int):
    """A state a few random legal moves in (installs, and at most one part buffered)."""
    plan, mask, cons, buffer = engine.plan, 0, engine.all_strategies, ()
    for _ in range(moves):
        left = [i for i in range(len(plan.parts)) if engine.next_unit(mask, i) is not None
                and plan.parts[i].id not in buffer]
        if not left:
            break
        i = rng.choice(left)
        u = engine.next_unit(mask, i)
        after = engine.consistent_after(mask, cons, u)
        if after and rng.random() < 0.7:
            mask, cons = mask | 1 << u, after
        elif not buffer:
            buffer = (plan.parts[i].id,)
    return mask, cons, buffer


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=5, max_units=7, max_strategies=3), seed=st.integers(0, 1000))
def test_a_window_over_the_whole_plan_is_the_weighted_optimum_to_the_last_bit(plan, seed):
    """Several strategies and quantities, costs and weights per part, at the start and a few moves in: the
    window's value is the weighted optimum's, the same doubles, and its action on every look is the optimum's."""
    rng = random.Random(seed)
    engine, (costs, weights) = OrderEngine(plan), _world(plan, rng)
    visible, capacity = rng.choice(SETTINGS)
    mask, cons, buffer = _walk(engine, rng, rng.randint(0, 3))
    if mask == engine.full or len(set(weights.values())) == 1:
        return
    optimum = optimal_solver(engine, merge=False, visible=visible, capacity=capacity, costs=costs, weights=weights)
    window = WeightedWindow(visible=visible, capacity=capacity, costs=costs, weights=weights, sizes=(64,),
                            max_states=10**6)
    table = window.table(engine, mask, cons, buffer)
    assert table.outside == 0
    key = optimum.policy_key(mask, cons, buffer)
    assert table.values[-1] == optimum.value(key)
    for look, _ in optimum._looks(optimum._bin_counts(key)):
        ours = window.choose_at(engine, mask, cons, buffer, 0, tuple(plan.parts[i].id for i in look))
        assert ours == optimum.best_action(key, look)[0], look


@pytest.mark.parametrize("seed", range(8))
def test_lumped_others_are_a_part_after_the_window(seed):
    """The window's weighted programme with ``others`` lumped units of one weight is the weighted optimum of
    the plan with a part of that many units and that weight required after every other part, less what those
    units cost after the window (each a look and a move)."""
    rng = random.Random(seed)
    ids = [f"p{i}" for i in range(rng.randint(2, 5))]
    requires = {b: [a for a in ids[:j] if rng.random() < 0.35] for j, b in enumerate(ids)}
    others, (visible, capacity) = rng.randint(1, 4), rng.choice(SETTINGS)
    costs = TimeModel(look=rng.choice([0.0, 0.25]), shake=rng.choice([1.0, 1.6]))
    weights = {p: rng.choice([0.5, 1.0, 2.0]) for p in ids} | {"_rest": rng.choice([0.7, 1.5])}
    explicit = make_plan(ids + [{"id": "_rest", "quantity": others}], {**requires, "_rest": ids})
    whole = optimal_solver(OrderEngine(explicit), merge=False, visible=visible, capacity=capacity, costs=costs,
                           weights=weights)
    lumped = CompiledWeightedWindowSolver(OrderEngine(make_plan(ids, requires)), visible=visible, capacity=capacity,
                                          costs=costs, weights=weights, others=others, other_move=costs.move("_rest"),
                                          other_weight=weights["_rest"])
    assert lumped.value() + others * (costs.look + costs.move("_rest")) == pytest.approx(whole.value(), rel=1e-12)
    assert lumped.states < whole.states      # the lumped units are not in the masks


def test_the_default_decides_by_the_weighted_window_with_its_work_counted_and_bounded():
    """KILBRID (45 parts) in a weighted bin with the optimum switched off: the weighted window decides,
    deterministically, its states within its cap."""
    plan = load_plan("salbp:KILBRID")
    weights = {p: 1.0 + (i % 3) for i, p in enumerate(plan.part_ids)}
    engine, runs = OrderEngine(plan), []
    for _ in range(2):
        policy = Lookahead(visible=2, capacity=2, weights=weights, optimal=False)
        runs.append([policy.choose_at(engine, 0, engine.all_strategies, (), 2, look)
                     for look in (("1", "2"), ("3", "1"), ("2", "7"), ("9", "12"))])
        assert isinstance(policy.window, WeightedWindow)
        work = policy.window.work
        assert work["windows"] > 0 and work["by_base"] == 0
        assert work["most_states"] <= policy.window.max_states
    assert runs[0] == runs[1]
    seq = Sequencer(plan, policy=Lookahead(visible=2, capacity=2, weights=weights, optimal=False))
    rule = seq.decide(["1", "2"]).rule
    assert "frontier window" in rule and "weighted" in rule, rule
