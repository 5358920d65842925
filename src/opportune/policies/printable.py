"""A decision's counts written as text at any size (Python's ``str()`` refuses ints of more than 4,300 digits),
and counts written for people (:func:`count_label`: the dashboard's and the service's explanations)."""

from __future__ import annotations

import re
from functools import lru_cache

# LABEL_DIGITS: counts of at most this many digits are written in full for people, longer ones as three
# significant digits and an exponent (engine/tuning.py says why); STR_BITS: the largest count str() writes
from opportune.engine.tuning import LABEL_DIGITS, STR_BITS

_ROUNDED = re.compile(r"(\d)(?:\.(\d*))?e\+?(\d+)", re.IGNORECASE)


def count_label(n: int | str) -> str:
    """A count as people read it: in full with grouped digits up to :data:`LABEL_DIGITS` digits, else
    three significant digits (rounded half up) and the exponent.  The one way the service writes counts
    for people: the dashboard shows these texts (``Count.text``, a run summary's ``count_text``) and the
    service's explanations (:func:`explain`) use them.

    Parameters
    ----------
    n : int or str
        A count (a non-negative int of any size), or the text the service keeps it as: decimal digits,
        or :func:`~opportune.engine.schedule.count_text`'s rounded form (``2.8462596809170545e+35659``).

    Returns
    -------
    str
        ``"336"``, ``"40,320"``, ``"6.13e98"``.

    Raises
    ------
    ValueError
        If ``n`` is negative, or text that is not a count.

    Examples
    --------
    >>> count_label(40320), count_label(10 ** 15 - 1), count_label(10 ** 15)
    ('40,320', '999,999,999,999,999', '1.00e15')
    >>> count_label(613 * 10 ** 96 + 4999), count_label(9996 * 10 ** 40), count_label("2.8462596809170545e+35659")
    ('6.13e98', '1.00e44', '2.85e35659')
    """
    if isinstance(n, int):
        if n < 0:
            raise ValueError(f"a count is not negative: {n}")
        from opportune.engine.schedule import count_text

        text = count_text(n, exact_digits=LABEL_DIGITS)   # O(digits past the bound): never the whole number
    else:
        text = n
    m = _ROUNDED.fullmatch(text)
    if m:
        digits, exponent = m[1] + (m[2] or ""), int(m[3])
    elif text.isdigit() and text.isascii():
        text = text.lstrip("0") or "0"
        if len(text) <= LABEL_DIGITS:
            return f"{int(text):,}"
        digits, exponent = text, len(text) - 1
    else:
        raise ValueError(f"not a count: {text[:40]!r}")
    head = int(digits[:3].ljust(3, "0")) + (len(digits) > 3 and digits[3] >= "5")   # the leading digits: exact
    if head == 1000:                                                                  # 9.995e44 -> 1.00e45
        head, exponent = 100, exponent + 1
    return f"{head // 100}.{head % 100:02d}e{exponent}"


@lru_cache(maxsize=1)
def _decimal_fraction():
    """A Fraction that writes itself as text however many digits its terms have (made on first use:
    ``fractions`` loads ``decimal``, which a plan's loading never needs)."""
    from fractions import Fraction

    from opportune.engine.schedule import decimal

    class DecimalFraction(Fraction):
        def __str__(self):
            if self.denominator == 1:
                return decimal(self.numerator)
            return f"{decimal(self.numerator)}/{decimal(self.denominator)}"

    return DecimalFraction


def printable_decision(decision, exact_digits: int | None = None):
    """The same decision, its counts and fractions ready to be written as text however many digits they have.

    Python refuses to write an int of more than 4,300 digits with ``str()`` (a guard against
    quadratic-time conversions of untrusted text, kept in force), and a plan of 2,000 unconstrained
    parts already has 2,000! (5,736 digits) sequences.  A decision's ``to_dict()`` and ``explain()``
    write counts with ``str()``: this gives them the large counts as decimal text (written by
    :func:`~opportune.engine.schedule.decimal`), so both work at any size and say exactly what they
    say of small counts.  The decision itself is returned when nothing in it is that large.
    (The lasting fix is for :mod:`opportune.policies.base` to write its counts with ``decimal``.)

    With ``exact_digits``, counts of more digits are written rounded by
    :func:`~opportune.engine.schedule.count_text` (an answer that must come back within a budget).
    """
    from dataclasses import replace
    from functools import partial

    from opportune.engine.schedule import count_text
    from opportune.engine.schedule import decimal as exact

    decimal = exact if exact_digits is None else partial(count_text, exact_digits=exact_digits)

    def large(n) -> bool:
        return isinstance(n, int) and n.bit_length() >= STR_BITS

    if not any(large(c.options) or large(c.total) for c in decision.candidates) and \
            not any(large(v.numerator) or large(v.denominator) for _, v in decision.positions):
        return decision
    candidates = tuple(replace(c, options=decimal(c.options) if large(c.options) else c.options,
                               total=decimal(c.total) if large(c.total) else c.total) for c in decision.candidates)
    positions = tuple((p, _decimal_fraction()(v.numerator, v.denominator)) for p, v in decision.positions)
    return replace(decision, candidates=candidates, positions=positions)
