"""Running the service with uvicorn, with logs that never show a credential.

Bearer tokens travel in headers, which uvicorn does not log.  A credential can
still come in a URL: the short-lived SSE ``ticket`` a browser puts in the query
string, or a token a careless client sends as ``?bearer=``, ``?Authorization=``
or under any other name.  So no query string reaches the logs: every value of
a URL's query is replaced by ``REDACTED`` (``/runs?limit=5&bearer=REDACTED``
becomes ``/runs?limit=REDACTED&bearer=REDACTED``), whatever its name, and
``ticket=``, ``token=`` and the like are redacted in any other log text too.
"""

from __future__ import annotations

import copy
import logging
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


def serve(*, db_url: str, host: str, port: int, max_body: int, access_log: bool = True) -> None:
    """Open the store, build the app and serve until interrupted."""
    import uvicorn

    from opportune.service.app import create_app
    from opportune.service.config import Settings

    app = create_app(Settings(db_url=db_url, max_body=max_body))
    logging.getLogger("opportune.service").info("database %s", safe_url(db_url))
    config = uvicorn.Config(app, host=host, port=port, log_config=log_config(), access_log=access_log,
                            timeout_graceful_shutdown=3, server_header=False, proxy_headers=False)
    uvicorn.Server(config).run()
