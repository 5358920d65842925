"""How far is the default policy from the best any online policy can do?  The certified lower bound of
:mod:`opportune.study.bounds`, per penalty, beside the exact optimum where it is known and beside the default
policy's mean on KILBRID, TONGE70 and ARC111.

Not a test: prints the two tables of docs/lower-bounds.md (markdown); ``--write docs/lower-bounds.md`` also
replaces them between the page's ``<!-- bound-small -->`` and ``<!-- bound-large -->`` markers.

* ``--small``: random plans of 8-20 parts (as the policy lab makes them), where the optimum is computed
  exactly: per setting, the optimum, the default policy's exact value where its programme finishes within
  ``--policy-seconds``, and the bound with each penalty (``motions``, ``relaxed``) with its 95% interval;
  ``below`` says whether the interval's low end is at most the optimum (it must be, on every row).
* ``--large``: per plan, number of visible parts and buffer locations, the default policy's (``lookahead``)
  mean time with its 95% interval (``simulate``'s way of deciding: within 50 ms per decision where the
  first exact counts take too long), the bound with each penalty, and the default's gap over the better
  bound (the policy's mean over the bound, less one: how far above the optimum it can be at most, up to
  Monte Carlo error), with the bounds' CPU seconds; where the policy lab's results (``--lab-results``) hold
  the plan's exact optimum in the setting, that optimum too, and whether the bound is at most it.

    python benchmarks/bench_bounds.py [--small] [--large] [--plans salbp:KILBRID,...] [--settings 2:-,2:1]
                                      [--trials 100] [--bound-trials 40] [--nodes 2000] [--write docs/lower-bounds.md]
                                      [--lab-results benchmarks/policy_lab_results.jsonl]
"""

from __future__ import annotations

import argparse
import json
import random
import re
import time
from dataclasses import replace
from pathlib import Path

from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.engine.deadline import Deadline
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.lookahead import Lookahead
from opportune.policies.optimal import OutOfTime, optimal_solver
from opportune.study.bounds import lower_bound
from opportune.study.report import summary
from opportune.study.simulate import StrategyUnavailable, StudyConfig, prepare, run_study

PENALTIES = ("motions", "relaxed")
SMALL = [(8, 1, 1), (8, 2, None), (12, 1, 1), (12, 2, 2), (12, 2, None), (16, 1, 1), (16, 2, 2), (20, 1, 1),
         (20, 2, 2)]


def lab_plan(seed: int, n: int):
    """A random precedence plan as the policy lab makes them: a random order, each earlier part required
    with chance 0.2-0.35."""
    rng = random.Random(seed)
    density = rng.uniform(0.2, 0.35)
    ids = [f"p{i}" for i in range(n)]
    order = ids[:]
    rng.shuffle(order)
    requires = {b: before for j, b in enumerate(order) if (before := [a for a in order[:j] if rng.random() < density])}
    return make_plan(ids, requires, name=f"random-{n}-{seed}")


def cap_text(capacity) -> str:
    return "unlimited" if capacity is None else str(capacity)


def bound_cell(plan, visible, capacity, penalty, args, relaxed_states=None) -> tuple[str, float, float, float]:
    """The bound as ``mean ± half``, its mean, its low end and its CPU seconds."""
    cpu = time.process_time()
    b = lower_bound(plan, visible=visible, capacity=capacity, trials=args.bound_trials, seed=0, penalty=penalty,
                    node_budget=args.nodes, relaxed_states=relaxed_states)
    return f"{b.mean:.2f} ± {b.half_width:.2f}", b.mean, b.low, time.process_time() - cpu


