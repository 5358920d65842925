"""The service's parts in-process: graph layout, tickets, request hashing, log redaction, error shapes, replay."""

from __future__ import annotations

import logging
import time

import pytest
from hypothesis import given, settings

from conftest import GEARBOX, CpuTime, random_plans
from opportune import load_plan
from opportune.formats.summary import summarize
from opportune.service import idempotency as idem
from opportune.service.auth import Authenticator, create_token
from opportune.service.errors import ApiError, from_validation
from opportune.service.graph import layout, layouts
from opportune.service.server import RedactCredentials, redact
from opportune.service.storage import Store


def test_gearbox_layout_is_layered_left_to_right():
    plan = load_plan(GEARBOX)
    (g,) = layouts(plan, summarize(plan))
    nodes = {n["id"]: n for n in g["nodes"]}
    assert [nodes[p]["layer"] for p in ("ca", "ba", "sm", "rl", "co", "st")] == [0, 1, 1, 2, 3, 4]
    assert len(g["edges"]) == 14
    for e in g["edges"]:
        xs = [p[0] for p in e["points"]]
        assert xs == sorted(xs) and len(set(xs)) == len(xs)  # every edge runs forward, one column a step
        assert e["points"][0] == [nodes[e["from"]]["x"], nodes[e["from"]]["y"]]
        assert e["points"][-1] == [nodes[e["to"]]["x"], nodes[e["to"]]["y"]]
    assert 0 < max(n["x"] for n in nodes.values()) < g["width"] and 0 < max(n["y"] for n in nodes.values()) < g["height"]


@settings(max_examples=40, deadline=None)
@given(random_plans(max_parts=8))
def test_layouts_place_every_part_once_without_overlap(plan):
    for s, g in zip(summarize(plan)["strategies"], layouts(plan, summarize(plan))):
        assert [n["id"] for n in g["nodes"]] == list(plan.part_ids)
        spots = [(n["x"], n["y"]) for n in g["nodes"]]
        assert len(set(spots)) == len(spots)
        layer = {n["id"]: n["layer"] for n in g["nodes"]}
        assert all(layer[b] < layer[a] for b, a in s["minimal"])


def test_deep_plans_do_not_recurse():
    from opportune import make_plan

    ids = [f"p{i}" for i in range(1200)]
    plan = make_plan(ids, {ids[i]: [ids[i - 1]] for i in range(1, len(ids))})
    g = layout(plan, [[ids[i - 1], ids[i]] for i in range(1, len(ids))])
    assert g["nodes"][-1]["layer"] == 1199


@pytest.fixture()
def store(tmp_path):
    s = Store(f"sqlite:///{tmp_path / 'u.db'}")
    yield s
    s.dispose()


def test_tickets_are_bound_to_a_run_a_token_and_a_time(store):
    auth = Authenticator(store, ticket_seconds=60)
    token_id, token = create_token(store, cell="c1")
    p = auth.token(token)
    assert p.cell == "c1" and auth.bearer(f"Bearer {token}") == p and auth.bearer(f"Basic {token}") is None
    assert auth.token(token + "x") is None
    t = auth.ticket(p, 5)
    assert auth.from_ticket(t, 5) == p
    assert auth.from_ticket(t, 6) is None
    tid, run, expiry, mac = t.split(".")
    assert auth.from_ticket(f"{tid}.{run}.{int(expiry) + 1000}.{mac}", 5) is None  # extended: signature breaks
    assert Authenticator(store, ticket_seconds=-1).from_ticket(Authenticator(store, ticket_seconds=-1).ticket(p, 5), 5) is None
    from opportune.service.auth import revoke_token

    revoke_token(store, token_id)
    assert auth.from_ticket(t, 5) is None  # a revoked token's tickets stop at once
    assert Authenticator(store).token(token) is None


def test_request_hash_ignores_layout_not_content():
    a = idem.request_hash("POST", "/runs/1/looks", {"visible": ["a", "b"]})
    assert a == idem.request_hash("POST", "/runs/1/looks", {"visible": ["a", "b"]})
    assert a != idem.request_hash("POST", "/runs/1/looks", {"visible": ["b", "a"]})
    assert a != idem.request_hash("POST", "/runs/2/looks", {"visible": ["a", "b"]})
    with pytest.raises(ApiError) as e:
        idem.check_key(None)
    assert e.value.status == 428
    assert idem.check_key(None, required=False) is None
    with pytest.raises(ApiError):
        idem.check_key("a\nb")


def test_credentials_in_urls_are_redacted_from_logs():
    assert redact("GET /runs/1/events?ticket=abc.1.2.xyz HTTP/1.1") == "GET /runs/1/events?ticket=REDACTED HTTP/1.1"
    assert redact("/x?a=1&token=opp_secret&b=2") == "/x?a=1&token=REDACTED&b=2"
    record = logging.LogRecord("uvicorn.access", logging.INFO, __file__, 1, '%s - "%s %s HTTP/%s" %d',
                               ("127.0.0.1:1", "GET", "/runs/1/events?ticket=s3cret", "1.1", 200), None)
    assert RedactCredentials().filter(record) and "s3cret" not in record.getMessage()


