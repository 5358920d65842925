"""Several products at once (issue 15, part 2): joint plans, the multi-fixture sequencer, the study, the CLI.

Brute force is the yardstick: the joint plan's admissible sequences are the interleavings of the
fixtures' (multinomial × product of counts), the paper's rule keeps the most completions of the joint
plan, and with one fixture the cell decides exactly as the single-product sequencer does.
"""

from __future__ import annotations

import json
import math
import random
from fractions import Fraction

import pytest
from conftest import brute_sequences, random_plans, respects, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from opportune import OrderEngine, Sequencer, make_plan
from opportune.datasets import example_path
from opportune.formats import load_plan
from opportune.multi import MultiSequencer, split_action
from opportune.planning.plan import MAX_STRATEGIES
from opportune.policies.named import make_policy
from opportune.planning.products import (
    MAX_PRODUCTS,
    ProductsError,
    combine_products,
    kind_of,
    kinds_in_bin,
    several_products,
    split_unit,
    unit_id,
)
from opportune.sequencer import LookError
from opportune.study.simulate import trial_seed
from opportune.study.simulate_products import CellRunner, ProductsConfig, run_products
from opportune.worlds import make_world

GEARBOX = load_plan(example_path("gearbox"))


def small_plans(max_parts=4, max_units=4):
    return random_plans(max_parts=max_parts, max_units=max_units, max_strategies=2)


def multinomial(counts) -> int:
    out, total = 1, 0
    for c in counts:
        total += c
        out *= math.comb(total, c)
    return out


def restrict(seq, fixture):
    """The kinds of one fixture's units in a joint sequence, in order."""
    return tuple(kind_of(u) for u in seq if split_unit(u)[1] == fixture)


def brute_count(plan, prefix=()) -> int:
    return len(brute_sequences(plan, prefix))


def joint_options(plans, installed, unit) -> int:
    """Completions of the joint plan after ``installed`` + ``unit``, by the interleaving formula with
    each fixture's completions counted by brute force."""
    after = (*installed, unit)
    counts, lengths = [], []
    for i, plan in enumerate(plans, 1):
        prefix = restrict(after, i)
        counts.append(brute_count(plan, prefix))
        lengths.append(plan.n_units - len(prefix))
    return multinomial(lengths) * math.prod(counts)


# ---------------------------------------------------------------- joint plans


@settings(max_examples=100, deadline=None)
@given(st.lists(small_plans(), min_size=2, max_size=3), st.booleans())
def test_joint_count_is_the_interleavings_of_the_products(plans, serial):
    joint = combine_products(plans, serial=serial)
    engine = OrderEngine(joint)
    counts = [brute_count(p) for p in plans]
    interleavings = 1 if serial else multinomial([p.n_units for p in plans])
    assert engine.count(0, engine.all_strategies) == interleavings * math.prod(counts)
    assert len(joint.strategies) == math.prod(len(p.strategies) for p in plans)
    if joint.n_units <= 7:   # tiny: every sequence of the joint plan by brute force
        sequences = brute_sequences(joint)
        assert len(sequences) == interleavings * math.prod(counts)
        for seq in sequences:   # each fixture's restriction is admissible in its own plan
            for i, plan in enumerate(plans, 1):
                assert any(respects(restrict(seq, i), s) for s in plan.strategies)


@settings(max_examples=30, deadline=None)
@given(small_plans(), st.integers(2, 3))
def test_copies_count(plan, n):
    joint = several_products(plan, n)
    engine = OrderEngine(joint)
    assert engine.count(0, engine.all_strategies) == multinomial([plan.n_units] * n) * brute_count(plan) ** n
    assert sorted(kinds_in_bin(joint)) == sorted([p.id for p in plan.parts for _ in range(p.quantity)] * n)


def test_unit_names_round_trip():
    assert split_unit(unit_id("a@b", 12)) == ("a@b", 12)
    for bad in ("x", "x@", "@1", "x@0", "x@01", "x@-1", "x@a"):
        with pytest.raises(ProductsError):
            split_unit(bad)


