"""The policy lab: every policy evaluated exactly against the optimum, in every setting, on random plans,
the gearbox and any folder of plans.

For ``--plans`` random plans (``--min-parts`` to ``--max-parts`` parts, one or two strategies, a
range of densities; seeded) and every plan file in ``--plans-dir``, each policy's exact expected
time (:class:`~opportune.policies.evaluate.PolicyEvaluator` in the uniform bin,
:class:`~opportune.policies.pile.PileSolver` in the pile) is divided by the optimum's, in every
setting of ``--visible`` (1, 2, 3) × ``--capacities`` (1, 2, unlimited) × ``--bins`` (uniform, pile);
the tables give the mean, median and largest gap per policy and setting, over all plans and over
those with two strategies, and how many plans a setting skipped (the optimum over ``--max-states``
states, or a plan's evaluation over ``--task-seconds``: said, never hidden).  Then the gearbox in
every setting.  No Monte Carlo: every number is exact.

Plans too large for exact evaluation (``--paired``, default KILBRID and TONGE70) are compared by
paired Monte Carlo instead: every policy runs on the same ``--paired-trials`` random bins (trial
``i`` of each sees the same bin), and the table gives each policy's mean time and its mean
difference from the paper's rule with the 95% interval of that difference (Student's t).

    python benchmarks/policy_lab.py                    # 30 plans of 8-12 parts, every setting, then KILBRID and TONGE70
    python benchmarks/policy_lab.py --plans 10 --visible 2 --capacities inf --bins uniform --plot docs/img/policy-gaps.png
    python benchmarks/policy_lab.py --plans 0 --plans-dir my-plans/ --paired ""
    python benchmarks/policy_lab.py --plans 0 --paired salbp:KILBRID --paired-trials 400
    python benchmarks/policy_lab.py --plans 0 --paired salbp:KILBRID --bound   # and a lower bound beside the means
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
from opportune.engine.deadline import Deadline
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.optimal import OptimalTooLarge, OutOfTime
from opportune.policies.pile import PileSolver
from opportune.policies.opportunistic import Opportunistic
from opportune.policies.variants import BinFirst, Lookahead, Slack

HERE = Path(__file__).resolve().parent
GEARBOX = HERE.parent / "examples" / "gearbox.yaml"


def policies(visible: int, capacity: int | None, bin: str = "uniform"):
    return {"paper": Opportunistic(), "bin-first": BinFirst(), "slack": Slack(),
            "lookahead": Lookahead(visible=visible, capacity=capacity, bin=bin)}


def random_plan(rng: random.Random, n: int, strategies: int, density: float, label: str = "random"):
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
        return make_plan(ids, requires(), name=f"{label}-{n}")
    return make_plan(ids, strategies={f"s{k}": requires() for k in range(strategies)}, name=f"{label}-{n}x{strategies}")


def gaps(plan, visible: int, capacity: int | None, bin: str = "uniform", *, max_states: int = 2_000_000,
         seconds: float | None = None) -> tuple[dict[str, float], float, int]:
    """Each policy's exact expected time over the optimum's, less one; the optimum; its states.  Raises
    OptimalTooLarge past ``max_states`` states and OutOfTime past ``seconds`` (the whole plan)."""
    engine = OrderEngine(plan)
    deadline = Deadline.after(seconds) if seconds is not None else None
    settings = dict(visible=visible, capacity=capacity, max_states=max_states)
    if bin == "pile":
        optimum = PileSolver(engine, **settings)
        optimum.deadline = deadline
        best, states = optimum.value(), optimum.states
    out = {}
    for name, policy in policies(visible, capacity, bin).items():
        ev = PileSolver(engine, policy, **settings) if bin == "pile" else PolicyEvaluator(engine, policy, **settings)
        ev.deadline = deadline
        value = ev.value()
        if bin != "pile" and not out:
            best, states = ev.optimal(), ev.states
        out[name] = value / best - 1
    return out, best, states


def _task(job):
    """One plan in one setting (a worker's job): (gaps, optimum, states) or the reason it was skipped."""
    plan, visible, capacity, bin, max_states, seconds = job
    try:
        return gaps(plan, visible, capacity, bin, max_states=max_states, seconds=seconds)
    except OptimalTooLarge:
        return f"over {max_states:,} states"
    except OutOfTime:
        return f"over {seconds:g} s"


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
                                   visible=args.paired_visible), workers=args.workers)
    doc = summary(result)["strategies"]
    print(f"\n{plan.name} ({plan.n_units} units): paired Monte Carlo, {args.paired_trials} trials per policy "
          f"on the same bins, uniform bin, {args.paired_visible} visible, unlimited buffer "
          f"({time.perf_counter() - start:.0f} s)")
    print(f"  {'policy':<10} {'mean time':>10}  {'against paper (95% interval)':>32}  {'s/trial':>8}")
    for name in PAIRED:
        s = doc[name]
        against = s.get("paired")
        text = "—" if against is None else \
            f"{against['mean_difference']:+.3f} ({against['ci95'][0]:+.3f} .. {against['ci95'][1]:+.3f})"
        per = result.seconds.get(name, 0.0) / max(1, s["trials"])
        print(f"  {name:<10} {s['time']['mean']:>10.3f}  {text:>32}  {per:>8.3f}")
    if args.bound:      # the best any online policy can do is at least this (opportune.study.bounds)
        from opportune.study.bounds import lower_bound

        b = lower_bound(plan, visible=args.paired_visible, trials=min(args.paired_trials, 100), seed=args.seed)
        print(f"  lower bound on any online policy: {b.mean:.3f} ± {b.half_width:.3f} (95%; {b.method}); each mean "
              "above it: " + ", ".join(f"{n} {100 * (doc[n]['time']['mean'] / b.mean - 1):+.1f}%" for n in PAIRED))


