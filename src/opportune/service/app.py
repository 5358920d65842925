"""The FastAPI application: routes, authentication, limits and error handling.

Routes (all JSON; OpenAPI at ``/openapi.json``, readable at ``/docs``):

=======  ==========================  =============================================================
POST     /plans                      upload a plan (YAML, JSON or SALBP .IN2), validated as ``opportune check``
GET      /plans, /plans/{id}         the plans this token may run / one plan with its summary
GET      /cells                      cells with their run counts
POST     /runs                       start a run: ``{"plan": id, "buffer_capacity": null, "label": ""}``
GET      /runs                       runs visible to the token (``?cell=&status=``)
GET      /runs/{id}                  a run's state, pending action, completions left
POST     /runs/{id}/looks            ``{"visible": [...]}`` → the decided action with its reasons
POST     /runs/{id}/outcomes         ``{"outcome": "success"|"failed"|"defective", "keep": "bin"|"buffer"}``
POST     /runs/{id}/cancel           drop the pending action (the robot did not do it)
GET      /runs/{id}/trace            the trace in the layout of the paper's Table 1
GET      /runs/{id}/graph            the precedence graph's layout, per strategy
POST     /runs/{id}/ticket           a short-lived ticket to open the event stream from a browser
GET      /runs/{id}/events           server-sent events (bearer header, or ``?ticket=``)
=======  ==========================  =============================================================

State-changing run requests need an ``Idempotency-Key`` header
(:mod:`opportune.service.idempotency`).  The dashboard is served at ``/``.

The OpenAPI document is exact: every route has a camelCase operation id (``uploadPlan``,
``startRun``, ``postLook``, ``postOutcome``, ...), documents its answer with a model of
:mod:`opportune.service.schemas` and the error model on each error status it can answer with
(naming the codes), and says where ``Idempotency-Key`` is required.  The models document; the
routes do not serialise through them, so answers (and replayed answers) keep their exact bytes.
"""

from __future__ import annotations

import asyncio
import logging
import re
import time
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Annotated, Literal, Optional
from urllib.parse import unquote

from fastapi import Depends, FastAPI, Header, Path as PathParam, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, Response, StreamingResponse
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from fastapi.staticfiles import StaticFiles
from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field
from pydantic_core import PydanticCustomError
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from opportune import __version__
from opportune.policies.named import DEFAULT_POLICY, FORMER_NAMES, POLICIES
from opportune.service import idempotency as idem
from opportune.formats.problems import CONTROL_CHARS, PRINTABLE
from opportune.limits import (MAX_BUFFER, MAX_FILE_BYTES, MAX_FILENAME, MAX_ID, MAX_KEY, MAX_LABEL, MAX_LOOK,
                              MAX_NAME, MAX_PAGE, MAX_PRODUCTS)
from opportune.service.auth import Principal
from opportune.service.config import Settings
from opportune.service.core import build as build_core
from opportune.service.errors import (ApiError, error_response, forbidden, from_validation, internal, is_json,
                                      new_reference, plan_not_found, unauthorized, unsupported_media_type)
from opportune.service.events import Broker, stream
from opportune.service.plans import accept_upload, list_plans, may_see
from opportune.service.schemas import (BOWMAN8_IN2, GEARBOX_PLAN, GEARBOX_PLAN_ID, GEARBOX_YAML, CancelAnswer, CellList,
                                       Graph, Health, LookAnswer, OutcomeAnswer, PlanDetail, PlanList, PlanUploaded,
                                       Run, RunList, Ticket, Trace, complete_openapi, errors)
from opportune.service.storage import Store

log = logging.getLogger("opportune.service")
STATIC = Path(__file__).parent / "static"
RUN_ID = PathParam(..., ge=1, le=2**62, description="The run's id")
MAX_OFFSET = 1_000_000_000  # GET /runs?offset=: far beyond any store, and within every database's integers
_SURROGATE = re.compile("[\ud800-\udfff]")

# The Idempotency-Key header as the OpenAPI states it: required.  The route itself reads it as optional, so
# that a request without it gets the service's own 428 (which says what to send), not a validation error.
IDEMPOTENCY_KEY = {"parameters": [{
    "name": idem.HEADER, "in": "header", "required": True,
    "description": "A fresh random string (e.g. a UUID) for every new request, reused when retrying it: a retry "
                   "gets the stored answer, byte for byte, and changes nothing",
    "schema": {"type": "string", "minLength": 1, "maxLength": MAX_KEY, "pattern": idem.KEY_PATTERN}}]}


