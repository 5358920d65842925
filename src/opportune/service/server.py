"""Running the service with uvicorn, with logs that never show a credential.

Bearer tokens travel in headers, which uvicorn does not log.  A credential can
still come in a URL: the short-lived SSE ``ticket`` a browser puts in the query
string, or a token a careless client sends as ``?bearer=``, ``?Authorization=``
or under any other name.  So no query string reaches the logs: every value of
a URL's query is replaced by ``REDACTED`` (``/runs?limit=5&bearer=REDACTED``
becomes ``/runs?limit=REDACTED&bearer=REDACTED``), whatever its name, and
``ticket=``, ``token=`` and the like are redacted in any other log text too.

Several processes (:func:`serve` with ``workers`` > 1, PostgreSQL only) run
under uvicorn's multiprocess supervisor: the parent binds the one listening
socket and starts ``workers`` processes that accept connections on it (the
kernel spreads the connections); it checks each worker every half second and
replaces one that died or hangs (``kill -9`` included), and a SIGTERM to the
parent stops them all.  Each worker builds its own application with
:func:`app_from_environment` from settings the parent leaves in the
environment (``OPPORTUNE_SERVE_SETTINGS``), and closes a keep-alive
connection now and then (:class:`Recycle`) so that connections spread over
the workers.
"""

from __future__ import annotations

import copy
import json
import logging
import os
import re

CREDENTIAL_IN_QUERY = re.compile(
    r"((?:ticket|token|access_token|bearer|authorization|api_key|apikey|key|password|secret)=)[^&\s\"]*",
    re.IGNORECASE)
# A URL's query: from '?' to the end of the URL (a space or quote ends it in a log line).
QUERY = re.compile(r"\?([^\s\"]*)")
PARAM_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-\[\]]{0,40}")


def redact(text: str) -> str:
    """``ticket=``, ``token=``, ``bearer=``, ``authorization=`` ... values in any text replaced by REDACTED."""
    return CREDENTIAL_IN_QUERY.sub(r"\1REDACTED", text)


def redact_query(text: str) -> str:
    """Every value of every URL query in ``text`` replaced by REDACTED, whatever its name.

    A parameter's name is kept when it looks like a name (letters, digits, ``_.-[]``, at most 41);
    anything else (a bare value, a name that could itself be a secret) is REDACTED whole.
    """
    def one(param: str) -> str:
        name, eq, _value = param.partition("=")
        if eq and PARAM_NAME.fullmatch(name) and not name.lower().startswith("opp_"):
            return f"{name}=REDACTED"
        return "REDACTED" if param else param

    return QUERY.sub(lambda m: "?" + "&".join(one(p) for p in m.group(1).split("&")), text)


def _clean(value: str) -> str:
    """A log argument without credentials: a path or URL loses its whole query."""
    value = redact(value)
    return redact_query(value) if value.startswith("/") or "://" in value else value


