"""The JSON shapes of the service: runs, trace rows (the paper's Table 1 layout), counts.

Every shape is built from the library's own ``to_dict()`` methods
(:class:`~opportune.sequencer.State`, :class:`~opportune.sequencer.Row`,
:class:`~opportune.policies.base.Decision`) plus what a remote client needs
and cannot compute: the admissible completions left, the parts installable
now, progress.  Big integers are decimal strings (JSON numbers lose digits), rounded past 4,300 digits.
"""

from __future__ import annotations

import datetime as dt
import threading
import time
from functools import lru_cache

from opportune.engine import Schedule
from opportune.engine.deadline import BudgetExceeded
from opportune.engine.schedule import EXACT_DIGITS, count_text, log10_int
from opportune.planning.costs import TimeModel
from opportune.policies.printable import count_label, printable_decision
from opportune.sequencer import Row


def iso(t: float | None) -> str | None:
    return None if t is None else dt.datetime.fromtimestamp(t, dt.timezone.utc).isoformat(timespec="milliseconds")


_counting = threading.local()


def counting_seconds(reset: bool = False) -> float:
    """Seconds this thread has spent in the answers' counts (:func:`count_view`, :func:`installable`)
    since the last reset: a look's counts take what its decision leaves, so the service leaves them
    out of what it reserves after a decision."""
    spent = getattr(_counting, "seconds", 0.0)
    if reset:
        _counting.seconds = 0.0
    return spent


def _counted(start: float) -> None:
    _counting.seconds = getattr(_counting, "seconds", 0.0) + time.perf_counter() - start


def count_view(schedule: Schedule) -> dict | None:
    """Admissible completions left: ``{"value": "336", "log10": 2.53, "text": "336"}``, or None when over the
    counting budget.  ``text`` is the count as people read it (:func:`~opportune.policies.printable.count_label`),
    what the dashboard shows."""
    start = time.perf_counter()
    try:
        n = schedule.count_result(estimate=False).value     # within the look's deadline on the engine
    except BudgetExceeded:
        return None
    finally:
        _counted(start)
    return dict(_count_text(n))


@lru_cache(maxsize=256)
def _count_text(n: int) -> tuple:
    """A count's decimal text, log10 and text for people, computed once per value: a run's answers repeat
    the same few counts.  Past :data:`~opportune.engine.schedule.EXACT_DIGITS` digits the decimal text is
    rounded (the exact text of a count of 10,000 free parts, 35,660 digits, takes 20 ms: too long for a
    look's answer)."""
    return (("value", count_text(n)), ("log10", round(log10_int(n), 6) if n > 0 else None),
            ("text", count_label(n)))


def installable(schedule: Schedule) -> list[str] | None:
    """Parts that can go in now, or None when counting them is over budget."""
    start = time.perf_counter()
    try:
        return list(schedule.installable())
    except BudgetExceeded:
        return None
    finally:
        _counted(start)


def decision_view(decision) -> dict:
    """A decision's JSON: its counts as decimal text (rounded past 4,300 digits), and ``explain``, the
    reasons in words with counts written for people (``6.13e98``: :func:`count_label`)."""
    return printable_decision(decision, EXACT_DIGITS).to_dict() | {"explain": decision.explain(count=count_label)}


def row_view(row: Row, n: int, engine, schedule: Schedule | None = None) -> dict:
    """Trace row ``n`` (1-based): Visible | Buffered | Installed | Action, the outcome, the reasons.

    ``count`` is the number of admissible completions *before* the action,
    which the dashboard plots falling as the run proceeds.  ``schedule``: the run's current
    schedule, used when the row was made at it (the pending row: no rebuilding it part by part).
    """
    d = row.to_dict()
    d["n"] = n
    d["action_text"] = "" if row.action.kind == "done" else str(row.action)
    at = schedule if schedule is not None and schedule.installed is row.installed else Schedule(engine, row.installed)
    d["count"] = count_view(at)
    d["reasons"] = decision_view(row.decision)
    return d


def run_summary(r) -> dict:
    """A run as listed (from its ``runs`` table row, without rebuilding its sequencer)."""
    return {
        "id": r["id"], "cell": r["cell"], "label": r["label"],
        "plan": {"id": r["plan_id"], "name": r.get("plan_name")},
        "status": r["status"], "policy": r["policy"], "buffer_capacity": r["buffer_capacity"],
        "products": r.get("products") or 1,
        "progress": {"installed": r["installed"], "units": r["units"]},
        "count": r["count"], "count_text": None if r["count"] is None else count_label(r["count"]),
        "pending": r["pending"], "seq": r["seq"],
        "created_at": iso(r["created_at"]), "updated_at": iso(r["updated_at"]),
    }


