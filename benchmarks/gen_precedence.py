"""Random assembly-like precedence graphs, in the spirit of SALBPGen (Otto, Otto & Scholl 2013).

Given a number of tasks *n*, a target order strength (OS: the share of the
n(n-1)/2 task pairs that are ordered in the transitive closure), a structure
and a seed, :func:`generate` builds a random DAG on tasks ``1..n`` numbered in a
topological order (every arc ``(i, j)`` has ``i < j``), returns its transitive
reduction (no arc implied by others) and task times.  The same arguments give
the same graph.

Structures: first a *skeleton* of arcs is laid out, sized from the target so
that it alone stays near or below it; then its arcs are added in random order,
with *joins* (a task to a random later one at most ~n/10 further) as one
proposal in ten, and all proposals once the skeleton is used up.

* ``chain`` — k = ⌊1/OS⌋ + 1 long chains, each task on a random one: most
  tasks have one predecessor and one successor, few joins.
* ``bottleneck`` — s = ⌈1/(1 - OS)⌉ + 1 stages separated by bottleneck tasks;
  each stage is a set of short branches (~4 tasks) that start after the
  opening bottleneck and end in the closing one, so a bottleneck joins
  several branches.
* ``mixed`` — chains on a random half of the tasks, stages on the other half.

How the order strength is reached: the graph starts with no arc (OS 0) and
arcs are added one at a time, so OS only rises.  The closure is kept as
Python-int bitsets (``above[x]``, ``below[x]``); before a proposed arc
``i -> j`` is accepted, its exact gain in comparable pairs is computed,
Σ over x ≤ i of |({j} ∪ above[j]) \\ above[x]| (O(|down(i)|) popcounts of
n-bit ints).  An arc that would take OS above target + 0.01 is refused (a
skeleton arc goes back to be tried later); adding stops as soon as
OS ≥ target − 0.0025.  When 200 proposals in a row are refused (near the
target most arcs would join large pieces), the arc of least gain among 200
sampled unordered pairs is added instead; if even that overshoots, adding
stops.  :func:`generate` then checks that OS is within ±0.03 of the target
(or one pair's worth for n ≤ 8, where one pair is more than 0.03).  In
practice it lands within ±0.01; n = 1000 takes 0.03–0.3 s.

Task times are drawn from a seeded distribution (``times``): ``bottom`` (peak
at small times, log-normal around 10, the default), ``middle`` (normal around
50) or ``bimodal`` (mostly short, some long), whole numbers in 1..100.

    PYTHONPATH=src python3 benchmarks/gen_precedence.py --n 300 --os 0.6 --structure mixed --seed 1 -o out.alb
    PYTHONPATH=src python3 benchmarks/gen_precedence.py --out-dir gen/   # n 300, 1000 × OS 0.2, 0.6, 0.9

Other benchmarks import it after adding ``benchmarks/`` to ``sys.path``:
``from gen_precedence import generate, order_strength``.
"""
from __future__ import annotations

import argparse
import math
import random
import sys
import time
from pathlib import Path

from opportune.engine.poset import Poset, bits
from opportune.formats.alb import graph_text, order_strength, poset_order_strength

__all__ = ["STRUCTURES", "generate", "order_strength"]

STRUCTURES = ("chain", "bottleneck", "mixed")
TIMES = ("bottom", "middle", "bimodal")
TOLERANCE = 0.03  # what generate() guarantees
AIM_BELOW, AIM_ABOVE = 0.0025, 0.01  # the window it aims at, well inside the tolerance
PATIENCE = 200  # rejected proposals in a row before a small-gain arc is searched for
JOIN = 0.1  # share of proposals that are joins while skeleton arcs remain
BRANCH = 4  # mean number of tasks in a branch between two bottlenecks