@pytest.mark.parametrize("n", [0, -1, MAX_PRODUCTS + 1, 1000, 2.5, "3", True, None])
def test_bad_numbers_of_products_are_refused(n):
    with pytest.raises(ProductsError, match="from 1 to 16|whole number"):
        several_products(GEARBOX, n)


def test_too_many_strategy_combinations_are_refused():
    plan = make_plan(["a", "b", "c"], strategies={"s1": {"b": ["a"]}, "s2": {"a": ["b"]}, "s3": {"c": ["a"]}})
    assert len(several_products(plan, 3).strategies) == 27
    with pytest.raises(ProductsError, match=f"beyond the limit of {MAX_STRATEGIES}"):
        several_products(plan, 4)          # 81 combinations
    with pytest.raises(ProductsError, match="at least one"):
        combine_products([])


# ---------------------------------------------------------------- decisions


@st.composite
def cells(draw):
    plans = draw(st.lists(small_plans(), min_size=2, max_size=3))
    if draw(st.booleans()):     # copies of one product: every kind on every fixture
        plans = [plans[0]] * len(plans)
    capacity = draw(st.sampled_from([None, 0, 1, 2]))
    policy = draw(st.sampled_from(["paper", "lookahead", "bin-first", "slack", "rollout"]))
    return plans, capacity, policy, draw(st.integers(0, 2**32))


def random_look(rng, state):
    in_bin = [k for k, n in state.in_bin.items() for _ in range(n)]
    k = rng.randint(0 if rng.random() < 0.1 else 1, min(3, len(in_bin))) if in_bin else 0
    return tuple(rng.sample(in_bin, k))


@settings(max_examples=200, deadline=None)
@given(cells())
def test_every_decision_is_legal_and_every_run_completes(case):
    plans, capacity, policy, seed = case
    rng = random.Random(seed)
    joint = combine_products(plans)
    seq = MultiSequencer(joint, make_policy(policy, capacity=capacity), buffer_capacity=capacity, budget=None)
    for _ in range(3000):
        state = seq.state
        if state.is_complete:
            break
        look = random_look(rng, state)
        d = seq.decide(look)
        a = d.action
        kind, fixture = split_action(a)
        if a.kind == "install":
            # the kind was visible (or buffered), its fixture still needs it, and it can go in there now
            assert kind in (look if a.source == "bin" else state.buffer)
            assert state.schedule.remaining.get(a.part, 0) > 0
            assert state.schedule.can_install(a.part)
        elif a.kind == "buffer":
            assert kind in look and fixture is None and len(state.buffer) < (capacity if capacity is not None else 99)
            # nothing visible or buffered could go on any fixture
            assert not any(state.schedule.can_install(u) for u in joint.part_ids
                           if kind_of(u) in set(look) | set(state.buffer))
        else:
            assert a.kind == "shake"
        outcome = rng.choice(["success"] * 6 + ["failed", "defective"]) if a.kind != "shake" else "success"
        seq.report(outcome)
    assert seq.state.is_complete
    assert seq.step(()).action.kind == "done"
    assert seq.state.buffer == ()
    for i, plan in enumerate(plans, 1):   # each fixture built its own product in an admissible order
        assert any(respects(restrict(seq.state.installed, i), s) for s in plan.strategies)
    assert all(f["complete"] for f in seq.state.to_dict()["fixtures"])


