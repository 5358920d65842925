"""The uniform bin's optimum: the looks as order statistics against brute force (every set of visible
units enumerated), the compiled programme (src/native/optimal.cpp, CompiledOptimalSolver) against the
Python one bit for bit, its sizing before it starts, its caps, and the look-ahead deciding by it on
plans past 16 units whenever it fits."""

from __future__ import annotations

import random
from itertools import combinations
from math import comb

import pytest
from conftest import random_plans
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from opportune import Sequencer, make_plan
from opportune.engine import OrderEngine
from opportune.engine.deadline import Deadline
from opportune.planning.costs import TimeModel
from opportune.policies.lookahead import Lookahead
from opportune.policies.optimal import (
    CompiledOptimalSolver,
    OptimalSolver,
    OptimalTooLarge,
    OutOfTime,
    compiled_optimal_available,
    optimal_solver,
    optimum_bytes,
)
from opportune.policies.states import estimate_states

CAPACITIES = (0, 1, 2, 3, None)
compiled = pytest.mark.skipif(not compiled_optimal_available(OrderEngine(make_plan(["a"], {}))),
                              reason="the compiled core is not built")


def _costs(plan, seed: int) -> TimeModel:
    rng = random.Random(seed)
    return TimeModel(shake=rng.choice([0.5, 1.0, 2.7]), look=rng.choice([0.0, 0.3]),
                     parts={p.id: rng.choice([1.0, 1.7, 0.35]) for p in plan.parts})


def brute_force(solver: OptimalSolver) -> float:
    """The optimum at the start with every set of visible units enumerated (units told apart, each set
    equally likely), the shake loop solved over them: no order statistics, no look distribution."""
    memo: dict = {}
    c_look, c_shake = solver.costs.look, solver.costs.shake

    def value(key) -> float:
        if key[0] == solver.engine.full:
            return 0.0
        if key in memo:
            return memo[key]
        units = [i for i, c in enumerate(solver._bin_counts(key)) for _ in range(c)]
        k = min(solver.visible, len(units))
        looks = list(combinations(range(len(units)), k))
        best = sorted(min((c + value(nxt) for c, nxt, _ in solver._moves(key, tuple(sorted(units[j] for j in seen)))),
                          default=float("inf")) for seen in looks)
        v, acted = float("inf"), 0
        for m in best:
            if m == float("inf"):
                break
            acted += 1
            p = acted / len(looks)
            v = min(v, (c_look + sum(best[:acted]) / len(looks) + (1 - p) * c_shake) / p)
        memo[key] = v
        return v

    return value(solver.start_key())


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=4, max_units=6, max_strategies=2), seed=st.integers(0, 1000))
def test_the_order_statistics_are_the_enumerated_looks(plan, seed):
    """The Python programme's looks as order statistics against every visible set enumerated, and against
    the look distribution it enumerated before (kept for a weighted bin), in every setting."""
    engine = OrderEngine(plan)
    costs = _costs(plan, seed)
    for visible in (1, 2, 3):
        for capacity in CAPACITIES:
            solver = OptimalSolver(engine, visible=visible, capacity=capacity, costs=costs)
            assert solver.uniform
            value = solver.value()
            assert value == pytest.approx(brute_force(solver), rel=1e-12), (visible, capacity)
            looks = OptimalSolver(engine, visible=visible, capacity=capacity, costs=costs)
            looks.uniform = False           # the look distribution, enumerated
            assert value == pytest.approx(looks.value(), rel=1e-12)
            assert solver.states == looks.states


def test_the_chances_of_the_best_visible_part_are_those_of_the_draws():
    """C(n − r, k) − C(n − r − c, k) over C(n, k): every k-set of n ranked units counted by its best unit."""
    for n in range(1, 9):
        for k in range(1, n + 1):
            firsts = [min(s) for s in combinations(range(n), k)]
            for r in range(n):
                for c in range(1, n - r + 1):
                    hits = sum(r <= f < r + c for f in firsts)
                    assert hits == comb(n - r, k) - comb(n - r - c, k)


@compiled
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=5, max_units=7, max_strategies=2), seed=st.integers(0, 1000))
def test_the_compiled_optimum_gives_the_same_doubles_as_python(plan, seed):
    """Every setting (1-3 visible; 0, 1, 2, 3 or unlimited buffer locations; one or two strategies; uneven
    costs): the value at the start and after every move of every look there, bit for bit, the same
    number of states, and that number the one counted before the work."""
    engine = OrderEngine(plan)
    costs = _costs(plan, seed)
    for visible in (1, 2, 3):
        for capacity in CAPACITIES:
            check_same_doubles(engine, visible=visible, capacity=capacity, costs=costs)


def check_same_doubles(engine, **settings) -> float:
    """The compiled and the Python programme in ``settings``: the value at the start and after every move of
    every look there bit for bit, the best actions, the same states, and that number the one counted before
    the work.  Returns the value."""
    py, cc = OptimalSolver(engine, **settings), CompiledOptimalSolver(engine, **settings)
    value = py.value()
    assert cc.value() == value, settings
    assert cc.states == py.states == estimate_states(engine, visible=settings["visible"],
                                                     capacity=settings["capacity"]).states
    start = py.start_key()
    for look, _ in py._looks(py._bin_counts(start)):
        assert cc.best_action(start, look) == py.best_action(start, look)
        for _, nxt, _ in py._moves(start, look):
            assert cc._value(nxt) == py._value(nxt)
    return value


