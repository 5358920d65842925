"""Policies beyond the paper's rule, measured against the optimum with :mod:`.evaluate`.

The paper's rule (:class:`~opportune.policies.opportunistic.Opportunistic`) installs the
candidate that keeps the most completions, and otherwise buffers the visible part needed
earliest.  Exact evaluation shows where it loses (issue 13): taking a buffered part while an
installable part is visible in the bin wastes the bin's opportunity, and "needed earliest"
ignores how soon a part can actually go in and how much waits on it.  Three variants:

* :class:`BinFirst` (``bin-first``): a visible installable part before any buffered one (the
  buffer keeps; the bin's part may be gone at the next look); otherwise the paper's rule.
* :class:`Slack` (``slack``): bin first, and when nothing can be installed it buffers the visible
  part with the least *slack*: expected position, minus the installs still needed before the
  part can go in, minus ``weight`` times the steps that wait on it.
* :class:`Lookahead` (``lookahead``): one step of policy improvement over a base policy: every
  legal action is scored by its cost plus the base policy's exact expected cost of finishing from
  where it leads (a dynamic programme, :class:`~opportune.policies.evaluate.PolicyEvaluator`), and
  the least wins.  It is never worse than its base.  On plans too large for the programme
  (more than ``max_states`` states) it decides as its base does, and says so.

All decide on the machine form of a state (``choose_at``), so simulations, replays and the
exact evaluation use them as they use the paper's rule.  ``bin-first`` and ``slack`` are, like the
paper's rule, short functions of the answers to their questions
(:class:`~opportune.policies.answers.Answers`); the look-ahead is in
:mod:`~opportune.policies.lookahead`.
"""

from __future__ import annotations

from opportune.policies.answers import Answers
from opportune.policies.base import Action
from opportune.policies.opportunistic import Opportunistic, paper_rule

__all__ = ["BinFirst", "Lookahead", "Slack"]  # noqa: F822 (Lookahead: from policies/lookahead.py, below)


def bin_first(ask: Answers) -> Answers:
    """The answers with the buffered parts out of sight while a visible part can be installed (the
    buffer keeps; the bin's part may be gone at the next look)."""
    if ask.buffer and ask.visible and ask.installable_in_bin():
        return ask.without_buffer()
    return ask


class BinFirst(Opportunistic):
    """The paper's rule, with a visible installable part always before a buffered one.

    Parameters
    ----------
    budget : float, optional
        Seconds per decision (``None``: always exact).
    seed : int, default 0
        With a budget, the seed of the estimates.
    chains : int, default 8
        With a budget, the estimates' population of chains.

    Examples
    --------
    >>> from opportune import make_plan, Sequencer
    >>> plan = make_plan(["a", "b", "c"], {"c": ["a"]})
    >>> BinFirst().choose_at(Sequencer(plan).state.schedule.engine, 0b001, 1, ("c",), 1.0, ("b",))
    Action(kind='install', part='b', source='bin')
    """

    name = "bin-first"
    rule_install = "install a visible candidate before a buffered one, the one that keeps the most options"

    def rule(self, ask: Answers) -> Action:
        return paper_rule(bin_first(ask))


class Slack(BinFirst):
    """Bin first; when nothing can be installed, buffer the visible part with the least slack.

    ``slack(p) = E[position of p] - (installs still needed before p can go in) - weight * (steps after p)``
    in a uniformly random completion, all counted in units of the remaining work.  The buffer choice
    of the paper's rule comes first; the slack is a question after it (:meth:`then`).

    Parameters
    ----------
    weight : float, default 0.1
        The weight of the steps that wait on a part.
    **kwargs
        ``budget``, ``seed`` and ``chains``, as for :class:`BinFirst`.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c", "d", "x"], {"b": ["a"], "c": ["b"], "d": ["x"]}))
    >>> Slack().choose_at(engine, 0, 1, (), 1.0, ("b", "d"))
    Action(kind='buffer', part='b', source=None)
    """

    name = "slack"

    def __init__(self, weight: float = 0.1, **kwargs):
        super().__init__(**kwargs)
        self.weight = weight

    @property
    def rule_buffer(self) -> str:
        return (f"nothing can be installed: buffer the visible part with the least slack (expected position, "
                f"minus the installs it waits for, minus {self.weight:g} per step waiting on it)")

    def then(self, ask: Answers, action: Action) -> Action:
        """A buffer choice among several visible parts: the one with the least slack (ties: declaration
        order); unanswered within the budget, the paper's choice stands.

        Parameters
        ----------
        ask : Answers
            The answers the rule had.
        action : Action
            The paper's rule's action.

        Returns
        -------
        Action
            The action decided.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d", "x"], {"b": ["a"], "c": ["b"], "d": ["x"]}))
        >>> Slack().then(Answers(engine, 0, 1, (), 1.0, ("b", "d")), Action("buffer", "d"))
        Action(kind='buffer', part='b', source=None)
        """
        parts = ask.visible_parts()
        if action.kind != "buffer" or len(parts) == 1:
            return action
        slack = ask.slack(parts, self.weight)
        if slack is None:
            return action
        return ask.pick("buffer", [(p, None) for p in sorted(slack, key=lambda p: (slack[p], ask.index(p)))])

    def least_slack(self, engine, mask: int, consistent: int, visible: tuple[str, ...]) -> str:
        """The visible part with the least slack (ties: declaration order), exactly.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask : int
            The installed units, as the engine's bit mask.
        consistent : int
            The strategies still consistent, as a bit mask.
        visible : tuple of str
            The look.

        Returns
        -------
        str
            The part.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c", "d", "x"], {"b": ["a"], "c": ["b"], "d": ["x"]}))
        >>> Slack().least_slack(engine, 0, 1, ("b", "d"))
        'b'
        """
        ask = Answers(engine, mask, consistent, (), 0, visible)
        slack = ask.slack(ask.visible_parts(), self.weight)
        return min(slack, key=lambda p: (slack[p], ask.index(p)))
