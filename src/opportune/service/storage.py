"""Storage: the service's tables and transactions, through SQLAlchemy Core.

SQLite (a file, WAL mode, ``synchronous=FULL``) by default; PostgreSQL by URL
for installations with many cells.  Tables:

* ``plans`` — validated plans, keyed by the SHA-256 of their canonical JSON;
* ``cells`` and ``tokens`` — bearer tokens stored as SHA-256 hashes only;
* ``runs`` — a plan being assembled in a cell, with a summary for listings;
* ``events`` — the event log of each run (looks, outcomes, cancels) with the
  answer that was sent; the sequencer's state is rebuilt by replaying it;
* ``idempotency`` — the stored answer of every state-changing request;
* ``plan_owners`` — which cells may see and run each plan (those that uploaded it);
* ``meta`` — the schema version and the secret that signs SSE tickets.

Writes go through :meth:`Store.write`: one transaction, committed before the
answer is sent.  On SQLite a write transaction starts with ``BEGIN IMMEDIATE``,
so that two writers never race between a read and a write; readers use a
separate pool and are never blocked by a writer (WAL).

Several server processes can share one PostgreSQL database (``opportune serve
--workers N``).  The schema is created under an advisory lock, so processes
starting together on a fresh database do not race.  Once a change to a run
is committed, the process announces it (:meth:`Store.announce`: a ``pg_notify``
of its own), and each process listens (:class:`ChangeListener`, one connection
per process) to wake its event streams at once for changes committed elsewhere.
"""

from __future__ import annotations

import json
import logging
import secrets
import threading
import time
from contextlib import contextmanager
from typing import Any, Callable, Iterator

from sqlalchemy import (
    Column,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Table,
    Text,
    create_engine,
    event,
    func,
    insert,
    inspect,
    select,
    text,
)
from sqlalchemy.engine import Connection, Engine
from sqlalchemy.exc import IntegrityError

SCHEMA_VERSION = "1"
CHANGES_CHANNEL = "opportune_runs"   # PostgreSQL NOTIFY channel: "<run id> <origin>" for every committed change
SCHEMA_LOCK = 0x6F70706F             # PostgreSQL advisory lock key held while creating the schema ("oppo")
# A notice is its own one-statement transaction that does not wait for the WAL to reach the disk:
# PostgreSQL serialises the commits of transactions that notify (a database-wide lock held until the
# commit is flushed), so a notice inside each write would make every write wait for the previous
# one's flush.  The change itself was committed durably before.
_NOTIFY = text("SELECT set_config('synchronous_commit', 'off', true), pg_notify(:channel, :payload)")
log = logging.getLogger("opportune.service")

metadata = MetaData()

plans = Table(
    "plans", metadata,
    Column("id", String(64), primary_key=True),          # sha256 hex of the canonical plan JSON
    Column("name", String(200), nullable=False),
    Column("format", String(8), nullable=False),          # yaml | json | in2: as uploaded
    Column("source", Text, nullable=False),               # the uploaded text, as uploaded
    Column("doc", Text, nullable=False),                  # plan.to_dict(), canonical JSON
    Column("created_at", Float, nullable=False),
)

cells = Table(
    "cells", metadata,
    Column("name", String(100), primary_key=True),
    Column("created_at", Float, nullable=False),
)

# Who may see and run a plan: the cells that uploaded it (operators read every plan).  A plan's content
# is stored once (its id is its content hash); each cell that uploads it becomes one of its owners.
plan_owners = Table(
    "plan_owners", metadata,
    Column("plan_id", String(64), ForeignKey("plans.id"), primary_key=True),
    Column("cell", String(100), ForeignKey("cells.name"), primary_key=True),
    Column("created_at", Float, nullable=False),
)

tokens = Table(
    "tokens", metadata,
    Column("id", String(16), primary_key=True),           # public id, for listing and revoking
    Column("hash", String(64), nullable=False, unique=True),
    Column("role", String(10), nullable=False),           # cell | operator
    Column("cell", String(100), ForeignKey("cells.name"), nullable=True),
    Column("label", String(200), nullable=False, default=""),
    Column("created_at", Float, nullable=False),
    Column("revoked_at", Float, nullable=True),
)

runs = Table(
    "runs", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("cell", String(100), ForeignKey("cells.name"), nullable=False),
    Column("plan_id", String(64), ForeignKey("plans.id"), nullable=False),
    Column("policy", String(40), nullable=False, default="opportunistic"),
    Column("buffer_capacity", Integer, nullable=True),
    Column("products", Integer, nullable=True),                       # fixtures fed from one bin (null: one)
    Column("label", String(200), nullable=False, default=""),
    Column("status", String(16), nullable=False, default="active"),   # active | complete
    Column("seq", Integer, nullable=False, default=0),                # events in the log
    Column("installed", Integer, nullable=False, default=0),
    Column("units", Integer, nullable=False),
    Column("count", Text, nullable=True),                             # completions left (decimal), if known
    Column("pending", String(200), nullable=True),                    # the pending action, in words
    Column("created_at", Float, nullable=False),
    Column("updated_at", Float, nullable=False),
    Index("ix_runs_cell", "cell"),
)

