"""The HTTP service's middleware (pure ASGI): what every request meets before a route reads it.

From the outside in: :class:`Timing` notes when a request arrives; :class:`CatchAll` turns an exception
no handler answered into a JSON 500; :class:`SecurityHeaders` adds ``nosniff`` and, on pages, a strict
Content-Security-Policy; :class:`BodyLimit` refuses a body over the limit (413) and a control character
in the path, query or body (400/422), before the application reads them.
"""

from __future__ import annotations

import logging
import re
import time
from urllib.parse import unquote

from opportune.formats.problems import CONTROL_CHARS
from opportune.service.errors import ApiError, error_response, internal, new_reference

__all__ = ["BodyLimit", "CatchAll", "SecurityHeaders", "Timing", "CSP"]

log = logging.getLogger("opportune.service")

# Pages and scripts come only from this server; nothing from the internet.
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
       "frame-ancestors 'none'; base-uri 'none'; form-action 'self'")

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
