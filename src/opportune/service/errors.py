"""Errors are part of the product: every refused request gets a JSON body that says where and what to do.

Shape (every 4xx and 5xx)::

    {"error": {"status": 409, "code": "look_refused", "message": "...", "hint": "...", "where": "body.visible[1]"}}

plus, for plans, ``problems`` (every finding of ``opportune check``).  No
traceback ever reaches a client: unexpected exceptions are logged with a
reference the client is given.
"""

from __future__ import annotations

import json
import logging
import secrets
from typing import Any

log = logging.getLogger("opportune.service")


class ApiError(Exception):
    """A refused request: HTTP status, a stable machine-readable ``code``, a message and a hint."""

    def __init__(self, status: int, code: str, message: str, hint: str = "", *, where: str | None = None,
                 extra: dict | None = None, headers: dict | None = None):
        super().__init__(message)
        self.status = status
        self.code = code
        self.message = message
        self.hint = hint
        self.where = where
        self.extra = extra or {}
        self.headers = headers or {}

    def body(self) -> dict:
        err: dict[str, Any] = {"status": self.status, "code": self.code, "message": self.message, "hint": self.hint}
        if self.where:
            err["where"] = self.where
        err.update(self.extra)
        return {"error": err}


def error_response(body: dict, status: int, headers: dict | None = None):
    """A JSON error answer that can always be sent.

    UTF-8 as every answer is; should a message carry text that UTF-8 cannot encode (half of a
    surrogate pair quoted from a request), the same JSON with every such character escaped.
    """
    from starlette.responses import Response

    try:
        content = json.dumps(body, ensure_ascii=False, separators=(",", ":")).encode("utf-8")
    except UnicodeEncodeError:
        content = json.dumps(body, ensure_ascii=True, separators=(",", ":")).encode("ascii")
    return Response(content, status_code=status, headers=headers, media_type="application/json")


# ---------------------------------------------------------------- the common ones

def unauthorized() -> ApiError:
    """No token or a token that is not valid: the same answer, so nothing is learnt about tokens."""
    return ApiError(401, "unauthorized", "a valid bearer token is required",
                    "send `Authorization: Bearer <token>`; tokens come from `opportune token create`",
                    headers={"WWW-Authenticate": "Bearer"})


def forbidden(message: str, hint: str = "") -> ApiError:
    return ApiError(403, "forbidden", message, hint)


def run_not_found(run_id: Any) -> ApiError:
    """Unknown run, or another cell's run: indistinguishable on purpose."""
    return ApiError(404, "run_not_found", f"no run {run_id} for this token",
                    "list your runs with GET /runs; a cell token sees only its own cell's runs")


def plan_not_found(plan_id: Any) -> ApiError:
    return ApiError(404, "plan_not_found", f"no plan {plan_id}", "upload the plan with POST /plans; its id is the returned `id`")


def unsupported_media_type(content_type: str) -> ApiError:
    """A body that is not JSON sent to a route that reads JSON (e.g. ``curl -d``, which sends a form)."""
    sent = f"`{content_type}`" if content_type else "no Content-Type"
    return ApiError(415, "unsupported_media_type", f"this request takes a JSON body, and was sent {sent}",
                    "send the body as JSON with `Content-Type: application/json`", where="header Content-Type")


def is_json(content_type: str | None) -> bool:
    """Whether FastAPI reads a body of this media type as JSON (``application/json``, ``*/*+json``)."""
    media = (content_type or "").split(";")[0].strip().lower()
    return media == "application/json" or (media.startswith("application/") and media.endswith("+json"))


def internal(ref: str) -> dict:
    return {"error": {"status": 500, "code": "internal_error",
                      "message": f"the service failed on this request (reference {ref}); nothing was changed",
                      "hint": "retry with the same Idempotency-Key; report the reference to the operator if it persists"}}


def new_reference() -> str:
    return secrets.token_hex(4)


# ---------------------------------------------------------------- request validation

def _where(loc) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def from_validation(errors: list[dict]) -> ApiError:
    """FastAPI/pydantic validation errors as one :class:`ApiError` (malformed JSON → 400, else 422)."""
    for e in errors:
        if e.get("type") == "json_invalid":
            ctx = e.get("ctx") or {}
            detail = ctx.get("error") or "invalid JSON"
            loc = e.get("loc") or ()
            pos = f" at character {loc[1]}" if len(loc) > 1 and isinstance(loc[1], int) else ""
            return ApiError(400, "malformed_json", f"the request body is not valid JSON: {detail}{pos}",
                            "send a JSON object with `Content-Type: application/json`", where="body")
    problems = []
    for e in errors:
        loc = tuple(e.get("loc") or ())
        msg = e.get("msg", "invalid value")
        if e.get("type") == "missing":
            msg = "this field is required"
        elif e.get("type") == "extra_forbidden":
            msg = "unknown field"
        problems.append({"where": _where(loc), "message": msg})
    first = problems[0] if problems else {"where": "body", "message": "invalid request"}
    more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
    return ApiError(422, "invalid_request", f"{first['where']}: {first['message']}{more}",
                    "see the request schema at /docs (OpenAPI: /openapi.json)", where=first["where"],
                    extra={"problems": problems})
