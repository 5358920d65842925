"""The service's answers as Pydantic models: the exact OpenAPI at ``/openapi.json``, and the typed client's types.

Each model is the JSON that :mod:`opportune.service.views` (and the routes of
:mod:`opportune.service.app`) build, field for field: the routes *document*
their answers with these models (``responses=``) but do not serialise through
them, so an answer's bytes, and a replayed answer's, are exactly what was
stored, and the hot path pays nothing for the schema.  The tests validate real
answers against the OpenAPI document built from these models.

Every object's schema is closed (``additionalProperties: false``): a field the
server sends but the schema does not name is a test failure, not drift.  The
models themselves ignore unknown fields when *reading* an answer
(:class:`opportune.client.Cell` reads answers with them), so a client keeps
working against a newer server that adds a field.

Errors are one shape on every status: :class:`ErrorBody`.  :func:`errors`
builds a route's ``responses=`` entries from the statuses and error codes the
route can answer with.
"""

from __future__ import annotations

import datetime as dt
import json
from functools import lru_cache
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, WithJsonSchema

from opportune.formats.problems import PRINTABLE
from opportune.limits import MAX_BODY, MAX_FILENAME


class Model(BaseModel):
    """A JSON object of an answer: closed in the schema, tolerant when read."""

    model_config = ConfigDict(extra="ignore", populate_by_name=True,
                              json_schema_extra={"additionalProperties": False})


Part = str
Pair = Annotated[list[str], Field(min_length=2, max_length=2, description="`[before, after]` part ids")]
Timestamp = Annotated[dt.datetime, Field(description="UTC, ISO 8601 with milliseconds")]
#: A plan in the file schema; the OpenAPI document refers to ``PlanDocument`` (:func:`plan_document_schemas`).
PlanDocument = Annotated[dict[str, Any], WithJsonSchema({"type": "object", "x-plan-document": True})]


def _no_default(schema: dict) -> None:
    schema.pop("default", None)


def absent(description: str, default: Any = None, **kw) -> Any:
    """A field that is left out of the JSON when it does not apply (never ``null``)."""
    return Field(default, description=description, json_schema_extra=_no_default, **kw)


# ---------------------------------------------------------------- errors

class PlanProblem(Model):
    """One finding of ``opportune check`` about a plan file."""

    severity: Literal["error", "warning"]
    code: str = Field(..., description="A stable code of the finding (e.g. `cycle`, `unknown_part`)")
    message: str
    hint: str
    file: str | None
    line: int | None = Field(..., description="1-based, where the format gives one")
    parts: list[Part] = Field(..., description="The part ids involved")


class FieldProblem(Model):
    """One invalid field of a request."""

    where: str = Field(..., description="e.g. `body.visible[2]`, `query.limit`, `header Idempotency-Key`")
    message: str


class ErrorDetail(Model):
    status: int = Field(..., description="The HTTP status again")
    code: str = Field(..., description="Stable and machine-readable, e.g. `look_contradicts_state`, `run_not_found`")
    message: str = Field(..., description="What is wrong, for a person")
    hint: str = Field(..., description="What to do about it (may be empty)")
    where: str = absent("Where the problem is, e.g. `body.visible[1]`; absent when it is not in the request")
    problems: list[PlanProblem | FieldProblem] = absent(
        "`invalid_plan`, `plan_refused`: every finding of `opportune check`; `invalid_request`: every invalid field")


class ErrorBody(Model):
    """Every 4xx and 5xx answer: ``{"error": {status, code, message, hint, where}}``."""

    error: ErrorDetail


#: What each status means, and the codes the service answers it with (shown in the OpenAPI document).
STATUS_TEXT = {
    400: "The request could not be read",
    401: "No valid bearer token",
    403: "The token may not do this",
    404: "Not found (another cell's run is not found either)",
    409: "Refused in the run's present state; nothing changed",
    413: f"The body is larger than `opportune serve --max-body` (at most {MAX_BODY:,} bytes)",
    415: "The body is not JSON (`Content-Type: application/json`)",
    422: "Invalid request; nothing changed",
    428: "The `Idempotency-Key` header is missing",
    500: "The service failed; nothing changed (retry with the same `Idempotency-Key`)",
    503: "Over the counting budget for now; nothing changed (retry with the same `Idempotency-Key`)",
}

