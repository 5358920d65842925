"""The sequencer over OPC UA: a real asyncua client against ``opportune serve --opcua`` in another process.

Table 1 over OPC UA gives what the library and the HTTP API give for the same looks; a refused call
answers a Bad status with the service's message and changes nothing; a run started over OPC UA is
the same run over HTTP; ``kill -9`` under a driving client loses no acknowledged call; a client
with a wrong token or an untrusted certificate is refused.
"""

from __future__ import annotations

import asyncio
import re
import shutil
import sqlite3
import subprocess
import sys
import threading

import pytest

pytest.importorskip("asyncua")

from asyncua import ua  # noqa: E402

from conftest import EXAMPLES, GEARBOX, REPO  # noqa: E402
from opportune import load_plan  # noqa: E402
from opportune.formats.looks import read_looks  # noqa: E402
from opportune.sequencer import Sequencer  # noqa: E402
from opportune.service.auth import create_token, revoke_token  # noqa: E402
from opportune.service.config import database_url  # noqa: E402
from opportune.service.opcua import client_certificate  # noqa: E402
from opportune.service.opcua_client import CellClient, Refused, listing  # noqa: E402
from opportune.service.storage import Store  # noqa: E402
from opportune.service.testing import Client, ServiceProcess  # noqa: E402

LOOKS = read_looks(EXAMPLES / "gearbox-table1.looks")
APP = "urn:opportune:test-cell"


def library_rows(looks):
    """The library's rows for these looks, without its closing ``done`` (a run is complete at its last install)."""
    return [row.to_dict() for row in Sequencer(load_plan(GEARBOX)).run(looks) if row.action.kind != "done"]


def strip(row):
    return {k: row[k] for k in ("visible", "buffered", "installed", "action", "outcome")}


class Events:
    """An OPC UA subscription's handler: the events received, in order."""

    got: list = []

    def event_notification(self, event):
        type(self).got.append(event)


class CellEvents(Events):
    got: list = []


@pytest.fixture(scope="session")
def client_cert(tmp_path_factory):
    """A client certificate and key, made once per session (RSA key generation takes a moment)."""
    return client_certificate(tmp_path_factory.mktemp("opcua-client"), APP)


def documented_listing() -> str:
    page = (REPO / "docs" / "opcua.md").read_text(encoding="utf-8")
    return re.search(r"<!-- address-space -->\n```text\n(.*?)```", page, re.S).group(1)


def shapes(text: str) -> set[str]:
    """A listing's lines with run ids and cell names made general, and the padding dropped."""
    text = re.sub(r"Runs/\d+", "Runs/ID", re.sub(r"Cells/[^/\s]+", "Cells/CELL", text))
    return {" ".join(line.split()) for line in text.splitlines() if line.strip()}


def trusting(pki, cert):
    (pki / "trusted").mkdir(parents=True, exist_ok=True)
    shutil.copy(cert, pki / "trusted" / "test-cell.der")


def cell(svc, token, client_cert, **kw):
    cert, key = client_cert
    return CellClient(svc.opcua_endpoint, token, certificate=cert, private_key=key, app_uri=APP, **kw)


