"""Storage: the service's tables and transactions, through SQLAlchemy Core.

SQLite (a file, WAL mode, ``synchronous=FULL``) by default; PostgreSQL by URL
for installations with many cells.  Tables:

* ``plans`` — validated plans, keyed by the SHA-256 of their canonical JSON;
* ``cells`` and ``tokens`` — bearer tokens stored as SHA-256 hashes only;
* ``runs`` — a plan being assembled in a cell, with a summary for listings;
* ``events`` — the event log of each run (looks, outcomes, cancels) with the
  answer that was sent; the sequencer's state is rebuilt by replaying it;
* ``idempotency`` — the stored answer of every state-changing request;
* ``meta`` — the schema version and the secret that signs SSE tickets.

Writes go through :meth:`Store.write`: one transaction, committed before the
answer is sent.  On SQLite a write transaction starts with ``BEGIN IMMEDIATE``,
so that two writers never race between a read and a write; readers use a
separate pool and are never blocked by a writer (WAL).
"""

from __future__ import annotations

import json
import secrets
import threading
import time
from contextlib import contextmanager
from typing import Any, Iterator

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
    insert,
    select,
)
from sqlalchemy.engine import Connection, Engine
from sqlalchemy.exc import IntegrityError

SCHEMA_VERSION = "1"

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
        if self.is_sqlite:
            self.writer = self._sqlite_engine(url, immediate=True)
            self.reader = self._sqlite_engine(url, immediate=False)
        else:
            self.writer = self.reader = create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20)
        metadata.create_all(self.writer)
        for index in idempotency.indexes:  # a database made by an older version has the table, not the index
            index.create(self.writer, checkfirst=True)
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

    def journal_mode(self) -> str | None:
        """SQLite's journal mode (``wal``), or None for other databases."""
        if not self.is_sqlite:
            return None
        with self.reader.connect() as conn:
            return conn.exec_driver_sql("PRAGMA journal_mode").scalar()

    def dispose(self) -> None:
        self.writer.dispose()
        if self.reader is not self.writer:
            self.reader.dispose()


def now() -> float:
    return time.time()
