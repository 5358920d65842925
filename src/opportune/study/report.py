"""Tables, files and figures of a simulation study.

``results.json`` (the ``--json`` document, with what made it under ``provenance`` and the run's
timings apart under ``timing``), ``trials.csv`` (one row per trial), and two figures as PNG, SVG and
PDF, drawn at print size (a single or a double column, text of 7 pt and up, Okabe–Ito colours):
``mean_time``, each strategy's mean time with its 95% interval against the exact optimum, and
``time_distribution``, the distribution of time per strategy.  :mod:`opportune.study.report_html` puts
them on one page.
"""

from __future__ import annotations

import csv
import json
import math
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

from opportune.study.simulate import METRICS, StudyResult

#: Each strategy's row label in figures and the report: what it does, in words.
LABELS = {
    "pallet": "pallet (parts in sequence)",
    "shake": "shake until next part shows",
    "kitting": "kitting (all parts laid out)",
    "buffer": "fixed sequence + buffer",
    "quantify": "quantify (learned order)",
    "paper": "paper's rule",
    "lookahead": "look-ahead (default)",
    "random": "random choice (ablation)",
    "optimal": "optimal policy (simulated)",
    "bin-first": "bin-first (rule variant)",
    "slack": "least slack (rule variant)",
    "rollout": "rollout (sampled look-ahead)",
}


def describe(values: list[float]) -> dict:
    """Mean, standard deviation, p5/p50/p95, max and the 95% confidence interval of the mean.

    Parameters
    ----------
    values : list of float
        The sample.

    Returns
    -------
    dict
        ``n``, ``mean``, ``sd`` (the sample's, n - 1), ``p5``, ``p50``, ``p95`` (linear
        interpolation, numpy's default), ``max`` and ``ci95`` (normal); ``None`` for each of an
        empty sample.

    Examples
    --------
    >>> d = describe([1.0, 2.0, 3.0, 4.0])
    >>> d["n"], d["mean"], d["p50"], d["max"], [round(x, 3) for x in d["ci95"]]
    (4, 2.5, 2.5, 4.0, [1.235, 3.765])
    """
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
    """The study as the ``--json`` document (``results.json``).

    Parameters
    ----------
    result : StudyResult
        The study.

    Returns
    -------
    dict
        The settings, the planned sequence, each strategy's statistics (:func:`describe` of every
        cost, the trials, the incomplete ones, the ratio to the optimum), the timing and the
        provenance.

    Examples
    --------
    >>> from opportune import load_plan
    >>> from opportune.study.simulate import StudyConfig, run_study
    >>> result = run_study(StudyConfig(load_plan("example:gearbox"), strategies=("paper",), trials=20, seed=1),
    ...                    workers=1)
    >>> doc = summary(result)
    >>> doc["strategies"]["paper"]["trials"], doc["strategies"]["paper"]["time"]["mean"]
    (20, 13.65)
    """
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
    reference = "paper" if result.trials.get("paper") else None
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
        "cell": cfg.cell.to_dict(),
        "trials": cfg.trials,
        "seed": cfg.seed,
        "interrupted": result.interrupted,
        "planned_sequence": list(result.prepared.sequence),
        "notes": notes(result),
        "strategies": strategies,
        "provenance": provenance(result),
        # Kept apart: the only fields that differ between two runs of the same study.  The same measures
        # on any number of workers: the study's elapsed time, and each strategy's CPU time summed over workers.
        "timing": {"wall_seconds": result.wall_seconds, "workers": result.workers,
                   "cpu_seconds": {name: result.cpu_seconds.get(name) for name in result.trials},
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
    from opportune.engine import compiled_core
    from opportune.study.simulate import hash_config, plan_sha256

    cfg = result.config
    return {
        "schema_version": SCHEMA_VERSION,
        "opportune": __version__,
        "python": platform.python_version(),
        "compiled_core": compiled_core() is not None,
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
        out.append("pallet: parts arrive in the planned sequence; the cost of engineering pallets, fixtures and "
                   "transport is outside the model (only robot motions and looks are counted)")
    if "quantify" in result.trials:
        out.append(f"quantify: statistics gathered over {result.config.training_runs} training runs "
                   "(their cost is not counted)")
    if "kitting" in result.trials:
        out.append("kitting: every part is laid out in its own location (the buffer capacity does not apply)")
    if result.interrupted:
        out.append("interrupted: only the trials that finished are reported")
    return out


def write_outputs(result: StudyResult, out_dir: str | Path) -> list[Path]:
    """Write ``results.json``, ``trials.csv`` and the figures (PNG, SVG and PDF) into ``out_dir``.

    Parameters
    ----------
    result : StudyResult
        The study.
    out_dir : str or os.PathLike
        The folder (made if missing).

    Returns
    -------
    list of pathlib.Path
        The files written.

    Raises
    ------
    OSError
        If the folder or a file cannot be written.

    Examples
    --------
    >>> import tempfile
    >>> from opportune import load_plan
    >>> from opportune.study.simulate import StudyConfig, run_study
    >>> result = run_study(StudyConfig(load_plan("example:gearbox"), strategies=("paper",), trials=10), workers=1)
    >>> [path.name for path in write_outputs(result, tempfile.mkdtemp())][:3]
    ['results.json', 'trials.csv', 'mean_time.png']
    """
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
                            f"{t.time:g}", f"{t.cycle_seconds:.6g}", int(t.complete)])
    written.append(out / "trials.csv")
    written += plot(result, doc, out)
    return written


