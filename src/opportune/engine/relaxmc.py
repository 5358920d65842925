"""Adaptive relaxation Monte Carlo: an estimate of the number of linear extensions with a stated interval.

The method of Talvitie, Kangas, Niinimäki and Koivisto, "Counting linear extensions in practice:
MCMC versus exponential Monte Carlo" (AAAI 2018), their ``armc``, in the compiled core
(``src/native/relax.cpp``):

1. *Relaxation.*  Cut the elements into pieces of ``k`` (≤ 64) elements, keeping as many comparable
   pairs inside the pieces as a random start improved by pairwise swaps keeps (the best of
   :data:`TRIES` starts).  The relaxed order R keeps only the order inside each piece, so
   ``e(R) = n! ∏ e(P_i) / n_i!`` with every piece counted exactly (the memoised recursion of the exact
   counter on one-word sets, doubles).
2. *Correction.*  A uniform linear extension of R is one of the order with probability
   ``p = e(P) / e(R)``.  Draws are built one element at a time from the pieces' memos and rejected at
   the first element placed before one of its predecessors, so most cost a few elements.
   ``e(P) = e(R) · p``.
3. *Adaptive k.*  ``k`` starts at 20 and grows by 5 while the next ``k``'s exact counts (predicted
   :data:`COUNT_GROWTH` times this one's, in memo entries) cost less than the draws the best
   relaxation so far still needs (predicted from a pilot of :data:`PILOT_DRAWS` draws, in elements
   placed): a larger ``k`` keeps more pairs, so ``p`` is larger and fewer draws are needed.  An order
   of at most 64 elements is first tried as one piece: its count is then exact.

The stated interval.  Draws stop at the first of: :func:`target_hits` linear extensions of the order
(the number that makes the interval's larger relative side at most ``rel_error`` however small ``p``
is), a cap on draws fixed before the first draw, or the deadline.  The interval is the exact
(Clopper–Pearson) binomial interval of ``p`` at ``confidence``, times ``e(R)``, which is exact.  It
holds with probability at least ``confidence`` under this stopping rule: its lower end is the exact
one for stopping at a fixed number of hits and for a fixed number of draws (the two failure events
nest, whichever stop comes first), and its upper end is the fixed-draws one, wider than the exact
one for stopping on hits.  Why not Dagum–Karp–Luby–Ross's rule (linext's): it guarantees
``1 ± ε`` but needs about three times the hits for the same width at 95 %.  A stop on the clock
depends a little on the draws (rejected draws are quicker), which the statement neglects; the tests
check coverage on orders with known counts.  The pilots' draws only choose ``k``: the estimate uses
fresh draws (another random stream), so the choice does not bias it.

Determinism: the partition, the counts and the draws depend only on ``seed`` (and ``k``); the choice
of ``k`` uses counted work (memo entries, elements placed), not the clock.  A stop on the clock (a
count cut short, draws stopped before the target) depends on the machine's speed, as elsewhere in
the engine.

Memory: each relaxation's memos are capped at ``max_bytes`` (checked before every allocation, the
hash tables' and the arrays' growth included); a count that would pass it stops with a status and
the best relaxation so far is used.  Two relaxations are alive at most: at most ``2 · max_bytes``
(512 MiB by default; the counts of sparse orders of 100 elements took 1-120 MB here).

Complexity: the partition O(n² + tries · swaps · (n / k) · k) operations; a piece's count O(memo
entries · k) (up to about 2^k entries on a piece without order, far fewer on ordered ones); a draw
O(elements placed · (parts + minimal elements)).

Example::

    >>> from opportune.engine.poset import Poset
    >>> p = Poset.from_pairs(6, [(0, 1), (2, 3)])
    >>> r = estimate(p, seconds=5.0)                    # 6 elements: one piece, counted exactly
    >>> r is None or (r.status, r.k, round(10 ** r.log10)) == ("exact", 6, 180)
    True
"""

from __future__ import annotations

import functools
import math
import statistics
import time
from dataclasses import dataclass, field