@settings(max_examples=150, deadline=None)
@given(st.lists(small_plans(max_parts=3, max_units=3), min_size=2, max_size=3), st.integers(0, 2**32))
def test_the_paper_rule_keeps_the_most_options_across_products(plans, seed):
    rng = random.Random(seed)
    joint = combine_products(plans)
    seq = MultiSequencer(joint, make_policy("paper"), budget=None)
    while not seq.state.is_complete:
        state = seq.state
        look = random_look(rng, state)
        a = seq.decide(look).action
        if a.kind == "install":
            # every legal (kind, fixture): a visible or buffered kind on a fixture that can take it now
            legal = [u for u in joint.part_ids if kind_of(u) in set(look) | set(state.buffer)
                     and state.schedule.can_install(u)]
            best = max(joint_options(plans, state.installed, u) for u in legal)
            assert joint_options(plans, state.installed, a.part) == best
            if joint.n_units <= 7:   # and straight from the joint plan's sequences
                assert brute_count(joint, (*state.installed, a.part)) == best
        elif a.kind == "buffer" and joint.n_units <= 7:
            # the kind needed earliest by any product: least expected position of any of its units
            completions = brute_sequences(joint, state.installed)
            def earliest(kind, completions=completions):
                return min(Fraction(sum(c.index(u) + 1 for c in completions), len(completions))
                           for u in joint.part_ids if kind_of(u) == kind and u in completions[0])
            assert earliest(a.part) == min(earliest(k) for k in set(look))
        seq.report("success")


@settings(max_examples=150, deadline=None)
@given(random_plans(max_parts=5, max_units=6, max_strategies=2), st.sampled_from([None, 0, 1, 2]),
       st.sampled_from(["paper", "lookahead", "slack"]), st.integers(0, 2**32))
def test_one_fixture_decides_as_today(plan, capacity, policy, seed):
    rng = random.Random(seed)
    # (the look-ahead scores its actions in a world with the cell's buffer: give it the capacity)
    one = Sequencer(plan, make_policy(policy, capacity=capacity), buffer_capacity=capacity, budget=None)
    cell = MultiSequencer(several_products(plan, 1), make_policy(policy, capacity=capacity), buffer_capacity=capacity,
                          budget=None)
    for _ in range(200):
        if one.state.is_complete:
            break
        look = random_look(rng, one.state)
        a, b = one.decide(look).action, cell.decide(look).action
        assert (a.kind, a.source) == (b.kind, b.source)
        assert a.part == (kind_of(b.part) if b.kind == "install" else b.part)
        if b.kind == "install":
            assert split_unit(b.part)[1] == 1
        one.report("success")
        cell.report("success")
    assert cell.state.is_complete == one.state.is_complete


def test_two_buffered_units_of_one_part_fill_two_locations():
    # Two units of p2 on the one fixture, both buffered: the policy must see both (a view that merged them
    # showed the optimum a free location, and it buffered p4 into a full buffer).
    plan = make_plan(["p0", "p1", {"id": "p2", "quantity": 2}, "p3", "p4"], {"p2": ["p1"], "p4": ["p2"]})
    for policy in ("lookahead", "paper", "slack"):
        one = Sequencer(plan, make_policy(policy, capacity=2), buffer_capacity=2, budget=None)
        cell = MultiSequencer(several_products(plan, 1), make_policy(policy, capacity=2), buffer_capacity=2,
                              budget=None)
        for look in (("p3",), ("p2",), ("p2",), ("p0",), ("p4",)):
            a, b = one.step(look).action, cell.step(look).action
            assert (a.kind, a.source) == (b.kind, b.source)
        assert cell.state.buffer.count("p2") == 2 and cell.state.buffer_free == 0
        view, units = cell.state.view(("p2", "p2", "p4"))
        assert view.buffer == ("p2@1", "p2@1") and units == ("p2@1", "p2@1", "p4@1")
        assert b.kind != "buffer"


def test_looks_of_kinds_are_checked():
    cell = MultiSequencer(several_products(GEARBOX, 2), budget=None)
    with pytest.raises(LookError, match="part kinds"):
        cell.decide(["ca@1"])
    with pytest.raises(LookError, match="unknown part"):
        cell.decide(["zz"])
    with pytest.raises(LookError, match="3 of part 'ca' but only 2"):
        cell.decide(["ca", "ca", "ca"])
    assert cell.state.installed == () and cell.pending is None   # refused looks change nothing
    d = cell.decide(["ca", "ca"])
    assert d.action.part in ("ca@1", "ca@2") and d.to_dict()["action"]["part"] == d.action.part


