"""The weighted bin's optimum compiled, and interchangeable parts merged.

The compiled programme (src/native/optimal.cpp, CompiledOptimalSolver with weights) against the Python
one bit for bit in every setting; the Python one's looks grouped by their best part against every look
taken one by one (as it was before); the programme on the plan with interchangeable parts merged against
the plan as declared; its memory known before it starts; its caps; the decisions naming the part seen;
and the look-ahead deciding by the optimum on plans of 18 and more units wherever it fits."""

from __future__ import annotations

import random

import pytest
from conftest import random_plans
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_optimal_compiled import _costs, check_caps, check_same_doubles, compiled

from opportune import Sequencer, make_plan
from opportune.engine import OrderEngine
from opportune.planning.costs import TimeModel
from opportune.planning.plan import Plan, Strategy
from opportune.policies import optimal
from opportune.policies.interchangeable import (
    interchangeable_groups,
    merge_interchangeable,
)
from opportune.policies.lookahead import Lookahead
from opportune.policies.optimal import (
    CompiledOptimalSolver,
    MergedOptimalSolver,
    OptimalSolver,
    compiled_optimal_available,
    optimal_solver,
    optimum_bytes,
    optimum_engine,
)
from opportune.policies.states import estimate_states

CAPACITIES = (0, 1, 2, None)


def _weights(plan, rng: random.Random) -> dict[str, float]:
    return {p.id: rng.choice([0.4, 1.0, 1.0, 2.5, 7.0]) for p in plan.parts}


def with_twins(plan: Plan, chosen: list[int], quantities: list[int]) -> Plan:
    """``plan`` with a twin of each chosen part (a part before and after the same parts in every strategy;
    its own quantity): interchangeable parts that are not declared as one part's units."""
    parts = list(plan.parts)
    twins = {}
    for i, q in zip(chosen, quantities):
        original = plan.parts[i % len(plan.parts)]
        twin = f"{original.id}_twin{len(twins)}"
        parts.append(type(original)(id=twin, quantity=q))
        twins.setdefault(original.id, []).append(twin)
    strategies = []
    for s in plan.strategies:
        requires = {a: list(bs) for a, bs in s.requires.items()}
        for a in list(requires):
            requires[a] += [t for b in requires[a] for t in twins.get(b, ())]
        for original, names in twins.items():
            for t in names:
                requires[t] = list(s.requires.get(original, ()))
        strategies.append(Strategy(s.name, {a: tuple(bs) for a, bs in requires.items() if bs}))
    return Plan(plan.name, tuple(parts), tuple(strategies))


@st.composite
def plans_with_twins(draw, max_parts=4, max_units=6):
    plan = draw(random_plans(max_parts=max_parts, max_units=max_units - 2, max_strategies=2))
    n = draw(st.integers(0, 2))
    chosen = draw(st.lists(st.integers(0, 10), min_size=n, max_size=n))
    return with_twins(plan, chosen, draw(st.lists(st.integers(1, 2), min_size=n, max_size=n)))


class PerLook(OptimalSolver):
    """The optimum with every look of a weighted bin taken on its own (the looks sorted by their best
    move, then the shake loop over them): as the Python programme was before it grouped them."""

    def _order_statistics(self, key):
        return sorted((min((c + self._value(nxt) for c, nxt, _ in self._moves(key, look)), default=float("inf")), p)
                      for look, p in self._looks(self._bin_counts(key)))


@compiled
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=plans_with_twins(), seed=st.integers(0, 10_000))
def test_the_compiled_weighted_optimum_gives_the_same_doubles_as_python(plan, seed):
    """Every setting (1-3 visible; 0, 1, 2 or unlimited locations; one or two strategies; quantities up to
    3; uneven costs and weights): the value at the start and after every move of every look there, bit
    for bit, the same states, and that number the one counted before the work; the Python programme's
    looks grouped by their best part within 1e-12 of every look taken on its own."""
    engine = OrderEngine(plan)
    rng = random.Random(seed)
    costs, weights = _costs(plan, seed), _weights(plan, rng)
    for visible in (1, 2, 3):
        for capacity in CAPACITIES:
            value = check_same_doubles(engine, visible=visible, capacity=capacity, costs=costs, weights=weights)
            per_look = PerLook(engine, visible=visible, capacity=capacity, costs=costs, weights=weights)
            assert value == pytest.approx(per_look.value(), rel=1e-12, abs=1e-12)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=plans_with_twins(), seed=st.integers(0, 10_000), weighted=st.booleans())
