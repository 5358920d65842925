"""Benchmark of adaptive relaxation Monte Carlo (:mod:`opportune.engine.relaxmc`): speed and honesty.

Table 1, speed: the random sparse orders of ``benchmarks/vs_peers.py`` (``n`` = 64, 80, 100, average
degree 3 and 5, the same generator and seeds), each estimated once within ``--seconds`` (3 s) aiming
at ±5 % at 95 %: wall and CPU seconds, the stated interval's larger relative side, the piece size
``k`` chosen, draws, hits, the memos' megabytes.  With ``--linext PATH`` (Talvitie et al.'s ``linext``,
built from its sources), its ``armc`` with ε = δ = 0.05 on the same order: its natural-log answer, its
wall seconds (it uses every core), and the difference of the two answers in percent.

Table 2, honesty: ``--runs`` (50) estimates with different seeds of orders whose count is known, the
share of stated 95 % intervals that hold it, and the widths and times.  The orders: sparse orders of
40 and 50 elements counted exactly by the engine, estimated with pieces of 20 (else one piece would
count them exactly and there would be nothing to cover); and two orders of 100 elements built with a
known count, also with pieces of 20 (pieces of 25 can be the four parts, exactly): four sparse orders
of 25 side by side (``100! / 25!^4`` times their counts) and a random forest (the hook-length formula).

    python benchmarks/bench_armc.py [--seconds 3] [--runs 50] [--linext ~/src/linext/linext]

Times depend on what else runs on the machine: say what did when quoting them.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_count import sparse_pairs

from opportune.engine import relaxmc
from opportune.engine.count import Counter
from opportune.engine.poset import Poset


def linext_armc(path: str, n: int, pairs, timeout: float) -> tuple[float, float | None]:
    """linext's ``armc`` (ε = δ = 0.05) on the order: (wall seconds, natural log of its answer or None)."""
    with tempfile.TemporaryDirectory() as folder:
        matrix = Path(folder) / "order.txt"
        rows = [[0] * n for _ in range(n)]
        for a, b in pairs:
            rows[a][b] = 1
        matrix.write_text("\n".join(" ".join(map(str, r)) for r in rows) + "\n")
        start = time.perf_counter()
        try:
            out = subprocess.run([path, str(matrix), "armc", "0.05", "0.05"], check=False, capture_output=True,
                                 text=True, timeout=timeout, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return time.perf_counter() - start, None
        wall = time.perf_counter() - start
        found = re.findall(r"(?<![A-Z_])LINEXT_LOG_COUNT (\S+)", out.stdout + out.stderr)   # lines start with times
        return wall, float(found[-1]) if found else None


def speed_table(args) -> None:
    print(f"Table 1: one estimate within {args.seconds:g} s aiming at ±{100 * args.rel_error:g} % at 95 %")
    head = (f"{'order':<18} {'wall s':>7} {'cpu s':>6} {'stated':>8} {'status':>7} {'k':>3} {'draws':>9} "
            f"{'hits':>5} {'MB':>5} {'ln count':>10}")
    if args.linext:
        head += f" {'linext ln':>10} {'linext s':>8} {'diff %':>7}"
    print(head)
    for degree in (3, 5):
        for n in (64, 80, 100):
            pairs = sparse_pairs(n, degree, seed=n * 100 + degree)
            p = Poset.from_pairs(n, pairs)
            wall, cpu = time.perf_counter(), time.process_time()
            r = relaxmc.estimate(p, args.seconds, rel_error=args.rel_error, seed=0, threads=args.threads)
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            ln = r.log10 * math.log(10)
            row = (f"{f'sparse k={degree} n={n}':<18} {wall:7.2f} {cpu:6.2f} {100 * r.rel_error:7.2f}% "
                   f"{r.status:>7} {r.k:3d} {r.draws:9d} {r.hits:5d} {r.bytes / 2**20:5.0f} {ln:10.4f}")
            if args.linext:
                lwall, lln = linext_armc(args.linext, n, pairs, args.linext_timeout)
                if lln is None:
                    row += f" {'timeout':>10} {lwall:8.2f} {'':>7}"
                else:
                    row += f" {lln:10.4f} {lwall:8.2f} {100 * math.expm1(ln - lln):7.2f}"
            print(row, flush=True)


def forest(n: int, seed: int) -> tuple[list[tuple[int, int]], int]:
    """A random forest (each element's parent drawn among the earlier ones, or none) and its count,
    n! / prod of subtree sizes (the hook-length formula)."""
    rng = random.Random(seed)
    parent = [-1] + [rng.randrange(-1, i) if rng.random() < 0.9 else -1 for i in range(1, n)]
    size = [1] * n
    for v in range(n - 1, 0, -1):
        if parent[v] >= 0:
            size[parent[v]] += size[v]
    count = math.factorial(n)
    for s in size:
        count //= s
    return [(parent[v], v) for v in range(n) if parent[v] >= 0], count


def side_by_side(parts: int, size: int, degree: float, seed: int) -> tuple[list[tuple[int, int]], int]:
    """``parts`` sparse orders of ``size`` elements next to each other, and the count of the whole."""
    pairs, count = [], math.factorial(parts * size)
    for i in range(parts):
        sub = sparse_pairs(size, degree, seed=seed + i)
        count = count // math.factorial(size) * Counter(Poset.from_pairs(size, sub), max_memo=None).count()
        pairs += [(a + i * size, b + i * size) for a, b in sub]
    return pairs, count


def coverage_table(args) -> None:
    print(f"\nTable 2: {args.runs} estimates (seeds 0..{args.runs - 1}) of orders with a known count, "
          f"±{100 * args.rel_error:g} % asked at 95 %, {args.seconds:g} s each")
    print(f"{'order':<26} {'k':>5} {'covered':>8} {'stated median':>14} {'stated max':>11} {'median s':>9} "
          f"{'max s':>6}")
    cases = []
    for n, degree in ((40, 3), (50, 3), (40, 5), (50, 5)):
        pairs = sparse_pairs(n, degree, seed=n * 100 + degree)
        p = Poset.from_pairs(n, pairs)
        cases.append((f"sparse k={degree} n={n}", p, Counter(p, max_memo=None).count(), 20))
    pairs, count = side_by_side(4, 25, 3, seed=77)
    cases.append(("4 x sparse k=3 n=25", Poset.from_pairs(100, pairs), count, 20))
    pairs, count = forest(100, seed=5)
    cases.append(("forest n=100", Poset.from_pairs(100, pairs), count, 20))
    for name, p, true, k in cases:
        covered, widths, times = 0, [], []
        for seed in range(args.runs):
            t = time.perf_counter()
            r = relaxmc.estimate(p, args.seconds, rel_error=args.rel_error, seed=seed, k=k, threads=args.threads)
            times.append(time.perf_counter() - t)
            widths.append(r.rel_error)
            covered += r.log10_low <= math.log10(true) <= r.log10_high
        widths.sort()
        times.sort()
        print(f"{name:<26} {k or 'auto':>5} {covered:>4}/{args.runs:<3} {100 * widths[len(widths) // 2]:13.2f}% "
              f"{100 * widths[-1]:10.2f}% {times[len(times) // 2]:9.2f} {times[-1]:6.2f}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="time for one estimate")
    ap.add_argument("--rel-error", type=float, default=0.05, help="the interval's half-width aimed at")
    ap.add_argument("--runs", type=int, default=50, help="estimates per order in the coverage table")
    ap.add_argument("--linext", help="path of linext's binary (its armc beside ours)")
    ap.add_argument("--linext-timeout", type=float, default=120.0)
    ap.add_argument("--skip-speed", action="store_true")
    ap.add_argument("--skip-coverage", action="store_true")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1,
                    help="threads that count and draw (default: one per core, as linext's armc and `opportune count`)")
    args = ap.parse_args()
    if not relaxmc.available():
        sys.exit("relaxation Monte Carlo needs the compiled core (pip install -e . with a compiler)")
    print(f"load average {os.getloadavg()[0]:.2f} at the start; {os.cpu_count()} cores, {args.threads} threads")
    if not args.skip_speed:
        speed_table(args)
    if not args.skip_coverage:
        coverage_table(args)
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
