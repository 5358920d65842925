"""opportune.client.Cell against a real service on a loopback port: a gearbox run, retries that the
service answers from its store of answers, and typed errors."""

from __future__ import annotations

import subprocess
import sys

import pytest

from conftest import GEARBOX
from test_sequencer import TABLE1

httpx = pytest.importorskip("httpx")
pytest.importorskip("fastapi")

from opportune.client import (ActionPending, Cell, CellError, InvalidPlan, LookContradictsState, NoPendingAction,  # noqa: E402
                              NotFound, ServerError, ServiceUnreachable, Unauthorized, UnknownPart)
from opportune.service.testing import ServiceProcess, free_port  # noqa: E402


def split(text):
    return [p for p in text.split(",") if p]


@pytest.fixture(scope="module")
def svc(tmp_path_factory):
    with ServiceProcess(tmp_path_factory.mktemp("client") / "client.db") as s:
        yield s


@pytest.fixture(scope="module")
def token(svc):
    return svc.token(cell="cell-c")


@pytest.fixture(scope="module")
def cell(svc, token):
    with Cell(svc.url, token, timeout=10) as c:
        yield c


@pytest.fixture(scope="module")
def plan(cell):
    return cell.upload_plan(GEARBOX)


class Flaky(httpx.HTTPTransport):
    """A real transport that fails some attempts: ``lose`` sends the request and drops the answer (the
    service did the work, the client never hears of it); ``refuse`` answers 503 without sending it."""

    def __init__(self, *, lose: int = 0, refuse: int = 0):
        super().__init__()
        self.lose, self.refuse = lose, refuse
        self.sent: list[httpx.Request] = []

    def handle_request(self, request):
        self.sent.append(request)
        if self.refuse:
            self.refuse -= 1
            return httpx.Response(503, json={"error": {"status": 503, "code": "counting_budget_exceeded",
                                                       "message": "busy", "hint": "retry"}})
        response = super().handle_request(request)
        if self.lose:
            self.lose -= 1
            response.read()
            response.close()
            raise httpx.ReadError("the answer was lost on the way back", request=request)
        return response


def test_a_gearbox_run_gives_table1(cell, plan):
    assert plan.name == "gearbox" and plan.units == 10 and plan.format == "yaml"
    assert cell.upload_plan(GEARBOX.read_text()).id == plan.id  # the same plan, as text: the same id
    run = cell.start_run(plan, label="client", policy="paper")   # Table 1's looks follow the paper's rule
    assert run.status == "active" and run.count.value == "336" and run.installable == ["ca"]
    for visible, buffered, installed, action in TABLE1:
        answer = cell.look(run, split(visible))
        assert f"{answer.action.kind} {answer.action.part}" == action, answer.decision.explain
        assert answer.row.buffered == split(buffered) and answer.row.installed == split(installed)
        assert answer.decision.exact and answer.run.pending is not None
        done = cell.outcome(answer, "success")
        assert done.row.outcome == "success" and done.run.pending is None
    assert cell.look(run.id, []).action.kind == "done"
    final = cell.state(run.id)
    assert final.status == "complete" and final.finished and final.progress.installed == 10
    trace = cell.trace(run.id)
    assert [f"{r.action.kind} {r.action.part}" for r in trace.rows[:-1]] == [a for *_, a in TABLE1]
    assert any(r.id == run.id and r.status == "complete" for r in cell.runs(status="complete"))
    assert cell.plan(plan.id).plan["name"] == "gearbox"
    assert cell.health().ok


