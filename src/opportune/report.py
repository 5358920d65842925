"""Tables, files and plots of a simulation study.

``results.json`` (the ``--json`` document, with what made it under
``provenance`` and the run's timings apart under ``timing``), ``trials.csv``
(one row per trial), and plots as PNG, SVG and PDF: the distribution of total
time per strategy, the mean time with its 95% confidence interval against the
optimum, and, when the optimum is known, each mean's ratio to it.
"""

from __future__ import annotations

import csv
import json
import math
import shlex
import sys
from pathlib import Path

from opportune.simulate import METRICS, StudyResult

LABELS = {
    "pallet": "pallet (eliminate)",
    "shake": "shake (reduce)",
    "kitting": "kitting (restore)",
    "buffer": "buffer (restore, intelligent)",
    "quantify": "quantify (statistics)",
    "opportunistic": "opportunistic",
    "random": "random (ablation)",
    "optimal": "optimal",
    "paper": "paper (the paper's rule)",
    "bin-first": "bin-first",
    "slack": "slack",
    "lookahead": "lookahead",
    "rollout": "rollout",
}


def describe(values: list[float]) -> dict:
    """Mean, standard deviation, p5/p50/p95, max and the 95% confidence interval of the mean."""
    n = len(values)
    if n == 0:
        return {"n": 0, "mean": None, "sd": None, "p5": None, "p50": None, "p95": None, "max": None, "ci95": None}
    xs = sorted(values)
    mean = sum(xs) / n
    sd = math.sqrt(sum((x - mean) ** 2 for x in xs) / (n - 1)) if n > 1 else 0.0
    half = 1.959963984540054 * sd / math.sqrt(n)

    def q(p):  # linear interpolation between order statistics (numpy's default)
        pos = (n - 1) * p
        lo = math.floor(pos)
        hi = min(lo + 1, n - 1)
        return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)

    return {"n": n, "mean": mean, "sd": sd, "p5": q(0.05), "p50": q(0.5), "p95": q(0.95), "max": xs[-1],
            "ci95": [mean - half, mean + half]}


def summary(result: StudyResult) -> dict:
    """The study as the ``--json`` document."""
    cfg = result.config
    optimum = result.prepared.optimal_start
    strategies = {}
    for name, trials in result.trials.items():
        doc = {m: describe([getattr(t, m) for t in trials]) for m in METRICS}
        doc["buffer_peak"] = doc["buffer_peak"]
        doc["trials"] = len(trials)
        doc["incomplete"] = sum(not t.complete for t in trials)
        mean_time = doc["time"]["mean"]
        doc["ratio_to_optimal"] = (mean_time / optimum) if optimum and mean_time is not None else None
        if name == "optimal":
            doc["expected_time"] = optimum
            doc["states"] = result.prepared.optimal_states
        if name == "quantify":
            doc["training_runs"] = cfg.training_runs
        strategies[name] = doc
    reference = next((r for r in ("opportunistic", "paper") if result.trials.get(r)), None)
    if reference is not None:
        for name, trials in result.trials.items():
            paired = paired_difference(trials, result.trials[reference]) if name != reference and trials else None
            if paired is not None:
                strategies[name]["paired"] = {"with": reference, **paired}
    return {
        "plan": cfg.plan.name,
        "bin": cfg.bin,
        "visible": cfg.visible,
        "buffer_capacity": cfg.buffer_capacity,
        "costs": cfg.costs.to_dict(),
        "trials": cfg.trials,
        "seed": cfg.seed,
        "interrupted": result.interrupted,
        "planned_sequence": list(result.prepared.sequence),
        "notes": notes(result),
        "strategies": strategies,
        "provenance": provenance(result),
        # Kept apart: the only fields that differ between two runs of the same study.
        "timing": {"seconds": {name: result.seconds.get(name) for name in result.trials},
                   "optimal_solve_seconds": result.prepared.optimal_seconds if optimum is not None else None},
    }


SCHEMA_VERSION = 1   # of this document; raised when a field changes meaning


def provenance(result: StudyResult) -> dict:
    """What made these numbers: versions, the plan's and the study's hashes, the policy settings.

    The same study (same plan, settings and seed) gives the same document on any machine and any
    number of workers, so nothing here depends on the machine or the time.
    """
    import platform

    from opportune import __version__
    from opportune.engine import native
    from opportune.simulate import hash_config, plan_sha256

    cfg = result.config
    return {
        "schema_version": SCHEMA_VERSION,
        "opportune": __version__,
        "python": platform.python_version(),
        "compiled_core": native.available(),
        "plan_sha256": plan_sha256(cfg.plan),
        "study_sha256": hash_config(cfg),
        "strategies": list(cfg.strategies),
        "decision_budget": cfg.decision_budget,
        # Enough to run the study again (`opportune simulate --from results.json`): its settings and the plan.
        "study": cfg.settings(),
        "plan": cfg.plan.to_dict(),
    }


