"""The figures and the one-page report of a simulation study (report.py, report_html.py), and the
study's timing: print sizes and fonts read from the matplotlib objects, labelled rows, visible
intervals against a second computation, a self-contained HTML page whose numbers are results.json's,
and the same timing measures on one worker and on two."""

from __future__ import annotations

import base64
import json
import math
import re
from html.parser import HTMLParser

import matplotlib
import matplotlib.colors
import pytest
from conftest import GEARBOX, run_cli

from opportune import load_plan
from opportune.study.report import (
    COLUMN_WIDTHS,
    GROUP_OF,
    GROUPS,
    MIN_FONT_PT,
    OKABE_ITO,
    OPTIMUM_COLOUR,
    figure_style,
    label,
    make_figures,
    summary,
)
from opportune.study.report_html import TABLE_COLUMNS, render_report
from opportune.study.simulate import StudyConfig, run_study

GEAR = load_plan(GEARBOX)
# the paper's comparison in small: every family of row, and the exact optimum (0.6 s to solve)
NAMES = ("pallet", "shake", "kitting", "buffer", "paper", "random", "optimal")


@pytest.fixture(scope="module")
def gear_study():
    return run_study(StudyConfig(GEAR, strategies=NAMES, trials=60, seed=3), workers=1)


@pytest.fixture(scope="module")
def figures(gear_study):
    with matplotlib.rc_context(figure_style()):
        figs = make_figures(gear_study)
        for f in figs:
            f.figure.canvas.draw()
    return {f.stem: f for f in figs}


def texts(fig):
    from matplotlib.text import Text

    return [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()]


def t_interval_scipy(values):
    from scipy.special import stdtrit  # Student's t quantile, outside the project

    n = len(values)
    mean = sum(values) / n
    sd = math.sqrt(sum((x - mean) ** 2 for x in values) / (n - 1))
    half = stdtrit(n - 1, 0.975) * sd / math.sqrt(n)
    return mean - half, mean + half


def test_figures_are_drawn_at_column_width_with_print_size_text(figures):
    assert list(figures) == ["mean_time", "time_distribution"]           # one mean figure: no ratio figure
    assert figures["mean_time"].figure.get_size_inches()[0] == COLUMN_WIDTHS["single"] == 3.5
    assert figures["time_distribution"].figure.get_size_inches()[0] == COLUMN_WIDTHS["double"] == 7.2
    for f in figures.values():
        fig = f.figure
        width, height = fig.get_size_inches()
        assert 1.5 < height < 9
        sizes = [t.get_fontsize() for t in texts(fig)]
        assert len(sizes) > 15 and min(sizes) >= MIN_FONT_PT == 7
        # nothing drawn outside the page: a title or legend wider than the column would be cut off in print
        box = fig.get_tightbbox(fig.canvas.get_renderer())
        assert box.x0 >= -0.02 and box.y0 >= -0.02 and box.x1 <= width + 0.02 and box.y1 <= height + 0.02, (f.stem, box)


def test_every_row_has_its_descriptive_label_best_first(figures, gear_study):
    doc = summary(gear_study)
    order = sorted(NAMES, key=lambda n: (doc["strategies"][n]["time"]["mean"], n))
    for f in figures.values():
        ax = f.figure.axes[0]
        shown = [t.get_text() for t in ax.get_yticklabels()]
        assert shown == [label(n) for n in order]
        assert all(len(s) > len(n) + 4 for s, n in zip(shown, order))   # words, not the bare names
    assert label("paper") == "paper's rule" and label("lookahead") == "look-ahead (default)"


