"""Runs: one plan being assembled in one cell, driven through the library's :class:`~opportune.sequencer.Sequencer`.

Event sourcing.  A run's state is *not* stored; its event log is — every
look (with the decision sent back), every outcome report, every cancel.  A
run's sequencer is rebuilt by replaying the log through a fresh
``Sequencer`` (the policy is deterministic), so the service runs exactly the
library's code, and a restart — even after ``kill -9`` — resumes every run
where its last committed event left it.  Replay checks each decision against
the recorded one and refuses to go on if they differ (a changed policy must
not silently re-interpret a robot's history).

A command (look, outcome, cancel) on a run:

1. takes the run's lock (requests on one run are serialised; different runs
   proceed in parallel, sharing only the plan's engine lock while counting);
2. answers a retried ``Idempotency-Key`` from the stored answer;
3. brings the live sequencer up to the run's committed event count, replaying
   the tail of the log that other server processes wrote since this one last
   saw the run;
4. applies the command to the live sequencer — a refused command raises
   before anything changes;
5. commits, in one transaction: the event with its answer, the run's summary
   (guarded by the run's event count: another process that wrote first makes
   this one rebuild and retry), and the idempotency record;
6. only then answers, and wakes the run's event streams (on PostgreSQL, those
   of the other processes too).

If the commit fails the live sequencer is dropped and rebuilt from the log
next time, so memory never runs ahead of the database.

Several processes (``opportune serve --workers N`` on PostgreSQL).  Each has
its own live sequencers; the database is the only shared state.  Step 3 makes
a request correct whichever process the previous one landed on, reads replay
the tail the same way, and step 5's guard serialises commands on one run
across processes optimistically: nothing is locked while deciding, and of two
processes deciding on the same run at once, the second to commit finds the
count moved, rebuilds from the log and tries again (up to ``ATTEMPTS`` times,
then 409 ``run_busy``, which a retry with the same key settles).  A process
that replays a decision another process took exactly, but can only estimate it
within its own decision budget (its counting memo is colder), decides it again
exactly rather than calling an estimate that differs a mismatch.
"""

from __future__ import annotations

import json
import random
import threading
import time
from collections import OrderedDict
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from typing import Callable

from sqlalchemy import bindparam, case, func, insert, select, update
from sqlalchemy.exc import IntegrityError

from opportune.engine.deadline import BudgetExceeded
from opportune.policies.base import Action, Decision, collector_paused
from opportune.policies.named import DEFAULT_POLICY, current_name, deprecation_note, make_policy
from opportune.sequencer import LookError, OutcomeError, Sequencer
from opportune.service import idempotency as idem
from opportune.service.auth import Principal
from opportune.service.errors import ApiError, forbidden, run_not_found
from opportune.service.latency import Reserves, decision_budget
from opportune.service.plans import LoadedPlan, PlanBook
from opportune.service.storage import Store, cells, dumps, events, now, plans, runs
from opportune.service.views import (count_view, counting_seconds, decision_view, row_view, run_complete, run_summary,
                                     run_view, trace_view)

# Statements of the hot path, built once (each request only binds values).
FORGET_EVERY = 60.0  # seconds between clean-ups of stored idempotent answers past their time
ATTEMPTS = 5         # tries of a command that another process's commit on the same run overtook

_RUN_ROW = (select(runs, plans.c.name.label("plan_name")).join(plans, plans.c.id == runs.c.plan_id)
            .where(runs.c.id == bindparam("run_id")))
_ADVANCE = (update(runs).where(runs.c.id == bindparam("b_id"), runs.c.seq == bindparam("b_expected"))
            .values(seq=bindparam("b_seq"), status=bindparam("b_status"), installed=bindparam("b_installed"),
                    count=bindparam("b_count"), pending=bindparam("b_pending"), updated_at=bindparam("b_t")))
_INSERT_EVENT = insert(events)


def plan_too_large(why: str, *, retry: bool = False) -> ApiError:
    return ApiError(503 if retry else 422, "plan_too_large",
                    f"this plan's admissible sequences cannot be counted exactly within the engine's budget ({why})",
                    "retry: the counting done so far is kept" if retry else
                    "the opportunistic policy needs exact counts: split the plan or reduce its freedom", where="body.plan")


