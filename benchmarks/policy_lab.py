"""The policy lab: every policy evaluated exactly against the optimum, in every setting, on random plans,
the gearbox and any folder of plans.

For ``--plans`` random plans (``--min-parts`` to ``--max-parts`` parts, one or two strategies, a
range of densities; seeded) and every plan file in ``--plans-dir``, each policy's exact expected
time (:class:`~opportune.policies.evaluate.PolicyEvaluator` in the uniform bin,
:class:`~opportune.policies.pile.PileSolver` in the pile) is divided by the optimum's, in every
setting of ``--visible`` (1, 2, 3) × ``--capacities`` (1, 2, unlimited) × ``--bins`` (uniform, pile);
the tables give the mean, median and largest gap per policy and setting (``--table``, ``--readme``
and ``--plot`` write them and the gap per setting), over all plans and over
those with two strategies, and how many plans a setting skipped (the optimum over ``--max-states``
states, or a plan's evaluation over ``--task-seconds``: said, never hidden).  Then the gearbox in
every setting.  No Monte Carlo: every number is exact.

Plans too large for exact evaluation (``--paired``, default KILBRID and TONGE70) are compared by
paired Monte Carlo instead: every policy runs on the same ``--paired-trials`` random bins (trial
``i`` of each sees the same bin), and the table gives each policy's mean time and its mean
difference from the paper's rule with the 95% interval of that difference (Student's t).

    python benchmarks/policy_lab.py                    # 30 plans of 8-12 parts, every setting, then KILBRID and TONGE70
    python benchmarks/policy_lab.py --results lab.jsonl --table docs/policy-lab.md --readme README.md \
        --plot docs/img/policy-lab.png --workers 2     # resumable; writes the tables and the figure
    python benchmarks/policy_lab.py --plans 10 --visible 2 --capacities inf --bins uniform --policies lookahead
    python benchmarks/policy_lab.py --plans 6 --min-parts 16 --max-parts 30 --visible 1 --capacities 1 \
        --bins uniform --policies lookahead --without-optimum --paired ""   # the fallback beside the optimum
    python benchmarks/policy_lab.py --plans 0 --plans-dir my-plans/ --paired ""
    python benchmarks/policy_lab.py --plans 0 --paired salbp:KILBRID --paired-trials 400
    python benchmarks/policy_lab.py --plans 0 --paired salbp:KILBRID --bound   # and a lower bound beside the means
"""

from __future__ import annotations

import argparse
import json
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
from opportune.policies.pile import PileSolver, pile_solver
from opportune.policies.opportunistic import Opportunistic
from opportune.policies.variants import BinFirst, Slack
from opportune.policies.lookahead import Lookahead

HERE = Path(__file__).resolve().parent
GEARBOX = HERE.parent / "examples" / "gearbox.yaml"


def policies(visible: int, capacity: int | None, bin: str = "uniform"):
    """The lab's policies by name; ``fallback`` is the default (lookahead) with its exact optimum switched
    off (``--without-optimum``): what decides where the optimum's programme does not fit."""
    return {"paper": Opportunistic(), "bin-first": BinFirst(), "slack": Slack(),
            "lookahead": Lookahead(visible=visible, capacity=capacity, bin=bin),
            "fallback": Lookahead(visible=visible, capacity=capacity, bin=bin, optimal=False)}


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
         seconds: float | None = None, only=None, compiled: bool = False) -> tuple[dict[str, float], float, int]:
    """Each policy's exact expected time over the optimum's, less one; the optimum; its states.  Raises
    OptimalTooLarge past ``max_states`` states and OutOfTime past ``seconds`` (the whole plan).  ``compiled``:
    the pile's optimum by the compiled core where it is built (the same values, far sooner)."""
    engine = OrderEngine(plan)
    deadline = Deadline.after(seconds) if seconds is not None else None
    settings = dict(visible=visible, capacity=capacity, max_states=max_states)
    if bin == "pile":
        optimum = (pile_solver if compiled else PileSolver)(engine, **settings)
        optimum.deadline = deadline
        best, states = optimum.value(), optimum.states
    out = {}
    for name, policy in policies(visible, capacity, bin).items():
        if only is not None and name not in only:
            continue
        ev = PileSolver(engine, policy, **settings) if bin == "pile" else PolicyEvaluator(engine, policy, **settings)
        ev.deadline = deadline
        value = ev.value()
        if bin != "pile" and not out:
            best, states = ev.optimal(), ev.states
        out[name] = value / best - 1
    return out, best, states