def test_the_mean_figure_shows_each_interval_and_the_optimum(figures, gear_study):
    """Every interval with a spread is drawn once, with caps, above its marker (hollow, in its family's
    colour): in the zoom panel for the rows near the optimum, in the first panel for the others."""
    from matplotlib.container import ErrorbarContainer

    doc = summary(gear_study)
    order = sorted(NAMES, key=lambda n: (doc["strategies"][n]["time"]["mean"], n))
    fig = figures["mean_time"].figure
    panels = [ax for ax in fig.axes if ax.get_yticklabels() and ax.get_label() != "<colorbar>" and ax.get_lines()]
    rows = {}   # label -> (axes, y)
    for ax in panels:
        for y, tick in enumerate(ax.get_yticklabels()):
            rows.setdefault(tick.get_text(), []).append((ax, y))
    assert set(rows) == {label(n) for n in order} and [t.get_text() for t in panels[0].get_yticklabels()] == \
        [label(n) for n in order]
    drawn = {}
    for ax in panels:
        for bar in (c for c in ax.containers if isinstance(c, ErrorbarContainer)):
            (segment,) = bar.lines[2][0].get_segments()
            assert segment[0][1] == segment[1][1] and len(bar.lines[1]) == 2     # caps at both ends
            name = order[[t.get_text() for t in panels[0].get_yticklabels()].index(
                ax.get_yticklabels()[int(segment[0][1])].get_text())]
            assert name not in drawn, name                                        # once
            drawn[name] = (ax, segment, bar.lines[2][0].get_zorder())
    for name in order:
        low, high = t_interval_scipy([t.time for t in gear_study.trials[name]])   # a second computation
        if high == low:                # pallet and kitting: no spread, nothing to draw but the marker
            assert name not in drawn
            continue
        ax, segment, zorder = drawn[name]
        assert segment[0][0] == pytest.approx(low) and segment[1][0] == pytest.approx(high)
        y = int(segment[0][1])
        (marker,) = [line for line in ax.get_lines() if list(line.get_ydata()) == [y]
                     and line.get_marker() in {g[2] for g in GROUPS.values()}]
        assert marker.get_zorder() < zorder and marker.get_markerfacecolor() == "white"   # the bar over it
        colour = matplotlib.colors.to_hex(marker.get_markeredgecolor())
        assert colour.upper() == GROUPS[GROUP_OF.get(name, "opportunistic")][1] in OKABE_ITO.values()
        if len(rows[label(name)]) == 2:   # in both panels: its interval in the zoom, where it is visible
            assert ax is panels[1] and high - low > 0.02 * (ax.get_xlim()[1] - ax.get_xlim()[0])
    optimum = gear_study.prepared.optimal_start
    for ax in panels:
        lines = [line for line in ax.get_lines() if list(line.get_xdata()) == [optimum, optimum]]
        assert len(lines) == 1 and lines[0].get_color() == OPTIMUM_COLOUR == OKABE_ITO["vermillion"]
    right = [t.get_text() for t in panels[0].child_axes[0].get_yticklabels()]
    assert right[order.index("pallet")].startswith("−26.3%")
    # a difference within the optimum's noise is marked, and the figure itself says what the mark means
    for name, text in zip(order, right):
        low, high = t_interval_scipy([t.time for t in gear_study.trials[name]])
        assert text.endswith("\u2020") == (low <= optimum <= high and low < high), (name, text)
    if any(text.endswith("\u2020") for text in right):
        assert any("\u2020 within sampling noise" in t.get_text() for t in texts(fig))


def test_the_gearbox_figure_enlarges_the_rows_near_the_optimum():
    """On the gearbox's 10,000-trial study (its intervals of ±0.03 on an axis of 10 to 28), the rows
    within 5% of the optimum get a zoom panel where each interval is wider than its marker."""
    from opportune.study.report import ZOOM_SPAN, _near_rows

    names = ["pallet", "lookahead", "optimal", "paper", "random", "buffer", "kitting", "shake"]
    means = [10.0, 13.55, 13.55, 13.69, 13.84, 15.13, 20.0, 27.83]
    cis = [(m - h, m + h) for m, h in zip(means, [0, 0.03, 0.03, 0.03, 0.03, 0.03, 0, 0.16])]
    near = _near_rows(names, means, cis, 13.5711)
    assert [names[i] for i in near] == ["lookahead", "optimal", "paper", "random"]
    assert all(abs(means[i] / 13.5711 - 1) <= ZOOM_SPAN for i in near)
    # spread out (intervals as wide as the gaps): nothing to enlarge
    assert _near_rows(names[:3], [13.0, 13.6, 14.2], [(12.0, 14.0), (12.6, 14.6), (13.2, 15.2)], 13.5711) == []


def test_the_caption_explains_the_optimums_noise_the_hidden_intervals_and_the_pallet(figures, gear_study):
    caption = figures["mean_time"].caption
    doc = summary(gear_study)
    mean = doc["strategies"]["optimal"]["time"]["mean"]
    assert f"{gear_study.prepared.optimal_start:.4f}" in caption and "no Monte Carlo error" in caption
    assert f"{mean:.2f}" in caption and "Monte Carlo noise" in caption
    # pallet and kitting have no spread at all: their intervals are narrower than the marker, and said so
    hidden = re.search(r"(Every interval|The intervals of)[^:]*narrower than", caption).group(0)
    if hidden.startswith("Every"):   # every interval but those named
        assert "pallet" not in hidden and "kitting" not in hidden and "shake" in hidden, hidden
    else:
        assert "pallet" in hidden and "kitting" in hidden and "shake" not in hidden, hidden
    assert "Pallet is below the optimum because its parts arrive in the planned sequence" in caption
    assert "5th and 95th percentiles" in figures["time_distribution"].caption


