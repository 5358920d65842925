"""The default's fallback against the optimum in the pile, a weighted bin and the uniform bin, estimated
along seeded runs where the exact evaluation is too slow.

The gap of a policy is the optimum's losses along the policy's own runs (the performance-difference
identity): at each look the policy meets, the optimum's expected cost after the policy's action less its
cost after its own best action, summed over a run, is in expectation the policy's expected cost less the
optimum's.  Each run is seeded (run ``i`` of every plan-setting draws from ``Random(seed × 1000 + i)``),
so two versions of a policy compared on the same runs are paired; the table gives the mean gap over the
optimum with the 95% interval of the mean (Student's t over the runs).  The policy is the lab's
``fallback`` (``Lookahead(optimal=False)``: the pile window, or the weighted window), the optimum the
compiled programme of the whole plan (the policy lab's plans of 16-20 parts fit it; in the uniform bin on
the plan with its interchangeable parts merged, so a shipped SALBP plan such as ``salbp:KILBRID`` fits it
too: 27.5 million states, about 1.1 GB and 60-90 CPU seconds with 2 locations).

A run in the pile keeps its top until a unit is taken from it (a real pile: the next unit of a random
stacking comes up), a shake restacks the bin; in a weighted bin every look is a fresh draw without
replacement, part ``i`` of the plan of weight :data:`WEIGHTS` ``[i mod 4]``; in the uniform bin likewise, every
weight 1.

    python benchmarks/bench_window_gap.py --bin pile --plans r1-16,r2-16x2,r2-20x2 --settings 1x2,2x2,3x2
    python benchmarks/bench_window_gap.py --bin weighted --plans r1-16 --settings 1x1 --runs 100
    python benchmarks/bench_window_gap.py --bin uniform --plans salbp:KILBRID --settings 1x2 --runs 100
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import time
from pathlib import Path

from opportune.engine import OrderEngine
from opportune.policies.lookahead import Lookahead
from opportune.policies.optimal import optimal_solver
from opportune.policies.pile import pile_solver

sys.path.insert(0, str(Path(__file__).resolve().parent))
from policy_lab import generate  # noqa: E402

#: The weighted bin's part weights, by declaration index modulo 4.
WEIGHTS = (0.5, 1.0, 2.0, 3.0)


def lab_plans(names: list[str], sizes: list[int], count: int, seed: int) -> list:
    """The policy lab's random plans of these sizes (``--sizes N --plans count --seed``) named in ``names``, and
    the shipped SALBP plans named ``salbp:NAME``."""
    from opportune import datasets

    lab = [n for n in names if not n.startswith("salbp:")]
    plans = {plan.name: plan for n in (sizes if lab else []) for plan, _ in generate(seed, count, n, n)}
    plans.update({n: datasets.salbp(n[len("salbp:"):]) for n in names if n.startswith("salbp:")})
    missing = [n for n in names if n not in plans]
    if missing:
        raise SystemExit(f"no lab plan named {', '.join(missing)}; there are {', '.join(plans)}")
    return [plans[n] for n in names]


def _draw(rng: random.Random, counts: list[int], k: int, weights: list[float]) -> list[int]:
    """``k`` units drawn without replacement, a unit of part ``i`` with chance proportional to ``weights[i]``."""
    counts, out = list(counts), []
    for _ in range(min(k, sum(counts))):
        live = [i for i, c in enumerate(counts) if c]
        i = rng.choices(live, weights=[counts[i] * weights[i] for i in live])[0]
        counts[i] -= 1
        out.append(i)
    return out


def run_losses(opt, policy, engine, rng: random.Random, pile: bool, weights: list[float]) -> tuple[float, int]:
    """One seeded run of ``policy``: the optimum's losses summed over its looks, and the looks."""
    key, costs = opt.start_key(), opt.costs
    stack: list[int] = []
    window: list[int] = []
    loss, looks = 0.0, 0

    def restack():
        nonlocal stack, window
        bin_units = [i for i, c in enumerate(opt._bin_counts(key)) for _ in range(c)]
        rng.shuffle(bin_units)
        window, stack = sorted(bin_units[:opt.visible]), bin_units[opt.visible:]

    if pile:
        restack()
    while key[0] != engine.full:
        if not pile:
            window = sorted(_draw(rng, list(opt._bin_counts(key)), opt.visible, weights))
        look = tuple(window)
        looks += 1
        shake = costs.shake + (opt._shake_value(key) if pile else opt._value(key))
        best = min([cost + opt._after(key, look, move, nxt) for cost, nxt, move in opt._moves(key, look)] + [shake])
        chosen = opt._policy_move(policy, key, look)
        if chosen is None:
            loss += shake - best
            if pile:
                restack()
            continue
        cost, nxt, move = chosen
        loss += cost + opt._after(key, look, move, nxt) - best
        if pile and not (move.kind == "install" and move.source == "buffer"):
            window.remove(opt.plan.index(move.part))
            window = sorted(window + stack[:1])
            stack = stack[1:]
        key = nxt
    return loss, looks


