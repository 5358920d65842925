"""Idempotent requests: a retried request returns the stored answer and changes nothing.

Every state-changing POST carries an ``Idempotency-Key`` header (any string
of 1–200 printable characters, fresh per request and reused on its retries).
The key is stored with a hash of the request (method, path, canonical JSON
body) and the answer, in the same transaction as the change itself.  A retry
with the same key and the same request gets the stored answer (header
``Idempotent-Replayed: true``); the same key with another request is refused
with 422.  Keys are scoped per cell (all tokens of a cell share them) or per
operator token.  Only answers that changed state are stored: a refused request
changed nothing, and its retry is judged afresh.

Stored answers are kept for ``Settings.idempotency_seconds`` (7 days by default:
far longer than any retry loop) and then forgotten, so the table does not grow
with every request the service ever answered; a request retried after that is
judged afresh.

The answer to a look, an outcome or a cancel is the response stored with its event in the run's log;
its key then stores where that is (``@event RUN SEQ``) rather than the same text again, so a look of
a large plan writes its answer once.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

from sqlalchemy import bindparam, delete, insert, select
from sqlalchemy.engine import Connection

from opportune.service.errors import ApiError
from opportune.service.storage import dumps, events, idempotency, now
from opportune.limits import MAX_KEY  # noqa: F401 (their home: the one table of limits)

HEADER = "Idempotency-Key"
#: A key as :func:`check_key` accepts it, as the OpenAPI document states it: printable characters of ISO 8859-1
#: (what an HTTP header carries), not starting or ending with a space (a server strips those).
KEY_PATTERN = "^[!-~\\xa1-\\xac\\xae-\\xff]([ -~\\xa1-\\xac\\xae-\\xff]*[!-~\\xa1-\\xac\\xae-\\xff])?$"
KEEP_SECONDS = 7 * 24 * 3600.0  # how long a stored answer is kept (the default of Settings.idempotency_seconds)


# Built once: the hot path binds values only.
_LOOKUP = select(idempotency.c.request_hash, idempotency.c.status, idempotency.c.response).where(
    idempotency.c.scope == bindparam("scope"), idempotency.c.key == bindparam("key"))
_INSERT = insert(idempotency)
_FORGET = delete(idempotency).where(idempotency.c.created_at < bindparam("before"))
_EVENT = select(events.c.response).where(events.c.run_id == bindparam("run_id"), events.c.seq == bindparam("seq"))
_POINTER = "@event "   # no JSON text starts so


@dataclass(frozen=True)
class Stored:
    """A stored answer: its status and its exact JSON text (sent again byte for byte)."""

    status: int
    text: str


def check_key(key: str | None, *, required: bool = True) -> str | None:
    """The key, validated; raises 428 when a required key is missing."""
    if key is None or key == "":
        if required:
            raise ApiError(428, "idempotency_key_required", f"this request changes state and needs an {HEADER} header",
                           f"send `{HEADER}: <a fresh random string>` and reuse it when you retry the same request",
                           where=f"header {HEADER}")
        return None
    if len(key) > MAX_KEY or not key.isprintable():
        raise ApiError(400, "bad_idempotency_key", f"the {HEADER} must be 1–{MAX_KEY} printable characters",
                       "use e.g. a UUID", where=f"header {HEADER}")
    return key


def request_hash(method: str, path: str, body: object) -> str:
    """SHA-256 of the request: the same JSON written differently hashes the same."""
    return hashlib.sha256(f"{method} {path}\n{dumps(body)}".encode()).hexdigest()


def lookup(conn: Connection, scope: str, key: str, req_hash: str) -> Stored | None:
    """The stored answer for this key, or None; 422 if the key was used for another request."""
    row = conn.execute(_LOOKUP, {"scope": scope, "key": key}).first()
    if row is None:
        return None
    if row.request_hash != req_hash:
        raise ApiError(422, "idempotency_key_reused",
                       f"the {HEADER} {key!r} was already used for a different request",
                       "use a fresh key for every new request; reuse a key only to retry the identical request",
                       where=f"header {HEADER}")
    text = row.response
    if text.startswith(_POINTER):   # the answer stored with an event of a run's log
        run_id, seq = map(int, text[len(_POINTER):].split())
        text = conn.execute(_EVENT, {"run_id": run_id, "seq": seq}).scalar_one()
    return Stored(row.status, text)


def remember(conn: Connection, scope: str, key: str, req_hash: str, status: int, text: str,
             event: tuple[int, int] | None = None) -> None:
    """Store an answer (its JSON text, as sent); with ``event=(run id, seq)``, where that text is already
    stored as that event's response (in the same transaction)."""
    conn.execute(_INSERT, {"scope": scope, "key": key, "request_hash": req_hash, "status": status,
                           "response": text if event is None else f"{_POINTER}{event[0]} {event[1]}",
                           "created_at": now()})


def forget_before(conn: Connection, before: float) -> int:
    """Forget the answers stored before the time ``before`` (seconds since the epoch); how many."""
    return conn.execute(_FORGET, {"before": before}).rowcount
