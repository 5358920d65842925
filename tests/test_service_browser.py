"""The dashboard in a real browser: Playwright driving Debian's chromium against a real server.

Signs in with an operator token, finds the run in its cell's list, opens the
run page and watches it advance as a cell posts looks and outcomes: the
graph's colours, the trace table and the count of admissible sequences
change live (server-sent events), and nothing is fetched from anywhere else.

On large plans (KILBRID, ARC111, a generated 1,000-task plan, a layer of 300
parts) at 1280x800 and 1920x1080: the frontier view fits every installable and
buffered part inside the graph panel, large enough to read, the count label is
the API's count as the page formats it, and find, zoom, pan, fit and the full
graph work.  Screenshots of each run page go to the test's tmp_path (their
paths are printed: ``pytest -s`` shows them).
"""

from __future__ import annotations

import json
import math
import os
import random
import re
import shutil
import time

import pytest
from conftest import GEARBOX

from opportune import load_plan, make_plan
from opportune.policies.printable import LABEL_DIGITS, count_label
from opportune.service.testing import Client, ServiceProcess

CHROMIUM = os.environ.get("OPPORTUNE_CHROMIUM", "/usr/bin/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]


@pytest.fixture()
def browser_context(tmp_path):
    if not (os.path.exists(CHROMIUM) or shutil.which(CHROMIUM)):
        pytest.fail(f"chromium not found at {CHROMIUM}: `make test` installs it (apt-get install chromium); "
                    "OPPORTUNE_CHROMIUM points elsewhere")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        context = pw.chromium.launch_persistent_context(str(tmp_path / "profile"), executable_path=CHROMIUM,
                                                        headless=True, args=ARGS)
        try:
            yield context
        finally:
            context.close()


def test_dashboard_watches_a_run_advance(tmp_path, browser_context):
    from playwright.sync_api import expect

    with ServiceProcess(tmp_path / "ui.db") as svc:
        cell = Client(svc.url, svc.token(cell="cell-7"))
        operator = svc.token(operator="ops")
        plan = cell.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"}).json()["id"]
        run_id = cell.post("/runs", {"plan": plan, "label": "SN-0042", "policy": "paper"}).json()["id"]
        assert cell.post(f"/runs/{run_id}/looks", {"visible": ["rl", "ra"]}).status_code == 200

        page = browser_context.new_page()
        requests, problems = [], []
        page.on("request", lambda r: requests.append(r.url))
        page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: problems.append(str(e)))

        # The list of runs per cell, after signing in once.
        page.goto(svc.url + "/")
        page.fill("#token", operator)
        page.click("#login-form button")
        row = page.locator(f"section[data-cell='cell-7'] tr[data-run='{run_id}']")
        expect(row).to_contain_text("gearbox")
        expect(row).to_contain_text("SN-0042")
        expect(row).to_contain_text("0/10")
        expect(row).to_contain_text("buffer rl")

        # The run page: graph, trace, count.
        row.click()
        page.wait_for_url(f"**/ui/runs/{run_id}")
        expect(page.locator("#live")).to_have_text("live")
        # The frontier by default: what can go in, what is seen, and the next layer; not the whole plan.
        expect(page.locator("#graph svg")).to_have_attribute("data-view", "frontier")
        nodes = page.locator("#graph g.node")
        expect(nodes).to_have_count(7)  # ca; rl and ra (seen); ba, sm, co, cl (next)
        expect(page.locator("[data-part='dr']")).to_have_count(0)
        expect(page.locator("#graph-note")).to_contain_text("Frontier: 7 of 10 parts")
        # The full graph, one click away; it stays chosen as the run advances.
        page.click("#view-full")
        expect(page.locator("#graph svg")).to_have_attribute("data-view", "full")
        expect(nodes).to_have_count(10)
        expect(page.locator("#graph polyline.edge")).to_have_count(14)
        expect(page.locator("[data-part='rl']")).to_have_attribute("data-state", "pending")
        expect(page.locator("[data-part='ca']")).to_have_attribute("data-state", "installable")
        expect(page.locator("[data-part='ra']")).to_have_attribute("data-state", "visible")
        trace = page.locator("#trace tbody tr")
        expect(trace).to_have_count(1)
        expect(trace.nth(0)).to_contain_text("buffer rl")
        expect(trace.nth(0)).to_contain_text("pending")
        expect(page.locator("#count")).to_have_attribute("data-value", "336")
        expect(page.locator("#pending")).to_contain_text("buffer rl")

        # The cell works on; the page follows without being reloaded.
        cell.post(f"/runs/{run_id}/outcomes", {"outcome": "success"})
        expect(page.locator("[data-part='rl']")).to_have_attribute("data-state", "buffered")
        expect(trace.nth(0)).to_contain_text("success")
        for visible in (["ca", "co"], ["co", "ml"], ["st", "dr"], ["cl", "ba"]):
            cell.post(f"/runs/{run_id}/looks", {"visible": visible})
            cell.post(f"/runs/{run_id}/outcomes", {"outcome": "success"})
        expect(trace).to_have_count(5)
        expect(trace.nth(4)).to_contain_text("install ba")
        expect(page.locator("[data-part='ca']")).to_have_attribute("data-state", "installed")
        expect(page.locator("[data-part='ba']")).to_have_attribute("data-state", "installed")
        expect(page.locator("[data-part='ml']")).to_have_attribute("data-state", "buffered")
        expect(page.locator("[data-edge='ca>ba']")).to_have_class("edge done")
        left = int(page.locator("#count").get_attribute("data-value"))
        assert 1 < left < 336  # installing ba took options away
        assert left == int(cell.get(f"/runs/{run_id}").json()["count"]["value"])
        # the chart: log10 of the count over log10 of the first, one point per number of units installed
        rows = cell.get(f"/runs/{run_id}/trace").json()["rows"]
        expected = {len(r["installed"]): r["count"]["log10"] / math.log10(336) for r in rows}
        expected[2] = math.log10(left) / math.log10(336)
        got, want = chart_series(page), sorted(expected.items())
        assert [x for x, _ in got] == [x for x, _ in want] and all(abs(a[1] - b[1]) < 1e-5 for a, b in zip(got, want))
        expect(page.locator("#pending")).to_contain_text("waiting for a look")
        expect(page.locator("#summary")).to_be_hidden()

        # The rest of Table 1: the run is complete at the outcome of its last install, and the page says so
        # without another look.
        for visible in (["cl", "co"], ["cl", "co"], ["cl", "co"], ["cl", "sm"], ["cl", "st"], ["cl", "st"],
                        ["ra", "st"], ["st"], ["st"], []):
            cell.post(f"/runs/{run_id}/looks", {"visible": visible})
            cell.post(f"/runs/{run_id}/outcomes", {"outcome": "success"})
        # Complete: a summary of the run, and a status that reads as done, not as a fault.
        expect(page.locator("#summary")).to_be_visible()
        expect(page.locator("#live")).to_be_hidden()
        expect(page.locator("#status")).to_have_text("complete")
        assert greenish(page.locator("#status")), page.locator("#status").evaluate("e => getComputedStyle(e).backgroundColor")
        expect(page.locator("#pending")).to_contain_text("the assembly is complete")
        expect(page.locator("#count")).to_have_attribute("data-value", "1")
        expect(page.locator("#chart .top-label")).to_have_text("336")
        run = cell.get(f"/runs/{run_id}").json()
        rows = cell.get(f"/runs/{run_id}/trace").json()["rows"]
        kinds = [r["action"]["kind"] for r in rows]
        assert run["totals"] == {"installed": 10, "looks": 15, "motions": 15, "buffer_moves": kinds.count("buffer"),
                                 "buffer_peak": max(len(r["buffered"]) for r in rows), "shakes": kinds.count("shake"),
                                 "failed": 0, "defects": 0, "time": 15.0}
        tiles = dict(zip(page.locator("#summary .tile .k").all_text_contents(),
                         page.locator("#summary .tile .v").all_text_contents()))
        assert tiles["parts installed"] == "10 of 10" and tiles["looks"] == "15" and tiles["motions"] == "15"
        assert tiles["buffer moves"] == f"{kinds.count('buffer')} (peak {run['totals']['buffer_peak']})"
        assert tiles["shakes"] == "0" and tiles["policy"] == "paper" and tiles["time (motions, shakes, looks)"] == "15"
        assert page.locator("#sequence li").all_text_contents() == run["state"]["installed"]
        assert set(run["state"]["installed"]) == set(GEARBOX_PARTS)
        shot = tmp_path / "dashboard-complete-1280x800.png"
        page.set_viewport_size({"width": 1280, "height": 800})
        page.screenshot(path=str(shot))
        print(f"screenshot: {shot}")
        page.click("#view-frontier")
        expect(page.locator("#graph-note")).to_contain_text("Complete: the last 2 parts")
        expect(page.locator("#graph g.node")).to_have_count(2)  # st and cl, which nothing requires

        # Back on the list, the progress moved.
        page.goto(svc.url + "/")
        expect(page.locator(f"tr[data-run='{run_id}']")).to_contain_text("10/10")
        expect(page.locator(f"tr[data-run='{run_id}']")).to_contain_text("complete")

        assert not problems, problems
        assert requests and all(u.startswith(svc.url + "/") for u in requests), [u for u in requests if not u.startswith(svc.url)]
        cell.close()