def test_validation_errors_say_where():
    err = from_validation([{"type": "string_type", "loc": ("body", "visible", 2), "msg": "Input should be a valid string"}])
    assert err.status == 422 and err.where == "body.visible[2]" and "valid string" in err.message
    err = from_validation([{"type": "json_invalid", "loc": ("body", 12), "msg": "JSON decode error",
                            "ctx": {"error": "Expecting value"}}])
    assert err.status == 400 and err.code == "malformed_json" and "character 12" in err.message


def test_sqlite_store_is_wal_and_durable(store):
    assert store.journal_mode() == "wal"
    with store.reader.connect() as c:
        assert c.exec_driver_sql("PRAGMA synchronous").scalar() == 2  # FULL
        assert c.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1


def test_a_replay_that_disagrees_with_the_record_is_refused(store):
    """If a later version decided differently, resuming must stop rather than re-interpret the robot's history."""
    import json

    from sqlalchemy import update

    from opportune.service.auth import Principal
    from opportune.service.plans import PlanBook, check_upload, store_plan
    from opportune.service.runs import RunManager
    from opportune.service.storage import events

    result, fmt, source = check_upload(GEARBOX.read_bytes(), "application/yaml", "g.yaml", "yaml")
    create_token(store, cell="c1")
    pid, _ = store_plan(store, result, fmt, source, "c1")
    me = Principal("t", "cell", "c1")
    m = RunManager(store, PlanBook(store))
    run = json.loads(m.create(me, {"plan": pid}, "k1", "/runs")[1])
    m.command(me, run["id"], "look", {"visible": ["rl", "ra"]}, "k2", "/x")
    m.command(me, run["id"], "outcome", {"outcome": "success", "keep": "bin"}, "k3", "/y")
    assert m.view(me, run["id"])["state"]["buffered"] == ["rl"]
    with store.write() as c:  # pretend the recorded decision was another one
        answer = json.loads(c.execute(events.select().where(events.c.seq == 1)).first().response)
        answer["action"] = {"kind": "buffer", "part": "ra", "source": None}
        c.execute(update(events).where(events.c.seq == 1).values(response=json.dumps(answer)))
    fresh = RunManager(store, PlanBook(store))  # a restarted server
    with pytest.raises(ApiError) as e:
        fresh.view(me, run["id"])
    assert e.value.status == 500 and e.value.code == "run_replay_mismatch"
    assert "decides buffer rl" in e.value.message and "'part': 'ra'" in e.value.message
    other = Principal("t2", "cell", "c2")
    with pytest.raises(ApiError) as e:
        fresh.view(other, run["id"])
    assert e.value.status == 404


def test_stored_answers_are_forgotten_after_their_time(store):
    """Idempotency records do not pile up forever: past ``keep_answers`` they are deleted (at most once a
    minute, with a later write); a fresh one stays, and a retry after the clean-up is judged afresh."""
    import json

    from sqlalchemy import func, select, update

    from opportune.service.auth import Principal
    from opportune.service.plans import PlanBook, check_upload, store_plan
    from opportune.service.runs import RunManager
    from opportune.service.storage import idempotency

    result, fmt, source = check_upload(GEARBOX.read_bytes(), "application/yaml", "g.yaml", "yaml")
    create_token(store, cell="c1")
    pid, _ = store_plan(store, result, fmt, source, "c1")
    me = Principal("t", "cell", "c1")
    m = RunManager(store, PlanBook(store), keep_answers=3600.0)
    first = json.loads(m.create(me, {"plan": pid}, "old", "/runs")[1])
    with store.write() as c:  # the first answer is two hours old
        c.execute(update(idempotency).where(idempotency.c.key == "old").values(created_at=time.time() - 7200))

    def keys():
        with store.read() as c:
            return {r.key for r in c.execute(select(idempotency.c.key))}

    assert m.create(me, {"plan": pid}, "old", "/runs")[2] is True  # still there: replayed
    m.command(me, first["id"], "look", {"visible": ["ca", "ba"]}, "k2", "/runs/1/looks")
    assert keys() == {"old", "k2"}  # the clean-up ran at the first write, before "old" aged: a minute later
    m._next_forget = 0.0             # ... it runs again
    m.command(me, first["id"], "outcome", {"outcome": "success"}, "k3", "/runs/1/outcomes")
    assert keys() == {"k2", "k3"}
    status, text, replayed = m.create(me, {"plan": pid}, "old", "/runs")  # judged afresh: a new run
    assert status == 201 and not replayed and json.loads(text)["id"] != first["id"]
    with store.read() as c:
        assert c.execute(select(func.count()).select_from(idempotency)).scalar() == 3