def links(run_id: str, *op_ids: str) -> dict:
    """OpenAPI links: the run an answer names (``run_id``, a runtime expression) to the operations on it."""
    return {op: {"operationId": op, "parameters": {"run_id": run_id}} for op in op_ids}


#: A plan file's text as a raw body: printable (tabs and line ends, no other control character), and no
#: larger than the readers read.
PLAN_TEXT = {"pattern": PRINTABLE, "maxLength": MAX_FILE_BYTES}
PLAN_LINKS = {"startRun": {"operationId": "startRun", "requestBody": {"plan": "$response.body#/id"}},
              "getPlan": {"operationId": "getPlan", "parameters": {"plan_id": "$response.body#/id"}}}
REPLAYED = {"Idempotent-Replayed": {"description": "`true` when this is the stored answer of an earlier request "
                                                   "with the same key", "schema": {"type": "string", "enum": ["true"]}}}


def _unicode(text: str) -> str:
    """Refuse text with half of a UTF-16 surrogate pair (JSON's "\\ud800"): it cannot be stored or sent back."""
    if _SURROGATE.search(text):
        raise ValueError("not valid Unicode text: it contains half of a UTF-16 surrogate pair (\\ud800-\\udfff); "
                         "send the character itself or both halves of the pair")
    return text


#: Text of a request: printable (the schema states it; :class:`BodyLimit` refuses a control character anywhere
#: in a request before it is read) and valid Unicode.
#: (The pattern is the schema's statement only: the middleware refuses first, and Pydantic's own check of a
#: pattern would read half of a surrogate pair as undecodable bytes rather than say what it is.)
Text = Annotated[str, AfterValidator(_unicode), Field(json_schema_extra={"pattern": PRINTABLE})]


