"""Simulation speed: trials per second per strategy, on the gearbox and on KILBRID (45 tasks).

Not a test: prints a table.  Targets (2-core machine): opportunistic on the gearbox ≥ 20,000
trials/s with both cores; KILBRID ≥ 500 trials/s; the optimum of the gearbox solved in < 30 s.

    python benchmarks/bench_simulate.py [--trials N] [--workers W] [--only gearbox|kilbrid]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from opportune import load_plan
from opportune.study.simulate import STRATEGIES, StudyConfig, prepare, run_study

ROOT = Path(__file__).resolve().parents[1]


def measure(plan, strategies, trials, workers, table, label):
    for strategy in strategies:
        config = StudyConfig(plan=plan, strategies=(strategy,), trials=trials, seed=0)
        t0 = time.perf_counter()
        prepared = prepare(config)
        prep = time.perf_counter() - t0
        t0 = time.perf_counter()
        result = run_study(config, workers=workers, prepared=prepared)
        run = time.perf_counter() - t0
        times = [t.time for t in result.trials[strategy]]
        table.add_row(label, strategy, f"{trials:,}", str(workers), f"{prep:.2f}", f"{run:.2f}",
                      f"{trials / run:,.0f}", f"{sum(times) / len(times):.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", choices=["gearbox", "kilbrid"], default=None)
    args = ap.parse_args()
    console = Console()
    console.print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
                  f"Python {platform.python_version()}")
    table = Table(title="simulation speed")
    for col in ("plan", "strategy", "trials", "workers", "prepare s", "run s", "trials/s", "mean time"):
        table.add_column(col, justify="right" if col not in ("plan", "strategy") else "left")
    if args.only in (None, "gearbox"):
        gear = load_plan(ROOT / "examples/gearbox.yaml")
        measure(gear, STRATEGIES, args.trials or 20_000, args.workers, table, "gearbox")
    if args.only in (None, "kilbrid"):
        kil = load_plan("salbp:KILBRID")
        strategies = [s for s in STRATEGIES if s != "optimal"]  # the optimum's state space is far too large
        measure(kil, strategies, args.trials or 2_000, args.workers, table, "KILBRID")
    console.print(table)


if __name__ == "__main__":
    main()
