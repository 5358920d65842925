"""Plans in the service: upload (validated exactly as ``opportune check``), content hash, and a per-plan cache.

A plan is stored under the SHA-256 of its canonical JSON (``plan.to_dict()``
with sorted keys), so the same plan uploaded twice — even once as YAML and
once as JSON — has one id.  The cache keeps, per plan, the one
:class:`~opportune.engine.OrderEngine` that every run of the plan shares (its
counting memo is what makes decisions cheap) and a lock that serialises the
engine's use between threads.
"""

from __future__ import annotations

import gc
import hashlib
import json
import re
import threading
import time
from collections import OrderedDict
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import partial

from sqlalchemy import insert, select
from sqlalchemy.exc import IntegrityError

from opportune.engine import OrderEngine, Schedule
from opportune.engine.deadline import Deadline
from opportune.engine.memory import memory_total, resident, trim
from opportune.formats import CheckResult, check_text, plan_from_dict
from opportune.formats.loader import detect_format, not_utf8
from opportune.planning.plan import Plan, PlanError
from opportune.service.errors import ApiError, plan_not_found
from opportune.service.storage import Store, dumps, now, plan_owners, plans
from opportune.limits import MAX_FILENAME  # noqa: F401 (their home: the one table of limits)

FORMATS = ("yaml", "json", "in2")
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
        if isinstance(data, dict) and "shipped" in data:
            extra = set(data) - {"shipped"}
            if extra:
                raise ApiError(422, "invalid_request", f"unknown field {ascii(sorted(map(str, extra))[0])[:60]} "
                               "beside `shipped`", "send {\"shipped\": \"salbp:ARC111\"} alone", where="body")
            return shipped_plan(data["shipped"], "body.shipped")
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


def shipped_plan(name, where: str) -> tuple[CheckResult, str, str]:
    """A plan shipped with the package, by the name the command line takes (``salbp:ARC111``,
    ``example:gearbox``; case aside): its check, format and text.  Any other name is a 422 ``unknown_plan``
    saying which names there are: nothing but the shipped files is ever opened."""
    from opportune.formats.loader import read_plan
    from opportune.formats.problems import did_you_mean, listing
    from opportune.formats.shipped import plan_names, resolve

    names = plan_names()
    known = {n.casefold(): n for n in names}
    if not isinstance(name, str) or name.casefold() not in known:
        shown = ascii(name)[:80] if isinstance(name, str) else "that is not a string"
        raise ApiError(422, "unknown_plan", f"no plan is shipped as {shown}",
                       (did_you_mean(name, names) if isinstance(name, str) else "")
                       + f"the package ships {listing(names)} ({len(names)} plans)", where=where)
    name = known[name.casefold()]
    path = resolve(name)
    fmt = "in2" if path.suffix.lower() == ".in2" else "yaml"
    return read_plan(name), fmt, path.read_text(encoding="latin-1" if fmt == "in2" else "utf-8")


def is_shipped_name(plan: str) -> bool:
    """Whether a run's ``plan`` names a shipped plan (``salbp:...``, ``example:...``) rather than giving an id."""
    from opportune.formats.shipped import EXAMPLE_PREFIX, PREFIX

    return plan.lower().startswith((PREFIX, EXAMPLE_PREFIX))


def store_plan(store: Store, result: CheckResult, fmt: str, source: str, owner: str) -> tuple[str, bool]:
    """Store a valid plan (its content once) and make the cell ``owner`` one of its owners; return its id
    and whether it is new to this cell (another cell's upload of the same plan says nothing to this one)."""
    plan = result.plan
    pid = plan_id(plan)

    def store_it() -> bool:
        with store.write() as c:
            if c.execute(select(plans.c.id).where(plans.c.id == pid)).first() is None:
                c.execute(insert(plans).values(id=pid, name=plan.name, format=fmt, source=source,
                                               doc=dumps(plan.to_dict()), created_at=now()))
            mine = select(plan_owners.c.plan_id).where(plan_owners.c.plan_id == pid, plan_owners.c.cell == owner)
            if c.execute(mine).first() is not None:
                return False
            c.execute(insert(plan_owners).values(plan_id=pid, cell=owner, created_at=now()))
        return True

    try:
        return pid, store_it()
    except IntegrityError:      # the same plan stored at the same moment by another request: now it is there
        return pid, store_it()


