"""The schedule: what has been installed, plus *all* admissible ways to finish.

The paper's schedule is "the sequence of steps that have been completed plus
the set of all possible sequences for completing the remaining steps".  A
:class:`Schedule` represents that set without listing it: every question
(how many completions, which parts can go in now, how many options each keeps,
where each part is expected to come) is answered by counting linear
extensions with the memoised :class:`~opportune.engine.count.Counter`.

How a plan becomes posets:

* **Quantities.**  A part with quantity *q* becomes *q* units chained
  ``u1 < u2 < ... < uq``.  Sequences of part ids correspond one-to-one to
  linear extensions of the chained units (exactly one of the *q!* orders of
  interchangeable units is the chained one), so identical units never
  multiply a count.
* **Several strategies.**  The admissible sequences are the union over the
  strategies still consistent with what was installed.  Its size is
  computed by inclusion–exclusion: the sequences admissible under every
  strategy of a set *T* are the linear extensions of the union of their
  orders (zero if that union has a cycle).  One counter per set *T*, each
  keeping its memo for the life of the plan.
"""

from __future__ import annotations

from abc import ABCMeta

from opportune.engine.count import Counter, entries_within
from opportune.engine.deadline import Deadline, as_deadline, no_collection
from opportune.engine.exact import ExactCounting
from opportune.engine.hub import HubPath
from opportune.engine.memory import MemoryUpkeep, memory_total
from opportune.engine.phases import CountQuestion, count_in_phases
from opportune.engine.poset import Poset, bits
from opportune.engine.questions import StateQuestions
# names callers import from here (their home: result.py, tuning.py)
from opportune.engine.result import EXACT_DIGITS, CountResult, count_text, decimal, interval_unbuilt, log10_int  # noqa: F401
from opportune.engine.tuning import COUNT_MARGIN, FIRST_TURN, MAX_STRATEGIES_EXACT  # noqa: F401
from opportune.engine.waysengine import WaysEngine
from opportune.planning.plan import Plan

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    import random
    from typing import Collection, Iterable, Sequence

    from fractions import Fraction     # loaded where a fraction is made: it loads decimal (5 ms at start-up)

#: An engine's default ``memory_limit``: a quarter of the machine's memory (a service sets its plan share).
DEFAULT_MEMORY = memory_total() // 4


class NotAdmissible(ValueError):
    """Installing a part would leave no admissible sequence (or the part is unknown / used up)."""

    def __init__(self, message: str, part: str | None = None):
        self.part = part
        super().__init__(message)


class OrderEngine(ExactCounting, StateQuestions, MemoryUpkeep, metaclass=ABCMeta):
    """The order engine of one plan: its unit posets and their counters.

    Create one per plan and share it between all schedules, sequencers and
    simulations of that plan: the memo (and the per-state caches below) is
    what makes repeated questions cheap.

    ``max_memo`` and ``time_limit`` bound each exact count; beyond them
    :meth:`Schedule.count_result` falls back to an estimate and says so.  ``max_memo=0``: as many
    entries as ``memory_limit`` (or :data:`DEFAULT_MEMORY`) holds at the order's entry size
    (:func:`~opportune.engine.count.entries_within`), what ``opportune count`` uses.
    """

    def __new__(cls, plan: Plan, **options):
        if cls is OrderEngine and getattr(plan, "ways", None) is not None:   # a plan written as ways
            return WaysEngine(plan, **options)
        return super().__new__(cls)

    def __init__(self, plan: Plan, *, max_memo: int | None = 2_000_000, time_limit: float | None = None,
                 deadline: Deadline | float | None = None, memory_limit: int | None = DEFAULT_MEMORY):
        """``deadline``: building the strategies' orders (a closure per strategy: O(units × covers)
        big-integer operations each, seconds for 64 strategies over 10,000 parts) stops past it with
        ``BudgetExceeded``.  ``memory_limit``: bytes the memos and caches may hold between decisions
        (see :meth:`maintain`; None: only each memo's entry cap)."""
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


