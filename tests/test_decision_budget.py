"""Decisions within a time budget: exact when the counts fit, else estimates that say how sure they are."""

from __future__ import annotations

import math
import random
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import CpuTime, random_plans
from test_engine_count_scans import random_poset
from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.engine.count import BudgetExceeded, Counter
from opportune.engine.sampling import CompletionChains, _t_cdf, t_quantile
from opportune.policies.look import LookState
from opportune.policies.opportunistic import Opportunistic, choose_exact
from opportune.sequencer import LookError, Sequencer


def test_chain_estimates_cover_the_exact_values_as_stated():
    """Over random orders, the stated 95% intervals (Student's t over the chains) of next-step shares
    and expected positions hold the exact values (from the counter) at least 85% of the time."""
    rng = random.Random(7)
    hits = total = 0
    for trial in range(12):
        n = rng.randint(6, 14)
        poset = random_poset(rng, n, rng.choice([0.1, 0.2, 0.35]))
        counter = Counter(poset)
        full = poset.full
        e = counter.count(full)
        sums = counter.position_sums(full)
        minimal = [u for u in range(n) if not poset.below[u]]
        chains = CompletionChains(poset, full, chains=8, seed=trial)
        chains.run(2_000)                                # burn-in
        est = chains.estimate(first=minimal, positions=range(n), steps=6_000, samples=60)
        q = t_quantile(0.975, 7)
        for u in minimal:
            value, se = est.first[u]
            hits += abs(value - counter.count(full & ~(1 << u)) / e) <= q * se + 1e-12
            total += 1
        for u in range(n):
            value, se = est.positions[u]
            hits += abs(value - sums[u] / e) <= q * se + 1e-12
            total += 1
    assert total > 100
    assert hits / total >= 0.85, (hits, total)


