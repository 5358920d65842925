"""The service's API page (/docs) in a real browser: the document's own examples, inline code as code
(no raw backticks), no example value made up as null, nothing fetched from elsewhere."""

from __future__ import annotations

import json

from opportune.service.testing import ServiceProcess
from test_service_browser import browser_context  # noqa: F401  (the fixture: chromium under Playwright)


def test_the_api_page_shows_the_documents_examples_and_code(tmp_path, browser_context):  # noqa: F811
    from playwright.sync_api import expect

    with ServiceProcess(tmp_path / "docs.db") as svc:
        page = browser_context.new_page()
        requests, problems = [], []
        page.on("request", lambda r: requests.append(r.url))
        page.on("pageerror", lambda e: problems.append(str(e)))
        page.goto(svc.url + "/docs")
        cards = page.locator("section.op")
        expect(cards.first).to_be_visible()
        spec = json.loads(page.evaluate("fetch('/openapi.json').then(r => r.text())"))
        operations = sum(len(methods) for methods in spec["paths"].values())
        expect(cards).to_have_count(operations)
        text = page.locator("#ops").inner_text()
        assert "`" not in text, "inline code should be shown as code, not between backticks"
        assert page.locator("#ops code").count() > 0
        upload = page.locator("section.op", has_text="POST /plans").first
        assert '"name": "gearbox"' in upload.inner_text()          # the document's own example body
        for pre in page.locator("#ops pre").all_inner_texts():
            assert "null" not in pre, pre        # no made-up null values (`"id": null` was shown once)
        assert not problems, problems
        assert all(u.startswith(svc.url + "/") for u in requests), requests
