"""The service's HTTP API against a real server on a loopback port, over a temporary SQLite file and
over a throwaway PostgreSQL server.

Table 1 of the paper driven over HTTP, idempotent retries, every bad input
(each refused with a JSON error and no change of state), access between
cells, concurrency, plan uploads and server-sent events.
"""

from __future__ import annotations

import json
import re
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest

from conftest import EXAMPLES, GEARBOX
from opportune import load_plan
from opportune.formats.looks import read_looks
from opportune.sequencer import Sequencer
from opportune.service.testing import Client, ServiceProcess
from test_sequencer import TABLE1

MAX_BODY = 64 * 1024


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def svc(request, tmp_path_factory):
    """The same API suite on both stores the service supports: a SQLite file and a PostgreSQL server."""
    where = tmp_path_factory.mktemp("svc")
    if request.param == "sqlite":
        db = where / "api.db"
    else:
        db = request.getfixturevalue("postgres").database("api")
    with ServiceProcess(db, max_body=MAX_BODY, log=where / "api.log") as s:
        yield s


@pytest.fixture(scope="module")
def tokens(svc):
    return {"a": svc.token(cell="cell-a"), "b": svc.token(cell="cell-b"), "op": svc.token(operator="ops")}


@pytest.fixture(scope="module")
def a(svc, tokens):
    c = Client(svc.url, tokens["a"])
    yield c
    c.close()


@pytest.fixture(scope="module")
def b(svc, tokens):
    c = Client(svc.url, tokens["b"])
    yield c
    c.close()


@pytest.fixture(scope="module")
def op(svc, tokens):
    c = Client(svc.url, tokens["op"])
    yield c
    c.close()


@pytest.fixture(scope="module")
def plan_id(a):
    r = a.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"}, key=False)
    assert r.status_code in (200, 201), r.text
    return r.json()["id"]


def new_run(client, plan_id, **extra) -> int:
    # the paper's rule: Table 1's looks were recorded under it (a run's default policy is the look-ahead)
    r = client.post("/runs", {"plan": plan_id, "policy": "paper", **extra})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def split(text):
    return [p for p in text.split(",") if p]


def library_trace(looks):
    """The trace the library itself gives for these looks (every action succeeding), without the closing
    ``done`` row: a run of the service is complete at its last install."""
    seq = Sequencer(load_plan(GEARBOX))
    return [row.to_dict() for row in seq.run(looks) if row.action.kind != "done"]


def strip(row):
    return {k: row[k] for k in ("visible", "buffered", "installed", "action", "outcome")}


def drive_table1(client, run_id):
    for visible, buffered, installed, action in TABLE1:
        r = client.post(f"/runs/{run_id}/looks", {"visible": split(visible)})
        assert r.status_code == 200, r.text
        body = r.json()
        kind, part = action.split()
        assert (body["action"]["kind"], body["action"]["part"]) == (kind, part), (visible, body["decision"]["explain"])
        assert body["row"]["buffered"] == split(buffered) and body["row"]["installed"] == split(installed)
        assert body["run"]["pending"]["action_text"].startswith(action)
        r = client.post(f"/runs/{run_id}/outcomes", {"outcome": "success"})
        assert r.status_code == 200, r.text
        # complete at the outcome of its last install, not before
        assert (r.json()["run"]["status"] == "complete") == (installed.count(",") == 8), r.text
    assert r.json()["run"]["finished"] is True
    r = client.post(f"/runs/{run_id}/looks", {"visible": []})      # nothing more to look at
    assert r.status_code == 409 and r.json()["error"]["code"] == "run_complete", r.text


# ---------------------------------------------------------------- Table 1


