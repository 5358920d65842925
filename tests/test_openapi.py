"""The OpenAPI document at /openapi.json says exactly what the service does.

* Every operation has a stable camelCase id, a response model, and the error model on every error status
  it can answer with; the Idempotency-Key header is required where the service requires it.
* Real answers, successes and refusals, validate against the document (an in-process app driving
  Table 1 and every kind of refusal).
* A client generated from the document (openapi-python-client, offline) drives a gearbox run over HTTP.
* Schemathesis, in process: no server error, and every answer's status, content type, headers and
  body as documented.
"""

from __future__ import annotations

import collections
import copy
import importlib
import json
import os
import re
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from conftest import GEARBOX
from test_sequencer import TABLE1

pytest.importorskip("fastapi")
from fastapi.testclient import TestClient  # noqa: E402
from jsonschema import Draft202012Validator  # noqa: E402
from referencing import Registry, Resource  # noqa: E402
from referencing.jsonschema import DRAFT202012  # noqa: E402

from opportune.service.app import create_app  # noqa: E402
from opportune.service.auth import create_token  # noqa: E402
from opportune.service.config import Settings  # noqa: E402
from opportune.service.storage import Store  # noqa: E402

MAX_BODY = 64 * 1024
OPERATIONS = {
    ("get", "/healthz"): "health",
    ("post", "/plans"): "uploadPlan",
    ("get", "/plans"): "listPlans",
    ("get", "/plans/{plan_id}"): "getPlan",
    ("get", "/cells"): "listCells",
    ("post", "/runs"): "startRun",
    ("get", "/runs"): "listRuns",
    ("get", "/runs/{run_id}"): "getRun",
    ("get", "/runs/{run_id}/trace"): "getTrace",
    ("get", "/runs/{run_id}/graph"): "getGraph",
    ("post", "/runs/{run_id}/looks"): "postLook",
    ("post", "/runs/{run_id}/outcomes"): "postOutcome",
    ("post", "/runs/{run_id}/cancel"): "cancelAction",
    ("post", "/runs/{run_id}/ticket"): "createTicket",
    ("get", "/runs/{run_id}/events"): "streamEvents",
}
WRITES = {"startRun", "postLook", "postOutcome", "cancelAction"}


def _pointer(text: str) -> str:
    return text.replace("~", "~0").replace("/", "~1").replace("{", "%7B").replace("}", "%7D")


def split(text):
    return [p for p in text.split(",") if p]


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """The application in process over a fresh SQLite file, with two cells' tokens and an operator's."""
    url = f"sqlite:///{tmp_path_factory.mktemp('openapi') / 'api.db'}"
    store = Store(url)
    tokens = {"a": create_token(store, cell="cell-a")[1], "b": create_token(store, cell="cell-b")[1],
              "op": create_token(store, operator="ops")[1]}
    app = create_app(Settings(db_url=url, max_body=MAX_BODY), store)
    with TestClient(app) as client:
        yield app, client, tokens


@pytest.fixture(scope="module")
def spec(env):
    app, client, _tokens = env
    r = client.get("/openapi.json")
    assert r.status_code == 200
    return r.json()


class Contract:
    """Sends requests by operation id and checks every answer against the OpenAPI document."""

    def __init__(self, spec: dict, client: TestClient):
        self.spec = spec
        self.client = client
        self.ops = {op["operationId"]: (method, path, op) for path, item in spec["paths"].items()
                    for method, op in item.items()}
        self.registry = Registry().with_resource("urn:openapi", Resource.from_contents(spec, default_specification=DRAFT202012))
        self.seen: set[tuple[str, int]] = set()
        self.codes: set[tuple[str, int, str]] = set()

    def check(self, op_id: str, response) -> None:
        _method, _path, op = self.ops[op_id]
        status = str(response.status_code)
        assert status in op["responses"], f"{op_id} answered {status}, not documented: {response.text[:300]}"
        documented = op["responses"][status]
        content = documented.get("content", {})
        media = response.headers["content-type"].split(";")[0]
        assert media in content, f"{op_id} {status}: content type {media}, documented {sorted(content)}"
        self.seen.add((op_id, response.status_code))
        for name, header in documented.get("headers", {}).items():
            if name.lower() in response.headers:
                self.validate({"$ref": "urn:openapi#/paths/" + _pointer(_path) + f"/{_method}/responses/{status}"
                               f"/headers/{_pointer(name)}/schema"}, response.headers[name.lower()], (op_id, name))
        if media == "text/event-stream":
            return self.check_events(op_id, content[media]["schema"], response.read().decode())
        ref = content[media]["schema"]["$ref"]  # every JSON answer is a named model
        self.validate({"$ref": "urn:openapi" + ref}, response.json(), (op_id, status))
        if response.status_code >= 400:   # the error's code is one the document names for this status
            code = response.json()["error"]["code"]
            assert f"`{code}`" in documented["description"], (op_id, status, code, documented["description"])
            self.codes.add((op_id, response.status_code, code))

    def validate(self, schema: dict, value, what) -> None:
        validator = Draft202012Validator(schema, registry=self.registry, format_checker=Draft202012Validator.FORMAT_CHECKER)
        problems = [f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(value)]
        assert not problems, f"{what} does not match {schema}: {problems[:5]}"

    def check_events(self, op_id: str, schema: dict, text: str) -> None:
        """Each event of the stream, and its JSON data, as documented for its name."""
        events = []
        for block in text.split("\n\n"):
            fields = dict(line.split(": ", 1) for line in block.splitlines() if line and not line.startswith(":"))
            if "data" in fields:
                events.append(fields)
        assert events, text[:200]
        for event in events:
            self.validate(schema, event, (op_id, event["event"]))
            branch = next(b for b in schema["oneOf"] if event["event"] in b["properties"]["event"]["enum"])
            data = branch["properties"]["data"]
            assert data["contentMediaType"] == "application/json"
            self.validate({"$ref": "urn:openapi" + data["contentSchema"]["$ref"]}, json.loads(event["data"]),
                          (op_id, event["event"]))
        self.events = [e["event"] for e in events]

    def __call__(self, op_id: str, token: str | None = None, *, key: str | bool | None = None, headers=None,
                 expect: int | None = None, **kw):
        method, path, _op = self.ops[op_id]
        params = {k: kw.pop(k) for k in list(kw) if "{" + k + "}" in path}
        h = dict(headers or {})
        if token:
            h["Authorization"] = f"Bearer {token}"
        if op_id in WRITES and key is not False:
            h["Idempotency-Key"] = key or uuid.uuid4().hex
        r = self.client.request(method.upper(), path.format(**params), headers=h, **kw)
        self.check(op_id, r)
        if expect is not None:
            assert r.status_code == expect, r.text[:500]
        return r