def estimate(plan, visible: int, capacity: int | None, bin: str, runs: int, seed: int,
             window_states: int | None = None, earlier: bool = False, several_factor: int | None = None) -> dict:
    """The fallback's gap over the optimum on ``runs`` seeded runs: mean, 95% half-width, the optimum;
    ``window_states``: the window's state cap instead of its default (to measure the cap's trade-off);
    ``several_factor``: the pile window's factor on its cap where several strategies are open
    (:data:`~opportune.engine.tuning.PILE_SEVERAL_FACTOR`; 1: the cap alone, as before it);
    ``earlier``: the uniform bin's earlier window (the others buffered as one, never installed; the parts
    in the order of their remaining ancestors alone)."""
    engine = OrderEngine(plan)
    weights = {p.id: WEIGHTS[i % len(WEIGHTS)] for i, p in enumerate(plan.parts)} if bin == "weighted" else None
    settings = dict(visible=visible, capacity=capacity, max_states=20_000_000)
    settings["max_states"] = 40_000_000 if bin == "uniform" else settings["max_states"]
    opt = pile_solver(engine, **settings) if bin == "pile" else optimal_solver(engine, merge=bin == "uniform",
                                                                                weights=weights, **settings)
    best = opt.value()
    policy = Lookahead(visible=visible, capacity=capacity, bin="pile" if bin == "pile" else "uniform",
                       weights=weights, optimal=False)
    if window_states is not None:
        policy._window_serves(engine)       # the weighted bin's window is made there
        policy.window.max_states = window_states
    if several_factor is not None:
        policy.window.several_factor = several_factor
    if earlier:
        policy.window.others, policy.window.descendants = "buffer", 0.0
    w = [weights[p.id] for p in plan.parts] if weights else [1.0] * len(plan.parts)
    losses, cpu = [], time.process_time()
    for i in range(runs):
        loss, _ = run_losses(opt, policy, engine, random.Random(seed * 1000 + i), bin == "pile", w)
        losses.append(loss / best)
    mean = statistics.mean(losses)
    half = (t975(runs - 1) * statistics.stdev(losses) / runs ** 0.5) if runs > 1 else float("inf")
    return {"mean": mean, "half": half, "optimum": best, "cpu": time.process_time() - cpu, "cap": policy.window.max_states,
            "factor": getattr(policy.window, "several_factor", 1),
            "window": policy.window.work if policy.window is not None else {}}


def t975(df: int) -> float:
    """Student's t 97.5% quantile (df degrees of freedom)."""
    from opportune.engine.stats import t_quantile

    return t_quantile(0.975, df)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", default="pile", choices=("pile", "weighted", "uniform"))
    ap.add_argument("--plans", default="r1-16,r2-16x2,r2-20x2",
                    help="the lab's plan names or salbp:NAME, comma-separated")
    ap.add_argument("--sizes", default="16,20", help="the lab's sizes the plans are drawn from")
    ap.add_argument("--lab-plans", type=int, default=3, help="the lab's plans a size (--plans there)")
    ap.add_argument("--settings", default="1x2,2x1,2x2,3x2", help="VISIBLExLOCATIONS, comma-separated (inf: unlimited)")
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--window-states", type=int, help="the window's state cap (default: the tuned one)")
    ap.add_argument("--several-factor", type=int, help="the pile window's factor on its cap where several "
                    "strategies are open and 2 locations or more (default: the tuned one; 1: none)")
    ap.add_argument("--earlier", action="store_true", help="the uniform bin's earlier window (the others buffered "
                    "as one, the order of remaining ancestors alone): the same runs, so the two are paired")
    args = ap.parse_args(argv)
    plans = lab_plans(args.plans.split(","), [int(s) for s in args.sizes.split(",")], args.lab_plans, 0)
    settings = [(int(v), None if c == "inf" else int(c)) for v, c in (s.split("x") for s in args.settings.split(","))]
    print("| plan | bin | setting | window states | runs | gap, mean | 95% interval | CPU, s |\n"
          "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: |")
    for plan in plans:
        for visible, capacity in settings:
            r = estimate(plan, visible, capacity, args.bin, args.runs, args.seed, args.window_states, args.earlier,
                         args.several_factor)
            cap = f"{r['cap']:,}" + (f" (×{r['factor']} with several open)" if r["factor"] != 1 else "")
            locations = "unlimited buffer" if capacity is None else f"{capacity} location{'s' * (capacity != 1)}"
            print(f"| {plan.name} | {args.bin} | {visible} visible, {locations} | "
                  f"{cap} | {args.runs} | {100 * r['mean']:+.2f}% | ±{100 * r['half']:.2f} | {r['cpu']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