# ---------------------------------------------------------------- legible at 1280x800: ARC111 as a cell runs it

LABEL_PX = 11   # the frontier's labels (part ids, layer headers) are drawn at least this many pixels high

# Every text of the frontier with its rendered font size (its computed size times the drawing's scale on
# screen) and its box; every number a person can read on the page (text shown, tooltips); every element of
# a panel wider inside than it shows (but the scrolling ones); every panel's content's right edge.
MEASURE = """() => {
  const svg = document.querySelector('#graph svg'), k = svg.getScreenCTM().a;
  const labels = [...svg.querySelectorAll('g.node text, text.layer')].map((t) => {
    const r = t.getBoundingClientRect();
    return { text: t.textContent, px: parseFloat(getComputedStyle(t).fontSize) * k,
             x: r.x, y: r.y, width: r.width, height: r.height };
  });
  const shown = [document.body.innerText, ...[...document.querySelectorAll('[title]')].map((e) => e.title),
                 ...[...document.querySelectorAll('svg title')].map((e) => e.textContent)].join('\\n');
  const visible = (e) => e.offsetParent !== null && !e.closest('svg');
  const overflowing = [...document.querySelectorAll('.card, .card *')]
    .filter((e) => visible(e) && e.scrollWidth > e.clientWidth + 1 && getComputedStyle(e).overflowX !== 'auto')
    .map((e) => `${e.tagName}#${e.id}.${e.className}: ${e.scrollWidth} > ${e.clientWidth}`);
  const cards = [...document.querySelectorAll('.card')].filter(visible).map((c) => ({
    id: c.id || c.className, right: c.getBoundingClientRect().right,
    inner: Math.max(0, ...[...c.querySelectorAll('*')].filter((e) => visible(e) && !e.closest('.graph, .trace'))
                                .map((e) => e.getBoundingClientRect().right)) }));
  return { labels, shown, overflowing, cards, pageWidth: document.documentElement.scrollWidth };
}"""