def test_table1_over_http_gives_table1_actions(a, plan_id):
    run_id = new_run(a, plan_id, label="table 1")
    start = a.get(f"/runs/{run_id}").json()
    assert start["count"] == {"value": "336", "log10": pytest.approx(2.526339, abs=1e-6), "text": "336"}
    assert start["installable"] == ["ca"] and start["status"] == "active"
    drive_table1(a, run_id)
    run = a.get(f"/runs/{run_id}").json()
    assert run["status"] == "complete" and run["state"]["complete"]
    assert run["state"]["installed"] == ["ca", "ba", "rl", "dr", "sm", "ml", "ra", "co", "st", "cl"]
    assert run["count"]["value"] == "1" and run["progress"] == {"installed": 10, "units": 10}
    trace = a.get(f"/runs/{run_id}/trace").json()["rows"]
    expected = library_trace(read_looks(EXAMPLES / "gearbox-table1.looks"))
    assert [strip(r) for r in trace] == expected
    assert [r["n"] for r in trace] == list(range(1, 16))
    counts = [int(r["count"]["value"]) for r in trace]  # completions left before each action: never rising
    assert counts[0] == 336 and counts[-1] == 1 and all(x >= y for x, y in zip(counts, counts[1:]))
    # Complete: looks are refused and nothing changes.
    r = a.post(f"/runs/{run_id}/looks", {"visible": []})
    assert r.status_code == 409 and r.json()["error"]["code"] == "run_complete"
    assert a.get(f"/runs/{run_id}").json()["seq"] == run["seq"]
    listed = {x["id"]: x for x in a.get("/runs").json()["runs"]}
    assert listed[run_id]["status"] == "complete" and listed[run_id]["progress"]["installed"] == 10


def test_failed_and_defective_outcomes_follow_the_library(a, plan_id):
    run_id = new_run(a, plan_id, buffer_capacity=1)
    seq = Sequencer(load_plan(GEARBOX), buffer_capacity=1)
    steps = [(["ca", "co"], "failed", "bin"), (["ca", "co"], "defective", "bin"), (["ca"], "success", "bin"),
             (["rl", "st"], "failed", "buffer"), (["ba"], "success", "bin")]
    for visible, outcome, keep in steps:
        r = a.post(f"/runs/{run_id}/looks", {"visible": visible})
        assert r.json()["action"] == seq.decide(visible).action.to_dict()
        r = a.post(f"/runs/{run_id}/outcomes", {"outcome": outcome, "keep": keep})
        assert r.status_code == 200, r.text
        seq.report(outcome, keep=keep)
        assert r.json()["run"]["state"] == seq.state.to_dict()
    assert [strip(x) for x in a.get(f"/runs/{run_id}/trace").json()["rows"]] == [row.to_dict() for row in seq.trace]
    # A cancel drops the pending action and is itself an event.
    a.post(f"/runs/{run_id}/looks", {"visible": ["sm"]})
    r = a.post(f"/runs/{run_id}/cancel")
    assert r.status_code == 200 and r.json()["cancelled"]["action"]["part"] == "sm"
    assert a.get(f"/runs/{run_id}").json()["pending"] is None
    r = a.post(f"/runs/{run_id}/cancel")
    assert r.status_code == 409 and r.json()["error"]["code"] == "no_pending_action"


# ---------------------------------------------------------------- idempotency


def test_retries_with_the_same_key_return_the_same_answer_and_change_nothing(a, plan_id):
    r1 = a.post("/runs", {"plan": plan_id}, key="run-key-1")
    r2 = a.post("/runs", {"plan": plan_id}, key="run-key-1")
    assert r1.status_code == r2.status_code == 201
    assert r1.content == r2.content and r2.headers["Idempotent-Replayed"] == "true"
    assert "Idempotent-Replayed" not in r1.headers
    run_id = r1.json()["id"]
    assert sum(1 for x in a.get("/runs").json()["runs"] if x["id"] == run_id) == 1

    look1 = a.post(f"/runs/{run_id}/looks", {"visible": ["rl", "ra"]}, key="look-1")
    look2 = a.post(f"/runs/{run_id}/looks", {"visible": ["rl", "ra"]}, key="look-1")
    assert look1.status_code == look2.status_code == 200 and look1.content == look2.content
    # The same JSON written differently is the same request.
    look3 = a.post(f"/runs/{run_id}/looks", content=b'{ "visible" : ["rl","ra"] }', key="look-1",
                   headers={"Content-Type": "application/json"})
    assert look3.content == look1.content
    out1 = a.post(f"/runs/{run_id}/outcomes", {"outcome": "success"}, key="out-1")
    out2 = a.post(f"/runs/{run_id}/outcomes", {"outcome": "success"}, key="out-1")
    assert out1.content == out2.content
    state = a.get(f"/runs/{run_id}").json()
    assert state["seq"] == 2 and state["state"]["buffered"] == ["rl"]
    # Replaying an old look after the state moved on still answers from the store.
    assert a.post(f"/runs/{run_id}/looks", {"visible": ["rl", "ra"]}, key="look-1").content == look1.content
    # Same key, different request: refused, nothing changes.
    r = a.post(f"/runs/{run_id}/outcomes", {"outcome": "failed"}, key="out-1")
    assert r.status_code == 422 and r.json()["error"]["code"] == "idempotency_key_reused"
    r = a.post(f"/runs/{run_id}/looks", {"visible": ["ca"]}, key="look-1")
    assert r.status_code == 422
    assert a.get(f"/runs/{run_id}").json()["seq"] == 2
    assert len(a.get(f"/runs/{run_id}/trace").json()["rows"]) == 1