def test_merging_interchangeable_parts_keeps_the_value(plan, seed, weighted):
    """The optimum on the plan with its interchangeable parts merged (twins, parts of no constraint, ...)
    against the plan as declared, within 1e-12, in every setting and bin; the merged programme compiled
    and in Python the same doubles; never more states; a part merged only with parts no strategy, cost
    or weight tells apart."""
    engine = OrderEngine(plan)
    rng = random.Random(seed)
    costs = _costs(plan, seed)
    weights = _weights(plan, rng) if weighted else None
    merged = merge_interchangeable(engine, costs, weights)
    for group in merged.groups:
        for i in group[1:]:
            a, b = plan.parts[group[0]], plan.parts[i]
            assert costs.move(a.id) == costs.move(b.id) and (weights or {}).get(a.id) == (weights or {}).get(b.id)
            for poset in engine.posets:     # neither before the other, in any strategy
                assert not poset.above[engine.first[group[0]]] >> engine.first[i] & 1
                assert not poset.above[engine.first[i]] >> engine.first[group[0]] & 1
    for visible in (1, 2, 3):
        for capacity in CAPACITIES:
            settings_ = dict(visible=visible, capacity=capacity, costs=costs, weights=weights)
            plain = OptimalSolver(engine, **settings_)
            solver = optimal_solver(engine, **settings_)
            value = solver.value()
            assert value == pytest.approx(plain.value(), rel=1e-12), (visible, capacity)
            assert solver.states <= plain.states
            if merged.reduced:
                inner = dict(settings_, weights=merged.weights(weights))
                python = OptimalSolver(merged.engine, **inner)
                assert isinstance(solver, MergedOptimalSolver) and python.value() == solver.inner.value()
                assert solver.states == python.states == estimate_states(merged.engine, visible=visible,
                                                                         capacity=capacity).states
                start = plain.start_key()
                for look, _ in plain._looks(plain._bin_counts(start)):
                    for _, nxt, _ in plain._moves(start, look):
                        assert solver._value(nxt) == pytest.approx(plain._value(nxt), rel=1e-12)


def test_the_groups_are_those_no_strategy_tells_apart():
    """Parts merged only when every strategy puts the same parts before and after each: a pair one
    strategy orders differently stays apart, as do parts of other costs or weights."""
    plan = Plan("two", tuple(make_plan(["a", "b", "c", "d"], {}).parts), (
        Strategy("s1", {"d": ("a", "b", "c")}),
        Strategy("s2", {"d": ("a", "b"), "c": ("a",)})))
    engine = OrderEngine(plan)
    assert interchangeable_groups(engine) == [[0], [1], [2], [3]]      # s2: c after a, not after b
    assert interchangeable_groups(OrderEngine(make_plan(["a", "b", "c", "d"], {"d": ["a", "b", "c"]}))) == [
        [0, 1, 2], [3]]
    flat = OrderEngine(make_plan(["a", "b", "c"], {}))
    assert interchangeable_groups(flat, TimeModel(parts={"b": 2.0})) == [[0, 2], [1]]
    assert interchangeable_groups(flat, weights={"c": 3.0}) == [[0, 1], [2]]