def test_kept_readings_build_on_each_other_and_still_cover_the_exact_values():
    """With ``keep``, looks at one state continue each other's readings (a unit asked again has more
    rounds behind it), the stated intervals still hold the exact values, and an installation clears
    the readings."""
    rng = random.Random(11)
    hits = total = 0
    for trial in range(8):
        n = rng.randint(8, 14)
        poset = random_poset(rng, n, 0.2)
        counter = Counter(poset)
        e, sums = counter.count(poset.full), counter.position_sums(poset.full)
        chains = CompletionChains(poset, poset.full, chains=8, seed=trial)
        chains.run(2_000)
        units = list(range(n))
        first = chains.estimate(positions=units[: n // 2 + 2], steps=2_000, samples=20, keep=True)
        second = chains.estimate(positions=units[n // 2:], steps=2_000, samples=20, keep=True)
        assert second.samples == 2 * first.samples          # the shared units have both calls' rounds
        q = t_quantile(0.975, 7)
        for est, asked in ((first, units[: n // 2 + 2]), (second, units[n // 2:])):
            for u in asked:
                value, se = est.positions[u]
                hits += abs(value - sums[u] / e) <= q * se + 1e-12
                total += 1
        u = next(u for u in units if not poset.below[u])
        chains.advance(poset.full & ~(1 << u))
        after = chains.estimate(positions=[v for v in units[n // 2:] if v != u], steps=200, samples=5, keep=True)
        assert after.samples == 5 * 8                          # the readings of the earlier state are gone
    assert hits / total >= 0.85, (hits, total)


def test_an_estimate_stops_early_when_no_candidate_is_better_by_more_than_the_margin():
    """Two parts with equal expected positions that are not interchangeable (mirror images: x < a,
    y < b): no number of samples makes one surely first, but both are surely within 1%, so the
    estimate ends long before its deadline and says why."""
    plan = make_plan([{"id": p} for p in ("x", "a", "y", "b", "z")], {"a": ["x"], "b": ["y"]})
    engine = OrderEngine(plan)
    policy = Opportunistic(budget=10.0, seed=3)
    with CpuTime() as cpu:
        action, how = policy._estimate(LookState(engine, 0, engine.all_strategies, (), math.inf, ("a", "b")),
                                       time.perf_counter() + 60.0)
    assert cpu.seconds < 2.0                     # long before its deadline, however busy the machine
    assert action.kind == "buffer" and not how.exact
    assert how.close and how.confidence < 0.999   # the decision then states the near tie (test_dashboard_text.py)
    exact = Counter(engine.posets[0]).position_sums()
    assert exact[engine.next_unit(0, plan.index("a"))] == exact[engine.next_unit(0, plan.index("b"))]


def test_chains_carry_on_after_an_installation():
    """After an installed step is dropped, every chain is still an admissible completion of what is left."""
    rng = random.Random(3)
    poset = random_poset(rng, 20, 0.15)
    chains = CompletionChains(poset, poset.full, seed=1)
    left = poset.full
    while left:
        chains.run(200)
        for order in chains.orders:
            assert sorted(order) == [u for u in range(20) if left >> u & 1]
            placed = 0
            for u in order:
                assert poset.below[u] & left & ~placed == 0
                placed |= 1 << u
        u = rng.choice([u for u in range(20) if left >> u & 1 and not poset.below[u] & left])
        left &= ~(1 << u)
        chains.advance(left)
    with pytest.raises(ValueError):
        chains.advance(poset.full)


def test_student_t_helpers_agree_with_scipy():
    from scipy import stats

    for df in (3, 7, 15, 40):
        assert t_quantile(0.975, df) == pytest.approx(stats.t.ppf(0.975, df), rel=0.01)
    # the finite series (whole df up to 100), and the incomplete beta beyond
    for df in (1, 2, 3, 4, 7, 8, 15, 40, 99, 100, 101, 250, 7.5):
        for t in (-40.0, -2.5, -0.3, 0.0, 1.1, 3.0, 12.0):
            assert _t_cdf(t, df) == pytest.approx(stats.t.cdf(t, df), abs=1e-9)


def _random_look(rng, state):
    in_bin = [p for p, n in state.in_bin.items() for _ in range(n)]
    return rng.sample(in_bin, min(len(in_bin), rng.randint(1, 3)))


@settings(max_examples=40, deadline=None)
@given(random_plans(max_parts=7, max_units=8), st.integers(0, 2**16), st.sampled_from([1e-9, 1e-4, 0.05]),
       st.sampled_from([None, 1, 2]))
def test_budgeted_decisions_are_the_exact_rules_whenever_they_say_exact(plan, seed, budget, capacity):
    """A budgeted decision marked exact is the exact rule's action; an estimated one is an action the
    state allows, with estimates, a method and a probability in [0, 1]."""
    rng = random.Random(seed)
    engine = OrderEngine(plan)
    seq = Sequencer(engine, Opportunistic(budget=budget, seed=seed), buffer_capacity=capacity, warm_up=0)
    while not seq.finished and len(seq.trace) < 60:
        look = _random_look(rng, seq.state) if not seq.state.is_complete else []
        state = seq.state
        decision = seq.decide(look)
        exact = choose_exact(engine, state.schedule.mask, state.schedule.consistent, state.buffer,
                             state.buffer_free, tuple(look))
        if decision.exact:
            assert decision.action == exact
        else:
            assert decision.method == "mcmc" and decision.estimates
            assert 0.0 <= decision.confidence <= 1.0
            d = decision.to_dict()
            assert d["exact"] is False and "confidence" in d and d["estimates"]
        if decision.action.kind != "done":
            seq.report("success")


def test_a_tiny_budget_estimates_and_a_large_one_is_exact_on_kilbrid():
    plan = load_plan("salbp:KILBRID")
    rng = random.Random(0)
    looks = []
    exact_seq = Sequencer(plan, budget=None)
    tiny = Sequencer(OrderEngine(plan), Opportunistic(budget=1e-9), warm_up=0)
    estimated = agree = 0
    while not exact_seq.state.is_complete:
        look = _random_look(rng, exact_seq.state)
        looks.append(look)
        d = exact_seq.decide(look)
        assert d.exact and d.to_dict()["exact"] is True and "seconds" not in d.to_dict()
        # The same state in the budgeted sequencer: it follows the exact sequencer's actions.
        t = tiny.decide(look)
        if not t.exact:
            estimated += 1
            agree += t.action == d.action
        tiny.cancel()
        tiny.replay(look, d.action)
        exact_seq.report("success")
        tiny.report("success")
    assert estimated >= 5                    # a budget of a nanosecond leaves estimates where there is a choice
    assert agree >= 0.6 * estimated, (agree, estimated)   # which mostly agree with the exact rule
    assert tiny.state.installed == exact_seq.state.installed


def test_replay_takes_a_recorded_action_and_refuses_one_that_does_not_fit():
    plan = make_plan(["a", "b", "c"], {"c": ["a"]})
    seq = Sequencer(plan)
    d = seq.replay(["b", "c"], seq.policy.choose(seq.state, ("b", "c")))
    assert d.action.kind == "install" and d.method == "replayed"
    seq.report("success")
    from opportune.policies.base import shared_action

    with pytest.raises(LookError):
        seq.replay(["c"], shared_action("install", "c", "bin"))     # c needs a first
    assert seq.pending is None and seq.state.installed == ("b",)    # nothing changed


def test_an_engine_deadline_stops_every_count_and_the_work_is_kept():
    """One deadline for all the counts of a decision; a count it stops continues later, exactly."""
    plan = load_plan("salbp:TONGE70")
    engine = OrderEngine(plan)
    with pytest.raises(BudgetExceeded):
        with engine.deadline(time.perf_counter() - 1):
            engine.count(0, engine.all_strategies)
    fresh = OrderEngine(plan)
    assert engine.count(0, engine.all_strategies) == fresh.count(0, fresh.all_strategies)


def test_a_budgeted_decision_pauses_the_collector_and_gives_it_back():
    """Garbage collection waits for the end of a budgeted decision (nested and overlapping pauses
    included) and is left as it was found, enabled or not."""
    import gc

    from opportune.policies.base import collector_paused

    plan = load_plan("example:gearbox")
    engine = OrderEngine(plan)
    seen = []
    policy = Opportunistic(budget=0.05)
    inner = policy._within_budget

    def spy(*args):
        seen.append(gc.isenabled())
        return inner(*args)

    policy._within_budget = spy
    was = gc.isenabled()
    try:
        for enabled in (True, False):
            (gc.enable if enabled else gc.disable)()
            policy.choose_at(engine, 0, engine.all_strategies, (), 1, tuple(plan.part_ids[:2]))
            assert seen.pop() is False
            assert gc.isenabled() is enabled
            with collector_paused():
                with collector_paused():
                    assert not gc.isenabled()
                assert not gc.isenabled()        # the outer pause still holds
            assert gc.isenabled() is enabled
    finally:
        (gc.enable if was else gc.disable)()


def test_no_collection_starts_inside_a_budgeted_decision():
    """The pause covers the whole decision, its first and last allocations included: with the
    collector set to run at every allocation, none starts between the call and its return (a
    pause written as a ``with`` block let the collection that waited start in the block's exit,
    inside the decision)."""
    import gc

    plan = load_plan("example:gearbox")
    engine = OrderEngine(plan)
    policy = Opportunistic(budget=0.05)
    look = tuple(plan.part_ids[:2])
    policy.choose_at(engine, 0, engine.all_strategies, (), 1, look)    # warm: the same work each time
    state = LookState(engine, 0, engine.all_strategies, (), 1, look)
    inside = [False]
    started = []

    def watch(phase, info):
        if phase == "start" and inside[0]:
            started.append(info["generation"])

    threshold = gc.get_threshold()
    was = gc.isenabled()
    gc.callbacks.append(watch)
    try:
        gc.enable()
        for _ in range(20):
            gc.set_threshold(1)
            inside[0] = True
            policy._budgeted(state)
            inside[0] = False
            gc.set_threshold(*threshold)
    finally:
        gc.callbacks.remove(watch)
        gc.set_threshold(*threshold)
        (gc.enable if was else gc.disable)()
    assert started == []


def test_a_budget_must_be_positive():
    with pytest.raises(ValueError):
        Opportunistic(budget=0)
    with pytest.raises(ValueError):
        Sequencer(make_plan(["a"]), budget=-1)


@pytest.mark.parametrize("policy", ["paper", "lookahead"])
def test_a_budgeted_simulation_keeps_memo_upkeep_out_of_its_decisions(policy, monkeypatch):
    """As the sequencer does, a budgeted study's decisions never evict, double or restart a memo (that
    upkeep once took a 50 ms decision to 163 ms); the upkeep runs between decisions."""
    from opportune.study.simulate import StudyConfig, TrialRunner, prepare

    plan = load_plan("examples/gearbox.yaml")
    config = StudyConfig(plan, strategies=(policy,), trials=1, seed=3, visible=2, decision_budget=0.05)
    engine = OrderEngine(plan)
    runner = TrialRunner(policy, engine, config, prepare(config, engine))
    inside = [False]
    calls = {True: 0, False: 0}
    maintain = Counter.maintain

    def counted(self, *args, **kw):
        calls[inside[0]] += 1
        return maintain(self, *args, **kw)

    monkeypatch.setattr(Counter, "maintain", counted)
    choose = runner._choose_at

    def deciding(*args):
        inside[0] = True
        try:
            return choose(*args)
        finally:
            inside[0] = False

    runner._choose_at = deciding
    runner.run(0)
    assert calls[True] == 0 and calls[False] > 0
