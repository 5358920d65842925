"""Plans in the service: upload (validated exactly as ``opportune check``), content hash, and a per-plan cache.

A plan is stored under the SHA-256 of its canonical JSON (``plan.to_dict()``
with sorted keys), so the same plan uploaded twice — even once as YAML and
once as JSON — has one id.  The cache keeps, per plan, the one
:class:`~opportune.engine.OrderEngine` that every run of the plan shares (its
counting memo is what makes decisions cheap) and a lock that serialises the
engine's use between threads.
"""

from __future__ import annotations

import hashlib
import json
import re
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

from sqlalchemy import insert, select

from opportune.engine import OrderEngine
from opportune.formats import CheckResult, check_text, plan_from_dict
from opportune.formats.loader import detect_format, not_utf8
from opportune.plan import Plan, PlanError
from opportune.service.errors import ApiError, plan_not_found
from opportune.service.storage import Store, dumps, now, plans

FORMATS = ("yaml", "json", "in2")
MAX_FILENAME = 200  # characters of an upload's file name (the name used in problems)
_SURROGATE = re.compile("[\ud800-\udfff]")


def _text_field(data: dict, name: str, max_length: int) -> str | None:
    """An optional string field of the upload wrapper, checked: 422 saying which and what is wrong."""
    value = data.get(name)
    if value is None:
        return None
    if not isinstance(value, str) or not value or len(value) > max_length or _SURROGATE.search(value) \
            or not value.isprintable():
        raise ApiError(422, "invalid_request",
                       f"`{name}` must be a string of 1–{max_length} printable characters",
                       "e.g. \"format\": \"yaml\"" if name == "format" else "e.g. \"filename\": \"gearbox.yaml\"",
                       where=f"body.{name}")
    return value


def plan_id(plan: Plan) -> str:
    return hashlib.sha256(dumps(plan.to_dict()).encode()).hexdigest()


