"""A long-running cell: decision latency with one order engine reused for assembly after assembly.

A cell that runs for hours keeps one engine per plan (as the service does): its memos and per-state
caches grow with every assembly, and are trimmed when they reach their caps.  This prints, for a
reused engine and for a fresh engine per assembly, the decisions taken in ``--seconds`` of
simulated assemblies (uniform bin, ``--visible`` parts per look, unlimited buffer, every action
succeeding), their wall and CPU time per decision (p50, p95, max, in ms), how many took longer
than the budget (wall, and CPU), and the engine maintenance done between looks.

    python benchmarks/bench_long_run.py                                   # ARC111, 90 s each, 50 ms
    python benchmarks/bench_long_run.py --plan salbp:KILBRID --seconds 30 --budget 0.02
    python benchmarks/bench_long_run.py --modes reused --seconds 600
    python benchmarks/bench_long_run.py --modes reused,inline       # upkeep held back vs inside decisions

Modes: ``reused`` (one engine; memo upkeep between looks, as the sequencer does it), ``fresh`` (an
engine per assembly), ``inline`` (one engine, but with the upkeep done where a cap is reached,
inside decisions: what the engine did before ``OrderEngine.deciding``; for comparison).

Wall time depends on what else runs on the machine; CPU time much less: a decision over budget in
CPU time is the program's doing.  CPU time is the deciding thread's (``time.thread_time``; the
compiled core runs on it): the process's also counts memory freed on a thread of its own while the
decision runs (a 512 MB tail memo of the compiled core), which takes no time from the decision.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import random
import time

from opportune import load_plan
from opportune.engine import OrderEngine
from opportune.policies.opportunistic import Opportunistic
from opportune.sequencer import Sequencer


def percentile(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))] if xs else float("nan")


def run(plan, mode: str, seconds: float, budget: float, visible: int, seed: int) -> dict:
    """Assemblies until ``seconds`` of wall time have passed; every decision's (wall, cpu)."""
    rng = random.Random(seed)
    if mode not in ("reused", "fresh", "inline"):
        raise SystemExit(f"unknown mode {mode!r}: use reused, fresh or inline")
    engine = OrderEngine(plan) if mode != "fresh" else None
    if mode == "inline":        # no hold during decisions, no upkeep between them
        engine.deciding = contextlib.nullcontext
        engine.maintain = lambda: False
    walls, cpus, assemblies = [], [], 0
    maintenance = [0, 0.0]       # maintenance calls, seconds spent in them (between looks)
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        e = engine if engine is not None else OrderEngine(plan)
        seq = Sequencer(e, Opportunistic(budget=budget, seed=rng.randrange(1 << 30)), budget=budget)
        while not seq.state.is_complete and time.perf_counter() < end:
            in_bin = [p for p, n in seq.state.in_bin.items() for _ in range(n)]
            look = tuple(rng.sample(in_bin, min(visible, len(in_bin))))
            w, c = time.perf_counter(), time.thread_time()
            seq.decide(look)
            walls.append(time.perf_counter() - w)
            cpus.append(time.thread_time() - c)
            before = getattr(e, "maintained", None)
            w = time.perf_counter()
            seq.report("success")
            if before is not None and e.maintained != before:
                maintenance[0] += 1
                maintenance[1] += time.perf_counter() - w
        assemblies += seq.state.is_complete
    ms = [1000 * x for x in walls]
    cms = [1000 * x for x in cpus]
    return {"mode": mode, "assemblies": assemblies, "decisions": len(walls),
            "wall p50": percentile(ms, 0.5), "wall p95": percentile(ms, 0.95), "wall max": max(ms, default=0),
            "cpu p50": percentile(cms, 0.5), "cpu p95": percentile(cms, 0.95), "cpu max": max(cms, default=0),
            "over (wall)": sum(x > budget for x in walls), "over (cpu)": sum(x > budget for x in cpus),
            "maintenance": maintenance[0], "maintenance s": maintenance[1]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--plan", default="salbp:ARC111", help="plan (file or salbp:NAME; default salbp:ARC111)")
    ap.add_argument("--seconds", type=float, default=90.0, help="seconds of assemblies per mode (default 90)")
    ap.add_argument("--budget", type=float, default=0.05, help="seconds per decision (default 0.05)")
    ap.add_argument("--visible", type=int, default=2, help="parts seen per look (default 2)")
    ap.add_argument("--modes", default="reused,fresh", help="reused, fresh or both (default reused,fresh)")
    ap.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    args = ap.parse_args(argv)
    plan = load_plan(args.plan)
    print(f"{args.plan}: {plan.n_units} units, budget {1000 * args.budget:.0f} ms, {args.seconds:g} s per mode; "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
    cols = ["mode", "assemblies", "decisions", "wall p50", "wall p95", "wall max", "cpu p50", "cpu p95", "cpu max",
            "over (wall)", "over (cpu)", "maintenance", "maintenance s"]
    print("  ".join(f"{c:>12}" for c in cols))
    for mode in args.modes.split(","):
        row = run(plan, mode.strip(), args.seconds, args.budget, args.visible, args.seed)
        print("  ".join(f"{row[c]:>12.1f}" if isinstance(row[c], float) else f"{row[c]:>12}" for c in cols), flush=True)
    print("times in ms per decision; 'over': decisions longer than the budget; maintenance: between looks")


if __name__ == "__main__":
    main()
