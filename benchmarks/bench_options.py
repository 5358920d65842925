"""The hot path of execution: options of every candidate in a state, once the memo is warm.

Target (issue 3): on the gearbox, under 20 µs per state.  Prints a table over every state
(down-set) of the gearbox and, for scale, over the states visited by random completions of KILBRID.

    python benchmarks/bench_options.py
"""

from __future__ import annotations

import random
import statistics
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from opportune import load_plan
from opportune.engine import OrderEngine, Schedule

ROOT = Path(__file__).resolve().parents[1]


def all_states(plan):
    """Every reachable schedule (installed set in some admissible order) of a small plan."""
    seen, frontier = {}, [Schedule(OrderEngine(plan))]
    engine = frontier[0].engine
    while frontier:
        s = frontier.pop()
        key = (s.mask, s.consistent)
        if key in seen:
            continue
        seen[key] = s
        frontier += [s.install(p) for p in s.installable()]
    return engine, list(seen.values())


def time_per_state(states, repeat=200, fresh=False):
    """Seconds per ``options()`` call.  ``fresh``: the counting memo is warm but the state's own
    caches (its options and counts) are cleared first, so every candidate is counted again."""
    for s in states:  # warm the memo and the per-state caches
        s.options()
    engine = states[0].engine
    best = []
    for s in states:
        t0 = time.perf_counter()
        for _ in range(repeat):
            if fresh:
                engine._options_cache.clear()
                engine._count_cache.clear()
            s.options()
        best.append((time.perf_counter() - t0) / repeat)
    return best


def main():
    console = Console()
    table = Table(title="options of every candidate in a state (warm memo)")
    for col in ("plan", "states", "state cache", "mean µs", "p95 µs", "max µs", "cold s (all states)"):
        table.add_column(col, justify="right" if col != "plan" else "left")
    gear = load_plan(ROOT / "examples/gearbox.yaml")
    t0 = time.perf_counter()
    engine, states = all_states(gear)
    for s in states:
        s.options()
    cold = time.perf_counter() - t0
    for fresh in (False, True):
        us = sorted(1e6 * t for t in time_per_state(states, fresh=fresh))
        table.add_row("gearbox", str(len(states)), "cleared" if fresh else "warm", f"{statistics.mean(us):.2f}",
                      f"{us[int(0.95 * len(us))]:.2f}", f"{us[-1]:.2f}", f"{cold:.3f}")
    kil = load_plan("salbp:KILBRID")
    engine = OrderEngine(kil)
    rng = random.Random(0)
    states = []
    t0 = time.perf_counter()
    for _ in range(20):
        s = Schedule(engine)
        while not s.is_complete:
            states.append(s)
            opts = s.options()
            s = s.install(rng.choice(list(opts)))
    cold = time.perf_counter() - t0
    for fresh in (False, True):
        us = sorted(1e6 * t for t in time_per_state(states, repeat=20, fresh=fresh))
        table.add_row("KILBRID (20 random runs)", str(len(states)), "cleared" if fresh else "warm",
                      f"{statistics.mean(us):.2f}", f"{us[int(0.95 * len(us))]:.2f}", f"{us[-1]:.2f}",
                      f"{cold:.3f}")
    console.print(table)


if __name__ == "__main__":
    main()
