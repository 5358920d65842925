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

The rule is :func:`paper_rule`, a function of the answers to its questions
(:class:`~opportune.policies.answers.Answers`): exact counts, or, where a decision
has a limit in seconds, estimates that say how sure they are (the answering layer
decides which, and the decision says so).
"""

from __future__ import annotations

import itertools
from fractions import Fraction

from opportune.engine import Schedule
from opportune.policies.answers import Answers, CountBasedRule
from opportune.policies.base import DONE, SHAKE, Action


def paper_rule(ask: Answers) -> Action:
    """The paper's rule: install the candidate that keeps the most options; else buffer the visible part
    needed earliest; else shake.  O(candidates log candidates) beyond the answers.

    Parameters
    ----------
    ask : Answers
        The answers for the state and look (exact, or estimated within a budget).

    Returns
    -------
    Action
        ``done`` once the assembly is complete, else the rule's action.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
    >>> paper_rule(Answers(engine, 0, engine.all_strategies, (), 1.0, ("b", "a")))
    Action(kind='install', part='a', source='bin')
    >>> paper_rule(Answers(engine, 0, engine.all_strategies, (), 1.0, ("c",)))
    Action(kind='buffer', part='c', source=None)
    """
    if ask.complete:
        return DONE
    can = ask.installable()
    if can:                                     # 1. the candidate that keeps the most options
        return most_options(ask, can)
    parts = ask.visible_parts()
    if parts and ask.free > 0:                  # 2. the visible part needed earliest
        position = ask.positions(parts)
        return ask.pick("buffer", [(p, None) for p in sorted(position, key=lambda p: (position[p], ask.index(p)))])
    return SHAKE                                # 3. nothing else helps


def most_options(ask: Answers, can: list[str]) -> Action:
    """Rule 1 among the candidates ``can``: most options, then bin before buffer, lower cost, buffered
    longest, declaration order.  A part both visible and buffered is a candidate from each; a part
    buffered twice, from its first location."""
    options = ask.options(can)
    keys = []
    for part, n in options.items():
        cost, index = ask.cost(part), ask.index(part)
        if part in ask.visible:
            keys.append(((-n, 0, cost, -1, index), part, "bin"))
        if part in ask.buffer:
            keys.append(((-n, 1, cost, ask.buffer.index(part), index), part, "buffer"))
    keys.sort()
    return ask.pick("install", [(part, source) for _, part, source in keys])


def choose_exact(engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                 visible: tuple[str, ...], *, order_first: bool = True) -> Action:
    """The paper's rule on exact counts, on the machine form of a state (see
    :class:`~opportune.policies.base.DecidesOnMasks`).  With ``order_first`` (the default),
    comparisons that the partial order alone settles (:mod:`opportune.engine.dominance`) are
    made without counting: the action is the same."""
    return paper_rule(Answers(engine, mask, consistent, buffer, free, visible, order_first=order_first))


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


class Opportunistic(CountBasedRule):
    """The paper's rule: install what keeps the most options; buffer what is needed earliest; shake last.

    Parameters
    ----------
    budget : float, optional
        Seconds per decision (``None``: always exact); ``Opportunistic(0.05)`` decides within 50 ms,
        estimating what it cannot count (see :class:`~opportune.policies.answers.CountBasedRule`).
    seed : int, default 0
        With a budget, the seed of the estimates.
    chains : int, default 8
        With a budget, the estimates' population of chains.

    Examples
    --------
    >>> from opportune import make_plan, Sequencer
    >>> seq = Sequencer(make_plan(["a", "b", "c"], {"c": ["a"]}), Opportunistic())
    >>> seq.decide(["a", "b"]).candidates[0]
    Candidate(part='a', source='bin', options=2, total=3, cost=2.0, buffered_at=None)
    """

    name = "paper"   # the paper's rule (formerly also "opportunistic": policies/named.py)
    #: Among buffered candidates equal in options and cost, the one buffered longest: the order decides.
    uses_buffer_order = True
    #: The rules in words, as the decisions give them (variants say theirs).
    rule_install = "install the candidate that keeps the most options"
    rule_buffer = "nothing can be installed: buffer the visible part needed earliest"

    def rule(self, ask: Answers) -> Action:
        return paper_rule(ask)

    def rank_candidates(self, state, visible):
        return ranked_candidates(state, visible)

    def rank_positions(self, state, visible):
        return buffer_choice(state, visible)

    def buffer_ties_at(self, engine, mask: int, consistent: int) -> list[tuple[int, int]]:
        """The pairs of parts whose order in the buffer can decide an action in this (installed,
        strategies) state.

        Both installable, with as many options and the same cost, so that "buffered longest" breaks their
        tie.  The exact evaluation keeps the buffer's order between the pairs of every state it can
        reach, and only between them.  Complexity: one count of options.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask : int
            The installed units, as the engine's bit mask.
        consistent : int
            The strategies still consistent, as a bit mask.

        Returns
        -------
        list of (int, int)
            Declaration indices, the lower first.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> Opportunistic().buffer_ties_at(engine, 0, 1), Opportunistic().buffer_ties_at(engine, 0b001, 1)
        ([(0, 1)], [])
        """
        here = Schedule.at(engine, mask, consistent)
        can = here.installable()
        if len(can) < 2:
            return []
        plan = engine.plan
        alike: dict[tuple, list[int]] = {}
        for part, options in here.options_for(can).items():
            alike.setdefault((options, plan.part(part).cost), []).append(plan.index(part))
        return [pair for group in alike.values() for pair in itertools.combinations(sorted(group), 2)]

    @staticmethod
    def decision_key(engine, capacity):
        """A function whose equal values mean equal decisions, for caching decisions in simulations.

        Only installable parts matter when there are candidates (with the buffered ones in buffer order,
        for the tie-break); otherwise the look and whether a buffer location is free.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        capacity : int or None
            Buffer locations (``None``: unlimited).

        Returns
        -------
        callable
            ``key(mask, consistent, buffer, sorted look)``, a hashable value.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> key = Opportunistic.decision_key(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]})), None)
        >>> key(0, 1, (), ("a", "b")) == key(0, 1, (), ("b", "a"))
        True
        """
        installable = engine.installable_set

        def key(mask, cons, buffer, look):
            can = installable(mask, cons)
            in_look = can.intersection(look)  # a set: which candidate comes from the bin, not in what order
            in_buffer = tuple([p for p in buffer if p in can]) if buffer else ()
            if in_look or in_buffer:
                return (mask, cons, in_look, in_buffer)
            return (mask, cons, look, capacity is None or len(buffer) < capacity)

        return key
