"""Server-sent events: a run's changes pushed to dashboards (and to any client that wants them).

A stream opens with a ``snapshot`` event (the run, its whole trace, the
layout of its precedence graph), then sends one event per committed change
— ``look``, ``outcome`` or ``cancel`` — carrying the answer that was sent to
the cell (the new or completed trace row and the run's new state), with the
run's event number as the SSE ``id``.  Events are read from the database, so
a stream only ever shows what is committed.  A client that reconnects gets a
fresh snapshot.  Comment lines keep idle connections open through proxies.

Changes made by other server processes (``opportune serve --workers N``, or
several servers on one database) reach a stream too:

* on PostgreSQL at once: once a change is committed its process sends a
  ``pg_notify`` (:meth:`~opportune.service.storage.Store.announce`), and each
  process's :class:`~opportune.service.storage.ChangeListener` wakes the
  :class:`Broker`'s streams of that run — milliseconds, as for a change made
  in the same process;
* always, by polling the log every ``Settings.sse_poll_seconds`` (2 s): the only
  way on SQLite, and the fallback on PostgreSQL while the listener reconnects.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from typing import AsyncIterator, Callable

from starlette.concurrency import run_in_threadpool


def sse(event: str, data: dict, id: int | None = None) -> str:
    """One event in the text/event-stream format (the JSON has no newlines)."""
    head = f"id: {id}\n" if id is not None else ""
    return f"{head}event: {event}\ndata: {json.dumps(data, separators=(',', ':'))}\n\n"


class Broker:
    """Wakes the streams of a run when it changes (thread-safe ``notify``: called after this process's
    commits, and by the database listener for other processes' commits)."""

    def __init__(self):
        self._subs: dict[int, set[asyncio.Event]] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._lock = threading.Lock()

    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop

    def subscribe(self, run_id: int) -> asyncio.Event:
        ev = asyncio.Event()
        with self._lock:
            self._subs.setdefault(run_id, set()).add(ev)
        return ev

    def unsubscribe(self, run_id: int, ev: asyncio.Event) -> None:
        with self._lock:
            subs = self._subs.get(run_id)
            if subs:
                subs.discard(ev)
                if not subs:
                    del self._subs[run_id]

    def notify(self, run_id: int) -> None:
        loop = self._loop
        with self._lock:
            subs = list(self._subs.get(run_id, ()))
        if loop is None or not subs:
            return
        for ev in subs:
            try:
                loop.call_soon_threadsafe(ev.set)
            except RuntimeError:  # loop closed: the server is stopping
                return


def _complete(run) -> bool:
    return isinstance(run, dict) and run.get("status") == "complete"


def _completion(run: dict) -> dict:
    """The ``complete`` event: the run's id, its final sequence, and what was installed in what order."""
    state = run.get("state") or {}
    return {"run": run.get("id"), "seq": run.get("seq"), "installed": state.get("installed"),
            "progress": run.get("progress")}


def event_payload(kind: str, answer: dict) -> dict:
    """What a stream sends for a committed event: the row it added or completed and the run's state."""
    out = {"seq": answer.get("seq"), "kind": kind, "run": answer.get("run")}
    if kind == "look" or kind == "outcome":
        out["row"] = answer.get("row")
    elif kind == "cancel":
        out["cancelled"] = answer.get("cancelled")
    return out


async def stream(run_id: int, snapshot: dict, broker: Broker,
                 events_after: Callable[[int, int], list], still_allowed: Callable[[], bool], *,
                 poll: float = 2.0, keepalive: float = 15.0, recheck: float = 10.0) -> AsyncIterator[str]:
    """The event stream of one run, from ``snapshot`` on (``snapshot["run"]["seq"]`` events already shown).

    ``still_allowed`` (whether the stream's token is still valid, asked of the database) is checked
    every ``recheck`` seconds (the token cache time), whether events are flowing or not, so a revoked
    token's stream ends within that time: with a last ``closed`` event, and nothing after it.
    """
    last = snapshot["run"]["seq"]
    sub = broker.subscribe(run_id)
    clock = time.monotonic
    try:
        yield "retry: 2000\n\n"
        yield sse("snapshot", snapshot, id=last)
        if _complete(snapshot.get("run")):
            yield sse("complete", _completion(snapshot["run"]), id=last)
            return
        next_check = clock() + recheck
        next_keepalive = clock() + keepalive
        while True:
            if clock() >= next_check:
                if not await run_in_threadpool(still_allowed):
                    yield sse("closed", {"reason": "the token of this stream is no longer valid"})
                    return
                next_check = clock() + recheck
            sub.clear()
            batch = await run_in_threadpool(events_after, run_id, last)
            for seq, kind, answer in batch:
                payload = event_payload(kind, answer)
                yield sse(kind, payload, id=seq)
                last = seq
                if _complete(payload.get("run")):
                    # the last part is in: say so, and end the stream (nothing can happen to the run now)
                    yield sse("complete", _completion(payload["run"]), id=seq)
                    return
            if batch:
                next_keepalive = clock() + keepalive
                continue
            wait = max(0.0, min(poll, next_check - clock(), next_keepalive - clock()))
            try:
                await asyncio.wait_for(sub.wait(), timeout=wait)
            except asyncio.TimeoutError:
                if clock() >= next_keepalive:
                    next_keepalive = clock() + keepalive
                    yield ": keepalive\n\n"
    finally:
        broker.unsubscribe(run_id, sub)
