"""Benchmark of the uniform bin's exact optimum: the compiled programme, the Python one, and the default
policy deciding by it on plans past 16 units.

Part 1, ``opportune evaluate`` on a 14-part random plan (the policy lab's generator, seed 108, edge
probability 0.15; 554,769 states with 2 visible and an unlimited buffer): the whole command, timed from
outside, then the optimum alone by each programme (the compiled one, ``CompiledOptimalSolver``; the
Python one with the looks as order statistics, ``OptimalSolver``; ``--old``: the Python one enumerating
the looks, as before), with its states and bytes.

Part 2, random plans like the policy lab's of 18, 20, 25 and 30 parts (one strategy, edge probability
0.2-0.35, uniform bin; ``--seeds`` plans a size), in two settings (1 visible, 1 location; 2 visible, 2
locations): the optimum's states, bytes and CPU seconds, the default policy's exact gap to it (it decides
by the optimum wherever that fits), and slack's exact gap (what the look-ahead decided by before on plans
of more than 16 units).

    python benchmarks/bench_optimum.py                  # both parts
    python benchmarks/bench_optimum.py --part 2 --seeds 3
    python benchmarks/bench_optimum.py --part 1 --old   # and the enumerating programme (minutes)
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from opportune.engine import OrderEngine
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.lookahead import Lookahead
from opportune.engine.deadline import Deadline
from opportune.policies.optimal import CompiledOptimalSolver, OptimalSolver, OutOfTime, optimum_bytes
from opportune.policies.variants import Slack
from opportune.policies.states import estimate_states

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from policy_lab import random_plan  # noqa: E402

SIZES = (18, 20, 25, 30)
SETTINGS = ((1, 1), (2, 2))


def plan14():
    """The 14-part plan of part 1: the policy lab's generator, seed 108."""
    rng = random.Random(108)
    density = rng.choice([0.1, 0.15, 0.2, 0.25, 0.3])
    return random_plan(rng, 14, 1, density, label="s108")


def plan_file(plan, folder: str) -> str:
    parts = [p.id for p in plan.parts]
    requires = {plan.parts[a].id: [] for _, a in plan.index_pairs(plan.strategies[0])}
    for b, a in plan.index_pairs(plan.strategies[0]):
        requires[plan.parts[a].id].append(plan.parts[b].id)
    path = os.path.join(folder, f"{plan.name}.json")
    with open(path, "w") as f:
        json.dump({"name": plan.name, "parts": parts, "strategies": [{"name": "s", "requires": requires}]}, f)
    return path


def children_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def cpu() -> float:
    return time.process_time()


def solve(programme, engine, visible, capacity, reserve=0):
    solver = programme(engine, visible=visible, capacity=capacity, max_states=10_000_000)
    solver.reserve(reserve)
    t0, c0 = time.perf_counter(), cpu()
    value = solver.value()
    return value, solver.states, getattr(solver, "bytes", None), time.perf_counter() - t0, cpu() - c0