def accept_upload(store: Store, book: "PlanBook", principal, raw: bytes, content_type: str | None,
                  filename: str | None = None, fmt: str | None = None) -> tuple[int, dict]:
    """Check an uploaded plan as ``opportune check`` does, and store it for the principal's cell if it is
    valid and fits its share of the server's memory; ``(201 if new to this cell else 200, the answer)``.
    A plan with errors raises 422 ``invalid_plan`` listing every problem.  O(size of the plan)."""
    return accept_checked(store, book, principal, *check_upload(raw, content_type, filename, fmt))


def accept_checked(store: Store, book: "PlanBook", principal, result: CheckResult, fmt: str,
                   source: str) -> tuple[int, dict]:
    """:func:`accept_upload` after the check: a plan with errors raises 422 ``invalid_plan``; a valid one
    that fits its share of memory is stored for the principal's cell."""
    problems = [pr.to_dict() for pr in result.problems]
    if not result.ok:
        first = result.errors[0] if result.errors else None
        raise ApiError(422, "invalid_plan",
                       f"the plan has {len(result.errors)} error(s)" + (f"; first: {first}" if first else ""),
                       "fix every problem listed (each has its line), then upload again",
                       where=first.where if first else "body", extra={"problems": problems})
    book.check_fits(result.plan)    # within its share of the server's memory, before it is stored
    pid, created = store_plan(store, result, fmt, source, principal.cell)
    from opportune.formats.summary import summarize

    return (201 if created else 200), {"id": pid, "name": result.plan.name, "created": created,
                                       "format": fmt, "parts": list(result.plan.part_ids),
                                       "units": result.plan.n_units, "summary": summarize(result.plan),
                                       "warnings": [w for w in problems if w["severity"] == "warning"]}


def may_see(store: Store, principal, pid: str) -> bool:
    """Whether ``principal`` may read and run plan ``pid``: an operator any stored plan, a cell the plans
    it uploaded.  One indexed read."""
    with store.read() as c:
        if principal.is_operator:
            return c.execute(select(plans.c.id).where(plans.c.id == pid)).first() is not None
        return c.execute(select(plan_owners.c.plan_id).where(plan_owners.c.plan_id == pid,
                                                             plan_owners.c.cell == principal.cell)).first() is not None


def list_plans(store: Store, principal) -> list[dict]:
    """The stored plans ``principal`` may see (an operator: all, with their owners; a cell: its own):
    id, name, format, when it was stored."""
    from opportune.service.views import iso

    with store.read() as c:
        q = select(plans.c.id, plans.c.name, plans.c.format, plans.c.created_at).order_by(plans.c.created_at)
        if not principal.is_operator:
            q = q.where(plans.c.id.in_(select(plan_owners.c.plan_id).where(plan_owners.c.cell == principal.cell)))
        rows = c.execute(q).mappings().all()
        owners: dict[str, list[str]] = {}
        if principal.is_operator:
            for pid, cell in c.execute(select(plan_owners.c.plan_id, plan_owners.c.cell).order_by(plan_owners.c.cell)):
                owners.setdefault(pid, []).append(cell)
    out = []
    for r in rows:
        item = {"id": r["id"], "name": r["name"], "format": r["format"], "created_at": iso(r["created_at"])}
        if principal.is_operator:
            item["owners"] = owners.get(r["id"], [])
        out.append(item)
    return out