events = Table(
    "events", metadata,
    Column("run_id", Integer, ForeignKey("runs.id"), primary_key=True),
    Column("seq", Integer, primary_key=True),                         # 1, 2, ... per run
    Column("kind", String(10), nullable=False),                       # look | outcome | cancel
    Column("request", Text, nullable=False),                          # JSON: what was asked
    Column("response", Text, nullable=False),                         # JSON: the answer sent
    Column("created_at", Float, nullable=False),
)

idempotency = Table(
    "idempotency", metadata,
    Column("scope", String(120), primary_key=True),                   # whose key: cell:NAME or token:ID
    Column("key", String(200), primary_key=True),
    Column("request_hash", String(64), nullable=False),
    Column("status", Integer, nullable=False),
    Column("response", Text, nullable=False),
    Column("created_at", Float, nullable=False),
    Index("idempotency_created", "created_at"),                       # old answers are forgotten by age
)

meta = Table(
    "meta", metadata,
    Column("key", String(40), primary_key=True),
    Column("value", Text, nullable=False),
)


def dumps(value: Any) -> str:
    """Canonical compact JSON (sorted keys): stored documents and hashes are stable."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=False)


class Store:
    """The database of one service: engines, schema creation, transactions.

    ``write()`` yields a connection inside one transaction (committed on exit,
    rolled back on an exception); ``read()`` one for reading.
    """

    def __init__(self, url: str):
        self.url = url
        self.is_sqlite = url.startswith("sqlite")
        self._write_lock = threading.Lock()
        self.origin = secrets.token_hex(6)   # names this store's own announcements (see ``listen``)
        self._listeners: list[ChangeListener] = []
        if self.is_sqlite:
            self.writer = self._sqlite_engine(url, immediate=True)
            self.reader = self._sqlite_engine(url, immediate=False)
        else:
            self.writer = self.reader = create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20)
        self.is_postgres = self.writer.dialect.name == "postgresql"
        self._autocommit = self.writer.execution_options(isolation_level="AUTOCOMMIT")
        self._announce_failed = False
        with self.writer.begin() as c:
            if self.is_postgres:  # processes starting together on a fresh database: one creates, the others wait
                c.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": SCHEMA_LOCK})
            metadata.create_all(c)
            for index in idempotency.indexes:  # a database made by an older version has the table, not the index
                index.create(c, checkfirst=True)
            # a database made before several products at once (issue 15) has runs without `products`
            if "products" not in {col["name"] for col in inspect(c).get_columns("runs")}:
                c.execute(text("ALTER TABLE runs ADD COLUMN products INTEGER"))
            # a database made before plans had owners: each cell owns the plans it has runs of (a plan never
            # run is seen by operators until a cell uploads it again)
            if c.execute(select(plan_owners.c.plan_id).limit(1)).first() is None:
                c.execute(insert(plan_owners).from_select(
                    ["plan_id", "cell", "created_at"],
                    select(runs.c.plan_id, runs.c.cell, func.min(runs.c.created_at)).group_by(runs.c.plan_id, runs.c.cell)))
        self._init_meta()

    @staticmethod
    def _sqlite_engine(url: str, *, immediate: bool) -> Engine:
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30},
                               pool_size=8 if immediate else 32, max_overflow=8 if immediate else 32)

        @event.listens_for(engine, "connect")
        def _connect(dbapi_connection, _record):
            # Let SQLAlchemy's "begin" event issue BEGIN (pysqlite's own handling would defer it).
            dbapi_connection.isolation_level = None
            cur = dbapi_connection.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=FULL")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA busy_timeout=30000")
            cur.close()

        if immediate:
            @event.listens_for(engine, "begin")
            def _begin(conn):
                conn.exec_driver_sql("BEGIN IMMEDIATE")
        # Readers run each statement on its own (autocommit): WAL gives each a consistent snapshot,
        # and a reader never holds a lock a writer waits for.

        return engine

    def _init_meta(self) -> None:
        try:
            with self.write() as c:
                have = dict(c.execute(select(meta.c.key, meta.c.value)).all())
                if "schema" not in have:
                    c.execute(insert(meta).values(key="schema", value=SCHEMA_VERSION))
                if "ticket_secret" not in have:
                    c.execute(insert(meta).values(key="ticket_secret", value=secrets.token_hex(32)))
        except IntegrityError:  # another server process initialised the database at the same moment
            pass
        with self.read() as c:
            self.ticket_secret = bytes.fromhex(c.execute(select(meta.c.value).where(meta.c.key == "ticket_secret")).scalar_one())

    @contextmanager
    def write(self) -> Iterator[Connection]:
        if self.is_sqlite:
            # SQLite has one writer at a time.  Queue this process's writers on a lock rather than
            # on SQLite's busy handler, whose sleeping back-off makes long tails under load.
            with self._write_lock, self.writer.begin() as conn:
                yield conn
        else:
            with self.writer.begin() as conn:
                yield conn

    @contextmanager
    def read(self) -> Iterator[Connection]:
        with self.reader.connect() as conn:
            with conn.begin():
                yield conn

    def announce(self, run_id: int) -> None:
        """After a run's change is committed: tell the other server processes (PostgreSQL; else nothing).

        Never fails: a notice that cannot be sent only means the other processes' event streams
        see the change at their next poll.  (A process killed between its commit and this notice
        leaves the same.)
        """
        if not self.is_postgres:
            return
        try:
            with self._autocommit.connect() as c:
                c.execute(_NOTIFY, {"channel": CHANGES_CHANNEL, "payload": f"{run_id} {self.origin}"})
            self._announce_failed = False
        except Exception as exc:
            if not self._announce_failed:  # once per outage, not once per request
                log.warning("could not notify the other server processes of a change (%s); their event streams "
                            "will see it at their next poll", type(exc).__name__)
            self._announce_failed = True

    def listen(self, on_change: Callable[[int], None]) -> "ChangeListener | None":
        """Call ``on_change(run_id)`` for each run another process changes (PostgreSQL with psycopg 3).

        Returns the listener (stopped by :meth:`dispose`), or None where the database cannot
        notify (SQLite: the event streams' poll is then how other processes' changes are seen).
        """
        if not self.is_postgres or self.writer.dialect.driver != "psycopg":
            return None
        cargs, cparams = self.writer.dialect.create_connect_args(self.writer.url)
        cparams = {k: v for k, v in cparams.items() if k != "context"}
        cparams.setdefault("connect_timeout", 10)

        def connect():
            import psycopg

            return psycopg.connect(*cargs, autocommit=True, **cparams)

        listener = ChangeListener(connect, on_change, ignore_origin=self.origin)
        self._listeners.append(listener)
        return listener

    def journal_mode(self) -> str | None:
        """SQLite's journal mode (``wal``), or None for other databases."""
        if not self.is_sqlite:
            return None
        with self.reader.connect() as conn:
            return conn.exec_driver_sql("PRAGMA journal_mode").scalar()

    def dispose(self) -> None:
        for listener in self._listeners:
            listener.stop()
        self._listeners.clear()
        self.writer.dispose()
        if self.reader is not self.writer:
            self.reader.dispose()


