"""Settings of the service: where runs are stored and the limits on requests."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from opportune.limits import DEFAULT_MAX_BODY, MAX_BODY, MIN_BODY, check_option

DEFAULT_DB = "sqlite:///./opportune.db"
DB_ENV = "OPPORTUNE_DB"
#: The longest a revoked token keeps working, on every protocol (``Settings.token_cache_seconds``'s default):
#: a checked token is trusted this long without asking the database again (HTTP requests, an open event
#: stream, an open OPC UA session's requests); every this often the OPC UA server closes the sessions of
#: revoked tokens.  A new OPC UA session and a method call always ask the database.  One indexed read per
#: token and period: 1 s costs nothing and keeps the window short.
REVOCATION_SECONDS = 1.0


def database_url(db: str | None) -> str:
    """A SQLAlchemy URL from ``--db``: a URL as given, a bare path as a SQLite file; default ``./opportune.db``.

    ``OPPORTUNE_DB`` is used when ``--db`` is not given.
    """
    db = db or os.environ.get(DB_ENV) or DEFAULT_DB
    if "://" in db:
        return db
    return "sqlite:///" + str(Path(db).expanduser().absolute())


@dataclass(frozen=True)
class Settings:
    """Everything :func:`opportune.service.app.create_app` needs.

    ``max_body`` bounds request bodies (bytes; at most :data:`opportune.limits.MAX_BODY`, the largest plan
    file the readers read: a larger value raises ValueError); ``token_cache_seconds`` is how
    long a checked token is trusted without asking the database again (a
    revoked token stops working within that time, over HTTP and OPC UA:
    :data:`REVOCATION_SECONDS` by default); ``ticket_seconds`` is how
    long an SSE ticket can be used to open a stream; ``live_runs`` is how many
    runs keep their sequencer in memory (others are rebuilt from the event log
    on demand); ``count_seconds`` bounds one exact count (the policy's
    decisions need exact counts; a plan too large for them is refused with a
    clear error instead of holding a request for minutes); ``idempotency_seconds``
    is how long the stored answer of an idempotent request is kept (a retry
    after that is judged afresh).  ``decision_budget`` is the seconds a look's decision
    may take (estimated, and marked so, when exact counts do not fit; the answer's
    counts get what the decision leaves of it (the decision's own counts stop by twice it at
    most), a read's 0.25 s; a count that misses its
    time is null); None: every decision exact, each count bounded by ``count_seconds``.

    Memory.  ``memory_cap`` bounds the memory the server holds beyond its footprint at start, over
    all plans; None: a quarter of the machine's memory (``MemTotal``).  Two checks keep it, between
    requests: the bytes the loaded plans' engines account (memos, vectors, tails, programmes,
    per-state caches; least recently used plans are evicted past the cap, their runs rebuilt from
    their logs when next asked), and the process's resident memory (past 85% of the cap, the plans'
    memos are shrunk to their newest quarter and freed pages given back; over the cap itself, least
    recently used plans are evicted, never the one used last).  One plan
    may hold at most ``plan_share`` of the cap: its engine keeps its accounted memos within half of that
    share between decisions (resident memory runs up to twice the accounted bytes), and a plan whose
    minimum working set is over the share is refused at upload (413).
    ``warm_up_seconds`` is the most time the warm-up of one plan (counting its first state, once per
    plan and process, in the background) may take.  ``request_seconds``: a request must arrive whole
    (line, headers, body) within this many seconds of its first byte or of its connection's opening,
    or its connection is closed (:mod:`opportune.service.protocol`).
    """

    db_url: str = DEFAULT_DB
    max_body: int = DEFAULT_MAX_BODY
    token_cache_seconds: float = REVOCATION_SECONDS
    ticket_seconds: float = 60.0
    live_runs: int = 512
    count_seconds: float = 10.0
    decision_budget: float | None = 0.05
    idempotency_seconds: float = 7 * 24 * 3600.0
    sse_poll_seconds: float = 2.0
    request_seconds: float = 10.0
    sse_keepalive_seconds: float = 15.0
    memory_cap: int | None = None
    plan_share: float = 0.5
    warm_up_seconds: float = 30.0

    def __post_init__(self):
        # a body larger than the readers' bound could only be refused after it was read
        check_option("max_body", self.max_body, MAX_BODY, MIN_BODY)