def _json_integer(value):
    """An integer as JSON Schema has it (``4``, ``4.0``): Pydantic alone would also read ``false`` as 0 and ``"4"``
    as 4 (schemathesis found a run started with ``"buffer_capacity": false``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PydanticCustomError("int_type", "Input should be a valid integer")
    return value


# Pages and scripts come only from this server; nothing from the internet.
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
       "frame-ancestors 'none'; base-uri 'none'; form-action 'self'")


# ---------------------------------------------------------------- request bodies

class RunIn(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"plan": GEARBOX_PLAN_ID, "label": "SN 1042", "buffer_capacity": 4, "policy": "paper"},
        {"plan": GEARBOX_PLAN_ID}]})
    plan: Text = Field(..., min_length=1, max_length=64,
                       description="A plan id returned by POST /plans, or a plan shipped with the package by name "
                                   "(`salbp:ARC111`, `example:gearbox`, as `opportune examples` lists them), "
                                   "stored for the token's cell as it starts")
    cell: Optional[Text] = Field(None, max_length=MAX_NAME,
                                 description="The cell; defaults to (and must be) the token's cell")
    buffer_capacity: Optional[Annotated[int, Field(ge=0, le=MAX_BUFFER), BeforeValidator(_json_integer)]] = Field(
        None, description="Buffer locations; null: unlimited")
    label: Text = Field("", max_length=MAX_LABEL, description="Free text shown on the dashboard (e.g. a serial number)")
    policy: Optional[Literal[POLICIES + tuple(FORMER_NAMES)]] = Field(
        None, description=f"The decision policy (default: {DEFAULT_POLICY}, the exact look-ahead; 'paper': the "
                          "paper's rule; 'opportunistic', its former name, runs it with a `note` in the answer)")
    products: Optional[Annotated[int, Field(ge=1, le=MAX_PRODUCTS), BeforeValidator(_json_integer)]] = Field(
        None, description="Build this many copies of the plan at once on as many fixtures fed from one bin (1–16; "
                          "default 1): looks then name part kinds, and each install says its fixture")


class LookIn(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"visible": ["rl", "ra"]}, {"visible": []}]})
    visible: list[Annotated[Text, Field(min_length=1, max_length=MAX_ID)]] = Field(
        ..., max_length=MAX_LOOK, description="Part ids seen in the bin now, repeated for several units; [] for nothing")


class OutcomeIn(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"outcome": "success"}, {"outcome": "failed", "keep": "buffer"}, {"outcome": "defective"}]})
    outcome: Literal["success", "failed", "defective"] = Field(..., description="What happened to the pending action")
    keep: Literal["bin", "buffer"] = Field("bin", description="After a failed install: part back in the bin, or kept in a buffer location")


class CancelIn(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{}]})


# ---------------------------------------------------------------- middleware

#: Characters no request may hold in its path, query or body text: C0 controls but tab, line feed and
#: carriage return, DEL, and C1 controls.  U+0000 cannot be stored in a PostgreSQL text column, and the
#: others would reach a terminal through the logs.
_CONTROL = re.compile(f"[{CONTROL_CHARS}]")
#: The same characters written as JSON escapes (an even number of backslashes before one is text).
_CONTROL_ESCAPE = re.compile(rb"(?<!\\)(?:\\\\)*\\u00(?:0[0-8bBcCeEfF]|1[0-9a-fA-F]|7[fF]|[89][0-9a-fA-F])")


def _control_problem(scope, body: bytes) -> ApiError | None:
    """A 400/422 for a control character in the path, the query or the body; None if there is none.
    O(length of the request)."""
    where = None
    if _CONTROL.search(scope.get("path", "")):
        where = "path"
    elif _CONTROL.search(unquote(scope.get("query_string", b"").decode("latin-1"))):
        where = "query"
    if where is not None:
        return ApiError(400, "invalid_request", f"the {where} holds a control character (such as U+0000 or ESC)",
                        "send printable text only", where=where)
    try:        # a body that is not UTF-8 is the handler's to refuse, with what it is instead
        text = body.decode("utf-8") if body else ""
    except UnicodeDecodeError:
        text = ""
    if text and (_CONTROL_ESCAPE.search(body) or _CONTROL.search(text)):
        return ApiError(422, "invalid_request", "the body holds a control character (such as U+0000 or ESC) in its "
                        "text", "send printable text only: part ids, names, labels and keys are printable",
                        where="body")
    return None


class BodyLimit:
    """Refuses bodies over ``limit`` bytes with 413 before the application reads them, and requests
    whose path, query or body holds a control character (see :data:`_CONTROL`) with 400/422 (pure ASGI).
    """

    def __init__(self, app, limit: int):
        self.app = app
        self.limit = limit

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        if scope["method"] in ("GET", "HEAD", "OPTIONS"):
            err = _control_problem(scope, b"")
            if err is not None:
                return await error_response(err.body(), err.status)(scope, receive, send)
            return await self.app(scope, receive, send)
        declared = dict(scope.get("headers") or []).get(b"content-length")
        too_big = declared is not None and declared.isdigit() and int(declared) > self.limit
        chunks: list[bytes] = []
        size = 0
        if not too_big:
            while True:
                message = await receive()
                if message["type"] == "http.disconnect":
                    return
                chunks.append(message.get("body", b""))
                size += len(chunks[-1])
                if size > self.limit:
                    too_big = True
                    break
                if not message.get("more_body"):
                    break
        if too_big:
            err = ApiError(413, "body_too_large", f"the request body is larger than the limit of {self.limit} bytes",
                           "send a smaller body; the limit is set with `opportune serve --max-body`", where="body")
            response = error_response(err.body(), 413, {"Connection": "close"})
            return await response(scope, receive, send)
        body = b"".join(chunks)
        err = _control_problem(scope, body)
        if err is not None:
            return await error_response(err.body(), err.status)(scope, receive, send)
        sent = False

        async def replay():
            nonlocal sent
            if not sent:
                sent = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)


class CatchAll:
    """The last line of defence: an exception no handler turned into an answer becomes a JSON 500 (pure ASGI).

    Starlette's own handler of last resort answers 500 but then re-raises, and the server closes the
    connection: a client's keep-alive connection, and any request pipelined on it, would be lost.
    Here the exception is logged (with a reference the client is given) and the request ends
    normally.  Nothing was committed: every change is committed just before its answer is sent.
    """

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        started = False

        async def tracking_send(message):
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, receive, tracking_send)
        except Exception as exc:  # MemoryError and RecursionError included: the request fails, the server lives
            ref = new_reference()
            log.error("internal error %s on %s %s", ref, scope.get("method"), scope.get("path"), exc_info=exc)
            if started:  # half an answer is out: nothing more can be said on this connection
                return
            response = error_response(internal(ref), 500)
            response.headers["x-content-type-options"] = "nosniff"
            await response(scope, receive, send)


class Timing:
    """Notes the moment a request arrives (``request.state.arrived``, on ``time.perf_counter``'s clock)
    and, once its answer's last byte is handed to the server, calls ``request.state.on_sent(moment)``
    if the handler set it: a look's budget counts from here, and the time its answer takes to leave
    is learned, not guessed (pure ASGI, the outermost layer).  O(1) per request.
    """

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        state = scope.setdefault("state", {})
        state["arrived"] = time.perf_counter()

        async def timed_send(message):
            await send(message)
            if message["type"] == "http.response.body" and not message.get("more_body"):
                on_sent = state.pop("on_sent", None)
                if on_sent is not None:
                    on_sent(time.perf_counter())

        await self.app(scope, receive, timed_send)


class SecurityHeaders:
    """``nosniff`` everywhere; a strict Content-Security-Policy on pages."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)

        async def send_with_headers(message):
            if message["type"] == "http.response.start":
                headers = list(message.get("headers") or [])
                headers.append((b"x-content-type-options", b"nosniff"))
                headers.append((b"referrer-policy", b"no-referrer"))
                if any(k == b"content-type" and v.startswith(b"text/html") for k, v in headers):
                    headers.append((b"content-security-policy", CSP.encode()))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)


