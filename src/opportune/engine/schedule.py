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


from opportune.engine.completions import CompletionQuestions
# names callers import from here (their homes: order_engine.py, result.py, tuning.py, poset.py)
from opportune.engine.order_engine import DEFAULT_MEMORY, OrderEngine  # noqa: F401
from opportune.engine.poset import bits
from opportune.engine.result import EXACT_DIGITS, CountResult, count_text, decimal, interval_unbuilt, log10_int  # noqa: F401
from opportune.engine.tuning import COUNT_MARGIN, FIRST_TURN, MAX_STRATEGIES_EXACT  # noqa: F401
from opportune.planning.plan import Plan

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Iterable, Sequence



class NotAdmissible(ValueError):
    """Installing a part would leave no admissible sequence (or the part is unknown / used up).

    Raised by :meth:`Schedule.install` (and by :class:`Schedule` for its ``installed`` parts); its
    message says which part and why, for a person to read.

    Parameters
    ----------
    message : str
        What is wrong, in words: the part is unknown, already installed, or still needs other parts
        first (named).
    part : str, optional
        The part's id, kept as ``error.part`` for a caller to act on.

    Examples
    --------
    >>> from opportune import make_plan
    >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
    >>> try:
    ...     s.install("c")
    ... except NotAdmissible as error:
    ...     print(error.part, "|", error)
    c | part 'c' cannot be installed yet: it requires a first
    """

    def __init__(self, message: str, part: str | None = None):
        self.part = part
        super().__init__(message)


#: Passes over every unit of a plan made to answer ``remaining`` or ``in_bin``, by name: a test
#: reads them to check that a service look makes a bounded number of them, whatever the plan's size.
PASSES: dict[str, int] = {}


def count_pass(name: str) -> None:
    """Count one pass over every unit (see :data:`PASSES`)."""
    PASSES[name] = PASSES.get(name, 0) + 1


class Schedule(CompletionQuestions):
    """A schedule: the parts installed so far (in order) plus all admissible completions.

    Immutable: :meth:`install` returns a new schedule sharing the plan's
    :class:`OrderEngine` (and so its memo), which makes branching cheap.

    Parameters
    ----------
    plan_or_engine : Plan or OrderEngine
        The plan (a new engine is built for it), or the plan's engine, to share its memo with every
        other schedule of the plan.
    installed : iterable of str, optional
        Part ids installed so far, in order (a part of quantity *q* may appear up to *q* times).

    Raises
    ------
    NotAdmissible
        A part of ``installed`` is unknown, used up, or cannot come where it does.

    Examples
    --------
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
        """The schedule of ``engine`` at a state given as bitmasks.

        What a policy deciding on masks asks its counting questions through, so that every count goes
        through this class.  O(1): no check that the state is reachable (the caller's states are).

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask : int
            The installed units (bit *u* for unit *u*; a part's units are numbered from
            ``engine.first[i]``, and installed lowest first).
        consistent : int
            The strategies still open (bit *k* for ``plan.strategies[k]``).
        installed : tuple of str, optional
            The installed sequence, if the caller keeps it (only :attr:`installed` shows it).

        Returns
        -------
        Schedule
            The schedule at that state, sharing ``engine``.

        Examples
        --------
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
        """The schedule after installing one unit of ``part`` (this one is unchanged).

        Parameters
        ----------
        part : str
            The part's id.

        Returns
        -------
        Schedule
            The new schedule, sharing this one's engine.

        Raises
        ------
        NotAdmissible
            ``part`` is unknown, already installed (every unit), or would leave no admissible
            sequence; the message names the parts it still needs.

        Examples
        --------
        >>> from opportune import make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> s.install("a").installed, s.install("a").install("c").count()
        (('a',), 1)
        >>> s.install("c")
        Traceback (most recent call last):
        ...
        opportune.engine.schedule.NotAdmissible: part 'c' cannot be installed yet: it requires a first
        """
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
        """Whether :meth:`install` would accept ``part`` now (never raises).

        Parameters
        ----------
        part : str
            A part id (an unknown one is simply not installable).

        Returns
        -------
        bool
            True if installing one unit of it leaves an admissible sequence.

        Examples
        --------
        >>> from opportune import make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> s.can_install("a"), s.can_install("c"), s.can_install("z")
        (True, False, False)
        """
        try:
            self._locate(part)
        except NotAdmissible:
            return False
        return True

    def missing_before(self, part: str) -> list[str]:
        """Parts still to install before ``part`` in the consistent strategy that misses the fewest.

        What a message says when ``part`` cannot go in yet.

        Parameters
        ----------
        part : str
            A part id of the plan.

        Returns
        -------
        list of str
            Those parts' ids in declaration order (empty if ``part`` can go in now or is used up).

        Raises
        ------
        KeyError
            ``part`` is not in the plan.

        Examples
        --------
        >>> from opportune import make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> s.missing_before("c"), s.install("b").missing_before("c"), s.missing_before("a")
        (['a', 'b'], ['a'], [])
        """
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
        """Whether every unit of the plan is installed (then :meth:`count` is 1).  O(1)."""
        return self.mask == self.engine.full

    @property
    def consistent_strategies(self) -> tuple[str, ...]:
        """Names of the strategies the installed sequence still respects."""
        return tuple(s.name for k, s in enumerate(self.plan.strategies) if self.consistent >> k & 1)

    def installable(self) -> tuple[str, ...]:
        """Parts that can be installed now (all their required parts installed in some consistent strategy).

        Returns
        -------
        tuple of str
            Their ids, in declaration order (empty once complete).

        Examples
        --------
        >>> from opportune import make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> s.installable(), s.install("a").installable()
        (('a', 'b'), ('b', 'c'))
        """
        return self.engine.installable(self.mask, self.consistent)

    def count(self) -> int:
        """Exact number of admissible completions: the value of ``count_result(estimate=False)``.

        Returns
        -------
        int
            The number of admissible ways to finish (1 once complete).

        Raises
        ------
        BudgetExceeded
            The exact count did not fit the engine's memo or time budget, or a deadline the caller
            holds (:class:`~opportune.engine.deadline.BudgetExceeded`); what was counted stays in the
            memos.  :meth:`count_result` estimates instead.

        Examples
        --------
        >>> from opportune import make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> s.count(), s.install("b").count(), s.install("b").install("a").install("c").count()
        (3, 1, 1)
        """
        return self.engine.count(self.mask, self.consistent)

    def warm_up(self, time_limit: float | None = None) -> bool:
        """Prepare the engine's tables and count this state exactly (:meth:`OrderEngine.warm_up`).

        How the plan is counted (a hub or not) is chosen here, once, and the memos every later
        question uses are filled.  What was built and counted is kept either way.  O(one exact count).

        Parameters
        ----------
        time_limit : float or None, optional
            Seconds it may take (None: no limit).

        Returns
        -------
        bool
            True if the exact count finished in time.

        Examples
        --------
        >>> from opportune import make_plan
        >>> Schedule(make_plan(["a", "b"], {"b": ["a"]})).warm_up(1.0)
        True
        """
        return self.engine.warm_up(time_limit, self.mask, self.consistent)

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