from opportune.engine.deadline import Deadline, as_deadline
from opportune.engine.poset import Poset, bits
from opportune.engine.tuning import (
    RELAX_MAX_N as MAX_N, RELAX_K_START as K_START, RELAX_K_STEP as K_STEP, RELAX_K_MAX as K_MAX,
    RELAX_TRIES as TRIES, RELAX_MAX_BYTES as MAX_BYTES, RELAX_COUNT_GROWTH as COUNT_GROWTH,
    RELAX_PILOT_DRAWS as PILOT_DRAWS, RELAX_PILOT_HITS as PILOT_HITS, RELAX_ENTRY_SECONDS as
    ENTRY_SECONDS, RELAX_STEP_SECONDS as STEP_SECONDS, RELAX_COUNT_SHARE as COUNT_SHARE,
    RELAX_MAX_THREADS as MAX_THREADS)

__all__ = ["MAX_N", "RelaxEstimate", "clopper_pearson", "estimate", "target_hits"]


@dataclass(frozen=True)
class RelaxEstimate:
    """An estimate ``log10`` of the number of linear extensions with its interval (``log10_low``,
    ``log10_high``) at ``confidence``: the relaxation's exact count (``log10_relaxed``, pieces of at
    most ``k``), ``draws`` uniform draws of it, ``hits`` of them linear extensions of the order.

    ``status``: ``"exact"`` (one piece, or no constraint between pieces: the count is exact up to
    the rounding of doubles), ``"hits"`` (the target number of hits reached), ``"draws"`` (the cap
    on draws reached first), ``"time"`` (the deadline came first), ``"none"`` (no relaxation could
    be counted within the time or memory; ``log10`` is nan), ``"hopeless"`` (see :func:`estimate`).
    ``bytes``: the memos of the relaxation used; ``run``: the relaxation and the draws made, for a
    later call to go on from (``estimate(..., resume=this)``), None where there is none."""

    log10: float
    log10_low: float
    log10_high: float
    confidence: float
    log10_relaxed: float
    k: int
    draws: int
    hits: int
    status: str
    bytes: int = 0
    run: _Run | None = field(default=None, compare=False, repr=False)

    @property
    def rel_error(self) -> float:
        """Half the interval's relative width, the larger side (as ``Estimate.rel_error``)."""
        if not math.isfinite(self.log10) or not math.isfinite(self.log10_low) or not math.isfinite(self.log10_high):
            return math.inf
        return max(10 ** (self.log10_high - self.log10) - 1, 1 - 10 ** (self.log10_low - self.log10))


# ------------------------------------------------------------------------------ binomial intervals

def _beta_cf(a: float, b: float, x: float) -> float:
    """The continued fraction of the incomplete beta function (modified Lentz), for x < (a+1)/(a+b+2)."""
    tiny = 1e-300
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    f = d
    for m in range(1, 100_000):
        m2 = 2 * m
        for num in (m * (b - m) * x / ((a + m2 - 1) * (a + m2)),
                    -(a + m) * (a + b + m) * x / ((a + m2) * (a + m2 + 1))):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + num / c
            c = c if abs(c) > tiny else tiny
            f *= c * d
        if abs(c * d - 1.0) < 1e-15:
            break
    return f


def _betainc(a: float, b: float, x: float) -> float:
    """The regularized incomplete beta function I_x(a, b) (a, b > 0)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1) / (a + b + 2):
        return math.exp(log_front) * _beta_cf(a, b, x) / a
    return 1.0 - math.exp(log_front) * _beta_cf(b, a, 1.0 - x) / b


def _beta_quantile(a: float, b: float, q: float) -> float:
    """The x with I_x(a, b) = q: Newton's method on log x from the normal approximation, kept within a
    bracket that shrinks as bisection's would (relative precision ~1e-12, a few steps where bisection
    took forty-five: 4 ms an interval at ten thousand hits)."""
    lo, hi = -745.0, 0.0
    log_beta = math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)
    mean, sd = a / (a + b), math.sqrt(a * b / ((a + b) ** 2 * (a + b + 1)))
    x0 = mean + statistics.NormalDist().inv_cdf(min(max(q, 1e-300), 1 - 1e-16)) * sd
    y = math.log(x0) if 0 < x0 < 1 else (lo + hi) / 2
    for _ in range(200):
        x = math.exp(y)
        f = _betainc(a, b, x) - q
        if f < 0:
            lo = y
        else:
            hi = y
        if hi - lo < 1e-13:
            return math.exp((lo + hi) / 2)
        # dI/dy = x^a (1 - x)^(b - 1) / B(a, b); a step outside the bracket bisects instead
        slope = math.exp(a * y + (b - 1) * math.log1p(-x) - log_beta) if x < 1 else 0.0
        step = y - f / slope if slope > 0 else math.nan
        if not lo < step < hi:
            step = (lo + hi) / 2
        if abs(step - y) < 1e-13 * max(1.0, abs(y)):
            return math.exp(step)
        y = step
    return math.exp((lo + hi) / 2)


def clopper_pearson(hits: int, draws: int, confidence: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper–Pearson) interval of a binomial proportion, ``hits`` of ``draws``, at
    ``confidence`` (each side fails with probability at most ``(1 - confidence) / 2``).

    O(bisection steps · continued-fraction terms), a few milliseconds.  Reference: Clopper & Pearson,
    Biometrika 26 (1934).

    >>> lo, hi = clopper_pearson(50, 100)
    >>> round(lo, 4), round(hi, 4)
    (0.3983, 0.6017)
    >>> clopper_pearson(0, 10)[0], round(clopper_pearson(0, 10)[1], 4)
    (0.0, 0.3085)
    """
    if not 0 <= hits <= draws or draws <= 0:
        return 0.0, 1.0
    alpha = 1.0 - confidence
    lo = 0.0 if hits == 0 else _beta_quantile(hits, draws - hits + 1, alpha / 2)
    hi = 1.0 if hits == draws else _beta_quantile(hits + 1, draws - hits, 1 - alpha / 2)
    return lo, hi