def test_keys_are_required_and_scoped_per_cell(a, b, plan_id):
    run_id = new_run(a, plan_id)
    r = a.post(f"/runs/{run_id}/looks", {"visible": ["ca"]}, key=False)
    assert r.status_code == 428 and r.json()["error"]["where"] == "header Idempotency-Key"
    r = a.post(f"/runs/{run_id}/looks", {"visible": ["ca"]}, key="x" * 201)
    assert r.status_code == 400 and r.json()["error"]["code"] == "bad_idempotency_key"
    assert a.get(f"/runs/{run_id}").json()["seq"] == 0
    # The same key in another cell is another request.
    ra = a.post("/runs", {"plan": plan_id}, key="shared-key")
    b.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"}, key=False)
    rb = b.post("/runs", {"plan": plan_id}, key="shared-key")
    assert ra.status_code == rb.status_code == 201 and ra.json()["id"] != rb.json()["id"]


# ---------------------------------------------------------------- bad input


def error_of(r, status):
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith("application/json")
    err = r.json()["error"]
    assert err["status"] == status and err["code"] and err["message"] and "Traceback" not in r.text
    return err


def test_every_bad_input_is_a_clear_json_error_and_changes_nothing(a, plan_id):
    run_id = new_run(a, plan_id)
    a.post(f"/runs/{run_id}/looks", {"visible": ["ca", "co"]})
    a.post(f"/runs/{run_id}/outcomes", {"outcome": "success"})
    before = (a.get(f"/runs/{run_id}").json(), a.get(f"/runs/{run_id}/trace").json())
    path = f"/runs/{run_id}/looks"
    json_headers = {"Content-Type": "application/json"}

    err = error_of(a.post(path, content=b'{"visible": ["ba",', headers=json_headers), 400)
    assert err["code"] == "malformed_json" and err["where"] == "body"
    err = error_of(a.post(path, content=b"", headers=json_headers), 422)
    err = error_of(a.post(path, {"visible": "ba"}), 422)
    assert err["where"] == "body.visible"
    err = error_of(a.post(path, {"visible": ["ba", 7]}), 422)
    assert err["where"] == "body.visible[1]"
    err = error_of(a.post(path, {"visible": ["ba"], "extra": 1}), 422)
    assert err["where"] == "body.extra" and "unknown field" in err["message"]
    err = error_of(a.post(path, {"visible": ["ba", "gera"]}), 422)
    assert err["code"] == "unknown_part" and err["where"] == "body.visible[1]" and "'gera'" in err["message"]
    err = error_of(a.post(path, {"visible": ["ca"]}), 409)  # ca is installed
    assert err["code"] == "look_contradicts_state" and "already installed" in err["message"]
    err = error_of(a.post(path, {"visible": ["ba", "ba"]}), 409)  # one ba in the plan
    assert "only 1 can be in the bin" in err["message"]
    err = error_of(a.post(f"/runs/{run_id}/outcomes", {"outcome": "success"}), 409)
    assert err["code"] == "no_pending_action" and "look" in err["hint"]
    err = error_of(a.post(f"/runs/{run_id}/outcomes", {"outcome": "great"}), 422)
    assert err["where"] == "body.outcome"
    err = error_of(a.post(f"/runs/{run_id}/outcomes", {}), 422)
    assert err["where"] == "body.outcome" and "required" in err["message"]
    big = {"visible": ["ba"] * (MAX_BODY // 4)}
    err = error_of(a.post(path, big), 413)
    assert err["code"] == "body_too_large" and str(MAX_BODY) in err["message"]
    err = error_of(a.post(path, content=b'{"visible": [' + b'"ba",' * 20000 + b'"ba"]}', headers=json_headers), 413)
    error_of(a.post("/runs/abc/looks", {"visible": []}), 422)
    error_of(a.post("/runs/999999/looks", {"visible": []}), 404)
    error_of(a.get("/no/such/route"), 404)
    error_of(a.http.delete(f"/runs/{run_id}"), 405)
    error_of(a.post("/runs", {"plan": "0" * 64}), 422)
    error_of(a.post("/runs", {"plan": plan_id, "buffer_capacity": -1}), 422)
    after = (a.get(f"/runs/{run_id}").json(), a.get(f"/runs/{run_id}/trace").json())
    assert after == before
    # A pending action: a second look is refused, the pending one stands.
    a.post(path, {"visible": ["ba"]})
    err = error_of(a.post(path, {"visible": ["sm"]}), 409)
    assert err["code"] == "action_pending"
    assert a.get(f"/runs/{run_id}").json()["pending"]["action"] == {"kind": "install", "part": "ba", "source": "bin"}


def test_plan_upload_is_checked_like_opportune_check(a, plan_id):
    bad = "name: bad\nparts: [ca, ba, rl]\nrequires:\n  ba: [rl]\n  rl: [ba]\n  ca: [cax]\n"
    err = error_of(a.post("/plans", content=bad, headers={"Content-Type": "application/yaml"}, key=False), 422)
    assert err["code"] == "invalid_plan"
    problems = err["problems"]
    assert any("cycle" in p["message"] for p in problems)
    unknown = [p for p in problems if "cax" in p["message"]]
    assert unknown and unknown[0]["line"] == 6 and unknown[0]["hint"]
    err = error_of(a.post("/plans", content="parts: [a, b\n", headers={"Content-Type": "application/yaml"}, key=False), 422)
    assert err["problems"][0]["code"] == "syntax" and err["problems"][0]["line"]
    error_of(a.post("/plans", content=b"\xff\xfe bad", headers={"Content-Type": "application/yaml"}, key=False), 422)
    error_of(a.post("/plans", content=b'{"parts": [', headers={"Content-Type": "application/json"}, key=False), 400)
    # The same plan as JSON, as a wrapper, and again as YAML: one id.
    doc = load_plan(GEARBOX).to_dict()
    r = a.post("/plans", doc, key=False)
    assert r.status_code == 200 and r.json()["id"] == plan_id and r.json()["created"] is False
    r = a.post("/plans", {"text": GEARBOX.read_text(), "format": "yaml", "filename": "gearbox.yaml"}, key=False)
    assert r.json()["id"] == plan_id
    r = a.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "text/plain"}, key=False)
    assert r.json()["id"] == plan_id
    # A SALBP .IN2 graph.
    in2 = "4\n1\n2\n3\n4\n1,2\n1,3\n2,4\n3,4\n-1,-1\n"
    r = a.post("/plans?format=in2&filename=TINY.IN2", content=in2, headers={"Content-Type": "text/plain"}, key=False)
    assert r.status_code == 201, r.text
    assert r.json()["parts"] == ["1", "2", "3", "4"] and r.json()["name"] == "TINY"
    got = a.get(f"/plans/{r.json()['id']}").json()
    assert got["summary"]["strategies"][0]["minimal"] == [["1", "2"], ["1", "3"], ["2", "4"], ["3", "4"]]
    assert [n["layer"] for n in got["graph"][0]["nodes"]] == [0, 1, 1, 2]
    error_of(a.get("/plans/" + "f" * 64), 404)


