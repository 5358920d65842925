"""Estimates from random completions, for decisions that must come back within a time budget.

The opportunistic rule needs only ratios: a candidate's *options* are the completions
times the probability that it comes next in a uniformly random completion, and "needed
earliest" is an expected position.  When the exact counts do not fit the budget, both
are estimated from a population of Markov chains on the completions (linear
extensions of what remains):

* **The chain** is that of Karzanov & Khachiyan (1991) in the lazy form analysed by
  Bubley & Dyer (1999): pick an adjacent pair of the sequence uniformly, and with
  probability 1/2 swap it if the two steps are unordered.  Its stationary distribution
  is uniform over the completions; Bubley & Dyer bound its mixing time by
  O(n³ log n) steps.
* **The population** (``chains`` sequences, default 8) lives from look to look.  A
  buffer move leaves the state unchanged, so the chains simply keep mixing.  After an
  installation the installed step, which was minimal, is removed from each sequence:
  what is left is still admissible (its distribution is nearly, not exactly, uniform;
  the following steps correct it), so no look starts from scratch.
* **The statistics are Rao–Blackwellised.**  Given the rest of a sequence, a step ``x``
  lies uniformly in the slots between its last predecessor and its first successor.
  So for a minimal candidate ``c``, ``P(c next) = E[1 / slots(c)]`` (each sequence
  without ``c`` corresponds to ``slots`` completions with it), and
  ``E[position(x)] = E[(p + q) / 2 + 1]`` with ``p`` the index of ``x``'s last
  predecessor (-1 if none) and ``q`` that of its first successor (``n`` if none).
  Every sample informs every question, and the variance is much lower than counting
  who came first.
* **Errors** come from the spread of the chains' means (Student's t, ``chains - 1``
  degrees of freedom), which accounts for the correlation within each chain.  They
  are honest once the chains have mixed; a population that has just been started (on
  the first look of a large plan) is marked so by its step count.

Complexity: one step is O(1) big-int bit tests; one sample of ``m`` questions is
O(n m) (a scan of the sequence per question).  In pure Python about 2–3 million
steps per second.

>>> from opportune.engine.poset import Poset
>>> p = Poset.from_pairs(3, [(0, 2)])          # 0 before 2; 1 free: 3 completions
>>> chains = CompletionChains(p, 0b111, seed=1)
>>> est = chains.estimate(first=[0, 1], positions=[1], steps=20_000)
>>> round(est.first[0][0], 1), round(est.first[1][0], 1)   # exact: 2/3 and 1/3
(0.7, 0.3)
>>> round(est.positions[1][0], 1)                           # exact: 2
2.0
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from statistics import NormalDist

from opportune.engine.poset import Poset

__all__ = ["ChainEstimate", "CompletionChains", "t_quantile"]


@dataclass(frozen=True)
class ChainEstimate:
    """Means and standard errors from a population of chains.

    ``first[u] = (p, se)``: estimated probability that unit ``u`` comes next;
    ``positions[u] = (e, se)``: estimated expected position (1 = next).
    ``per_chain`` keeps each chain's means (``{"first": {u: [..]}, "positions": ...}``)
    for paired comparisons between candidates; ``samples`` and ``steps`` say how much
    work stands behind the numbers.
    """

    first: dict[int, tuple[float, float]]
    positions: dict[int, tuple[float, float]]
    per_chain: dict[str, dict[int, list[float]]]
    samples: int
    steps: int

    def prob_greater(self, kind: str, a: int, b: int) -> float:
        """Estimated probability that the true value of ``a`` exceeds that of ``b`` (paired over chains)."""
        xs, ys = self.per_chain[kind][a], self.per_chain[kind][b]
        diffs = [x - y for x, y in zip(xs, ys)]
        k = len(diffs)
        mean = sum(diffs) / k
        if k < 2:
            return 0.5
        var = sum((d - mean) ** 2 for d in diffs) / (k - 1)
        se = math.sqrt(var / k)
        if se == 0:
            return 1.0 if mean > 0 else 0.0 if mean < 0 else 0.5
        return _t_cdf(mean / se, k - 1)


class CompletionChains:
    """A population of Markov chains on the completions of a set of steps under one order.

    ``poset`` gives the order (bitmask ``below``/``above`` per element); ``remaining``
    the steps still to do.  Call :meth:`advance` when steps are installed and
    :meth:`estimate` to run the chains and read the statistics.
    """

    def __init__(self, poset: Poset, remaining: int, *, chains: int = 8, seed: int = 0):
        if chains < 2:
            raise ValueError("at least 2 chains are needed to state an error")
        self._poset = poset
        self._covers_up: list[list[int]] | None = None
        self.below = poset.below
        self.above = poset.above
        self.comparable = [b | a for b, a in zip(poset.below, poset.above)]
        self.rng = random.Random(seed)
        self.remaining = remaining
        self.orders = [self._random_topological(remaining) for _ in range(chains)]
        self.steps = 0          # steps per chain since the population was started

    def _random_topological(self, remaining: int) -> list[int]:
        """A random admissible sequence of ``remaining`` (an up-set: what is left after installing a
        down-set), by Kahn's algorithm on the cover relations with a random minimal step each time:
        not uniform, just spread.  O(n + covers)."""
        if self._covers_up is None:
            up: list[list[int]] = [[] for _ in self.below]
            for a, b in self._poset.cover_pairs():
                up[a].append(b)
            self._covers_up = up
        up, rng = self._covers_up, self.rng
        waiting = {u: 0 for u in _bits(remaining)}
        for u in waiting:
            for v in up[u]:
                if v in waiting:
                    waiting[v] += 1
        minimal = [u for u, k in waiting.items() if k == 0]
        out: list[int] = []
        while minimal:
            i = rng.randrange(len(minimal))
            u = minimal[i]
            minimal[i] = minimal[-1]
            minimal.pop()
            out.append(u)
            for v in up[u]:
                k = waiting.get(v)
                if k is not None:
                    waiting[v] = k - 1
                    if k == 1:
                        minimal.append(v)
        return out

    def advance(self, remaining: int) -> None:
        """Move to a later state: drop the steps no longer remaining (they were installed)."""
        gone = self.remaining & ~remaining
        if remaining & ~self.remaining:
            raise ValueError("the chains can only move forward (install steps, not undo them)")
        if gone:
            self.orders = [[u for u in order if not gone >> u & 1] for order in self.orders]
            self.remaining = remaining

    def run(self, steps: int) -> None:
        """``steps`` lazy adjacent-swap steps on every chain."""
        comparable, rnd = self.comparable, self.rng.random
        for order in self.orders:
            m = 2 * (len(order) - 1)
            if m <= 0:
                continue
            for _ in range(steps):
                j = int(rnd() * m)
                if j & 1:
                    continue            # the lazy half: makes the chain aperiodic
                i = j >> 1
                a = order[i]
                b = order[i + 1]
                if not comparable[a] >> b & 1:
                    order[i] = b
                    order[i + 1] = a
        self.steps += steps

    def estimate(self, first=(), positions=(), *, steps: int = 0, samples: int = 32,
                 deadline: float | None = None, clock=None) -> ChainEstimate:
        """Run the chains and estimate, for each unit in ``first`` (minimal now), the probability
        that it comes next, and for each unit in ``positions``, its expected position.

        Either ``steps`` per chain in total, taken as ``samples`` rounds, or rounds until
        ``deadline`` (by ``clock``, e.g. ``time.perf_counter``), at least two.  Each round
        runs the chains, then reads one sample from each.
        """
        first, positions = list(first), list(positions)
        for u in first:
            if self.below[u] & self.remaining:
                raise ValueError(f"unit {u} is not minimal: it cannot come next")
        k = len(self.orders)
        acc_first = {u: [0.0] * k for u in first}
        acc_pos = {u: [0.0] * k for u in positions}
        n_samples = 0
        # Rounds short enough to stop near a deadline (about a millisecond of steps over all chains).
        per_round = max(1, steps // max(1, samples)) if steps else max(1, min(len(self.orders[0]) * 4, 400))
        rounds = 0
        while True:
            self.run(per_round)
            for c, order in enumerate(self.orders):
                if first or positions:
                    self._read(order, first, positions, acc_first, acc_pos, c)
            n_samples += 1
            rounds += 1
            if steps:
                if rounds >= samples:
                    break
            elif rounds >= 2 and (deadline is None or clock() >= deadline):
                break
        means_first = {u: [x / n_samples for x in xs] for u, xs in acc_first.items()}
        means_pos = {u: [x / n_samples for x in xs] for u, xs in acc_pos.items()}
        return ChainEstimate(
            first={u: _mean_se(xs) for u, xs in means_first.items()},
            positions={u: _mean_se(xs) for u, xs in means_pos.items()},
            per_chain={"first": means_first, "positions": means_pos},
            samples=n_samples * k, steps=self.steps)

    def _read(self, order, first, positions, acc_first, acc_pos, c) -> None:
        """Add one chain's Rao–Blackwellised statistics for the current sequence."""
        above, below = self.above, self.below
        n = len(order)
        for u in first:
            # u stands before its first successor, at index i of the sequence: without u there are
            # i slots for it (before each of the i - 1 others up to that successor, or just there).
            up = above[u]
            slots = n
            for i, v in enumerate(order):
                if up >> v & 1:
                    slots = i
                    break
            acc_first[u][c] += 1.0 / slots
        for u in positions:
            up, down = above[u], below[u]
            p, q = -1, n
            seen = False
            for i, v in enumerate(order):
                if v == u:
                    seen = True
                elif not seen:
                    if down >> v & 1:
                        p = i
                elif up >> v & 1:
                    q = i
                    break
            # Without u, its slots are the insertion indices p + 1 .. q - 1 (p: last predecessor,
            # q: first successor, indices with u); uniform there, its mean 1-based position is this.
            acc_pos[u][c] += (p + q) / 2 + 1


def _mean_se(xs: list[float]) -> tuple[float, float]:
    k = len(xs)
    mean = sum(xs) / k
    var = sum((x - mean) ** 2 for x in xs) / (k - 1) if k > 1 else float("inf")
    return mean, math.sqrt(var / k)


def t_quantile(q: float, df: int) -> float:
    """Student's t quantile (Cornish–Fisher expansion; within 1% of the exact value for df ≥ 3)."""
    z = NormalDist().inv_cdf(q)
    g1 = (z ** 3 + z) / 4
    g2 = (5 * z ** 5 + 16 * z ** 3 + 3 * z) / 96
    g3 = (3 * z ** 7 + 19 * z ** 5 + 17 * z ** 3 - 15 * z) / 384
    return z + g1 / df + g2 / df ** 2 + g3 / df ** 3


def _t_cdf(t: float, df: int) -> float:
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


def _bits(mask: int):
    while mask:
        low = mask & -mask
        yield low.bit_length() - 1
        mask ^= low
