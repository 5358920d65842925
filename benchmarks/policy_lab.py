"""The policy lab: every policy evaluated exactly against the optimum, on random plans and the gearbox.

For ``--plans`` random plans (``--min-parts`` to ``--max-parts`` parts, one or two strategies, a
range of densities; seeded), each policy's exact expected time
(:class:`~opportune.policies.evaluate.PolicyEvaluator`, uniform bin, ``--visible`` parts per
look) is divided by the optimum's; the table gives the mean, median and largest gap per policy,
over all plans and over those with two strategies.  Then the gearbox with buffer capacity 1, 2
and unlimited with 2 parts visible, 1, 2 and unlimited with 1, unlimited and 1 with 3.  No Monte
Carlo: every number is exact.

Plans too large for exact evaluation (``--paired``, default KILBRID and TONGE70) are compared by
paired Monte Carlo instead: every policy runs on the same ``--paired-trials`` random bins (trial
``i`` of each sees the same bin), and the table gives each policy's mean time and its mean
difference from the paper's rule with the 95% interval of that difference (Student's t).

    python benchmarks/policy_lab.py                    # 30 plans of 8-12 parts, then KILBRID and TONGE70
    python benchmarks/policy_lab.py --plans 10 --max-parts 10 --plot docs/img/policy-gaps.png
    python benchmarks/policy_lab.py --plans 0 --paired salbp:KILBRID --paired-trials 400
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import time
from pathlib import Path

from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.opportunistic import Opportunistic
from opportune.policies.variants import BinFirst, Lookahead, Slack

HERE = Path(__file__).resolve().parent
GEARBOX = HERE.parent / "examples" / "gearbox.yaml"


def policies(visible: int, capacity: int | None):
    return {"paper": Opportunistic(), "bin-first": BinFirst(), "slack": Slack(),
            "lookahead": Lookahead(visible=visible, capacity=capacity)}


def random_plan(rng: random.Random, n: int, strategies: int, density: float):
    ids = [f"p{i}" for i in range(n)]

    def requires() -> dict[str, list[str]]:
        order = ids[:]
        rng.shuffle(order)
        out: dict[str, list[str]] = {}
        for j, b in enumerate(order):
            before = [a for a in order[:j] if rng.random() < density]
            if before:
                out[b] = before
        return out

    if strategies == 1:
        return make_plan(ids, requires(), name=f"random-{n}")
    return make_plan(ids, strategies={f"s{k}": requires() for k in range(strategies)}, name=f"random-{n}x{strategies}")


def gaps(plan, visible: int, capacity: int | None) -> tuple[dict[str, float], float, int]:
    engine = OrderEngine(plan)
    out = {}
    best = None
    states = 0
    for name, policy in policies(visible, capacity).items():
        ev = PolicyEvaluator(engine, policy, visible=visible, capacity=capacity, max_states=2_000_000)
        value = ev.value()
        if best is None:
            best = ev.optimal()
            states = ev.states
        out[name] = value / best - 1
    return out, best, states


def summarise(rows: list[dict[str, float]]) -> dict[str, tuple[float, float, float]]:
    names = rows[0].keys()
    return {k: (statistics.mean(r[k] for r in rows), statistics.median(r[k] for r in rows), max(r[k] for r in rows))
            for k in names}


def print_summary(title: str, rows: list[dict[str, float]]) -> None:
    print(f"\n{title} ({len(rows)} plans): gap to the optimum, mean / median / max")
    for name, (mean, median, top) in summarise(rows).items():
        print(f"  {name:<10} {100 * mean:+8.3f}% {100 * median:+8.3f}% {100 * top:+8.3f}%")


PAIRED = ("paper", "bin-first", "slack", "lookahead", "rollout")


def paired(spec: str, args) -> None:
    """Every policy on the same random bins of a plan too large for exact evaluation: the mean time, and
    the mean difference from the paper's rule with its 95% interval."""
    from opportune.report import summary
    from opportune.simulate import StudyConfig, run_study

    plan = load_plan(spec)
    start = time.perf_counter()
    result = run_study(StudyConfig(plan, strategies=PAIRED, trials=args.paired_trials, seed=args.seed,
                                   visible=args.visible), workers=args.workers)
    doc = summary(result)["strategies"]
    print(f"\n{plan.name} ({plan.n_units} units): paired Monte Carlo, {args.paired_trials} trials per policy "
          f"on the same bins, uniform bin, {args.visible} visible, unlimited buffer "
          f"({time.perf_counter() - start:.0f} s)")
    print(f"  {'policy':<10} {'mean time':>10}  {'against paper (95% interval)':>32}  {'s/trial':>8}")
    for name in PAIRED:
        s = doc[name]
        against = s.get("paired")
        text = "—" if against is None else \
            f"{against['mean_difference']:+.3f} ({against['ci95'][0]:+.3f} .. {against['ci95'][1]:+.3f})"
        per = result.seconds.get(name, 0.0) / max(1, s["trials"])
        print(f"  {name:<10} {s['time']['mean']:>10.3f}  {text:>32}  {per:>8.3f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", type=int, default=30)
    ap.add_argument("--min-parts", type=int, default=8)
    ap.add_argument("--max-parts", type=int, default=12)
    ap.add_argument("--visible", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--plot", type=Path, help="write a dot plot of each policy's gap per plan here (PNG or PDF)")
    ap.add_argument("--paired", default="salbp:KILBRID,salbp:TONGE70",
                    help="plans compared by paired Monte Carlo (comma-separated; empty: none)")
    ap.add_argument("--paired-trials", type=int, default=200)
    ap.add_argument("--workers", type=int, default=None, help="worker processes of the paired studies")
    args = ap.parse_args(argv)

    rng = random.Random(args.seed)
    rows, multi, labels = [], [], []
    t0 = time.perf_counter()
    for i in range(args.plans):
        n = rng.randint(args.min_parts, args.max_parts)
        k = 2 if i % 3 == 2 else 1                     # a third of the plans have two strategies
        density = rng.choice([0.1, 0.2, 0.3])
        plan = random_plan(rng, n, k, density)
        g, best, states = gaps(plan, args.visible, None)
        rows.append(g)
        labels.append(plan.name)
        if k == 2:
            multi.append(g)
        print(f"plan {i:2d}: {n} parts, {k} strateg{'y' if k == 1 else 'ies'}, density {density}: optimum "
              f"{best:.4f} ({states:,} states); " + ", ".join(f"{p} {100 * v:+.3f}%" for p, v in g.items()),
              flush=True)
    if rows:
        print_summary("random plans", rows)
    if multi:
        print_summary("random plans with two strategies", multi)

    gear = load_plan(GEARBOX)
    if args.plans:
        print("\ngearbox: gap to the optimum per setting")
    for visible, capacity in ((2, None), (2, 1), (2, 2), (1, None), (1, 1), (1, 2), (3, None), (3, 1)) if args.plans else ():
        g, best, _ = gaps(gear, visible, capacity)
        cap = "unlimited" if capacity is None else capacity
        print(f"  visible {visible}, buffer {cap:<9}: optimum {best:.4f}; "
              + ", ".join(f"{p} {100 * v:+.3f}%" for p, v in g.items()))
    if args.plans:
        print(f"\n{time.perf_counter() - t0:.0f} s")
    for spec in filter(None, args.paired.split(",")):
        paired(spec, args)

    if args.plot and rows:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        plt.rcParams["svg.fonttype"] = "none"
        fig, ax = plt.subplots(figsize=(8, 3.6), dpi=150)
        names = list(rows[0])
        for j, name in enumerate(names):
            ys = [100 * r[name] for r in rows]
            xs = [j + (i - len(rows) / 2) * 0.6 / len(rows) for i in range(len(rows))]
            ax.scatter(xs, ys, s=12, label=name)
        ax.set_xticks(range(len(names)), names)
        ax.set_ylabel("gap to the optimum (%)")
        ax.set_title(f"exact expected time against the optimum, {len(rows)} random plans "
                     f"({args.min_parts}-{args.max_parts} parts; uniform bin, {args.visible} visible)", fontsize=9)
        ax.axhline(0, color="grey", lw=0.8)
        fig.tight_layout()
        args.plot.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.plot, metadata={"Date": None} if args.plot.suffix == ".pdf" else None)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