# ---------------------------------------------------------------- figures

#: Print widths of a journal's single and double column, in inches.  Every figure is drawn at one of
#: them, so its text prints at the size it was set in (never below :data:`MIN_FONT_PT`).
COLUMN_WIDTHS = {"single": 3.5, "double": 7.2}
MIN_FONT_PT = 7
#: Okabe & Ito's palette, distinguishable with every common colour-vision deficiency and in grey.
OKABE_ITO = {"black": "#000000", "orange": "#E69F00", "sky blue": "#56B4E9", "bluish green": "#009E73",
             "yellow": "#F0E442", "blue": "#0072B2", "vermillion": "#D55E00", "reddish purple": "#CC79A7"}
#: Families of strategies, each with its colour and marker (shape too, for a print in grey).
GROUPS = {
    "fixed": ("fixed sequence", OKABE_ITO["blue"], "s"),
    "opportunistic": ("opportunistic", OKABE_ITO["orange"], "o"),
    "ablation": ("ablation", OKABE_ITO["reddish purple"], "^"),
    "optimal": ("optimal policy", OKABE_ITO["bluish green"], "D"),
}
GROUP_OF = {"pallet": "fixed", "shake": "fixed", "kitting": "fixed", "buffer": "fixed", "quantify": "fixed",
            "random": "ablation", "optimal": "optimal"}
OPTIMUM_COLOUR = OKABE_ITO["vermillion"]
MARKER_PT = 4.0   # marker diameter, points


@dataclass
class Figure:
    """One figure of a study: its file stem, the matplotlib figure, its print width and its caption."""

    stem: str
    figure: object
    width: str
    caption: str


def figure_style() -> dict:
    """The rc settings of every figure: print-size fonts, thin lines, text kept as text, no random ids."""
    return {"svg.fonttype": "none", "pdf.fonttype": 42, "svg.hashsalt": "opportune",
            "font.size": MIN_FONT_PT, "axes.titlesize": 8, "axes.labelsize": MIN_FONT_PT,
            "xtick.labelsize": MIN_FONT_PT, "ytick.labelsize": MIN_FONT_PT, "legend.fontsize": MIN_FONT_PT,
            "figure.titlesize": 8, "axes.linewidth": 0.6, "xtick.major.width": 0.6, "ytick.major.width": 0.6,
            "xtick.major.size": 2.5, "ytick.major.size": 2.5, "lines.linewidth": 0.8, "grid.linewidth": 0.4}


def _plain(text: str, limit: int = 60) -> str:
    """Text for a figure: no control characters, no mathtext (``$``), at most ``limit`` characters."""
    text = "".join(c if c.isprintable() else "?" for c in str(text)).replace("$", r"\$")
    return text if len(text) <= limit else text[:limit - 1] + "…"


def label(name: str) -> str:
    """The descriptive row label of a strategy (``look-ahead (default)``, ``paper's rule``)."""
    return LABELS.get(name, name)


