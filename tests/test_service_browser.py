"""The dashboard in a real browser: Playwright driving Debian's chromium against a real server.

Signs in with an operator token, finds the run in its cell's list, opens the
run page and watches it advance as a cell posts looks and outcomes: the
graph's colours, the trace table and the count of admissible sequences
change live (server-sent events), and nothing is fetched from anywhere else.
"""

from __future__ import annotations

import os
import shutil

import pytest

from conftest import GEARBOX
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
        nodes = page.locator("#graph g.node")
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

        # Back on the list, the progress moved.
        page.goto(svc.url + "/")
        expect(page.locator(f"tr[data-run='{run_id}']")).to_contain_text("2/10")

        assert not problems, problems
        assert requests and all(u.startswith(svc.url + "/") for u in requests), [u for u in requests if not u.startswith(svc.url)]
        cell.close()
