"""The look-ahead's optimum prepared as per-plan work: its states listed in slices (the one call's answer),
solved in slices (the optimum's own values), taken up by a look-ahead with a budget whose listing did not
fit (its decisions then the optimum's), refused by states or bytes as a decision would be, and in the
service prepared in the background for a run's settings."""

from __future__ import annotations

import random
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from opportune import make_plan
from opportune.engine import OrderEngine
from opportune.engine.deadline import Deadline
from opportune.policies.lookahead import Lookahead
from opportune.policies.optimal import optimal_solver
from opportune.policies.states import StateListing, estimate_states

OPTIMUM = Lookahead.OPTIMAL_RULE


def random_plan(seed: int, n: int, p: float):
    rng = random.Random(seed)
    parts = [f"p{i}" for i in range(n)]
    return make_plan(parts, {x: [q for q in parts[:i] if rng.random() < p] for i, x in enumerate(parts)})


def prepared(policy, engine, seconds: float = 0.002) -> tuple[bool, int]:
    """Prepare in slices of ``seconds``: (the answer, slices taken)."""
    slices = 0
    while True:
        slices += 1
        done = policy.prepare(engine, Deadline.after(seconds))
        if done is not None:
            return done, slices


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), n=st.integers(1, 9), visible=st.integers(1, 3),
       capacity=st.sampled_from([0, 1, 2, None]), pile=st.booleans())
def test_a_listing_in_slices_gives_the_one_calls_answer(seed, n, visible, capacity, pile):
    """A slice whose deadline has passed lists one key: as many slices as keys give the one call's count."""
    engine = OrderEngine(random_plan(seed, n, 0.3))
    whole = estimate_states(engine, visible=visible, capacity=capacity, pile=pile, time_limit=None)
    listing = StateListing(engine, visible=visible, capacity=capacity, pile=pile)
    slices, result = 0, None
    while result is None:
        slices += 1
        result = listing.advance(Deadline(0.0))
    assert (result.states, result.exact, result.keys) == (whole.states, True, whole.keys)
    assert slices == whole.keys + 1         # the last slice finds the walk over
    short = StateListing(engine, visible=visible, capacity=capacity, pile=pile, stop_above=whole.states - 1)
    cut = short.advance(Deadline.NEVER)
    assert not cut.exact and whole.states - 1 < cut.low <= whole.states


def test_a_prepared_optimum_is_the_optimum_and_a_budgeted_lookahead_takes_it_up():
    """Slices of a preparation give the optimum's value to the bit (a solver of its own on a fresh engine);
    a look-ahead with no time to list its states decides otherwise before, and as the look-ahead without a
    budget after, on every look of several states."""
    plan = random_plan(2, 14, 0.15)
    engine = OrderEngine(plan)
    budgeted = Lookahead(visible=1, capacity=2, budget=1e-9)
    look = (plan.parts[-1].id,)
    budgeted.choose_at(engine, 0, 1, (), 2.0, look)
    assert budgeted.deciding_rule != OPTIMUM and "per-plan work" in budgeted.refusal
    done, slices = prepared(Lookahead(visible=1, capacity=2), engine)
    assert done is True and slices >= 1
    own = optimal_solver(OrderEngine(plan), visible=1, capacity=2, merge=True)
    ready = Lookahead(visible=1, capacity=2)
    assert ready.prepare(engine) is True        # at once: ready
    exact = Lookahead(visible=1, capacity=2)
    rng = random.Random(0)
    mask, buffer = 0, ()
    for _ in range(8):
        for i, part in enumerate(plan.parts):
            if mask >> engine.first[i] & 1:
                continue            # installed: not in the bin
            visible = (part.id,)
            assert budgeted.choose_at(engine, mask, 1, buffer, 2.0 - len(buffer), visible) == \
                exact.choose_at(engine, mask, 1, buffer, 2.0 - len(buffer), visible)
            assert budgeted.deciding_rule == OPTIMUM
        ready_parts = [i for i in range(engine.n_units) if not mask >> i & 1
                       and not engine.posets[0].below[i] & ~mask]
        mask |= 1 << rng.choice(ready_parts)
    assert budgeted.last_cost is not None
    assert engine.kept["lookahead programmes"] and exact._evaluator.value() == own.value()


def test_a_preparation_is_refused_by_states_and_by_bytes_as_a_decision_would_be(monkeypatch):
    """Over the state cap or the engine's grant: False with the reason, and asked again, False at once (the
    listing is not redone)."""
    plan = random_plan(3, 12, 0.2)
    monkeypatch.setattr(Lookahead, "COMPILED_STATES", 50)
    policy = Lookahead(visible=2, capacity=1, max_states=50)
    engine = OrderEngine(plan)
    assert policy.prepare(engine) is False
    job = next(iter(engine.kept["lookahead optima under way"].values()))
    assert "more than 50" in job.refusal and job.solver is None
    keys = job.listing.keys
    assert policy.prepare(engine) is False and job.listing.keys == keys
    monkeypatch.undo()
    small = OrderEngine(plan, memory_limit=10_000)
    assert Lookahead(visible=2, capacity=1).prepare(small) is False
    job = next(iter(small.kept["lookahead optima under way"].values()))
    assert "bytes" in job.refusal
    assert Lookahead(visible=2, capacity=1, optimal=False).prepare(OrderEngine(plan)) is False