# ---------------------------------------------------------------- the application

def create_app(settings: Settings | None = None, store: Store | None = None) -> FastAPI:
    """The service's ASGI application over a store (created from ``settings.db_url`` if not given); its
    :class:`~opportune.service.core.Core` is ``app.state.core``."""
    settings = settings or Settings()
    broker = Broker()
    core = build_core(settings, store, notify=broker.notify)
    store, book, auth, manager = core.store, core.book, core.auth, core.manager

    @asynccontextmanager
    async def lifespan(_app):
        broker.bind(asyncio.get_running_loop())
        yield
        book.close()
        store.dispose()

    app = FastAPI(
        title="opportune",
        version=__version__,
        summary="The opportunistic sequencer of Fox & Kempf as a service for robot cells.",
        description=(
            "A cell posts what its camera sees (`POST /runs/{id}/looks`) and gets the action to do; it then reports "
            "the outcome (`POST /runs/{id}/outcomes`). Every look, decision and outcome is committed before the "
            "answer is sent. Authenticate with `Authorization: Bearer <token>` (`opportune token create CELL`). "
            "Send an `Idempotency-Key` header on POSTs that change a run and reuse it on retries. Errors are "
            "`{\"error\": {status, code, message, hint, where}}`."),
        docs_url=None, redoc_url=None, lifespan=lifespan,
    )
    app.state.store, app.state.manager, app.state.auth, app.state.broker = store, manager, auth, broker
    app.state.core = core   # what another front end served beside this one shares (the OPC UA server)
    bearer = HTTPBearer(auto_error=False, description="A cell or operator token from `opportune token create`")

    # ------------------------------------------------------------ errors

    @app.exception_handler(ApiError)
    async def _api_error(_request, exc: ApiError):
        return error_response(exc.body(), exc.status, exc.headers)

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError):
        errs = list(exc.errors())
        ctype = request.headers.get("content-type")
        sent = request.headers.get("content-length", "0") != "0" or "transfer-encoding" in request.headers
        if sent and not is_json(ctype) and any(tuple(e.get("loc") or ())[:1] == ("body",) for e in errs):
            err = unsupported_media_type((ctype or "").split(";")[0].strip())  # FastAPI read no JSON from it
        else:
            err = from_validation(errs)
        return error_response(err.body(), err.status)

    def allowed_methods(request: Request) -> list[str]:
        """Every method some route serves at this path (Starlette names only the first route's)."""
        methods: set[str] = set()
        for route in app.router.routes:
            match, _scope = route.matches(request.scope)
            if match is not Match.NONE and getattr(route, "methods", None):
                methods |= set(route.methods)
        return sorted(methods | {"OPTIONS"}) if methods else []

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException):
        headers = dict(getattr(exc, "headers", None) or {})
        if exc.status_code == 404:
            err = ApiError(404, "not_found", f"no such resource: {request.method} {request.url.path}",
                           "see the routes at /docs")
        elif exc.status_code == 405:
            allowed = allowed_methods(request)
            headers["Allow"] = ", ".join(allowed)
            if request.method == "OPTIONS" and allowed:  # what may be done here: 204 with the Allow header
                return Response(status_code=204, headers=headers)
            err = ApiError(405, "method_not_allowed", f"{request.method} is not allowed on {request.url.path}",
                           f"this path serves {', '.join(m for m in allowed if m not in ('HEAD', 'OPTIONS'))}; "
                           "see the routes at /docs")
        elif exc.status_code == 400:  # the body could not be parsed at all (e.g. JSON nested too deep)
            err = ApiError(400, "malformed_body", f"the request body could not be read: {exc.detail}",
                           "send a JSON object with `Content-Type: application/json`, as described at /docs",
                           where="body")
        else:
            err = ApiError(exc.status_code, "http_error", str(exc.detail))
        return error_response(err.body(), err.status, headers)

    # ------------------------------------------------------------ who is asking

    def principal(creds: Optional[HTTPAuthorizationCredentials] = Depends(bearer)) -> Principal:
        p = auth.token(creds.credentials) if creds and creds.credentials else None
        if p is None:
            raise unauthorized()
        return p

    def replayable(status: int, text: str, replayed: bool) -> Response:
        # The same bytes the first time and on every retry: the stored answer is this JSON text.
        return Response(text, status_code=status, media_type="application/json",
                        headers={"Idempotent-Replayed": "true"} if replayed else None)

    # ------------------------------------------------------------ pages

    @app.get("/", include_in_schema=False)
    def index():
        return FileResponse(STATIC / "index.html", media_type="text/html")

    @app.get("/ui/runs/{run_id}", include_in_schema=False)
    def run_page(run_id: int = RUN_ID):
        return FileResponse(STATIC / "run.html", media_type="text/html")

    @app.get("/favicon.ico", include_in_schema=False)
    def favicon():
        return FileResponse(STATIC / "favicon.svg", media_type="image/svg+xml")

    @app.get("/docs", include_in_schema=False)
    def docs():
        return FileResponse(STATIC / "docs.html", media_type="text/html")

    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/healthz", tags=["service"], operation_id="health",
             summary="Liveness: the service answers and its database is reachable",
             responses={200: {"model": Health, "description": "The service and its database answer"},
                        **errors({500: ["internal_error"]})})
    def healthz():
        return {"ok": True, "version": __version__, "journal_mode": store.journal_mode()}

    # ------------------------------------------------------------ plans

    @app.post("/plans", tags=["plans"], status_code=201, operation_id="uploadPlan",
              summary="Upload a plan, validated as opportune check does",
              responses={201: {"model": PlanUploaded, "description": "The plan was stored", "links": PLAN_LINKS},
                         200: {"model": PlanUploaded, "description": "The plan was already stored (same content hash)",
                               "links": PLAN_LINKS},
                         **errors({400: ["malformed_json", "malformed_body"], 401: ["unauthorized"],
                                   403: ["forbidden"], 413: ["body_too_large", "plan_too_large_for_memory"],
                                   422: ["invalid_plan", "invalid_request", "unknown_plan"],
                                   500: ["internal_error"]})},
              openapi_extra={"requestBody": {"required": True, "content": {
                  "application/json": {"schema": {"anyOf": [
                      {"$ref": "#/components/schemas/PlanDocument"},
                      {"$ref": "#/components/schemas/PlanUploadWrapper"},
                      {"$ref": "#/components/schemas/PlanShipped"}]}, "examples": {
                      "document": {"summary": "The gearbox as a plan document", "value": GEARBOX_PLAN},
                      "wrapped": {"summary": "The gearbox's plan file, wrapped",
                                  "value": {"text": GEARBOX_YAML, "format": "yaml", "filename": "gearbox.yaml"}},
                      "shipped": {"summary": "A plan shipped with the package, by name",
                                  "value": {"shipped": "salbp:ARC111"}}}},
                  "application/yaml": {"schema": {"type": "string", "description": "A plan file in YAML",
                                                  **PLAN_TEXT},
                                       "examples": {"gearbox": {"summary": "The gearbox", "value": GEARBOX_YAML}}},
                  "text/plain": {"schema": {"type": "string", "description": "YAML, JSON or SALBP .IN2, detected",
                                            **PLAN_TEXT},
                                 "examples": {"gearbox": {"summary": "The gearbox, in YAML", "value": GEARBOX_YAML},
                                              "in2": {"summary": "A SALBP .IN2 file (BOWMAN8)",
                                                      "value": BOWMAN8_IN2}}}}}})
    async def upload_plan(request: Request, p: Principal = Depends(principal),
                          format: Optional[Literal["yaml", "json", "in2"]] = Query(None, description="Format of a raw body"),
                          filename: Optional[str] = Query(None, min_length=1, max_length=MAX_FILENAME, pattern=PRINTABLE,
                                                          description="Name used in problems")):
        if p.is_operator:
            raise forbidden("an operator token reads plans and runs; only a cell's token can upload a plan",
                            "upload the plan with the token of the cell that will assemble it")
        raw = await request.body()
        ctype = request.headers.get("content-type")
        if ctype and ctype.split(";")[0].strip().lower() in ("application/yaml", "application/x-yaml", "text/yaml") and not format:
            format = "yaml"

        status, body = await run_in_threadpool(accept_upload, store, book, p, raw, ctype, filename, format)
        return JSONResponse(body, status_code=status)

    @app.get("/plans", tags=["plans"], operation_id="listPlans",
             summary="The plans this token may run (a cell: those it uploaded; an operator: every plan, with "
                     "its owners)",
             responses={200: {"model": PlanList}, **errors({401: ["unauthorized"], 500: ["internal_error"]})})
    def get_plans(p: Principal = Depends(principal)):
        return {"plans": list_plans(store, p)}

    @app.get("/plans/{plan_id}", tags=["plans"], operation_id="getPlan",
             summary="A plan: its document (file schema), summary and graph layout",
             responses={200: {"model": PlanDetail},
                        **errors({401: ["unauthorized"], 404: ["plan_not_found"],
                                  422: ["plan_refused", "invalid_request"], 500: ["internal_error"]})})
    def get_plan(plan_id: str = PathParam(..., max_length=64, pattern=PRINTABLE,
                                          description="A plan id returned by POST /plans"),
                 p: Principal = Depends(principal)):
        if not may_see(store, p, plan_id):    # another cell's plan: not found, as one that does not exist
            raise plan_not_found(plan_id)
        loaded = book.get(plan_id)
        return {"id": loaded.id, "name": loaded.plan.name, "plan": loaded.plan.to_dict(), "summary": loaded.summary,
                "graph": loaded.layouts}

    # ------------------------------------------------------------ cells and runs

    @app.get("/cells", tags=["runs"], operation_id="listCells",
             summary="Cells with their numbers of runs (a cell token sees itself)",
             responses={200: {"model": CellList}, **errors({401: ["unauthorized"], 500: ["internal_error"]})})
    def list_cells(p: Principal = Depends(principal)):
        return {"cells": manager.cells(p)}

    # The errors every request that changes a run can meet, and those of one on a run that exists.
    write_errors = {400: ["malformed_json", "malformed_body", "bad_idempotency_key"], 401: ["unauthorized"],
                    403: ["forbidden"], 413: ["body_too_large"], 415: ["unsupported_media_type"],
                    428: ["idempotency_key_required"]}
    run_errors = {**write_errors, 404: ["run_not_found"], 500: ["internal_error", "run_replay_mismatch"],
                  503: ["counting_budget_exceeded"]}

    @app.post("/runs", tags=["runs"], status_code=201, operation_id="startRun",
              summary="Start a run of a stored plan in the token's cell", openapi_extra=IDEMPOTENCY_KEY,
              responses={201: {"model": Run, "description": "The new run", "headers": REPLAYED,
                               "links": links("$response.body#/id", "postLook", "getRun", "getTrace", "getGraph",
                                              "createTicket")},
                         **errors({**write_errors,
                                   413: ["body_too_large", "plan_too_large_for_memory"],
                                   422: ["invalid_request", "unknown_plan", "invalid_plan", "plan_too_large",
                                         "plan_refused", "idempotency_key_reused"],
                                   500: ["internal_error"], 503: ["plan_too_large"]})})
    def create_run(body: RunIn, request: Request, p: Principal = Depends(principal),
                   idempotency_key: Optional[str] = Header(None, alias=idem.HEADER, include_in_schema=False)):
        key = idem.check_key(idempotency_key)
        # without `products` when not given: a retried request hashes as it did before runs had products
        fields = body.model_dump(exclude={"products"} if body.products is None else None)
        return replayable(*manager.create(p, fields, key, request.url.path))

    @app.get("/runs", tags=["runs"], operation_id="listRuns",
             summary="Runs this token may see, newest first",
             responses={200: {"model": RunList},
                        **errors({401: ["unauthorized"], 422: ["invalid_request"], 500: ["internal_error"]})})
    def list_runs(p: Principal = Depends(principal), cell: Optional[str] = Query(None, max_length=MAX_NAME, pattern=PRINTABLE),
                  status: Optional[Literal["active", "complete"]] = None,
                  limit: int = Query(200, ge=1, le=MAX_PAGE, description=f"At most this many runs (1–{MAX_PAGE:,})"),
                  offset: int = Query(0, ge=0, le=MAX_OFFSET, description="Skip this many runs (0–1,000,000,000)")):
        return {"runs": manager.list(p, cell=cell, status=status, limit=limit, offset=offset)}

    read_errors = errors({401: ["unauthorized"], 404: ["run_not_found"], 422: ["invalid_request", "plan_refused"],
                          500: ["internal_error", "run_replay_mismatch"]})

    @app.get("/runs/{run_id}", tags=["runs"], operation_id="getRun",
             summary="A run's state: installed, buffered, in the bin, pending action, completions left",
             responses={200: {"model": Run}, **read_errors})
    def get_run(run_id: int = RUN_ID, p: Principal = Depends(principal)):
        return manager.view(p, run_id)

    @app.get("/runs/{run_id}/trace", tags=["runs"], operation_id="getTrace",
             summary="The trace: Visible | Buffered | Installed | Action | Outcome (Table 1)",
             responses={200: {"model": Trace}, **read_errors})
    def get_trace(run_id: int = RUN_ID, p: Principal = Depends(principal)):
        return manager.trace(p, run_id)

    @app.get("/runs/{run_id}/graph", tags=["runs"], operation_id="getGraph",
             summary="Layout of the plan's precedence graph, per strategy",
             responses={200: {"model": Graph}, **read_errors})
    def get_graph(run_id: int = RUN_ID, p: Principal = Depends(principal)):
        return {"run_id": run_id, "strategies": manager.graph(p, run_id)}

    @app.post("/runs/{run_id}/looks", tags=["runs"], operation_id="postLook",
              summary="A look: the parts seen in the bin → the action to do, with its reasons",
              openapi_extra=IDEMPOTENCY_KEY,
              responses={200: {"model": LookAnswer, "description": "The action to do", "headers": REPLAYED,
                               "links": links("$response.body#/run_id", "postOutcome", "cancelAction", "getRun")},
                         **errors({**run_errors,
                                   409: ["look_contradicts_state", "action_pending", "run_complete", "run_busy"],
                                   422: ["invalid_request", "unknown_part", "idempotency_key_reused",
                                         "plan_refused"]})})
    def post_look(body: LookIn, request: Request, run_id: int = RUN_ID, p: Principal = Depends(principal),
                  idempotency_key: Optional[str] = Header(None, alias=idem.HEADER, include_in_schema=False)):
        key = idem.check_key(idempotency_key)
        # the look's budget counts from its arrival; the seconds its answer then takes to leave are learned
        answer = manager.command(p, run_id, "look", body.model_dump(), key, request.url.path,
                                 arrived=getattr(request.state, "arrived", None))
        request.state.on_sent = manager.answer_sent(time.perf_counter())
        return replayable(*answer)

    @app.post("/runs/{run_id}/outcomes", tags=["runs"], operation_id="postOutcome",
              summary="The outcome of the pending action", openapi_extra=IDEMPOTENCY_KEY,
              responses={200: {"model": OutcomeAnswer, "description": "The completed row and the run",
                               "headers": REPLAYED, "links": links("$response.body#/run_id", "postLook", "getTrace")},
                         **errors({**run_errors, 409: ["no_pending_action", "outcome_refused", "run_busy"],
                                   422: ["invalid_request", "idempotency_key_reused", "plan_refused"]})})
    def post_outcome(body: OutcomeIn, request: Request, run_id: int = RUN_ID, p: Principal = Depends(principal),
                     idempotency_key: Optional[str] = Header(None, alias=idem.HEADER, include_in_schema=False)):
        key = idem.check_key(idempotency_key)
        return replayable(*manager.command(p, run_id, "outcome", body.model_dump(), key, request.url.path))

    @app.post("/runs/{run_id}/cancel", tags=["runs"], operation_id="cancelAction",
              summary="Drop the pending action (the robot did not carry it out)", openapi_extra=IDEMPOTENCY_KEY,
              responses={200: {"model": CancelAnswer, "description": "The dropped row and the run",
                               "headers": REPLAYED, "links": links("$response.body#/run_id", "postLook")},
                         **errors({**run_errors, 409: ["no_pending_action", "run_busy"],
                                   422: ["invalid_request", "idempotency_key_reused", "plan_refused"]})})
    def post_cancel(request: Request, run_id: int = RUN_ID, p: Principal = Depends(principal),
                    idempotency_key: Optional[str] = Header(None, alias=idem.HEADER, include_in_schema=False),
                    body: Optional[CancelIn] = None):
        key = idem.check_key(idempotency_key)
        return replayable(*manager.command(p, run_id, "cancel", {}, key, request.url.path))

    # ------------------------------------------------------------ live updates

    @app.post("/runs/{run_id}/ticket", tags=["events"], operation_id="createTicket",
              summary="A short-lived ticket to open this run's event stream from a browser",
              responses={200: {"model": Ticket},
                         **errors({401: ["unauthorized"], 404: ["run_not_found"], 413: ["body_too_large"],
                                   422: ["invalid_request"], 500: ["internal_error"]})})
    def post_ticket(run_id: int = RUN_ID, p: Principal = Depends(principal)):
        manager.row(p, run_id)
        ticket = auth.ticket(p, run_id)
        return {"ticket": ticket, "expires_in": int(settings.ticket_seconds),
                "url": f"/runs/{run_id}/events?ticket={ticket}"}

    @app.get("/runs/{run_id}/events", tags=["events"], operation_id="streamEvents",
             summary="Server-sent events: a snapshot, then every committed change",
             response_class=StreamingResponse,
             responses={200: {"content": {"text/event-stream": {}},
                              "description": "`snapshot`, then `look`, `outcome`, `cancel` events (each event's "
                                             "`data` is JSON, as described per event), and `complete` when the run "
                                             "completes or `closed` when the token is revoked"},
                        **errors({401: ["unauthorized"], 404: ["run_not_found"],
                                  422: ["invalid_request", "plan_refused"],
                                  500: ["internal_error", "run_replay_mismatch"]})})
    async def get_events(run_id: int = RUN_ID, creds: Optional[HTTPAuthorizationCredentials] = Depends(bearer),
                         ticket: Optional[str] = Query(None, max_length=200, pattern=PRINTABLE,
                                                       description="From POST /runs/{id}/ticket")):
        def who() -> Principal:
            p = auth.token(creds.credentials) if creds and creds.credentials else None
            if p is None and ticket:
                p = auth.from_ticket(ticket, run_id)
            if p is None:
                raise unauthorized()
            return p

        p = await run_in_threadpool(who)

        def snapshot():
            both = manager.view(p, run_id, with_trace=True)
            return {"run": both["run"], "trace": both["trace"], "graph": manager.graph(p, run_id)}

        snap = await run_in_threadpool(snapshot)
        return StreamingResponse(
            stream(run_id, snap, broker, manager.events_after, lambda: auth.by_id(p.token_id) is not None,
                   poll=settings.sse_poll_seconds, keepalive=settings.sse_keepalive_seconds,
                   recheck=settings.token_cache_seconds),
            media_type="text/event-stream",
            headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})

    generated_openapi = app.openapi

    def openapi() -> dict:
        """FastAPI's document, completed (:func:`opportune.service.schemas.complete_openapi`)."""
        if app.openapi_schema is None:
            app.openapi_schema = complete_openapi(generated_openapi())
        return app.openapi_schema

    app.openapi = openapi
    app.add_middleware(BodyLimit, limit=settings.max_body)
    app.add_middleware(SecurityHeaders)
    app.add_middleware(CatchAll)  # covers the two above as well
    app.add_middleware(Timing)    # outermost: a request's clock starts before any other work
    return app
