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
``particles`` make each run both less variable and less skewed (a run's cost and spread on ARC111,
measured: the documentation's page on counting, which also says how the interval came to take
the logs into account).  Orders with a hub are counted exactly through it
(:mod:`opportune.engine.hub`), which :func:`estimate_count` tries before sampling; the estimator is
what is left for orders with neither structure.

An estimate always comes back, on time.  Everything stops at one
:class:`~opportune.engine.deadline.Deadline`, read inside a run and inside a
path, not only between them.  Before any run, one pass over the order
(:class:`OrderSketch`, O(n + covers)) gives certain bounds (layers of minimal
elements below; insertion counts and a chain partition above) and the first
path of Knuth's estimator (hook-weighted sequential importance sampling,
unbiased from one path).  Where no run fits the time (a run costs about
``SMC_COST`` × particles × n² seconds: thousands of elements), the estimate is
the mean of such paths and the interval is the order's bounds; with no time at
all, the middle of the bounds ``1 <= e <= n!``.
"""

from __future__ import annotations

import gc
import math
import random
import time
from dataclasses import dataclass, field, replace
from statistics import NormalDist

from opportune.engine.count import Counter
from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline
from opportune.engine.hub import hub_split
from opportune.engine.poset import Poset, bits, components, cut_blocks
from opportune.engine.tuning import (
    ERROR_MARGIN as _MARGIN, SMC_COST, SKETCH_FLOOR, SKETCH_FLOOR_MOST, ARMC_MAX_N, ARMC_MIN_N,
    ARMC_SHARE, ARMC_HOPELESS)

__all__ = ["Estimate", "OrderSketch", "estimate_count", "relaxation_estimate"]


@dataclass(frozen=True)
class Estimate:
    """An estimated number of linear extensions.

    ``value`` is the estimate; with probability ``confidence`` the true count
    lies within ``value * (1 ± rel_error)``.  ``method`` is ``"exact"`` (then
    ``rel_error == 0``, ``confidence == 1`` and ``exact`` holds the int) or
    ``"smc"`` (sequential Monte Carlo; ``samples`` is then the number of
    independent runs whose spread gives the interval), ``"armc"`` (adaptive relaxation Monte Carlo,
    :mod:`opportune.engine.relaxmc`; ``samples`` draws of an exactly counted relaxation, an exact
    binomial interval), ``"sis"`` (sequential
    importance sampling: ``samples`` uniform-choice paths, each an unbiased
    estimate; no stated ``rel_error``) or ``"bounds"`` (not one sample finished
    in time: the geometric middle of the bounds).  ``log10_value`` is usable
    when ``value`` overflows a float.

    ``log10_low`` and ``log10_high`` bound the count on a log scale: the
    stated interval where it is finite, always within the certain bounds
    that the order itself gives (:class:`OrderSketch`), so they are finite
    whenever the estimate was asked for (the interval holds with probability
    at least ``confidence``; from the order's bounds alone, surely).
    """

    value: float
    rel_error: float
    confidence: float
    method: str
    samples: int = 0
    log10_value: float = float("nan")
    exact: int | None = field(default=None, compare=False)
    seconds: float = field(default=0.0, compare=False)
    log10_low: float = field(default=float("nan"), compare=False)
    log10_high: float = field(default=float("nan"), compare=False)
    #: ``"armc"``: the relaxation and its draws, for a later estimate of the same set to go on from
    #: (``resume=`` of :func:`relaxation_estimate` and :func:`estimate_count`)
    resume: object = field(default=None, compare=False, repr=False)

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


_LN10 = math.log(10)


def _peel(succ: dict[int, list[int]], indeg: dict[int, int]) -> tuple[list[int], list[int]]:
    """Layers of minimal elements peeled one after another (Kahn's algorithm by rounds): the size of
    each layer and the elements in layer order.  O(elements + covers).

    >>> _peel({0: [2], 1: [2], 2: []}, {0: 0, 1: 0, 2: 2})
    ([2, 1], [0, 1, 2])
    """
    deg = dict(indeg)
    sizes, order = [], []
    frontier = [i for i, d in indeg.items() if d == 0]
    while frontier:
        sizes.append(len(frontier))
        order.extend(frontier)
        nxt = []
        for x in frontier:
            for y in succ[x]:
                deg[y] -= 1
                if not deg[y]:
                    nxt.append(y)
        frontier = nxt
    return sizes, order


class OrderSketch:
    """What a single pass over the order of a set ``s`` tells about its number of linear extensions
    ``e(s)``: certain bounds, and a cheap unbiased estimate from one random path.

    Built from the covers within ``s`` (the minimal elements of ``above[x] & s``; the same descent as
    :meth:`~opportune.engine.poset.Poset.cover_pairs`), O(|s| + covers) big-int operations when the
    elements are numbered in a topological order, as plans usually are; the ``deadline`` is read
    every 32 elements (:class:`BudgetExceeded` past it).  Then, in O(|s| + covers) list operations:

    * ``low``: ``ln e(s) >= sum ln(|L|!)`` over the layers ``L`` of minimal elements peeled off one
      after another (all of a layer may come in any order once the layers before it are done; the
      layers of maximal elements too, and the larger of the two is kept);
    * ``high``: the smaller of two upper bounds.  Inserting the elements one at a time in a
      topological order, element ``i`` goes after all its predecessors, so into at most
      ``1 + (i - |predecessors|)`` slots: ``e(s) <= prod (1 + i - |below(x_i) & s|)``.  And every
      linear extension is an interleaving of the chains of a chain partition (greedy, along the
      covers): ``e(s) <= |s|! / prod |C|!``.  Both are exact for a chain and for an antichain.
    * :meth:`sample`: one path of Knuth's estimator (sequential importance sampling): remove a
      minimal element chosen at random (by its hook) until nothing is left; the product of the
      inverse probabilities of the choices is an unbiased estimate of ``e(s)``.  O(|s| + covers),
      the deadline read every 256 steps.

    >>> p = Poset.from_pairs(4, [(0, 1), (2, 3)])          # two chains of two: 6 linear extensions
    >>> o = OrderSketch(p, p.full)
    >>> round(math.exp(o.low)), round(math.exp(o.high))    # layers {0, 2}, {1, 3}: 2! 2! = 4
    (4, 6)
    >>> round(math.exp(o.sample(random.Random(1))))       # a forest: every path gives the count
    6
    """

    def __init__(self, poset: Poset, s: int, deadline: Deadline | float | None = None):
        dl = as_deadline(deadline)
        above, below = poset.above, poset.below
        self.n = n = s.bit_count()
        up: dict[int, list[int]] = {}
        indeg: dict[int, int] = {}
        for k, i in enumerate(bits(s)):
            if not k & 31:
                dl.check("the bounds of an estimate")
            rest = above[i] & s
            direct = []
            steps = 0
            while rest:
                low = rest & -rest
                j = low.bit_length() - 1
                under = below[j] & rest
                while under:        # j is not minimal in what is left: go down
                    low = under & -under
                    j = low.bit_length() - 1
                    under = below[j] & rest
                    steps += 1
                    if not steps & 1023:
                        dl.check("the bounds of an estimate")
                direct.append(j)
                rest &= ~(above[j] | low)
            up[i] = direct
            indeg.setdefault(i, 0)
            for j in direct:
                indeg[j] = indeg.get(j, 0) + 1
        self.up = up
        self.indeg = indeg
        self.minimal = [i for i, d in indeg.items() if d == 0]
        self.logs = [0.0] + [math.log(k) for k in range(1, n + 1)]
        # layers of minimal elements, peeled one after another (Kahn's algorithm by rounds)
        layers, order = _peel(up, indeg)
        dl.check("the bounds of an estimate")
        low_min = sum(math.lgamma(k + 1) for k in layers)
        # layers of maximal elements (the same on the dual order)
        down: dict[int, list[int]] = {i: [] for i in up}
        for i, js in up.items():
            for j in js:
                down[j].append(i)
        low_max = sum(math.lgamma(k + 1) for k in _peel(down, {i: len(js) for i, js in up.items()})[0])
        self.low = max(low_min, low_max)
        # insertion bound along the layer order; the hooks for the proposal of sample()
        ins = 0.0
        hook: dict[int, int] = {}
        for k, x in enumerate(order):
            if not k & 255:
                dl.check("the bounds of an estimate")
            ins += math.log(1 + k - (below[x] & s).bit_count())
            hook[x] = 1 + (above[x] & s).bit_count()
        self.hook = hook
        # greedy chain partition along the covers: a chain goes on from a cover below whose chain ends there
        tail_free: set[int] = set()
        size: dict[int, int] = {}
        chain_of: dict[int, int] = {}
        for x in order:
            for p in down[x]:
                if p in tail_free:
                    tail_free.discard(p)
                    c = chain_of[p]
                    break
            else:
                c = x
            chain_of[x] = c
            size[c] = size.get(c, 0) + 1
            tail_free.add(x)
        chains = math.lgamma(n + 1) - sum(math.lgamma(k + 1) for k in size.values())
        self.high = max(self.low, min(ins, chains))

    def sample(self, rng: random.Random, deadline: Deadline | float | None = None) -> float | None:
        """Natural log of one unbiased estimate of ``e(s)``; None past ``deadline`` (read every 256 steps).

        Knuth's estimator with a proposal: remove a minimal element ``x`` with probability
        ``q(x)`` proportional to its hook ``h(x) = 1 + |above(x) & s|`` (what a uniformly random
        linear extension puts first with probability ``h(x) / |s|`` on a forest), and multiply
        the ``1 / q(x)`` of the path: an unbiased estimate, exact on forests, far less variable
        than uniform choices on assembly orders.  (The hooks stay fixed along a path: nothing
        removed is above an element still there.)  O(|s| + covers) list operations, plus
        O(log |s|) per step for the weighted choice.
        """
        dl = as_deadline(deadline)
        up, hook = self.up, self.hook
        deg = dict(self.indeg)
        # the minimal elements in buckets by the binary length of their hooks: a bucket is chosen by
        # its total, then an element of it uniformly and kept with probability hook / 2^length (at
        # least 1/2), so that an element is chosen with probability hook / total in O(log n)
        buckets: list[list[int]] = [[] for _ in range(max(hook.values(), default=1).bit_length() + 1)]
        sums = [0] * len(buckets)
        pos: dict[int, int] = {}
        h_total = 0
        for x in self.minimal:
            b = hook[x].bit_length()
            pos[x] = len(buckets[b])
            buckets[b].append(x)
            sums[b] += hook[x]
            h_total += hook[x]
        rnd = rng.random
        log = math.log
        total = 0.0
        step = 0
        while h_total:
            r = rnd() * h_total
            b = 0
            for b, sb in enumerate(sums):
                if r < sb:
                    break
                r -= sb
            bucket = buckets[b]
            while not bucket:           # float rounding at the end of the walk: the last non-empty one
                b -= 1
                bucket = buckets[b]
            top = 1 << b
            while True:
                x = bucket[int(rnd() * len(bucket))]
                if rnd() * top < hook[x]:
                    break
            w = hook[x]
            total += log(h_total / w)
            h_total -= w
            sums[b] -= w
            last = bucket.pop()
            if last != x:
                bucket[pos[x]] = last
                pos[last] = pos[x]
            for y in up[x]:
                d = deg[y] - 1
                deg[y] = d
                if not d:
                    wy = hook[y]
                    c = wy.bit_length()
                    pos[y] = len(buckets[c])
                    buckets[c].append(y)
                    sums[c] += wy
                    h_total += wy
            step += 1
            if not step & 255 and dl.expired():
                return None
        return total

    @staticmethod
    def trivial(n: int) -> tuple[float, float]:
        """The bounds that hold for every order of ``n`` elements: ``1 <= e <= n!`` (natural logs)."""
        return 0.0, math.lgamma(n + 1)


def _log_mean(logs: list[float]) -> float:
    """Natural log of the mean of numbers given by their natural logs."""
    mx = max(logs)
    if mx == -math.inf:
        return mx
    return mx + math.log(sum(math.exp(x - mx) for x in logs) / len(logs))


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

    def _exact(self, s: int, deadline: Deadline = Deadline.NEVER) -> int | None:
        """e(s) from the memo, or counted under the small tail budget; None if over it (or past
        ``deadline``)."""
        c = self.counter
        v = c.cached(s)
        if v is not None or s & (s - 1) == 0:
            return 1 if v is None else v
        try:
            return c.count(s, deadline=deadline)
        except BudgetExceeded:
            return None

    def probe_tail(self, root: int, rng: random.Random, deadline: Deadline = Deadline.NEVER) -> int:
        """The largest size (found by bisection on random remaining sets) the exact counter handles
        cheaply; what is known so far once ``deadline`` has passed (read at every step of a path)."""
        below = self.poset.below

        def random_rest(size: int) -> int | None:
            s = root
            while s.bit_count() > size:
                if deadline.expired():
                    return None
                mins = [i for i in bits(s) if not below[i] & s]
                s ^= 1 << rng.choice(mins)
            return s

        lo, hi = 1, root.bit_count()        # lo: handled; hi: not handled (the whole piece was not)
        while hi - lo > max(1, hi // 20):
            mid = (lo + hi) // 2
            ok = True
            for _ in range(2):
                t = random_rest(mid)
                if t is None:
                    return lo
                if self._exact(t, deadline) is None:
                    ok = False
                    break
            if ok:
                lo = mid
            else:
                hi = mid
        return lo

    def run(self, root: int, tail: int, rng: random.Random, deadline: Deadline | float) -> float | None:
        """Natural log of one unbiased estimate of e(root); None if the deadline passed first (read
        every 64 sets of a step, so a step of a large population stops on time too)."""
        dl = as_deadline(deadline)
        expired = dl.expired
        above, up_t, nbytes, log1 = self.above, self.up_t, self.nbytes, self.log1
        tail = min(tail, self.tails.get(root, tail))
        log, exp = math.log, math.exp
        exact = self._exact
        B = self.particles
        states: dict[int, list] = {root: [1.0, 0.0]}     # set -> [weight, log hook guess]
        scale = 0.0                                       # log of the common factor of all weights
        terms: list[float] = []                           # log contributions of finished sets
        while states:
            if expired():
                return None
            kids: dict[int, list] = {}
            get = kids.get
            for k, (s, (w, lh)) in enumerate(states.items()):
                if not k & 63 and k and expired():
                    return None
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
                    if not tried & 63 and expired():
                        return None
                    v = exact(t, dl)
                    if v is None:
                        if expired():       # cut by the clock: not a sign that the tail is too large
                            return None
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
                if expired():           # (a resampling sorts the population: one check before it)
                    return None
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


def _pieces(counter: Counter, mask: int, deadline: Deadline = Deadline.NEVER) -> tuple[float, list[int]]:
    """Split ``mask`` as the exact counter does (cut elements, components), counting cheap pieces exactly.

    Returns the log of the exact factor (multinomials and exactly counted pieces)
    and the pieces left to estimate: connected sets without cut elements.  Raises
    :class:`BudgetExceeded` past ``deadline`` (read for every set split).
    """
    below, above = counter.poset.below, counter.poset.above
    logf = 0.0
    hard = []
    stack = [mask]
    while stack:
        deadline.check("splitting a set for an estimate")
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
        comps = components(above, s, counter.scan(s)[0], deadline=deadline)
        if len(comps) > 1:
            logf += math.lgamma(s.bit_count() + 1) - sum(math.lgamma(c.bit_count() + 1) for c in comps)
            stack.extend(comps)
            continue
        hard.append(s)
    return logf, hard




def relaxmc_available() -> bool:
    """True when adaptive relaxation Monte Carlo can run (the compiled core is there)."""
    from opportune.engine import relaxmc
    return relaxmc.available()


def _armc(poset: Poset, mask: int, rel_error: float, confidence: float, seed: int, deadline: Deadline,
          low: float, high: float, start: float, whole: bool = True,
          resume: Estimate | None = None, count_share: float | None = None, threads: int = 1) -> Estimate | None:
    """Adaptive relaxation Monte Carlo on the subposet ``mask`` (:func:`opportune.engine.relaxmc.estimate`)
    as an :class:`Estimate` (method ``"armc"``, ``samples`` its draws), its value and interval within
    the certain bounds ``low``/``high`` (natural logs); None without the compiled core, without a hit,
    or when the draws it would need are hopeless within ``deadline``."""
    from opportune.engine import relaxmc

    try:
        sub = poset if mask == poset.full else poset.restrict(mask, deadline=deadline)[0]
    except BudgetExceeded:
        return None
    r = relaxmc.estimate(sub, rel_error=rel_error, confidence=confidence, seed=seed, deadline=deadline,
                         hopeless=ARMC_HOPELESS, whole=whole, count_share=count_share, threads=threads,
                         resume=resume.resume if resume is not None and resume.method == "armc" else None)
    if r is None or not math.isfinite(r.log10) or r.hits == 0 and r.status != "exact":
        return None
    lmean = min(max(r.log10 * _LN10, low), high)
    lo = max(low, min(high, r.log10_low * _LN10))
    hi = min(high, max(low, r.log10_high * _LN10))
    return Estimate(math.exp(lmean) if lmean < 709 else math.inf, r.rel_error, confidence, "armc", r.draws,
                    lmean / _LN10, None, time.perf_counter() - start, lo / _LN10, hi / _LN10, r)


def relaxation_estimate(poset: Poset, mask: int | None = None, *, rel_error: float = 0.01, seed: int = 0,
                        confidence: float = 0.95, deadline: Deadline | float | None = None,
                        whole: bool = True, resume: Estimate | None = None,
                        count_share: float | None = None, threads: int = 1) -> Estimate | None:
    """Adaptive relaxation Monte Carlo (:mod:`opportune.engine.relaxmc`) on the subposet ``mask`` of
    ``poset`` as an :class:`Estimate` (method ``"armc"``; where one piece held the whole order, its
    count in doubles, ``rel_error`` of about 1e-9), its interval within the order's trivial bounds
    ``1 <= e <= n!``; None where it does not apply (no compiled core, fewer than :data:`ARMC_MIN_N` or more than :data:`ARMC_MAX_N`
    elements, no finite ``deadline``) or found no hit in time.  Stops once the interval is within
    ``rel_error``, and at once where the draws it would need are hopeless.  ``whole=False``: no
    one-piece count first (see :func:`opportune.engine.relaxmc.estimate`); ``resume``: an earlier
    estimate of the same set by this function, whose draws go on (see there); ``count_share``: the
    share of the time for counting relaxations (default :data:`opportune.engine.relaxmc.COUNT_SHARE`);
    ``threads``: threads that draw (the same answer for any number, but for a stop on the clock).

    >>> from opportune.engine.poset import Poset
    >>> e = relaxation_estimate(Poset.antichain(3), deadline=Deadline.after(1.0))
    >>> e is None or e.value                                  # too small: None
    True
    """
    start = time.perf_counter()
    if mask is None:
        mask = poset.full
    dl = as_deadline(deadline)
    if not (ARMC_MIN_N <= mask.bit_count() <= ARMC_MAX_N and dl.finite and relaxmc_available()) or dl.expired():
        return None
    low, high = OrderSketch.trivial(mask.bit_count())
    return _armc(poset, mask, rel_error, confidence, seed, dl, low, high, start, whole, resume, count_share, threads)


def estimate_count(poset: Poset, mask: int | None = None, *, rel_error: float = 0.01,
                   time_limit: float | None = 10.0, seed: int = 0, confidence: float = 0.95,
                   counter: Counter | None = None, exact_memo: int = 300_000, particles: int = 1024,
                   tail: int | None = None, tail_memo: int = 500, min_runs: int = 20, hub: float = 0.85,
                   overrun: float = math.inf, deadline: Deadline | float | None = None,
                   relaxation: bool | None = None, resume: Estimate | None = None, threads: int = 1) -> Estimate:
    """Estimate the number of linear extensions of the subposet induced on ``mask``, with a stated error.

    All the work stops at ``deadline`` and ``time_limit`` seconds from now, as below; the call returns
    within the granularity of the checks after it (every loop whose length depends on the order
    reads the deadline, inside a run or a path too).  The steps, the first with the answer giving it:

    1. the exact counter (at most ``exact_memo`` new memo entries and a quarter of ``time_limit``):
       the exact count with ``rel_error=0`` if it finishes;
    2. one pass over the order (:class:`OrderSketch`: certain bounds, and one path of Knuth's
       estimator, so that an estimate exists from that pass on);
    3. the set split into pieces as the counter does, each hard piece counted exactly through a hub
       (:func:`~opportune.engine.hub.hub_split`) until the fraction ``hub`` of ``time_limit`` has
       passed;
    4. with the compiled core, on a set of :data:`ARMC_MIN_N` to :data:`ARMC_MAX_N` elements, with
       ``exact_memo > 0`` (its relaxations are exact counts) and a time limit or deadline (without
       one its draws could go on for ever where hits are rare): adaptive relaxation Monte Carlo on
       the whole set (:mod:`opportune.engine.relaxmc`), with the share :data:`ARMC_SHARE` of the
       time left.  Its estimate (method ``"armc"``, ``samples`` its draws) is returned at once if
       its stated interval is within ``rel_error``, else at the end if it is narrower than the
       runs';
    5. what is still not counted is estimated by sequential Monte Carlo (see the module doc),
       repeating independent runs until the stated ``confidence`` interval of their mean (see
       :func:`_stated_error`) is within ``rel_error`` of it (after at least ``min_runs`` runs:
       stopping as soon as a few runs happen to agree would make the interval optimistic) or
       ``time_limit`` seconds have passed (the first two runs may go on ``overrun`` seconds longer,
       never past ``deadline``: without two runs no error can be stated).  A run predicted
       (``SMC_COST``) to take longer than the time left is not started (and one that would take
       more than a quarter of the time left has fewer particles, down to 64): the time, up to the
       end of the first two runs', goes to more paths of Knuth's estimator, whose mean is then the
       estimate (method ``"sis"``, no stated error).

    The returned ``rel_error`` is the half-width actually achieved (infinite with fewer than two
    runs): it may exceed the requested one by far (hundreds of percent from 2–3 runs of a variable
    estimator), and is then the honest statement of the error.  ``log10_low``/``log10_high`` always
    hold finite bounds (the stated interval within the order's certain bounds), and ``value`` is
    never nan.  Deterministic given ``seed`` when it stops on accuracy; a stop on the clock depends
    on machine speed.

    Parameters
    ----------
    poset : Poset
        The order.
    mask : int or None, optional
        The elements to count the orders of (a bitmask; None: all of them).
    rel_error : float, default 0.01
        The relative error to stop at (the interval's half-width over the estimate).
    time_limit : float or None, default 10.0
        Seconds for the whole estimate (None: none but ``deadline``).
    seed : int, default 0
        Seed of every random draw.
    confidence : float, default 0.95
        The probability the stated interval should hold, in (0, 1).
    counter : Counter or None, optional
        The plan's counter of ``poset``, to reuse (and extend) its memo (None, or one of another
        order: a new one).
    exact_memo : int, default 300,000
        New memo entries the first exact try may add (0: no exact try, and no relaxation Monte
        Carlo unless ``relaxation`` is True).
    particles : int, default 1024
        Sets per step of each sequential Monte Carlo run.
    tail : int or None, optional
        Sets of at most this many elements are finished exactly (None: the largest size the
        counter handles within ``tail_memo`` new entries, found by probing).
    tail_memo : int, default 500
        The memo entries that probe allows.
    min_runs : int, default 20
        Runs before the error may stop the estimate.
    hub : float, default 0.85
        The share of ``time_limit`` the hub split may use (0 disables it).
    overrun : float, default inf
        Seconds the first two runs may go on past ``time_limit`` (never past ``deadline``).
    deadline : Deadline or float or None, optional
        When all the work stops (a :class:`~opportune.engine.deadline.Deadline`; a float is a
        ``time.perf_counter()`` moment; None: none).
    relaxation : bool or None, optional
        Relaxation Monte Carlo on or off (None: on when ``exact_memo > 0``).
    resume : Estimate or None, optional
        An earlier ``"armc"`` estimate of the same set, whose relaxation and draws it goes on with.
    threads : int, default 1
        Threads that count and draw in relaxation Monte Carlo (the same answer for any number, but
        for a stop on the clock).

    Returns
    -------
    Estimate
        The estimate: ``value``, ``rel_error``, ``confidence``, ``method`` (``"exact"``, ``"smc"``,
        ``"armc"``, ``"sis"`` or ``"bounds"``), ``log10_low``/``log10_high``, and the count itself
        in ``exact`` when exact.

    Raises
    ------
    ValueError
        ``mask`` is not a subset of ``0..n-1``, or ``confidence`` is not in (0, 1).

    Examples
    --------
    >>> p = Poset.from_pairs(4, [(0, 1), (2, 3)])
    >>> e = estimate_count(p)
    >>> e.value, e.rel_error, e.method
    (6.0, 0.0, 'exact')
    >>> n = Poset.from_pairs(4, [(0, 2), (1, 2), (1, 3)])     # the "N": connected, no cut element
    >>> e = estimate_count(n, exact_memo=0, tail=0, rel_error=0.05, seed=1)
    >>> e.method, round(e.value, 9), e.rel_error            # 2 sets per step at most: nothing sampled
    ('smc', 5.0, 0.0)
    >>> e = estimate_count(n, exact_memo=0, deadline=Deadline.after(0.0))   # no time at all: the bounds'
    >>> e.method, 10 ** e.log10_low <= 5 <= 10 ** e.log10_high           # pass still, and its first path
    ('sis', True)
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
    hard_end = as_deadline(deadline)
    e = _Estimation(poset, mask, counter, start, hard_end, hard_end.within(time_limit),
                    hard_end.within(None if time_limit is None else time_limit + overrun), rel_error, confidence, seed)
    try:
        return e.run(time_limit, exact_memo, particles, tail, tail_memo, min_runs, hub,
                     exact_memo > 0 if relaxation is None else relaxation, resume, threads)
    finally:
        counter.max_memo, counter.time_limit = e.saved


class _Estimation:
    """One call of :func:`estimate_count`: its deadlines, what its steps found so far (the certain
    bounds, the paths of Knuth's estimator, the runs, the relaxation estimate), and the steps."""

    def __init__(self, poset: Poset, mask: int, counter: Counter, start: float, hard_end: Deadline,
                 soft: Deadline, runs_end: Deadline, rel_error: float, confidence: float, seed: int):
        self.poset, self.mask, self.counter, self.start = poset, mask, counter, start
        self.hard_end, self.soft, self.runs_end = hard_end, soft, runs_end
        self.rel_error, self.confidence, self.seed = rel_error, confidence, seed
        self.saved = counter.max_memo, counter.time_limit
        self.low, self.high = OrderSketch.trivial(mask.bit_count())
        self.armc = None
        self.sketch = None
        self.sis: list[float] = []
        self.runs: list[float] = []
        self.logf = 0.0
        self.half = math.inf
        self.sis_rng = random.Random(seed * 1_000_003 + 999_983)

    def exact(self, v: int) -> Estimate:
        lg = _log10_int(v)
        return Estimate(_float_or_inf(v), 0.0, 1.0, "exact", 0, lg, v, time.perf_counter() - self.start, lg, lg)

    def memo(self, entries: int) -> None:
        """The counter's memo budget for a step: ``entries`` new ones, within its own."""
        self.counter.max_memo = entries if self.saved[0] is None else min(entries, self.saved[0])

    def run(self, time_limit, exact_memo, particles, tail, tail_memo, min_runs, hub, relaxation, resume,
            threads) -> Estimate:
        """The steps in order: the first that has the answer gives it."""
        # 1. exact, under a budget
        self.memo(exact_memo)
        self.counter.time_limit = None
        try:
            return self.exact(self.counter.count(self.mask, deadline=self.hard_end.within(
                None if time_limit is None else time_limit / 4)))
        except BudgetExceeded:
            pass
        done = self.sketch_pass()
        if done is not None:
            return done
        hard, done = self.pieces(time_limit, particles, tail_memo, hub)
        if done is not None:
            return done
        if self.sketch is not None and relaxation:
            done = self.relaxation(resume, threads)
            if done is not None:
                return done
        self.sampling(hard, particles, tail, tail_memo, min_runs)
        return self.answer()

    def sketch_pass(self) -> Estimate | None:
        """2. One pass over the order: certain bounds, and the first path of Knuth's estimator (the
        answer where the bounds meet: a chain or an antichain)."""
        mask, hard_end = self.mask, self.hard_end
        try:
            # the certain bounds are what every answer has: their one pass gets at least about its own
            # cost (SKETCH_FLOOR per element, at most SKETCH_FLOOR_MOST seconds) even where the time is spent,
            # on a busy machine too; past that, the trivial bounds
            floor = time.perf_counter() + min(SKETCH_FLOOR_MOST, SKETCH_FLOOR * mask.bit_count())
            collecting = gc.isenabled()
            gc.disable()        # a full collection (tens of ms in a large process) must not eat the floor
            try:
                self.sketch = OrderSketch(self.poset, mask, hard_end if hard_end.at >= floor else Deadline(floor))
            finally:
                if collecting:
                    gc.enable()
            self.low, self.high = self.sketch.low, self.sketch.high
        except BudgetExceeded:
            pass
        if self.sketch is None:
            return None
        lv = self.sketch.sample(self.sis_rng, hard_end)     # even past the deadline: the first path
        if lv is not None:
            self.sis.append(lv)
        low, high = self.low, self.high
        if high - low < 1e-12 * max(1.0, high):     # a chain or an antichain: the bounds are the count
            return Estimate(math.exp(low) if low < 709 else math.inf, math.expm1(high - low), 1.0,
                            "bounds", len(self.sis), low / _LN10, None, time.perf_counter() - self.start,
                            low / _LN10, high / _LN10)
        return None

    def paths(self, most: int, end: Deadline) -> None:
        """More paths of Knuth's estimator, until there are ``most`` or ``end``."""
        while len(self.sis) < most and not end.expired():
            lv = self.sketch.sample(self.sis_rng, end)
            if lv is None:
                break
            self.sis.append(lv)

    def pieces(self, time_limit, particles, tail_memo, hub) -> tuple[list[int] | None, Estimate | None]:
        """3. The pieces that are still hard, each tried exactly through a hub: ``(the hard pieces or
        None, the exact answer if every piece was counted)``.  Not even tried where a run on pieces a
        tenth of the whole would not fit in the time: splitting 10,000 elements costs seconds, better
        spent on paths."""
        counter, mask, saved = self.counter, self.mask, self.saved
        self.memo(tail_memo)
        try:
            if (self.sketch is not None
                    and SMC_COST * max(2, particles) * mask.bit_count() ** 2 > 100 * self.runs_end.remaining()):
                raise BudgetExceeded("no run of the sequential Monte Carlo fits", reason="time")
            self.logf, hard = _pieces(counter, mask, self.runs_end)
            if hard and hub:
                # exact again, splitting the hard pieces at a hub (most of the time left, shared out)
                counter.max_memo, counter.time_limit = saved
                soft = self.soft
                hub_end = soft if time_limit is None else soft.sooner(Deadline(self.start + time_limit * hub))
                for i, s in enumerate(hard):
                    if hub_end.expired() or hub_split(counter, s, deadline=hub_end.share(1 / (len(hard) - i))) is None:
                        break
                else:
                    hard = []
                self.memo(tail_memo)
                counter.time_limit = None
                if hard:
                    self.logf, hard = _pieces(counter, mask, self.runs_end)
            if not hard:                # every piece is in the memo: the whole is one cheap exact count
                counter.max_memo = None
                return hard, self.exact(counter.count(mask, deadline=self.hard_end))
        except BudgetExceeded:
            hard = None
        return hard, None

    def relaxation(self, resume, threads) -> Estimate | None:
        """4. Adaptive relaxation Monte Carlo (compiled core) on the whole set: an exactly counted
        relaxation and a binomial interval; the answer at once when it is as narrow as asked, else
        kept to compare with the runs'."""
        mask, soft = self.mask, self.soft
        if (ARMC_MIN_N <= mask.bit_count() <= ARMC_MAX_N and relaxmc_available() and soft.finite
                and not soft.expired()):
            self.armc = _armc(self.poset, mask, self.rel_error, self.confidence, self.seed, soft.share(ARMC_SHARE),
                              self.low, self.high, self.start, resume=resume, threads=threads)
            if self.armc is not None and self.armc.rel_error <= self.rel_error:
                return self.armc
            if self.armc is not None:        # an error is stated already: the runs need not overrun for one
                self.runs_end = soft
        return None

    def sampling(self, hard, particles, tail, tail_memo, min_runs) -> None:
        """5. Sequential Monte Carlo runs on the hard pieces where one fits (and a few more paths
        beside them), else more paths."""
        # a run is started if one could finish before the end of the first two runs' time: even one
        # run is a better estimate than the paths (which are kept if none finishes)
        smc_fits = bool(hard) and (SMC_COST * max(2, particles) * sum(s.bit_count() ** 2 for s in hard)
                                   <= self.runs_end.remaining())
        if self.sketch is not None and smc_fits:
            # a twentieth of the time for more paths (a hundred at most): an estimate however the
            # runs below fare
            self.paths(100, self.soft.share(0.05))
        if smc_fits:
            # fewer particles (down to 64) when a run would take more than a quarter of the time left
            cost = SMC_COST * sum(s.bit_count() ** 2 for s in hard)
            while particles > 64 and cost * particles > self.runs_end.remaining() / 4:
                particles //= 2
            self.smc_runs(hard, particles, tail, tail_memo, min_runs)
        elif self.sketch is not None:
            # no run fits: the time goes to more paths (a thousand at most: their mean settles slowly,
            # and the work is better left to a longer time limit than spent on a hopeless spread)
            self.paths(1000, self.runs_end)

    def smc_runs(self, hard, particles, tail, tail_memo, min_runs) -> None:
        """Independent runs until their stated interval is within the error asked (after ``min_runs``)
        or the time is up (the first two runs may go on to ``runs_end``)."""
        soft, runs_end, runs = self.soft, self.runs_end, self.runs
        smc = _SMC(self.poset, self.counter, particles, tail_memo)
        probe_rng = random.Random(self.seed * 7919 + 1)
        tails = [tail if tail is not None else smc.probe_tail(s, probe_rng, runs_end) for s in hard]
        while True:
            rng = random.Random(self.seed * 1_000_003 + len(runs))
            total = 0.0
            # the first two runs may go on past the soft end: without them no error can be stated
            run_end = soft if len(runs) >= 2 else runs_end
            for s, t in zip(hard, tails):
                lv = smc.run(s, t, rng, run_end)
                if lv is None:
                    break
                total += lv
            else:
                runs.append(total)
            n = len(runs)
            if n >= 2:
                self.half = _stated_error(runs, self.confidence)
                if self.half <= self.rel_error and n >= min_runs:
                    break
            if soft.expired() and (len(runs) >= 2 or runs_end.expired()):
                break

    def answer(self) -> Estimate:
        """The estimate from what the steps found, its interval within the order's certain bounds."""
        armc, half, low, high = self.armc, self.half, self.low, self.high
        if armc is not None and armc.rel_error < half:    # the narrower stated interval
            return replace(armc, seconds=time.perf_counter() - self.start)
        if self.runs:
            method, lmean = "smc", _log_mean(self.runs) + self.logf
        elif self.sis:
            method, lmean, half = "sis", _log_mean(self.sis), math.inf
        else:
            method, lmean, half = "bounds", (low + high) / 2, math.inf
        lmean = min(max(lmean, low), high)
        lo, hi = low, high
        if half < 1:
            lo = max(low, min(high, lmean + math.log1p(-half)))
        if math.isfinite(half):
            hi = min(high, max(low, lmean + math.log1p(half)))
        value = math.exp(lmean) if lmean < 709 else float("inf")
        return Estimate(value, half, self.confidence, method, len(self.runs) or len(self.sis), lmean / _LN10, None,
                        time.perf_counter() - self.start, lo / _LN10, hi / _LN10)
