"""A decision's counts written as text at any size (Python's ``str()`` refuses ints of more than 4,300 digits)."""

from __future__ import annotations

from functools import lru_cache

_BIG = 14_000  # bits: fewer than 4,215 decimal digits, which str() writes


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
        return isinstance(n, int) and n.bit_length() >= _BIG

    if not any(large(c.options) or large(c.total) for c in decision.candidates) and \
            not any(large(v.numerator) or large(v.denominator) for _, v in decision.positions):
        return decision
    candidates = tuple(replace(c, options=decimal(c.options) if large(c.options) else c.options,
                               total=decimal(c.total) if large(c.total) else c.total) for c in decision.candidates)
    positions = tuple((p, _decimal_fraction()(v.numerator, v.denominator)) for p, v in decision.positions)
    return replace(decision, candidates=candidates, positions=positions)
