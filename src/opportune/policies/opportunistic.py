"""The paper's opportunistic policy (sections 3–4), made exact so results are reproducible.

At each look, the candidates are the installable parts among those visible
in the bin and those in buffer locations.

1. If there are candidates, install the one that leaves the most admissible
   completions.  Ties: a part visible in the bin before a buffered one (the bin
   opportunity may vanish at the next look; the buffer keeps), then the lower
   acquire + install cost, then among buffered parts the one buffered longest,
   then declaration order.
2. Else, if a part is visible and a buffer location is free, buffer the
   visible part needed earliest: the smallest expected position in a uniformly
   random admissible completion.  Ties: declaration order.
3. Else shake.

With a decision budget (``Opportunistic(budget=0.05)``, seconds per decision) the rule
is applied to exact counts when they fit a share of the budget, and otherwise to
estimates from random completions (:mod:`opportune.engine.sampling`) that fill the rest
of it.  The decision then says so: ``exact=False``, the method, each candidate's
estimated share of completions or expected position with its standard error, and the
estimated probability that the action is the exact rule's.  An estimate ends early, keeping the
rest of the budget, once it is sure (that probability at least 0.999) or once, as surely, no other
candidate is better by more than 1% (of the best share of options, or of the steps remaining for an
expected position): candidates that close are a toss-up the samples would take the whole budget to
settle, for no measurable difference in the outcome.  The chains' readings at a state are kept from
look to look while nothing is installed, so a run of buffer choices builds on itself.  Steps that are
interchangeable in the state (the same predecessors and successors among what
remains) have equal exact values, so estimates treat them as tied and the exact
tie-breaks decide between them.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from fractions import Fraction

from opportune.engine.count import BudgetExceeded
from opportune.engine.dominance import earliest_by_order, most_options_by_order
from opportune.engine.sampling import CompletionChains
from opportune.policies.base import (DONE, SHAKE, Action, Candidate, Decision, DecidesOnMasks, Estimate,
                                     pause_collector, resume_collector, shared_action)

MARGIN = 0.1            # share of the budget kept for building the answer after the estimate
EXACT_SHARE = (0.25, 0.6)  # share of the budget the exact attempt gets (after a failure, after a success)
SURE = 0.999           # an estimate this sure of its choice stops early, keeping the rest of the budget
MIXED_STEPS = 20       # moves per chain, per step remaining, before an early stop is trusted
EXACT_FIRST = 0.2      # exact attempts first while they have taken under this share of the budget
PROBE_SHARE = 0.3      # else a first estimate gets this share (and ends the decision if it is sure)
SLOW_WEIGHT = 0.3      # weight of the last exact attempt in the moving average of their time
SLOW_DECAY = 0.97      # that average shrinks after each sure estimate, so exact counts are tried again
SIZE_BAND = 5          # ... kept per band of this many steps remaining (see _budgeted)
INDIFFERENT = 0.01     # estimates stop once no other candidate is better by more than this (see _CLOSE)
FAILING = 0.4          # an average above this share of the budget: exact attempts have been failing there


_CLOSE = (f"stopped early: with probability >= {SURE} no other candidate is better than this one by more than "
          f"{100 * INDIFFERENT:g}% (of its share of options, or of the steps remaining for positions)")


def _join(*notes: str) -> str:
    return "; ".join(n for n in notes if n)


def ranked_candidates(state, visible: tuple[str, ...]) -> list[tuple]:
    """Installable candidates best first, as ``(sort key, part, source, buffer position)``.

    The sort key is rule 1: most options, bin before buffer, lower cost,
    buffered longest, declaration order.  A part both visible and buffered is
    a candidate from each; a part buffered twice, from its first location.
    """
    buffer = state.buffer
    options = state.schedule.options_for((*visible, *buffer))  # the installable ones, with their options
    if not options:
        return []
    plan = state.plan
    out = []
    for part, n in options.items():  # only the installable ones: usually few, while the buffer can be long
        cost, index = plan.part(part).cost, plan.index(part)
        if part in visible:
            out.append(((-n, 0, cost, -1, index), part, "bin", None))
        if part in buffer:
            pos = buffer.index(part)
            out.append(((-n, 1, cost, pos, index), part, "buffer", pos))
    out.sort()
    return out


def buffer_choice(state, visible: tuple[str, ...]) -> list[tuple]:
    """Visible parts ranked by rule 2, as ``(expected position, declaration index, part)``."""
    total, ranked = _buffer_ranking(state, visible)
    return [(Fraction(s, total), index, part) for s, index, part in ranked]


def _buffer_ranking(state, visible: tuple[str, ...]) -> tuple[int, list[tuple]]:
    """Rule 2 on integers: ``(completions, [(position sum, declaration index, part), ...])``, best first.

    The expected positions are the sums over one denominator, the completions.
    """
    total, sums = state.schedule.position_sums_for(set(visible))
    plan = state.plan
    return total, sorted((s, plan.index(p), p) for p, s in sums.items())


@dataclass(frozen=True)
class _How:
    """How a budgeted choice was reached (exact, or which estimates and how sure)."""

    exact: bool = True
    method: str = "exact"
    estimates: tuple[Estimate, ...] = ()
    confidence: float = 1.0
    note: str = ""
    close: bool = False     # estimated: no other candidate better by more than INDIFFERENT (see _CLOSE)

    @property
    def settled(self) -> bool:
        """Exact, or an estimate sure enough to end the decision."""
        return self.exact or self.confidence >= SURE or self.close


_EXACT = _How()


def _settled(engine, mask: int, consistent: int, parts: list[str], rule) -> list[str] | None:
    """The parts the order alone proves best under ``rule`` (see :mod:`opportune.engine.dominance`),
    or None: only with one consistent strategy (a union's counts do not follow one order)."""
    if consistent & (consistent - 1):
        return None
    plan = engine.plan
    unit_of = {engine.next_unit(mask, plan.index(p)): p for p in parts}
    best = rule(engine.posets[consistent.bit_length() - 1], engine.full & ~mask, list(unit_of))
    return None if best is None else [unit_of[u] for u in best]


def choose_by_order(engine, mask: int, consistent: int, buffer: tuple[str, ...], visible: tuple[str, ...],
                    can: list[str]) -> Action | None:
    """The rule's action when the partial order alone settles it (:mod:`opportune.engine.dominance`),
    else None.  ``can``: the installable parts among the visible and buffered ones (at least two, or
    none with two visible parts to choose from and a free location)."""
    if can:
        settled = _settled(engine, mask, consistent, can, most_options_by_order)
        return None if settled is None else _best_install(engine.plan, dict.fromkeys(settled, 0), visible, buffer)
    settled = _settled(engine, mask, consistent, list(dict.fromkeys(visible)), earliest_by_order)
    return None if settled is None else shared_action("buffer", min(settled, key=engine.plan.index))


def _best_install(plan, options: dict[str, int], visible, buffer) -> Action:
    """The candidate with the least sort key of :func:`ranked_candidates`, found without sorting."""
    best = None
    for part, n in options.items():
        cost, index = plan.part(part).cost, plan.index(part)
        if part in visible:
            key = (-n, 0, cost, -1, index, part, "bin")
            if best is None or key < best:
                best = key
        if part in buffer:
            key = (-n, 1, cost, buffer.index(part), index, part, "buffer")
            if best is None or key < best:
                best = key
    return shared_action("install", best[5], best[6])


def choose_exact(engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                 visible: tuple[str, ...], *, order_first: bool = True) -> Action:
    """The paper's rule on exact counts, on the machine form of a state (see
    :class:`~opportune.policies.base.DecidesOnMasks`).

    The best candidate is the least sort key of :func:`ranked_candidates` (keys are distinct:
    a part's bin and buffer candidates differ in the source), found without sorting.  With
    ``order_first`` (the default), comparisons that the partial order alone settles
    (:mod:`opportune.engine.dominance`) are made without counting: the action is the same.
    """
    if mask == engine.full:
        return DONE
    asked = (*visible, *buffer)
    can = engine.installable_among(mask, consistent, asked)
    if len(can) == 1:  # one candidate part: nothing to compare, so nothing to count
        part = can[0]
        return shared_action("install", part, "bin" if part in visible else "buffer")
    if order_first and (can or (visible and free > 0 and len(set(visible)) > 1)):
        settled = choose_by_order(engine, mask, consistent, buffer, visible, can)
        if settled is not None:     # the order alone settles it: the same action, without counting
            return settled
    if can:
        return _best_install(engine.plan, engine.options_for(mask, consistent, can), visible, buffer)
    if visible and free > 0:
        parts = set(visible)
        if len(parts) == 1:  # one part to buffer: nothing to compare
            return shared_action("buffer", visible[0])
        plan = engine.plan
        _, sums = engine.position_sums_for(mask, consistent, parts)
        return shared_action("buffer", min((s, plan.index(p), p) for p, s in sums.items())[2])
    return SHAKE


class Opportunistic(DecidesOnMasks):
    """Install what keeps the most options; buffer what is needed earliest; shake last.

    ``budget``: seconds per decision (None: always exact, however long it takes).  With a
    budget, ``seed`` and ``chains`` set the estimates' random streams and population.
    """

    name = "opportunistic"
    #: Among buffered candidates equal in options and cost, the one buffered longest: the order decides.
    uses_buffer_order = True

    def buffer_ties_at(self, engine, mask: int, consistent: int) -> list[tuple[int, int]]:
        """The pairs of parts (declaration indices, the lower first) whose order in the buffer can decide
        an action in this (installed, strategies) state: both installable, with as many options and the
        same cost, so that "buffered longest" breaks their tie.  The exact evaluation keeps the buffer's
        order between the pairs of every state it can reach, and only between them.  Complexity: one
        count of options.

        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> Opportunistic().buffer_ties_at(engine, 0, 1), Opportunistic().buffer_ties_at(engine, 0b001, 1)
        ([(0, 1)], [])
        """
        can = engine.installable(mask, consistent)
        if len(can) < 2:
            return []
        plan = engine.plan
        alike: dict[tuple, list[int]] = {}
        for part, options in engine.options_for(mask, consistent, can).items():
            alike.setdefault((options, plan.part(part).cost), []).append(plan.index(part))
        return [pair for group in alike.values() for pair in itertools.combinations(sorted(group), 2)]

    def __init__(self, budget: float | None = None, *, seed: int = 0, chains: int = 8):
        if budget is not None and not budget > 0:
            raise ValueError("the decision budget must be a positive number of seconds (or None)")
        self.budget = budget
        self.seed = seed
        self.chains = chains
        # Exact decisions depend only on the state and the look, so a simulation may cache them.
        self.deterministic = budget is None
        self._population: tuple | None = None   # (engine, strategy, CompletionChains)
        self._starts = 0
        self._share = {"install": EXACT_SHARE[1], "buffer": EXACT_SHARE[1]}
        # recent seconds of an exact attempt (moving average), per kind of decision and steps remaining
        self._slow: dict[tuple[str, int], float] = {}
        self._probe_ok: dict[tuple[str, int], float] = {}   # share of recent probes that settled, likewise

    #: The rules in words, as the decisions give them (variants say theirs).
    rule_install = "install the candidate that keeps the most options"
    rule_buffer = "nothing can be installed: buffer the visible part needed earliest"

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        """The action on the machine form of a state: :func:`choose_exact`, or within the budget."""
        return self._how(engine, mask, consistent, buffer, free, visible)[0]

    def _how(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
             visible: tuple[str, ...]) -> tuple[Action, "_How"]:
        """The action and how it was reached: the one place a variant changes the rule (see
        :mod:`~opportune.policies.variants`), for ``choose_at`` and ``decide`` alike."""
        if self.budget is None:
            return choose_exact(engine, mask, consistent, buffer, free, visible), _EXACT
        return self._budgeted(engine, mask, consistent, buffer, free, visible)

    # ------------------------------------------------------------ within a budget

    def _budgeted(self, engine, mask, consistent, buffer, free, visible) -> tuple[Action, _How]:
        """The rule within the budget (:meth:`_within_budget`), with the garbage collector paused: a
        collection waits for the next look (see :func:`~opportune.policies.base.pause_collector`)."""
        pause_collector()       # before anything allocates, resumed after the answer is built
        try:
            return self._within_budget(engine, mask, consistent, buffer, free, visible)
        finally:
            resume_collector()

    def _within_budget(self, engine, mask, consistent, buffer, free, visible) -> tuple[Action, _How]:
        """The rule within the budget.  Exact counts first while they have been quick; where they have
        been slow (a large plan's early states), a short estimate first, which ends the decision if it
        settles it (:attr:`_How.settled`: sure, or no other candidate better by more than INDIFFERENT),
        then the exact attempt, then the estimate again with what is left of the budget.  Where exact
        attempts have been failing, the estimate goes on instead of trying them; where short estimates
        have mostly not settled and exact attempts still fit, they are skipped.

        How slow exact attempts have been is kept per kind of decision and per band of steps remaining:
        on an assembly the cost of exact counts follows how far it has come (ARC111's expected positions
        never fit 50 ms with 100 or more steps to go, and fit easily with 50), so each trial's early
        states learn from the last trial's early states rather than from its late ones.
        """
        start = time.perf_counter()
        end = start + self.budget * (1 - MARGIN)
        if mask == engine.full:
            return DONE, _EXACT
        asked = (*visible, *buffer)
        can = engine.installable_among(mask, consistent, asked)
        if len(can) == 1 or (not can and len(set(visible)) == 1) or not can and not (visible and free > 0):
            # one candidate, one part to buffer, or a shake: nothing to count
            return choose_exact(engine, mask, consistent, buffer, free, visible), _EXACT
        settled = choose_by_order(engine, mask, consistent, buffer, visible, can)
        if settled is not None:
            return settled, _EXACT
        kind = "install" if can else "buffer"
        key = (kind, (engine.full & ~mask).bit_count() // SIZE_BAND)
        slow = self._slow.get(key, 0.0)
        probe = None
        failing = slow > FAILING * self.budget
        if slow > EXACT_FIRST * self.budget and (failing or self._probe_ok.get(key, 1.0) >= 0.5):
            # a probe where exact counts are slow, unless probes have mostly been unsure here (many
            # close candidates) while the exact counts still fit
            probe = self._estimate(engine, mask, consistent, buffer, visible, can,
                                   start + self.budget * PROBE_SHARE, stop_when_sure=True)
            ok = probe[1].settled
            self._probe_ok[key] = (1 - SLOW_WEIGHT) * self._probe_ok.get(key, 1.0) + SLOW_WEIGHT * ok
            if ok:
                self._slow[key] = slow * SLOW_DECAY   # try the exact counts again some day
                return probe
            if failing:   # exact attempts here have been failing: estimate on instead
                return self._estimate(engine, mask, consistent, buffer, visible, can, end, stop_when_sure=True)
        began = time.perf_counter()
        try:
            with engine.deadline(began + self.budget * self._share[kind]):
                action = choose_exact(engine, mask, consistent, buffer, free, visible, order_first=False)
            self._share[kind] = EXACT_SHARE[1]
            self._slow[key] = (1 - SLOW_WEIGHT) * slow + SLOW_WEIGHT * (time.perf_counter() - began)
            return action, _EXACT
        except BudgetExceeded:
            self._share[kind] = EXACT_SHARE[0]
            self._slow[key] = (1 - SLOW_WEIGHT) * slow + SLOW_WEIGHT * 2 * self.budget
        if time.perf_counter() >= end and probe is not None:
            return probe
        return self._estimate(engine, mask, consistent, buffer, visible, can, end, stop_when_sure=True)

    def _estimate(self, engine, mask, consistent, buffer, visible, can, end: float, *,
                  stop_when_sure: bool) -> tuple[Action, _How]:
        """The rule applied to estimates from the population of chains, run until ``end`` (or until sure).
        The readings are kept while the state stays (``keep``): a decision's second estimate, and the
        next look's at the same state, continue them."""
        plan = engine.plan
        remaining = engine.full & ~mask
        clock = time.perf_counter
        if can:
            units = {p: engine.next_unit(mask, plan.index(p)) for p in can}
            chains, note = self._chains(engine, mask, consistent, tuple(units.values()))
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

            est = chains.estimate(first=set(first.values()), deadline=end, clock=clock,
                                  settled=sure if stop_when_sure else None, keep=True)
            value = {p: 0.0 for p in can} | _tied_means(chains, remaining, first, est.first)
            keys = []
            for part in can:
                cost, index = plan.part(part).cost, plan.index(part)
                if part in visible:
                    keys.append(((-value[part], 0, cost, -1, index), part, "bin"))
                if part in buffer:
                    keys.append(((-value[part], 1, cost, buffer.index(part), index), part, "buffer"))
            keys.sort()
            best = keys[0][1]
            conf = _confidence(est, "first", first, best, chains, remaining, higher=True)
            close = conf < SURE and best in first and _confidence(
                est, "first", first, best, chains, remaining, higher=True, margin=INDIFFERENT * value[best]) >= SURE
            estimates = tuple(Estimate(part, "share", value[part],
                                       est.first[first[part]][1] if part in first else 0.0, source)
                              for _, part, source in keys)
            return (shared_action("install", best, keys[0][2]),
                    _How(False, "mcmc", estimates, conf, _join(note, _CLOSE if close else ""), close))
        chains, note = self._chains(engine, mask, consistent)
        parts = list(dict.fromkeys(visible))
        at = {p: engine.next_unit(mask, plan.index(p)) for p in parts}

        margin = INDIFFERENT * remaining.bit_count()

        def sure(e):
            if not _mixed(chains):
                return False
            v = _tied_means(chains, remaining, at, e.positions)
            top = min(parts, key=v.__getitem__)
            return (_confidence(e, "positions", at, top, chains, remaining, higher=False) >= SURE or
                    _confidence(e, "positions", at, top, chains, remaining, higher=False, margin=margin) >= SURE)

        est = chains.estimate(positions=set(at.values()), deadline=end, clock=clock,
                              settled=sure if stop_when_sure else None, keep=True)
        value = _tied_means(chains, remaining, at, est.positions)
        ranked = sorted((value[p], plan.index(p), p) for p in parts)
        best = ranked[0][2]
        conf = _confidence(est, "positions", at, best, chains, remaining, higher=False)
        close = conf < SURE and _confidence(est, "positions", at, best, chains, remaining, higher=False,
                                            margin=margin) >= SURE
        estimates = tuple(Estimate(p, "position", v, est.positions[at[p]][1]) for v, _, p in ranked)
        return shared_action("buffer", best), _How(False, "mcmc", estimates, conf,
                                                   _join(note, _CLOSE if close else ""), close)

    def _chains(self, engine, mask: int, consistent: int, candidates=()) -> tuple[CompletionChains, str]:
        """The population of chains for this state: carried on from the last look if the state
        only moved forward, else started afresh.  With several consistent strategies the chains follow
        the one in which most ``candidates`` (units) can come next (the current one on a tie)."""
        strategies = [s for s in range(engine.k) if consistent >> s & 1]
        strategy = strategies[0]
        if len(strategies) > 1 and candidates:
            remaining = engine.full & ~mask
            current = self._population[1] if self._population and self._population[0] is engine else None
            strategy = max(strategies, key=lambda s: (
                sum(not engine.posets[s].below[u] & remaining for u in candidates), s == current, -s))
        note = ""
        if len(strategies) > 1:   # the chains follow one order: say which
            note = f"estimated on strategy '{engine.plan.strategies[strategy].name}' alone"
        remaining = engine.full & ~mask
        pop = self._population
        if pop is None or pop[0] is not engine or pop[1] != strategy or remaining & ~pop[2].remaining:
            self._starts += 1
            chains = CompletionChains(engine.posets[strategy], remaining, chains=self.chains,
                                      seed=self.seed * 1_000_003 + self._starts)
            self._population = pop = (engine, strategy, chains)
        else:
            pop[2].advance(remaining)
        return pop[2], note

    # ------------------------------------------------------------ decisions with reasons

    @staticmethod
    def decision_key(engine, capacity):
        """A function of (installed mask, strategies, buffer, sorted look) whose equal values mean equal
        decisions — for caching decisions in simulations.  Only installable parts matter when there are
        candidates (with the buffered ones in buffer order, for the tie-break); otherwise the look and
        whether a buffer location is free."""
        installable = engine.installable_set

        def key(mask, cons, buffer, look):
            can = installable(mask, cons)
            in_look = can.intersection(look)  # a set: which candidate comes from the bin, not in what order
            in_buffer = tuple([p for p in buffer if p in can]) if buffer else ()
            if in_look or in_buffer:
                return (mask, cons, in_look, in_buffer)
            return (mask, cons, look, capacity is None or len(buffer) < capacity)

        return key

    def decide(self, state, visible: tuple[str, ...]) -> Decision:
        start = time.perf_counter()
        sched = state.schedule
        action, how = self._how(sched.engine, sched.mask, sched.consistent, state.buffer, state.buffer_free, visible)
        if action.kind == "done":
            return Decision(DONE, "the assembly is complete")
        if not how.exact:
            rule = self.rule_install if action.kind == "install" else self.rule_buffer
            return Decision(action, rule, note=how.note, exact=False, method=how.method, estimates=how.estimates,
                            confidence=how.confidence, seconds=time.perf_counter() - start)
        if action.kind == "install":
            rule = self.rule_install
            try:   # options not needed to decide (a lone candidate, or settled by the order): count them if they fit
                with state.schedule.engine.deadline(None if self.budget is None
                                                    else start + self.budget * (1 - MARGIN)):
                    ranked = ranked_candidates(state, visible)
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
                    ranked = buffer_choice(state, visible)
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
            return state.schedule.count()
        engine = state.schedule.engine
        try:
            with engine.deadline(start + self.budget * (1 - MARGIN)):
                return state.schedule.count()
        except BudgetExceeded:
            return None


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
    for part, u in unit_of.items():
        if u == ub or u in seen or _signature(chains, remaining, u) == sig:
            continue
        seen.add(u)
        if margin:
            miss += est.prob_greater(kind, u, ub, margin) if higher else est.prob_greater(kind, ub, u, margin)
        else:
            miss += 1 - (est.prob_greater(kind, ub, u) if higher else est.prob_greater(kind, u, ub))
    return max(0.0, 1 - miss)
