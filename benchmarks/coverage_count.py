"""Coverage of the estimator's stated interval: does the 95% interval of ``estimate_count`` hold the truth?

Repeats :func:`opportune.engine.estimate.estimate_count` with different seeds on
orders whose exact count is known, with the exact paths switched off
(``exact_memo=0``, ``hub=0``) so that every answer is a sequential Monte Carlo
estimate, and prints per case and time limit:

* ``runs``: repetitions (one estimate each);
* ``cover``: share of them whose stated interval ``value * (1 ± rel_error)``
  contains the exact count (``hits/runs``; the goal is ≥ 90% everywhere);
* ``stated``: median stated relative error; ``actual``: median ``|value/exact - 1|``;
  ``worst``: the largest ``|exact/value - 1| / stated`` (> 1 is a miss: the interval is
  ``value * (1 ± stated)``);
* ``reps``: median number of independent SMC runs behind one estimate; ``sec``: mean seconds.

Cases (``--cases``, comma-separated; ``--list`` shows them):

* ``KILBRID``, ``TONGE70``, ``ARC111``: the SALBP graphs shipped with the package, with the
  estimator's defaults (1,024 particles, probed exact tail) as ``Schedule.count_result`` uses
  them.  ARC111's exact value is the one in docs/counting.md (counted through its hub).
* ``KILBRID-p64``, ``TONGE70-p128``: few particles and a short exact tail, as in the tests,
  so that the sampling error is large; ``ARC111-p128``: 128 particles (a run takes ~0.4 s
  instead of ~3 s, so more runs fit in the time).
* ``rand30``, ``rand40``: a new random order per repetition (seeded; ``n`` tasks,
  each pair related with the given probability), with few particles; ``rand36-default``
  and ``rand40-default`` use the defaults (each repetition costs an exact count of up to ~3 s).  ``small``: the tests' small random orders (10–22 tasks, 8 particles).

Every estimate asks for ``--rel-error`` (default 0.01, as ``count_result`` does), so it stops on
accuracy only when its interval is that narrow and otherwise on the clock.  With
``--jobs 2`` two repetitions run side by side, which makes each slower (a "busy machine").

    nice .venv/bin/python benchmarks/coverage_count.py --cases KILBRID-p64,rand30 --limits 0.5,2 --runs 40
    nice .venv/bin/python benchmarks/coverage_count.py --cases ARC111 --limits 2 --runs 20 --jobs 2

Reference (issue 11; the 2-core machine, shared with other work: load 2–5, so runs per estimate vary
between measurements).  Coverage, hits/runs, and median stated error, before (Student's t on the runs'
estimates, accuracy stop from 4 runs) and after (``_stated_error``: t on the estimates and on their
logs, a skew margin, accuracy stop from 20 runs); ``actual`` is the median actual error after:

    case            limit  before              after                 actual   runs/est. after
    small            0.5   30/30  ±1.0%        29/30  ±1.0%          0.18%    188
    small              2   29/30  ±1.0%        29/30  ±1.0%          0.14%    188
    rand30           0.5   29/30  ±7.8%        27/30  ±5.1%          1.5%     116
    rand30             2   29/30  ±3.4%        29/30  ±2.5%          0.80%    461
    KILBRID          0.5   30/30  ±0.00%       29/30  ±0.00%         0.00%    20
    KILBRID            2   30/30  ±0.00%       29/30  ±0.00%         0.00%    20
    KILBRID-p64      0.5   25/30  ±30%         29/30  ±36%           9.2%     17
    KILBRID-p64        2   25/30  ±14%         29/30  ±12%           3.8%     73
    KILBRID-p64       10   19/20  ±5.0%        19/20  ±4.9%          0.93%    372
    TONGE70          0.5   30/30  ±24%         30/30  ±12%           1.6%     2
    TONGE70            2   29/30  ±3.7%        28/30  ±1.7%          0.71%    14
    TONGE70           10   36/40  ±0.98%       38/40  ±0.99%         0.29%    39
    TONGE70-p128     0.5   29/30  ±71%         29/30  ±48%           7.6%     10
    TONGE70-p128       2   28/30  ±22%         28/30  ±20%           4.3%     41
    TONGE70-p128      10   19/20  ±9.0%        20/20  ±9.6%          2.3%     133
    rand40           0.5   28/30  ±12%         30/30  ±10%           4.3%     39
    rand40             2   27/30  ±6.2%        56/60  ±6.0%          2.0%     108
    rand36-default   0.5   28/30  ±4.3%        29/30  ±6.0%          0.30%    2
    rand36-default     2   27/30  ±1.0%        30/30  ±0.85%         0.19%    14
    rand36-default    10   18/20  ±0.96%       20/20  ±0.71%         0.12%    20
    rand40-default   0.5   30/30  ±13%         30/30  ±18%           0.67%    2
    rand40-default     2   30/30  ±11%         30/30  ±6.6%          0.53%    2.5
    ARC111             2   26/30  ±258%        29/30  ±13,000%       33%      2
    ARC111            10   25/30  ±206%        28/30  ±570%          22%      3
    ARC111-p128        2   19/30  ±194%        55/60  huge           57%      5–11
    ARC111-p128       10   22/30  ±73%         30/30  ±326%          28%      28

Before, the lowest coverage was 63% (ARC111 with 128 particles) and 83% on the default ARC111 and on
KILBRID with 64 particles; after, every case is at 90% or more, pooling repeated measurements
(ARC111-p128 at 2 s: 26/30 in one, 29/30 in another; rand40 at 2 s: 26/30 and 30/30, where two
seeds give means 3 standard errors off).  ARC111's time limits below ~6 s
are the same as 2 s: its first two runs (3 s each) always finish.  Two runs of an estimator whose
runs vary 4-fold honestly say little: ARC111 needs the hub split (exact), not these estimates.
"""