def make_figures(result: StudyResult, doc: dict | None = None) -> list[Figure]:
    """The study's figures, drawn (not saved): the mean time of each strategy against the optimum
    (single column) and the distribution of time per strategy (double column).

    Call inside ``matplotlib.rc_context(figure_style())``.  Strategies appear in one order in both,
    best mean first.  Cost: O(trials) to draw.

    Parameters
    ----------
    result : StudyResult
        The study.
    doc : dict, optional
        The study's :func:`summary` (computed when not given).

    Returns
    -------
    list of Figure
        Each figure with its file stem, column width and caption; empty when no trial finished.

    Examples
    --------
    >>> import matplotlib; from opportune import load_plan; from opportune.study.simulate import StudyConfig, run_study
    >>> r = run_study(StudyConfig(load_plan("example:gearbox"), strategies=("paper",), trials=20), workers=1)
    >>> with matplotlib.rc_context(figure_style()):
    ...     [(f.stem, f.width, float(f.figure.get_size_inches()[0])) for f in make_figures(r)]
    [('mean_time', 'single', 3.5), ('time_distribution', 'double', 7.2)]
    """
    doc = doc or summary(result)
    names = [n for n in result.trials if result.trials[n]]
    if not names:  # interrupted before any trial finished: nothing to draw
        return []
    names.sort(key=lambda n: (doc["strategies"][n]["time"]["mean"], n))
    cis = [_t_interval([t.time for t in result.trials[n]]) for n in names]
    return [_mean_figure(result, doc, names, cis), _distribution_figure(result, doc, names)]


def _new_figure(width: float, height: float, rows: tuple[float, ...] = (1.0,)):
    """A figure of that print size with one axes per entry of ``rows`` (their relative heights), stacked,
    outside pyplot: no backend is switched and no global figure list grows (a notebook that calls this
    keeps its own).  One axes is returned as it is, several as a list."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure as MatplotlibFigure

    fig = MatplotlibFigure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    if len(rows) == 1:
        return fig, fig.subplots()
    return fig, list(fig.subplots(len(rows), 1, height_ratios=list(rows)))


def _percent(x: float, digits: int = 1) -> str:
    """``+0.9%``, ``−26.3%`` (a true minus sign, as on the axes)."""
    return f"{100 * x:+.{digits}f}%".replace("-", "\u2212")


def _setting(doc: dict) -> str:
    cap = "unlimited" if doc["buffer_capacity"] is None else doc["buffer_capacity"]
    return f"{doc['bin']} bin, {doc['visible']} visible, buffer {cap}, {doc['trials']:,} trials, seed {doc['seed']}"


#: The mean-time figure's zoom: the rows whose mean is within this fraction of the optimum (or, without
#: one, of the best mean of a policy that draws from the bin) get a second panel of their own when their
#: intervals are squeezed in the first (all of them span less than :data:`ZOOM_WHEN` of its axis): on the
#: gearbox the intervals of ±0.03 sit on an axis of 10 to 28, and only the zoom shows them.
ZOOM_SPAN = 0.05
ZOOM_WHEN = 0.15
#: Marks a difference from the optimum that is sampling noise (the optimum inside the mean's interval).
NOISE_MARK = "\u2020"


def _near_rows(names: list[str], means: list[float], cis: list[tuple[float, float]], optimum) -> list[int]:
    """The rows of the zoom panel (indices into ``names``), or none when the first panel shows them well."""
    reference = optimum or min((m for n, m in zip(names, means) if n not in ("pallet", "kitting")), default=None)
    if not reference:
        return []
    near = [i for i, m in enumerate(means) if abs(m / reference - 1) <= ZOOM_SPAN]
    if len(near) < 2:
        return []
    span = max(cis[i][1] for i in near) - min(cis[i][0] for i in near)
    whole = max(c[1] for c in cis) - min(c[0] for c in cis)
    return near if span < ZOOM_WHEN * whole else []


def _difference(mean: float, ci: tuple[float, float], optimum: float) -> str:
    """The right-hand column: the mean's difference from the optimum, marked when it is sampling noise."""
    noise = ci[0] <= optimum <= ci[1] and ci[0] < ci[1]
    return _percent(mean / optimum - 1) + (NOISE_MARK if noise else "\u2007")


