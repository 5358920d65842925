"""Benchmark of ``opportune relax``'s exact minimum-weight feedback arc set on over-constrained plans.

Each SALBP graph shipped with the package gets ``extra`` contradictory constraints: pairs ``(a, b)``
where the plan already puts ``a`` before ``b`` (directly or through other tasks), drawn with a seed,
each added as ``b -> a``.  Every constraint weighs 1.  One row per (graph, extra, seed): the largest
knot (strongly connected component) to solve, the weight of the cheapest relaxation, whether it is
proven minimal, and the seconds :func:`opportune.derive.relax.min_feedback_arc_set` took.  Then the
same for dense random knots (each arc present with probability 1/2, weights 1 to 9), where the
subset DP does the work.

Reference (2-core dev machine, Python 3.12, time limit 30 s per row): every row proven minimal;
SALBP knots of up to 111 tasks in 0.00 to 1.7 s (most under 0.1 s); dense knots of 16, 18 and 20
parts in about 0.8, 2 and 7-8 s (the machine shared with other jobs).

    python benchmarks/bench_relax.py [--time-limit 30]
"""

from __future__ import annotations

import argparse
import random
import time

from opportune import datasets
from opportune.engine.poset import Poset
from opportune.derive.relax import RelaxTimeout, min_feedback_arc_set, strongly_connected_components


def largest_knot(ids, arcs) -> int:
    index = {p: i for i, p in enumerate(ids)}
    succ: list[list[int]] = [[] for _ in ids]
    for u, v in arcs:
        succ[index[u]].append(index[v])
    return max(len(c) for c in strongly_connected_components(len(ids), succ))


def solve(ids, arcs, time_limit: float) -> tuple[float, str, float]:
    start = time.perf_counter()
    try:
        weight, _ = min_feedback_arc_set(ids, arcs, time_limit=time_limit)
        proof = "minimal"
    except RelaxTimeout as exc:
        weight, proof = exc.weight, "NOT PROVEN"
    return weight, proof, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--time-limit", type=float, default=30.0, help="seconds per row")
    args = parser.parse_args()
    print(f"{'plan':<10} {'tasks':>5} {'arcs':>5} {'extra':>5} {'seed':>4} {'knot':>5} {'weight':>6}  {'proof':<10} seconds")
    for name in ("KILBRID", "TONGE70", "ARC111"):
        plan = datasets.salbp(name)
        ids = plan.part_ids
        pairs = plan.strategies[0].pairs()
        index = {p: i for i, p in enumerate(ids)}
        poset = Poset.from_pairs(len(ids), [(index[b], index[a]) for b, a in pairs])
        comparable = [(i, j) for j in range(len(ids)) for i in range(len(ids)) if (poset.below[j] >> i) & 1]
        for extra in (3, 10, 30):
            for seed in range(3):
                rng = random.Random(seed)
                arcs = {(b, a): 1 for b, a in pairs}
                for i, j in rng.sample(comparable, extra):
                    arcs[(ids[j], ids[i])] = 1
                weight, proof, seconds = solve(ids, arcs, args.time_limit)
                print(f"{name:<10} {len(ids):>5} {len(arcs):>5} {extra:>5} {seed:>4} {largest_knot(ids, arcs):>5} "
                      f"{weight:>6g}  {proof:<10} {seconds:.2f}", flush=True)
    for n in (12, 16, 18, 20):
        rng = random.Random(n)
        ids = [f"p{i}" for i in range(n)]
        arcs = {(u, v): rng.randint(1, 9) for u in ids for v in ids if u != v and rng.random() < 0.5}
        weight, proof, seconds = solve(ids, arcs, args.time_limit)
        print(f"{'dense':<10} {n:>5} {len(arcs):>5} {'-':>5} {n:>4} {largest_knot(ids, arcs):>5} {weight:>6g}  "
              f"{proof:<10} {seconds:.2f}", flush=True)


if __name__ == "__main__":
    main()
