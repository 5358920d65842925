"""The speed and memory of each programme ``opportune evaluate`` runs: the figures its refusal quotes and
its default caps are made of (``EVALUATE_*`` in src/opportune/engine/tuning.py).

Each row runs one programme on one plan and setting in a child process, stopped after ``--seconds``
(wall clock; its states so far still give its rate): the states it stored, its CPU seconds, states per CPU
second, and its peak resident memory less a child's that built the same engine and stopped there (bytes
per state; the compiled programmes also say their own bytes).  Programmes: the compiled optimum (uniform,
weighted, pile bin; on the plan with its interchangeable parts merged, as the command solves it), the
Python optimum (no compiled core), and a policy's own evaluation in Python (the
paper's rule; the look-ahead with its optimum switched off, which decides by its frontier window; the
rollout, which decides by an exact look-ahead on plans of up to 16 parts).

    python benchmarks/bench_evaluate_rates.py                 # every row, 20 s each at most
    python benchmarks/bench_evaluate_rates.py --rows 0 1 --seconds 10
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: (label, plan, bin, visible, capacity, programme)
ROWS = (
    ("KILBRID", "salbp:KILBRID", "uniform", 1, 1, "compiled optimum"),
    ("KILBRID", "salbp:KILBRID", "uniform", 2, 1, "compiled optimum"),
    ("s108 (14 parts)", "plan14", "uniform", 2, None, "compiled optimum"),
    ("s108 (14 parts)", "plan14", "weighted", 2, 1, "compiled optimum"),
    ("s108 (14 parts)", "plan14", "pile", 2, 1, "compiled optimum"),
    ("KILBRID", "salbp:KILBRID", "weighted", 1, 1, "compiled optimum"),
    ("s108 (14 parts)", "plan14", "uniform", 2, None, "Python optimum"),
    ("KILBRID", "salbp:KILBRID", "pile", 1, 1, "Python optimum"),
    ("s108 (14 parts)", "plan14", "uniform", 2, None, "paper, in Python"),
    ("KILBRID", "salbp:KILBRID", "uniform", 1, 1, "paper, in Python"),
    ("KILBRID", "salbp:KILBRID", "pile", 1, 1, "paper, in Python"),
    ("s108 (14 parts)", "plan14", "uniform", 2, None, "lookahead without optimum, in Python"),
    ("s108 (14 parts)", "plan14", "pile", 2, 1, "lookahead without optimum, in Python"),
    ("s108 (14 parts)", "plan14", "weighted", 2, 1, "Python optimum"),
    ("s108 (14 parts)", "plan14", "uniform", 2, None, "rollout, in Python"),
)


def load(name: str):
    from opportune import load_plan

    if name == "plan14":
        from bench_optimum import plan14

        return plan14()
    return load_plan(name)


def programme(engine, bin: str, visible: int, capacity, what: str):
    """The programme of a row, as ``opportune evaluate`` makes it, and how to read its states."""
    from opportune.policies.evaluate import PolicyEvaluator
    from opportune.policies.lookahead import Lookahead
    from opportune.policies.opportunistic import Opportunistic
    from opportune.policies.optimal import OptimalSolver, optimal_solver
    from opportune.policies.pile import PileSolver, pile_solver

    settings = dict(visible=visible, capacity=capacity, max_states=50_000_000)
    weights = {p.id: 1.0 + (i % 3) for i, p in enumerate(engine.plan.parts)} if bin == "weighted" else None
    if what == "compiled optimum":
        if bin == "pile":
            return pile_solver(engine, **settings), "states"
        return optimal_solver(engine, weights=weights, **settings), "states"
    if what == "Python optimum":
        if bin == "pile":
            return PileSolver(engine, **settings), "states"
        return OptimalSolver(engine, weights=weights, **settings), "states"
    if what.startswith("rollout"):
        from opportune.policies.named import make_policy

        policy = make_policy("rollout", visible=visible, capacity=capacity, bin=bin, weights=weights)
    else:
        policy = (Opportunistic() if what.startswith("paper") else
                  Lookahead(optimal=False, bin=bin, weights=weights, visible=visible, capacity=capacity))
    if bin == "pile":
        return PileSolver(engine, policy, **settings), "states"
    return PolicyEvaluator(engine, policy, weights=weights, **settings), "policy_states"


def one(row: int, seconds: float, build_only: bool) -> dict:
    """A row's measures, in this process."""
    from opportune.engine import OrderEngine
    from opportune.engine.deadline import Deadline
    from opportune.policies.optimal import OutOfTime

    label, name, bin, visible, capacity, what = ROWS[row]
    engine = OrderEngine(load(name))
    solver, counted = programme(engine, bin, visible, capacity, what)
    if build_only:
        return {"rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}
    solver.deadline = Deadline.after(seconds)
    c0 = time.process_time()
    finished = True
    try:
        solver.value()
    except OutOfTime:
        finished = False
    cpu = time.process_time() - c0
    return {"states": getattr(solver, counted), "cpu": cpu, "finished": finished,
            "rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
            "own_bytes": getattr(solver, "bytes", None)}


def child(row: int, seconds: float, build_only: bool = False) -> dict:
    args = [sys.executable, __file__, "--one", str(row), "--seconds", str(seconds)] + ["--build-only"] * build_only
    out = subprocess.run(args, capture_output=True, text=True)
    if out.returncode:
        return {"error": out.stderr.strip().splitlines()[-1:]}
    return json.loads(out.stdout)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, nargs="*", help="only these rows (0-based)")
    ap.add_argument("--seconds", type=float, default=20.0, help="wall-clock seconds a row may run")
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--build-only", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one is not None:
        print(json.dumps(one(args.one, args.seconds, args.build_only)))
        return 0
    print(f"load: {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} cores\n")
    print("| plan | bin | visible | buffer | programme | states | finished | CPU s | states/CPU s | "
          "bytes/state (RSS) | bytes/state (own) |\n" + "| --- " * 11 + "|")
    for i in (args.rows if args.rows is not None else range(len(ROWS))):
        label, _, bin, visible, capacity, what = ROWS[i]
        r, base = child(i, args.seconds), child(i, args.seconds, build_only=True)
        head = f"| {label} | {bin} | {visible} | {'unlimited' if capacity is None else capacity} | {what} |"
        if "error" in r or "error" in base:
            print(f"{head} {r.get('error') or base.get('error')} |", flush=True)
            continue
        n = max(1, r["states"])
        own = f"{r['own_bytes'] / n:.0f}" if r["own_bytes"] else ""
        print(f"{head} {r['states']:,} | {'yes' if r['finished'] else 'no'} | {r['cpu']:.2f} | "
              f"{r['states'] / max(r['cpu'], 1e-9):,.0f} | {(r['rss'] - base['rss']) / n:.0f} | {own} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
