"""The answering layer: what a count-based rule asks at a look, answered exactly when the counts fit
the decision budget and by estimate otherwise, each answer saying how sure it is.

A rule (the paper's, ``bin-first``, ``slack``: :mod:`~opportune.policies.opportunistic`,
:mod:`~opportune.policies.variants`) is a short function of an :class:`Answers`: it asks for the
installable parts, each candidate's options (completions kept after installing it), the visible
parts' expected positions or slack, and names its choice with :meth:`Answers.pick`.  It holds no
budget, clock or estimate: a :class:`CountBasedRule` (the class those rules derive from) runs it
over answers of one kind at a time and keeps what it learns from look to look.

Answers come in four kinds (``Answers.mode``), each a small class with one interface, chosen once
when the answers are made (by name in :data:`MODES`):

* :class:`ByOrder` (``"order"``): only what needs no counting (one candidate, one part to buffer, or
  what the partial order alone settles, :mod:`opportune.engine.dominance`); anything else raises
  :class:`MustCount`;
* :class:`Exact` (``"exact"``): exact counts, the order's shortcuts first unless ``order_first=False``
  (within the engine's deadline, if the caller set one: :class:`~opportune.engine.deadline.BudgetExceeded`);
* :class:`Estimated` (``"estimate"``): from a population of random completions
  (:class:`~opportune.engine.sampling.CompletionChains`), run until ``end`` or until sure;
* :class:`After` (``"then"``): a question asked after the rule has decided (the slack after the
  paper's buffer choice): exact if that fits a share of the budget, else estimated with what is left,
  else unanswered (None).

With a decision budget (seconds per decision) the rule is applied to exact counts when they fit a share
of the budget, and otherwise to estimates that fill the rest of it.  The decision then says so:
``exact=False``, the method, each candidate's estimated share of completions or expected position with
its standard error, and the estimated probability that the action is the exact rule's.  An estimate ends
early, keeping the rest of the budget, once it is sure (that probability at least
:data:`~opportune.engine.tuning.SURE`) or once, as surely, no other candidate is better by more than
:data:`~opportune.engine.tuning.INDIFFERENT` (of the best share of options, or of the steps remaining
for an expected position): candidates that close are a toss-up the samples would take the whole budget
to settle, for no measurable difference in the outcome.  The chains' readings at a state are kept from
look to look while nothing is installed, so a run of buffer choices builds on itself.  Steps that are
interchangeable in the state (the same predecessors and successors among what remains) have equal exact
values, so estimates treat them as tied and the exact tie-breaks decide between them.

Exact counts first while they have been quick; where they have been slow (a large plan's early
states), a short estimate (a probe) first, which ends the decision if it settles it, then the exact
attempt, then the estimate again with what is left of the budget.  How slow exact attempts have
been is kept per kind of question and per band of steps remaining (the readings):
on an assembly the cost of exact counts follows how far it has come (docs/decisions.md gives
ARC111's measurements), so each trial's early states
learn from the last trial's early states rather than from its late ones.  Every share and margin of
this split is decided by one frozen :class:`~opportune.policies.budget.Budget` the rule makes, whose
defaults :mod:`opportune.engine.tuning` documents; the engine receives deadlines only.

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
from operator import attrgetter

from opportune.engine.deadline import BudgetExceeded
from opportune.engine.dominance import earliest_by_order, most_options_by_order
from opportune.engine.stats import prob_positive
from opportune.engine.tuning import EXACT_SHARE, MIXED_STEPS
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
from opportune.policies.budget import Budget
from opportune.policies.look import LookState

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.engine.sampling import CompletionChains   # made by Schedule.chains



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
        Estimated: no other candidate better by more than :data:`~opportune.engine.tuning.INDIFFERENT`
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

    def population_for(self, look: LookState, candidates=()) -> tuple[CompletionChains, str]:
        """The population of chains for this state: carried on from the last look if the state
        only moved forward, else started afresh.  With several consistent strategies the chains follow
        the one in which most ``candidates`` (units) can come next (the current one on a tie)."""
        engine, mask, consistent = look.engine, look.mask, look.consistent
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
            chains = look.schedule.chains(strategy, chains=self.chains, seed=self.seed * 1_000_003 + self.starts)
            self.population = pop = (engine, strategy, chains)
        else:
            pop[2].advance(remaining)
        return pop[2], note


# ------------------------------------------------------------ the kinds of answers


class Exact:
    """Exact answers, and the one interface of every kind of answers (chosen once, when the answers are
    made): the rule's questions on a :class:`~opportune.policies.look.LookState` (:meth:`options`,
    :meth:`positions`, :meth:`slack`), the ranking the rule picked from (:meth:`picked`) and how the
    choice was reached (:meth:`how`).

    Exact answers try what the partial order alone settles first (unless ``order_first`` is False), then
    count (within the engine's deadline, if the caller set one).
    """

    name = "exact"
    #: The settings of :class:`Answers` this kind takes.
    SETTINGS: tuple[str, ...] = ("order_first",)
    #: How the rule decided, when nothing was estimated here.
    after = EXACT
    #: The estimate that decided and the ranking picked, for :meth:`how` (None: nothing is estimated).
    record: dict | None = None

    def __init__(self, order_first: bool = True):
        self.order_first = order_first

    @classmethod
    def made(cls, settings: dict) -> Exact:
        """This kind, from the settings of :class:`Answers` (those it takes)."""
        return cls(**{name: settings[name] for name in cls.SETTINGS})

    def options(self, look: LookState, parts: list[str]) -> dict:
        known = self._uncounted(look, parts, most_options_by_order, "install")
        return known if known is not None else look.schedule.options_for(parts)

    def positions(self, look: LookState, parts: list[str]) -> dict:
        known = self._uncounted(look, parts, earliest_by_order, "buffer")
        return known if known is not None else look.schedule.position_sums_for(set(parts))[1]

    def slack(self, look: LookState, parts: list[str], weight: float) -> dict | None:
        return _exact_slack(look, parts, weight)

    def picked(self, ranked: list) -> None:
        if self.record is not None:
            self.record["ranked"] = ranked

    def how(self) -> How:
        rec = self.record
        if not rec or "how" not in rec:     # nothing was estimated
            return self.after
        return rec["how"](rec["ranked"])

    def _uncounted(self, look: LookState, parts: list[str], by_order, kind: str) -> dict | None:
        """What needs no count: the one part asked (nothing to compare), or the best parts the order alone
        proves (``by_order``), tied at 0; else :meth:`_counted`."""
        if len(parts) == 1:
            return {parts[0]: 0}
        if self.order_first:
            settled = _settled(look, parts, by_order)
            if settled is not None:
                return dict.fromkeys(settled, 0)
        return self._counted(kind)

    def _counted(self, kind: str) -> None:
        """Where the order does not settle a question: None, it is counted."""
        return None


class ByOrder(Exact):
    """Only what needs no counting: one candidate, one part to buffer, or what the partial order alone
    settles; any other question raises :class:`MustCount`."""

    name = "order"

    def _counted(self, kind: str) -> None:
        raise MustCount(kind)

    def slack(self, look: LookState, parts: list[str], weight: float) -> dict | None:
        raise MustCount("buffer")


class Estimated(Exact):
    """Estimates from a population of random completions (the ``readings``' chains), run until ``end``
    or, with ``stop_when_sure``, until sure."""

    name = "estimate"
    SETTINGS = ("readings", "end", "stop_when_sure")

    def __init__(self, readings: Readings | None = None, end: float = math.inf, stop_when_sure: bool = True):
        super().__init__()
        self.record = {}    # shared with the answers without the buffer (the same kind)
        self.estimates = Estimates(readings, end, stop_when_sure, self.record)

    def options(self, look: LookState, parts: list[str]) -> dict:
        return self.estimates.options(look, parts)

    def positions(self, look: LookState, parts: list[str]) -> dict:
        return self.estimates.positions(look, parts)

    def slack(self, look: LookState, parts: list[str], weight: float) -> dict | None:
        return self.estimates.slack(look, parts, weight)


class After(Exact):
    """A question asked after the rule decided (``after``: how): the rule's own questions exact, the
    slack exact if that fits ``exact_seconds`` (and the rule was exact), else estimated until ``end``,
    else unanswered (None)."""

    name = "then"
    SETTINGS = ("order_first", "readings", "end", "stop_when_sure", "after", "exact_seconds")

    def __init__(self, order_first: bool = True, readings: Readings | None = None, end: float = math.inf,
                 stop_when_sure: bool = True, after: How = EXACT, exact_seconds: float = math.inf):
        super().__init__(order_first)
        self.end, self.after, self.exact_seconds = end, after, exact_seconds
        self.record = {}
        self.estimates = Estimates(readings, end, stop_when_sure, self.record)

    def slack(self, look: LookState, parts: list[str], weight: float) -> dict | None:
        if self.after.exact:    # else the rule's positions did not fit just now: the slack's will not either
            try:
                with look.engine.deadline(min(self.end, time.perf_counter() + self.exact_seconds)):
                    return _exact_slack(look, parts, weight)
            except BudgetExceeded:
                pass
        if time.perf_counter() >= self.end:
            return None
        return self.estimates.slack(look, parts, weight)


#: The kinds of answers by name (:class:`Answers`' ``mode``).
MODES: dict[str, type[Exact]] = {kind.name: kind for kind in (ByOrder, Exact, Estimated, After)}
# the kinds that keep nothing, made once (a decision makes answers of one or two of them)
_EXACT, _COUNTED, _BY_ORDER = Exact(), Exact(order_first=False), ByOrder()


def _settled(look: LookState, parts: list[str], rule) -> list[str] | None:
    """The parts the order alone proves best under ``rule`` (see :mod:`opportune.engine.dominance`),
    or None: only with one consistent strategy (a union's counts do not follow one order)."""
    consistent = look.consistent
    if consistent & (consistent - 1) or not look.engine.posets:     # (a plan written as ways has no order)
        return None
    unit_of = {look.unit(p): p for p in parts}
    best = rule(look.engine.posets[consistent.bit_length() - 1], look.remaining, list(unit_of))
    return None if best is None else [unit_of[u] for u in best]


def _needed_after(look: LookState, part: str) -> tuple[int, int]:
    """The installs still needed before ``part`` can go in, and the steps that wait on it (the engine's
    :meth:`~opportune.engine.questions.StateQuestions.waits`: under the consistent strategy that frees it
    soonest, or by the ways of a plan written as ways)."""
    return look.engine.waits(look.mask, look.consistent, look.unit(part))


def _exact_slack(look: LookState, parts: list[str], weight: float) -> dict:
    total, sums = look.schedule.position_sums_for(set(parts))
    out = {}
    for part, s in sums.items():
        needed, after = _needed_after(look, part)
        out[part] = s / total - needed - weight * after
    return out


class Estimates:
    """The estimated answers: from the ``readings``' population of chains (a population of its own if
    None), until ``end`` or, with ``stop_when_sure``, until sure; each answer writes into ``record`` how
    it would say how sure the rule's choice is."""

    def __init__(self, readings: Readings | None, end: float, stop_when_sure: bool, record: dict):
        # a population of its own unless a policy passes the one it keeps
        self.readings = Readings(0, 8) if readings is None else readings
        self.end, self.stop_when_sure, self.record = end, stop_when_sure, record

    def options(self, look: LookState, can: list[str]) -> dict:
        remaining = look.remaining
        units = {p: look.unit(p) for p in can}
        chains, note = self.readings.population_for(look, tuple(units.values()))
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
        if est is None:
            return self.unestimated(dict.fromkeys(can, 0.0), note)
        value = {p: 0.0 for p in can} | _tied_means(chains, remaining, first, est.first)

        def how(ranked) -> How:
            best = ranked[0][0]
            conf = _confidence(est, "first", first, best, chains, remaining, higher=True)
            close = conf < SURE and best in first and _confidence(
                est, "first", first, best, chains, remaining, higher=True, margin=INDIFFERENT * value[best]) >= SURE
            estimates = tuple(Estimate(part, "share", value[part], est.first[first[part]][1] if part in first else 0.0,
                                       source) for part, source in ranked)
            return How(False, "mcmc", estimates, conf, note, close)

        self.record.update(how=how, ranked=None)
        return value

    def positions(self, look: LookState, parts: list[str]) -> dict:
        remaining = look.remaining
        chains, note = self.readings.population_for(look)
        at = {p: look.unit(p) for p in parts}
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
        if est is None:
            return self.unestimated(dict.fromkeys(parts, 0.0), note)
        value = _tied_means(chains, remaining, at, est.positions)

        def how(ranked) -> How:
            best = ranked[0][0]
            conf = _confidence(est, "positions", at, best, chains, remaining, higher=False)
            close = conf < SURE and _confidence(est, "positions", at, best, chains, remaining, higher=False,
                                                margin=margin) >= SURE
            estimates = tuple(Estimate(p, "position", value[p], est.positions[at[p]][1]) for p, _ in ranked)
            return How(False, "mcmc", estimates, conf, note, close)

        self.record.update(how=how, ranked=None)
        return value

    def slack(self, look: LookState, parts: list[str], weight: float) -> dict:
        """The slack with the expected positions estimated by the population of chains, until ``end`` or
        until sure."""
        chains, note = self.readings.population_for(look)
        at = {p: look.unit(p) for p in parts}
        offset = {}
        for part in parts:
            needed, after = _needed_after(look, part)
            offset[part] = -needed - weight * after
        index = look.engine.plan.index

        def best_of(e):
            return min(parts, key=lambda p: (e.positions[at[p]][0] + offset[p], index(p)))

        margin = INDIFFERENT * look.steps_left

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
        if est is None:     # the installs missing and the steps waiting, without the positions
            return self.unestimated(offset, note)
        value = {p: est.positions[at[p]][0] + offset[p] for p in parts}

        def how(ranked) -> How:
            best = ranked[0][0]
            estimates = tuple(Estimate(p, "slack", value[p], est.positions[at[p]][1]) for p, _ in ranked)
            conf = confidence(est, best)
            close = conf < SURE and confidence(est, best, margin) >= SURE
            return How(False, "mcmc", estimates, conf, note, close)

        self.record.update(how=how, ranked=None)
        return value


    def unestimated(self, value: dict, note: str) -> dict:
        """The answer when not one sample of the estimate fitted before ``end`` (a large plan of ways, whose
        every sample is a run over all parts left): ``value``, what needs no sample (ties, or the part of
        the slack known without positions), so the rule's tie-breaks decide, said so with confidence 0."""
        why = "no estimate fitted the decision budget: decided by the rule's tie-breaks"
        how = How(False, "tie-breaks", (), 0.0, f"{note}; {why}" if note else why)
        self.record.update(how=lambda ranked: how, ranked=None)
        return value


def _of_look(name: str, doc: str) -> property:
    """A read-only attribute of :class:`Answers` that is its look state's ``name``."""
    return property(attrgetter(f"look.{name}"), doc=doc)


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
        estimates, or a question asked after the rule; the name of one of the :data:`MODES` classes,
        made once from the settings below that it takes (:meth:`on` takes one made already).
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

    __slots__ = ("look", "mode")

    def __init__(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                 visible: tuple[str, ...], *, mode: str = "exact", order_first: bool = True,
                 readings: Readings | None = None, end: float = math.inf, stop_when_sure: bool = True,
                 after: How = EXACT, exact_seconds: float = math.inf):
        kind = MODES.get(mode) if isinstance(mode, str) else None
        if kind is None:
            raise ValueError(f"answers are asked in one of the modes {', '.join(MODES)}, not {mode!r}")
        self.look = LookState(engine, mask, consistent, buffer, free, visible)
        self.mode = kind.made({"order_first": order_first, "readings": readings, "end": end,
                               "stop_when_sure": stop_when_sure, "after": after, "exact_seconds": exact_seconds})

    @classmethod
    def on(cls, look: LookState, mode: Exact | None = None) -> Answers:
        """The answers at a :class:`~opportune.policies.look.LookState`, of a kind made already.

        Parameters
        ----------
        look : LookState
            The state and look.
        mode : Exact, optional
            The kind of answers: :class:`Exact` (the default, ``Exact()``), :class:`ByOrder`,
            :class:`Estimated` or :class:`After`.

        Returns
        -------
        Answers
            The answers.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> Answers.on(LookState(engine, 0, 1, (), 1.0, ("a", "b")), Exact(order_first=False)).options(["a", "b"])
        {'a': 2, 'b': 1}
        """
        ask = cls.__new__(cls)
        ask.look = look
        ask.mode = _EXACT if mode is None else mode
        return ask

    # ------------------------------------------------------------ the state

    # what a rule reads of the state, as the look state has it
    engine = _of_look("engine", "The plan's engine.")
    mask = _of_look("mask", "The installed units, as the engine's bit mask.")
    consistent = _of_look("consistent", "The strategies still consistent, as a bit mask.")
    buffer = _of_look("buffer", "The buffered parts, in buffer order.")
    free = _of_look("free", "Free buffer locations (``math.inf``: unlimited).")
    visible = _of_look("visible", "The look.")
    schedule = _of_look("schedule", "The state as a :class:`~opportune.engine.Schedule`: every exact count goes "
                                    "through it.")
    complete = _of_look("complete", "Whether every unit is installed.")

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
        return self.look.installable()

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
        return self.look.installable_in_bin()

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
        return self.look.visible_parts()

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
        return Answers.on(self.look.without_buffer(), self.mode)

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

    # ------------------------------------------------------------ the questions (the kind answers them)

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
        return self.mode.options(self.look, parts)

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
        return self.mode.positions(self.look, parts)

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
        return self.mode.slack(self.look, parts, weight)

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
        self.mode.picked(ranked)
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
        return self.mode.how()


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

    A rule with a question after it gets :data:`~opportune.engine.tuning.THEN_SHARES`\\ ``[0]`` of the
    budget (``budget``; the whole is ``total_budget``).  A decision costs what its answers cost; within a
    budget, at most about the budget (the estimates' and counts' checks of the clock, and building the
    reasons, are the rest).  Every split is decided by one frozen
    :class:`~opportune.policies.budget.Budget` (``limits``), made here.

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

    def __init__(self, budget: float | None = None, *, seed: int = 0, chains: int = 8):
        # the one place a decision's budget is split: the rule's share, so that with the question after
        # it the decision keeps the whole budget (ValueError if not a positive number of seconds)
        self.limits = Budget.for_rule(budget, asks_after=self._asks_after())
        self.seed = seed
        self.chains = chains
        # Exact decisions depend only on the state and the look, so a simulation may cache them.
        self.deterministic = budget is None
        self.readings = Readings(seed, chains)

    @classmethod
    def _asks_after(cls) -> bool:
        return cls.then is not CountBasedRule.then

    @property
    def total_budget(self) -> float | None:
        """Seconds per decision, the question after the rule included (``None``: exact decisions)."""
        return self.limits.seconds

    @total_budget.setter
    def total_budget(self, seconds: float | None) -> None:     # the service scales a look's budget
        self.limits = self.limits.with_seconds(seconds)

    @property
    def budget(self) -> float | None:
        """The rule's seconds per decision (``None``: exact decisions)."""
        return self.limits.rule_seconds

    @budget.setter
    def budget(self, seconds: float | None) -> None:
        self.limits = self.limits.with_seconds(None if seconds is None else seconds / self.limits.rule_share)

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
        return self._how(LookState(engine, mask, consistent, buffer, free, visible))[0]

    def choose_look(self, look: LookState) -> Action:
        """:meth:`choose_at` on the six as one value (what the rules that fall back on this one call).

        Parameters
        ----------
        look : LookState
            The state and look.

        Returns
        -------
        Action
            The action (no reasons).

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> Opportunistic().choose_look(LookState(engine, 0, engine.all_strategies, (), 1.0, ("c",)))
        Action(kind='buffer', part='c', source=None)
        """
        return self._how(look)[0]

    def _how(self, look: LookState) -> tuple[Action, How]:
        """The action and how it was reached, for ``choose_at`` and ``decide`` alike."""
        if self.total_budget is None:
            ask = Answers.on(look)
            return self.then(ask, self.rule(ask)), EXACT
        return self._budgeted(look)

    def _budgeted(self, look: LookState) -> tuple[Action, How]:
        """The rule within the budget (:meth:`_within_budget`), then its question after, with the garbage
        collector paused: a collection waits for the next look (see
        :func:`~opportune.policies.base.pause_collector`)."""
        pause_collector()       # before anything allocates, resumed after the answer is built
        try:
            start = time.perf_counter()
            action, how = self._within_budget(look)
            if not self._asks_after():
                return action, how
            ask = Answers.on(look, After(readings=self.readings, end=self.limits.then_end(start), after=how,
                                         exact_seconds=self.limits.then_exact_seconds))
            action = self.then(ask, action)
            return action, ask.how()
        finally:
            resume_collector()

    def _within_budget(self, look: LookState) -> tuple[Action, How]:
        """The rule within the budget: what the order alone settles, else exact counts first while they
        have been quick; where they have been slow, a probe first, which ends the decision if it settles
        it (:attr:`How.settled`), then the exact attempt, then the estimate again with what is left of the
        budget.  Where exact attempts have been failing, the estimate goes on instead of trying them;
        where probes have mostly not settled and exact attempts still fit, they are skipped."""
        limits = self.limits
        start = time.perf_counter()
        end = limits.end(start)
        try:    # one candidate, one part to buffer, a shake, or what the order settles: nothing to count
            return self.rule(Answers.on(look, _BY_ORDER)), EXACT
        except MustCount as need:
            kind = need.kind
        r = self.readings
        key = limits.band(kind, look.steps_left)
        slow = r.slow.get(key, 0.0)
        probe = None
        if limits.probe_first(slow, r.probe_ok.get(key, 1.0)):
            # a probe where exact counts are slow, unless probes have mostly been unsure here (many
            # close candidates) while the exact counts still fit
            probe = self._estimate(look, limits.probe_end(start))
            ok = probe[1].settled
            r.probe_ok[key] = limits.averaged(r.probe_ok.get(key, 1.0), ok)
            if ok:
                r.slow[key] = slow * limits.slow_decay   # try the exact counts again some day
                return probe
            if limits.is_failing(slow):   # exact attempts here have been failing: estimate on instead
                return self._estimate(look, end)
        began = time.perf_counter()
        try:
            with look.engine.deadline(limits.exact_end(began, r.share[kind])):
                action = self.rule(Answers.on(look, _COUNTED))
            r.share[kind] = limits.exact_share[1]
            r.slow[key] = limits.averaged(slow, time.perf_counter() - began)
            return action, EXACT
        except BudgetExceeded:
            r.share[kind] = limits.exact_share[0]
            r.slow[key] = limits.averaged(slow, limits.failed_reading)
        if time.perf_counter() >= end and probe is not None:
            return probe
        return self._estimate(look, end)

    def _estimate(self, look: LookState, end: float) -> tuple[Action, How]:
        """The rule applied to estimates from the population of chains, run until ``end`` (or until sure).
        The readings are kept while the state stays: a decision's second estimate, and the next look's
        at the same state, continue them."""
        ask = Answers.on(look, Estimated(self.readings, end))
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
        look = LookState.of(state, visible)
        action, how = self._how(look)
        if action.kind == "done":
            return Decision(DONE, "the assembly is complete")
        if not how.exact:
            rule = self.rule_install if action.kind == "install" else self.rule_buffer
            return Decision(action, rule, note=how.note, exact=False, method=how.method, estimates=how.estimates,
                            confidence=how.confidence, seconds=time.perf_counter() - start, close=how.close)
        if action.kind == "install":
            rule = self.rule_install
            try:   # options not needed to decide (a lone candidate, or settled by the order): count them if they fit
                with look.engine.deadline(self.limits.end(start)):
                    ranked = self.rank_candidates(state, visible)
            except BudgetExceeded:
                lone = len(look.installable()) == 1
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
                with look.engine.deadline(self.limits.end(start)):
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
            return state.schedule.count_result(estimate=False, deadline=self.limits.end(start)).value
        except BudgetExceeded:
            return None
