"""The paper's comparison on one page: a self-contained HTML report of a simulation study.

``opportune simulate PLAN --report out.html`` writes it; :func:`write_report` does the same from
Python.  One file, nothing fetched: the styles are inline and the figures are SVG embedded as
``data:`` URIs, so it opens the same offline, attached to a mail or archived with a paper.  It holds
the setup (plan, bin, visible parts, buffer, costs, trials, seed, the machine), the table of every
strategy, the two figures of :mod:`opportune.study.report` with their captions, and notes (what the rows
mean, the optimum's Monte Carlo noise, the pallet's place below the optimum).  The same study (same
plan, settings and seed, on the same machine) gives the same bytes: no dates and no timings (those
are in ``results.json``'s ``timing``).

>>> from opportune import load_plan
>>> from opportune.study.simulate import StudyConfig, run_study
>>> page = render_report(run_study(StudyConfig(load_plan("example:gearbox"), strategies=("paper",),
...                                            trials=20), workers=1))
>>> page.startswith("<!DOCTYPE html>"), '<tr data-strategy="paper">' in page, "://" in page
(True, True, False)
"""

from __future__ import annotations

import base64
import html
import io
import os
import platform
import shlex
import sys
from pathlib import Path

from opportune.study.report import LABELS, figure_style, label, make_figures, pallet_note, summary
from opportune.study.simulate import StudyResult

__all__ = ["REPORT_SUFFIXES", "TABLE_COLUMNS", "render_report", "write_report"]

REPORT_SUFFIXES = (".html", ".htm")

#: The table's columns: (key of the cell, heading, the value in results.json's strategy document, format).
TABLE_COLUMNS = (
    ("mean", "mean time", lambda s: s["time"]["mean"], "{:.3f}"),
    ("ci_low", "95% interval, from", lambda s: s["time"]["ci95"][0], "{:.3f}"),
    ("ci_high", "to", lambda s: s["time"]["ci95"][1], "{:.3f}"),
    ("sd", "sd", lambda s: s["time"]["sd"], "{:.2f}"),
    ("cycle_seconds", "mean cycle s", lambda s: (s.get("cycle_seconds") or {}).get("mean"), "{:.1f}"),
    ("p5", "p5", lambda s: s["time"]["p5"], "{:g}"),
    ("p50", "median", lambda s: s["time"]["p50"], "{:g}"),
    ("p95", "p95", lambda s: s["time"]["p95"], "{:g}"),
    ("max", "max", lambda s: s["time"]["max"], "{:g}"),
    ("motions", "motions", lambda s: s["motions"]["mean"], "{:.2f}"),
    ("buffer_moves", "buffer moves", lambda s: s["buffer_moves"]["mean"], "{:.2f}"),
    ("shakes", "shakes", lambda s: s["shakes"]["mean"], "{:.2f}"),
    ("buffer_peak", "buffer peak", lambda s: s["buffer_peak"]["mean"], "{:.2f}"),
    ("ratio", "× optimum", lambda s: s["ratio_to_optimal"], "{:.4f}"),
    ("paired", "paired difference", lambda s: (s.get("paired") or {}).get("mean_difference"), "{:+.3f}"),
)

def _cell_text(cell: dict) -> str:
    """The cell model of a study, in one line (for the seconds column)."""
    text = (f"robot {cell['speed']:g} m/s; bin–fixture {cell['bin_fixture']:g} m, bin–buffer {cell['bin_buffer']:g} m, "
            f"buffer–fixture {cell['buffer_fixture']:g} m; pick {cell['pick']:g} s, place {cell['place']:g} s, "
            f"install {cell['install']:g} s, look {cell['camera']:g} s, shake {cell['shake']:g} s")
    if cell.get("parts"):
        text += "; per part: " + ", ".join(f"{p} " + ", ".join(f"{k} {v:g} s" for k, v in sorted(t.items()))
                                           for p, t in sorted(cell["parts"].items()))
    return text


