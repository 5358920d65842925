"""Benchmark of `opportune derive` on generated assemblies of 10, 30, 100 and 300 parts.

Three families, each part written as an OBJ of closed unit cubes:

* ``block``: a near-cubic block cut into ``n`` connected parts grown from random seeds (one seed per
  size), derived with the default directions (the axes and the contacts' normals);
* ``wall``: bricks two cells long, ten a course, in stack bond (each brick on one below), derived
  with ``--gravity -z``;
* ``bond``: the same in running bond (each brick on two below, half bricks at the ends), ``--gravity -z``.

Each row gives the parts, the directions, the blocking checks (body-pair tests after the bounding
boxes), the contacts, the CPU seconds of the whole derivation (reading, contacts, blocking, the
plan), the strategies of the exact plan (``ways`` where it is written as each part's ways in) and its
count (``Schedule.count_result``, exact or marked estimated, with the CPU seconds it took), or why it
was refused.  ``--markdown`` prints the table docs/derive.md quotes.

Usage: ``python benchmarks/bench_derive.py [--sizes 10,30,100,300] [--families block,wall,bond] [--seed 0]``

Reference (2-core machine shared with other jobs, load 18 to 20; CPU seconds):

    family parts    block dirs    checks contacts    cpu_s strat  count
     block    10    3x3x4    6        82       46     0.71     1  10^6.56
     block    30    4x4x6    6       416      147     0.41  ways  10^31.21 (estimated, ±46.3% at 95%)
     block   100    7x7x7    6     2,458      610     1.83  ways  10^145.02 (estimated, ±217.7% at 95%)
     block   300  10x10x9    6    10,456    1,743     6.89  ways  10^522.05 (estimated, ±315.9% at 95%)
      wall   300  20x1x30    6    11,400      850     2.99     1  10^290.25
      bond    21   20x1x2    6       240       39     0.15  ways  10^17.76 (estimated, ±6.4% at 95%)
      bond    94   20x1x9    6     2,022      245     1.14  ways  10^115.93 (estimated, ±155.2% at 95%)
      bond   294  20x1x28    6    14,462      806     4.26  ways  10^437.14 (estimated, ±205.9% at 95%)

The geometry scales (300 parts, 1,743 contacts, 14,462 blocking checks in a few seconds); where the
exact union of partial orders outgrows a plan (the random blocks, the running bond under gravity) the
plan is written as each part's ways in, as exact, and counted by sequential Monte Carlo with its interval.
"""

from __future__ import annotations

import argparse
import itertools
import random
import tempfile
import time
from pathlib import Path

from opportune.derive import DeriveError, derive
from opportune.engine import Schedule

STEPS = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))
#: Seconds (of the clock) a count may take, four times as many on 300 parts (within the minute of the target).
COUNT_SECONDS = 10.0
#: Cubes per part on average: parts of a few cubes, as the tests' assemblies have.
CUBES_PER_PART = 3
QUADS = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]