def test_a_buffered_kind_goes_to_the_fixture_that_needs_it():
    # a then b on each of two fixtures: b seen first is buffered as a kind, and goes to the fixture given an a
    plan = make_plan(["a", "b"], {"b": ["a"]})
    cell = MultiSequencer(several_products(plan, 2), budget=None)
    assert str(cell.step(["b"]).action) == "buffer b"            # a kind, no fixture yet
    assert cell.state.in_bin == {"a": 2, "b": 1}
    assert str(cell.step(["a"]).action) == "install a@1"
    d = cell.step([])
    assert (d.action.part, d.action.source) == ("b@1", "buffer")
    assert cell.state.buffer == () and cell.state.in_bin == {"a": 1, "b": 1}
    assert [f["installed"] for f in cell.state.fixtures()] == [["a", "b"], []]


# ---------------------------------------------------------------- the study


def test_the_fast_trial_loop_matches_the_sequencer():
    plans = (GEARBOX,) * 2
    config = ProductsConfig(plans, trials=5, buffer_capacity=2, policies=("paper",))
    runner = CellRunner(combine_products(plans), "paper", config)
    for k in range(5):
        fast = runner.run(random.Random(trial_seed(0, k, 0)))
        world = make_world("uniform", visible=2)
        world.reset(kinds_in_bin(runner.engine.plan), random.Random(trial_seed(0, k, 0)))
        seq = MultiSequencer(runner.engine, make_policy("paper"), buffer_capacity=2, budget=None)
        order = runner.order
        motions = shakes = looks = 0
        while not seq.state.is_complete:
            look = tuple(sorted(world.look(), key=order.__getitem__))
            looks += 1
            a = seq.decide(look).action
            kind, _ = split_action(a)
            if a.kind == "shake":
                world.shake()
                shakes += 1
            else:
                if a.source != "buffer":
                    world.take(kind)
                motions += 1
            seq.report("success")
        assert (fast["motions"], fast["shakes"], fast["looks"]) == (motions, shakes, looks)


def test_one_product_is_the_same_in_every_mode():
    result = run_products(ProductsConfig((GEARBOX,), trials=30, policies=("paper",)))
    times = {mode: [t["time"] for t in trials] for (mode, _), trials in result.trials.items()}
    assert times["together"] == times["independent"] == times["serial"]


def test_two_fixtures_beat_one_after_another():
    config = ProductsConfig((GEARBOX,) * 2, trials=150, buffer_capacity=2, policies=("paper",))
    rows = {r["mode"]: r for r in run_products(config).summary()["rows"]}
    assert all(r["complete"] == 150 for r in rows.values())
    assert rows["together"]["time"]["ci95"][1] < rows["serial"]["time"]["ci95"][0]
    assert rows["together"]["buffer_max"] <= 2


def test_joint_plans_too_many_strategies_to_count_are_refused_unless_estimated():
    # 2 strategies on each of 4 fixtures: 16 combinations, beyond the 12 an exact union count takes
    plan = make_plan(["a", "b", "c"], strategies={"ab": {"b": ["a"]}, "ba": {"a": ["b"]}}, name="two-ways")
    with pytest.raises(ProductsError, match="16 combinations .* at most 12 .* --decision-budget"):
        run_products(ProductsConfig((plan,) * 4, trials=2, policies=("paper",)))
    rows = run_products(ProductsConfig((plan,) * 4, trials=2, policies=("paper",), decision_budget=0.01)
                        ).summary()["rows"]
    assert all(r["complete"] == 2 for r in rows)


# ---------------------------------------------------------------- command line