def _draw_means(ax, names, means, cis, optimum, xlim, marker_pt: float, enlarged=()) -> None:
    """One panel of the mean-time figure: a row per strategy, its 95% interval drawn over a hollow marker
    (but for the rows in ``enlarged``, whose intervals the zoom panel draws)."""
    from matplotlib.ticker import MaxNLocator

    n = len(names)
    ys = list(range(n))
    if optimum:
        ax.axvline(optimum, color=OPTIMUM_COLOUR, linestyle="--", linewidth=0.9, zorder=1)
    for y, name, mean, (low, high) in zip(ys, names, means, cis):
        _, colour, marker = GROUPS[GROUP_OF.get(name, "opportunistic")]
        # the interval above a hollow marker: it shows through, with caps, wherever it is wider than a line
        ax.plot([mean], [y], linestyle="none", marker=marker, ms=marker_pt, mfc="white", mec=colour, mew=0.8,
                zorder=3)
        if name in enlarged or high == low:   # drawn in the zoom panel, or no spread (pallet, kitting)
            continue
        ax.errorbar([mean], [y], xerr=[[mean - low], [high - mean]], fmt="none", ecolor="black", elinewidth=0.9,
                    capsize=2.5, capthick=0.9, zorder=4)
    ax.set_yticks(ys, [_plain(label(name)) for name in names])
    ax.set_ylim(n - 0.5, -0.5)   # best at the top
    ax.set_xlim(*xlim)
    ax.xaxis.set_major_locator(MaxNLocator(nbins=5))   # a few ticks: none whose label spills past the column
    ax.ticklabel_format(axis="x", useOffset=False)
    ax.grid(axis="x", alpha=0.35)
    if optimum:
        right = ax.secondary_yaxis("right")
        right.set_yticks(ys, [_difference(m, c, optimum) for m, c in zip(means, cis)])
        right.tick_params(length=0)


def _limits(values: list[float]) -> tuple[float, float]:
    low, high = min(values), max(values)
    pad = max(0.04 * (high - low), 0.01 * max(abs(high), 1.0))   # equal means (nothing to decide) too
    return low - pad, high + pad


def _mean_figure(result: StudyResult, doc: dict, names: list[str], cis: list[tuple[float, float]]) -> Figure:
    from matplotlib.lines import Line2D

    n = len(names)
    optimum = result.prepared.optimal_start
    means = [doc["strategies"][name]["time"]["mean"] for name in names]
    near = _near_rows(names, means, cis, optimum)
    extra = [optimum] if optimum else []
    rows = (n + 0.6, len(near) + 1.2) if near else (1.0,)
    fig, axes = _new_figure(COLUMN_WIDTHS["single"], 1.25 + 0.19 * n + (0.3 + 0.19 * len(near) if near else 0),
                            rows)
    ax, zoom = (axes[0], axes[1]) if near else (axes, None)
    _draw_means(ax, names, means, cis, optimum, _limits([c[0] for c in cis] + [c[1] for c in cis] + extra), MARKER_PT,
                [names[i] for i in near])
    if near:
        sub = [names[i] for i in near]
        sub_cis = [cis[i] for i in near]
        zlim = _limits([c[0] for c in sub_cis] + [c[1] for c in sub_cis] + extra)
        ax.axvspan(*zlim, color="#000000", alpha=0.12, linewidth=0, zorder=0)
        _draw_means(zoom, sub, [means[i] for i in near], sub_cis, optimum, zlim, MARKER_PT)
        zoom.set_title("the shaded band, enlarged", loc="left", fontsize=MIN_FONT_PT, pad=3)
    if optimum:
        ax.annotate("vs optimum", xy=(1, 1), xycoords="axes fraction", xytext=(3, 2), textcoords="offset points",
                    ha="left", va="bottom")
    (zoom or ax).set_xlabel("mean time per assembly, with its 95% interval")
    cap = "unlimited" if doc["buffer_capacity"] is None else doc["buffer_capacity"]
    # on the figure, not the axes: the whole column's width for it
    fig.suptitle(f"{_plain(doc['plan'], 30)}: {doc['trials']:,} trials, seed {doc['seed']}\n"
                 f"{doc['bin']} bin, {doc['visible']} visible, buffer {cap}", x=0.02, ha="left")
    handles = [Line2D([], [], linestyle="none", marker=GROUPS[g][2], mfc="white", mec=GROUPS[g][1], ms=MARKER_PT,
                      label=GROUPS[g][0])
               for g in GROUPS if any(GROUP_OF.get(name, "opportunistic") == g for name in names)]
    if optimum:
        handles.append(Line2D([], [], color=OPTIMUM_COLOUR, linestyle="--", label=f"exact optimum, {optimum:.4f}"))
    legend = fig.legend(handles=handles, loc="outside lower center", ncols=2, frameon=False, handletextpad=0.4,
                        columnspacing=1.0)
    noisy = optimum and any(c[0] <= optimum <= c[1] and c[0] < c[1] for c in cis)
    if noisy:   # said on the figure itself: a PNG travels without its caption
        legend.set_title(f"{NOISE_MARK} within sampling noise: the optimum lies inside\nthis mean's 95% interval",
                         prop={"size": MIN_FONT_PT})
        legend.set_alignment("left")
    fig.canvas.draw()   # lay it out: the caption says which intervals the markers hide
    enlarged = {names[i] for i in near}
    hidden = [name for name, (lo, hi) in zip(names, cis)
              if hi - lo < _marker_width(fig, zoom if name in enlarged else ax)]
    return Figure("mean_time", fig, "single", mean_caption(result, doc, names, cis, hidden, zoomed=bool(near)))


