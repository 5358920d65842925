"""The order engine of one plan: its unit posets, their counters and the caches every schedule shares.

One per plan (:class:`OrderEngine`); the counting methods it inherits live in
:mod:`~opportune.engine.exact`, the questions about states in :mod:`~opportune.engine.questions`
and its memory upkeep in :mod:`~opportune.engine.memory`.
"""

from __future__ import annotations

from abc import ABCMeta

from opportune.engine.count import Counter, entries_within
from opportune.engine.deadline import Deadline, as_deadline
from opportune.engine.exact import ExactCounting
from opportune.engine.hub import HubPath
from opportune.engine.memory import MemoryUpkeep, memory_total
from opportune.engine.poset import Poset
from opportune.engine.questions import StateQuestions
from opportune.engine.waysengine import WaysEngine

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.planning.plan import Plan

#: An engine's default ``memory_limit``: a quarter of the machine's memory (a service sets its plan share).
DEFAULT_MEMORY = memory_total() // 4


class OrderEngine(ExactCounting, StateQuestions, MemoryUpkeep, metaclass=ABCMeta):
    """The order engine of one plan: its unit posets and their counters.

    Create one per plan and share it between all schedules, sequencers and
    simulations of that plan: the memo (and the per-state caches below) is
    what makes repeated questions cheap.  A part of quantity *q* is *q* units, chained; each strategy
    is one :class:`~opportune.engine.poset.Poset` on the units (``posets``, ``n_units`` units, ``k``
    strategies).  Building them is O(units × covers) big-integer operations per strategy.

    Parameters
    ----------
    plan : Plan
        The plan (checked, as :func:`~opportune.formats.loader.make_plan` and
        :func:`~opportune.formats.loader.load_plan` make them).
    max_memo : int or None, default 2,000,000
        Memo entries each exact count may add; beyond them (or ``time_limit``)
        :meth:`Schedule.count_result` falls back to an estimate and says so.  ``0``: as many entries
        as ``memory_limit`` (or :data:`DEFAULT_MEMORY`) holds at the order's entry size
        (:func:`~opportune.engine.count.entries_within`), what ``opportune count`` uses; None: no cap.
    time_limit : float or None, optional
        Seconds each exact count may take (None: no limit of its own).
    deadline : Deadline or float or None, optional
        When building the strategies' orders must stop (a
        :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()`` moment; None:
        never).
    memory_limit : int or None, default DEFAULT_MEMORY
        Bytes the memos and caches may hold between decisions (see :meth:`maintain`; None: only each
        memo's entry cap).

    Raises
    ------
    BudgetExceeded
        Building the orders went past ``deadline``
        (:class:`~opportune.engine.deadline.BudgetExceeded`).

    Examples
    --------
    >>> from opportune import Schedule, make_plan
    >>> plan = make_plan(["a", {"id": "b", "quantity": 2}, "c"], {"c": ["a"]})
    >>> engine = OrderEngine(plan)
    >>> engine.n_units, engine.k
    (4, 1)
    >>> Schedule(engine).count(), Schedule(engine).install("b").count()     # one memo for both
    (6, 3)
    """

    def __new__(cls, plan: Plan, *, max_memo: int | None = 2_000_000, time_limit: float | None = None,
                deadline: Deadline | float | None = None, memory_limit: int | None = DEFAULT_MEMORY):
        if cls is OrderEngine and getattr(plan, "ways", None) is not None:   # a plan written as ways
            return WaysEngine(plan, max_memo=max_memo, time_limit=time_limit, deadline=deadline,
                              memory_limit=memory_limit)
        return super().__new__(cls)

    def __init__(self, plan: Plan, *, max_memo: int | None = 2_000_000, time_limit: float | None = None,
                 deadline: Deadline | float | None = None, memory_limit: int | None = DEFAULT_MEMORY):
        dl = as_deadline(deadline)
        self.plan = plan
        self.time_limit = time_limit
        self._start_upkeep(memory_limit)
        # Units: part i owns units first[i] .. first[i] + quantity - 1, installed in that order.
        self.first: list[int] = []
        self.unit_part: list[int] = []
        for i, part in enumerate(plan.parts):
            self.first.append(len(self.unit_part))
            self.unit_part.extend([i] * part.quantity)
        self.n_units = len(self.unit_part)
        self.full = (1 << self.n_units) - 1
        if max_memo == 0:
            # bytes, not entries: an entry on 1,000 units takes 20 times one on 50
            max_memo = entries_within(self.n_units, memory_limit or DEFAULT_MEMORY)
        self.max_memo = max_memo
        chain = [(u, u + 1) for u in range(self.n_units - 1) if self.unit_part[u] == self.unit_part[u + 1]]
        self.posets: list[Poset] = []
        for strategy in plan.strategies:
            pairs = list(chain)
            for b, a in plan.index_pairs(strategy):
                # Every constraint applies to every unit: last unit of b before first unit of a.
                pairs.append((self.first[b] + plan.parts[b].quantity - 1, self.first[a]))
            self.posets.append(Poset.from_pairs(self.n_units, pairs, deadline=dl))
        self.k = len(self.posets)
        self.all_strategies = (1 << self.k) - 1
        self._counters: dict[int, Counter | None] = {}
        # Per-state caches, keyed by mask | consistent << n_units: one int, no tuple to build and hash.
        self._count_cache: dict[int, int] = {}
        self._options_cache: dict[int, dict[str, int]] = {}
        self._positions_cache: dict[int, tuple[int, dict[int, int]]] = {}  # (count, unit sums)
        self._option_cache: dict[int, tuple[dict, dict[str, int]]] = {}  # (installable, options)
        self._installable_cache: dict[int, frozenset[str]] = {}
        self._terms_cache: dict[int, list] = {}
        self._quantity = [p.quantity for p in plan.parts]
        self._nbytes = max(1, (self.n_units + 7) // 8)
        self._above: list | None = None
        self._unit_ids = [plan.parts[i].id for i in self.unit_part]
        self._part_units = {p.id: ((1 << p.quantity) - 1) << self.first[i] for i, p in enumerate(plan.parts)}
        # Per counter whose plain count failed on a hub: its persistent hub path (None: no hub found).
        self._hubs: dict[Counter, HubPath | None] = {}
        self._hub_search: dict[Counter, HubPath] = {}   # a hub search cut short by a deadline, to resume
        self._probe_left: dict[Counter, int] = {}       # new memo entries the plain probe may still add
        self._until: float | None = None                # the deadline of :meth:`deadline`, if any


# the engine of a plan written as ways is an order engine to every caller (isinstance), by its own class
OrderEngine.register(WaysEngine)