def test_table_1_over_opcua_is_the_same_run_as_over_http(tmp_path, client_cert):
    pki = tmp_path / "pki"
    trusting(pki, client_cert[0])
    # anonymous sessions (development, loopback) act as cell `dev`, which has no token: seen at the end
    with ServiceProcess(tmp_path / "t.db", opcua=True, pki=pki,
                        extra_args=("--no-access-log", "--opcua-anonymous", "dev")) as svc:
        token = svc.token(cell="cell-1")
        http = Client(svc.url, token)

        operator = svc.token(operator="alice")

        async def subscribe(session, node: str, handler):
            etype = await session.client.nodes.base_event_type.get_child(f"{session.ns}:RunChangedEventType")
            subscription = await session.client.create_subscription(20, handler)
            await subscription.subscribe_events(session.client.get_node(session.node_id(node)), etype)

        async def drive():
            async with cell(svc, token, client_cert) as ua_cell, cell(svc, operator, client_cert) as watcher:
                # every change of a run is an event on Objects/Opportune (for operators) and on its cell's object
                await subscribe(watcher, "Opportune", Events())
                plan = await ua_cell.upload_plan(GEARBOX.read_text())
                r = http.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"},
                              key=False)
                assert r.json()["id"] == plan        # one plan, whichever protocol stored it
                run_ua = await ua_cell.start_run(plan, policy="paper", label="SN 1")
                await subscribe(ua_cell, "Cells/cell-1", CellEvents())     # its cell's object exists now
                run_http = http.post("/runs", {"plan": plan, "policy": "paper"}).json()["id"]
                assert await ua_cell.read(run_ua, "State") == "Idle"
                for look in LOOKS:
                    got = await ua_cell.look(run_ua, list(look))
                    over_http = http.post(f"/runs/{run_http}/looks", {"visible": list(look)}).json()
                    assert got["answer"]["action"] == over_http["action"]
                    assert (got["action"], got["part"] or None) == (over_http["action"]["kind"],
                                                                     over_http["action"]["part"])
                    assert got["explanation"] == over_http["decision"]["explain"]
                    assert (await ua_cell.outcome(run_ua, "success"))["seq"] == got["seq"] + 1
                    assert http.post(f"/runs/{run_http}/outcomes", {"outcome": "success"}).status_code == 200
                for _ in range(200):       # the last event of each run has arrived
                    if {(e.RunId, e.Seq) for e in Events.got + CellEvents.got} >= {(run_ua, 30), (run_http, 30)}:
                        break
                    await asyncio.sleep(0.05)
                return run_ua, run_http, plan, ua_cell

        run_ua, run_http, plan, _ = asyncio.run(drive())
        for run in (run_ua, run_http):    # one event per change, in order, whichever protocol made it
            events = [(e.Seq, e.Kind, e.State) for e in Events.got if e.RunId == run]
            assert events == [(0, "start", "Idle")] + [(k, "look" if k % 2 else "outcome", "Execute")
                                                      for k in range(1, 30)] + [(30, "outcome", "Complete")]
            # the cell's own subscription: the same, from when it subscribed
            assert [(e.Seq, e.Kind, e.State) for e in CellEvents.got if e.RunId == run] == events[events.index(
                next(x for x in events if x[0] >= (1 if run == run_ua else 0))):]
        # The run driven over OPC UA, read over HTTP: Table 1, as the library decides it.
        seen = http.get(f"/runs/{run_ua}").json()
        assert seen["status"] == "complete" and seen["cell"] == "cell-1" and seen["label"] == "SN 1"
        rows = [strip(r) for r in http.get(f"/runs/{run_ua}/trace").json()["rows"]]
        assert rows == library_rows(LOOKS)
        assert rows == [strip(r) for r in http.get(f"/runs/{run_http}/trace").json()["rows"]]

        async def refusals_and_retries():
            async with cell(svc, token, client_cert) as ua_cell:
                # The variables of the finished run, as HTTP states it.
                assert await ua_cell.read(run_ua, "State") == "Complete"
                assert await ua_cell.read(run_ua, "Installed") == seen["state"]["installed"]
                assert await ua_cell.read(run_ua, "Seq") == seen["seq"]
                assert await ua_cell.read(run_ua, "AdmissibleCount") == seen["count"]["value"]
                active = ua.NodeId("Cells/cell-1/ActiveRuns", ua_cell.ns)
                assert run_ua not in await ua_cell.client.get_node(active).read_value()

                run = await ua_cell.start_run(plan, policy="paper", buffer_capacity=2, request_id="start-2")
                assert await ua_cell.start_run(plan, policy="paper", buffer_capacity=2, request_id="start-2") == run
                first = await ua_cell.look(run, ["rl", "ra"], request_id="look-1")
                assert (first["action"], first["part"], first["replayed"]) == ("buffer", "rl", False)
                again = await ua_cell.look(run, ["rl", "ra"], request_id="look-1")     # a retry: the recorded answer
                assert again["replayed"] and again["answer"] == first["answer"]
                # the same request id over HTTP is the same request: the same answer, byte for byte
                r = http.post(f"/runs/{run}/looks", {"visible": ["rl", "ra"]}, key="look-1")
                assert r.headers.get("Idempotent-Replayed") == "true" and r.json() == first["answer"]
                assert await ua_cell.read(run, "PendingAction") == "buffer rl"
                await ua_cell.outcome(run, "success")
                assert await ua_cell.read(run, "Buffered") == ["rl"]
                before = http.get(f"/runs/{run}").json()
                for n, (call, status, said) in enumerate((
                        (ua_cell.look(run, ["rl"]), "BadInvalidArgument", "rl"),         # rl is in the buffer now
                        (ua_cell.look(run, ["ra", "cace"]), "BadInvalidArgument", "did you mean 'ca'"),
                        (ua_cell.outcome(run, "success"), "BadInvalidState", "no action is pending"),
                        (ua_cell.outcome(run, "exploded"), "BadInvalidArgument", "success, failed or defective"),
                        (ua_cell.look(run, ["ra"], request_id=""), "BadInvalidArgument", "RequestId is empty"),
                        (ua_cell.look(run + 100, ["ra"]), "BadNotFound", f"no run {run + 100}"),
                        (ua_cell.look(run, ["ra"], request_id="look-1"), "BadInvalidArgument", "already used"),
                        (ua_cell.start_run("0" * 64), "BadInvalidArgument", "no plan"),
                        (ua_cell.look(run, ["ra"] * 100_001), "BadInvalidArgument", "at most 100,000"),
                        (ua_cell.look(run, ["x" * 201]), "BadInvalidArgument", "Visible[0] must be 1-200"),
                        (ua_cell.start_run(plan, policy="best"), "BadInvalidArgument", "unknown policy"),
                        (ua_cell.start_run("parts: [a, a]"), "BadInvalidArgument", "invalid_plan"),
                        (ua_cell.upload_plan("#" * (1 << 20) + "\nparts: [a]"), "BadRequestTooLarge", "--max-body"),
                        (ua_cell.upload_plan("parts: [a\x00]"), "BadInvalidArgument", "control character"))):
                    with pytest.raises(Refused) as refused:
                        await call
                    assert refused.value.name == status and said in refused.value.message, (n, refused.value)
                after = http.get(f"/runs/{run}").json()
                assert {k: after[k] for k in ("seq", "state", "pending", "count")} == \
                       {k: before[k] for k in ("seq", "state", "pending", "count")}       # nothing changed
                assert await ua_cell.read(run, "Seq") == before["seq"]
                assert run in await ua_cell.client.get_node(active).read_value()
                # a run started over HTTP shows up in the address space too
                other = http.post("/runs", {"plan": plan}).json()["id"]
                for _ in range(100):
                    try:
                        if await ua_cell.read(other, "State") == "Idle":
                            break
                    except ua.UaStatusCodeError:
                        pass
                    await asyncio.sleep(0.05)
                assert await ua_cell.read(other, "Policy") == "lookahead"
                text = await listing(ua_cell.client)
                for line in ("Opportune/Look(RunId: Int64, Visible: String[], RequestId: String)",
                             f"s=Runs/{run}/AdmissibleCount", f"Objects/Opportune/Runs/{run}/Installed: String[]"):
                    assert line in text, text
                # docs/opcua.md lists what this server has, node for node (runs and cells aside)
                assert shapes(documented_listing()) == shapes(text)

        asyncio.run(refusals_and_retries())

        async def anonymous():
            async with CellClient(svc.opcua_endpoint, None) as dev:     # no security, no token: cell dev's runs
                with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                    await dev.read(run_ua, "State")                     # cell-1's
                run = await dev.start_run(GEARBOX.read_text(), policy="paper")
                assert (await dev.look(run, ["rl", "ra"]))["part"] == "rl"
                return run

        dev_run = asyncio.run(anonymous())
        assert http.get(f"/runs/{dev_run}").status_code == 404          # not cell-1's
        watcher = Client(svc.url, operator)
        assert watcher.get(f"/runs/{dev_run}").json()["cell"] == "dev"
        watcher.close()

        stranger = client_certificate(tmp_path / "stranger", APP)      # the same application, not in the trust list

        other_cell = Client(svc.url, svc.token(cell="cell-2"))
        other_cell.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"}, key=False)
        theirs = other_cell.post("/runs", {"plan": plan}).json()["id"]
        other_cell.close()

        async def refused_sessions():
            async with cell(svc, token, client_cert) as ua_cell:    # another cell's run: its values are not ours
                node = ua_cell.client.get_node(ua_cell.node_id(f"Runs/{theirs}/State"))
                for _ in range(100):    # its nodes appear once the server has seen the run started over HTTP
                    try:
                        assert (await node.read_browse_name()).Name == "State"      # the structure is no secret
                        break
                    except ua.UaStatusCodeError:
                        await asyncio.sleep(0.05)
                with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                    await node.read_value()
                with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                    await subscribe(ua_cell, "Cells/cell-2", CellEvents())
                with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                    await subscribe(ua_cell, "Opportune", CellEvents())       # every cell's events: operators'
                assert await ua_cell.read(run_ua, "State") == "Complete"   # its own, still
            for who, cert, status in (("opp_not-a-token", client_cert, ua.uaerrors.BadUserAccessDenied),
                                      (token, stranger, ua.uaerrors.BadCertificateUntrusted)):
                c = CellClient(svc.opcua_endpoint, who, certificate=cert[0], private_key=cert[1], app_uri=APP)
                with pytest.raises(status):
                    await c.connect()
                await c.__aexit__(None, None, None)
            async with cell(svc, operator, client_cert) as reader:   # an operator reads, and drives nothing
                assert await reader.read(run_ua, "State") == "Complete"
                with pytest.raises(Refused) as refused:
                    await reader.start_run(plan)
                assert refused.value.name == "BadUserAccessDenied" and "operator" in refused.value.message
            token_id, short_lived = create_token(store, cell="cell-1")
            async with cell(svc, short_lived, client_cert) as session:   # a token revoked during a session
                await session.start_run(plan)
                revoke_token(store, token_id)
                with pytest.raises(Refused) as refused:
                    await session.start_run(plan)
                assert refused.value.name == "BadUserAccessDenied" and "revoked" in refused.value.message

        store = Store(database_url(str(tmp_path / "t.db")))
        asyncio.run(refused_sessions())
        store.dispose()

        # The reference cell drives a simulated bin through the server, end to end.
        done = subprocess.run([sys.executable, str(EXAMPLES / "opcua_cell.py"), "example:gearbox", "--endpoint",
                               svc.opcua_endpoint, "--token", token, "--cert", str(client_cert[0]), "--key",
                               str(client_cert[1]), "--app-uri", APP, "--policy", "paper", "--seed", "3"],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr[-2000:]
        run = int(done.stdout.split()[1])
        rows = [strip(r) for r in http.get(f"/runs/{run}/trace").json()["rows"]]
        assert rows == library_rows([tuple(r["visible"]) for r in rows])   # the library's decisions, look by look
        installed = http.get(f"/runs/{run}").json()["state"]["installed"]
        assert done.stdout.splitlines()[-1] == "installed: " + " ".join(installed) and len(installed) == 10
        http.close()


def test_kill_9_under_a_driving_opcua_client_loses_no_acknowledged_call(tmp_path, client_cert):
    """OPC UA alone (``--no-http``), anonymous sessions refused by default; every call of Table 1 has a
    request id, and its answer, acknowledged before the kill or got by retrying it after, is applied once."""
    pki = tmp_path / "pki"
    trusting(pki, client_cert[0])
    db = tmp_path / "k.db"
    svc = ServiceProcess(db, opcua=True, pki=pki, extra_args=("--no-http",))
    calls = [c for look in LOOKS for c in (("look", list(look)), ("outcome", "success"))]
    answers: dict[int, dict] = {}     # index of the call -> its answer, as the client received it
    in_flight: list[int] = []
    try:
        svc.start()
        token = svc.token(cell="cell-1")

        async def one(ua_cell, run, i):
            kind, arg = calls[i]
            if kind == "look":
                return await ua_cell.look(run, arg, request_id=f"call-{i}")
            return await ua_cell.outcome(run, arg, request_id=f"call-{i}")

        async def start():
            for who, status in ((None, ua.uaerrors.BadIdentityTokenRejected),):   # anonymous: refused by default
                c = CellClient(svc.opcua_endpoint, who, certificate=client_cert[0], private_key=client_cert[1],
                               app_uri=APP)
                with pytest.raises(status):
                    await c.connect()
                await c.__aexit__(None, None, None)
            with pytest.raises(ua.uaerrors.BadSecurityModeRejected):    # nor a session without security
                await CellClient(svc.opcua_endpoint, None).connect()
            async with cell(svc, token, client_cert) as ua_cell:
                return await ua_cell.start_run(GEARBOX.read_text(), policy="paper", request_id="start")

        run = asyncio.run(start())

        async def drive():
            async with cell(svc, token, client_cert, timeout=5) as ua_cell:
                for i in range(len(calls)):
                    in_flight[:] = [i]
                    try:
                        answers[i] = await one(ua_cell, run, i)
                    except Exception:
                        return      # the server is gone

        driver = threading.Thread(target=asyncio.run, args=(drive(),))
        driver.start()
        while len(answers) < 11 and driver.is_alive():
            driver.join(0.005)
        svc.kill()
        driver.join(30)
        acked = len(answers)
        assert 11 <= acked < len(calls) and in_flight == [acked]

        svc.start()          # the same database and certificates, a new process on a new port

        async def resume():
            async with cell(svc, token, client_cert) as ua_cell:
                assert await ua_cell.read(run, "Seq") >= answers[acked - 1]["seq"]   # every acknowledged call survived
                again = await one(ua_cell, run, acked - 1)           # the last acknowledged call, repeated
                assert again["replayed"] and again["answer"] == answers[acked - 1]["answer"]
                # the call in flight at the kill, retried with its request id, then the rest
                for i in range(acked, len(calls)):
                    answers[i] = await one(ua_cell, run, i)
                return await ua_cell.read(run, "State"), await ua_cell.read(run, "Installed")

        state, installed = asyncio.run(resume())
    finally:
        svc.stop()
    # Each call applied exactly once, in order, and the decisions are the library's for Table 1.
    assert [answers[i]["seq"] for i in range(len(calls))] == list(range(1, len(calls) + 1))
    rows = library_rows(LOOKS)
    assert [answers[2 * k]["answer"]["action"] for k in range(len(LOOKS))] == [r["action"] for r in rows]
    assert state == "Complete" and installed == answers[len(calls) - 1]["answer"]["run"]["state"]["installed"]
    with sqlite3.connect(db) as con:
        assert con.execute("SELECT count(*) FROM events WHERE run_id = ?", (run,)).fetchone()[0] == len(calls)


def test_a_taken_opcua_port_is_a_one_line_error(tmp_path):
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = subprocess.run([sys.executable, "-m", "opportune.cli", "serve", "--db", str(tmp_path / "t.db"),
                               "--opcua", "--no-http", "--opcua-endpoint", f"opc.tcp://127.0.0.1:{port}",
                               "--opcua-pki", str(tmp_path / "pki")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert f"error: cannot listen on opc.tcp://127.0.0.1:{port}" in done.stderr and "choose another port" in done.stderr


@pytest.mark.parametrize("args, said", [
    (("--opcua", "--opcua-endpoint", "opc.tcp://0.0.0.0:4840", "--opcua-anonymous", "cell-1"), "loopback only"),
    (("--opcua", "--opcua-endpoint", "http://127.0.0.1:4840"), "not an opc.tcp://HOST:PORT URL"),
    (("--opcua", "--opcua-endpoint", "opc.tcp://127.0.0.1:99999"), "bad port"),
    (("--opcua", "--workers", "2"), "--workers 1"),
    (("--no-http",), "add --opcua"),
    (("--opcua", "--opcua-anonymous", "bad name!"), "invalid cell name"),
])
def test_serve_opcua_mistakes_are_refused_before_anything_starts(tmp_path, args, said):
    from typer.testing import CliRunner

    from opportune.cli import app

    r = CliRunner().invoke(app, ["serve", "--db", str(tmp_path / "t.db"), *args])
    assert r.exit_code == 1 and said in r.output and "Traceback" not in r.output, r.output
    assert not (tmp_path / "opcua-pki").exists()
