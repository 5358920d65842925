"""The counting methods of :meth:`~opportune.engine.schedule.Schedule.count_result`, as phases.

Each phase is a small object with one interface, ``run(question, deadline) -> PhaseResult``: it works
on the :class:`CountQuestion` (the state, the error asked, what earlier phases left) until
``deadline`` and says why it stopped (:class:`StopReason`).  ``count_result`` runs :data:`PHASES` in
order and answers with the first phase's result that carries an answer:

1. :class:`ExactTurns`: the exact plain count (:class:`ExactPlain`) and the engine's count through a
   hub (:class:`ExactHub`) take turns, with relaxation Monte Carlo's first go
   (:class:`EarlyRelaxation`) after the second round;
2. :class:`RelaxationMonteCarlo`: that first estimate's draws go on when it stated an error wider than
   asked;
3. :class:`SequentialMonteCarlo`: each inclusion–exclusion term's estimate
   (:func:`~opportune.engine.estimate.estimate_count`: certain bounds, Knuth's estimator, sequential
   Monte Carlo runs); exact after all if every term was;
4. :class:`CertainBounds`: the terms' estimates joined into one interval, within the certain bounds
   on the union.

The time each phase gets and why is in :mod:`opportune.engine.tuning`.
"""

from __future__ import annotations

import enum
import math
import time
from dataclasses import dataclass, field, replace

from opportune.engine import tuning
from opportune.engine.deadline import BudgetExceeded, Deadline
from opportune.engine.result import CountResult, _signed_sum_log10

__all__ = ["PHASES", "CertainBounds", "CountQuestion", "EarlyRelaxation", "ExactHub", "ExactPlain", "ExactTurns",
           "PhaseResult", "RelaxationMonteCarlo", "SequentialMonteCarlo", "StopReason", "count_in_phases"]


class StopReason(enum.Enum):
    """Why a phase stopped: what :attr:`PhaseResult.stop` says.

    A reason is also found from its text: ``StopReason("time")`` is ``StopReason.OUT_OF_TIME``.

    Attributes
    ----------
    EXACT
        It counted exactly: the answer.
    OUT_OF_TIME
        Its deadline came first.
    OUT_OF_MEMORY
        Its memo budget ran out.
    ESTIMATED
        It stated an estimate (the answer, or a step towards it).
    SKIPPED
        It does not apply to this question.

    Raises
    ------
    ValueError
        Looking up a text that is no reason's.

    Examples
    --------
    >>> StopReason("time") is StopReason.OUT_OF_TIME, StopReason.EXACT.value
    (True, 'exact')
    >>> StopReason("late")
    Traceback (most recent call last):
    ...
    ValueError: 'late' is not a valid StopReason
    """

    EXACT = "exact"                 # it counted exactly: the answer
    OUT_OF_TIME = "time"            # its deadline came first
    OUT_OF_MEMORY = "memory"        # its memo budget ran out
    ESTIMATED = "estimated"         # it stated an estimate (the answer, or a step towards it)
    SKIPPED = "skipped"             # it does not apply to this question


@dataclass(slots=True)
class PhaseResult:
    """What a phase gives back: why it stopped, and the answer if it has one.

    Parameters
    ----------
    stop : StopReason
        Why the phase stopped.
    answer : CountResult or None, optional
        The count, if this phase has the answer (:func:`count_in_phases` returns the first).

    Examples
    --------
    >>> r = PhaseResult(StopReason.EXACT, CountResult(3))
    >>> r.stop.value, r.answer.value, PhaseResult(StopReason.SKIPPED).answer
    ('exact', 3, None)
    """

    stop: StopReason
    answer: CountResult | None = None