def test_shipped_plans_are_uploaded_and_run_by_name_and_nothing_else_is_opened(a, b, svc):
    """The names the command line takes (`salbp:ARC111`, `salbp:kilbrid`, `example:gearbox`) upload a shipped
    plan, or start a run of it, for the token's cell; any other name is a 422 naming what is shipped."""
    from opportune import datasets

    r = a.post("/plans", {"shipped": "salbp:ARC111"}, key=False)
    assert r.status_code in (200, 201), r.text
    arc = r.json()
    assert arc["name"] == "ARC111" and arc["format"] == "in2" and arc["units"] == len(datasets.salbp("ARC111").parts)
    assert arc["id"] in {p["id"] for p in a.get("/plans").json()["plans"]}
    # a run by name: the same plan, stored for the cell that starts it (cell b had not uploaded it)
    run = b.post("/runs", {"plan": "salbp:arc111", "policy": "paper"})
    assert run.status_code == 201, run.text
    assert run.json()["plan"] == {"id": arc["id"], "name": "ARC111"}
    assert arc["id"] in {p["id"] for p in b.get("/plans").json()["plans"]}
    gear = a.post("/runs", {"plan": "example:gearbox", "policy": "paper"})
    assert gear.status_code == 201 and gear.json()["count"]["value"] == "336", gear.text
    r = a.post(f"/runs/{gear.json()['id']}/looks", {"visible": ["ca", "rl"]})
    assert r.json()["action"] == {"kind": "install", "part": "ca", "source": "bin"}
    # only the shipped plans: not a path, not a looks file, not a misspelt name (which gets a suggestion)
    for name, where in [("salbp:../../etc/passwd", "body.plan"), ("example:gearbox-table1", "body.plan"),
                        ("salbp:ARC11", "body.plan"), ("example:/etc/passwd", "body.plan")]:
        err = error_of(a.post("/runs", {"plan": name}), 422)
        assert err["code"] == "unknown_plan" and err["where"] == where and "salbp:ARC111" in err["hint"], err
    assert "did you mean 'salbp:ARC111'?" in error_of(a.post("/runs", {"plan": "salbp:ARC11"}), 422)["hint"]
    err = error_of(a.post("/plans", {"shipped": "salbp:NOPE"}, key=False), 422)
    assert err["code"] == "unknown_plan" and err["where"] == "body.shipped"
    err = error_of(a.post("/plans", {"shipped": "salbp:ARC111", "text": "x"}, key=False), 422)
    assert err["code"] == "invalid_request"
    # a shipped example that is not a valid plan is refused as `opportune check` refuses it
    err = error_of(a.post("/plans", {"shipped": "example:gearbox-overconstrained"}, key=False), 422)
    assert err["code"] == "invalid_plan" and any(p["code"] == "cycle" for p in err["problems"])