def block_for(n: int) -> tuple[int, int, int]:
    """A near-cubic block of about ``n * CUBES_PER_PART`` cells, three high at least."""
    side = max(2, round((n * CUBES_PER_PART) ** (1 / 3)))
    depth = max(3, -(-n * CUBES_PER_PART // (side * side)))
    return side, side, depth


def partition(block, n: int, seed: int) -> dict[str, list]:
    rng = random.Random(seed)
    cells = list(itertools.product(*(range(k) for k in block)))
    inside = set(cells)
    owner = {c: i for i, c in enumerate(rng.sample(cells, n))}
    frontier = list(owner)
    while frontier:
        c = frontier.pop(rng.randrange(len(frontier)))
        free = [s for s in ((c[0] + a, c[1] + b, c[2] + d) for a, b, d in STEPS) if s in inside and s not in owner]
        if free:
            cell = rng.choice(free)
            owner[cell] = owner[c]
            frontier += [c, cell]
    parts: dict[str, list] = {}
    for c, p in sorted(owner.items()):
        parts.setdefault(f"p{p:03d}", []).append(c)
    return parts


def write(folder: Path, parts: dict[str, list]) -> None:
    for name, cells in parts.items():
        lines = []
        for n, (x, y, z) in enumerate(cells):
            lines += [f"v {x + i} {y + j} {z + k}" for i in (0, 1) for j in (0, 1) for k in (0, 1)]
            for q in QUADS:
                a, b, c, d = (8 * n + i for i in q)
                lines += [f"f {a} {b} {c}", f"f {a} {c} {d}"]
        (folder / f"{name}.obj").write_text("\n".join(lines) + "\n")


def wall(n: int, running: bool) -> tuple[dict[str, list], tuple[int, int, int]]:
    """A wall of about ``n`` bricks two cells long, ten bricks a course: stacked (each brick on one below)
    or in running bond (each course shifted by half a brick: a brick on two below, half bricks at the ends)."""
    width, courses = 20, max(1, int(n / (10.5 if running else 10)))
    parts: dict[str, list] = {}
    for z in range(courses):
        cuts = list(range(0, width + 1, 2))
        if running and z % 2:
            cuts = [0] + list(range(1, width, 2)) + [width]
        for k, (a, b) in enumerate(zip(cuts, cuts[1:])):
            parts[f"b{z:02d}_{k:02d}"] = [(x, 0, z) for x in range(a, b)]
    return parts, (width, 1, courses)


#: The generated families: how each assembly is made, and the options it is derived with.
FAMILIES = {
    "block": ("a random voxel block (parts grown from random seeds), default directions", {}),
    "wall": ("a stack-bond wall, --gravity -z", {"gravity": "-z"}),
    "bond": ("a running-bond wall, --gravity -z", {"gravity": "-z"}),
}


def row(family: str, n: int, seed: int, markdown: bool = False) -> str:
    if family == "block":
        block = block_for(n)
        parts = partition(block, n, seed)
    else:
        parts, block = wall(n, running=family == "bond")
    options = FAMILIES[family][1]
    head = f"{family:>6} {len(parts):>5} {'x'.join(map(str, block)):>8}"
    if markdown:
        head = f"| {family} | {len(parts)} | {'×'.join(map(str, block))} |"
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write(folder, parts)
        start = time.process_time()
        try:
            derived = derive(folder, **options)
        except DeriveError as exc:
            total = time.process_time() - start
            if markdown:      # the message's first clause: where the union outgrew the limit
                return f"{head} | | | {total:.2f} | | refused: {str(exc).split(' (')[0]} | |"
            return f"{head} {'':>4} {'':>9} {'':>8} {total:>8.2f}  refused: {exc}"
        total = time.process_time() - start
        d = derived.to_dict()
        start = time.process_time()
        counted = Schedule(derived.plan).count_result(time_limit=COUNT_SECONDS if n <= 100 else 4 * COUNT_SECONDS,
                                                      seed=seed)
        counting = time.process_time() - start
        count = f"10^{counted.log10:.2f}" + ("" if counted.exact else f" (estimated, ±{_percent(counted.rel_error)} "
                                                                      f"at 95%, {counted.method})")
        strategies = "ways" if derived.plan.is_ways else d["strategies"]
        if markdown:
            return (f"{head} {len(d['directions'])} | {d['blocking_checks']:,} | {d['contacts']:,} | {total:.2f} | "
                    f"{strategies} | {count} | {counting:.2f} |")
        return (f"{head} {len(d['directions']):>4} {d['blocking_checks']:>9,} {d['contacts']:>8,} {total:>8.2f} "
                f"{strategies:>5}  {count}  ({counting:.2f} s CPU)")


def _percent(rel: float) -> str:
    return f"{100 * rel:.1f}%" if rel < 10 else "unbounded"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10,30,100,300")
    parser.add_argument("--families", default=",".join(FAMILIES))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table (docs/derive.md)")
    args = parser.parse_args()
    if args.markdown:
        print("| family | parts | cells | directions | blocking checks | contacts | CPU s | strategies | count | "
              "count CPU s |\n|---|---:|---|---:|---:|---:|---:|---:|---|---:|")
    else:
        print(f"{'family':>6} {'parts':>5} {'block':>8} {'dirs':>4} {'checks':>9} {'contacts':>8} {'cpu_s':>8} "
              f"{'strat':>5}  count")
    for family in args.families.split(","):
        for n in (int(s) for s in args.sizes.split(",")):
            print(row(family, n, args.seed, args.markdown), flush=True)


if __name__ == "__main__":
    main()