def small_table(args) -> list[str]:
    lines = [f"uniform bin; the bound on {args.bound_trials} bins, at most {args.nodes:,} nodes per bin; the "
             f"default's exact value where its programme finishes within {args.policy_seconds:g} s", "",
             f"| plan | visible | locations | optimum (states) | default | motions bound | relaxed bound, "
             f"{args.small_share:.0%} of the states | relaxed bound | below |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for n, visible, capacity in SMALL:
        plan = lab_plan(n, n)
        engine = OrderEngine(plan)
        solver = optimal_solver(engine, visible=visible, capacity=capacity, max_states=5_000_000)
        best = solver.value()
        ev = PolicyEvaluator(engine, Lookahead(visible=visible, capacity=capacity), visible=visible,
                             capacity=capacity, max_states=5_000_000)
        ev.deadline = Deadline.after(args.policy_seconds)
        try:
            default = f"{ev.value():.3f}"
        except OutOfTime:
            default = f"over {args.policy_seconds:g} s"
        cells, below = [], True
        share = max(50, int(args.small_share * solver.states))
        for penalty, states in (("motions", None), ("relaxed", share), ("relaxed", None)):
            text, _, low, _ = bound_cell(plan, visible, capacity, penalty, args, states)
            cells.append(text)
            below &= low <= best + 1e-9
        lines.append(f"| {plan.name} | {visible} | {cap_text(capacity)} | {best:.3f} ({solver.states:,}) | "
                     f"{default} | {' | '.join(cells)} | {'yes' if below else '**no**'} |")
        print(lines[-1], flush=True)
    return lines


def policy_mean(plan, visible: int, capacity, trials: int) -> tuple[float, float, str]:
    """The default policy's mean time, half-width of its 95% interval, and how it decided
    (as ``simulate`` does: within 50 ms per decision where the first exact counts take too long)."""
    config = StudyConfig(plan, strategies=("lookahead",), trials=trials, seed=0, visible=visible,
                         buffer_capacity=capacity)
    how = "exact"
    try:
        prepare(config)
    except StrategyUnavailable:
        from opportune.sequencer import DEFAULT_BUDGET

        config = replace(config, decision_budget=DEFAULT_BUDGET)
        how = f"{1000 * DEFAULT_BUDGET:g} ms per decision"
    t = summary(run_study(config, workers=1))["strategies"]["lookahead"]["time"]
    low, high = t["ci95"]
    return t["mean"], (high - low) / 2, how


def lab_optima(path: Path | None) -> dict[tuple, tuple[float, float | None]]:
    """The exact optima the policy lab computed (uniform bin), with the default's exact value where the lab
    measured its gap (else None), by (plan name, visible, locations)."""
    found: dict[tuple, tuple[float, float | None]] = {}
    if path is None or not path.exists():
        return found
    for line in path.read_text(encoding="utf-8").splitlines():
        r = json.loads(line)
        if r.get("bin", "uniform") == "uniform" and r.get("optimum"):
            key, gap = (r["plan"], r["visible"], r["capacity"]), r.get("gaps", {}).get("lookahead")
            exact = None if gap is None else r["optimum"] * (1 + gap)
            found[key] = (r["optimum"], exact if exact is not None else found.get(key, (0, None))[1])
    return found


def large_table(args) -> list[str]:
    optima = lab_optima(args.lab_results)
    lines = [f"uniform bin, seed 0; the policy on {args.trials} bins, the bound on {args.bound_trials} (at most "
             f"{args.nodes:,} nodes per bin); the bounds' CPU seconds; the optimum where the policy lab computed it. "
             "The gap is the default's value over the larger bound, less one: its exact value where the lab measured "
             "it (then marked *exact*), else its mean",
             "",
             "| plan | visible | locations | default policy | optimum | motions bound | relaxed bound | gap | bound s |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for spec in args.plans.split(","):
        plan = load_plan(spec)
        for setting in args.settings.split(","):
            visible, capacity = (int(x) if x != "-" else None for x in setting.split(":"))
            mean, half, how = policy_mean(plan, visible, capacity, args.trials)
            cells, best, bsecs, low = [], 0.0, 0.0, float("-inf")
            for penalty in PENALTIES:
                text, value, lo, s = bound_cell(plan, visible, capacity, penalty, args)
                cells.append(text)
                best, bsecs, low = max(best, value), bsecs + s, max(low, lo)
            optimum, exact = optima.get((plan.name, visible, capacity), (None, None))
            known = "—" if optimum is None else f"{optimum:.2f}" + ("" if low <= optimum + 1e-9 else " (**bound above**)")
            note = "" if how == "exact" else f" ({how})"
            gap = f"{100 * (mean / best - 1):+.1f}%" if exact is None else f"{100 * (exact / best - 1):+.1f}% (exact)"
            lines.append(f"| {plan.name} ({plan.n_units}) | {visible} | {cap_text(capacity)} | {mean:.2f} ± {half:.2f}"
                         f"{note} | {known} | {' | '.join(cells)} | {gap} | {bsecs:.0f} |")
            print(lines[-1], flush=True)
    return lines


def write(page: Path, name: str, lines: list[str]) -> None:
    """Replace the table between ``<!-- name -->`` and ``<!-- /name -->`` on ``page``."""
    text = page.read_text(encoding="utf-8")
    pattern = re.compile(rf"(<!-- {name} -->\n).*?(<!-- /{name} -->)", re.S)
    if not pattern.search(text):
        raise SystemExit(f"{page}: no <!-- {name} --> ... <!-- /{name} --> block to replace")
    page.write_text(pattern.sub(lambda m: m.group(1) + "\n".join(lines) + "\n" + m.group(2), text), encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="the random plans where the optimum is known")
    ap.add_argument("--large", action="store_true", help="the SALBP plans")
    ap.add_argument("--plans", default="salbp:KILBRID,salbp:TONGE70,salbp:ARC111")
    ap.add_argument("--settings", default="2:-,1:-,2:2,2:1,1:1",
                    help="visible:locations pairs, comma-separated ('-': unlimited)")
    ap.add_argument("--trials", type=int, default=100, help="trials of the default policy")
    ap.add_argument("--bound-trials", type=int, default=40, help="trials (bins) of the bound")
    ap.add_argument("--nodes", type=int, default=2_000, help="nodes of one trial's inner search, at most")
    ap.add_argument("--small-share", type=float, default=0.25,
                    help="states of the relaxed plan in the small table's middle column, as a share of the optimum's "
                         "(a partial relaxation)")
    ap.add_argument("--policy-seconds", type=float, default=60.0, help="the default's exact programme, at most")
    ap.add_argument("--lab-results", type=Path, default=Path(__file__).resolve().parent / "policy_lab_results.jsonl",
                    help="the policy lab's results: the exact optima it computed, shown beside the bounds")
    ap.add_argument("--write", type=Path,
                    help="a page whose <!-- bound-small --> / <!-- bound-large --> tables to replace")
    args = ap.parse_args(argv)
    if not (args.small or args.large):
        args.small = args.large = True
    for name, wanted, table in (("bound-small", args.small, small_table), ("bound-large", args.large, large_table)):
        if wanted:
            lines = table(args)
            print()
            if args.write:
                write(args.write, name, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
