"""Access: bearer tokens per cell, operator tokens, and short-lived tickets for event streams.

* A token is ``opp_`` + ``secrets.token_urlsafe(32)``; only its SHA-256 is
  stored, and the check compares hashes in constant time.  The token itself
  is printed once, by ``opportune token create``.
* A *cell* token sees and drives only its own cell's runs.  An *operator*
  token reads everything (the dashboard) and drives nothing.
* Browsers cannot put a header on an ``EventSource``: the dashboard asks for a
  *ticket* (``POST /runs/{id}/ticket``, with its bearer token) and opens
  ``/runs/{id}/events?ticket=...``.  A ticket is an HMAC-signed
  ``token id . run . expiry``, valid only for that run and only for
  ``ticket_seconds`` to *open* a stream; it is never the token, and the
  access log redacts it (:mod:`opportune.service.server`).
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import re
import secrets
import threading
import time
from dataclasses import dataclass

from sqlalchemy import insert, select, update

from opportune.limits import MAX_NAME
from opportune.service.config import REVOCATION_SECONDS
from opportune.service.storage import Store, cells, now, tokens

TOKEN_PREFIX = "opp_"
#: A cell's or an operator's name (matched whole: ``$`` alone would let a final line feed through).
CELL_NAME = re.compile(rf"[A-Za-z0-9][A-Za-z0-9._-]{{0,{MAX_NAME - 1}}}")


@dataclass(frozen=True)
class Principal:
    """Who is asking: a cell (drives its own runs) or an operator (reads everything)."""

    token_id: str
    role: str                 # "cell" | "operator"
    cell: str | None = None
    label: str = ""

    @property
    def is_operator(self) -> bool:
        return self.role == "operator"

    @property
    def scope(self) -> str:
        """Whose idempotency keys these are: all tokens of a cell share one scope."""
        return f"cell:{self.cell}" if self.role == "cell" else f"token:{self.token_id}"

    def can_see(self, cell: str) -> bool:
        return self.is_operator or self.cell == cell


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


class TokenError(ValueError):
    """A token command that cannot be carried out (bad cell name, unknown token id)."""


def check_cell_name(cell: str, what: str = "cell") -> str:
    """``cell``, if it is a valid name of a cell (or, ``what="operator"``, of an operator); else
    :class:`TokenError` saying what a name may hold (the name shown with its control characters escaped)."""
    if not isinstance(cell, str) or not CELL_NAME.fullmatch(cell):
        raise TokenError(f"invalid {what} name {ascii(cell)[:120]}: use letters, digits, '.', '_' or '-' (at most "
                         f"{MAX_NAME}, starting with a letter or digit)")
    return cell


def create_token(store: Store, *, cell: str | None = None, operator: str | None = None) -> tuple[str, str]:
    """Create a token for a cell (creating the cell if new) or an operator; return ``(token_id, token)``.

    The token is returned once and never stored.
    """
    if (cell is None) == (operator is None):
        raise TokenError("give either a cell or an operator name")
    if operator is not None:    # shown by `token list` and in the dashboard, as a cell's name is
        check_cell_name(operator, "operator")
    token = TOKEN_PREFIX + secrets.token_urlsafe(32)
    token_id = secrets.token_hex(4)
    t = now()
    with store.write() as c:
        if cell is not None:
            _ensure_cell(c, check_cell_name(cell), t)
        c.execute(insert(tokens).values(id=token_id, hash=hash_token(token), role="cell" if cell else "operator",
                                        cell=cell, label=operator or "", created_at=t))
    return token_id, token


def _ensure_cell(c, cell: str, t: float) -> None:
    if c.execute(select(cells.c.name).where(cells.c.name == cell)).first() is None:
        c.execute(insert(cells).values(name=cell, created_at=t))


def ensure_cell(store: Store, cell: str) -> None:
    """Create the cell ``cell`` unless it exists (a cell that runs without a token of its own: the OPC UA
    server's anonymous cell, for development).  :class:`TokenError` for a bad name."""
    with store.write() as c:
        _ensure_cell(c, check_cell_name(cell), now())


def list_tokens(store: Store) -> list[dict]:
    """Every token without its secret: id, role, cell, label, created, revoked."""
    with store.read() as c:
        rows = c.execute(select(tokens.c.id, tokens.c.role, tokens.c.cell, tokens.c.label, tokens.c.created_at,
                                tokens.c.revoked_at).order_by(tokens.c.created_at)).mappings().all()
    return [dict(r) for r in rows]


def revoke_token(store: Store, token_id: str) -> None:
    with store.write() as c:
        n = c.execute(update(tokens).where(tokens.c.id == token_id, tokens.c.revoked_at.is_(None))
                      .values(revoked_at=now())).rowcount
    if not n:
        raise TokenError(f"no active token with id {token_id!r}: see `opportune token list`")


class Authenticator:
    """Checks bearer tokens and tickets against the store, trusting a checked token for ``cache_seconds``
    (:data:`REVOCATION_SECONDS` by default); ``clock`` (monotonic seconds) is injectable for tests."""

    def __init__(self, store: Store, *, cache_seconds: float = REVOCATION_SECONDS, ticket_seconds: float = 60.0,
                 clock=time.monotonic):
        self.store = store
        self.cache_seconds = cache_seconds
        self.ticket_seconds = ticket_seconds
        self.clock = clock
        self._cache: dict[str, tuple[Principal, float]] = {}
        self._alive: dict[str, tuple[bool, float]] = {}
        self._lock = threading.Lock()

    def bearer(self, authorization: str | None) -> Principal | None:
        """The principal of an ``Authorization: Bearer ...`` header, or None."""
        if not authorization:
            return None
        scheme, _, token = authorization.partition(" ")
        if scheme.lower() != "bearer" or not token.strip():
            return None
        return self.token(token.strip())

    def token(self, token: str, *, fresh: bool = False) -> Principal | None:
        """The principal of a token, or None if it is unknown or revoked; from the cache if checked within
        ``cache_seconds`` and not ``fresh`` (then the database is asked: an OPC UA session's activation)."""
        digest = hash_token(token)
        t = self.clock()
        with self._lock:
            hit = self._cache.get(digest)
        if hit and hit[1] > t and not fresh:
            return hit[0]
        with self.store.read() as c:
            row = c.execute(select(tokens).where(tokens.c.hash == digest)).mappings().first()
        if row is None or not hmac.compare_digest(row["hash"], digest) or row["revoked_at"] is not None:
            return None
        p = Principal(row["id"], row["role"], row["cell"], row["label"])
        with self._lock:
            if len(self._cache) > 10_000:
                self._cache.clear()
            self._cache[digest] = (p, t + self.cache_seconds)
        return p

    def by_id(self, token_id: str) -> Principal | None:
        with self.store.read() as c:
            row = c.execute(select(tokens).where(tokens.c.id == token_id)).mappings().first()
        if row is None or row["revoked_at"] is not None:
            return None
        return Principal(row["id"], row["role"], row["cell"], row["label"])

    def alive(self, token_id: str) -> bool:
        """Whether the token ``token_id`` is still valid, asking the database at most every ``cache_seconds``
        (an open OPC UA session's requests).  O(1) but for one indexed read per period."""
        t = self.clock()
        with self._lock:
            hit = self._alive.get(token_id)
        if hit and hit[1] > t:
            return hit[0]
        ok = self.by_id(token_id) is not None
        with self._lock:
            if len(self._alive) > 10_000:
                self._alive.clear()
            self._alive[token_id] = (ok, t + self.cache_seconds)
        return ok

    def revoked(self, token_ids) -> set[str]:
        """Which of ``token_ids`` are revoked or gone (one read); they are no longer trusted from the cache."""
        ids = set(token_ids)
        with self.store.read() as c:
            live = {r[0] for r in c.execute(select(tokens.c.id).where(tokens.c.id.in_(ids),
                                                                      tokens.c.revoked_at.is_(None)))}
        gone = ids - live
        with self._lock:
            for token_id in gone:
                self._alive[token_id] = (False, float("inf"))   # a revocation is not undone
        return gone

    # ------------------------------------------------------------ tickets for event streams

    def _sign(self, payload: str) -> str:
        mac = hmac.new(self.store.ticket_secret, payload.encode(), hashlib.sha256).digest()[:18]
        return base64.urlsafe_b64encode(mac).decode().rstrip("=")

    def ticket(self, principal: Principal, run_id: int) -> str:
        expiry = int(time.time() + self.ticket_seconds)
        payload = f"{principal.token_id}.{run_id}.{expiry}"
        return f"{payload}.{self._sign(payload)}"

    def from_ticket(self, ticket: str, run_id: int) -> Principal | None:
        """The principal of a valid, unexpired ticket for this run, or None."""
        try:
            token_id, run, expiry, mac = ticket.split(".")
            run_ok = int(run) == run_id
            fresh = int(expiry) >= time.time()
        except (ValueError, AttributeError):
            return None
        if not hmac.compare_digest(mac, self._sign(f"{token_id}.{run}.{expiry}")) or not run_ok or not fresh:
            return None
        return self.by_id(token_id)