def test_decisions_name_the_part_seen():
    """Four screws declared as four parts (merged as one part's four units): the optimum installs the
    screw it sees, whichever it is, never the group's first, and the look-ahead says so."""
    plan = make_plan(["s1", "s2", "s3", "s4", "cover"], {"cover": ["s1", "s2", "s3", "s4"]})
    engine = OrderEngine(plan)
    solver = optimal_solver(engine, visible=1, capacity=1)
    assert isinstance(solver, MergedOptimalSolver)
    start = solver.start_key()
    for screw in ("s1", "s2", "s3", "s4"):
        action, _ = solver.best_action(start, (plan.index(screw),))
        assert (action.kind, action.part) == ("install", screw)
    after_s3 = (1 << engine.first[plan.index("s3")], start[1], start[2])
    action, _ = solver.best_action(after_s3, (plan.index("s1"),))
    assert (action.kind, action.part) == ("install", "s1")
    decision = Sequencer(plan, policy=Lookahead(visible=1, capacity=1)).decide(("s4",))
    assert decision.action.part == "s4" and decision.rule == Lookahead.OPTIMAL_RULE


def _layers(width: int, depth: int) -> Plan:
    """``depth`` layers of ``width`` parts, each part after every part of the layer before: the parts of
    a layer are interchangeable."""
    ids = [[f"l{d}p{i}" for i in range(width)] for d in range(depth)]
    return make_plan([p for layer in ids for p in layer],
                     {p: ids[d - 1] for d in range(1, depth) for p in ids[d]}, name=f"layers-{width}x{depth}")


@compiled
def test_the_look_ahead_decides_by_the_merged_optimum_past_16_units():
    """24 parts in 4 layers of 6 interchangeable parts, 2 visible, 2 locations: as declared its optimum
    needs 25,903 states; merged, 201.  With the look-ahead's compiled cap at 1,000 states it decides by the
    exact optimum (sized and built on the merged plan: the states it stored are the 201 counted before),
    and its action is the optimum's on the plan as declared."""
    plan = _layers(6, 4)
    engine = OrderEngine(plan)
    assert engine.n_units == 24
    plain = estimate_states(engine, visible=2, capacity=2).states
    merged = estimate_states(optimum_engine(engine), visible=2, capacity=2).states
    assert plain > 1_000 >= merged
    policy = Lookahead(visible=2, capacity=2, max_states=100)
    policy.COMPILED_STATES = 1_000
    seq = Sequencer(plan, policy=policy)
    decision = seq.decide(("l0p3", "l1p0"))
    assert decision.rule == Lookahead.OPTIMAL_RULE and policy.deciding_rule == Lookahead.OPTIMAL_RULE
    ev = policy._evaluator
    assert isinstance(ev, MergedOptimalSolver) and ev.states == merged
    reference = OptimalSolver(seq.state.schedule.engine, visible=2, capacity=2)
    look = tuple(sorted(plan.index(p) for p in ("l0p3", "l1p0")))
    action, cost = reference.best_action(reference.start_key(), look)
    assert decision.action == action and f"{cost:.4f}" in decision.note


@compiled
def test_the_look_ahead_decides_by_the_weighted_optimum_past_16_units():
    """A 20-part plan of two chains in a weighted bin: the look-ahead decides by the compiled optimum
    (not the Python programme's cap, not the step over slack), storing the states counted before."""
    ids = [f"p{i:02d}" for i in range(20)]
    plan = make_plan(ids, {ids[i]: [ids[i - 2]] for i in range(2, 20)})
    weights = {p: 1.0 + (i % 3) for i, p in enumerate(ids)}
    policy = Lookahead(visible=2, capacity=1, weights=weights, max_states=10)
    decision = Sequencer(plan, policy=policy).decide(("p05", "p01"))
    assert decision.rule == Lookahead.OPTIMAL_RULE
    ev = policy._evaluator
    assert isinstance(ev, CompiledOptimalSolver)
    assert ev.states == estimate_states(ev.engine, visible=2, capacity=1).states > 10


