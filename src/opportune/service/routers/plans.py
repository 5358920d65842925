"""``/plans``: upload a plan (validated as ``opportune check``), the plans a token may run, one plan."""

from __future__ import annotations

from typing import Callable, Literal, Optional

from fastapi import APIRouter, Depends, Path as PathParam, Query, Request
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from opportune.formats.problems import PRINTABLE
from opportune.limits import MAX_FILE_BYTES, MAX_FILENAME
from opportune.service.auth import Principal
from opportune.service.errors import forbidden, plan_not_found
from opportune.service.plans import PlanBook, accept_upload, list_plans, may_see
from opportune.service.schemas import (BOWMAN8_IN2, GEARBOX_PLAN, GEARBOX_YAML, PlanDetail, PlanList, PlanUploaded,
                                       errors)
from opportune.service.storage import Store

__all__ = ["router"]

#: A plan file's text as a raw body: printable (tabs and line ends, no other control character), and no
#: larger than the readers read.
PLAN_TEXT = {"pattern": PRINTABLE, "maxLength": MAX_FILE_BYTES}
PLAN_LINKS = {"startRun": {"operationId": "startRun", "requestBody": {"plan": "$response.body#/id"}},
              "getPlan": {"operationId": "getPlan", "parameters": {"plan_id": "$response.body#/id"}}}


def router(store: Store, book: PlanBook, principal: Callable[..., Principal]) -> APIRouter:
    """The plan routes over ``store`` and ``book``; ``principal``: the dependency that says who is asking."""
    api = APIRouter()

    @api.post("/plans", tags=["plans"], status_code=201, operation_id="uploadPlan",
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

    @api.get("/plans", tags=["plans"], operation_id="listPlans",
             summary="The plans this token may run (a cell: those it uploaded; an operator: every plan, with "
                     "its owners)",
             responses={200: {"model": PlanList}, **errors({401: ["unauthorized"], 500: ["internal_error"]})})
    def get_plans(p: Principal = Depends(principal)):
        return {"plans": list_plans(store, p)}

    @api.get("/plans/{plan_id}", tags=["plans"], operation_id="getPlan",
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

    return api
