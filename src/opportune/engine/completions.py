"""Questions about the completions of a schedule: how many, each part's options and positions, samples.

:class:`CompletionQuestions` is the part of :class:`~opportune.engine.schedule.Schedule` that asks
the plan's :class:`~opportune.engine.order_engine.OrderEngine` about the admissible ways to finish
from the schedule's state (its ``engine``, ``mask`` and ``consistent``); the schedule itself keeps
the state and installs.
"""

from __future__ import annotations

from opportune.engine.deadline import Deadline, as_deadline, no_collection
from opportune.engine.phases import CountQuestion, count_in_phases
from opportune.engine.result import CountResult

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    import random
    from typing import Collection, Iterable

    from fractions import Fraction     # loaded where a fraction is made: it loads decimal (5 ms at start-up)

    from opportune.engine.schedule import Schedule


class CompletionQuestions:
    """What a schedule asks about its completions (a mixin of :class:`~opportune.engine.schedule.Schedule`:
    it reads the schedule's ``engine``, ``mask``, ``consistent`` and ``installed``)."""

    __slots__ = ()

    def chains(self, strategy: int, *, chains: int = 8, seed: int = 0):
        """A population of Markov chains on this state's completions under one strategy.

        For estimates when the exact counts do not fit a decision's budget.  O(steps left × chains)
        to start.

        Parameters
        ----------
        strategy : int
            The strategy's index in ``plan.strategies``.
        chains : int, default 8
            Independent chains (their spread states the estimates' error).
        seed : int, default 0
            Seed of the chains' random streams.

        Returns
        -------
        CompletionChains
            The chains, each started at a completion of this state
            (:class:`~opportune.engine.sampling.CompletionChains`).

        Examples
        --------
        >>> from opportune import Schedule, make_plan
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
        with an interval.

        The one way to count a state: the exact methods, the hub split and the estimates are chosen
        here (and in :meth:`OrderEngine.count` for the exact part), never by the caller.
        Everything stops at one :class:`~opportune.engine.deadline.Deadline`: ``plain + time_limit``
        seconds from the call, or ``deadline`` if sooner, where ``plain`` is the engine's own time
        limit, or a tenth of ``time_limit`` if it has none.  The call returns within that plus
        ``COUNT_MARGIN`` seconds (:mod:`opportune.engine.tuning`: the granularity of the deadline
        checks and assembling the answer; no automatic cycle collection runs inside it, see
        :func:`~opportune.engine.deadline.no_collection`; how far past the deadline it was measured
        to end: the documentation's page on time limits).  Building the inclusion–exclusion terms is
        inside the budget (a deadline between unions); building the engine's orders is the caller's
        (O(units + pairs) big-integer operations, in :class:`OrderEngine`).

        Parameters
        ----------
        rel_error : float, default 0.01
            The relative error an estimate aims at: the estimate stops early once its 95% interval is
            within it.
        time_limit : float, default 10.0
            Seconds the call may take beyond the engine's own exact time (see above).
        seed : int, default 0
            Seed of the estimates' random draws (the answer is the same for the same seed, but for a
            stop on the clock).
        exact_share : float, default 0.65
            The share of ``time_limit`` the exact phases may run before the estimate takes over.
        deadline : Deadline or float or None, optional
            A moment everything stops at if sooner (a :class:`~opportune.engine.deadline.Deadline` or
            a ``time.perf_counter()`` moment).
        threads : int, default 1
            Threads that count and draw in relaxation Monte Carlo (its counts, draws and answer are
            the same for any number, but for a stop on the clock; the exact phases use one).
        estimate : bool, default True
            False: the exact count alone, the same way, within ``deadline``, or with ``deadline=None``
            within whatever :meth:`OrderEngine.deadline` the caller holds, else the engine's time
            limit per count; ``time_limit`` and the estimate's settings are then unused.
            :meth:`count` is the same, as a plain ``int``.

        Returns
        -------
        CountResult
            Always with a value.  ``exact`` and an ``int`` value, or an estimate with a finite
            interval (``log10_low``/``log10_high``: the stated interval within the order's certain
            bounds, ``1 <= count <= n!`` at the very least) and its ``rel_error`` (infinite when no
            error could be stated from the runs) and ``method``.

        Raises
        ------
        BudgetExceeded
            Only with ``estimate=False``: the exact count did not fit
            (:class:`~opportune.engine.deadline.BudgetExceeded`; what was counted stays in the memos).

        Notes
        -----
        The phases (:mod:`opportune.engine.phases`; their times and why: :mod:`opportune.engine.tuning`):

        1. the exact count until ``plain + exact_share * time_limit`` seconds: the plain count and the
           engine's count through a hub in turns of ``FIRST_TURN`` seconds, doubling every round, with
           relaxation Monte Carlo's go (at most ``EARLY_SECONDS``) after the second round.  No turn's
           length depends on ``time_limit``: an exact count that fits one limit comes at the same
           moment with any longer one;
        2. if still not exact, the estimate gets the rest, shared between the inclusion–exclusion
           terms (certain bounds, Knuth's estimator, sequential Monte Carlo runs), stopping early once
           the 95% interval is within ``rel_error``.

        The phases' times are scaled down if ``deadline`` leaves less than ``plain + time_limit``, and
        the exact phases end early enough to leave the estimate its pass over each order,
        ``ESTIMATE_RESERVE`` seconds per element.  A deadline already passed still gives the first
        turn and the estimate ``GRACE`` seconds each: a small plan is exact.

        Examples
        --------
        >>> from opportune import Schedule, make_plan
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

        Returns
        -------
        dict of str to int
            Part id → completions after installing one unit of it, for each installable part in
            declaration order; the counts add up to :meth:`count`.

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import Schedule, make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))      # a b c, a c b, b a c
        >>> s.options()
        {'a': 2, 'b': 1}
        """
        return self.engine.options(self.mask, self.consistent)

    def options_for(self, parts: Collection[str]) -> dict[str, int]:
        """:meth:`options` for just these parts: fewer counts when a look shows only a few.

        Parameters
        ----------
        parts : collection of str
            Part ids (those not installable now are left out of the answer).

        Returns
        -------
        dict of str to int
            Part id → completions after installing it, for those of ``parts`` installable now, in
            declaration order.

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import Schedule, make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))      # a b c, a c b, b a c
        >>> s.options_for(["c", "b"])       # c cannot go in yet
        {'b': 1}
        """
        return self.engine.options_for(self.mask, self.consistent, parts)

    def next_probabilities(self) -> dict[str, Fraction]:
        """Probability that each installable part comes next in a uniformly random admissible completion.

        Returns
        -------
        dict of str to Fraction
            Part id → its exact probability (:meth:`options` over :meth:`count`), for each
            installable part in declaration order.

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import Schedule, make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))      # a b c, a c b, b a c
        >>> {part: str(p) for part, p in s.next_probabilities().items()}
        {'a': '2/3', 'b': '1/3'}
        """
        total = self.count()
        from fractions import Fraction

        return {p: Fraction(c, total) for p, c in self.options().items()}

    def expected_positions(self) -> dict[str, Fraction]:
        """Expected position (1 = next) of each remaining part in a uniformly random admissible completion.

        For a part with several units left, the position of its next unit: when it is first needed.

        Returns
        -------
        dict of str to Fraction
            Part id → its exact expected position, for each part with units left.

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import Schedule, make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))      # a b c, a c b, b a c
        >>> {part: str(p) for part, p in s.expected_positions().items()}
        {'a': '4/3', 'b': '2', 'c': '8/3'}
        """
        return self.engine.expected_positions(self.mask, self.consistent)

    def position_sums_for(self, parts: Iterable[str]) -> tuple[int, dict[str, int]]:
        """The completions and each part's position summed over them, for these parts.

        Each sum divided by the completions is the part's expected position (see
        :meth:`expected_positions`), without the fractions and for fewer parts.

        Parameters
        ----------
        parts : iterable of str
            Part ids (those with no unit left are left out of the answer).

        Returns
        -------
        tuple of (int, dict of str to int)
            ``(completions, position sums)``: part id → the sum over all admissible completions of
            the position (1 = next) of its next unit.

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import Schedule, make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))      # a b c, a c b, b a c
        >>> s.position_sums_for(["c", "a"])      # c: 3 + 2 + 3, a: 1 + 1 + 2
        (3, {'c': 8, 'a': 4})
        """
        return self.engine.position_sums_for(self.mask, self.consistent, parts)

    def sample(self, seed: int | random.Random | None = 0) -> list[str]:
        """One admissible completion drawn uniformly at random (exactly, from the counts).

        Parameters
        ----------
        seed : int or random.Random or None, default 0
            A seed, or the random stream to draw from (None: a fresh unseeded one).

        Returns
        -------
        list of str
            The part ids still to install, in the drawn order.

        Raises
        ------
        BudgetExceeded
            An exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import Schedule, make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))      # a b c, a c b, b a c
        >>> tuple(s.sample(seed=1)) in s.completions()
        True
        >>> s.sample(seed=1) == s.sample(seed=1)
        True
        """
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
        """Every admissible completion, in lexicographic order of declaration.

        Parameters
        ----------
        limit : int, default 100,000
            Most completions it lists.

        Returns
        -------
        list of tuple of str
            Each completion as the part ids still to install, in order.

        Raises
        ------
        ValueError
            There are more than ``limit`` completions (count or sample them instead).
        BudgetExceeded
            The exact count did not fit the engine's budget
            (:class:`~opportune.engine.deadline.BudgetExceeded`).

        Examples
        --------
        >>> from opportune import Schedule, make_plan
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))      # a b c, a c b, b a c
        >>> s.completions()
        [('a', 'b', 'c'), ('a', 'c', 'b'), ('b', 'a', 'c')]
        >>> s.completions(limit=2)
        Traceback (most recent call last):
        ...
        ValueError: 3 completions is more than the limit of 2: count or sample them instead
        """
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
