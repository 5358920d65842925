"""One deadline per look: the decision gets what the rest of the request leaves of the budget.

A look request has one :class:`~opportune.engine.deadline.Deadline`, started when it arrives, one
decision budget later.  The work after the decision (the answer's counts, building and serialising
the answer, the database commit) takes time too; :class:`Reserves` learns it per plan from the last
looks (a high percentile of the measured seconds, bounded), and the decision's budget is what is
left of the request's after that reserve.  So the whole request fits the budget, give or take the
percentile's misses.

>>> r = Reserves(0.05)
>>> r.after_decision("p")             # nothing measured yet: the starting guess
0.015
>>> for s in (0.004, 0.005, 0.006):
...     r.measured("p", after_decision=s, after_counts=s / 2)
>>> r.after_decision("p")             # the largest of the recent ones (the 95th percentile of three)
0.006
"""

from __future__ import annotations

import threading
from collections import OrderedDict, deque
from contextlib import contextmanager

#: The reserve before anything is measured for a plan, as a share of the budget.
FIRST_GUESS = 0.3
#: The reserve is never more than this share of the budget: the decision keeps the rest.
MOST = 0.6
#: Nor less than this many seconds (the clock's and the scheduler's jitter).
LEAST = 0.002
#: Recent looks remembered per plan, and plans remembered (least recently used forgotten): bounded memory.
WINDOW = 40
PLANS = 256
#: The percentile of recent post-decision times kept in reserve.
PERCENTILE = 0.95


class Reserves:
    """Seconds to keep in reserve after a look's decision (and after its answer's counts), per plan,
    plus the seconds an answer takes to leave the server once returned (the same for every plan).

    O(WINDOW log WINDOW) per reading, O(1) per measurement; memory O(PLANS × WINDOW).  Thread-safe.
    """

    def __init__(self, budget: float):
        self.budget = budget
        self._lock = threading.Lock()
        self._plans: OrderedDict[str, tuple[deque, deque]] = OrderedDict()
        self._outside: deque = deque(maxlen=WINDOW)

    def measured_outside(self, seconds: float) -> None:
        """Record the seconds one look's answer took from its return to its last byte sent."""
        with self._lock:
            self._outside.append(seconds)

    def outside(self) -> float:
        """Seconds an answer recently needed to leave once returned (the 95th percentile; 0 before any)."""
        with self._lock:
            xs = sorted(self._outside)
        return xs[min(len(xs) - 1, int(PERCENTILE * len(xs)))] if xs else 0.0

    def measured(self, plan_id: str, *, after_decision: float, after_counts: float) -> None:
        """Record one look: seconds from the decision's end, and from the answer's counts' end, to the reply."""
        with self._lock:
            seen = self._plans.get(plan_id)
            if seen is None:
                seen = self._plans[plan_id] = (deque(maxlen=WINDOW), deque(maxlen=WINDOW))
                while len(self._plans) > PLANS:
                    self._plans.popitem(last=False)
            else:
                self._plans.move_to_end(plan_id)
            seen[0].append(after_decision)
            seen[1].append(after_counts)

    def _reserve(self, plan_id: str, which: int, guess: float) -> float:
        with self._lock:
            seen = self._plans.get(plan_id)
            xs = sorted(seen[which]) if seen and seen[which] else None
        if xs is None:
            x = guess
        else:
            x = xs[min(len(xs) - 1, int(PERCENTILE * len(xs)))]
        return min(MOST * self.budget, max(LEAST, x + self.outside()))

    def after_decision(self, plan_id: str) -> float:
        """Seconds the rest of a look of this plan needs after its decision."""
        return self._reserve(plan_id, 0, FIRST_GUESS * self.budget)

    def after_counts(self, plan_id: str) -> float:
        """Seconds a look of this plan needs after its answer's counts (building, storing, sending)."""
        return self._reserve(plan_id, 1, FIRST_GUESS * self.budget / 2)


#: Where a policy keeps its seconds per decision: its own, and those of the rules it falls back on
#: (a look-ahead's base within what its programme leaves).
_BUDGETS = ("budget", "lookahead_budget", "total_budget")
_PARTS = ("fallback", "fallback_alone", "base")


def _budgets(policy) -> list[tuple[object, str, float]]:
    """Every (object, attribute, seconds) of a policy's decision budgets, each object once."""
    out, seen = [], set()
    for obj in (policy, *(getattr(policy, name, None) for name in _PARTS)):
        if obj is None or id(obj) in seen:
            continue
        seen.add(id(obj))
        for name in _BUDGETS:
            v = getattr(obj, name, None)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                out.append((obj, name, v))
    return out


@contextmanager
def decision_budget(policy, seconds: float | None):
    """Within the block, a budgeted policy's decisions get ``seconds`` instead of its own budget (at
    most that budget, at least a tenth of it): every budget it holds, its fallbacks' included, is
    scaled by the same factor and given back after.  A policy with no budget (exact decisions) is
    left alone.  O(1).

    >>> from opportune.policies.opportunistic import Opportunistic
    >>> p = Opportunistic(budget=0.05)
    >>> with decision_budget(p, 0.03):
    ...     round(p.budget, 3)
    0.03
    >>> p.budget
    0.05
    """
    held = _budgets(policy)
    if seconds is None or not held:
        yield
        return
    nominal = held[0][2]
    factor = max(0.1, min(1.0, seconds / nominal))
    for obj, name, v in held:
        setattr(obj, name, v * factor)
    try:
        yield
    finally:
        for obj, name, v in held:
            setattr(obj, name, v)
