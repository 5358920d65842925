"""Look latency through OPC UA beside HTTP: p50/p95 of the ``Look`` call on the gearbox and ARC111.

One ``opportune serve --opcua`` on loopback (SQLite, its defaults: 50 ms decision budget), one cell;
per plan, runs driven alternately through each protocol with the same seeded looks (1-3 units drawn
from what is still in the bin, each decided action's outcome ``success``), until ``--looks`` looks per
protocol.  Latency is measured at the client, call to answer: OPC UA over Basic256Sha256 Sign &
Encrypt (asyncua), HTTP with a keep-alive connection (httpx).  Server and client share the machine.

    .venv/bin/python benchmarks/bench_opcua.py               # a Markdown table
    .venv/bin/python benchmarks/bench_opcua.py --looks 100 --plans gearbox
"""

from __future__ import annotations

import argparse
import asyncio
import platform
import random
import sys
import tempfile
import time
from pathlib import Path

from opportune.datasets import example_path, salbp_path
from opportune.service.opcua import client_certificate
from opportune.service.opcua_client import CellClient
from opportune.service.testing import Client, ServiceProcess

PLANS = {"gearbox": example_path("gearbox"), "ARC111": salbp_path("ARC111")}
APP = "urn:opportune:bench"


def percentile(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[max(0, min(len(xs) - 1, int(round(q / 100 * len(xs) + 0.5)) - 1))] if xs else float("nan")


def a_look(rng: random.Random, run: dict) -> list[str]:
    units = [p for p, n in sorted(run["state"]["in_bin"].items()) for _ in range(n)]
    return rng.sample(units, min(len(units), rng.randint(1, 3)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--looks", type=int, default=300, help="looks measured per plan and protocol")
    ap.add_argument("--plans", nargs="*", default=list(PLANS), choices=list(PLANS))
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-opcua-"))
    cert, key = client_certificate(tmp / "client", APP, trust_in=tmp / "pki")
    rows = []
    with ServiceProcess(tmp / "bench.db", opcua=True, pki=tmp / "pki", extra_args=("--no-access-log",)) as svc:
        token = svc.token(cell="bench")
        http = Client(svc.url, token)
        for name in args.plans:
            r = http.post(f"/plans?filename={PLANS[name].name}", content=PLANS[name].read_bytes(),
                          headers={"Content-Type": "text/plain"}, key=False)
            assert r.status_code in (200, 201), r.text
            plan = r.json()["id"]
            lat_http: list[float] = []
            lat_ua: list[float] = []

            def http_run(rng: random.Random) -> None:
                run_id = http.post("/runs", {"plan": plan}).json()["id"]
                run = http.get(f"/runs/{run_id}").json()
                while len(lat_http) < args.looks:
                    visible = a_look(rng, run)
                    t0 = time.perf_counter()
                    r = http.post(f"/runs/{run_id}/looks", {"visible": visible})
                    lat_http.append(time.perf_counter() - t0)
                    assert r.status_code == 200, r.text
                    run = http.post(f"/runs/{run_id}/outcomes", {"outcome": "success"}).json()["run"]
                    if run["status"] == "complete":
                        return

            async def ua_run(cell: CellClient, rng: random.Random) -> None:
                run_id = await cell.start_run(plan)
                run = http.get(f"/runs/{run_id}").json()
                while len(lat_ua) < args.looks:
                    visible = a_look(rng, run)
                    t0 = time.perf_counter()
                    await cell.look(run_id, visible)
                    lat_ua.append(time.perf_counter() - t0)
                    out = await cell.outcome(run_id, "success")
                    run = out["answer"]["run"]
                    if out["status"] == "complete":
                        return

            async def drive():
                # Runs alternate between the protocols, each pair with the same seeded looks: both meet the
                # plan's engine equally warm.
                async with CellClient(svc.opcua_endpoint, token, certificate=cert, private_key=key,
                                      app_uri=APP) as cell:
                    k = 0
                    while len(lat_http) < args.looks or len(lat_ua) < args.looks:
                        http_run(random.Random(args.seed + k))
                        await ua_run(cell, random.Random(args.seed + k))
                        k += 1

            asyncio.run(drive())
            for proto, lat in (("HTTP", lat_http), ("OPC UA (Basic256Sha256, Sign & Encrypt)", lat_ua)):
                rows.append((name, proto, len(lat), 1000 * percentile(lat, 50), 1000 * percentile(lat, 95),
                             1000 * max(lat)))
        http.close()
    print(f"<!-- bench_opcua.py --looks {args.looks} --seed {args.seed}; {platform.machine()}, "
          f"Python {sys.version.split()[0]} -->")
    print("| plan | protocol | looks | p50 ms | p95 ms | max ms |")
    print("|---|---|---:|---:|---:|---:|")
    for name, proto, n, p50, p95, mx in rows:
        print(f"| {name} | {proto} | {n} | {p50:.1f} | {p95:.1f} | {mx:.1f} |")


if __name__ == "__main__":
    main()