def test_an_unknown_part_in_a_look_gets_the_suggestion_the_command_line_gives(a, plan_id, tmp_path):
    """One suggestion for a misspelt part, over HTTP and in `opportune replay` (case aside too)."""
    from typer.testing import CliRunner

    from opportune.cli import app

    run_id = new_run(a, plan_id)
    looks = tmp_path / "typo.looks"
    for typo, meant in [("RL", "rl"), ("rll", "rl"), ("cover", None)]:
        err = error_of(a.post(f"/runs/{run_id}/looks", {"visible": ["ca", typo]}), 422)
        assert err["code"] == "unknown_part" and err["where"] == "body.visible[1]"
        looks.write_text(f"ca {typo}\n")
        cli = CliRunner().invoke(app, ["replay", str(GEARBOX), str(looks)])
        assert cli.exit_code == 1
        if meant is None:
            assert "did you mean" not in err["hint"] and "did you mean" not in cli.output
        else:
            assert err["hint"].startswith(f"did you mean '{meant}'? ") and f"did you mean '{meant}'?" in cli.output
        assert err["hint"] in " ".join(cli.output.split()), (err["hint"], cli.output)


# ---------------------------------------------------------------- access


def test_access_is_refused_without_leaking(svc, a, b, op, plan_id):
    run_id = new_run(a, plan_id)
    anon = Client(svc.url, None)
    wrong = Client(svc.url, "opp_" + "x" * 43)
    try:
        for client in (anon, wrong):
            err = error_of(client.get(f"/runs/{run_id}"), 401)
            assert err["code"] == "unauthorized"
            assert error_of(client.get("/runs/999999"), 401) == err  # 401 before anything is looked up
            error_of(client.post(f"/runs/{run_id}/looks", {"visible": ["ca"]}), 401)
            error_of(client.post("/plans", content="parts: [a]", headers={"Content-Type": "application/yaml"}), 401)
            error_of(client.get(f"/runs/{run_id}/events"), 401)
        assert anon.get(f"/runs/{run_id}").headers["www-authenticate"] == "Bearer"
    finally:
        anon.close()
        wrong.close()
    # Another cell's run looks exactly like a run that does not exist.
    missing = 10**9
    for method, suffix, body in [("get", "", None), ("get", "/trace", None), ("get", "/graph", None),
                                 ("get", "/events", None), ("post", "/looks", {"visible": ["ca"]}),
                                 ("post", "/outcomes", {"outcome": "success"}), ("post", "/cancel", None),
                                 ("post", "/ticket", None)]:
        call = getattr(b, method)
        theirs = call(f"/runs/{run_id}{suffix}", **({"json": body} if body is not None else {}))
        nothing = call(f"/runs/{missing}{suffix}", **({"json": body} if body is not None else {}))
        assert theirs.status_code == nothing.status_code == 404, (suffix, theirs.text)
        assert theirs.text.replace(str(run_id), "N") == nothing.text.replace(str(missing), "N")
    assert run_id not in [x["id"] for x in b.get("/runs").json()["runs"]]
    assert run_id not in [x["id"] for x in b.get("/runs?cell=cell-a").json()["runs"]]
    assert [c["name"] for c in b.get("/cells").json()["cells"]] == ["cell-b"]
    err = error_of(b.post("/runs", {"plan": plan_id, "cell": "cell-a"}), 403)
    assert "cell-b" in err["message"]
    # The operator reads everything and drives nothing.
    assert op.get(f"/runs/{run_id}").status_code == 200
    assert run_id in [x["id"] for x in op.get("/runs").json()["runs"]]
    assert {"cell-a", "cell-b"} <= {c["name"] for c in op.get("/cells").json()["cells"]}
    error_of(op.post(f"/runs/{run_id}/looks", {"visible": ["ca"]}), 403)
    error_of(op.post("/runs", {"plan": plan_id}), 403)
    error_of(op.post(f"/runs/{missing}/looks", {"visible": ["ca"]}), 404)
    listed = {p["id"]: p for p in op.get("/plans").json()["plans"]}
    assert "cell-a" in listed[plan_id]["owners"]
    assert plan_id in [p["id"] for p in a.get("/plans").json()["plans"]]
    assert a.get(f"/runs/{run_id}").json()["seq"] == 0