class Closure:
    """A DAG on ``0..n-1`` (arcs ``i < j``) with its transitive closure kept as bitsets.

    ``comparable`` is the number of ordered pairs of the closure.
    """

    def __init__(self, n: int):
        self.n = n
        self.above = [0] * n
        self.below = [0] * n
        self.comparable = 0

    def ordered(self, i: int, j: int) -> bool:
        return bool(self.above[i] >> j & 1)

    def gain(self, i: int, j: int) -> int:
        """Comparable pairs the arc ``i -> j`` would add.  O(|down(i)|) popcounts of n-bit ints."""
        up = self.above[j] | 1 << j
        above = self.above
        return sum((up & ~above[x]).bit_count() for x in bits(self.below[i] | 1 << i))

    def add(self, i: int, j: int, gain: int) -> None:
        """Add the arc ``i -> j`` (``gain`` from :meth:`gain`).  O(|down(i)| + |up(j)|) big-int ORs."""
        up, down = self.above[j] | 1 << j, self.below[i] | 1 << i
        for x in bits(down):
            self.above[x] |= up
        for y in bits(up):
            self.below[y] |= down
        self.comparable += gain

    def poset(self) -> Poset:
        return Poset(self.n, self.below, self.above)  # already closed and acyclic


# ---------------------------------------------------------------- skeletons: the shape, laid out first


def chain_skeleton(nodes: list[int], target: float, rng: random.Random) -> list[tuple[int, int]]:
    """Arcs of k long chains over ``nodes`` (sorted): each task joins a random chain.  O(len(nodes)).

    k = ⌊1/target⌋ + 1, so that the complete chains alone (order strength
    about 1/k) stay just below the target and a few joins finish the job.
    """
    k = int(1 / target) + 1 if target > 0 else 1
    chains: list[list[int]] = [[] for _ in range(k)]
    for x in nodes:
        chains[rng.randrange(k)].append(x)
    return [(a, b) for chain in chains for a, b in zip(chain, chain[1:])]


