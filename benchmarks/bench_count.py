"""Benchmark of the order engine's counting on real SALBP precedence graphs.

Prints one row per ``.IN2`` file: tasks, precedence pairs, the number of linear
extensions (or its log10 and digit count), whether it is exact, cold seconds,
memo size, and the cost of a repeated (memoised) query.  Files whose exact
count exceeds the budget get an :func:`estimate_count` with its stated error
(sequential Monte Carlo; the runs line says how many independent runs gave
the interval).

Reference (2-core dev machine, Python 3.11; plain exact attempt 2 s, then hub split / estimator 10 s):

    file          tasks pairs  count                        exact?            seconds      memo   lookup
    MITCHELL.IN2     21    27  1449624                      yes                 0.001        67    168ns
    HESKIA.IN2       28    39  10^20.2317 (21 digits)       yes                 0.001        16    170ns
    KILBRID.IN2      45    62  10^29.2974 (30 digits)       yes                 0.025      3239    160ns
    TONGE70.IN2      70    86  10^46.9716 (47 digits)       yes                 0.135     15141    161ns
    ARC111.IN2      111   176  -                            no: time budget     2.006    256513
      └ exact                  10^103.0294 (104 digits)     yes: hub split      6.496    286763

ARC111 defeats the plain recursion (600 s and 46M memo entries were not enough)
but is exact through its hub, task 91 (see ``opportune.engine.hub``).  The
sequential Monte Carlo estimator, used only when the hub split fails too,
stated 10^103.05 ±36% in 10 s there, and long runs agree with the exact count.

    PYTHONPATH=src python3 benchmarks/bench_count.py [--data DIR] [--exact-time S] [--estimate-time S]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from opportune.engine.count import BudgetExceeded, Counter
from opportune.engine.estimate import estimate_count
from opportune.engine.poset import Poset
from opportune.formats.salbp import read_in2

from opportune import datasets

DEFAULT_DATA = datasets.salbp_path("KILBRID").parent  # the graphs shipped in the package


def show_count(v: int) -> str:
    s = str(v)
    if len(s) <= 16:
        return s
    return f"10^{math.log10(v):.4f} ({len(s)} digits)"


def lookup_ns(counter: Counter, mask: int, reps: int = 200_000) -> float:
    count = counter.count
    t = time.perf_counter()
    for _ in range(reps):
        count(mask)
    return (time.perf_counter() - t) / reps * 1e9


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--exact-time", type=float, default=2.0, help="time limit of the plain exact attempt per file")
    ap.add_argument("--max-memo", type=int, default=2_000_000)
    ap.add_argument("--estimate-time", type=float, default=10.0)
    ap.add_argument("--rel-error", type=float, default=0.01)
    ap.add_argument("--particles", type=int, default=1024, help="sets per step of the estimator")
    args = ap.parse_args(argv)
    if not args.data.is_dir():
        print(f"no data folder at {args.data}", file=sys.stderr)
        return 2
    rows = []
    for path in args.data.glob("*.IN2"):
        graph = read_in2(path)
        rows.append((graph.n, path, [(a - 1, b - 1) for a, b in graph.pairs]))
    rows.sort()
    head = f"{'file':<13} {'tasks':>5} {'pairs':>5}  {'count':<28} {'exact?':<16} {'seconds':>8} {'memo':>9} {'lookup':>8}"
    print(head)
    print("-" * len(head))
    for n, path, pairs in rows:
        t = time.perf_counter()
        poset = Poset.from_pairs(n, pairs)
        counter = Counter(poset, max_memo=args.max_memo, time_limit=args.exact_time)
        try:
            v = counter.count()
            dt = time.perf_counter() - t
            ns = lookup_ns(counter, poset.full)
            print(f"{path.name:<13} {n:>5} {len(pairs):>5}  {show_count(v):<28} {'yes':<16} {dt:>8.3f} "
                  f"{counter.memo_size:>9} {ns:>6.0f}ns", flush=True)
        except BudgetExceeded as exc:
            dt = time.perf_counter() - t
            print(f"{path.name:<13} {n:>5} {len(pairs):>5}  {'-':<28} {'no: ' + exc.reason + ' budget':<16} "
                  f"{dt:>8.3f} {counter.memo_size:>9} {'':>8}", flush=True)
            t = time.perf_counter()
            counter.max_memo = None
            # the plain attempt above already had its budget: next the hub split, then (if needed) sampling
            est = estimate_count(poset, rel_error=args.rel_error, time_limit=args.estimate_time, counter=counter,
                                 particles=args.particles, exact_memo=0)
            dt = time.perf_counter() - t
            if est.exact is not None:
                shown, status, label = show_count(est.exact), "yes: hub split", "  └ exact"
            else:
                shown = f"10^{est.log10_value:.4f}" if est.samples else "-"
                status, label = f"est ±{100 * est.rel_error:.2f}%", "  └ estimate"
            print(f"{label:<13} {'':>5} {'':>5}  {shown:<28} {status:<16} {dt:>8.3f} "
                  f"{counter.memo_size:>9} {'':>8}", flush=True)
            if est.exact is None:
                hi = est.log10_value + math.log10(1 + est.rel_error)
                if est.rel_error < 1:
                    span = f"10^{est.log10_value + math.log10(1 - est.rel_error):.3f} .. 10^{hi:.3f}"
                else:
                    span = f"0 .. 10^{hi:.3f}"
                print(f"{'':<13} {'':>5} {'':>5}  ({est.method}: {est.samples} runs of {args.particles} particles; "
                      f"{100 * est.confidence:.0f}% CI {span})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