def test_a_plan_belongs_to_the_cells_that_uploaded_it(svc, plan_id):
    """Cell B neither sees nor runs cell A's plan, exactly as if it did not exist; B's upload of the same
    plan says `created: true` (nothing about A), and from then on B runs it too; operators see both owners."""
    c = Client(svc.url, svc.token(cell="cell-own"))
    try:
        assert plan_id not in [p["id"] for p in c.get("/plans").json()["plans"]]
        theirs, nothing = c.get(f"/plans/{plan_id}"), c.get("/plans/" + "0" * 64)
        assert theirs.status_code == nothing.status_code == 404
        assert theirs.text.replace(plan_id, "N") == nothing.text.replace("0" * 64, "N")
        err = error_of(c.post("/runs", {"plan": plan_id}), 422)
        assert err["code"] == "unknown_plan"
        r = c.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"}, key=False)
        assert r.status_code == 201 and r.json()["created"] is True and r.json()["id"] == plan_id
        again = c.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"}, key=False)
        assert again.status_code == 200 and again.json()["created"] is False
        assert c.get(f"/plans/{plan_id}").status_code == 200
        assert c.post("/runs", {"plan": plan_id}).status_code == 201
        assert [p["id"] for p in c.get("/plans").json()["plans"]] == [plan_id]
    finally:
        c.close()


# ---------------------------------------------------------------- concurrency


def test_concurrent_requests_on_one_run_are_serialized(a, plan_id):
    run_id = new_run(a, plan_id)
    barrier = threading.Barrier(8)

    def look(_):
        barrier.wait()
        return a.post(f"/runs/{run_id}/looks", {"visible": ["ca", "co"]})

    with ThreadPoolExecutor(8) as pool:
        results = list(pool.map(look, range(8)))
    codes = sorted(r.status_code for r in results)
    assert codes == [200] + [409] * 7, [r.text for r in results]
    assert all(r.json()["error"]["code"] == "action_pending" for r in results if r.status_code == 409)
    assert a.get(f"/runs/{run_id}").json()["seq"] == 1


def test_runs_driven_at_once_each_follow_the_library(svc, plan_id):
    cells = [Client(svc.url, svc.token(cell=f"par-{i}")) for i in range(4)]
    for c in cells:     # each cell runs the plans it uploaded
        assert c.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"},
                      key=False).json()["id"] == plan_id
    try:
        runs = [new_run(c, plan_id) for c in cells]
        with ThreadPoolExecutor(4) as pool:
            list(pool.map(lambda cr: drive_table1(*cr), zip(cells, runs)))
        expected = library_trace(read_looks(EXAMPLES / "gearbox-table1.looks"))
        for c, run_id in zip(cells, runs):
            assert [strip(r) for r in c.get(f"/runs/{run_id}/trace").json()["rows"]] == expected
    finally:
        for c in cells:
            c.close()


