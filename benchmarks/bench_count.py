"""Benchmark of the order engine's counting on real SALBP precedence graphs.

Prints one row per ``.IN2`` file: tasks, precedence pairs, the number of linear
extensions (or its log10 and digit count), whether it is exact, cold seconds,
memo size, and the cost of a repeated (memoised) query.  Files whose exact
count exceeds the budget get an :func:`estimate_count` with its stated error.

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

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "salbp"


def read_in2(path: Path) -> tuple[int, list[tuple[int, int]]]:
    """Private minimal .IN2 reader (n, durations, 1-based pairs up to ``-1,-1``), 0-based pairs out."""
    lines = [ln.strip() for ln in path.read_bytes().decode("latin-1").splitlines()]
    lines = [ln for ln in lines if ln]
    n = int(lines[0])
    pairs = []
    for ln in lines[1 + n:]:
        a, b = (int(t) for t in ln.split(","))
        if (a, b) == (-1, -1):
            break
        pairs.append((a - 1, b - 1))
    return n, pairs


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
    ap.add_argument("--exact-time", type=float, default=10.0, help="time limit of the exact attempt per file")
    ap.add_argument("--max-memo", type=int, default=2_000_000)
    ap.add_argument("--estimate-time", type=float, default=10.0)
    ap.add_argument("--rel-error", type=float, default=0.01)
    args = ap.parse_args(argv)
    if not args.data.is_dir():
        print(f"no data folder at {args.data}", file=sys.stderr)
        return 2
    rows = []
    for path in args.data.glob("*.IN2"):
        n, pairs = read_in2(path)
        rows.append((n, path, pairs))
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
            est = estimate_count(poset, rel_error=args.rel_error, time_limit=args.estimate_time, counter=counter)
            dt = time.perf_counter() - t
            shown = f"10^{est.log10_value:.4f}"
            status = f"est ±{100 * est.rel_error:.2f}%"
            print(f"{'  └ estimate':<13} {'':>5} {'':>5}  {shown:<28} {status:<16} {dt:>8.3f} "
                  f"{counter.memo_size:>9} {'':>8}", flush=True)
            print(f"{'':<13} {'':>5} {'':>5}  ({est.method}, {est.samples} samples, "
                  f"{100 * est.confidence:.0f}% CI)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