from __future__ import annotations

import argparse
import functools
import math
import random
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

from opportune import datasets
from opportune.engine.count import Counter
from opportune.engine.estimate import estimate_count
from opportune.engine.poset import Poset
from opportune.formats.salbp import read_in2

ARC111 = int("10699784376412101459782493168195923005080661642039797082750047251791783909891289373479579282476892160000")


@dataclass(frozen=True)
class Case:
    name: str
    source: str                  # "salbp:NAME" or "random:n_lo:n_hi:density" or "small"
    particles: int = 1024
    tail: int | None = None      # None: probed, as by default


CASES = {c.name: c for c in [
    Case("KILBRID", "salbp:KILBRID"),
    Case("TONGE70", "salbp:TONGE70"),
    Case("ARC111", "salbp:ARC111"),
    Case("KILBRID-p64", "salbp:KILBRID", 64, 10),
    Case("TONGE70-p128", "salbp:TONGE70", 128, 15),
    Case("ARC111-p128", "salbp:ARC111", 128),
    Case("rand30", "random:30:30:0.1", 16, 4),
    Case("rand40", "random:40:40:0.08", 32, 6),
    Case("rand36-default", "random:36:36:0.1"),
    Case("rand40-default", "random:40:40:0.08"),
    Case("small", "small", 8, 2),
]}


def random_poset(n: int, density: float, rng: random.Random) -> Poset:
    """A random order: a random permutation, each pair in its order related with probability ``density``
    (the same construction as tests/test_engine_estimate.py)."""
    perm = list(range(n))
    rng.shuffle(perm)
    pairs = [(perm[i], perm[j]) for i in range(n) for j in range(i + 1, n) if rng.random() < density]
    return Poset.from_pairs(n, pairs)


@functools.cache
def instance(case: Case, rep: int) -> tuple[Poset, int]:
    """The order of repetition ``rep`` of ``case`` and its exact number of linear extensions (cached)."""
    kind, _, rest = case.source.partition(":")
    if kind == "salbp":
        if rest != case.name:
            return instance(CASES[rest], 0)
        graph = read_in2(datasets.salbp_path(rest))
        p = Poset.from_pairs(graph.n, [(a - 1, b - 1) for a, b in graph.pairs])
        return p, ARC111 if rest == "ARC111" else Counter(p).count()
    rng = random.Random(f"{case.name}/{rep}")
    if kind == "small":
        p = random_poset(rng.randint(10, 22), rng.choice([0.1, 0.2, 0.3]), rng)
    else:
        lo, hi, density = rest.split(":")
        p = random_poset(rng.randint(int(lo), int(hi)), float(density), rng)
    return p, Counter(p, max_memo=None).count()