@dataclass(slots=True)
class CountQuestion:
    """One call of ``count_result``: the state asked about, the error asked, and what the phases
    leave for one another (the inclusion–exclusion terms, the first relaxation estimate, the terms'
    estimates).  Made by :meth:`ask`; the phases read and fill it.

    Parameters
    ----------
    schedule : Schedule
        The state asked about (:class:`~opportune.engine.schedule.Schedule`).
    rel_error : float
        The relative error an estimate aims at.
    seed : int
        Seed of the estimates' draws.
    threads : int
        Threads for relaxation Monte Carlo.
    start : float
        When the call began (a ``time.perf_counter()`` moment).
    end : Deadline
        The call's one deadline.
    terms : list or None
        The inclusion–exclusion terms, ``(sign, counter)`` each (None: they did not fit the time, or
        too many strategies; :meth:`grace` then takes the single strategies).
    remaining : int
        The units still to install (a bitmask).
    exact_end : float, default 0.0
        When the exact phases end (a ``time.perf_counter()`` moment).
    union_only : bool, default False
        True once the terms are the single strategies only: the answer is bounds on their union.
    early : Estimate or None, optional
        Relaxation Monte Carlo's first estimate, once made.
    ests : list of Estimate, optional
        Each term's estimate, in order, once made.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine.deadline import Deadline
    >>> from opportune.engine.schedule import Schedule
    >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
    >>> q = CountQuestion.ask(s, rel_error=0.01, time_limit=1.0, seed=0, exact_share=0.65,
    ...                       deadline=Deadline.NEVER, threads=1)
    >>> q.remaining == 0b111, len(q.terms), q.start < q.exact_end < q.end.at
    (True, 1, True)
    """

    schedule: object
    rel_error: float
    seed: int
    threads: int
    start: float
    end: Deadline
    terms: list | None
    remaining: int
    exact_end: float = 0.0
    union_only: bool = False
    early: object = None
    ests: list = field(default_factory=list)

    @classmethod
    def ask(cls, schedule, rel_error: float, time_limit: float, seed: int, exact_share: float,
            deadline: Deadline, threads: int) -> "CountQuestion":
        """The question of one ``count_result`` call: its deadline, its terms and when its exact
        phases end.

        The deadline is ``plain + time_limit`` seconds from now, or ``deadline`` if sooner, where
        ``plain`` is the engine's own time limit, or a tenth of ``time_limit``; the terms are built
        within it.

        Parameters
        ----------
        schedule : Schedule
            The state to count (:class:`~opportune.engine.schedule.Schedule`).
        rel_error : float
            The relative error an estimate aims at.
        time_limit : float
            Seconds beyond the engine's own exact time.
        seed : int
            Seed of the estimates' draws.
        exact_share : float
            The share of ``time_limit`` the exact phases may run.
        deadline : Deadline
            A moment to stop at if sooner (``Deadline.NEVER``: none).
        threads : int
            Threads for relaxation Monte Carlo.

        Returns
        -------
        CountQuestion
            The question, its terms None if they did not fit the deadline.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine.deadline import Deadline
        >>> from opportune.engine.schedule import Schedule
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> q = CountQuestion.ask(s, rel_error=0.01, time_limit=1.0, seed=0, exact_share=0.65,
        ...                       deadline=Deadline.NEVER, threads=1)
        >>> q.rel_error, round(q.end.remaining())      # 0.1 s of plain time + 1 s
        (0.01, 1)
        """
        start = time.perf_counter()
        engine = schedule.engine
        plain = engine.time_limit if engine.time_limit is not None else time_limit / 10
        end = deadline.within(plain + time_limit)
        try:
            terms = list(engine.terms(schedule.consistent, end))
        except BudgetExceeded:
            terms = None
        q = cls(schedule, rel_error, seed, threads, start, end, terms, engine.full & ~schedule.mask)
        if terms is not None:
            # the phases share what is left of the time (a caller's deadline may have taken some),
            # and the exact ones leave the estimate at least its one pass over each order
            # (ESTIMATE_RESERVE seconds per element: its bounds and first path)
            avail = max(0.0, end.remaining())
            scale = min(1.0, avail / (plain + time_limit)) if plain + time_limit > 0 else 0.0
            last = end.at - min(avail / 2, tuning.ESTIMATE_RESERVE * q.remaining.bit_count() * len(terms))
            q.exact_end = min(start + (plain + exact_share * time_limit) * scale, last)
        return q

    def grace(self) -> None:
        """Once the exact phases are over: the estimate gets at least ``GRACE`` seconds (its pass over
        the orders, if they are small), and without the terms, the single strategies.

        Changes the question in place: ``end`` moves to ``GRACE`` seconds from now if it was sooner;
        ``terms`` becomes one ``(1, counter)`` per consistent strategy if it was None
        (``union_only`` then True).

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine.deadline import Deadline
        >>> from opportune.engine.schedule import Schedule
        >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> q = CountQuestion.ask(s, rel_error=0.01, time_limit=1.0, seed=0, exact_share=0.65,
        ...                       deadline=Deadline.after(0.0), threads=1)
        >>> q.terms = None          # as when the terms did not fit the time
        >>> q.grace()
        >>> q.union_only, len(q.terms), q.end.remaining() > 0
        (True, 1, True)
        """
        if self.end.remaining() < tuning.GRACE:
            self.end = Deadline.after(tuning.GRACE)
        if self.terms is None:
            # too many strategies for inclusion–exclusion, or no time to build its terms: the union
            # lies between its largest strategy and the sum of them
            engine = self.schedule.engine
            self.terms = [(1, engine.counter(1 << s)) for s in range(engine.k) if self.schedule.consistent >> s & 1]
            self.union_only = True