def _task(job):
    """One plan in one setting (a worker's job): (gaps, optimum, states) or the reason it was skipped."""
    plan, visible, capacity, bin, max_states, seconds, only, compiled = job
    try:
        return gaps(plan, visible, capacity, bin, max_states=max_states, seconds=seconds, only=only, compiled=compiled)
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
    from opportune.study.report import summary
    from opportune.study.simulate import StudyConfig, run_study

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
        from opportune.study.bounds import describe_gaps, lower_bound, policy_gaps

        b = lower_bound(plan, visible=args.paired_visible, trials=min(args.paired_trials, 100), seed=args.seed)
        print(f"  lower bound on any online policy: {b.mean:.3f} ± {b.half_width:.3f} (95%; {b.method}); each "
              "mean against it: " + describe_gaps(policy_gaps(b, {n: doc[n]["time"] for n in PAIRED})))


def setting_name(visible: int, capacity: int | None, bin: str) -> str:
    return f"{bin}, {visible} visible, buffer {'unlimited' if capacity is None else capacity}"


POLICIES = ("paper", "bin-first", "slack", "lookahead", "fallback")
DEFAULT_POLICIES = POLICIES[:4]     # the fallback with --without-optimum (or --policies)
TABLE_HEAD = "| setting | plans | skipped |"      # how --readme finds the lab's table in a document
SKIPPED_TAIL = "plan-settings skipped"


def _key(args, plan, setting) -> str:
    """A job's identity in ``--results``: the plans' generator, the plan, the setting and the cap."""
    visible, capacity, bin = setting
    return (f"{args.seed}:{args.min_parts}-{args.max_parts}:{plan.name}:{visible}:"
            f"{'inf' if capacity is None else capacity}:{bin}:{args.max_states}")


def _keep(done: dict, key: str, rec: dict, max_states: int) -> None:
    """Read one line of ``--results`` into ``done``. An exact result stands whatever state cap it was
    run with (the cap decides only whether a plan is skipped), so it is filed under this run's cap; a
    later line wins, its gaps added to an earlier result's (a rerun of one policy keeps the others'),
    and a skip never hides a result."""
    if "skipped" not in rec:
        key = f"{key.rsplit(':', 1)[0]}:{max_states}"
    old = done.get(key)
    if "skipped" in rec:
        if old is None or "skipped" in old:
            done[key] = rec
        return
    if old is not None and "skipped" not in old:
        rec = {**rec, "gaps": {**old["gaps"], **rec["gaps"]}}
    done[key] = rec


def _record(plan, setting, r, two: bool) -> dict:
    visible, capacity, bin = setting
    out = {"plan": plan.name, "visible": visible, "capacity": capacity, "bin": bin, "two_strategies": two}
    if isinstance(r, str):
        out["skipped"] = r
    else:
        out.update(gaps=r[0], optimum=r[1], states=r[2])
    return out


def _run_jobs(jobs, args, done: dict, sink) -> None:
    """Run the jobs not in ``done``, each reported as it finishes (a full run takes hours) and appended
    to ``--results`` at once, so that an interrupted run goes on from where it stopped."""
    def needed(key) -> bool:          # not run, skipped (with --redo-skipped), or without a policy asked for
        rec = done.get(key)
        if rec is None or "skipped" in rec:
            return rec is None or args.redo_skipped
        return not set(args.policies) <= set(rec["gaps"])

    todo = [j for j in jobs if needed(j[0])]

    def report(job, r) -> None:
        key, plan, setting, two = job
        rec = _record(plan, setting, r, two)
        done[key] = rec
        if isinstance(r, str):
            print(f"{setting_name(*setting)}: {plan.name}: skipped ({r})", flush=True)
        else:
            print(f"{setting_name(*setting)}: {plan.name}: optimum {r[1]:.4f} ({r[2]:,} states); "
                  + ", ".join(f"{p} {100 * v:+.3f}%" for p, v in r[0].items()), flush=True)
        if sink is not None:
            sink.write(json.dumps({"key": key, **rec}) + "\n")
            sink.flush()

    tasks = [(plan, *setting, args.max_states, args.task_seconds, args.policies, args.compiled_optimum)
             for _, plan, setting, _ in todo]
    if args.workers > 1 and len(todo) > 1:
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(args.workers) as pool:
            futures = {pool.submit(_task, t): job for t, job in zip(tasks, todo)}
            for f in as_completed(futures):
                report(futures[f], f.result())
    else:
        for t, job in zip(tasks, todo):
            report(job, _task(t))


