"""Decisions in real time: latency of the budgeted opportunistic policy over full simulated runs.

For each plan: the warm-up (a new sequencer counting its first state), then ``--trials``
simulated trials (uniform bin, ``--visible`` parts per look, unlimited buffer) of the
opportunistic policy with a decision budget, timing every decision.  Where the exact
decision can be computed offline (a second engine, no budget, ``--offline-limit``
seconds per plan), the share of decisions identical to the exact rule's, and the mean
cost of the budgeted policy against the exact one on the same trials
(``--exact-trials``).

    python benchmarks/bench_decisions.py                       # KILBRID, TONGE70, ARC111, generated graphs
    python benchmarks/bench_decisions.py --plans salbp:ARC111 --trials 5
    python benchmarks/bench_decisions.py --plans gen:300:0.6 --trials 2
    python benchmarks/bench_decisions.py --policy lookahead --settings all --plans salbp:ARC111,gen:1000:0.6 --trials 1

Plans: ``salbp:NAME``, a plan file, or ``gen:N:OS`` (a generated assembly-like graph of
``N`` tasks and order strength ``OS``, from ``gen_precedence.py`` beside this file, seed 1).
Timings depend on the machine and on what else runs on it: the table says which machine.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from opportune import load_plan
from opportune.engine import OrderEngine
from opportune.engine.count import BudgetExceeded
from opportune.policies.look import LookState
from opportune.policies.opportunistic import choose_exact
from opportune.study.simulate import StudyConfig, TrialRunner, prepare

HERE = Path(__file__).resolve().parent
DEFAULT_PLANS = ["salbp:KILBRID", "salbp:TONGE70", "salbp:ARC111",
                 "gen:300:0.2", "gen:300:0.6", "gen:300:0.9", "gen:1000:0.2", "gen:1000:0.6", "gen:1000:0.9"]


def plan_of(spec: str):
    if spec.startswith("gen:"):
        sys.path.insert(0, str(HERE))
        from gen_precedence import generate
        from opportune import make_plan

        _, n, os_ = spec.split(":")
        pairs, times = generate(int(n), float(os_), "mixed", seed=1)
        ids = [str(i + 1) for i in range(int(n))]
        requires: dict[str, list[str]] = {}
        for a, b in pairs:
            requires.setdefault(str(b), []).append(str(a))
        plan = make_plan([{"id": i, "install": t} for i, t in zip(ids, times)], requires, name=f"gen-{n}-os{os_}")
        return plan, False
    plan = load_plan(spec)
    return plan, True


def pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))] if xs else float("nan")


def run_plan(spec: str, args, visible: int, capacity: int | None = None, bin: str = "uniform") -> dict:
    plan, offline_ok = plan_of(spec)
    config = StudyConfig(plan, strategies=(args.policy,), trials=args.trials, seed=args.seed, bin=bin,
                         visible=visible, buffer_capacity=capacity, decision_budget=args.budget,
                         count_time_limit=args.warm_up)
    engine = OrderEngine(plan)
    t0 = time.perf_counter()
    prepared = prepare(config, engine)          # the warm-up: count the first state
    warm = time.perf_counter() - t0
    runner = TrialRunner(args.policy, engine, config, prepared)
    policy = runner.policy
    records: list[tuple] = []
    paper = args.policy in ("opportunistic", "paper")
    choose_at = runner._choose_at

    def timed(engine_, mask, cons, buffer, free, look):
        s = time.perf_counter()
        if paper:       # the paper's rule says how it decided: exact, or estimated with a confidence
            action, how = policy._budgeted(LookState(engine_, mask, cons, buffer, free, look))
            exact, confidence = how.exact, how.confidence
        else:           # another policy: its latency (and, for the look-ahead, whether its programme decided)
            action = choose_at(engine_, mask, cons, buffer, free, look)
            exact, confidence = getattr(policy, "last_cost", None) is not None, 1.0
        records.append((time.perf_counter() - s, exact, confidence, (mask, cons, buffer, free, look), action))
        return action

    runner._choose_at = timed
    budget_costs = []
    t1 = time.perf_counter()
    for trial in range(args.trials):
        budget_costs.append(runner.run(trial).time)
    run_seconds = time.perf_counter() - t1
    lat = [r[0] for r in records]
    out = {"plan": plan.name, "n": plan.n_units, "warm": warm, "decisions": len(lat),
           "p50": pct(lat, 0.5), "p95": pct(lat, 0.95), "max": max(lat), "exact": sum(r[1] for r in records),
           "conf": statistics.mean([r[2] for r in records if not r[1]] or [1.0]),
           "budget_cost": statistics.mean(budget_costs), "trials": args.trials, "run_s": run_seconds}
    if not offline_ok or not paper or (visible, capacity, bin) != (args.visible, None, "uniform"):
        # the offline checks compare with the paper's exact rule, in the first setting
        return out
    # Offline: the exact rule on the same states and looks (its own engine, no budget).  A decision
    # marked exact is the exact rule's (tests/test_decision_budget.py); the estimated ones are checked
    # here, as many as the time allows.
    # An exact trial whose counts do not fit the engine's memo ends the exact trials, said in the table.
    exact_engine = OrderEngine(plan)
    limit = time.perf_counter() + args.offline_limit
    exact_n = sum(1 for r in records if r[1])
    same = checked = 0
    for _, was_exact, _, (mask, cons, buffer, free, look), action in records:
        if was_exact:
            continue
        left = limit - time.perf_counter()
        if left <= 0:
            break
        try:
            with exact_engine.deadline(time.perf_counter() + left):
                exact = choose_exact(exact_engine, mask, cons, buffer, free, look)
        except BudgetExceeded:
            break
        checked += 1
        same += exact == action
    out["identical"] = (exact_n + same, exact_n + checked, same, checked)
    if args.exact_trials:
        exact_config = StudyConfig(plan, strategies=("paper",), trials=args.exact_trials, seed=args.seed,
                                   visible=visible)
        exact_runner = TrialRunner("paper", exact_engine, exact_config, prepared)
        n = min(args.exact_trials, args.trials)
        costs = []
        t2 = time.perf_counter()
        for trial in range(n):
            try:
                costs.append(exact_runner.run(trial).time)
            except BudgetExceeded as exc:
                out["exact_stopped"] = str(exc)
                break
            if time.perf_counter() - t2 > args.offline_limit:
                break
        if costs:
            out["exact_cost"] = statistics.mean(costs)
            out["paired_budget_cost"] = statistics.mean(budget_costs[:len(costs)])
            out["exact_trials"] = len(costs)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--plans", default=",".join(DEFAULT_PLANS), help="comma-separated plan specs")
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--policy", default="paper",
                    help="the policy timed: paper (the paper's rule, with the offline checks), bin-first, "
                         "slack or lookahead (latency only)")
    ap.add_argument("--budget", type=float, default=0.05, help="seconds per decision")
    ap.add_argument("--visible", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--warm-up", type=float, default=10.0, help="seconds to count the first state")
    ap.add_argument("--offline-limit", type=float, default=120.0, help="seconds per plan for the exact checks")
    ap.add_argument("--exact-trials", type=int, default=3, help="trials of the exact policy, for the mean cost")
    ap.add_argument("--settings", default="", help="'all': also every setting of 1-3 visible x buffer 1, 2, "
                    "unlimited x uniform and pile bins (a row each; the offline checks in the first only)")
    args = ap.parse_args(argv)
    settings = [(args.visible, None, "uniform")]
    if args.settings == "all":
        settings += [(v, c, b) for b in ("uniform", "pile") for v in (1, 2, 3) for c in (1, 2, None)
                     if (v, c, b) != settings[0]]
    console = Console(width=160)
    table = Table(title=f"budgeted {args.policy} decisions (budget {1000 * args.budget:g} ms; "
                        f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()})")
    for col in ("plan", "setting", "tasks", "warm-up s", "decisions", "p50 ms", "p95 ms", "max ms", "exact",
                "mean conf.", "identical to exact (estimated ones checked)", "mean cost: budget / exact (trials)"):
        table.add_column(col, justify="left" if col == "plan" else "right")
    for spec, (visible, capacity, bin) in ((s, t) for s in args.plans.split(",") for t in settings):
        r = run_plan(spec.strip(), args, visible, capacity, bin)
        ident = r.get("identical")
        cost = f"{r['budget_cost']:.2f}"
        if "exact_cost" in r:
            diff = r["paired_budget_cost"] / r["exact_cost"] - 1
            cost = f"{r['paired_budget_cost']:.2f} / {r['exact_cost']:.2f} ({100 * diff:+.2f}%, {r['exact_trials']})"
        if "exact_stopped" in r:
            cost += " (exact trials stopped: memo over its cap)"
            console.print(f"[dim]{spec}: the exact trials stopped: {r['exact_stopped']}[/dim]")
        setting = f"{bin}, {visible} visible, buffer {'unlimited' if capacity is None else capacity}"
        table.add_row(r["plan"], setting, str(r["n"]), f"{r['warm']:.2f}", str(r["decisions"]), f"{1000 * r['p50']:.2f}",
                      f"{1000 * r['p95']:.1f}", f"{1000 * r['max']:.1f}",
                      f"{100 * r['exact'] / r['decisions']:.0f}%", f"{r['conf']:.3f}",
                      f"{100 * ident[0] / ident[1]:.1f}% of {ident[1]} ({ident[2]}/{ident[3]} est.)"
                      if ident and ident[1] else "n/a", cost)
        console.print(f"[dim]{spec}, {setting}: {r['trials']} trials in {r['run_s']:.1f} s, "
                      f"max decision {1000 * r['max']:.1f} ms[/dim]")
    console.print(table)


if __name__ == "__main__":
    main()
