"""What a count answers: :class:`CountResult` (exact, or an estimate with its interval), and counts as
text however many digits they have (:func:`count_text`, :func:`decimal`, :func:`log10_int`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

from opportune.engine.tuning import EXACT_DIGITS, STR_BITS

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.planning.plan import Plan

__all__ = ["EXACT_DIGITS", "CountResult", "count_text", "decimal", "interval_unbuilt", "log10_int"]


@dataclass(frozen=True)
class CountResult:
    """A number of admissible sequences: exact, or an estimate with its stated error.

    ``value`` is an ``int`` when ``exact``; otherwise a float estimate whose
    true value lies within ``value * (1 ± rel_error)`` with probability
    ``confidence``.  What :meth:`~opportune.engine.schedule.Schedule.count_result` answers.

    Parameters
    ----------
    value : int or float
        The count (an ``int`` when exact), or the estimate (a float, ``inf`` past 1.8e308).
    exact : bool, default True
        Whether ``value`` is the exact count.
    rel_error : float, default 0.0
        The stated relative error of an estimate (``inf``: none could be stated).
    confidence : float, default 1.0
        The probability the stated interval holds.
    method : str, default "exact"
        How it was found (``"exact"``; for an estimate e.g. ``"smc"``, ``"armc"``, ``"sis"``,
        ``"bounds"``, several joined by ``+``, ``"union:"`` first when only the strategies' union
        was bounded).
    log10_value : float or None, optional
        ``log10`` of an estimate, kept beside ``value``: an estimate past 1.8e308 (a plan of a few
        hundred steps) is ``inf`` as a float.
    log10_low, log10_high : float or None, optional
        ``log10`` of the ends of an interval holding the count: the stated one within the certain
        bounds the orders give (so finite for every estimate
        :meth:`~opportune.engine.schedule.Schedule.count_result` makes; None where nobody gave one).

    Examples
    --------
    >>> exact = CountResult(336)
    >>> exact.value, exact.exact, exact.interval_log10 == (exact.log10, exact.log10)
    (336, True, True)
    >>> big = CountResult(math.inf, exact=False, rel_error=0.05, confidence=0.95, method="smc",
    ...                   log10_value=400.0, log10_low=399.98, log10_high=400.02)
    >>> big.log10, big.interval_log10
    (400.0, (399.98, 400.02))
    """

    value: int | float
    exact: bool = True
    rel_error: float = 0.0
    confidence: float = 1.0
    method: str = "exact"
    log10_value: float | None = None
    log10_low: float | None = None
    log10_high: float | None = None

    @property
    def log10(self) -> float:
        """``log10`` of the count (of the estimate; ``-inf`` for 0), from an ``int`` of any size."""
        if self.log10_value is not None:
            return self.log10_value
        return log10_int(self.value) if isinstance(self.value, int) else (
            math.log10(self.value) if self.value > 0 else float("-inf"))

    @property
    def interval_log10(self) -> tuple[float, float] | None:
        """``(log10 low, log10 high)``: the count itself when exact, else the interval given (None
        if none was)."""
        if self.exact:
            return self.log10, self.log10
        if self.log10_low is None or self.log10_high is None:
            return None
        return self.log10_low, self.log10_high


def interval_unbuilt(plan: Plan) -> CountResult:
    """What is certain of a plan's count without building its orders: at least 1 (a plan is checked to
    have an admissible sequence) and at most the sequences of its units with each part's units in
    order, ``n! / (q1! q2! ...)`` (from the log-gamma function, O(parts)).  An estimate, marked so, at
    the middle of that interval (in logarithms).

    >>> from opportune import make_plan
    >>> r = interval_unbuilt(make_plan(["a", "b", "c"], {}))
    >>> r.exact, round(r.log10_high, 6) == round(math.log10(6), 6), r.log10_low
    (False, True, 0.0)
    """
    q = [p.quantity for p in plan.parts]
    high = max(0.0, (math.lgamma(sum(q) + 1) - sum(math.lgamma(k + 1) for k in q)) / math.log(10))
    mid = high / 2
    return CountResult(10.0 ** mid if mid < 308 else math.inf, exact=False, rel_error=math.inf, confidence=1.0,
                       method="bounds", log10_value=mid, log10_low=0.0, log10_high=high)


def _signed_sum_log10(parts: list[tuple[int, float, float]]) -> tuple[float, float]:
    """``(log10 of the sum, its relative error)`` of terms given as ``(sign, log10 of the value,
    relative error)``, the errors adding up; in log space, since the values may be far past a float
    (nan, with an infinite error, if the sum is not positive or a term is unknown).

    >>> log10, rel = _signed_sum_log10([(1, 400.0, 0.1), (-1, 399.0, 0.1)])
    >>> round(log10, 6), round(rel, 6)      # 10^400 - 10^399 = 9 × 10^399, errors 10^399 + 10^398
    (399.954243, 0.122222)
    """
    if not parts or any(math.isnan(lg) for _, lg, _ in parts):
        return float("nan"), math.inf
    top = max(lg for _, lg, _ in parts)
    if top == -math.inf:
        return float("nan"), math.inf
    total = sum(sign * 10.0 ** (lg - top) for sign, lg, _ in parts)
    # an unbounded error stays unbounded however small its term looks (its size is what is unknown)
    err = sum(rel if math.isinf(rel) else rel * 10.0 ** (lg - top) for _, lg, rel in parts if rel)
    if not total > 0:
        return float("nan"), math.inf
    return top + math.log10(total), err / total


def decimal(n: int) -> str:
    """An int as decimal text, however many digits, without lifting Python's guard on int/str
    conversions (4,300 digits: a guard for parsing untrusted text, which stays in force): the number
    is split by a power of ten until the pieces are short enough.

    >>> len(decimal(10 ** 10_000))
    10001
    """
    if n < 0:
        return "-" + decimal(-n)
    if n.bit_length() < STR_BITS:            # fewer than 4,215 digits
        return str(n)
    half = int(n.bit_length() * 0.30103) // 2
    high, low = divmod(n, 10 ** half)
    return decimal(high) + decimal(low).zfill(half)


def count_text(n: int, exact_digits: int = EXACT_DIGITS) -> str:
    """A count as text: exact decimal when it has at most ``exact_digits`` digits
    (:data:`~opportune.engine.tuning.EXACT_DIGITS` by default: Python's own guard on int-to-text
    conversion), otherwise its first 17 significant digits (truncated, not rounded) in scientific
    notation.  O(d) in the digits d beyond the bound (one power of ten and one division), O(d²) within it.

    Parameters
    ----------
    n : int
        The count (a negative one gets its sign).
    exact_digits : int, default EXACT_DIGITS
        Most digits written exactly.

    Returns
    -------
    str
        The decimal text, or the scientific notation past ``exact_digits`` digits.

    Examples
    --------
    >>> count_text(336)
    '336'
    >>> count_text(10 ** 5000 + 123, exact_digits=100)
    '1.0000000000000000e+5000'
    >>> count_text(2 ** 20000, exact_digits=100)
    '3.9802768403379665e+6020'
    >>> count_text(12345678901234567, exact_digits=15), count_text(1234567890123456, exact_digits=15)
    ('1.2345678901234567e+16', '1.234567890123456e+15')
    """
    if n < 0:
        return "-" + count_text(-n, exact_digits)
    if n.bit_length() * 0.30103 < exact_digits - 1:     # surely within the bound
        return decimal(n)
    return _count_text(n, exact_digits)


@lru_cache(maxsize=64)   # an answer repeats its counts (a decision's, its row's, the run's): written once
def _count_text(n: int, exact_digits: int) -> str:
    e = int(log10_int(n))              # the exponent, up to the float's last-place error: checked
    p = 10 ** e
    if n < p:
        e, p = e - 1, p // 10
    elif n >= 10 * p:
        e, p = e + 1, 10 * p
    if e < exact_digits:
        return decimal(n)
    head = str(n // (p // 10 ** 16)) if e >= 16 else str(n)   # the first 17 digits (all, if fewer)
    return f"{head[0]}.{head[1:]}e+{e}"


def log10_int(n: int) -> float:
    """``log10(n)`` for an int of any size, without its decimal digits (Python refuses to write ints of
    more than 4,300 digits as text by default, and writing them is quadratic).

    >>> round(log10_int(10 ** 5000), 9)
    5000.0
    """
    if n <= 0:
        return float("-inf")
    shift = max(0, n.bit_length() - 64)
    return math.log10(n >> shift) + shift * math.log10(2)