def setting_rows(records: list[dict], names) -> tuple[list[dict], list[str], list[dict]]:
    """The evaluated gaps, the skipped plans (with why) and the gaps of the plans with two strategies."""
    rows = [r["gaps"] for r in records if "gaps" in r]
    skipped = [f"{r['plan']} ({r['skipped']})" for r in records if "skipped" in r]
    multi = [r["gaps"] for r in records if "gaps" in r and r["two_strategies"]]
    return [{n: g[n] for n in names} for g in rows], skipped, [{n: g[n] for n in names} for g in multi]


def pct(x: float) -> str:
    """A gap in percent; a rounding error's minus sign on an exact 0 is not shown."""
    v = 100 * x
    return f"{0.0 if abs(v) < 5e-4 else v:+.3f}%"


def markdown(settings, per_setting, gear, names, n_plans: int, brief: bool = False) -> str:
    """The lab's tables in Markdown: every setting's gaps over the plans, and the gearbox's (``brief``: the
    first table alone, and how many were skipped)."""
    head = "| setting | plans | skipped | " + " | ".join(f"{n} mean | {n} max" for n in names) + " |"
    lines = [head, "| --- | ---: | ---: | " + " | ".join("---: | ---:" for _ in names) + " |"]
    for setting in settings:
        rows, skipped, _ = per_setting[setting]
        if not rows:
            lines.append(f"| {setting_name(*setting)} | 0 | {len(skipped)} | " + " | ".join("— | —" for _ in names) + " |")
            continue
        s = summarise(rows)
        lines.append(f"| {setting_name(*setting)} | {len(rows)} | {len(skipped)} | "
                     + " | ".join(f"{pct(s[n][0])} | {pct(s[n][2])}" for n in names) + " |")
    out = [f"Gap of each policy's exact expected time to the optimum's, over {n_plans} plans "
           "(mean and largest); a plan is skipped when its optimum's programme is over the lab's "
           "state cap or time, or was not run, and then listed below."
           + (" `fallback` is the default (`lookahead`) with its exact optimum switched off (`--without-optimum`): "
              "what decides where the optimum's programme does not fit." if "fallback" in names else ""), "", *lines]
    skips = [(setting_name(*st), per_setting[st][1]) for st in settings if per_setting[st][1]]
    if brief:
        n_skip = sum(len(s) for _, s in skips)
        return "\n".join(out + ["", f"{n_skip} {SKIPPED_TAIL}, each listed in docs/policy-lab.md."] * bool(n_skip)) + "\n"
    if skips:
        out += ["", "Skipped: " + "; ".join(f"{name}: {', '.join(s)}" for name, s in skips) + "."]
    if gear:
        out += ["", "The gearbox:", "",
                "| setting | optimum | " + " | ".join(names) + " |",
                "| --- | ---: | " + " | ".join("---:" for _ in names) + " |"]
        for setting in settings:
            r = gear.get(setting)
            if r is None:
                continue
            if "skipped" in r:
                out.append(f"| {setting_name(*setting)} | skipped ({r['skipped']}) | " + " | ".join("—" for _ in names) + " |")
            else:
                out.append(f"| {setting_name(*setting)} | {r['optimum']:.4f} | "
                           + " | ".join(pct(r['gaps'][n]) for n in names) + " |")
    return "\n".join(out) + "\n"


def replace_block(path: Path, text: str) -> None:
    """Put ``text`` in place of the lab's table in ``path``: the Markdown table whose header starts with
    :data:`TABLE_HEAD`, with the line after it that says how many were skipped (the table must be there)."""
    lines = path.read_text().split("\n")
    start = next((k for k, line in enumerate(lines) if line.startswith(TABLE_HEAD)), None)
    if start is None:
        raise SystemExit(f"{path}: no lab table (a line starting {TABLE_HEAD!r}); put one where the table goes")
    end = start
    while end < len(lines) and lines[end].startswith("|"):
        end += 1
    if end + 1 < len(lines) and not lines[end] and SKIPPED_TAIL in lines[end + 1]:
        end += 2
    new = text.rstrip("\n").split("\n")
    new = new[next(k for k, line in enumerate(new) if line.startswith(TABLE_HEAD)):]
    path.write_text("\n".join(lines[:start] + new + lines[end:]))