def paired_difference(trials, reference) -> dict | None:
    """Mean difference of total time against ``reference`` on the same trials (the same bins: trial
    ``i`` of every strategy draws from the same random stream), with its 95% interval (Student's t on
    the differences).  Pairing removes the bins' own variance: a difference of a few hundredths is
    resolved by trials whose means each carry an interval ten times wider.  None without common trials.
    """
    mine = {t.trial: t.time for t in trials}
    pairs = [mine[t.trial] - t.time for t in reference if t.trial in mine]
    if len(pairs) < 2:
        return None
    low, high = _t_interval(pairs)
    return {"n": len(pairs), "mean_difference": sum(pairs) / len(pairs), "ci95": [low, high]}


def notes(result: StudyResult) -> list[str]:
    out = []
    if "pallet" in result.trials:
        out.append("pallet: the cost of engineering pallets, fixtures and transport is outside the model; "
                   "only robot motions are counted")
    if "quantify" in result.trials:
        out.append(f"quantify: statistics gathered over {result.config.training_runs} training runs "
                   "(their cost is not counted)")
    if "kitting" in result.trials:
        out.append("kitting: every part is laid out in its own location (the buffer capacity does not apply)")
    if result.interrupted:
        out.append("interrupted: only the trials that finished are reported")
    return out


def write_outputs(result: StudyResult, out_dir: str | Path) -> list[Path]:
    """Write results.json, trials.csv and the plots (PNG and SVG) into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    doc = summary(result)
    if sys.argv and Path(sys.argv[0]).name == "opportune":   # the command that wrote the file, when it was one
        doc["provenance"]["command"] = " ".join(shlex.quote(a) for a in ["opportune", *sys.argv[1:]])
    (out / "results.json").write_text(json.dumps(doc, indent=2) + "\n")
    written.append(out / "results.json")
    with open(out / "trials.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["strategy", "trial", *METRICS, "complete"])
        for name, trials in result.trials.items():
            for t in trials:
                w.writerow([name, t.trial, t.motions, t.buffer_moves, t.shakes, t.looks, t.buffer_peak,
                            f"{t.time:g}", int(t.complete)])
    written.append(out / "trials.csv")
    written += plot(result, doc, out)
    return written


def plot(result: StudyResult, doc: dict, out: Path) -> list[Path]:
    """Two figures (three with the exact optimum), each as PNG (300 dpi), SVG (text as text) and PDF,
    byte-identical for the same study.

    Strategies appear in one order in both, best mean first.  The distribution's whiskers are the 5th
    and 95th percentiles (the legend says so); the means are dots with their 95% intervals (Student's t
    for few trials) on an axis around the data, not bars from zero that make close means look alike;
    with the optimum, each mean's ratio to it with the same interval (``ratio_to_optimal``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [n for n in result.trials if result.trials[n]]
    written = []
    if not names:  # interrupted before any trial finished: nothing to draw
        return written
    names.sort(key=lambda n: (doc["strategies"][n]["time"]["mean"], n))
    title = (f"{doc['plan']}: {doc['bin']} bin, {doc['visible']} visible, "
             f"{doc['trials']:,} trials, seed {doc['seed']}")
    labels = [LABELS.get(n, n) for n in names]
    style = {"svg.fonttype": "none", "pdf.fonttype": 42, "svg.hashsalt": "opportune"}

    with plt.rc_context(style):
        # 1. Distribution of total time per strategy (best mean at the top).
        fig, ax = plt.subplots(figsize=(9, 0.6 * len(names) + 2))
        data = [[t.time for t in result.trials[n]] for n in names]
        ax.boxplot(data, orientation="horizontal", whis=(5, 95), showfliers=True,
                   flierprops={"markersize": 2, "alpha": 0.3}, label="box: quartiles; whiskers: 5th-95th percentile")
        ax.set_yticks(range(1, len(names) + 1), labels)
        ax.invert_yaxis()
        ax.set_xlabel("total time per assembly (motions + shakes, time units)")
        ax.set_title(f"Distribution of total time\n{title}", fontsize=10)
        ax.grid(axis="x", alpha=0.3)
        ax.legend(loc="lower right", fontsize=8, handlelength=0, handletextpad=0)
        written += _save(fig, out, "time_distribution")

        # 2. Mean time with its 95% interval, against the optimum.
        fig, ax = plt.subplots(figsize=(9, 0.5 * len(names) + 2))
        means = [doc["strategies"][n]["time"]["mean"] for n in names]
        cis = [_t_interval([t.time for t in result.trials[n]]) for n in names]
        err = [[m - c[0] for m, c in zip(means, cis)], [c[1] - m for m, c in zip(means, cis)]]
        ys = list(range(len(names)))
        ax.errorbar(means, ys, xerr=err, fmt="o", color="#4C72B0", capsize=3, label="mean, 95% interval")
        ax.set_yticks(ys, labels)
        ax.invert_yaxis()
        optimum = result.prepared.optimal_start
        if optimum:
            ax.axvline(optimum, color="#C44E52", linestyle="--", label=f"optimum (exact) {optimum:.4f}")
        for y, m, c in zip(ys, means, cis):
            label = f"{m:.2f}" + (f"  (×{m / optimum:.3f})" if optimum else "")
            ax.text(c[1], y, "  " + label, va="center", fontsize=8)
        low = min(c[0] for c in cis + ([(optimum, optimum)] if optimum else []))
        high = max(c[1] for c in cis)
        span = max(high - low, 1e-9)
        ax.set_xlim(low - 0.05 * span, high + 0.35 * span)
        ax.legend(loc="upper right", fontsize=8)
        ax.set_xlabel("mean total time per assembly (time units)")
        ax.set_title(f"Mean cost against the optimum\n{title}", fontsize=10)
        ax.grid(axis="x", alpha=0.3)
        written += _save(fig, out, "mean_time")

        # 3. Ratio to the optimum, when it is known: the exact optimum has no error, so each interval is
        #    the mean's interval divided by it.
        if optimum:
            fig, ax = plt.subplots(figsize=(7, 0.45 * len(names) + 1.8))
            ratios = [m / optimum for m in means]
            rerr = [[(m - c[0]) / optimum for m, c in zip(means, cis)], [(c[1] - m) / optimum for m, c in zip(means, cis)]]
            ax.errorbar(ratios, ys, xerr=rerr, fmt="o", color="#4C72B0", capsize=3, label="mean / optimum, 95% interval")
            ax.axvline(1.0, color="#C44E52", linestyle="--", label="optimum")
            for y, r, c in zip(ys, ratios, cis):
                ax.text(c[1] / optimum, y, f"  {100 * (r - 1):+.2f}%", va="center", fontsize=8)
            ax.set_yticks(ys, labels)
            ax.invert_yaxis()
            low = min(1.0, min(c[0] for c in cis) / optimum)
            high = max(c[1] for c in cis) / optimum
            span = max(high - low, 1e-9)
            ax.set_xlim(low - 0.05 * span, high + 0.3 * span)
            ax.set_xlabel(f"mean total time / exact optimum ({optimum:.4f})")
            ax.set_title(f"Ratio to the optimum\n{title}", fontsize=10)
            ax.grid(axis="x", alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)   # best first, at the top: the top right is free
            written += _save(fig, out, "ratio_to_optimal")
    return written