@compiled
def test_the_weighted_bytes_are_known_before_and_the_caps_hold(monkeypatch):
    """The bytes held stay within those computed before (the table, the pairs, the look cache); a look
    cache too small for one bin gives the same doubles; the state cap and the deadline stop the programme,
    and what it finished stays."""
    plan = make_plan([f"p{i}" for i in range(10)], {f"p{i}": [f"p{i - 1}"] for i in range(1, 10, 2)})
    engine = OrderEngine(plan)
    weights = {p: 1.0 + i for i, p in enumerate(plan.part_ids)}
    est = estimate_states(engine, visible=3, capacity=2)
    cc = CompiledOptimalSolver(engine, visible=3, capacity=2, weights=weights)
    cc.reserve(est.states)
    value = cc.value()
    assert cc.states == est.states
    assert cc.bytes <= optimum_bytes(est.states, est.keys, compiled=True, weighted_looks=(est.looks, 3))
    assert cc.bytes > optimum_bytes(est.states, est.keys, compiled=True)      # its looks are counted
    monkeypatch.setattr(optimal, "COMPILED_LOOK_CACHE_BYTES", 0)             # cleared at every bin
    assert CompiledOptimalSolver(engine, visible=3, capacity=2, weights=weights).value() == value
    check_caps(lambda **cap: CompiledOptimalSolver(engine, visible=3, capacity=2, weights=weights, **cap), value,
               est.states)


def test_the_factory_falls_back_to_python_with_the_same_values(monkeypatch):
    """Without the compiled core (OPPORTUNE_PURE_PYTHON=1), weights out of range, or more visible parts
    than the compiled weighted bin codes: the Python programme, merged all the same, the same value."""
    plan = make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["a"]})
    engine = OrderEngine(plan)
    weights = {"a": 2.0, "b": 1.0, "c": 3.0, "d": 3.0}
    value = optimal_solver(engine, visible=2, capacity=1, weights=weights).value()
    many = optimal_solver(engine, visible=11, capacity=1, weights=weights)
    assert type(many.inner) is OptimalSolver
    assert not compiled_optimal_available(engine, {"a": float("inf")})
    monkeypatch.setattr(optimal, "_native", None)
    python = optimal_solver(engine, visible=2, capacity=1, weights=weights)
    assert isinstance(python, MergedOptimalSolver) and type(python.inner) is OptimalSolver
    assert python.value() == value


@compiled
def test_with_the_core_switched_off_the_python_programme_gives_the_same_doubles():
    """``OPPORTUNE_PURE_PYTHON=1`` in a fresh interpreter: the weighted and the uniform optimum by the
    Python programme (merged all the same), the same doubles as the compiled one here."""
    import os
    import subprocess
    import sys

    code = ("from opportune import make_plan; from opportune.engine import OrderEngine; "
            "from opportune.policies.optimal import optimal_solver; "
            "e = OrderEngine(make_plan(list('abcdef'), {'e': ['a', 'b'], 'f': ['c']})); "
            "w = dict(a=2.0, b=2.0, c=0.5, d=1.0, e=3.0, f=1.0); "
            "s = [optimal_solver(e, visible=2, capacity=1, weights=x) for x in (w, None)]; "
            "print(*[type(x.inner).__name__ + ' ' + repr(x.value()) for x in s])")
    env = dict(os.environ, OPPORTUNE_PURE_PYTHON="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    engine = OrderEngine(make_plan(list("abcdef"), {"e": ["a", "b"], "f": ["c"]}))
    weights = dict(a=2.0, b=2.0, c=0.5, d=1.0, e=3.0, f=1.0)
    here = [optimal_solver(engine, visible=2, capacity=1, weights=w) for w in (weights, None)]
    assert all(type(s.inner) is CompiledOptimalSolver for s in here)
    assert out.stdout.split() == ["OptimalSolver", repr(here[0].value()), "OptimalSolver", repr(here[1].value())]


def test_the_merged_plans_go_with_their_engine():
    """The merged plan is cached per engine and dropped with it (the cache never refers to the engine)."""
    import gc
    import weakref

    from opportune.policies import interchangeable

    engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
    assert optimum_engine(engine) is optimum_engine(engine) is not engine
    assert optimum_engine(OrderEngine(make_plan(["a", "b"], {"b": ["a"]}))).plan.part_ids == ("a", "b")
    assert engine in interchangeable._MERGED
    alive = weakref.ref(engine)
    del engine
    gc.collect()
    assert alive() is None
