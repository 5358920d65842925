"""Decisions in real time on plans written as ways: latency of the budgeted counting policies on derived blocks.

For each size (random voxel blocks from ``bench_derive.py``, derived by ``opportune derive``, written as
each part's ways in) and policy: one simulated trial (uniform bin, 2 visible, unlimited buffer, at most
``--looks`` looks) with a decision budget, timing every decision's wall clock and CPU; the load beside.

    python benchmarks/bench_ways_decisions.py                          # 30, 100, 300 parts; 4 policies
    python benchmarks/bench_ways_decisions.py --sizes 100 --policies paper --budget 0.05

Reference (2-core machine shared with other jobs; budget 0.05 s; 100 looks, 30 on 30 parts):

    parts  policy     wall p50  p95    max    | cpu p50  p95    max    | load
      30   paper      0.045   0.059  0.060   | 0.013  0.016  0.016   | 16.7
     100   paper      0.048   0.060  0.063   | 0.014  0.016  0.018   | 16.5
     300   paper      0.046   0.059  0.078   | 0.012  0.016  0.022   | 19.3
     300   slack      0.028   0.056  0.058   | 0.008  0.015  0.016   | 18.1
     100   bin-first  0.045   0.062  0.064   | 0.013  0.017  0.020   | 17.6
     100   rollout    0.044   0.057  0.064   | 0.013  0.016  0.017   | 20.5
     300   rollout    0.060   0.159  0.207   | 0.016  0.040  0.045   | 22.2

Before (the same measurement, load 12): paper on 100 parts took 1.5 s at most (p95 1.4 s).  The CPU
stays within the budget now; the wall clock passes it only by what the machine's load takes.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_derive import block_for, partition, write  # noqa: E402

from opportune.derive import derive  # noqa: E402
from opportune.engine import OrderEngine  # noqa: E402
from opportune.study.simulate import StudyConfig, TrialRunner, prepare  # noqa: E402


def block_plan(n: int, seed: int):
    with tempfile.TemporaryDirectory() as tmp:
        write(Path(tmp), partition(block_for(n), n, seed))
        return derive(Path(tmp)).plan


def row(plan, policy: str, budget: float, looks: int) -> str:
    config = StudyConfig(plan, strategies=(policy,), trials=1, seed=1, bin="uniform", visible=2,
                         decision_budget=budget, count_time_limit=1.0)
    engine = OrderEngine(plan)
    runner = TrialRunner(policy, engine, config, prepare(config, engine))
    wall, cpu = [], []
    decide = runner._decide_now

    def timed(*args):
        t, c = time.perf_counter(), time.process_time()
        out = decide(*args)
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
        return out

    runner._decide_now = timed
    runner.limit = looks
    runner.run(0)

    def pct(xs, q):
        xs = sorted(xs)
        return xs[min(len(xs) - 1, int(q * len(xs)))]

    return (f"{len(plan.parts):>5}  {policy:<9} {pct(wall, .5):.3f}   {pct(wall, .95):.3f}  {max(wall):.3f}   | "
            f"{pct(cpu, .5):.3f}  {pct(cpu, .95):.3f}  {max(cpu):.3f}   | {os.getloadavg()[0]:.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="30,100,300")
    ap.add_argument("--policies", default="paper,bin-first,slack,rollout")
    ap.add_argument("--budget", type=float, default=0.05)
    ap.add_argument("--looks", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    print("parts  policy     wall p50  p95    max    | cpu p50  p95    max    | load")
    for n in map(int, args.sizes.split(",")):
        plan = block_plan(n, args.seed)
        for policy in args.policies.split(","):
            print(row(plan, policy, args.budget, args.looks), flush=True)


if __name__ == "__main__":
    main()