def _marker_width(fig, ax) -> float:
    """A marker's width in the data units of the axes' x (after the figure is laid out)."""
    box = ax.get_window_extent()
    x0, x1 = ax.get_xlim()
    return MARKER_PT / 72 * (x1 - x0) / (box.width / fig.dpi)


def _distribution_figure(result: StudyResult, doc: dict, names: list[str]) -> Figure:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    n = len(names)
    optimum = result.prepared.optimal_start
    fig, ax = _new_figure(COLUMN_WIDTHS["double"], 1.2 + 0.22 * n)
    ys = list(range(n))
    data = [[t.time for t in result.trials[name]] for name in names]
    parts = ax.boxplot(data, positions=ys, orientation="horizontal", whis=(5, 95), showfliers=False, widths=0.6,
                       patch_artist=True, medianprops={"color": "black", "linewidth": 1.0})
    for i, name in enumerate(names):
        colour = GROUPS[GROUP_OF.get(name, "opportunistic")][1]
        parts["boxes"][i].set(facecolor=colour + "55", edgecolor=colour, linewidth=0.9)
        for line in parts["whiskers"][2 * i:2 * i + 2] + parts["caps"][2 * i:2 * i + 2]:
            line.set(color=colour, linewidth=0.9)
        # the trials beyond the whiskers, each value once: 10,000 trials repeat a few dozen values, and
        # drawing every one made files of megabytes that look the same
        low, high = (parts["caps"][2 * i].get_xdata()[0], parts["caps"][2 * i + 1].get_xdata()[0])
        beyond = sorted({x for x in data[i] if x < low or x > high})
        ax.plot(beyond, [i] * len(beyond), linestyle="none", marker=".", ms=2.5, mew=0, color=colour, alpha=0.6)
    means = [doc["strategies"][name]["time"]["mean"] for name in names]
    ax.plot(means, ys, linestyle="none", marker="D", ms=3, mfc="white", mec="black", mew=0.7, zorder=4)
    if optimum:
        ax.axvline(optimum, color=OPTIMUM_COLOUR, linestyle="--", linewidth=0.9, zorder=1)
    ax.set_yticks(ys, [_plain(label(name)) for name in names])
    ax.set_ylim(n - 0.5, -0.5)
    ax.set_xlabel("total time per assembly (time units: motions, shakes and looks)")
    ax.grid(axis="x", alpha=0.35)
    title = f"{_plain(doc['plan'], 60)}: distribution of time per assembly; {_setting(doc)}"
    if len(title) > 95:   # wider than the two columns at 8 pt: the setting on a line of its own
        title = title.replace("; ", "\n", 1)
    fig.suptitle(title, x=0.01, ha="left")
    handles = [Patch(facecolor="#BBBBBB", edgecolor="black", label="box: quartiles, line: median"),
               Line2D([], [], color="black", marker="|", label="whiskers: 5th and 95th percentiles"),
               Line2D([], [], linestyle="none", marker="D", ms=3, mfc="white", mec="black", label="mean")]
    if optimum:
        handles.append(Line2D([], [], color=OPTIMUM_COLOUR, linestyle="--", label=f"exact optimum, {optimum:.4f}"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), frameon=False)
    return Figure("time_distribution", fig, "double", distribution_caption(result, doc))