def ways_policy(asked: str | None) -> None:
    """Refuse (422) a run of a plan written as ways under a policy that does not take one yet, the
    service's default included, naming those that do (:data:`~opportune.formats.ways.WAYS_POLICIES`)."""
    from opportune.formats.ways import WAYS_POLICIES

    policy = current_name(asked or DEFAULT_POLICY, warn=False)
    if policy not in WAYS_POLICIES:
        which = f"policy '{policy}'" if asked else f"the default policy '{policy}'"
        raise ApiError(422, "policy_not_for_ways", f"{which} does not take a plan written as ways yet",
                       f"choose a policy that does: {', '.join(WAYS_POLICIES)}", where="body.policy")


class ReplayMismatch(Exception):
    pass


class _Stale(Exception):
    """Another writer advanced the run since this process last read it."""


@dataclass
class LiveRun:
    """A run with its sequencer in memory, in step with the first ``applied`` events of its log."""

    id: int
    cell: str
    plan_id: str
    label: str
    capacity: int | None
    created_at: float
    policy: str = "paper"             # its name (policies/named.py); runs from before policies were chosen: the paper's
    products: int = 1                 # fixtures fed from one bin (its plan is then the joint plan: opportune.planning.products)
    lock: threading.RLock = field(default_factory=threading.RLock)
    sequencer: Sequencer | None = None
    applied: int = 0


def apply(sequencer: Sequencer, kind: str, request: dict):
    """Apply one command of the event log to a sequencer (the same calls the library's users make)."""
    if kind == "look":
        return sequencer.decide(request["visible"])
    if kind == "outcome":
        return sequencer.report(request["outcome"], keep=request.get("keep", "bin"))
    if kind == "cancel":
        return sequencer.cancel()
    raise ValueError(f"unknown event kind {kind!r}")


READ_COUNT_SECONDS = 0.25  # with a decision budget: most time a read spends counting (counts that miss it are null)
START_WARM_UP = 1.0        # with a decision budget: seconds the first run of a plan spends warming it up at its start
START_COUNT_SECONDS = 0.5  # with a decision budget: most time a run's start spends on its answer's counts