def run_complete(seq) -> bool:
    """A run is complete once its last part is installed (the outcome of the last install, with
    nothing pending), or once it answered ``done`` (runs of earlier versions ended so)."""
    return seq.finished or (seq.pending is None and seq.state.is_complete)


def run_totals(seq, plan) -> dict:
    """What a run took, from its trace: the paper's accounting, as ``simulate`` counts a trial (a motion
    per install or buffer move, a shake, a look at the plan's ``simulation.costs``), with the actions
    that failed and the defects besides.  O(rows).

    Parameters
    ----------
    seq : Sequencer
        The run's sequencer (its trace: each row a look, the action decided and its outcome).
    plan : Plan
        The run's plan (its costs).

    Returns
    -------
    dict
        ``installed``, ``looks``, ``motions``, ``buffer_moves``, ``buffer_peak``, ``shakes``, ``failed``,
        ``defects`` and ``time``.

    Examples
    --------
    >>> from opportune import load_plan
    >>> from opportune.sequencer import Sequencer
    >>> seq = Sequencer(load_plan("example:gearbox"))
    >>> for look in (["rl", "ra"], ["ca"]):     # buffer rl, install ca
    ...     _ = seq.decide(look); _ = seq.report("success")
    >>> run_totals(seq, seq.state.plan)
    {'installed': 1, 'looks': 2, 'motions': 2, 'buffer_moves': 1, 'buffer_peak': 1, 'shakes': 0, 'failed': 0, \
'defects': 0, 'time': 2.0}
    """
    costs = TimeModel.from_plan(plan)
    looks = motions = buffer_moves = shakes = failed = 0
    peak, time_ = 0, 0.0
    for row in seq.trace:
        kind = row.action.kind
        peak = max(peak, len(row.buffered))
        if kind == "done":        # runs of earlier versions ended with a look answered "done"
            continue
        looks += 1
        if kind == "shake":
            shakes += 1
            time_ += costs.shake
            continue
        part = row.action.part    # several products: KIND@FIXTURE, costed as its kind
        motions += 1
        buffer_moves += kind == "buffer"
        failed += str(row.outcome).startswith("failed")
        time_ += costs.move(part if part in costs.parts else part.rsplit("@", 1)[0])
    state = seq.state
    peak = max(peak, len(state.buffer))
    return {"installed": len(state.installed), "looks": looks, "motions": motions, "buffer_moves": buffer_moves,
            "buffer_peak": peak, "shakes": shakes, "failed": failed, "defects": state.defects,
            "time": time_ + looks * costs.look}


def run_view(live, loaded, updated_at: float) -> dict:
    """A run's full state from its live sequencer."""
    seq = live.sequencer
    state = seq.state
    pending = seq.pending
    last = pending or (seq.trace[-1] if seq.trace else None)
    return {
        "id": live.id, "cell": live.cell, "label": live.label,
        "plan": {"id": loaded.id, "name": loaded.plan.name},
        "status": "complete" if run_complete(seq) else "active",
        "policy": live.policy, "buffer_capacity": state.capacity, "products": getattr(live, "products", 1),
        "seq": live.applied,
        "state": state.to_dict(),
        "installable": installable(state.schedule),
        "progress": {"installed": len(state.installed), "units": loaded.engine.n_units},
        "count": count_view(state.schedule),
        "pending": row_view(pending, len(seq.trace) + 1, loaded.engine, state.schedule) if pending else None,
        "last_look": list(last.visible) if last else [],
        "rows": len(seq.trace) + (1 if pending else 0),
        "finished": run_complete(seq),
        "totals": run_totals(seq, loaded.plan) if run_complete(seq) else None,
        "created_at": iso(live.created_at), "updated_at": iso(updated_at),
    }


def trace_view(live, loaded) -> list[dict]:
    """Every row so far (pending one last, with ``outcome: null``)."""
    seq = live.sequencer
    rows = [row_view(r, i, loaded.engine) for i, r in enumerate(seq.trace, start=1)]
    if seq.pending is not None:
        rows.append(row_view(seq.pending, len(rows) + 1, loaded.engine))
    return rows
