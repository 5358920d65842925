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
        expect(page.locator("#chart circle")).to_have_count(6)
        expect(page.locator("#pending")).to_contain_text("waiting for a look")

        # The rest of Table 1: the run is complete at the outcome of its last install, and the page says so
        # without another look.
        for visible in (["cl", "co"], ["cl", "co"], ["cl", "co"], ["cl", "sm"], ["cl", "st"], ["cl", "st"],
                        ["ra", "st"], ["st"], ["st"], []):
            cell.post(f"/runs/{run_id}/looks", {"visible": visible})
            cell.post(f"/runs/{run_id}/outcomes", {"outcome": "success"})
        expect(page.locator("#live")).to_have_text("complete")
        expect(page.locator("#pending")).to_contain_text("the assembly is complete")
        expect(page.locator("#count")).to_have_attribute("data-value", "1")
        expect(page.locator("#chart .top-label")).to_have_text("336")
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


# ---------------------------------------------------------------- large plans: frontier, fit, zoom, pan, find

def fmt_count(value: str | None) -> str:
    """The count as app.js's fmtCount writes it: grouped digits up to 15 digits, then ``d.dde<exp>``."""
    if value is None:
        return "—"
    m = re.fullmatch(r"(\d+(?:\.\d+)?)e\+?(\d+)", value, re.IGNORECASE)
    if m:
        return fmt_sci(float(m[1]), int(m[2]))
    if len(value) <= 15:
        return f"{int(value):,}"
    return fmt_sci(float(f"{value[0]}.{value[1:17]}"), len(value) - 1)


def fmt_log10(lg: float) -> str:
    """A count from its log10, as app.js's fmtLog10 writes the chart's top label."""
    if lg < 15:
        return f"{round(10 ** lg):,}"
    return fmt_sci(10 ** (lg - math.floor(lg)), math.floor(lg))


def fmt_sci(m: float, e: int) -> str:
    if float(f"{m:.2f}") >= 10:
        m, e = m / 10, e + 1
    return f"{m:.2f}e{e}"


def test_count_formats_agree_with_the_counts():
    # fmt_count is the test's oracle for the page: check it against the numbers themselves.
    assert fmt_count("336") == "336"
    assert fmt_count("198328699307040961787398932480") == "1.98e29"
    assert fmt_count(str(10**103 * 107 // 100)) == "1.07e103"
    assert fmt_count(str(99996 * 10**39)) == "1.00e44"             # rounding carries into the exponent
    assert fmt_count("2.8462596809170545e+35659") == "2.85e35659"  # the service's text past 4,300 digits
    assert fmt_log10(math.log10(336)) == "336"
    assert fmt_log10(29.297386) == "1.98e29"


def layered_plan(n: int = 1000, back: int = 5, seed: int = 7):
    """``n`` tasks, each requiring 1 or 2 of the ``back`` tasks before it: deep and narrow, like a long
    assembly line (narrow enough that its admissible sequences are counted exactly in a fraction of a second)."""
    rng = random.Random(seed)
    ids = [f"t{i:04d}" for i in range(n)]
    requires = {ids[i]: rng.sample(ids[max(0, i - back):i], min(i, rng.randint(1, 2))) for i in range(1, n)}
    return make_plan(ids, requires, name=f"layered-{n}")


def start_run(cell, plan, name) -> int:
    """Upload ``plan`` (as JSON), start a run, wait for its first count, and make up to three looks,
    each with a successful outcome: the first installs, the others buffer parts needed later."""
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
    first = run["installable"][0]
    for look in range(3):
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
                expect(page.locator("#count")).to_have_text(fmt_count(run["count"]["value"]))
                logs = [r["count"]["log10"] for r in rows if r["count"]] + [run["count"]["log10"]]
                expect(page.locator("#chart .top-label")).to_have_text(fmt_log10(max(logs)))

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

        # The page's own formatting agrees with this test's at every magnitude.
        rng = random.Random(3)
        values = [str(rng.randrange(10 ** (d - 1), 10 ** d)) for d in range(1, 400, 3)] + [str(99996 * 10**39)]
        assert page.evaluate("vs => vs.map((v) => fmtCount({ value: v }))", values) == [fmt_count(v) for v in values]

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