def now() -> float:
    return time.time()


class ChangeListener:
    """A thread that LISTENs on PostgreSQL for runs changed by other server processes.

    One connection per process, outside the pools.  Each notice ``"<run id> <origin>"`` whose origin
    is not this process's store calls ``on_change(run_id)`` (the event broker's ``notify``: it only
    wakes streams open on that run).  If the connection fails, it reconnects with a growing pause
    (0.5 s to 10 s); changes in between are seen by the streams' own poll.
    """

    def __init__(self, connect: Callable[[], Any], on_change: Callable[[int], None], *, ignore_origin: str = "",
                 channel: str = CHANGES_CHANNEL):
        self._connect = connect
        self._on_change = on_change
        self._ignore = ignore_origin
        self._channel = channel
        self._stop = threading.Event()
        self.listening = threading.Event()   # set while LISTEN is in place
        self._thread = threading.Thread(target=self._run, name="opportune-listen", daemon=True)
        self._thread.start()

    def _dispatch(self, payload: str) -> None:
        run, _, origin = payload.partition(" ")
        if origin == self._ignore or not run.isdigit():
            return
        try:
            self._on_change(int(run))
        except Exception:  # a broken callback must not end the listening
            log.exception("waking the event streams of run %s failed", run)

    def _run(self) -> None:
        pause = 0.5
        while not self._stop.is_set():
            try:
                with self._connect() as conn:
                    conn.execute(f"LISTEN {self._channel}")
                    self.listening.set()
                    pause = 0.5
                    check = time.monotonic() + 30.0
                    while not self._stop.is_set():
                        for notice in conn.notifies(timeout=1.0):
                            self._dispatch(notice.payload)
                            if self._stop.is_set():
                                break
                        if time.monotonic() >= check:  # a server gone silently: find out, and reconnect
                            conn.execute("SELECT 1")
                            check = time.monotonic() + 30.0
            except Exception as exc:
                if self._stop.is_set():
                    break
                log.warning("listening for changes made by other server processes failed (%s: %s); "
                            "event streams poll meanwhile; retrying in %.1f s", type(exc).__name__,
                            str(exc).splitlines()[0] if str(exc) else "", pause)
                self._stop.wait(pause)
                pause = min(10.0, pause * 2)
            finally:
                self.listening.clear()

    def stop(self, timeout: float = 3.0) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)
