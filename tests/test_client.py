"""opportune.client.Cell and AsyncCell against a real service on a loopback port: gearbox runs, retries
that the service answers from its store of answers, and typed errors.  Each scenario is an async function
run with ``asyncio.run``, once with an ``AsyncCell`` and once with a ``Cell`` (whose methods it awaits
through :class:`Awaiting`)."""

from __future__ import annotations

import asyncio
import inspect
import subprocess
import sys

import pytest

from conftest import GEARBOX
from test_sequencer import TABLE1

httpx = pytest.importorskip("httpx")
pytest.importorskip("fastapi")

from opportune.client import (ActionPending, AsyncCell, Cell, CellError, InvalidPlan, LookContradictsState,  # noqa: E402
                              NoPendingAction, NotFound, RunComplete, ServerError, ServiceUnreachable, Unauthorized,
                              UnknownPart)
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


class Failing:
    """A real transport that fails some attempts: ``lose`` sends the request and drops the answer (the
    service did the work, the client never hears of it); ``refuse`` answers 503 without sending it."""

    def __init__(self, *, lose: int = 0, refuse: int = 0):
        super().__init__()
        self.lose, self.refuse = lose, refuse
        self.sent: list[httpx.Request] = []

    def refusal(self, request):
        self.sent.append(request)
        if self.refuse:
            self.refuse -= 1
            return httpx.Response(503, json={"error": {"status": 503, "code": "counting_budget_exceeded",
                                                       "message": "busy", "hint": "retry"}})
        return None

    def delivered(self, request, response):
        if self.lose:  # the answer stays unread on its connection, which the client closes at the end
            self.lose -= 1
            raise httpx.ReadError("the answer was lost on the way back", request=request)
        return response


class Flaky(Failing, httpx.HTTPTransport):
    def handle_request(self, request):
        return self.refusal(request) or self.delivered(request, super().handle_request(request))


class AsyncFlaky(Failing, httpx.AsyncHTTPTransport):
    async def handle_async_request(self, request):
        return self.refusal(request) or self.delivered(request, await super().handle_async_request(request))


class Awaiting:
    """A :class:`Cell` used as an :class:`AsyncCell` is (``async with`` it, ``await`` its methods), so that
    one scenario tests both clients."""

    def __init__(self, cell: Cell):
        self.cell = cell

    def __getattr__(self, name):
        value = getattr(self.cell, name)
        if not callable(value):
            return value

        async def call(*args, **kwargs):
            return value(*args, **kwargs)

        return call

    async def __aenter__(self):
        return self

    async def __aexit__(self, *exc):
        self.cell.close()


@pytest.fixture(params=["sync", "async"])
def kind(request):
    """Which client a test drives: ``Cell`` (through :class:`Awaiting`) or ``AsyncCell``."""
    return request.param


def connect(kind, url, token, *, lose=0, refuse=0, **kw):
    """A client of the test's kind; ``lose``, ``refuse``: over a failing transport (``client.http._transport``)."""
    if lose or refuse:
        kw["transport"] = (AsyncFlaky if kind == "async" else Flaky)(lose=lose, refuse=refuse)
    return AsyncCell(url, token, **kw) if kind == "async" else Awaiting(Cell(url, token, **kw))


async def table1(c, plan, label):
    """A gearbox run under the paper's rule, every action succeeding: Table 1's actions, row by row."""
    run = await c.start_run(plan, label=label, policy="paper")   # Table 1's looks follow the paper's rule
    assert run.status == "active" and run.count.value == "336" and run.installable == ["ca"]
    for visible, buffered, installed, action in TABLE1:
        answer = await c.look(run, split(visible))
        assert f"{answer.action.kind} {answer.action.part}" == action, answer.decision.explain
        assert answer.row.buffered == split(buffered) and answer.row.installed == split(installed)
        assert answer.decision.exact and answer.run.pending is not None
        done = await c.outcome(answer, "success")
        assert done.row.outcome == "success" and done.run.pending is None
        assert (done.run.status == "complete") == (action == TABLE1[-1][3])   # complete at its last install
    with pytest.raises(RunComplete):
        await c.look(run.id, [])
    return run