_CSS = """
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; color: #111; max-width: 72rem;
       margin: 2rem auto; padding: 0 1rem; }
h1 { font-size: 1.5rem; margin-bottom: .2rem; } h2 { font-size: 1.15rem; margin-top: 2rem; }
.sub { color: #555; margin-top: 0; }
table { border-collapse: collapse; font-variant-numeric: tabular-nums; }
th, td { padding: .25rem .5rem; border-bottom: 1px solid #ddd; vertical-align: top; }
table.results { font-size: .8rem; } table.results td.num { text-align: right; white-space: nowrap; }
table.results th, table.results td { padding: .2rem .3rem; }
table.results th[scope=row] { text-align: left; width: 10rem; font-weight: 500; }
table.results th[scope=row] .name { display: block; }
table.results thead th { text-align: right; font-weight: 600; vertical-align: bottom; hyphens: auto; }
table.results th:first-child { text-align: left; }
table.setup th { text-align: left; font-weight: 600; white-space: nowrap; }
code { font-size: .92em; } .name { color: #555; font-size: .85em; }
figure { margin: 1.5rem 0; } figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: .9rem; color: #333; max-width: 52rem; }
@media print { body { margin: 0; max-width: none; } h2 { break-after: avoid; } figure { break-inside: avoid; } }
"""


def _t(value) -> str:
    """Text for the page: escaped, control characters shown as ``\\xNN`` (never sent raw to a reader)."""
    text = "".join(c if c.isprintable() or c in "\n\t" else f"\\x{ord(c):02x}" for c in str(value))
    return html.escape(text, quote=True)


def _machine() -> str:
    from opportune import __version__
    from opportune.engine import compiled_core

    core = "compiled core" if compiled_core() is not None else "pure Python"
    return (f"{platform.system()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
            f"opportune {__version__} ({core})")


def _svg_uri(figure) -> str:
    """The figure as an SVG ``data:`` URI, with no dates in it (the same study, the same bytes)."""
    buf = io.BytesIO()
    figure.savefig(buf, format="svg", metadata={"Date": None, "Creator": None})
    return "data:image/svg+xml;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _setup_rows(result: StudyResult, doc: dict) -> list[tuple[str, str]]:
    cfg = result.config
    plan = cfg.plan
    costs = doc["costs"]
    cost_text = f"motion {costs['motion']:g}, shake {costs['shake']:g}, look {costs['look']:g}"
    if costs.get("parts"):
        cost_text += "; per part: " + ", ".join(f"{p} {c:g}" for p, c in sorted(costs["parts"].items()))
    strategies = len(getattr(plan, "strategies", ()) or ())
    rows = [
        ("plan", f"{plan.name}: {plan.n_units} parts" + (f", {strategies} alternative strategies" if strategies > 1
                                                          else "")),
        ("bin", {"uniform": "uniform: every part in the bin equally likely to be seen",
                 "weighted": "weighted: parts seen in proportion to their visibility",
                 "pile": "pile: the top of a stacked pile is seen; a shake restacks it",
                 "conveyor": "conveyor: parts pass a window and come round again",
                 "physics": "physics: rigid parts heaped in a MuJoCo bin, seen through occlusion"}.get(doc["bin"], doc["bin"])),
        ("visible", f"{doc['visible']} parts per look"),
        ("buffer", "unlimited" if doc["buffer_capacity"] is None else f"{doc['buffer_capacity']} locations"),
        ("costs", cost_text + " (time units)"),
        *([("cell", _cell_text(doc["cell"]))] if doc.get("cell") else []),
        ("trials", f"{doc['trials']:,} per strategy, the same bins for every strategy (trial i draws the same bin)"),
        ("seed", str(doc["seed"])),
        ("decisions", "exact" if cfg.decision_budget is None else
         f"within {1000 * cfg.decision_budget:g} ms each (estimated where counts do not fit: machine-dependent)"),
        ("planned sequence", " ".join(doc["planned_sequence"]) + " (the fixed sequence of pallet, shake, kitting "
                                                                 "and buffer)"),
    ]
    if result.prepared.optimal_start is not None:
        rows.append(("exact optimum", f"{result.prepared.optimal_start:.4f} expected time, a dynamic programme over "
                                      f"{result.prepared.optimal_states:,} states"))
    rows.append(("machine", _machine()))
    prov = doc["provenance"]
    rows.append(("plan SHA-256", prov["plan_sha256"]))
    if prov.get("command"):
        rows.append(("command", prov["command"]))
    return rows