def _exact_by(schedule, terms: list, remaining: int, until: float, plain_only: bool) -> CountResult:
    """One turn of :class:`ExactTurns`: every count of the engine stops at ``until``."""
    # the engine's deadline sets each count's time limit when it starts, and the counters' own
    # deadline holds whatever runs after that
    saved = [(c, c.deadline) for _, c in terms]
    for c, _ in saved:
        c.deadline = until
    try:
        with schedule.engine.time_limited(None), schedule.engine.deadline(until):
            if plain_only:      # each term's counter by itself (its own choice of method per piece)
                for _, c in terms:
                    c.count(remaining)
            return CountResult(schedule.count())
    finally:
        for c, d in saved:
            c.deadline = d


class ExactPlain:
    """One turn of the plain count: each term's counter by itself, choosing a method per hard piece."""

    plain_only = True

    def run(self, q: CountQuestion, deadline: Deadline) -> PhaseResult:
        try:
            return PhaseResult(StopReason.EXACT, _exact_by(q.schedule, q.terms, q.remaining, deadline.at,
                                                           self.plain_only))
        except BudgetExceeded as exc:
            # each call may add max_memo entries: a memo limit is not one turn after another
            return PhaseResult(StopReason.OUT_OF_TIME if exc.reason == "time" else StopReason.OUT_OF_MEMORY)


class ExactHub(ExactPlain):
    """One turn of the engine's count, which looks for a hub and counts through it
    (:meth:`~opportune.engine.exact.ExactCounting.count`)."""

    plain_only = False


class EarlyRelaxation:
    """Relaxation Monte Carlo's go inside the exact phases (one strategy), while a narrow interval is
    still possible, to a looser error than asked (``EARLY_ERROR``), for at most ``EARLY_SECONDS``: the
    later phases may narrow it, going on with its draws (its memos, at most relaxmc.MAX_BYTES, stay
    until count_result returns)."""

    def run(self, q: CountQuestion, deadline: Deadline) -> PhaseResult:
        from opportune.engine.estimate import relaxation_estimate

        q.early = relaxation_estimate(q.terms[0][1].poset, q.remaining, rel_error=max(q.rel_error, tuning.EARLY_ERROR),
                                      seed=q.seed, whole=False, count_share=tuning.EARLY_COUNT_SHARE,
                                      threads=q.threads, deadline=Deadline(min(deadline.at, time.perf_counter()
                                                                               + tuning.EARLY_SECONDS)))
        return PhaseResult(StopReason.SKIPPED if q.early is None else StopReason.ESTIMATED)


