"""Load test of the service: N cells driving gearbox runs at once against a real server on loopback.

Each cell (a thread with its own token and keep-alive connection) starts a
run, then loops: a look of 1–3 units drawn from what is still in the bin,
the decided action's outcome (``success``), until the run is done; then the
next run.  Every request is a committed transaction (SQLite, WAL,
``synchronous=FULL``; or PostgreSQL with its durable defaults, ``fsync=on``,
``synchronous_commit=on``).  Bounded by ``--duration``; loopback only; the
server, the database and the clients share the machine, so the numbers are a
floor.

    .venv/bin/python benchmarks/load_service.py --cells 20 --duration 20
    .venv/bin/python benchmarks/load_service.py --db postgresql --workers 2
    .venv/bin/python benchmarks/load_service.py --table      # SQLite 1, PostgreSQL 1, 2 and 4 processes: a Markdown table

``--db postgresql`` starts a throwaway PostgreSQL server (Debian's server
programs, as the tests do); ``--db postgresql+psycopg://...`` uses yours (a
fresh database is best: runs are added to it).  ``--workers N`` runs
``opportune serve --workers N`` (PostgreSQL only): N processes on one port.
The CPU seconds each server process used are reported, to show how the load
was shared.
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


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds a process has used (Linux /proc)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return float("nan")
    fields = stat[stat.rindex(")") + 2:].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(*, cells: int, duration: float, plan: Path, seed: int, db: str, workers: int) -> dict:
    """One load run against a fresh server; the results as a dict."""
    from opportune.service.testing import Client, PostgresServer, ServiceProcess

    tmp = Path(tempfile.mkdtemp(prefix="opportune-load-"))
    pg = None
    if db == "sqlite":
        url, store = tmp / "load.db", "SQLite WAL synchronous=FULL"
    elif db == "postgresql":
        pg = PostgresServer(durable=True).start()
        url, store = pg.database("load"), "PostgreSQL (throwaway server, fsync=on)"
    else:
        url, store = db, "PostgreSQL" if db.startswith("postgresql") else db.split(":")[0]
    svc = ServiceProcess(url, extra_args=("--no-access-log",), log=tmp / "server.log", workers=workers)
    lat: dict[str, list[float]] = {}
    counts = {"runs": 0, "errors": 0}
    lock = threading.Lock()
    try:
        svc.start()
        servers = svc.worker_pids() if workers > 1 else [svc.proc.pid]
        tokens = [svc.token(cell=f"load-{i:02d}") for i in range(cells)]
        clients = [Client(svc.url, t) for t in tokens]
        r = clients[0].post("/plans", content=plan.read_bytes(), headers={"Content-Type": "application/yaml"},
                            params={"filename": plan.name})
        r.raise_for_status()
        plan_id = r.json()["id"]
        for c in clients:  # warm the connection pools and the engine's memo
            c.get("/healthz")
        cpu0 = [cpu_seconds(p) for p in servers]
        own0 = time.process_time()
        start = time.monotonic()
        until = start + duration
        threads = [threading.Thread(target=cell_loop, args=(c, plan_id, random.Random(seed * 1000 + i), until,
                                                             lat, counts, lock)) for i, c in enumerate(clients)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        elapsed = time.monotonic() - start
        cpu = [round(cpu_seconds(p) - c0, 1) for p, c0 in zip(servers, cpu0)]
        own = round(time.process_time() - own0, 1)
        for c in clients:
            c.close()
    finally:
        svc.stop()
        if pg is not None:
            pg.stop()
    every = [x for xs in lat.values() for x in xs]
    return {
        "cells": cells, "db": store, "workers": workers, "seconds": round(elapsed, 2), "requests": len(every),
        "requests_per_s": round(len(every) / elapsed, 1), "runs_completed": counts["runs"], "errors": counts["errors"],
        "latency_ms": {k: {"n": len(v), "p50": round(1000 * statistics.median(v), 2),
                           "p95": round(1000 * percentile(v, 95), 2), "p99": round(1000 * percentile(v, 99), 2)}
                       for k, v in sorted(lat.items()) + [("all", every)]},
        "server_cpu_s": cpu, "client_cpu_s": own,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
    }


def report(result: dict) -> None:
    print(f"{result['db']}, {result['workers']} process(es): {result['cells']} cells, {result['seconds']} s, "
          f"{result['requests']} requests, {result['requests_per_s']} requests/s, {result['runs_completed']} runs "
          f"completed, {result['errors']} errors; server CPU s per process {result['server_cpu_s']}, "
          f"clients {result['client_cpu_s']} ({result['machine']})")
    print(f"{'request':<12} {'n':>7} {'p50 ms':>8} {'p95 ms':>8} {'p99 ms':>8}")
    for k, v in result["latency_ms"].items():
        print(f"{k:<12} {v['n']:>7} {v['p50']:>8} {v['p95']:>8} {v['p99']:>8}")


def markdown(results: list[dict]) -> str:
    lines = ["| store | processes | requests/s | p50 ms | p95 ms | p99 ms | errors | server CPU s (per process) |",
             "|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in results:
        a = r["latency_ms"]["all"]
        cpu = " + ".join(f"{c:g}" for c in r["server_cpu_s"])
        lines.append(f"| {r['db'].split(' (')[0]} | {r['workers']} | {r['requests_per_s']:.0f} | {a['p50']:.0f} | "
                     f"{a['p95']:.0f} | {a['p99']:.0f} | {r['errors']} | {cpu} of {r['seconds']:.0f} s |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, default=20)
    ap.add_argument("--duration", type=float, default=20.0, help="seconds of load")
    ap.add_argument("--plan", type=Path, default=REPO / "examples" / "gearbox.yaml")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--db", default="sqlite",
                    help="sqlite (a fresh file), postgresql (a throwaway server) or a postgresql+psycopg:// URL")
    ap.add_argument("--workers", type=int, default=1, help="server processes (more than 1: PostgreSQL only)")
    ap.add_argument("--table", action="store_true",
                    help="measure SQLite with 1 process and PostgreSQL with 1, 2 and 4; print a Markdown table")
    ap.add_argument("--json", action="store_true", help="print the results as JSON")
    args = ap.parse_args(argv)
    common = dict(cells=args.cells, duration=args.duration, plan=args.plan, seed=args.seed)
    if args.table:
        configs = [("sqlite", 1), ("postgresql", 1), ("postgresql", 2), ("postgresql", 4)]
    else:
        if args.workers > 1 and not args.db.startswith("postgresql"):
            ap.error("--workers above 1 needs --db postgresql (or a PostgreSQL URL)")
        configs = [(args.db, args.workers)]
    results = []
    for db, workers in configs:
        results.append(measure(db=db, workers=workers, **common))
        if not args.json:
            report(results[-1])
            print()
    if args.json:
        print(json.dumps(results if args.table else results[0], indent=2))
    elif args.table:
        print(markdown(results))
    return 1 if any(r["errors"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