def _table(doc: dict) -> str:
    names = sorted(doc["strategies"], key=lambda n: (doc["strategies"][n]["time"]["mean"] is None,
                                                     doc["strategies"][n]["time"]["mean"] or 0, n))
    head = "".join(f"<th>{_t(heading)}</th>" for _, heading, _, _ in TABLE_COLUMNS)
    rows = []
    for name in names:
        s = doc["strategies"][name]
        cells = []
        for key, _, get, fmt in TABLE_COLUMNS:
            value = get(s) if s["time"]["n"] else None
            if value is None:
                cells.append(f'<td class="num" data-key="{key}">—</td>')
            else:
                cells.append(f'<td class="num" data-key="{key}" data-value="{value!r}">{_t(fmt.format(value))}</td>')
        rows.append(f'<tr data-strategy="{_t(name)}"><th scope="row">{_t(label(name))} '
                    f'<span class="name">(<code>{_t(name)}</code>)</span></th>{"".join(cells)}</tr>')
    return (f'<table class="results"><thead><tr><th>strategy</th>{head}</tr></thead>\n<tbody>\n'
            + "\n".join(rows) + "\n</tbody></table>")


def _notes(result: StudyResult, doc: dict) -> list[str]:
    names = [n for n in doc["strategies"] if doc["strategies"][n]["time"]["n"]]
    optimum = result.prepared.optimal_start
    out = []
    absent = lambda name: "" if name in names else " (not run in this study)"
    # both labels always: the default policy and the paper's rule are what a reader compares first
    out.append(f"<i>{_t(LABELS['lookahead'])}</i> is <code>lookahead</code>{absent('lookahead')}, the policy "
               "<code>opportune evaluate</code> and the service use by default: one step of exact policy improvement "
               "over the paper's rule (every legal action scored by its cost plus the exact expected cost of "
               "finishing), on plans of up to 16 parts; on larger ones it decides by least slack.")
    out.append(f"<i>{_t(LABELS['paper'])}</i> is <code>paper</code>{absent('paper')} (formerly also named "
               "<code>opportunistic</code>), Fox and "
               "Kempf's rule: install the visible part that keeps the most admissible completions; when none can go "
               "in, buffer the visible part needed earliest; shake only when nothing else helps. "
               "<code>replay</code> and the library's <code>Sequencer</code> use it by default, so the paper's "
               "Table 1 replays as printed.")
    if optimum is not None:
        text = (f"The exact optimum, {optimum:.4f}, is computed (a dynamic programme), not simulated: it has no "
                "Monte Carlo error.")
        if "optimal" in names:
            s = doc["strategies"]["optimal"]["time"]
            low, high = s["ci95"]
            text += (f" The row <i>{_t(LABELS['optimal'])}</i> plays the optimal policy on the sampled bins: its mean "
                     f"{s['mean']:.3f} (95% interval {low:.3f} to {high:.3f}) estimates the optimum, and differs "
                     "from it only by the noise of the estimate. A row below the exact optimum by less than its "
                     "interval's half-width is that noise, not a better policy.")
        out.append(text)
    if "pallet" in names:
        out.append(_t(pallet_note(result, doc)))
    paired = [(n, doc["strategies"][n]["paired"]) for n in names if "paired" in doc["strategies"][n]]
    if paired:
        ref = paired[0][1]["with"]
        out.append(f"Paired difference: each strategy's mean difference of time from <i>{_t(label(ref))}</i> on the same "
                   "bins (trial i of every strategy draws the same bin), which removes the bins' own variance: "
                   + "; ".join(f"{_t(label(n))} {p['mean_difference']:+.3f} (95% interval {p['ci95'][0]:+.3f} to "
                               f"{p['ci95'][1]:+.3f})" for n, p in paired) + ".")
    out += [_t(note) for note in doc["notes"]]
    out.append("Time is in the plan's time units: each robot motion, shake and look at its cost above; the figures "
               "and the table count the same time. Timings of the run are in results.json (<code>timing</code>), "
               "not here, so that the same study gives the same page.")
    return out