def test_arc111_is_legible_at_1280x800_and_its_progress_shows(tmp_path, browser_context):
    """ARC111 (111 tasks, 1.07e103 sequences) run by a cell that sees two or three parts a look: at every
    step checked the frontier's labels are at least 11 px and inside the panel, no panel overflows, no
    number on the page is longer than 15 digits, and the chart of sequences left falls as parts go in."""
    from playwright.sync_api import expect

    plan = load_plan("salbp:ARC111")
    rng = random.Random(11)
    with ServiceProcess(tmp_path / "arc.db") as svc:
        cell = Client(svc.url, svc.token(cell="cell-3"))
        run_id = start_run(cell, plan, "ARC111", looks=0)
        page = browser_context.new_page()
        problems = []
        page.on("pageerror", lambda e: problems.append(str(e)))
        page.set_viewport_size({"width": 1280, "height": 800})
        page.goto(f"{svc.url}/ui/runs/{run_id}")
        page.fill("#token", svc.token(operator="ops"))
        page.click("#login-form button")
        expect(page.locator("#live")).to_have_text("live")
        smallest = math.inf
        for step in range(31):
            run = cell.get(f"/runs/{run_id}").json()
            if step % 10 == 0:  # once the page has caught up with the run: measure it
                expect(page.locator("#count")).to_have_attribute("data-value", run["count"]["value"])
                expect(page.locator("#trace tbody tr")).to_have_count(run["rows"])
                got = page.evaluate(MEASURE)
                panel = page.locator("#graph").bounding_box()
                assert got["labels"], step
                for label in got["labels"]:
                    assert label["px"] >= LABEL_PX and label["height"] >= LABEL_PX, (step, label)
                    assert inside(label, panel), (step, label, panel)
                smallest = min(smallest, *(label["px"] for label in got["labels"]))
                longest = max(len(m.replace(",", "")) for m in re.findall(r"\d[\d,]*", got["shown"]))
                assert longest <= LABEL_DIGITS, (step, longest)
                assert not got["overflowing"] and got["pageWidth"] <= 1280, (step, got["overflowing"], got["pageWidth"])
                for card in got["cards"]:
                    assert card["inner"] <= card["right"] + 0.5, (step, card)
                page.screenshot(path=str(tmp_path / f"arc111-step{step}-1280x800.png"))
            in_bin = [p for p, k in run["state"]["in_bin"].items() for _ in range(k)]
            installable = [p for p in run["installable"] if p in in_bin]
            look = rng.sample(in_bin, min(2, len(in_bin))) + (installable[:1] if rng.random() < 0.7 else [])
            assert cell.post(f"/runs/{run_id}/looks", {"visible": list(dict.fromkeys(look))}).status_code == 200
            assert cell.post(f"/runs/{run_id}/outcomes", {"outcome": "success"}).status_code == 200

        # The chart: log10 of the count relative to the first, from 1 at the start to 0 at the end, against
        # the units installed out of 111: it has fallen as far as the count has.
        run = cell.get(f"/runs/{run_id}").json()
        first = cell.get(f"/runs/{run_id}/trace").json()["rows"][0]["count"]
        expect(page.locator("#count")).to_have_attribute("data-value", run["count"]["value"])
        series = chart_series(page)
        assert series[0] == (0, 1.0) and run["progress"]["installed"] >= 15, (series[:3], run["progress"])
        assert series[-1][0] == run["progress"]["installed"]
        assert abs(series[-1][1] - run["count"]["log10"] / first["log10"]) < 1e-6
        assert all(a[1] >= b[1] for a, b in zip(series, series[1:]))          # installing never adds options
        ys = [float(p.split(",")[1]) for p in page.locator("#chart polyline").get_attribute("points").split()]
        plot = page.locator("#chart svg").bounding_box()["height"] - 42       # the chart's height less its margins
        assert max(ys) - min(ys) >= (1 - series[-1][1]) * plot - 1 and max(ys) - min(ys) >= 10, (ys, series[-1])
        expect(page.locator("#chart .top-label")).to_have_text(first["text"])
        page.screenshot(path=str(tmp_path / "arc111-1280x800.png"))
        print(f"screenshots: {tmp_path}; smallest label {smallest:.1f} px")

        # The longest count written in full (15 digits, 17 free parts: 17!) and the shortest written as an
        # exponent (18!) fit the count's panel too.
        for n, text in ((17, "355,687,428,096,000"), (18, "6.40e15")):
            run_id = start_run(cell, make_plan([f"p{i}" for i in range(n)], {}, name=f"free-{n}"), f"free-{n}", looks=0)
            page.goto(f"{svc.url}/ui/runs/{run_id}")
            expect(page.locator("#count")).to_have_text(text)
            got = page.evaluate(MEASURE)
            assert not got["overflowing"] and all(c["inner"] <= c["right"] + 0.5 for c in got["cards"]), got
        assert not problems, problems
        cell.close()


