"""Estimates from random completions, for decisions that must come back within a time budget.

The opportunistic rule needs only ratios: a candidate's *options* are the completions
times the probability that it comes next in a uniformly random completion, and "needed
earliest" is an expected position.  When the exact counts do not fit the budget, both
are estimated from a population of Markov chains on the completions (linear
extensions of what remains):

* **The chain** is a random-scan Gibbs sampler on the completions: draw a step of the
  sequence uniformly, take it out, and put it back in a uniformly random slot between its
  last predecessor and its first successor.  Given the rest, that slot is uniform, so the
  uniform distribution over completions is stationary; the adjacent swaps of Karzanov &
  Khachiyan (1991), whose mixing Bubley & Dyer (1999) bound by O(n³ log n) steps, are
  among its moves, so it is irreducible, and it moves a step across the whole sequence
  in one move where they move it one place.
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

Complexity: one move is a few C-level scans of the sequence (O(n) each, one per cover
neighbour of the step moved); one sample of ``m`` questions is O(n m) (a scan of the
sequence per question).

>>> from opportune.engine.poset import Poset, bits
>>> p = Poset.from_pairs(3, [(0, 2)])          # 0 before 2; 1 free: 3 completions
>>> chains = CompletionChains(p, 0b111, seed=1)
>>> est = chains.estimate(first=[0, 1], positions=[1], steps=20_000)
>>> abs(est.first[0][0] - 2 / 3) < 0.05, abs(est.first[1][0] - 1 / 3) < 0.05   # P(next)
(True, True)
>>> abs(est.positions[1][0] - 2) < 0.1                                          # E[position]
True
"""

from __future__ import annotations

import math
import random
import threading
import time
from array import array
from collections import OrderedDict
from dataclasses import dataclass

from opportune.engine import native
from opportune.engine.deadline import Deadline, as_deadline
from opportune.engine.poset import Poset, bits
from opportune.engine.stats import _t_cdf, prob_positive, t_quantile  # noqa: F401 (their documented import)
from opportune.engine.tuning import START_KEEP, START_KEEP_UNITS

_M64 = (1 << 64) - 1
_TO_UNIT = 1.0 / (1 << 53)

__all__ = ["ChainEstimate", "CompletionChains", "prob_positive", "t_quantile"]

_starts: OrderedDict = OrderedDict()
_starts_lock = threading.Lock()


@dataclass(frozen=True)
class ChainEstimate:
    """Means and standard errors from a population of chains.

    ``first[u] = (p, se)``: estimated probability that unit ``u`` comes next;
    ``positions[u] = (e, se)``: estimated expected position (1 = next).
    ``per_chain`` keeps each chain's means (``{"first": {u: [..]}, "positions": ...}``)
    for paired comparisons between candidates; ``samples`` and ``steps`` say how much
    work stands behind the numbers.  Made by :meth:`CompletionChains.estimate`.

    Parameters
    ----------
    first : dict of int to (float, float)
        Unit → its chance of coming next and that chance's standard error.
    positions : dict of int to (float, float)
        Unit → its expected position and that position's standard error.
    per_chain : dict of str to dict of int to list of float
        ``"first"`` and ``"positions"``: unit → each chain's mean.
    samples : int
        Readings behind the means (rounds × chains).
    steps : int
        Moves per chain since the population was started.

    Examples
    --------
    >>> est = ChainEstimate({0: (0.6, 0.05)}, {}, {"first": {0: [0.55, 0.65]}, "positions": {}}, 2, 100)
    >>> est.first[0], est.per_chain["first"][0]
    ((0.6, 0.05), [0.55, 0.65])
    """

    first: dict[int, tuple[float, float]]
    positions: dict[int, tuple[float, float]]
    per_chain: dict[str, dict[int, list[float]]]
    samples: int
    steps: int

    def prob_greater(self, kind: str, a: int, b: int, margin: float = 0.0) -> float:
        """Estimated probability that the true value of ``a`` exceeds that of ``b`` by more than
        ``margin`` (paired over chains).

        Parameters
        ----------
        kind : str
            ``"first"`` (chances of coming next) or ``"positions"`` (expected positions).
        a, b : int
            The units compared, both asked of the estimate as ``kind``.
        margin : float
            How much more ``a``'s value must be.

        Returns
        -------
        float
            The probability, from Student's t on the chains' paired differences.

        Examples
        --------
        >>> est = ChainEstimate({}, {}, {"first": {0: [0.7, 0.6, 0.65, 0.7], 1: [0.3, 0.4, 0.35, 0.3]}}, 4, 10)
        >>> est.prob_greater("first", 0, 1) > 0.99, est.prob_greater("first", 1, 0) < 0.01
        (True, True)
        """
        xs, ys = self.per_chain[kind][a], self.per_chain[kind][b]
        return prob_positive([x - y - margin for x, y in zip(xs, ys)])


