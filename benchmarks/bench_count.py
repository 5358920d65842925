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

Random sparse orders (``--sparse``, on by default) are the family of Talvitie et al.'s
linext benchmarks: a random permutation of ``n`` elements, each pair joined (in that
order) with probability ``k / (n - 1)`` (average degree ``k``), one seeded order per
``(n, k)``.  Each is counted the way ``opportune count --time-limit T`` counts (an
:class:`~opportune.engine.schedule.OrderEngine` with a tenth of ``T`` for the plain count,
then :meth:`~opportune.engine.schedule.Schedule.count_result` with the rest): exact or
not, engine seconds (wall and CPU: the machine may be shared), the method(s) that
finished the hard pieces (``plain``: the recursion within its probe; ``up``/``down``:
the recursion removing first/last elements; ``downsets``: the dynamic programme over
down-sets; ``hub``: the hub split; ``smc``: the estimate) and whether the call kept
``T`` plus the stated margin (10% + 0.2 s).  ``--alb FILE...`` adds ``.alb`` graphs
(if :mod:`opportune.formats.alb` is there) counted the same way.

Reference (same machine, ``--time-limit 10``; before the per-piece choice of method, the
same orders gave: exact only for n = 40 (both k) and n = 50, k = 5 (0.7 s); estimates
after 6.5-13.3 s, the limit not kept for n = 100, k = 3):

    order               n pairs  count                        exact?   wall s   cpu s method(s)      limit kept?
    avgdeg-3 n=40      40    75  10^32.0384 (33 digits)       yes        0.18    0.16 up             yes
    avgdeg-3 n=50      50    92  10^41.4119 (42 digits)       yes        1.46    1.41 up             yes
    avgdeg-3 n=64      64   108  ~10^65.053 ±560%             no         8.43    8.39 smc            yes
    avgdeg-3 n=80      80   110  ~10^93.577 ±1173%            no         9.03    8.89 smc            yes
    avgdeg-3 n=100    100   155  ~10^115.456 ±152%            no         8.43    8.32 smc            yes
    avgdeg-5 n=40      40   108  10^27.3837 (28 digits)       yes        0.15    0.15 down           yes
    avgdeg-5 n=50      50   125  10^38.1886 (39 digits)       yes        0.46    0.45 up             yes
    avgdeg-5 n=64      64   168  ~10^54.737 ±122%             no         8.51    8.47 smc            yes
    avgdeg-5 n=80      80   201  ~10^77.621 ±168%             no         8.43    8.37 smc            yes
    avgdeg-5 n=100    100   244  ~10^110.676 ±60652%          no         8.43    8.32 smc            yes

The C++ ``linext`` counts such orders of 50 elements exactly in 0.05-2 s.  Pure Python
spends about 5 us per memo entry and these need 0.05-5 million entries in the better
direction, so of twelve orders of 50 elements (k = 3, 5; seeds 0-5; the counter alone,
default budgets) five were exact in 0.3-6 s and seven needed more than the
2-million-entry memo budget (> 11 s).  The
estimates get what the exact phases leave (about 3 s of 10) and say how little that is.

    PYTHONPATH=src python3 benchmarks/bench_count.py [--data DIR] [--exact-time S] [--estimate-time S]
        [--no-salbp] [--no-sparse] [--sizes 40,50,64,80,100] [--degrees 3,5] [--time-limit T] [--alb FILE...]
