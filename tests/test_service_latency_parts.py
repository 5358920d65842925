"""The parts of a look that grow with the plan stay bounded: counts written as text, the parts installable
among those asked about, a set's elements, the tables that find installable units, a wide antichain's
count, and a look's answer stored once (each checked against a second, plain computation)."""

from __future__ import annotations

import random
from math import factorial, prod

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opportune import make_plan
from opportune.engine import OrderEngine
from opportune.engine import poset as poset_module
from opportune.engine.count import Counter
from opportune.engine.poset import Poset, bits, byte_unions
from opportune.engine.schedule import EXACT_DIGITS, count_text, decimal
from opportune.service.latency import LEAST, Reserves


# ---------------------------------------------------------------- counts as text

@settings(max_examples=200, deadline=None)
@given(st.one_of(st.integers(0, 10**60), st.integers(1, 60_000).map(lambda b: (1 << b) - 1),
                 st.integers(4_290, 4_310).map(lambda e: 10**e), st.integers(4_290, 4_310).map(lambda e: 10**e - 1),
                 st.integers(1, 40_000).flatmap(lambda b: st.integers(1 << (b - 1), (1 << b) - 1))))
def test_a_count_is_written_exactly_up_to_its_bound_and_by_its_first_17_digits_past_it(n):
    exact = decimal(n)
    text = count_text(n)
    if len(exact) <= EXACT_DIGITS:
        assert text == exact
    else:
        assert text == f"{exact[0]}.{exact[1:17]}e+{len(exact) - 1}"


def test_a_decision_past_the_bound_is_written_rounded_only_when_asked():
    from opportune.policies.printable import printable_decision
    from opportune.sequencer import Sequencer

    seq = Sequencer(make_plan([f"p{i}" for i in range(2000)], {}), budget=None)
    decision = seq.decide(["p1", "p2"])
    exact = printable_decision(decision)
    rounded = printable_decision(decision, EXACT_DIGITS)
    full = decimal(factorial(1999))
    assert [c.options for c in exact.candidates] == [full, full]
    assert [c.options for c in rounded.candidates] == [f"{full[0]}.{full[1:17]}e+{len(full) - 1}"] * 2
    assert full not in rounded.explain() and full[:17] in exact.explain().replace("\n", "")


# ---------------------------------------------------------------- a set's elements, tables

@settings(max_examples=300, deadline=None)
@given(st.integers(1, 5000).flatmap(lambda n: st.tuples(st.just(n), st.integers(0, (1 << n) - 1))),
       st.integers(0, 6))