def render_report(result: StudyResult, doc: dict | None = None) -> str:
    """The report of a study as one HTML document (a string).

    Deterministic: the same study gives the same text.  Cost: drawing the figures, O(trials).

    Parameters
    ----------
    result : StudyResult
        The study.
    doc : dict, optional
        The study's :func:`~opportune.study.report.summary` (computed when not given).

    Returns
    -------
    str
        The HTML document, its figures inline (SVG).

    Examples
    --------
    >>> from opportune import load_plan
    >>> from opportune.study.simulate import StudyConfig, run_study
    >>> result = run_study(StudyConfig(load_plan("example:gearbox"), strategies=("paper",), trials=10), workers=1)
    >>> render_report(result).startswith("<!DOCTYPE html>")
    True
    """
    import matplotlib

    doc = doc or summary(result)
    with matplotlib.rc_context(figure_style()):
        figures = [(f, _svg_uri(f.figure)) for f in make_figures(result, doc)]
    setup = "\n".join(f"<tr><th scope=\"row\">{_t(k)}</th><td>{_t(v)}</td></tr>" for k, v in _setup_rows(result, doc))
    figs = "\n".join(
        f'<figure id="{f.stem}"><img src="{uri}" alt="{_t(f.stem.replace("_", " "))} of every strategy" '
        f'width="{int(f.figure.get_size_inches()[0] * 160)}">'
        f"<figcaption><b>Figure {i}.</b> {_t(f.caption)} "
        f"({'single' if f.width == 'single' else 'double'}-column size, "
        f"{f.figure.get_size_inches()[0]:g} in wide.)</figcaption></figure>"
        for i, (f, uri) in enumerate(figures, 1))
    notes = "\n".join(f"<li>{note}</li>" for note in _notes(result, doc))
    cap = "unlimited buffer" if doc["buffer_capacity"] is None else f"buffer of {doc['buffer_capacity']}"
    interrupted = ('<p><strong>Interrupted: only the trials that finished are reported.</strong></p>'
                   if doc["interrupted"] else "")
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{_t(doc['plan'])}: the paper's comparison, by simulation</title>
<style>{_CSS}</style>
</head>
<body>
<h1>{_t(doc['plan'])}: the paper's comparison, by simulation</h1>
<p class="sub">Every strategy of Fox and Kempf's comparison against the same simulated bins: {_t(doc['bin'])} bin,
{doc['visible']} visible, {cap}, {doc['trials']:,} trials per strategy, seed {doc['seed']}.</p>
{interrupted}
<h2 id="setup">Setup</h2>
<table class="setup">
{setup}
</table>
<h2 id="results">Results</h2>
<p>Time per assembly, best mean first; the interval is the mean's 95% confidence interval; motions, buffer
moves, shakes and buffer peak are means per assembly; × optimum divides the mean by the exact optimum.</p>
{_table(doc)}
<h2 id="figures">Figures</h2>
{figs or "<p>No trial finished: nothing to draw.</p>"}
<h2 id="notes">Notes</h2>
<ul>
{notes}
</ul>
</body>
</html>
"""


def write_report(result: StudyResult, path: str | Path, doc: dict | None = None) -> Path:
    """Write :func:`render_report` to ``path`` (UTF-8).

    Parameters
    ----------
    result : StudyResult
        The study.
    path : str or os.PathLike
        The file written.
    doc : dict, optional
        The study's :func:`~opportune.study.report.summary` (computed when not given).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    OSError
        If the file cannot be written.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from opportune import load_plan
    >>> from opportune.study.simulate import StudyConfig, run_study
    >>> result = run_study(StudyConfig(load_plan("example:gearbox"), strategies=("paper",), trials=10), workers=1)
    >>> write_report(result, pathlib.Path(tempfile.mkdtemp()) / "report.html").name
    'report.html'
    """
    doc = doc or summary(result)
    if sys.argv and Path(sys.argv[0]).name == "opportune" and "command" not in doc["provenance"]:
        doc = {**doc, "provenance": {**doc["provenance"],
                                     "command": " ".join(shlex.quote(a) for a in ["opportune", *sys.argv[1:]])}}
    path = Path(path)
    path.write_text(render_report(result, doc), encoding="utf-8")
    return path