def mean_caption(result: StudyResult, doc: dict, names: list[str], cis: list[tuple[float, float]],
                 hidden: list[str], zoomed: bool = False) -> str:
    """The caption of the mean-time figure: what is drawn, the zoom, the optimum's noise, the hidden
    intervals, the pallet."""
    optimum = result.prepared.optimal_start
    out = [f"Mean time per assembly of each strategy over {doc['trials']:,} trials (hollow marker), with its 95% "
           "interval (Student's t; black bar with caps), best first."]
    if zoomed:
        out.append("The lower panel enlarges the shaded band of the upper one, where the strategies closest to the "
                   "best lie: there the intervals are wide enough to see.")
    if optimum:
        out.append(f"The dashed line is the exact optimum, {optimum:.4f}: the least expected time any policy can "
                   f"achieve, from a dynamic programme over {result.prepared.optimal_states:,} states, with no "
                   "Monte Carlo error. The right-hand column is each mean's difference from it.")
        noisy = [n for n, (lo, hi) in zip(names, cis) if lo <= optimum <= hi and lo < hi]
        if noisy:
            quoted = ", ".join(f"'{label(n)}'" for n in noisy)
            out.append(f"A difference marked {NOISE_MARK} ({quoted}) is within sampling noise: the optimum lies "
                       "inside that mean's interval. No policy's expected time is below the optimum, so a mean below "
                       "it (the simulated optimum's own, for one) only says the sampled bins were kind.")
        if "optimal" in names:
            mean = doc["strategies"]["optimal"]["time"]["mean"]
            low, high = cis[names.index("optimal")]
            inside = low <= optimum <= high
            out.append(f"The row '{label('optimal')}' plays that optimal policy on the same bins: its mean, "
                       f"{mean:.2f} ({_percent(mean / optimum - 1, 2)}), is an estimate of the optimum, and its "
                       f"interval, {low:.2f} to {high:.2f}, "
                       + ("contains the exact value: the difference is Monte Carlo noise." if inside else
                          "misses the exact value, as one 95% interval in twenty does: the difference is Monte "
                          "Carlo noise."))
    if hidden:
        width = max((hi - lo) / 2 for name, (lo, hi) in zip(names, cis) if name in hidden)
        shown = [name for name in names if name not in hidden]
        quoted = lambda group: ", ".join(f"'{label(n)}'" for n in group)
        if not shown:
            which = f"Every interval (half-width at most {width:.2f}) is narrower than its marker"
        elif len(shown) < len(hidden):
            which = (f"Every interval but {'that' if len(shown) == 1 else 'those'} of {quoted(shown)} (half-width "
                     f"at most {width:.2f}) is narrower than its marker")
        else:
            which = f"The intervals of {quoted(hidden)} (half-width at most {width:.2f}) are narrower than their markers"
        out.append(which + ": the table gives each.")
    if "pallet" in names:
        out.append("Pallet is below the optimum because its parts arrive in the planned sequence: it never "
                   "buffers or shakes, and what the pallets cost is outside the model.")
    return " ".join(out)


def distribution_caption(result: StudyResult, doc: dict) -> str:
    out = [f"Distribution of the time per assembly over {doc['trials']:,} trials of each strategy (the same bins "
           "for all): boxes span the quartiles, with the median; whiskers reach the 5th and 95th percentiles; "
           "dots mark the times of trials beyond them (each time once); diamonds are the means."]
    if result.prepared.optimal_start:
        out.append(f"The dashed line is the exact optimum's expected time, {result.prepared.optimal_start:.4f}.")
    return " ".join(out)


