"""Statistics of the estimates: Student's t distribution function and quantile, and the probability
that a mean is positive, from a handful of independent runs (the chains of
:mod:`~opportune.engine.sampling`, the replicates of a study).

Pure functions on floats, no counting: what the policies and the study's reports use to state how
sure an estimate is, without loading the counters.

>>> round(t_quantile(0.975, 30), 3)
2.042
>>> prob_positive([1.0, 1.2, 0.9, 1.1]) > 0.99
True
"""

from __future__ import annotations

import math
from statistics import NormalDist

__all__ = ["prob_positive", "t_quantile"]


def prob_positive(diffs: list[float]) -> float:
    """Estimated probability that the true mean of ``diffs`` (one value per chain) is positive.

    Student's t over the chains: how sure a policy may be that one option beats another from a
    handful of independent estimates.  O(len(diffs)).

    Parameters
    ----------
    diffs : list of float
        One value per independent chain (or replicate).

    Returns
    -------
    float
        A probability in [0, 1]: 0.5 with fewer than two values; 1 or 0 when they all agree
        exactly (no spread) on a positive or negative mean.

    Examples
    --------
    >>> prob_positive([1.0, 1.2, 0.9, 1.1]) > 0.99, prob_positive([-1.0, -1.2, -0.9]) < 0.01
    (True, True)
    >>> prob_positive([0.5]), prob_positive([2.0, 2.0]), round(prob_positive([1.0, -1.0]), 6)
    (0.5, 1.0, 0.5)
    """
    k = len(diffs)
    if k < 2:
        return 0.5
    mean = sum(diffs) / k
    se = math.sqrt(sum((d - mean) ** 2 for d in diffs) / (k - 1) / k)
    if se == 0:
        return 1.0 if mean > 0 else 0.0 if mean < 0 else 0.5
    return _t_cdf(mean / se, k - 1)


def t_quantile(q: float, df: int) -> float:
    """Student's t quantile (Cornish–Fisher expansion; within 1% of the exact value for df ≥ 3).

    What the estimates' stated intervals are made of.  O(1).

    Parameters
    ----------
    q : float
        The probability, in (0, 1).
    df : int
        Degrees of freedom (runs - 1).

    Returns
    -------
    float
        ``t`` with ``P(T <= t) = q`` for Student's ``T`` with ``df`` degrees of freedom.

    Raises
    ------
    StatisticsError
        ``q`` is not strictly between 0 and 1 (:class:`statistics.StatisticsError`).

    Examples
    --------
    >>> round(t_quantile(0.975, 30), 3), round(t_quantile(0.975, 4), 3)     # tables: 2.042, 2.776
    (2.042, 2.769)
    >>> t_quantile(0.5, 10)
    0.0
    """
    z = NormalDist().inv_cdf(q)
    g1 = (z ** 3 + z) / 4
    g2 = (5 * z ** 5 + 16 * z ** 3 + 3 * z) / 96
    g3 = (3 * z ** 7 + 19 * z ** 5 + 17 * z ** 3 - 15 * z) / 384
    return z + g1 / df + g2 / df ** 2 + g3 / df ** 3


def _t_cdf(t: float, df: int) -> float:
    """Student's t distribution function: a finite series for whole ``df`` up to 100 (Abramowitz and
    Stegun 26.7.3-4; the chains give df = chains - 1), else the regularised incomplete beta."""
    if isinstance(df, int) and 1 <= df <= 100:
        theta = math.atan(t / math.sqrt(df))
        c2 = math.cos(theta) ** 2
        if df % 2:      # odd: 1/2 + (theta + sin cos (1 + 2/3 c^2 + 2·4/(3·5) c^4 + ...)) / pi
            term, total = 1.0, 1.0 if df > 1 else 0.0
            for k in range(1, (df - 1) // 2):
                term *= c2 * (2 * k) / (2 * k + 1)
                total += term
            return 0.5 + (theta + math.sin(theta) * math.cos(theta) * total) / math.pi
        term = total = 1.0  # even: 1/2 + sin/2 (1 + 1/2 c^2 + 1·3/(2·4) c^4 + ...)
        for k in range(1, df // 2):
            term *= c2 * (2 * k - 1) / (2 * k)
            total += term
        return 0.5 + 0.5 * math.sin(theta) * total
    return _t_cdf_beta(t, df)


def _t_cdf_beta(t: float, df: float) -> float:
    """Student's t distribution function (regularised incomplete beta by continued fraction)."""
    x = df / (df + t * t)
    tail = 0.5 * _betainc(df / 2, 0.5, x)
    return 1 - tail if t > 0 else tail


def _betainc(a: float, b: float, x: float) -> float:
    """Regularised incomplete beta I_x(a, b) (Numerical Recipes' continued fraction)."""
    if x <= 0:
        return 0.0
    if x >= 1:
        return 1.0
    lbeta = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log(1 - x)
    front = math.exp(lbeta)
    if x < (a + 1) / (a + b + 2):
        return front * _betacf(a, b, x) / a
    return 1 - front * _betacf(b, a, 1 - x) / b


def _betacf(a: float, b: float, x: float) -> float:
    tiny = 1e-300
    qab, qap, qam = a + b, a + 1, a - 1
    c, d = 1.0, 1 - qab * x / qap
    d = 1 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 200):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1 + aa * d
        d = 1 / (d if abs(d) > tiny else tiny)
        c = 1 + aa / c if abs(1 + aa / c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1 + aa * d
        d = 1 / (d if abs(d) > tiny else tiny)
        c = 1 + aa / c if abs(1 + aa / c) > tiny else tiny
        delta = d * c
        h *= delta
        if abs(delta - 1) < 1e-12:
            break
    return h
