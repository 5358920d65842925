"""A look through the service fits its decision budget at any plan size: the decision gets what the rest of
the request leaves, and the rest makes a bounded number of passes over the plan's parts (counted work, not
wall time: the machine may be busy)."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opportune import make_plan
from opportune.engine import Schedule
from opportune.engine import schedule as schedule_module
from opportune.sequencer import Sequencer, State
from opportune.service.latency import LEAST, MOST, Reserves, decision_budget


@pytest.fixture()
def app(tmp_path):
    from fastapi.testclient import TestClient

    from opportune.service.app import create_app
    from opportune.service.auth import create_token
    from opportune.service.config import Settings
    from opportune.service.storage import Store

    url = f"sqlite:///{tmp_path / 'l.db'}"
    store = Store(url)
    headers = {"Authorization": f"Bearer {create_token(store, cell='c')[1]}"}
    application = create_app(Settings(db_url=url, max_body=1 << 24), store)
    with TestClient(application) as client:
        keys = iter(range(10**9))

        def post(path, body):
            r = client.post(path, json=body, headers={**headers, "Idempotency-Key": f"k{next(keys)}"})
            assert r.status_code in (200, 201), r.text
            return r.json()

        yield application, post
    store.dispose()


def test_looks_make_a_bounded_number_of_passes_over_the_parts_and_learn_their_reserve(app):
    application, post = app
    n, looks = 2000, 12
    plan = post("/plans", {"name": "free", "parts": [f"p{i}" for i in range(n)]})
    run = post("/runs", {"plan": plan["id"]})
    rng = random.Random(1)
    passes = schedule_module.PASSES
    before = dict(passes)
    manager = application.state.manager
    budgets = []
    for _ in range(looks):
        in_bin = [p for p, k in run["state"]["in_bin"].items() for _ in range(k)]
        live = manager._live[run["id"]]
        policy = live.sequencer.policy
        decide = policy.decide
        nominal = (policy.lookahead_budget, policy.fallback.budget, policy.fallback_alone.total_budget)
        policy.decide = lambda state, visible: (budgets.append(policy.lookahead_budget), decide(state, visible))[1]
        answer = post(f"/runs/{run['id']}/looks", {"visible": rng.sample(in_bin, 3)})
        del policy.decide
        assert (policy.lookahead_budget, policy.fallback.budget, policy.fallback_alone.total_budget) == nominal  # given back
        run = post(f"/runs/{run['id']}/outcomes", {"outcome": "success"})["run"]
        assert sum(run["state"]["in_bin"].values()) == n - len(run["state"]["installed"]) - len(run["state"]["buffered"])
    assert answer["decision"]
    made = {k: passes.get(k, 0) - before.get(k, 0) for k in passes}
    # once per state for what is in the bin (a new state each outcome), never again per look for the
    # units left (found at the run's start, then carried from schedule to schedule)
    assert made.get("in_bin", 0) <= looks + 2, made
    assert made.get("remaining", 0) <= 2, made
    # each decision had the budget less the reserve the rest of the look needs, learned from the looks
    assert all(LEAST <= 0.05 - b + 1e-9 for b in budgets) and all(b <= 0.05 for b in budgets), budgets
    reserve = manager.reserves.after_decision(plan["id"])
    assert LEAST <= reserve <= MOST * 0.05


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(0, 5), min_size=1, max_size=12), st.data())
def test_remaining_and_in_bin_carried_along_equal_a_fresh_count(quantities, data):
    plan = make_plan([{"id": f"p{i}", "quantity": q or 1} for i, q in enumerate(quantities)], {})
    seq = Sequencer(plan, budget=None)
    _ = seq.state.in_bin                      # found once; the rest is carried along
    for _ in range(data.draw(st.integers(0, plan.n_units))):
        in_bin = [p for p, k in seq.state.in_bin.items() for _ in range(k)]
        if not in_bin:
            break
        look = data.draw(st.lists(st.sampled_from(in_bin), min_size=1, max_size=2, unique=True))
        seq.decide(look)
        seq.report(data.draw(st.sampled_from(["success", "success", "failed", "defective"])),
                   keep=data.draw(st.sampled_from(["bin", "buffer"])))
        s = seq.state
        fresh = Schedule(seq.engine, s.installed)
        assert s.schedule.remaining == fresh.remaining
        expected = dict(fresh.remaining)
        for p in s.buffer:
            expected[p] -= 1
        assert s.in_bin == {p: k for p, k in expected.items() if k > 0}
        assert State(fresh, s.buffer, s.capacity).in_bin == s.in_bin
        s.in_bin.clear()                      # a copy: the state keeps its own
        assert s.in_bin or s.is_complete or s.buffer


def test_reserves_are_a_bounded_percentile_per_plan_and_forget_old_plans():
    r = Reserves(0.05)
    assert r.after_decision("a") == pytest.approx(0.015)
    for s in [0.001] * 19 + [0.2]:
        r.measured("a", after_decision=s, after_counts=s)
    assert r.after_decision("a") == pytest.approx(MOST * 0.05)   # the outlier is the 95th percentile: capped
    for _ in range(40):
        r.measured("a", after_decision=0.0, after_counts=0.0)
    assert r.after_decision("a") == LEAST                         # the window moved on; never below the floor
    for i in range(300):
        r.measured(f"p{i}", after_decision=0.01, after_counts=0.01)
    assert len(r._plans) == 256 and "a" not in r._plans


def test_a_decision_budget_is_shrunk_within_bounds_and_given_back():
    class P:
        budget = 0.05

    p = P()
    with decision_budget(p, 0.02):
        assert p.budget == pytest.approx(0.02)
    with decision_budget(p, -1.0):
        assert p.budget == pytest.approx(0.005)   # a tenth of the budget at least: a decision is always made
    with decision_budget(p, 1.0):
        assert p.budget == 0.05
    assert p.budget == 0.05
    p.budget = None
    with decision_budget(p, 0.01):
        assert p.budget is None


@settings(max_examples=25, deadline=None)
@given(st.integers(3, 40), st.data())
def test_chains_started_from_the_shared_place_are_the_chains_started_afresh(n, data):
    from opportune.engine import sampling
    from opportune.engine.poset import Poset

    pairs = data.draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1))
                               .filter(lambda p: p[0] < p[1]), max_size=2 * n))
    poset = Poset.from_pairs(n, pairs)
    remaining = (1 << n) - 1
    seed = data.draw(st.integers(0, 5))
    sampling._starts.clear()
    fresh = sampling.CompletionChains(poset, remaining, chains=4, seed=seed)
    assert len(sampling._starts) == 1
    shared = sampling.CompletionChains(poset, remaining, chains=4, seed=seed)   # from the kept start
    assert shared.orders == fresh.orders and shared._state == fresh._state
    a = fresh.estimate(first=[0], positions=[n - 1], steps=200)
    b = shared.estimate(first=[0], positions=[n - 1], steps=200)
    assert a.first == b.first and a.positions == b.positions
    for s in range(10, 10 + 2 * sampling.START_KEEP):                            # bounded: oldest forgotten
        sampling.CompletionChains(poset, remaining, chains=2, seed=s)
    assert len(sampling._starts) == sampling.START_KEEP
