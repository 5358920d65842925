"""``/runs``: start a run, list runs, read one (its state, trace and graph), and drive it: looks,
outcomes, cancels (each needs an ``Idempotency-Key``; a retry gets the stored answer)."""

from __future__ import annotations

import time
from typing import Callable, Literal, Optional

from fastapi import APIRouter, Depends, Header, Query, Request

from opportune.formats.problems import PRINTABLE
from opportune.limits import MAX_NAME, MAX_PAGE
from opportune.service import idempotency as idem
from opportune.service.auth import Principal
from opportune.service.bodies import CancelIn, LookIn, OutcomeIn, RunIn
from opportune.service.routers.depends import IDEMPOTENCY_KEY, REPLAYED, RUN_ID, links, replayable
from opportune.service.runs import RunManager
from opportune.service.schemas import CancelAnswer, Graph, LookAnswer, OutcomeAnswer, Run, RunList, Trace, errors

__all__ = ["MAX_OFFSET", "router"]

MAX_OFFSET = 1_000_000_000  # GET /runs?offset=: far beyond any store, and within every database's integers

# The errors every request that changes a run can meet, those of one on a run that exists, and those of
# reading a run.
WRITE_ERRORS = {400: ["malformed_json", "malformed_body", "bad_idempotency_key"], 401: ["unauthorized"],
                403: ["forbidden"], 413: ["body_too_large"], 415: ["unsupported_media_type"],
                428: ["idempotency_key_required"]}
RUN_ERRORS = {**WRITE_ERRORS, 404: ["run_not_found"], 500: ["internal_error", "run_replay_mismatch"],
              503: ["counting_budget_exceeded"]}
READ_ERRORS = errors({401: ["unauthorized"], 404: ["run_not_found"], 422: ["invalid_request", "plan_refused"],
                      500: ["internal_error", "run_replay_mismatch"]})


def router(manager: RunManager, principal: Callable[..., Principal]) -> APIRouter:
    """The run routes over ``manager``; ``principal``: the dependency that says who is asking."""
    api = APIRouter()
    _start_and_list(api, manager, principal)
    _read(api, manager, principal)
    _drive(api, manager, principal)
    return api


def _start_and_list(api: APIRouter, manager: RunManager, principal: Callable[..., Principal]) -> None:
    """Start a run; list the runs a token may see."""

    @api.post("/runs", tags=["runs"], status_code=201, operation_id="startRun",
              summary="Start a run of a stored plan in the token's cell", openapi_extra=IDEMPOTENCY_KEY,
              responses={201: {"model": Run, "description": "The new run", "headers": REPLAYED,
                               "links": links("$response.body#/id", "postLook", "getRun", "getTrace", "getGraph",
                                              "createTicket")},
                         **errors({**WRITE_ERRORS,
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

    @api.get("/runs", tags=["runs"], operation_id="listRuns",
             summary="Runs this token may see, newest first",
             responses={200: {"model": RunList},
                        **errors({401: ["unauthorized"], 422: ["invalid_request"], 500: ["internal_error"]})})
    def list_runs(p: Principal = Depends(principal), cell: Optional[str] = Query(None, max_length=MAX_NAME, pattern=PRINTABLE),
                  status: Optional[Literal["active", "complete"]] = None,
                  limit: int = Query(200, ge=1, le=MAX_PAGE, description=f"At most this many runs (1–{MAX_PAGE:,})"),
                  offset: int = Query(0, ge=0, le=MAX_OFFSET, description="Skip this many runs (0–1,000,000,000)")):
        return {"runs": manager.list(p, cell=cell, status=status, limit=limit, offset=offset)}


def _read(api: APIRouter, manager: RunManager, principal: Callable[..., Principal]) -> None:
    """A run's state, its trace and its graph."""

    @api.get("/runs/{run_id}", tags=["runs"], operation_id="getRun",
             summary="A run's state: installed, buffered, in the bin, pending action, completions left",
             responses={200: {"model": Run}, **READ_ERRORS})
    def get_run(run_id: int = RUN_ID, p: Principal = Depends(principal)):
        return manager.view(p, run_id)

    @api.get("/runs/{run_id}/trace", tags=["runs"], operation_id="getTrace",
             summary="The trace: Visible | Buffered | Installed | Action | Outcome (Table 1)",
             responses={200: {"model": Trace}, **READ_ERRORS})
    def get_trace(run_id: int = RUN_ID, p: Principal = Depends(principal)):
        return manager.trace(p, run_id)

    @api.get("/runs/{run_id}/graph", tags=["runs"], operation_id="getGraph",
             summary="Layout of the plan's precedence graph, per strategy",
             responses={200: {"model": Graph}, **READ_ERRORS})
    def get_graph(run_id: int = RUN_ID, p: Principal = Depends(principal)):
        return {"run_id": run_id, "strategies": manager.graph(p, run_id)}


def _drive(api: APIRouter, manager: RunManager, principal: Callable[..., Principal]) -> None:
    """Looks, outcomes and cancels: each needs an ``Idempotency-Key``; a retry gets the stored answer."""

    @api.post("/runs/{run_id}/looks", tags=["runs"], operation_id="postLook",
              summary="A look: the parts seen in the bin → the action to do, with its reasons",
              openapi_extra=IDEMPOTENCY_KEY,
              responses={200: {"model": LookAnswer, "description": "The action to do", "headers": REPLAYED,
                               "links": links("$response.body#/run_id", "postOutcome", "cancelAction", "getRun")},
                         **errors({**RUN_ERRORS,
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

    @api.post("/runs/{run_id}/outcomes", tags=["runs"], operation_id="postOutcome",
              summary="The outcome of the pending action", openapi_extra=IDEMPOTENCY_KEY,
              responses={200: {"model": OutcomeAnswer, "description": "The completed row and the run",
                               "headers": REPLAYED, "links": links("$response.body#/run_id", "postLook", "getTrace")},
                         **errors({**RUN_ERRORS, 409: ["no_pending_action", "outcome_refused", "run_busy"],
                                   422: ["invalid_request", "idempotency_key_reused", "plan_refused"]})})
    def post_outcome(body: OutcomeIn, request: Request, run_id: int = RUN_ID, p: Principal = Depends(principal),
                     idempotency_key: Optional[str] = Header(None, alias=idem.HEADER, include_in_schema=False)):
        key = idem.check_key(idempotency_key)
        return replayable(*manager.command(p, run_id, "outcome", body.model_dump(), key, request.url.path))

    @api.post("/runs/{run_id}/cancel", tags=["runs"], operation_id="cancelAction",
              summary="Drop the pending action (the robot did not carry it out)", openapi_extra=IDEMPOTENCY_KEY,
              responses={200: {"model": CancelAnswer, "description": "The dropped row and the run",
                               "headers": REPLAYED, "links": links("$response.body#/run_id", "postLook")},
                         **errors({**RUN_ERRORS, 409: ["no_pending_action", "run_busy"],
                                   422: ["invalid_request", "idempotency_key_reused", "plan_refused"]})})
    def post_cancel(request: Request, run_id: int = RUN_ID, p: Principal = Depends(principal),
                    idempotency_key: Optional[str] = Header(None, alias=idem.HEADER, include_in_schema=False),
                    body: Optional[CancelIn] = None):
        key = idem.check_key(idempotency_key)
        return replayable(*manager.command(p, run_id, "cancel", {}, key, request.url.path))
