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

The routes live in :mod:`opportune.service.routers`, one module a resource; the request bodies in
:mod:`opportune.service.bodies`, the middleware in :mod:`opportune.service.middleware` and the error
handlers in :mod:`opportune.service.handlers`.  :func:`create_app` puts them together.
"""

from __future__ import annotations

import asyncio
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi.security import HTTPBearer

from opportune import __version__
from opportune.service.config import Settings
from opportune.service.core import build as build_core
from opportune.service.events import Broker
from opportune.service.handlers import install_handlers
from opportune.service.middleware import BodyLimit, CatchAll, SecurityHeaders, Timing
from opportune.service.routers import cells, dashboard, events, plans, runs
from opportune.service.routers.depends import principal_dependency
from opportune.service.schemas import complete_openapi
from opportune.service.storage import Store

__all__ = ["create_app"]

SUMMARY = "The opportunistic sequencer of Fox & Kempf as a service for robot cells."
DESCRIPTION = (
    "A cell posts what its camera sees (`POST /runs/{id}/looks`) and gets the action to do; it then reports "
    "the outcome (`POST /runs/{id}/outcomes`). Every look, decision and outcome is committed before the "
    "answer is sent. Authenticate with `Authorization: Bearer <token>` (`opportune token create CELL`). "
    "Send an `Idempotency-Key` header on POSTs that change a run and reuse it on retries. Errors are "
    "`{\"error\": {status, code, message, hint, where}}`.")


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

    app = FastAPI(title="opportune", version=__version__, summary=SUMMARY, description=DESCRIPTION,
                  docs_url=None, redoc_url=None, lifespan=lifespan)
    app.state.store, app.state.manager, app.state.auth, app.state.broker = store, manager, auth, broker
    app.state.core = core   # what another front end served beside this one shares (the OPC UA server)
    bearer = HTTPBearer(auto_error=False, description="A cell or operator token from `opportune token create`")
    principal = principal_dependency(auth, bearer)
    # in this order: the OpenAPI document lists the operations as the routes are included
    routers = [dashboard.router(store), plans.router(store, book, principal), cells.router(manager, principal),
               runs.router(manager, principal), events.router(manager, auth, broker, settings, bearer, principal)]
    for router in routers:
        app.include_router(router)
    dashboard.mount_static(app)
    install_handlers(app, routers)
    _complete_openapi(app)
    app.add_middleware(BodyLimit, limit=settings.max_body)
    app.add_middleware(SecurityHeaders)
    app.add_middleware(CatchAll)  # covers the two above as well
    app.add_middleware(Timing)    # outermost: a request's clock starts before any other work
    return app


def _complete_openapi(app: FastAPI) -> None:
    """``app.openapi()``: FastAPI's document, completed (:func:`opportune.service.schemas.complete_openapi`)."""
    generated_openapi = app.openapi

    def openapi() -> dict:
        if app.openapi_schema is None:
            app.openapi_schema = complete_openapi(generated_openapi())
        return app.openapi_schema

    app.openapi = openapi