@compiled
def test_the_bytes_are_known_before_and_the_caps_hold():
    """The bytes held once reserved are those computed before; the state cap and the deadline stop the
    programme (OptimalTooLarge, OutOfTime), and what it finished stays: a later call ends with the same value."""
    engine = OrderEngine(make_plan([f"p{i}" for i in range(12)], {f"p{i}": [f"p{i - 1}"] for i in range(1, 12, 2)}))
    est = estimate_states(engine, visible=2, capacity=2)
    cc = CompiledOptimalSolver(engine, visible=2, capacity=2)
    cc.reserve(est.states)
    value = cc.value()
    assert cc.states == est.states and cc.bytes == optimum_bytes(est.states, est.keys, compiled=True)
    check_caps(lambda **cap: CompiledOptimalSolver(engine, visible=2, capacity=2, **cap), value, est.states)


def check_caps(make, value: float, states: int) -> None:
    """The state cap and the deadline stop the programme ``make(**cap)`` builds (OptimalTooLarge at half its
    ``states``, OutOfTime), and what it finished stays: a later call ends with ``value``."""
    small = make(max_states=states // 2)
    with pytest.raises(OptimalTooLarge):
        small.value()
    assert 0 < small.states <= states // 2
    late = make()
    late.deadline = Deadline.after(0.0)
    with pytest.raises(OutOfTime):
        late.value()
    late.deadline = None
    assert late.value() == value


def test_the_factory_falls_back_to_python(monkeypatch):
    """Weights out of range, buffer contents past the core's codes, or no compiled core
    (OPPORTUNE_PURE_PYTHON=1): the Python programme; weights that differ are compiled too."""
    from opportune.policies import optimal

    engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
    assert type(optimal_solver(engine, weights={"a": 2.0})) is CompiledOptimalSolver
    assert type(optimal_solver(engine, weights={"a": -1.0})) is OptimalSolver
    assert optimal_solver(engine, weights={"a": 2.0, "b": 2.0, "c": 2.0}).uniform
    # 63 parts of one unit, one before each of the others: 2^63 buffer contents, past the core's 64-bit
    # codes (as 63 parts of no constraint they would be merged: one part of 63 units)
    ids = [f"p{i}" for i in range(63)]
    wide = OrderEngine(make_plan(ids, {p: ids[:i] for i, p in enumerate(ids) if i}))
    assert not compiled_optimal_available(wide) and type(optimal_solver(wide)) is OptimalSolver
    monkeypatch.setattr(optimal, "_native", None)
    assert not compiled_optimal_available(engine)
    assert type(optimal_solver(engine)) is OptimalSolver


def _chains(n: int) -> object:
    """n parts in two chains: few states whatever n (the down-sets are pairs of chain prefixes)."""
    ids = [f"p{i:02d}" for i in range(n)]
    return make_plan(ids, {ids[i]: [ids[i - 2]] for i in range(2, n)}, name=f"chains-{n}")


def test_the_default_policy_decides_by_the_optimum_past_16_units():
    """A 20-part plan of two chains (a few thousand states): the look-ahead decides by the exact optimum
    (no rule on units), says so, and its action is the optimum's."""
    plan = _chains(20)
    settings = dict(visible=2, capacity=2)
    seq = Sequencer(plan, policy=Lookahead(**settings))
    engine = seq.state.schedule.engine
    solver = optimal_solver(engine, **settings)
    look = ("p05", "p01")
    decision = seq.decide(look)
    assert decision.rule == Lookahead.OPTIMAL_RULE and "(the optimum's)" in decision.note
    action, cost = solver.best_action(solver.start_key(), tuple(sorted(plan.index(p) for p in look)))
    assert decision.action == action and f"{cost:.4f}" in decision.note


def test_the_sizing_refuses_before_starting():
    """Over the state cap, or over the bytes the engine grants: the look-ahead's optimum is refused before
    any state is stored, the frontier window decides, and the decision says why."""
    plan = _chains(20)
    over_states = Lookahead(visible=2, capacity=2, max_states=10)     # the base's programme stops soon too
    over_states.COMPILED_STATES = 1_000
    decision = Sequencer(plan, policy=over_states).decide(("p05", "p01"))
    assert decision.rule.startswith("by its frontier window, because its optimum needs"), decision.rule
    assert "states, more than 1,000" in over_states.refusal and not over_states._optimum
    engine = OrderEngine(plan, memory_limit=10_000)     # a programme may hold half: 5,000 bytes
    small = Lookahead(visible=2, capacity=2, max_states=10)
    small.choose_at(engine, 0, engine.all_strategies, (), 2, ("p05", "p01"))
    assert "bytes" in small.refusal and not small._optimum and engine.programmes == {}


@pytest.mark.parametrize("capacity", [1, None])
def test_a_policy_deciding_by_the_optimum_is_worth_the_optimum(capacity):
    """The look-ahead deciding by the optimum: its value taken as the optimum's is its value evaluated look
    by look (every look of every state it reaches asks it), to the last ulps; with another world, or its step
    over slack, it is evaluated look by look."""
    from opportune.policies.evaluate import PolicyEvaluator

    engine = OrderEngine(_chains(8))
    quick = PolicyEvaluator(engine, Lookahead(visible=2, capacity=capacity), visible=2, capacity=capacity)
    value = quick.value()
    assert quick.by_optimum and quick.policy_states == 0
    slow = PolicyEvaluator(engine, Lookahead(visible=2, capacity=capacity), visible=2, capacity=capacity)
    slow.OPTIMUM_SHORTCUT = False
    assert slow.value() == pytest.approx(value, rel=1e-12) and slow.policy_states > 0 and not slow.by_optimum
    other = PolicyEvaluator(engine, Lookahead(visible=1, capacity=capacity), visible=2, capacity=capacity)
    step = PolicyEvaluator(engine, Lookahead(visible=2, capacity=capacity, optimal=False), visible=2, capacity=capacity)
    assert other.value() >= value - 1e-12 and step.value() >= value - 1e-12
    assert not other.by_optimum and not step.by_optimum