def plot_settings(path: Path, settings, per_setting, names) -> None:
    """One row per setting: each policy's mean gap (dot) and largest gap (end of its line)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams["svg.fonttype"] = "none"
    shown = [st for st in settings if per_setting[st][0]]
    fig, ax = plt.subplots(figsize=(7, 0.28 * len(shown) + 1.2), dpi=150)
    for j, name in enumerate(names):
        for i, st in enumerate(shown):
            s = summarise(per_setting[st][0])[name]
            y = i + (j - (len(names) - 1) / 2) * 0.18
            ax.plot([100 * s[0], 100 * s[2]], [y, y], color=f"C{j}", lw=1)
            ax.plot([100 * s[0]], [y], "o", color=f"C{j}", ms=3.5, label=name if i == 0 else None)
    ax.set_yticks(range(len(shown)), [f"{setting_name(*st)} ({len(per_setting[st][0])})" for st in shown], fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("symlog", linthresh=0.01)
    ax.set_xlabel("gap to the optimum (%): mean (dot) to largest (line end); dashed: 0.3%", fontsize=8)
    ax.axvline(0, color="grey", lw=0.6)
    ax.tick_params(axis="x", labelsize=7)
    # gaps are never below 0 but by rounding; the right edge past the largest gap and the 0.3% mark
    top = max([0.3] + [100 * summarise(per_setting[st][0])[n][2] for st in shown for n in names])
    ax.axvline(0.3, color="grey", lw=0.6, ls="--")
    ticks = [t for t in (0, 0.01, 0.1, 0.3, 1, 3, 10, 30, 100) if t <= top * 1.5]
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
    ax.set_xlim(-0.002, top * 1.5)
    ax.legend(fontsize=7, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=len(names), frameon=False)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, metadata={"Date": None} if path.suffix == ".pdf" else None)
    plt.close(fig)
    print(f"wrote {path}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", type=int, default=30)
    ap.add_argument("--min-parts", type=int, default=8)
    ap.add_argument("--max-parts", type=int, default=12)
    ap.add_argument("--plans-dir", type=Path, help="also every plan file in this folder (.yaml, .json, .IN2, ...)")
    ap.add_argument("--visible", default="1,2,3", help="parts visible per look, comma-separated")
    ap.add_argument("--capacities", default="1,2,inf", help="buffer capacities, comma-separated (inf: unlimited)")
    ap.add_argument("--bins", default="uniform,pile", help="bins, comma-separated (uniform, pile)")
    ap.add_argument("--policies", default=",".join(DEFAULT_POLICIES),
                    help=f"policies evaluated against the optimum, comma-separated ({', '.join(POLICIES)})")
    ap.add_argument("--without-optimum", action="store_true",
                    help="also the default policy with its exact optimum switched off (the column 'fallback'): "
                         "its fallback measured where the optimum is known")
    ap.add_argument("--only", default="", help="only these plans (names, comma-separated: r3-11, gearbox, ...)")
    ap.add_argument("--compiled-optimum", action="store_true",
                    help="the pile's optimum by the compiled core (the same values as the Python programme, 32-46x sooner)")
    ap.add_argument("--max-states", type=int, default=2_000_000, help="states of one exact programme, at most")
    ap.add_argument("--task-seconds", type=float, default=600.0, help="seconds for one plan in one setting, at most")
    ap.add_argument("--workers", type=int, default=1, help="worker processes (plans x settings, and the paired studies)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", type=Path, help="append every plan-setting's result here (JSON lines) and skip "
                    "those already there: an interrupted run goes on where it stopped")
    ap.add_argument("--redo-skipped", action="store_true", help="run again the plan-settings --results has as skipped")
    ap.add_argument("--table", type=Path, help="write the tables in Markdown here")
    ap.add_argument("--readme", type=Path, help="replace the every-setting table in this file (found by its header)")
    ap.add_argument("--plot", type=Path, help="write the gap per setting here (PNG or PDF)")
    ap.add_argument("--paired", default="salbp:KILBRID,salbp:TONGE70",
                    help="plans compared by paired Monte Carlo (comma-separated; empty: none)")
    ap.add_argument("--paired-trials", type=int, default=200)
    ap.add_argument("--paired-visible", type=int, default=2, help="parts visible per look in the paired studies")
    ap.add_argument("--bound", action="store_true",
                    help="also a certified lower bound on any online policy beside the paired studies' means")
    args = ap.parse_args(argv)
    args.policies = tuple(p for p in args.policies.split(",") if p)
    if args.without_optimum and "fallback" not in args.policies:
        args.policies += ("fallback",)
    unknown = set(args.policies) - set(POLICIES)
    if unknown or not args.policies:
        ap.error(f"--policies: unknown {', '.join(sorted(unknown)) or '(none given)'}; choose from {', '.join(POLICIES)}")
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
    gear = load_plan(GEARBOX)
    t0 = time.perf_counter()
    only = {name for name in args.only.split(",") if name}
    unknown = only - {plan.name for plan in plans} - {gear.name}
    if unknown:
        ap.error(f"--only: no plan named {', '.join(sorted(unknown))}; the plans are {', '.join(p.name for p in plans)}, "
                 f"{gear.name}")
    jobs = [(_key(args, plan, s), plan, s, i in two) for s in settings for i, plan in enumerate(plans)
            if not only or plan.name in only]
    gear_jobs = [(_key(args, gear, s), gear, s, False) for s in settings
                 if args.plans and (not only or gear.name in only)]
    done: dict[str, dict] = {}
    if args.results is not None and args.results.exists():
        for line in args.results.read_text().splitlines():
            if line.strip():
                rec = json.loads(line)
                _keep(done, rec.pop("key"), rec, args.max_states)
    n_plans = len({plan.name for _, plan, _, _ in jobs})
    sink = None if args.results is None else args.results.open("a")
    try:
        _run_jobs(jobs + gear_jobs, args, done, sink)
    finally:
        if sink is not None:
            sink.close()

    names = list(args.policies)
    per_setting = {}
    table = []
    for setting in settings:
        name = setting_name(*setting)
        recs = [done.get(key, {"plan": plan.name, "skipped": "not run"}) for key, plan, s, _ in jobs if s == setting]
        rows, skipped, multi = setting_rows(recs, names)
        per_setting[setting] = (rows, skipped, multi)
        if rows:
            print_summary(f"random plans{' and the folder' * bool(args.plans_dir)}, {name}", rows)
            table.append((name, len(rows), len(skipped), summarise(rows)))
        if multi:
            print_summary(f"with two strategies, {name}", multi)
        if skipped:
            print(f"  skipped: {', '.join(skipped)}")
    if table:
        print(f"\nevery setting: gap to the optimum, mean / max (%), over the plans evaluated ({n_plans} plans)")
        print(f"  {'setting':<36} {'plans':>5} {'skipped':>7}  " + "  ".join(f"{n:>17}" for n in names))
        for name, n_done, skip, summ in table:
            print(f"  {name:<36} {n_done:>5} {skip:>7}  "
                  + "  ".join(f"{100 * summ[n][0]:>+8.3f} {100 * summ[n][2]:>+8.3f}" for n in names))
    gear_done = {s: done[key] for key, _, s, _ in gear_jobs if key in done}
    if gear_done:
        print("\ngearbox: gap to the optimum per setting")
        for setting, r in gear_done.items():
            if "skipped" in r:
                print(f"  {setting_name(*setting):<36}: skipped ({r['skipped']})")
            else:
                print(f"  {setting_name(*setting):<36}: optimum {r['optimum']:.4f}; "
                      + ", ".join(f"{p} {100 * r['gaps'][p]:+.3f}%" for p in names))
    print(f"\n{time.perf_counter() - t0:.0f} s")
    text = markdown(settings, per_setting, gear_done, names, n_plans)
    if args.table:
        args.table.parent.mkdir(parents=True, exist_ok=True)
        args.table.write_text("# The policy lab\n\nWritten by `benchmarks/policy_lab.py --table`; how it works: "
                              "[the paper's comparison](comparison.md).\n\n" + text)
        print(f"wrote {args.table}")
    if args.readme:
        replace_block(args.readme, markdown(settings, per_setting, gear_done, names, n_plans, brief=True))
        print(f"wrote the lab's table into {args.readme}")
    if args.plot:
        plot_settings(args.plot, settings, per_setting, names)
    for spec in filter(None, args.paired.split(",")):
        paired(spec, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