def test_cli_products_json():
    result = run_cli("simulate", "example:gearbox", "--products", "2", "--trials", "20", "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    assert doc["products"] == 2
    assert {(r["mode"], r["policy"]) for r in doc["rows"]} == {
        (m, p) for m in ("together", "independent", "serial") for p in ("paper", "lookahead")}
    assert all(r["complete"] == 20 for r in doc["rows"])


def test_cli_products_table():
    result = run_cli("simulate", "example:gearbox", "--products", "3", "--trials", "10", "--strategies", "paper")
    assert result.exit_code == 0, result.output
    assert "gearbox ×3" in result.output and result.output.count("paper") == 3   # a row per cell


@pytest.mark.parametrize("args, message", [
    (["--products", "0"], "from 1 to 16"),
    (["--products", "1000"], "from 1 to 16"),
    (["--products", "two"], "not a valid"),
    (["--products", "2", "--workers", "2"], "--workers does not apply"),
    (["--products", "2", "--strategies", "optimal"], "cannot run several products"),
    (["--products", "2", "--strategies", " , "], "empty"),
])
def test_cli_products_bad_input(args, message):
    result = run_cli("simulate", "example:gearbox", "--trials", "5", *args)
    assert result.exit_code != 0
    assert message in result.output


# ---------------------------------------------------------------- the service


def test_a_two_fixture_gearbox_run_over_http(tmp_path):
    """A run with ``"products": 2`` driven to completion over HTTP (in process, SQLite), every answer as the
    OpenAPI document says; the run's fixtures in its state; rebuilt the same from its log by a new app."""
    pytest.importorskip("fastapi")
    from conftest import GEARBOX as GEARBOX_FILE
    from fastapi.testclient import TestClient
    from test_openapi import Contract

    from opportune.service.app import create_app
    from opportune.service.auth import create_token
    from opportune.service.config import Settings
    from opportune.service.storage import Store

    url = f"sqlite:///{tmp_path / 'api.db'}"
    store = Store(url)
    token = create_token(store, cell="cell-a")[1]
    with TestClient(create_app(Settings(db_url=url), store)) as client:
        api = Contract(client.get("/openapi.json").json(), client)
        plan = api("uploadPlan", token, content=GEARBOX_FILE.read_text(),
                   headers={"Content-Type": "application/yaml"}).json()["id"]
        for bad in (0, 17, "2", 2.5, True):
            r = api("startRun", token, json={"plan": plan, "products": bad}, expect=422)
            assert "products" in r.text
        two_ways = api("uploadPlan", token, json={"name": "two-ways", "parts": ["a", "b"], "strategies": [
            {"name": "ab", "requires": {"b": ["a"]}}, {"name": "ba", "requires": {"a": ["b"]}}]}).json()["id"]
        # 16 combinations of strategies: beyond exact counting, so decided within the service's budget
        many = api("startRun", token, json={"plan": two_ways, "products": 4}, expect=201).json()
        answer = api("postLook", token, run_id=many["id"], json={"visible": ["a", "b"]}, expect=200).json()
        assert answer["action"]["kind"] == "install" and answer["fixture"] in (1, 2, 3, 4)
        run = api("startRun", token, json={"plan": plan, "products": 2, "policy": "paper", "buffer_capacity": 3},
                  expect=201).json()
        assert run["products"] == 2 and run["state"]["in_bin"]["ca"] == 2
        assert [f["fixture"] for f in run["state"]["fixtures"]] == [1, 2]
        rid = run["id"]
        r = api("postLook", token, run_id=rid, json={"visible": ["ca@1"]}, expect=422)   # a kind, not a unit
        bin_ = kinds_in_bin(several_products(GEARBOX, 2))
        rng = random.Random(7)
        for _ in range(500):
            look = rng.sample(bin_, min(2, len(bin_)))
            answer = api("postLook", token, run_id=rid, json={"visible": look}, expect=200).json()
            action = answer["action"]
            if action["kind"] == "install":
                assert answer["part_kind"] == kind_of(action["part"]) and answer["fixture"] in (1, 2)
                if action["source"] == "bin":
                    bin_.remove(answer["part_kind"])
            elif action["kind"] == "buffer":
                assert answer["fixture"] is None
                bin_.remove(action["part"])
            outcome = api("postOutcome", token, run_id=rid, json={"outcome": "success"}, expect=200).json()
            if outcome["run"]["status"] == "complete":      # complete at the last install of the last fixture
                break
        final = api("getRun", token, run_id=rid, expect=200).json()
        assert final["status"] == "complete" and not bin_
        assert all(f["complete"] and sorted(f["installed"]) == sorted(GEARBOX.part_ids)
                   for f in final["state"]["fixtures"])
        listed = api("listRuns", token, expect=200).json()["runs"]
        assert [x["products"] for x in listed if x["id"] == rid] == [2]
    with TestClient(create_app(Settings(db_url=url, decision_budget=None), Store(url))) as client:
        api = Contract(client.get("/openapi.json").json(), client)   # exact decisions: refused, nothing started
        r = api("startRun", token, json={"plan": two_ways, "products": 4}, expect=422)
        assert "at most 12" in r.json()["error"]["message"]
        assert len(api("listRuns", token, expect=200).json()["runs"]) == 2
    with TestClient(create_app(Settings(db_url=url), Store(url))) as client:   # a restart: rebuilt from the log
        api = Contract(client.get("/openapi.json").json(), client)
        again = api("getRun", token, run_id=rid, expect=200).json()
        assert again["state"] == final["state"] and again["rows"] == final["rows"]


def test_a_database_from_before_products_gains_the_column(tmp_path):
    """A service database made before several products at once (no `products` column) is brought up to date."""
    pytest.importorskip("sqlalchemy")
    from sqlalchemy import create_engine, inspect, text

    from opportune.service.storage import Store

    url = f"sqlite:///{tmp_path / 'old.db'}"
    Store(url)
    engine = create_engine(url)
    with engine.begin() as c:
        c.execute(text("ALTER TABLE runs DROP COLUMN products"))
    assert "products" not in {col["name"] for col in inspect(engine).get_columns("runs")}
    engine.dispose()
    Store(url)
    engine = create_engine(url)
    assert "products" in {col["name"] for col in inspect(engine).get_columns("runs")}
    engine.dispose()


# ---------------------------------------------------------------- hostile input


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.integers(-10**30, 10**30), st.floats(allow_nan=True), st.text(max_size=5), st.none(),
                 st.booleans(), st.lists(st.integers(), max_size=2)))
