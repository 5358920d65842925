"""The bound's penalties (opportune.study.bounds, opportune.study.relaxation): each one a subsolution on every
state of small random plans (checked against the exact optimum state by state), every trial's inner value
at most the penalised cost of the optimum's own path on the same bin, the bound below the optimum for
every penalty, and a penalty whose mean is not zero caught by the same check."""

from __future__ import annotations

import math
import random
import statistics
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import GEARBOX, run_cli
from opportune import load_plan
from opportune.engine import OrderEngine
from opportune.policies.optimal import OptimalSolver, same_action
from opportune.study.bounds import PENALTIES, Z95, BoundError, Keys, inner_minimum, lower_bound, penalty_for
from opportune.study.relaxation import relax_plan
from test_bounds import lab_plan

PENALISED = ("none", "motions", "relaxed", "optimal")


def small_world(seed: int):
    """A random plan of 5-8 parts as the lab makes them (one or two strategies) and a world for it."""
    rng = random.Random(seed)
    plan = lab_plan(seed, rng.randint(5, 8), strategies=rng.choice([1, 1, 2]), density=rng.uniform(0.2, 0.5))
    return plan, rng.choice([1, 2, 3]), rng.choice([None, 0, 1, 2])


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), budget=st.sampled_from([60, 300, 3_000]))
def test_the_relaxed_plans_values_are_a_subsolution_below_the_optimum_on_every_state(seed, budget):
    """At every state of the exact optimum: *V̂* ≤ *V**, the Bellman residual ≥ 0 (what makes every step of the
    inner problem non-negative), and the residual by order statistics equals the one over every look."""
    plan, visible, capacity = small_world(seed)
    engine = OrderEngine(plan)
    exact = OptimalSolver(engine, visible=visible, capacity=capacity, max_states=10**6)
    exact.value()
    pen = penalty_for("relaxed", OptimalSolver(engine, visible=visible, capacity=capacity), budget)
    for key, best in exact._values.items():
        v = pen.value(key)
        assert v <= best + 1e-9, (key, v, best)
        r = pen.residual(key)
        assert r >= -1e-9, (key, r)
        by_looks = sum(p * pen.look_term(key, look, list(exact._moves(key, look)))
                       for look, p in exact._look_distribution(pen.bin_counts(key)))
        assert r == pytest.approx(exact.costs.look + by_looks - v, abs=1e-9)


def test_the_relaxed_plan_keeps_the_common_order_and_projects_the_states():
    """Two strategies that disagree on b: only the order both keep (a before c) is kept; the merged part's
    units are the members' units, installed and buffered ones counted."""
    from opportune import make_plan

    plan = make_plan(["a", "b", "c", "d"], strategies={"s": {"c": ["a"], "b": ["a"]}, "t": {"c": ["a", "b"]}})
    r = relax_plan(plan, [0, 1, 2])
    assert r.plan.strategies[0].pairs() == [("a", "c")]
    r2 = relax_plan(plan, [0, 2])
    assert [(p.id, p.quantity) for p in r2.plan.parts] == [("a", 1), ("c", 1), ("free0", 2)]
    assert r2.project((0b0011, 3, (0, 0, 0, 1))) == (0b0101, 1, (0, 0, 1))


def policy_path(solver, pen, keys: Keys) -> float:
    """The optimum's own path on one trial's keys, its cost less the penalty: the inner problem's objective
    on one action sequence, so the inner minimum is at most this, trial by trial."""
    key, t, total, c = solver.start_key(), 0, 0.0, solver.costs
    while key[0] != solver.engine.full:
        look = keys.look(t, pen.bin_counts(key))
        moves = list(solver._moves(key, look))
        f = pen.look_term(key, look, moves)
        mean_f = pen.residual(key) + pen.value(key) - c.look     # E_L f(s, L)
        action, _ = solver.best_action(key, look)
        step = next(((cost, nxt) for cost, nxt, a in moves if same_action(a, action)), (c.shake, key))
        total += c.look + step[0] - (f - mean_f)
        key, t = step[1], t + 1
    return total


def trial_values(solver, pen, trials: int, seed: int) -> list[float]:
    """Each trial's inner minimum, exactly as :func:`lower_bound` draws its keys."""
    out = []
    for trial in range(trials):
        keys = Keys(list(solver.quantity), None, solver.visible, random.Random(f"bound:{seed}:{trial}"))
        value, exact, _ = inner_minimum(solver, pen, keys, 10**6, 10_000)
        assert exact
        out.append(value)
    return out


def assert_below(values: list[float], best: float) -> None:
    """The check every bound must pass: its 95% interval reaches down to the optimum or below."""
    mean = statistics.fmean(values)
    half = Z95 * statistics.stdev(values) / math.sqrt(len(values))
    assert mean - half <= best + 1e-9, f"bound {mean:.4f} ± {half:.4f} above the optimum {best:.4f}"


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), penalty=st.sampled_from(PENALISED), trial_seed=st.integers(0, 99))
def test_each_trial_is_at_most_the_optimums_own_penalised_path(seed, penalty, trial_seed):
    """Deterministic, trial by trial: the inner minimum is at most the inner objective of one action sequence,
    the optimum's own on the same bin (whose mean over bins is the optimum, the penalty's mean being zero)."""
    plan, visible, capacity = small_world(seed)
    solver = OptimalSolver(OrderEngine(plan), visible=visible, capacity=capacity, max_states=10**6)
    solver.value()
    pen = penalty_for(penalty, solver, 100)
    for trial, value in enumerate(trial_values(solver, pen, 4, seed=trial_seed)):
        keys = Keys(list(solver.quantity), None, visible, random.Random(f"bound:{trial_seed}:{trial}"))
        assert value <= policy_path(solver, pen, keys) + 1e-9