ERROR_HEADERS = {
    401: {"WWW-Authenticate": {"description": "`Bearer`", "schema": {"type": "string"}}},
    413: {"Connection": {"description": "`close`", "schema": {"type": "string"}}},
}


def errors(codes: dict[int, list[str]]) -> dict[int, dict]:
    """``responses=`` entries: for each status, the error model and the codes the route answers it with.
    Every route may answer 400 ``invalid_request``: a control character in its path or query."""
    codes = {**codes, 400: list(dict.fromkeys([*codes.get(400, []), "invalid_request"]))}
    out: dict[int, dict] = {}
    for status, names in sorted(codes.items()):
        text = STATUS_TEXT[status]
        if names:
            text += ": " + ", ".join(f"`{n}`" for n in names)
        entry: dict = {"model": ErrorBody, "description": text}
        if status in ERROR_HEADERS:
            entry["headers"] = ERROR_HEADERS[status]
        out[status] = entry
    return out


# ---------------------------------------------------------------- decisions and trace rows

class Action(Model):
    """One robot action: install a part (from the bin or a buffer location), buffer a visible part, or
    shake the bin and look again.  (``done`` closes the traces of runs from earlier versions, which took
    one more look after the last install; a run is now complete at the outcome of its last install.)"""

    kind: Literal["install", "buffer", "shake", "done"]
    part: Part | None = Field(..., description="The part to install or buffer; null for shake and done")
    source: Literal["bin", "buffer"] | None = Field(..., description="Where an installed part comes from; "
                                                                         "null for the other actions")


class Candidate(Model):
    """A part that could be installed now, with the admissible completions installing it keeps."""

    part: Part
    source: Literal["bin", "buffer"]
    options: str = Field(..., description="Admissible completions left after installing it (decimal text)")
    total: str | None = Field(..., description="Admissible completions now (decimal text); null when not counted")
    cost: float = Field(..., description="acquire + install")
    buffered_at: int | None = Field(..., description="Position in the buffer (0: buffered longest)")


class Position(Model):
    """The expected position (1 = next) of a visible part, which decided a buffer choice."""

    part: Part
    expected: float
    exact: str = Field(..., description="The exact fraction, e.g. `7/3`")


class Estimate(Model):
    """An estimated share of completions or expected position, with its standard error."""

    part: Part
    kind: Literal["share", "position", "slack"]
    value: float
    se: float
    source: Literal["bin", "buffer"] | None


class Decision(Model):
    """An action with the reasons it was chosen.  Estimated decisions (over the decision budget) also
    carry ``estimates``, ``confidence`` and ``seconds``."""

    action: Action
    rule: str = Field(..., description="Which rule of the policy applied")
    note: str
    candidates: list[Candidate] = Field(..., description="Every installable candidate, best first")
    positions: list[Position]
    exact: bool = Field(..., description="Whether the rule was applied to exact counts")
    method: str = Field(..., description="`exact`, or the estimate used (e.g. `mcmc`)")
    explain: str = Field(..., description="The reasons, as text")
    estimates: list[Estimate] = Field(default_factory=list, description="Only when `exact` is false")
    confidence: float = absent("Only when `exact` is false: the estimated probability that the action is the one "
                               "the exact rule would choose", 1.0)
    close: bool = absent("Only when `exact` is false: the estimate stopped on a near tie, at least 99.9% sure that "
                         "no other candidate is better by more than 1%; that is what the decision then states "
                         "(`explain`), and `confidence` changes nothing measurable", False)
    seconds: float = absent("Only when `exact` is false: the time the decision took", 0.0)


class Count(Model):
    """A number of admissible completions, as decimal text (JSON numbers lose digits): exact up to 4,300
    digits; a larger count is written with its first 17 digits in scientific notation
    (``2.8462596809170545e+35659``), as writing it exactly would take longer than a look's budget."""

    value: str
    log10: float | None = Field(..., description="log10 of the value; null when the value is 0")
    text: str = Field(..., description="The count as people read it, as the dashboard and `explain` write it: in full "
                                       "with grouped digits up to 15 digits (`40,320`), else three significant "
                                       "digits and the exponent (`6.13e98`)")


Outcome = Literal["success", "failed", "defective"]