def check_upload(raw: bytes, content_type: str | None, filename: str | None, fmt: str | None) -> tuple[CheckResult, str, str]:
    """Validate an uploaded plan; return the check result, the format and the source text.

    ``application/json`` bodies are either a plan in JSON or a wrapper
    ``{"text": ..., "format": ..., "filename": ...}``; any other body is the
    plan file itself, its format from ``fmt``, the file name's suffix, or its
    content (as ``opportune check`` detects it).
    """
    ctype = (content_type or "").split(";")[0].strip().lower()
    if ctype == "application/json":
        try:
            data = json.loads(raw.decode("utf-8-sig"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            pos = f" at line {exc.lineno} column {exc.colno}" if isinstance(exc, json.JSONDecodeError) else ""
            raise ApiError(400, "malformed_json", f"the request body is not valid JSON{pos}",
                           "send a plan in JSON, or {\"text\": <plan file text>, \"format\": \"yaml\"}",
                           where="body") from None
        except (RecursionError, ValueError):
            # Nested deeper than the parser goes, or a number too long to read: a plan in JSON, whose
            # check below says what and where.
            data = None
        if isinstance(data, dict) and "text" in data:
            text = data.get("text")
            if not isinstance(text, str) or _SURROGATE.search(text):
                raise ApiError(422, "invalid_request", "`text` must be the plan file's text (a string of valid Unicode)",
                               "send the file's text as a JSON string", where="body.text")
            extra = set(data) - {"text", "format", "filename"}
            if extra:
                shown = ascii(sorted(map(str, extra))[0])[:60]
                raise ApiError(422, "invalid_request", f"unknown field {shown}",
                               "the upload wrapper has `text`, `format` and `filename`", where="body")
            fmt = _text_field(data, "format", 10) or fmt
            filename = _text_field(data, "filename", MAX_FILENAME) or filename
            raw = text.encode("utf-8")
        else:  # a plan in JSON: ?format= names the format of a raw body, and this one is JSON
            fmt = "json"
    if fmt is not None and fmt not in FORMATS:
        raise ApiError(422, "invalid_request", f"unknown plan format {fmt!r}", "use yaml, json or in2", where="format")
    if filename is not None and (_SURROGATE.search(filename) or not filename.isprintable()):
        raise ApiError(422, "invalid_request", "`filename` must be printable text", "e.g. ?filename=gearbox.yaml",
                       where="filename")
    name = filename or "upload"
    if fmt is None:
        fmt = detect_format(name, raw[:200].decode("latin-1"))
    if fmt == "in2":
        from opportune.formats.salbp import check_in2_bytes

        return check_in2_bytes(raw, file=name), fmt, raw.decode("latin-1")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        problem = not_utf8(raw, exc, name)
        raise ApiError(422, "invalid_plan", problem.message, problem.hint, where=problem.where,
                       extra={"problems": [problem.to_dict()]}) from None
    return check_text(text, fmt=fmt, file=name), fmt, text


def store_plan(store: Store, result: CheckResult, fmt: str, source: str) -> tuple[str, bool]:
    """Store a valid plan (if new); return its id and whether it was new."""
    plan = result.plan
    pid = plan_id(plan)
    with store.write() as c:
        if c.execute(select(plans.c.id).where(plans.c.id == pid)).first() is not None:
            return pid, False
        c.execute(insert(plans).values(id=pid, name=plan.name, format=fmt, source=source,
                                       doc=dumps(plan.to_dict()), created_at=now()))
    return pid, True


def list_plans(store: Store) -> list[dict]:
    """Every stored plan: id, name, format, when it was stored."""
    from opportune.service.views import iso

    with store.read() as c:
        rows = c.execute(select(plans.c.id, plans.c.name, plans.c.format, plans.c.created_at)
                         .order_by(plans.c.created_at)).mappings().all()
    return [{"id": r["id"], "name": r["name"], "format": r["format"], "created_at": iso(r["created_at"])} for r in rows]


@dataclass
class LoadedPlan:
    """A stored plan ready for runs: the plan, its shared engine (and the lock guarding it), summary and layout.

    The engine's counts are bounded in time (``count_seconds`` per count) and
    memory (each counter's per-call ``max_memo`` and its ``max_total`` cap, beyond which the
    oldest memo entries are evicted): the opportunistic policy needs exact
    counts, and a request must not hold a plan's lock for minutes.
    """

    id: str
    plan: Plan
    engine: OrderEngine
    summary: dict
    created_at: float
    lock: threading.Lock = field(default_factory=threading.Lock)
    too_large: str | None = None    # why exact counting of this plan is over the engine's memory budget
    _layouts: list | None = None

    @property
    def layouts(self) -> list[dict]:
        if self._layouts is None:
            from opportune.service.graph import layouts

            self._layouts = layouts(self.plan, self.summary)
        return self._layouts


class PlanBook:
    """Stored plans, loaded on demand and kept (at most ``size``, least recently used dropped)."""

    def __init__(self, store: Store, size: int = 64, *, count_seconds: float | None = None):
        self.store = store
        self.size = size
        self.count_seconds = count_seconds
        self._plans: OrderedDict[str, LoadedPlan] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, pid: str) -> LoadedPlan:
        with self._lock:
            hit = self._plans.get(pid)
            if hit is not None:
                self._plans.move_to_end(pid)
                return hit
        with self.store.read() as c:
            row = c.execute(select(plans.c.doc, plans.c.created_at).where(plans.c.id == pid)).first()
        if row is None:
            raise plan_not_found(pid)
        from opportune.formats.summary import summarize

        try:
            plan = plan_from_dict(json.loads(row.doc))
        except PlanError as exc:  # stored by an earlier version, over this version's limits
            raise ApiError(422, "plan_refused", f"plan {pid} is stored, but this version refuses it: "
                           f"{exc.problems[0].message if exc.problems else exc}",
                           "upload a plan within the limits (opportune check says what they are)",
                           where="body.plan", extra={"problems": [p.to_dict() for p in exc.problems]}) from None
        loaded = LoadedPlan(pid, plan, OrderEngine(plan, time_limit=self.count_seconds), summarize(plan), row.created_at)
        with self._lock:
            hit = self._plans.setdefault(pid, loaded)
            self._plans.move_to_end(pid)
            while len(self._plans) > self.size:
                self._plans.popitem(last=False)
        return hit

    def exists(self, pid: str) -> bool:
        with self.store.read() as c:
            return c.execute(select(plans.c.id).where(plans.c.id == pid)).first() is not None