#: Passes over every unit of a plan made to answer ``remaining`` or ``in_bin``, by name: a test
#: reads them to check that a service look makes a bounded number of them, whatever the plan's size.
PASSES: dict[str, int] = {}


def count_pass(name: str) -> None:
    """Count one pass over every unit (see :data:`PASSES`)."""
    PASSES[name] = PASSES.get(name, 0) + 1


class Schedule:
    """A schedule: the parts installed so far (in order) plus all admissible completions.

    Immutable: :meth:`install` returns a new schedule sharing the plan's
    :class:`OrderEngine` (and so its memo), which makes branching cheap.

    >>> from opportune import make_plan
    >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
    >>> s.count(), s.installable()
    (3, ('a', 'b'))
    >>> s.options()
    {'a': 2, 'b': 1}
    >>> s.install("b").count()
    1
    """

    __slots__ = ("engine", "plan", "installed", "mask", "consistent", "_left")

    def __init__(self, plan_or_engine: Plan | OrderEngine, installed: Iterable[str] = ()):
        engine = plan_or_engine if isinstance(plan_or_engine, OrderEngine) else OrderEngine(plan_or_engine)
        self.engine = engine
        self.plan = engine.plan
        self.installed: tuple[str, ...] = ()
        self.mask = 0
        self.consistent = engine.all_strategies
        self._left: dict[str, int] | None = None   # ``remaining``, once asked (see there)
        for part in installed:
            self._install_in_place(part)

    @classmethod
    def _make(cls, engine, installed, mask, consistent) -> "Schedule":
        s = object.__new__(cls)
        s.engine, s.plan, s.installed, s.mask, s.consistent = engine, engine.plan, installed, mask, consistent
        s._left = None
        return s

    @classmethod
    def at(cls, engine: OrderEngine, mask: int, consistent: int, installed: tuple[str, ...] = ()) -> "Schedule":
        """The schedule of ``engine`` at a state given as bitmasks: ``mask`` the installed units,
        ``consistent`` the strategies still open (``installed`` the sequence, if the caller keeps it).
        What a policy deciding on masks asks its counting questions through, so that every count goes
        through this class.  O(1): no check that the state is reachable (the caller's states are).

        >>> from opportune import make_plan
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> Schedule.at(engine, 0b001, engine.all_strategies).options()
        {'b': 1, 'c': 1}
        """
        return cls._make(engine, installed, mask, consistent)

    def _locate(self, part: str) -> tuple[int, int, int]:
        if part not in self.plan:
            raise NotAdmissible(f"unknown part '{part}'", part)
        i = self.plan.index(part)
        u = self.engine.next_unit(self.mask, i)
        if u is None:
            q = self.plan.parts[i].quantity
            raise NotAdmissible(
                f"part '{part}' is already installed" + (f" ({q} of {q} units)" if q > 1 else ""), part)
        after = self.engine.consistent_after(self.mask, self.consistent, u)
        if not after:
            missing = self.missing_before(part)
            raise NotAdmissible(
                f"part '{part}' cannot be installed yet: it requires {', '.join(missing)} first"
                if missing else f"installing '{part}' now leaves no admissible sequence", part)
        return i, u, after

    def _install_in_place(self, part: str) -> None:
        _, u, after = self._locate(part)
        self.installed += (part,)
        self.mask |= 1 << u
        self.consistent = after
        self._left = None

    def install(self, part: str) -> "Schedule":
        """The schedule after installing one unit of ``part``; raises :class:`NotAdmissible`."""
        _, u, after = self._locate(part)
        s = Schedule._make(self.engine, self.installed + (part,), self.mask | 1 << u, after)
        left = self._left
        if left is not None:   # one part fewer: a C-level copy, not another pass over the units
            left = dict(left)
            if left[part] == 1:
                del left[part]
            else:
                left[part] -= 1
            s._left = left
        return s

    def can_install(self, part: str) -> bool:
        try:
            self._locate(part)
        except NotAdmissible:
            return False
        return True

    def missing_before(self, part: str) -> list[str]:
        """Parts still to install before ``part`` in the consistent strategy that misses the fewest."""
        i = self.plan.index(part)
        u = self.engine.next_unit(self.mask, i)
        if u is None:
            return []
        if self.plan.ways is not None:
            return self.engine.missing_before(self.mask, part)
        best = None
        for s in range(self.engine.k):
            if self.consistent >> s & 1:
                lacking = self.engine.posets[s].below[u] & ~self.mask
                parts = sorted({self.engine.unit_part[v] for v in _bits(lacking)} - {i})
                if best is None or len(parts) < len(best):
                    best = parts
        return [self.plan.parts[j].id for j in best or []]

    @property
    def remaining(self) -> dict[str, int]:
        """Units still to install, per part (declaration order; parts with none left omitted).

        Found once per schedule, by one pass over the units left (O(units)), and carried to the
        schedules :meth:`install` makes (a dictionary copy): a service look asks for it several times.
        A new dictionary each time (the caller may change it).

        >>> from opportune import make_plan
        >>> Schedule(make_plan(["a", "b"], {})).install("b").remaining
        {'a': 1}
        """
        left = self._left
        if left is None:
            count_pass("remaining")
            left = {}
            for u in _bits(self.engine.full & ~self.mask):
                pid = self.plan.parts[self.engine.unit_part[u]].id
                left[pid] = left.get(pid, 0) + 1
            self._left = left
        return dict(left)

    @property
    def is_complete(self) -> bool:
        return self.mask == self.engine.full

    @property
    def consistent_strategies(self) -> tuple[str, ...]:
        """Names of the strategies the installed sequence still respects."""
        return tuple(s.name for k, s in enumerate(self.plan.strategies) if self.consistent >> k & 1)

    def installable(self) -> tuple[str, ...]:
        """Parts that can be installed now (all their required parts installed in some consistent strategy)."""
        return self.engine.installable(self.mask, self.consistent)

    def count(self) -> int:
        """Exact number of admissible completions (raises BudgetExceeded if over budget): the value of
        ``count_result(estimate=False)``."""
        return self.engine.count(self.mask, self.consistent)

    def warm_up(self, time_limit: float | None = None) -> bool:
        """Prepare the engine's tables and count this state exactly within ``time_limit`` seconds
        (:meth:`OrderEngine.warm_up`): how the plan is counted (a hub or not) is chosen here, once,
        and the memos every later question uses are filled.  True if it finished in time; what was
        built and counted is kept either way.  O(one exact count).

        >>> from opportune import make_plan
        >>> Schedule(make_plan(["a", "b"], {"b": ["a"]})).warm_up(1.0)
        True
        """
        return self.engine.warm_up(time_limit, self.mask, self.consistent)

    def chains(self, strategy: int, *, chains: int = 8, seed: int = 0):
        """A population of Markov chains on this state's completions under one strategy (its index),
        for estimates when the exact counts do not fit a decision's budget
        (:class:`~opportune.engine.sampling.CompletionChains`).  O(steps left × chains) to start.

        >>> from opportune import make_plan
        >>> pop = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]})).chains(0, seed=1)
        >>> est = pop.estimate(first=[0, 1], steps=20_000)
        >>> abs(est.first[0][0] - 2 / 3) < 0.05
        True
        """
        if self.plan.ways is not None:      # a plan written as ways: completions drawn by sequential Monte Carlo
            from opportune.engine.ways import WaysChains

            return WaysChains(self.engine.table, self.mask, chains=chains, seed=seed)
        from opportune.engine.sampling import CompletionChains    # here: a count never draws

        return CompletionChains(self.engine.posets[strategy], self.engine.full & ~self.mask, chains=chains, seed=seed)

    def count_result(self, *, rel_error: float = 0.01, time_limit: float = 10.0, seed: int = 0,
                     exact_share: float = 0.65, deadline=None, threads: int = 1, estimate: bool = True) -> CountResult:
        """Number of completions: exact within the engine's budget, else a clearly marked estimate
        with an interval.  The one way to count a state: the exact methods, the hub split and the
        estimates are chosen here (and in :meth:`OrderEngine.count` for the exact part), never by
        the caller.

        ``estimate=False``: the exact count alone, the same way, within ``deadline`` (a
        :class:`~opportune.engine.deadline.Deadline` or a ``time.perf_counter()`` moment), or with
        ``deadline=None`` within whatever :meth:`OrderEngine.deadline` the caller holds, else the
        engine's time limit per count; :class:`~opportune.engine.deadline.BudgetExceeded` if it does
        not fit (what was counted stays in the memos).  ``time_limit`` and the estimate's settings
        are then unused.  :meth:`count` is the same, as a plain ``int``.

        Everything stops at one :class:`~opportune.engine.deadline.Deadline`: ``plain + time_limit``
        seconds from the call, or ``deadline`` if sooner, where ``plain`` is the engine's own time
        limit, or a tenth of ``time_limit`` if it has none.  The call returns within that plus
        ``COUNT_MARGIN`` (0.25 s of CPU time, measured at most 0.1 s past it on orders of up to
        10,000 elements: the granularity of the deadline checks and assembling the answer; no automatic
        cycle collection runs inside it, see :func:`~opportune.engine.deadline.no_collection`).  Phases:

        (The phases' times below are scaled down if ``deadline`` leaves less than ``plain +
        time_limit``, and the exact phases end early enough to leave the estimate its pass over
        each order, ``ESTIMATE_RESERVE`` seconds per element.  A deadline already passed still
        gives the first turn and the estimate ``GRACE`` seconds each: a small plan is exact.)

        1. the exact count until ``plain + exact_share * time_limit`` seconds: the plain count and the
           engine's count through a hub in turns of ``FIRST_TURN`` seconds, doubling every round, with
           relaxation Monte Carlo's go (at most ``EARLY_SECONDS``) after the second round.  No turn's
           length depends on ``time_limit``: an exact count that fits one limit comes at the same
           moment with any longer one;
        2. if still not exact, the estimate gets the rest, shared between the inclusion–exclusion
           terms (certain bounds, Knuth's estimator, sequential Monte Carlo runs), stopping early once
           the 95% interval is within ``rel_error``.

        Each phase and its times: :mod:`opportune.engine.phases` and :mod:`opportune.engine.tuning`.

        The answer always has a value, and an estimate always has a finite interval
        (``log10_low``/``log10_high``: the stated interval within the order's certain bounds,
        ``1 <= count <= n!`` at the very least); ``rel_error`` is infinite when no error could be
        stated from the runs.  Building the inclusion–exclusion terms is inside the budget (a
        deadline between unions); building the engine's orders is the caller's (O(units + pairs)
        big-int operations, ~0.1 s for 10,000 units).  ``threads``: threads that count and draw in
        relaxation Monte Carlo (its counts, draws and answer are the same for any number, but for a
        stop on the clock; the exact phases use one).

        >>> from opportune import make_plan
        >>> r = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]})).count_result(time_limit=1.0)
        >>> r.value, r.exact, r.interval_log10 == (r.log10, r.log10)
        (3, True, True)
        >>> Schedule(make_plan(["a", "b", "c"], {"c": ["a"]})).count_result(estimate=False).value
        3
        """

        if self.plan.ways is not None:      # a plan written as ways: its own exact count and estimate
            return self.engine.count_result(self.mask, rel_error=rel_error, time_limit=time_limit, seed=seed,
                                            exact_share=exact_share, deadline=deadline, estimate=estimate)
        if not estimate:
            if deadline is None:
                return CountResult(self.engine.count(self.mask, self.consistent))
            with self.engine.deadline(as_deadline(deadline).at):
                return CountResult(self.engine.count(self.mask, self.consistent))
        with no_collection():       # a full collection of the caller's heap is no part of this call's time
            return self._count_timed(rel_error, time_limit, seed, exact_share, as_deadline(deadline), threads)

    def _count_timed(self, rel_error: float, time_limit: float, seed: int, exact_share: float, deadline: Deadline,
                     threads: int) -> CountResult:
        """:meth:`count_result` with an estimate: its phases (:mod:`opportune.engine.phases`) in order."""
        return count_in_phases(CountQuestion.ask(self, rel_error, time_limit, seed, exact_share, deadline, threads))

    def options(self) -> dict[str, int]:
        """For each installable part, how many admissible completions remain after installing it.

        These are the paper's "future sequencing options" that the opportunistic
        policy maximises.  Cached per state, so repeated questions are dict look-ups.
        """
        return self.engine.options(self.mask, self.consistent)

    def options_for(self, parts: Collection[str]) -> dict[str, int]:
        """:meth:`options` for just these parts (those of them installable now; declaration order)."""
        return self.engine.options_for(self.mask, self.consistent, parts)

    def next_probabilities(self) -> dict[str, Fraction]:
        """Probability that each installable part comes next in a uniformly random admissible completion."""
        total = self.count()
        from fractions import Fraction

        return {p: Fraction(c, total) for p, c in self.options().items()}

    def expected_positions(self) -> dict[str, Fraction]:
        """Expected position (1 = next) of each remaining part in a uniformly random admissible completion.

        For a part with several units left, the position of its next unit: when it is first needed.
        """
        return self.engine.expected_positions(self.mask, self.consistent)

    def position_sums_for(self, parts: Iterable[str]) -> tuple[int, dict[str, int]]:
        """``(completions, position sums)`` of these parts (those remaining): each sum divided by
        the completions is the part's expected position (see :meth:`expected_positions`)."""
        return self.engine.position_sums_for(self.mask, self.consistent, parts)

    def sample(self, seed: int | random.Random | None = 0) -> list[str]:
        """One admissible completion drawn uniformly at random (exactly, from the counts)."""
        import random     # here: a count never draws

        rng = seed if isinstance(seed, random.Random) else random.Random(seed)
        s, out = self, []
        while not s.is_complete:
            opts = s.options()
            r = rng.randrange(sum(opts.values()))
            for part, c in opts.items():
                if r < c:
                    break
                r -= c
            out.append(part)
            s = s.install(part)
        return out

    def completions(self, limit: int = 100_000) -> list[tuple[str, ...]]:
        """Every admissible completion, in lexicographic order of declaration; refuses above ``limit``."""
        total = self.count()
        if total > limit:
            raise ValueError(f"{total} completions is more than the limit of {limit}: count or sample them instead")
        out: list[tuple[str, ...]] = []

        def walk(s: Schedule, prefix: tuple[str, ...]):
            if s.is_complete:
                out.append(prefix)
                return
            for part in s.options():
                walk(s.install(part), prefix + (part,))

        walk(self, ())
        return out

    def __repr__(self) -> str:
        return f"Schedule({self.plan.name!r}, installed={list(self.installed)!r})"

    def __eq__(self, other) -> bool:
        return isinstance(other, Schedule) and other.engine is self.engine and other.installed == self.installed

    def __hash__(self) -> int:
        return hash((id(self.engine), self.installed))


_bits = bits   # (the name this module's callers and tests use)


def schedule(plan: Plan, installed: Sequence[str] = ()) -> Schedule:
    """Shorthand for ``Schedule(plan, installed)``."""
    return Schedule(plan, installed)