def test_the_service_prepares_a_runs_optimum_in_the_background(tmp_path):
    """With the default decision budget, too short to list the optimum's states, a run decides by the optimum once the
    background preparation is ready (the decisions of a look-ahead without a budget), and not without it
    (``optimum_seconds`` 0: it stops at once).  The preparation is once per plan and setting."""
    from test_service_plan_memory import Cell

    plan = random_plan(2, 24, 0.06)     # 40,770 states with no buffer: listed in a third of a second, not 17 ms
    first = plan.parts[0].id
    rules = {}
    for seconds in (0.0, 600.0):
        (tmp_path / str(seconds)).mkdir()
        with Cell(tmp_path / str(seconds), optimum_seconds=seconds) as cell:
            pid = cell.upload(plan)
            run = cell.post("/runs", {"plan": pid, "buffer_capacity": 0}, expect=201)
            (loaded,) = cell.book.loaded()
            for _ in range(2_000):          # the background work ends by its own deadline or when done
                if loaded.optima.get(("lookahead", 0)) not in ("waiting", "under way"):
                    break
                time.sleep(0.01)
            cell.post("/runs", {"plan": pid, "buffer_capacity": 0}, expect=201)
            assert list(loaded.optima) == [("lookahead", 0)]        # once per plan and setting
            answer = cell.post(f"/runs/{run['id']}/looks", {"visible": [first, plan.parts[1].id]})
            rules[seconds] = (loaded.optima[("lookahead", 0)], answer["decision"]["rule"], answer["action"])
    assert rules[0.0][0] == "stopped" and rules[0.0][1] != OPTIMUM
    assert rules[600.0][0] == "ready" and rules[600.0][1] == OPTIMUM
    exact = Lookahead(visible=2, capacity=0).choose_at(OrderEngine(plan), 0, 1, (), 0.0, (first, plan.parts[1].id))
    assert rules[600.0][2] == exact.to_dict()


def test_a_run_decided_by_its_window_resumes_once_its_optimum_is_ready(tmp_path):
    """Looks recorded while the frontier window decided, then the optimum prepared, then the run rebuilt from
    its log (as after its plan's eviction or a restart): it replays what was done (the optimum would decide
    some of those looks otherwise), and its next look is the optimum's."""
    from test_service_plan_memory import Cell

    plan = random_plan(2, 24, 0.06)
    rng = random.Random(4)
    with Cell(tmp_path, optimum_seconds=0.0) as cell:
        pid = cell.upload(plan)
        run = cell.post("/runs", {"plan": pid, "buffer_capacity": 1}, expect=201)
        (loaded,) = cell.book.loaded()
        exact, differ = Lookahead(visible=2, capacity=1), 0
        for _ in range(12):
            in_bin = [p for p, n in run["state"]["in_bin"].items() for _ in range(n)]
            look = rng.sample(in_bin, 2)
            live = cell.app.state.manager._live[run["id"]]
            state = live.sequencer.state
            answer = cell.post(f"/runs/{run['id']}/looks", {"visible": look})
            assert answer["decision"]["rule"] != OPTIMUM
            differ += exact.decide(state, tuple(look)).action.to_dict() != answer["action"]
            run = cell.post(f"/runs/{run['id']}/outcomes", {"outcome": "success"})["run"]
        assert differ      # the optimum would have decided some of these looks otherwise
        manager = cell.app.state.manager
        with loaded.lock:       # as the service's background work would (the run's own settings)
            assert manager._policy(loaded, 1, "lookahead", budget=None).prepare(loaded.engine) is True
        cell.app.state.manager._forget(cell.app.state.manager._live[run["id"]])
        in_bin = [p for p, n in run["state"]["in_bin"].items() for _ in range(n)]
        answer = cell.post(f"/runs/{run['id']}/looks", {"visible": rng.sample(in_bin, 2)})
        assert answer["decision"]["rule"] == OPTIMUM
        trace = cell.client.get(f"/runs/{run['id']}/trace", headers=cell.headers)
        assert trace.status_code == 200, trace.text


def test_a_look_whose_deadline_cuts_the_base_rules_count_is_still_the_optimums():
    """The optimum needs no base: where the look's deadline has passed before the base rule's count, the
    decision is still an action of least expected cost, the optimum's (its ties by kind and order)."""
    plan = random_plan(2, 24, 0.06)
    engine = OrderEngine(plan)
    assert Lookahead(visible=2, capacity=1).prepare(engine) is True
    look = (plan.parts[5].id, plan.parts[9].id)
    exact = Lookahead(visible=2, capacity=1)
    action = exact.choose_at(OrderEngine(plan), 0, 1, (), 1.0, look)
    budgeted = Lookahead(visible=2, capacity=1, budget=0.05)
    with engine.deadline(Deadline(0.0).at):     # passed: the base rule cannot count
        cut = budgeted.choose_at(engine, 0, 1, (), 1.0, look)
    assert budgeted.deciding_rule == OPTIMUM
    assert abs(budgeted.last_cost - exact.last_cost) < 1e-9
    assert cut == action or abs(budgeted.last_cost - exact.last_cost) < 1e-12


