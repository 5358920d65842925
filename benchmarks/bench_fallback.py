"""The default policy's fallback against the optimum on plans of 16-30 parts, where the optimum is known,
and its decisions' CPU time on plans too large for the optimum.

The look-ahead decides by the exact optimum wherever its programme fits; elsewhere by its fallback: in a
uniform bin the exact optimum of a frontier window, the rest of the plan lumped
(:class:`~opportune.policies.window.FrontierWindow`).  Here its exact optimum is switched off
(``Lookahead(optimal=False)``, the lab's ``fallback``, ``evaluate --without-optimum``) on random plans built
by the policy lab's generator (one strategy, edge probability 0.2-0.35, seeded), whose optimum's programme
holds at most ``--max-optimum-states`` states (counted first; plans over it are drawn again), and each
policy's exact expected time is divided by the optimum's, in the uniform bin:

    python benchmarks/bench_fallback.py                         # 3 plans each of 16, 20, 25, 30 parts
    python benchmarks/bench_fallback.py --sizes 20 --plans 5 --policies fallback,paper --settings 1x1,2x2

With ``--decisions``, the default's decisions along one seeded run of each plan named (its optimum does
not fit there), with its CPU and wall time per decision and the window's counted work:

    python benchmarks/bench_fallback.py --decisions salbp:KILBRID,salbp:TONGE70,salbp:ARC111 --settings 1x1,2x2,3x2
    python benchmarks/bench_fallback.py --decisions salbp:ARC111 --settings 2x2 --budget 0.05
    python benchmarks/bench_fallback.py --decisions salbp:KILBRID --settings 1x1,2x2,3x2 --bin pile

``--bin pile``: the same in the pile bin, whose fallback is the pile's frontier window
(:class:`~opportune.policies.pile_window.PileWindow`); a run's looks are then drawn from the bin, not kept
on a pile's top (the CPU per decision, not the gap, is what that mode measures).  ``--bin weighted`` (with
``--decisions``): a weighted bin, part ``i`` of weight 1 + i mod 3, whose fallback is the weighted window
(:class:`~opportune.policies.weighted_window.WeightedWindow`).
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import time
from pathlib import Path

from opportune import load_plan
from opportune.engine import OrderEngine
from opportune.policies.lookahead import Lookahead
from opportune.policies.states import estimate_states

sys.path.insert(0, str(Path(__file__).resolve().parent))
from policy_lab import POLICIES, gaps, random_plan  # noqa: E402

SETTINGS = ((1, 1), (2, 2), (3, 2))      # (visible, buffer locations)


def _locations(capacity) -> str:
    """Buffer locations in words (None: an unlimited buffer)."""
    return "unlimited buffer" if capacity is None else f"{capacity} location{'s' * (capacity != 1)}"


def draw_plans(n: int, count: int, seed: int, max_states: int, settings=SETTINGS, strategies: int = 1) -> list:
    """``count`` plans of ``n`` parts (of ``strategies`` strategies) whose optimum holds at most ``max_states``
    states in every setting."""
    rng = random.Random(seed * 1000 + n)
    plans = []
    while len(plans) < count:
        plan = random_plan(rng, n, strategies, rng.uniform(0.2, 0.35), label=f"s{seed}-{len(plans)}")
        engine = OrderEngine(plan)
        if all(estimate_states(engine, visible=v, capacity=c, stop_above=max_states, time_limit=5.0).states
               <= max_states for v, c in settings):
            plans.append(plan)
    return plans


def decisions(name: str, settings, seed: int, budget: float | None, bin: str = "uniform",
              several_factor: int | None = None) -> None:
    """CPU time of each decision of the default policy along one seeded run of a plan too large for its
    optimum (a fresh state at most moves), and the window's counted work; ``several_factor``: the pile
    window's factor on its cap where several strategies are open (default: the tuned one)."""
    plan = load_plan(name)
    for visible, capacity in settings:
        engine, rng = OrderEngine(plan), random.Random(seed)
        weights = {p: 1.0 + i % 3 for i, p in enumerate(plan.part_ids)} if bin == "weighted" else None
        policy = Lookahead(visible=visible, capacity=capacity, budget=budget, bin="pile" if bin == "pile" else "uniform",
                           weights=weights)
        if several_factor is not None:
            policy.window.several_factor = several_factor
        mask, consistent, buffer, times, walls = 0, engine.all_strategies, (), [], []
        while mask != engine.full:
            in_bin = [p for i, p in enumerate(plan.part_ids) if engine.next_unit(mask, i) is not None and p not in buffer]
            look = tuple(rng.sample(in_bin, min(visible, len(in_bin))))
            start, wall = time.process_time(), time.perf_counter()
            free = float("inf") if capacity is None else capacity - len(buffer)
            action = policy.choose_at(engine, mask, consistent, buffer, free, look)
            times.append(time.process_time() - start)
            walls.append(time.perf_counter() - wall)
            if action.kind == "buffer":
                buffer += (action.part,)
            elif action.kind == "install":
                unit = engine.next_unit(mask, plan.index(action.part))
                mask, consistent = mask | (1 << unit), engine.consistent_after(mask, consistent, unit)
                if action.source == "buffer":
                    buffer = tuple(sorted(buffer, key=lambda p: p != action.part))[1:]
        later = sorted(times[1:])       # the first decision also lists the optimum's states (a second at most)
        work = policy.window.work
        print(f"| {plan.name}{f' ({bin})' * (bin != 'uniform')} | {visible} visible, {_locations(capacity)} | {len(times)} | "
              f"{1000 * times[0]:.0f} | {1000 * statistics.mean(later):.1f} | {1000 * later[int(0.99 * len(later))]:.1f} | "
              f"{1000 * later[-1]:.1f} | {1000 * max(walls[1:]):.1f} | {work['windows']:,} | {work['most_states']:,} | "
              f"{work['by_base']} |", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="16,20,25,30", help="parts per plan, comma-separated")
    ap.add_argument("--plans", type=int, default=3, help="plans per size")
    ap.add_argument("--policies", default="fallback", help=f"comma-separated, from {', '.join(POLICIES)}")
    ap.add_argument("--max-optimum-states", type=int, default=60_000)
    ap.add_argument("--task-seconds", type=float, default=300.0, help="one plan in one setting, at most")
    ap.add_argument("--settings", default="1x1,2x2,3x2", help="VISIBLExLOCATIONS, comma-separated (inf: unlimited)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--strategies", type=int, default=1, help="strategies per plan (the lab draws a third with two)")
    ap.add_argument("--decisions", help="time the default's decisions along a run of these plans instead "
                    "(comma-separated, e.g. salbp:KILBRID,salbp:ARC111)")
    ap.add_argument("--budget", type=float, help="with --decisions: the policy's decision budget (s; default none)")
    ap.add_argument("--bin", default="uniform", choices=("uniform", "pile", "weighted"),
                    help="the bin (default uniform; weighted: with --decisions, part i of weight 1 + i mod 3)")
    ap.add_argument("--several-factor", type=int, help="with --decisions --bin pile: the window's factor on its cap "
                    "where several strategies are open and 2 locations or more (default: the tuned one; 1: none)")
    args = ap.parse_args(argv)
    if args.bin == "weighted" and not args.decisions:
        ap.error("--bin weighted times decisions only (--decisions): the policy lab has no weighted bin")
    names = [p for p in args.policies.split(",") if p]
    settings = [(int(v), None if c == "inf" else int(c)) for v, c in (s.split("x") for s in args.settings.split(","))]
    if args.decisions:
        print("| plan | setting | decisions | first, ms | mean, ms | 99th percentile, ms | largest, ms | largest wall, ms | windows | "
              "most states | by slack |\n| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        for name in args.decisions.split(","):
            decisions(name, settings, args.seed, args.budget, args.bin, args.several_factor)
        return 0
    rows = []
    for n in map(int, args.sizes.split(",")):
        for plan in draw_plans(n, args.plans, args.seed, args.max_optimum_states, settings, args.strategies):
            for visible, capacity in settings:
                start = time.process_time()
                try:
                    g, best, states = gaps(plan, visible, capacity, args.bin, only=names, seconds=args.task_seconds,
                                           max_states=10 * args.max_optimum_states)
                except Exception as exc:        # said, never hidden: a row with why
                    print(f"{n} parts, {plan.name}, {visible} visible, {_locations(capacity)}: skipped ({exc})")
                    continue
                cpu = time.process_time() - start
                rows.append((n, visible, capacity, g))
                print(f"{n} parts, {plan.name}, {visible} visible, {_locations(capacity)}: optimum {best:.4f} "
                      f"({states:,} states); " + ", ".join(f"{k} {100 * v:+.3f}%" for k, v in g.items())
                      + f" ({cpu:.1f} s CPU)", flush=True)
    print("\n| parts | setting | plans | " + " | ".join(f"{k} mean | {k} max" for k in names) + " |")
    print("| ---: | --- | ---: | " + " | ".join("---: | ---:" for _ in names) + " |")
    for key in sorted({r[:3] for r in rows}, key=lambda k: (k[0], k[1], float("inf") if k[2] is None else k[2])):
        got = [r[3] for r in rows if r[:3] == key]
        cells = " | ".join(f"{100 * statistics.mean(g[k] for g in got):+.2f}% | {100 * max(g[k] for g in got):+.2f}%"
                           for k in names)
        print(f"| {key[0]} | {key[1]} visible, {_locations(key[2])} | {len(got)} | {cells} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
