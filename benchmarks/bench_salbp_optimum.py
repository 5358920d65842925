"""Benchmark: the exact optimum on real precedence graphs with few buffer locations, or its wall.

KILBRID (45 tasks), TONGE70 (70) and ARC111 (111), uniform bin, 1-3 visible parts, 1 and 2 buffer
locations: per setting, the optimum's states (listed before the work by ``estimate_states`` on the plan
with its interchangeable parts merged, and on the plan as declared), the bytes the compiled programme
holds for them (``optimum_bytes``), and either the optimum (computed by ``optimal_solver``, within a
deadline and the bytes the plan's engine grants) or the wall: the states and bytes it would need
("at least" where the listing stopped).  A plan past 64 units is outside the compiled programme (64-bit
sets); its wall is the listing's figure all the same.

Prints a Markdown table (the one in docs/decisions.md); wall and CPU seconds beside each attempt.
``--random N``: instead, the state reduction by merging on N random plans a size like the policy lab's
(16, 20, 25 and 30 parts, edge probability 0.2-0.35, one or two strategies, seeded), 2 visible and 2
locations: how many plans have parts to merge, and the states as declared over the states merged.

    python benchmarks/bench_salbp_optimum.py                       # every plan and setting
    python benchmarks/bench_salbp_optimum.py --plans KILBRID --seconds 60
    python benchmarks/bench_salbp_optimum.py --random 20
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import time
from pathlib import Path

from opportune import load_plan
from opportune.engine import OrderEngine
from opportune.engine.deadline import Deadline
from opportune.policies.interchangeable import merge_interchangeable
from opportune.policies.optimal import (
    OptimalTooLarge,
    OutOfTime,
    compiled_optimal_available,
    optimal_solver,
    optimum_bytes,
)
from opportune.policies.states import big, estimate_states

PLANS = ("KILBRID", "TONGE70", "ARC111")
VISIBLE = (1, 2, 3)
LOCATIONS = (1, 2)


def count(est) -> str:
    """A state count in the table: exact, or "≥ proven (~estimated)"."""
    if est.exact:
        return f"{est.states:,}"
    return f"≥ {big(est.low)}" + (f" (~{big(est.states)})" if est.states > est.low else "")


def attempt(engine, merged, visible: int, locations: int, seconds: float, sizes) -> dict:
    """One setting: its sizes (``sizes``: the counts on the merged plan and as declared, which do not
    depend on the visible parts in a Markov bin), and the optimum where it fits (by the engine's grant and
    the time)."""
    est, plain = sizes
    need = optimum_bytes(est.states, est.keys, compiled=True)
    row = dict(states=count(est), plain=count(plain), bytes=big(need), value=None, seconds="")
    units = "" if compiled_optimal_available(merged.engine) else f"; {engine.n_units} units, over the compiled 64"
    if not est.exact:
        # the keys listed before the listing stopped: a lower bound on the pairs as on the states
        least = optimum_bytes(est.low, min(est.keys, est.low), compiled=True)
        row["bytes"] = f"≥ {big(least)} (~{big(need)})"
        row["value"] = f"wall: ≥ {big(est.low)} states, ≥ {big(least)} bytes{units}"
        return row
    if units:
        row["value"] = f"wall: {big(est.states)} states{units}"
        return row
    if not engine.reserve_programme(("bench", visible, locations), need):
        row["value"] = f"wall: {big(est.states)} states, {big(need)} bytes (over the plan's memory share)"
        return row
    solver = optimal_solver(engine, visible=visible, capacity=locations, max_states=est.states + 1)
    solver.reserve(est.states)
    solver.deadline = Deadline.after(seconds)
    wall, cpu = time.perf_counter(), time.process_time()
    try:
        row["value"] = f"{solver.value():.6f}"
    except OutOfTime:
        row["value"] = f"wall: {big(est.states)} states, {big(need)} bytes (past {seconds:.0f} s at {big(solver.states)})"
    except OptimalTooLarge:
        row["value"] = f"wall: over {big(est.states)} states"
    row["seconds"] = f"{time.perf_counter() - wall:.1f} ({time.process_time() - cpu:.1f} CPU)"
    engine.programmes.pop(("bench", visible, locations), None)
    return row


def reduction(plans: int) -> None:
    """The state reduction by merging on random plans like the policy lab's (see the module's docstring)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from policy_lab import random_plan

    print("| parts | strategies | plans | with parts merged | states as declared / merged: median | max |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: |")
    for n in (16, 20, 25, 30):
        for strategies in (1, 2):
            ratios, reduced = [], 0
            for seed in range(plans):
                rng = random.Random(1000 * n + 100 * strategies + seed)
                engine = OrderEngine(random_plan(rng, n, strategies, rng.uniform(0.2, 0.35)))
                merged = merge_interchangeable(engine)
                reduced += merged.reduced
                plain = estimate_states(engine, visible=2, capacity=2, time_limit=5)
                fewer = estimate_states(merged.engine, visible=2, capacity=2, time_limit=5)
                if plain.exact and fewer.exact:
                    ratios.append(plain.states / fewer.states)
            print(f"| {n} | {strategies} | {plans} | {reduced} | {statistics.median(ratios):.2f} ({len(ratios)} counted) "
                  f"| {max(ratios):.2f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plans", nargs="+", default=list(PLANS))
    ap.add_argument("--visible", nargs="+", type=int, default=list(VISIBLE))
    ap.add_argument("--locations", nargs="+", type=int, default=list(LOCATIONS))
    ap.add_argument("--seconds", type=float, default=600.0, help="deadline of each optimum (default 600)")
    ap.add_argument("--listing", type=float, default=60.0, help="seconds for each state count (default 60)")
    ap.add_argument("--random", type=int, metavar="N", help="the state reduction on N random plans a size instead")
    args = ap.parse_args()
    print(f"load: {os.getloadavg()[0]:.1f} (1 min), {os.cpu_count()} cores\n")
    if args.random:
        reduction(args.random)
        return
    print("| plan | visible | locations | states (merged) | states (as declared) | bytes | optimum | seconds |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | --- | ---: |")
    for name in args.plans:
        plan = load_plan(f"salbp:{name}")
        engine = OrderEngine(plan)
        merged = merge_interchangeable(engine)
        label = f"{name} ({len(plan.parts)} parts, {len(merged.groups)} merged)"
        for locations in args.locations:
            # a Markov bin's states do not depend on the visible parts: counted once per location count
            sizes = tuple(estimate_states(e, capacity=locations, time_limit=args.listing) for e in (merged.engine, engine))
            for visible in args.visible:
                r = attempt(engine, merged, visible, locations, args.seconds, sizes)
                print(f"| {label} | {visible} | {locations} | {r['states']} | {r['plain']} | {r['bytes']} | "
                      f"{r['value']} | {r['seconds']} |", flush=True)


if __name__ == "__main__":
    main()