class Row(Model):
    """One row of the trace, in the layout of the paper's Table 1 (state *before* the action)."""

    n: int = Field(..., description="1-based row number")
    visible: list[Part]
    buffered: list[Part]
    installed: list[Part]
    action: Action
    action_text: str = Field(..., description="e.g. `install ca`, `buffer rl`; empty for done")
    outcome: Literal["success", "failed", "defective", "failed, buffered"] | None = Field(
        ..., description="null while the action is pending (and for done)")
    count: Count | None = Field(..., description="Admissible completions before the action; null when over the "
                                                    "counting budget")
    reasons: Decision


# ---------------------------------------------------------------- examples in the OpenAPI document

#: The gearbox (``examples/gearbox.yaml``) as a plan document and as a file, and its id: the upload examples
#: of :mod:`opportune.service.app` send it, and the run examples are its Table 1 run (``policy: paper``) at
#: row 6, as the service answers them (tests/test_openapi.py checks both).
GEARBOX_PLAN = {
    "name": "gearbox", "description": "Ten-part gearbox of Fox & Kempf (reconstructed Figure 2)",
    "parts": ["ca", "ba", "rl", "dr", "sm", "ml", "ra", {"id": "co", "name": "cover"}, "st", "cl"],
    "requires": {"ba": ["ca"], "rl": ["ba"], "dr": ["ba"], "sm": ["ca"], "ml": ["sm"], "ra": ["ba"],
                 "co": ["rl", "dr", "ml", "ra"], "st": ["co"], "cl": ["rl", "sm", "ra"]},
}
GEARBOX_PLAN_ID = "8b871313b178f38819308677759c6fe510f3aeaec250cb00b07de0c214c36760"
GEARBOX_YAML = """\
name: gearbox
description: Ten-part gearbox of Fox & Kempf (reconstructed Figure 2)
parts: [ca, ba, rl, dr, sm, ml, ra, {id: co, name: cover}, st, cl]
requires:            # X: parts that must be installed before X
  ba: [ca]
  rl: [ba]
  dr: [ba]
  sm: [ca]
  ml: [sm]
  ra: [ba]
  co: [rl, dr, ml, ra]
  st: [co]
  cl: [rl, sm, ra]
"""
#: A SALBP file (BOWMAN8, shipped in ``opportune/datasets/salbp``): tasks, their times, precedences, ``-1,-1``.
BOWMAN8_IN2 = "8\n11\n17\n9\n5\n8\n12\n10\n3\n1,2\n2,3\n2,4\n3,5\n3,6\n4,6\n5,7\n6,8\n-1,-1\n"

_INSTALL_RL = {"kind": "install", "part": "rl", "source": "buffer"}
_DECISION = {
    "action": _INSTALL_RL, "rule": "install the candidate that keeps the most options", "note": "",
    "candidates": [
        {"part": "rl", "source": "buffer", "options": "49", "total": "228", "cost": 2.0, "buffered_at": 0},
        {"part": "dr", "source": "buffer", "options": "42", "total": "228", "cost": 2.0, "buffered_at": 2}],
    "positions": [], "exact": True, "method": "exact",
    "explain": "install rl (from buffer): install the candidate that keeps the most options\n"
               "  candidate rl from buffer #1: keeps 49 of 228 completions, cost 2\n"
               "  candidate dr from buffer #3: keeps 42 of 228 completions, cost 2",
}
_ROW = {"n": 6, "visible": ["cl", "co"], "buffered": ["rl", "ml", "dr"], "installed": ["ca", "ba"],
        "action": _INSTALL_RL, "action_text": "install rl (from buffer)", "outcome": None,
        "count": {"value": "228", "log10": 2.357935, "text": "228"}, "reasons": _DECISION}
RUN_EXAMPLE = {
    "id": 17, "cell": "cell-1", "label": "SN 1042",
    "plan": {"id": GEARBOX_PLAN_ID, "name": "gearbox"}, "status": "active", "policy": "paper", "buffer_capacity": 4,
    "products": 1,
    "seq": 11,
    "state": {"installed": ["ca", "ba"], "buffered": ["rl", "ml", "dr"],
              "in_bin": {"sm": 1, "ra": 1, "co": 1, "st": 1, "cl": 1}, "capacity": 4, "strategies": ["default"],
              "complete": False, "defects": 0},
    "installable": ["rl", "dr", "sm", "ra"], "progress": {"installed": 2, "units": 10},
    "count": {"value": "228", "log10": 2.357935, "text": "228"}, "pending": _ROW, "last_look": ["cl", "co"], "rows": 6,
    "finished": False, "totals": None, "created_at": "2025-03-14T09:41:07.215+00:00", "updated_at": "2025-03-14T09:43:52.604+00:00",
}
LOOK_EXAMPLE = {"run_id": 17, "seq": 11, "action": _INSTALL_RL, "decision": _DECISION, "row": _ROW,
                "run": RUN_EXAMPLE}