def test_a_gearbox_run_gives_table1(svc, token, plan, kind):
    assert plan.name == "gearbox" and plan.units == 10 and plan.format == "yaml"

    async def drive():
        async with connect(kind, svc.url, token, timeout=10) as c:
            assert (await c.upload_plan(GEARBOX.read_text())).id == plan.id  # the same plan, as text: the same id
            # two runs at once (an AsyncCell's requests interleave; a Cell's run one after the other)
            runs = await asyncio.gather(*(table1(c, plan, f"{kind} {i}") for i in range(2)))
            for run in runs:
                final = await c.state(run.id)
                assert final.status == "complete" and final.finished and final.progress.installed == 10
                trace = await c.trace(run.id)
                assert [f"{r.action.kind} {r.action.part}" for r in trace.rows] == [a for *_, a in TABLE1]
            done = {r.id for r in await c.runs(status="complete")}
            assert {run.id for run in runs} <= done
            assert (await c.plan(plan.id)).plan["name"] == "gearbox"
            assert (await c.health()).ok

    asyncio.run(drive())


def test_a_lost_answer_is_retried_with_the_same_key_and_answered_from_the_store(svc, token, cell, plan, kind):
    run = cell.start_run(plan.id)

    async def drive():
        async with connect(kind, svc.url, token, lose=1, backoff=0.01) as c:
            answer = await c.look(run.id, ["rl", "ra"])
            assert c.attempts == 2 and c.replayed  # the second attempt got the stored answer of the first
            sent = c.http._transport.sent
            assert len(sent) == 2 and sent[0].headers["Idempotency-Key"] == sent[1].headers["Idempotency-Key"]
            assert sent[0].content == sent[1].content
        assert f"{answer.action.kind} {answer.action.part}" == "buffer rl"
        state = cell.state(run.id)
        assert state.seq == 1 and state.rows == 1  # decided once, not twice
        # the next request has a key of its own
        async with connect(kind, svc.url, token, lose=1, backoff=0.01) as c:
            await c.outcome(run.id, "success")
            again = c.http._transport.sent
            assert c.replayed and len({r.headers["Idempotency-Key"] for r in again}) == 1
            assert again[0].headers["Idempotency-Key"] != sent[0].headers["Idempotency-Key"]
        assert cell.state(run.id).seq == 2

    asyncio.run(drive())


def test_the_same_request_sent_twice_gets_the_first_answer_byte_for_byte(svc, token, cell, plan):
    run = cell.start_run(plan.id)
    with httpx.Client(base_url=svc.url, headers={"Authorization": f"Bearer {token}"}) as h:
        sent = [h.post(f"/runs/{run.id}/looks", json={"visible": ["ca"]}, headers={"Idempotency-Key": "same-key"})
                for _ in range(2)]
    assert sent[0].status_code == sent[1].status_code == 200
    assert sent[1].content == sent[0].content and sent[1].headers["Idempotent-Replayed"] == "true"
    assert cell.state(run.id).seq == 1


def test_a_server_error_is_retried_and_a_refusal_is_not(svc, token, cell, plan, kind):
    run = cell.start_run(plan.id)

    async def drive():
        async with connect(kind, svc.url, token, refuse=2, backoff=0.01) as c:
            assert (await c.look(run.id, ["ca"])).action.part == "ca"
            assert c.attempts == 3 and not c.replayed
            assert len({r.headers["Idempotency-Key"] for r in c.http._transport.sent}) == 1
        async with connect(kind, svc.url, token, refuse=5, retries=2, backoff=0.01) as c:
            with pytest.raises(ServerError) as err:
                await c.state(run.id)
            assert err.value.status == 503 and c.attempts == 3
            c.http._transport.refuse = 0
            with pytest.raises(ActionPending):
                await c.look(run.id, ["st"])  # install ca is pending: a 409, refused at once
            assert c.attempts == 1

    asyncio.run(drive())