def setting_name(visible: int, capacity: int | None, bin: str) -> str:
    return f"{bin}, {visible} visible, buffer {'unlimited' if capacity is None else capacity}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", type=int, default=30)
    ap.add_argument("--min-parts", type=int, default=8)
    ap.add_argument("--max-parts", type=int, default=12)
    ap.add_argument("--plans-dir", type=Path, help="also every plan file in this folder (.yaml, .json, .IN2, ...)")
    ap.add_argument("--visible", default="1,2,3", help="parts visible per look, comma-separated")
    ap.add_argument("--capacities", default="1,2,inf", help="buffer capacities, comma-separated (inf: unlimited)")
    ap.add_argument("--bins", default="uniform,pile", help="bins, comma-separated (uniform, pile)")
    ap.add_argument("--max-states", type=int, default=2_000_000, help="states of one exact programme, at most")
    ap.add_argument("--task-seconds", type=float, default=600.0, help="seconds for one plan in one setting, at most")
    ap.add_argument("--workers", type=int, default=1, help="worker processes (plans x settings, and the paired studies)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--plot", type=Path, help="write a dot plot of each policy's gap per plan here (PNG or PDF), "
                    "for the first setting")
    ap.add_argument("--paired", default="salbp:KILBRID,salbp:TONGE70",
                    help="plans compared by paired Monte Carlo (comma-separated; empty: none)")
    ap.add_argument("--paired-trials", type=int, default=200)
    ap.add_argument("--paired-visible", type=int, default=2, help="parts visible per look in the paired studies")
    ap.add_argument("--bound", action="store_true",
                    help="also a certified lower bound on any online policy beside the paired studies' means")
    args = ap.parse_args(argv)
    settings = [(v, None if c == "inf" else int(c), b) for b in args.bins.split(",")
                for v in map(int, args.visible.split(",")) for c in args.capacities.split(",")]

    rng = random.Random(args.seed)
    plans, two = [], set()
    for i in range(args.plans):
        n = rng.randint(args.min_parts, args.max_parts)
        k = 2 if i % 3 == 2 else 1                     # a third of the plans have two strategies
        density = rng.choice([0.1, 0.2, 0.3])
        plans.append(random_plan(rng, n, k, density, label=f"r{i}"))
        if k == 2:
            two.add(i)
    if args.plans_dir is not None:
        for path in sorted(args.plans_dir.iterdir()):
            if path.is_file() and not path.name.startswith("."):
                plan = load_plan(path)
                plans.append(plan)
                if len(plan.strategies) > 1:
                    two.add(len(plans) - 1)
    t0 = time.perf_counter()
    jobs = [(plan, *setting, args.max_states, args.task_seconds) for setting in settings for plan in plans]
    results = []

    def report(job, r) -> None:         # each plan in each setting as it is done (a full run takes hours)
        plan, setting = job[0], setting_name(*job[1:4])
        if isinstance(r, str):
            print(f"{setting}: {plan.name}: skipped ({r})", flush=True)
        else:
            print(f"{setting}: {plan.name}: optimum {r[1]:.4f} ({r[2]:,} states); "
                  + ", ".join(f"{p} {100 * v:+.3f}%" for p, v in r[0].items()), flush=True)
        results.append(r)

    if args.workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(args.workers) as pool:
            for job, r in zip(jobs, pool.map(_task, jobs)):
                report(job, r)
    else:
        for job in jobs:
            report(job, _task(job))
    table = []
    first_rows = []
    for s_i, setting in enumerate(settings):
        name = setting_name(*setting)
        rows, multi, skipped = [], [], []
        for p_i, plan in enumerate(plans):
            r = results[s_i * len(plans) + p_i]
            if isinstance(r, str):
                skipped.append(f"{plan.name} ({r})")
                continue
            rows.append(r[0])
            if p_i in two:
                multi.append(r[0])
        if rows:
            print_summary(f"random plans{' and the folder' * bool(args.plans_dir)}, {name}", rows)
            table.append((name, len(rows), len(skipped), summarise(rows)))
        if multi:
            print_summary(f"with two strategies, {name}", multi)
        if skipped:
            print(f"  skipped: {', '.join(skipped)}")
        if s_i == 0:
            first_rows = rows
    if table:
        names = list(table[0][3])
        print(f"\nevery setting: gap to the optimum, mean / max (%), over the plans evaluated ({len(plans)} plans)")
        print(f"  {'setting':<36} {'plans':>5} {'skipped':>7}  " + "  ".join(f"{n:>17}" for n in names))
        for name, done, skip, summ in table:
            print(f"  {name:<36} {done:>5} {skip:>7}  "
                  + "  ".join(f"{100 * summ[n][0]:>+8.3f} {100 * summ[n][2]:>+8.3f}" for n in names))

    gear = load_plan(GEARBOX)
    if args.plans:
        print("\ngearbox: gap to the optimum per setting")
        for visible, capacity, bin in settings:
            r = _task((gear, visible, capacity, bin, args.max_states, args.task_seconds))
            if isinstance(r, str):
                print(f"  {setting_name(visible, capacity, bin):<36}: skipped ({r})")
                continue
            g, best, _ = r
            print(f"  {setting_name(visible, capacity, bin):<36}: optimum {best:.4f}; "
                  + ", ".join(f"{p} {100 * v:+.3f}%" for p, v in g.items()))
        print(f"\n{time.perf_counter() - t0:.0f} s")
    rows = first_rows
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
                     f"({args.min_parts}-{args.max_parts} parts; {setting_name(*settings[0])})", fontsize=9)
        ax.axhline(0, color="grey", lw=0.8)
        fig.tight_layout()
        args.plot.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.plot, metadata={"Date": None} if args.plot.suffix == ".pdf" else None)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
