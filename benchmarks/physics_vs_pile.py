"""Is the pile a fair model of a physical bin?  The paper's comparison on the gearbox in the abstract
bins (uniform, pile) and in the physical bin (MuJoCo), in time units and in seconds of the default cell.

Not a test: prints the table of docs/physics.md (markdown), the physical bin's trial rate (CPU seconds
per trial, one core), and draws docs/img/physics-vs-pile.png.

    python benchmarks/physics_vs_pile.py [--trials N] [--abstract-trials N] [--workers W] [--plan example:gearbox]
                                         [--summaries FILE] [--figure PNG]

``--summaries FILE`` keeps the three studies' summaries in FILE (JSON) and, when it exists, draws the figure
and prints the table from it without running the studies again.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

from opportune import load_plan
from opportune.study.report import COLUMN_WIDTHS, OKABE_ITO, figure_style, label, summary
from opportune.study.simulate import STRATEGIES, StudyConfig, run_study

ROOT = Path(__file__).resolve().parents[1]
BINS = ("uniform", "pile", "physics")
STYLE = {"uniform": (OKABE_ITO["sky blue"], "s"), "pile": (OKABE_ITO["orange"], "o"),
         "physics": (OKABE_ITO["blue"], "D")}


def study(plan, bin_model, trials, workers):
    strategies = tuple(s for s in STRATEGIES if s not in ("optimal", "random"))
    config = StudyConfig(plan, strategies=strategies, trials=trials, bin=bin_model, seed=0)
    began = time.perf_counter()
    result = run_study(config, workers=workers)
    return result, summary(result), time.perf_counter() - began


def figure(docs: dict, out: Path) -> None:
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    names = sorted(docs["physics"]["strategies"], key=lambda n: docs["physics"]["strategies"][n]["cycle_seconds"]["mean"])
    with matplotlib.rc_context(figure_style()):
        # the double column: the narrowest intervals (about ±1 s) then show beside 3-point markers
        fig = Figure(figsize=(COLUMN_WIDTHS["double"], 1.0 + 0.3 * len(names)), layout="constrained")
        FigureCanvasAgg(fig)
        ax = fig.subplots()
        offsets = {b: (i - 1) * 0.22 for i, b in enumerate(BINS)}
        for b, doc in docs.items():
            colour, marker = STYLE[b]
            for y, name in enumerate(names):
                s = doc["strategies"][name]["cycle_seconds"]
                ax.errorbar([s["mean"]], [y + offsets[b]], xerr=[[s["mean"] - s["ci95"][0]], [s["ci95"][1] - s["mean"]]],
                            fmt=marker, ms=3.0, mfc="none", mec=colour, mew=0.9, ecolor=colour, elinewidth=1.0,
                            capsize=2.0, capthick=1.0)
        ax.set_yticks(range(len(names)), [label(n) for n in names])
        ax.set_ylim(len(names) - 0.5, -0.5)
        ax.set_xlabel("mean cycle time per assembly in the default cell, seconds, with its 95% interval")
        ax.grid(axis="x", alpha=0.35)
        trials = {b: d["trials"] for b, d in docs.items()}
        fig.suptitle(f"{docs['physics']['plan']}: the paper's strategies in three bins; 2 visible, unlimited buffer; "
                     f"trials per strategy: uniform and pile {trials['pile']:,}, physics {trials['physics']:,}",
                     x=0.01, ha="left")
        fig.legend(handles=[Line2D([], [], linestyle="none", marker=STYLE[b][1], mfc="none", mec=STYLE[b][0], ms=3.0,
                                   label=f"{b} bin") for b in BINS],
                   loc="outside lower center", ncols=3, frameon=False)
        fig.savefig(out, dpi=300, metadata={"Software": None})


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, default=200, help="trials per strategy in the physical bin")
    ap.add_argument("--abstract-trials", type=int, default=10_000, help="trials per strategy in uniform and pile")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--plan", default="example:gearbox")
    ap.add_argument("--summaries", type=Path, default=None)
    ap.add_argument("--figure", type=Path, default=ROOT / "docs/img/physics-vs-pile.png")
    args = ap.parse_args()
    plan = load_plan(args.plan)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    docs = json.loads(args.summaries.read_text()) if args.summaries and args.summaries.exists() else {}
    for b in BINS if not docs else ():
        result, doc, wall = study(plan, b, args.trials if b == "physics" else args.abstract_trials, args.workers)
        docs[b] = doc
        cpu = sum(result.cpu_seconds.values())
        n = sum(len(t) for t in result.trials.values())
        print(f"{b}: {n:,} trials in {wall:.1f} s wall on {args.workers} workers, {cpu:.1f} CPU s: "
              f"{n / cpu:,.1f} trials/s on one core; per strategy (CPU s per trial): "
              + ", ".join(f"{s} {result.cpu_seconds[s] / len(t):.3f}" for s, t in result.trials.items()))
    if args.summaries and not args.summaries.exists():
        args.summaries.write_text(json.dumps(docs))
    names = sorted(docs["physics"]["strategies"], key=lambda n: docs["physics"]["strategies"][n]["cycle_seconds"]["mean"])
    print()
    print("| strategy | " + " | ".join(f"{b}: time units | {b}: cycle s" for b in BINS) + " | physics: shakes |")
    print("|---|" + "---:|" * (2 * len(BINS) + 1))
    for name in names:
        cells = []
        for b in BINS:
            s = docs[b]["strategies"][name]
            half = lambda m: (s[m]["ci95"][1] - s[m]["ci95"][0]) / 2
            cells += [f"{s['time']['mean']:.2f} ± {half('time'):.2f}", f"{s['cycle_seconds']['mean']:.1f} ± {half('cycle_seconds'):.1f}"]
        cells.append(f"{docs['physics']['strategies'][name]['shakes']['mean']:.2f}")
        print(f"| {label(name)} | " + " | ".join(cells) + " |")
    figure(docs, args.figure)
    print(f"\nwrote {args.figure}")


if __name__ == "__main__":
    main()