class ExactTurns:
    """The exact phases, until ``exact_end``: :class:`ExactPlain` and :class:`ExactHub` take turns,
    each resuming from its memos: ``FIRST_TURN`` seconds each, then twice as long at every round, the
    plain count a ``PLAIN_SHARE`` of the engine's turn once a hub is found.  After the second round
    (or when the memo budget ends the exact count), :class:`EarlyRelaxation`.  No turn's length
    depends on the time limit, which only cuts the sequence short: a count that finishes within a
    limit finishes at the same moment within any longer one (what a share of the limit did
    instead, measured: the documentation's page on time limits)."""

    exact = True
    turns = (ExactPlain(), ExactHub())

    def run(self, q: CountQuestion, deadline: Deadline) -> PhaseResult:
        if q.terms is None:
            return PhaseResult(StopReason.SKIPPED)
        engine = q.schedule.engine
        exact_end = deadline.at
        tried = over_memo = False
        turn = tuning.FIRST_TURN
        plain_only = True
        while True:
            now = time.perf_counter()
            hub = engine.hub_found_in(q.terms)
            seconds = turn * (tuning.PLAIN_SHARE if plain_only and hub else 1.0)
            # a deadline spent before the call (reading the plan) still leaves a small plan its exact
            # count: GRACE seconds, within COUNT_MARGIN
            until = min(now + seconds, exact_end)
            if turn == tuning.FIRST_TURN and plain_only:
                until = max(until, q.start + tuning.GRACE)
            stop = False
            if not (plain_only and over_memo):
                result = self.turns[not plain_only].run(q, Deadline(until))
                if result.stop is StopReason.EXACT:
                    return result
                if result.stop is StopReason.OUT_OF_MEMORY:
                    stop, over_memo = not plain_only, True
                if plain_only:
                    # the plain turn was the engine's probe of the plain count: its turn looks for a hub at once
                    for _, c in q.terms:
                        engine.end_probe(c)
            if time.perf_counter() >= exact_end:
                return PhaseResult(StopReason.OUT_OF_TIME)
            if not plain_only and (turn > tuning.FIRST_TURN or stop) and not tried and len(q.terms) == 1:
                tried = True
                EarlyRelaxation().run(q, Deadline(exact_end))
            if stop:
                return PhaseResult(StopReason.OUT_OF_MEMORY)
            if not plain_only:
                turn *= 2
            plain_only = not plain_only


class RelaxationMonteCarlo:
    """The first relaxation estimate's draws go on for ``EARLY_RESUME`` of the estimate phase, when it
    stated an error wider than asked (one strategy): its draws are the best use of the time."""

    exact = False

    def run(self, q: CountQuestion, deadline: Deadline) -> PhaseResult:
        early = q.early
        if early is None or early.resume is None or early.rel_error <= q.rel_error or len(q.terms) != 1:
            return PhaseResult(StopReason.SKIPPED)
        from opportune.engine.estimate import relaxation_estimate

        q.early = relaxation_estimate(q.terms[0][1].poset, q.remaining, rel_error=q.rel_error, seed=q.seed,
                                      resume=early, threads=q.threads,
                                      deadline=Deadline.after(tuning.EARLY_RESUME * max(0.0, deadline.remaining()))
                                      ) or early
        return PhaseResult(StopReason.ESTIMATED)


class SequentialMonteCarlo:
    """Each term's estimate (:func:`~opportune.engine.estimate.estimate_count`), sharing what is left:
    certain bounds from each order and Knuth's estimator from its first path on, then sequential Monte
    Carlo runs where they fit (fewer particles, down to 64, when time is short); without its own hub
    split if the exact phases looked for a hub already.  Exact after all if every term was."""

    exact = False

    def run(self, q: CountQuestion, deadline: Deadline) -> PhaseResult:
        from opportune.engine.estimate import estimate_count

        engine, terms, early, n = q.schedule.engine, q.terms, q.early, q.remaining.bit_count()
        exact: int | None = 0
        for i, (sign, counter) in enumerate(terms):
            share = deadline.share(1 / (len(terms) - i))
            seconds = max(0.0, share.remaining())
            # the hub split again only if the exact phases did not already look for a hub (found one,
            # found none, or were cut short in the search: a new split would start over with less time)
            hub = {"hub": 0.0} if engine.hub_looked_for(counter) else {}
            # fewer particles when time is short, so that two runs fit (a run of p particles on n
            # elements takes about SMC_COST p n^2 seconds: ARC111 with 1,024 particles ~3 s)
            particles = 1024
            while particles > 64 and tuning.SMC_COST * particles * n * n > seconds / 4:
                particles //= 2
            # each of k terms at confidence 1 - 0.05/k, so that all k intervals hold together with
            # probability at least 95% (a union bound); one term keeps the plain 95%
            est = estimate_count(counter.poset, q.remaining, rel_error=q.rel_error / max(1, len(terms)),
                                 time_limit=seconds / 2, overrun=math.inf, deadline=share, seed=q.seed,
                                 counter=counter, exact_memo=0, particles=particles,
                                 confidence=1 - 0.05 / len(terms), relaxation=early is not None
                                 and early.rel_error > q.rel_error, resume=early, threads=q.threads, **hub)
            if early is not None and est.exact is None and early.rel_error < est.rel_error:
                # the narrower stated interval, within the order's certain bounds
                est = replace(early, log10_low=max(early.log10_low, est.log10_low),
                              log10_high=min(early.log10_high, est.log10_high))
            q.ests.append(est)
            exact = None if exact is None or est.exact is None else exact + sign * est.exact
        if exact is not None and not q.union_only:    # every term was counted exactly after all (through a hub)
            return PhaseResult(StopReason.EXACT, CountResult(exact))
        return PhaseResult(StopReason.ESTIMATED)