@functools.lru_cache(maxsize=64)
def target_hits(rel_error: float, confidence: float = 0.95) -> int:
    """The fewest hits whose Clopper–Pearson interval has its larger relative side at most
    ``rel_error`` however small the proportion (the widest case, a proportion near 0).

    >>> target_hits(0.05)
    1615
    """
    if not rel_error > 0:
        raise ValueError("rel_error must be positive")

    def width(h: int) -> float:
        n = h * 10**7                   # p = 1e-7: the small-proportion limit, to well within 1e-4
        lo, hi = clopper_pearson(h, n, confidence)
        return max(hi * n / h - 1, 1 - lo * n / h)

    # bracket the answer from the normal approximation's (z / rel_error)^2, in steps of 2 rel_error: a
    # dozen evaluations of 4 ms each, where doubling from 1 took 50 of them (0.2 s at 1%)
    z = statistics.NormalDist().inv_cdf(0.5 + confidence / 2)
    step = 1 + 2 * rel_error
    lo = hi = max(1, int((z / rel_error) ** 2))
    while lo > 1 and width(lo) <= rel_error:
        lo, hi = max(1, int(lo / step)), lo
    while width(hi) > rel_error:
        lo, hi = hi, int(hi * step) + 1
        if hi > 10**9:
            raise ValueError("rel_error too small")
    while lo < hi:
        mid = (lo + hi) // 2
        if width(mid) > rel_error:
            lo = mid + 1
        else:
            hi = mid
    return hi


# ------------------------------------------------------------------------------ the estimate

@dataclass(frozen=True)
class _Run:
    """A counted relaxation and the draws made from it so far (draws 0 .. ``draws`` - 1 of the stream ``mix``)."""

    relax: object
    n: int
    log_r: float
    k: int
    mix: int
    draws: int
    hits: int


@dataclass
class _Candidate:
    relax: object
    log_r: float
    k: int
    entries_work: float      # seconds its count is predicted to take (entries · ENTRY_SECONDS)
    draw_seconds: float      # predicted seconds of the draws it still needs (inf: no pilot hit)
    hit_seconds: float       # predicted seconds per hit (inf: no pilot hit)


def _native():
    from opportune.engine.native import _native as core
    return core if core is not None and hasattr(core, "ArmcRelaxation") else None


def available() -> bool:
    """True when the compiled core with relaxation Monte Carlo is there (else :func:`estimate` gives None)."""
    return _native() is not None