#: The answers' examples, by component: set by :func:`complete_openapi`, since FastAPI writes its document
#: without ``null`` values (they would be lost from the examples).
ANSWER_EXAMPLES = {"Run": [RUN_EXAMPLE], "LookAnswer": [LOOK_EXAMPLE]}


# ---------------------------------------------------------------- runs

class PlanRef(Model):
    id: str
    name: str


class Progress(Model):
    installed: int
    units: int


class Fixture(Model):
    """One fixture of a run building several products at once."""

    fixture: int = Field(..., description="1, 2, …")
    installed: list[Part] = Field(..., description="Part kinds installed on it, in order")
    complete: bool


class RunState(Model):
    """Where the assembly stands."""

    installed: list[Part] = Field(..., description="In installation order")
    buffered: list[Part] = Field(..., description="In buffer order (first: buffered longest)")
    in_bin: dict[Part, int] = Field(..., description="Units that can still be in the bin, per part")
    capacity: int | None = Field(..., description="Buffer locations; null: unlimited")
    strategies: list[str] = Field(..., description="Strategies still consistent with what was installed")
    complete: bool
    defects: int
    fixtures: list[Fixture] | None = Field(None, description="Several products at once: each fixture's installed "
                                                             "part kinds and whether its product is complete")


class Totals(Model):
    """What a complete run took, in the paper's accounting (the trace's actions and their outcomes)."""

    installed: int = Field(..., description="Units installed")
    looks: int = Field(..., description="Looks answered (rows of the trace)")
    motions: int = Field(..., description="Robot motions: installs and buffer moves reported, failed and defective "
                                          "ones included (the robot moved)")
    buffer_moves: int = Field(..., description="Buffer moves reported (bin to a buffer location)")
    buffer_peak: int = Field(..., description="Most parts in the buffer at once")
    shakes: int
    failed: int = Field(..., description="Actions reported failed")
    defects: int = Field(..., description="Parts found defective")
    time: float = Field(..., description="Motions, shakes and looks at the plan's costs (`simulation.costs`; by "
                                         "default a motion and a shake 1 each, a look 0): `simulate`'s time")


class Run(Model):
    """A run's full state."""

    id: int
    cell: str
    label: str
    plan: PlanRef
    status: Literal["active", "complete"]
    policy: str
    buffer_capacity: int | None
    products: int = Field(1, description="Products built at once on as many fixtures from one bin; with more than "
                                         "one, looks and buffered parts are part kinds and an install's part is "
                                         "KIND@FIXTURE")
    seq: int = Field(..., description="Events applied so far")
    state: RunState
    installable: list[Part] | None = Field(..., description="Parts that can go in now; null when over the "
                                                               "counting budget")
    progress: Progress
    count: Count | None = Field(..., description="Admissible completions left; null when over the counting budget")
    pending: Row | None = Field(..., description="The action decided and not yet reported")
    last_look: list[Part]
    rows: int = Field(..., description="Rows of the trace so far (the pending one included)")
    finished: bool
    totals: Totals | None = Field(..., description="Once the run is complete: what it took; null until then")
    created_at: Timestamp
    updated_at: Timestamp
    note: str = absent("Only in the answer of a run started under a policy's former name ('opportunistic'): what "
                       "to write instead")


class RunSummary(Model):
    """A run as listed."""

    id: int
    cell: str
    label: str
    plan: PlanRef
    status: Literal["active", "complete"]
    policy: str
    buffer_capacity: int | None
    products: int = Field(1, description="Products built at once (fixtures fed from one bin)")
    progress: Progress
    count: str | None = Field(..., description="Admissible completions left (decimal text)")
    count_text: str | None = Field(None, description="The same count as people read it (`Count.text`)")
    pending: str | None = Field(..., description="The pending action, as text")
    seq: int
    created_at: Timestamp
    updated_at: Timestamp