def part1(old: bool) -> None:
    plan = plan14()
    engine = OrderEngine(plan)
    est = estimate_states(engine, visible=2, capacity=None, time_limit=30)
    print(f"## 1. {plan.name}: 14 parts, 2 visible, unlimited buffer ({est.describe()} states)\n")
    with tempfile.TemporaryDirectory() as folder:
        path = plan_file(plan, folder)
        t0, kids = time.perf_counter(), children_cpu()
        out = subprocess.run([sys.executable, "-m", "opportune", "evaluate", path, "--visible", "2", "--json",
                              "--max-states", "2000000"], capture_output=True, text=True)
        wall, used = time.perf_counter() - t0, children_cpu() - kids
    if out.returncode:
        print(out.stdout, out.stderr)
        return
    doc = json.loads(out.stdout)
    print("| what | value | states | bytes | wall s | CPU s |\n| --- | --- | --- | --- | --- | --- |")
    print(f"| `opportune evaluate` (lookahead and optimum), whole command | {doc['optimal']:.6f} | "
          f"{doc['states']:,} | | {wall:.1f} | {used:.1f} |")
    rows = [("compiled optimum (`CompiledOptimalSolver`)", CompiledOptimalSolver, est.states),
            ("Python optimum, looks as order statistics", OptimalSolver, 0)]
    for name, programme, reserve in rows:
        value, states, nbytes, wall, used = solve(programme, engine, 2, None, reserve)
        shown = f"{nbytes:,}" if nbytes is not None else f"~{states * 1000:,} (estimate)"
        print(f"| {name} | {value:.6f} | {states:,} | {shown} | {wall:.2f} | {used:.2f} |")
    if old:
        solver = OptimalSolver(engine, visible=2, capacity=None, max_states=10_000_000)
        solver.uniform = False
        t0, c0 = time.perf_counter(), cpu()
        value = solver.value()
        print(f"| Python optimum, every look enumerated (before) | {value:.6f} | {solver.states:,} | | "
              f"{time.perf_counter() - t0:.1f} | {cpu() - c0:.1f} |")
    print(f"\nbytes known before (`optimum_bytes`): {optimum_bytes(est.states, est.keys, compiled=True):,}\n")


def part2(seeds: int, seconds: float) -> None:
    print("## 2. Random plans past 16 units: the default policy against the optimum\n")
    print("| plan | parts | density | setting | states | bytes | optimum s (CPU) | optimum | lookahead gap | "
          "decides by | slack gap (before, past 16 units) |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for n in SIZES:
        for seed in range(seeds):
            rng = random.Random(1000 * n + seed)
            density = rng.uniform(0.2, 0.35)
            plan = random_plan(rng, n, 1, density, label=f"b{n}-{seed}")
            engine = OrderEngine(plan)
            for visible, capacity in SETTINGS:
                row(plan, engine, density, visible, capacity, seconds)


def row(plan, engine, density, visible, capacity, seconds: float) -> None:
    setting = f"{visible} visible, {capacity} location{'s' if capacity > 1 else ''}"
    head = f"| {plan.name} | {len(plan.parts)} | {density:.2f} | {setting} |"
    est = estimate_states(engine, visible=visible, capacity=capacity, stop_above=Lookahead.COMPILED_STATES,
                          time_limit=10)
    if not est.exact or est.states > Lookahead.COMPILED_STATES:
        print(f"{head} {est.describe()} | | | | over the cap | | |")
        return
    value, states, nbytes, _, used = solve(CompiledOptimalSolver, engine, visible, capacity, est.states)
    ahead = Lookahead(visible=visible, capacity=capacity)
    # the look-ahead's value: the optimum's where it decides by it (tests/test_optimal_compiled.py checks
    # that against its look-by-look evaluation), else evaluated look by look
    ev = PolicyEvaluator(engine, ahead, visible=visible, capacity=capacity, max_states=10_000_000)
    gap = ev.value() / value - 1
    source = "optimum" if ev.by_optimum else "step over slack"
    slack = PolicyEvaluator(engine, Slack(), visible=visible, capacity=capacity, max_states=10_000_000)
    slack.deadline = Deadline.after(seconds)
    try:
        before = f"{100 * (slack.value() / value - 1):+.2f}%"
    except OutOfTime:
        before = f"(over {seconds:g} s)"
    print(f"{head} {states:,} | {nbytes:,} | {used:.2f} | {value:.4f} | {100 * gap:+.4f}% | {source} | {before} |",
          flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", type=int, choices=(1, 2), help="only this part")
    ap.add_argument("--seeds", type=int, default=2, help="plans per size in part 2")
    ap.add_argument("--slack-seconds", type=float, default=300.0, help="seconds for slack's exact value, per row")
    ap.add_argument("--old", action="store_true", help="also the Python programme enumerating the looks (minutes)")
    args = ap.parse_args(argv)
    print(f"load: {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} cores\n")
    if args.part in (None, 1):
        part1(args.old)
    if args.part in (None, 2):
        part2(args.seeds, args.slack_seconds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
