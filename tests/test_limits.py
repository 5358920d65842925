"""One table of limits (:mod:`opportune.limits`): the command line and the service read every bound from it.

* Each module's bound is the table's, and so is each bound the OpenAPI document, the plan's JSON Schema
  and the command line's options state.
* docs/service.md prints the table as the module has it.
* ``serve --max-body`` (and ``Settings.max_body``) may lower the body's bound, never raise it past the
  largest plan file the readers read; a body past it is refused (413) before it is read, and plan text
  past it is refused as a file of that size is, in the library too.
* A plan past a bound is refused by ``opportune check`` and by ``POST /plans`` with the same message.
"""

from __future__ import annotations

import json
import re
import uuid
from pathlib import Path

import pytest
from typer.testing import CliRunner

from opportune import limits
from opportune.cli import app as cli_app
from opportune.formats.problems import CONTROL_CHARS

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


def test_every_module_takes_its_bounds_from_the_table():
    from opportune.formats import documents, graphs, looks, sequences, validate
    from opportune.planning import plan, products

    taken = {
        "plan_bytes": documents.MAX_FILE_BYTES, "parts": plan.MAX_PARTS, "quantity": plan.MAX_QUANTITY,
        "units": plan.MAX_UNITS, "strategies": plan.MAX_STRATEGIES, "constraints": plan.MAX_CONSTRAINTS,
        "weight": plan.MAX_WEIGHT, "values": documents.MAX_VALUES, "depth": documents.MAX_DEPTH,
        "aliases": documents.MAX_ALIASES, "alias_values": documents.MAX_ALIAS_VALUES, "text": validate.MAX_TEXT, "id": validate.MAX_ID,
        "tasks": graphs.MAX_TASKS, "pairs": graphs.MAX_PAIRS, "lines": graphs.MAX_LINES,
        "line_chars": graphs.MAX_LINE_CHARS, "products": products.MAX_PRODUCTS,
        "looks_bytes": looks.MAX_LOOKS_BYTES, "looks": looks.MAX_LOOKS, "look_parts": looks.MAX_LOOK_PARTS,
        "sequence_bytes": sequences.MAX_SEQUENCE_BYTES, "sequences": sequences.MAX_SEQUENCES,
        "sequence_items": sequences.MAX_SEQUENCE_ITEMS,
    }
    pytest.importorskip("fastapi")
    from opportune.service import config, idempotency, plans

    taken.update({"key": idempotency.MAX_KEY, "filename": plans.MAX_FILENAME})
    assert {k: v for k, v in taken.items()} == {k: limits.LIMITS[k].value for k in taken}
    assert config.Settings().max_body == limits.DEFAULT_MAX_BODY <= limits.MAX_BODY == limits.MAX_FILE_BYTES
    # the table's keys are unique and every one of its rows is either read by both doors or says which
    assert len(limits.LIMITS) == len({lim.key for lim in limits.LIMITS.values()})


