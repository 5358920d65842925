"""The default policy's fallback on plans written as ways, against the optimum, where the optimum is known.

On a plan written as ways the frontier windows (which read the strategies' orders) do not serve: where its
optimum does not fit, the look-ahead decides by one step of policy improvement over the paper's rule on plans
of at most ``LOOKAHEAD_STEP_UNITS`` parts, else by the paper's rule itself.  Here, on voxel blocks of 14-20
parts derived from geometry under gravity and written as ways (``derive(..., form="ways", gravity="-z")``:
the supports are needs; the generator of
``benchmarks/bench_derive.py``), each policy's exact expected time (:class:`~opportune.policies.evaluate.
PolicyEvaluator`, the uniform bin) is divided by the optimum's: ``step`` (the look-ahead with its optimum
switched off, the step allowed on every size here), ``paper`` and ``bin-first``.

    python benchmarks/bench_ways_fallback.py                         # 2 blocks each of 14, 17, 20 parts
    python benchmarks/bench_ways_fallback.py --sizes 16 --plans 3 --settings 1x1,2x2 --gravity none
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from opportune.derive import DeriveError, derive
from opportune.engine import OrderEngine
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.lookahead import Lookahead
from opportune.policies.named import make_policy
from opportune.policies.optimal import optimal_solver
from opportune.policies.states import estimate_states

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_derive import block_for, partition, write  # noqa: E402


def ways_blocks(n: int, count: int, seed: int, max_states: int, settings, gravity: str | None) -> list:
    """``count`` voxel blocks of ``n`` parts derived as ways whose optimum holds at most ``max_states`` states in
    every setting (blocks with no admissible sequence, or too many states, are drawn again)."""
    plans, k = [], 0
    while len(plans) < count and k < 200:
        k += 1
        with tempfile.TemporaryDirectory() as tmp:
            write(Path(tmp), partition(block_for(n), n, seed * 1000 + n * 10 + k))
            try:
                plan = derive(Path(tmp), form="ways", gravity=gravity).plan
            except DeriveError:
                continue
        engine = OrderEngine(plan)
        if all(estimate_states(engine, visible=v, capacity=c, stop_above=max_states, time_limit=10.0).states
               <= max_states for v, c in settings):
            plans.append(plan)
    return plans


def stepping(visible: int, capacity) -> Lookahead:
    """The look-ahead with its optimum off, the step over the paper's rule allowed on every size."""
    policy = Lookahead(optimal=False, visible=visible, capacity=capacity)
    policy.STEP_UNITS = 64
    return policy


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="14,17,20")
    ap.add_argument("--plans", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--settings", default="1x1,2x0", help="visible x buffer locations, comma-separated")
    ap.add_argument("--max-optimum-states", type=int, default=20_000)
    ap.add_argument("--gravity", default="-z", help="derive's --gravity (supports become needs); 'none': none")
    args = ap.parse_args()
    settings = [tuple(int(x) for x in s.split("x")) for s in args.settings.split(",")]
    print("| parts | setting | plan states | optimum | step / optimum | paper / optimum | bin-first / optimum | CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    ratios: dict[str, list[float]] = {"step": [], "paper": [], "bin-first": []}
    for n in (int(x) for x in args.sizes.split(",")):
        gravity = None if args.gravity == "none" else args.gravity
        for plan in ways_blocks(n, args.plans, args.seed, args.max_optimum_states, settings, gravity):
            for visible, capacity in settings:
                start = time.process_time()
                world = dict(visible=visible, capacity=capacity)
                best_solver = optimal_solver(OrderEngine(plan), **world)
                best = best_solver.value()
                row = {"step": PolicyEvaluator(OrderEngine(plan), stepping(visible, capacity), **world).value(),
                       "paper": PolicyEvaluator(OrderEngine(plan), make_policy("paper"), **world).value(),
                       "bin-first": PolicyEvaluator(OrderEngine(plan), make_policy("bin-first"), **world).value()}
                for k, v in row.items():
                    ratios[k].append(v / best)
                print(f"| {len(plan.parts)} | {visible}x{capacity} | {best_solver.states:,} | {best:.3f} | "
                      + " | ".join(f"{row[k] / best:.4f}" for k in ("step", "paper", "bin-first"))
                      + f" | {time.process_time() - start:.1f} |", flush=True)
    for k, v in ratios.items():
        if v:
            print(f"{k}: mean ratio {statistics.mean(v):.4f}, worst {max(v):.4f} over {len(v)} plan-settings")


if __name__ == "__main__":
    main()
