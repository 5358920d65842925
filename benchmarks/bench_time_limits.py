"""Does ``opportune count --time-limit T`` keep T plus its margin on every order, and is an exact count
never slower with a longer limit?

Runs the whole command (a fresh process, as a user runs it: Python's start-up, reading the plan, the
count, writing the answer and ending) on each order at each limit and prints a table: the process's
wall time and how far past T it ended, its CPU time (user + system, all threads: relaxation Monte Carlo
draws on every core, so CPU may exceed wall), and the answer.  The limit's promise is T plus
``COUNT_MARGIN`` (0.25 s) from the command's start; the wall time here includes Python's start-up
before it (about 0.1–0.2 s: the "start" row, a 6-element plan).  The load average is printed at the
start and the end of each row's run: on a loaded machine the wall time stretches, not the CPU time.

Orders: the two sub-DAGs of the ``pigs`` Bayesian network in ``tests/data`` (128 and 100 nodes),
SALBP's ARC111 and TONGE70, and generated assembly-like graphs (``gen_precedence.py``, seed 1: 300
tasks of order strength 0.2 and 0.6, 1,000 tasks of 0.6), unless ``--orders`` names others.

    python benchmarks/bench_time_limits.py [--limits 0.5 1 3 10] [--orders FILE_OR_NAME ...] [--threads 0]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

from gen_precedence import _write, file_name  # noqa: E402  (a sibling script)


def default_orders(tmp: Path) -> list[str]:
    """The orders named in the module's docstring (the generated ones written into ``tmp``)."""
    out = [str(ROOT / "tests" / "data" / "bn_pigs_n128.IN2"), str(ROOT / "tests" / "data" / "bn_pigs_n100.IN2"),
           "salbp:ARC111", "salbp:TONGE70"]
    for n, strength in ((300, 0.2), (300, 0.6), (1000, 0.6)):
        path = tmp / file_name(n, strength)
        with contextlib.redirect_stdout(io.StringIO()):     # (it says what it wrote)
            _write(path, n, strength, "mixed", 1, "bottom")
        out.append(str(path))
    return out


def run(order: str, limit: float | None, threads: int) -> dict:
    """One ``opportune count ORDER --time-limit LIMIT --json`` (``limit`` None: the "start" row's
    6-element plan with the default limit): wall and CPU seconds, the answer, the load before and after."""
    code = "import sys\nsys.argv = ['opportune', *sys.argv[1:]]\nfrom opportune.launch import main\nmain()\n"
    args = ["count", order, "--json", "--threads", str(threads)]
    if limit is not None:
        args += ["--time-limit", str(limit)]
    load = os.getloadavg()[0]
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    out, err = proc.communicate()
    wall = time.perf_counter() - start
    try:
        doc = json.loads(out)
    except ValueError:
        doc = {"error": (err or out).strip()[-200:]}
    return {"wall": wall, "doc": doc, "load": (load, os.getloadavg()[0])}


def cpu_of(order: str, limit: float | None, threads: int) -> tuple[dict, float]:
    """:func:`run` and the CPU seconds (user + system) of its process, from the children's totals."""
    before = os.times()
    row = run(order, limit, threads)
    after = os.times()
    return row, (after.children_user - before.children_user) + (after.children_system - before.children_system)


def answer(doc: dict) -> str:
    if "error" in doc:
        return "error: " + str(doc["error"])
    if doc.get("exact"):
        return f"exact (log10 {doc['log10']:.3f})"
    rel = doc.get("rel_error")
    return f"{doc.get('method')} ±{100 * rel:.1f}%" if rel is not None else f"{doc.get('method')} (no error stated)"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--limits", type=float, nargs="+", default=[0.5, 1.0, 3.0, 10.0])
    ap.add_argument("--orders", nargs="+", help="plan files or shipped names (default: see the docstring)")
    ap.add_argument("--threads", type=int, default=0, help="--threads of the command (0: one per core)")
    args = ap.parse_args(argv)
    margin = 0.25
    with tempfile.TemporaryDirectory() as tmp:
        orders = args.orders or default_orders(Path(tmp))
        row, cpu = cpu_of("example:gearbox", None, args.threads)
        print(f"start (6-element plan): wall {row['wall']:.2f} s, CPU {cpu:.2f} s, load {row['load'][0]:.2f}")
        print()
        print("| order | limit s | wall s | past limit s | CPU s | answer | load (start → end) |")
        print("|---|---:|---:|---:|---:|---|---|")
        worst = -1e9
        for order in orders:
            exact_at: list[tuple[float, float]] = []
            for limit in args.limits:
                row, cpu = cpu_of(order, limit, args.threads)
                past = row["wall"] - limit
                worst = max(worst, past)
                name = Path(order).stem if "/" in order else order
                print(f"| {name} | {limit:g} | {row['wall']:.2f} | {past:+.2f} | {cpu:.2f} | {answer(row['doc'])} "
                      f"| {row['load'][0]:.2f} → {row['load'][1]:.2f} |", flush=True)
                if row["doc"].get("exact"):
                    exact_at.append((limit, row["wall"]))
            slower = [(a, b) for (la, a), (lb, b) in zip(exact_at, exact_at[1:]) if b > a + 0.2]
            if slower:
                print(f"|   ↳ exact count slower with a longer limit: {slower} | | | | | | |")
        print()
        print(f"most past the limit: {worst:+.2f} s (the promise: +{margin} s after Python's start-up)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