def test_a_plan_too_large_to_count_is_refused_clearly(store):
    import json

    from opportune import make_plan
    from opportune.service.auth import Principal
    from opportune.service.plans import PlanBook, store_plan
    from opportune.service.runs import RunManager
    from opportune.formats.loader import CheckResult

    import random

    rng = random.Random(1)  # 30 parts each needing 3 of 30 others: far too many states to count in 0.05 s
    bottom, top = [f"b{i}" for i in range(30)], [f"t{i}" for i in range(30)]
    wide = make_plan(bottom + top, {t: rng.sample(bottom, 3) for t in top}, name="wide")
    create_token(store, cell="c1")
    pid, _ = store_plan(store, CheckResult(wide, []), "json", json.dumps(wide.to_dict()), "c1")
    me = Principal("t", "cell", "c1")
    m = RunManager(store, PlanBook(store, count_seconds=0.05))
    with CpuTime() as cpu, pytest.raises(ApiError) as e:
        m.create(me, {"plan": pid}, "k1", "/runs")
    assert cpu.seconds < 5
    assert e.value.code == "plan_too_large" and e.value.status == 503 and "retry" in e.value.hint
    assert m.list(me) == []  # nothing was stored


def test_with_a_decision_budget_a_plan_too_large_to_count_runs_on_estimates_and_resumes(store):
    """The same wide plan, with a decision budget: the run starts, its looks are answered with estimated
    decisions (marked so), and a restarted server resumes it from the recorded actions."""
    import json
    import random

    from opportune import make_plan
    from opportune.formats.loader import CheckResult
    from opportune.service.auth import Principal
    from opportune.service.plans import PlanBook, store_plan
    from opportune.service.runs import RunManager

    rng = random.Random(1)
    bottom, top = [f"b{i}" for i in range(30)], [f"t{i}" for i in range(30)]
    wide = make_plan(bottom + top, {t: rng.sample(bottom, 3) for t in top}, name="wide")
    create_token(store, cell="c1")
    pid, _ = store_plan(store, CheckResult(wide, []), "json", json.dumps(wide.to_dict()), "c1")
    me = Principal("t", "cell", "c1")
    m = RunManager(store, PlanBook(store, count_seconds=0.05), budget=0.02, warm_up=0.05)
    # the paper's rule asks for counts (the default decides by its frontier window, which needs none)
    run = json.loads(m.create(me, {"plan": pid, "policy": "paper"}, "k1", "/runs")[1])
    estimated = 0
    for i, look in enumerate([["t0", "t1", "t2"], ["b3", "b4", "t5"], ["b7", "t8", "b9"]]):
        answer = json.loads(m.command(me, run["id"], "look", {"visible": look}, f"l{i}", "/x")[1])
        estimated += answer["decision"]["exact"] is False
        m.command(me, run["id"], "outcome", {"outcome": "success"}, f"o{i}", "/y")
    assert estimated >= 1
    before = m.view(me, run["id"])["state"]
    fresh = RunManager(store, PlanBook(store, count_seconds=0.05), budget=0.02, warm_up=0.05)   # a restart
    assert fresh.view(me, run["id"])["state"] == before
    rows = fresh.trace(me, run["id"])["rows"]
    assert [r["action"] for r in rows] == [r["action"] for r in m.trace(me, run["id"])["rows"]]
    assert any(r["reasons"]["exact"] is False and r["reasons"]["estimates"] for r in rows)   # as recorded


def test_a_database_from_before_plan_owners_gives_each_cell_the_plans_it_ran(tmp_path):
    """Opening a database whose plans have no owners yet: every cell owns the plans it has runs of (and
    only those); a plan nobody ran is seen by operators only, until a cell uploads it again."""
    from dataclasses import replace

    from sqlalchemy import delete, insert, select

    from opportune.formats.loader import CheckResult
    from opportune.service.auth import Principal
    from opportune.service.plans import check_upload, list_plans, may_see, store_plan
    from opportune.service.storage import now, plan_owners, runs

    url = f"sqlite:///{tmp_path / 'old.db'}"
    store = Store(url)
    for cell in ("c1", "c2"):
        create_token(store, cell=cell)
    result, fmt, source = check_upload(GEARBOX.read_bytes(), "application/yaml", "g.yaml", "yaml")
    ran, _ = store_plan(store, result, fmt, source, "c1")
    idle, _ = store_plan(store, CheckResult(replace(load_plan(GEARBOX), name="never run"), []), "json", "{}", "c1")
    with store.write() as c:
        c.execute(insert(runs).values(cell="c2", plan_id=ran, units=10, created_at=now(), updated_at=now()))
        c.execute(delete(plan_owners))                  # as a database made before owners existed
    store.dispose()
    store = Store(url)
    try:
        with store.read() as c:
            assert c.execute(select(plan_owners.c.plan_id, plan_owners.c.cell)).all() == [(ran, "c2")]
        c1, c2, op = Principal("t1", "cell", "c1"), Principal("t2", "cell", "c2"), Principal("t3", "operator")
        assert may_see(store, c2, ran) and not may_see(store, c1, ran) and not may_see(store, c2, idle)
        assert may_see(store, op, idle) and [p["id"] for p in list_plans(store, c2)] == [ran]
        assert {p["id"]: p["owners"] for p in list_plans(store, op)} == {ran: ["c2"], idle: []}
        assert store_plan(store, result, fmt, source, "c1") == (ran, True)     # new to c1, not to the store
    finally:
        store.dispose()
