"""A run's live updates: a short-lived ticket (for a browser, which cannot send a bearer header on an
event stream) and the server-sent events themselves."""

from __future__ import annotations

from typing import Callable, Optional

from fastapi import APIRouter, Depends, Query
from fastapi.responses import StreamingResponse
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.concurrency import run_in_threadpool

from opportune.formats.problems import PRINTABLE
from opportune.service.auth import Authenticator, Principal
from opportune.service.config import Settings
from opportune.service.errors import unauthorized
from opportune.service.events import Broker, stream
from opportune.service.routers.depends import RUN_ID
from opportune.service.runs import RunManager
from opportune.service.schemas import Ticket, errors

__all__ = ["router"]


def router(manager: RunManager, auth: Authenticator, broker: Broker, settings: Settings, bearer: HTTPBearer,
           principal: Callable[..., Principal]) -> APIRouter:
    """The event routes: tickets from ``auth``, streams fed by ``broker`` with ``manager``'s events, timed by
    ``settings``; ``bearer`` reads a token, ``principal`` says who is asking."""
    api = APIRouter()

    @api.post("/runs/{run_id}/ticket", tags=["events"], operation_id="createTicket",
              summary="A short-lived ticket to open this run's event stream from a browser",
              responses={200: {"model": Ticket},
                         **errors({401: ["unauthorized"], 404: ["run_not_found"], 413: ["body_too_large"],
                                   422: ["invalid_request"], 500: ["internal_error"]})})
    def post_ticket(run_id: int = RUN_ID, p: Principal = Depends(principal)):
        manager.row(p, run_id)
        ticket = auth.ticket(p, run_id)
        return {"ticket": ticket, "expires_in": int(settings.ticket_seconds),
                "url": f"/runs/{run_id}/events?ticket={ticket}"}

    @api.get("/runs/{run_id}/events", tags=["events"], operation_id="streamEvents",
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

    return api