class RedactCredentials(logging.Filter):
    """No URL query and no ``ticket=...``-like value in a log record's arguments or message."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):
            record.args = tuple(_clean(a) if isinstance(a, str) else a for a in record.args)
        elif isinstance(record.args, dict):
            record.args = {k: _clean(v) if isinstance(v, str) else v for k, v in record.args.items()}
        if isinstance(record.msg, str):
            record.msg = redact(record.msg)
        return True


def log_config() -> dict:
    from uvicorn.config import LOGGING_CONFIG

    cfg = copy.deepcopy(LOGGING_CONFIG)
    cfg.setdefault("filters", {})["redact"] = {"()": "opportune.service.server.RedactCredentials"}
    for handler in cfg["handlers"].values():
        handler.setdefault("filters", []).append("redact")
    cfg["loggers"]["opportune.service"] = {"handlers": ["default"], "level": "INFO", "propagate": False}
    return cfg


def safe_url(url: str) -> str:
    """A database URL for printing: the password hidden."""
    from sqlalchemy.engine import make_url

    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # an unparsable URL is reported by the store itself
        return url


SETTINGS_ENV = "OPPORTUNE_SERVE_SETTINGS"
RECYCLE_EVERY = 100   # with several workers: a keep-alive connection is closed after about this many requests


class Recycle:
    """Closes a keep-alive connection after about ``every`` requests (``Connection: close`` on one answer
    in ``every``, at random), so that clients reconnect from time to time and the workers sharing the
    port even out.

    Workers accept new connections from one socket; a client keeps its connection, and so its worker,
    for as long as it likes, and connections made in a burst (every cell at start-up) can all land on
    one worker.  Reconnecting once in a hundred requests costs a TCP handshake on loopback or a LAN;
    HTTP clients reconnect on their own.  Event streams are left alone.  (Pure ASGI.)
    """

    def __init__(self, app, every: int = RECYCLE_EVERY):
        import random

        self.app = app
        self.every = every
        self._random = random.Random()

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["path"].endswith("/events") or self._random.random() * self.every >= 1:
            return await self.app(scope, receive, send)

        async def closing(message):
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", ()), (b"connection", b"close")]}
            await send(message)

        await self.app(scope, receive, closing)


def app_from_environment():
    """The application of one worker process, from the settings :func:`serve` put in the environment."""
    from opportune.service.app import create_app
    from opportune.service.config import Settings

    from opportune.service.protocol import Guarded

    settings = Settings(**json.loads(os.environ[SETTINGS_ENV]))
    Guarded.seconds = settings.request_seconds
    logging.getLogger("opportune.service").info("worker %d: database %s", os.getpid(), safe_url(settings.db_url))
    app = create_app(settings)
    app.add_middleware(Recycle)
    return app


def serve(*, db_url: str, host: str, port: int, max_body: int, access_log: bool = True, workers: int = 1,
          settings: dict | None = None, opcua=None, http: bool = True) -> None:
    """Open the store, build the app and serve until interrupted; with ``workers`` > 1, that many processes
    sharing the port and the database (PostgreSQL: :func:`opportune.cli.service.serve` refuses SQLite).
    ``settings``: further :class:`~opportune.service.config.Settings` fields by name.  ``opcua``: an
    :class:`~opportune.service.opcua.OpcUaOptions` to serve OPC UA too, on the same run manager (it
    listens before HTTP does), or alone with ``http=False``."""
    settings = {"db_url": db_url, "max_body": max_body, **(settings or {})}
    if not http:
        from opportune.service.config import Settings
        from opportune.service.core import build
        from opportune.service.opcua import serve_alone

        core = build(Settings(**settings))
        try:
            serve_alone(core, opcua, on_ready=lambda: logging.getLogger("opportune.service").warning(
                "OPC UA on %s (database %s)", opcua.endpoint, safe_url(db_url)))
        finally:
            core.close()
        return
    import uvicorn

    from opportune.service.protocol import REQUEST_SECONDS, Guarded

    Guarded.seconds = float(settings.get("request_seconds", REQUEST_SECONDS))
    common = dict(host=host, port=port, log_config=log_config(), access_log=access_log, timeout_graceful_shutdown=3,
                  server_header=False, proxy_headers=False, http=Guarded)
    if workers > 1:
        # Spawned workers import the application by name; the settings travel in the environment.
        os.environ[SETTINGS_ENV] = json.dumps(settings)
        uvicorn.run("opportune.service.server:app_from_environment", factory=True, workers=workers, **common)
        return

    from opportune.service.app import create_app
    from opportune.service.config import Settings

    app = create_app(Settings(**settings))
    logging.getLogger("opportune.service").info("database %s", safe_url(db_url))
    beside = None
    if opcua is not None:
        from opportune.service.opcua import OpcUaThread

        beside = OpcUaThread(app.state.core, opcua).start()
    try:
        uvicorn.Server(uvicorn.Config(app, **common)).run()
    finally:
        if beside is not None:
            beside.stop()
