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
    """A SQLAlchemy URL from ``--db``: a URL as given, a bare path as a SQLite file.

    Parameters
    ----------
    db : str or None
        A database URL or a SQLite file's path; ``None``: ``OPPORTUNE_DB`` if set, else
        ``./opportune.db``.

    Returns
    -------
    str
        The URL (a SQLite file's path made absolute).

    Examples
    --------
    >>> database_url("postgresql+psycopg://cell@db.local/runs")
    'postgresql+psycopg://cell@db.local/runs'
    >>> database_url("/var/lib/opportune/runs.db")
    'sqlite:////var/lib/opportune/runs.db'
    """
    db = db or os.environ.get(DB_ENV) or DEFAULT_DB
    if "://" in db:
        return db
    return "sqlite:///" + str(Path(db).expanduser().absolute())


@dataclass(frozen=True)
class Settings:
    """Everything :func:`opportune.service.app.create_app` needs.

    Memory.  ``memory_cap`` is kept by two checks, between requests: the bytes the loaded plans'
    engines account (memos, vectors, tails, programmes, per-state caches; least recently used plans
    are evicted past the cap, their runs rebuilt from their logs when next asked), and the process's
    resident memory (past 85% of the cap, the plans' memos are shrunk to their newest quarter and
    freed pages given back; over the cap itself, least recently used plans are evicted, never the one
    used last).

    Parameters
    ----------
    db_url : str, default "sqlite:///./opportune.db"
        Where runs are stored (:func:`database_url`).
    max_body : int, default 1048576
        Bytes of a request body; at most :data:`opportune.limits.MAX_BODY`, the largest plan file the
        readers read.
    token_cache_seconds : float, default 1.0
        How long a checked token is trusted without asking the database again: a revoked token stops
        working within that time, over HTTP and OPC UA (:data:`REVOCATION_SECONDS`).
    ticket_seconds : float, default 60.0
        How long an SSE ticket can be used to open a stream.
    live_runs : int, default 512
        Runs that keep their sequencer in memory (others are rebuilt from the event log on demand).
    count_seconds : float, default 10.0
        The most one exact count may take: a plan too large for the policy's exact counts is refused
        with a clear error instead of holding a request for minutes.
    decision_budget : float or None, default 0.05
        Seconds a look's decision may take (estimated, and marked so, when exact counts do not fit);
        the answer's counts get what the decision leaves of it (the decision's own counts stop by
        twice it at most), a read's 0.25 s; a count that misses its time is null.  ``None``: every
        decision exact, each count bounded by ``count_seconds``.
    idempotency_seconds : float, default 604800.0
        How long the stored answer of an idempotent request is kept (a retry after that is judged
        afresh).
    sse_poll_seconds : float, default 2.0
        How often an event stream polls the log for changes.
    request_seconds : float, default 10.0
        A request must arrive whole (line, headers, body) within this many seconds of its first byte
        or of its connection's opening, or its connection is closed
        (:mod:`opportune.service.protocol`).
    sse_keepalive_seconds : float, default 15.0
        How often an idle event stream sends a comment, so that proxies keep it open.
    memory_cap : int, optional
        Bytes the server may hold beyond its footprint at start, over all plans; ``None``: a quarter
        of the machine's memory (``MemTotal``).
    plan_share : float, default 0.5
        The share of the cap one plan may hold: its engine keeps its accounted memos within half of
        that share between decisions (resident memory runs up to twice the accounted bytes), and a
        plan whose minimum working set is over the share is refused at upload (413).
    warm_up_seconds : float, default 30.0
        The most time the warm-up of one plan (counting its first state, once per plan and process,
        in the background) may take.
    optimum_seconds : float or None, default 600.0
        With a decision budget, the most time the background preparation of the look-ahead's exact optimum
        may take, once per plan and setting (policy, buffer locations; its states and bytes bounded by the
        policy's own cap and the plan's memory share): its runs decide by it once it is ready, by the
        frontier window until then.  None: no limit.

    Raises
    ------
    ValueError
        If ``max_body`` is over :data:`opportune.limits.MAX_BODY` or under the least body a request
        needs.

    Examples
    --------
    >>> Settings(decision_budget=0.1).max_body
    1048576
    >>> Settings(max_body=10**12)
    Traceback (most recent call last):
        ...
    ValueError: max_body 1,000,000,000,000 is over its maximum of 33,554,432 bytes (32 MiB): the readers read no larger plan file, so a larger body could only be refused later; give at most 33554432
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
    optimum_seconds: float | None = 600.0

    def __post_init__(self):
        # a body larger than the readers' bound could only be refused after it was read
        check_option("max_body", self.max_body, MAX_BODY, MIN_BODY)