def test_the_service_prepares_one_setting_at_a_time_per_plan(tmp_path):
    """Runs of two buffer settings on one plan: their optima are prepared one after the other (one thread a
    plan, the second waiting), both ready in the end, each run's decisions the optimum's."""
    from test_service_plan_memory import Cell

    plan = random_plan(7, 16, 0.15)
    with Cell(tmp_path) as cell:
        pid = cell.upload(plan)
        runs = {c: cell.post("/runs", {"plan": pid, "buffer_capacity": c}, expect=201) for c in (1, 2)}
        (loaded,) = cell.book.loaded()
        seen = set()
        for _ in range(3_000):
            seen.add(tuple(loaded.optima.values()))
            if all(v not in ("waiting", "under way") for v in loaded.optima.values()):
                break
            time.sleep(0.01)
        assert loaded.optima == {("lookahead", 1): "ready", ("lookahead", 2): "ready"}
        assert all(states.count("under way") <= 1 for states in seen)
        for c, run in runs.items():
            look = [plan.parts[-1].id, plan.parts[-2].id]
            assert cell.post(f"/runs/{run['id']}/looks", {"visible": look})["decision"]["rule"] == OPTIMUM


@pytest.mark.parametrize("pile", [False, True])
@pytest.mark.parametrize("ways", [False, True])
def test_a_prepared_optimum_decides_as_the_look_ahead_without_a_budget_in_every_bin_and_kind(pile, ways):
    """The pile's programme and a plan written as ways too: a budgeted look-ahead taking the prepared optimum
    decides, with the same expected cost, as a look-ahead without a budget on a fresh engine, on every look
    of one unit at the start."""
    from test_ways_optimum import feasible_ways_plan

    plan = feasible_ways_plan(5, 7) if ways else random_plan(5, 9, 0.25)
    settings = dict(visible=1, capacity=1, **({"bin": "pile"} if pile else {}))
    engine = OrderEngine(plan)
    done, _ = prepared(Lookahead(**settings), engine)
    assert done is True
    for part in plan.parts:
        budgeted, exact = Lookahead(budget=1e-9, **settings), Lookahead(**settings)
        action = budgeted.choose_at(engine, 0, engine.all_strategies, (), 1.0, (part.id,))
        fresh = OrderEngine(plan)
        assert action == exact.choose_at(fresh, 0, fresh.all_strategies, (), 1.0, (part.id,))
        assert budgeted.deciding_rule == OPTIMUM and budgeted.last_cost == exact.last_cost


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), n=st.integers(2, 9), visible=st.integers(1, 3), capacity=st.integers(1, 2))
def test_the_optimum_asks_its_base_only_to_break_a_tie(seed, n, visible, capacity):
    """Where the optimum decides, the base rule's count (early in a large plan, a look's whole budget) is
    asked only where several actions are equally least; the decision is the base's action among the least,
    else the least by kind and order: an action of least expected cost (an independent solver's values)."""
    plan = random_plan(seed, n, 0.3)
    engine = OrderEngine(plan)
    policy = Lookahead(visible=visible, capacity=capacity)
    asked = []
    choose = policy.base.choose_at
    policy.base.choose_at = lambda *a, **k: asked.append(a[5]) or choose(*a, **k)
    own = optimal_solver(OrderEngine(plan), visible=visible, capacity=capacity, merge=False)
    rng = random.Random(seed)
    mask, buffer = 0, ()
    while mask != (1 << engine.n_units) - 1:
        in_bin = [p.id for i, p in enumerate(plan.parts) if not mask >> engine.first[i] & 1 and p.id not in buffer]
        look = tuple(sorted(rng.sample(in_bin, min(visible, len(in_bin))))) if in_bin else ()
        action = policy.choose_at(engine, mask, 1, buffer, capacity - len(buffer), look)
        assert policy.deciding_rule == OPTIMUM
        key = own.policy_key(mask, 1, buffer)
        idx = tuple(sorted(plan.index(p) for p in look))
        values = {str(a): c + own._after(key, idx, a, nxt) for c, nxt, a in own.policy_moves(key, idx)}
        values["shake"] = own.costs.shake + own._after_shake(key)
        least = min(values.values())
        tied = [a for a, v in values.items() if v <= least + 1e-12]
        assert abs(values[str(action)] - least) < 1e-9
        assert (look in asked) == (len(tied) > 1)
        asked.clear()
        if action.kind == "install":
            mask |= 1 << engine.first[plan.index(action.part)]
            buffer = tuple(b for b in buffer if b != action.part) if action.source == "buffer" else buffer
        elif action.kind == "buffer":
            buffer = tuple(sorted(buffer + (action.part,)))
