"""Running the service with uvicorn, with logs that never show a credential.

Bearer tokens travel in headers, which uvicorn does not log.  The one
credential that can appear in a URL — the short-lived SSE ``ticket`` a browser
puts in the query string — is replaced by ``REDACTED`` in the access log.
"""

from __future__ import annotations

import copy
import logging
import re

CREDENTIAL_IN_QUERY = re.compile(r"((?:ticket|token|access_token)=)[^&\s\"]*", re.IGNORECASE)


def redact(text: str) -> str:
    return CREDENTIAL_IN_QUERY.sub(r"\1REDACTED", text)


class RedactCredentials(logging.Filter):
    """Redacts ``ticket=...`` (and any ``token=...``) in log record arguments and messages."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):
            record.args = tuple(redact(a) if isinstance(a, str) else a for a in record.args)
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