# ---------------------------------------------------------------- server-sent events


def read_events(response, n, timeout=10.0):
    """The first ``n`` events of a stream: (event, id, data)."""
    out, event, ident, data = [], None, None, None
    deadline = time.monotonic() + timeout
    for line in response.iter_lines():
        if line.startswith("event: "):
            event = line[7:]
        elif line.startswith("id: "):
            ident = int(line[4:])
        elif line.startswith("data: "):
            data = json.loads(line[6:])
        elif line == "" and event:
            out.append((event, ident, data))
            event, ident, data = None, None, None
            if len(out) == n:
                return out
        if time.monotonic() > deadline:
            break
    return out


def test_events_stream_every_committed_change(svc, a, plan_id):
    run_id = new_run(a, plan_id)
    got: list = []

    def listen():
        with httpx.Client(base_url=svc.url, headers=a.http.headers, timeout=20) as h:
            with h.stream("GET", f"/runs/{run_id}/events") as r:
                assert r.headers["content-type"].startswith("text/event-stream")
                got.extend(read_events(r, 4))

    t = threading.Thread(target=listen)
    t.start()
    time.sleep(0.5)
    a.post(f"/runs/{run_id}/looks", {"visible": ["rl", "ra"]})
    a.post(f"/runs/{run_id}/outcomes", {"outcome": "success"})
    a.post(f"/runs/{run_id}/looks", {"visible": ["ca"]})
    t.join(20)
    assert [(e, i) for e, i, _ in got] == [("snapshot", 0), ("look", 1), ("outcome", 2), ("look", 3)]
    snap = got[0][2]
    assert snap["trace"] == [] and snap["graph"][0]["nodes"][0]["id"] == "ca" and snap["run"]["count"]["value"] == "336"
    assert got[1][2]["row"]["action"] == {"kind": "buffer", "part": "rl", "source": None}
    assert got[2][2]["row"]["outcome"] == "success" and got[2][2]["run"]["state"]["buffered"] == ["rl"]
    assert got[3][2]["run"]["pending"]["action"]["part"] == "ca"


def test_browser_tickets_open_only_their_run_and_never_reach_the_log(svc, a, op, plan_id):
    run_id = new_run(a, plan_id)
    other = new_run(a, plan_id)
    ticket = op.post(f"/runs/{run_id}/ticket").json()
    assert ticket["url"] == f"/runs/{run_id}/events?ticket={ticket['ticket']}" and ticket["expires_in"] > 0
    with httpx.Client(base_url=svc.url, timeout=10) as anon:
        with anon.stream("GET", ticket["url"]) as r:
            assert r.status_code == 200
            assert read_events(r, 1)[0][0] == "snapshot"
        assert anon.get(f"/runs/{other}/events?ticket={ticket['ticket']}").status_code == 401
        forged = ticket["ticket"][:-4] + ("AAAA" if not ticket["ticket"].endswith("AAAA") else "BBBB")
        assert anon.get(f"/runs/{run_id}/events?ticket={forged}").status_code == 401
        assert anon.get(f"/runs/{run_id}/events?ticket=garbage").status_code == 401
    time.sleep(0.3)
    log = svc.log_text()
    assert "ticket=REDACTED" in log
    assert ticket["ticket"] not in log and ticket["ticket"].split(".")[-1] not in log
    assert "opp_" not in log


# ---------------------------------------------------------------- pages and docs


def test_pages_docs_and_openapi_are_served_from_the_package(svc):
    with httpx.Client(base_url=svc.url, timeout=10) as h:
        spec = h.get("/openapi.json").json()
        assert {"/plans", "/runs", "/runs/{run_id}/looks", "/runs/{run_id}/outcomes", "/runs/{run_id}/events"} <= set(spec["paths"])
        assert "bearer" in json.dumps(spec["components"]["securitySchemes"]).lower()
        for path in ("/", "/ui/runs/1", "/docs"):
            r = h.get(path)
            assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
            assert "default-src 'self'" in r.headers["content-security-policy"]
        for name in ("app.js", "app.css", "docs.js"):
            assert h.get(f"/static/{name}").status_code == 200
    from opportune.service.routers.dashboard import STATIC as static

    for f in static.iterdir():
        text = f.read_text()
        hosts = set(re.findall(r"(?:https?:)?//([\w-]+(?:\.[\w-]+)+)", text))
        assert hosts <= {"www.w3.org"}, (f.name, hosts)  # nothing fetched from the internet (w3.org: the SVG namespace)