def _walk(node, path=()):
    if isinstance(node, dict):
        yield path, node
        for k, v in node.items():
            yield from _walk(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _walk(v, path + (i,))


def test_the_plan_schema_states_the_tables_bounds_and_printable_text():
    from opportune.formats.validate import plan_schema

    schema = plan_schema()
    assert schema["properties"]["parts"]["maxItems"] == limits.MAX_PARTS
    assert schema["properties"]["strategies"]["maxItems"] == limits.MAX_STRATEGIES
    strings = [(p, n) for p, n in _walk(schema) if n.get("type") == "string"]
    assert len(strings) >= 8
    # the length is said once, not as each string's maxLength: a pattern with a maxLength of 100,000 costs
    # schemathesis seconds per generated plan
    assert f"at most {limits.MAX_TEXT:,} characters" in schema["description"]
    for path, node in strings:
        pattern = re.compile(node["pattern"])
        assert not pattern.search("a\x1bb") and not pattern.search("a\x9bb") and not pattern.search("\x07"), path
        assert pattern.search("ca"), path


def test_the_command_lines_options_take_the_tables_bounds():
    import typer.main

    command = typer.main.get_command(cli_app)
    for name in ("replay", "simulate", "evaluate"):
        [option] = [p for p in command.commands[name].params if p.name == "buffer_capacity"]
        assert option.type.max == limits.MAX_BUFFER, name
    refused = runner.invoke(cli_app, ["replay", "example:gearbox", "example:gearbox-table1", "--buffer-capacity",
                                      str(limits.MAX_BUFFER + 1)])
    assert refused.exit_code == 2 and f"{limits.MAX_BUFFER}" in refused.output


def test_the_service_page_prints_the_table():
    text = (ROOT / "docs" / "service.md").read_text(encoding="utf-8")
    printed = text.split("<!-- limits-table -->\n", 1)[1].split("\n<!-- /limits-table -->", 1)[0]
    assert printed == limits.markdown_table()
    assert "service.md#limits" in (ROOT / "docs" / "plan-files.md").read_text(encoding="utf-8")


def test_an_option_may_lower_a_limit_and_not_raise_it():
    assert limits.check_option("--max-body", limits.MAX_BODY, limits.MAX_BODY) == limits.MAX_BODY
    with pytest.raises(ValueError, match=f"maximum of 33,554,432 bytes .32 MiB.*at most {limits.MAX_BODY}"):
        limits.check_option("--max-body", limits.MAX_BODY + 1, limits.MAX_BODY)
    with pytest.raises(ValueError, match="minimum"):
        limits.check_option("--max-body", 10, limits.MAX_BODY, limits.MIN_BODY)


def test_plan_text_past_the_file_bound_is_refused_as_a_file_is(tmp_path):
    from opportune.formats.loader import check_text, read_plan

    big = tmp_path / "big.yaml"
    with big.open("wb") as f:        # sparse: the reader reads the bound and one byte more, then stops
        f.truncate(limits.MAX_FILE_BYTES + 1)
    from_file = read_plan(big).errors[0]
    text = "parts: [a]\n" + "#" * limits.MAX_FILE_BYTES
    from_text = check_text(text, file=str(big)).errors[0]
    assert from_file.message == from_text.message and "33,554,432 bytes" in from_text.message
    # multi-byte characters count as the bytes a file of them would hold
    assert not check_text("parts: [a]\n# " + "é" * (limits.MAX_FILE_BYTES // 2 + 10)).ok
    assert check_text("parts: [a]\n# " + "é" * 1000).ok


# ---------------------------------------------------------------- the service

@pytest.fixture(scope="module")
def service(tmp_path_factory):
    pytest.importorskip("fastapi")
    from fastapi.testclient import TestClient

    from opportune.service.app import create_app
    from opportune.service.auth import create_token
    from opportune.service.config import Settings
    from opportune.service.storage import Store

    url = f"sqlite:///{tmp_path_factory.mktemp('limits') / 'l.db'}"
    store = Store(url)
    token = create_token(store, cell="cell-l")[1]
    with TestClient(create_app(Settings(db_url=url, max_body=limits.MAX_BODY), store)) as client:
        yield client, {"Authorization": f"Bearer {token}"}


def test_max_body_past_the_readers_bound_is_refused_at_start(tmp_path):
    from opportune.service.config import Settings

    with pytest.raises(ValueError, match="maximum of 33,554,432 bytes"):
        Settings(max_body=64 << 20)
    r = runner.invoke(cli_app, ["serve", "--max-body", str(64 << 20), "--db", str(tmp_path / "s.db")])
    assert r.exit_code == 1 and "--max-body 67,108,864 is over its maximum of 33,554,432 bytes" in r.output, r.output
    assert not (tmp_path / "s.db").exists()     # refused before anything is opened
    r = runner.invoke(cli_app, ["serve", "--max-body", "100", "--db", str(tmp_path / "s.db")])
    assert r.exit_code == 1 and "minimum of 1,024" in r.output, r.output


def test_a_body_past_the_bound_is_refused_at_the_largest_max_body(service):
    client, auth = service
    body = b"#" * (limits.MAX_BODY + 1)
    r = client.post("/plans", content=body, headers={**auth, "Content-Type": "application/yaml"})
    assert r.status_code == 413 and r.json()["error"]["code"] == "body_too_large", r.text[:300]
    assert f"{limits.MAX_BODY}" in r.json()["error"]["message"]
    # without a declared length (chunked), counted as it arrives
    r = client.post("/plans", content=iter([body[:1 << 24], body[1 << 24:]]),
                    headers={**auth, "Content-Type": "application/yaml"})
    assert r.status_code == 413, r.text[:300]


def test_check_and_the_service_refuse_a_plan_past_a_bound_with_the_same_message(service, tmp_path):
    client, auth = service
    plans = {
        "parts": "parts: [" + ", ".join(f"p{i}" for i in range(limits.MAX_PARTS + 1)) + "]\n",
        "text": "name: " + "n" * (limits.MAX_TEXT + 1) + "\nparts: [a]\n",
        "id": "parts: [a, " + "i" * (limits.MAX_ID + 1) + "]\n",
        "strategies": "parts: [a, b]\nstrategies: [" + ", ".join(
            f"{{name: s{i}, requires: {{b: [a]}}}}" for i in range(limits.MAX_STRATEGIES + 1)) + "]\n",
    }
    for what, text in plans.items():
        path = tmp_path / f"{what}.yaml"
        path.write_text(text)
        cli = runner.invoke(cli_app, ["check", str(path), "--json"])
        assert cli.exit_code == 1, (what, cli.output[:300])
        cli_messages = [p["message"] for p in json.loads(cli.stdout)["problems"]]
        r = client.post("/plans", params={"filename": str(path)}, content=text.encode(),
                        headers={**auth, "Content-Type": "application/yaml", "Idempotency-Key": uuid.uuid4().hex})
        assert r.status_code == 422, (what, r.text[:300])
        service_messages = [p["message"] for p in r.json()["error"]["problems"]]
        assert cli_messages == service_messages and f"{limits.LIMITS[what].value:,}" in cli_messages[0], what


def test_the_openapi_document_states_the_tables_bounds(service):
    client, _auth = service
    doc = client.get("/openapi.json").json()
    schemas = doc["components"]["schemas"]
    run, look = schemas["RunIn"]["properties"], schemas["LookIn"]["properties"]
    assert run["label"]["maxLength"] == limits.MAX_LABEL
    assert run["cell"]["anyOf"][0]["maxLength"] == limits.MAX_NAME
    assert run["buffer_capacity"]["anyOf"][0]["maximum"] == limits.MAX_BUFFER
    assert run["products"]["anyOf"][0]["maximum"] == limits.MAX_PRODUCTS
    assert look["visible"]["maxItems"] == limits.MAX_LOOK
    assert look["visible"]["items"]["maxLength"] == limits.MAX_ID
    assert schemas["PlanDocumentPartId"]["anyOf"][0]["maxLength"] == limits.MAX_ID
    params = {(p["in"], p["name"]): p["schema"] for item in doc["paths"].values() for op in item.values()
              for p in op.get("parameters", [])}
    assert params[("header", "Idempotency-Key")]["maxLength"] == limits.MAX_KEY
    assert params[("query", "limit")]["maximum"] == limits.MAX_PAGE
    assert params[("query", "filename")]["anyOf"][0]["maxLength"] == limits.MAX_FILENAME
    assert f"{limits.MAX_BODY:,}" in doc["paths"]["/plans"]["post"]["responses"]["413"]["description"]
    # every text a request may send is stated printable: a control character is invalid input, not a refusal
    texts = [(path, node) for path, node in _walk(doc) if node.get("type") == "string" and "enum" not in node
             and path[:3] != ("components", "schemas", "ErrorBody") and "pattern" not in node
             and any(k in path for k in ("requestBody", "parameters", "RunIn", "LookIn", "PlanUploadWrapper"))]
    assert not texts, texts[:5]
    for path, node in _walk(doc):
        if "pattern" in node and any(k in path for k in ("RunIn", "LookIn", "PlanUploadWrapper", "parameters")):
            assert not re.search(node["pattern"], "a\x1bb"), path
    assert CONTROL_CHARS  # the characters the patterns leave out are the ones the middleware refuses
