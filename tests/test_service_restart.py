"""Nothing is lost: ``kill -9`` in the middle of runs, restart on the same database, finish.

Every answer a cell received is in the trace after the restart; a request
whose answer was lost with the server is retried with its Idempotency-Key
and applied exactly once; the finished traces are the library's own.
"""

from __future__ import annotations

import random
import sqlite3
import threading

import httpx
import pytest

from conftest import EXAMPLES, GEARBOX
from opportune import load_plan
from opportune.formats.looks import read_looks
from opportune.sequencer import Sequencer
from opportune.service.testing import Client, ServiceProcess

LOOKS = read_looks(EXAMPLES / "gearbox-table1.looks")


def library_rows(looks):
    """The library's rows for these looks, without its closing ``done`` (a run is complete at its last install)."""
    return [row.to_dict() for row in Sequencer(load_plan(GEARBOX)).run(looks) if row.action.kind != "done"]


def strip(row):
    return {k: row[k] for k in ("visible", "buffered", "installed", "action", "outcome")}


def upload(client):
    r = client.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"}, key=False)
    assert r.status_code in (200, 201), r.text
    return r.json()["id"]


def test_kill_9_mid_run_then_restart_and_finish(tmp_path):
    db = tmp_path / "restart.db"
    svc = ServiceProcess(db)
    try:
        svc.start()
        token = svc.token(cell="cell-1")
        c = Client(svc.url, token)
        run_id = c.post("/runs", {"plan": upload(c), "policy": "paper"}).json()["id"]   # Table 1's rule
        for look in LOOKS[:7]:
            assert c.post(f"/runs/{run_id}/looks", {"visible": list(look)}).status_code == 200
            assert c.post(f"/runs/{run_id}/outcomes", {"outcome": "success"}).status_code == 200
        pending = c.post(f"/runs/{run_id}/looks", {"visible": list(LOOKS[7])}, key="look-8")
        assert pending.status_code == 200
        before = c.get(f"/runs/{run_id}").json()
        c.close()
        svc.kill()

        svc.start()  # same database, new process, new port
        c = Client(svc.url, token)
        after = c.get(f"/runs/{run_id}").json()
        assert {k: after[k] for k in ("seq", "state", "pending", "count", "rows")} == \
               {k: before[k] for k in ("seq", "state", "pending", "count", "rows")}
        assert after["pending"]["action"] == {"kind": "buffer", "part": "co", "source": None}
        # The answer of a request made before the crash is still the answer.
        assert c.post(f"/runs/{run_id}/looks", {"visible": list(LOOKS[7])}, key="look-8").content == pending.content
        assert c.post(f"/runs/{run_id}/outcomes", {"outcome": "success"}).status_code == 200
        for look in LOOKS[8:]:
            r = c.post(f"/runs/{run_id}/looks", {"visible": list(look)})
            assert r.status_code == 200, r.text
            assert c.post(f"/runs/{run_id}/outcomes", {"outcome": "success"}).status_code == 200
        trace = c.get(f"/runs/{run_id}/trace").json()["rows"]
        assert [strip(r) for r in trace] == library_rows(LOOKS)
        assert c.get(f"/runs/{run_id}").json()["status"] == "complete"
        c.close()
    finally:
        svc.stop()
    with sqlite3.connect(db) as con:
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert con.execute("SELECT count(*) FROM events WHERE run_id = ?", (run_id,)).fetchone()[0] == 30  # 15 looks, 15 outcomes


def drive(client: Client, run_id: int, rng: random.Random, acknowledged: list, stop: threading.Event):
    """Drive a run with random looks until stopped or complete; record every answer received."""
    while not stop.is_set():
        try:
            state = client.get(f"/runs/{run_id}").json()
            if state["status"] == "complete":
                return
            if state["pending"]:
                req = ("outcomes", {"outcome": "success"})
            else:
                units = [p for p, n in state["state"]["in_bin"].items() for _ in range(n)]
                req = ("looks", {"visible": rng.sample(units, min(len(units), rng.randint(1, 3)))})
            r = client.post(f"/runs/{run_id}/{req[0]}", req[1])
        except httpx.HTTPError:
            return  # the server is gone
        if r.status_code == 200:
            acknowledged.append(r.json()["seq"])


@pytest.mark.parametrize("store", ["sqlite", "postgresql"])
def test_kill_9_under_load_loses_no_acknowledged_answer(tmp_path, request, store):
    db = tmp_path / "load.db" if store == "sqlite" else request.getfixturevalue("postgres").database("load")
    svc = ServiceProcess(db, extra_args=("--no-access-log",), log=tmp_path / "load.log")
    n = 4
    try:
        svc.start()
        clients = [Client(svc.url, svc.token(cell=f"cell-{i}"), timeout=5) for i in range(n)]
        plan = [upload(c) for c in clients][0]     # each cell uploads the plans it runs
        runs = [c.post("/runs", {"plan": plan, "policy": "paper"}).json()["id"] for c in clients]
        acked: list[list[int]] = [[] for _ in range(n)]
        stop = threading.Event()
        threads = [threading.Thread(target=drive, args=(clients[i], runs[i], random.Random(i), acked[i], stop))
                   for i in range(n)]
        for t in threads:
            t.start()
        while sum(len(a) for a in acked) < 24:  # well into the runs
            threads[0].join(0.02)
        svc.kill()
        stop.set()
        for t in threads:
            t.join(10)
        for c in clients:
            c.close()

        svc.start()
        for i in range(n):
            c = Client(svc.url, svc.token(cell=f"cell-{i}"))
            run = c.get(f"/runs/{runs[i]}").json()
            assert run["seq"] >= max(acked[i], default=0)  # every acknowledged event survived
            drive(c, runs[i], random.Random(100 + i), [], threading.Event())
            run = c.get(f"/runs/{runs[i]}").json()
            assert run["finished"] and run["status"] == "complete"
            rows = c.get(f"/runs/{runs[i]}/trace").json()["rows"]
            # The whole trace is what the library decides for the looks that were recorded.
            assert [strip(r) for r in rows] == library_rows([tuple(r["visible"]) for r in rows])
            assert run["state"]["installed"] and len(run["state"]["installed"]) == 10
            c.close()
    finally:
        svc.stop()
