"""The learning curve: how many observed sequences it takes to learn the gearbox's plan exactly.

Each repetition draws ``--max-k`` uniformly random admissible sequences of the true plan (exactly
uniform: :meth:`opportune.engine.count.Counter.sample`, seeded per repetition) and, for every
``k = 1 .. --max-k``, learns a plan from the first ``k`` of them (:func:`opportune.derive.learn.learn_plan`).
The sequences of one repetition are nested (its ``k + 1`` sequences are its ``k`` plus one), so a
repetition recovers the plan from some ``k`` on.  Per ``k``, over the repetitions:

* **recovered**: the fraction whose learned order is the true one (same transitive closure);
* **wrong covers**: the mean number of cover constraints of the learned plan that the true plan does
  not have (learning only ever adds constraints: the true plan admits every observed sequence);
* **flagged wrong / flagged right**: the mean number of wrong (and of right) cover constraints whose
  accident probability is above 0.05, i.e. how well the accident probability points at the wrong ones.

Past ``--max-k`` (up to ``--recovery-k``) only the recovered fraction is measured, from the learned
order alone (no counting), to find where recovery reaches 99%.

    python benchmarks/learning_curve.py                          # gearbox, k = 1..60 (150), 200 repetitions
    python benchmarks/learning_curve.py --plot docs/img/learning-curve.png
    python benchmarks/learning_curve.py --plan salbp:MERTENS --reps 50
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path

from opportune.engine import OrderEngine
from opportune.formats.loader import read_plan
from opportune.derive.learn import learn_plan, learned_order


def closure_pairs(plan) -> set[tuple[str, str]]:
    """The (single-strategy) plan's order, transitively closed, as (before, after) id pairs."""
    from opportune.engine.poset import Poset

    ids = plan.part_ids
    poset = Poset.from_pairs(len(ids), plan.index_pairs(plan.strategies[0]))
    return {(ids[a], ids[b]) for a in range(len(ids)) for b in bits_of(poset.above[a])}


def bits_of(mask: int):
    while mask:
        low = mask & -mask
        yield low.bit_length() - 1
        mask ^= low


def curve(plan, max_k: int, reps: int, seed: int, max_accident: float = 0.05, recovery_k: int = 0) -> list[dict]:
    """One row per k: recovered fraction, mean wrong covers, mean flagged wrong / right covers; rows past
    ``max_k`` (up to ``recovery_k``) give the recovered fraction only (no counting: the order alone)."""
    if len(plan.strategies) != 1:
        raise SystemExit(f"{plan.name} has {len(plan.strategies)} strategies; the curve needs one")
    engine = OrderEngine(plan)
    counter = engine.counter(1)
    true = closure_pairs(plan)
    ids = [plan.parts[i].id for i in engine.unit_part]
    last = max(max_k, recovery_k)
    rows = [{"k": k, "recovered": 0, "wrong": 0, "flagged_wrong": 0, "flagged_right": 0, "right": 0}
            for k in range(1, last + 1)]
    parts = list(plan.part_ids)
    for rep in range(reps):
        rng = random.Random(seed * 1_000_003 + rep)
        seqs = [[ids[u] for u in counter.sample(rng)] for _ in range(last)]
        for row in rows[max_k:]:
            order = learned_order(seqs[:row["k"]], parts)
            row["recovered"] += {(parts[a], parts[b]) for a in range(len(parts))
                                 for b in bits_of(order.above[a])} == true
        for row in rows[:max_k]:
            learned = learn_plan(seqs[:row["k"]], max_accident=max_accident, time_limit=None)
            got = closure_pairs(learned.plan)
            row["recovered"] += got == true
            for c in learned.constraints:
                right = (c.before, c.after) in true
                flagged = c.accident_probability > max_accident
                row["right" if right else "wrong"] += 1
                row["flagged_right" if right else "flagged_wrong"] += flagged
    for row in rows:
        for key in ("recovered", "wrong", "flagged_wrong", "flagged_right", "right"):
            row[key] /= reps
    return rows


def first_k(rows: list[dict], level: float) -> int | None:
    return next((r["k"] for r in rows if r["recovered"] >= level), None)


def plot(rows: list[dict], path: Path, title: str, max_k: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ks = [r["k"] for r in rows]
    full = rows[:max_k]
    fig, left = plt.subplots(figsize=(7.5, 4.2))
    left.plot(ks, [r["recovered"] for r in rows], color="tab:blue", lw=2, label="P(plan recovered exactly)")
    left.set_xlabel("observed sequences k (uniformly random admissible sequences)")
    left.set_ylabel("probability of exact recovery", color="tab:blue")
    left.set_ylim(0, 1.02)
    left.grid(alpha=0.3)
    right = left.twinx()
    ks = ks[:max_k]
    right.plot(ks, [r["wrong"] for r in full], color="tab:red", lw=1.5, label="wrong cover constraints (mean)")
    right.plot(ks, [r["flagged_wrong"] for r in full], color="tab:red", lw=1, ls="--",
               label="… of them flagged (accident > 0.05)")
    right.plot(ks, [r["flagged_right"] for r in full], color="tab:gray", lw=1, ls=":",
               label="right constraints flagged (mean)")
    right.set_ylabel("constraints per learned plan", color="tab:red")
    right.set_ylim(bottom=0)
    lines = left.get_lines() + right.get_lines()
    left.legend(lines, [ln.get_label() for ln in lines], loc="center right", fontsize=8)
    left.set_title(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plan", default="example:gearbox", help="single-strategy plan (default example:gearbox)")
    ap.add_argument("--max-k", type=int, default=60, help="largest number of observed sequences (default 60)")
    ap.add_argument("--recovery-k", type=int, default=150,
                    help="extend the recovered fraction alone up to this k (default 150)")
    ap.add_argument("--reps", type=int, default=200, help="repetitions per k (default 200)")
    ap.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    ap.add_argument("--plot", type=Path, help="write the plot here (PNG)")
    args = ap.parse_args(argv)
    result = read_plan(args.plan)
    if not result.ok:
        raise SystemExit("\n".join(str(p) for p in result.errors))
    plan = result.plan
    start = time.perf_counter()
    rows = curve(plan, args.max_k, args.reps, args.seed, recovery_k=args.recovery_k)
    elapsed = time.perf_counter() - start
    print(f"{plan.name}: {args.reps} repetitions, seed {args.seed}, {elapsed:.1f} s")
    print(f"{'k':>3}  {'recovered':>9}  {'wrong':>6}  {'flagged wrong':>13}  {'right':>6}  {'flagged right':>13}")
    for r in rows[:args.max_k]:
        print(f"{r['k']:>3}  {r['recovered']:>9.3f}  {r['wrong']:>6.2f}  {r['flagged_wrong']:>13.2f}  "
              f"{r['right']:>6.2f}  {r['flagged_right']:>13.2f}")
    for level in (0.5, 0.9, 0.99):
        k = first_k(rows, level)
        print(f"recovered with probability >= {level:g} from k = {k if k is not None else f'> {len(rows)}'}")
    if len(rows) > args.max_k:
        print("recovered, further k: " + ", ".join(f"{r['k']}: {r['recovered']:.3f}" for r in rows[args.max_k::10]))
    if args.plot:
        plot(rows, args.plot, f"Learning {plan.name}'s plan from k random admissible sequences "
                              f"({args.reps} repetitions)", args.max_k)
        print(f"wrote {args.plot}", file=sys.stderr)


if __name__ == "__main__":
    main()