class RunList(Model):
    runs: list[RunSummary]


class LookAnswer(Model):
    """The action decided for a look, with its reasons, the new trace row and the run."""

    run_id: int
    seq: int
    action: Action
    decision: Decision
    row: Row
    run: Run
    part_kind: Part | None = Field(None, description="Several products at once: the part kind to pick (null for a "
                                                     "shake or done)")
    fixture: int | None = Field(None, description="Several products at once: the fixture an install goes to "
                                                  "(null for a buffer move, a shake or done)")


class OutcomeAnswer(Model):
    run_id: int
    seq: int
    outcome: Outcome
    keep: Literal["bin", "buffer"]
    row: Row = Field(..., description="The completed row")
    run: Run


class CancelAnswer(Model):
    run_id: int
    seq: int
    cancelled: Row = Field(..., description="The row of the dropped action")
    run: Run


class Trace(Model):
    run_id: int
    seq: int
    rows: list[Row] = Field(..., description="Every row so far; the pending one last, with `outcome: null`")


# ---------------------------------------------------------------- plans and graphs

class StrategySummary(Model):
    name: str
    declared: int = Field(..., description="Constraints as declared")
    minimal: list[Pair] = Field(..., description="The transitive reduction (Hasse diagram)")
    implied: int = Field(..., description="Constraints in the transitive closure")


class PlanSummary(Model):
    plan: str
    parts: int
    units: int
    strategies: list[StrategySummary]


class Node(Model):
    id: Part
    name: str | None
    quantity: int
    layer: int
    x: float
    y: float


class Edge(Model):
    from_: Part = Field(..., alias="from")
    to: Part
    points: list[Annotated[list[float], Field(min_length=2, max_length=2)]] = Field(
        ..., description="`[x, y]` points, through the bend points of long edges")


class Layout(Model):
    """A layered layout of one strategy's precedence graph (the dashboard draws it)."""

    strategy: str
    width: float
    height: float
    nodes: list[Node]
    edges: list[Edge]


class Graph(Model):
    run_id: int
    strategies: list[Layout]


class PlanUploaded(Model):
    id: str = Field(..., description="The plan's id (SHA-256 of its canonical JSON): the same plan has one id")
    name: str
    created: bool = Field(..., description="False when the plan was already stored")
    format: Literal["yaml", "json", "in2"]
    parts: list[Part]
    units: int
    summary: PlanSummary
    warnings: list[PlanProblem]


class PlanListed(Model):
    id: str
    name: str
    format: Literal["yaml", "json", "in2"]
    created_at: Timestamp
    owners: list[str] | None = Field(None, description="The cells that uploaded the plan (in an operator's list "
                                                       "only)")


class PlanList(Model):
    plans: list[PlanListed]


class PlanDetail(Model):
    id: str
    name: str
    plan: PlanDocument = Field(..., description="The plan in the file schema (`opportune schema`)")
    summary: PlanSummary
    graph: list[Layout]


class CellSummary(Model):
    name: str
    runs: int
    active: int


class CellList(Model):
    cells: list[CellSummary]


class Ticket(Model):
    ticket: str
    expires_in: int = Field(..., description="Seconds the ticket can be used to open a stream")
    url: str = Field(..., description="The stream's URL with the ticket")


class Health(Model):
    ok: bool
    version: str
    journal_mode: str | None = Field(..., description="SQLite's journal mode (`wal`); null for other databases")


# ---------------------------------------------------------------- server-sent events (GET /runs/{id}/events)

class EventSnapshot(Model):
    """``snapshot``: the run, its whole trace and its graph's layout, when a stream opens."""

    run: Run
    trace: list[Row]
    graph: list[Layout]


class EventRow(Model):
    """``look`` (a new pending row) or ``outcome`` (a completed row), with the run after it."""

    seq: int
    kind: Literal["look", "outcome"]
    run: Run
    row: Row


class EventCancel(Model):
    """``cancel``: the dropped row, with the run after it."""

    seq: int
    kind: Literal["cancel"]
    run: Run
    cancelled: Row


class EventComplete(Model):
    """``complete``: the last part is in; the stream ends after it."""

    run: int = Field(..., description="The run's id")
    seq: int
    installed: list[Part] = Field(..., description="In installation order")
    progress: Progress