def test_errors_are_typed(svc, token, cell, plan, kind):
    async def drive():
        async with connect(kind, svc.url, token) as c:
            with pytest.raises(NotFound) as err:
                await c.state(10**9)
            e = err.value
            assert (e.status, e.code) == (404, "run_not_found") and "GET /runs" in e.hint and isinstance(e, CellError)
            assert "404 run_not_found" in str(e)

            run = await c.start_run(plan.id)
            with pytest.raises(LookContradictsState) as err:
                await c.look(run.id, ["rl", "rl"])  # one unit of rl in the plan
            e = err.value
            assert (e.status, e.code, e.where) == (409, "look_contradicts_state", "body.visible") and e.hint
            with pytest.raises(UnknownPart) as err:
                await c.look(run.id, ["rl", "gear"])
            assert (err.value.status, err.value.where) == (422, "body.visible[1]")
            with pytest.raises(NoPendingAction):
                await c.outcome(run.id, "success")
            with pytest.raises(NoPendingAction):
                await c.cancel(run.id)
            await c.look(run.id, ["ca"])
            assert (await c.cancel(run.id)).cancelled.action.part == "ca"
            assert (await c.state(run.id)).seq == 2  # the refusals changed nothing
            with pytest.raises(InvalidPlan) as err:
                await c.upload_plan({"name": "cycle", "parts": ["a", "b"], "requires": {"a": ["b"], "b": ["a"]}})
            assert err.value.problems and err.value.problems[0]["severity"] == "error"
            with pytest.raises(TypeError):
                await c.look(run.id, "ca")  # a list of part ids, not one string
        with pytest.raises(Unauthorized) as err:
            async with connect(kind, svc.url, "opp_not-a-token") as c:
                await c.state(run.id)
        assert err.value.status == 401

    asyncio.run(drive())


def test_no_answer_at_all_is_service_unreachable(kind):
    async def drive():
        async with connect(kind, f"http://127.0.0.1:{free_port()}", "opp_x", retries=1, backoff=0.01, timeout=2) as c:
            with pytest.raises(ServiceUnreachable) as err:
                await c.look(1, [])
            assert err.value.status is None and c.attempts == 2

    asyncio.run(drive())


def test_both_clients_have_the_same_methods_and_an_async_cell_awaits_them():
    methods = [name for name in dir(Cell) if not name.startswith("_") and name != "close"]
    assert {"upload_plan", "start_run", "look", "outcome", "cancel", "state", "trace", "runs", "health"} <= set(methods)
    blocking, waiting = Cell("http://127.0.0.1:9", "opp_x"), AsyncCell("http://127.0.0.1:9", "opp_x")
    for name in methods:
        assert getattr(AsyncCell, name) is getattr(Cell, name)  # one definition, sent by each client's transport
        answer = inspect.signature(getattr(blocking, name)).return_annotation
        assert answer == inspect.signature(getattr(waiting, name)).return_annotation and "_Call" not in answer
        assert inspect.iscoroutinefunction(getattr(waiting, name))
        assert not inspect.iscoroutinefunction(getattr(blocking, name))
    blocking.close()
    asyncio.run(waiting.aclose())


def test_without_httpx_the_import_says_what_to_install():
    code = "import sys; sys.modules['httpx'] = None\ntry:\n import opportune.client\nexcept ImportError as e:\n print(e)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout
    assert "pip install 'opportune[service]'" in out and "httpx" in out


def test_a_path_given_as_a_string_is_read_as_a_file(cell, plan, tmp_path):
    """``upload_plan("examples/gearbox.yaml")`` reads the file (it used to be taken for plan text: 422); a
    one-line name of a plan file that does not exist says so, before any request."""
    assert cell.upload_plan(str(GEARBOX)).id == plan.id
    with pytest.raises(FileNotFoundError, match="no such plan file"):
        cell.upload_plan(str(tmp_path / "nope.yaml"))


def test_a_shipped_plan_is_uploaded_and_run_by_its_name(cell):
    """`salbp:ARC111` names the shipped graph, not a file to read here: the service reads it."""
    up = cell.upload_plan("salbp:ARC111")
    assert up.name == "ARC111" and up.format == "in2" and up.units == 111
    run = cell.start_run("example:gearbox", policy="paper")
    assert run.plan.name == "gearbox" and run.count.value == "336"
    with pytest.raises(CellError) as info:
        cell.upload_plan("salbp:NOPE")
    assert info.value.code == "unknown_plan" and "salbp:ARC111" in info.value.hint
