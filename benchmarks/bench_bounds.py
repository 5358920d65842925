"""How far is the default policy from the best any online policy can do on large plans?  The certified lower
bound of :mod:`opportune.study.bounds` beside the default policy's mean, on KILBRID, TONGE70 and ARC111.

Not a test: prints the table of docs/lower-bounds.md (markdown): per plan and number of visible parts, the
default policy's (``lookahead``) mean time with its 95% interval (``simulate``'s defaults: uniform bin,
unlimited buffer, seed 0), the bound with its 95% interval, the gap (the policy's mean over the bound,
less one: how far above the optimum the policy can be at most, up to Monte Carlo error) and the CPU
seconds of each.

    python benchmarks/bench_bounds.py [--plans salbp:KILBRID,salbp:TONGE70,salbp:ARC111] [--visible 2,1]
                                      [--trials 200] [--bound-trials 100] [--nodes 5000] [--penalty auto]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

from opportune import load_plan
from opportune.study.report import summary
from opportune.study.simulate import StrategyUnavailable, StudyConfig, prepare, run_study
from opportune.study.bounds import PENALTIES, lower_bound


def policy_mean(plan, visible: int, trials: int) -> tuple[float, float, float, str]:
    """The default policy's mean time, half-width of its 95% interval, CPU seconds, and how it decided
    (as ``simulate`` does: within 50 ms per decision where the first exact counts take too long)."""
    config = StudyConfig(plan, strategies=("lookahead",), trials=trials, seed=0, visible=visible)
    how = "exact"
    try:
        prepare(config)
    except StrategyUnavailable:
        from opportune.sequencer import DEFAULT_BUDGET

        config = replace(config, decision_budget=DEFAULT_BUDGET)
        how = f"{1000 * DEFAULT_BUDGET:g} ms per decision"
    cpu = time.process_time()
    result = run_study(config, workers=1)
    t = summary(result)["strategies"]["lookahead"]["time"]
    low, high = t["ci95"]
    return t["mean"], (high - low) / 2, time.process_time() - cpu, how


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", default="salbp:KILBRID,salbp:TONGE70,salbp:ARC111")
    ap.add_argument("--visible", default="2,1", help="parts visible per look, comma-separated")
    ap.add_argument("--trials", type=int, default=200, help="trials of the default policy")
    ap.add_argument("--bound-trials", type=int, default=100, help="trials (bins) of the bound")
    ap.add_argument("--nodes", type=int, default=5_000, help="nodes of one trial's inner search, at most")
    ap.add_argument("--penalty", default="auto", choices=PENALTIES)
    args = ap.parse_args(argv)
    print(f"uniform bin, unlimited buffer, seed 0; the policy on {args.trials} bins, the bound on "
          f"{args.bound_trials} ('{args.penalty}' penalty, at most {args.nodes:,} nodes per bin); CPU seconds\n")
    print("| plan | visible | default policy | lower bound | gap | exact inner | policy s | bound s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for spec in args.plans.split(","):
        plan = load_plan(spec)
        for visible in (int(v) for v in args.visible.split(",")):
            mean, half, secs, how = policy_mean(plan, visible, args.trials)
            cpu = time.process_time()
            b = lower_bound(plan, visible=visible, trials=args.bound_trials, seed=0, penalty=args.penalty,
                            node_budget=args.nodes)
            bsecs = time.process_time() - cpu
            note = "" if how == "exact" else f" ({how})"
            print(f"| {plan.name} ({plan.n_units}) | {visible} | {mean:.2f} ± {half:.2f}{note} | "
                  f"{b.mean:.2f} ± {b.half_width:.2f} | {100 * (mean / b.mean - 1):+.1f}% | "
                  f"{b.exact_trials}/{b.trials} | {secs:.0f} | {bsecs:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
