"""Estimating the number of linear extensions, with a stated error, when exact counting is too expensive.

:func:`estimate_count` first tries the exact :class:`~opportune.engine.count.Counter`
under a budget; if that succeeds the answer is exact (``rel_error == 0``).
Otherwise the set is split into independent pieces exactly as the exact
counter splits it (cut elements, components; pieces whose count is cheap are
counted exactly), and every remaining piece is estimated by **sequential Monte
Carlo over the lattice of down-sets with merging** (a population version of
Knuth's estimator, in the spirit of Rubinstein's stochastic enumeration):

* the population at step ``k`` is a set of distinct remaining sets ``S``
  (what is left after ``k`` first elements), each with a weight ``w(S)``: an
  unbiased estimate of the number of ways to have removed the rest;
* one step replaces every ``S`` by its children ``S - x`` (``x`` minimal) and
  *merges* children that are the same set, adding their weights — while the
  population is small this is the exact dynamic programme;
* a child small enough for the exact counter (at most ``tail`` elements,
  found by probing; each attempt under a small memo budget) leaves the
  population and contributes ``w(S) e(S)`` exactly;
* when there are more than ``particles`` sets, ``particles`` of them are kept
  by systematic sampling with inclusion probability ``π(S)`` proportional to
  ``w(S) h(S)`` (capped at 1), and a kept set's weight becomes ``w(S) / π(S)``
  (Horvitz–Thompson, so every step stays unbiased).  ``h`` is the hook-length
  guess ``|S|! / Π (1 + |above(y) ∩ S|)`` of ``e(S)`` (exact for forests).

One run gives one unbiased estimate of the count.  Independent runs
(replicates, each with its own random stream) are repeated until the stated
interval is within ``rel_error`` (after at least ``min_runs``, 20 by
default), or the time is up.  The value is the mean of the runs (unbiased).
The stated ``rel_error`` (:func:`_stated_error`) is the larger relative
distance from it to an end of two Student's t intervals — one on the runs'
estimates, one on their logs (the runs are close to lognormal) — with the t
quantile widened by a margin that grows with the spread of the logs and
shrinks like ``1/sqrt(runs)``, calibrated on measured runs
(``benchmarks/coverage_count.py``).

Honest limits: the estimator is unbiased, but on wide posets its distribution
is right-skewed (rare runs find much of the mass), so a few runs usually lie
below the truth, and the interval for a few runs is wide: it has to be.  More
``particles`` make each run both less variable and less skewed.  On ARC111
(111 tasks) a run of 1,024 particles takes ~3 s, and its estimate varies
4-fold (80 runs: coefficient of variation 0.83, logs spread 0.62 and skewed
0.6; the largest run 4.7 times the truth); 10 s give 2–3 runs and an interval
of hundreds of percent.  Until issue 11 the interval was Student's t on the
estimates alone, stopped on accuracy from 4 runs on: it covered the truth in
only 63–90% of the cases measured with few particles or few runs (and missed
ARC111's by 5% while stating ±3.7%).  With 128 particles ARC111's runs spread
1.1 in logs (the largest of 300 runs 58 times the truth): no interval from
the runs is reliable there (resampled, coverage falls to 87% at 40 runs), so
use more particles.
The previous estimator (one-path importance sampling) stated ±55–120% on
ARC111 around 10^102.3–10^102.9, while long runs of this one (8,000 and
40,000 particles) agree on about 10^103.0–10^103.1.  ARC111 is now counted
exactly through its hub (:mod:`opportune.engine.hub`, 10^103.0294), which
:func:`estimate_count` tries before sampling; the estimator is what is left
for orders with neither structure.
"""

from __future__ import annotations

import math
import random
import time
from dataclasses import dataclass, field
from statistics import NormalDist

from opportune.engine.count import BudgetExceeded, Counter
from opportune.engine.hub import hub_split
from opportune.engine.poset import Poset, bits, components, cut_blocks

__all__ = ["Estimate", "estimate_count"]


@dataclass(frozen=True)
class Estimate:
    """An estimated number of linear extensions.

    ``value`` is the estimate; with probability ``confidence`` the true count
    lies within ``value * (1 ± rel_error)``.  ``method`` is ``"exact"`` (then
    ``rel_error == 0``, ``confidence == 1`` and ``exact`` holds the int) or
    ``"smc"`` (sequential Monte Carlo; ``samples`` is then the number of
    independent runs whose spread gives the interval).  ``log10_value`` is
    usable when ``value`` overflows a float.
    """

    value: float
    rel_error: float
    confidence: float
    method: str
    samples: int = 0
    log10_value: float = float("nan")
    exact: int | None = field(default=None, compare=False)
    seconds: float = field(default=0.0, compare=False)

    def interval(self) -> tuple[float, float]:
        """The stated interval ``(value * (1 - rel_error), value * (1 + rel_error))``."""
        return self.value * (1 - self.rel_error), self.value * (1 + self.rel_error)