"""

from __future__ import annotations

import argparse
import math
import random
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


def sparse_pairs(n: int, k: float, seed: int) -> list[tuple[int, int]]:
    """A random order of average degree ``k`` (linext's ``random_average_degree``): a random permutation,
    each pair joined in that order with probability ``k / (n - 1)``."""
    rng = random.Random(seed)
    perm = list(range(n))
    rng.shuffle(perm)
    p = k / (n - 1)
    return [(perm[i], perm[j]) for i in range(n) for j in range(i + 1, n) if rng.random() < p]


MARGIN = (0.10, 0.2)    # the time limit is kept if the call returns within T * (1 + 10%) + 0.2 s


def count_like_cli(n: int, pairs: list[tuple[int, int]], time_limit: float) -> dict:
    """Count an order as ``opportune count --time-limit T`` does; what it found and how long it took."""
    from opportune import make_plan
    from opportune.engine import OrderEngine, Schedule

    ids = [str(i + 1) for i in range(n)]
    requires: dict[str, list[str]] = {}
    for a, b in set(pairs):
        requires.setdefault(ids[b], []).append(ids[a])
    plan = make_plan(ids, requires, name="sparse")
    wall, cpu = time.perf_counter(), time.process_time()
    engine = OrderEngine(plan, max_memo=2_000_000, time_limit=time_limit / 10)
    result = Schedule(engine).count_result(time_limit=time_limit * 9 / 10)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    methods: dict[str, int] = {}
    hub = False
    for counter in engine._counters.values():
        if counter is not None:
            for name, k in counter.methods.items():
                methods[name] = methods.get(name, 0) + k
            hub = hub or bool(engine._hubs.get(counter))
    used = sorted(methods) + (["hub"] if hub else [])
    if not result.exact:
        used.append(result.method)
    return {"result": result, "wall": wall, "cpu": cpu, "methods": "+".join(used) or "plain",
            "kept": wall <= time_limit * (1 + MARGIN[0]) + MARGIN[1]}


def show_result(result) -> str:
    if result.exact:
        return show_count(int(result.value))
    if result.value != result.value:            # nan: not even one estimate run finished
        return "-"
    return f"~10^{result.log10:.3f} ±{100 * result.rel_error:.0f}%"


def sparse_rows(sizes: list[int], degrees: list[float], time_limit: float) -> None:
    head = (f"{'order':<16} {'n':>4} {'pairs':>5}  {'count':<28} {'exact?':<7} {'wall s':>7} {'cpu s':>7} "
            f"{'method(s)':<14} {'limit kept?':<11}")
    print(f"\nrandom sparse orders (linext's family), counted as `opportune count --time-limit {time_limit:g}`")
    print(head)
    print("-" * len(head))
    for k in degrees:
        for n in sizes:
            pairs = sparse_pairs(n, k, seed=1000 * n + int(10 * k))
            r = count_like_cli(n, pairs, time_limit)
            print(f"{f'avgdeg-{k:g} n={n}':<16} {n:>4} {len(pairs):>5}  {show_result(r['result']):<28} "
                  f"{'yes' if r['result'].exact else 'no':<7} {r['wall']:>7.2f} {r['cpu']:>7.2f} "
                  f"{r['methods']:<14} {'yes' if r['kept'] else 'NO':<11}", flush=True)


def alb_rows(files: list[Path], time_limit: float) -> None:
    try:
        from opportune.formats.alb import read_alb
    except ImportError:
        print("\n--alb: opportune.formats.alb is not available in this checkout; skipped", file=sys.stderr)
        return
    head = (f"{'file':<24} {'n':>5} {'pairs':>6}  {'count':<28} {'exact?':<7} {'wall s':>7} {'cpu s':>7} "
            f"{'method(s)':<14} {'limit kept?':<11}")
    print(f"\n.alb graphs, counted as `opportune count --time-limit {time_limit:g}`")
    print(head)
    print("-" * len(head))
    for path in files:
        try:
            graph = read_alb(path)
        except Exception as exc:                # a bad file is reported, not fatal
            print(f"{path.name:<24} cannot be read: {exc}")
            continue
        pairs = [(a - 1, b - 1) for a, b in graph.pairs]
        r = count_like_cli(graph.n, pairs, time_limit)
        print(f"{path.name[:24]:<24} {graph.n:>5} {len(pairs):>6}  {show_result(r['result']):<28} "
              f"{'yes' if r['result'].exact else 'no':<7} {r['wall']:>7.2f} {r['cpu']:>7.2f} "
              f"{r['methods']:<14} {'yes' if r['kept'] else 'NO':<11}", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--exact-time", type=float, default=2.0, help="time limit of the plain exact attempt per file")
    ap.add_argument("--max-memo", type=int, default=2_000_000)
    ap.add_argument("--estimate-time", type=float, default=10.0)
    ap.add_argument("--rel-error", type=float, default=0.01)
    ap.add_argument("--particles", type=int, default=1024, help="sets per step of the estimator")
    ap.add_argument("--no-salbp", action="store_true", help="skip the SALBP graphs")
    ap.add_argument("--no-sparse", action="store_true", help="skip the random sparse orders")
    ap.add_argument("--sizes", default="40,50,64,80,100", help="sizes n of the random sparse orders")
    ap.add_argument("--degrees", default="3,5", help="average degrees k of the random sparse orders")
    ap.add_argument("--time-limit", type=float, default=10.0,
                    help="`opportune count --time-limit` for the sparse orders and the .alb graphs")
    ap.add_argument("--alb", type=Path, nargs="+", default=[], metavar="FILE", help=".alb graphs to count too")
    args = ap.parse_args(argv)
    if not args.no_salbp:
        status = salbp_rows(args)
        if status:
            return status
    if not args.no_sparse:
        sparse_rows([int(x) for x in args.sizes.split(",") if x], [float(x) for x in args.degrees.split(",") if x],
                    args.time_limit)
    if args.alb:
        alb_rows(args.alb, args.time_limit)
    return 0


def salbp_rows(args) -> int:
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