# ---------------------------------------------------------------- large plans: frontier, fit, zoom, pan, find

GEARBOX_PARTS = ("ca", "ba", "rl", "dr", "sm", "ml", "ra", "co", "st", "cl")


def chart_series(page) -> list:
    """The chart's points as it plots them: ``[units installed, log10(count) / log10(first count)]``."""
    return [tuple(p) for p in json.loads(page.locator("#chart svg").get_attribute("data-series"))]


def greenish(locator) -> bool:
    """Whether an element's background is a green (a status that reads as done), not a red or a grey."""
    r, g, b = map(int, re.findall(r"\d+", locator.evaluate("e => getComputedStyle(e).backgroundColor"))[:3])
    return g > r + 40 and g > b + 20


def layered_plan(n: int = 1000, back: int = 5, seed: int = 7):
    """``n`` tasks, each requiring 1 or 2 of the ``back`` tasks before it: deep and narrow, like a long
    assembly line (narrow enough that its admissible sequences are counted exactly in a fraction of a second)."""
    rng = random.Random(seed)
    ids = [f"t{i:04d}" for i in range(n)]
    requires = {ids[i]: rng.sample(ids[max(0, i - back):i], min(i, rng.randint(1, 2))) for i in range(1, n)}
    return make_plan(ids, requires, name=f"layered-{n}")