def _log10_int(v: int) -> float:
    return math.log10(v) if v > 0 else float("-inf")


def _float_or_inf(v: int) -> float:
    try:
        return float(v)
    except OverflowError:
        return float("inf")


def _t_quantile(p: float, df: int) -> float:
    """Quantile ``p`` of Student's t with ``df`` degrees of freedom (closed forms for 1, 2; else
    the Cornish–Fisher expansion around the normal quantile, accurate to ~1e-3 for df >= 3)."""
    if df == 1:
        return math.tan(math.pi * (p - 0.5))
    if df == 2:
        return (2 * p - 1) / math.sqrt(2 * p * (1 - p))
    z = NormalDist().inv_cdf(p)
    z2 = z * z
    g1 = (z2 + 1) * z / 4
    g2 = ((5 * z2 + 16) * z2 + 3) * z / 96
    g3 = (((3 * z2 + 19) * z2 + 17) * z2 - 15) * z / 384
    g4 = ((((79 * z2 + 776) * z2 + 1482) * z2 - 1920) * z2 - 945) * z / 92160
    return z + g1 / df + g2 / df ** 2 + g3 / df ** 3 + g4 / df ** 4


#: The stated half-width uses Student's t quantile times ``1 + _MARGIN * (1 + skew) / sqrt(n)``,
#: where ``skew`` is the skewness of a lognormal with the runs' spread of logs, or that of the runs
#: if larger: a margin calibrated on measured replicate distributions (see :func:`_stated_error`).
_MARGIN = 0.5


def _stated_error(runs: list[float], confidence: float) -> float:
    """The relative half-width to state for the mean of the runs (natural logs of their estimates).

    Two intervals for the true count, each from Student's t on the ``n``
    runs; the larger relative distance from the mean of the runs to an end of
    either is stated:

    * on the counts themselves: ``mean ± t s / sqrt(n)``;
    * on their logs (the modified Cox interval for the mean of a lognormal,
      Olsson, J. Stat. Educ. 13(1), 2005): with ``m`` and ``s²`` the mean and
      variance of the logs, ``log count`` lies in
      ``m + s²/2 ± t sqrt(s²/n + s⁴/(2(n - 1)))``.  Normalising constants from
      sequential Monte Carlo tend to be lognormal (Bérard, Del Moral & Doucet,
      Electron. J. Probab. 19, 2014) and the runs measured here nearly are
      (the logs of one run are skewed 0.1–0.6): runs that happen to lie close
      together below the truth — the usual failure of the first interval on a
      right-skewed estimator — still give a long upper side.

    Both use the quantile ``t`` of Student's t with ``n - 1`` degrees of
    freedom times ``1 + _MARGIN * (1 + g) / sqrt(n)``, where ``g`` is the
    larger of ``(e^{s²} + 2) sqrt(e^{s²} - 1)``, the skewness of a lognormal
    with log-spread ``s``, and the skewness of the runs' estimates themselves
    (the logs can be skewed too: 0.76 for TONGE70 with 1,024 particles, where
    ``s`` is 0.03 and the lognormal's skewness 0.09).  The error of the t
    interval on skewed data shrinks like ``g / sqrt(n)``, hence the form; the
    constants are calibrated, not derived, and deliberately conservative: the
    statement is meant as *at least* ``confidence``.  Calibration: hundreds of
    runs each of KILBRID (64 particles), TONGE70 (1,024 and 128), ARC111 (1,024
    and 128) and random orders (the cases of ``benchmarks/coverage_count.py``),
    resampled ``n`` at a time.  Without the margin the log interval covered the
    truth in only 91–93% of samples of 3–10 runs of the more skewed ones
    (TONGE70 with 128 particles, logs skewed 0.5; ARC111 with 1,024, logs
    spread 0.6), and 1–3 points less when the runs stop as soon as the
    interval is narrow enough (hence also ``min_runs=20``); with it, at least
    94.5% at every number of runs from 2 to 40 (but see the limit below), and
    96–99% for exactly lognormal runs.  Real repeated estimates
    (``benchmarks/coverage_count.py``, 20–60 seeds per case and time limit)
    covered the truth in at least 90% of them in every case measured.
    Limit: when the logs spread by more than about 1 (ARC111 with 128
    particles: the rare runs 10–60 times the truth carry the mean) the
    statement is enormous with few runs and, with many, still too narrow
    (resampled: 93% at 20 runs, 88% at 40): use more particles.
    """
    n = len(runs)
    if n < 2 or min(runs) == -math.inf:       # a run that found nothing: no interval can be trusted
        return math.inf
    if min(runs) == max(runs):
        return 0.0
    m = sum(runs) / n
    s2 = sum((x - m) ** 2 for x in runs) / (n - 1)
    if s2 > 50:
        return math.inf
    mx = max(runs)
    ws = [math.exp(x - mx) for x in runs]
    mean = sum(ws) / n
    m2 = sum((w - mean) ** 2 for w in ws) / n
    sample_skew = abs(sum((w - mean) ** 3 for w in ws) / n) / m2 ** 1.5 if m2 > 0 else 0.0
    g = max((math.exp(s2) + 2) * math.sqrt(math.expm1(s2)), sample_skew)
    t = _t_quantile(0.5 + confidence / 2, n - 1) * (1 + _MARGIN * (1 + g) / math.sqrt(n))
    sd = math.sqrt(m2 * n / (n - 1))
    half = t * sd / math.sqrt(n) / mean
    centre = m + s2 / 2 - (mx + math.log(mean))       # relative to the log of the mean of the runs
    w = t * math.sqrt(s2 / n + s2 * s2 / (2 * (n - 1)))
    up = math.expm1(centre + w) if centre + w < 709 else math.inf
    return max(half, up, -math.expm1(centre - w))


