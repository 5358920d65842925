"""Load test of the service: N cells driving gearbox runs at once against a real server on loopback.

Each cell (a thread with its own token and keep-alive connection) starts a
run, then loops: a look of 1–3 units drawn from what is still in the bin,
the decided action's outcome (``success``), until the run is done; then the
next run.  Every request is a committed transaction (SQLite, WAL,
``synchronous=FULL``).  Bounded by ``--duration``; loopback only; the server
and the clients share the machine, so the numbers are a floor.

    .venv/bin/python benchmarks/load_service.py --cells 20 --duration 20
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def percentile(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    if not xs:
        return float("nan")
    k = max(0, min(len(xs) - 1, int(round(q / 100 * len(xs) + 0.5)) - 1))
    return xs[k]


def cell_loop(client, plan_id: str, rng: random.Random, until: float, lat: dict, counts: dict, lock: threading.Lock):
    def timed(kind, path, body):
        t0 = time.perf_counter()
        r = client.post(path, body)
        dt = time.perf_counter() - t0
        with lock:
            lat.setdefault(kind, []).append(dt)
            if r.status_code >= 400:
                counts["errors"] += 1
        return r

    while time.monotonic() < until:
        r = timed("create run", "/runs", {"plan": plan_id})
        if r.status_code != 201:
            return
        run = r.json()
        rid = run["id"]
        in_bin = run["state"]["in_bin"]
        while time.monotonic() < until:
            units = [p for p, n in in_bin.items() for _ in range(n)]
            visible = rng.sample(units, min(len(units), rng.randint(1, 3)))
            r = timed("look", f"/runs/{rid}/looks", {"visible": visible})
            if r.status_code != 200:
                return
            if r.json()["action"]["kind"] == "done":
                with lock:
                    counts["runs"] += 1
                break
            r = timed("outcome", f"/runs/{rid}/outcomes", {"outcome": "success"})
            if r.status_code != 200:
                return
            in_bin = r.json()["run"]["state"]["in_bin"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, default=20)
    ap.add_argument("--duration", type=float, default=20.0, help="seconds of load")
    ap.add_argument("--plan", type=Path, default=REPO / "examples" / "gearbox.yaml")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true", help="print the results as JSON")
    args = ap.parse_args(argv)

    from opportune.service.testing import Client, ServiceProcess

    tmp = Path(tempfile.mkdtemp(prefix="opportune-load-"))
    svc = ServiceProcess(tmp / "load.db", extra_args=("--no-access-log",))
    lat: dict[str, list[float]] = {}
    counts = {"runs": 0, "errors": 0}
    lock = threading.Lock()
    try:
        svc.start()
        tokens = [svc.token(cell=f"load-{i:02d}") for i in range(args.cells)]
        clients = [Client(svc.url, t) for t in tokens]
        r = clients[0].post("/plans", content=args.plan.read_bytes(), headers={"Content-Type": "application/yaml"},
                            params={"filename": args.plan.name})
        r.raise_for_status()
        plan_id = r.json()["id"]
        for c in clients:  # warm the connection pools and the engine's memo
            c.get("/healthz")
        start = time.monotonic()
        until = start + args.duration
        threads = [threading.Thread(target=cell_loop, args=(c, plan_id, random.Random(args.seed * 1000 + i), until,
                                                             lat, counts, lock)) for i, c in enumerate(clients)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        elapsed = time.monotonic() - start
        for c in clients:
            c.close()
    finally:
        svc.stop()
    every = [x for xs in lat.values() for x in xs]
    result = {
        "cells": args.cells, "seconds": round(elapsed, 2), "requests": len(every),
        "requests_per_s": round(len(every) / elapsed, 1), "runs_completed": counts["runs"], "errors": counts["errors"],
        "latency_ms": {k: {"n": len(v), "p50": round(1000 * statistics.median(v), 2),
                           "p95": round(1000 * percentile(v, 95), 2), "p99": round(1000 * percentile(v, 99), 2)}
                       for k, v in sorted(lat.items()) + [("all", every)]},
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, SQLite WAL synchronous=FULL",
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"{result['cells']} cells, {result['seconds']} s, {result['requests']} requests, "
              f"{result['requests_per_s']} requests/s, {result['runs_completed']} runs completed, "
              f"{result['errors']} errors ({result['machine']})")
        print(f"{'request':<12} {'n':>7} {'p50 ms':>8} {'p95 ms':>8} {'p99 ms':>8}")
        for k, v in result["latency_ms"].items():
            print(f"{k:<12} {v['n']:>7} {v['p50']:>8} {v['p95']:>8} {v['p99']:>8}")
    return 1 if counts["errors"] else 0


if __name__ == "__main__":
    sys.exit(main())
