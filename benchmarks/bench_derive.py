"""Benchmark of `opportune derive` on generated voxel assemblies.

A block of unit cubes is cut into ``n`` connected parts (grown from random seeds, one seed per size),
each part written as an OBJ of closed cubes; the assembly is derived with ``--directions axes`` and
the row gives the parts, directions, blocking checks (body-pair tests after the bounding boxes), CPU
seconds of the blocking relation and of the whole derivation, the strategies of the exact plan, and
its count (``Schedule.count_result``, exact or marked estimated), or why it was refused.

Usage: ``python benchmarks/bench_derive.py [--sizes 10,30,100,300] [--seed 0]``

Reference (2-core machine shared with other jobs, load about 4; CPU seconds):

    parts    block dirs    checks  block_s  total_s strat  count
       10    3x3x4    6        82     0.92     0.12     1  10^6.56
       30    4x4x6    6       416     0.28     2.99  refused: the exact plan needs more than 64 strategies
      100    7x7x7    6     2,458     1.43     1.40  refused: 1.1e23 combinations of insertion directions
      300  10x10x9    6    10,456     4.68     4.61  refused: 1.7e75 combinations of insertion directions

(``block_s`` includes importing trimesh on the first row.)  The blocking relation scales (300 parts
in under 5 s); the exact union of direction choices does not: random voxel blocks of 30 parts and more
have too many incomparable choices for one plan of at most 64 strategies, and are refused, never
approximated.
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


def row(family: str, n: int, seed: int) -> str:
    if family == "block":
        block = block_for(n)
        parts = partition(block, n, seed)
    else:
        parts, block = wall(n, running=family == "bond")
    options = FAMILIES[family][1]
    head = f"{family:>6} {len(parts):>5} {'x'.join(map(str, block)):>8}"
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write(folder, parts)
        start = time.process_time()
        try:
            derived = derive(folder, **options)
        except DeriveError as exc:
            total = time.process_time() - start
            return f"{head} {'':>4} {'':>9} {'':>8} {total:>8.2f}  refused: {exc}"
        total = time.process_time() - start
        d = derived.to_dict()
        counted = Schedule(derived.plan).count_result(time_limit=10.0)
        count = f"10^{counted.log10:.2f}" + ("" if counted.exact else " (estimated)")
        return (f"{head} {len(d['directions']):>4} {d['blocking_checks']:>9,} {d['contacts']:>8,} {total:>8.2f} "
                f"{d['strategies']:>5}  {count}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10,30,100,300")
    parser.add_argument("--families", default=",".join(FAMILIES))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"{'family':>6} {'parts':>5} {'block':>8} {'dirs':>4} {'checks':>9} {'contacts':>8} {'cpu_s':>8} "
          f"{'strat':>5}  count")
    for family in args.families.split(","):
        for n in (int(s) for s in args.sizes.split(",")):
            print(row(family, n, args.seed), flush=True)


if __name__ == "__main__":
    main()