# ---------------------------------------------------------------- the report


class Page(HTMLParser):
    """The attributes that could fetch something, and the results table's cells."""

    def __init__(self):
        super().__init__()
        self.links, self.cells, self.rows, self._cell = [], [], [], None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.links += [(tag, k, v) for k, v in attrs.items() if k in ("src", "href", "srcset", "data", "action",
                                                                         "poster", "xlink:href")]
        if tag == "tr" and "data-strategy" in attrs:
            self.rows.append(attrs["data-strategy"])
        if tag == "td" and "data-key" in attrs:
            self._cell = [self.rows[-1], attrs["data-key"], attrs.get("data-value"), ""]

    def handle_data(self, data):
        if self._cell is not None:
            self._cell[3] += data

    def handle_endtag(self, tag):
        if tag == "td" and self._cell is not None:
            self.cells.append(tuple(self._cell))
            self._cell = None


def test_the_report_is_one_page_with_the_numbers_of_results_json(tmp_path):
    # --json prints results.json's document (without writing the figure files: faster)
    r = run_cli("simulate", GEARBOX, "--trials", 40, "--seed", 5, "--workers", 1, "--json",
                "--strategies", "pallet,buffer,paper,random,optimal", "--report", tmp_path / "report.html")
    assert r.exit_code == 0, r.output
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    doc = json.loads(r.output)

    parsed = Page()
    parsed.feed(page)
    # self-contained: everything it would load is inline
    assert parsed.links and all(v.startswith(("data:", "#")) for _, _, v in parsed.links), parsed.links
    assert not re.search(r"<script|<link|@import|url\(|<iframe|<object", page, re.IGNORECASE)
    assert "://" not in page
    # the table: one row per strategy, every number the one in results.json
    assert sorted(parsed.rows) == sorted(doc["strategies"])
    getters = {key: (get, fmt) for key, _, get, fmt in TABLE_COLUMNS}
    assert len(parsed.cells) == len(doc["strategies"]) * len(TABLE_COLUMNS)
    for name, key, value, text in parsed.cells:
        get, fmt = getters[key]
        expected = get(doc["strategies"][name])
        if expected is None:
            assert value is None and text == "—"
        else:
            assert float(value) == expected and text == fmt.format(expected), (name, key)
    # the setup, the figures (SVG, with their descriptive rows), the notes
    for words in ("gearbox: 10 parts", "uniform", "2 parts per look", "unlimited", "40 per strategy",
                  "<th scope=\"row\">seed</th><td>5</td>", "machine", "look-ahead (default)",
                  "paper&#x27;s rule", "no Monte Carlo error", "Pallet is the cost with no uncertainty"):
        assert words in page, words
    svgs = [base64.b64decode(v.split(",", 1)[1]).decode() for tag, k, v in parsed.links if tag == "img"]
    assert len(svgs) == 2 and all(s.lstrip().startswith(("<?xml", "<svg")) for s in svgs)
    assert all(("paper&#x27;s rule" in s or "paper's rule" in s) and "<dc:date>" not in s for s in svgs)


def test_the_report_is_the_same_for_the_same_study():
    config = StudyConfig(GEAR, strategies=("pallet", "paper", "random"), trials=30, seed=11)
    one, two = (render_report(run_study(config, workers=w)) for w in (1, 2))
    assert one == two and "30 trials per strategy, seed 11" in one


def test_a_report_that_cannot_be_written_is_refused_before_the_study(tmp_path):
    (tmp_path / "adir").mkdir()
    cases = [(tmp_path / "report.pdf", "ending in .html"),
             (tmp_path / "missing" / "report.html", "does not exist"),
             (tmp_path / "adir", "is a directory")]
    for path, words in cases:
        # 10 million trials: only a refusal before the study finishes in a test's time
        r = run_cli("simulate", GEARBOX, "--trials", 10_000_000, "--report", path)
        assert r.exit_code == 2 and words in r.output and "error:" in r.output, r.output
        assert not (tmp_path / "missing").exists()
    # but a report inside --out's directory, which the command makes before writing the report, is fine
    from opportune.cli.simulate import _check_report_path

    _check_report_path(tmp_path / "new" / "report.html", None, tmp_path / "new", False)   # no exit
    r = run_cli("simulate", GEARBOX, "--products", 2, "--report", tmp_path / "r.html", "--json")
    assert r.exit_code == 2 and "--products" in json.loads(r.output)["error"]["message"]
    assert not (tmp_path / "r.html").exists()


# ---------------------------------------------------------------- timing