class RunManager:
    """Creates runs, applies commands to them, and answers questions about them."""

    def __init__(self, store: Store, book: PlanBook, *, size: int = 512, notify: Callable[[int], None] = lambda _: None,
                 keep_answers: float = idem.KEEP_SECONDS, budget: float | None = None, warm_up: float | None = 10.0,
                 optimum: float | None = 600.0):
        self.store = store
        self.budget = budget        # seconds per decision (None: exact decisions)
        # what a look of each plan needs after its decision (learned): the decision gets the rest
        self.reserves = Reserves(budget) if budget is not None else None
        self.warm_up = warm_up      # seconds the warm-up of a plan (its first state's count) may take, once per plan
        self.optimum = optimum      # seconds the preparation of a look-ahead's optimum may take, once per plan and setting
        self.book = book
        self.size = size
        self.notify = notify
        self._watchers: list[Callable[[int], None]] = []   # more than the streams: e.g. the OPC UA server
        self.keep_answers = keep_answers  # seconds a stored idempotent answer is kept
        self._next_forget = 0.0           # monotonic time of the next clean-up of old answers
        self._live: OrderedDict[int, LiveRun] = OrderedDict()
        self._mutex = threading.Lock()
        self._last_used: dict[int, LoadedPlan] = {}   # per thread: the plan its current request used
        # PostgreSQL: wake this process's streams when another process commits (None on SQLite).
        self.listener = store.listen(self._changed)
        book.on_evict.append(self._plan_evicted)

    def watch(self, callback: Callable[[int], None]) -> None:
        """Call ``callback(run_id)`` after every committed change of a run (this process's, and on PostgreSQL
        the other processes'), besides ``notify``; from the thread that committed: it must return at once."""
        self._watchers.append(callback)

    def _changed(self, run_id: int) -> None:
        self.notify(run_id)
        for callback in self._watchers:
            callback(run_id)

    def _plan_evicted(self, pid: str) -> None:
        """The book evicted a plan's engine: drop the live sequencers on it (those not in use now; the
        others are rebuilt by :meth:`_sync`, which finds their engine is not the plan's any more), so
        that its memory goes.  Each is rebuilt from its run's log on its next request."""
        with self._mutex:
            on_plan = [live for live in self._live.values() if live.plan_id == pid]
        for live in on_plan:
            if live.lock.acquire(blocking=False):
                try:
                    self._forget(live)
                finally:
                    live.lock.release()

    def _remember(self, c, scope: str, key: str, h: str, status: int, text: str,
                  event: tuple[int, int] | None = None) -> None:
        """Store an answer (or where its event holds it); at most once a minute, in the same transaction,
        forget those past their time."""
        idem.remember(c, scope, key, h, status, text, event)
        clock = time.monotonic()
        if clock >= self._next_forget:
            self._next_forget = clock + FORGET_EVERY
            idem.forget_before(c, now() - self.keep_answers)

    # ------------------------------------------------------------ access

    def row(self, principal: Principal, run_id: int, *, key: tuple[str, str, str] | None = None):
        """The run's table row, if this principal may see it; else 404 (never saying whose it is).

        With ``key=(scope, key, request hash)``, also the stored answer of that idempotency key
        (read on the same connection): ``(row, stored or None)``.
        """
        with self.store.read() as c:
            r = c.execute(_RUN_ROW, {"run_id": run_id}).mappings().first()
            if r is None or not principal.can_see(r["cell"]):
                raise run_not_found(run_id)
            stored = idem.lookup(c, *key) if key else None
        return (dict(r), stored) if key else dict(r)

    def _live_for(self, r: dict) -> LiveRun:
        with self._mutex:
            live = self._live.get(r["id"])
            if live is None:
                live = LiveRun(r["id"], r["cell"], r["plan_id"], r["label"], r["buffer_capacity"], r["created_at"],
                               current_name(r["policy"], warn=False), r.get("products") or 1)
                self._live[r["id"]] = live
            self._live.move_to_end(r["id"])
            if len(self._live) > self.size:
                for rid in list(self._live)[: len(self._live) - self.size]:
                    old = self._live[rid]
                    if old.lock.acquire(blocking=False):  # never drop a run in use
                        try:
                            del self._live[rid]
                        finally:
                            old.lock.release()
        return live

    def _sync(self, live: LiveRun, loaded: LoadedPlan, seq_in_db: int) -> None:
        """Bring the live sequencer up to the database's event log (replaying what it lacks). Caller holds live.lock."""
        if live.sequencer is not None and live.sequencer.engine is not loaded.engine:
            self._forget(live)      # its plan was evicted and loaded again: rebuilt on the plan's new engine
        # ``applied`` only grows after a commit, so a live run ahead of ``seq_in_db`` is newer than that read.
        if live.sequencer is not None and live.applied >= seq_in_db:
            return
        start = live.applied if live.sequencer is not None else 0
        with self.store.read() as c:
            rows = c.execute(select(events.c.seq, events.c.kind, events.c.request, events.c.response)
                             .where(events.c.run_id == live.id, events.c.seq > start)
                             .order_by(events.c.seq)).all()
        self._replay(live, loaded, rows)

    def _replay(self, live: LiveRun, loaded: LoadedPlan, rows) -> None:
        with loaded.lock:
            if live.sequencer is None:
                live.sequencer = self._sequencer(loaded, live.capacity, live.policy, live.products)
                live.applied = 0
            try:
                for ev in rows:
                    request = json.loads(ev.request)
                    recorded = json.loads(ev.response).get("decision", {}) if ev.kind == "look" else {}
                    if recorded.get("exact") is False or (ev.kind == "look" and self._decided_by_time(live)):
                        # An estimated decision depends on time and chance, a budgeted look-ahead's on what it
                        # had prepared by then (its window, or its optimum once ready): replay it as it was taken.
                        taken = Decision.recorded(recorded)
                        live.sequencer.replay(request["visible"], replace(taken, exact=recorded.get("exact", True)))
                        live.applied = ev.seq
                        continue
                    result = apply(live.sequencer, ev.kind, request)
                    if ev.kind == "look":
                        recorded = json.loads(ev.response)["action"]
                        if result.action.to_dict() != recorded:
                            if result.exact or live.sequencer.pending is None:
                                raise ReplayMismatch(f"event {ev.seq}: this version decides {result.action}, "
                                                     f"the run recorded {recorded}")
                            # Out of budget here, where the recording process counted exactly.
                            live.sequencer.cancel()
                            self._decide_exactly(live, loaded, request["visible"], recorded, ev.seq)
                    live.applied = ev.seq
            except (ReplayMismatch, LookError, OutcomeError) as exc:
                live.sequencer, live.applied = None, 0
                raise ApiError(500, "run_replay_mismatch",
                               f"run {live.id} cannot be resumed by this version of opportune: {exc}",
                               "finish the run with the version that started it, or start a new run") from None

    def _decided_by_time(self, live: LiveRun) -> bool:
        """Whether the run's looks were decided by what its policy had prepared by then: a look-ahead within a
        decision budget, whose frontier window decides until its optimum, prepared in the background, is
        ready (and whose window is cut by the look's deadline).  O(1)."""
        return self.budget is not None and getattr(live.sequencer.policy, "prepare", None) is not None

    def _decide_exactly(self, live: LiveRun, loaded: LoadedPlan, visible: list, recorded: dict, seq: int) -> None:
        """Replay a decision recorded as exact that this process could only estimate within its budget.

        Decided again with exact counts and no time limit but the engine's own (so the trace row
        has the same reasons as in the process that took it), and compared; if even the engine's
        limit is not enough, the recorded action is taken as it was (the log is the truth).
        """
        sequencer = live.sequencer
        budgeted, sequencer.policy = sequencer.policy, self._policy(loaded, live.capacity, live.policy, budget=None)
        try:
            decision = sequencer.decide(visible)
        except BudgetExceeded:
            sequencer.replay(visible, Action.from_dict(recorded))
            return
        finally:
            sequencer.policy = budgeted
        if decision.action.to_dict() != recorded:
            raise ReplayMismatch(f"event {seq}: this version decides {decision.action}, the run recorded {recorded}")

    def _sequencer(self, loaded: LoadedPlan, capacity: int | None, policy: str, products: int = 1) -> Sequencer:
        """A new sequencer of the run's policy on the plan's shared engine; for several products, a
        :class:`~opportune.multi.MultiSequencer` on the joint plan (looks of part kinds).  Its first state
        is counted by the plan's warm-up (:meth:`PlanBook.warm`, once per plan), not here: a run's start
        does bounded work."""
        make = Sequencer
        if products > 1:
            from opportune.multi import MultiSequencer as make
        return make(loaded.engine, self._policy(loaded, capacity, policy, budget=self.budget),
                    buffer_capacity=capacity, budget=self.budget, warm_up=0)

    def _joint_plan(self, base: LoadedPlan, products: int, cell: str) -> LoadedPlan:
        """The stored joint plan of ``products`` copies of a stored plan (stored now if new, owned by ``cell``)."""
        from types import SimpleNamespace

        from opportune.engine.schedule import MAX_STRATEGIES_EXACT
        from opportune.planning.products import ProductsError, several_products
        from opportune.service.plans import store_plan

        try:
            joint = several_products(base.plan, products)
            if self.budget is None and len(joint.strategies) > MAX_STRATEGIES_EXACT:
                raise ProductsError(f"{products} products give {len(joint.strategies)} combinations of the plan's "
                                    f"strategies, and exact decisions count a union of at most "
                                    f"{MAX_STRATEGIES_EXACT} strategies")
        except ProductsError as exc:
            raise ApiError(422, "invalid_request", str(exc), "use fewer products", where="body.products") from None
        pid, _ = store_plan(self.store, SimpleNamespace(plan=joint), "json", dumps(joint.to_dict()), cell)
        return self.book.get(pid)

    @staticmethod
    def _policy(loaded: LoadedPlan, capacity: int | None, name: str, *, budget: float | None):
        """The run's policy object: the look-ahead scores its actions in the plan's own bin model."""
        sim = loaded.plan.simulation
        return make_policy(name, budget=budget, visible=sim.get("visible", 2), capacity=capacity)

    def _loaded(self, live: LiveRun) -> LoadedPlan:
        return self.book.get(live.plan_id)

    def _forget(self, live: LiveRun) -> None:
        live.sequencer, live.applied = None, 0

    # ------------------------------------------------------------ creating runs

    def create(self, principal: Principal, body: dict, key: str, path: str) -> tuple[int, str, bool]:
        """Start a run of a stored plan in the principal's cell; return ``(status, answer JSON text, replayed)``.

        Bounded work: the plan's engine, memos and warm-up are the plan's, built once per process (the
        first run warms the plan up for at most ``START_WARM_UP`` seconds, the rest goes on in the
        background), and the answer's counts take at most ``START_COUNT_SECONDS``."""
        with self.book.busy():
            return self._create(principal, body, key, path)

    def _create(self, principal: Principal, body: dict, key: str, path: str) -> tuple[int, str, bool]:
        if principal.is_operator:
            raise forbidden("an operator token reads runs; only a cell's token can start one",
                            "use the token of the cell that will assemble the plan")
        cell = body.get("cell") or principal.cell
        if cell != principal.cell:
            raise forbidden(f"this token drives cell {principal.cell!r} only", "omit `cell` or use that cell's token")
        h = idem.request_hash("POST", path, body)
        with self.store.read() as c:
            stored = idem.lookup(c, principal.scope, key, h)
        if stored:
            return stored.status, stored.text, True
        from opportune.service.plans import accept_checked, is_shipped_name, may_see, shipped_plan

        if is_shipped_name(body["plan"]):   # a shipped plan by name: stored for this cell, then run by its id
            body = {**body, "plan": accept_checked(self.store, self.book, principal,
                                                   *shipped_plan(body["plan"], "body.plan"))[1]["id"]}
        if not may_see(self.store, principal, body["plan"]):    # another cell's plan is not known here either
            raise ApiError(422, "unknown_plan", f"no plan {body['plan']!r} for cell {principal.cell!r}",
                           "upload it first with POST /plans (with this cell's token) and use the `id` it returns",
                           where="body.plan")
        loaded = self.book.get(body["plan"])
        products = body.get("products") or 1
        if products > 1:   # several products at once: a run of the joint plan, fed from one bin
            loaded = self._joint_plan(loaded, products, principal.cell)
        if loaded.too_large:
            raise plan_too_large(loaded.too_large)
        if loaded.plan.is_ways:
            ways_policy(body.get("policy"))
        if self.budget is not None:
            # Once per plan: the first run counts its first state for up to START_WARM_UP seconds here (small
            # plans finish), the rest goes on in the background; later runs find it done or under way.
            self.book.warm(loaded, self.warm_up, foreground=START_WARM_UP)
        # With a decision budget, the answer's counts: those the warm-up found (from the memos), or, once it has
        # finished, at most START_COUNT_SECONDS of counting (a run of a plan whose first state is not counted yet
        # starts at once, its count null).
        until = (time.perf_counter() + (START_COUNT_SECONDS if loaded.warm == "done" else 0.0)
                 if self.budget is not None else None)
        with loaded.lock, loaded.engine.deadline(until):
            asked = body.get("policy") or DEFAULT_POLICY
            policy = current_name(asked, warn=False)   # a former name runs its policy, under the name now
            sequencer = self._sequencer(loaded, body.get("buffer_capacity"), policy, products)
            if self.budget is None:
                try:  # the policy needs exact counts: find out now, not at the robot's first look
                    sequencer.state.schedule.options()
                except BudgetExceeded as exc:
                    if exc.reason == "memo":
                        loaded.too_large = str(exc)
                    raise plan_too_large(str(exc), retry=exc.reason != "memo") from None
            count = count_view(sequencer.state.schedule)
        t = now()
        try:
            with self.store.write() as c:
                stored = idem.lookup(c, principal.scope, key, h)
                if stored:
                    return stored.status, stored.text, True
                run_id = c.execute(insert(runs).values(
                    cell=cell, plan_id=loaded.id, policy=policy, products=products if products > 1 else None,
                    buffer_capacity=body.get("buffer_capacity"), label=body.get("label") or "", status="active", seq=0,
                    installed=0, units=loaded.plan.n_units, count=count["value"] if count else None, pending=None,
                    created_at=t, updated_at=t)).inserted_primary_key[0]
                live = LiveRun(run_id, cell, loaded.id, body.get("label") or "", body.get("buffer_capacity"), t,
                               policy, products, sequencer=sequencer)
                with loaded.lock, loaded.engine.deadline(until):   # the same bound as the count above
                    answer = run_view(live, loaded, t)
                if asked != policy:
                    answer["note"] = deprecation_note(asked)
                text = dumps(answer)
                self._remember(c, principal.scope, key, h, 201, text)
        except IntegrityError:  # the same key, concurrently, in another process
            with self.store.read() as c:
                stored = idem.lookup(c, principal.scope, key, h)
            if stored:
                return stored.status, stored.text, True
            raise
        with self._mutex:
            self._live[run_id] = live
        self._changed(run_id)
        self.book.settle(loaded)
        setting = (policy, body.get("buffer_capacity"))
        if self.budget is not None and products == 1 and setting not in loaded.optima:
            # the look-ahead's optimum as per-plan work, in the background: its runs' decisions take it up once
            # it is ready (their frontier window decides meanwhile); asked once per setting, not at every run
            self.book.prepare(loaded, self._policy(loaded, setting[1], policy, budget=None), setting, self.optimum)
        return 201, text, False

    # ------------------------------------------------------------ commands

    def command(self, principal: Principal, run_id: int, kind: str, request: dict, key: str, path: str,
                arrived: float | None = None) -> tuple[int, str, bool]:
        """Apply a look, outcome or cancel; return ``(status, answer JSON text, replayed)``.  ``arrived``:
        when the request arrived (``time.perf_counter()``), where a look's budget starts (default: now)."""
        if principal.is_operator:
            self.row(principal, run_id)  # 404 first: an operator learns nothing new from a 403 on a real run
            raise forbidden("an operator token reads runs; only the run's cell drives it",
                            "use the token of the cell the run belongs to")
        if arrived is None:   # the look's one deadline starts here: its budget covers the whole request
            arrived = time.perf_counter()
        h = idem.request_hash("POST", path, request)
        try:
            # A look, answer and commit included, runs with the cyclic collector paused (not only its decision):
            # a full collection walks a large plan's memos (100+ ms) and would otherwise land in the answer's
            # serialisation; paused, it runs after the look, while the robot acts.
            with self.book.busy(), collector_paused() if kind == "look" and self.budget is not None else nullcontext():
                return self._command(principal, run_id, kind, request, key, path, h, arrived)
        finally:
            used = self._last_used.pop(threading.get_ident(), None)
            # Measuring a plan (up to ~20 ms on a large one) and evicting are for the outcome that follows
            # every look's action, not for the look: its answer waits for nothing but its own work.
            if kind != "look":
                self.book.settle(used)

    def answer_sent(self, returned: float):
        """A callback for the moment a look's answer has been sent, given the moment it was returned
        (``time.perf_counter()``): the seconds between are kept in reserve for later looks."""
        reserves = self.reserves
        if reserves is None:
            return None
        return lambda sent: reserves.measured_outside(sent - returned)

    def _command(self, principal, run_id, kind, request, key, path, h, arrived=None):
        for attempt in range(ATTEMPTS):
            if attempt:  # another process committed on this run meanwhile: let it finish, then rebuild
                time.sleep(random.uniform(0, 0.005 * 2 ** attempt))
            r, stored = self.row(principal, run_id, key=(principal.scope, key, h))
            if stored:
                return stored.status, stored.text, True
            live = self._live_for(r)
            with live.lock:
                if r["seq"] != live.applied and live.sequencer is not None:
                    # Changed since the row was read (a request on this run just finished): read again.
                    r, stored = self.row(principal, run_id, key=(principal.scope, key, h))
                    if stored:
                        return stored.status, stored.text, True
                loaded = self._loaded(live)
                self._sync(live, loaded, r["seq"])
                try:
                    return self._command_locked(principal, live, loaded, kind, request, key, h, arrived)
                except _Stale:
                    self._forget(live)
                    continue
                finally:
                    self._last_used[threading.get_ident()] = loaded
        raise ApiError(409, "run_busy", f"run {run_id} is being changed by another server process",
                       "retry the request with the same Idempotency-Key")

    def _command_locked(self, principal, live: LiveRun, loaded: LoadedPlan, kind, request, key, h, arrived=None):
        seq = live.sequencer
        expected = live.applied
        marks: dict[str, float] = {}
        try:
            # With a decision budget, one deadline for the request, one budget after it arrived: the decision
            # gets what is left after the reserve the rest of a look of this plan has recently needed, the
            # answer's counts what is left after the reserve for building, storing and sending the answer (memo
            # hits cost nothing; a count that misses it is null).  The decision's counts stop by twice the
            # budget at most (the policy keeps to its budget; this is the safety net).
            start = time.perf_counter() if arrived is None else arrived
            until = start + 2 * self.budget if self.budget is not None else None
            answer_until = None
            think = None
            if self.budget is not None:
                end = start + self.budget
                answer_until = end - self.reserves.after_counts(loaded.id)
                think = end - self.reserves.after_decision(loaded.id) - time.perf_counter()
            with loaded.lock, loaded.engine.deadline(until), decision_budget(seq.policy, think):
                answer = self._apply_checked(live, loaded, kind, request, answer_until, marks)  # a refusal changes nothing
        except ApiError:
            raise
        except BudgetExceeded as exc:
            self._forget(live)  # rebuilt from the log next time: memory never runs ahead of the database
            raise ApiError(503, "counting_budget_exceeded", f"the decision needs an exact count that is over budget: {exc}",
                           "retry the same request: the counting done so far is kept" if exc.reason == "time"
                           else "this plan is too large for exact counting; nothing was changed") from None
        except BaseException:
            self._forget(live)
            raise
        t = now()
        state = seq.state
        count = answer["run"]["count"]
        text = dumps(answer)  # serialised once: stored with the event, stored for retries, sent
        try:
            with self.store.write() as c:
                n = c.execute(_ADVANCE, {
                    "b_id": live.id, "b_expected": expected, "b_seq": expected + 1,
                    "b_status": "complete" if run_complete(seq) else "active", "b_installed": len(state.installed),
                    "b_count": count["value"] if count else None,
                    "b_pending": str(seq.pending.action) if seq.pending else None, "b_t": t}).rowcount
                if n != 1:
                    raise _Stale()
                c.execute(_INSERT_EVENT, {"run_id": live.id, "seq": expected + 1, "kind": kind, "request": dumps(request),
                                          "response": text, "created_at": t})
                # The key's primary key makes a concurrent use of the same key (another run, another
                # process) fail here: the transaction rolls back and the retry answers from the store.
                self._remember(c, principal.scope, key, h, 200, text, event=(live.id, expected + 1))
        except _Stale:
            raise
        except IntegrityError:
            self._forget(live)
            raise _Stale() from None
        except BaseException:
            self._forget(live)
            raise
        live.applied = expected + 1
        self.store.announce(live.id)  # the other processes' streams (PostgreSQL)
        self._changed(live.id)        # this process's
        if self.reserves is not None and "decided" in marks:
            done = time.perf_counter()
            # the answer's counts take what the decision leaves: not reserved for
            self.reserves.measured(loaded.id, after_decision=done - marks["decided"] - marks["counting"],
                                   after_counts=done - marks["counted"])
        return 200, text, False

    def _apply_checked(self, live: LiveRun, loaded: LoadedPlan, kind: str, request: dict,
                       answer_until: float | None = None, marks: dict | None = None) -> dict:
        """Apply the command to the live sequencer and build the answer (its counts by ``answer_until``, a
        ``time.perf_counter()`` value, if given); a refusal changes nothing.  For a look, ``marks`` gets
        the moments its decision (``decided``) and its answer's counts (``counted``) ended."""
        if answer_until is not None and kind != "look":
            with loaded.engine.deadline(answer_until):
                return self._apply_checked(live, loaded, kind, request)
        seq = live.sequencer
        n_next = live.applied + 1
        if kind == "look":
            plan = loaded.plan
            # several products: the bin holds part kinds (x), not the fixtures' units (x@2)
            known = list(seq.layout.units) if live.products > 1 else plan.part_ids
            for i, part in enumerate(request["visible"]):
                if part not in (seq.layout.units if live.products > 1 else plan):
                    from opportune.formats.problems import unknown_part_hint

                    raise ApiError(422, "unknown_part", f"unknown part {part!r} in the look",
                                   unknown_part_hint(part, known, "the plan's parts" if live.products == 1
                                                     else "the products' part kinds"), where=f"body.visible[{i}]")
            if run_complete(seq):    # its last part is installed: nothing more to look at
                raise ApiError(409, "run_complete", f"run {live.id} is complete: its last part is installed",
                               "start a new run (POST /runs) for the next assembly", where="path")
            code = "action_pending" if seq.pending is not None else "look_contradicts_state"
            hint = {"action_pending": "report the pending action's outcome (POST /runs/{id}/outcomes) or cancel it first",
                    "look_contradicts_state": "send only parts that can still be in the bin (see `state.in_bin` in GET /runs/{id})",
                    }[code]
            try:
                decision = apply(seq, kind, request)
                decided = time.perf_counter()
                counting_seconds(reset=True)
            except LookError as exc:
                raise ApiError(409, code, str(exc), hint.replace("{id}", str(live.id)), where="body.visible") from None
            row = seq.pending or seq.trace[-1]
            n_row = len(seq.trace) + (1 if seq.pending else 0)
            with loaded.engine.deadline(answer_until) if answer_until is not None else nullcontext():
                run = run_view(live, loaded, now())
                run["seq"] = n_next
                answer = {"run_id": live.id, "seq": n_next, "action": decision.action.to_dict(),
                          "decision": decision_view(decision),
                          "row": row_view(row, n_row, loaded.engine, seq.state.schedule), "run": run}
            if marks is not None:
                marks["decided"], marks["counted"], marks["counting"] = decided, time.perf_counter(), counting_seconds()
            if live.products > 1:   # which fixture an install goes to (the action's part is KIND@FIXTURE)
                from opportune.multi import split_action

                answer["part_kind"], answer["fixture"] = split_action(decision.action)
            return answer
        if kind == "outcome":
            pending = seq.pending
            try:
                apply(seq, kind, request)
            except OutcomeError as exc:
                code = "no_pending_action" if pending is None else "outcome_refused"
                hint = (f"send a look first (POST /runs/{live.id}/looks): an outcome reports the action it decided"
                        if pending is None else "report another outcome for this action, or cancel it")
                raise ApiError(409, code, str(exc), hint, where="body.outcome") from None
            run = run_view(live, loaded, now())
            run["seq"] = n_next
            return {"run_id": live.id, "seq": n_next, "outcome": request["outcome"], "keep": request.get("keep", "bin"),
                    "row": row_view(seq.trace[-1], len(seq.trace), loaded.engine), "run": run}
        if kind == "cancel":
            pending = seq.pending
            try:
                apply(seq, kind, request)
            except OutcomeError:
                raise ApiError(409, "no_pending_action", "no action is pending: nothing to cancel",
                               f"send a look first (POST /runs/{live.id}/looks)") from None
            run = run_view(live, loaded, now())
            run["seq"] = n_next
            return {"run_id": live.id, "seq": n_next,
                    "cancelled": row_view(pending, len(seq.trace) + 1, loaded.engine), "run": run}
        raise ValueError(kind)

    # ------------------------------------------------------------ questions

    def view(self, principal: Principal, run_id: int, *, with_trace: bool = False) -> dict:
        with self.book.busy():
            return self._view(principal, run_id, with_trace)

    def _view(self, principal: Principal, run_id: int, with_trace: bool) -> dict:
        r = self.row(principal, run_id)
        live = self._live_for(r)
        with live.lock:
            loaded = self._loaded(live)
            self._sync(live, loaded, r["seq"])
            # With a decision budget, a read's counts (one per trace row) share a bounded time too.
            until = time.perf_counter() + READ_COUNT_SECONDS if self.budget is not None else None
            with loaded.lock, loaded.engine.deadline(until):
                out = run_view(live, loaded, r["updated_at"])
                if with_trace:
                    out = {"run": out, "trace": trace_view(live, loaded)}
        self.book.settle(loaded)
        return out

    def trace(self, principal: Principal, run_id: int) -> dict:
        both = self.view(principal, run_id, with_trace=True)
        return {"run_id": run_id, "seq": both["run"]["seq"], "rows": both["trace"]}

    def graph(self, principal: Principal, run_id: int) -> list[dict]:
        r = self.row(principal, run_id)
        return self.book.get(r["plan_id"]).layouts

    def list(self, principal: Principal, *, cell: str | None = None, status: str | None = None,
             limit: int = 200, offset: int = 0) -> list[dict]:
        q = select(runs, plans.c.name.label("plan_name")).join(plans, plans.c.id == runs.c.plan_id)
        if not principal.is_operator:
            q = q.where(runs.c.cell == principal.cell)
        if cell:
            q = q.where(runs.c.cell == cell)
        if status:
            q = q.where(runs.c.status == status)
        q = q.order_by(runs.c.id.desc()).limit(limit).offset(offset)
        with self.store.read() as c:
            return [run_summary(dict(r)) for r in c.execute(q).mappings().all()]

    def cells(self, principal: Principal) -> list[dict]:
        q = (select(cells.c.name, func.count(runs.c.id).label("runs"),
                    func.coalesce(func.sum(case((runs.c.status == "active", 1), else_=0)), 0).label("active"))
             .select_from(cells.outerjoin(runs, runs.c.cell == cells.c.name)).group_by(cells.c.name).order_by(cells.c.name))
        if not principal.is_operator:
            q = q.where(cells.c.name == principal.cell)
        with self.store.read() as c:
            return [{"name": r.name, "runs": r.runs, "active": int(r.active or 0)} for r in c.execute(q).all()]

    def events_after(self, run_id: int, after: int, limit: int = 200) -> list[tuple[int, str, dict]]:
        """Committed events of a run after ``after`` (the caller has checked access)."""
        with self.store.read() as c:
            rows = c.execute(select(events.c.seq, events.c.kind, events.c.response)
                             .where(events.c.run_id == run_id, events.c.seq > after)
                             .order_by(events.c.seq).limit(limit)).all()
        return [(r.seq, r.kind, json.loads(r.response)) for r in rows]

    def last_event(self, run_id: int) -> tuple[int, str, dict] | None:
        """A run's last committed event ``(seq, kind, answer)``, or None if it has none (the caller has checked
        access).  One indexed read."""
        with self.store.read() as c:
            r = c.execute(select(events.c.seq, events.c.kind, events.c.response).where(events.c.run_id == run_id)
                          .order_by(events.c.seq.desc()).limit(1)).first()
        return None if r is None else (r.seq, r.kind, json.loads(r.response))