def one(args: tuple[str, float, int, float]) -> tuple[bool, float, float, int, float, str, float]:
    """One estimate: (covered, stated error, actual error, SMC runs, seconds, method, |truth/value - 1| / stated)."""
    name, limit, rep, rel_error = args
    case = CASES[name]
    poset, exact = instance(case, rep)
    t = time.perf_counter()
    e = estimate_count(poset, exact_memo=0, hub=0, particles=case.particles, tail=case.tail,
                       rel_error=rel_error, time_limit=limit, seed=rep)
    dt = time.perf_counter() - t
    if e.method == "exact":
        return True, 0.0, 0.0, 0, dt, e.method, 0.0
    # relative error in logs, so that ARC111's 10^103 never overflows a float
    actual = abs(math.expm1((e.log10_value - math.log10(exact)) * math.log(10)))
    lo, hi = 1 - e.rel_error, 1 + e.rel_error
    ratio = math.exp((math.log10(exact) - e.log10_value) * math.log(10))   # truth / value
    covered = lo - 1e-12 <= ratio <= hi + 1e-12
    miss = abs(ratio - 1) / e.rel_error if e.rel_error > 0 else (0.0 if abs(ratio - 1) < 1e-9 else math.inf)
    return covered, e.rel_error, actual, e.samples, dt, e.method, miss


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="KILBRID-p64,TONGE70-p128,rand30,rand40,small",
                    help="comma-separated case names (see --list); 'all' for every one")
    ap.add_argument("--limits", default="0.5,2", help="comma-separated time limits in seconds")
    ap.add_argument("--runs", type=int, default=30, help="repetitions (seeds 0..runs-1) per case and limit")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--rel-error", type=float, default=0.01, help="the requested relative error")
    ap.add_argument("--jobs", type=int, default=1, help="repetitions run side by side")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    args = ap.parse_args(argv)
    if args.list:
        for c in CASES.values():
            print(f"{c.name:<15} {c.source:<22} particles={c.particles} tail={'probed' if c.tail is None else c.tail}")
        return 0
    names = list(CASES) if args.cases == "all" else [s.strip() for s in args.cases.split(",") if s.strip()]
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"unknown case(s): {', '.join(unknown)} (see --list)", file=sys.stderr)
        return 2
    limits = [float(x) for x in args.limits.split(",")]
    head = (f"{'case':<15} {'limit':>5} {'runs':>4} {'cover':>6} {'hits':>7} {'stated':>8} {'actual':>8} "
            f"{'worst':>6} {'reps':>5} {'sec':>6}")
    print(head)
    print("-" * len(head), flush=True)
    pool = ProcessPoolExecutor(args.jobs) if args.jobs > 1 else None
    lowest = 1.0
    try:
        for name in names:
            for limit in limits:
                jobs = [(name, limit, rep, args.rel_error) for rep in range(args.first_seed, args.first_seed + args.runs)]
                res = list(pool.map(one, jobs)) if pool else [one(j) for j in jobs]
                hits = sum(r[0] for r in res)
                cover = hits / len(res)
                lowest = min(lowest, cover)
                methods = {r[5] for r in res}
                note = "" if methods == {"smc"} else f"  ({', '.join(sorted(methods))})"
                print(f"{name:<15} {limit:>5g} {len(res):>4} {cover:>6.0%} {f'{hits}/{len(res)}':>7} "
                      f"{statistics.median(r[1] for r in res):>8.2%} {statistics.median(r[2] for r in res):>8.2%} "
                      f"{max(r[6] for r in res):>6.2f} {statistics.median(r[3] for r in res):>5g} "
                      f"{statistics.fmean(r[4] for r in res):>6.2f}{note}", flush=True)
    finally:
        if pool:
            pool.shutdown()
    print(f"lowest coverage: {lowest:.0%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