class CompletionChains:
    """A population of Markov chains on the completions of a set of steps under one order.

    ``poset`` gives the order (bitmask ``below``/``above`` per element); ``remaining``
    the steps still to do.  Call :meth:`advance` when steps are installed and
    :meth:`estimate` to run the chains and read the statistics.  Starting the population costs
    O(n + covers) per chain.  The chains run compiled where the core is (:mod:`opportune.engine.native`)
    and in pure Python elsewhere, drawing from the same stream: the same seed gives the same moves.

    Parameters
    ----------
    poset : Poset
        The order (bitmask ``below``/``above`` per element).
    remaining : int
        The steps still to do, a bitmask: an up-set of ``poset`` (what is left after installing a down-set).
    chains : int
        Chains in the population, at least 2 (their spread gives the stated errors).
    seed : int
        Seed of the chains' random stream.
    deadline : Deadline, float or None
        When starting the population must stop (a :class:`~opportune.engine.deadline.Deadline` or a
        ``time.perf_counter()`` moment, read every 256 steps; None: never).

    Raises
    ------
    ValueError
        With fewer than 2 chains.
    BudgetExceeded
        Past ``deadline`` while starting (:class:`~opportune.engine.deadline.BudgetExceeded`).

    Examples
    --------
    >>> p = Poset.from_pairs(4, [(0, 1), (2, 3)])     # two chains of two steps
    >>> chains = CompletionChains(p, p.full, chains=4, seed=7)
    >>> [sorted(o) for o in chains.orders] == [[0, 1, 2, 3]] * 4      # each chain: a whole sequence
    True
    >>> all(o.index(0) < o.index(1) and o.index(2) < o.index(3) for o in chains.orders)   # admissible
    True
    """

    def __init__(self, poset: Poset, remaining: int, *, chains: int = 8, seed: int = 0,
                 deadline: Deadline | float | None = None):
        if chains < 2:
            raise ValueError("at least 2 chains are needed to state an error")
        self._poset = poset
        self._covers: tuple | None = None
        self.below = poset.below
        self.above = poset.above
        self.rng = random.Random(seed)
        self.remaining = remaining
        self.chains = chains
        dl = as_deadline(deadline)
        key = (id(poset), remaining, chains, seed)
        with _starts_lock:
            kept = _starts.get(key)
            if kept is not None and kept[0] is poset:
                _starts.move_to_end(key)
        # The starting sequences and the moves draw from one splitmix64 stream, so the compiled chains
        # and the pure-Python ones start alike and make the same moves from the same seed.
        self._core = None
        self._state = self.rng.getrandbits(64)
        orders = None
        if kept is not None and kept[0] is poset:
            _, self._covers, packed, state = kept
            if packed is not None:      # pure Python: the sequences themselves, and the stream after them
                orders, self._state = [list(o) for o in packed], state
        preds, succs = self._neighbours(dl)
        if native._native is not None:
            if orders is None:          # O(chains × (n + covers)) compiled: no deadline needed
                self._core = native._native.Chains.start(len(self.below), preds, succs, list(bits(remaining)),
                                                         chains, self._state)
                self._state = self._core.state()
            else:
                self._core = native._native.Chains(len(self.below), preds, succs, orders, self._state)
        elif orders is None:
            orders = self._start_orders(remaining, chains, dl)
        if kept is None and remaining.bit_count() <= START_KEEP_UNITS:
            # compiled, the start is quick to draw again: only the covers are kept
            entry = (poset, self._covers, None, None) if orders is None else \
                (poset, self._covers, [array("i", o) for o in orders], self._state)
            with _starts_lock:
                _starts[key] = entry
                while len(_starts) > START_KEEP:
                    _starts.popitem(last=False)
        if self._core is None:
            self._orders = orders
        self.steps = 0          # steps per chain since the population was started
        self._kept: tuple[dict, dict] = ({}, {})   # readings kept at this state (estimate(keep=True))

    @property
    def orders(self) -> list[list[int]]:
        """The chains' current sequences (a copy when they run compiled)."""
        return self._core.orders() if self._core is not None else self._orders

    def _start_orders(self, remaining: int, chains: int, deadline: Deadline = Deadline.NEVER) -> list[list[int]]:
        """``chains`` random admissible sequences of ``remaining`` (an up-set: what is left after
        installing a down-set), by Kahn's algorithm on the cover relations with a uniformly drawn
        minimal step each time: not uniform, just spread.  The draws are the compiled start's
        (``Chains.start``), from the population's splitmix64 stream.  O(chains × (n + covers)); the
        deadline read every 256 steps."""
        preds, succs = self._neighbours()
        state = self._state
        units = list(bits(remaining))
        waiting0 = {u: sum(1 for v in preds[u] if remaining >> v & 1) for u in units}
        orders = []
        for _ in range(chains):
            waiting = dict(waiting0)
            minimal = [u for u in units if not waiting[u]]
            out: list[int] = []
            while minimal:
                if not len(out) & 255:
                    deadline.check("starting the chains")
                state = (state + 0x9E3779B97F4A7C15) & _M64
                z = ((state ^ (state >> 30)) * 0xBF58476D1CE4E5B9) & _M64
                z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _M64
                i = int(((z ^ (z >> 31)) >> 11) * _TO_UNIT * len(minimal))
                u = minimal[i]
                minimal[i] = minimal[-1]
                minimal.pop()
                out.append(u)
                for v in succs[u]:
                    k = waiting.get(v)
                    if k is not None:
                        waiting[v] = k - 1
                        if k == 1:
                            minimal.append(v)
            orders.append(out)
        self._state = state
        return orders

    def advance(self, remaining: int) -> None:
        """Move to a later state: drop the steps no longer remaining (they were installed).

        What is left of each sequence is still admissible, so the chains go on from there; readings
        kept with ``estimate(keep=True)`` are dropped.  O(chains × n).

        Parameters
        ----------
        remaining : int
            The steps still to do now, a bitmask: a subset of :attr:`remaining`.

        Raises
        ------
        ValueError
            When ``remaining`` holds a step the chains no longer have (steps cannot be undone).

        Examples
        --------
        >>> p = Poset.from_pairs(3, [(0, 2)])
        >>> chains = CompletionChains(p, 0b111, seed=1)
        >>> chains.advance(0b110)                           # step 0 installed
        >>> sorted(chains.orders[0]), chains.remaining
        ([1, 2], 6)
        >>> chains.advance(0b111)
        Traceback (most recent call last):
        ...
        ValueError: the chains can only move forward (install steps, not undo them)
        """
        gone = self.remaining & ~remaining
        if remaining & ~self.remaining:
            raise ValueError("the chains can only move forward (install steps, not undo them)")
        if gone:
            self._kept = ({}, {})       # readings of the earlier state: they do not carry over
            if self._core is not None:
                self._core.drop(list(bits(gone)))
            else:
                self._orders = [[u for u in order if not gone >> u & 1] for order in self._orders]
            self.remaining = remaining

    def run(self, steps: int, deadline: Deadline | float | None = None) -> None:
        """``steps`` moves on every chain: a step of the sequence drawn uniformly is taken out and put
        back in a uniformly random slot between its last predecessor and its first successor (a
        random-scan Gibbs sampler: given the others, its slot is uniform among the valid ones).

        One move can carry a step across the whole sequence, where the adjacent swaps of Karzanov
        and Khachiyan move it one place: on ARC111 the chains mix in far fewer moves.  Each move
        costs a few C-level list scans (``list.index`` for its cover neighbours).

        Parameters
        ----------
        steps : int
            Moves per chain.
        deadline : Deadline, float or None
            Stop once it has passed (read every 64 moves of a chain), with fewer moves made (counted
            in :attr:`steps`); None: make them all.

        Examples
        --------
        >>> p = Poset.from_pairs(3, [(0, 2)])
        >>> chains = CompletionChains(p, 0b111, seed=1)
        >>> chains.run(100); chains.steps
        100
        >>> all(o.index(0) < o.index(2) for o in chains.orders)     # every move keeps the order
        True
        """
        dl = as_deadline(deadline)
        if dl.finite and steps > 64:        # in pieces, so that the clock is read between them
            done = 0
            while done < steps and not dl.expired():
                self.run(min(64, steps - done))
                done += 64
            return
        if self._core is not None:
            self._core.run(steps)
            self.steps += steps
            return
        preds, succs = self._neighbours()
        rem = self.remaining
        state = self._state

        def rnd():      # splitmix64, as the compiled chains draw
            nonlocal state
            state = (state + 0x9E3779B97F4A7C15) & _M64
            z = ((state ^ (state >> 30)) * 0xBF58476D1CE4E5B9) & _M64
            z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _M64
            return ((z ^ (z >> 31)) >> 11) * _TO_UNIT

        for order in self._orders:
            n = len(order)
            if n < 2:
                continue
            for _ in range(steps):
                i = int(rnd() * n)
                u = order[i]
                p = -1
                for v in preds[u]:
                    if rem >> v & 1:
                        j = order.index(v, 0, i)
                        if j > p:
                            p = j
                q = n
                for v in succs[u]:
                    j = order.index(v, i + 1)
                    if j < q:
                        q = j
                if q - p > 2:       # more than one slot: take it out, put it back at random
                    del order[i]
                    order.insert(p + 1 + int(rnd() * (q - 1 - p)), u)
        self._state = state
        self.steps += steps

    def _neighbours(self, deadline: Deadline | None = None) -> tuple[list[list[int]], list[list[int]]]:
        """Cover predecessors and successors of every element (built once): the last predecessor and
        first successor of a step in a sequence are among them."""
        if self._covers is None:
            preds: list[list[int]] = [[] for _ in self.below]
            succs: list[list[int]] = [[] for _ in self.below]
            for a, b in self._poset.cover_pairs(deadline=deadline):
                succs[a].append(b)
                preds[b].append(a)
            self._covers = (preds, succs)
        return self._covers

    def estimate(self, first=(), positions=(), *, steps: int = 0, samples: int = 32,
                 deadline: float | None = None, clock=None, settled=None,
                 min_rounds: int = 8, keep: bool = False) -> ChainEstimate:
        """Run the chains and estimate, for each unit in ``first`` (minimal now), the probability
        that it comes next, and for each unit in ``positions``, its expected position.

        Either ``steps`` per chain in total, taken as ``samples`` rounds, or rounds until
        ``deadline`` (a :class:`~opportune.engine.deadline.Deadline`, or a moment of ``clock``, e.g.
        ``time.perf_counter``, or of an injected clock), at least two; with both, the rounds stop at
        whichever comes first (at least two).  Each round
        runs the chains, then reads one sample from each.  With a deadline, ``settled`` (a
        function of the estimate so far) may end the rounds early, once every unit has
        ``min_rounds`` rounds: a decision that is already sure need not spend the rest of its budget.

        ``keep``: the readings are kept with the population until it advances, and a later call
        with ``keep`` continues them for the units it asks about again.  Looks at one state (a run of
        looks where nothing can be installed: one buffer choice after another) then build on each
        other instead of starting again, so a part's expected position seen twice is known better the
        second time.  A unit's rounds may differ from another's; each chain's means are still means
        of its own readings, so the comparisons over chains stay valid.

        Parameters
        ----------
        first : iterable of int
            Units, each minimal in :attr:`remaining`, whose chance of coming next is asked.
        positions : iterable of int
            Units whose expected position (1 = next) is asked.
        steps : int
            Moves per chain in total (0: rounds until ``deadline``).
        samples : int
            Rounds that ``steps`` is spread over.
        deadline : Deadline, float or None
            When the rounds stop: a :class:`~opportune.engine.deadline.Deadline` (also read inside
            the moves), or a moment of ``clock``.
        clock : callable or None
            The clock ``deadline`` is a moment of (e.g. ``time.perf_counter``, or an injected one).
        settled : callable or None
            A function of the estimate so far: True ends the rounds early (with a deadline).
        min_rounds : int
            Rounds every unit has before ``settled`` is asked.
        keep : bool
            Keep the readings with the population, and continue those kept, until it advances.

        Returns
        -------
        ChainEstimate
            Means and standard errors per unit, each chain's means, and the work behind them.

        Raises
        ------
        ValueError
            When a unit of ``first`` is not minimal (it cannot come next).

        Examples
        --------
        0 before 1, 2 free: of the 3 completions ``0 1 2``, ``0 2 1`` and ``2 0 1``, two start with 0
        and one with 2, and 1 stands at 2, 3 and 3:

        >>> p = Poset.from_pairs(3, [(0, 1)])
        >>> est = CompletionChains(p, 0b111, seed=3).estimate(first=[0, 2], positions=[1], steps=4_000)
        >>> abs(est.first[0][0] - 2 / 3) < 0.06, abs(est.first[2][0] - 1 / 3) < 0.06
        (True, True)
        >>> abs(est.positions[1][0] - 8 / 3) < 0.1, est.samples       # 32 rounds of 8 chains
        (True, 256)
        >>> CompletionChains(p, 0b111).estimate(first=[1], steps=10)
        Traceback (most recent call last):
        ...
        ValueError: unit 1 is not minimal: it cannot come next
        """
        moves_until = deadline if isinstance(deadline, Deadline) else None   # read inside the moves too
        if moves_until is not None:
            deadline, clock = (moves_until.at if moves_until.finite else None), time.perf_counter
        first, positions = list(first), list(positions)
        for u in first:
            if self.below[u] & self.remaining:
                raise ValueError(f"unit {u} is not minimal: it cannot come next")
        k = self.chains
        kept = self._kept if keep else ({}, {})
        acc_first = {u: kept[0].get(u) or [[0.0] * k, 0] for u in first}
        acc_pos = {u: kept[1].get(u) or [[0.0] * k, 0] for u in positions}
        if keep:
            kept[0].update(acc_first)
            kept[1].update(acc_pos)
        # Rounds short enough to stop near a deadline (a millisecond or two of moves over all chains).
        per_round = max(1, steps // max(1, samples)) if steps else max(1, min(self.remaining.bit_count(), 100))
        rounds = 0
        least = min((a[1] for a in (*acc_first.values(), *acc_pos.values())), default=0)
        if settled is not None and not steps and least >= min_rounds:
            summary = self._summary(acc_first, acc_pos)
            if settled(summary):        # what was kept already settles it: no moves at all
                return summary
        while True:
            self.run(per_round, moves_until)
            if first or positions:
                self._read_all(first, positions, acc_first, acc_pos)
            rounds += 1
            least += 1
            if steps:
                if rounds >= samples or (deadline is not None and clock is not None and least >= 2
                                         and clock() >= deadline):
                    break
            elif least >= 2 and (deadline is None or clock() >= deadline):
                break
            elif settled is not None and least >= min_rounds and rounds % 4 == 0 and settled(
                    self._summary(acc_first, acc_pos)):
                break
        return self._summary(acc_first, acc_pos)

    def _summary(self, acc_first, acc_pos) -> ChainEstimate:
        means_first = {u: [x / n for x in xs] for u, (xs, n) in acc_first.items()}
        means_pos = {u: [x / n for x in xs] for u, (xs, n) in acc_pos.items()}
        rounds = max((n for _, n in (*acc_first.values(), *acc_pos.values())), default=0)
        return ChainEstimate(
            first={u: _mean_se(xs) for u, xs in means_first.items()},
            positions={u: _mean_se(xs) for u, xs in means_pos.items()},
            per_chain={"first": means_first, "positions": means_pos},
            samples=rounds * self.chains, steps=self.steps)

    def _read_all(self, first, positions, acc_first, acc_pos) -> None:
        """Add every chain's statistics for its current sequence (``acc[u]``: ``[sums per chain, rounds]``)."""
        sums_first = {u: acc_first[u][0] for u in first}
        sums_pos = {u: acc_pos[u][0] for u in positions}
        if self._core is None:
            for c, order in enumerate(self._orders):
                self._read(order, first, positions, sums_first, sums_pos, c)
        else:
            f, e = self._core.read(first, positions)
            for c, (fs, es) in enumerate(zip(f, e)):
                for u, x in zip(first, fs):
                    sums_first[u][c] += x
                for u, x in zip(positions, es):
                    sums_pos[u][c] += x
        for u in first:
            acc_first[u][1] += 1
        for u in positions:
            acc_pos[u][1] += 1

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