def _int_bytes(bits: int) -> int:
    """Bytes of a Python int of ``bits`` bits (30-bit digits)."""
    return 28 + 4 * (-(-bits // 30))


def min_working_set(plan: Plan) -> int:
    """Bytes a plan's engine needs before its first decision, from its size alone (nothing is built).

    Per strategy, the unit order's ``below``/``above`` bitsets (2 n ints of n bits); per counter, the
    byte tables of its scans (2 · ⌈n/8⌉ · 256 ints of n bits, filled lazily above 1,024 units: then an
    eighth is counted); and the first state's memo, at least one count per unit.  O(strategies).

    >>> from opportune import make_plan
    >>> min_working_set(make_plan([f"p{i}" for i in range(1000)], {})) > 10 * 2**20
    True
    """
    n = max(1, plan.n_units)
    k = max(1, len(plan.strategies))
    word = _int_bytes(n) + 8            # an n-bit int and its list slot
    orders = k * 2 * n * word
    tables = 2 * (-(-n // 8)) * 256 * word
    if n > 1024:
        tables //= 8
    memo = n * (2 * word + 100)
    return orders + tables + memo + 65_536


@dataclass
class LoadedPlan:
    """A stored plan ready for runs: the plan, its shared engine (and the lock guarding it), summary and layout.

    The engine's counts are bounded in time (``count_seconds`` per count) and
    memory (each counter's per-call ``max_memo`` and its ``max_total`` cap, beyond which the
    oldest memo entries are evicted): the opportunistic policy needs exact
    counts, and a request must not hold a plan's lock for minutes.

    Everything a plan needs before its first decision is built once per process and shared by every
    run of the plan: the engine with its memos, the warm-up (counting the first state, in the
    background, in slices of the lock: :meth:`PlanBook.warm`) and the look-ahead's programme (shared
    per engine by the policy).  ``nbytes`` is what :class:`PlanBook` last accounted for it.
    """

    id: str
    plan: Plan
    engine: OrderEngine
    summary: dict
    created_at: float
    lock: threading.Lock = field(default_factory=threading.Lock)
    too_large: str | None = None    # why exact counting of this plan is over the engine's memory budget
    nbytes: int = 0                 # accounted bytes (engine, programme), updated between requests
    measured: float = float("-inf")  # time.monotonic() of the last measurement
    warm: str = "not started"       # the warm-up: not started, running, done, stopped (time or memory)
    warm_slices: int = 0            # slices of warm-up work done (each under the lock, within its deadline)
    # the look-ahead optima prepared for its runs' settings (policy name, buffer locations): "waiting", "under
    # way", "ready", "does not fit", "stopped" (time, eviction or memory); one at a time, in the order asked
    optima: dict = field(default_factory=dict)
    _to_prepare: list = field(default_factory=list)
    evicted: bool = False
    _stop: threading.Event = field(default_factory=threading.Event)
    _layouts: list | None = None

    @property
    def layouts(self) -> list[dict]:
        if self._layouts is None:
            from opportune.service.graph import layouts

            self._layouts = layouts(self.plan, self.summary)
        return self._layouts

    def measure(self) -> int:
        """Bytes held for this plan: its engine (memos, vectors, tails, per-state caches) and the
        look-ahead programmes on it.  Caller holds ``lock`` (the memos must not change meanwhile)."""
        from opportune.policies.lookahead import programme_bytes

        total = self.engine.nbytes() + programme_bytes(self.engine)
        self.nbytes = total
        self.measured = time.monotonic()
        return total


WARM_SLICE = 0.02   # seconds of warm-up work per hold of a plan's lock: a look waits at most this long
WARM_GAP = 0.005    # seconds the warm-up lets go of the lock between slices, so that a waiting look gets it
WARM_YIELD = 1.0    # longest a warm-up waits for requests in progress before its next slice
WARM_IDLE = 0.05    # seconds without a request before a warm-up slice starts
#: Past this share of its memory cap (beyond its footprint at start), a process shrinks its plans' memos ...
HIGH_WATER = 0.85
#: ... to this share of each (the newest entries), ...
SHRINK_KEEP = 0.25
#: ... spending at most this many seconds per plan between two requests (the rest, after the next one);
SHRINK_SECONDS = 0.05
#: then it acts again only once its memory has grown by this share of the cap beyond what was left.
REARM = 0.05
MEASURE_EVERY = 0.5  # seconds between measurements of a plan in use (one decision adds a bounded number of entries)


class PlanBook:
    """Stored plans, loaded on demand and kept within a memory cap (least recently used evicted).

    ``memory_cap`` bounds the bytes accounted over every loaded plan (None: a quarter of the
    machine's memory); a plan may use at most ``plan_share`` of it, and one whose minimum working set
    (:func:`min_working_set`) is over that share is refused (413) before anything is built.  The cap
    is enforced by :meth:`settle`, between requests: whole plans are evicted, least recently used
    first, never one whose lock is held (inside a decision; a plan over its share first loses its
    per-state caches, see :meth:`settle`); an evicted plan's runs are rebuilt from
    their logs on their next request (``on_evict`` tells the run manager).  ``size`` still bounds the
    number of plans kept.
    """

    def __init__(self, store: Store, size: int = 64, *, count_seconds: float | None = None,
                 memory_cap: int | None = None, plan_share: float = 0.5, resident=resident):
        if memory_cap is not None and memory_cap <= 0:
            raise ValueError("memory_cap must be a positive number of bytes (or None: a quarter of the memory)")
        if not 0 < plan_share <= 1:
            raise ValueError("plan_share must be in (0, 1]")
        self.store = store
        self.size = size
        self.count_seconds = count_seconds
        self.memory_cap = memory_cap if memory_cap is not None else memory_total() // 4
        self.plan_share = plan_share
        self.resident = resident        # () -> this process's resident bytes (or None); tests inject one
        self.baseline = resident() or 0     # the process's footprint before any plan: not the plans'
        self.shrinks = 0                # times the plans' memos were shrunk for the process's memory
        self._floor = 0                 # resident bytes beyond the baseline after the last shrink
        self.on_evict: list = []        # callables(pid), told when a plan is evicted
        self.loads = 0                  # engines built (a reloaded, evicted plan counts again)
        self.evictions = 0
        self.active = 0                 # requests in progress (see busy)
        self.last_request = float("-inf")   # time.monotonic() when the last one ended
        self._plans: OrderedDict[str, LoadedPlan] = OrderedDict()
        self._lock = threading.Lock()
        self._evicted: list[str] = []   # evicted, not yet told to ``on_evict``

    @property
    def share(self) -> int:
        """Most bytes one plan may hold."""
        return int(self.memory_cap * self.plan_share)

    def check_fits(self, plan: Plan) -> None:
        """Refuse (413) a plan whose minimum working set is over its share of the memory cap. O(strategies)."""
        need = min_working_set(plan)
        if need > self.share:
            mb = 2 ** 20
            raise ApiError(413, "plan_too_large_for_memory",
                           f"this plan needs at least {need / mb:,.0f} MB to be counted ({plan.n_units:,} units, "
                           f"{len(plan.strategies)} strateg{'y' if len(plan.strategies) == 1 else 'ies'}), over its "
                           f"share of the server's memory ({self.share / mb:,.0f} MB of a cap of "
                           f"{self.memory_cap / mb:,.0f} MB)",
                           "split the plan into smaller ones (fewer units or strategies), or start the server "
                           "with a larger memory cap", where="body")

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
        self.check_fits(plan)   # stored under a larger cap, or a joint plan of several products
        self.settle(room=min_working_set(plan))
        # resident memory runs above the accounted bytes (allocator slack, memory freed and reused): half the share
        engine = OrderEngine(plan, time_limit=self.count_seconds, memory_limit=self.share // 2)
        loaded = LoadedPlan(pid, plan, engine, summarize(plan), row.created_at)
        with self._lock:
            hit = self._plans.setdefault(pid, loaded)
            self._plans.move_to_end(pid)
            if hit is loaded:
                self.loads += 1
                loaded.nbytes = min_working_set(plan)
        self.settle()
        return hit

    # ------------------------------------------------------------ the warm-up, once per plan

    def warm(self, loaded: LoadedPlan, seconds: float | None, *, foreground: float = 0.0, background: bool = True) -> None:
        """Count the plan's first state, once per loaded plan, for at most ``seconds`` in all (None: no
        limit): up to ``foreground`` seconds now (the caller must not hold the plan's lock), the rest in
        a background thread, in slices of :data:`WARM_SLICE` seconds under the plan's lock, until done,
        out of time, or the plan's memory share is reached.  A look between slices decides with what is
        counted so far (within its own budget).  Later calls do nothing (counted: ``warm_slices``).

        What it counts stays in the engine's memos, so each slice continues where the last stopped.
        """
        with self._lock:
            if loaded.warm != "not started":
                return
            loaded.warm = "running"
        from opportune.engine.deadline import Deadline

        end = Deadline.after(seconds)
        if foreground > 0 and self._warm_slice(loaded, end.within(foreground)):
            return
        if not background:
            loaded.warm = "stopped"
            return
        threading.Thread(target=self._warm_loop, args=(loaded, end), name=f"warm-up {loaded.id[:8]}",
                         daemon=True).start()

    def _warm_slice(self, loaded: LoadedPlan, until) -> bool:
        """One slice of the warm-up (until the Deadline ``until``); True when the warm-up is over."""
        with loaded.lock:
            if loaded.evicted or loaded._stop.is_set():
                loaded.warm = "stopped"
                return True
            try:
                done = Schedule(loaded.engine).warm_up(max(0.0, until.remaining()))
            except (MemoryError, RecursionError):   # beyond what this process can count: decisions will say so
                done = None
            loaded.warm_slices += 1
            if done:
                loaded.warm = "done"
            elif done is None:
                loaded.warm = "stopped"
            elif time.monotonic() >= loaded.measured + MEASURE_EVERY and loaded.measure() > self.share:
                loaded.warm = "stopped"     # the memos reached the plan's share: no more warming
            return loaded.warm != "running"

    @contextmanager
    def busy(self):
        """Marks a request in progress: the warm-ups pause meanwhile (a Python thread counting beside a
        decision would take half of the interpreter's time from it)."""
        with self._lock:
            self.active += 1
        try:
            yield
        finally:
            with self._lock:
                self.active -= 1
                self.last_request = time.monotonic()

    def _warm_loop(self, loaded: LoadedPlan, end) -> None:
        if not self._in_slices(end, lambda until: self._warm_slice(loaded, until)):
            loaded.warm = "stopped"

    def _in_slices(self, end, work) -> bool:
        """Call ``work(until)`` in slices of :data:`WARM_SLICE` seconds until it returns True (then True) or
        ``end`` passes (then False), requests first: a slice waits for the requests in progress, at most
        :data:`WARM_YIELD`."""
        over = False
        while not over and not end.expired():
            waited = 0.0
            # requests first (a cell's next look follows its last answer closely); still, a slice per WARM_YIELD
            while (self.active or time.monotonic() - self.last_request < WARM_IDLE) and waited < WARM_YIELD:
                time.sleep(WARM_GAP)
                waited += WARM_GAP
            over = work(end.within(WARM_SLICE))
            self.settle()
            time.sleep(WARM_GAP)
        self.settle()
        return over

    # ------------------------------------------------------------ the look-ahead's optimum, once per plan and setting

    def prepare(self, loaded: LoadedPlan, policy, setting, seconds: float | None) -> None:
        """Prepare the exact optimum of ``policy`` (a look-ahead without a budget, of the run's settings) on
        the plan, once per plan and ``setting``, in a background thread, in slices of :data:`WARM_SLICE`
        seconds under the plan's lock between requests, for at most ``seconds`` each (None: no limit); one
        setting at a time per plan (one thread), the others waiting in the order asked.  Its states and bytes
        are bounded by the policy (:meth:`~opportune.policies.lookahead.Lookahead.prepare`: its state cap and
        the engine's grant, over every setting).  The runs' look-aheads with a budget take it up once it is
        ready: until then their frontier window decides.  ``loaded.optima[setting]`` says how it went.  A
        policy without ``prepare`` is left alone.  O(1) here."""
        if getattr(policy, "prepare", None) is None:
            return
        with self._lock:
            if setting in loaded.optima:
                return
            loaded.optima[setting] = "waiting"
            loaded._to_prepare.append((policy, setting, seconds))
            if len(loaded._to_prepare) > 1:
                return          # the plan's thread takes it after those before it
        threading.Thread(target=self._prepare_loop, args=(loaded,), name=f"optimum {loaded.id[:8]}",
                         daemon=True).start()

    def _prepare_loop(self, loaded: LoadedPlan) -> None:
        """The plan's preparations, one after another, until none waits."""
        while True:
            with self._lock:
                if not loaded._to_prepare:
                    return
                policy, setting, seconds = loaded._to_prepare[0]
                loaded.optima[setting] = "under way"
            if not self._in_slices(Deadline.after(seconds), partial(self._prepare_slice, loaded, policy, setting)):
                loaded.optima[setting] = "stopped"
            with self._lock:
                loaded._to_prepare.pop(0)

    def _prepare_slice(self, loaded: LoadedPlan, policy, setting, until) -> bool:
        """One slice of an optimum's preparation (until the Deadline ``until``); True when it is over."""
        with loaded.lock:
            if loaded.evicted or loaded._stop.is_set():
                loaded.optima[setting] = "stopped"
                return True
            try:
                done = policy.prepare(loaded.engine, until)
            except (MemoryError, RecursionError):   # beyond this process: the window goes on deciding
                done = False
            if done is not None:
                loaded.optima[setting] = "ready" if done else "does not fit"
            return done is not None

    # ------------------------------------------------------------ memory

    def nbytes(self) -> int:
        """Bytes accounted over every loaded plan (as last measured)."""
        with self._lock:
            return sum(p.nbytes for p in self._plans.values())

    def settle(self, used: LoadedPlan | None = None, *, room: int = 0) -> None:
        """Between requests: measure ``used`` (if its lock is free), then evict least recently used plans
        not in use until the accounted bytes plus ``room`` fit the cap.  A plan over its own share first
        loses its per-state caches (its runs go on, nothing to rebuild), and is evicted if that is not
        enough.  Then the process itself: see :meth:`hold_resident`.  O(plans + sampled memos of the
        plans measured)."""
        now = time.monotonic()
        if used is not None and now >= used.measured + MEASURE_EVERY and used.lock.acquire(blocking=False):
            try:
                if not used.evicted:
                    used.measure()
            finally:
                used.lock.release()
        with self._lock:
            total = sum(p.nbytes for p in self._plans.values()) + room
            items = list(self._plans.items())
            for k, (pid, p) in enumerate(items):
                over_share = p.nbytes > self.share
                if total <= self.memory_cap and len(self._plans) <= self.size and not over_share:
                    continue
                # first the per-state caches (its runs go on without a rebuild)
                before = self._try(p, p.engine.clear_state_caches) if over_share else None
                if before is not None:
                    total += p.nbytes - before
                    if p.nbytes <= self.share and total <= self.memory_cap:
                        continue
                if k == len(items) - 1 and not room:
                    break       # the plan used last: its cell's next look would rebuild it (its engine shrinks itself)
                if self._evict(pid, p):
                    total -= p.nbytes
        if self._tell():
            gc.collect()        # an engine's counters hold closures over themselves: freed by the collector only
            trim()
        self.hold_resident()

    def hold_resident(self) -> None:
        """Keep what this process holds beyond its footprint at start (:attr:`baseline`) under the cap,
        with a margin.  The accounted bytes are sampled estimates and freed memory is not all given
        back, so the resident memory itself is read (O(1)).  Past :data:`HIGH_WATER` of the cap, every
        plan not in use loses all but the newest :data:`SHRINK_KEEP` of its memos (largest plans first;
        its runs go on) and the freed pages go back to the system.  Only if the process is then still
        over the cap itself are least recently used plans evicted, never the most recently used one
        (the cell at work would rebuild it inside its next look).  Memory freed inside the process is
        reused before the process grows again, so after acting it waits until the resident memory has
        grown by :data:`REARM` of the cap beyond what it was, or reached the cap (no cascade of shrinks
        and evictions that free nothing the system sees).  Never a plan whose lock is held (inside a decision)."""
        held = self._held()
        cap = self.memory_cap
        if held is None or held <= max(HIGH_WATER * cap, min(self._floor + REARM * cap, cap)):
            return
        acted = False
        for p in sorted(self.loaded(), key=lambda p: -p.nbytes):
            if self._try(p, lambda: p.engine.shrink(SHRINK_KEEP, Deadline.after(SHRINK_SECONDS))) is not None:
                self.shrinks += 1
                acted = True
        trim()
        for p in self.loaded()[:-1]:
            if (self._held() or 0) <= cap:
                break
            with self._lock:
                gone = self._plans.get(p.id) is p and self._evict(p.id, p)
            if gone:
                acted = True
                self._tell()
                gc.collect()        # an engine's counters hold closures over themselves: freed by the collector only
                trim()
        if acted:                   # (all in use: the next request between decisions tries again)
            self._floor = self._held() or 0

    def _held(self) -> int | None:
        """Resident bytes beyond the footprint at start (None where they cannot be read)."""
        rss = self.resident()
        return None if rss is None else rss - self.baseline

    @staticmethod
    def _try(p: LoadedPlan, work) -> int | None:
        """Do ``work`` on a plan not in use and measure it again: its bytes before (None: its lock is
        held, or it is evicted)."""
        if not p.lock.acquire(blocking=False):
            return None
        try:
            if p.evicted:
                return None
            before = p.nbytes
            work()
            p.measure()
            return before
        finally:
            p.lock.release()

    def _evict(self, pid: str, p: LoadedPlan) -> bool:
        """Drop a plan not in use (caller holds ``_lock``); False if its lock is held."""
        if not p.lock.acquire(blocking=False):
            return False            # inside a decision (or a warm-up slice): next time
        try:
            del self._plans[pid]
            p.evicted = True
            p._stop.set()
        finally:
            p.lock.release()
        self.evictions += 1
        self._evicted.append(pid)
        return True

    def _tell(self) -> int:
        """Tell ``on_evict`` of the plans evicted since the last call; how many there were."""
        with self._lock:
            evicted, self._evicted = self._evicted, []
        for pid in evicted:
            for tell in self.on_evict:
                tell(pid)
        return len(evicted)

    def close(self) -> None:
        """Stop every warm-up (the service is shutting down)."""
        for p in self.loaded():
            p._stop.set()

    def loaded(self) -> list[LoadedPlan]:
        """The plans loaded now, least recently used first."""
        with self._lock:
            return list(self._plans.values())

    def exists(self, pid: str) -> bool:
        with self.store.read() as c:
            return c.execute(select(plans.c.id).where(plans.c.id == pid)).first() is not None
