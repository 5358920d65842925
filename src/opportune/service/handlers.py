"""The HTTP service's exception handlers: every refusal answered as the JSON error of
:mod:`opportune.service.errors` (an :class:`~opportune.service.errors.ApiError`, a request the models
refuse, a path or method that does not exist, a body that cannot be parsed)."""

from __future__ import annotations

from functools import partial
from typing import Iterable, Sequence

from fastapi import APIRouter, FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import Response
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import BaseRoute, Match

from opportune.service.errors import ApiError, error_response, from_validation, is_json, unsupported_media_type

__all__ = ["install_handlers"]


def install_handlers(app: FastAPI, routers: Sequence[APIRouter] = ()) -> None:
    """Answer ``app``'s refusals as JSON errors: its own, the models' (422, or 415 for a body that is not
    JSON), and Starlette's (404, 405 with the ``Allow`` header, 204 for ``OPTIONS``, 400).

    ``routers``: those included in ``app``.  A 405 names every method served at its path, read from the
    application's routes and these routers' (FastAPI may keep an included router's routes behind one
    entry of the application's, depending on its version)."""
    routes = (app.router.routes, *(r.routes for r in routers))
    app.add_exception_handler(ApiError, _api_error)
    app.add_exception_handler(RequestValidationError, _validation)
    app.add_exception_handler(StarletteHTTPException, partial(_http, routes=routes))


async def _api_error(_request, exc: ApiError):
    return error_response(exc.body(), exc.status, exc.headers)


async def _validation(request: Request, exc: RequestValidationError):
    errs = list(exc.errors())
    ctype = request.headers.get("content-type")
    sent = request.headers.get("content-length", "0") != "0" or "transfer-encoding" in request.headers
    if sent and not is_json(ctype) and any(tuple(e.get("loc") or ())[:1] == ("body",) for e in errs):
        err = unsupported_media_type((ctype or "").split(";")[0].strip())  # FastAPI read no JSON from it
    else:
        err = from_validation(errs)
    return error_response(err.body(), err.status)


def _allowed_methods(request: Request, routes: Iterable[Sequence[BaseRoute]]) -> list[str]:
    """Every method some route serves at this path (Starlette names only the first route's)."""
    methods: set[str] = set()
    for route in (route for group in routes for route in group):
        if getattr(route, "methods", None):
            match, _scope = route.matches(request.scope)
            if match is not Match.NONE:
                methods |= set(route.methods)
    return sorted(methods | {"OPTIONS"}) if methods else []


async def _http(request: Request, exc: StarletteHTTPException, *, routes: Iterable[Sequence[BaseRoute]]):
    headers = dict(getattr(exc, "headers", None) or {})
    if exc.status_code == 404:
        err = ApiError(404, "not_found", f"no such resource: {request.method} {request.url.path}",
                       "see the routes at /docs")
    elif exc.status_code == 405:
        allowed = _allowed_methods(request, routes)
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