def estimate(poset: Poset, seconds: float | None = None, *, rel_error: float = 0.05, confidence: float = 0.95,
             seed: int = 0, deadline: Deadline | float | None = None, k: int | None = None,
             max_bytes: int = MAX_BYTES, max_draws: int | None = None,
             hopeless: float | None = None, whole: bool = True,
             resume: RelaxEstimate | None = None, count_share: float | None = None,
             threads: int = 1) -> RelaxEstimate | None:
    """Estimate the number of linear extensions of ``poset`` within ``seconds`` and ``deadline``, aiming
    at a stated interval of relative half-width ``rel_error`` at ``confidence`` (see the module's text).

    None where the compiled core is missing or the order has fewer than 2 or more than :data:`MAX_N`
    elements; otherwise a :class:`RelaxEstimate` (status ``"none"`` when no relaxation could be
    counted in time or memory, or ``"hopeless"``: fewer than ``hopeless`` hits are predicted in the
    time left, and no draw is made, so a caller can spend it otherwise).  ``k``
    fixes the piece size (no adaptation); ``max_draws`` caps the draws (default: none but the clock);
    ``whole=False`` skips the one-piece count of an order of at most 64 elements (for a caller whose
    exact counter is at work on it anyway: that count took most of a ±5% estimate's time on 64 elements).
    ``resume``: an earlier estimate of the same order (its ``run``): its relaxation is drawn from again,
    from where its draws stopped, and the two calls' draws make one run (the stopping rule's statement
    holds for the whole, which stopped on the clock once and went on), instead of starting over.
    ``count_share``: the share of the time the relaxations' exact counts may take, their own time
    (None: :data:`COUNT_SHARE`; the rest is for draws, and an order whose draws never hit spends it all
    before it is found hopeless).  ``threads``: threads that count the pieces and draw (the counts,
    the draws and their outcomes are the same for any number: only a stop on the clock or the memory
    cap falls elsewhere; at most :data:`MAX_THREADS`).
    Complexity: see the module.

    >>> from opportune.engine.poset import Poset
    >>> r = estimate(Poset.from_pairs(4, [(0, 1)]), deadline=Deadline.after(0.0))
    >>> r is None or r.status in ("none", "exact")
    True
    """
    core = _native()
    n = poset.n
    if core is None or not 2 <= n <= MAX_N:
        return None
    if not 0 < confidence < 1:
        raise ValueError("confidence must be in (0, 1)")
    if not 1 <= threads <= MAX_THREADS:
        raise ValueError(f"threads must be in 1..{MAX_THREADS}")
    end = as_deadline(deadline).within(seconds)
    hits_wanted = target_hits(rel_error, confidence)
    none = RelaxEstimate(math.nan, -math.inf, math.inf, confidence, math.nan, 0, 0, 0, "none")
    mix = (seed * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) % 2**64
    counting = _Counting(core, poset, end, COUNT_SHARE if count_share is None else count_share, max_bytes,
                         threads, confidence)
    if resume is not None and resume.run is not None:
        if resume.run.n != n:
            raise ValueError(f"resume: an estimate of an order of {resume.run.n} elements, not {n}")
        return _draw(resume.run, hits_wanted, end, confidence, max_draws, threads)
    # an order of at most 64 elements: one piece, exact if it fits (a third of the counting time)
    if n <= K_MAX and (k is None and whole or k is not None and k >= n):
        relax, status, log_r = counting.relaxation([list(range(n))], counting.deadline().share(0.3) if k is None
                                                   else counting.deadline())
        if status == 0:
            return counting.exact(relax, log_r, n)
        del relax
        if k is not None:
            return none
    steps = [min(k, K_MAX, n)] if k is not None else list(range(K_START, min(K_MAX, n - 1) + 1, K_STEP))
    best = counting.best(steps, hits_wanted, mix)
    if best is None:
        return none
    if isinstance(best, RelaxEstimate):     # a relaxation without a cross pair: the count itself
        return best
    if hopeless is not None and end.finite and best.hit_seconds * hopeless / threads > end.remaining():
        return RelaxEstimate(math.nan, -math.inf, math.inf, confidence, best.log_r / math.log(10), best.k, 0, 0,
                             "hopeless", best.relax.bytes())
    return _draw(_Run(best.relax, n, best.log_r, best.k, mix, 0, 0), hits_wanted, end, confidence, max_draws, threads)