class EventClosed(Model):
    """``closed``: the stream's token is no longer valid; the stream ends after it."""

    reason: str


EVENTS = {"snapshot": EventSnapshot, "look": EventRow, "outcome": EventRow, "cancel": EventCancel,
          "complete": EventComplete, "closed": EventClosed}


def event_schema() -> dict:
    """One server-sent event: its name, its id (the run's event number) and its JSON data, per event name."""
    def one(names: list[str], model: type[BaseModel]) -> dict:
        return {"type": "object", "required": ["event", "data"], "additionalProperties": False, "properties": {
            "event": {"enum": names}, "id": {"type": "string", "description": "The run's event number"},
            "retry": {"type": "integer"},
            "data": {"type": "string", "contentMediaType": "application/json",
                     "contentSchema": {"$ref": f"#/components/schemas/{model.__name__}"}}}}

    by_model: dict[type[BaseModel], list[str]] = {}
    for name, model in EVENTS.items():
        by_model.setdefault(model, []).append(name)
    return {"oneOf": [one(names, model) for model, names in by_model.items()]}


# ---------------------------------------------------------------- request bodies shown in the schema

class PlanUploadWrapper(BaseModel):
    """A plan file's text in JSON (any format; ``format`` and ``filename`` as the query parameters)."""

    model_config = ConfigDict(extra="forbid")
    text: str = Field(..., pattern=PRINTABLE, description="The plan file's text (printable: tabs and line ends "
                                                           "but no other control character)")
    format: Literal["yaml", "json", "in2"] | None = Field(None, description="Detected when absent")
    filename: str | None = Field(None, min_length=1, max_length=MAX_FILENAME, pattern=PRINTABLE,
                                 description="Name used in problems")


def shipped_schema() -> dict:
    """The upload of a plan shipped with the package, by name: ``{"shipped": "salbp:ARC111"}``."""
    from opportune.formats.shipped import plan_names

    return {"type": "object", "title": "PlanShipped", "required": ["shipped"], "additionalProperties": False,
            "description": "A plan shipped with the package, by the name the command line takes "
                           "(`opportune examples` lists them)",
            "properties": {"shipped": {"type": "string", "enum": list(plan_names())}}}


def complete_openapi(doc: dict) -> dict:
    """Add to FastAPI's document what its routes cannot say: the plan file's schema (the upload's request
    body and every plan document point at it), the events of the event stream, and the answers' examples."""
    from pydantic.json_schema import models_json_schema

    schemas = doc.setdefault("components", {}).setdefault("schemas", {})
    schemas.update(plan_document_schemas())
    schemas["PlanShipped"] = shipped_schema()
    _, defs = models_json_schema([(PlanUploadWrapper, "validation")] + [(m, "serialization") for m in EVENTS.values()],
                                 ref_template="#/components/schemas/{model}")
    for name, schema in defs.get("$defs", {}).items():
        schemas.setdefault(name, schema)
    for name, examples in ANSWER_EXAMPLES.items():
        schemas[name]["examples"] = json.loads(json.dumps(examples))
    stream = doc["paths"]["/runs/{run_id}/events"]["get"]["responses"]["200"]["content"]["text/event-stream"]
    stream["schema"] = event_schema()

    def point(node):
        if isinstance(node, dict):
            if node.pop("x-plan-document", None):
                node.clear()
                node["$ref"] = "#/components/schemas/PlanDocument"
                return
            for value in node.values():
                point(value)
        elif isinstance(node, list):
            for value in node:
                point(value)

    point(schemas)
    return doc


@lru_cache(maxsize=1)
def plan_document_schemas() -> dict[str, dict]:
    """The plan file's JSON Schema (``opportune schema``) as OpenAPI components: ``PlanDocument`` and its parts."""
    from opportune.formats.validate import plan_schema

    doc = json.loads(json.dumps(plan_schema()))
    defs = doc.pop("$defs", {})
    for key in ("$schema", "$id"):
        doc.pop(key, None)
    names = {name: "PlanDocument" + name[:1].upper() + name[1:] for name in defs}
    text = json.dumps({"PlanDocument": doc, **{names[k]: v for k, v in defs.items()}})
    for name, new in names.items():
        text = text.replace(f'"#/$defs/{name}"', f'"#/components/schemas/{new}"')
    return json.loads(text)