@pytest.mark.parametrize("workers", [1, 2])
def test_timing_means_the_same_on_one_worker_and_on_two(workers):
    names = ("paper", "random", "buffer")
    config = StudyConfig(GEAR, strategies=names, trials=120, seed=1)
    result = run_study(config, workers=workers, chunk_size=20)
    timing = summary(result)["timing"]
    assert set(timing) == {"wall_seconds", "workers", "cpu_seconds", "optimal_solve_seconds"}
    assert timing["workers"] == workers and timing["optimal_solve_seconds"] is None
    assert list(timing["cpu_seconds"]) == list(names) and all(v > 0 for v in timing["cpu_seconds"].values())
    # CPU seconds summed over the workers: never more than the workers could spend in the study's elapsed time
    # (the former per-strategy wall clock counted the same seconds once per strategy on several workers).
    # Not a time bound: load only adds elapsed time, so these hold on a loaded machine as on an idle one.
    assert sum(timing["cpu_seconds"].values()) <= workers * timing["wall_seconds"] + 0.05
    assert timing["wall_seconds"] >= result.prepared.seconds > 0
    assert result.seconds == result.cpu_seconds                     # the former name reads the same numbers


def test_a_plan_name_with_markup_and_dollars_is_text_on_the_page_and_in_the_figures():
    from opportune import make_plan

    name = "<b onload=x>$\\frac$ & co"   # markup, and mathtext that matplotlib could not parse
    plan = make_plan(["a", "b", "c"], {"c": ["a"]}, name=name)
    page = render_report(run_study(StudyConfig(plan, strategies=("pallet", "paper"), trials=8), workers=1))
    assert "<b onload" not in page and "&lt;b onload=x&gt;$\\frac$ &amp; co" in page


def test_long_names_and_equal_means_stay_on_the_page():
    from opportune import make_plan

    plan = make_plan(["a", "b", "c"], {"c": ["a"]}, name="a plan whose name is much longer than a column's title " * 2)
    result = run_study(StudyConfig(plan, strategies=("pallet", "paper", "slack", "bin-first"), trials=10),
                       workers=1)
    with matplotlib.rc_context(figure_style()):
        for f in make_figures(result):
            f.figure.canvas.draw()
            width, height = f.figure.get_size_inches()
            box = f.figure.get_tightbbox(f.figure.canvas.get_renderer())
            assert box.x0 >= -0.02 and box.x1 <= width + 0.02 and box.y1 <= height + 0.02, (f.stem, box)
            assert min(t.get_fontsize() for t in texts(f.figure)) >= MIN_FONT_PT
            low, high = f.figure.axes[0].get_xlim()
            assert low < 3 < high and high - low > 0.05          # every mean is 3: a readable axis around it


def test_the_report_table_fits_a_1280_pixel_window(tmp_path):
    """In Debian's chromium (as tests/test_service_browser.py drives it) at 1280x800, the results table of a
    study with every strategy but the slow rollout fits the text column: no horizontal scroll, and no cell
    whose text overflows it."""
    import os
    import shutil

    from opportune.study.simulate import ALL_STRATEGIES

    chromium = os.environ.get("OPPORTUNE_CHROMIUM", "/usr/bin/chromium")
    if not (os.path.exists(chromium) or shutil.which(chromium)):
        pytest.fail(f"chromium not found at {chromium}: `make test` installs it (apt-get install chromium); "
                    "OPPORTUNE_CHROMIUM points elsewhere")
    from playwright.sync_api import sync_playwright

    names = tuple(n for n in ALL_STRATEGIES if n != "rollout")
    page_file = tmp_path / "report.html"
    page_file.write_text(render_report(run_study(StudyConfig(GEAR, strategies=names, trials=40, seed=1), workers=1)),
                         encoding="utf-8")
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, headless=True,
                                     args=["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run"])
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            page.goto(page_file.as_uri())
            sizes = page.evaluate("""() => {
                const table = document.querySelector('table.results').getBoundingClientRect();
                const body = document.body, style = getComputedStyle(body);
                const cells = [...document.querySelectorAll('table.results th, table.results td')]
                    .filter(c => c.scrollWidth > c.clientWidth + 1).map(c => c.textContent);
                return {page: document.documentElement.scrollWidth, right: table.right, columns:
                        document.querySelectorAll('table.results thead th').length,
                        text_right: body.getBoundingClientRect().right - parseFloat(style.paddingRight),
                        overflowing: cells};
            }""")
        finally:
            browser.close()
    assert sizes["columns"] == len(TABLE_COLUMNS) + 1
    assert sizes["page"] <= 1280 and sizes["right"] <= sizes["text_right"] + 0.5, sizes
    assert sizes["overflowing"] == [], sizes
