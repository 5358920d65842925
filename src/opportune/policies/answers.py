"""The answering layer: what a count-based rule asks at a look, answered exactly when the counts fit
the decision budget and by estimate otherwise, each answer saying how sure it is.

A rule (the paper's, ``bin-first``, ``slack``: :mod:`~opportune.policies.opportunistic`,
:mod:`~opportune.policies.variants`) is a short function of an :class:`Answers`: it asks for the
installable parts, each candidate's options (completions kept after installing it), the visible
parts' expected positions or slack, and names its choice with :meth:`Answers.pick`.  It holds no
budget, clock or estimate: a :class:`CountBasedRule` (the class those rules derive from) runs it
over answers of one kind at a time and keeps what it learns from look to look.

Answers come in four kinds (``Answers.mode``):

* ``"order"``: only what needs no counting (one candidate, one part to buffer, or what the partial
  order alone settles, :mod:`opportune.engine.dominance`); anything else raises :class:`MustCount`;
* ``"exact"``: exact counts, the order's shortcuts first unless ``order_first=False`` (within the
  engine's deadline, if the caller set one: :class:`~opportune.engine.deadline.BudgetExceeded`);
* ``"estimate"``: from a population of random completions
  (:class:`~opportune.engine.sampling.CompletionChains`), run until ``end`` or until sure;
* ``"then"``: a question asked after the rule has decided (the slack after the paper's buffer
  choice): exact if that fits a share of the budget, else estimated with what is left, else
  unanswered (None).

With a decision budget (seconds per decision) the rule is applied to exact counts when they fit a
share of the budget, and otherwise to estimates that fill the rest of it.  The decision then says
so: ``exact=False``, the method, each candidate's estimated share of completions or expected
position with its standard error, and the estimated probability that the action is the exact
rule's.  An estimate ends early, keeping the rest of the budget, once it is sure (that probability
at least :data:`SURE`) or once, as surely, no other candidate is better by more than
:data:`INDIFFERENT` (of the best share of options, or of the steps remaining for an expected
position): candidates that close are a toss-up the samples would take the whole budget to settle,
for no measurable difference in the outcome.  The chains' readings at a state are kept from look to
look while nothing is installed, so a run of buffer choices builds on itself.  Steps that are
interchangeable in the state (the same predecessors and successors among what remains) have equal
exact values, so estimates treat them as tied and the exact tie-breaks decide between them.

Exact counts first while they have been quick; where they have been slow (a large plan's early
states), a short estimate (a probe) first, which ends the decision if it settles it, then the exact
attempt, then the estimate again with what is left of the budget.  How slow exact attempts have
been is kept per kind of question and per band of :data:`SIZE_BAND` steps remaining (the readings):
on an assembly the cost of exact counts follows how far it has come (docs/decisions.md gives
ARC111's measurements), so each trial's early states
learn from the last trial's early states rather than from its late ones.

>>> from opportune import make_plan
>>> from opportune.engine import OrderEngine
>>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
>>> ask = Answers(engine, 0, engine.all_strategies, (), 1.0, ("a", "b"))
>>> ask.installable(), ask.options(["a", "b"])      # the order alone: a keeps more (the best, tied at 0)
(['a', 'b'], {'a': 0})
>>> Answers(engine, 0, engine.all_strategies, (), 1.0, ("a", "b"), order_first=False).options(["a", "b"])
{'a': 2, 'b': 1}
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from opportune.engine import Schedule
from opportune.engine.deadline import BudgetExceeded
from opportune.engine.dominance import earliest_by_order, most_options_by_order
from opportune.engine.stats import prob_positive
from opportune.policies.base import (
    DONE,
    INDIFFERENT,
    SHAKE,
    SURE,
    Action,
    Candidate,
    DecidesOnMasks,
    Decision,
    Estimate,
    pause_collector,
    resume_collector,
    shared_action,
)

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.engine.sampling import CompletionChains   # made by Schedule.chains

MARGIN = 0.1            # share of the budget kept for building the answer after the estimate
EXACT_SHARE = (0.25, 0.6)  # share of the budget the exact attempt gets (after a failure, after a success)
# SURE (0.999): an estimate this sure of its choice stops early, keeping the rest of the budget (policies.base)
MIXED_STEPS = 20       # moves per chain, per step remaining, before an early stop is trusted
EXACT_FIRST = 0.2      # exact attempts first while they have taken under this share of the budget
PROBE_SHARE = 0.3      # else a first estimate gets this share (and ends the decision if it is sure)
SLOW_WEIGHT = 0.3      # weight of the last exact attempt in the moving average of their time
SLOW_DECAY = 0.97      # that average shrinks after each sure estimate, so exact counts are tried again
SIZE_BAND = 5          # ... kept per band of this many steps remaining
# INDIFFERENT (0.01): estimates stop once no other candidate is better by more than this (policies.base)
FAILING = 0.4          # an average above this share of the budget: exact attempts have been failing there
#: With a question after the rule (:meth:`CountBasedRule.then`): the share of the budget the rule gets,
#: and the share the exact answer to the question may take before it is estimated with what is left.
THEN_SHARES = (0.6, 0.3)

MODES = ("order", "exact", "estimate", "then")


class MustCount(Exception):
    """A question that needs counting, asked of answers that may not count (``mode="order"``)."""

    def __init__(self, kind: str):
        super().__init__(kind)
        self.kind = kind        # "install" (options) or "buffer" (positions, slack)


@dataclass(frozen=True)
class How:
    """How a choice was reached: exact, or which estimates and how sure.

    Parameters
    ----------
    exact : bool, default True
        Decided on exact numbers.
    method : str, default "exact"
        The estimate's method otherwise.
    estimates : tuple of Estimate, default ()
        The estimates that decided.
    confidence : float, default 1.0
        The estimated probability that the choice is the exact rule's.
    note : str, default ""
        More about the choice.
    close : bool, default False
        Estimated: no other candidate better by more than :data:`INDIFFERENT`
        (:meth:`Decision.certainty <opportune.policies.base.Decision.certainty>`).

    Examples
    --------
    >>> How().settled, How(exact=False, method="mcmc", confidence=0.5).settled
    (True, False)
    """

    exact: bool = True
    method: str = "exact"
    estimates: tuple[Estimate, ...] = ()
    confidence: float = 1.0
    note: str = ""
    close: bool = False     # estimated: no other candidate better by more than INDIFFERENT (Decision.certainty)

    @property
    def settled(self) -> bool:
        """Exact, or an estimate sure enough to end the decision."""
        return self.exact or self.confidence >= SURE or self.close


EXACT = How()


class Readings:
    """What a policy keeps from decision to decision: the population of chains (carried on while the
    state only moves forward), the exact attempts' shares of the budget per kind of question, the moving
    average of their seconds and the share of probes that settled, per kind and band of steps remaining."""

    def __init__(self, seed: int, chains: int):
        self.seed = seed
        self.chains = chains
        self.population: tuple | None = None   # (engine, strategy, CompletionChains)
        self.starts = 0
        self.share = {"install": EXACT_SHARE[1], "buffer": EXACT_SHARE[1]}
        self.slow: dict[tuple[str, int], float] = {}
        self.probe_ok: dict[tuple[str, int], float] = {}

    def population_for(self, engine, mask: int, consistent: int, candidates=()) -> tuple[CompletionChains, str]:
        """The population of chains for this state: carried on from the last look if the state
        only moved forward, else started afresh.  With several consistent strategies the chains follow
        the one in which most ``candidates`` (units) can come next (the current one on a tie)."""
        strategies = [s for s in range(engine.k) if consistent >> s & 1]
        strategy = strategies[0]
        if len(strategies) > 1 and candidates:
            remaining = engine.full & ~mask
            current = self.population[1] if self.population and self.population[0] is engine else None
            strategy = max(strategies, key=lambda s: (
                sum(not engine.posets[s].below[u] & remaining for u in candidates), s == current, -s))
        note = ""
        if len(strategies) > 1:   # the chains follow one order: say which
            note = f"estimated on strategy '{engine.plan.strategies[strategy].name}' alone"
        remaining = engine.full & ~mask
        pop = self.population
        if pop is None or pop[0] is not engine or pop[1] != strategy or remaining & ~pop[2].remaining:
            self.starts += 1
            chains = Schedule.at(engine, mask, consistent).chains(strategy, chains=self.chains,
                                                                  seed=self.seed * 1_000_003 + self.starts)
            self.population = pop = (engine, strategy, chains)
        else:
            pop[2].advance(remaining)
        return pop[2], note


class Answers:
    """The answers to a rule's questions at one look.

    After the rule, :meth:`how` says how sure its choice is.  Each question costs what its count costs
    (the engine's memos), or the estimate's time.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask : int
        The installed units, as the engine's bit mask.
    consistent : int
        The strategies still consistent, as a bit mask.
    buffer : tuple of str
        The buffered parts, in buffer order.
    free : float
        Free buffer locations (``math.inf``: unlimited).
    visible : tuple of str
        The look.
    mode : {"order", "exact", "estimate", "then"}, default "exact"
        The kind of answers (see the module's text): what needs no counting, exact counts,
        estimates, or a question asked after the rule.
    order_first : bool, default True
        Exact answers try what the partial order alone settles before counting.
    readings : Readings, optional
        In the estimate modes, the chains kept from look to look (``None``: a population of its own).
    end : float, default math.inf
        In the estimate modes, the clock time (``time.perf_counter``) the estimate stops by.
    stop_when_sure : bool, default True
        An estimate stops early once it is sure of its choice.
    after : How, default EXACT
        In mode ``"then"``: how the rule decided.
    exact_seconds : float, default math.inf
        In mode ``"then"``: the seconds the exact answer may take.

    Raises
    ------
    ValueError
        If ``mode`` is not one of :data:`MODES`.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
    >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
    >>> ask.installable(), ask.options(["a", "b"])
    (['a', 'b'], {'a': 0})
    """

    __slots__ = (
        "_record",
        "after",
        "buffer",
        "consistent",
        "end",
        "engine",
        "exact_seconds",
        "free",
        "mask",
        "mode",
        "order_first",
        "readings",
        "stop_when_sure",
        "visible",
    )

    def __init__(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                 visible: tuple[str, ...], *, mode: str = "exact", order_first: bool = True,
                 readings: Readings | None = None, end: float = math.inf, stop_when_sure: bool = True,
                 after: How = EXACT, exact_seconds: float = math.inf):
        self.engine, self.mask, self.consistent = engine, mask, consistent
        self.buffer, self.free, self.visible = buffer, free, visible
        self.mode, self.order_first = mode, order_first
        if readings is None and mode in ("estimate", "then"):
            readings = Readings(0, 8)   # a population of its own (a policy passes the one it keeps)
        self.readings, self.end, self.stop_when_sure = readings, end, stop_when_sure
        if mode not in MODES:
            raise ValueError(f"answers are asked in one of the modes {', '.join(MODES)}, not {mode!r}")
        # "then": how the rule decided, and the seconds the exact answer may take
        self.after, self.exact_seconds = after, exact_seconds
        # the estimate that decided, for how(); shared with without_buffer() (exact answers need none)
        self._record: dict | None = {} if mode in ("estimate", "then") else None

    # ------------------------------------------------------------ the state

    @property
    def schedule(self) -> Schedule:
        """The state as a :class:`~opportune.engine.Schedule`: every exact count goes through it."""
        return Schedule.at(self.engine, self.mask, self.consistent)

    @property
    def complete(self) -> bool:
        return self.mask == self.engine.full

    def installable(self) -> list[str]:
        """The installable parts among the visible and the buffered ones.

        Returns
        -------
        list of str
            The candidates.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.installable()
        ['a', 'b']
        """
        return self.engine.installable_among(self.mask, self.consistent, (*self.visible, *self.buffer))

    def installable_in_bin(self) -> list[str]:
        """The installable parts among the visible ones.

        Returns
        -------
        list of str
            The bin's candidates.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.installable_in_bin()
        ['a']
        """
        return self.engine.installable_among(self.mask, self.consistent, self.visible)

    def visible_parts(self) -> list[str]:
        """The visible parts, each once, in the look's order.

        Returns
        -------
        list of str
            The parts.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.visible_parts()
        ['a', 'c']
        """
        return list(dict.fromkeys(self.visible))

    def without_buffer(self) -> Answers:
        """The same answers with the buffered parts out of sight (the bin's candidates only).

        Returns
        -------
        Answers
            Answers of the same mode, sharing what the estimates record.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.without_buffer().installable()
        ['a']
        """
        other = Answers(self.engine, self.mask, self.consistent, (), self.free, self.visible, mode=self.mode,
                        order_first=self.order_first, readings=self.readings, end=self.end,
                        stop_when_sure=self.stop_when_sure, after=self.after, exact_seconds=self.exact_seconds)
        other._record = self._record
        return other

    def index(self, part: str) -> int:
        """A part's declaration position (the last tie-break of every rule).

        Parameters
        ----------
        part : str
            The part.

        Returns
        -------
        int
            Its position in the plan.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.index("c")
        2
        """
        return self.engine.plan.index(part)

    def cost(self, part: str) -> float:
        """A part's handling cost, acquire + install (a tie-break).

        Parameters
        ----------
        part : str
            The part.

        Returns
        -------
        float
            The cost of one unit.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.cost("c")
        2.0
        """
        return self.engine.plan.part(part).cost

    def _settled(self, parts: list[str], rule) -> list[str] | None:
        """The parts the order alone proves best under ``rule`` (see :mod:`opportune.engine.dominance`),
        or None: only with one consistent strategy (a union's counts do not follow one order)."""
        consistent, engine = self.consistent, self.engine
        if consistent & (consistent - 1) or not engine.posets:     # (a plan written as ways has no order)
            return None
        unit_of = {engine.next_unit(self.mask, self.index(p)): p for p in parts}
        best = rule(engine.posets[consistent.bit_length() - 1], engine.full & ~self.mask, list(unit_of))
        return None if best is None else [unit_of[u] for u in best]

    # ------------------------------------------------------------ the questions

    def options(self, parts: list[str]) -> dict:
        """Each candidate's options: the completions left after installing it.

        Exact answers are counts, and may hold only the best parts, tied at 0, where that is all the
        order alone proves (or the one part asked); estimated answers are shares of the completions
        (0.0 for a part that cannot come next in the chains' strategy).

        Parameters
        ----------
        parts : list of str
            Installable candidates.

        Returns
        -------
        dict of str to int or float
            Each part's options, or share.

        Raises
        ------
        MustCount
            In mode ``"order"``, when the order alone does not settle it.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.options(["a", "b"])
        {'a': 0}
        >>> Answers(engine, 0, engine.all_strategies, (), 1.0, ("a", "b"), order_first=False).options(["a", "b"])
        {'a': 3, 'b': 1}
        """
        if self.mode == "estimate":
            return self._estimated_options(parts)
        known = self._uncounted(parts, most_options_by_order, "install")
        return known if known is not None else self.schedule.options_for(parts)

    def positions(self, parts: list[str]) -> dict:
        """Each part's expected position in a uniformly random completion (1 = next).

        Exact as the sum of its positions over all completions (one denominator, so the same order), or
        estimated; exact answers may hold only the earliest parts, tied, as for :meth:`options`.

        Parameters
        ----------
        parts : list of str
            Visible parts.

        Returns
        -------
        dict of str to int or float
            Each part's position sum (exact) or expected position (estimated).

        Raises
        ------
        MustCount
            In mode ``"order"``, when the order alone does not settle it.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> answers = Answers(engine, 0, engine.all_strategies, (), 1.0, ("a", "b"), order_first=False)
        >>> sorted(answers.positions(["a", "b"]).items())
        [('a', 5), ('b', 10)]
        """
        if self.mode == "estimate":
            return self._estimated_positions(parts)
        known = self._uncounted(parts, earliest_by_order, "buffer")
        return known if known is not None else self.schedule.position_sums_for(set(parts))[1]

    def _uncounted(self, parts: list[str], by_order, kind: str) -> dict | None:
        """What needs no count: the one part asked (nothing to compare), or the best parts the order alone
        proves (``by_order``), tied at 0; else None, or :class:`MustCount` where answers may not count."""
        if len(parts) == 1:
            return {parts[0]: 0}
        if self.order_first:
            settled = self._settled(parts, by_order)
            if settled is not None:
                return dict.fromkeys(settled, 0)
        if self.mode == "order":
            raise MustCount(kind)
        return None

    def slack(self, parts: list[str], weight: float) -> dict | None:
        """Each part's slack: expected position, minus the installs still needed before it can go in, minus
        ``weight`` times the steps that wait on it (with several strategies open, under the one that
        frees it soonest).

        Asked after the rule (``mode="then"``): exact if it fits, else estimated with what is left,
        else None.

        Parameters
        ----------
        parts : list of str
            Visible parts.
        weight : float
            The weight of the steps that wait on a part.

        Returns
        -------
        dict of str to float, or None
            Each part's slack; ``None`` when no time is left (mode ``"then"``).

        Raises
        ------
        MustCount
            In mode ``"order"``.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.slack(["c"], 0.1)
        {'c': 1.4}
        """
        if self.mode == "order":
            raise MustCount("buffer")
        if self.mode == "estimate":
            return self._estimated_slack(parts, weight)
        if self.mode == "exact":
            return self._exact_slack(parts, weight)
        if self.after.exact:    # else the rule's positions did not fit just now: the slack's will not either
            try:
                with self.engine.deadline(min(self.end, time.perf_counter() + self.exact_seconds)):
                    return self._exact_slack(parts, weight)
            except BudgetExceeded:
                pass
        if time.perf_counter() >= self.end:
            return None
        return self._estimated_slack(parts, weight)

    def pick(self, kind: str, ranked: list[tuple[str, str | None]]) -> Action:
        """The action for the first of ``ranked``: the rule's choice.

        Estimated answers keep the ranking to say how sure the choice is (:meth:`how`).

        Parameters
        ----------
        kind : {"install", "buffer"}
            The action's kind.
        ranked : list of (str, str or None)
            ``(part, source)``, best first.

        Returns
        -------
        Action
            The action for the first.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.pick("install", [("a", "bin"), ("b", "buffer")])
        Action(kind='install', part='a', source='bin')
        """
        if self._record is not None:
            self._record["ranked"] = ranked
        part, source = ranked[0]
        return shared_action(kind, part, source)

    def how(self) -> How:
        """How the rule's choice was reached: exact, or the estimate that decided with its confidence.

        Returns
        -------
        How
            :data:`EXACT` when nothing was estimated.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"c": ["a"], "d": ["c"]}))
        >>> ask = Answers(engine, 0, engine.all_strategies, ("b",), 1.0, ("a", "c", "a"))
        >>> ask.pick("install", [("a", "bin")]).part, ask.how().exact
        ('a', True)
        """
        rec = self._record
        if not rec or "how" not in rec:     # nothing was estimated
            return self.after
        return rec["how"](rec["ranked"])

    # ------------------------------------------------------------ exact

    def _needed_after(self, part: str) -> tuple[int, int]:
        """The installs still needed before ``part`` can go in, and the steps that wait on it (under the
        consistent strategy that frees it soonest)."""
        engine, remaining = self.engine, self.engine.full & ~self.mask
        posets = [engine.posets[i] for i in range(engine.k) if self.consistent >> i & 1]
        u = engine.next_unit(self.mask, self.index(part))
        return (min((p.below[u] & remaining).bit_count() for p in posets),
                min((p.above[u] & remaining).bit_count() for p in posets))

    def _exact_slack(self, parts, weight: float) -> dict:
        total, sums = self.schedule.position_sums_for(set(parts))
        out = {}
        for part, s in sums.items():
            needed, after = self._needed_after(part)
            out[part] = s / total - needed - weight * after
        return out

    # ------------------------------------------------------------ estimated

    def _estimated_options(self, can: list[str]) -> dict:
        engine, mask = self.engine, self.mask
        remaining = engine.full & ~mask
        units = {p: engine.next_unit(mask, self.index(p)) for p in can}
        chains, note = self.readings.population_for(engine, mask, self.consistent, tuple(units.values()))
        # a candidate that cannot come next in the chains' strategy has no share there
        first = {p: u for p, u in units.items() if not chains.below[u] & remaining}

        def sure(e):   # the best so far is the exact rule's choice, or none other is better by the margin
            if not _mixed(chains):
                return False
            v = _tied_means(chains, remaining, first, e.first)
            top = max(first, key=v.__getitem__)
            return (_confidence(e, "first", first, top, chains, remaining, higher=True) >= SURE or
                    _confidence(e, "first", first, top, chains, remaining, higher=True,
                                margin=INDIFFERENT * v[top]) >= SURE)

        est = chains.estimate(first=set(first.values()), deadline=self.end, clock=time.perf_counter,
                              settled=sure if self.stop_when_sure else None, keep=True)
        value = {p: 0.0 for p in can} | _tied_means(chains, remaining, first, est.first)

        def how(ranked) -> How:
            best = ranked[0][0]
            conf = _confidence(est, "first", first, best, chains, remaining, higher=True)
            close = conf < SURE and best in first and _confidence(
                est, "first", first, best, chains, remaining, higher=True, margin=INDIFFERENT * value[best]) >= SURE
            estimates = tuple(Estimate(part, "share", value[part], est.first[first[part]][1] if part in first else 0.0,
                                       source) for part, source in ranked)
            return How(False, "mcmc", estimates, conf, note, close)

        self._record.update(how=how, ranked=None)
        return value

    def _estimated_positions(self, parts: list[str]) -> dict:
        engine, mask = self.engine, self.mask
        remaining = engine.full & ~mask
        chains, note = self.readings.population_for(engine, mask, self.consistent)
        at = {p: engine.next_unit(mask, self.index(p)) for p in parts}
        margin = INDIFFERENT * remaining.bit_count()

        def sure(e):
            if not _mixed(chains):
                return False
            v = _tied_means(chains, remaining, at, e.positions)
            top = min(parts, key=v.__getitem__)
            return (_confidence(e, "positions", at, top, chains, remaining, higher=False) >= SURE or
                    _confidence(e, "positions", at, top, chains, remaining, higher=False, margin=margin) >= SURE)

        est = chains.estimate(positions=set(at.values()), deadline=self.end, clock=time.perf_counter,
                              settled=sure if self.stop_when_sure else None, keep=True)
        value = _tied_means(chains, remaining, at, est.positions)

        def how(ranked) -> How:
            best = ranked[0][0]
            conf = _confidence(est, "positions", at, best, chains, remaining, higher=False)
            close = conf < SURE and _confidence(est, "positions", at, best, chains, remaining, higher=False,
                                                margin=margin) >= SURE
            estimates = tuple(Estimate(p, "position", value[p], est.positions[at[p]][1]) for p, _ in ranked)
            return How(False, "mcmc", estimates, conf, note, close)

        self._record.update(how=how, ranked=None)
        return value

    def _estimated_slack(self, parts: list[str], weight: float) -> dict:
        """The slack with the expected positions estimated by the population of chains, until ``end`` or
        until sure."""
        engine, mask = self.engine, self.mask
        chains, note = self.readings.population_for(engine, mask, self.consistent)
        at = {p: engine.next_unit(mask, self.index(p)) for p in parts}
        offset = {}
        for part in parts:
            needed, after = self._needed_after(part)
            offset[part] = -needed - weight * after
        index = self.index

        def best_of(e):
            return min(parts, key=lambda p: (e.positions[at[p]][0] + offset[p], index(p)))

        margin = INDIFFERENT * (engine.full & ~mask).bit_count()

        def confidence(e, best, margin=0.0):
            """P(``best`` has the least slack), or with ``margin``: P(no other part's slack is less by
            more than ``margin``); paired over the chains, a union bound over the parts."""
            miss = 0.0
            for p in parts:
                if p != best:   # slack of p - slack of best, per chain
                    diffs = [x - y + offset[p] - offset[best] for x, y in
                             zip(e.per_chain["positions"][at[p]], e.per_chain["positions"][at[best]])]
                    miss += prob_positive([-d - margin for d in diffs]) if margin else 1 - prob_positive(diffs)
            return max(0.0, 1 - miss)

        est = chains.estimate(positions=set(at.values()), deadline=self.end, clock=time.perf_counter, keep=True,
                              settled=lambda e: _mixed(chains) and (confidence(e, best_of(e)) >= SURE or
                                                                    confidence(e, best_of(e), margin) >= SURE))
        value = {p: est.positions[at[p]][0] + offset[p] for p in parts}

        def how(ranked) -> How:
            best = ranked[0][0]
            estimates = tuple(Estimate(p, "slack", value[p], est.positions[at[p]][1]) for p, _ in ranked)
            conf = confidence(est, best)
            close = conf < SURE and confidence(est, best, margin) >= SURE
            return How(False, "mcmc", estimates, conf, note, close)

        self._record.update(how=how, ranked=None)
        return value



def _mixed(chains: CompletionChains) -> bool:
    """Whether the population has run long enough for its errors to be trusted when stopping early
    (a population just started from spread-out, not uniform, sequences has not)."""
    return chains.steps >= MIXED_STEPS * max(1, chains.remaining.bit_count())


def _signature(chains: CompletionChains, remaining: int, unit: int) -> tuple[int, int]:
    return chains.below[unit] & remaining, chains.above[unit] & remaining


def _tied_means(chains, remaining: int, unit_of: dict, estimates: dict) -> dict:
    """Each part's estimate, averaged over the parts interchangeable with it in this state
    (equal exact values: the exact tie-breaks then decide between them, as in the exact rule)."""
    groups: dict[tuple, list] = {}
    for part, u in unit_of.items():
        groups.setdefault(_signature(chains, remaining, u), []).append(part)
    out = {}
    for members in groups.values():
        mean = sum(estimates[unit_of[p]][0] for p in members) / len(members)
        for p in members:
            out[p] = mean
    return out


def _confidence(est, kind: str, unit_of: dict, best: str, chains, remaining: int, *, higher: bool,
                margin: float = 0.0) -> float:
    """Estimated probability that ``best`` is the exact rule's choice: every other part (not
    interchangeable with it) is truly worse; a union bound over them (paired over the chains).
    With ``margin``: that no other part is better than ``best`` by more than ``margin``."""
    ub = unit_of[best]
    sig = _signature(chains, remaining, ub)
    miss = 0.0
    seen = set()
    for u in unit_of.values():
        if u == ub or u in seen or _signature(chains, remaining, u) == sig:
            continue
        seen.add(u)
        if margin:
            miss += est.prob_greater(kind, u, ub, margin) if higher else est.prob_greater(kind, ub, u, margin)
        else:
            miss += 1 - (est.prob_greater(kind, ub, u) if higher else est.prob_greater(kind, u, ub))
    return max(0.0, 1 - miss)


class CountBasedRule(DecidesOnMasks):
    """A policy whose rule is a function of :class:`Answers` (:meth:`rule`, and optionally a question
    after it, :meth:`then`), decided exactly or within ``budget`` seconds per decision.

    A rule with a question after it gets :data:`THEN_SHARES`\\ ``[0]`` of the budget (``budget``; the
    whole is ``total_budget``).  A decision costs what its answers cost; within a budget, at most
    about the budget (the estimates' and counts' checks of the clock, and building the reasons, are
    the rest).

    Parameters
    ----------
    budget : float, optional
        Seconds per decision (``None``: always exact, however long it takes).
    seed : int, default 0
        With a budget, the seed of the estimates' random streams.
    chains : int, default 8
        With a budget, the estimates' population of chains.

    Raises
    ------
    ValueError
        If ``budget`` is not a positive number of seconds.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> from opportune.policies.variants import Slack
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
    >>> p = Slack(budget=0.05)
    >>> p.choose_at(engine, 0, engine.all_strategies, (), 1.0, ("b", "a")), p.total_budget, round(p.budget, 3)
    (Action(kind='install', part='a', source='bin'), 0.05, 0.03)
    """

    #: The rules in words, as the decisions give them.
    rule_install = ""
    rule_buffer = ""
    #: With a question after the rule: the share of the whole budget its exact answer may take.
    EXACT_SLACK_SHARE = THEN_SHARES[1]

    def __init__(self, budget: float | None = None, *, seed: int = 0, chains: int = 8):
        if budget is not None and not budget > 0:
            raise ValueError("the decision budget must be a positive number of seconds (or None)")
        self.total_budget = budget
        # the rule's share, so that with the question after it the decision keeps the whole budget
        self.budget = budget * THEN_SHARES[0] if budget is not None and self._asks_after() else budget
        self.seed = seed
        self.chains = chains
        # Exact decisions depend only on the state and the look, so a simulation may cache them.
        self.deterministic = budget is None
        self.readings = Readings(seed, chains)

    @classmethod
    def _asks_after(cls) -> bool:
        return cls.then is not CountBasedRule.then

    def rule(self, ask: Answers) -> Action:
        """The action, from the answers to the rule's questions.

        Parameters
        ----------
        ask : Answers
            The answering layer for the state and look: exact counts, or estimates within the budget.

        Returns
        -------
        Action
            The rule's action.

        Raises
        ------
        NotImplementedError
            In this base class: each policy defines its rule.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> Opportunistic().rule(Answers(engine, 0, engine.all_strategies, (), 1.0, ("b", "a")))
        Action(kind='install', part='a', source='bin')
        """
        raise NotImplementedError

    def then(self, ask: Answers, action: Action) -> Action:
        """The action after a question asked once the rule has decided (none here: the rule's action).

        Parameters
        ----------
        ask : Answers
            The same answers the rule had.
        action : Action
            The rule's action.

        Returns
        -------
        Action
            The action decided.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> engine = OrderEngine(make_plan(["a", "b"], {}))
        >>> Opportunistic().then(Answers(engine, 0, 1, (), 1.0, ("a",)), Action("shake"))
        Action(kind='shake', part=None, source=None)
        """
        return action

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        """The action on the machine form of a state: exact, or within the budget.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask : int
            The installed units, as the engine's bit mask.
        consistent : int
            The strategies still consistent, as a bit mask.
        buffer : tuple of str
            The buffered parts, in the order they were buffered.
        free : float
            Free buffer locations (``math.inf``: unlimited).
        visible : tuple of str
            The look.

        Returns
        -------
        Action
            The action (no reasons: :meth:`decide` gives them).

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> Opportunistic().choose_at(engine, 0, engine.all_strategies, (), 1.0, ("c",))
        Action(kind='buffer', part='c', source=None)
        """
        return self._how(engine, mask, consistent, buffer, free, visible)[0]

    def _how(self, engine, mask, consistent, buffer, free, visible) -> tuple[Action, How]:
        """The action and how it was reached, for ``choose_at`` and ``decide`` alike."""
        if self.total_budget is None:
            ask = Answers(engine, mask, consistent, buffer, free, visible)
            return self.then(ask, self.rule(ask)), EXACT
        return self._budgeted(engine, mask, consistent, buffer, free, visible)

    def _budgeted(self, engine, mask, consistent, buffer, free, visible) -> tuple[Action, How]:
        """The rule within the budget (:meth:`_within_budget`), then its question after, with the garbage
        collector paused: a collection waits for the next look (see
        :func:`~opportune.policies.base.pause_collector`)."""
        pause_collector()       # before anything allocates, resumed after the answer is built
        try:
            start = time.perf_counter()
            action, how = self._within_budget(engine, mask, consistent, buffer, free, visible)
            if not self._asks_after():
                return action, how
            ask = Answers(engine, mask, consistent, buffer, free, visible, mode="then", readings=self.readings,
                          end=start + self.total_budget * (1 - MARGIN), after=how,
                          exact_seconds=self.total_budget * self.EXACT_SLACK_SHARE)
            action = self.then(ask, action)
            return action, ask.how()
        finally:
            resume_collector()

    def _within_budget(self, engine, mask, consistent, buffer, free, visible) -> tuple[Action, How]:
        """The rule within the budget: what the order alone settles, else exact counts first while they
        have been quick; where they have been slow, a probe first, which ends the decision if it settles
        it (:attr:`How.settled`), then the exact attempt, then the estimate again with what is left of the
        budget.  Where exact attempts have been failing, the estimate goes on instead of trying them;
        where probes have mostly not settled and exact attempts still fit, they are skipped."""
        start = time.perf_counter()
        end = start + self.budget * (1 - MARGIN)
        try:    # one candidate, one part to buffer, a shake, or what the order settles: nothing to count
            return self.rule(Answers(engine, mask, consistent, buffer, free, visible, mode="order")), EXACT
        except MustCount as need:
            kind = need.kind
        r = self.readings
        key = (kind, (engine.full & ~mask).bit_count() // SIZE_BAND)
        slow = r.slow.get(key, 0.0)
        probe = None
        failing = slow > FAILING * self.budget
        if slow > EXACT_FIRST * self.budget and (failing or r.probe_ok.get(key, 1.0) >= 0.5):
            # a probe where exact counts are slow, unless probes have mostly been unsure here (many
            # close candidates) while the exact counts still fit
            probe = self._estimate(engine, mask, consistent, buffer, visible, None, start + self.budget * PROBE_SHARE,
                                   stop_when_sure=True, free=free)
            ok = probe[1].settled
            r.probe_ok[key] = (1 - SLOW_WEIGHT) * r.probe_ok.get(key, 1.0) + SLOW_WEIGHT * ok
            if ok:
                r.slow[key] = slow * SLOW_DECAY   # try the exact counts again some day
                return probe
            if failing:   # exact attempts here have been failing: estimate on instead
                return self._estimate(engine, mask, consistent, buffer, visible, None, end, stop_when_sure=True,
                                      free=free)
        began = time.perf_counter()
        try:
            with engine.deadline(began + self.budget * r.share[kind]):
                action = self.rule(Answers(engine, mask, consistent, buffer, free, visible, order_first=False))
            r.share[kind] = EXACT_SHARE[1]
            r.slow[key] = (1 - SLOW_WEIGHT) * slow + SLOW_WEIGHT * (time.perf_counter() - began)
            return action, EXACT
        except BudgetExceeded:
            r.share[kind] = EXACT_SHARE[0]
            r.slow[key] = (1 - SLOW_WEIGHT) * slow + SLOW_WEIGHT * 2 * self.budget
        if time.perf_counter() >= end and probe is not None:
            return probe
        return self._estimate(engine, mask, consistent, buffer, visible, None, end, stop_when_sure=True, free=free)

    def _estimate(self, engine, mask, consistent, buffer, visible, can, end: float, *,
                  stop_when_sure: bool, free: float = math.inf) -> tuple[Action, How]:
        """The rule applied to estimates from the population of chains, run until ``end`` (or until sure).
        The readings are kept while the state stays: a decision's second estimate, and the next look's
        at the same state, continue them.  (``can``: unused, the rule asks.)"""
        ask = Answers(engine, mask, consistent, buffer, free, visible, mode="estimate", readings=self.readings,
                      end=end, stop_when_sure=stop_when_sure)
        action = self.rule(ask)
        return action, ask.how()

    # ------------------------------------------------------------ decisions with reasons

    def rank_candidates(self, state, visible: tuple[str, ...]) -> list[tuple]:
        """The installable candidates best first, for the decision's reasons.

        Parameters
        ----------
        state : State
            The sequencer's state.
        visible : tuple of str
            The look.

        Returns
        -------
        list of tuple
            ``(sort key, part, source, buffer position)``; the sort key's first element is minus the
            options.

        Raises
        ------
        NotImplementedError
            In this base class: each policy ranks by its own rule.

        Examples
        --------
        >>> from opportune import make_plan, Sequencer
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> state = Sequencer(make_plan(["a", "b", "c"], {"c": ["a"]})).state
        >>> Opportunistic().rank_candidates(state, ("a", "b"))
        [((-2, 0, 2.0, -1, 0), 'a', 'bin', None), ((-1, 0, 2.0, -1, 1), 'b', 'bin', None)]
        """
        raise NotImplementedError

    def rank_positions(self, state, visible: tuple[str, ...]) -> list[tuple]:
        """The visible parts best first by their expected positions, for the decision's reasons.

        Parameters
        ----------
        state : State
            The sequencer's state.
        visible : tuple of str
            The look.

        Returns
        -------
        list of tuple
            ``(expected position, declaration index, part)``.

        Raises
        ------
        NotImplementedError
            In this base class: each policy ranks by its own rule.

        Examples
        --------
        >>> from opportune import make_plan, Sequencer
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> state = Sequencer(make_plan(["a", "b", "c"], {"c": ["a"]})).state
        >>> Opportunistic().rank_positions(state, ("c",))
        [(Fraction(8, 3), 2, 'c')]
        """
        raise NotImplementedError

    def decide(self, state, visible: tuple[str, ...]) -> Decision:
        """The action with its reasons.

        The candidates' options and the completions now, or the visible parts' expected positions,
        counted within what is left of the budget (said where they do not fit); an estimated decision
        gives its estimates and how sure it is instead.

        Parameters
        ----------
        state : State
            The sequencer's state.
        visible : tuple of str
            The look, checked against the state.

        Returns
        -------
        Decision
            The action and why.

        Examples
        --------
        >>> from opportune import make_plan, Sequencer
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> state = Sequencer(make_plan(["a", "b", "c"], {"c": ["a"]})).state
        >>> decision = Opportunistic().decide(state, ("c",))
        >>> decision.action, decision.positions
        (Action(kind='buffer', part='c', source=None), (('c', Fraction(8, 3)),))
        """
        start = time.perf_counter()
        sched = state.schedule
        action, how = self._how(sched.engine, sched.mask, sched.consistent, state.buffer, state.buffer_free, visible)
        if action.kind == "done":
            return Decision(DONE, "the assembly is complete")
        if not how.exact:
            rule = self.rule_install if action.kind == "install" else self.rule_buffer
            return Decision(action, rule, note=how.note, exact=False, method=how.method, estimates=how.estimates,
                            confidence=how.confidence, seconds=time.perf_counter() - start, close=how.close)
        if action.kind == "install":
            rule = self.rule_install
            try:   # options not needed to decide (a lone candidate, or settled by the order): count them if they fit
                with state.schedule.engine.deadline(None if self.budget is None
                                                    else start + self.budget * (1 - MARGIN)):
                    ranked = self.rank_candidates(state, visible)
            except BudgetExceeded:
                sched = state.schedule
                lone = len(sched.engine.installable_among(sched.mask, sched.consistent, (*visible, *state.buffer))) == 1
                why = ("the only candidate" if lone else
                       "settled by the partial order alone: no other candidate is followed by every step that must "
                       "follow it")
                return Decision(action, rule, note=f"{why}; the options were not counted within the budget",
                                seconds=time.perf_counter() - start)
            total = self._total(state, start)
            candidates = tuple(Candidate(part, source, -key[0], total, key[2], pos) for key, part, source, pos in ranked)
            return Decision(action, rule, candidates, seconds=time.perf_counter() - start)
        if action.kind == "buffer":
            rule = self.rule_buffer
            try:
                with state.schedule.engine.deadline(None if self.budget is None
                                                    else start + self.budget * (1 - MARGIN)):
                    ranked = self.rank_positions(state, visible)
            except BudgetExceeded:   # a lone visible part: decided without them, and they do not fit
                return Decision(action, rule, note="its expected position was not computed within the budget",
                                seconds=time.perf_counter() - start)
            return Decision(action, rule, positions=tuple((p, pos) for pos, _, p in ranked),
                            seconds=time.perf_counter() - start)
        why = "nothing visible" if not visible else "nothing installable and the buffer is full"
        return Decision(SHAKE, "shake", note=why)

    def _total(self, state, start: float) -> int | None:
        """The completions now, for the reasons: within what is left of the budget (None if it does not fit)."""
        if self.budget is None:
            return state.schedule.count_result(estimate=False).value
        try:
            return state.schedule.count_result(estimate=False, deadline=start + self.budget * (1 - MARGIN)).value
        except BudgetExceeded:
            return None