def test_any_number_of_products_is_taken_or_refused_clearly(n):
    try:
        joint = several_products(make_plan(["a", "b"], {"b": ["a"]}), n)
    except ProductsError as exc:
        assert "16" in str(exc) or "whole number" in str(exc)
    else:
        assert isinstance(n, (int, float)) and not isinstance(n, bool) and 1 <= n <= MAX_PRODUCTS
        assert joint.n_units == 2 * n


@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(st.sampled_from(["ca", "ba", "co", "ca@1", "zz", ""]), st.text(max_size=4),
                          st.integers(), st.none()), max_size=25))
def test_hostile_looks_are_refused_and_change_nothing(look):
    cell = MultiSequencer(several_products(GEARBOX, 2), budget=None)
    try:
        cell.decide(look)
    except LookError:
        assert cell.pending is None and cell.state.installed == () and cell.trace == []
    else:
        assert all(k in GEARBOX.part_ids for k in look) and all(look.count(k) <= 2 for k in look)


def test_the_docstring_examples_hold():
    import doctest

    import opportune.multi
    import opportune.planning.products
    import opportune.study.simulate_products

    for module in (opportune.planning.products, opportune.multi, opportune.study.simulate_products):
        failed, tried = doctest.testmod(module)
        assert tried and not failed, module.__name__