# ---------------------------------------------------------------- the document itself


def test_every_operation_has_its_id_models_and_errors(spec):
    found = {(m, p): op["operationId"] for p, item in spec["paths"].items() for m, op in item.items()}
    assert found == OPERATIONS
    schemas = spec["components"]["schemas"]
    assert "HTTPValidationError" not in schemas and "ValidationError" not in schemas
    for (method, path), op_id in OPERATIONS.items():
        op = spec["paths"][path][method]
        statuses = {int(s) for s in op["responses"]}
        assert any(200 <= s < 300 for s in statuses), op_id
        assert 500 in statuses, op_id
        for status, answer in op["responses"].items():
            content = answer.get("content", {})
            if int(status) >= 400:
                error_body = {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorBody"}}}
                assert content == error_body, (op_id, status)
                assert "`" in answer["description"], (op_id, status)  # names the error codes
            elif op_id != "streamEvents":
                assert set(content) == {"application/json"} and "$ref" in content["application/json"]["schema"], op_id
        if op_id != "health":
            assert 401 in statuses and op.get("security"), op_id
        if "{run_id}" in path:
            assert {404, 422} <= statuses, op_id
        keys = [p for p in op.get("parameters", []) if p["name"] == "Idempotency-Key"]
        if op_id in WRITES:
            assert keys and keys[0]["required"] is True and keys[0]["in"] == "header", op_id
            assert {400, 403, 413, 415, 428} <= statuses, op_id
            success = op["responses"]["201" if op_id == "startRun" else "200"]
            assert "Idempotent-Replayed" in success["headers"]
        else:
            assert not keys, op_id
    for path in ("/runs/{run_id}/outcomes", "/runs/{run_id}/cancel"):
        assert "`no_pending_action`" in spec["paths"][path]["post"]["responses"]["409"]["description"]
    look = spec["paths"]["/runs/{run_id}/looks"]["post"]["responses"]
    assert "`look_contradicts_state`" in look["409"]["description"]
    assert look["200"]["content"]["application/json"]["schema"] == {"$ref": "#/components/schemas/LookAnswer"}
    assert spec["paths"]["/runs/{run_id}/events"]["get"]["responses"]["200"]["content"].keys() == {"text/event-stream"}
    # the plan upload: a plan in the file schema (opportune schema), or its text in a wrapper, or the file itself
    body = spec["paths"]["/plans"]["post"]["requestBody"]["content"]
    assert set(body) == {"application/json", "application/yaml", "text/plain"}
    assert schemas["PlanDocument"]["required"] == ["parts"] and "PlanDocumentPart" in schemas
    assert schemas["PlanDetail"]["properties"]["plan"] == {"$ref": "#/components/schemas/PlanDocument"}
    # every answer's object is closed: a field the server adds without the schema is a test failure
    for name, schema in schemas.items():
        if schema.get("type") == "object" and not name.startswith("PlanDocument") and name not in (
                "CancelIn", "LookIn", "OutcomeIn", "RunIn", "PlanUploadWrapper"):
            assert schema.get("additionalProperties") is False, name
    Draft202012Validator.check_schema({"$defs": schemas})


def test_the_document_is_valid_openapi_3_1(spec):
    assert spec["openapi"].startswith("3.1")
    try:  # the OpenAPI 3.1 meta-schema, as schemathesis ships it (the dev extra)
        from schemathesis.specs.openapi.definitions import OPENAPI_31
    except ImportError:
        pytest.skip("schemathesis is not installed: pip install -e '.[dev]'")
    problems = [f"{'/'.join(map(str, e.absolute_path))}: {e.message[:200]}"
                for e in Draft202012Validator(OPENAPI_31).iter_errors(spec)]
    assert not problems, problems[:5]
    for path, item in spec["paths"].items():
        for method, op in item.items():
            for p in op.get("parameters", []):
                if p["in"] == "path":
                    assert p["required"] is True and "{" + p["name"] + "}" in path, (method, path)


# ---------------------------------------------------------------- real answers against the document


def test_real_answers_match_the_document(env, spec):
    _app, client, t = env
    call = Contract(spec, client)
    a, b, op = t["a"], t["b"], t["op"]
    yaml = GEARBOX.read_text()

    call("health", expect=200)
    # plans
    up = call("uploadPlan", a, content=yaml, headers={"Content-Type": "application/yaml"}).json()
    plan = up["id"]
    call("uploadPlan", a, json={"text": yaml, "format": "yaml", "filename": "gearbox.yaml"}, expect=200)
    pair = {"name": "pair", "parts": ["x", {"id": "y", "quantity": 2}], "requires": {"y": ["x"]}}
    call("uploadPlan", a, json=pair, expect=201)
    # ?format= is the format of a raw body: a plan in JSON is read as JSON whatever it says (schemathesis found it)
    call("uploadPlan", a, json=pair, params={"format": "in2", "filename": "pair.IN2"}, expect=200)
    bad = call("uploadPlan", a, content="name: c\nparts: [a, b]\nrequires: {a: [b], b: [a]}\n",
               headers={"Content-Type": "application/yaml"}, expect=422).json()
    assert bad["error"]["code"] == "invalid_plan" and bad["error"]["problems"]
    call("uploadPlan", a, content=b"{not json", headers={"Content-Type": "application/json"}, expect=400)
    # a shipped plan by name, and names that are not shipped (nothing else is opened)
    assert call("uploadPlan", a, json={"shipped": "salbp:BOWMAN8"}).status_code in (200, 201)   # 200: stored
    call("uploadPlan", a, json={"shipped": "salbp:../../etc/passwd"}, expect=422)
    call("uploadPlan", a, json={"shipped": "example:gearbox-overconstrained"}, expect=422)   # invalid_plan
    call("uploadPlan", a, json={"text": yaml, "colour": "red"}, expect=422)
    call("uploadPlan", a, content=b"x" * (MAX_BODY + 1), headers={"Content-Type": "text/plain"}, expect=413)
    call("uploadPlan", op, content=yaml, headers={"Content-Type": "application/yaml"}, expect=403)
    call("uploadPlan", None, content=yaml, headers={"Content-Type": "application/yaml"}, expect=401)
    call("uploadPlan", "opp_not-a-token", content=yaml, headers={"Content-Type": "application/yaml"}, expect=401)
    call("listPlans", op, expect=200)
    call("listPlans", a, expect=200)   # a cell: the plans it uploaded
    call("getPlan", a, plan_id=plan, expect=200)
    call("getPlan", a, plan_id="0" * 64, expect=404)
    call("listCells", a, expect=200)
    call("listCells", op, expect=200)

    # a run: Table 1, every action succeeding
    key = uuid.uuid4().hex
    first = call("startRun", a, json={"plan": plan, "label": "table 1", "policy": "paper"}, key=key, expect=201)
    again = call("startRun", a, json={"plan": plan, "label": "table 1", "policy": "paper"}, key=key, expect=201)
    assert again.content == first.content and again.headers["idempotent-replayed"] == "true"
    run = first.json()["id"]
    call("startRun", a, json={"plan": plan, "label": "other"}, key=key, expect=422)  # the key, reused
    call("startRun", a, json={"plan": plan}, key=False, expect=428)
    call("startRun", a, json={"plan": plan}, key="k" * 201, expect=400)
    call("startRun", a, json={"plan": "nope"}, expect=422)
    call("startRun", a, json={"plan": "example:gearbox-overconstrained"}, expect=422)   # invalid_plan
    call("startRun", a, json={"plan": "salbp:NOPE"}, expect=422)                       # unknown_plan
    call("startRun", a, json={"plan": plan, "buffer_capacity": -1}, expect=422)
    call("startRun", a, json={"plan": plan, "cell": "cell-b"}, expect=403)
    call("startRun", op, json={"plan": plan}, expect=403)
    call("startRun", a, content=b'{"plan": ', headers={"Content-Type": "application/json"}, expect=400)
    call("getRun", a, run_id=run, expect=200)
    call("createTicket", a, run_id=run, expect=200)
    for visible, _buffered, _installed, action in TABLE1:
        look = call("postLook", a, run_id=run, json={"visible": split(visible)}, expect=200).json()
        assert f"{look['action']['kind']} {look['action']['part']}" == action
        call("postLook", a, run_id=run, json={"visible": split(visible)}, expect=409)  # action_pending
        call("getTrace", a, run_id=run, expect=200)
        call("postOutcome", a, run_id=run, json={"outcome": "success"}, expect=200)
    call("postLook", a, run_id=run, json={"visible": ["ca"]}, expect=409)  # run_complete: cl was the last part
    call("postLook", a, run_id=run, json={"visible": []}, expect=409)  # run_complete
    call("postOutcome", a, run_id=run, json={"outcome": "success"}, expect=409)  # no_pending_action
    call("cancelAction", a, run_id=run, expect=409)
    done = call("getRun", a, run_id=run, expect=200).json()
    assert done["status"] == "complete"
    call("getTrace", a, run_id=run, expect=200)
    call("getGraph", a, run_id=run, expect=200)
    with client.stream("GET", f"/runs/{run}/events", headers={"Authorization": f"Bearer {a}"}) as r:
        call.check("streamEvents", r)  # a complete run's stream: its snapshot, then complete, then the end
    assert call.events == ["snapshot", "complete"]

    # failures, defects, cancels, a limited buffer
    run2 = call("startRun", a, json={"plan": plan, "buffer_capacity": 1}, expect=201).json()["id"]
    call("postLook", a, run_id=run2, json={"visible": ["ca", "rl"]}, expect=200)  # install ca
    call("postOutcome", a, run_id=run2, json={"outcome": "failed", "keep": "buffer"}, expect=200)
    call("postLook", a, run_id=run2, json={"visible": ["rl"]}, expect=200)
    call("cancelAction", a, run_id=run2, json={}, expect=200)
    call("postLook", a, run_id=run2, json={"visible": ["rl", "dr"]}, expect=200)
    call("postOutcome", a, run_id=run2, json={"outcome": "defective"}, expect=200)
    call("postLook", a, run_id=run2, json={"visible": []}, expect=200)  # shake
    call("postOutcome", a, run_id=run2, json={"outcome": "failed"}, expect=409)  # a shake only succeeds
    call("postOutcome", a, run_id=run2, json={"outcome": "maybe"}, expect=422)
    call("postLook", a, run_id=run2, json={"visible": ["zz"]}, expect=422)  # unknown_part
    call("postLook", a, run_id=run2, json={"visible": "ca"}, expect=422)
    call("postLook", a, run_id=run2, json={"visible": ["ca"]}, key=False, expect=428)
    call("postLook", b, run_id=run2, json={"visible": ["ca"]}, expect=404)  # another cell's run
    call("postLook", op, run_id=run2, json={"visible": ["ca"]}, expect=403)
    call("postLook", a, run_id=10**9, json={"visible": []}, expect=404)
    call("postLook", a, run_id=run2, content=b"x" * (MAX_BODY + 1), expect=413)
    # a body that is not JSON (curl -d sends a form): 415, saying which Content-Type to send
    refused = call("postLook", a, run_id=run2, content=b'{"visible": []}',
                   headers={"Content-Type": "application/x-www-form-urlencoded"}, expect=415).json()["error"]
    assert refused["code"] == "unsupported_media_type" and "application/json" in refused["hint"]
    call("startRun", a, content=json.dumps({"plan": plan}).encode(), headers={"Content-Type": "text/plain"},
         expect=415)
    call("getRun", a, run_id=run2, expect=200)
    call("getTrace", a, run_id=run2, expect=200)
    call("getRun", b, run_id=run2, expect=404)
    call("getRun", op, run_id=run2, expect=200)
    call("getRun", a, run_id=0, expect=422)
    call("getGraph", a, run_id=10**9, expect=404)
    call("getTrace", None, run_id=run2, expect=401)
    call("createTicket", a, run_id=10**9, expect=404)
    call("listRuns", a, expect=200)
    call("listRuns", op, params={"status": "complete", "limit": 5}, expect=200)
    call("listRuns", a, params={"limit": 0}, expect=422)
    r = client.get(f"/runs/{run2}/events", params={"ticket": "forged"})
    call.check("streamEvents", r)
    assert r.status_code == 401
    call.check("streamEvents", client.get(f"/runs/{10**9}/events", headers={"Authorization": f"Bearer {a}"}))

    successes = {op_id for op_id, status in call.seen if status < 300}
    assert successes == set(OPERATIONS.values())
    assert {("uploadPlan", 422, "unknown_plan"), ("startRun", 422, "invalid_plan"), ("postLook", 428,
            "idempotency_key_required"), ("postLook", 413, "body_too_large")} <= call.codes


def test_an_estimated_decision_matches_the_document(spec):
    """Decisions over the decision budget (estimated, with their estimates) are not reached by a gearbox run."""
    from opportune.policies.base import Action, Decision, Estimate
    from opportune.service.views import decision_view

    decision = Decision(Action("install", "rl", "bin"), "install the candidate that keeps the most options",
                        exact=False, method="mcmc", estimates=(Estimate("rl", "share", 0.4, 0.01, "bin"),
                                                               Estimate("ra", "position", 2.5, 0.2)),
                        confidence=0.93, seconds=0.048)
    view = decision_view(decision)
    assert {"estimates", "confidence", "seconds"} <= set(view)
    Contract(spec, None).validate({"$ref": "urn:openapi#/components/schemas/Decision"}, view, "estimated decision")
    replayed = decision_view(Decision.recorded(json.loads(json.dumps(view))))
    Contract(spec, None).validate({"$ref": "urn:openapi#/components/schemas/Decision"}, replayed, "replayed decision")


# ---------------------------------------------------------------- examples


def examples(spec: dict):
    """Every example in the document: ``(place, media type, schema, value)``; the place is a component
    (``RunIn``, with no media type) or an operation id (``uploadPlan``), the schema the example's own."""
    for name, schema in spec["components"]["schemas"].items():
        for value in schema.get("examples", []):
            yield name, None, {"$ref": f"urn:openapi#/components/schemas/{name}"}, value
    for path, item in spec["paths"].items():
        for method, op in item.items():
            for where, body in [("requestBody", op.get("requestBody", {}))] + [
                    (f"responses/{status}", answer) for status, answer in op["responses"].items()]:
                for media, content in body.get("content", {}).items():
                    schema = {"$ref": f"urn:openapi#/paths/{_pointer(path)}/{method}/{where}/content/{_pointer(media)}/schema"}
                    for example in content.get("examples", {}).values():
                        yield op["operationId"], media, schema, example["value"]


def examples_by_place(spec: dict) -> dict[str, list]:
    """The examples' values by place (those of an operation as ``(media type, value)``)."""
    found: dict[str, list] = {}
    for place, media, _schema, value in examples(spec):
        found.setdefault(place, []).append((media, value) if media else copy.deepcopy(value))
    return found


def test_every_example_validates_against_its_schema(spec):
    places = examples_by_place(spec)
    assert {"RunIn", "LookIn", "OutcomeIn", "CancelIn", "uploadPlan", "LookAnswer", "Run"} <= set(places)
    assert {media for media, _value in places["uploadPlan"]} == {"application/json", "application/yaml", "text/plain"}
    check = Contract(spec, None)
    for place, media, schema, value in examples(spec):
        check.validate(schema, value, (place, media))
    with pytest.raises(AssertionError):  # the validation has teeth
        check.validate({"$ref": "urn:openapi#/components/schemas/LookIn"}, {"visible": "rl"}, "LookIn broken")


def test_the_request_examples_are_accepted_and_the_answer_examples_are_real(env, spec):
    """Sent as they are, the request examples are accepted; the run they start, driven through Table 1 to
    row 6, answers the document's LookAnswer and Run examples (but for its id, cell and times)."""
    _app, client, t = env
    call = Contract(spec, client)
    a = t["a"]
    found = examples_by_place(spec)
    runs, looks, outcomes, cancels = (found[k] for k in ("RunIn", "LookIn", "OutcomeIn", "CancelIn"))
    plans = {call("uploadPlan", a, headers={"Content-Type": media},
                  **({"json": value} if media == "application/json" else {"content": value.encode()})).json()["id"]
             for media, value in found["uploadPlan"]}
    assert runs[0]["plan"] in plans and len(plans) == 3  # the gearbox, a SALBP file, and a shipped SALBP graph
    assert {call("startRun", a, json=body, expect=201).json()["plan"]["id"] for body in runs} == {runs[0]["plan"]}
    run = call("startRun", a, json=runs[0], expect=201).json()["id"]  # the paper's rule, 4 buffer locations

    def normal(answer):  # what differs from run to run, but the id: its cell and times
        return json.loads(re.sub(r'"(created_at|updated_at|cell)": "[^"]*"', r'"\1": ""', json.dumps(answer)))

    assert split(TABLE1[0][0]) == looks[0]["visible"]
    for visible, *_ in TABLE1[:5]:
        call("postLook", a, run_id=run, json={"visible": split(visible)}, expect=200)
        call("postOutcome", a, run_id=run, json=outcomes[0], expect=200)
    look = call("postLook", a, run_id=run, json={"visible": split(TABLE1[5][0])}, expect=200).json()
    [look_example], [run_example] = found["LookAnswer"], found["Run"]
    run_example["id"] = look_example["run_id"] = look_example["run"]["id"] = run
    assert normal(look) == normal(look_example)
    assert normal(call("getRun", a, run_id=run, expect=200).json()) == normal(run_example)
    call("postOutcome", a, run_id=run, json=outcomes[0], expect=200)
    # the other examples, each where the run allows it: nothing visible (a buffered part is installed), an
    # install that failed (the part kept in the buffer), cancelled, and a defective part
    for body in [*outcomes[1:], *cancels]:
        call("postLook", a, run_id=run, json=looks[1], expect=200)
        call("cancelAction" if body in cancels else "postOutcome", a, run_id=run, json=body, expect=200)


# ---------------------------------------------------------------- a generated client


def generate_client(spec: dict, where: Path, package: str = "opportune_api") -> Path:
    """Generate a Python client from the document with openapi-python-client (offline) into ``where``."""
    pytest.importorskip("openapi_python_client")
    (where / "openapi.json").write_text(json.dumps(spec))
    (where / "config.yaml").write_text(json.dumps({"package_name_override": package, "post_hooks": []}))
    exe = Path(sys.executable).parent / "openapi-python-client"
    command = [str(exe)] if exe.exists() else [sys.executable, "-m", "openapi_python_client"]
    done = subprocess.run([*command, "generate", "--path", str(where / "openapi.json"), "--meta", "none",
                           "--output-path", str(where / package), "--config", str(where / "config.yaml")],
                          capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"})
    assert done.returncode == 0, done.stdout + done.stderr
    return where / package


def test_a_generated_client_drives_a_gearbox_run(spec, tmp_path):
    from opportune.service.testing import ServiceProcess

    generate_client(spec, tmp_path)
    sys.path.insert(0, str(tmp_path))
    try:
        api = importlib.import_module("opportune_api")
        from opportune_api.api.plans import get_plan, upload_plan
        from opportune_api.api.runs import get_run, get_trace, post_look, post_outcome, start_run
        from opportune_api.models import (ErrorBody, LookAnswer, LookIn, OutcomeIn, OutcomeInOutcome,
                                          PlanUploadWrapper, Run, RunIn, RunInPolicyType0)

        with ServiceProcess(tmp_path / "gen.db") as svc:
            client = api.AuthenticatedClient(base_url=svc.url, token=svc.token(cell="cell-g"),
                                             raise_on_unexpected_status=True)
            with client:
                up = upload_plan.sync_detailed(client=client, body=PlanUploadWrapper(text=GEARBOX.read_text(),
                                                                                    filename="gearbox.yaml"))
                assert up.status_code == 201, up.content
                plan = up.parsed
                assert plan.name == "gearbox" and plan.units == 10
                assert get_plan.sync(plan.id, client=client).plan.name == "gearbox"
                # the paper's rule (an enumerated choice in the document): Table 1's looks follow it
                run = start_run.sync(client=client, body=RunIn(plan=plan.id, label="generated",
                                                               policy=RunInPolicyType0("paper")),
                                     idempotency_key=uuid.uuid4().hex)
                assert isinstance(run, Run) and run.count.value == "336"
                for visible, _buffered, _installed, action in TABLE1:
                    key = uuid.uuid4().hex
                    first = post_look.sync_detailed(run.id, client=client, body=LookIn(visible=split(visible)),
                                                    idempotency_key=key)
                    answer = first.parsed
                    assert isinstance(answer, LookAnswer), first.content
                    assert f"{answer.action.kind} {answer.action.part}" == action
                    # a retry with the same key: the same answer, byte for byte, and nothing changed
                    retry = post_look.sync_detailed(run.id, client=client, body=LookIn(visible=split(visible)),
                                                    idempotency_key=key)
                    assert retry.content == first.content and retry.headers["idempotent-replayed"] == "true"
                    done = post_outcome.sync(run.id, client=client, body=OutcomeIn(outcome=OutcomeInOutcome.SUCCESS),
                                             idempotency_key=uuid.uuid4().hex)
                    assert done.row.outcome == "success"
                refused = post_look.sync(run.id, client=client, body=LookIn(visible=["ca"]),
                                         idempotency_key=uuid.uuid4().hex)
                assert isinstance(refused, ErrorBody) and refused.error.code == "run_complete"
                assert refused.error.status == 409 and refused.error.hint
                final = get_run.sync(run.id, client=client)
                assert final.status == "complete" and final.state.installed == split(TABLE1[-1][2]) + ["cl"]
                trace = get_trace.sync(run.id, client=client)
                assert len(trace.rows) == len(TABLE1)
    finally:
        sys.path.remove(str(tmp_path))
        for name in [m for m in sys.modules if m == "opportune_api" or m.startswith("opportune_api.")]:
            del sys.modules[name]


# ---------------------------------------------------------------- schemathesis

try:
    import schemathesis
    from hypothesis import HealthCheck, settings
    from schemathesis.checks import not_a_server_error
    from schemathesis.specs.openapi.checks import (content_type_conformance, ignored_auth, missing_required_header,
                                                   negative_data_rejection, response_headers_conformance,
                                                   response_schema_conformance, status_code_conformance,
                                                   unsupported_method)
except ImportError:  # the dev extra installs it (make test does)
    schemathesis = None

if schemathesis is None:
    def test_schemathesis_finds_answers_as_documented():
        pytest.skip("schemathesis is not installed: pip install -e '.[dev]'")

    def test_schemathesis_follows_the_links_from_a_run_to_its_looks_and_outcomes():
        pytest.skip("schemathesis is not installed: pip install -e '.[dev]'")
else:
    # Every check but positive_data_acceptance, which takes the refusal of a request the schema allows for
    # a bug: here most are the point (an unknown plan or part, a look that contradicts the run, no pending
    # action).  A missing Idempotency-Key is a 428, which says what to send.
    @schemathesis.check
    def error_code_documented(ctx, response, case):
        """An error's code is one the document names for its operation and status (the descriptions list them)."""
        if response.status_code < 400 or case.method.upper() != case.operation.method.upper():
            return None     # (another method on the path, sent by unsupported_method: a 405 the path answers)
        answers = case.operation.definition.raw["responses"]
        documented = answers.get(str(response.status_code), {}).get("description", "")
        code = response.json()["error"]["code"]
        if f"`{code}`" not in documented:
            raise AssertionError(f"{case.operation.label} answered {response.status_code} `{code}`, which the "
                                 f"document does not name: {documented!r}")
        return None

    CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_headers_conformance,
              response_schema_conformance, missing_required_header, negative_data_rejection, unsupported_method,
              ignored_auth, error_code_documented]
    # The checks' settings are the repository's schemathesis.toml, which `st run` reads too (one source):
    # a missing Idempotency-Key is a 428, and every refusal of invalid data is one of the service's.
    import tomllib

    CHECK_SETTINGS = tomllib.loads((Path(__file__).resolve().parents[1] / "schemathesis.toml").read_text())["checks"]
    assert CHECK_SETTINGS["missing_required_header"] == {"expected-statuses": [428]}

    @pytest.fixture(scope="module")
    def fuzz_ids(env):
        """The gearbox plan and a run of it, of cell a: path parameters that exist."""
        _app, client, t = env
        h = {"Authorization": f"Bearer {t['a']}"}
        plan = client.post("/plans", content=GEARBOX.read_text(),
                           headers={**h, "Content-Type": "application/yaml"}).json()["id"]
        run = client.post("/runs", json={"plan": plan}, headers={**h, "Idempotency-Key": uuid.uuid4().hex}).json()["id"]
        return {"path.plan_id": plan, "path.run_id": run}

    @pytest.fixture(scope="module")
    def fuzz_env(env, fuzz_ids):
        """The application for schemathesis: a cell's token, the gearbox plan and a run it may drive."""
        app, _client, t = env
        config = schemathesis.Config.from_dict({
            "seed": 12,
            "auth": {"openapi": {"HTTPBearer": {"bearer": t["a"]}}},
            "generation": {"max-examples": 25, "deterministic": True},
            "checks": CHECK_SETTINGS,
            # path parameters of a plan and a run that exist, so that looks and outcomes reach the sequencer
            "parameters": fuzz_ids,
        })
        return schemathesis.openapi.from_asgi("/openapi.json", app, config=config)

    @pytest.fixture
    def fuzzed(fuzz_env, request):
        # schemathesis 4 renames the test node per operation through `_nodeid`, which pytest 9.2 calls `_id`
        if not hasattr(request.node, "_nodeid"):
            request.node._nodeid = request.node.nodeid
        return fuzz_env

    # The event stream of an active run never ends by itself: its events are checked above, on a complete run.
    fuzz = schemathesis.pytest.from_fixture("fuzzed").exclude(operation_id="streamEvents")

    @fuzz.parametrize()
    @settings(deadline=None, suppress_health_check=list(HealthCheck))
    def test_schemathesis_finds_answers_as_documented(case):
        case.call_and_validate(checks=CHECKS)

    @pytest.fixture
    def fuzzed_by_an_operator(env, fuzz_ids, request):
        """The same application fuzzed with an operator's token: reads answer, every write is a 403, nothing
        is a 5xx (a few examples each: the answers are the cell's, seen from another door)."""
        if not hasattr(request.node, "_nodeid"):
            request.node._nodeid = request.node.nodeid
        app, _client, t = env
        config = schemathesis.Config.from_dict({
            "seed": 13, "auth": {"openapi": {"HTTPBearer": {"bearer": t["op"]}}},
            "generation": {"max-examples": 6, "deterministic": True}, "checks": CHECK_SETTINGS,
            "parameters": fuzz_ids})
        return schemathesis.openapi.from_asgi("/openapi.json", app, config=config)

    fuzz_operator = schemathesis.pytest.from_fixture("fuzzed_by_an_operator").exclude(operation_id="streamEvents")

    @fuzz_operator.parametrize()
    @settings(deadline=None, suppress_health_check=list(HealthCheck))
    def test_schemathesis_with_an_operator_token_finds_answers_as_documented(case):
        case.call_and_validate(checks=CHECKS)


    # ------------------------------------------------------------ stateful: runs driven through the links

    class FreshDatabase:
        """One application whose database is put back to a copy of a template (a cell's token, the gearbox plan)
        before each scenario: the same requests get the same answers (run ids from 1), which Hypothesis needs to
        generate, replay and shrink scenarios ("inconsistent data generation" otherwise).  Decisions are exact
        whatever the machine's load (``decision_budget=None``: over a budget a decision is estimated).

        The application is built once, and with it the gearbox's engine and the look-ahead's programme, which
        the scenarios share: an application per scenario spent most of the test building its routes and the
        programme again.  Exact decisions are a function of the run's state, so a programme carried over from
        the last scenario decides as a new one would."""

        def __init__(self, template: Path):
            self.template, self.db = template, template.with_name("scenario.db")
            shutil.copy(template, self.db)
            url = f"sqlite:///{self.db}"
            self.store = Store(url)
            self.app = create_app(Settings(db_url=url, max_body=MAX_BODY, decision_budget=None), self.store)

        def reset(self) -> None:
            self.store.dispose()   # every pooled connection closed (the pools open new ones on the new file)
            for name in (f"{self.db.name}-wal", f"{self.db.name}-shm"):
                self.db.with_name(name).unlink(missing_ok=True)
            shutil.copy(self.template, self.db)
            # the last scenario's runs, kept live in memory: the next scenario's run ids start from 1 again
            self.app.state.manager._live.clear()

    def test_schemathesis_follows_the_links_from_a_run_to_its_looks_and_outcomes(tmp_path):
        """Scenarios of up to 10 requests that start a run (from an uploaded plan, or the gearbox's id) and
        follow the document's links: startRun → postLook → postOutcome or cancelAction → postLook ...  Every
        answer as documented, and no server error.  Looks see the gearbox's parts, so that runs proceed."""
        template = tmp_path / "template.db"
        store = Store(f"sqlite:///{template}")
        token = create_token(store, cell="cell-a")[1]
        with TestClient(create_app(Settings(db_url=f"sqlite:///{template}"), store)) as client:
            plan = client.post("/plans", content=GEARBOX.read_text(), headers={
                "Authorization": f"Bearer {token}", "Content-Type": "application/yaml"}).json()["id"]
        store.dispose()
        fresh = FreshDatabase(template)
        parts = ["ca", "ba", "rl", "dr", "sm", "ml", "ra", "co", "st", "cl"]
        config = schemathesis.Config.from_dict({
            "seed": 12,
            "auth": {"openapi": {"HTTPBearer": {"bearer": token}}},
            "generation": {"deterministic": True},
            # not the constants schemathesis would collect from the modules loaded so far: other tests change them
            "analysis": {"constants": {"enabled": False}},
            # the links the document declares (not those schemathesis would infer: reads, mostly)
            "phases": {"stateful": {"inference": {"algorithms": []}}},
            # as in the stateless test, a refusal of what the schema allows is not taken for a bug
            "checks": {**CHECK_SETTINGS, "positive_data_acceptance": {"enabled": False}},
            "dictionaries": {"parts": {"values": parts}, "plans": {"values": [plan]}, "cells": {"values": ["cell-a"]}},
            "parameters": {"body.visible[*]": {"dictionary": "parts", "probability": 0.95},
                           "body.plan": {"dictionary": "plans", "probability": 0.9},
                           "body.cell": {"dictionary": "cells", "probability": 0.9},
                           # one product: the looks name the gearbox's parts (several products are driven over
                           # HTTP in test_products.py, and fuzzed by the stateless test above)
                           "body.products": 1},
        })
        schema = schemathesis.openapi.from_asgi("/openapi.json", fresh.app, config=config).include(
            operation_id=["uploadPlan", "startRun", "postLook", "postOutcome", "cancelAction"])
        machine = schema.as_state_machine()
        # Scenarios start with a plan or a run: a look, outcome or cancel on a random run id is a 404 that leads
        # nowhere.  The other starting rules are hidden, and the transition controller told which remain (else
        # it keeps budget for them, and the scenarios are no longer replayed alike).
        starts = frozenset(name for name in machine.root_rules if name.endswith(("_POST_plans", "_POST_runs")))
        assert len(starts) == 2, machine.root_rules
        seen: collections.Counter = collections.Counter()

        class Workflow(machine):
            root_rules = starts
            _root_labels = frozenset({"POST /plans", "POST /runs"})

            def setup(self):
                fresh.reset()

            def after_call(self, response, case):
                super().after_call(response, case)
                seen[case.operation.definition.raw["operationId"], response.status_code] += 1

        for name in machine.root_rules - starts:
            setattr(Workflow, name, None)
        # The derandomized scenarios follow the schema and this function's text: enough of them that some reach
        # outcomes and cancels whatever ran before (more as the schema grew: `products`, owners, 400 everywhere)
        Workflow.run(settings=settings(derandomize=True, database=None, max_examples=120, stateful_step_count=10,
                                       deadline=None, suppress_health_check=list(HealthCheck)))
        fresh.store.dispose()
        # the runs were driven (dozens of runs started and looks decided, outcomes and cancels, alone or after the
        # other tests): far fewer would mean the links no longer lead there
        assert seen["startRun", 201] >= 40 and seen["postLook", 200] >= 25, seen
        assert seen["postOutcome", 200] >= 8 and seen["cancelAction", 200] >= 6, seen
