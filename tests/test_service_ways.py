"""Plans written as ways through the service, HTTP and OPC UA: uploaded, run to completion with only
admitted installs under each policy that takes them, a policy that does not (the default included,
while it does not) refused with a 422 naming those that do, and the same limits as a file's."""

from __future__ import annotations

import asyncio
import random

import pytest
import yaml

from opportune.formats.ways import WAYS_POLICIES
from opportune.limits import MAX_WAYS
from opportune.policies.named import DEFAULT_POLICY, POLICIES
from opportune.service.testing import Client, ServiceProcess
from test_ways import admitted, random_ways_plan

pytest.importorskip("asyncua")

from test_opcua import APP, client_cert, trusting  # noqa: E402,F401 (the session's client certificate)


def ways_text() -> tuple[str, object]:
    """A random plan of ways of 9 parts with needs, that admits a sequence, as its file's text."""
    from opportune.engine.ways import WaysCounter
    from opportune.planning.ways import WaysTable

    rng = random.Random(5)
    while True:
        plan = random_ways_plan(rng, 9)
        if WaysCounter(WaysTable.of(plan)).count(0):
            return yaml.safe_dump(plan.to_dict(), sort_keys=False), plan


def drive(post, plan, run_id: int) -> list[str]:
    """Looks of the parts not yet installed nor buffered until the run completes; the installs in order."""
    rng = random.Random(run_id)
    installed, buffered = [], []
    for _ in range(20 * len(plan.parts)):
        left = [p for p in plan.part_ids if p not in installed and p not in buffered]
        r = post(f"/runs/{run_id}/looks", {"visible": rng.sample(left, min(2, len(left)))})
        assert r.status_code == 200, r.text
        action = r.json()["action"]
        r = post(f"/runs/{run_id}/outcomes", {"outcome": "success"})
        assert r.status_code == 200, r.text
        if action["kind"] == "install":
            installed.append(action["part"])
            if action["part"] in buffered:
                buffered.remove(action["part"])
        elif action["kind"] == "buffer":
            buffered.append(action["part"])
        if r.json()["run"]["status"] == "complete":
            break
    return installed


@pytest.fixture(scope="module")
def svc(tmp_path_factory, client_cert):  # noqa: F811
    where = tmp_path_factory.mktemp("ways-svc")
    trusting(where / "pki", client_cert[0])
    with ServiceProcess(where / "w.db", opcua=True, pki=where / "pki", extra_args=("--no-access-log",)) as s:
        yield s


@pytest.fixture
def http(svc):
    """A cell's HTTP client, closed after the test (its socket otherwise waits for a later collection)."""
    client = Client(svc.url, svc.token(cell="cell-w"))
    yield client
    client.close()


def test_a_ways_plan_runs_over_http_under_every_policy_that_takes_one(http):
    text, plan = ways_text()
    r = http.post("/plans", content=text, headers={"Content-Type": "application/yaml"}, key=False)
    assert r.status_code in (200, 201), r.text
    pid = r.json()["id"]
    for policy in [p for p in WAYS_POLICIES if p in POLICIES]:     # the study's strategies are not run policies
        r = http.post("/runs", {"plan": pid, "policy": policy, "buffer_capacity": 2})
        assert r.status_code == 201, (policy, r.text)
        installed = drive(http.post, plan, r.json()["id"])
        assert sorted(installed) == sorted(plan.part_ids) and admitted(plan, installed), (policy, installed)
        trace = http.get(f"/runs/{r.json()['id']}").json()
        assert trace["status"] == "complete"
    # two products side by side from one bin: the joint plan is written as ways too
    r = http.post("/runs", {"plan": pid, "policy": "paper", "products": 2})
    assert r.status_code == 201, r.text
    for policy in sorted(set(POLICIES) - set(WAYS_POLICIES)):
        r = http.post("/runs", {"plan": pid, "policy": policy})
        assert r.status_code == 422 and r.json()["error"]["code"] == "policy_not_for_ways", r.text
        assert all(p in r.json()["error"]["hint"] for p in WAYS_POLICIES)
    r = http.post("/runs", {"plan": pid})
    if DEFAULT_POLICY in WAYS_POLICIES:
        assert r.status_code == 201, r.text
    else:
        assert r.status_code == 422 and "the default policy" in r.json()["error"]["message"], r.text


def test_a_ways_plan_over_the_limits_is_refused_as_a_file_is(http):
    too_many = {"name": "many", "parts": ["a", "b"], "ways": {"a": [{"blockers": ["b"]}] * (MAX_WAYS + 1)}}
    r = http.post("/plans", content=yaml.safe_dump(too_many), headers={"Content-Type": "application/yaml"}, key=False)
    assert r.status_code == 422, r.text
    assert f"at most {MAX_WAYS:,} are accepted" in r.text
    none = {"name": "none", "parts": ["a", "b"], "ways": {"a": [{"blockers": ["b"]}], "b": [{"blockers": ["a"]}]}}
    r = http.post("/plans", content=yaml.safe_dump(none), headers={"Content-Type": "application/yaml"}, key=False)
    assert r.status_code == 422 and "admit no sequence" in r.text, r.text


def test_a_ways_plan_runs_over_opcua(svc, client_cert):  # noqa: F811
    from opportune.service.opcua_client import CellClient, Refused

    token = svc.token(cell="cell-u")
    cert, key = client_cert
    text, plan = ways_text()

    async def run():
        async with CellClient(svc.opcua_endpoint, token, certificate=cert, private_key=key, app_uri=APP) as cell:
            pid = await cell.upload_plan(text)
            run_id = await cell.start_run(pid, policy="slack", buffer_capacity=2)
            rng = random.Random(1)
            installed, buffered = [], []
            for _ in range(20 * len(plan.parts)):
                if await cell.read(run_id, "State") == "Complete":
                    break
                left = [p for p in plan.part_ids if p not in installed and p not in buffered]
                got = await cell.look(run_id, rng.sample(left, min(2, len(left))))
                await cell.outcome(run_id, "success")
                if got["action"] == "install":
                    installed.append(got["part"])
                    if got["part"] in buffered:
                        buffered.remove(got["part"])
                elif got["action"] == "buffer":
                    buffered.append(got["part"])
            state = await cell.read(run_id, "State")
            refused = None
            if DEFAULT_POLICY not in WAYS_POLICIES:
                try:
                    await cell.start_run(pid)
                except Refused as exc:
                    refused = str(exc)
            return installed, state, refused

    installed, state, refused = asyncio.run(run())
    assert state == "Complete" and sorted(installed) == sorted(plan.part_ids) and admitted(plan, installed)
    if DEFAULT_POLICY not in WAYS_POLICIES:
        assert refused is not None and "does not take a plan written as ways" in refused, refused