def test_a_lost_answer_is_retried_with_the_same_key_and_answered_from_the_store(svc, token, cell, plan):
    run = cell.start_run(plan.id)
    flaky = Flaky(lose=1)
    with Cell(svc.url, token, transport=flaky, backoff=0.01) as c:
        answer = c.look(run.id, ["rl", "ra"])
        assert c.attempts == 2 and c.replayed  # the second attempt got the stored answer of the first
        keys = [r.headers["Idempotency-Key"] for r in flaky.sent]
        assert len(keys) == 2 and keys[0] == keys[1]
        assert flaky.sent[0].content == flaky.sent[1].content
    assert f"{answer.action.kind} {answer.action.part}" == "buffer rl"
    state = cell.state(run.id)
    assert state.seq == 1 and state.rows == 1  # decided once, not twice
    # the next request has a key of its own
    flaky = Flaky(lose=1)
    with Cell(svc.url, token, transport=flaky, backoff=0.01) as c:
        c.outcome(run.id, "success")
        assert c.replayed and len({r.headers["Idempotency-Key"] for r in flaky.sent}) == 1
        assert flaky.sent[0].headers["Idempotency-Key"] not in keys
    assert cell.state(run.id).seq == 2
    # the same request sent twice by hand: the second answer is the first, byte for byte
    with httpx.Client(base_url=svc.url, headers={"Authorization": f"Bearer {token}"}) as h:
        sent = [h.post(f"/runs/{run.id}/looks", json={"visible": ["ca"]}, headers={"Idempotency-Key": "same-key"})
                for _ in range(2)]
    assert sent[0].status_code == sent[1].status_code == 200
    assert sent[1].content == sent[0].content and sent[1].headers["Idempotent-Replayed"] == "true"
    assert cell.state(run.id).seq == 3


def test_a_server_error_is_retried_and_a_refusal_is_not(svc, token, cell, plan):
    run = cell.start_run(plan.id)
    flaky = Flaky(refuse=2)
    with Cell(svc.url, token, transport=flaky, backoff=0.01) as c:
        assert c.look(run.id, ["ca"]).action.part == "ca"
        assert c.attempts == 3 and not c.replayed
        assert len({r.headers["Idempotency-Key"] for r in flaky.sent}) == 1
    flaky = Flaky(refuse=5)
    with Cell(svc.url, token, transport=flaky, retries=2, backoff=0.01) as c:
        with pytest.raises(ServerError) as err:
            c.state(run.id)
        assert err.value.status == 503 and c.attempts == 3
        flaky.refuse = 0
        with pytest.raises(ActionPending):
            c.look(run.id, ["st"])  # install ca is pending: a 409, refused at once
        assert c.attempts == 1


def test_errors_are_typed(svc, cell, plan):
    with pytest.raises(NotFound) as err:
        cell.state(10**9)
    e = err.value
    assert (e.status, e.code) == (404, "run_not_found") and "GET /runs" in e.hint and isinstance(e, CellError)
    assert "404 run_not_found" in str(e)

    run = cell.start_run(plan.id)
    with pytest.raises(LookContradictsState) as err:
        cell.look(run.id, ["rl", "rl"])  # one unit of rl in the plan
    e = err.value
    assert (e.status, e.code, e.where) == (409, "look_contradicts_state", "body.visible") and e.hint
    with pytest.raises(UnknownPart) as err:
        cell.look(run.id, ["rl", "gear"])
    assert (err.value.status, err.value.where) == (422, "body.visible[1]")
    with pytest.raises(NoPendingAction):
        cell.outcome(run.id, "success")
    with pytest.raises(NoPendingAction):
        cell.cancel(run.id)
    cell.look(run.id, ["ca"])
    assert cell.cancel(run.id).cancelled.action.part == "ca"
    assert cell.state(run.id).seq == 2  # the refusals changed nothing
    with pytest.raises(InvalidPlan) as err:
        cell.upload_plan({"name": "cycle", "parts": ["a", "b"], "requires": {"a": ["b"], "b": ["a"]}})
    assert err.value.problems and err.value.problems[0]["severity"] == "error"
    with pytest.raises(Unauthorized) as err:
        with Cell(svc.url, "opp_not-a-token") as c:
            c.state(run.id)
    assert err.value.status == 401


def test_no_answer_at_all_is_service_unreachable():
    with Cell(f"http://127.0.0.1:{free_port()}", "opp_x", retries=1, backoff=0.01, timeout=2) as c:
        with pytest.raises(ServiceUnreachable) as err:
            c.look(1, [])
        assert err.value.status is None and c.attempts == 2


def test_without_httpx_the_import_says_what_to_install():
    code = "import sys; sys.modules['httpx'] = None\ntry:\n import opportune.client\nexcept ImportError as e:\n print(e)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout
    assert "pip install 'opportune[service]'" in out and "httpx" in out