def bottleneck_skeleton(nodes: list[int], target: float, rng: random.Random) -> list[tuple[int, int]]:
    """Arcs of s stages of short branches between s-1 bottleneck tasks over ``nodes`` (sorted).  O(len(nodes)).

    Every branch of a stage starts after the stage's opening bottleneck and
    ends in its closing one.  Complete, s stages order about 1 - 1/s of the
    pairs, so s = ⌈1/(1 - target)⌉ + 1 leaves room for the target; branches
    have about :data:`BRANCH` tasks, so a bottleneck joins several of them.
    """
    m = len(nodes)
    stages = min(math.ceil(1 / (1 - target)) + 1 if target < 1 else m, max(1, m // 3))
    # Bottlenecks near the stage boundaries, jittered, at least one task apart.
    cuts = sorted({min(m - 2, max(1, round(m * t / stages) + rng.randint(-1, 1))) for t in range(1, stages)})
    necks = [nodes[c] for c in cuts] if m >= 3 else []
    bounds = [-1] + cuts + [m]
    arcs = []
    for s in range(len(bounds) - 1):
        members = nodes[bounds[s] + 1: bounds[s + 1]]
        opening = necks[s - 1] if s > 0 else None
        closing = necks[s] if s < len(necks) else None
        count = max(1, round(len(members) / BRANCH))
        branches: list[list[int]] = [[] for _ in range(count)]
        for x in members:
            branches[rng.randrange(count)].append(x)
        for branch in filter(None, branches):
            path = ([opening] if opening is not None else []) + branch + ([closing] if closing is not None else [])
            arcs += zip(path, path[1:])
    return arcs


def skeleton(n: int, target: float, structure: str, rng: random.Random) -> list[tuple[int, int]]:
    """The arcs of the structure on ``0..n-1``; ``mixed``: chains on a random half of the tasks, stages on the rest."""
    nodes = list(range(n))
    if structure == "chain":
        return chain_skeleton(nodes, target, rng)
    if structure == "bottleneck":
        return bottleneck_skeleton(nodes, target, rng)
    coin = [rng.random() < 0.5 for _ in nodes]
    half = [x for x in nodes if coin[x]]
    rest = [x for x in nodes if not coin[x]]
    return chain_skeleton(half, target, rng) + bottleneck_skeleton(rest, target, rng)


class Proposals:
    """Candidate arcs ``(i, j)``, ``i < j``: skeleton arcs in random order, and joins.

    A join links a task to a random later task at most ~n/10 further: it
    ties chains or branches together.  Joins are :data:`JOIN` of the
    proposals while skeleton arcs remain, all of them after.
    """

    def __init__(self, g: Closure, arcs: list[tuple[int, int]], rng: random.Random):
        self.g, self.rng, self.arcs = g, rng, list(arcs)
        self.reach = 2 + max(10, g.n // 10)

    def next(self) -> tuple[tuple[int, int], bool]:
        """An arc, and whether it is a skeleton arc (taken out of the skeleton: see :meth:`put_back`)."""
        rng = self.rng
        if self.arcs and rng.random() >= JOIN:
            k = rng.randrange(len(self.arcs))
            self.arcs[k], self.arcs[-1] = self.arcs[-1], self.arcs[k]
            return self.arcs.pop(), True
        n = self.g.n
        i = rng.randrange(n - 1)
        return (i, rng.randrange(i + 1, min(n, i + self.reach))), False

    def put_back(self, arc: tuple[int, int]) -> None:
        """A skeleton arc that gained too much now: it may fit later, once other arcs ordered its pairs."""
        self.arcs.append(arc)


def _smallest_gain_arc(g: Closure, rng: random.Random, samples: int = 200) -> tuple[int, int, int] | None:
    """The arc of least gain among ``samples`` random unordered pairs ``i < j``, or ``None`` if all are ordered.

    O(n + samples × (n + |down(i)|)) big-int operations.
    """
    n, full = g.n, (1 << g.n) - 1
    free = [i for i in range(n - 1) if (full >> (i + 1) << (i + 1)) & ~g.above[i]]
    best = None
    for _ in range(samples if free else 0):
        i = free[rng.randrange(len(free))]
        later = (full >> (i + 1) << (i + 1)) & ~g.above[i]
        k = rng.randrange(later.bit_count())
        j = next(x for t, x in enumerate(bits(later)) if t == k)
        gain = g.gain(i, j)
        if best is None or gain < best[2]:
            best = (i, j, gain)
    return best


def _random_dag(n: int, target: float, structure: str, rng: random.Random) -> Closure:
    """Add proposed arcs until OS ≥ target − AIM_BELOW, refusing those that pass target + AIM_ABOVE."""
    g = Closure(n)
    total = n * (n - 1) // 2
    low = math.ceil((target - AIM_BELOW) * total)
    high = math.floor((target + AIM_ABOVE) * total)
    if low > high:  # few tasks: no count of pairs in the window, aim at the nearest one
        low = high = round(target * total)
    proposals = Proposals(g, skeleton(n, target, structure, rng), rng)
    rejected = 0
    while g.comparable < low:
        if rejected >= PATIENCE:
            rejected = 0
            best = _smallest_gain_arc(g, rng)
            if best is None or g.comparable + best[2] > high:
                break  # nothing fits the window: the tolerance check in generate() decides
            g.add(*best)
            continue
        arc, structural = proposals.next()
        if g.ordered(*arc):  # implied already: a skeleton arc is dropped for good
            rejected += 1
            continue
        gain = g.gain(*arc)
        if g.comparable + gain > high:
            if structural:
                proposals.put_back(arc)
            rejected += 1
            continue
        g.add(arc[0], arc[1], gain)
        rejected = 0
    return g


def _times(n: int, kind: str, seed: int) -> list[int]:
    """n whole task times in 1..100 from the ``kind`` distribution, from their own seeded stream."""
    rng = random.Random(f"times-{seed}")  # independent of the graph: changing one leaves the other

    def draw():
        if kind == "bottom":
            return rng.lognormvariate(math.log(10), 0.8)
        if kind == "middle":
            return rng.gauss(50, 15)
        return rng.gauss(20, 7) if rng.random() < 0.7 else rng.gauss(70, 10)

    return [min(100, max(1, round(draw()))) for _ in range(n)]


def generate(n: int, order_strength: float, structure: str = "mixed", seed: int = 0,
             times: str = "bottom") -> tuple[list[tuple[int, int]], list[int]]:
    """A random precedence graph on tasks ``1..n``: its arcs (1-based, transitively reduced, sorted) and task times.

    The order strength of the result is within ±0.03 of ``order_strength``,
    or of one pair's worth, 1/(n(n-1)/2), if that is more (n ≤ 8); else
    ``ValueError`` (not seen in practice).  ``structure`` is ``chain``,
    ``bottleneck`` or ``mixed`` and ``times`` the task time distribution (see
    the module's text).  Deterministic for given arguments.  Cost: O(n) per
    arc added (big-int operations on n-bit masks), 0.03–0.3 s for n = 1000.
    """
    if structure not in STRUCTURES:
        raise ValueError(f"structure must be one of {', '.join(STRUCTURES)}, got {structure!r}")
    if times not in TIMES:
        raise ValueError(f"times must be one of {', '.join(TIMES)}, got {times!r}")
    if n < 1 or not 0 <= order_strength <= 1:
        raise ValueError("need n ≥ 1 and an order strength from 0 to 1")
    g = _random_dag(n, order_strength, structure, random.Random(f"graph-{structure}-{seed}"))
    poset = g.poset()
    reached = poset_order_strength(poset)
    if n > 1 and abs(reached - order_strength) > max(TOLERANCE, 1 / (n * (n - 1) // 2)):
        raise ValueError(f"could not reach order strength {order_strength} with {n} tasks (got {reached:.3f})")
    arcs = [(a + 1, b + 1) for a, b in poset.cover_pairs()]
    return arcs, _times(n, times, seed)


def file_name(n: int, strength: float, structure: str = "mixed", seed: int = 1) -> str:
    """``gen-n300-os0.6.alb`` for the default structure and seed; other ones are added to the name."""
    extra = ("" if structure == "mixed" else f"-{structure}") + ("" if seed == 1 else f"-seed{seed}")
    return f"gen-n{n}-os{strength:g}{extra}.alb"


def _write(path: Path, n: int, strength: float, structure: str, seed: int, times: str) -> None:
    start = time.perf_counter()
    arcs, task_times = generate(n, strength, structure, seed, times)
    seconds = time.perf_counter() - start
    path.write_text(graph_text(task_times, arcs), encoding="ascii")
    print(f"{path}: {n} tasks, {len(arcs)} arcs, order strength {order_strength(n, arcs):.3f} "
          f"(target {strength}), {seconds:.2f} s")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", help="number of tasks (several with --out-dir; default 300 1000)")
    ap.add_argument("--os", type=float, nargs="+", dest="strength",
                    help="target order strength(s) (several with --out-dir; default 0.2 0.6 0.9)")
    ap.add_argument("--structure", choices=STRUCTURES, default="mixed")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--times", choices=TIMES, default="bottom", help="task time distribution")
    where = ap.add_mutually_exclusive_group(required=True)
    where.add_argument("-o", "--out", type=Path, help="the .alb file to write (one n, one OS)")
    where.add_argument("--out-dir", type=Path, help="write every n × OS there, named like gen-n300-os0.6.alb")
    args = ap.parse_args(argv)
    if args.out is not None:
        if len(args.n or []) != 1 or len(args.strength or []) != 1:
            ap.error("-o writes one graph: give one --n and one --os")
        _write(args.out, args.n[0], args.strength[0], args.structure, args.seed, args.times)
        return 0
    args.out_dir.mkdir(parents=True, exist_ok=True)
    for n in args.n or [300, 1000]:
        for strength in args.strength or [0.2, 0.6, 0.9]:
            name = file_name(n, strength, args.structure, args.seed)
            _write(args.out_dir / name, n, strength, args.structure, args.seed, args.times)
    return 0


if __name__ == "__main__":
    sys.exit(main())
