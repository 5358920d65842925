"""A decision's budget: the one value that says how a count-based rule's seconds are split.

A :class:`~opportune.policies.answers.CountBasedRule` makes one :class:`Budget` when it is made (its
``budget`` seconds, and whether a question follows the rule) and decides every split from it: the
moment the rule's answer must be ready, the probe's share, the exact attempt's share, the question
after the rule, and how the readings of past decisions are averaged.  Its defaults are the lines of
:mod:`opportune.engine.tuning` that say why each has its value; the engine below receives a deadline
(a moment) and nothing else about time.

>>> b = Budget.for_rule(0.05, asks_after=True)
>>> round(b.rule_seconds, 3), round(b.end(10.0) - 10.0, 3), round(b.then_exact_seconds, 3)
(0.03, 0.027, 0.015)
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from opportune.engine.tuning import (
    DECISION_MARGIN,
    EXACT_FIRST,
    EXACT_SHARE,
    FAILING,
    PROBE_SHARE,
    PROBES_SETTLING,
    SIZE_BAND,
    SLOW_DECAY,
    SLOW_WEIGHT,
    THEN_SHARES,
)

__all__ = ["Budget"]


@dataclass(frozen=True)
class Budget:
    """A decision's seconds and how they are split (frozen: a changed budget is a new value).

    Parameters
    ----------
    seconds : float, optional
        Seconds per decision, the question after the rule included (``None``: exact decisions, no clock).
    rule_share : float, default 1.0
        The rule's share of ``seconds`` (less than the whole when a question follows it).
    margin : float, default DECISION_MARGIN
        Share of the rule's seconds (and of the whole, for the question after it) kept for building the
        answer after the estimate.
    then_exact_share : float, default THEN_SHARES[1]
        Share of ``seconds`` the question's exact answer may take before it is estimated.
    exact_share : tuple of float, default EXACT_SHARE
        Share of the rule's seconds an exact attempt gets: after a failed one, after a successful one.
    exact_first : float, default EXACT_FIRST
        Exact attempts come first while their moving average takes under this share of the rule's seconds.
    probe_share : float, default PROBE_SHARE
        Otherwise a first estimate (a probe) gets this share.
    probes_settling : float, default PROBES_SETTLING
        Where they are slow but not failing, a probe first only while at least this share of probes settled.
    failing : float, default FAILING
        An average above this share: exact attempts have been failing (the estimate goes on instead).
    slow_weight : float, default SLOW_WEIGHT
        Weight of the last reading in the moving averages.
    slow_decay : float, default SLOW_DECAY
        The average of exact attempts' seconds shrinks by this after each sure probe.
    size_band : int, default SIZE_BAND
        The readings are kept per band of this many steps remaining.

    Raises
    ------
    ValueError
        If ``seconds`` is not a positive number (or None).

    Examples
    --------
    >>> Budget(0.05).end(1.0), Budget().end(1.0)
    (1.045, None)
    >>> Budget(0.0)
    Traceback (most recent call last):
    ...
    ValueError: the decision budget must be a positive number of seconds (or None)
    """

    seconds: float | None = None
    rule_share: float = 1.0
    margin: float = DECISION_MARGIN
    then_exact_share: float = THEN_SHARES[1]
    exact_share: tuple[float, float] = EXACT_SHARE
    exact_first: float = EXACT_FIRST
    probe_share: float = PROBE_SHARE
    probes_settling: float = PROBES_SETTLING
    failing: float = FAILING
    slow_weight: float = SLOW_WEIGHT
    slow_decay: float = SLOW_DECAY
    size_band: int = SIZE_BAND

    def __post_init__(self):
        if self.seconds is not None and not self.seconds > 0:
            raise ValueError("the decision budget must be a positive number of seconds (or None)")

    @classmethod
    def for_rule(cls, seconds: float | None, *, asks_after: bool) -> Budget:
        """The budget of a rule: the whole of ``seconds``, or with a question after it
        ``THEN_SHARES[0]`` of them (the question gets the rest).

        Parameters
        ----------
        seconds : float, optional
            Seconds per decision (``None``: exact decisions).
        asks_after : bool
            Whether a question follows the rule (:meth:`~opportune.policies.answers.CountBasedRule.then`).

        Returns
        -------
        Budget
            The budget, with the tuning module's shares and margins.

        Examples
        --------
        >>> Budget.for_rule(0.05, asks_after=False).rule_seconds
        0.05
        """
        return cls(seconds, rule_share=THEN_SHARES[0] if asks_after else 1.0)

    @property
    def rule_seconds(self) -> float | None:
        """The rule's seconds (``None`` without a budget)."""
        if self.seconds is None:
            return None
        return self.seconds if self.rule_share == 1.0 else self.seconds * self.rule_share

    def with_seconds(self, seconds: float | None) -> Budget:
        """The same split of other seconds (the service scales a decision's budget to a look's time left).

        Parameters
        ----------
        seconds : float, optional
            The new seconds per decision.

        Returns
        -------
        Budget
            A new budget.

        Examples
        --------
        >>> Budget(0.05, rule_share=0.5).with_seconds(0.1).rule_seconds
        0.05
        """
        return replace(self, seconds=seconds)

    def end(self, start: float) -> float | None:
        """The moment the rule's answer must be ready: ``start`` plus the rule's seconds less the margin.

        Parameters
        ----------
        start : float
            The decision's start (a ``time.perf_counter()`` moment).

        Returns
        -------
        float or None
            A ``time.perf_counter()`` moment; ``None`` without a budget.

        Examples
        --------
        >>> Budget(1.0).end(5.0)
        5.9
        """
        if self.seconds is None:
            return None
        return start + self.rule_seconds * (1 - self.margin)

    def then_end(self, start: float) -> float:
        """The moment the question after the rule must be answered: the whole budget less the margin.

        Parameters
        ----------
        start : float
            The decision's start (a ``time.perf_counter()`` moment).

        Returns
        -------
        float
            A ``time.perf_counter()`` moment.

        Examples
        --------
        >>> Budget.for_rule(1.0, asks_after=True).then_end(5.0)
        5.9
        """
        return start + self.seconds * (1 - self.margin)

    @property
    def then_exact_seconds(self) -> float:
        """The seconds the question's exact answer may take."""
        return self.seconds * self.then_exact_share

    def probe_end(self, start: float) -> float:
        """The moment a probe (the first estimate, where exact attempts have been slow) stops.

        Parameters
        ----------
        start : float
            The decision's start (a ``time.perf_counter()`` moment).

        Returns
        -------
        float
            A ``time.perf_counter()`` moment.

        Examples
        --------
        >>> Budget(1.0).probe_end(5.0)
        5.3
        """
        return start + self.rule_seconds * self.probe_share

    def exact_end(self, began: float, share: float) -> float:
        """The moment an exact attempt begun at ``began`` stops: ``share`` of the rule's seconds later.

        Parameters
        ----------
        began : float
            The attempt's start (a ``time.perf_counter()`` moment).
        share : float
            Its share, one of :attr:`exact_share` (the readings keep which).

        Returns
        -------
        float
            A ``time.perf_counter()`` moment, the deadline the engine receives.

        Examples
        --------
        >>> Budget(1.0).exact_end(5.0, 0.25)
        5.25
        """
        return began + self.rule_seconds * share

    def band(self, kind: str, steps_left: int) -> tuple[str, int]:
        """The readings' key of a question: its kind and band of steps remaining.

        Parameters
        ----------
        kind : {"install", "buffer"}
            The kind of question.
        steps_left : int
            The steps remaining in the state.

        Returns
        -------
        tuple of (str, int)
            The key.

        Examples
        --------
        >>> Budget(1.0).band("install", 12)
        ('install', 2)
        """
        return kind, steps_left // self.size_band

    def probe_first(self, slow: float, probe_ok: float) -> bool:
        """Whether a probe comes before the exact attempt: exact attempts have been slow here, and
        either failing or probes have mostly settled (else many close candidates: exact counts, while
        they still fit, decide better).

        Parameters
        ----------
        slow : float
            The moving average of exact attempts' seconds here.
        probe_ok : float
            The moving share of probes that settled here.

        Returns
        -------
        bool
            Probe first.

        Examples
        --------
        >>> Budget(1.0).probe_first(0.1, 1.0), Budget(1.0).probe_first(0.3, 1.0), Budget(1.0).probe_first(0.3, 0.0)
        (False, True, False)
        """
        return (slow > self.exact_first * self.rule_seconds
                and (self.is_failing(slow) or probe_ok >= self.probes_settling))

    def is_failing(self, slow: float) -> bool:
        """Whether exact attempts have been failing here (their average over :attr:`failing` of the rule's
        seconds): the estimate goes on instead of trying them.

        Parameters
        ----------
        slow : float
            The moving average of exact attempts' seconds here.

        Returns
        -------
        bool
            Failing.

        Examples
        --------
        >>> Budget(1.0).is_failing(0.5)
        True
        """
        return slow > self.failing * self.rule_seconds

    def averaged(self, average: float, reading: float) -> float:
        """A moving average after one more reading.

        Parameters
        ----------
        average : float
            The average so far.
        reading : float
            The new reading (seconds, or 1/0 for a probe that settled or not).

        Returns
        -------
        float
            The new average.

        Examples
        --------
        >>> round(Budget(1.0).averaged(1.0, 0.0), 3)
        0.7
        """
        return (1 - self.slow_weight) * average + self.slow_weight * reading

    @property
    def failed_reading(self) -> float:
        """The reading of an exact attempt that did not fit: twice the rule's seconds."""
        return 2 * self.rule_seconds