def start_run(cell, plan, name, looks: int = 3) -> int:
    """Upload ``plan`` (as JSON), start a run, wait for its first count, and make up to ``looks`` (at most
    three) looks, each with a successful outcome: the first installs, the others buffer parts needed later."""
    body = json.dumps(plan.to_dict())
    plan_id = cell.post("/plans", content=body, headers={"Content-Type": "application/json"}).json()["id"]
    run_id = cell.post("/runs", {"plan": plan_id, "label": name}).json()["id"]
    for _ in range(300):  # the plan's first count is made in the background, once per plan (ARC111: seconds)
        run = cell.get(f"/runs/{run_id}").json()
        if run["count"] is not None:
            break
        time.sleep(0.1)
    else:
        pytest.fail(f"{name}: no count after 30 s")
    if not looks:
        return run_id
    first = run["installable"][0]
    for look in range(looks):
        later = [p for p in plan.part_ids if p not in run["installable"] and p not in run["state"]["buffered"]
                 and p not in run["state"]["installed"]]
        if not later:
            break
        visible = [[first, later[-1]], [later[len(later) // 2]], [later[len(later) // 3], later[-2:][0]]][look]
        visible = list(dict.fromkeys(visible))
        assert cell.post(f"/runs/{run_id}/looks", {"visible": visible}).status_code == 200
        assert cell.post(f"/runs/{run_id}/outcomes", {"outcome": "success"}).status_code == 200
        run = cell.get(f"/runs/{run_id}").json()
    assert run["state"]["installed"] == [first] and run["state"]["buffered"], run["state"]
    return run_id


def inside(box, outer, slack: float = 0.5) -> bool:
    return (box["x"] >= outer["x"] - slack and box["y"] >= outer["y"] - slack
            and box["x"] + box["width"] <= outer["x"] + outer["width"] + slack
            and box["y"] + box["height"] <= outer["y"] + outer["height"] + slack)


def test_dashboard_frontier_on_large_plans(tmp_path, browser_context):
    from playwright.sync_api import expect

    plans = {"gearbox": load_plan(GEARBOX), "KILBRID": load_plan("salbp:KILBRID"),
             "ARC111": load_plan("salbp:ARC111"), "layered-1000": layered_plan()}
    with ServiceProcess(tmp_path / "big.db") as svc:
        cell = Client(svc.url, svc.token(cell="cell-9"))  # plans are per cell: this cell uploads its own
        runs = {name: start_run(cell, plan, name) for name, plan in plans.items()}

        page = browser_context.new_page()
        requests, problems = [], []
        page.on("request", lambda r: requests.append(r.url))
        page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: problems.append(str(e)))
        page.goto(f"{svc.url}/ui/runs/{runs['gearbox']}")
        page.fill("#token", svc.token(operator="ops"))
        page.click("#login-form button")

        for width, height in ((1280, 800), (1920, 1080)):
            page.set_viewport_size({"width": width, "height": height})
            screen = {"x": 0, "y": 0, "width": width, "height": height}
            for name, run_id in runs.items():
                page.goto(f"{svc.url}/ui/runs/{run_id}")
                expect(page.locator("#live")).to_have_text("live")
                run = cell.get(f"/runs/{run_id}").json()
                rows = cell.get(f"/runs/{run_id}/trace").json()["rows"]
                expect(page.locator("#graph svg")).to_have_attribute("data-view", "frontier")
                assert run["count"]["text"] == count_label(run["count"]["value"])   # the service writes it
                expect(page.locator("#count")).to_have_text(run["count"]["text"])
                expect(page.locator("#chart .top-label")).to_have_text(rows[0]["count"]["text"])

                # The graph panel takes most of the width and fits the screen; every installable and
                # buffered part is drawn inside it, large enough to read.
                panel = page.locator("#graph").bounding_box()
                assert inside(panel, screen) and panel["width"] >= 0.55 * width, (name, width, panel)
                shown = page.locator("#graph g.node").count()
                assert shown <= 40 or shown < len(plans[name].part_ids) // 10, (name, shown)
                for part in set(run["installable"]) | set(run["state"]["buffered"]):
                    node = page.locator(f"#graph g.node[data-part='{part}']")
                    box = node.locator("rect").bounding_box()
                    assert inside(box, panel), (name, width, part, box, panel)
                    assert box["height"] >= 19.5, (name, width, part, box)  # 26 units at 0.75 px a unit or more
                    expected = "buffered" if part in run["state"]["buffered"] else "installable"
                    assert node.get_attribute("data-state") in (expected, "visible"), (name, part)

                shot = tmp_path / f"dashboard-{name}-{width}x{height}.png"
                page.screenshot(path=str(shot))
                print(f"screenshot: {shot}")

        # A frontier 300 parts tall (a layer of 300 parts, all installable) wraps into columns that fit the
        # panel: every part inside it.
        wide = make_plan([f"w{i:03d}" for i in range(300)] + ["top"], {"top": [f"w{i:03d}" for i in range(300)]},
                         name="wide")
        run_id = start_run(cell, wide, "wide")
        page.set_viewport_size({"width": 1280, "height": 800})
        page.goto(f"{svc.url}/ui/runs/{run_id}")
        expect(page.locator("#live")).to_have_text("live")
        expect(page.locator("#graph g.node")).to_have_count(301)
        panel = page.locator("#graph").bounding_box()
        boxes = page.evaluate("""() => [...document.querySelectorAll('#graph g.node')].map((g) => {
            const r = g.querySelector('rect').getBoundingClientRect();
            return { part: g.dataset.part, x: r.x, y: r.y, width: r.width, height: r.height }; })""")
        outside = [b["part"] for b in boxes if not inside(b, panel)]
        assert not outside, outside
        assert min(b["height"] for b in boxes) >= 10, boxes[0]  # 26 units at 0.38 px a unit or more
        shot = tmp_path / "dashboard-wide-300-1280x800.png"
        page.screenshot(path=str(shot))
        print(f"screenshot: {shot}")

        # On the 1,000-task run: find a part off the frontier, zoom, pan, fit, and back to the frontier.
        page.set_viewport_size({"width": 1280, "height": 800})
        run_id = runs["layered-1000"]
        page.goto(f"{svc.url}/ui/runs/{run_id}")
        expect(page.locator("#live")).to_have_text("live")
        svg = page.locator("#graph svg")
        page.fill("#find", "nope")
        page.press("#find", "Enter")
        expect(page.locator("#find-note")).to_have_text('no part "nope" in this plan')
        page.fill("#find", "T0700")  # ids are found ignoring case
        page.press("#find", "Enter")
        expect(svg).to_have_attribute("data-view", "full")
        found = page.locator("#graph g.node[data-part='t0700']")
        expect(found).to_have_class("node found")
        panel = page.locator("#graph").bounding_box()
        box = found.locator("rect:not(.halo)").bounding_box()
        assert abs(box["x"] + box["width"] / 2 - (panel["x"] + panel["width"] / 2)) < 2, (box, panel)
        assert abs(box["y"] + box["height"] / 2 - (panel["y"] + panel["height"] / 2)) < 2, (box, panel)

        def view_box():
            return [float(v) for v in svg.get_attribute("viewBox").split()]

        before = view_box()
        page.mouse.move(panel["x"] + panel["width"] / 2, panel["y"] + panel["height"] / 2)
        page.mouse.wheel(0, -400)  # wheel up: zoom in about the pointer
        page.wait_for_function("w => Number(document.querySelector('#graph svg').viewBox.baseVal.width) < w",
                               arg=before[2])
        zoomed = view_box()
        scale = panel["width"] / zoomed[2]
        page.mouse.down()
        page.mouse.move(panel["x"] + panel["width"] / 2 - 200, panel["y"] + panel["height"] / 2, steps=4)
        page.mouse.up()
        panned = view_box()
        assert abs((panned[0] - zoomed[0]) * scale - 200) < 2 and abs(panned[1] - zoomed[1]) < 1e-6, (zoomed, panned)
        page.click("#fit")  # the whole plan in the panel
        for part in ("t0000", "t0999"):
            assert inside(page.locator(f"#graph g.node[data-part='{part}'] rect").bounding_box(), panel), part
        expect(page.locator("#graph g.node")).to_have_count(1000)
        page.click("#view-frontier")
        expect(svg).to_have_attribute("data-view", "frontier")
        run = cell.get(f"/runs/{run_id}").json()
        for part in run["state"]["buffered"]:
            assert inside(page.locator(f"#graph g.node[data-part='{part}']").bounding_box(), panel), part

        assert not problems, problems
        assert all(u.startswith(svc.url + "/") for u in requests), [u for u in requests if not u.startswith(svc.url)]
        cell.close()