def _t_interval(values: list[float]) -> tuple[float, float]:
    """95% interval of the mean, Student's t (exact for few trials, the normal one for many)."""
    from opportune.engine.sampling import t_quantile

    n = len(values)
    mean = sum(values) / n
    if n < 2:
        return mean, mean
    sd = math.sqrt(sum((x - mean) ** 2 for x in values) / (n - 1))
    half = t_quantile(0.975, n - 1) * sd / math.sqrt(n)
    return mean - half, mean + half


def _save(fig, out: Path, stem: str) -> list[Path]:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    # no dates or versions in the files: the same study gives byte-identical figures
    metadata = {"png": {"Software": None}, "svg": {"Date": None, "Creator": None},
                "pdf": {"CreationDate": None, "ModDate": None, "Producer": None, "Creator": None}}
    paths = [out / f"{stem}.{ext}" for ext in ("png", "svg", "pdf")]
    for path in paths:
        fig.savefig(path, dpi=300, metadata=metadata[path.suffix[1:]])
    plt.close(fig)
    return paths


def table_rows(doc: dict) -> list[list[str]]:
    """Rows for the human table: one per strategy, best mean time first."""
    rows = []
    for name, s in sorted(doc["strategies"].items(),
                          key=lambda kv: (kv[1]["time"]["mean"] is None, kv[1]["time"]["mean"] or 0)):
        t = s["time"]
        ratio = s["ratio_to_optimal"]
        if not t["n"]:  # a study interrupted before any trial of this strategy finished
            rows.append([name, "no trial finished", *["—"] * 7])
            continue
        half = (t["ci95"][1] - t["ci95"][0]) / 2
        rows.append([
            name,
            f"{t['mean']:.2f} ± {half:.2f}",
            f"{t['sd']:.2f}",
            f"{t['p5']:g}/{t['p50']:g}/{t['p95']:g}",
            f"{t['max']:g}",
            f"{s['motions']['mean']:.2f}",
            f"{s['shakes']['mean']:.2f}",
            f"{s['buffer_peak']['mean']:.2f}",
            "—" if ratio is None else f"{ratio:.3f}",
        ])
    return rows


TABLE_HEADER = ["strategy", "time (95% CI)", "sd", "p5/p50/p95", "max", "motions", "shakes", "buf peak",
                "× opt"]