def test_a_revoked_token_is_refused(svc, plan_id):
    from typer.testing import CliRunner

    from opportune.cli import app

    created = CliRunner().invoke(app, ["token", "create", "cell-r", "--db", str(svc.db), "--json"])
    assert created.exit_code == 0, created.output
    doc = json.loads(created.stdout)
    revoked = CliRunner().invoke(app, ["token", "revoke", doc["id"], "--db", str(svc.db)])
    assert revoked.exit_code == 0, revoked.output
    c = Client(svc.url, doc["token"])
    try:
        assert error_of(c.get("/runs"), 401)["code"] == "unauthorized"
        error_of(c.post("/runs", {"plan": plan_id}), 401)
    finally:
        c.close()


def test_the_event_stream_says_when_the_run_completes_and_ends(svc, a, plan_id):
    """When a run completes (the outcome of its last install), the stream sends a `complete` event and
    ends; a stream opened on a complete run gets its snapshot and `complete` at once."""
    run_id = new_run(a, plan_id)
    got: list = []

    def listen():
        with httpx.Client(base_url=svc.url, headers=a.http.headers, timeout=30) as h:
            with h.stream("GET", f"/runs/{run_id}/events") as r:
                got.extend(read_events(r, 100, timeout=25))    # returns when the server ends the stream

    t = threading.Thread(target=listen)
    t.start()
    time.sleep(0.5)
    drive_table1(a, run_id)
    t.join(30)
    assert not t.is_alive()
    assert got[-1][0] == "complete" and got[-2][0] == "outcome" and got[-2][2]["row"]["action"]["part"] == "cl"
    done = got[-1][2]
    assert done["run"] == run_id and done["installed"] == ["ca", "ba", "rl", "dr", "sm", "ml", "ra", "co", "st", "cl"]
    with httpx.Client(base_url=svc.url, headers=a.http.headers, timeout=10) as h:
        with h.stream("GET", f"/runs/{run_id}/events") as r:
            again = read_events(r, 100, timeout=8)
    assert [e for e, _, _ in again] == ["snapshot", "complete"]


def test_a_run_takes_its_policy_by_name_and_the_default_is_the_lookahead(svc, a, plan_id):
    """Without `policy` a run decides by the look-ahead, as the library's Lookahead would; a named policy is
    kept with the run; an unknown one is refused and starts nothing."""
    from opportune.policies.named import DEFAULT_POLICY

    r = a.post("/runs", {"plan": plan_id})
    assert r.status_code == 201, r.text
    run = r.json()
    assert run["policy"] == DEFAULT_POLICY == "lookahead"
    answer = a.post(f"/runs/{run['id']}/looks", {"visible": ["ca", "rl"]}).json()
    assert answer.get("action") == {"kind": "install", "part": "ca", "source": "bin"}, answer
    assert "base rule" in answer["decision"]["rule"] or "least expected cost" in answer["decision"]["rule"]
    assert a.get(f"/runs/{run['id']}").json()["policy"] == "lookahead"
    listed = {x["id"]: x["policy"] for x in a.get("/runs").json()["runs"]}
    assert listed[run["id"]] == "lookahead"
    slack = new_run(a, plan_id, policy="slack")
    assert a.get(f"/runs/{slack}").json()["policy"] == "slack"
    # the paper's rule's former name runs it, under its name now, and the answer says what to write
    former = a.post("/runs", {"plan": plan_id, "policy": "opportunistic"})
    assert former.status_code == 201, former.text
    assert former.json()["policy"] == "paper" and "write 'paper'" in former.json()["note"]
    assert a.get(f"/runs/{former.json()['id']}").json()["policy"] == "paper"
    assert "note" not in run
    before = len(a.get("/runs").json()["runs"])
    err = error_of(a.post("/runs", {"plan": plan_id, "policy": "teleport"}), 422)
    assert "policy" in json.dumps(err)
    assert len(a.get("/runs").json()["runs"]) == before