def pallet_note(result: StudyResult, doc: dict) -> str:
    """What the pallet row means, with this study's numbers: why it is below the optimum."""
    cfg = result.config
    units = cfg.plan.n_units
    pallet = doc["strategies"]["pallet"]["time"]["mean"]
    text = (f"Pallet is the cost with no uncertainty left: its {units} parts arrive in the planned sequence, so it "
            "makes one motion per part (and one look each, at the look cost), and never buffers or shakes. Every "
            "policy installs each part with one motion; a bin policy also pays for each part it buffers (a second "
            "motion), each shake and each look spent waiting, which the order of arrival forces on it whenever no "
            "visible part can go in.")
    optimum = result.prepared.optimal_start
    if optimum:
        text += (f" Its {_percent(pallet / optimum - 1, 0)} against the optimum is what the uncertainty of the "
                 f"order costs even the best policy")
        moves = doc["strategies"].get("optimal", {}).get("buffer_moves", {}).get("mean")
        text += (f" (the simulated optimum makes {moves:.2f} buffer moves per assembly)." if moves is not None
                 else ".")
    text += (" The price of eliminating the uncertainty (the pallets and fixtures, and loading them in sequence "
             "upstream) is outside the model.")
    return text


def plot(result: StudyResult, doc: dict, out: Path) -> list[Path]:
    """The figures of :func:`make_figures`, each as PNG (300 dpi), SVG (text as text) and PDF,
    byte-identical for the same study."""
    import matplotlib

    written = []
    with matplotlib.rc_context(figure_style()):
        for figure in make_figures(result, doc):
            written += _save(figure.figure, out, figure.stem)
    return written


def _t_interval(values: list[float]) -> tuple[float, float]:
    """95% interval of the mean, Student's t (exact for few trials, the normal one for many)."""
    from opportune.engine.stats import t_quantile

    n = len(values)
    mean = sum(values) / n
    if n < 2:
        return mean, mean
    sd = math.sqrt(sum((x - mean) ** 2 for x in values) / (n - 1))
    half = t_quantile(0.975, n - 1) * sd / math.sqrt(n)
    return mean - half, mean + half


def _save(fig, out: Path, stem: str) -> list[Path]:
    # no dates or versions in the files: the same study gives byte-identical figures
    metadata = {"png": {"Software": None}, "svg": {"Date": None, "Creator": None},
                "pdf": {"CreationDate": None, "ModDate": None, "Producer": None, "Creator": None}}
    paths = [out / f"{stem}.{ext}" for ext in ("png", "svg", "pdf")]
    for path in paths:
        fig.savefig(path, dpi=300, metadata=metadata[path.suffix[1:]])
    return paths


def table_rows(doc: dict) -> list[list[str]]:
    """Rows for the human table: one per strategy, best mean time first."""
    rows = []
    for name, s in sorted(doc["strategies"].items(),
                          key=lambda kv: (kv[1]["time"]["mean"] is None, kv[1]["time"]["mean"] or 0)):
        t = s["time"]
        ratio = s["ratio_to_optimal"]
        if not t["n"]:  # a study interrupted before any trial of this strategy finished
            rows.append([name, "no trial finished", *["—"] * 8])
            continue
        half = (t["ci95"][1] - t["ci95"][0]) / 2
        sec = s["cycle_seconds"]
        rows.append([
            name,
            f"{t['mean']:.2f} ± {half:.2f}",
            f"{sec['mean']:.1f} ± {(sec['ci95'][1] - sec['ci95'][0]) / 2:.1f}",
            f"{t['sd']:.2f}",
            f"{t['p5']:g}/{t['p50']:g}/{t['p95']:g}",
            f"{t['max']:g}",
            f"{s['motions']['mean']:.2f}",
            f"{s['shakes']['mean']:.2f}",
            f"{s['buffer_peak']['mean']:.2f}",
            "—" if ratio is None else f"{ratio:.3f}",
        ])
    return rows


TABLE_HEADER = ["strategy", "time (95% CI)", "cycle s (95% CI)", "sd", "p5/p50/p95", "max", "motions", "shakes", "buf peak",
                "× opt"]
