"""Counting beside the peers: opportune, linext and LEcount on the same orders, side by side.

This script builds nothing and downloads nothing: give it the peers' programs, built locally from
their sources, with ``--linext PATH`` (Talvitie & Koivisto's ``linext``; its ``exact`` method, and
``armc``, the adaptive relaxation Monte Carlo, for estimates) and ``--lecount PATH`` (Kangas et al.'s
LEcount, IJCAI 2016).  A peer not given shows "not given" in its columns.

The orders (all seeded, the same on every run):

* the SALBP precedence graphs shipped with opportune (``--salbp``, names);
* generated assembly graphs (``benchmarks/gen_precedence.py``): 300 tasks at order strength 0.9,
  and a layered assembly graph of 300 tasks (each task needs one or two of the previous dozen,
  and one in twenty also one much earlier one);
* random sparse orders of linext's benchmarks (``--sizes``, ``--degrees``): a random permutation of
  ``n`` elements, each pair joined in that order with probability ``k / (n - 1)``.

For each order: opportune's whole process (``opportune count FILE --json --time-limit T``, wall
seconds, as a user runs it) and its engine alone (the same count in this process, wall and CPU
seconds, without Python's start-up and the plan's loading); each peer's whole process on the
adjacency-matrix file the peers read (``--timeout`` seconds at most).  ``exact`` columns say
whether an exact count came back and agree with each other (``log10`` to 1e-6); ``armc`` gives
linext's estimate with ``--epsilon``/``--delta``.

    python benchmarks/vs_peers.py --linext ~/src/linext/linext --lecount ~/src/lecount/lecount
    python benchmarks/vs_peers.py --sizes 40,50 --degrees 3 --no-generated --salbp KILBRID
    python benchmarks/vs_peers.py --json > peers.json

Times depend on what else runs on the machine: run it alone.  The table states the load average
before and after, and every process's CPU seconds (user and system, its children's included) beside
its wall seconds: on a shared machine compare those (the last column does, engine CPU against the
fastest exact peer's).  ``--no-armc`` skips linext's estimates (exact counts only).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import random
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_count import sparse_pairs  # noqa: E402

LN10 = math.log(10)


def layered_pairs(n: int, seed: int, window: int = 12) -> list[tuple[int, int]]:
    """A layered assembly graph: task ``i`` needs one or two of the ``window`` tasks before it, and one
    task in twenty also needs one much earlier task (a long arc)."""
    rng = random.Random(f"layered-{n}-{seed}")
    pairs = set()
    for i in range(1, n):
        for a in rng.sample(range(max(0, i - window), i), min(i, rng.choice((1, 2)))):
            pairs.add((a, i))
        if i > 3 * window and rng.random() < 0.05:
            pairs.add((rng.randrange(0, i - 2 * window), i))
    return sorted(pairs)


def orders(args) -> list[tuple[str, int, list[tuple[int, int]]]]:
    """``(name, n, pairs)`` of every order asked for (0-based elements, pairs ``a`` before ``b``)."""
    out = []
    if args.salbp:
        from opportune.datasets import salbp_path
        from opportune.formats.salbp import read_in2

        for name in args.salbp.split(","):
            g = read_in2(salbp_path(name))
            out.append((name, g.n, [(a - 1, b - 1) for a, b in g.pairs]))
    if not args.no_generated:
        from gen_precedence import generate

        arcs, _ = generate(300, 0.9, "mixed", 1)
        out.append(("gen-300-0.9", 300, [(a - 1, b - 1) for a, b in arcs]))
        out.append(("layered-300", 300, layered_pairs(300, 1)))
    for k in [float(x) for x in args.degrees.split(",") if x]:
        for n in [int(x) for x in args.sizes.split(",") if x]:
            out.append((f"sparse k={k:g} n={n}", n, sparse_pairs(n, k, seed=n * 100 + int(k))))
    return out


def write_files(folder: Path, name: str, n: int, pairs) -> tuple[Path, Path]:
    """The order as a plan (JSON, for opportune) and as an adjacency matrix (for the peers)."""
    stem = re.sub(r"[^\w.-]+", "_", name)
    plan = folder / f"{stem}.json"
    ids = [f"t{i}" for i in range(n)]
    requires: dict[str, list[str]] = {}
    for a, b in pairs:
        requires.setdefault(ids[b], []).append(ids[a])
    plan.write_text(json.dumps({"name": stem, "parts": ids, "requires": requires}))
    matrix = folder / f"{stem}.txt"
    rows = [[0] * n for _ in range(n)]
    for a, b in pairs:
        rows[a][b] = 1
    matrix.write_text("\n".join(" ".join(map(str, r)) for r in rows) + "\n")
    return plan, matrix


def children_cpu() -> float:
    """CPU seconds (user and system) of the finished child processes so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(argv: list[str], timeout: float, *, stderr: bool = False) -> tuple[float, float, str | None]:
    """Wall and CPU seconds, and the programme's standard output followed by its standard error if
    ``stderr`` (None if killed at ``timeout`` or failed): linext writes ``LINEXT_LOG_COUNT`` to
    standard error."""
    t0, c0 = time.perf_counter(), children_cpu()
    try:
        p = subprocess.run(argv, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:        # (run() kills and reaps it: its CPU time is counted)
        return time.perf_counter() - t0, children_cpu() - c0, None
    wall, cpu = time.perf_counter() - t0, children_cpu() - c0
    return wall, cpu, ((p.stdout + p.stderr if stderr else p.stdout) if p.returncode == 0 else None)


def run_opportune(plan: Path, time_limit: float) -> dict:
    wall, cpu, out = timed([sys.executable, "-m", "opportune", "count", str(plan), "--json", "--time-limit",
                            str(time_limit)], time_limit + 30)
    if out is None:
        return {"wall": wall, "cpu": cpu, "exact": False, "log10": None}
    doc = json.loads(out)
    return {"wall": wall, "cpu": cpu, "exact": doc["exact"], "log10": doc["log10"],
            "rel_error": doc.get("rel_error")}


def run_engine(n: int, pairs, time_limit: float) -> dict:
    """The count in this process, as ``opportune count`` makes it, without start-up and loading."""
    from opportune import make_plan
    from opportune.engine import OrderEngine, Schedule

    ids = [f"t{i}" for i in range(n)]
    requires: dict[str, list[str]] = {}
    for a, b in pairs:
        requires.setdefault(ids[b], []).append(ids[a])
    plan = make_plan(ids, requires, name="order")
    wall, cpu = time.perf_counter(), time.process_time()
    engine = OrderEngine(plan, max_memo=0, time_limit=time_limit / 10)      # as the command's default
    result = Schedule(engine).count_result(time_limit=time_limit * 9 / 10)
    return {"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu, "exact": result.exact,
            "log10": result.log10}


def run_linext(binary: str | None, matrix: Path, method: str, args) -> dict | None:
    if binary is None:
        return None
    wall, cpu, out = timed([binary, str(matrix), method, str(args.epsilon), str(args.delta)], args.timeout,
                           stderr=True)
    if out is None:
        return {"wall": wall, "cpu": cpu, "log10": None}
    found = re.findall(r"LINEXT_LOG_COUNT\s+(\S+)", out)
    return {"wall": wall, "cpu": cpu, "log10": float(found[-1]) / LN10 if found else None}


def run_lecount(binary: str | None, matrix: Path, args) -> dict | None:
    if binary is None:
        return None
    wall, cpu, out = timed([binary, str(matrix), *args.lecount_args.split()], args.timeout, stderr=True)
    if out is None:
        return {"wall": wall, "cpu": cpu, "log10": None}
    numbers = re.findall(r"\b\d+(?:\.\d+)?(?:[eE][+-]?\d+)?\b", out)
    if not numbers:
        return {"wall": wall, "cpu": cpu, "log10": None}
    value = numbers[-1]
    log10 = (len(value) - 1 + math.log10(int(value[:17]) / 10 ** (min(len(value), 17) - 1))
             if value.isdigit() else math.log10(float(value)))
    return {"wall": wall, "cpu": cpu, "log10": log10}


def cell(r: dict | None, *, exact: bool = True) -> str:
    if r is None:
        return "not given"
    if r.get("log10") is None:
        return f"— ({r['wall']:.2f} s; CPU {r['cpu']:.2f})"
    return f"{r['log10']:.4f} {'' if exact else '≈'}({r['wall']:.2f} s; CPU {r['cpu']:.2f})"


def verdict(ours: dict, engine: dict, peers: list[dict | None]) -> str:
    """Ahead or behind the fastest exact peer, by whole-process time (engine time when both are under 1 s)."""
    if all(p is None for p in peers):
        return "no peer given"
    exact = [p for p in peers if p is not None and p.get("log10") is not None]
    if not exact:
        return "only opportune exact" if ours["exact"] else "—"
    best = min(p["wall"] for p in exact)
    if not ours["exact"]:
        return f"behind: not exact (peer {best:.2f} s)"
    mine = ours["wall"] if max(ours["wall"], best) > 1 else engine["wall"]
    return f"{'ahead' if mine <= best else 'behind'} ×{max(mine, best) / max(min(mine, best), 1e-6):.1f}"


def cpu_verdict(ours: dict, engine: dict, peers: list[dict | None]) -> str:
    """Engine CPU seconds against the fastest exact peer's process CPU seconds (what a shared machine
    still compares fairly), and the process's too where either takes over a second."""
    exact = [p for p in peers if p is not None and p.get("log10") is not None]
    if not exact or not ours["exact"]:
        return "—"
    best = min(p["cpu"] for p in exact)

    def ratio(mine: float) -> str:
        return f"{'ahead' if mine <= best else 'behind'} ×{max(mine, best) / max(min(mine, best), 1e-3):.2f}"

    out = f"engine {ratio(engine['cpu'])}"
    if max(ours["cpu"], best) > 1:
        out += f", process {ratio(ours['cpu'])}"
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--linext", help="path to a linext binary (built from its source)")
    ap.add_argument("--lecount", help="path to an LEcount binary (built from its source)")
    ap.add_argument("--lecount-args", default="--quiet", help="LEcount's options (default: --quiet)")
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds per peer run (default 60)")
    ap.add_argument("--time-limit", type=float, default=60.0, help="opportune's --time-limit (default 60)")
    ap.add_argument("--epsilon", type=float, default=0.01, help="linext armc's relative error (default 0.01)")
    ap.add_argument("--delta", type=float, default=0.05, help="linext armc's failure probability (default 0.05)")
    ap.add_argument("--salbp", default="KILBRID,TONGE70,ARC111", help="SALBP graphs (comma-separated; empty: none)")
    ap.add_argument("--no-generated", action="store_true", help="skip the generated and layered graphs")
    ap.add_argument("--sizes", default="40,50,64,80,100", help="sizes n of the random sparse orders")
    ap.add_argument("--degrees", default="3,5", help="average degrees k of the random sparse orders")
    ap.add_argument("--no-armc", action="store_true", help="skip linext's estimates (armc): exact counts only")
    ap.add_argument("--json", action="store_true", help="one JSON object per order instead of the table")
    args = ap.parse_args(argv)
    for name, path in (("linext", args.linext), ("LEcount", args.lecount)):
        if path is not None and not os.access(path, os.X_OK):
            ap.error(f"--{name.lower()} {path}: not an executable file")

    load0 = os.getloadavg()[0]
    rows = []
    with tempfile.TemporaryDirectory(prefix="opportune-peers-") as tmp:
        for name, n, pairs in orders(args):
            plan, matrix = write_files(Path(tmp), name, n, pairs)
            row = {"order": name, "n": n, "pairs": len(pairs),
                   "opportune": run_opportune(plan, args.time_limit),
                   "engine": run_engine(n, pairs, args.time_limit),
                   "linext": run_linext(args.linext, matrix, "exact", args),
                   "armc": None if args.no_armc else run_linext(args.linext, matrix, "armc", args),
                   "lecount": run_lecount(args.lecount, matrix, args)}
            logs = [r["log10"] for r in (row["opportune"], row["linext"], row["lecount"])
                    if r is not None and r.get("log10") is not None and (r is not row["opportune"] or r["exact"])]
            row["agree"] = all(abs(x - logs[0]) < 1e-6 * max(1.0, abs(logs[0])) for x in logs)
            row["verdict"] = verdict(row["opportune"], row["engine"], [row["linext"], row["lecount"]])
            row["cpu_verdict"] = cpu_verdict(row["opportune"], row["engine"], [row["linext"], row["lecount"]])
            rows.append(row)
            if args.json:
                print(json.dumps(row), flush=True)
    if args.json:
        return 0
    print(f"| order | n | pairs | opportune log10 (process s) | engine s (CPU s) | linext exact | linext armc "
          f"(ε={args.epsilon:g}, δ={args.delta:g}) | LEcount | counts agree | opportune vs fastest peer | "
          f"by CPU |")
    print("|---|---:|---:|---|---:|---|---|---|---|---|---|")
    for r in rows:
        o, e = r["opportune"], r["engine"]
        ours = cell(o, exact=o["exact"]) + ("" if o["exact"] else " estimate")
        print(f"| {r['order']} | {r['n']} | {r['pairs']} | {ours} | {e['wall']:.2f} ({e['cpu']:.2f}) | "
              f"{cell(r['linext'])} | {'skipped' if args.no_armc else cell(r['armc'], exact=False)} | "
              f"{cell(r['lecount'])} | "
              f"{'yes' if r['agree'] else 'NO'} | {r['verdict']} | {r['cpu_verdict']} |")
    print(f"\n{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; load average "
          f"{load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end; opportune --time-limit "
          f"{args.time_limit:g} s, peers stopped after {args.timeout:g} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