class CertainBounds:
    """The terms' estimates joined: certain bounds on the union (at least its largest strategy's count,
    at most the sum of them and, with every term, the inclusion–exclusion sum of the terms' bounds;
    at most n! whatever the orders), the stated interval within them.  Always an answer."""

    exact = False

    def run(self, q: CountQuestion, deadline: Deadline) -> PhaseResult:
        ests, n = q.ests, q.remaining.bit_count()
        singles = q.schedule.consistent.bit_count()
        missed = sum(1 - e.confidence for e in ests if e.rel_error > 0 and e.exact is None)
        low = max(e.log10_low for e in ests[:singles])
        high = _signed_sum_log10([(1, e.log10_high, 0.0) for e in ests[:singles]])[0]
        if q.union_only:
            log10, rel = max(e.log10_value for e in ests[:singles]), math.inf
        else:
            both = _signed_sum_log10([(sign, e.log10_high if sign > 0 else e.log10_low, 0.0)
                                      for (sign, _), e in zip(q.terms, ests)])[0]
            if not math.isnan(both):
                high = min(high, both)
            # the intervals of the terms add up; they all hold at once with probability >= 1 - sum(misses)
            log10, rel = _signed_sum_log10([(sign, e.log10_value, e.rel_error) for (sign, _), e in zip(q.terms, ests)])
        high = max(low, min(high, math.lgamma(n + 1) / math.log(10)))
        if math.isnan(log10):
            log10, rel = (low + high) / 2, math.inf
        log10 = min(max(log10, low), high)
        lo, hi = low, high
        if rel < 1:
            lo = max(low, min(high, log10 + math.log10(1 - rel)))
        if math.isfinite(rel):
            hi = min(high, max(low, log10 + math.log10(1 + rel)))
        methods = "+".join(sorted({e.method for e in ests}))
        return PhaseResult(StopReason.ESTIMATED, CountResult(
            10.0 ** log10 if log10 < 308 else math.inf, exact=False, rel_error=rel, confidence=max(0.0, 1 - missed),
            method=("union:" if q.union_only else "") + methods, log10_value=log10, log10_low=lo, log10_high=hi))


#: The phases of ``count_result``, in order.
PHASES = (ExactTurns(), RelaxationMonteCarlo(), SequentialMonteCarlo(), CertainBounds())


def count_in_phases(q: CountQuestion) -> CountResult:
    """Run :data:`PHASES` on ``q`` in order: the first answer is the count.

    The exact phases end at ``q.exact_end``, the others at ``q.end`` (at least ``GRACE`` seconds after
    the exact ones).  What ``Schedule.count_result`` does with an estimate allowed.

    Parameters
    ----------
    q : CountQuestion
        The question (:meth:`CountQuestion.ask`); the phases fill it as they go.

    Returns
    -------
    CountResult
        The first answer a phase gives: exact, or an estimate with its interval
        (:class:`CertainBounds` always answers).

    Raises
    ------
    AssertionError
        Never with :data:`PHASES` as they are: only if no phase answered (a guard, should the last
        phase ever be one that may not answer).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine.deadline import Deadline
    >>> from opportune.engine.schedule import Schedule
    >>> s = Schedule(make_plan(["a", "b", "c"], {"c": ["a"]}))
    >>> q = CountQuestion.ask(s, rel_error=0.01, time_limit=1.0, seed=0, exact_share=0.65,
    ...                       deadline=Deadline.NEVER, threads=1)
    >>> r = count_in_phases(q)
    >>> r.value, r.exact
    (3, True)
    """
    for phase in PHASES:
        if phase.exact:
            result = phase.run(q, Deadline(q.exact_end))
        else:
            result = phase.run(q, q.end)
        if result.answer is not None:
            return result.answer
        if phase.exact:
            q.grace()
    raise AssertionError("CertainBounds always answers")   # pragma: no cover