class _SMC:
    """Sequential Monte Carlo with merging over the remaining sets of one poset (see the module doc)."""

    def __init__(self, poset: Poset, counter: Counter, particles: int, tail_memo: int):
        self.poset = poset
        self.counter = counter
        self.particles = max(2, particles)
        self.tail_memo = tail_memo
        self.above = list(poset.above)
        self.nbytes, self.up_t, _ = counter._tables()
        self.log1 = [math.log(k + 1) for k in range(poset.n + 2)]
        self.tails: dict[int, int] = {}      # piece -> tail size lowered by failures in earlier runs

    def _exact(self, s: int) -> int | None:
        """e(s) from the memo, or counted under the small tail budget; None if over it."""
        c = self.counter
        v = c.cached(s)
        if v is not None or s & (s - 1) == 0:
            return 1 if v is None else v
        try:
            return c.count(s)
        except BudgetExceeded:
            return None

    def probe_tail(self, root: int, rng: random.Random) -> int:
        """The largest size (found by bisection on random remaining sets) the exact counter handles cheaply."""
        below = self.poset.below

        def random_rest(size: int) -> int:
            s = root
            while s.bit_count() > size:
                mins = [i for i in bits(s) if not below[i] & s]
                s ^= 1 << rng.choice(mins)
            return s

        lo, hi = 1, root.bit_count()        # lo: handled; hi: not handled (the whole piece was not)
        while hi - lo > max(1, hi // 20):
            mid = (lo + hi) // 2
            if all(self._exact(random_rest(mid)) is not None for _ in range(2)):
                lo = mid
            else:
                hi = mid
        return lo

    def run(self, root: int, tail: int, rng: random.Random, deadline: float) -> float | None:
        """Natural log of one unbiased estimate of e(root); None if the deadline passed first."""
        above, up_t, nbytes, log1 = self.above, self.up_t, self.nbytes, self.log1
        tail = min(tail, self.tails.get(root, tail))
        log, exp = math.log, math.exp
        exact = self._exact
        B = self.particles
        states: dict[int, list] = {root: [1.0, 0.0]}     # set -> [weight, log hook guess]
        scale = 0.0                                       # log of the common factor of all weights
        terms: list[float] = []                           # log contributions of finished sets
        while states:
            if time.perf_counter() > deadline:
                return None
            kids: dict[int, list] = {}
            get = kids.get
            for s, (w, lh) in states.items():
                up = 0
                for tu, byte in zip(up_t, s.to_bytes(nbytes, "little")):
                    if byte:
                        up |= tu[byte]
                m = s & ~up
                while m:
                    b = m & -m
                    m ^= b
                    t = s ^ b
                    e = get(t)
                    if e is None:
                        kids[t] = [w, lh + log1[(above[b.bit_length() - 1] & s).bit_count()]]
                    else:
                        e[0] += w
            if not kids:
                break
            size = next(iter(kids)).bit_count()
            if size <= tail:
                # finish what the exact counter handles; if it keeps failing, the tail starts lower
                states = {}
                tried = failed = 0
                for t, e in kids.items():
                    if failed >= 3 and failed * 20 > tried:
                        states[t] = e
                        continue
                    tried += 1
                    if not tried & 63 and time.perf_counter() > deadline:
                        return None
                    v = exact(t)
                    if v is None:
                        failed += 1
                        states[t] = e
                    elif e[0] > 0:
                        terms.append(scale + log(e[0]) + log(v))
                if failed >= 3 and failed * 20 > tried:
                    tail = size - 1
                    self.tails[root] = min(self.tails.get(root, tail), tail)
            else:
                states = kids
            if len(states) > B:
                states = self._resample(states, rng)
            if states:
                mw = max(e[0] for e in states.values())
                if mw > 0:
                    for e in states.values():
                        e[0] /= mw
                    scale += log(mw)
        if not terms:
            return float("-inf")
        mx = max(terms)
        return mx + log(sum(exp(x - mx) for x in terms))

    def _resample(self, states: dict[int, list], rng: random.Random) -> dict[int, list]:
        """Keep ``particles`` sets, each with probability π ∝ weight × guess (capped at 1); reweight by 1/π."""
        B = self.particles
        items = list(states.items())
        mlh = max(e[1] for _, e in items)
        exp = math.exp
        a = [e[0] * exp(e[1] - mlh) for _, e in items]
        # the threshold c with sum(min(1, c * a_i)) == B
        srt = sorted(a, reverse=True)
        rest = math.fsum(srt)
        k = 0
        c = B / rest
        while c * srt[k] >= 1.0:
            rest -= srt[k]
            k += 1
            if k >= B or rest <= 0:
                break
            c = (B - k) / rest
        # systematic sampling: the points u, u + 1, ... over the running sum of the π < 1
        nxt = rng.random()
        acc = 0.0
        out: dict[int, list] = {}
        for (t, e), ai in zip(items, a):
            pi = c * ai
            if pi >= 1.0:
                out[t] = e
                continue
            acc += pi
            if acc > nxt:
                nxt += 1.0
                out[t] = [e[0] / pi, e[1]]
        return out


def _pieces(counter: Counter, mask: int) -> tuple[float, list[int]]:
    """Split ``mask`` as the exact counter does (cut elements, components), counting cheap pieces exactly.

    Returns the log of the exact factor (multinomials and exactly counted pieces)
    and the pieces left to estimate: connected sets without cut elements.
    """
    below, above = counter.poset.below, counter.poset.above
    logf = 0.0
    hard = []
    stack = [mask]
    while stack:
        s = stack.pop()
        if s & (s - 1) == 0:
            continue
        v = counter.cached(s)
        if v is not None:
            logf += math.log(v)
            continue
        cuts = 0
        for i in bits(s):
            if ((below[i] | above[i]) & s) | 1 << i == s:
                cuts |= 1 << i
        if cuts:
            stack.extend(cut_blocks(below, above, s, cuts))
            continue
        comps = components(above, s, counter.scan(s)[0])
        if len(comps) > 1:
            logf += math.lgamma(s.bit_count() + 1) - sum(math.lgamma(c.bit_count() + 1) for c in comps)
            stack.extend(comps)
            continue
        hard.append(s)
    return logf, hard


def estimate_count(poset: Poset, mask: int | None = None, *, rel_error: float = 0.01, time_limit: float = 10.0,
                   seed: int = 0, confidence: float = 0.95, counter: Counter | None = None,
                   exact_memo: int = 300_000, particles: int = 1024, tail: int | None = None,
                   tail_memo: int = 500, min_runs: int = 20, hub: float = 0.85,
                   overrun: float = math.inf) -> Estimate:
    """Estimate the number of linear extensions of the subposet induced on ``mask``, with a stated error.

    Tries the exact counter first (at most ``exact_memo`` new memo entries and
    a quarter of ``time_limit``); if it finishes, returns the exact count with
    ``rel_error=0``.  Otherwise splits the set into pieces as the counter does
    and tries to count each hard piece exactly through a hub
    (:func:`~opportune.engine.hub.hub_split`) until the fraction ``hub`` of
    ``time_limit`` has passed (0 disables this).  What is still not counted
    is estimated by sequential Monte Carlo (see the module doc) with ``particles`` sets per step, finishing sets of at most ``tail``
    elements exactly (default: the largest size the counter handles within
    ``tail_memo`` new entries, found by probing), and repeats independent runs
    until the stated ``confidence`` interval of their mean (see
    :func:`_stated_error`) is within ``rel_error`` of it (after at least
    ``min_runs`` runs: stopping as soon as a few runs happen to agree would
    make the interval optimistic) or ``time_limit`` seconds have passed (the
    first two runs always finish, so a limit too short for them
    is exceeded rather than returning no error at all — by at most ``overrun`` seconds: past that
    the estimate may come from one run, with no stated error, or from none: ``value`` nan).  The returned ``rel_error`` is the half-width actually achieved
    (infinite with fewer than two runs) — it may exceed the requested one by
    far (hundreds of percent from 2–3 runs of a variable estimator), and is
    then the honest statement of the error.

    Pass the plan's ``counter`` to reuse (and extend) its memo.  Deterministic
    given ``seed`` when it stops on accuracy; a stop on the clock depends on
    machine speed.

    >>> p = Poset.from_pairs(4, [(0, 1), (2, 3)])
    >>> e = estimate_count(p)
    >>> e.value, e.rel_error, e.method
    (6.0, 0.0, 'exact')
    >>> n = Poset.from_pairs(4, [(0, 2), (1, 2), (1, 3)])     # the "N": connected, no cut element
    >>> e = estimate_count(n, exact_memo=0, tail=0, rel_error=0.05, seed=1)
    >>> e.method, round(e.value, 9), e.rel_error            # 2 sets per step at most: nothing sampled
    ('smc', 5.0, 0.0)
    """
    start = time.perf_counter()
    if mask is None:
        mask = poset.full
    if mask < 0 or mask & ~poset.full:
        raise ValueError(f"mask {mask!r} is not a subset of 0..{poset.n - 1}")
    if not 0 < confidence < 1:
        raise ValueError("confidence must be in (0, 1)")
    if counter is None or counter.poset != poset:
        counter = Counter(poset, max_memo=None)

    saved = counter.max_memo, counter.time_limit
    try:
        # 1. exact, under a budget
        counter.max_memo = exact_memo if saved[0] is None else min(exact_memo, saved[0])
        counter.time_limit = time_limit / 4
        try:
            exact = counter.count(mask)
        except BudgetExceeded:
            exact = None
        if exact is not None:
            return Estimate(_float_or_inf(exact), 0.0, 1.0, "exact", 0, _log10_int(exact), exact,
                            time.perf_counter() - start)

        # 2. sequential Monte Carlo on the pieces that are still hard
        counter.max_memo = tail_memo if saved[0] is None else min(tail_memo, saved[0])
        counter.time_limit = None
        logf, hard = _pieces(counter, mask)
        if hard and hub:
            # 2. exact again, splitting the hard pieces at a hub (most of the time left, shared out)
            counter.max_memo, counter.time_limit = saved
            for i, s in enumerate(hard):
                left = (start + time_limit * hub) - time.perf_counter()
                if left <= 0 or hub_split(counter, s, time_limit=left / (len(hard) - i)) is None:
                    break
            else:
                hard = []
            counter.max_memo = tail_memo if saved[0] is None else min(tail_memo, saved[0])
            counter.time_limit = None
            if hard:
                logf, hard = _pieces(counter, mask)
        if not hard:                    # every piece is in the memo: the whole is one cheap exact count
            counter.max_memo = None
            exact = counter.count(mask)
            return Estimate(_float_or_inf(exact), 0.0, 1.0, "exact", 0, _log10_int(exact), exact,
                            time.perf_counter() - start)
        smc = _SMC(poset, counter, particles, tail_memo)
        probe_rng = random.Random(seed * 7919 + 1)
        tails = [tail if tail is not None else smc.probe_tail(s, probe_rng) for s in hard]
        deadline = start + time_limit
        runs: list[float] = []
        half = math.inf
        while True:
            rng = random.Random(seed * 1_000_003 + len(runs))
            total = 0.0
            # the first two runs finish whatever the clock says: without them no error can be stated
            run_deadline = deadline if len(runs) >= 2 else deadline + overrun
            for s, t in zip(hard, tails):
                lv = smc.run(s, t, rng, run_deadline)
                if lv is None:
                    break
                total += lv
            else:
                runs.append(total)
            n = len(runs)
            if n >= 2:
                half = _stated_error(runs, confidence)
                if half <= rel_error and n >= min_runs:
                    break
            now = time.perf_counter()
            if now >= deadline and (len(runs) >= 2 or now >= deadline + overrun):
                break
    finally:
        counter.max_memo, counter.time_limit = saved
    if not runs:
        return Estimate(float("nan"), math.inf, confidence, "smc", 0, float("nan"), None,
                        time.perf_counter() - start)
    mx = max(runs)
    lmean = mx + math.log(sum(math.exp(x - mx) for x in runs) / len(runs)) + logf
    value = math.exp(lmean) if lmean < 709 else float("inf")
    return Estimate(value, half, confidence, "smc", len(runs), lmean / math.log(10), None,
                    time.perf_counter() - start)