class _Counting:
    """The relaxations' exact counts of one :func:`estimate` call: they may take ``share`` of the time,
    their own time only (not the partitions' search or the pilots' draws, which would leave a loaded
    machine's larger pieces uncounted)."""

    def __init__(self, core, poset: Poset, end: Deadline, share: float, max_bytes: int, threads: int,
                 confidence: float):
        self.core, self.n, self.end = core, poset.n, end
        self.preds = [list(bits(poset.below[v])) for v in range(poset.n)]
        self.budget = share * end.remaining() if end.finite else math.inf
        self.spent = 0.0
        self.max_bytes, self.threads, self.confidence = max_bytes, threads, confidence

    def left(self) -> float:
        return self.budget - self.spent

    def deadline(self) -> Deadline:
        return self.end.sooner(Deadline.after(max(0.0, self.left()))) if self.end.finite else self.end

    def relaxation(self, pieces: list[list[int]], until: Deadline):
        relax = self.core.ArmcRelaxation(self.n, self.preds, pieces)
        began = time.perf_counter()
        status, log_r = relax.count(until.seconds(), self.max_bytes, self.threads)
        self.spent += time.perf_counter() - began
        return relax, status, log_r

    def exact(self, relax, log_r: float, kk: int) -> RelaxEstimate:
        lg = log_r / math.log(10)
        err = 1e-9 / math.log(10)        # the doubles' rounding over at most 64 levels of sums
        return RelaxEstimate(lg, lg - err, lg + err, self.confidence, lg, kk, 0, 0, "exact", relax.bytes())

    def best(self, steps: list[int], hits_wanted: int, mix: int) -> _Candidate | RelaxEstimate | None:
        """The piece size among ``steps`` whose draws are predicted to take least (None if none was
        counted; the exact count where a relaxation is the order itself)."""
        n, end, threads = self.n, self.end, self.threads
        best: _Candidate | None = None
        for kk in steps:
            if self.left() <= 0 or end.expired():
                break
            pieces, _inside, _tries = self.core.armc_partition(n, self.preds, kk, TRIES, (mix + kk) % 2**64,
                                                               self.deadline().share(0.1).seconds())
            if not pieces:
                break
            relax, status, log_r = self.relaxation(pieces, self.deadline())
            if status != 0:
                break
            if relax.cross_pairs() == 0:
                return self.exact(relax, log_r, kk)
            entries_work = relax.entries() * ENTRY_SECONDS
            # the pilot: how often a draw hits and how much work a draw is
            _st, d, h, placed = relax.sample(PILOT_DRAWS, PILOT_HITS, end.seconds(),
                                             (mix ^ 0x5851F42D4C957F2D) + kk, 0, threads)
            per_hit = math.inf if h == 0 else d / h * (placed / max(1, d)) * STEP_SECONDS
            cand = _Candidate(relax, log_r, kk, entries_work, hits_wanted * per_hit, per_hit)
            if best is None or (cand.draw_seconds, cand.log_r) < (best.draw_seconds, best.log_r):
                best = cand
            del relax, cand
            # the next k's count is worth it only while it is cheaper than the draws still needed (both
            # shared by the threads: its pieces counted at once, the draws in blocks), and fits in the time
            nxt = COUNT_GROWTH * max(entries_work, 1e-4)
            at_once = min(threads, -(-n // min(n, kk + K_STEP)))
            if nxt > best.draw_seconds or (end.finite and nxt / at_once > self.left()):
                break
        return best


def _draw(run: _Run, hits_wanted: int, end: Deadline, confidence: float, max_draws: int | None,
          threads: int = 1) -> RelaxEstimate:
    """Draw from ``run``'s relaxation, after its draws so far, until ``hits_wanted`` hits in all, ``max_draws``
    draws in all, or ``end``; the estimate of every draw made, with the run to go on from."""
    relax = run.relax
    cap = ((1 << 62) if max_draws is None else max_draws) - run.draws
    status, d, h, _placed = relax.sample(max(0, cap), max(0, hits_wanted - run.hits), end.seconds(), run.mix,
                                         run.draws, threads) if cap > 0 and run.hits < hits_wanted else (
        0 if run.hits >= hits_wanted else 1, 0, 0, 0)
    draws, hits = run.draws + d, run.hits + h
    after = _Run(relax, run.n, run.log_r, run.k, run.mix, draws, hits)
    log10_r = run.log_r / math.log(10)
    lo, hi = clopper_pearson(hits, draws, confidence)
    how = {0: "hits", 1: "draws", 2: "time"}.get(status, "time")
    if hits == 0:
        up = log10_r + math.log10(hi) if hi > 0 else log10_r
        return RelaxEstimate(up - 1, -math.inf, up, confidence, log10_r, run.k, draws, hits, how, relax.bytes(), after)
    return RelaxEstimate(log10_r + math.log10(hits / draws), log10_r + math.log10(lo), log10_r + math.log10(hi),
                         confidence, log10_r, run.k, draws, hits, how, relax.bytes(), after)