class Biased:
    """A penalty whose mean is not zero: it says each look's mean is ``bias`` more than it is (so it charges
    every look ``bias`` less than it should): not dual feasible, and the bound it gives is wrong."""

    def __init__(self, pen, bias: float):
        self.pen, self.bias = pen, bias
        self.value, self.look_term, self.bin_counts = pen.value, pen.look_term, pen.bin_counts

    def residual(self, key) -> float:
        return self.pen.residual(key) + self.bias


@pytest.mark.parametrize("name,visible,capacity", [("lab-1", 2, 2), ("lab-3", 1, None), ("gearbox", 1, 1)])
def test_every_penalty_stays_below_the_optimum_and_a_biased_one_does_not(name, visible, capacity):
    plan = load_plan(GEARBOX) if name == "gearbox" else lab_plan(int(name[4]), 8 + int(name[4]) % 3)
    engine = OrderEngine(plan)
    best = OptimalSolver(engine, visible=visible, capacity=capacity, max_states=10**6).value()
    solver = OptimalSolver(engine, visible=visible, capacity=capacity, max_states=10**6)
    solver.value()
    for penalty in PENALISED:
        pen = penalty_for(penalty, solver, 200)   # a relaxed plan of at most 200 states: a partial one
        values = trial_values(solver, pen, 40, seed=11)
        for trial, value in enumerate(values):
            keys = Keys(list(solver.quantity), None, visible, random.Random(f"bound:11:{trial}"))
            assert value <= policy_path(solver, pen, keys) + 1e-9, (penalty, trial)
        assert_below(values, best)
    biased = trial_values(solver, Biased(penalty_for("motions", solver), 0.5), 40, seed=11)
    with pytest.raises(AssertionError, match="above the optimum"):
        assert_below(biased, best)


def test_the_relaxed_penalty_charges_blocking_on_a_large_plan_with_one_location():
    """KILBRID (45 parts), one buffer location: the relaxed plan's optimum at the start is far above the 45
    motions, the bound at least that, both certified (the default policy's mean there is about 130)."""
    r = lower_bound(load_plan("salbp:KILBRID"), visible=2, capacity=1, trials=2, seed=0, node_budget=50,
                    penalty="relaxed", relaxed_states=100_000)
    assert r.penalty == "relaxed" and r.start_value > 80 and r.mean >= r.start_value - 1e-9
    assert r.to_dict()["start_value"] == r.start_value


def test_auto_takes_the_relaxed_penalty_with_a_limited_buffer_only():
    plan = lab_plan(5, 9)
    assert lower_bound(plan, trials=2, penalty="auto", max_states=10).penalty == "motions"
    assert lower_bound(plan, capacity=1, trials=2, penalty="auto", max_states=10).penalty == "relaxed"
    assert lower_bound(plan, capacity=1, trials=2, penalty="auto").penalty == "optimal"


@pytest.mark.parametrize("kwargs,words", [
    ({"relaxed_states": 0}, "relaxed_states must be"), ({"relaxed_states": True}, "relaxed_states must be"),
    ({"relaxed_states": 10**9}, "relaxed_states must be"),
    ({"penalty": "relaxed", "relaxed_states": 1}, "even with no order kept"),
])
def test_a_bad_relaxed_request_says_what_to_change(kwargs, words):
    with pytest.raises(BoundError, match=words):
        lower_bound(load_plan(GEARBOX), trials=2, **kwargs)


def test_simulate_refuses_the_optimums_penalty_on_a_large_plan_before_the_study(monkeypatch):
    """The optimum's penalty on KILBRID: refused after counting its states (at most 2 s), not after a study of
    100,000 trials; one line, exit code 2, no traceback."""
    import opportune.study.simulate as study

    def no_study(*args, **kwargs):
        raise AssertionError("the study ran before the bound's request was checked")

    monkeypatch.setattr(study, "run_study", no_study)
    cpu = time.process_time()
    out = run_cli("simulate", "salbp:KILBRID", "--trials", "100000", "--bound", "--penalty", "optimal")
    assert out.exit_code == 2 and time.process_time() - cpu < 20
    lines = [line for line in out.output.splitlines() if line.startswith("error")]
    assert len(lines) == 1 and "more than 200,000 states" in lines[0] and "'relaxed'" in lines[0]
    wrong = run_cli("simulate", GEARBOX, "--trials", "100000", "--bound", "--penalty", "relax")
    assert wrong.exit_code == 2 and f"choose from {', '.join(PENALTIES)}" in wrong.output
    assert len(wrong.output.strip().splitlines()) == 1