def test_bits_lists_every_set_bit_in_order_dense_or_sparse(nm, thin):
    n, mask = nm
    rng = random.Random(mask % 1000)
    for _ in range(thin):   # thinner and thinner: the sparse path on wide masks
        mask &= rng.getrandbits(n)
    assert list(bits(mask)) == [i for i in range(n) if mask >> i & 1]


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(0, 2**40 - 1), min_size=1, max_size=40))
def test_tables_of_four_bits_and_of_eight_give_the_same_unions(sets):
    n = len(sets)
    eight, four = byte_unions(sets, n), byte_unions(sets, n, width=4)
    rng = random.Random(n)
    for _ in range(20):
        s = rng.getrandbits(n)
        want = 0
        for i in bits(s):
            want |= sets[i]
        by8 = by4 = 0
        for j, byte in enumerate(s.to_bytes((n + 7) // 8, "little")):
            by8 |= eight[j][byte]
            by4 |= four[2 * j][byte & 15] | (four[2 * j + 1][byte >> 4] if 2 * j + 1 < len(four) else 0)
        assert by8 == by4 == want


def _layered_plan(n: int, seed: int):
    rng = random.Random(seed)
    requires = {f"t{i}": [f"t{j}" for j in rng.sample(range(max(0, i - 12), i), min(i, rng.randint(0, 2)))]
                for i in range(n)}
    return make_plan([f"t{i}" for i in range(n)], {k: v for k, v in requires.items() if v})


@pytest.mark.parametrize("n", [300, 2500])
def test_installable_parts_among_those_asked_are_those_with_no_predecessor_left(n):
    """Below and above the size where the tables switch to four bits; the answer for a few parts asked
    about comes without listing every installable part, and equals the plain definition."""
    engine = OrderEngine(_layered_plan(n, n))
    engine.prepare()
    rng = random.Random(n)
    below = engine.posets[0].below
    mask = 0
    for _ in range(6):
        for _ in range(rng.randint(1, n // 6)):   # install some installable units
            can = engine.installable_units(mask, engine.all_strategies)
            mask |= 1 << rng.choice(list(bits(can)))
        remaining = engine.full & ~mask
        plain = [u for u in range(n) if remaining >> u & 1 and not below[u] & remaining]
        assert list(bits(engine.installable_units(mask, engine.all_strategies))) == plain
        asked = rng.sample(engine.plan.part_ids, 40)
        asked += asked[:5]                     # a look may name a part twice (two units of it seen)
        want = [engine.plan.part_ids[u] for u in plain if engine.plan.part_ids[u] in asked]
        fresh = OrderEngine(engine.plan)       # its entry for this state is new: no list of all parts
        assert fresh.installable_among(mask, fresh.all_strategies, asked) == want
        assert engine.installable(mask, engine.all_strategies) == tuple(engine.plan.part_ids[u] for u in plain)
        assert engine.installable_among(mask, engine.all_strategies, asked) == want   # from the full list


def test_options_of_parts_with_several_units_follow_their_next_unit():
    plan = make_plan([{"id": "a", "quantity": 3}, "b", {"id": "c", "quantity": 2}], {"c": ["a"]})
    engine = OrderEngine(plan)
    mask = 0
    for step in ("a", "b", "a"):
        full = engine.options(mask, engine.all_strategies)
        assert OrderEngine(plan).options_for(mask, engine.all_strategies, ("c", "a", "zzz")) == \
            {p: n for p, n in full.items() if p in ("a", "c")}
        mask |= 1 << engine.next_unit(mask, plan.index(step))


def test_prepare_builds_the_tables_so_that_no_decision_does(monkeypatch):
    engine = OrderEngine(_layered_plan(400, 3))
    built = []
    real = poset_module.byte_unions
    monkeypatch.setattr("opportune.engine.questions.byte_unions", lambda *a, **k: built.append(1) or real(*a, **k))
    engine.warm_up(0.2)                       # the tables first, then counting (done or not)
    assert built == [1]
    engine.installable_units(0, engine.all_strategies)
    assert built == [1]                       # nothing more built at a decision


# ---------------------------------------------------------------- a wide set's count

@pytest.mark.parametrize("seed", range(4))
def test_a_wide_set_of_lone_elements_and_chains_counts_as_its_multinomial(seed):
    """Past the narrow scans (more than 64 elements): lone elements and chains, counted by the wide
    branch, against the multinomial n! / (c1! c2! ...) for chains of lengths c1, c2, ..."""
    rng = random.Random(seed)
    lengths = [rng.randint(1, 4) for _ in range(rng.randint(30, 120))]
    pairs, at = [], 0
    for k in lengths:
        pairs += [(at + i, at + i + 1) for i in range(k - 1)]
        at += k
    n = at
    got = Counter(Poset.from_pairs(n, pairs)).count()
    assert got == factorial(n) // prod(factorial(k) for k in lengths)
    assert Counter(Poset.from_pairs(n, [])).count() == factorial(n)    # an antichain


# ---------------------------------------------------------------- a look's answer, stored once

def test_a_looks_answer_is_stored_once_and_a_retry_gets_the_same_bytes(tmp_path):
    from fastapi.testclient import TestClient
    from sqlalchemy import select

    from opportune.service.app import create_app
    from opportune.service.auth import create_token
    from opportune.service.config import Settings
    from opportune.service.storage import Store, events, idempotency

    url = f"sqlite:///{tmp_path / 's.db'}"
    store = Store(url)
    auth = {"Authorization": f"Bearer {create_token(store, cell='c')[1]}"}
    app = create_app(Settings(db_url=url), store)
    with TestClient(app) as client:
        plan = client.post("/plans", json={"parts": ["a", "b", "c"]}, headers={**auth, "Idempotency-Key": "p"}).json()
        run = client.post("/runs", json={"plan": plan["id"]}, headers={**auth, "Idempotency-Key": "r"}).json()
        first = client.post(f"/runs/{run['id']}/looks", json={"visible": ["b"]}, headers={**auth, "Idempotency-Key": "l"})
        again = client.post(f"/runs/{run['id']}/looks", json={"visible": ["b"]}, headers={**auth, "Idempotency-Key": "l"})
        assert first.status_code == again.status_code == 200
        assert again.content == first.content and again.headers["Idempotent-Replayed"] == "true"
        with store.read() as c:
            kept = c.execute(select(idempotency.c.response).where(idempotency.c.key == "l")).scalar_one()
            logged = c.execute(select(events.c.response).where(events.c.run_id == run["id"])).scalars().all()
        assert kept == f"@event {run['id']} 1" and logged == [first.text]
        # the seconds an answer takes to leave, once returned, were measured and are kept in reserve
        assert app.state.manager.reserves.outside() > 0
    store.dispose()


def test_the_time_an_answer_takes_to_leave_is_added_to_every_plans_reserve():
    r = Reserves(0.05)
    for _ in range(10):
        r.measured("a", after_decision=0.004, after_counts=0.002)
    assert r.after_decision("a") == pytest.approx(0.004)
    for _ in range(10):
        r.measured_outside(0.003)
    assert r.after_decision("a") == pytest.approx(0.007) and r.after_counts("a") == pytest.approx(0.005)
    assert r.after_decision("b") == pytest.approx(0.015 + 0.003)      # the first guess, plus the same
    assert Reserves(0.05).outside() == 0.0 and LEAST > 0
